//! fmi2DoStep through the packaged FMU's C API, 1 ms communication step, as an importer drives it:
//! set motor_torque, doStep, get link_angle; in every regime of issue 12 (cold, heating, cooling,
//! fmpy's time grid, gravity, friction, backlash, all of them while heating), beside a bare 6×6
//! matrix–vector step timed in the same run. Median ns per step over repeated runs, and the ratio
//! to the mat-vec. Then, if the project's venv exists, the cold loop driven by fmpy
//! (tests/python/bench_fmpy_dostep.py) for the ratio.
//!
//!   cargo bench --bench dostep
//!
//! Environment (for callgrind or a quick look): DOSTEP_STEPS (steps per run, default 200 000),
//! DOSTEP_RUNS (runs per regime, default 3), DOSTEP_REGIME (only regimes whose label contains it;
//! `budget`: only the work budget's worst cases, one step each),
//! DOSTEP_NO_FMPY (skip fmpy), DOSTEP_FMU (another .fmu than target/fmu/ThermoVIA.fmu: an earlier
//! commit's build, for a before/after measured in one session).

use std::hint::black_box;
use std::process::Command;
use std::time::Instant;

use thermovia_importer::Fmu;

const STEP: f64 = 1e-3;

struct Regime {
    label: &'static str,
    /// PCL, housing and ambient start here, °C.
    start_c: f64,
    ambient_c: f64,
    heater_w: f64,
    /// h passed as t(k+1) − t(k) with t(k) = k·1 ms (fmpy's time grid) instead of exactly 1 ms.
    time_grid: bool,
    /// Each h drawn within ±this share of 1 ms (a logger's jittered timestamps, as `calibrate`
    /// replays them): a step length met once.
    jitter: f64,
    params: &'static [(&'static str, f64)],
}

const GRAVITY: (&str, f64) = ("gravity_link_mass", 0.91);
const FRICTION: (&str, f64) = ("coulomb_friction", 0.05);
/// A link that sticks and slips (the motor's 2 N·m against 1.7 N·m of friction on a light link):
/// near rest the friction's slope goes into the exponential steps' linear part.
const HEAVY_FRICTION: (&str, f64) = ("coulomb_friction", 1.7);
const LIGHT_LINK: (&str, f64) = ("link_inertia", 0.023);
/// A Stribeck excess as the campaign's rigs draw it (fresh rig 508: 0.033 N·m at 0.16 rad/s).
const STRIBECK: (&str, f64) = ("stribeck_friction", 0.05);
const STRIBECK_SPEED: (&str, f64) = ("stribeck_velocity", 0.16);
const BACKLASH: (&str, f64) = ("backlash_width", 0.01);
/// The crystallinity on the melting curve both ways (the model before issue 20), for the cost of
/// the kinetics in the same run.
const EQUILIBRIUM: (&str, f64) = ("crystallisation", 0.0);
/// The causal viscoelastic law (docs/physics.md §5c): its branch rides in the same exact step.
const PRONY: (&str, f64) = ("viscoelastic_law", 1.0);
/// Modelica's ElastoBacklash (docs/physics.md §10): its capped spells go to Dormand–Prince.
const ELASTO_BACKLASH: (&str, f64) = ("backlash_law", 1.0);

