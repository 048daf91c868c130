//! What a run shows: task metrics per thermal scenario and the co-simulation error against the
//! monolithic reference.

use super::dynamics::ArmConfig;
use super::sim::{JointProps, Scenario, Trace};

/// What the task shows for one thermal scenario.
#[derive(Clone, Debug, serde::Serialize)]
pub struct TaskMetrics {
    pub scenario: Scenario,
    pub joints: [JointProps; 2],
    pub first_contact_s: Option<f64>,
    /// Largest wall force within 50 ms of the first contact: the impact itself, before the
    /// controllers push through the joints.
    pub impact_force_n: f64,
    pub peak_contact_force_n: f64,
    pub peak_contact_force_time_s: f64,
    /// Mean wall force over the last 0.1 s (the arm pressing at rest).
    pub final_contact_force_n: f64,
    /// Times the tip left the wall after the first contact.
    pub rebounds: usize,
    /// From the first contact until the tip stays within 1 mm of its final position.
    pub settling_time_s: Option<f64>,
    /// Largest distance of the tip from the planned path before the contact, mm.
    pub max_tracking_error_mm: f64,
    pub peak_transmitted_torque_nm: [f64; 2],
    pub peak_motor_torque_nm: [f64; 2],
}

pub fn task_metrics(cfg: &ArmConfig, scenario: &Scenario, joints: [JointProps; 2], tr: &Trace) -> TaskMetrics {
    let n = tr.t.len();
    let first = tr.contact_force.iter().position(|&f| f > 0.0);
    let (mut peak, mut peak_t) = (0.0, 0.0);
    for k in 0..n {
        if tr.contact_force[k] > peak {
            peak = tr.contact_force[k];
            peak_t = tr.t[k];
        }
    }
    let tail: Vec<usize> = (0..n).filter(|&k| tr.t[k] >= tr.t[n - 1] - 0.1).collect();
    let final_force = tail.iter().map(|&k| tr.contact_force[k]).sum::<f64>() / tail.len() as f64;
    let fin = tr.tip[n - 1];
    let mut rebounds = 0;
    if let Some(f0) = first {
        for k in f0 + 1..n {
            if tr.contact_force[k] == 0.0 && tr.contact_force[k - 1] > 0.0 {
                rebounds += 1;
            }
        }
    }
    let from = first.unwrap_or(0);
    let settling = (from..n)
        .rev()
        .find(|&k| (tr.tip[k][0] - fin[0]).hypot(tr.tip[k][1] - fin[1]) > 1e-3)
        .map(|k| if k + 1 < n { tr.t[k + 1] - tr.t[from] } else { f64::NAN })
        .or(Some(0.0))
        .filter(|v| v.is_finite());
    let mut track: f64 = 0.0;
    for k in 0..first.unwrap_or(n) {
        let p = cfg.tip(cfg.plan(tr.t[k]).0);
        track = track.max((tr.tip[k][0] - p[0]).hypot(tr.tip[k][1] - p[1]));
    }
    let peak_of = |f: &dyn Fn(usize) -> f64| (0..n).map(f).fold(0.0, |a: f64, b: f64| a.max(b.abs()));
    TaskMetrics {
        scenario: scenario.clone(),
        joints,
        first_contact_s: first.map(|k| tr.t[k]),
        impact_force_n: first.map_or(0.0, |f0| {
            (f0..n).take_while(|&k| tr.t[k] <= tr.t[f0] + 0.05).map(|k| tr.contact_force[k]).fold(0.0, f64::max)
        }),
        peak_contact_force_n: peak,
        peak_contact_force_time_s: peak_t,
        final_contact_force_n: final_force,
        rebounds,
        settling_time_s: settling,
        max_tracking_error_mm: track * 1e3,
        peak_transmitted_torque_nm: [
            peak_of(&|k| tr.transmitted_torque[k][0]),
            peak_of(&|k| tr.transmitted_torque[k][1]),
        ],
        peak_motor_torque_nm: [peak_of(&|k| tr.motor_torque[k][0]), peak_of(&|k| tr.motor_torque[k][1])],
    }
}

/// Co-simulation error against the monolithic reference at one step.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StepError {
    pub step_s: f64,
    pub scenario: String,
    /// max_t |tip_cosim − tip_ref|, m.
    pub tip_error_m: f64,
    /// tip_error / tip travel (largest distance of the reference tip from its start).
    pub relative_error: f64,
    /// max_t,i |q_i,cosim − q_i,ref| / max_i (range of q_i,ref).
    pub relative_joint_error: f64,
    pub peak_force_error_n: f64,
}

/// Compares a co-simulated trace with a reference sampled every `ref_dt` (h a multiple of it).
pub fn compare(cosim: &Trace, reference: &Trace, h: f64, ref_dt: f64, scenario: &str) -> StepError {
    let stride = (h / ref_dt).round() as usize;
    let travel = reference
        .tip
        .iter()
        .map(|p| (p[0] - reference.tip[0][0]).hypot(p[1] - reference.tip[0][1]))
        .fold(0.0, f64::max);
    let range = |i: usize| {
        let v = reference.q.iter().map(|q| q[i]);
        v.clone().fold(f64::NEG_INFINITY, f64::max) - v.fold(f64::INFINITY, f64::min)
    };
    let q_range = range(0).max(range(1));
    let (mut e, mut eq) = (0.0f64, 0.0f64);
    for (k, p) in cosim.tip.iter().enumerate() {
        let r = reference.tip[(k * stride).min(reference.tip.len() - 1)];
        e = e.max((p[0] - r[0]).hypot(p[1] - r[1]));
        let rq = reference.q[(k * stride).min(reference.q.len() - 1)];
        eq = eq.max((cosim.q[k][0] - rq[0]).abs().max((cosim.q[k][1] - rq[1]).abs()));
    }
    let peak = |t: &Trace| t.contact_force.iter().cloned().fold(0.0, f64::max);
    StepError {
        step_s: h,
        scenario: scenario.into(),
        tip_error_m: e,
        relative_error: e / travel,
        relative_joint_error: eq / q_range,
        peak_force_error_n: (peak(cosim) - peak(reference)).abs(),
    }
}
