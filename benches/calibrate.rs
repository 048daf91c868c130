//! `cargo bench --bench calibrate`: the issues' benchmark (10 and 12). 8 runs (22/40/50/60 °C ×
//! 0.5/1 Hz) of 20 s at 1 kHz from a truth model with two nonlinear effects (Coulomb friction
//! 0.05 N·m and gravity m·g·d = 1.249 N·m, the paper's 0.91 kg at 0.14 m) and non-default moduli;
//! the whole loop (baseline fits under each damping law, diagnosis, effect search, refits, the
//! black-box reference, the blocked held-out fold, report without plots) is timed. Prints each
//! repetition and the median.
//!
//! Then issue 28's small rigid servo: 8 torque-driven runs of 20 s at 1 kHz (20 000 samples each)
//! from a rotor of 1e-4 kg·m² with viscous and Coulomb friction under torque steps up to 200 rad/s,
//! written by a truth in this file (RK4, not the FMU); target ≤ 60 s. Then a real closed-loop log,
//! the EMPS drive (reference-driven), as the README's EMPS command runs it.

use thermovia_importer::Fmu;
use thermovia_tools::calibrate::synthetic::{generate, write_atomically, SynthArgs};
use thermovia_tools::calibrate::{calibrate, CalibrateArgs, Calibration};

fn main() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target").join("bench-calibrate");
    let data = dir.join("data");
    let data_s = data.to_str().unwrap().to_string();
    let synth =
        SynthArgs::from_cli(&["--coulomb-friction", "0.05", "--gravity-mgl", "1.249", "--out", &data_s]).unwrap();
    let files = generate(
        &synth,
        Fmu::open(thermovia_tools::default_fmu_path()).expect("build the FMU first: cargo run --release -p fmu-build"),
    )
    .unwrap();
    write_atomically(&data, &files.into_iter().map(|(n, t)| (n, t.into_bytes())).collect::<Vec<_>>()).unwrap();
    let reps: usize = std::env::var("CALIBRATE_BENCH_REPS").ok().and_then(|v| v.parse().ok()).unwrap_or(3);
    let report = dir.join("report");
    let median = timed(reps, &[&data_s, "--out", report.to_str().unwrap(), "--no-plots"], |rep, s, c| {
        let o = c.outcome.as_ref().unwrap();
        let added: Vec<_> = o.final_fit.spec.effects.iter().map(|e| e.name()).collect();
        format!(
            "rep {rep}: {s:.2} s, {} samples, baseline RMSE {:.3e}, final {:.3e}, added {added:?}",
            o.baseline.n,
            o.baseline.rmse(),
            o.final_fit.rmse()
        )
    });
    println!("calibrate 8 runs x 20 s at 1 kHz with effect search: median {median:.2} s over {reps} (target ≤ 5 s)");
    rigid_servo(&dir.join("servo"), reps);
    closed_loop_emps(&dir.join("emps"), reps);
}

/// The servo's truth: J q'' = u − B q' − Fc sign(q'), RK4 at 0.1 ms (the sign smoothed over 1e-2 rad/s,
/// so the integrator does not chatter at rest).
const SERVO: (f64, f64, f64) = (1e-4, 2.5e-4, 5e-3);

