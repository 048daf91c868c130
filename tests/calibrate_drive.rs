//! Drive runs end to end (docs/interfaces.md, "Runs from other rigs and drives"): the EMPS
//! benchmark against its published figures, and small synthetic files for each drive mode and the
//! linear axis, written from truth models integrated here (explicit RK4 in this file, not the FMU).

mod common;

use std::path::{Path, PathBuf};

use serde_json::Value;
use thermovia_tools::calibrate::data::parse_run;
use thermovia_tools::calibrate::{calibrate, CalibrateArgs};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");

fn run_calibrate(args: &[&str]) -> Value {
    let fmu = common::fmu_path();
    let mut all: Vec<&str> = args.to_vec();
    let fmu_s = fmu.to_str().unwrap().to_string();
    all.extend_from_slice(&["--fmu", &fmu_s, "--no-plots"]);
    let args = CalibrateArgs::from_cli(&all).unwrap();
    let report = calibrate(&args).unwrap().report;
    // a refit that failed a selection test is never kept (one that passed them all may still lose
    // to a better refit of its round)
    for a in rejected_or_kept(&report) {
        assert!(a["kept"] == false || a["failed"].as_array().unwrap().is_empty(), "{a}");
    }
    report
}

/// Every refit a drive search judged (its rounds' attempts and its combinations; a device's
/// attempts carry no Wald test).
fn rejected_or_kept(j: &Value) -> Vec<&Value> {
    let rounds =
        j["rounds"].as_array().into_iter().flatten().flat_map(|r| r["attempts"].as_array().into_iter().flatten());
    rounds.chain(j["combinations"].as_array().into_iter().flatten()).filter(|a| a.get("wald_chi2").is_some()).collect()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn added(j: &Value) -> Vec<String> {
    j["added_effects"].as_array().unwrap().iter().map(|e| e["effect"].as_str().unwrap().to_string()).collect()
}

fn final_param(j: &Value, name: &str) -> f64 {
    f(&final_row(j, name)["value"])
}

/// The final parameters' row of `name`: value, std_error, unit.
fn final_row<'a>(j: &'a Value, name: &str) -> &'a Value {
    let p = j["parameters"]["final"].as_array().unwrap().iter().find(|p| p["name"] == name);
    p.unwrap_or_else(|| panic!("no {name} in {}", j["parameters"]["final"]))
}

