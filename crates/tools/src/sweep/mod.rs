//! The paper's experiment in co-simulation: 0.5 Hz and 1 Hz sweeps across temperature (issue 3).
//!
//! For each temperature a fresh FMU instance is heated from room temperature by the heater loop
//! (housing thermocouple only) with the motor at rest, the state is saved, and each frequency runs
//! from that same state: the motor loop drives θ0 sin ωt from rest, the start-up transient is
//! dropped, and whole steady cycles are analysed (amplitudes, Decay, phase, the paper's estimator
//! and its closed form, against the moduli the FMU reports it used).
//!
//! - [`rig`]: the paper's rig around the FMU: motor PD loop, heater PI loop, the stepping loops.
//! - [`analysis`]: first harmonics over whole cycles.
//! - [`estimator`]: Eq. 15–16, the closed form, conditioning.
//! - [`report`]: summary.json, CSVs, the Markdown report; [`plots`]: SVG figures.

pub mod analysis;
pub mod cycle;
pub mod estimator;
pub mod plots;
pub mod report;
pub mod rig;

use std::path::PathBuf;
use std::time::Instant;

use analysis::Complex;
use estimator::{Conditioning, Estimate, EstimateError, Iterated, Known};
use rig::{HeaterLoop, MotorLoop, Trace, Vrs, WarmupResult, ZERO_CELSIUS};
use thermovia_importer::{Fmu, HarnessError};

/// Encoder resolution of the device: 2500 ppr, ×4 decoding [PAPER].
pub const ENCODER_COUNT_RAD: f64 = 2.0 * std::f64::consts::PI / 10_000.0;

/// `thermovia sweep` options.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "cli", derive(clap::Args))]
pub struct SweepArgs {
    /// Folder for summary.json, report.md, CSVs and SVG plots (written atomically: a failed run
    /// leaves any previous folder untouched).
    #[cfg_attr(feature = "cli", arg(long, default_value = "out/sweep"))]
    pub out: PathBuf,
    /// The FMU to drive [default: target/fmu/ThermoVIA.fmu of this workspace].
    #[cfg_attr(feature = "cli", arg(long))]
    pub fmu: Option<PathBuf>,
    /// Housing temperatures of the runs, °C (comma- or space-separated).
    #[cfg_attr(feature = "cli", arg(long, num_args = 1.., value_delimiter = ',', default_value = "22,40,50,60"))]
    pub temperatures: Vec<f64>,
    /// Motor frequencies, Hz (comma- or space-separated). The step must divide each period.
    #[cfg_attr(feature = "cli", arg(long, num_args = 1.., value_delimiter = ',', default_value = "0.5,1"))]
    pub frequencies: Vec<f64>,
    /// Motor amplitude θ0, rad, as every angle of the command line (the paper's value is lost;
    /// 0.26–0.79 rad, 15–45°, plausible) [default: π/6 = 0.5236, 30°].
    #[cfg_attr(feature = "cli", arg(long, default_value_t = std::f64::consts::FRAC_PI_6, hide_default_value = true))]
    pub amplitude_rad: f64,
    /// Communication step of the harmonic runs, s.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1e-3))]
    pub step: f64,
    /// Start-up transient dropped before the analysis, in cycles.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 6))]
    pub settle_cycles: usize,
    /// Whole steady cycles analysed.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 4))]
    pub cycles: usize,
    /// Motor PD proportional gain, N·m/rad.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 400.0))]
    pub motor_kp: f64,
    /// Motor PD derivative gain, N·m·s/rad (2√(kp J_m) ≈ 2.8 is critical damping of the bare motor).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 3.0))]
    pub motor_kd: f64,
    /// Heater power limit, W (the paper: 5–15 W).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 10.0))]
    pub heater_max_w: f64,
    /// Heater PI proportional gain, W/K.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 4.0))]
    pub heater_kp: f64,
    /// Heater PI integral gain, W/(K·s).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.2))]
    pub heater_ki: f64,
    /// Communication step of the warm-up, s. The motor is at rest with zero torque there, so the
    /// (exactly integrated) mechanics stays at rest; the FMU's `max_internal_step` is set to this
    /// value so the thermal Runge–Kutta takes steps of this size (time constants ≥ 5 s).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.1))]
    pub warmup_step: f64,
    /// How long the housing is held at the target before the runs, s (the PCL inside lags; no
    /// sensor there on the device).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 600.0))]
    pub soak: f64,
    /// Tolerance for "reached the target", K.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.5))]
    pub reach_tolerance: f64,
    /// Uncertainty of H assumed when judging the conditioning of the estimator on the simulated
    /// data (absolute; the simulation is exact up to rounding and leftover transient).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1e-7))]
    pub h_uncertainty: f64,
    /// Largest acceptable predicted relative error of E' or E'' before an estimate is flagged.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 0.1))]
    pub error_limit: f64,
    /// Heater powers of the heating study (22 °C → the highest temperature, housing held vs
    /// constant power), W (comma- or space-separated).
    #[cfg_attr(feature = "cli", arg(long, num_args = 1.., value_delimiter = ',', default_value = "5,10,15"))]
    pub heating_powers: Vec<f64>,
    /// Heater power of the heating–cooling cycle study, W (0: no cycle study).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 10.0))]
    pub cycle_power: f64,
    /// PCL temperature at which the cycle's heater goes off, °C.
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 60.0))]
    pub cycle_target: f64,
    /// Longest cycle, s (heating and passive cooling).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 20000.0))]
    pub cycle_max_s: f64,
    /// The FMU's `crystallisation` parameter for the sweep's runs (0 equilibrium, 1 Nakamura).
    #[cfg_attr(feature = "cli", arg(long, default_value_t = 1))]
    pub crystallisation: i32,
    /// No progress bar (also hidden when stderr is not a terminal or CI=true).
    #[cfg_attr(feature = "cli", arg(long))]
    pub quiet: bool,
}

