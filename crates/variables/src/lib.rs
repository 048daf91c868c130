//! The one table of FMU variables. `modelDescription.xml`, the value-reference dispatch in the FMI
//! layer, the start values, the README's variable table and the MuJoCo plugin's config keys are all
//! generated from `VARIABLES`, so they cannot disagree. Start values are read from `Model::default()`
//! through each row's getter.

#![forbid(unsafe_code)]

use thermovia_model::material::MaterialTable;
use thermovia_model::{
    BacklashLaw, Crystallisation, LinkDrive, Model, MotorDrive, ThermalDrive, Transmission, ViscoelasticLaw,
};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Causality {
    Parameter,
    /// Derived from parameters by the model; readable, never set, no start value.
    CalculatedParameter,
    Input,
    Output,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variability {
    Fixed,
    Tunable,
    Continuous,
}

impl Causality {
    /// The FMI spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Causality::Parameter => "parameter",
            Causality::CalculatedParameter => "calculatedParameter",
            Causality::Input => "input",
            Causality::Output => "output",
        }
    }
}

impl Variability {
    /// The FMI spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Variability::Fixed => "fixed",
            Variability::Tunable => "tunable",
            Variability::Continuous => "continuous",
        }
    }
}

pub type RealGet = fn(&mut Model) -> f64;
pub type RealSet = fn(&mut Model, f64);
pub type IntGet = fn(&mut Model) -> i32;
pub type IntSet = fn(&mut Model, i32);

#[derive(Clone, Copy)]
pub enum Access {
    Real { get: RealGet, set: Option<RealSet> },
    Integer { get: IntGet, set: Option<IntSet> },
}

/// A named Integer type: an FMI Enumeration, so tools show names instead of numbers.
pub struct Enumeration {
    pub name: &'static str,
    /// (value, name, description)
    pub items: &'static [(i32, &'static str, &'static str)],
}

#[derive(Clone, Copy)]
pub struct Variable {
    pub name: &'static str,
    pub value_reference: u32,
    pub causality: Causality,
    pub variability: Variability,
    /// FMI unit name ("" for dimensionless).
    pub unit: &'static str,
    /// Inclusive bounds, the same numbers in modelDescription.xml and in the binary's checks.
    /// Every parameter and input has both: its physical range, which also bounds the work of a step.
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub description: &'static str,
    /// Where the default comes from: PAPER, LIT, EST (with the reasoning) or MODE/NUMERICS.
    pub source: &'static str,
    pub access: Access,
    /// Integer variables only: the enumeration they are declared as.
    pub enumeration: Option<&'static Enumeration>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BaseType {
    Real,
    Integer,
}

impl Variable {
    pub fn base_type(&self) -> BaseType {
        match self.access {
            Access::Real { .. } => BaseType::Real,
            Access::Integer { .. } => BaseType::Integer,
        }
    }

    /// Start value as the binary uses it (from the default model).
    pub fn start(&self) -> f64 {
        let mut m = Model::default();
        match self.access {
            Access::Real { get, .. } => get(&mut m),
            Access::Integer { get, .. } => get(&mut m) as f64,
        }
    }

    /// Checks a value against the variable's range; the error names the variable.
    #[inline]
    pub fn check_range(&self, v: f64) -> Result<(), String> {
        let below = matches!(self.min, Some(b) if v < b);
        let above = matches!(self.max, Some(b) if v > b);
        if v.is_finite() && !below && !above {
            return Ok(());
        }
        self.out_of_range(v)
    }

    #[cold]
    #[inline(never)]
    fn out_of_range(&self, v: f64) -> Result<(), String> {
        if !v.is_finite() {
            return Err(format!("{} = {v} is not a finite number", self.name));
        }
        match (self.min, self.max) {
            (Some(b), _) if v < b => Err(format!("{} = {v} is below its minimum {b} {}", self.name, self.unit)),
            (_, Some(b)) if v > b => Err(format!("{} = {v} is above its maximum {b} {}", self.name, self.unit)),
            _ => Ok(()),
        }
    }

    /// Whether the variable is set from outside (parameters, inputs), so it carries a start value
    /// and belongs to a saved state; outputs and calculated parameters are derived.
    pub fn has_start(&self) -> bool {
        matches!(self.causality, Causality::Parameter | Causality::Input)
    }
}

