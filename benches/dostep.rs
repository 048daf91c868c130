//! fmi2DoStep through the packaged FMU's C API, 1 ms communication step, as an importer drives it:
//! set motor_torque, doStep, get link_angle. Median over repeated 20 s runs; then, if the project's
//! venv exists, the same loop driven by fmpy (tests/python/bench_fmpy_dostep.py) for the ratio.
//!
//!   cargo bench --bench dostep

use std::process::Command;
use std::time::Instant;

use thermovia_importer::Fmu;

const STEP: f64 = 1e-3;
const STEPS: usize = 20_000;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

/// ns per doStep for one 20 s run from a fresh initialisation.
fn run(fmu: &Fmu, temperature_c: f64) -> f64 {
    let mut inst = fmu.instantiate(None).unwrap();
    let t_k = 273.15 + temperature_c;
    inst.initialize(0.0, None, &[("initial_housing_temperature", t_k), ("initial_pcl_temperature", t_k)]).unwrap();
    inst.set("ambient_temperature", t_k).unwrap();
    let torque = inst.handle("motor_torque").unwrap().value_reference;
    let link = inst.handle("link_angle").unwrap().value_reference;
    let mut out = [0.0];
    let w = 2.0 * std::f64::consts::PI * 0.5;
    let start = Instant::now();
    for k in 0..STEPS {
        let t = k as f64 * STEP;
        inst.set_reals(&[torque], &[2.0 * (w * t).sin()]).unwrap();
        inst.step(STEP).unwrap();
        inst.get_reals(&[link], &mut out).unwrap();
    }
    std::hint::black_box(out);
    start.elapsed().as_secs_f64() * 1e9 / STEPS as f64
}

fn main() {
    let fmu =
        Fmu::open(thermovia_tools::default_fmu_path()).expect("build the FMU first: cargo run --release -p fmu-build");
    for (label, temp) in [("cold PCL (22 °C)", 22.0), ("hot PCL (60 °C)", 60.0)] {
        run(&fmu, temp); // warm caches
        let samples: Vec<f64> = (0..15).map(|_| run(&fmu, temp)).collect();
        let med = median(samples.clone());
        let min = samples.iter().cloned().fold(f64::INFINITY, f64::min);
        println!(
            "doStep 1 ms via C API, {label}: median {med:.0} ns (min {min:.0} ns) incl. one set + one get; {:.0}x faster than real time",
            1e6 / med
        );
    }
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let python = root.join(".venv/bin/python");
    if !python.exists() {
        println!("fmpy comparison skipped: no .venv (run scripts/setup-python.sh)");
        return;
    }
    let rust_ns = median((0..15).map(|_| run(&fmu, 22.0)).collect());
    let out = Command::new(python)
        .arg(root.join("tests/python/bench_fmpy_dostep.py"))
        .arg(root.join("target/fmu/ThermoVIA.fmu"))
        .output()
        .expect("run the fmpy benchmark");
    let text = String::from_utf8_lossy(&out.stdout);
    match text.trim().lines().last().and_then(|l| l.parse::<f64>().ok()) {
        Some(fmpy_ns) => println!(
            "fmpy driving the same FMU (same loop): median {fmpy_ns:.0} ns per step; Rust harness is {:.1}x faster (same run)",
            fmpy_ns / rust_ns
        ),
        None => println!("fmpy benchmark failed: {}{}", text, String::from_utf8_lossy(&out.stderr)),
    }
}