/// The EMPS benchmark, nothing declared beyond the files: the targets of issues 11 and 19.
#[test]
fn emps_estimation_and_validation_beat_the_published_parameters_simulated_the_same_way() {
    let est = format!("{ROOT}/data/emps/emps_estimation.csv");
    let val = format!("{ROOT}/data/emps/emps_validation.csv");
    let published = format!("{ROOT}/data/emps/published.json");
    let j = run_calibrate(&[&est, "--validate", &val, "--published", &published]);
    assert!(
        rejected_or_kept(&j).iter().any(|a| !a["failed"].as_array().unwrap().is_empty()),
        "EMPS's search rejects a refit and names the test it failed: {}",
        j["rounds"]
    );
    let (est_base, est_final) = (f(&j["baseline"]["relerr_percent"]), f(&j["final"]["relerr_percent"]));
    let (val_base, val_final) =
        (f(&j["validation"]["baseline"]["relerr_percent"]), f(&j["validation"]["final"]["relerr_percent"]));
    eprintln!(
        "EMPS: estimation {est_base:.4} → {est_final:.4} %, validation {val_base:.4} → {val_final:.4} %, added {:?}",
        added(&j)
    );
    assert_eq!(j["units"]["position"], "m");
    assert_eq!(added(&j)[0], "coulomb_friction", "{}", j["diagnosis"]);
    // the published IDIM-LS parameters simulated by this loop on the same runs (issue 19): an
    // independent re-simulation on the log's 1 ms grid without delay gives 0.00109 % and 0.00137 %
    // (pulses at their logged 35.64 N per unit), 0.00159 % at the declared gain. Both with the
    // published law's hard friction sign: then they agree to rounding (the figures have three
    // digits: ±0.5 %); with the FMU's default smoothing (1e-3 m/s) ours were 7, 4 and 2.5 % lower
    let same = &j["published_same_simulation"]["relerr_percent"];
    let (same_est, same_val) = (f(&same["estimation"]), f(&same["validation"]));
    eprintln!("published parameters, same simulation: {same_est:.5} %, {same_val:.5} % ({same})");
    for (ours, independent) in [(same_est, 0.00109), (same_val, 0.00137)] {
        assert!((ours / independent - 1.0).abs() < 0.01, "same simulation {ours} % vs independent {independent} %");
    }
    let at_declared = f(&same["validation_at_declared_drive_gain"]);
    assert!((at_declared / 0.00159 - 1.0).abs() < 0.01, "at the declared gain {at_declared} %");
    // the final model beats them on both sets; the printed 0.0138 % / 0.0080 % are no target
    assert!(est_final < same_est, "estimation {est_final} % vs {same_est} %");
    assert!(val_final < same_val, "validation {val_final} % vs {same_val} %");
    // the baseline without friction is clearly worse on the held-out set
    assert!(val_base >= 2.0 * val_final, "baseline {val_base} % vs final {val_final} %");
    // the model of the published structure lands on the published parameters
    let rows = j["comparison"]["parameters"].as_array().unwrap();
    let ours = |name: &str| {
        let r = rows.iter().find(|r| r["parameter"] == name).unwrap();
        (f(&r["ours_same_structure"]), f(&r["published"]))
    };
    for (name, tol) in [("inertia", 0.01), ("viscous_friction", 0.05), ("coulomb_friction", 0.05)] {
        let (o, p) = ours(name);
        assert!((o - p).abs() <= tol * p.abs(), "{name}: ours {o}, published {p}");
    }
    let (o, p) = ours("offset");
    assert!((o - p).abs() <= 0.5, "offset: ours {o}, published {p}");
    // the held-out load column is applied at the gain the force log shows (35.64 N per unit, not
    // the declared 35.15), never at the one fitted to the held-out positions (reported only)
    let lc = &j["validation"]["load_column"];
    assert_eq!(lc["source"], "force_log", "{lc}");
    assert_eq!(f(&lc["applied_gain"]), f(&lc["force_log_gain"]), "{lc}");
    assert!((f(&lc["applied_gain"]) - 35.64).abs() < 0.01, "{lc}");
    assert_ne!(f(&lc["applied_gain"]), f(&lc["fitted_gain"]), "{lc}");
    assert!(f(&lc["as_recorded"]["final"]["relerr_percent"]) > val_final);
}

// ---- synthetic truths (explicit integration, apart from the FMU) ----

/// A rigid body m x'' = u + load − b x' − F_c tanh(x'/v_s) (+ asymmetric terms), RK4 with 20
/// sub-steps per sample, the input held over each sample. v_s = 1e-3 is the FMU's documented
/// friction smoothing, so the truth and the model share the friction law.
#[derive(Clone, Copy)]
struct Body {
    m: f64,
    b: f64,
    fc: f64,
    load: f64,
}

impl Body {
    fn accel(&self, v: f64, u: f64, load: f64) -> f64 {
        (u + load + self.load - self.b * v - self.fc * (v / 1e-3).tanh()) / self.m
    }
    fn step(&self, x: &mut f64, v: &mut f64, u: f64, load: f64, h: f64) {
        let n = 20;
        let dt = h / n as f64;
        for _ in 0..n {
            let (x0, v0) = (*x, *v);
            let k1 = (v0, self.accel(v0, u, load));
            let k2 = (v0 + 0.5 * dt * k1.1, self.accel(v0 + 0.5 * dt * k1.1, u, load));
            let k3 = (v0 + 0.5 * dt * k2.1, self.accel(v0 + 0.5 * dt * k2.1, u, load));
            let k4 = (v0 + dt * k3.1, self.accel(v0 + dt * k3.1, u, load));
            *x = x0 + dt / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
            *v = v0 + dt / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
        }
    }
}

