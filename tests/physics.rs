//! Physics of the plain-Rust model against hand calculations and an independent reference
//! integration (no FMI here: the model crate is what the FMU wraps).

use thermovia_model::mechanics::{self, Coefficients, Drive, State};
use thermovia_model::params::ZERO_CELSIUS;
use thermovia_model::thermal::ThermalInputs;
use thermovia_model::{BacklashLaw, Model, MotorDrive, Params, ViscoelasticLaw};

fn celsius(t: f64) -> f64 {
    ZERO_CELSIUS + t
}

/// A model resting at `temp_c` everywhere (housing, PCL, ambient).
fn at_temperature(mut p: Params, temp_c: f64) -> Model {
    p.initial_housing_temperature = celsius(temp_c);
    p.initial_pcl_temperature = celsius(temp_c);
    let mut m = Model::new(p);
    m.inputs.ambient_temperature = celsius(temp_c);
    m
}

/// K_s r_s² + E'(T) κ r_p² by hand from Table 1 and the repaired Table 2 row.
fn hand_stiffness(e_storage_kpa: f64) -> f64 {
    let springs = 1.16e3 * 12.0 * 0.0222_f64.powi(2);
    let pcl = e_storage_kpa * 1e3 * 0.064 * 0.02075_f64.powi(2);
    springs + pcl
}

#[test]
fn static_deflection_is_load_torque_over_effective_stiffness() {
    for (temp, e1) in [(22.0, 985.34), (60.0, 180.0)] {
        let p = Params { motor_drive: MotorDrive::PrescribedAngle, ..Params::default() };
        let mut m = at_temperature(p, temp);
        m.inputs.load_torque = 0.3;
        for _ in 0..10_000 {
            m.step(1e-3).unwrap();
        }
        let expected = 0.3 / hand_stiffness(e1);
        let got = m.link_angle();
        assert!((got - expected).abs() < 1e-9 * expected.abs().max(1e-3), "{temp} °C: {got} vs {expected}");
        assert!((m.effective_stiffness() - hand_stiffness(e1)).abs() < 1e-9 * hand_stiffness(e1));
    }
}

/// Upward zero crossings of a sampled signal, linearly interpolated.
fn zero_crossings(t: &[f64], y: &[f64]) -> Vec<f64> {
    (1..y.len())
        .filter(|&i| y[i - 1] < 0.0 && y[i] >= 0.0)
        .map(|i| t[i - 1] + (t[i] - t[i - 1]) * (-y[i - 1]) / (y[i] - y[i - 1]))
        .collect()
}

fn measured_frequency(m: &mut Model, seconds: f64) -> f64 {
    let h = 1e-4;
    let (mut ts, mut ys) = (Vec::new(), Vec::new());
    for k in 0..(seconds / h) as usize {
        m.step(h).unwrap();
        ts.push((k + 1) as f64 * h);
        ys.push(m.link_angle() - m.motor_angle());
    }
    let z = zero_crossings(&ts, &ys);
    (z.len() - 1) as f64 / (z[z.len() - 1] - z[0])
}

#[test]
fn natural_frequencies_match_hand_calculation() {
    // Tiny damping: C = K''/ω with ω = 2π·1 kHz.
    let mut p = Params {
        excitation_frequency: 1000.0,
        initial_link_angle: 0.01,
        motor_drive: MotorDrive::PrescribedAngle,
        ..Params::default()
    };
    let k = hand_stiffness(985.34);
    let c = 834.45e3 * 0.064 * 0.02075_f64.powi(2) / (2.0 * std::f64::consts::PI * 1000.0);
    // Link against a held motor: ω_d = √(K/J_l) √(1 − ζ²)
    let (jl, jm) = (p.link_inertia, p.motor_inertia);
    let zeta = c / (2.0 * (k * jl).sqrt());
    let expected = (k / jl).sqrt() * (1.0 - zeta * zeta).sqrt() / (2.0 * std::f64::consts::PI);
    let mut m = at_temperature(p.clone(), 22.0);
    let f = measured_frequency(&mut m, 3.0);
    assert!((f - expected).abs() < 1e-4 * expected, "held motor: {f} Hz vs {expected} Hz");
    assert!((expected - 6.92).abs() < 0.01, "hand value {expected}: docs/physics.md quotes ≈ 7 Hz cold");

    // Free motor: the relative mode of two inertias, √(K (1/J_m + 1/J_l)).
    p.motor_drive = MotorDrive::Torque;
    p.motor_damping = 0.0;
    let j_eff = jm * jl / (jm + jl);
    let zeta = c / (2.0 * (k * j_eff).sqrt());
    let expected = (k / j_eff).sqrt() * (1.0 - zeta * zeta).sqrt() / (2.0 * std::f64::consts::PI);
    let mut m = at_temperature(p, 22.0);
    let f = measured_frequency(&mut m, 2.0);
    assert!((f - expected).abs() < 1e-4 * expected, "free motor: {f} Hz vs {expected} Hz");
}

/// Held over one 1 ms step: motor torque, or (prescribed motor) angle and speed commands.
#[derive(Clone, Copy)]
struct StepInput {
    torque: f64,
    angle: f64,
    speed: f64,
}

