//! The co-simulated arm: two ThermoVIA instances driven by `harness::cosim::Master`, with the
//! rigid-body arm, contact and controllers in the master's exchange function.

use super::dynamics::{ArmConfig, V2};
use thermovia_importer::cosim::{Exchange, Master, Port};
use thermovia_importer::Fmu;

pub const ROOM_K: f64 = 295.15;
pub use crate::report::ZERO_CELSIUS;

/// Thermal set-up of one run: each joint's PCL (and housing) temperature, held steady by a heater
/// power that balances the passive loss (0 W at room temperature).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Scenario {
    pub name: String,
    pub pcl_temperature_c: V2,
}

impl Scenario {
    pub fn cold() -> Self {
        Scenario { name: "cold".into(), pcl_temperature_c: [22.0, 22.0] }
    }
    pub fn hot() -> Self {
        Scenario { name: "hot".into(), pcl_temperature_c: [60.0, 60.0] }
    }
}

/// What the master and the reference know about a joint, read from an FMU instance at its
/// temperature (K, C are the FMU's own `effective_stiffness`/`effective_damping` outputs).
#[derive(Clone, Copy, Debug, serde::Serialize)]
pub struct JointProps {
    pub stiffness: f64,
    pub damping: f64,
    pub holding_power: f64,
    pub coupling_inertia: f64,
}

/// FMU parameters of joint `i` at PCL temperature `temp_c`.
pub fn joint_parameters(cfg: &ArmConfig, i: usize, temp_c: f64, initial: Option<(V2, V2)>) -> Vec<(&'static str, f64)> {
    let t = ZERO_CELSIUS + temp_c;
    let mut p = vec![
        ("link_inertia", cfg.coupling_inertia()[i]),
        ("motor_inertia", cfg.motor_inertia),
        ("motor_damping", cfg.motor_damping),
        ("excitation_frequency", cfg.excitation_frequency),
        ("viscoelastic_law", cfg.viscoelastic_law as f64),
        ("initial_pcl_temperature", t),
        ("initial_housing_temperature", t),
    ];
    if let Some((q, m)) = initial {
        p.push(("initial_link_angle", q[i]));
        p.push(("initial_motor_angle", m[i]));
    }
    p
}

/// Reads K, C and the loss conductance from a throw-away instance at the scenario's temperatures.
pub fn probe(fmu: &Fmu, cfg: &ArmConfig, scenario: &Scenario) -> Result<[JointProps; 2], String> {
    let mut out = [JointProps { stiffness: 0.0, damping: 0.0, holding_power: 0.0, coupling_inertia: 0.0 }; 2];
    let ji = cfg.coupling_inertia();
    for i in 0..2 {
        let e = |e: thermovia_importer::HarnessError| e.to_string();
        let mut inst = fmu.instantiate(Some("probe")).map_err(e)?;
        inst.initialize(0.0, None, &joint_parameters(cfg, i, scenario.pcl_temperature_c[i], None)).map_err(e)?;
        let g = inst.get("housing_ambient_conductance").map_err(e)?;
        out[i] = JointProps {
            stiffness: inst.get("effective_stiffness").map_err(e)?,
            damping: inst.get("effective_damping").map_err(e)?,
            holding_power: g * (ZERO_CELSIUS + scenario.pcl_temperature_c[i] - ROOM_K),
            coupling_inertia: ji[i],
        };
    }
    Ok(out)
}

/// Time series of one run, at every communication point.
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct Trace {
    pub t: Vec<f64>,
    pub q: Vec<V2>,
    pub qd: Vec<V2>,
    pub motor_angle: Vec<V2>,
    pub transmitted_torque: Vec<V2>,
    pub motor_torque: Vec<V2>,
    pub tip: Vec<V2>,
    /// Wall force on the tip, N (≥ 0).
    pub contact_force: Vec<f64>,
    pub pcl_temperature_c: Vec<V2>,
}

impl Trace {
    /// An empty trace with room for `n` samples (growing it in the loop costs page faults).
    pub fn with_capacity(n: usize) -> Self {
        let v2 = || Vec::with_capacity(n);
        Trace {
            t: Vec::with_capacity(n),
            q: v2(),
            qd: v2(),
            motor_angle: v2(),
            transmitted_torque: v2(),
            motor_torque: v2(),
            tip: Vec::new(),
            contact_force: Vec::new(),
            pcl_temperature_c: v2(),
        }
    }

    /// Records one sample with the motor torques `u`; `finish` adds the tip and wall force
    /// afterwards (kept out of the stepping loop).
    pub fn push(&mut self, t: f64, y: &JointOutputs, u: V2) {
        self.t.push(t);
        self.q.push(y.q);
        self.qd.push(y.qd);
        self.motor_angle.push(y.motor_angle);
        self.transmitted_torque.push(y.tau);
        self.motor_torque.push(u);
        self.pcl_temperature_c.push(y.pcl_temperature_c);
    }

    pub fn finish(&mut self, cfg: &ArmConfig) {
        self.tip = self.q.iter().map(|&q| cfg.tip(q)).collect();
        self.contact_force = self.q.iter().zip(&self.qd).map(|(&q, &v)| -cfg.contact_force(q, v)[0]).collect();
    }
}

const OUTPUTS: [&str; 7] = [
    "link_angle",
    "link_speed",
    "motor_angle",
    "motor_speed",
    "transmitted_torque",
    "effective_stiffness",
    "pcl_temperature",
];
const INPUTS: [&str; 3] = ["motor_torque", "load_torque", "heater_power"];

