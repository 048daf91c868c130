//! The causal (Prony) viscoelastic law in the time domain (issue 20, item 3; docs/physics.md §5c).

use std::f64::consts::PI;

use thermovia_model::mechanics;
use thermovia_model::params::ZERO_CELSIUS;
use thermovia_model::{LinkDrive, Model, Params, ThermalDrive, ViscoelasticLaw};

/// The transmission's complex stiffness K* = τ̂/Δ̂ at `frequency`, measured in the time domain:
/// the motor driven by a sine torque against a held link (link-driven mode, zero command) at a
/// PCL held at `temperature_c`, Fourier coefficients of the transmitted torque and the deflection
/// over four whole cycles after 80 s of settling.
fn measured_complex_stiffness(law: ViscoelasticLaw, temperature_c: f64, frequency: f64) -> (f64, f64) {
    let p = Params {
        viscoelastic_law: law,
        link_drive: LinkDrive::Prescribed,
        thermal_drive: ThermalDrive::PrescribedHousing,
        initial_pcl_temperature: ZERO_CELSIUS + temperature_c,
        initial_housing_temperature: ZERO_CELSIUS + temperature_c,
        excitation_frequency: frequency,
        ..Params::default()
    };
    let mut m = Model::new(p);
    m.inputs.housing_temperature_command = ZERO_CELSIUS + temperature_c;
    // 0.1 ms: the torque is held over a step, and its images at multiples of 1/h alias onto the
    // fundamental in sampled Fourier coefficients (through the dashpot, 5e-4 of K'' at 1 ms, 1e-5 here)
    let h = 1e-4;
    let period_steps = (1.0 / frequency / h).round() as usize;
    // the slowest mode relaxes with λ(K_s r_s² + K_M)/(K_s r_s²), 3.5 s at 22 °C
    let settle = (80.0 / h) as usize;
    let cycles = 4;
    let (mut tau_c, mut tau_s, mut d_c, mut d_s) = (0.0, 0.0, 0.0, 0.0);
    for k in 0..settle + cycles * period_steps {
        let t = k as f64 * h;
        m.inputs.motor_torque = 0.5 * (2.0 * PI * frequency * (t + 0.5 * h)).sin();
        m.step(h).unwrap();
        if k >= settle {
            let phase = 2.0 * PI * frequency * (t + h);
            let (s, c) = phase.sin_cos();
            let tau = m.transmitted_torque();
            let delta = m.motor_angle() - m.link_angle();
            tau_c += tau * c;
            tau_s += tau * s;
            d_c += delta * c;
            d_s += delta * s;
        }
    }
    // K* = τ̂/Δ̂ with x̂ = x_s + i x_c (a sine's phasor)
    let (tr, ti, dr, di) = (tau_s, tau_c, d_s, d_c);
    let den = dr * dr + di * di;
    ((tr * dr + ti * di) / den, (ti * dr - tr * di) / den)
}

/// With the Prony law, a harmonic run measures exactly the complex stiffness the law was fitted
/// with, K_s r_s² + κ(E_∞ + iωη + E_1 iωλ/(1 + iωλ)), at both fit frequencies and a third one it
/// was not fitted at (the law is one law at every frequency); with the hysteretic law at its own
/// excitation frequency, the table's K_s r_s² + κ(E′ + iE″) (the measurement's own check).
#[test]
fn a_harmonic_run_measures_the_complex_stiffness_of_the_law() {
    let p = Params { viscoelastic_law: ViscoelasticLaw::Prony, ..Params::default() };
    let law = p.fit_prony_law();
    let (springs, kappa) = (p.spring_torsional_stiffness(), p.modulus_to_torsion());
    for t in [22.0, 40.0, 50.0, 60.0] {
        let (re, im) = measured_complex_stiffness(ViscoelasticLaw::Hysteretic, t, 0.5);
        let (e1, e2) = p.material_table.moduli_pa(t);
        println!("hysteretic {t} °C: {re} + {im}i, table {} + {}i", springs + kappa * e1, kappa * e2);
        assert!((re / (springs + kappa * e1) - 1.0).abs() < 1e-4, "hysteretic {t} °C: K' {re}");
        assert!((im / (kappa * e2) - 1.0).abs() < 1e-4, "hysteretic {t} °C: K'' {im}");
        for f in [0.5, 1.0, 2.0] {
            let (re, im) = measured_complex_stiffness(ViscoelasticLaw::Prony, t, f);
            let (e1, e2) = law.at(t).complex_modulus(law.relaxation_time, 2.0 * PI * f);
            let (want_re, want_im) = (springs + kappa * e1, kappa * e2);
            println!("Prony {t} °C {f} Hz: K* {re:.6} + {im:.6}i, law {want_re:.6} + {want_im:.6}i");
            assert!((re / want_re - 1.0).abs() < 1e-4, "{t} °C {f} Hz: K' {re} against {want_re}");
            assert!((im / want_im - 1.0).abs() < 1e-4, "{t} °C {f} Hz: K'' {im} against {want_im}");
        }
    }
}

/// The Prony law's relaxing branch is the transmission's Maxwell branch: both at once are refused.
#[test]
fn the_prony_law_refuses_a_maxwell_branch_beside_it() {
    let p = Params { viscoelastic_law: ViscoelasticLaw::Prony, maxwell_stiffness: 2.0, ..Params::default() };
    let why = p.conflict().expect("a conflict");
    assert!(why.contains("maxwell_stiffness must be 0"), "{why}");
    assert!(Params { maxwell_stiffness: 2.0, ..Params::default() }.conflict().is_none());
    assert!(Params { viscoelastic_law: ViscoelasticLaw::Prony, ..Params::default() }.conflict().is_none());
}

