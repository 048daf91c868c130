//! Real-time factor of the two-joint arm co-simulation at a 1 ms communication step: two ThermoVIA
//! instances through the C API, the rigid-body arm, wall and controllers in the master. Median of
//! several runs; instantiation is timed separately from the stepping loop.
//!
//! `cargo run --release -p fmu-build && cargo bench --bench arm`

use std::time::Instant;

use thermovia::arm::dynamics::ArmConfig;
use thermovia::arm::sim::{cosimulate, Scenario};
use thermovia::harness::Fmu;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

fn main() {
    let fmu = Fmu::open_default().expect("build the FMU first: cargo run --release -p fmu-build");
    let h = 1e-3;
    let runs = 9;
    for scenario in [Scenario::cold(), Scenario::hot()] {
        let cfg = ArmConfig { duration: 10.0, ..ArmConfig::default() };
        let mut total = Vec::new();
        let mut stepping = Vec::new();
        for _ in 0..runs {
            let t0 = Instant::now();
            let mut t_first = None;
            // the first progress call comes after setup and the first step: time the loop from there
            cosimulate(&fmu, &cfg, &scenario, h, None, |f| {
                if t_first.is_none() && f == 0.0 {
                    t_first = Some(Instant::now());
                }
            })
            .expect("co-simulation");
            let end = Instant::now();
            total.push(cfg.duration / (end - t0).as_secs_f64());
            stepping.push(cfg.duration / (end - t_first.unwrap_or(t0)).as_secs_f64());
        }
        println!(
            "arm {:4} joints, h = 1 ms, {} s simulated: real-time factor median {:.0}× (stepping loop {:.0}×; min {:.0}×, max {:.0}× over {runs} runs)",
            scenario.name,
            cfg.duration,
            median(total.clone()),
            median(stepping),
            total.iter().cloned().fold(f64::INFINITY, f64::min),
            total.iter().cloned().fold(0.0, f64::max),
        );
    }
}
