//! The model alone (no FMI layer) on a link its friction holds: 1.7 N·m of Coulomb friction on a
//! 0.023 kg·m² link, the motor torque-driven at 2 sin(πt) N·m, 250 000 steps of 1 ms. Prints the
//! time a step, the solver's attempted steps and the final link angle (docs/numerics.md quotes it).
//!
//!   cargo run --release -p thermovia-model --example sticking
use thermovia_model::{Model, Params, StepWork};

fn main() {
    let p = Params { coulomb_friction: 1.7, link_inertia: 0.023, ..Params::default() };
    let mut m = Model::new(p);
    let mut work = StepWork::default();
    let w = std::f64::consts::PI;
    let steps = 250_000;
    let started = std::time::Instant::now();
    for k in 0..steps {
        m.inputs.motor_torque = 2.0 * (w * k as f64 * 1e-3).sin();
        if let Err(e) = m.step_counting(1e-3, &mut work) {
            eprintln!("step {k} failed: {e}");
            std::process::exit(1);
        }
    }
    println!(
        "{:?} a step, {} attempted solver steps in {} sub-steps, final link angle {:.12e} rad",
        started.elapsed() / steps,
        work.solver_attempts,
        work.substeps,
        m.link_angle()
    );
}