fn quantise(x: f64, q: f64) -> f64 {
    (x / q).round() * q
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    std::fs::create_dir_all(dir).unwrap();
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.to_str().unwrap().to_string()
}

/// A linear axis under a position controller with the EMPS velocity estimate, reference replayed.
fn closed_loop_file(body: Body, seconds: f64, pulses: bool, start_step: f64) -> String {
    let (kp, kd, sat, t) = (2.0e5, 2.0e3, 40.0, 1e-3);
    let n = (seconds / t).round() as usize + 1;
    let reference =
        |tt: f64| start_step + 0.1 * (1.0 - (std::f64::consts::PI * tt).cos()) + 0.02 * (2.3 * tt).sin() * tt.min(1.0);
    let mut text = String::from(
        "# source=synthetic closed loop (tests/calibrate_drive.rs)\n# axis=linear\n# transmission=rigid\n# drive=reference\n\
         # controller_kp=200000\n# controller_kd=2000\n# controller_saturation=40\n# controller_period_s=0.001\n",
    );
    text += if pulses {
        "time_s,reference_position_m,motor_position_m,motor_force_n,load_force_n\n"
    } else {
        "time_s,reference_position_m,motor_position_m,motor_force_n\n"
    };
    let (mut x, mut v) = (0.0, 0.0);
    let (mut q_prev, mut qf_prev) = (0.0, 0.0);
    for k in 0..n {
        let tt = k as f64 * t;
        let q = quantise(x, 1e-7);
        let qf = 0.5 * (q + q_prev);
        let speed = (qf - qf_prev) / t;
        (q_prev, qf_prev) = (q, qf);
        let r = reference(tt);
        let u = (kp * (r - q) - kd * speed).clamp(-sat, sat);
        let load = if pulses && (tt % 1.0) >= 0.5 { 25.0 } else { 0.0 };
        text += &format!("{tt},{r},{q},{u}");
        if pulses {
            text += &format!(",{load}");
        }
        text += "\n";
        body.step(&mut x, &mut v, u, load, t);
    }
    text
}

/// Reference drive, linear axis, rigid transmission: the baseline, then Coulomb friction found,
/// with every parameter back in the file's units and the held-out pulses used as a load.
#[test]
fn reference_drive_on_a_linear_axis_finds_coulomb_friction_and_its_parameters() {
    let truth = Body { m: 20.0, b: 50.0, fc: 8.0, load: -2.0 };
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("drive-reference");
    let est = write(&dir, "est.csv", &closed_loop_file(truth, 4.0, false, 0.0));
    let val = write(&dir, "val.csv", &closed_loop_file(truth, 4.0, true, 0.0));
    // the controller saturates in the moves (40 N), so the master must reproduce the saturation
    let saturated = std::fs::read_to_string(&est)
        .unwrap()
        .lines()
        .filter(|l| l.split(',').nth(3).and_then(|u| u.parse::<f64>().ok()).is_some_and(|u| u.abs() == 40.0))
        .count();
    assert!(saturated > 20, "{saturated} saturated samples");
    let j = run_calibrate(&[&est, "--validate", &val]);
    eprintln!("reference: added {:?}, parameters {}", added(&j), j["parameters"]["final"]);
    assert_eq!(j["units"], serde_json::json!({"position": "m", "torque": "N", "inertia": "kg"}));
    // symmetric Coulomb friction only: neither asymmetric nor Stribeck friction
    assert_eq!(added(&j), vec!["coulomb_friction"], "{}", j["rounds"]);
    let close = |name: &str, truth: f64, rel: f64| {
        let got = final_param(&j, name);
        assert!((got - truth).abs() <= rel * truth.abs(), "{name}: {got}, truth {truth}");
    };
    close("inertia", 20.0, 0.02);
    close("viscous_friction", 50.0, 0.05);
    close("coulomb_friction", 8.0, 0.05);
    close("constant_load", -2.0, 0.15);
    // a closed loop reports its force parameters from the logged force and whether it took them
    let levels = &j["inverse_model"]["force_levels"];
    let (wald, limit, ratio) = (f(&levels["wald_chi2"]), f(&levels["limit"]), f(&levels["position_rms_ratio"]));
    assert!(wald.is_finite() && wald >= 0.0 && limit > 10.0 && ratio > 0.0, "{levels}");
    assert_eq!(levels["taken"].as_bool(), Some(wald <= limit || ratio <= 1.0), "{levels}");
    assert!(f(&j["validation"]["final"]["relerr_percent"]) < 0.5 * f(&j["validation"]["baseline"]["relerr_percent"]));
    // no drive gain declared: the pulses are taken as recorded, in newtons
    assert_eq!(f(&j["validation"]["load_column"]["applied_gain"]), 1.0);
}