#[cfg(feature = "cli")]
impl Default for SweepArgs {
    fn default() -> Self {
        use clap::Parser;
        #[derive(clap::Parser)]
        struct W {
            #[cfg_attr(feature = "cli", command(flatten))]
            a: SweepArgs,
        }
        W::parse_from(["sweep"]).a
    }
}

/// One temperature × frequency condition, analysed.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Condition {
    pub temperature_c: f64,
    pub frequency_hz: f64,
    pub motor_amplitude_rad: f64,
    pub link_amplitude_rad: f64,
    pub decay_rad: f64,
    pub decay_normalized: Option<f64>,
    pub phase_deg: f64,
    /// Closed-form estimates (exact for this model).
    pub k_eff_nm_per_rad: f64,
    pub c_eff_nms_per_rad: f64,
    pub e_storage_kpa: f64,
    pub e_loss_kpa: f64,
    pub commanded_amplitude_rad: f64,
    pub h_re: f64,
    pub h_im: f64,
    pub closed_form_status: String,
    /// The paper's Eq. 15–16 iterated.
    pub paper_method: Option<Iterated>,
    pub paper_method_status: String,
    /// What the FMU reports it used, averaged over the analysed cycles.
    pub model_k_eff_nm_per_rad: f64,
    pub model_c_eff_nms_per_rad: f64,
    pub model_e_storage_kpa: f64,
    pub model_e_loss_kpa: f64,
    pub housing_temperature_c: f64,
    pub pcl_temperature_c: f64,
    /// Spread (max − min) of the PCL temperature over the analysed cycles, K.
    pub pcl_temperature_drift_k: f64,
    /// Analytic H = K*/(K* − J_l ω²) at the model's values.
    pub analytic_h_re: f64,
    pub analytic_h_im: f64,
    /// Conditioning on the simulated data (uncertainty `h_uncertainty`).
    pub conditioning: Conditioning,
    /// Conditioning if H were read to one encoder count of the link amplitude (the device).
    pub conditioning_encoder: Conditioning,
    /// Relative error of the closed-form E', E'' against the model's values.
    pub e_storage_error: f64,
    pub e_loss_error: f64,
    pub paper_e_storage_error: Option<f64>,
    pub paper_e_loss_error: Option<f64>,
    /// RMS distance of the steady link angle from a sinusoid, relative to its amplitude.
    pub link_non_sinusoidal: f64,
    /// Time after which the link stays within 0.1 % of θ0 of its steady sinusoid, s.
    pub transient_s: f64,
    /// Largest |θm − θ0 sin ωt| over the analysed cycles, rad (motor tracking).
    pub motor_tracking_error_rad: f64,
    #[serde(skip)]
    pub trace: Trace,
    #[serde(skip)]
    pub window: (usize, usize),
}