macro_rules! real_param {
    ($vr:expr, $field:ident, $var:ident, $unit:expr, $min:expr, $max:expr, $desc:expr, $src:expr) => {
        Variable {
            name: stringify!($field),
            value_reference: $vr,
            causality: Causality::Parameter,
            variability: Variability::$var,
            unit: $unit,
            min: Some($min),
            max: Some($max),
            description: $desc,
            source: $src,
            access: Access::Real { get: |m| m.params().$field, set: Some(|m, v| m.params_mut().$field = v) },
            enumeration: None,
        }
    };
}

macro_rules! real_calculated {
    ($vr:expr, $name:ident, $unit:expr, $desc:expr, $src:expr, $get:expr) => {
        Variable {
            name: stringify!($name),
            value_reference: $vr,
            causality: Causality::CalculatedParameter,
            variability: Variability::Fixed,
            unit: $unit,
            min: None,
            max: None,
            description: $desc,
            source: $src,
            access: Access::Real { get: $get, set: None },
            enumeration: None,
        }
    };
}

/// An Integer parameter of the FMU's mode enumerations: `field` of the model's parameters, read as
/// its discriminant, set from an integer the range check has already admitted.
macro_rules! mode_param {
    ($vr:expr, $field:ident, $min:expr, $max:expr, $enumeration:ident, $desc:expr, $source:expr, |$v:ident| $from:expr) => {
        Variable {
            name: stringify!($field),
            value_reference: $vr,
            causality: Causality::Parameter,
            variability: Variability::Fixed,
            unit: "",
            min: Some($min),
            max: Some($max),
            description: $desc,
            source: $source,
            access: Access::Integer {
                get: |m| m.params().$field as i32,
                set: Some(|m, $v| m.params_mut().$field = $from),
            },
            enumeration: Some(&$enumeration),
        }
    };
}

macro_rules! real_input {
    ($vr:expr, $field:ident, $unit:expr, $min:expr, $max:expr, $desc:expr) => {
        Variable {
            name: stringify!($field),
            value_reference: $vr,
            causality: Causality::Input,
            variability: Variability::Continuous,
            unit: $unit,
            min: Some($min),
            max: Some($max),
            description: $desc,
            source: "input",
            access: Access::Real { get: |m| m.inputs.$field, set: Some(|m, v| m.inputs.$field = v) },
            enumeration: None,
        }
    };
}

macro_rules! real_output {
    ($vr:expr, $name:ident, $unit:expr, $desc:expr, $get:expr) => {
        Variable {
            name: stringify!($name),
            value_reference: $vr,
            causality: Causality::Output,
            variability: Variability::Continuous,
            unit: $unit,
            min: None,
            max: None,
            description: $desc,
            source: "output",
            access: Access::Real { get: $get, set: None },
            enumeration: None,
        }
    };
}

/// Temperatures: from 1 K to 10,000 K (every material property here is long gone at either end,
/// but the numerics stay finite).
pub const T_MIN: f64 = 1.0;
const T_MAX: f64 = 1e4;
/// Angles: ±1e6 rad (160,000 turns).
const ANGLE: f64 = 1e6;

pub static MATERIAL_TABLE: Enumeration = Enumeration {
    name: "MaterialTable",
    items: &[
        (1, "repaired_experimental", "Table 2 experimental columns, small entries read as MPa (default)"),
        (2, "printed_experimental", "Table 2 experimental columns as printed"),
        (3, "repaired_estimated", "Table 2 estimated columns, small entries read as MPa"),
        (4, "printed_estimated", "Table 2 estimated columns as printed"),
    ],
};

pub static MOTOR_DRIVE: Enumeration = Enumeration {
    name: "MotorDrive",
    items: &[
        (0, "torque", "motor_torque drives the motor inertia"),
        (1, "prescribed_angle", "the motor follows motor_angle_command with slope motor_speed_command"),
    ],
};

pub static LINK_DRIVE: Enumeration = Enumeration {
    name: "LinkDrive",
    items: &[
        (0, "integrated", "the FMU integrates the link (link_inertia, load_torque, link-side effects)"),
        (1, "prescribed", "a rigid-body engine integrates the link: it follows link_angle_command with slope link_speed_command over each step"),
    ],
};

pub static TRANSMISSION: Enumeration = Enumeration {
    name: "Transmission",
    items: &[
        (0, "compliant", "springs and PCL between motor and link (the device)"),
        (1, "rigid", "motor and link are one body (a drive without a link encoder)"),
    ],
};

