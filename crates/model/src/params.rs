//! Model parameters. Defaults, units, ranges and the source of every number live in the one
//! variable table (`crate::variables`); this struct only holds the values.

use super::material::MaterialTable;
use super::prony::PronyLaw;

/// How the motor side is driven.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MotorDrive {
    /// `motor_torque` drives the motor inertia (the device as built).
    Torque = 0,
    /// The motor angle follows `motor_angle_command` with slope `motor_speed_command` over each
    /// step: measured motor angle as the input to the link, as a calibration needs.
    PrescribedAngle = 1,
}

/// What couples motor and link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transmission {
    /// Springs ∥ Kelvin–Voigt PCL (∥ Maxwell branch, with backlash): the device as built.
    Compliant = 0,
    /// Motor and link are one body: inertia J_m + J_l, viscous B_m + B_l, every torque (motor, load,
    /// friction, gravity) on that body; the link angle equals the motor angle. For drives without
    /// a link encoder (a ball-screw axis), so a calibration need not fake rigidity with a huge
    /// stiffness (a stiff ODE under the adaptive solver).
    Rigid = 1,
}

/// How the output link moves (issue 21).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LinkDrive {
    /// The FMU integrates the link: `link_inertia`, `load_torque`, link damping, friction, gravity.
    Integrated = 0,
    /// A rigid-body engine integrates the link: its angle is `link_angle_command` at the start of
    /// each step and moves at `link_speed_command` over it (held). The link's inertia and every
    /// link-side torque belong to the engine; the FMU integrates motor, transmission and heat, and
    /// reports the transmission's torque on the link averaged over the step
    /// (`transmitted_torque_mean`).
    Prescribed = 1,
}

/// How the thermal side is driven.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ThermalDrive {
    /// `heater_power` drives the two-node heater/housing + PCL network.
    Heater = 0,
    /// The housing follows `housing_temperature_command` (a measured thermocouple); the PCL follows
    /// the housing through `thermal_lag_time_constant` (0: no lag).
    PrescribedHousing = 1,
}

/// How the PCL's crystallinity follows temperature.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Crystallisation {
    /// Crystallinity is the melting curve's at the PCL temperature, heating and cooling alike
    /// (the model before issue 20: stiffness returns at the melting temperature).
    Equilibrium = 0,
    /// Melting on the melting curve, crystallisation by Nakamura's non-isothermal kinetics with a
    /// Hoffman–Lauritzen rate (docs/physics.md §5a): a supercooled melt that recrystallises well
    /// below the melting temperature, at a temperature that depends on the cooling rate.
    Nakamura = 1,
}

/// The PCL's viscoelastic law (docs/physics.md §5c).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViscoelasticLaw {
    /// Kelvin–Voigt with the table's E′, E″ and C = K″/ω at `excitation_frequency` (the paper's
    /// law: exact in steady harmonic motion at that frequency).
    Hysteretic = 0,
    /// A spring, a dashpot and one Maxwell branch per table row ([`PronyLaw`]): causal at every
    /// frequency, for transients; no `excitation_frequency`.
    Prony = 1,
}