fn servo_run(seed: u64) -> String {
    let (j, b, fc) = SERVO;
    let mut rng = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    let mut uniform = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        (rng >> 11) as f64 / (1u64 << 53) as f64
    };
    // torque steps: a level in ±0.05 N·m (up to 200 rad/s at steady state) held 0.5–2 s
    let (mut level, mut until, mut t) = (0.0, 0.0, 0.0);
    let (mut q, mut v) = (0.0f64, 0.0f64);
    let quantum = std::f64::consts::TAU / 4096.0;
    let mut text = String::from(
        "# temperature_c=22\n# drive=motor_torque\n# transmission=rigid\n# source=benches/calibrate.rs\n\
         time_s,motor_angle_rad,motor_torque_nm\n",
    );
    let acc = |u: f64, v: f64| (u - b * v - fc * (v / 1e-2).tanh()) / j;
    for k in 0..20_000 {
        if t >= until {
            level = 0.05 * (2.0 * uniform() - 1.0);
            until = t + 0.5 + 1.5 * uniform();
        }
        let u_logged = level + 1e-4 * (2.0 * uniform() - 1.0);
        text += &format!("{:.4},{:.6},{u_logged:.6}\n", k as f64 * 1e-3, (q / quantum).round() * quantum);
        for _ in 0..10 {
            let h = 1e-4;
            let (k1q, k1v) = (v, acc(level, v));
            let (k2q, k2v) = (v + 0.5 * h * k1v, acc(level, v + 0.5 * h * k1v));
            let (k3q, k3v) = (v + 0.5 * h * k2v, acc(level, v + 0.5 * h * k2v));
            let (k4q, k4v) = (v + h * k3v, acc(level, v + h * k3v));
            q += h / 6.0 * (k1q + 2.0 * k2q + 2.0 * k3q + k4q);
            v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
        }
        t += 1e-3;
    }
    text
}

fn rigid_servo(dir: &std::path::Path, reps: usize) {
    let data = dir.join("data");
    let runs: Vec<(String, Vec<u8>)> =
        (0..8).map(|r| (format!("servo_{r}.csv"), servo_run(r + 1).into_bytes())).collect();
    write_atomically(&data, &runs).unwrap();
    let out = dir.join("report");
    let median = timed(reps, &[data.to_str().unwrap(), "--out", out.to_str().unwrap(), "--no-plots"], |rep, s, c| {
        format!(
            "servo rep {rep}: {s:.2} s, {} (truth: inertia {:.1e}, viscous {:.1e}, Coulomb {:.1e})",
            final_parameters(c),
            SERVO.0,
            SERVO.1,
            SERVO.2
        )
    });
    println!("calibrate a rigid servo, 8 torque-driven runs x 20 000 samples: median {median:.2} s over {reps} (target ≤ 60 s)");
}

/// A real closed-loop log: the EMPS drive's estimation run (reference-driven), its validation run
/// scored and its published parameters simulated, as the README's EMPS command runs them.
fn closed_loop_emps(dir: &std::path::Path, reps: usize) {
    let emps = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data").join("emps");
    let file = |name: &str| emps.join(name).to_str().unwrap().to_string();
    let (est, val, published) = (file("emps_estimation.csv"), file("emps_validation.csv"), file("published.json"));
    let out = dir.join("report");
    let args = [&est, "--validate", &val, "--published", &published, "--out", out.to_str().unwrap(), "--no-plots"];
    let median = timed(reps, &args, |rep, s, c| format!("EMPS rep {rep}: {s:.2} s, {}", final_parameters(c)));
    println!(
        "calibrate the EMPS closed-loop drive (estimation, validation, published): median {median:.2} s over {reps}"
    );
}

/// Times `reps` calibrations with `args`, printing `line(rep, seconds, calibration)` for each; the
/// median in seconds.
fn timed(reps: usize, args: &[&str], line: impl Fn(usize, f64, &Calibration) -> String) -> f64 {
    let mut times = Vec::new();
    for rep in 0..reps {
        let args = CalibrateArgs::from_cli(args).unwrap();
        let t = std::time::Instant::now();
        let c = calibrate(&args).unwrap();
        let s = t.elapsed().as_secs_f64();
        println!("{}", line(rep, s, &c));
        times.push(s);
    }
    times.sort_by(|a, b| a.partial_cmp(b).unwrap());
    times[reps / 2]
}

/// A drive report's final parameters, "name value" each.
fn final_parameters(c: &Calibration) -> String {
    let found: Vec<String> = c.report["parameters"]["final"]
        .as_array()
        .into_iter()
        .flatten()
        .map(|p| format!("{} {:.4e}", p["name"].as_str().unwrap_or("?"), p["value"].as_f64().unwrap_or(f64::NAN)))
        .collect();
    found.join(", ")
}