pub static THERMAL_DRIVE: Enumeration = Enumeration {
    name: "ThermalDrive",
    items: &[
        (0, "heater", "heater_power drives the thermal network"),
        (1, "prescribed_housing", "the housing follows housing_temperature_command"),
    ],
};

pub static CRYSTALLISATION: Enumeration = Enumeration {
    name: "Crystallisation",
    items: &[
        (
            0,
            "equilibrium",
            "crystallinity on the melting curve at the PCL temperature, heating and cooling (no hysteresis)",
        ),
        (
            1,
            "nakamura",
            "melting on the melting curve, crystallisation by Nakamura/Hoffman–Lauritzen kinetics (default)",
        ),
    ],
};

pub static VISCOELASTIC_LAW: Enumeration = Enumeration {
    name: "ViscoelasticLaw",
    items: &[
        (0, "hysteretic", "the table's E', E'' with C = K''/omega at excitation_frequency (the paper's law; default)"),
        (
            1,
            "prony",
            "a spring, a dashpot and one Maxwell branch fitted to the table at 0.5 and 1 Hz: causal, for transients",
        ),
    ],
};

pub static BACKLASH_LAW: Enumeration = Enumeration {
    name: "BacklashLaw",
    items: &[
        (0, "clipped", "the clipped spring-damper: tau_c + tau_d beyond the play, never pulling (default)"),
        (
            1,
            "elasto_backlash",
            "Modelica's Rotational.Components.ElastoBacklash: the damper's torque capped by the spring's, never pulling",
        ),
    ],
};

