//! Can a causal, passive viscoelastic law reproduce the material table's moduli at 0.5 and 1 Hz?
//! (issue 20, item 3; docs/physics.md §5c)
//!
//! A generalised Maxwell (Prony) solid has the complex modulus
//!
//!   E*(ω) = E_∞ + Σ_k E_k iωλ_k / (1 + iωλ_k),   E_∞, E_k ≥ 0 (passive: it never gives energy back)
//!
//! Every branch's storage modulus E_k (ωλ)²/(1 + (ωλ)²) rises with ω, and a branch's loss falls with
//! ω only where ωλ > 1/√2, where its storage is at least half its loss. The hysteretic law of the
//! material table has E′ and E″ independent of frequency, with E″ up to 3× E′ (50 °C); no
//! non-negative Prony series matches that at two frequencies an octave apart. This module fits the
//! best one (non-negative least squares over a log grid of relaxation times, on the relative errors
//! at the given frequencies) so that the shortfall is measured, not argued.

use nalgebra::{DMatrix, DVector};

/// A fitted Prony series: E_∞ and (E_k, λ_k), Pa and s.
#[derive(Clone, Debug)]
pub struct PronySeries {
    pub e_inf: f64,
    pub branches: Vec<(f64, f64)>,
}

impl PronySeries {
    /// (E′, E″) at angular frequency ω, Pa.
    pub fn complex_modulus(&self, omega: f64) -> (f64, f64) {
        self.branches.iter().fold((self.e_inf, 0.0), |(s, l), &(e, lam)| {
            let x = omega * lam;
            let d = 1.0 + x * x;
            (s + e * x * x / d, l + e * x / d)
        })
    }
}

/// Relaxation times 10^(a + (b − a) i/(n − 1)) s.
pub fn log_grid(a: f64, b: f64, n: usize) -> Vec<f64> {
    (0..n).map(|i| 10f64.powf(a + (b - a) * i as f64 / (n - 1) as f64)).collect()
}

/// The non-negative Prony series over `lambdas` (plus E_∞) that minimises the sum of squared
/// relative errors of E′ and E″ against `targets` = [(ω, E′, E″)].
pub fn fit(targets: &[(f64, f64, f64)], lambdas: &[f64]) -> PronySeries {
    fit_weighted(targets, lambdas, &vec![1.0; 2 * targets.len()])
}

/// The non-negative Prony series whose largest relative error is least (minimax), by Lawson's
/// iteratively reweighted least squares (each equation's weight times its error, normalised);
/// returns it with that error.
pub fn fit_minimax(targets: &[(f64, f64, f64)], lambdas: &[f64], iterations: usize) -> (PronySeries, f64) {
    let mut weights = vec![1.0 / (2 * targets.len()) as f64; 2 * targets.len()];
    let mut best: Option<(PronySeries, f64)> = None;
    for _ in 0..iterations {
        let series = fit_weighted(targets, lambdas, &weights);
        let errors = relative_errors(&series, targets);
        let worst = errors.iter().fold(0.0_f64, |a, e| a.max(e.abs()));
        if best.as_ref().is_none_or(|(_, b)| worst < *b) {
            best = Some((series, worst));
        }
        for (w, e) in weights.iter_mut().zip(&errors) {
            *w *= e.abs().max(1e-300);
        }
        let total: f64 = weights.iter().sum();
        weights.iter_mut().for_each(|w| *w /= total);
    }
    best.expect("at least one iteration")
}

/// E′ and E″ relative errors at each target, in order.
pub fn relative_errors(series: &PronySeries, targets: &[(f64, f64, f64)]) -> Vec<f64> {
    targets
        .iter()
        .flat_map(|&(w, s, l)| {
            let (fs, fl) = series.complex_modulus(w);
            [fs / s - 1.0, fl / l - 1.0]
        })
        .collect()
}

fn fit_weighted(targets: &[(f64, f64, f64)], lambdas: &[f64], weights: &[f64]) -> PronySeries {
    let (m, n) = (2 * targets.len(), lambdas.len() + 1);
    let mut a = DMatrix::<f64>::zeros(m, n);
    for (i, &(w, e1, e2)) in targets.iter().enumerate() {
        a[(2 * i, 0)] = 1.0 / e1;
        for (j, &lam) in lambdas.iter().enumerate() {
            let x = w * lam;
            let d = 1.0 + x * x;
            a[(2 * i, j + 1)] = x * x / d / e1;
            a[(2 * i + 1, j + 1)] = x / d / e2;
        }
    }
    for (i, w) in weights.iter().enumerate() {
        let r = w.sqrt();
        a.row_mut(i).scale_mut(r);
    }
    let b = DVector::from_iterator(m, weights.iter().map(|w| w.sqrt()));
    let x = nnls(&a, &b);
    PronySeries {
        e_inf: x[0],
        branches: lambdas.iter().enumerate().filter(|(j, _)| x[j + 1] > 0.0).map(|(j, &l)| (x[j + 1], l)).collect(),
    }
}

