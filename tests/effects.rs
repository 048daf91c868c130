//! Each effect of the library, on its own, through the packaged FMU, against a hand calculation.
//! Numbers: K_s r_s² = 1160 N/m · 12 · (0.0222 m)² and κ r_p² = 0.064 m · (0.02075 m)² (the
//! defaults, PAPER Table 1 / EST), E'(22 °C) = 985.34 kPa, E''(22 °C) = 834.45 kPa (Table 2).

mod common;

use thermovia_importer::{Fmu, Instance};

const KS: f64 = 1160.0 * 12.0 * 0.0222 * 0.0222;
const KAPPA_R2: f64 = 0.064 * 0.02075 * 0.02075;
const E1_22: f64 = 985.34e3;
const E2_22: f64 = 834.45e3;
const ROOM: f64 = 295.15;
const H: f64 = 1e-3;

/// An instance with the motor following commands (motor_drive = 1) and the housing held at 22 °C.
fn prescribed(fmu: &Fmu, params: &[(&str, f64)]) -> Instance {
    let mut i = fmu.instantiate(None).unwrap();
    let mut p = vec![("motor_drive", 1.0), ("thermal_drive", 1.0)];
    p.extend_from_slice(params);
    i.initialize(0.0, None, &p).unwrap();
    i.set("housing_temperature_command", ROOM).unwrap();
    i
}

/// Motor at constant speed v for `seconds`; returns θm − θl at the end.
fn ramp(i: &mut Instance, v: f64, seconds: f64) -> f64 {
    let n = (seconds / H).round() as usize;
    for k in 0..n {
        i.set("motor_angle_command", v * k as f64 * H).unwrap();
        i.set("motor_speed_command", v).unwrap();
        i.step(H).unwrap();
    }
    i.get("motor_angle").unwrap() - i.get("link_angle").unwrap()
}

fn close(a: f64, b: f64, rel: f64) -> bool {
    (a - b).abs() <= rel * b.abs()
}

#[test]
fn modulus_scales_multiply_the_table() {
    let f = common::fmu();
    let i0 = &mut prescribed(&f, &[]);
    let i1 = &mut prescribed(&f, &[("storage_modulus_scale", 0.5), ("loss_modulus_scale", 2.0)]);
    let omega = 2.0 * std::f64::consts::PI * 0.5;
    for (i, s1, s2) in [(i0, 1.0, 1.0), (i1, 0.5, 2.0)] {
        let k = i.get("effective_stiffness").unwrap();
        let c = i.get("effective_damping").unwrap();
        assert!(close(k, KS + s1 * E1_22 * KAPPA_R2, 1e-9), "K {k}");
        assert!(close(c, s2 * E2_22 * KAPPA_R2 / omega, 1e-9), "C {c}");
    }
}

/// Steady ramp: the link moves with the motor, Δ' = 0, so K Δ balances the ground torque:
/// Δ = (F + B v) / K.
#[test]
fn coulomb_friction_lags_a_ramp_by_f_over_k() {
    let f = common::fmu();
    let k = KS + E1_22 * KAPPA_R2;
    let mut i = prescribed(&f, &[("coulomb_friction", 0.05)]);
    let d = ramp(&mut i, 0.2, 5.0);
    assert!(close(d, 0.05 / k, 1e-3), "Δ {d} vs {}", 0.05 / k);
}

#[test]
fn link_damping_lags_a_ramp_by_bv_over_k() {
    let f = common::fmu();
    let k = KS + E1_22 * KAPPA_R2;
    let mut i = prescribed(&f, &[("link_damping", 0.1)]);
    let d = ramp(&mut i, 0.2, 5.0);
    assert!(close(d, 0.1 * 0.2 / k, 1e-3), "Δ {d} vs {}", 0.02 / k);
}

/// With play b the contact sits b/2 further: Δ = b/2 + F/K.
#[test]
fn backlash_adds_half_the_play_to_the_lag() {
    let f = common::fmu();
    let k = KS + E1_22 * KAPPA_R2;
    let mut i = prescribed(&f, &[("coulomb_friction", 0.05), ("backlash_width", 0.01)]);
    let d = ramp(&mut i, 0.2, 5.0);
    assert!(close(d, 0.005 + 0.05 / k, 1e-3), "Δ {d} vs {}", 0.005 + 0.05 / k);
    // inside the play nothing is transmitted: a link displaced within ±b/2 stays put
    let mut i = prescribed(&f, &[("backlash_width", 0.01), ("initial_link_angle", 0.004)]);
    i.set("motor_angle_command", 0.0).unwrap();
    i.set("motor_speed_command", 0.0).unwrap();
    for _ in 0..500 {
        i.step(H).unwrap();
    }
    assert_eq!(i.get("link_angle").unwrap(), 0.004);
    assert_eq!(i.get("transmitted_torque").unwrap(), 0.0);
}