/// The backlash's contact law beyond the play (docs/physics.md §10).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BacklashLaw {
    /// The clipped spring–damper: τ_c + τ_d, never pulling (the MSL documentation's curve 2).
    Clipped = 0,
    /// Modelica's `Rotational.Components.ElastoBacklash`: the damper's torque capped by the
    /// spring's, τ_c + min(τ_c, τ_d) (max on the negative side), never pulling: continuous torque
    /// at the start of contact.
    ElastoBacklash = 1,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Params {
    // mechanics
    pub motor_inertia: f64,
    pub motor_damping: f64,
    pub link_inertia: f64,
    pub link_damping: f64,
    pub spring_stiffness: f64,
    pub spring_count: f64,
    pub spring_radius: f64,
    pub pcl_radius: f64,
    pub pcl_shape_factor: f64,
    pub material_table: MaterialTable,
    pub excitation_frequency: f64,
    /// Multiplies the table's E' and E'' (calibration: measured moduli per run).
    pub storage_modulus_scale: f64,
    pub loss_modulus_scale: f64,
    pub viscoelastic_law: ViscoelasticLaw,
    /// The Prony law fitted to the scaled table, kept so it is fitted once per parameter set
    /// (`Model` fills it; `None` means fit when asked, see [`Params::prony_law`]).
    pub prony: Option<PronyLaw>,
    // effects (all off by default)
    pub maxwell_stiffness: f64,
    pub maxwell_relaxation_time: f64,
    pub coulomb_friction: f64,
    /// Half the difference of the Coulomb levels: F+ = F_c + this, F− = F_c − this.
    pub coulomb_friction_asymmetry: f64,
    /// Half the difference of the viscous coefficients: B+ = B_l + this, B− = B_l − this.
    pub viscous_friction_asymmetry: f64,
    pub stribeck_friction: f64,
    pub stribeck_velocity: f64,
    pub friction_smoothing_velocity: f64,
    pub backlash_width: f64,
    pub backlash_law: BacklashLaw,
    pub gravity_link_mass: f64,
    pub gravity_com_distance: f64,
    pub gravity_offset: f64,
    pub thermal_lag_time_constant: f64,
    // thermal
    pub pcl_mass: f64,
    pub pcl_specific_heat_solid: f64,
    pub pcl_specific_heat_melt: f64,
    pub pcl_latent_heat: f64,
    pub pcl_melting_temperature: f64,
    pub pcl_melting_width: f64,
    // crystallisation kinetics (docs/physics.md §5a)
    pub crystallisation: Crystallisation,
    /// ΔH of a perfect PCL crystal, J/kg: crystallinity X = X_c (1 − χ), X_c = L / this.
    pub pcl_perfect_crystal_latent_heat: f64,
    pub avrami_exponent: f64,
    /// Hoffman–Lauritzen's equilibrium melting temperature T_m⁰, K: the rate vanishes there.
    pub pcl_equilibrium_melting_temperature: f64,
    pub pcl_glass_transition_temperature: f64,
    /// U*/R, K (T∞ = T_g − 30 K).
    pub crystallisation_activation_temperature: f64,
    /// K_g, K².
    pub crystallisation_nucleation_constant: f64,
    /// Isothermal half-time t½ at `crystallisation_reference_temperature`, s.
    pub crystallisation_half_time: f64,
    pub crystallisation_reference_temperature: f64,
    pub housing_heat_capacity: f64,
    pub heater_pcl_conductance: f64,
    pub housing_ambient_conductance: f64,
    // initial state
    pub initial_motor_angle: f64,
    pub initial_link_angle: f64,
    pub initial_motor_speed: f64,
    pub initial_link_speed: f64,
    pub initial_housing_temperature: f64,
    pub initial_pcl_temperature: f64,
    // modes and numerics
    pub motor_drive: MotorDrive,
    pub link_drive: LinkDrive,
    pub transmission: Transmission,
    pub thermal_drive: ThermalDrive,
    pub max_internal_step: f64,
    pub solver_tolerance: f64,
}

pub const GRAVITY: f64 = 9.80665;
pub const ZERO_CELSIUS: f64 = 273.15;

impl Default for Params {
    fn default() -> Self {
        Params {
            motor_inertia: 0.005,
            motor_damping: 0.01,
            link_inertia: 0.018,
            link_damping: 0.0,
            spring_stiffness: 1160.0,
            spring_count: 12.0,
            spring_radius: 0.0222,
            pcl_radius: 0.02075,
            pcl_shape_factor: 0.064,
            material_table: MaterialTable::RepairedExperimental,
            excitation_frequency: 0.5,
            storage_modulus_scale: 1.0,
            loss_modulus_scale: 1.0,
            viscoelastic_law: ViscoelasticLaw::Hysteretic,
            prony: None,
            maxwell_stiffness: 0.0,
            maxwell_relaxation_time: 0.1,
            coulomb_friction: 0.0,
            coulomb_friction_asymmetry: 0.0,
            viscous_friction_asymmetry: 0.0,
            stribeck_friction: 0.0,
            stribeck_velocity: 0.05,
            friction_smoothing_velocity: 1e-3,
            backlash_width: 0.0,
            backlash_law: BacklashLaw::Clipped,
            gravity_link_mass: 0.0,
            gravity_com_distance: 0.14,
            gravity_offset: 0.0,
            thermal_lag_time_constant: 0.0,
            pcl_mass: 3.3e-3,
            pcl_specific_heat_solid: 1700.0,
            pcl_specific_heat_melt: 2100.0,
            pcl_latent_heat: 70e3,
            pcl_melting_temperature: ZERO_CELSIUS + 58.0,
            pcl_melting_width: 2.5,
            crystallisation: Crystallisation::Nakamura,
            pcl_perfect_crystal_latent_heat: 139.5e3,
            avrami_exponent: 2.5,
            pcl_equilibrium_melting_temperature: ZERO_CELSIUS + 69.0,
            pcl_glass_transition_temperature: ZERO_CELSIUS - 60.0,
            crystallisation_activation_temperature: 755.0,
            crystallisation_nucleation_constant: 9.782e4,
            crystallisation_half_time: 60.0,
            crystallisation_reference_temperature: ZERO_CELSIUS + 35.0,
            housing_heat_capacity: 2.0,
            heater_pcl_conductance: 0.35,
            housing_ambient_conductance: 0.02,
            initial_motor_angle: 0.0,
            initial_link_angle: 0.0,
            initial_motor_speed: 0.0,
            initial_link_speed: 0.0,
            initial_housing_temperature: ZERO_CELSIUS + 22.0,
            initial_pcl_temperature: ZERO_CELSIUS + 22.0,
            motor_drive: MotorDrive::Torque,
            link_drive: LinkDrive::Integrated,
            transmission: Transmission::Compliant,
            thermal_drive: ThermalDrive::Heater,
            max_internal_step: 1e-3,
            solver_tolerance: 1e-10,
        }
    }
}

