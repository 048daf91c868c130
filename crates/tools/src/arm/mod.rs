//! A two-joint planar arm in a vertical plane whose joints are ThermoVIA FMU instances (issue 5).
//!
//! # Coupling scheme (Jacobi, zero-order hold, one-step delay)
//! Each FMU's link *is* its arm joint: the FMU integrates motor, transmission and link exactly over
//! the step; the master owns the rest of the arm (inertia coupling, Coriolis, gravity, the wall at
//! the tip) and the joint controllers. At every communication point t_n:
//!
//! 1. FMU → master: link angle q_i, link speed q_i', motor angle and speed, transmitted torque τ_i,
//!    effective stiffness K_i, PCL temperature (all at t_n).
//! 2. The master solves the arm's forward dynamics a = M(q)⁻¹ (τ − c(q, q') − g(q) + Jᵀ F_wall)
//!    and sends `load_torque_i = J_i a_i − τ_i`: with τ held at its t_n value, the FMU's link (of
//!    inertia J_i) would then accelerate exactly as the arm's joint does. It also sends the motor
//!    torque of the joint PD and the heater power.
//! 3. Both FMUs step from t_n to t_n + h with these inputs held (Jacobi: neither sees the other's
//!    t_{n+1} outputs). The arm's reaction to the change of τ within the step reaches the FMU one
//!    step late; inside the step the FMU uses mobility 1/J_i instead of the arm's M⁻¹.
//!
//! J_i (`link_inertia` of FMU i, a fixed parameter) is the smallest effective inertia 1/(M⁻¹)_ii
//! the arm shows at joint i over all elbow angles. The output hub's own inertia (`hub_inertia`) is
//! part of the master's M(q); the FMU's `link_inertia` is a coupling choice, not extra mass. A tiny
//! J_i (the FMU as a bare hub) does not work with this scheme: the hub then holds τ at its t_n
//! value and the arm's inertia reaches the joint only through J_i a_i.
//!
//! The error is first order in h. The stability limit (`stability`) comes from the explicit
//! loops: the sampled motor PD (worst with a hot, weakly damped PCL), the wall contact and the
//! delayed inertia coupling; steps at or above it are refused.

pub mod dynamics;
pub mod metrics;
pub mod options;
pub mod reference;
pub mod report;
pub mod sim;
pub mod stability;
pub mod thermal;

use dynamics::ArmConfig;
pub use metrics::{compare, task_metrics, StepError, TaskMetrics};
pub use options::ArmArgs;
pub use report::summary;
use sim::Scenario;