/// The whole sweep.
#[derive(Debug)]
pub struct SweepResult {
    pub args: SweepArgs,
    pub conditions: Vec<Condition>,
    pub warmups: Vec<(WarmupResult, Trace)>,
    pub heating: Vec<rig::HeatingResult>,
    /// Heating–cooling cycles (issue 20): crystallisation kinetics and the equilibrium law.
    pub cooling_cycles: Vec<cycle::CycleResult>,
    pub known: Known,
    pub link_inertia: f64,
    pub ambient_c: f64,
    /// Wall time of the sweep proper: opening the FMU, warm-ups, runs, analysis.
    pub simulate_seconds: f64,
    /// Wall time of the heating study (extra instances heated at several powers).
    pub heating_seconds: f64,
    pub fmu_path: PathBuf,
}

/// What can stop a sweep, each with what to fix.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// An option out of range, naming the option and the value.
    #[error("{0}")]
    Options(String),
    /// The FMU refused a call, or could not be loaded.
    #[error(transparent)]
    Fmu(#[from] HarnessError),
    /// Writing the outputs failed (the message names the path).
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error("summary.json: {0}")]
    Json(#[from] serde_json::Error),
    /// A plot could not be drawn.
    #[error("plot: {0}")]
    Plot(String),
}

fn validate(a: &SweepArgs) -> Result<(), String> {
    if a.temperatures.is_empty() || a.frequencies.is_empty() {
        return Err("need at least one temperature and one frequency".into());
    }
    // Signs and ranges first, so a negative step is called negative, not "does not divide".
    let positive =
        [("--step", a.step, "s"), ("--warmup-step", a.warmup_step, "s"), ("--heater-max-w", a.heater_max_w, "W")];
    for (option, value, unit) in positive {
        if !(value > 0.0) || !value.is_finite() {
            return Err(format!("{option} {value}: must be a finite number > 0 {unit}"));
        }
    }
    check_amplitude(a.amplitude_rad)?;
    if !(a.soak >= 0.0) {
        return Err(format!("--soak {}: must be ≥ 0 s", a.soak));
    }
    if a.cycles < 1 {
        return Err(format!("--cycles {}: must be ≥ 1", a.cycles));
    }
    if !(a.cycle_power >= 0.0) || !a.cycle_power.is_finite() {
        return Err(format!("--cycle-power {}: must be a finite number ≥ 0 W", a.cycle_power));
    }
    if !(a.cycle_max_s > 0.0) || !a.cycle_max_s.is_finite() {
        return Err(format!("--cycle-max-s {}: must be a finite number > 0 s", a.cycle_max_s));
    }
    if !(0..=1).contains(&a.crystallisation) {
        return Err(format!("--crystallisation {}: 0 (equilibrium) or 1 (Nakamura)", a.crystallisation));
    }
    for &f in &a.frequencies {
        if !(f > 0.0) || !f.is_finite() {
            return Err(format!("--frequencies {f}: each frequency must be a finite number > 0 Hz"));
        }
        if analysis::samples_per_period(f, a.step).is_none() {
            return Err(format!(
                "--step {} s does not divide the period of {f} Hz into a whole number (≥ 8) of steps",
                a.step
            ));
        }
    }
    Ok(())
}

