//! The fit itself, on runs the FMU makes: where Levenberg–Marquardt alone stops short.

mod common;

use thermovia_tools::calibrate::fit::{levenberg_marquardt, DampingLaw, Effect, ModelSpec, Problem, SpringBank};
use thermovia_tools::calibrate::sim::{SimInput, Simulator};

/// A link driven at 1/40 of its natural frequency (fresh rig 144's shape: J = 4.8e-3 kg·m², K = 19 N·m/rad,
/// 0.24 Hz, 500 Hz for 7.5 s) with gravity and Coulomb friction, fitted from the truth with every torque
/// 27× too large (where the campaign's fit of that rig ended): the link barely feels its inertia, so
/// K, C and the effects' torques scaled together move it almost alike, and the fit must still find
/// the truth's scale.
#[test]
fn a_fit_started_with_every_torque_scaled_finds_the_truths_scale() {
    let sim = Simulator::new(common::fmu(), 2).unwrap();
    let (rate, duration, frequency, amplitude) = (500.0, 7.5, 0.2424, 0.17);
    let time: Vec<f64> = (0..=(rate * duration) as usize).map(|k| k as f64 / rate).collect();
    let w = 2.0 * std::f64::consts::PI * frequency;
    let input = SimInput {
        motor: time.iter().map(|t| amplitude * (w * t).sin()).collect(),
        housing_k: vec![295.15; time.len()],
        time,
        frequency_hz: frequency,
        link_inertia: Some(4.84e-3),
        link0: 0.0,
        com_distance: 0.14,
        initial_link_speed: 0.0,
        after_gap: false,
    };
    let spec = ModelSpec {
        effects: vec![Effect::Gravity, Effect::CoulombFriction],
        law: DampingLaw::Viscous,
        springs: SpringBank::Scaled,
        elasto_backlash: false,
    };
    // [ln K, ln C] ++ gravity (a, b) ++ Coulomb level, N·m
    let truth = vec![19.26f64.ln(), 0.0587f64.ln(), 0.168, 0.0, 0.0054];
    let blank = Problem::new(&sim, vec![input.clone()], vec![vec![0.0; input.time.len()]], vec![0], &[22.0]).unwrap();
    let measured = blank.outputs(&spec, &truth).expect("the truth simulates");
    let prob = Problem::new(&sim, vec![input], measured, vec![0], &[22.0]).unwrap();
    let s: f64 = 27.0;
    let start = vec![truth[0] + s.ln(), truth[1] + s.ln(), 0.168 * s, 0.0, 0.0054 * s];
    let fit = levenberg_marquardt(&prob, spec, start, 60).unwrap();
    let k = fit.p[0].exp();
    assert!((k / 19.26 - 1.0).abs() < 0.1, "K = {k:.3} N·m/rad, truth 19.26 (started at {:.1})", 19.26 * s);
    assert!((fit.p[2] / 0.168 - 1.0).abs() < 0.1, "m g d = {:.4} N·m, truth 0.168", fit.p[2]);
}

/// The fit never asks the FMU for a gravity it refuses: a link that stays still while the motor
/// swings (a broken coupling) once drove the gravity's mass past the FMU's `gravity_link_mass`
/// maximum (1e4 kg) in a difference step, and `calibrate` ended with the FMU's refusal. The gravity's
/// components are bounded where their norm stays inside it, and a fit started there simulates.
#[test]
fn the_gravitys_bounds_stay_inside_what_the_fmu_accepts() {
    let sim = Simulator::new(common::fmu(), 1).unwrap();
    let time: Vec<f64> = (0..=2000).map(|k| k as f64 / 1000.0).collect();
    let d = 0.14;
    let input = SimInput {
        motor: time.iter().map(|t| 0.1 * (std::f64::consts::TAU * t).sin()).collect(),
        housing_k: vec![295.15; time.len()],
        time,
        frequency_hz: 1.0,
        link_inertia: Some(0.018),
        link0: 0.0,
        com_distance: d,
        initial_link_speed: 0.0,
        after_gap: false,
    };
    let n = input.time.len();
    let prob = Problem::new(&sim, vec![input], vec![vec![0.0; n]], vec![0], &[22.0]).unwrap();
    let spec = ModelSpec {
        effects: vec![Effect::Gravity],
        law: DampingLaw::Viscous,
        springs: SpringBank::Scaled,
        elasto_backlash: false,
    };
    let (lower, upper) = prob.bounds(&spec);
    let most = 1e4 * 9.80665 * d;
    let bound = |b: &[Option<f64>], j: usize| b[j].unwrap_or_else(|| panic!("gravity component {j} unbounded"));
    // the farthest corner of the box the two components may take
    let (a, b) = (bound(&upper, 2).max(-bound(&lower, 2)), bound(&upper, 3).max(-bound(&lower, 3)));
    assert!(a > 0.0 && a.hypot(b) <= most * (1.0 + 1e-12), "m·g·d up to {} N·m, the FMU's {most}", a.hypot(b));
    let corner = vec![34f64.ln(), 0.1f64.ln(), bound(&upper, 2), bound(&upper, 3)];
    prob.outputs(&spec, &corner).expect("the FMU simulates the gravity at its bounds' corner");
}