/// `backlash_law` = 1 (Modelica's ElastoBacklash) caps the damper's torque by the spring's: a motor
/// ramping at 0.2 rad/s into the play of a free link meets it with the clipped law's jump, about
/// C·v = E''(22 °C) κ r_p² / ω · v = 1.46 N·m at 0.5 Hz (then decaying as the light link catches up),
/// and with ElastoBacklash's 2 K Δ̃, rising from zero.
#[test]
fn elasto_backlash_meets_the_play_without_the_dampers_jump() {
    let f = common::fmu();
    let c = E2_22 * KAPPA_R2 / (2.0 * std::f64::consts::PI * 0.5);
    let v = 0.2;
    let contact_torques = |law: f64| -> Vec<f64> {
        let mut i = prescribed(&f, &[("backlash_width", 0.01), ("backlash_law", law)]);
        let mut torques = Vec::new();
        for k in 0..100 {
            i.set("motor_angle_command", v * k as f64 * H).unwrap();
            i.set("motor_speed_command", v).unwrap();
            i.step(H).unwrap();
            let tau = i.get("transmitted_torque").unwrap();
            if tau != 0.0 || !torques.is_empty() {
                torques.push(tau);
            }
        }
        torques
    };
    let (clipped, elasto) = (contact_torques(0.0), contact_torques(1.0));
    eprintln!("first steps in contact: clipped {:?}\nElastoBacklash {:?}", &clipped[..8], &elasto[..8]);
    assert!(clipped.len() > 10 && elasto.len() > 10, "contact reached: {clipped:?} {elasto:?}");
    assert!(clipped[0] > 0.5 * c * v, "the clipped law jumps: {} vs C·v {}", clipped[0], c * v);
    assert!(elasto[0] > 0.0 && elasto[0] < 0.02 * c * v, "ElastoBacklash starts at {} (C·v {})", elasto[0], c * v);
    assert!(elasto[..8].windows(2).all(|w| w[1] > w[0]), "and rises: {:?}", &elasto[..8]);
}

/// Motor held at 0, link hanging at offset 0.3 rad with m g d = 0.91 kg · g · 0.14 m: the rest
/// angle solves K(0 − θ) = m g d sin(θ − 0.3) (Newton's method by hand below).
#[test]
fn gravity_rest_angle_balances_the_transmission() {
    let f = common::fmu();
    let k = KS + E1_22 * KAPPA_R2;
    let mgd = 0.91 * 9.80665 * 0.14;
    let mut th: f64 = 0.0;
    for _ in 0..50 {
        let g = -k * th - mgd * (th - 0.3).sin();
        let dg = -k - mgd * (th - 0.3).cos();
        th -= g / dg;
    }
    let mut i = prescribed(&f, &[("gravity_link_mass", 0.91), ("gravity_com_distance", 0.14), ("gravity_offset", 0.3)]);
    i.set("motor_angle_command", 0.0).unwrap();
    i.set("motor_speed_command", 0.0).unwrap();
    for _ in 0..10_000 {
        i.step(H).unwrap();
    }
    let got = i.get("link_angle").unwrap();
    assert!(th > 0.0 && close(got, th, 1e-6), "θ {got} vs {th}");
}

/// Housing stepped from 22 to 60 °C: T_pcl(t) = T1 + (T0 − T1) e^{−t/τ}.
#[test]
fn thermal_lag_is_first_order() {
    let f = common::fmu();
    let tau = 2.0;
    let mut i = prescribed(&f, &[("thermal_lag_time_constant", tau)]);
    i.set("housing_temperature_command", ROOM + 38.0).unwrap();
    for _ in 0..2000 {
        i.step(H).unwrap();
    }
    let expected = ROOM + 38.0 - 38.0 * (-1.0f64).exp();
    let got = i.get("pcl_temperature").unwrap();
    assert!((got - expected).abs() < 1e-9 * expected, "{got} vs {expected}");
    assert_eq!(i.get("housing_temperature").unwrap(), ROOM + 38.0);
}

/// Harmonic steady state at 5 Hz (near the link resonance, where stiffness matters) with a Maxwell branch: link amplitude
/// |H| = |K + iωC + K_M iωλ/(1+iωλ)| / |−Jω² + iωC + K + K_M iωλ/(1+iωλ)|.
#[test]
fn maxwell_branch_matches_the_complex_stiffness() {
    let f = common::fmu();
    let (freq, theta0, km, lam, j) = (5.0, 0.05, 20.0, 0.03, 0.018);
    let w = 2.0 * std::f64::consts::PI * freq;
    let k = KS + E1_22 * KAPPA_R2;
    let c = E2_22 * KAPPA_R2 / w;
    let amp = |km: f64| {
        // complex arithmetic by hand: (re, im)
        let d = 1.0 + (w * lam).powi(2);
        let (mre, mim) = (km * (w * lam).powi(2) / d, km * w * lam / d);
        let (nre, nim) = (k + mre, w * c + mim);
        let (dre, dim) = (-j * w * w + k + mre, w * c + mim);
        (nre.hypot(nim)) / (dre.hypot(dim))
    };
    let simulate = |km: f64| {
        let mut i = prescribed(
            &f,
            &[
                ("excitation_frequency", freq),
                ("maxwell_stiffness", km),
                ("maxwell_relaxation_time", lam),
                ("link_inertia", j),
            ],
        );
        let n = 6000;
        let (mut s, mut cs, mut m) = (0.0, 0.0, 0.0);
        for kk in 0..n {
            let t = kk as f64 * H;
            let th = theta0 * (w * t).sin();
            let th1 = theta0 * (w * (t + H)).sin();
            i.set("motor_angle_command", th).unwrap();
            i.set("motor_speed_command", (th1 - th) / H).unwrap();
            i.step(H).unwrap();
            if kk >= n - 1000 {
                let l = i.get("link_angle").unwrap();
                s += l * (w * (t + H)).sin();
                cs += l * (w * (t + H)).cos();
                m += 1.0;
            }
        }
        2.0 * s.hypot(cs) / m / theta0
    };
    let (with, without) = (simulate(km), simulate(0.0));
    assert!(close(with, amp(km), 1e-3), "{with} vs {}", amp(km));
    assert!(close(without, amp(0.0), 1e-3), "{without} vs {}", amp(0.0));
    assert!((amp(km) - amp(0.0)).abs() > 1e-2 * amp(0.0), "the branch must matter at this setting");
}