/// `--amplitude-rad` of `sweep` and `synth`: at most a half turn, which also catches an amplitude
/// meant in degrees (30 for 30°).
pub fn check_amplitude(amplitude_rad: f64) -> Result<(), String> {
    use crate::calibrate::quality::short;
    if amplitude_rad > 0.0 && amplitude_rad <= std::f64::consts::PI {
        return Ok(());
    }
    let hint = if amplitude_rad > std::f64::consts::PI && amplitude_rad <= 360.0 {
        format!(" (in degrees? {}° is {} rad)", short(amplitude_rad), short(amplitude_rad.to_radians()))
    } else {
        String::new()
    };
    Err(format!("--amplitude-rad {}: must be a number > 0 and ≤ π rad{hint}", short(amplitude_rad)))
}

/// What one temperature gives: its conditions (one per frequency), its warm-up if heated, and what
/// the estimator needs to know of the FMU.
struct TemperatureBlock {
    conditions: Vec<Condition>,
    warmup: Option<(WarmupResult, Trace)>,
    known: Known,
    ambient_c: f64,
}

/// Warm-up to `temp_c` (when above ambient) and one harmonic run per frequency, on one instance.
fn temperature_block(
    args: &SweepArgs,
    fmu: &Fmu,
    temp_c: f64,
    progress: &(dyn Fn(&str) + Sync),
) -> Result<TemperatureBlock, SweepError> {
    let mut inst = fmu.instantiate(None)?;
    inst.initialize(
        0.0,
        None,
        &[
            ("excitation_frequency", args.frequencies[0]),
            ("max_internal_step", args.warmup_step.max(args.step)),
            ("crystallisation", args.crystallisation as f64),
        ],
    )?;
    let vrs = Vrs::resolve(&inst)?;
    let (jm, bm) = (inst.get("motor_inertia")?, inst.get("motor_damping")?);
    let k = Known {
        link_inertia: inst.get("link_inertia")?,
        // the FMU's own calculated parameters: the tools do not re-derive its formulas
        spring_stiffness: inst.get("spring_bank_stiffness")?,
        modulus_to_torsion: inst.get("modulus_to_torsion")?,
    };
    let ambient_c = inst.get("ambient_temperature")? - ZERO_CELSIUS;
    let heater = HeaterLoop {
        target_k: temp_c + ZERO_CELSIUS,
        kp: args.heater_kp,
        ki: args.heater_ki,
        p_max: args.heater_max_w,
        integral: 0.0,
    };
    if temp_c < ambient_c - args.reach_tolerance {
        return Err(SweepError::Options(format!(
            "{temp_c} °C is below the ambient {ambient_c:.2} °C: the device has heaters only (no cooling)"
        )));
    }
    let mut warmup = None;
    let heater = if temp_c > ambient_c + args.reach_tolerance {
        let (heater, w, trace) =
            warm_up_until(&mut inst, &vrs, heater, args.warmup_step, args.soak, args.reach_tolerance)?;
        warmup = Some((w, trace));
        progress(&format!("warm-up to {temp_c} °C"));
        Some(heater)
    } else {
        progress(&format!("{temp_c} °C: room temperature, no heating"));
        None
    };
    let saved = inst.save_state()?;
    let mut conditions = Vec::new();
    for &f in &args.frequencies {
        inst.restore_state(&saved)?;
        inst.set("excitation_frequency", f)?;
        let omega = 2.0 * std::f64::consts::PI * f;
        let motor = MotorLoop {
            amplitude: args.amplitude_rad,
            omega,
            kp: args.motor_kp,
            kd: args.motor_kd,
            motor_inertia: jm,
            motor_damping: bm,
        };
        let n = analysis::samples_per_period(f, args.step).expect("validated");
        let steps = n * (args.settle_cycles + args.cycles);
        let trace = rig::harmonic_run(&mut inst, &vrs, &motor, heater, args.step, steps)?;
        conditions.push(analyse(args, &k, temp_c, f, &motor, trace, n));
        progress(&format!("{temp_c} °C, {f} Hz"));
    }
    Ok(TemperatureBlock { conditions, warmup, known: k, ambient_c })
}