/// Classical RK4 with a fine fixed step on the same right-hand side: an integrator independent of
/// the model's exact exponential and of its adaptive Dormand–Prince.
fn reference_link_angles(p: &Params, temp_c: f64, input: impl Fn(f64) -> StepInput, seconds: f64) -> Vec<f64> {
    let c = Coefficients::at(p, celsius(temp_c));
    let mut x = State::from([p.initial_motor_angle, 0.0, p.initial_link_angle, 0.0, 0.0]);
    let h = 1e-5;
    let mut out = Vec::new();
    for k in 0..(seconds * 1000.0).round() as usize {
        let i = input(k as f64 * 1e-3);
        if p.motor_drive == MotorDrive::PrescribedAngle {
            x[mechanics::MOTOR_ANGLE] = i.angle;
            x[mechanics::MOTOR_SPEED] = i.speed;
        }
        let u = Drive::new(i.torque, 0.0);
        for _ in 0..100 {
            let f = |x: &State| mechanics::derivative(p, &c, x, &u);
            let k1 = f(&x);
            let k2 = f(&(x + k1 * (h / 2.0)));
            let k3 = f(&(x + k2 * (h / 2.0)));
            let k4 = f(&(x + k3 * h));
            x += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (h / 6.0);
        }
        out.push(x[mechanics::LINK_ANGLE]);
    }
    out
}

fn model_link_angles(p: &Params, temp_c: f64, input: impl Fn(f64) -> StepInput, seconds: f64) -> Vec<f64> {
    let mut m = at_temperature(p.clone(), temp_c);
    (0..(seconds * 1000.0).round() as usize)
        .map(|k| {
            let i = input(k as f64 * 1e-3);
            m.inputs.motor_torque = i.torque;
            m.inputs.motor_angle_command = i.angle;
            m.inputs.motor_speed_command = i.speed;
            m.step(1e-3).unwrap();
            m.link_angle()
        })
        .collect()
}

fn torque(f: impl Fn(f64) -> f64) -> impl Fn(f64) -> StepInput {
    move |t| StepInput { torque: f(t), angle: 0.0, speed: 0.0 }
}

/// The motor follows θ(t) piecewise-linearly between the 1 ms samples.
fn prescribed(theta: impl Fn(f64) -> f64) -> impl Fn(f64) -> StepInput {
    move |t| StepInput { torque: 0.0, angle: theta(t), speed: (theta(t + 1e-3) - theta(t)) / 1e-3 }
}

