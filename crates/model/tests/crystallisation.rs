//! The PCL's crystallinity as a state (issue 20): rate-dependent crystallisation on cooling,
//! energy conserved over a heating–cooling cycle with the latent heat included.

use thermovia_model::params::ZERO_CELSIUS;
use thermovia_model::{Crystallisation, Model, Params, ThermalDrive};

/// Cools the prescribed PCL (no lag: a DSC pan) linearly from 70 °C at `rate_k_per_min` and
/// returns the temperature of the fastest crystallisation (the exotherm's peak), °C.
fn crystallisation_peak(law: Crystallisation, rate_k_per_min: f64) -> f64 {
    let p = Params {
        thermal_drive: ThermalDrive::PrescribedHousing,
        crystallisation: law,
        initial_pcl_temperature: ZERO_CELSIUS + 70.0,
        initial_housing_temperature: ZERO_CELSIUS + 70.0,
        max_internal_step: 0.05,
        ..Params::default()
    };
    let mut m = Model::new(p);
    let h = 0.05;
    let rate = rate_k_per_min / 60.0;
    let (mut peak_rate, mut peak_t) = (0.0, f64::NAN);
    let mut x = m.crystallinity();
    let mut t = ZERO_CELSIUS + 70.0;
    while t > ZERO_CELSIUS + 5.0 {
        t -= rate * h;
        m.inputs.housing_temperature_command = t;
        m.step(h).unwrap();
        let x1 = m.crystallinity();
        if (x1 - x) / h > peak_rate {
            peak_rate = (x1 - x) / h;
            peak_t = t;
        }
        x = x1;
    }
    let xc = thermovia_model::crystallisation::ultimate_crystallinity(m.params());
    assert!(x > 0.999 * xc, "crystallised to {x} of {xc}");
    peak_t - ZERO_CELSIUS
}

#[test]
fn crystallisation_temperature_falls_with_cooling_rate() {
    let slow = crystallisation_peak(Crystallisation::Nakamura, 2.0);
    let fast = crystallisation_peak(Crystallisation::Nakamura, 10.0);
    println!("Tc at 2 K/min {slow:.2} °C, at 10 K/min {fast:.2} °C");
    // Faster cooling leaves less time at each temperature: the melt supercools further.
    assert!(slow - fast > 3.0, "Tc {slow} (2 K/min) vs {fast} (10 K/min)");
    // well below the melting range, where PCL crystallises in DSC (25–40 °C, docs/physics.md §5a)
    assert!(fast > 20.0 && slow < 45.0, "{fast} {slow}");
    // The rate-independent law crystallises on its melting curve at any rate.
    let eq_slow = crystallisation_peak(Crystallisation::Equilibrium, 2.0);
    let eq_fast = crystallisation_peak(Crystallisation::Equilibrium, 10.0);
    println!("equilibrium law: {eq_slow:.2} °C and {eq_fast:.2} °C");
    assert!((eq_slow - eq_fast).abs() < 0.05 && (eq_slow - 58.0).abs() < 0.1);
}

/// 10 W until the PCL reaches 60 °C, then the heater off until it has recrystallised.
fn heating_cooling_cycle(law: Crystallisation) -> (Model, Vec<(f64, f64, f64)>) {
    let p = Params { crystallisation: law, max_internal_step: 0.01, ..Params::default() };
    let mut m = Model::new(p);
    m.inputs.heater_power = 10.0;
    let h = 0.01;
    let mut trace = Vec::new();
    let mut time = 0.0;
    let xc = thermovia_model::crystallisation::ultimate_crystallinity(m.params());
    while time < 20_000.0 {
        if m.thermal.pcl_temperature >= ZERO_CELSIUS + 60.0 {
            m.inputs.heater_power = 0.0;
        }
        m.step(h).unwrap();
        time += h;
        trace.push((time, m.thermal.pcl_temperature, m.crystallinity()));
        if m.inputs.heater_power == 0.0 && m.crystallinity() > 0.99 * xc {
            break;
        }
    }
    (m, trace)
}

#[test]
fn heater_energy_is_heat_lost_plus_stored_over_a_full_cycle_latent_heat_included() {
    let start = Model::default();
    let (m, trace) = heating_cooling_cycle(Crystallisation::Nakamura);
    let p = m.params();
    let stored = m.thermal.stored_heat(p) - start.thermal.stored_heat(p);
    let residual = m.thermal.heater_energy - m.thermal.heat_lost - stored;
    let relative = residual.abs() / m.thermal.heater_energy;
    let (time, ..) = *trace.last().unwrap();
    // The latent heat went in on heating and came out on cooling: it passed through the balance.
    let peak_latent = p.pcl_mass * p.pcl_latent_heat * 0.83;
    println!(
        "cycle of {time:.0} s: heater {:.3} J, lost {:.3} J, stored {stored:.3} J, residual {residual:e} J ({relative:e}), latent now {:.3} J",
        m.thermal.heater_energy,
        m.thermal.heat_lost,
        m.thermal.latent_heat(p)
    );
    assert!(m.thermal.heater_energy > peak_latent);
    assert!(relative < 1e-6, "{relative:e}");
    // The exotherm: while crystallising, the cooling PCL warms up again.
    let min_before_rise = trace.windows(2).any(|w| w[1].2 > w[0].2 + 1e-6 && w[1].1 > w[0].1);
    assert!(min_before_rise, "no exotherm on the cooling curve");
}