/// A run logged from a reference step: the controller saturates, then leaves saturation within
/// the first samples, so a quadratic over them misreads the speed the body starts with (campaign
/// drive rig 149: 2.9e-4 m/s for a start at rest), and a simulation started there carries the
/// error until the controller has taken it out. The fit estimates each run's initial speed with
/// the model instead.
#[test]
fn a_reference_drive_fits_the_speed_each_run_starts_with() {
    let truth = Body { m: 20.0, b: 50.0, fc: 8.0, load: -2.0 };
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("drive-start");
    let text = closed_loop_file(truth, 4.0, false, 0.002);
    let est = write(&dir, "est.csv", &text);
    let run = parse_run(Path::new(&est), &text).unwrap();
    let read = thermovia_tools::calibrate::drive::initial_speed(&run.time, &run.motor);
    let j = run_calibrate(&[&est]);
    let row = final_row(&j, "initial_speed[est.csv]");
    let (fitted, se) = (f(&row["value"]), f(&row["std_error"]));
    // the body starts at rest: the fit's estimate holds 0 within its standard error, the start's
    // quadratic does not
    assert!(fitted.abs() < 3.0 * se, "fitted {fitted} ± {se} m/s");
    assert!(read.abs() > 3.0 * se, "the start's quadratic reads {read} m/s, ± {se}: no misread start to test");
    assert!((final_param(&j, "coulomb_friction") - 8.0).abs() < 0.05 * 8.0, "{}", j["parameters"]["final"]);
}

/// Issue 19: without a force log, the held-out load column is applied × the declared drive gain
/// on the file's word, never × the gain that best fits the held-out positions. The truth's pulses
/// are 25 N; the file logs them as 10 "volts" with `drive_gain_n_per_v=2.5` and no force column.
#[test]
fn without_a_force_log_the_load_column_takes_the_declared_gain() {
    let truth = Body { m: 20.0, b: 50.0, fc: 8.0, load: -2.0 };
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("drive-declared-gain");
    let est = write(&dir, "est.csv", &closed_loop_file(truth, 4.0, false, 0.0));
    let mut volts = String::new();
    for line in closed_loop_file(truth, 4.0, true, 0.0).lines() {
        let line = match line.split(',').collect::<Vec<_>>().as_slice() {
            _ if line.starts_with('#') => line.to_string(),
            [t, r, q, _force, _load] if line.starts_with("time_s") => format!("{t},{r},{q},load_force_n"),
            [t, r, q, _force, load] => format!("{t},{r},{q},{}", load.parse::<f64>().unwrap() / 2.5),
            other => panic!("{other:?}"),
        };
        volts += &line;
        volts += "\n";
        if line.starts_with("# drive=") {
            volts += "# drive_gain_n_per_v=2.5\n";
        }
    }
    let val = write(&dir, "val.csv", &volts);
    let j = run_calibrate(&[&est, "--validate", &val]);
    let lc = &j["validation"]["load_column"];
    assert_eq!(lc["source"], "declared", "{lc}");
    assert_eq!(f(&lc["applied_gain"]), 2.5, "{lc}");
    assert!(lc["note"].as_str().unwrap().contains("on the file's word"), "{lc}");
    // applied at the declared gain the held-out set is predicted as well as the fitting set
    let (val_final, as_recorded) =
        (f(&j["validation"]["final"]["relerr_percent"]), f(&lc["as_recorded"]["final"]["relerr_percent"]));
    assert!(val_final < 0.5 * as_recorded, "declared gain {val_final} %, as recorded {as_recorded} %");
}

