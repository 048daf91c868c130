//! The plugin instance's `<config key=… value=…>`: the FMU's parameter names, read through the same
//! variable table that writes `modelDescription.xml`, with its ranges and its refusals.

use thermovia_model::{LinkDrive, Model, MotorDrive, Params, ThermalDrive, Transmission};
use thermovia_variables::{by_name, Access, Causality, Variable, VARIABLES};

/// The actuator whose ctrl is the heater power (W): a zero-gain `general` actuator, so that its
/// `ctrlrange` bounds the heater natively. Without one the heater is off.
pub const HEATER_KEY: &str = "heater";
/// The share of the joint's own `damping` (N·m·s/rad) that stands for the transmission's damping,
/// taken implicitly by MuJoCo's integrator; the plugin gives it back explicitly (see `joint`).
pub const IMPLICIT_DAMPING_KEY: &str = "implicit_damping";

/// What the plugin reads from its config.
#[derive(Clone, Debug)]
pub struct Setup {
    pub params: Params,
    pub ambient_temperature: f64,
    pub heater: Option<String>,
    pub implicit_damping: f64,
}

/// Every key the plugin declares to MuJoCo: the table's parameters and inputs (so that the ones
/// the plugin does not take are refused with the reason, not as unknown) and its own two.
pub fn keys() -> Vec<&'static str> {
    VARIABLES
        .iter()
        .filter(|v| matches!(v.causality, Causality::Parameter | Causality::Input))
        .map(|v| v.name)
        .chain([HEATER_KEY, IMPLICIT_DAMPING_KEY])
        .collect()
}

/// Why a name of the table is not a config key of the plugin (`None`: it is one).
fn not_here(name: &str) -> Option<&'static str> {
    Some(match name {
        "link_inertia"
        | "link_damping"
        | "coulomb_friction"
        | "stribeck_friction"
        | "stribeck_velocity"
        | "friction_smoothing_velocity"
        | "coulomb_friction_asymmetry"
        | "viscous_friction_asymmetry"
        | "gravity_link_mass"
        | "gravity_com_distance"
        | "gravity_offset" => {
            "the link is MuJoCo's: give its inertia, gravity, damping and friction in the MJCF (body, \
             joint damping, frictionloss)"
        }
        "initial_link_angle" | "initial_link_speed" => "the link's posture is MuJoCo's (qpos, qvel, keyframes)",
        "initial_motor_angle" | "initial_motor_speed" => {
            "the motor starts aligned with the joint, unloaded, at the first step after a reset; to start it \
             elsewhere write its state into plugin_state (thermovia_joint.set_motor)"
        }
        "motor_torque" => "the motor torque is the actuator's ctrl",
        "heater_power" => "the heater power is the ctrl of the actuator the `heater` key names",
        "load_torque" => "loads on the link are MuJoCo's (qfrc_applied, xfrc_applied, contacts)",
        "motor_angle_command" | "motor_speed_command" => "the motor is torque-driven: the ctrl is its torque",
        "housing_temperature_command" => "the plugin has no housing-temperature channel (thermal_drive is 0)",
        "link_angle_command" | "link_speed_command" => "MuJoCo gives the link's angle and speed every step",
        _ => return None,
    })
}

/// The modes the plugin is: link-driven, torque-driven motor, compliant, heater-driven.
const FIXED_MODES: [(&str, i32, &str); 4] = [
    ("link_drive", 1, "MuJoCo integrates the link: the plugin is the link-driven mode"),
    ("motor_drive", 0, "the actuator's ctrl is the motor torque"),
    ("transmission", 0, "a rigid transmission has no torque of its own to apply on the joint"),
    ("thermal_drive", 0, "the heater power is the only thermal channel"),
];

fn default_params() -> Params {
    Params {
        link_drive: LinkDrive::Prescribed,
        motor_drive: MotorDrive::Torque,
        transmission: Transmission::Compliant,
        thermal_drive: ThermalDrive::Heater,
        ..Params::default()
    }
}