pub static VARIABLES: &[Variable] = &[
    // ---- inputs
    real_input!(0, heater_power, "W", 0.0, 1e4, "Electrical power into the heaters (>= 0)"),
    real_input!(1, motor_torque, "N.m", -1e4, 1e4, "Torque from the motor on the motor side (motor_drive = 0)"),
    real_input!(2, load_torque, "N.m", -1e4, 1e4, "External torque on the output link"),
    real_input!(3, ambient_temperature, "K", T_MIN, T_MAX, "Temperature of the surroundings"),
    real_input!(4, motor_angle_command, "rad", -ANGLE, ANGLE, "Motor angle at the start of the step (motor_drive = 1)"),
    real_input!(5, motor_speed_command, "rad/s", -1e4, 1e4, "Motor speed over the step (motor_drive = 1)"),
    real_input!(6, housing_temperature_command, "K", T_MIN, T_MAX, "Measured housing temperature (thermal_drive = 1)"),
    real_input!(7, link_angle_command, "rad", -ANGLE, ANGLE, "Link angle at the start of the step, from the engine that integrates the link (link_drive = 1)"),
    real_input!(8, link_speed_command, "rad/s", -1e4, 1e4, "Link speed over the step, held (link_drive = 1)"),
    // ---- outputs
    real_output!(100, motor_angle, "rad", "Motor / housing angle θm", |m| m.motor_angle()),
    real_output!(101, motor_speed, "rad/s", "Motor speed θm'", |m| m.motor_speed()),
    real_output!(102, link_angle, "rad", "Output link angle θl", |m| m.link_angle()),
    real_output!(103, link_speed, "rad/s", "Output link speed θl'", |m| m.link_speed()),
    real_output!(104, pcl_temperature, "K", "PCL temperature (no sensor on the device: the model's estimate)", |m| m.thermal.pcl_temperature),
    real_output!(105, housing_temperature, "K", "Housing surface temperature, where the thermocouple sits", |m| m.thermal.housing_temperature),
    real_output!(106, transmitted_torque, "N.m", "Torque through springs + PCL (+ Maxwell branch)", |m| m.transmitted_torque()),
    real_output!(107, effective_stiffness, "N.m/rad", "K_eff = Re K*(ω) at the excitation frequency and current PCL temperature", |m| m.effective_stiffness()),
    real_output!(108, effective_damping, "N.m.s/rad", "C_eff = Im K*(ω)/ω at the excitation frequency and current PCL temperature", |m| m.effective_damping()),
    real_output!(109, storage_modulus, "Pa", "E'(T) of the PCL at its current temperature", |m| m.coefficients().storage_modulus),
    real_output!(110, loss_modulus, "Pa", "E''(T) of the PCL at its current temperature", |m| m.coefficients().loss_modulus),
    real_output!(111, pcl_melt_fraction, "", "Molten share of the crystallisable PCL, 1 − X/X_c = χ(T_f) (0 solid, 1 melt; a supercooled melt stays molten below the melting range)", |m| m.melt_fraction()),
    real_output!(114, pcl_crystallinity, "", "Crystallinity X of the PCL (crystal mass fraction; X_c on the heating branch when cold)", |m| m.crystallinity()),
    real_output!(115, pcl_structural_temperature, "K", "T_f ≥ T_p: the heating branch's temperature for the PCL's crystallinity (= pcl_temperature on the heating branch)", |m| m.thermal.pcl_structural_temperature),
    real_output!(112, heater_energy, "J", "Electrical energy into the heaters since initialisation", |m| m.thermal.heater_energy),
    real_output!(113, heat_lost, "J", "Heat lost to ambient since initialisation", |m| m.thermal.heat_lost),
    real_output!(120, transmitted_torque_mean, "N.m", "Transmission torque on the link averaged over the last step: its impulse over the step / h, what an engine that integrates the link applies over its next step (link_drive = 1)", |m| m.transmitted_torque_mean),
    // ---- mechanical parameters
    real_param!(200, motor_inertia, Fixed, "kg.m2", 1e-9, 1e3, "J_m, motor + gearbox inertia on the housing side", "EST: rotor inertia reflected through the gearbox; the paper gives none"),
    real_param!(201, motor_damping, Fixed, "N.m.s/rad", 0.0, 1e4, "B_m, viscous loss of motor and gearbox", "EST: small; the motor is position-controlled in the experiments"),
    real_param!(202, link_inertia, Fixed, "kg.m2", 1e-9, 1e3, "J_l, output link with its 0.91 kg mass", "EST: 0.91 kg at 0.14 m plus a light PETG link (the paper's value is lost)"),
    real_param!(203, link_damping, Fixed, "N.m.s/rad", 0.0, 1e4, "B_l, viscous link damping to ground (effect link_damping)", "PAPER: bearing friction minimised in the experiments; off"),
    real_param!(204, spring_stiffness, Fixed, "N/m", 0.0, 1e12, "Stiffness of each compression spring", "PAPER Table 1: 1.16 N/mm"),
    real_param!(205, spring_count, Fixed, "", 0.0, 1e3, "Number of springs", "PAPER Table 1: 12 (total 13.92 N/mm)"),
    real_param!(206, spring_radius, Fixed, "m", 1e-6, 10.0, "r_s, distance of the springs from the axis", "PAPER Table 1: 22.20 mm (K_s r_s² = 6.86 N·m/rad)"),
    real_param!(207, pcl_radius, Fixed, "m", 1e-6, 10.0, "r_p, mean distance of the PCL from the axis", "PAPER Table 1: 20.75 mm"),
    real_param!(208, pcl_shape_factor, Fixed, "m", 1e-9, 10.0, "κ = 3A/L0, PCL cavities' area over thickness", "EST: A ≈ 143 mm², L0 ≈ 6.7 mm per cavity, so cold PCL adds ~4× the spring stiffness"),
    real_calculated!(280, spring_bank_stiffness, "N.m/rad", "K_s = k·n·r_s², torsional stiffness of the spring bank", "from spring_stiffness, spring_count, spring_radius", |m| m.params().spring_torsional_stiffness()),
    real_calculated!(281, modulus_to_torsion, "m3/rad", "κ·r_p²: PCL torsional stiffness per pascal of modulus (K_pcl = E'·this)", "from pcl_shape_factor, pcl_radius", |m| m.params().modulus_to_torsion()),
    real_param!(209, excitation_frequency, Tunable, "Hz", 1e-3, 1e4, "Frequency of the harmonic run: C = K''/ω (hysteretic loss)", "PAPER: 0.5 and 1 Hz"),
    real_param!(210, storage_modulus_scale, Tunable, "", 1e-12, 1e12, "Multiplies E'(T) of the material table (calibration of the storage modulus)", "CALIBRATION: 1 = the table as it is"),
    real_param!(211, loss_modulus_scale, Tunable, "", 1e-12, 1e12, "Multiplies E''(T) of the material table (calibration of the loss modulus)", "CALIBRATION: 1 = the table as it is"),
    // ---- effects, all off by default
    real_param!(220, maxwell_stiffness, Fixed, "N.m/rad", 0.0, 1e9, "K_M of a Maxwell branch (effect frequency_dependent_modulus)", "EFFECT: off"),
    real_param!(221, maxwell_relaxation_time, Fixed, "s", 1e-6, 1e4, "λ of the Maxwell branch", "EFFECT: 0.1 s placeholder while K_M = 0"),
    real_param!(222, coulomb_friction, Fixed, "N.m", 0.0, 1e4, "Coulomb friction torque on the link (effect coulomb_friction)", "EFFECT: off"),
    real_param!(223, stribeck_friction, Fixed, "N.m", 0.0, 1e4, "Static friction above Coulomb, fading with speed", "EFFECT: off"),
    real_param!(224, stribeck_velocity, Fixed, "rad/s", 1e-6, 1e4, "Speed scale of the Stribeck excess", "EST: 0.05 rad/s"),
    real_param!(225, friction_smoothing_velocity, Fixed, "rad/s", 1e-9, 1e3, "tanh smoothing of sign(θl') in the friction law", "NUMERICS: 1e-3 rad/s"),
    real_param!(226, backlash_width, Fixed, "rad", 0.0, 10.0, "Total play of the transmission; dead zone ±width/2 that never pulls, centred on the unloaded element's rest (r q with a relaxing branch, else 0) (effect backlash)", "EFFECT: off"),
    real_param!(227, gravity_link_mass, Fixed, "kg", 0.0, 1e4, "Mass on a link in a vertical plane (effect gravity)", "EFFECT: off (the device carries 0.91 kg, PAPER)"),
    real_param!(228, gravity_com_distance, Fixed, "m", 0.0, 100.0, "Distance of that mass's centre from the axis", "PAPER: link length 140 mm"),
    real_param!(229, gravity_offset, Fixed, "rad", -100.0, 100.0, "Link angle of the hanging rest position", "EFFECT: 0"),
    real_param!(231, coulomb_friction_asymmetry, Fixed, "N.m", -1e4, 1e4, "Half the difference of the Coulomb levels: F+ = coulomb_friction + this, F- = coulomb_friction - this (effect asymmetric_friction)", "EFFECT: off"),
    real_param!(232, viscous_friction_asymmetry, Fixed, "N.m.s/rad", -1e4, 1e4, "Half the difference of the viscous coefficients: B+ = link_damping + this, B- = link_damping - this (effect asymmetric_friction)", "EFFECT: off"),
    real_param!(230, thermal_lag_time_constant, Fixed, "s", 0.0, 1e6, "Lag of the PCL behind the prescribed housing temperature (thermal_drive = 1; effect thermal_lag)", "EFFECT: off"),
    // ---- thermal parameters
    real_param!(240, pcl_mass, Fixed, "kg", 1e-9, 1e3, "PCL mass, all cavities", "PAPER Table 1: 1.10 g × 3 cavities"),
    real_param!(241, pcl_specific_heat_solid, Fixed, "J/(kg.K)", 1.0, 1e5, "c_s of solid PCL", "LIT: ≈ 1.7 J/(g·K)"),
    real_param!(242, pcl_specific_heat_melt, Fixed, "J/(kg.K)", 1.0, 1e5, "c_l of molten PCL", "LIT: ≈ 2.1 J/(g·K)"),
    real_param!(243, pcl_latent_heat, Fixed, "J/kg", 0.0, 1e7, "Heat of fusion of this PCL", "LIT/PAPER: ≈ 70 J/g"),
    real_param!(244, pcl_melting_temperature, Fixed, "K", T_MIN, T_MAX, "Centre of the melting range", "LIT: melting 56–64 °C; 58 °C"),
    real_param!(245, pcl_melting_width, Fixed, "K", 1e-3, 1e3, "Half-width of the tanh melting step", "EST: 2.5 K (onset 50–55 °C, LIT)"),
    real_param!(249, pcl_perfect_crystal_latent_heat, Fixed, "J/kg", 1.0, 1e7, "ΔH₁₀₀, heat of fusion of a perfect PCL crystal: ultimate crystallinity X_c = pcl_latent_heat / this", "LIT: 139.5 J/g"),
    real_calculated!(282, pcl_ultimate_crystallinity, "", "X_c = pcl_latent_heat / pcl_perfect_crystal_latent_heat: crystallinity of the cold PCL on the heating branch", "from pcl_latent_heat, pcl_perfect_crystal_latent_heat (0.50; DSC of a commercial PCL at 10 K/min: 86.2/139.5 = 0.62, LIT)", |m| thermovia_model::crystallisation::ultimate_crystallinity(m.params())),
    real_param!(250, avrami_exponent, Fixed, "", 1.0, 4.0, "n of Nakamura's law α = 1 − exp(−(∫K dt)ⁿ)", "EST: 2.5 (PCL 2–3, LIT)"),
    real_param!(251, pcl_equilibrium_melting_temperature, Fixed, "K", T_MIN, T_MAX, "T_m⁰ of Hoffman–Lauritzen: the crystallisation rate vanishes there", "LIT: 342 K (69 °C); Gibbs–Thomson estimates reach 376 K"),
    real_param!(252, pcl_glass_transition_temperature, Fixed, "K", T_MIN, T_MAX, "T_g: Hoffman–Lauritzen's T∞ = T_g − 30 K", "LIT: ≈ −60 °C"),
    real_param!(253, crystallisation_activation_temperature, Fixed, "K", 0.0, 1e5, "U*/R, Hoffman–Lauritzen's transport activation energy over the gas constant", "LIT: U* = 1500 cal/mol = 6276 J/mol (Hoffman's universal value), U*/R = 755 K"),
    real_param!(254, crystallisation_nucleation_constant, Fixed, "K2", 0.0, 1e8, "K_g, Hoffman–Lauritzen's nucleation constant", "EST: 9.782e4 K², fitted with the half-time to t½(35 °C) = 60 s and t½(45 °C) = 1200 s (PCL 0.5–3e5, LIT)"),
    real_param!(255, crystallisation_half_time, Fixed, "s", 1e-6, 1e9, "Isothermal crystallisation half-time t½ at crystallisation_reference_temperature", "EST: 60 s at 35 °C (gives Tc ≈ 30 °C at 10 K/min, 37 °C at 2 K/min)"),
    real_param!(256, crystallisation_reference_temperature, Fixed, "K", T_MIN, T_MAX, "Temperature of crystallisation_half_time", "EST: 35 °C"),
    real_param!(246, housing_heat_capacity, Fixed, "J/K", 1e-6, 1e7, "C_h of heater foils and housing skin that heat quickly", "EST: the paper's 250–500 J budget leaves room for little more than the PCL"),
    real_param!(247, heater_pcl_conductance, Fixed, "W/K", 1e-9, 1e4, "G_hp from heaters into the PCL", "EST: k = 0.2 W/(m·K) (LIT) over ≈ 18 cm² heater contact, 3 mm path, ×3 for the slab mean"),
    real_param!(248, housing_ambient_conductance, Fixed, "W/K", 0.0, 1e4, "G_ha from housing to ambient", "EST: natural convection ≈ 8 W/(m²·K) over ≈ 25 cm² exposed"),
    // ---- initial state
    real_param!(260, initial_motor_angle, Fixed, "rad", -ANGLE, ANGLE, "θm at initialisation", "0"),
    real_param!(261, initial_link_angle, Fixed, "rad", -ANGLE, ANGLE, "θl at initialisation", "0"),
    real_param!(264, initial_motor_speed, Fixed, "rad/s", -1e4, 1e4, "θm' at initialisation (rigid: the body's speed)", "0"),
    real_param!(265, initial_link_speed, Fixed, "rad/s", -1e4, 1e4, "θl' at initialisation (compliant transmission)", "0"),
    real_param!(262, initial_housing_temperature, Fixed, "K", T_MIN, T_MAX, "Housing temperature at initialisation", "PAPER: room 22 °C"),
    real_param!(263, initial_pcl_temperature, Fixed, "K", T_MIN, T_MAX, "PCL temperature at initialisation", "PAPER: room 22 °C"),
    // ---- numerics
    real_param!(270, max_internal_step, Fixed, "s", 1e-7, 10.0, "Longest internal sub-step, independent of the communication step", "NUMERICS"),
    real_param!(271, solver_tolerance, Fixed, "", 1e-14, 1e-2, "Local error tolerance per step, relative to 1 + the magnitude of each state, used when friction, backlash or gravity is on: Dormand–Prince accepts an estimate ≤ tol; exponential Runge–Kutta keeps its 4th-order solution x4 when the embedded estimate x4 − x3 (the 3rd-order solution's error) is ≤ 2·tol (0.01·tol with Stribeck friction)", "NUMERICS"),
    // ---- modes (Integer)
    mode_param!(300, material_table, 1.0, 4.0, MATERIAL_TABLE, "PCL moduli: 1 repaired experimental (default), 2 printed experimental, 3 repaired estimated, 4 printed estimated", "PAPER Table 2; repair EST (docs/physics.md §4)", |v| MaterialTable::from_index(v).expect("range-checked")),
    mode_param!(301, motor_drive, 0.0, 1.0, MOTOR_DRIVE, "0: motor_torque drives the motor; 1: the motor follows motor_angle_command", "MODE", |v| if v == 0 { MotorDrive::Torque } else { MotorDrive::PrescribedAngle }),
    mode_param!(305, link_drive, 0.0, 1.0, LINK_DRIVE, "0: the FMU integrates the link; 1: an engine integrates it and the FMU follows link_angle_command / link_speed_command (a force element: transmitted_torque_mean is the torque on the link)", "MODE", |v| if v == 0 { LinkDrive::Integrated } else { LinkDrive::Prescribed }),
    mode_param!(303, transmission, 0.0, 1.0, TRANSMISSION, "0: springs and PCL couple motor and link; 1: rigid, motor and link one body of inertia motor_inertia + link_inertia, damping motor_damping + link_damping", "MODE", |v| if v == 0 { Transmission::Compliant } else { Transmission::Rigid }),
    mode_param!(302, thermal_drive, 0.0, 1.0, THERMAL_DRIVE, "0: heater_power drives the thermal network; 1: the housing follows housing_temperature_command", "MODE", |v| if v == 0 { ThermalDrive::Heater } else { ThermalDrive::PrescribedHousing }),
    mode_param!(304, crystallisation, 0.0, 1.0, CRYSTALLISATION, "0: crystallinity follows the melting curve both ways; 1: melting on the curve, crystallisation by Nakamura's kinetics on cooling (supercooling, rate-dependent Tc)", "MODE: 1 (docs/physics.md §5a); the heating branch is the same in both", |v| if v == 0 { Crystallisation::Equilibrium } else { Crystallisation::Nakamura }),
    mode_param!(307, backlash_law, 0.0, 1.0, BACKLASH_LAW, "0: clipped spring-damper beyond the play, tau_c + tau_d, never pulling; 1: Modelica's ElastoBacklash, tau_c + min(tau_c, tau_d) (max on the negative side), never pulling: no torque jump at the start of contact", "MODE: 0 (docs/physics.md §10)", |v| if v == 0 { BacklashLaw::Clipped } else { BacklashLaw::ElastoBacklash }),
    mode_param!(306, viscoelastic_law, 0.0, 1.0, VISCOELASTIC_LAW, "0: hysteretic Kelvin-Voigt, C = K''/omega at excitation_frequency (exact in steady harmonic motion at that frequency; the paper's sweeps); 1: Prony, a spring, a dashpot and one Maxwell branch per table row, causal at every frequency (use for transients; needs maxwell_stiffness = 0)", "MODE: 0 (docs/physics.md §5c); the Prony law misses the table by 6-31 % at 0.5/1 Hz, as every passive law must", |v| if v == 0 { ViscoelasticLaw::Hysteretic } else { ViscoelasticLaw::Prony }),
];