/// Ports of one joint in the master.
struct JointPorts {
    y: [Port; 7],
    u: [Port; 3],
}

/// What the master knows about both joints at a communication point (index = joint).
#[derive(Clone, Copy, Debug, Default)]
pub struct JointOutputs {
    pub q: V2,
    pub qd: V2,
    pub motor_angle: V2,
    pub motor_speed: V2,
    /// Transmitted torque τ_t.
    pub tau: V2,
    /// Effective stiffness K_eff (for the controller's deflection compensation).
    pub stiffness: V2,
    pub pcl_temperature_c: V2,
}

impl JointOutputs {
    /// Gathers the outputs in `OUTPUTS` order from `get`.
    fn gather(ports: &[JointPorts], get: impl Fn(Port) -> f64) -> Self {
        let y = |k: usize| [get(ports[0].y[k]), get(ports[1].y[k])];
        let pcl = y(6);
        JointOutputs {
            q: y(0),
            qd: y(1),
            motor_angle: y(2),
            motor_speed: y(3),
            tau: y(4),
            stiffness: y(5),
            pcl_temperature_c: [pcl[0] - ZERO_CELSIUS, pcl[1] - ZERO_CELSIUS],
        }
    }
}

/// The arm's exchange at one communication point: what each FMU gets to hold over [t_n, t_n + h].
/// Returns (motor torques, load torques).
pub fn master_law(cfg: &ArmConfig, props: &[JointProps; 2], t: f64, y: &JointOutputs) -> (V2, V2) {
    let a = cfg.acceleration(y.q, y.qd, y.tau);
    // The FMU's link (inertia J_i) would accelerate at a_i if τ_t stayed at its t_n value.
    let load = [props[0].coupling_inertia * a[0] - y.tau[0], props[1].coupling_inertia * a[1] - y.tau[1]];
    (cfg.motor_torque(t, y.motor_angle, y.motor_speed, y.stiffness), load)
}

/// Co-simulates the arm with communication step `h`, recording every step. `stability_limit`
/// (from `stability::limit`) is checked unless None (only the limit's own numerical check passes
/// None, to run on purpose just above it).
pub fn cosimulate(
    fmu: &Fmu,
    cfg: &ArmConfig,
    scenario: &Scenario,
    h: f64,
    stability_limit: Option<f64>,
    mut progress: impl FnMut(f64),
) -> Result<Trace, String> {
    cfg.validate()?;
    if !(h.is_finite() && h > 0.0) {
        return Err(format!("the communication step must be a positive number of seconds, got {h}"));
    }
    if let Some(limit) = stability_limit {
        if h >= limit {
            return Err(format!(
                "communication step {:.3} ms is at or above this arm's stability limit {:.3} ms (explicit, one-step-delayed coupling; \
                 see `thermovia arm --help`): use a smaller --step, or a smaller kd",
                h * 1e3,
                limit * 1e3
            ));
        }
    }
    let props = probe(fmu, cfg, scenario)?;
    let init = cfg.initial_angles([props[0].stiffness, props[1].stiffness]);
    let mut master = Master::new(0.0, None);
    let mut ports = Vec::new();
    for (i, name) in ["shoulder", "elbow"].into_iter().enumerate() {
        let params = joint_parameters(cfg, i, scenario.pcl_temperature_c[i], Some(init));
        let p = master.add(fmu, name, &params, &INPUTS, &OUTPUTS).map_err(|e| e.to_string())?;
        // thermal quantities change over seconds: read them every 10 ms, not every step
        let every = ((0.01 / h).round() as u64).max(1);
        master.read_every(p, &["effective_stiffness", "pcl_temperature"], every).map_err(|e| e.to_string())?;
        let y = OUTPUTS.map(|n| master.output(p, n).expect("declared"));
        let u = INPUTS.map(|n| master.input(p, n).expect("declared"));
        ports.push(JointPorts { y, u });
    }
    let n = (cfg.duration / h).round() as u64;
    let mut trace = Trace::with_capacity(n as usize + 1);
    let mut exchange = |t: f64, io: &mut Exchange| -> Result<(), String> {
        let y = JointOutputs::gather(&ports, |p| io.get(p));
        if !y.q.iter().chain(y.qd.iter()).all(|v| v.is_finite() && v.abs() < 1e6) {
            return Err("the arm's state ran away (non-finite or huge joint angles/speeds)".into());
        }
        let (u, load) = master_law(cfg, &props, t, &y);
        for i in 0..2 {
            io.set(ports[i].u[0], u[i]);
            io.set(ports[i].u[1], load[i]);
            io.set(ports[i].u[2], props[i].holding_power);
        }
        trace.push(t, &y, u);
        Ok(())
    };
    let every = (n / 100).max(1);
    for k in 0..n {
        master.step(h, &mut exchange).map_err(|e| e.to_string())?;
        if k % every == 0 {
            progress(k as f64 / n as f64);
        }
    }
    progress(1.0);
    // the last communication point (outputs only; the inputs it computes are not used)
    let y = JointOutputs::gather(&ports, |p| master.get(p));
    let (u, _) = master_law(cfg, &props, master.time(), &y);
    trace.push(master.time(), &y, u);
    trace.finish(cfg);
    Ok(trace)
}