/// Reads the config through `value` (the text of a key, `None` when absent). Errors name the key.
pub fn parse(value: &dyn Fn(&str) -> Option<String>) -> Result<Setup, String> {
    let mut model = Model::with_params_only(default_params());
    let ambient = by_name("ambient_temperature").expect("the table has ambient_temperature");
    let mut setup =
        Setup { params: Params::default(), ambient_temperature: ambient.start(), heater: None, implicit_damping: 0.0 };
    for key in keys() {
        let Some(text) = value(key).map(|t| t.trim().to_string()).filter(|t| !t.is_empty()) else { continue };
        if key == HEATER_KEY {
            setup.heater = Some(text);
            continue;
        }
        if key == IMPLICIT_DAMPING_KEY {
            let d = number(key, &text)?;
            if !(d >= 0.0) || !d.is_finite() {
                return Err(format!("{key} = {text} must be a finite damping >= 0 N.m.s/rad"));
            }
            setup.implicit_damping = d;
            continue;
        }
        if let Some(why) = not_here(key) {
            return Err(format!("{key} is not a config key of thermovia.joint: {why}"));
        }
        let v = by_name(key).expect("keys() come from the table");
        let x = value_of(v, &text)?;
        v.check_range(x)?;
        if key == "ambient_temperature" {
            setup.ambient_temperature = x;
            continue;
        }
        if let Some((_, required, why)) = FIXED_MODES.iter().find(|(name, _, _)| *name == key) {
            if x != *required as f64 {
                return Err(format!("{key} = {text}: thermovia.joint is {key} = {required} ({why})"));
            }
            continue;
        }
        match v.access {
            Access::Real { set: Some(set), .. } => set(&mut model, x),
            Access::Integer { set: Some(set), .. } => set(&mut model, x as i32),
            _ => return Err(format!("{key} cannot be set")),
        }
    }
    if let Some(why) = model.params().conflict() {
        return Err(why);
    }
    setup.params = model.params().clone();
    Ok(setup)
}

fn number(key: &str, text: &str) -> Result<f64, String> {
    text.parse::<f64>().map_err(|_| format!("{key} = \"{text}\" is not a number"))
}

/// A value as the table's setter takes it: a number, or for an enumeration one of its item names.
fn value_of(v: &Variable, text: &str) -> Result<f64, String> {
    if let Ok(x) = text.parse::<f64>() {
        if matches!(v.access, Access::Integer { .. }) && x.fract() != 0.0 {
            return Err(format!("{} = {text} is not an integer", v.name));
        }
        return Ok(x);
    }
    match v.enumeration {
        Some(e) => e.items.iter().find(|(_, name, _)| *name == text).map(|(i, _, _)| *i as f64).ok_or_else(|| {
            let names: Vec<String> = e.items.iter().map(|(i, n, _)| format!("{n} ({i})")).collect();
            format!("{} = \"{text}\" is none of {}", v.name, names.join(", "))
        }),
        None => Err(format!("{} = \"{text}\" is not a number", v.name)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    fn parse_map(pairs: &[(&str, &str)]) -> Result<Setup, String> {
        let map: HashMap<String, String> = pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        parse(&|k: &str| map.get(k).cloned())
    }

    #[test]
    fn defaults_are_the_fmus_in_the_link_driven_mode() {
        let s = parse_map(&[]).unwrap();
        let fmu = Params::default();
        assert_eq!(s.params.pcl_mass, fmu.pcl_mass);
        assert_eq!(s.params.spring_stiffness, fmu.spring_stiffness);
        assert_eq!(s.params.link_drive, LinkDrive::Prescribed);
        assert_eq!(s.heater, None);
        assert_eq!(s.implicit_damping, 0.0);
    }

    #[test]
    fn values_go_through_the_tables_setters_and_ranges() {
        let s = parse_map(&[("pcl_mass", "0.004"), ("viscoelastic_law", "1"), ("heater", "h1")]).unwrap();
        assert_eq!(s.params.pcl_mass, 0.004);
        assert_eq!(s.params.viscoelastic_law, thermovia_model::ViscoelasticLaw::Prony);
        assert_eq!(s.heater.as_deref(), Some("h1"));
        let e = parse_map(&[("pcl_mass", "-1")]).unwrap_err();
        assert!(e.contains("pcl_mass") && e.contains("minimum"), "{e}");
        let e = parse_map(&[("pcl_mass", "heavy")]).unwrap_err();
        assert!(e.contains("pcl_mass") && e.contains("not a number"), "{e}");
        let e = parse_map(&[("crystallisation", "0.5")]).unwrap_err();
        assert!(e.contains("not an integer"), "{e}");
    }

    #[test]
    fn what_belongs_to_mujoco_is_refused_with_the_reason() {
        for key in ["link_inertia", "gravity_link_mass", "initial_link_angle", "motor_torque", "initial_motor_angle"] {
            let e = parse_map(&[(key, "1")]).unwrap_err();
            assert!(e.starts_with(key) && e.contains("not a config key"), "{e}");
        }
        let e = parse_map(&[("link_drive", "0")]).unwrap_err();
        assert!(e.contains("link_drive = 1"), "{e}");
        assert!(parse_map(&[("link_drive", "1")]).is_ok());
        let e = parse_map(&[("viscoelastic_law", "1"), ("maxwell_stiffness", "5")]).unwrap_err();
        assert!(e.contains("Prony"), "{e}");
        let e = parse_map(&[("implicit_damping", "-2")]).unwrap_err();
        assert!(e.contains("implicit_damping"), "{e}");
    }

    #[test]
    fn every_key_is_declared_once() {
        let k = keys();
        let mut sorted = k.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), k.len());
        assert!(k.contains(&"pcl_mass") && k.contains(&"ambient_temperature") && k.contains(&HEATER_KEY));
    }
}
