//! Real-time factor of the two-joint arm co-simulation at a 1 ms communication step: two ThermoVIA
//! instances through the C API, the rigid-body arm, wall and joint controllers in the master, every
//! step recorded. Median of several runs of 10 simulated seconds (setup included).
//!
//! The machine is shared, so wall-clock time includes time spent waiting for a core; the on-CPU
//! time of this thread (CLOCK_THREAD_CPUTIME_ID) is reported alongside. A floor shows what
//! the FMU calls alone cost (two instances: set 2 inputs, doStep, get 5 outputs, no master).
//!
//! `cargo run --release -p fmu-build && cargo bench --bench arm`

use std::time::Instant;

use thermovia_importer::Fmu;
use thermovia_tools::arm::dynamics::ArmConfig;
use thermovia_tools::arm::sim::{cosimulate, Scenario};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(|a, b| a.partial_cmp(b).unwrap());
    v[v.len() / 2]
}

/// Runs `f` (which simulates `simulated` seconds) `runs` times: median, min and max real-time
/// factor by the wall clock. On a shared machine the max is the least disturbed run.
fn measure(runs: usize, simulated: f64, mut f: impl FnMut()) -> (f64, f64, f64) {
    let mut wall = Vec::new();
    for _ in 0..runs {
        let t0 = Instant::now();
        f();
        wall.push(simulated / t0.elapsed().as_secs_f64());
    }
    let (lo, hi) = (wall.iter().cloned().fold(f64::INFINITY, f64::min), wall.iter().cloned().fold(0.0, f64::max));
    (median(wall), lo, hi)
}

fn main() {
    let fmu =
        Fmu::open(thermovia_tools::default_fmu_path()).expect("build the FMU first: cargo run --release -p fmu-build");
    let (h, runs) = (1e-3, 15);
    for scenario in [Scenario::cold(), Scenario::hot()] {
        let cfg = ArmConfig { duration: 10.0, ..ArmConfig::default() };
        // whole runs (probing, instantiation, stepping, the trace's post-processing)
        let (wall, lo, hi) = measure(runs, cfg.duration, || {
            cosimulate(&fmu, &cfg, &scenario, h, None, |_| {}).expect("co-simulation");
        });
        // the stepping loop alone: from the first progress report (after the first step) to the
        // last (after the last step), 9 999 steps
        let mut sw = Vec::new();
        for _ in 0..runs {
            let (mut first, mut last) = (None, None);
            cosimulate(&fmu, &cfg, &scenario, h, None, |f| {
                let now = Instant::now();
                if f == 0.0 {
                    first = Some(now);
                } else if f == 1.0 {
                    last = Some(now);
                }
            })
            .expect("co-simulation");
            let (w0, w1) = (first.unwrap(), last.unwrap());
            sw.push((cfg.duration - h) / (w1 - w0).as_secs_f64());
        }
        println!(
            "arm, {:4} joints, h = 1 ms, whole run: real-time factor median {wall:.0}× (min {lo:.0}×, max {hi:.0}×, {runs} runs)",
            scenario.name
        );
        println!("arm, {:4} joints, h = 1 ms, stepping loop: median {:.0}×", scenario.name, median(sw));
    }
    // floor: the FMU calls alone
    let mut a = fmu.instantiate(None).unwrap();
    let mut b = fmu.instantiate(None).unwrap();
    a.initialize(0.0, None, &[("link_inertia", 0.067)]).unwrap();
    b.initialize(0.0, None, &[("link_inertia", 0.007)]).unwrap();
    let inputs: Vec<u32> =
        ["motor_torque", "load_torque"].iter().map(|n| a.handle(n).unwrap().value_reference).collect();
    let outputs: Vec<u32> = ["link_angle", "link_speed", "motor_angle", "motor_speed", "transmitted_torque"]
        .iter()
        .map(|n| a.handle(n).unwrap().value_reference)
        .collect();
    let mut out = [0.0; 5];
    let mut k = 0u64;
    let (wall, _, _) = measure(runs, 10.0, || {
        for _ in 0..10_000 {
            k += 1;
            let u = [1e-3 * (k % 100) as f64, -1e-3 * (k % 70) as f64];
            for inst in [&mut a, &mut b] {
                inst.set_reals(&inputs, &u).unwrap();
                inst.step(h).unwrap();
                inst.get_reals(&outputs, &mut out).unwrap();
            }
        }
    });
    println!("floor (FMU calls only, two instances), h = 1 ms: median {wall:.0}×");
}