/// Runs every condition through the FMU. `progress` is called after each finished unit of work
/// (one warm-up or one run) with a label.
pub fn simulate(args: &SweepArgs, progress: impl FnMut(&str) + Send) -> Result<SweepResult, SweepError> {
    validate(args).map_err(SweepError::Options)?;
    let fmu_path = args.fmu.clone().unwrap_or_else(crate::default_fmu_path);
    let started = Instant::now();
    let fmu = Fmu::open(&fmu_path)?;
    let progress = std::sync::Mutex::new(progress);
    let report = |label: &str| (progress.lock().unwrap_or_else(|p| p.into_inner()))(label);
    // Temperatures are independent (each its own instance, warm-up and runs): one worker per core,
    // results kept in the order of --temperatures, so the output does not depend on the cores.
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get()).min(args.temperatures.len());
    let next = std::sync::atomic::AtomicUsize::new(0);
    let slots: Vec<std::sync::Mutex<Option<Result<TemperatureBlock, SweepError>>>> =
        args.temperatures.iter().map(|_| std::sync::Mutex::new(None)).collect();
    std::thread::scope(|scope| {
        for _ in 0..workers {
            scope.spawn(|| loop {
                let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                let Some(&temp_c) = args.temperatures.get(i) else { break };
                let block = temperature_block(args, &fmu, temp_c, &report);
                *slots[i].lock().unwrap_or_else(|p| p.into_inner()) = Some(block);
            });
        }
    });
    let (mut conditions, mut warmups) = (Vec::new(), Vec::new());
    let (mut known, mut ambient_c, mut link_inertia) = (None, 22.0, 0.0);
    for slot in slots {
        let block = slot.into_inner().unwrap_or_else(|p| p.into_inner()).expect("every temperature ran")?;
        conditions.extend(block.conditions);
        warmups.extend(block.warmup);
        (known, ambient_c, link_inertia) = (Some(block.known), block.ambient_c, block.known.link_inertia);
    }
    let progress = |label: &str| report(label);
    let simulate_seconds = started.elapsed().as_secs_f64();
    let started = Instant::now();
    // Heating study from room temperature to the highest target (cheap: coarse step, motor at rest).
    let mut heating = Vec::new();
    let top = args.temperatures.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    if top > ambient_c + args.reach_tolerance {
        for &p in &args.heating_powers {
            for hold in [true, false] {
                let mut inst = fmu.instantiate(None)?;
                inst.initialize(0.0, None, &[("max_internal_step", args.warmup_step)])?;
                let vrs = Vrs::resolve(&inst)?;
                let heater = HeaterLoop {
                    target_k: top + ZERO_CELSIUS,
                    kp: args.heater_kp,
                    ki: args.heater_ki,
                    p_max: p,
                    integral: 0.0,
                };
                heating.push(rig::heating_study(
                    &mut inst,
                    &vrs,
                    heater,
                    hold,
                    args.reach_tolerance,
                    args.warmup_step,
                    1800.0,
                )?);
            }
        }
        progress("heating study");
    }
    // Heating–cooling cycle, new law and old side by side (cheap: coarse step, motor at rest).
    let mut cooling_cycles = Vec::new();
    if args.cycle_power > 0.0 {
        for law in [1, 0] {
            cooling_cycles.push(cycle::cycle_study(
                &fmu,
                law,
                args.cycle_power,
                args.cycle_target,
                args.warmup_step,
                args.cycle_max_s,
                1.0,
            )?);
        }
        progress("heating–cooling cycle");
    }
    let heating_seconds = started.elapsed().as_secs_f64();
    normalize_decay(&mut conditions, args.temperatures[0]);
    Ok(SweepResult {
        args: args.clone(),
        conditions,
        warmups,
        heating,
        cooling_cycles,
        known: known.expect("at least one temperature"),
        link_inertia,
        ambient_c,
        simulate_seconds,
        heating_seconds,
        fmu_path,
    })
}