const REGIMES: &[Regime] = &[
    Regime {
        label: "cold, linear, exact h",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[],
    },
    Regime {
        label: "hot (60 °C), linear",
        start_c: 60.0,
        ambient_c: 60.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[],
    },
    Regime {
        label: "heating at 8 W",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 8.0,
        time_grid: false,
        jitter: 0.0,
        params: &[],
    },
    Regime {
        label: "cooling from 60 °C",
        start_c: 60.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[],
    },
    Regime {
        label: "cooling, equilibrium law",
        start_c: 60.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[EQUILIBRIUM],
    },
    Regime {
        label: "heating, equilibrium law",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 8.0,
        time_grid: false,
        jitter: 0.0,
        params: &[EQUILIBRIUM],
    },
    Regime {
        label: "h = t(k+1) − t(k)",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: true,
        jitter: 0.0,
        params: &[],
    },
    Regime {
        label: "jittered h (±15 %), 50 °C, linear",
        start_c: 50.0,
        ambient_c: 50.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.15,
        params: &[],
    },
    Regime {
        label: "jittered h (±15 %), 50 °C, Coulomb friction 0.05 N·m",
        start_c: 50.0,
        ambient_c: 50.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.15,
        params: &[FRICTION],
    },
    Regime {
        label: "gravity 0.91 kg at 0.14 m",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[GRAVITY],
    },
    Regime {
        label: "Coulomb friction 0.05 N·m",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[FRICTION],
    },
    Regime {
        label: "Coulomb friction 1.7 N·m, sticking",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[HEAVY_FRICTION, LIGHT_LINK],
    },
    Regime {
        label: "Coulomb friction 0.05 N·m with a Stribeck excess 0.05 N·m at 0.16 rad/s",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[FRICTION, STRIBECK, STRIBECK_SPEED],
    },
    Regime {
        label: "Coulomb friction 1.7 N·m with a Stribeck excess 0.05 N·m at 0.16 rad/s, sticking",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[HEAVY_FRICTION, STRIBECK, STRIBECK_SPEED, LIGHT_LINK],
    },
    Regime {
        label: "backlash 0.01 rad",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[BACKLASH],
    },
    Regime {
        label: "backlash 0.01 rad, Prony law",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[BACKLASH, PRONY],
    },
    Regime {
        label: "backlash 0.01 rad, ElastoBacklash",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 0.0,
        time_grid: false,
        jitter: 0.0,
        params: &[BACKLASH, ELASTO_BACKLASH],
    },
    Regime {
        label: "all three while heating, ElastoBacklash",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 8.0,
        time_grid: true,
        jitter: 0.0,
        params: &[GRAVITY, FRICTION, BACKLASH, ELASTO_BACKLASH],
    },
    Regime {
        label: "heating at 8 W, Prony law",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 8.0,
        time_grid: false,
        jitter: 0.0,
        params: &[PRONY],
    },
    Regime {
        label: "all three while heating, Prony law",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 8.0,
        time_grid: true,
        jitter: 0.0,
        params: &[GRAVITY, FRICTION, BACKLASH, PRONY],
    },
    Regime {
        label: "all three while heating",
        start_c: 22.0,
        ambient_c: 22.0,
        heater_w: 8.0,
        time_grid: true,
        jitter: 0.0,
        params: &[GRAVITY, FRICTION, BACKLASH],
    },
];

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

/// ns per doStep for one run of `steps` from a fresh initialisation.
fn run(fmu: &Fmu, r: &Regime, steps: usize) -> f64 {
    let mut inst = fmu.instantiate(None).unwrap();
    let t_k = 273.15 + r.start_c;
    let mut params = vec![("initial_housing_temperature", t_k), ("initial_pcl_temperature", t_k)];
    params.extend_from_slice(r.params);
    inst.initialize(0.0, None, &params).unwrap();
    inst.set("ambient_temperature", 273.15 + r.ambient_c).unwrap();
    inst.set("heater_power", r.heater_w).unwrap();
    let torque = inst.handle("motor_torque").unwrap().value_reference;
    let link = inst.handle("link_angle").unwrap().value_reference;
    let mut out = [0.0];
    let w = 2.0 * std::f64::consts::PI * 0.5;
    let start = Instant::now();
    for k in 0..steps {
        let t = k as f64 * STEP;
        let h = if r.time_grid {
            (k + 1) as f64 * STEP - t
        } else {
            // a deterministic spread over ±jitter (7919 is prime: the sequence does not repeat soon)
            STEP * (1.0 + r.jitter * ((k * 7919 % 1000) as f64 / 500.0 - 1.0))
        };
        inst.set_reals(&[torque], &[2.0 * (w * t).sin()]).unwrap();
        inst.step(h).unwrap();
        inst.get_reals(&[link], &mut out).unwrap();
    }
    black_box(out);
    start.elapsed().as_secs_f64() * 1e9 / steps as f64
}

/// ns per step of a bare 6×6 matrix–vector step x ← Φ x + Γ u (the floor any exact linear step
/// pays), with the same input as the FMU loop.
fn matvec(steps: usize) -> f64 {
    let mut phi = [[0.0; 6]; 6];
    for (i, row) in phi.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = if i == j { 0.99 } else { 1e-3 / (1.0 + (i + j) as f64) };
        }
    }
    let phi = black_box(phi);
    let gamma = black_box([1e-3; 6]);
    let mut x = [0.0; 6];
    let w = 2.0 * std::f64::consts::PI * 0.5;
    let start = Instant::now();
    for k in 0..steps {
        let u = 2.0 * (w * k as f64 * STEP).sin();
        let mut y = [0.0; 6];
        for i in 0..6 {
            y[i] = gamma[i] * u + (0..6).map(|j| phi[i][j] * x[j]).sum::<f64>();
        }
        x = black_box(y);
    }
    black_box(x);
    start.elapsed().as_secs_f64() * 1e9 / steps as f64
}