/// A prescribed motor that steps between ±0.15 rad every 2 s (each step over about 0.1 s) and
/// rests in between, as a logged step response does.
fn motor_steps(t: f64) -> f64 {
    0.15 * (5.0 * (std::f64::consts::PI * t / 2.0).sin()).tanh()
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

#[test]
fn exact_step_matches_fine_reference_over_20_s_cold_and_hot() {
    let w = 2.0 * std::f64::consts::PI * 0.5;
    for temp in [22.0, 60.0] {
        let p = Params::default();
        let reference = reference_link_angles(&p, temp, torque(|t| 2.0 * (w * t).sin()), 20.0);
        let model = model_link_angles(&p, temp, torque(|t| 2.0 * (w * t).sin()), 20.0);
        let err = max_abs_diff(&reference, &model);
        let amplitude = reference.iter().fold(0.0_f64, |a, x| a.max(x.abs()));
        assert!(amplitude > 0.1, "the run moves: {amplitude} rad");
        assert!(err < 1e-6, "{temp} °C: max |Δθl| = {err:e} rad");
    }
}

/// One accuracy scenario of issue 12: parameters, start temperature (PCL, housing and ambient
/// unless `ambient_c` differs), heater power, the communication steps a master passes, and the
/// input held over each step.
struct Scenario<F: Fn(f64) -> StepInput> {
    params: Params,
    start_c: f64,
    ambient_c: f64,
    heater_power: f64,
    steps: Vec<f64>,
    input: F,
}

/// Steps of 1 ms over `seconds` as fmpy passes them: t(k+1) − t(k) with t(k) = k·1 ms.
fn time_grid_steps(seconds: f64) -> Vec<f64> {
    (0..(seconds * 1000.0).round() as usize).map(|k| (k + 1) as f64 * 1e-3 - k as f64 * 1e-3).collect()
}

fn exact_steps(seconds: f64) -> Vec<f64> {
    vec![1e-3; (seconds * 1000.0).round() as usize]
}

/// Independent of the model's mechanics: the thermal network advanced by the model's own thermal
/// step (not under test here), and over each communication step a fine fixed-step RK4 (100 sub-steps)
/// (1000 with backlash) on the full right-hand side with the moduli at the modulus temperature interpolated linearly in
/// time across the step (no lattice, no table, no frozen coefficients).
fn reference_run<F: Fn(f64) -> StepInput>(s: &Scenario<F>) -> Vec<f64> {
    let p = &s.params;
    let mut m = at_temperature(p.clone(), s.start_c);
    m.inputs.ambient_temperature = celsius(s.ambient_c);
    m.inputs.heater_power = s.heater_power;
    let thermal_inputs = ThermalInputs {
        heater_power: s.heater_power,
        ambient_temperature: celsius(s.ambient_c),
        housing_temperature_command: celsius(s.start_c),
    };
    let mut thermal = m.thermal.clone();
    let mut x = State::from([p.initial_motor_angle, 0.0, p.initial_link_angle, 0.0, 0.0]);
    let mut t = 0.0;
    let mut out = Vec::new();
    for &h in &s.steps {
        let i = (s.input)(t);
        if p.motor_drive == MotorDrive::PrescribedAngle {
            x[mechanics::MOTOR_ANGLE] = i.angle;
            x[mechanics::MOTOR_SPEED] = i.speed;
        }
        let u = Drive::new(i.torque, 0.0);
        // the temperature the moduli are read at (the PCL's on the heating branch, mixed towards
        // the amorphous row while the melt is supercooled: docs/physics.md §5b)
        let t0 = thermal.modulus_temperature(p);
        thermal.advance(p, &thermal_inputs, h);
        let t1 = thermal.modulus_temperature(p);
        let c0 = Coefficients::at(p, t0);
        let c = |frac: f64| if t1 == t0 { c0 } else { Coefficients::at(p, t0 + (t1 - t0) * frac) };
        // Backlash switches the torque (its damper) on and off: RK4's error at each switch is
        // O(dt²), so those runs take 1 µs sub-steps (100 sub-steps leave 6e-7 rad of it).
        let n = if p.backlash_width > 0.0 { 1000 } else { 100 };
        let dt = h / n as f64;
        for j in 0..n {
            let (ca, cm, cb) = (c(j as f64 / n as f64), c((j as f64 + 0.5) / n as f64), c((j + 1) as f64 / n as f64));
            let k1 = mechanics::derivative(p, &ca, &x, &u);
            let k2 = mechanics::derivative(p, &cm, &(x + k1 * (dt / 2.0)), &u);
            let k3 = mechanics::derivative(p, &cm, &(x + k2 * (dt / 2.0)), &u);
            let k4 = mechanics::derivative(p, &cb, &(x + k3 * dt), &u);
            x += (k1 + k2 * 2.0 + k3 * 2.0 + k4) * (dt / 6.0);
        }
        t += h;
        out.push(x[mechanics::LINK_ANGLE]);
    }
    out
}

/// The model as an FMU master drives it; also returns the PCL temperature's range, °C.
fn model_run<F: Fn(f64) -> StepInput>(s: &Scenario<F>) -> (Vec<f64>, f64, f64) {
    let mut m = at_temperature(s.params.clone(), s.start_c);
    m.inputs.ambient_temperature = celsius(s.ambient_c);
    m.inputs.heater_power = s.heater_power;
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    let mut t = 0.0;
    let angles = s
        .steps
        .iter()
        .map(|&h| {
            let i = (s.input)(t);
            m.inputs.motor_torque = i.torque;
            m.inputs.motor_angle_command = i.angle;
            m.inputs.motor_speed_command = i.speed;
            m.step(h).unwrap();
            t += h;
            lo = lo.min(m.thermal.pcl_temperature - ZERO_CELSIUS);
            hi = hi.max(m.thermal.pcl_temperature - ZERO_CELSIUS);
            m.link_angle()
        })
        .collect();
    (angles, lo, hi)
}

type Input = Box<dyn Fn(f64) -> StepInput>;

/// Issue 12's regimes, each 20 s against the fine reference: max |Δθl| < 1e-6 rad, the bound the
/// cold and hot runs above hold.
#[test]
fn every_regime_matches_fine_reference_over_20_s() {
    let w = 2.0 * std::f64::consts::PI * 0.5;
    let drive = || torque(move |t| 2.0 * (w * t).sin());
    let w1 = 2.0 * std::f64::consts::PI * 1.0;
    let motion = || prescribed(move |t| 0.5 * (w1 * t).sin());
    let prescribed_motor = Params { motor_drive: MotorDrive::PrescribedAngle, ..Params::default() };
    // the paper's loaded link: 0.91 kg at 0.14 m (the default distance)
    let gravity = Params { gravity_link_mass: 0.91, ..prescribed_motor.clone() };
    let friction = Params { coulomb_friction: 0.05, ..Params::default() };
    let backlash = Params { backlash_width: 0.01, ..prescribed_motor.clone() };
    // Backlash between contact events takes exact steps (free, engaged, clipped): the bench's
    // torque-driven motor, and a Maxwell branch, whose deflection follows Δ̃ while clipped and
    // relaxes inside the play.
    let backlash_torque = Params { backlash_width: 0.01, ..Params::default() };
    let backlash_maxwell = Params {
        backlash_width: 0.01,
        maxwell_stiffness: 8.0,
        maxwell_relaxation_time: 0.05,
        ..prescribed_motor.clone()
    };
    // a newton-metre and more on a light link: near rest the friction's slope F/(v_s J_l) is 7e4 /s,
    // and the exponential steps take it into their linear part (mechanics::friction_linearisation)
    let heavy_friction = Params { coulomb_friction: 1.7, link_inertia: 0.023, ..prescribed_motor.clone() };
    let smooth = Params { gravity_link_mass: 0.91, coulomb_friction: 0.05, ..prescribed_motor.clone() };
    // a quarter newton-metre holding the link through the rests between a prescribed motor's
    // steps: there the linearised step takes over from 16 explicit steps a sub-step
    let held_friction = Params { coulomb_friction: 0.25, ..prescribed_motor.clone() };
    // a Stribeck excess as the campaign draws it, whose falling level a few v_s out makes the
    // friction's slope negative there (the step linearises it at nothing)
    let stribeck = |p: &Params| Params { stribeck_friction: 0.05, stribeck_velocity: 0.16, ..p.clone() };
    let heavy_stribeck = stribeck(&heavy_friction);
    let held_stribeck = stribeck(&held_friction);
    let all = Params { gravity_link_mass: 0.91, coulomb_friction: 0.05, backlash_width: 0.01, ..prescribed_motor };
    // The Prony law's branch remembers its deflection through the play, which moves the play
    // (mechanics::play_centre): torque-driven, the motor crosses it hundreds of times. Fitted once
    // here, as the model does, so the reference's coefficients need no fit per evaluation.
    let prony = |p: Params| {
        let p = Params { viscoelastic_law: ViscoelasticLaw::Prony, ..p };
        Params { prony: Some(p.fit_prony_law()), ..p }
    };
    let backlash_prony = prony(Params { backlash_width: 0.01, ..Params::default() });
    let all_prony = prony(all.clone());
    // Modelica's ElastoBacklash: the capped spells (τ = 2τ_c) go to Dormand–Prince
    let elasto = |p: Params| Params { backlash_law: BacklashLaw::ElastoBacklash, ..p };
    let elasto_torque = elasto(Params { backlash_width: 0.01, ..Params::default() });
    let elasto_all = elasto(all.clone());
    let elasto_prony = elasto(prony(Params { backlash_width: 0.01, ..Params::default() }));
    // Steps off 1 ms by a few 1e-10 relative: beyond fmpy's jitter, past the propagator's step key.
    // A variable-step master: every step a new length (new tables each time, bounded caches).
    let varying: Vec<f64> = (0..20_000).map(|k| 1e-3 * (1.0 + 0.1 * (k as f64 * 0.37).sin())).collect();
    let skewed: Vec<f64> = (0..20_000).map(|k| 1e-3 * (1.0 + [3e-10, -4e-10, 1e-12, 0.0][k % 4])).collect();
    let scenarios: Vec<(&str, Scenario<Input>, f64)> = vec![
        ("heating at 8 W", sc(Params::default(), 22.0, 22.0, 8.0, exact_steps(20.0), Box::new(drive())), 5.0),
        (
            "heating at 8 W from 38 °C (across 40 °C)",
            sc(Params::default(), 38.0, 38.0, 8.0, exact_steps(20.0), Box::new(drive())),
            2.0,
        ),
        ("cooling from 60 °C", sc(Params::default(), 60.0, 22.0, 0.0, exact_steps(20.0), Box::new(drive())), 0.2),
        (
            "h = t(k+1) − t(k), cold",
            sc(Params::default(), 22.0, 22.0, 0.0, time_grid_steps(20.0), Box::new(drive())),
            0.0,
        ),
        (
            "h = t(k+1) − t(k), heating",
            sc(Params::default(), 22.0, 22.0, 8.0, time_grid_steps(20.0), Box::new(drive())),
            5.0,
        ),
        ("h off 1 ms by 4e-10, heating", sc(Params::default(), 22.0, 22.0, 8.0, skewed, Box::new(drive())), 5.0),
        ("gravity 0.91 kg", sc(gravity.clone(), 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(motion())), 0.0),
        (
            "Coulomb friction 0.05 N·m",
            sc(friction, 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(torque(move |t| 1.5 * (w1 * t).sin()))),
            0.0,
        ),
        (
            "Coulomb friction 1.7 N·m, light link",
            sc(heavy_friction, 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(motion())),
            0.0,
        ),
        (
            "Coulomb friction 0.25 N·m, held between steps",
            sc(held_friction, 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(prescribed(motor_steps))),
            0.0,
        ),
        (
            "Coulomb 1.7 N·m and a Stribeck excess, light link",
            sc(heavy_stribeck, 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(motion())),
            0.0,
        ),
        (
            "Coulomb 0.25 N·m and a Stribeck excess, held between steps",
            sc(held_stribeck, 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(prescribed(motor_steps))),
            0.0,
        ),
        ("backlash 0.01 rad", sc(backlash.clone(), 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(motion())), 0.0),
        (
            "backlash, torque-driven motor",
            sc(backlash_torque, 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(drive())),
            0.0,
        ),
        (
            "backlash while heating, fmpy's h",
            sc(backlash, 22.0, 22.0, 8.0, time_grid_steps(20.0), Box::new(motion())),
            5.0,
        ),
        (
            "backlash with a Maxwell branch",
            sc(backlash_maxwell, 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(motion())),
            0.0,
        ),
        (
            "gravity, heating, h varying ±10 % every step",
            sc(gravity.clone(), 22.0, 22.0, 8.0, varying, Box::new(motion())),
            5.0,
        ),
        ("gravity and friction while heating", sc(smooth, 22.0, 22.0, 8.0, exact_steps(20.0), Box::new(motion())), 5.0),
        ("all three while heating, fmpy's h", sc(all, 22.0, 22.0, 8.0, time_grid_steps(20.0), Box::new(motion())), 5.0),
        (
            "backlash with the Prony law, torque-driven",
            sc(backlash_prony, 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(drive())),
            0.0,
        ),
        (
            "all three, Prony law, heating, fmpy's h",
            sc(all_prony, 22.0, 22.0, 8.0, time_grid_steps(20.0), Box::new(motion())),
            5.0,
        ),
        (
            "ElastoBacklash, torque-driven",
            sc(elasto_torque, 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(drive())),
            0.0,
        ),
        (
            "ElastoBacklash with the Prony law",
            sc(elasto_prony, 22.0, 22.0, 0.0, exact_steps(20.0), Box::new(drive())),
            0.0,
        ),
        (
            "all three, ElastoBacklash, heating, fmpy's h",
            sc(elasto_all, 22.0, 22.0, 8.0, time_grid_steps(20.0), Box::new(motion())),
            5.0,
        ),
    ];
    let mut failures = Vec::new();
    for (label, s, min_rise) in &scenarios {
        let reference = reference_run(s);
        let (model, lo, hi) = model_run(s);
        let err = max_abs_diff(&reference, &model);
        let amplitude = reference.iter().fold(0.0_f64, |a, x| a.max(x.abs()));
        println!("{label:<42} max |Δθl| = {err:.2e} rad (amplitude {amplitude:.3} rad, PCL {lo:.2}–{hi:.2} °C)");
        assert!(amplitude > 0.05, "{label}: the run moves ({amplitude} rad)");
        assert!(hi - lo >= *min_rise, "{label}: the PCL temperature must move by {min_rise} K: {lo}–{hi} °C");
        if err.is_nan() || err >= 1e-6 {
            failures.push(format!("{label}: {err:e} rad"));
        }
    }
    assert!(failures.is_empty(), "max |Δθl| ≥ 1e-6 rad: {failures:?}");
}

fn sc<F: Fn(f64) -> StepInput>(
    params: Params,
    start_c: f64,
    ambient_c: f64,
    heater_power: f64,
    steps: Vec<f64>,
    input: F,
) -> Scenario<F> {
    Scenario { params, start_c, ambient_c, heater_power, steps, input }
}

#[test]
fn adaptive_step_matches_fine_reference_with_nonlinear_effects() {
    let w = 2.0 * std::f64::consts::PI * 1.0;
    // Prescribed motor (as in calibration): a driven, damped link, not a chaotic free pendulum.
    let p = Params {
        motor_drive: MotorDrive::PrescribedAngle,
        coulomb_friction: 0.05,
        gravity_link_mass: 0.3,
        backlash_width: 0.01,
        ..Params::default()
    };
    for temp in [22.0, 60.0] {
        let reference = reference_link_angles(&p, temp, prescribed(|t| 0.5 * (w * t).sin()), 20.0);
        let model = model_link_angles(&p, temp, prescribed(|t| 0.5 * (w * t).sin()), 20.0);
        let err = max_abs_diff(&reference, &model);
        assert!(err < 1e-6, "{temp} °C: max |Δθl| = {err:e} rad");
    }
    // Torque-driven with link friction: the free motor makes the run drift, yet no chaos.
    let p = Params { coulomb_friction: 0.05, stribeck_friction: 0.02, ..Params::default() };
    for temp in [22.0, 60.0] {
        let reference = reference_link_angles(&p, temp, torque(|t| 1.5 * (w * t).sin()), 20.0);
        let model = model_link_angles(&p, temp, torque(|t| 1.5 * (w * t).sin()), 20.0);
        let err = max_abs_diff(&reference, &model);
        assert!(err < 1e-6, "torque-driven, {temp} °C: max |Δθl| = {err:e} rad");
    }
}

#[test]
fn stiffest_parameters_stay_exact_and_stable() {
    // Printed Table 2 at its stiffest (cold), a very slow excitation (C = K''/ω ≈ 370 N·m·s/rad)
    // and a light motor: the fast pole is near −4e5 1/s, 400× beyond explicit RK4's limit at 1 ms.
    let mut p = Params {
        material_table: thermovia_model::material::MaterialTable::PrintedExperimental,
        excitation_frequency: 0.01,
        motor_inertia: 1e-3,
        ..Params::default()
    };
    let step = || torque(|t| if t < 1.0 { 1.0 } else { -0.5 });
    let coarse = model_link_angles(&p, 22.0, step(), 5.0);
    p.max_internal_step = 1e-5;
    let fine = model_link_angles(&p, 22.0, step(), 5.0);
    assert!(coarse.iter().all(|x| x.is_finite()));
    let err = max_abs_diff(&coarse, &fine);
    // Both runs are exact discretisations; what separates them is the rounding of 500 000 vs
    // 5 000 products with a matrix of condition ~1e5, a few 1e-9 rad: two orders under the
    // 1e-6 rad accuracy claimed for the integrator.
    assert!(err < 1e-8, "1 ms vs 10 µs sub-steps differ by {err:e} rad");
}

#[test]
fn heating_at_10_w_reaches_60_c_in_the_pcl_within_the_papers_30_to_90_s() {
    let mut m = at_temperature(Params::default(), 22.0);
    m.inputs.heater_power = 10.0;
    let mut t = 0.0;
    while m.thermal.pcl_temperature < celsius(60.0) && t < 600.0 {
        m.step(0.01).unwrap();
        t += 0.01;
    }
    let energy = m.thermal.heater_energy;
    assert!((30.0..=90.0).contains(&t), "PCL reached 60 °C after {t:.1} s");
    // The paper's budget: 250 J sensible, up to ~500 J with latent heat, plus the heater and losses.
    assert!((400.0..=900.0).contains(&energy), "{energy:.0} J");
}

#[test]
fn heater_energy_equals_stored_plus_lost_to_rounding() {
    let mut m = at_temperature(Params::default(), 22.0);
    m.inputs.ambient_temperature = celsius(20.0);
    let stored0 = m.thermal.stored_heat(m.params());
    let mut peak_pcl: f64 = 0.0;
    for k in 0..20_000 {
        m.inputs.heater_power = if k < 8_000 { 12.0 } else { 0.0 };
        m.step(0.01).unwrap();
        peak_pcl = peak_pcl.max(m.thermal.pcl_temperature);
    }
    assert!(peak_pcl > celsius(65.0), "the run must pass through the melt: peak {peak_pcl} K");
    let th = &m.thermal;
    let balance = th.heater_energy - (th.stored_heat(m.params()) - stored0) - th.heat_lost;
    assert!(th.heater_energy > 900.0 && th.heat_lost > 100.0, "the run must heat and lose heat");
    assert!(balance.abs() < 1e-10 * th.heater_energy, "imbalance {balance:e} J of {} J", th.heater_energy);
}

#[test]
fn a_step_that_fails_leaves_the_model_unchanged() {
    let p = Params {
        coulomb_friction: 0.01,
        solver_tolerance: 1e-30, // unreachable: the adaptive solver must give up, not loop
        ..Params::default()
    };
    let mut m = at_temperature(p, 22.0);
    m.inputs.motor_torque = 1.0;
    let before = m.clone();
    assert!(m.step(1e-3).is_err());
    assert!(m == before);
}

/// Runs `a` 1,500 steps of 1 ms on fmpy's time grid with a sinusoidal motor torque, rebuilds a
/// fresh model from its parameters, inputs and state alone (as a deserialized FMU state is), and
/// checks both go on bit-identically for 1,500 more steps.
fn continues_bit_identically_from_its_state(a: &mut Model, what: &str) {
    let drive = |m: &mut Model, k: usize| {
        m.inputs.motor_torque = 1.5 * (k as f64 * 1e-3 * 6.0).sin();
        m.step((k + 1) as f64 * 1e-3 - k as f64 * 1e-3).unwrap();
    };
    for k in 0..1500 {
        drive(a, k);
    }
    let mut b = Model::new(a.params().clone());
    b.inputs = a.inputs.clone();
    b.set_state(&a.state());
    for k in 1500..3000 {
        drive(a, k);
        drive(&mut b, k);
        assert!(*a == b, "{what}: diverged at step {k}");
    }
}

/// The propagator tables, step keys and exponential Runge–Kutta coefficients are caches: a model
/// rebuilt from the state alone (as a deserialized FMU state is) continues bit-identically, in
/// every integrator path, while heating and on fmpy's time grid.
#[test]
fn caches_do_not_change_the_trajectory() {
    let cases = [
        Params::default(),
        Params { gravity_link_mass: 0.91, coulomb_friction: 0.05, stribeck_friction: 0.02, ..Params::default() },
        Params { backlash_width: 0.01, gravity_link_mass: 0.3, ..Params::default() },
        // a link that sticks: linearised steps, each damping's matrix exponential built once and kept
        Params { coulomb_friction: 1.7, link_inertia: 0.023, ..Params::default() },
    ];
    for p in cases {
        let mut a = at_temperature(p.clone(), 35.0);
        a.inputs.heater_power = 8.0;
        continues_bit_identically_from_its_state(&mut a, &format!("{p:?}"));
    }
    // A supercooled melt crystallising (issue 20): the kinetics' caches (rate anchors, T_f's χ and
    // θ) must not change the trajectory either; Nakamura's integral is part of the state.
    let p = Params::default();
    let mut a = Model::new(p.clone());
    a.inputs.ambient_temperature = celsius(22.0);
    let (t, melt) = (celsius(38.0), celsius(60.0));
    a.thermal.pcl_temperature = t;
    a.thermal.housing_temperature = t;
    a.thermal.pcl_structural_temperature = melt;
    a.thermal.pcl_enthalpy = thermovia_model::thermal::pcl_sensible_enthalpy(&p, t)
        + p.pcl_mass * p.pcl_latent_heat * thermovia_model::thermal::melt_fraction(&p, melt);
    let x0 = a.crystallinity();
    continues_bit_identically_from_its_state(&mut a, "crystallising");
    assert!(a.crystallinity() > x0 + 1e-4, "crystallised {x0} -> {}", a.crystallinity());
    assert!(a.thermal.pcl_structural_temperature > a.thermal.pcl_temperature, "still supercooled");
}

/// The work budget covers the exponential Runge–Kutta path too (found by the fuzzer after the
/// speed work: 4.8 kN·m of smoothed friction at 0.1 µs sub-steps made every sub-step take 1,024
/// explicit exponential steps, 1e8 in one doStep). Since the friction's slope goes into the
/// linear part near rest (mechanics::friction_linearisation) that step completes. At 0.05 µs
/// sub-steps (8e4 in a 4 ms step) 550 N·m of friction holds the explicit steps to some 16 each
/// (short of what linearising a held link pays for), 1.3e6 in all: the step must end with the
/// budget's failure, state unchanged.
#[test]
fn steep_friction_at_tiny_sub_steps_runs_out_of_budget_instead_of_hanging() {
    let at = |max_internal_step: f64, coulomb_friction: f64| {
        let p = Params {
            coulomb_friction,
            max_internal_step,
            material_table: thermovia_model::material::MaterialTable::PrintedExperimental,
            ..Params::default()
        };
        let mut m = Model::new(p);
        m.initialize();
        m.inputs.motor_torque = 1.0;
        m
    };
    let mut m = at(1e-7, 4773.8);
    m.step(1e-2).expect("the linearised steps take the fuzzer's step");
    assert!(m.link_angle().is_finite() && m.link_angle().abs() < 1e-3, "the link sticks: {}", m.link_angle());
    let mut m = at(5e-8, 550.0);
    let before = m.link_angle();
    match m.step(4e-3) {
        Err(thermovia_model::StepFailure::SolverBudget { .. }) => {}
        other => panic!("expected the solver budget to end the step, got {other:?}"),
    }
    assert_eq!(m.link_angle(), before, "a failed step changes nothing");
}

/// Steps shorter than the model resolves are refused by name, not as "a state became NaN" (issue
/// 19); the shortest one accepted integrates to a finite state, the state is unchanged otherwise.
#[test]
fn a_step_too_small_to_resolve_is_refused_with_that_reason() {
    let mut m = Model::new(Params::default());
    m.initialize();
    m.inputs.heater_power = 8.0;
    m.inputs.motor_torque = 1.0;
    let bits = |m: &Model| m.state().iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let before = bits(&m);
    for h in [1e-300, 1e-200, thermovia_model::MIN_RESOLVABLE_STEP / 2.0] {
        match m.step(h) {
            Err(f @ thermovia_model::StepFailure::StepTooSmall { .. }) => {
                assert!(f.to_string().contains("too small to resolve"), "{f}")
            }
            other => panic!("h = {h:e}: expected StepTooSmall, got {other:?}"),
        }
        assert_eq!(bits(&m), before, "h = {h:e}: a refused step changes nothing");
    }
    m.step(thermovia_model::MIN_RESOLVABLE_STEP).expect("the shortest resolvable step");
    assert!([m.link_angle(), m.link_speed(), m.thermal.pcl_temperature].iter().all(|x| x.is_finite()));
}

/// A link that friction holds through the rests of a stepping motor costs a few solver steps per
/// communication step, not the explicit stability limit's hundreds (campaign rigs of logged step
/// responses spent most of their search budget there): counted work, not wall time. Measured
/// 2026-11-27: 18.4 per step; 266.6 with explicit steps up to 256 a sub-step for a held link too. The accuracy
/// of the same run is in `every_regime_matches_fine_reference_over_20_s`.
#[test]
fn a_link_held_by_friction_between_motor_steps_takes_few_solver_steps() {
    use thermovia_model::StepWork;
    let p = Params { coulomb_friction: 0.25, motor_drive: MotorDrive::PrescribedAngle, ..Params::default() };
    let mut m = at_temperature(p, 22.0);
    let input = prescribed(motor_steps);
    let mut work = StepWork::default();
    let steps = 20_000;
    for k in 0..steps {
        let i = input(k as f64 * 1e-3);
        m.inputs.motor_angle_command = i.angle;
        m.inputs.motor_speed_command = i.speed;
        m.step_counting(1e-3, &mut work).expect("a held link steps");
    }
    let per_step = work.solver_attempts as f64 / steps as f64;
    println!("{work:?}: {per_step:.1} attempted solver steps per communication step");
    assert!(per_step < 60.0, "{per_step:.1} attempts per step: {work:?}");
}

/// Every step's work is bounded by the budget the model counts (work, not wall time, which a
/// shared machine makes noise): steps that would need more sub-steps are refused before any work,
/// and the stiffest legal rigs, with and without the adaptive solver, stay within the sub-step and
/// attempt budgets whatever they return. Timing lives in `cargo bench --bench dostep`.
#[test]
fn every_step_is_bounded_by_the_work_budget() {
    use thermovia_model::{StepFailure, StepWork, MAX_SOLVER_ATTEMPTS_PER_STEP, MAX_SUBSTEPS_PER_STEP};
    for h in [1e6, 1e10, 1e300, f64::MAX] {
        let mut m = Model::new(Params::default());
        m.initialize();
        let mut work = StepWork::default();
        match m.step_counting(h, &mut work) {
            Err(StepFailure::TooManySubsteps { .. }) => {}
            other => panic!("h = {h:e}: expected TooManySubsteps, got {other:?}"),
        }
        assert_eq!(work, StepWork::default(), "h = {h:e}: refused before any work");
    }
    let d = Params::default;
    let rigs = [
        ("spring_count = 1e3", Params { spring_count: 1e3, ..d() }),
        ("spring_stiffness = 1e7", Params { spring_stiffness: 1e7, ..d() }),
        ("max_internal_step = 1e-7", Params { max_internal_step: 1e-7, ..d() }),
        ("stiff, with friction", Params { spring_stiffness: 1e7, coulomb_friction: 1.0, ..d() }),
        ("stiff, with backlash", Params { spring_stiffness: 1e7, backlash_width: 0.01, ..d() }),
        ("light link, friction", Params { link_inertia: 1e-9, coulomb_friction: 1e3, ..d() }),
    ];
    for (name, p) in rigs {
        let mut m = Model::new(p);
        m.initialize();
        m.inputs.motor_torque = 1.0;
        let mut work = StepWork::default();
        let outcome = m.step_counting(1.0, &mut work);
        println!("{name}: {outcome:?}, {work:?}");
        assert!(work.substeps as f64 <= MAX_SUBSTEPS_PER_STEP, "{name}: {work:?}");
        assert!(work.solver_attempts <= MAX_SOLVER_ATTEMPTS_PER_STEP, "{name}: {work:?}");
        if let Err(f) = outcome {
            assert!(
                matches!(
                    f,
                    StepFailure::TooManySubsteps { .. }
                        | StepFailure::SolverBudget { .. }
                        | StepFailure::SolverStalled { .. }
                ),
                "{name}: {f:?}"
            );
        }
    }
    // The counter counts: a nonlinear step of 1 s takes sub-steps and solver attempts.
    let mut m = Model::new(Params { coulomb_friction: 0.1, ..d() });
    m.initialize();
    m.inputs.motor_torque = 1.0;
    let mut work = StepWork::default();
    m.step_counting(1.0, &mut work).unwrap();
    assert!(work.substeps >= 1 && work.solver_attempts >= work.substeps, "{work:?}");
}

/// Link-driven mode (issue 21): the link follows the engine's angle and speed over each step, and
/// `transmitted_torque_mean` is the impulse the step integrated. Energy through the joint — into
/// the transmission from the motor, minus out to the link at the engine's speeds — must equal what
/// the transmission stores plus what it dissipates.
fn link_driven(motor: MotorDrive, loss_scale: f64) -> Model {
    let p = Params {
        link_drive: thermovia_model::LinkDrive::Prescribed,
        motor_drive: motor,
        motor_damping: 0.0,
        loss_modulus_scale: loss_scale,
        ..Params::default()
    };
    at_temperature(p, 40.0)
}

/// The engine's side: a link path of straight pieces, speed v_n over step n (continuous angle).
fn link_speed(t: f64) -> f64 {
    0.8 * (2.0 * std::f64::consts::PI * 0.7 * t).cos() + 0.3 * (2.0 * std::f64::consts::PI * 2.3 * t).sin()
}

#[test]
fn link_driven_torque_motor_passes_its_work_to_the_link_and_the_springs_exactly() {
    // a torque-driven motor (the engine's use) on a lossless transmission: motor work − link work
    // = the change of stored energy, every term from step ends (B_m = 0, C ≈ 0)
    let mut m = link_driven(MotorDrive::Torque, 1e-12);
    let h = 1e-3;
    let k = m.effective_stiffness();
    let stored = |m: &Model| 0.5 * k * (m.motor_angle() - m.link_angle()).powi(2);
    let (mut link_angle, mut w_motor, mut w_link, mut through) = (0.0, 0.0, 0.0, 0.0);
    let e0 = stored(&m);
    for n in 0..2000 {
        let t = n as f64 * h;
        let v = link_speed(t);
        let tau_m = 2.0 * (2.0 * std::f64::consts::PI * 1.1 * t).sin() - 30.0 * (m.motor_angle() - 0.2 * t.sin());
        m.inputs.link_angle_command = link_angle;
        m.inputs.link_speed_command = v;
        m.inputs.motor_torque = tau_m;
        let (a0, s0) = (m.motor_angle(), m.motor_speed());
        m.step(h).unwrap();
        assert!((m.link_angle() - (link_angle + v * h)).abs() < 1e-12, "the link follows the engine");
        assert_eq!(m.link_speed(), v);
        link_angle += v * h;
        let dw_motor =
            tau_m * (m.motor_angle() - a0) - 0.5 * m.params().motor_inertia * (m.motor_speed().powi(2) - s0 * s0);
        let dw_link = v * m.transmitted_torque_mean * h;
        w_motor += dw_motor;
        w_link += dw_link;
        through += dw_motor.abs() + dw_link.abs();
    }
    let balance = w_motor - w_link - (stored(&m) - e0);
    assert!(through > 0.1, "the test moves energy: {through} J");
    assert!(
        balance.abs() <= 1e-6 * through,
        "motor {w_motor} J − link {w_link} J − stored: {balance:e} of {through} J"
    );
}

#[test]
fn link_driven_transmission_stores_and_dissipates_what_passes_through_it() {
    // both sides prescribed, the PCL damping on: the relative speed is constant over each step, so
    // the dissipation ∫ C Δ'² dt is exact from step ends, and the energy through the joint,
    // Σ (u_n − v_n) τ̄_n h, must equal ΔE_stored + dissipated
    let mut m = link_driven(MotorDrive::PrescribedAngle, 1.0);
    let h = 1e-3;
    let (k, c) = (m.effective_stiffness(), m.effective_damping());
    assert!(c > 0.1, "C {c}");
    let stored = |m: &Model| 0.5 * k * (m.motor_angle() - m.link_angle()).powi(2);
    let (mut link_angle, mut motor_angle) = (0.0, 0.0);
    let (mut through, mut dissipated, mut scale) = (0.0, 0.0, 0.0);
    let e0 = stored(&m);
    for n in 0..2000 {
        let t = n as f64 * h;
        let (u, v) = (0.5 * (2.0 * std::f64::consts::PI * 0.9 * t).sin(), link_speed(t));
        m.inputs.motor_angle_command = motor_angle;
        m.inputs.motor_speed_command = u;
        m.inputs.link_angle_command = link_angle;
        m.inputs.link_speed_command = v;
        m.step(h).unwrap();
        motor_angle += u * h;
        link_angle += v * h;
        let flow = (u - v) * m.transmitted_torque_mean * h;
        through += flow;
        scale += flow.abs();
        dissipated += c * (u - v).powi(2) * h;
    }
    let balance = through - (stored(&m) - e0) - dissipated;
    assert!(dissipated > 0.1 * scale, "dissipation matters here: {dissipated} of {scale} J");
    assert!(
        balance.abs() <= 1e-6 * scale,
        "through {through} J, stored {} J, dissipated {dissipated} J: {balance:e}",
        stored(&m) - e0
    );
}

#[test]
fn link_driven_motor_matches_an_independent_integration_with_the_link_moving_as_commanded() {
    // the motor's ODE with the link on its commanded path, RK4 at 1 µs in this test, against the
    // model's exact steps of 1 ms: motor angle, speed and the mean torque
    let mut m = link_driven(MotorDrive::Torque, 1.0);
    let (k, c) = (m.effective_stiffness(), m.effective_damping());
    let jm = m.params().motor_inertia;
    let h = 1e-3;
    let (mut x, mut w) = (0.0f64, 0.0f64); // reference motor angle and speed
    let mut link_angle = 0.0;
    for n in 0..300 {
        let t = n as f64 * h;
        let v = link_speed(t);
        let tau_m = 1.5 * (2.0 * std::f64::consts::PI * 1.3 * t).cos();
        m.inputs.link_angle_command = link_angle;
        m.inputs.link_speed_command = v;
        m.inputs.motor_torque = tau_m;
        m.step(h).unwrap();
        let sub = 1000;
        let dt = h / sub as f64;
        let mut impulse = 0.0;
        for i in 0..sub {
            let s0 = i as f64 * dt;
            let f = |s: f64, x: f64, w: f64| {
                let torque = k * (x - (link_angle + v * s)) + c * (w - v);
                (w, (tau_m - torque) / jm, torque)
            };
            let (k1x, k1w, t1) = f(s0, x, w);
            let (k2x, k2w, t2) = f(s0 + dt / 2.0, x + dt / 2.0 * k1x, w + dt / 2.0 * k1w);
            let (k3x, k3w, t3) = f(s0 + dt / 2.0, x + dt / 2.0 * k2x, w + dt / 2.0 * k2w);
            let (k4x, k4w, t4) = f(s0 + dt, x + dt * k3x, w + dt * k3w);
            x += dt / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x);
            w += dt / 6.0 * (k1w + 2.0 * k2w + 2.0 * k3w + k4w);
            impulse += dt / 6.0 * (t1 + 2.0 * t2 + 2.0 * t3 + t4);
        }
        link_angle += v * h;
        assert!((m.motor_angle() - x).abs() < 1e-9, "step {n}: motor angle {} vs {x}", m.motor_angle());
        assert!((m.motor_speed() - w).abs() < 1e-6, "step {n}: motor speed {} vs {w}", m.motor_speed());
        let mean = impulse / h;
        assert!(
            (m.transmitted_torque_mean - mean).abs() < 1e-6 * (1.0 + mean.abs()),
            "step {n}: mean torque {} vs {mean}",
            m.transmitted_torque_mean
        );
    }
}
