//! The dostep bench's regimes on the model alone (no FMU), for callgrind and quick timing:
//!   cargo run --release -p thermovia-model --example regime -- [steps] [REGIME][-prony] [runs]
//! REGIME: all (gravity, friction and backlash while heating: the default), heating, cooling,
//! cold, gravity, friction, backlash (the last three cold). Prints the median and the fastest ns
//! per step over `runs` runs from a fresh model, the k-th with a torque amplitude of 2 + 0.01·k N·m.
use thermovia_model::{Model, Params};

fn run(which: &str, steps: usize, amplitude: f64) -> (f64, f64) {
    let (regime, prony) = match which.strip_suffix("-prony") {
        Some(regime) => (regime, true),
        None => (which, false),
    };
    let (start_c, ambient_c, heater) = match regime {
        "cooling" => (60.0, 22.0, 0.0),
        "heating" | "all" => (22.0, 22.0, 8.0),
        "cold" | "gravity" | "friction" | "backlash" => (22.0, 22.0, 0.0),
        _ => panic!("unknown regime {which:?}: all, heating, cooling, cold, gravity, friction or backlash, optionally with -prony"),
    };
    let mut p = Params {
        initial_housing_temperature: 273.15 + start_c,
        initial_pcl_temperature: 273.15 + start_c,
        ..Params::default()
    };
    if prony {
        p.viscoelastic_law = thermovia_model::ViscoelasticLaw::Prony;
    }
    // the dostep bench's loads: 0.91 kg at 0.14 m, 0.05 N·m, 0.01 rad
    if matches!(regime, "all" | "gravity") {
        p.gravity_link_mass = 0.91;
    }
    if matches!(regime, "all" | "friction") {
        p.coulomb_friction = 0.05;
    }
    if matches!(regime, "all" | "backlash") {
        p.backlash_width = 0.01;
    }
    let mut m = Model::new(p);
    m.inputs.ambient_temperature = 273.15 + ambient_c;
    m.inputs.heater_power = heater;
    let w = 2.0 * std::f64::consts::PI * 0.5;
    let start = std::time::Instant::now();
    for k in 0..steps {
        let t = k as f64 * 1e-3;
        // fmpy's time grid, as the bench's "all three" regime
        let h = (k + 1) as f64 * 1e-3 - t;
        m.inputs.motor_torque = amplitude * (w * t).sin();
        m.step(h).unwrap();
    }
    (start.elapsed().as_secs_f64() * 1e9 / steps as f64, m.link_angle())
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let steps: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(200_000);
    let which = args.get(2).map(String::as_str).unwrap_or("all");
    let runs: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(1);
    let mut ns: Vec<f64> = Vec::new();
    let mut angle = 0.0;
    // The torque-driven runs are chaotic: each run takes a slightly different amplitude, so the
    // median is over trajectories, not one (DOSTEP's 2 N·m is the first).
    for r in 0..runs {
        let (t, a) = run(which, steps, 2.0 + 0.01 * r as f64);
        ns.push(t);
        angle = a;
    }
    ns.sort_by(f64::total_cmp);
    println!("{which}: median {:.0} ns/step, fastest {:.0} (link angle at the end {angle})", ns[ns.len() / 2], ns[0]);
}
