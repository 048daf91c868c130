//! `cargo bench --bench sweep`: wall time of the full default sweep (8 conditions with warm-up)
//! through the packaged FMU, median of several runs, and the same sweep driven by fmpy
//! (tests/python/sweep_fmpy_bench.py, same master) measured in the same invocation; prints both
//! medians and their ratio, and checks that the two drivers computed the same H.
//!
//! Environment: SWEEP_BENCH_RUNS (default 7), SWEEP_BENCH_FMPY_RUNS (default 3),
//! SWEEP_BENCH_PYTHON (default .venv/bin/python; create it with scripts/setup-python.sh).

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use thermovia_tools::sweep::{self, SweepArgs};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name).ok().and_then(|v| v.parse().ok()).unwrap_or(default)
}

fn main() {
    let fmu = thermovia_tools::default_fmu_path();
    if !fmu.exists() {
        eprintln!("sweep bench: {} missing; run `cargo run --release -p fmu-build` first", fmu.display());
        std::process::exit(1);
    }
    // The sweep proper, as fmpy runs it: no heating study.
    let args = SweepArgs { quiet: true, heating_powers: vec![], ..SweepArgs::default() };
    let runs = env_usize("SWEEP_BENCH_RUNS", 7);
    let out = std::env::temp_dir().join(format!("thermovia-sweep-bench-{}", std::process::id()));

    // Simulation only (open the FMU, warm-ups, 8 runs, analysis), then with every output written.
    let mut sim = Vec::new();
    let mut full = Vec::new();
    let mut last = None;
    for _ in 0..runs {
        let t0 = Instant::now();
        let r = sweep::simulate(&args, |_| {}).expect("sweep");
        sim.push(t0.elapsed().as_secs_f64());
        sweep::report::write_all(&r, &out).expect("outputs");
        full.push(t0.elapsed().as_secs_f64());
        last = Some(r);
    }
    let _ = std::fs::remove_dir_all(&out);
    let r = last.expect("at least one run");
    let steps: usize = r.conditions.iter().map(|c| c.trace.len() - 1).sum::<usize>()
        + r.warmups.iter().map(|(_, t)| t.len() - 1).sum::<usize>();
    let med = median(sim.clone());
    println!("sweep through the packaged FMU (Rust harness), {runs} runs:");
    println!("  sweep (open FMU, 3 warm-ups, 8 runs, analysis):     median {:.3} s  [{}]", med, fmt_list(&sim));
    println!("  + writing report, JSON, CSVs, SVGs:                  median {:.3} s", median(full));
    println!("  {} doSteps per sweep: {:.2} µs per doStep incl. master and set/get", steps, med / steps as f64 * 1e6);
    println!("  under the 2 s budget: {}", if med < 2.0 { "yes" } else { "NO" });

    let python = std::env::var("SWEEP_BENCH_PYTHON")
        .unwrap_or_else(|_| Path::new(env!("CARGO_MANIFEST_DIR")).join(".venv/bin/python").display().to_string());
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/python/sweep_fmpy_bench.py");
    let fmpy_runs = env_usize("SWEEP_BENCH_FMPY_RUNS", 3);
    let output = Command::new(&python).arg(&script).arg(&fmu).arg("--repeat").arg(fmpy_runs.to_string()).output();
    let output = match output {
        Ok(o) if o.status.success() => o,
        Ok(o) => {
            eprintln!("fmpy sweep failed: {}", String::from_utf8_lossy(&o.stderr));
            std::process::exit(1);
        }
        Err(e) => {
            eprintln!("cannot run {python} ({e}); create the venv with scripts/setup-python.sh");
            std::process::exit(1);
        }
    };
    let v: serde_json::Value = serde_json::from_slice(&output.stdout).expect("fmpy bench prints JSON");
    let fmpy_med = v["median_s"].as_f64().expect("median_s");
    let times: Vec<f64> = v["times_s"].as_array().unwrap().iter().filter_map(|t| t.as_f64()).collect();
    println!(
        "same sweep driven by fmpy {} (FMU2Slave, same master), {fmpy_runs} runs:",
        v["fmpy_version"].as_str().unwrap_or("?")
    );
    println!("  median {:.3} s  [{}]", fmpy_med, fmt_list(&times));
    println!("ratio fmpy / Rust harness: {:.1}x", fmpy_med / med);

    // Same FMU, same master: the two drivers must compute the same H.
    let mut worst: f64 = 0.0;
    for (c, p) in r.conditions.iter().zip(v["conditions"].as_array().unwrap()) {
        assert_eq!(c.temperature_c, p["temperature_c"].as_f64().unwrap());
        assert_eq!(c.frequency_hz, p["frequency_hz"].as_f64().unwrap());
        let d = (c.h_re - p["h_re"].as_f64().unwrap()).hypot(c.h_im - p["h_im"].as_f64().unwrap());
        worst = worst.max(d / c.conditioning.h_minus_1);
    }
    println!("largest |H_rust − H_fmpy| / |H − 1| over the 8 conditions: {worst:.1e}");
    assert!(worst < 1e-6, "the Rust and fmpy drivers disagree");
}

fn fmt_list(v: &[f64]) -> String {
    v.iter().map(|t| format!("{t:.3}")).collect::<Vec<_>>().join(", ")
}