/// Rigid transmission (`transmission` = 1): one body of inertia J_m + J_l and damping B_m + B_l
/// under motor torque τ and load L from rest: v(t) = (τ + L)/B (1 − e^{−Bt/J}),
/// x(t) = (τ + L)/B (t − J/B (1 − e^{−Bt/J})); motor and link angles equal; initial speed honoured.
#[test]
fn rigid_transmission_is_one_body() {
    let f = common::fmu();
    let (jm, jl, bm, bl, tau, load) = (0.3, 0.7, 0.5, 1.5, 2.0, -0.5);
    let mut i = f.instantiate(None).unwrap();
    let p = [
        ("transmission", 1.0),
        ("motor_inertia", jm),
        ("link_inertia", jl),
        ("motor_damping", bm),
        ("link_damping", bl),
        ("initial_link_angle", 5.0), // ignored: the link is the motor
    ];
    i.initialize(0.0, None, &p).unwrap();
    i.set("motor_torque", tau).unwrap();
    i.set("load_torque", load).unwrap();
    for _ in 0..2000 {
        i.step(H).unwrap();
    }
    let (j, b, u, t) = (jm + jl, bm + bl, tau + load, 2.0);
    let x = u / b * (t - j / b * (1.0 - (-b * t / j).exp()));
    let v = u / b * (1.0 - (-b * t / j).exp());
    let (xm, xl) = (i.get("motor_angle").unwrap(), i.get("link_angle").unwrap());
    assert!(close(xm, x, 1e-9), "motor {xm} vs {x}");
    assert_eq!(xm, xl);
    assert!(close(i.get("link_speed").unwrap(), v, 1e-9));
    // the motor side passes on τ − B_m v − J_m a
    let a = u / j * (-b * t / j).exp();
    let tt = i.get("transmitted_torque").unwrap();
    assert!(close(tt, tau - bm * v - jm * a, 1e-6), "transmitted {tt}");

    // initial speed: coasting against damping only, x = v0 J/B (1 − e^{−Bt/J})
    let mut i = f.instantiate(None).unwrap();
    i.initialize(
        0.0,
        None,
        &[("transmission", 1.0), ("motor_damping", 0.0), ("link_damping", 0.2), ("initial_motor_speed", 1.5)],
    )
    .unwrap();
    for _ in 0..1000 {
        i.step(H).unwrap();
    }
    let j: f64 = 0.005 + 0.018;
    let x = 1.5 * j / 0.2 * (1.0 - (-0.2 * 1.0 / j).exp());
    assert!(close(i.get("link_angle").unwrap(), x, 1e-9));
}

/// Asymmetric friction: a rigid body pushed by a constant torque reaches v = (τ − F±)/B±, with
/// F± = F_c ± a_c and B± = B_l ± a_v in each direction (adaptive solver, smoothed sign).
#[test]
fn asymmetric_friction_has_a_level_for_each_direction() {
    let f = common::fmu();
    let (fc, ac, bl, av) = (0.3, 0.1, 0.5, -0.2);
    for (tau, level, damping) in [(1.0, fc + ac, bl + av), (-1.0, fc - ac, bl - av)] {
        let mut i = f.instantiate(None).unwrap();
        let p = [
            ("transmission", 1.0),
            ("motor_damping", 0.0),
            ("link_damping", bl),
            ("coulomb_friction", fc),
            ("coulomb_friction_asymmetry", ac),
            ("viscous_friction_asymmetry", av),
        ];
        i.initialize(0.0, None, &p).unwrap();
        i.set("motor_torque", tau).unwrap();
        for _ in 0..3000 {
            i.step(H).unwrap();
        }
        let v = i.get("motor_speed").unwrap();
        let expect = tau.signum() * (tau.abs() - level) / damping;
        assert!(close(v, expect, 1e-6), "τ {tau}: v {v}, expected {expect}");
    }
}