/// Torque drive on a rotary rigid axis: the measured torque drives the FMU (motor_drive 0) and the
/// motor angle is predicted.
#[test]
fn torque_drive_on_a_rotary_axis_recovers_inertia_viscous_and_coulomb() {
    let truth = Body { m: 0.02, b: 0.05, fc: 0.04, load: 0.0 };
    let t = 1e-3;
    let mut text = String::from("# axis=rotary\n# transmission=rigid\n# drive=motor_torque\n# temperature_c=22\n");
    text += "time_s,motor_angle_rad,motor_torque_nm\n";
    let (mut x, mut v) = (0.0, 0.0);
    for k in 0..=3000 {
        let tt = k as f64 * t;
        let u =
            0.3 * (2.0 * std::f64::consts::PI * 1.0 * tt).sin() + 0.15 * (2.0 * std::f64::consts::PI * 2.7 * tt).sin();
        text += &format!("{tt},{},{u}\n", quantise(x, 2.0 * std::f64::consts::PI / 1e5));
        truth.step(&mut x, &mut v, u, 0.0, t);
    }
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("drive-torque");
    let file = write(&dir, "torque.csv", &text);
    let j = run_calibrate(&[&file]);
    eprintln!("torque: added {:?}, parameters {}", added(&j), j["parameters"]["final"]);
    assert_eq!(j["units"]["position"], "rad");
    assert_eq!(added(&j), vec!["coulomb_friction"], "{}", j["rounds"]);
    for (name, truth, rel) in
        [("inertia", 0.02, 0.02), ("viscous_friction", 0.05, 0.05), ("coulomb_friction", 0.04, 0.05)]
    {
        let got = final_param(&j, name);
        assert!((got - truth).abs() <= rel * truth, "{name}: {got}, truth {truth}");
    }
    assert!(j["held_out"].as_str().unwrap().contains("no held-out set"));
    assert!(j["search_budget"].is_null(), "{}", j["search_budget"]);
    // the drive goes through the same search as the device: out of budget, it keeps the baseline
    // and says what it skipped
    let j = run_calibrate(&[&file, "--search-budget", "0"]);
    assert_eq!(j["search_budget"]["exhausted"], true, "{}", j["search_budget"]);
    assert!(added(&j).is_empty(), "{:?}", added(&j));
    assert_eq!(j["final"]["relerr_percent"], j["baseline"]["relerr_percent"]);
}

