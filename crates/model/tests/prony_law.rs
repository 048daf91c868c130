//! The causal (Prony) viscoelastic law in the time domain (issue 20, item 3; docs/physics.md §5c).

use std::f64::consts::PI;

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