/// Lawson and Hanson's active-set non-negative least squares: min |A x − b|, x ≥ 0.
pub fn nnls(a: &DMatrix<f64>, b: &DVector<f64>) -> DVector<f64> {
    let n = a.ncols();
    let mut x = DVector::<f64>::zeros(n);
    let mut passive = vec![false; n];
    let scale = a.abs().max().max(1e-300) * b.abs().max().max(1e-300);
    for _ in 0..3 * n {
        let w = a.transpose() * (b - a * &x);
        let candidate = (0..n).filter(|&j| !passive[j]).max_by(|&i, &j| w[i].total_cmp(&w[j]));
        match candidate {
            Some(j) if w[j] > 1e-12 * scale => passive[j] = true,
            _ => break,
        }
        loop {
            let cols: Vec<usize> = (0..n).filter(|&j| passive[j]).collect();
            let ap = a.select_columns(&cols);
            let zp = ap.clone().svd(true, true).solve(b, 1e-14).expect("SVD was asked for U and V");
            let mut z = DVector::<f64>::zeros(n);
            for (k, &j) in cols.iter().enumerate() {
                z[j] = zp[k];
            }
            if cols.iter().all(|&j| z[j] > 0.0) {
                x = z;
                break;
            }
            // step from x towards z until the first passive variable reaches 0, drop it
            let alpha =
                cols.iter().filter(|&&j| z[j] <= 0.0).map(|&j| x[j] / (x[j] - z[j])).fold(f64::INFINITY, f64::min);
            x += (z - &x) * alpha;
            for &j in &cols {
                if x[j] <= 1e-15 * scale {
                    passive[j] = false;
                    x[j] = 0.0;
                }
            }
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::{MaterialTable, TABLE_TEMPERATURES_C};

    const TWO_PI: f64 = 2.0 * std::f64::consts::PI;

    /// The fitter recovers a causal target: the moduli of a known three-branch series at four
    /// frequencies are met to 1e-9 (so the shortfall below is the law's, not the fitter's).
    #[test]
    fn nnls_fit_reproduces_the_moduli_of_a_prony_series() {
        let truth = PronySeries { e_inf: 3e5, branches: vec![(5e5, 0.01), (8e5, 0.1), (2e5, 1.0)] };
        let targets: Vec<(f64, f64, f64)> = [0.25, 0.5, 1.0, 2.0]
            .iter()
            .map(|f| {
                let (s, l) = truth.complex_modulus(TWO_PI * f);
                (TWO_PI * f, s, l)
            })
            .collect();
        let fitted = fit(&targets, &log_grid(-3.0, 1.0, 41));
        for &(w, s, l) in &targets {
            let (fs, fl) = fitted.complex_modulus(w);
            assert!((fs / s - 1.0).abs() < 1e-9 && (fl / l - 1.0).abs() < 1e-9, "{fs} {s} {fl} {l}");
        }
    }

    /// Issue 20 asked for a Prony law matching the table's E′, E″ at 0.5 and 1 Hz to 1 % at every
    /// table temperature. The table's moduli do not depend on frequency (hysteretic loss). Over
    /// λ = 1e-4…1e4 s every non-negative Prony series misses them by more than 1 % at every row: its
    /// largest relative error is at least its root-mean-square error, which is at least the
    /// least-squares optimum's (asserted > 1 %). The minimax fit (reweighting, printed with the
    /// least-squares one; values in docs/physics.md §5c) must respect the same bound.
    #[test]
    fn no_passive_prony_series_matches_frequency_independent_moduli_an_octave_apart() {
        let lambdas = log_grid(-4.0, 4.0, 81);
        let (e1, e2) = MaterialTable::RepairedExperimental.rows_kpa();
        for (i, &t) in TABLE_TEMPERATURES_C.iter().enumerate() {
            let (s, l) = (e1[i] * 1e3, e2[i] * 1e3);
            let targets = [(TWO_PI * 0.5, s, l), (TWO_PI * 1.0, s, l)];
            let ls = relative_errors(&fit(&targets, &lambdas), &targets);
            let rms = (ls.iter().map(|e| e * e).sum::<f64>() / 4.0).sqrt();
            let (minimax, worst) = fit_minimax(&targets, &lambdas, 200);
            let pct = |v: &[f64]| v.iter().map(|e| (e * 1000.0).round() / 10.0).collect::<Vec<_>>();
            println!(
                "{t} °C: tan δ {:.2}; least squares {:?} % (rms {:.1} %); minimax {:?} % ({} branches)",
                l / s,
                pct(&ls),
                100.0 * rms,
                pct(&relative_errors(&minimax, &targets)),
                minimax.branches.len()
            );
            assert!(rms > 0.01, "{t} °C: rms {rms}");
            assert!(worst >= rms * (1.0 - 1e-9), "{t} °C: minimax {worst} below the bound {rms}");
        }
    }
}
