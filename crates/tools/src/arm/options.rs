//! `thermovia arm` options: the arm, the controllers, the wall and the runs.

use std::path::PathBuf;

use super::dynamics::ArmConfig;

/// Shown after the options by `thermovia arm --help`.
#[cfg_attr(not(feature = "cli"), allow(dead_code))]
const ARM_HELP: &str = "\
What it does:
  A planar two-link arm in a vertical plane with a ThermoVIA FMU at each joint (two instances of
  one .fmu); rigid-body dynamics, gravity, the joint controllers and a wall live in the master.
  The tip makes the same move into the same compliant wall with cold (22 °C) and heated joints,
  then presses against it. The report compares peak forces and settling, checks the co-simulation
  against a monolithic ODE at 0.5/1/2/5 ms, gives the coupling's stability limit (a --step at or
  above it is refused), and times heating and passive cooling of one joint.

Coupling (Jacobi, inputs held over the step, one-step delay):
  FMU -> master: link angle/speed, motor angle/speed, transmitted torque (every step),
                 effective stiffness and PCL temperature (every 10 ms)
  master -> FMU: motor_torque (PD), load_torque = J_i a_i - tau_i, heater_power

Output (--out, replaced atomically): report.md, report.json, tip_path.svg, tip_x.svg,
  contact_force.svg, joint_torques.svg, coupling_error.svg, impedance_switch_*.svg

Examples:
  cargo run --release -p fmu-build
  cargo run --release --bin thermovia -- arm --out out/arm
  cargo run --release --bin thermovia -- arm --payload 0.5 --kd 1.0 --step 0.002";

/// `thermovia arm` options (see `ARM_HELP`).
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
#[cfg_attr(feature = "cli", command(after_long_help = ARM_HELP, allow_negative_numbers = true))]
pub struct ArmArgs {
    /// Folder for the report and plots (replaced atomically).
    #[cfg_attr(feature = "cli", arg(long, default_value = "out/arm"))]
    pub out: PathBuf,
    /// The FMU to load [default: target/fmu/ThermoVIA.fmu]
    #[cfg_attr(feature = "cli", arg(long))]
    pub fmu: Option<PathBuf>,
    /// Communication step of the task runs, s. Must be below the stability limit the report prints.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1e-3))]
    pub step: f64,
    /// Length of link 1 (shoulder → elbow), m.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().l1))]
    pub l1: f64,
    /// Length of link 2 (elbow → tip), m.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().l2))]
    pub l2: f64,
    /// Mass of link 1 (uniform rod), kg.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().m1))]
    pub m1: f64,
    /// Mass of link 2 (uniform rod), kg.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().m2))]
    pub m2: f64,
    /// Mass of the elbow actuator carried at the end of link 1, kg (the paper's device: 0.86 kg).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().elbow_mass))]
    pub elbow_mass: f64,
    /// Payload at the tip, kg (0: none).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().payload_mass))]
    pub payload: f64,
    /// Joint PD proportional gain on the motor angle, N·m/rad.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().kp))]
    pub kp: f64,
    /// Joint PD derivative gain on the motor speed, N·m·s/rad (the hot joints' stability limit
    /// falls as kd rises above the PCL's damping).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().kd))]
    pub kd: f64,
    /// Wall position x, m (the goal lies behind it, so the tip strikes it).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().wall_x))]
    pub wall_x: f64,
    /// Wall stiffness, N/m (a soft obstacle or a person: a few N/mm).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().wall_stiffness))]
    pub wall_stiffness: f64,
    /// Wall damping, N·s/m.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().wall_damping))]
    pub wall_damping: f64,
    /// Length of each task run, s.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = ArmConfig::default().duration))]
    pub duration: f64,
    /// PCL temperature of the heated joints, °C.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 60.0))]
    pub hot_c: f64,
    /// Heater power for the switching-time run, W (the paper: 5–15 W).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 10.0))]
    pub heater_power: f64,
    /// Longest passive cooling simulated, s.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 3600.0))]
    pub cooling_limit: f64,
}

impl ArmArgs {
    pub fn config(&self) -> ArmConfig {
        ArmConfig {
            l1: self.l1,
            l2: self.l2,
            m1: self.m1,
            m2: self.m2,
            elbow_mass: self.elbow_mass,
            payload_mass: self.payload,
            kp: self.kp,
            kd: self.kd,
            wall_x: self.wall_x,
            wall_stiffness: self.wall_stiffness,
            wall_damping: self.wall_damping,
            duration: self.duration,
            ..ArmConfig::default()
        }
    }
}