/// Torque steps on a small rotary servo whose torque log carries 1 % noise (campaign drive rig 55's
/// shape: the open-loop simulation drifts by that noise integrated twice). The friction is the
/// library's Coulomb friction: once it is in, nothing is left that the library lacks, so the run
/// is not `unexplained`. Read in the simulated position, the sign-of-speed pattern of that drift
/// was 0.33 on rig 55 and flagged it; read in the equation error, which chose the parameters, it
/// is gone.
#[test]
fn torque_steps_with_a_noisy_torque_log_are_explained_once_coulomb_friction_is_in() {
    let truth = Body { m: 6e-5, b: 4e-5, fc: 8.5e-4, load: 0.0 };
    let (t, q) = (2e-3, 2.0 * std::f64::consts::PI / 10_000.0);
    let mut state = 55u64;
    let mut uniform = || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut text = String::from("# axis=rotary\n# transmission=rigid\n# drive=motor_torque\n# temperature_c=22\n");
    text += "time_s,motor_angle_rad,motor_torque_nm\n";
    let (mut x, mut v) = (0.0, 0.0);
    let (mut level, mut next_step, mut sign) = (0.0, 0.0, 1.0);
    for k in 0..=10_000 {
        let tt = k as f64 * t;
        if tt >= next_step {
            // steps above the break-away, alternating sign mostly, dwelling 0.3-1.5 s
            level = sign * (1.2 * truth.fc + 2.0 * truth.fc * uniform());
            sign = if uniform() < 0.8 { -sign } else { sign };
            next_step = tt + 0.3 + 1.2 * uniform();
        }
        // the log's noise: 1 % of the level, a sum of uniforms for a near-Gaussian draw
        let logged = level * (1.0 + 0.01 * ((0..12).map(|_| uniform()).sum::<f64>() - 6.0));
        text += &format!("{tt},{},{logged}\n", quantise(x, q));
        truth.step(&mut x, &mut v, level, 0.0, t);
    }
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("drive-torque-steps");
    let file = write(&dir, "steps.csv", &text);
    let j = run_calibrate(&[&file]);
    eprintln!("torque steps: added {:?}, residual {}", added(&j), j["residual"]);
    assert_eq!(added(&j), vec!["coulomb_friction"], "{}", j["rounds"]);
    assert_eq!(j["inverse_model"]["method"], "equation error");
    assert!(j["residual"]["of"].as_str().unwrap().contains("equation error"), "{}", j["residual"]);
    // the baseline's residual carries the friction's sign; the final one, whose least squares holds
    // the sign's column, none in its own weights
    assert!(f(&j["residual"]["baseline_corr_sign_speed"]) > 0.3, "{}", j["residual"]);
    assert!(f(&j["residual"]["final_corr_sign_speed"]).abs() < 1e-3, "{}", j["residual"]);
    assert_eq!(j["unexplained"], false, "{}", j["residual"]);
}