/// The row with this name.
pub fn by_name(name: &str) -> Option<&'static Variable> {
    VARIABLES.iter().find(|v| v.name == name)
}

/// The row with this value reference and base type.
#[inline]
pub fn by_reference(ty: BaseType, vr: u32) -> Option<&'static Variable> {
    use std::sync::OnceLock;
    // Read-only after first use: one dense row-index table per base type (value references are
    // small), so the C API's hot get/set path costs an array access, not a search. Inline arrays,
    // no heap: unloading the library loses nothing.
    const NO_ROW: u8 = u8::MAX;
    static INDEX: OnceLock<[[u8; VR_LIMIT]; 2]> = OnceLock::new();
    let index = INDEX.get_or_init(|| {
        let mut tables = [[NO_ROW; VR_LIMIT]; 2];
        for (i, v) in VARIABLES.iter().enumerate() {
            tables[v.base_type() as usize][v.value_reference as usize] = i as u8;
        }
        tables
    });
    match *index[ty as usize].get(vr as usize)? {
        NO_ROW => None,
        row => Some(&VARIABLES[row as usize]),
    }
}

/// Every value reference is below this (the index in `by_reference` is this long).
pub const VR_LIMIT: usize = 512;

/// The README's variable table (Markdown), generated from `VARIABLES`.
pub fn markdown_table() -> String {
    let mut s = String::from("| name | causality | variability | type | unit | start | range | description | source |\n|---|---|---|---|---|---|---|---|---|\n");
    for v in VARIABLES {
        let start = if v.has_start() { format_number(v.start()) } else { String::new() };
        let range = match (v.min, v.max) {
            (Some(lo), Some(hi)) => format!("{} … {}", format_number(lo), format_number(hi)),
            (Some(lo), None) => format!("≥ {}", format_number(lo)),
            (None, Some(hi)) => format!("≤ {}", format_number(hi)),
            (None, None) => String::new(),
        };
        s += &format!(
            "| `{}` | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            v.name,
            v.causality.as_str(),
            v.variability.as_str(),
            v.enumeration.map_or(format!("{:?}", v.base_type()), |e| format!("Enumeration {}", e.name)),
            v.unit,
            start,
            range,
            v.description,
            if matches!(v.source, "input" | "output") { "" } else { v.source }
        );
    }
    s
}