#[derive(Clone, Debug, serde::Serialize)]
pub struct StabilityReport {
    /// Limit of the linearised scheme per scenario (cold, hot), s.
    pub limit_cold_s: Option<f64>,
    pub limit_hot_s: Option<f64>,
    /// The limit applied (the smaller).
    pub limit_s: f64,
    pub estimates_cold: stability::Estimates,
    pub estimates_hot: stability::Estimates,
    /// Nonlinear co-simulation through the FMU (limiting scenario) just below / above the limit:
    /// (step, growth of the speed amplitude: last 0.5 s over the 0.5 s after the move ends, < 1
    /// decays; infinite, null in JSON, when the run stopped because the state ran away; diverged).
    pub check_below: (f64, f64, bool),
    pub check_above: (f64, f64, bool),
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct ArmReport {
    pub config: ArmConfig,
    pub coupling_inertia: [f64; 2],
    pub step_s: f64,
    pub stability: StabilityReport,
    pub accuracy: Vec<StepError>,
    /// Largest step at which the relative tip error stays under 1 % (first-order fit, checked).
    pub step_for_one_percent_s: f64,
    pub one_percent_check: Vec<StepError>,
    pub tasks: Vec<TaskMetrics>,
    pub switching: thermal::SwitchResult,
    /// The task again, cold and hot, with the joints' Prony law (an impact with a causal damping
    /// law against the hysteretic one at `excitation_frequency`).
    pub prony: ImpactLaws,
    pub reference_steps: usize,
    /// Wall-clock time of the task co-simulations per simulated second → real-time factor.
    pub real_time_factor: f64,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct ImpactLaws {
    /// Stability limit of the coupling with the Prony law's K_eff, C_eff (cold, hot), s.
    pub limit_cold_s: Option<f64>,
    pub limit_hot_s: Option<f64>,
    /// Cold and hot, as `ArmReport::tasks` (whose runs use the hysteretic law).
    pub tasks: Vec<TaskMetrics>,
}

/// Runs the nonlinear co-simulation at `h` with the limit check off (only for the limit's own
/// check) and returns the speed-amplitude growth and whether it diverged.
fn probe_stability(fmu: &thermovia_importer::Fmu, cfg: &ArmConfig, scenario: &Scenario, h: f64) -> (f64, f64, bool) {
    let mut c = cfg.clone();
    c.duration = (cfg.move_start + cfg.move_duration + 3.0).max(cfg.duration);
    let end_move = cfg.move_start + cfg.move_duration;
    match sim::cosimulate(fmu, &c, scenario, h, None, |_| {}) {
        Err(_) => (h, f64::INFINITY, true),
        Ok(tr) => {
            let amp = |a: f64, b: f64| {
                tr.t.iter()
                    .zip(&tr.qd)
                    .filter(|(t, _)| **t >= a && **t < b)
                    .map(|(_, v)| v[0].abs().max(v[1].abs()))
                    .fold(0.0, f64::max)
            };
            let early = amp(end_move + 0.5, end_move + 1.0);
            let late = amp(c.duration - 0.5, c.duration + 1.0);
            let growth = if early > 0.0 { late / early } else { 0.0 };
            (h, growth, !(growth < 1.0) || !late.is_finite())
        }
    }
}

/// What can stop `thermovia arm`, each with what to fix.
#[derive(Debug, thiserror::Error)]
pub enum ArmError {
    /// An option or the arm's configuration is out of range (naming it and the value).
    #[error("{0}")]
    Options(String),
    /// The FMU could not be loaded or refused a call.
    #[error(transparent)]
    Fmu(#[from] thermovia_importer::HarnessError),
    /// A co-simulation, the reference or the heating run failed (the message says where).
    #[error("{0}")]
    Simulation(String),
    /// Writing the report failed (the message names the path).
    #[error(transparent)]
    Io(#[from] std::io::Error),
}

pub fn run(args: &ArmArgs, progress: &dyn crate::output::Progress) -> Result<(), ArmError> {
    let cfg = args.config();
    cfg.validate().map_err(|e| ArmError::Options(format!("arm configuration refused: {e}")))?;
    if !(args.step.is_finite() && args.step > 0.0) {
        return Err(ArmError::Options(format!("--step {}: must be a positive number of seconds", args.step)));
    }
    if !(args.hot_c.is_finite() && args.hot_c > 22.0) {
        return Err(ArmError::Options(format!("--hot-c {}: must be above room temperature (22 °C)", args.hot_c)));
    }
    crate::output::make_parent(&args.out)?;
    let fmu_path = args.fmu.clone().unwrap_or_else(crate::default_fmu_path);
    let fmu = thermovia_importer::Fmu::open(&fmu_path)?;
    let cold = Scenario::cold();
    let hot = Scenario { name: "hot".into(), pcl_temperature_c: [args.hot_c; 2] };

    progress.start(700);
    let stage = |k: u64, msg: &'static str| {
        progress.set_label(msg);
        progress.set_position(100 * k);
    };

    // 1. stability limit
    stage(0, "stability limit");
    let props_cold = sim::probe(&fmu, &cfg, &cold).map_err(ArmError::Simulation)?;
    let props_hot = sim::probe(&fmu, &cfg, &hot).map_err(ArmError::Simulation)?;
    let limit_cold = stability::limit(&cfg, &props_cold);
    let limit_hot = stability::limit(&cfg, &props_hot);
    let limit = limit_cold.unwrap_or(f64::INFINITY).min(limit_hot.unwrap_or(f64::INFINITY));
    if args.step >= limit {
        return Err(ArmError::Options(format!(
            "--step {:.3} ms is at or above the coupling's stability limit {:.3} ms for this arm (cold joints: {}, hot joints: {}); \
             the explicit loops (sampled motor PD against the PCL's damping, wall contact, delayed inertia coupling) would diverge. \
             Use a smaller --step or a smaller --kd.",
            args.step * 1e3,
            limit * 1e3,
            limit_cold.map_or("none".into(), |v| format!("{:.3} ms", v * 1e3)),
            limit_hot.map_or("none".into(), |v| format!("{:.3} ms", v * 1e3)),
        )));
    }
    let limiting = if limit_hot.unwrap_or(f64::INFINITY) <= limit_cold.unwrap_or(f64::INFINITY) { &hot } else { &cold };
    let check_below =
        if limit.is_finite() { probe_stability(&fmu, &cfg, limiting, 0.95 * limit) } else { (0.0, 0.0, false) };
    let check_above =
        if limit.is_finite() { probe_stability(&fmu, &cfg, limiting, 1.05 * limit) } else { (0.0, 0.0, false) };

    // 2. the task, cold and hot, at the chosen step
    let mut traces = Vec::new();
    let mut tasks = Vec::new();
    let mut wall_time = 0.0;
    for (k, (sc, props)) in [(&cold, props_cold), (&hot, props_hot)].into_iter().enumerate() {
        stage(1 + k as u64, if k == 0 { "task, cold joints" } else { "task, hot joints" });
        let t0 = std::time::Instant::now();
        let tr = sim::cosimulate(&fmu, &cfg, sc, args.step, Some(limit), |f| {
            progress.set_position(100 * (1 + k as u64) + (100.0 * f) as u64)
        })
        .map_err(ArmError::Simulation)?;
        wall_time += t0.elapsed().as_secs_f64();
        tasks.push(task_metrics(&cfg, sc, props, &tr));
        traces.push(tr);
    }
    let real_time_factor = 2.0 * cfg.duration / wall_time;

    // 2b. the same impact with the causal (Prony) law
    let prony_cfg = ArmConfig { viscoelastic_law: 1, ..cfg.clone() };
    let mut prony = ImpactLaws { limit_cold_s: None, limit_hot_s: None, tasks: Vec::new() };
    let mut prony_traces = Vec::new();
    for sc in [&cold, &hot] {
        let props = sim::probe(&fmu, &prony_cfg, sc).map_err(ArmError::Simulation)?;
        let lim = stability::limit(&prony_cfg, &props);
        if sc.name == cold.name {
            prony.limit_cold_s = lim;
        } else {
            prony.limit_hot_s = lim;
        }
        let lim = lim.unwrap_or(f64::INFINITY);
        if args.step >= lim {
            return Err(ArmError::Options(format!(
                "--step {:.3} ms is at or above the coupling's stability limit with the Prony law, {:.3} ms ({} joints): use a smaller --step",
                args.step * 1e3,
                lim * 1e3,
                sc.name
            )));
        }
        let tr = sim::cosimulate(&fmu, &prony_cfg, sc, args.step, Some(lim), |_| {}).map_err(ArmError::Simulation)?;
        prony.tasks.push(task_metrics(&prony_cfg, sc, props, &tr));
        prony_traces.push(tr);
    }

    // 3. accuracy against the monolithic reference
    stage(3, "accuracy vs monolithic");
    let ref_dt = 1e-4; // every step tried is a multiple of it
    let mut refs = Vec::new();
    let mut reference_steps = 0;
    for props in [&props_cold, &props_hot] {
        let (r, n) = reference::simulate(&cfg, props, ref_dt, 1e-10).map_err(ArmError::Simulation)?;
        reference_steps += n;
        refs.push(r);
    }
    let mut accuracy = Vec::new();
    let steps: Vec<f64> = [5e-4, 1e-3, 2e-3, 5e-3].into_iter().filter(|h| *h < limit).collect();
    if steps.is_empty() {
        return Err(ArmError::Options(format!(
            "the stability limit {:.3} ms is below the smallest compared step (0.5 ms): lower --kd or --kp",
            limit * 1e3
        )));
    }
    for (i, h) in steps.iter().enumerate() {
        for (j, sc) in [&cold, &hot].into_iter().enumerate() {
            let tr = sim::cosimulate(&fmu, &cfg, sc, *h, Some(limit), |_| {}).map_err(ArmError::Simulation)?;
            accuracy.push(compare(&tr, &refs[j], *h, ref_dt, &sc.name));
        }
        progress.set_position(300 + (100 * (i + 1) / steps.len()) as u64);
    }
    // first order: e ≈ c·h; c from the smallest step (the cleanest asymptotic value), then checked
    let c = accuracy.iter().filter(|e| e.step_s == steps[0]).map(|e| e.relative_error / e.step_s).fold(0.0, f64::max);
    // on the reference's sample grid, below the stability limit
    let mut h1 =
        if c > 0.0 { ((0.01 / c).min(0.999 * limit) / ref_dt).floor() * ref_dt } else { steps[steps.len() - 1] };
    let mut one_percent_check = Vec::new();
    while h1 >= ref_dt {
        one_percent_check.clear();
        for (j, sc) in [&cold, &hot].into_iter().enumerate() {
            if h1 < limit {
                let tr = sim::cosimulate(&fmu, &cfg, sc, h1, Some(limit), |_| {}).map_err(ArmError::Simulation)?;
                one_percent_check.push(compare(&tr, &refs[j], h1, ref_dt, &sc.name));
            }
        }
        if one_percent_check.iter().all(|e| e.relative_error < 0.01) {
            break;
        }
        h1 -= ref_dt;
    }

    // 4. impedance switching time
    stage(4, "heating and passive cooling");
    let switching = thermal::switching(&fmu, args.heater_power, args.hot_c, args.cooling_limit, 0.01, |f| {
        progress.set_position(400 + (300.0 * f.min(1.0)) as u64)
    })
    .map_err(ArmError::Simulation)?;
    progress.finish();

    let report = ArmReport {
        config: cfg.clone(),
        coupling_inertia: cfg.coupling_inertia(),
        step_s: args.step,
        stability: StabilityReport {
            limit_cold_s: limit_cold,
            limit_hot_s: limit_hot,
            limit_s: limit,
            estimates_cold: stability::estimates(&cfg, &props_cold),
            estimates_hot: stability::estimates(&cfg, &props_hot),
            check_below,
            check_above,
        },
        accuracy,
        step_for_one_percent_s: h1,
        one_percent_check,
        tasks,
        switching,
        prony,
        reference_steps,
        real_time_factor,
    };
    crate::output::replace_folder(&args.out, |dir| {
        report::write_report(dir, &cfg, &report, &traces, &prony_traces, &refs).map_err(std::io::Error::other)
    })?;
    println!("{}", summary(&report));
    println!("report: {}", args.out.join("report.md").display());
    Ok(())
}
