//! `cargo bench --bench exponential`: the cost of one exponential Runge–Kutta step's coefficients,
//! built afresh as a linearised friction step builds them (`EtdStep::with_link_damping`: the
//! φ-blocks' structured Taylor series at h/2, one squaring, the step's table), against the general
//! routine the blocks were taken with before 2026-12-07 (nalgebra's Padé 13 on the whole 10×10
//! augmented matrix at h/2, that alone: the former path also squared and filled the same table).
//! In the regimes a calibration meets: the paper's bench at 1 ms without friction's slope, a
//! sticking link's slope, a 5 kHz logger's step, a stiff light link, a soft PCL at 60 °C.
//! Median ns per build over EXP_BENCH_REPS repetitions (default 7) of 20 000 builds, the two
//! alternating within each repetition.

use std::hint::black_box;
use std::time::Instant;

use thermovia_model::mechanics::{
    linear_system_with, phi_augmented, Coefficients, Coupling, EtdStep, LINEARISED_DAMPING_GRID, LINK_SPEED,
};
use thermovia_model::params::ZERO_CELSIUS;
use thermovia_model::Params;

struct Case {
    label: &'static str,
    params: Params,
    celsius: f64,
    h: f64,
    /// The linearised friction's damping in units of the grid's spacing, LINEARISED_DAMPING_GRID·J_l/h.
    slope_multiple: f64,
}

fn main() {
    let reps: usize = std::env::var("EXP_BENCH_REPS").ok().and_then(|v| v.parse().ok()).unwrap_or(7).max(1);
    let bench = Params::default();
    let stiff_light = Params {
        link_inertia: 0.2 * bench.link_inertia,
        spring_stiffness: 10.0 * bench.spring_stiffness,
        ..bench.clone()
    };
    let cases = [
        Case {
            label: "paper's bench, 1 ms, no slope",
            params: bench.clone(),
            celsius: 22.0,
            h: 1e-3,
            slope_multiple: 0.0,
        },
        Case {
            label: "paper's bench, 1 ms, sticking",
            params: bench.clone(),
            celsius: 22.0,
            h: 1e-3,
            slope_multiple: 5e3,
        },
        Case {
            label: "5 kHz logger, 0.2 ms, sliding",
            params: bench.clone(),
            celsius: 40.0,
            h: 2e-4,
            slope_multiple: 8.0,
        },
        Case {
            label: "stiff light link, 1 ms, sticking",
            params: stiff_light,
            celsius: 22.0,
            h: 1e-3,
            slope_multiple: 5e3,
        },
        Case { label: "60 °C (soft PCL), 1 ms, sliding", params: bench, celsius: 60.0, h: 1e-3, slope_multiple: 8.0 },
    ];
    const BUILDS: usize = 20_000;
    println!("one step's coefficients built afresh; median of {reps} × {BUILDS} builds, ns per build");
    for case in &cases {
        let p = &case.params;
        let c = Coefficients::at(p, ZERO_CELSIUS + case.celsius);
        let damping = case.slope_multiple * LINEARISED_DAMPING_GRID * p.link_inertia / case.h;
        let (mut a, b) = linear_system_with(p, &c, Coupling::Engaged);
        a[(LINK_SPEED, LINK_SPEED)] -= p.per_link_inertia(damping);
        let augmented = phi_augmented(&a, &b, p.per_link_inertia(1.0), 0.5 * case.h);
        let (mut structured, mut general) = (Vec::new(), Vec::new());
        for _ in 0..reps {
            let start = Instant::now();
            for k in 0..BUILDS {
                // a slope that moves by a hair each build, as a sliding link's does
                let d = damping * (1.0 + 1e-12 * k as f64);
                black_box(EtdStep::with_link_damping(p, &c, black_box(case.h), Coupling::Engaged, d));
            }
            structured.push(start.elapsed().as_secs_f64() * 1e9 / BUILDS as f64);
            let start = Instant::now();
            for _ in 0..BUILDS {
                black_box(black_box(augmented).exp());
            }
            general.push(start.elapsed().as_secs_f64() * 1e9 / BUILDS as f64);
        }
        let (s, g) = (median(&mut structured), median(&mut general));
        println!("  {:<34} with_link_damping {s:7.0}   nalgebra exp alone {g:7.0}   ratio {:.2}", case.label, s / g);
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}