/// Shortest text that reads back to the same f64 (what the XML and README print).
pub fn format_number(v: f64) -> String {
    let s = format!("{v}");
    if s.len() > 12 {
        format!("{v:e}")
    } else {
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn value_references_are_unique_per_base_type_and_names_unique() {
        assert!(VARIABLES.len() < u8::MAX as usize, "the row index is a u8");
        let mut seen = std::collections::HashSet::new();
        let mut names = std::collections::HashSet::new();
        for v in VARIABLES {
            assert!(seen.insert((v.base_type(), v.value_reference)), "duplicate vr {}", v.value_reference);
            assert!((v.value_reference as usize) < VR_LIMIT, "vr {} needs a longer index", v.value_reference);
            assert!(names.insert(v.name), "duplicate name {}", v.name);
        }
    }

    #[test]
    fn enumerations_cover_their_variables_ranges() {
        for v in VARIABLES {
            if let Some(e) = v.enumeration {
                let values: Vec<f64> = e.items.iter().map(|(x, _, _)| *x as f64).collect();
                assert_eq!(v.base_type(), BaseType::Integer, "{}", v.name);
                let (Some(lo), Some(hi)) = (v.min, v.max) else { panic!("{} needs a range", v.name) };
                let expected: Vec<f64> = (lo as i32..=hi as i32).map(f64::from).collect();
                assert_eq!(values, expected, "{}", v.name);
            }
        }
    }

    #[test]
    fn every_start_value_is_inside_its_own_range() {
        for v in VARIABLES.iter().filter(|v| v.has_start()) {
            v.check_range(v.start()).unwrap();
        }
    }

    /// FMI's min and max are inclusive: the binary takes exactly the bounds it declares and
    /// refuses the next representable number outside them.
    #[test]
    fn every_parameter_and_input_has_an_inclusive_range_the_check_agrees_with() {
        for v in VARIABLES.iter().filter(|v| v.has_start()) {
            let (Some(lo), Some(hi)) = (v.min, v.max) else { panic!("{} has no complete range", v.name) };
            assert!(lo <= v.start() && v.start() <= hi, "{}", v.name);
            v.check_range(lo).unwrap();
            v.check_range(hi).unwrap();
            assert!(v.check_range(lo.next_down()).is_err(), "{}", v.name);
            assert!(v.check_range(hi.next_up()).is_err(), "{}", v.name);
            assert_eq!(format_number(lo).parse::<f64>().unwrap(), lo, "{}", v.name);
            assert_eq!(format_number(hi).parse::<f64>().unwrap(), hi, "{}", v.name);
        }
    }

    #[test]
    fn lookup_by_reference_finds_every_row() {
        for v in VARIABLES {
            assert_eq!(by_reference(v.base_type(), v.value_reference).unwrap().name, v.name);
        }
        assert!(by_reference(BaseType::Real, 99_999).is_none());
        assert!(by_reference(BaseType::Integer, 0).is_none());
    }

    #[test]
    fn range_check_names_the_variable() {
        let e = by_name("link_inertia").unwrap().check_range(-1.0).unwrap_err();
        assert!(e.contains("link_inertia"), "{e}");
        let e = by_name("heater_power").unwrap().check_range(-0.5).unwrap_err();
        assert!(e.contains("heater_power"), "{e}");
        assert!(by_name("heater_power").unwrap().check_range(f64::NAN).is_err());
    }
}