fn main() {
    // DOSTEP_FMU: another build (an earlier commit's) for a before/after in one session
    let path =
        std::env::var_os("DOSTEP_FMU").map(std::path::PathBuf::from).unwrap_or_else(thermovia_tools::default_fmu_path);
    let fmu = Fmu::open(&path)
        .unwrap_or_else(|e| panic!("{}: {e} (build the FMU first: cargo run --release -p fmu-build)", path.display()));
    println!("{}", path.display());
    let steps = env_usize("DOSTEP_STEPS", 200_000);
    let runs = env_usize("DOSTEP_RUNS", 3);
    let only = std::env::var("DOSTEP_REGIME").unwrap_or_default();
    println!("fmi2DoStep via the C API, h = 1 ms, set motor_torque + doStep + get link_angle; median of {runs} x {steps} steps");
    if only == "budget" {
        worst_cases(&fmu, runs.max(3));
        return;
    }
    matvec(steps); // warm up
    let mut base = Vec::new();
    let mut rows = Vec::new();
    for r in REGIMES.iter().filter(|r| r.label.contains(only.as_str())) {
        run(&fmu, r, steps.min(20_000)); // warm caches
                                         // Alternate the mat-vec with the FMU runs so both see the same load.
        let mut samples = Vec::new();
        for _ in 0..runs {
            base.push(matvec(steps));
            samples.push(run(&fmu, r, steps));
        }
        rows.push((r.label, samples));
    }
    if base.is_empty() {
        println!("no regime matches DOSTEP_REGIME={only}");
        return;
    }
    let mv = median(base.clone());
    for (label, samples) in rows {
        let med = median(samples.clone());
        let (min, max) = samples.iter().fold((f64::INFINITY, 0.0_f64), |(a, b), &x| (a.min(x), b.max(x)));
        println!(
            "  {label:<28} median {med:>7.0} ns  (min {min:.0}, max {max:.0})  {:>5.1}x the 6x6 mat-vec",
            med / mv
        );
    }
    let (min, max) = base.iter().fold((f64::INFINITY, 0.0_f64), |(a, b), &x| (a.min(x), b.max(x)));
    println!(
        "  {:<28} median {mv:>7.1} ns  (min {min:.1}, max {max:.1}), timed between the runs above",
        "bare 6x6 mat-vec step"
    );
    if only.is_empty() {
        worst_cases(&fmu, runs.max(3));
    }
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = root.join(".venv/bin/python");
    if std::env::var_os("DOSTEP_NO_FMPY").is_some() || !only.is_empty() {
        return;
    }
    if !python.exists() {
        println!("fmpy comparison skipped: no .venv (run scripts/setup-python.sh)");
        return;
    }
    let rust_ns = median((0..15).map(|_| run(&fmu, &REGIMES[0], 20_000)).collect());
    let out = Command::new(python)
        .arg(root.join("tests/python/bench_fmpy_dostep.py"))
        .arg(root.join("target/fmu/ThermoVIA.fmu"))
        .output()
        .expect("run the fmpy benchmark");
    let text = String::from_utf8_lossy(&out.stdout);
    match text.trim().lines().last().and_then(|l| l.parse::<f64>().ok()) {
        Some(fmpy_ns) => println!(
            "fmpy driving the same FMU (same loop, cold): median {fmpy_ns:.0} ns per step; Rust harness {rust_ns:.0} ns, {:.1}x faster (same run)",
            fmpy_ns / rust_ns
        ),
        None => println!("fmpy benchmark failed: {}{}", text, String::from_utf8_lossy(&out.stderr)),
    }
}

/// The work budget's worst cases, timed (the tests count their work; the time belongs here): one
/// fmi2DoStep of each, median of `runs`, with what it returned.
fn worst_cases(fmu: &Fmu, runs: usize) {
    type Case = (&'static str, f64, &'static [(&'static str, f64)], f64);
    let cases: &[Case] = &[
        ("h = 1e300, refused before any work", 1e300, &[], 0.0),
        ("100 s of heating in 1e5 sub-steps", 100.0, &[], 8.0),
        ("stiff spring under 1 N·m friction", 1.0, &[("spring_stiffness", 1e7), ("coulomb_friction", 1.0)], 0.0),
        ("light link, 1e3 N·m friction", 1.0, &[("link_inertia", 1e-9), ("coulomb_friction", 1e3)], 0.0),
    ];
    println!("worst cases of the work budget (one fmi2DoStep each, median of {runs}):");
    for (label, h, params, heater) in cases {
        let mut times = Vec::new();
        let mut outcome = String::new();
        for _ in 0..runs {
            let mut i = fmu.instantiate(None).expect("instantiate");
            i.initialize(0.0, None, params).expect("initialize");
            i.set("heater_power", *heater).expect("heater");
            i.set("motor_torque", 1.0).expect("torque");
            let started = Instant::now();
            let r = i.step(*h);
            times.push(started.elapsed().as_secs_f64());
            outcome = match r {
                Ok(()) => "OK".into(),
                // the reason the FMU logged, after "discarded:"
                Err(e) => {
                    let text = format!("{e}");
                    let why = text.split("discarded: ").nth(1).unwrap_or(&text);
                    why.split(';').next().unwrap_or(why).chars().take(70).collect()
                }
            };
        }
        println!("  {label:<40} median {:>9.3} ms  ({outcome})", 1e3 * median(times));
    }
}