impl Params {
    /// `torque` / J_l, the link's acceleration under a torque; 0 when the link is prescribed
    /// ([`LinkDrive::Prescribed`]): its speed is then held over the step whatever acts on it, which
    /// is the limit J_l → ∞ of every step of the mechanics (exact, exponential and adaptive alike).
    /// A division, as before the mode existed, so integrated links keep their results bit for bit.
    pub fn per_link_inertia(&self, torque: f64) -> f64 {
        match self.link_drive {
            LinkDrive::Integrated => torque / self.link_inertia,
            LinkDrive::Prescribed => 0.0,
        }
    }

    /// The Prony law of the scaled material table: the kept fit, or a new one.
    pub fn prony_law(&self) -> PronyLaw {
        self.prony.unwrap_or_else(|| self.fit_prony_law())
    }

    pub fn fit_prony_law(&self) -> PronyLaw {
        let (e1, e2) = self.material_table.rows_kpa();
        PronyLaw::fit(e1.map(|e| e * 1e3 * self.storage_modulus_scale), e2.map(|e| e * 1e3 * self.loss_modulus_scale))
    }

    /// λ of the transmission's relaxing branch: the Prony law's, or the Maxwell effect's.
    pub fn branch_relaxation_time(&self) -> f64 {
        match self.viscoelastic_law {
            ViscoelasticLaw::Hysteretic => self.maxwell_relaxation_time,
            ViscoelasticLaw::Prony => self.prony_law().relaxation_time,
        }
    }

    /// Whether the transmission has a relaxing branch (the Maxwell effect, or the Prony law's):
    /// with backlash its deflection moves the play ([`crate::mechanics::play_centre`]).
    pub fn has_relaxing_branch(&self) -> bool {
        self.maxwell_stiffness != 0.0 || self.viscoelastic_law == ViscoelasticLaw::Prony
    }

    /// Why these parameters cannot run together, if they cannot.
    pub fn conflict(&self) -> Option<String> {
        (self.viscoelastic_law == ViscoelasticLaw::Prony && self.maxwell_stiffness != 0.0).then(|| {
            format!(
                "viscoelastic_law = 1 (Prony) uses the transmission's relaxing branch for the PCL, so \
                 maxwell_stiffness must be 0 (it is {})",
                self.maxwell_stiffness
            )
        })
    }

    /// K_s r_s²: torsional stiffness of the spring bank, N·m/rad (Eq. 4).
    pub fn spring_torsional_stiffness(&self) -> f64 {
        self.spring_stiffness * self.spring_count * self.spring_radius * self.spring_radius
    }

    /// κ r_p²: converts a tensile modulus (Pa) into a torsional stiffness (N·m/rad) (Eq. 2, 10, 11).
    pub fn modulus_to_torsion(&self) -> f64 {
        self.pcl_shape_factor * self.pcl_radius * self.pcl_radius
    }

    /// m g d of the gravity effect, N·m.
    pub fn gravity_torque_amplitude(&self) -> f64 {
        self.gravity_link_mass * GRAVITY * self.gravity_com_distance
    }

    /// True when the link feels no nonlinear torque (gravity, friction); backlash aside.
    pub fn link_torque_is_linear(&self) -> bool {
        self.coulomb_friction == 0.0
            && self.coulomb_friction_asymmetry == 0.0
            && self.viscous_friction_asymmetry == 0.0
            && self.stribeck_friction == 0.0
            && self.gravity_link_mass == 0.0
    }

    /// True when every enabled effect is linear, so the exact exponential step applies.
    pub fn mechanics_is_linear(&self) -> bool {
        self.link_torque_is_linear() && self.backlash_width == 0.0
    }
}