/// A model whose transmission has a relaxing branch and a play of 0.01 rad: the Prony law's
/// branch, or the Maxwell effect's (K_M = 8 N·m/rad, λ = 0.05 s) under the hysteretic law.
fn with_branch_and_backlash(prony: bool, extra: Params) -> Model {
    let p = if prony {
        Params { viscoelastic_law: ViscoelasticLaw::Prony, backlash_width: 0.01, ..extra }
    } else {
        Params { maxwell_stiffness: 8.0, maxwell_relaxation_time: 0.05, backlash_width: 0.01, ..extra }
    };
    Model::new(p)
}

/// Elastic energy of the transmission, ½K e² + ½K_M (e − q)², with e the element's deflection:
/// its rest r q inside the play, Δ ∓ b/2 beyond it; plus both inertias' kinetic energy.
fn mechanical_energy(m: &mut Model) -> f64 {
    let c = m.coefficients();
    let p = m.params().clone();
    let x = m.state();
    let q = x[mechanics::MAXWELL_DEFLECTION];
    let state = mechanics::State::from([x[0], x[1], x[2], x[3], x[4]]);
    let e = match mechanics::contact(&p, &c, &state) {
        mechanics::Contact::Free => mechanics::play_centre(&c, &state),
        mode => x[0] - x[2] - mode.offset(&p),
    };
    0.5 * c.stiffness * e * e
        + 0.5 * c.maxwell_stiffness * (e - q) * (e - q)
        + 0.5 * p.motor_inertia * x[1] * x[1]
        + 0.5 * p.link_inertia * x[3] * x[3]
}

/// Backlash with a remembering branch is passive: over every 1 ms step of a torque-driven run
/// through the play, the mechanical energy grows by no more than the motor's work (its torque is
/// held over the step). The law before the play was centred on the element's rest deflection
/// began each contact with a torque of −K_M q (≈ 1 N·m cold with the Prony law). The energy is
/// continuous at the play's edges only where the centre is right; a misplaced centre (10 % of r)
/// passes this test, since one step's dissipation swamps the jump: the exact placement is
/// `mechanics::tests::a_remembering_branch_moves_the_play_so_contact_starts_at_zero_torque`.
#[test]
fn backlash_with_a_relaxing_branch_is_passive() {
    for prony in [true, false] {
        let mut m = with_branch_and_backlash(prony, Params::default());
        let (h, w) = (1e-3, 2.0 * PI * 0.5);
        let (mut contacts, mut worst) = (0, f64::NEG_INFINITY);
        let mut was_free = true;
        for k in 0..20_000 {
            let torque = 2.0 * (w * k as f64 * h).sin();
            m.inputs.motor_torque = torque;
            let (e0, motor0) = (mechanical_energy(&mut m), m.motor_angle());
            m.step(h).unwrap();
            let gain = mechanical_energy(&mut m) - e0 - torque * (m.motor_angle() - motor0);
            worst = worst.max(gain);
            assert!(gain <= 1e-9 * e0.max(1e-6), "prony {prony}, step {k}: energy grew {gain:e} J beyond the work");
            let c = m.coefficients();
            let s = m.state();
            let free = mechanics::in_play(m.params(), &c, &mechanics::State::from([s[0], s[1], s[2], s[3], s[4]]));
            contacts += usize::from(was_free && !free);
            was_free = free;
        }
        println!("prony {prony}: {contacts} contacts, largest energy gain beyond the work in a step {worst:e} J");
        assert!(contacts >= 16, "prony {prony}: the run must cross the play ({contacts} contacts)");
    }
}

/// Inside the play the unloaded element rests at r q and the branch recovers exactly:
/// q(t) = q0 e^{(r−1)t/λ}, on both stepping paths through the play (backlash alone: the exact
/// free step; with friction: the exponential Runge–Kutta step), the motor and link at rest.
#[test]
fn inside_the_play_the_unloaded_element_recovers_its_set() {
    for prony in [true, false] {
        for friction in [0.0, 0.05] {
            let mut m = with_branch_and_backlash(prony, Params { coulomb_friction: friction, ..Params::default() });
            let c = m.coefficients();
            let r = mechanics::unloaded_share(&c);
            let lam = m.params().branch_relaxation_time();
            // the set r q0 half-way to the edge: it moves towards 0 and never leaves the play
            let q0 = 0.5 * 0.5 * m.params().backlash_width / r;
            let mut s = m.state();
            s[0] = 0.5 * r * q0;
            s[mechanics::MAXWELL_DEFLECTION] = q0;
            m.set_state(&s);
            let (h, steps) = (1e-3, 3000);
            let mut worst: f64 = 0.0;
            for k in 1..=steps {
                m.step(h).unwrap();
                let want = q0 * ((r - 1.0) * k as f64 * h / lam).exp();
                worst = worst.max((m.state()[mechanics::MAXWELL_DEFLECTION] - want).abs() / q0);
            }
            let s = m.state();
            println!("prony {prony}, friction {friction}: r = {r:.4}, λ = {lam:.4} s, worst |q − q0 e^((r−1)t/λ)|/q0 {worst:e}");
            assert!(worst < 1e-11, "prony {prony}, friction {friction}: {worst:e}");
            assert_eq!([s[1], s[3]], [0.0, 0.0], "nothing moved but the branch");
            assert!(r > 0.1 && r < 1.0, "a branch that matters: r = {r}");
        }
    }
}