/// Torque drive on the compliant device: motor and link angles are both predicted (the residual
/// stacks two outputs). Truth: the two-mass model integrated here, J_m θm'' = τ − B_m θm' − τ_t,
/// J_l θl'' = τ_t, τ_t = K Δ + C Δ', with K = K_s r_s² + 0.8 E'(22 °C) κ r_p² and
/// C = 1.25 E''(22 °C) κ r_p² / ω at the declared 0.5 Hz (E' = 985.34 kPa, E'' = 834.45 kPa, Table 2;
/// J_m = 0.005, B_m = 0.01, the FMU's defaults; J_l = 0.018 declared).
#[test]
fn torque_drive_on_the_compliant_device_recovers_the_moduli_from_motor_and_link() {
    let kappa = 0.064 * 0.02075 * 0.02075;
    let k = 1160.0 * 12.0 * 0.0222 * 0.0222 + 0.8 * 985.34e3 * kappa;
    let c = 1.25 * 834.45e3 * kappa / (2.0 * std::f64::consts::PI * 0.5);
    let (jm, bm, jl) = (0.005, 0.01, 0.018);
    let deriv = |x: [f64; 4], u: f64| {
        let tt = k * (x[0] - x[2]) + c * (x[1] - x[3]);
        [x[1], (u - bm * x[1] - tt) / jm, x[3], tt / jl]
    };
    let mut text =
        String::from("# drive=motor_torque\n# temperature_c=22\n# frequency_hz=0.5\n# link_inertia_kgm2=0.018\n");
    text += "time_s,motor_angle_rad,link_angle_rad,motor_torque_nm\n";
    let mut x = [0.0; 4];
    let q = 2.0 * std::f64::consts::PI / 1e5;
    let n = 3000;
    for step in 0..=n {
        let tt = step as f64 * 1e-3;
        let u = 0.2 * (std::f64::consts::PI * tt).sin() + 0.1 * (2.0 * std::f64::consts::PI * 3.1 * tt).sin();
        text += &format!("{tt},{},{},{u}\n", quantise(x[0], q), quantise(x[2], q));
        let h = 1e-3 / 20.0;
        for _ in 0..20 {
            let add =
                |a: [f64; 4], b: [f64; 4], s: f64| [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2], a[3] + s * b[3]];
            let k1 = deriv(x, u);
            let k2 = deriv(add(x, k1, 0.5 * h), u);
            let k3 = deriv(add(x, k2, 0.5 * h), u);
            let k4 = deriv(add(x, k3, h), u);
            for i in 0..4 {
                x[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
    }
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("drive-compliant");
    let file = write(&dir, "compliant.csv", &text);
    let j = run_calibrate(&[&file]);
    eprintln!("compliant: added {:?}, parameters {}, final {}", added(&j), j["parameters"]["final"], j["final"]);
    // two outputs per sample
    assert_eq!(f(&j["final"]["samples"]), 2.0 * (n + 1) as f64);
    let s1 = final_param(&j, "storage_modulus_scale[0]");
    let s2 = final_param(&j, "loss_modulus_scale[0]");
    assert!((s1 - 0.8).abs() < 0.02 * 0.8, "storage scale {s1}");
    assert!((s2 - 1.25).abs() < 0.05 * 1.25, "loss scale {s2}");
    assert!(added(&j).is_empty(), "no friction in the truth: {:?}", added(&j));
    // the transmission as the paper's quantities, through the FMU's own outputs
    let id = &j["identified"][0];
    assert!((f(&id["stiffness"]) - k).abs() < 0.01 * k, "K {} vs {k}", id["stiffness"]);
    assert!((f(&id["damping"]) - c).abs() < 0.02 * c, "C {} vs {c}", id["damping"]);
    assert!(f(&id["stiffness_std"]) > 0.0 && f(&id["natural_frequency_hz"]) > 0.0);
}

// ---- metadata errors: file, line, what was wrong ----

fn parse_err(text: &str) -> String {
    parse_run(Path::new("run.csv"), text).unwrap_err().to_string()
}

#[test]
fn bad_drive_metadata_names_file_line_and_what_was_wrong() {
    let e =
        parse_err("# temperature_c=22\n# drive=velocity\ntime_s,motor_angle_rad,link_angle_rad\n0,0,0\n1,1,1\n2,2,2\n");
    assert!(
        e.starts_with("run.csv:2: metadata drive=\"velocity\" is not one of motor_angle, motor_torque, reference"),
        "{e}"
    );

    let e = parse_err("# axis=angular\ntime_s,motor_angle_rad,link_angle_rad\n0,0,0\n1,1,1\n2,2,2\n");
    assert!(e.starts_with("run.csv:1: metadata axis=\"angular\""), "{e}");

    let head = "# axis=linear\n# transmission=rigid\n# drive=reference\n# controller_kd=10\n# controller_saturation=5\n# controller_period_s=0.001\n";
    let rows = "time_s,reference_position_m,motor_position_m\n0,0,0\n0.001,0,0\n0.002,0,0\n";
    let e = parse_err(&format!("{head}{rows}"));
    assert!(e.starts_with("run.csv: drive=reference needs the controller: missing `# controller_kp=`"), "{e}");

    let e = parse_err(&format!("# controller_kp=fast\n{head}{rows}"));
    assert!(e.starts_with("run.csv:1: metadata controller_kp=\"fast\" is not a positive number"), "{e}");

    let e = parse_err(&format!("# controller_kp=1e5\n{}{rows}", head.replace("0.001", "0.01")));
    assert!(e.starts_with("run.csv:7: controller_period_s=0.01 but the samples are 0.001000 s apart"), "{e}");

    // a rotary column in a linear file
    let e = parse_err(&format!("# controller_kp=1e5\n{head}time_s,reference_position_m,motor_angle_rad\n0,0,0\n"));
    assert!(
        e.contains("run.csv:8")
            && e.contains("missing required column \"motor_position_m\"")
            && e.contains("axis=linear"),
        "{e}"
    );

    let e = parse_err("# transmission=rigid\n# temperature_c=22\ntime_s,motor_angle_rad\n0,0\n1,1\n2,2\n");
    assert!(e.starts_with("run.csv:1: transmission=rigid with drive=motor_angle leaves nothing to predict"), "{e}");

    let e = parse_err("# axis=linear\n# drive=motor_torque\n# transmission=rigid\n# link_inertia_kgm2=2\ntime_s,motor_position_m,motor_force_n\n0,0,0\n1,1,1\n2,2,2\n");
    assert!(e.starts_with("run.csv:4: link_inertia_kgm2 on a linear axis"), "{e}");

    let e = parse_err(
        "# drive=motor_torque\n# temperature_c=22\ntime_s,motor_angle_rad,link_angle_rad\n0,0,0\n1,1,1\n2,2,2\n",
    );
    assert!(e.contains("missing required column \"motor_torque_nm\""), "{e}");
}

#[test]
fn a_bad_file_stops_the_command_with_file_line_and_reason() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("drive-bad");
    let file = write(&dir, "bad.csv", "# axis=linear\n# drive=reference\n# transmission=rigid\n# controller_kp=-3\ntime_s,reference_position_m,motor_position_m\n0,0,0\n0.001,0,0\n0.002,0,0\n");
    let out_dir = dir.join("out");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_thermovia"))
        .args(["calibrate", &file, "--out", out_dir.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(!out.status.success());
    assert!(err.contains("bad.csv:4: metadata controller_kp=\"-3\" is not a positive number"), "{err}");
    assert!(!out_dir.exists());
}

#[test]
fn calibrate_help_teaches_the_drive_modes_with_examples() {
    let out =
        std::process::Command::new(env!("CARGO_BIN_EXE_thermovia")).args(["calibrate", "--help"]).output().unwrap();
    let help = String::from_utf8(out.stdout).unwrap();
    for needle in [
        "Examples:",
        "--validate",
        "--published",
        "drive=reference",
        "drive=motor_torque",
        "data/emps/emps_estimation.csv",
    ] {
        assert!(help.contains(needle), "{needle} missing from:\n{help}");
    }
}

/// Runs driven by the measured motor angle (the device loop) take a held-out set too: simulated
/// with the fitted moduli of the nearest temperature, reported under "validation". Held-out runs
/// judge the model and never choose it: at another frequency they favour the truth's hysteretic
/// damping, which one frequency in the fitting set cannot identify, and the law stays viscous.
#[test]
fn device_runs_report_their_held_out_error() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("device-validate");
    let fmu = common::fmu_path();
    for (name, freq, seed) in [("est", "0.5", "1"), ("val", "0.5", "2"), ("val1hz", "1", "3")] {
        let out = dir.join(name);
        let status = std::process::Command::new(env!("CARGO_BIN_EXE_thermovia"))
            .args(["synth", "--out", out.to_str().unwrap(), "--temperatures", "40", "--frequencies", freq])
            .args(["--duration", "4", "--seed", seed, "--fmu", fmu.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(status.status.success(), "{}", String::from_utf8_lossy(&status.stderr));
    }
    let est = dir.join("est");
    let j = run_calibrate(&[est.to_str().unwrap(), "--validate", dir.join("val").to_str().unwrap()]);
    let v = &j["validation"];
    assert_eq!(v["runs"].as_array().unwrap().len(), 1);
    // clean truth (0.8 E', 1.25 E'', noise 1e-4 rad + quantisation): the held-out error is near the noise
    let rmse = f(&v["final"]["rmse_rad"]);
    assert!(rmse < 1e-3, "held-out RMSE {rmse}");
    assert!(f(&v["final"]["relerr_percent"]) > 0.0 && f(&j["final"]["relerr_percent"]) > 0.0);

    let j = run_calibrate(&[est.to_str().unwrap(), "--validate", dir.join("val1hz").to_str().unwrap()]);
    assert_eq!(j["damping_law"]["chosen"], "viscous", "{}", j["damping_law"]);
    let notes = j["held_out"]["notes"].to_string();
    assert!(notes.contains("they favour hysteretic"), "{notes}");
    assert!(j["held_out"]["method"].as_str().unwrap().starts_with("a blocked fold"), "{}", j["held_out"]);
}