/// Heats until the housing is within `tol` of the target, then holds it `soak` s.
fn warm_up_until(
    inst: &mut thermovia_importer::Instance,
    vrs: &Vrs,
    heater: HeaterLoop,
    h: f64,
    soak: f64,
    tol: f64,
) -> Result<(HeaterLoop, WarmupResult, Trace), HarnessError> {
    // Heat-up phase in chunks until the housing reaches the target (bounded: 1 h).
    let (mut heater, mut res, mut trace) = rig::warm_up(inst, vrs, heater, h, 0.0, tol)?;
    let chunk = 10.0;
    while res.housing_reached_s.is_none() && res.duration_s < 3600.0 {
        let t_off = res.duration_s;
        let (h2, r2, t2) = rig::warm_up(inst, vrs, heater, h, chunk, tol)?;
        heater = h2;
        merge(&mut res, &mut trace, r2, t2, t_off);
    }
    let t_off = res.duration_s;
    let (h2, r2, t2) = rig::warm_up(inst, vrs, heater, h, soak, tol)?;
    merge(&mut res, &mut trace, r2, t2, t_off);
    Ok((h2, res, trace))
}

fn merge(res: &mut WarmupResult, trace: &mut Trace, r2: WarmupResult, t2: Trace, t_off: f64) {
    let shift = |o: Option<f64>| o.map(|t| t + t_off);
    if res.housing_reached_s.is_none() {
        res.housing_reached_s = shift(r2.housing_reached_s);
        res.housing_reached_energy_j = r2.housing_reached_energy_j;
    }
    if res.pcl_reached_s.is_none() {
        res.pcl_reached_s = shift(r2.pcl_reached_s);
        res.pcl_reached_energy_j = r2.pcl_reached_energy_j;
    }
    res.duration_s += r2.duration_s;
    res.energy_j = r2.energy_j;
    res.final_housing_c = r2.final_housing_c;
    res.final_pcl_c = r2.final_pcl_c;
    // skip the chunk's first sample: it repeats the previous chunk's last
    for k in 1..t2.len() {
        trace.time.push(t2.time[k] + t_off);
        trace.reference.push(t2.reference[k]);
        trace.motor_torque.push(t2.motor_torque[k]);
        trace.heater_power.push(t2.heater_power[k]);
        for (c, src) in trace.outputs.iter_mut().zip(&t2.outputs) {
            c.push(src[k]);
        }
    }
}

fn analyse(args: &SweepArgs, k: &Known, temp_c: f64, f: f64, motor: &MotorLoop, trace: Trace, n: usize) -> Condition {
    let omega = motor.omega;
    let len = n * args.cycles;
    let start = trace.len() - len;
    let t = &trace.time;
    let cm = analysis::first_harmonic(t, trace.column(rig::O_MOTOR_ANGLE), omega, start, len);
    let cl = analysis::first_harmonic(t, trace.column(rig::O_LINK_ANGLE), omega, start, len);
    let h = cl / cm;
    let mean = |o: usize| analysis::stats(&trace.column(o)[start..]).0;
    let (model_k, model_c) = (mean(rig::O_K_EFF), mean(rig::O_C_EFF));
    let (model_e1, model_e2) = (mean(rig::O_E1), mean(rig::O_E2));
    let (_, pmin, pmax) = analysis::stats(&trace.column(rig::O_PCL)[start..]);
    let analytic = estimator::link_over_motor(model_k, model_c, omega, k.link_inertia);
    let phase = -h.arg();
    let k_star_model = Complex::new(model_k, omega * model_c);

    let (closed, closed_status) = match estimator::closed_form(h, omega, k, args.h_uncertainty, args.error_limit) {
        Ok((e, _)) => (Some(e), "ok".to_string()),
        Err(e @ EstimateError::TooUncertain { estimate, .. }) => (Some(estimate), format!("flagged: {e}")),
        Err(e) => (None, e.to_string()),
    };
    let nan = Estimate { k_eff: f64::NAN, c_eff: f64::NAN, e_storage: f64::NAN, e_loss: f64::NAN };
    let est = closed.unwrap_or(nan);
    let (paper, paper_status) = match estimator::paper_iterative(h.norm(), phase, omega, k, 1e-12, 10_000_000) {
        Ok(it) => (Some(it), format!("converged in {} iterations", it.iterations)),
        Err(e) => (None, e.to_string()),
    };
    let rel = |a: f64, b: f64| (a - b) / b;
    let motor_amp = cm.norm();
    let link_amp = cl.norm();
    let tracking = (start..trace.len())
        .map(|i| (trace.column(rig::O_MOTOR_ANGLE)[i] - motor.reference(t[i]).0).abs())
        .fold(0.0, f64::max);
    let encoder_dh = ENCODER_COUNT_RAD / motor_amp;
    Condition {
        temperature_c: temp_c,
        frequency_hz: f,
        motor_amplitude_rad: motor_amp,
        link_amplitude_rad: link_amp,
        decay_rad: motor_amp - link_amp,
        decay_normalized: None,
        phase_deg: phase.to_degrees(),
        k_eff_nm_per_rad: est.k_eff,
        c_eff_nms_per_rad: est.c_eff,
        e_storage_kpa: est.e_storage / 1e3,
        e_loss_kpa: est.e_loss / 1e3,
        commanded_amplitude_rad: motor.amplitude,
        h_re: h.re,
        h_im: h.im,
        closed_form_status: closed_status,
        paper_method: paper,
        paper_method_status: paper_status,
        model_k_eff_nm_per_rad: model_k,
        model_c_eff_nms_per_rad: model_c,
        model_e_storage_kpa: model_e1 / 1e3,
        model_e_loss_kpa: model_e2 / 1e3,
        housing_temperature_c: mean(rig::O_HOUSING) - ZERO_CELSIUS,
        pcl_temperature_c: mean(rig::O_PCL) - ZERO_CELSIUS,
        pcl_temperature_drift_k: pmax - pmin,
        analytic_h_re: analytic.re,
        analytic_h_im: analytic.im,
        conditioning: Conditioning::of(h, k_star_model, k, args.h_uncertainty),
        conditioning_encoder: Conditioning::of(h, k_star_model, k, encoder_dh),
        e_storage_error: rel(est.e_storage, model_e1),
        e_loss_error: rel(est.e_loss, model_e2),
        paper_e_storage_error: paper.map(|p| rel(p.estimate.e_storage, model_e1)),
        paper_e_loss_error: paper.map(|p| rel(p.estimate.e_loss, model_e2)),
        link_non_sinusoidal: analysis::non_sinusoidal_fraction(t, trace.column(rig::O_LINK_ANGLE), omega, start, len),
        transient_s: analysis::transient_end(
            t,
            trace.column(rig::O_LINK_ANGLE),
            omega,
            start,
            len,
            1e-3 * motor.amplitude,
        ),
        motor_tracking_error_rad: tracking,
        trace,
        window: (start, len),
    }
}

/// Decay normalised to the first temperature's Decay at the same frequency.
fn normalize_decay(conditions: &mut [Condition], reference_c: f64) {
    let refs: Vec<(f64, f64)> =
        conditions.iter().filter(|c| c.temperature_c == reference_c).map(|c| (c.frequency_hz, c.decay_rad)).collect();
    for c in conditions.iter_mut() {
        c.decay_normalized = refs.iter().find(|(f, _)| *f == c.frequency_hz).map(|(_, d)| c.decay_rad / d);
    }
}

/// `thermovia sweep`: simulate, then write the outputs atomically.
pub fn run(args: &SweepArgs, progress: &dyn crate::output::Progress) -> Result<(), SweepError> {
    validate(args).map_err(SweepError::Options)?;
    crate::output::make_parent(&args.out)?;
    let total = args.temperatures.len() * (args.frequencies.len() + 1)
        + usize::from(!args.heating_powers.is_empty())
        + usize::from(args.cycle_power > 0.0);
    progress.start(total as u64);
    let mut done = 0;
    let result = simulate(args, |label| {
        done += 1;
        progress.set_label(label);
        progress.set_position(done);
    });
    progress.finish();
    let result = result?;
    let written = report::write_all(&result, &args.out)?;
    eprintln!(
        "sweep: {} conditions simulated in {:.2} s (+ {:.2} s heating study) through {}; wrote {} files to {}",
        result.conditions.len(),
        result.simulate_seconds,
        result.heating_seconds,
        result.fmu_path.display(),
        written,
        args.out.display()
    );
    Ok(())
}
