//! The PCL's causal viscoelastic law (issue 20, item 3; docs/physics.md §5c).
//!
//! A generalised Maxwell (Prony) solid has the complex modulus
//!
//!   E*(ω) = E_∞ + iωη + Σ_k E_k iωλ_k / (1 + iωλ_k),   E_∞, η, E_k ≥ 0 (passive: it never gives energy back)
//!
//! Every branch's storage modulus E_k (ωλ)²/(1 + (ωλ)²) rises with ω, and a branch's loss falls with
//! ω only where ωλ > 1/√2, where its storage is at least half its loss. The hysteretic law of the
//! material table has E′ and E″ independent of frequency, with E″ up to 3× E′ (50 °C); no
//! non-negative Prony series matches that at two frequencies an octave apart. [`fit`] finds the
//! best one over a log grid of relaxation times (non-negative least squares on the relative errors)
//! so that the shortfall is measured, not argued; [`PronyLaw`] is the law the FMU runs with
//! `viscoelastic_law` = 1: a spring, a dashpot and one branch per table row, as good as that optimum.

use nalgebra::{DMatrix, DVector};

/// A fitted Prony series: E_∞ and (E_k, λ_k), Pa and s.
#[derive(Clone, Debug)]
pub struct PronySeries {
    pub e_inf: f64,
    /// A dashpot in parallel (the limit λ → 0 of a branch with E λ fixed), Pa·s.
    pub viscosity: f64,
    pub branches: Vec<(f64, f64)>,
}

impl PronySeries {
    /// (E′, E″) at angular frequency ω, Pa.
    pub fn complex_modulus(&self, omega: f64) -> (f64, f64) {
        self.branches.iter().fold((self.e_inf, omega * self.viscosity), |(s, l), &(e, lam)| {
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
    // columns: E_∞, η, then one per relaxation time
    let (m, n) = (2 * targets.len(), lambdas.len() + 2);
    let mut a = DMatrix::<f64>::zeros(m, n);
    for (i, &(w, e1, e2)) in targets.iter().enumerate() {
        a[(2 * i, 0)] = 1.0 / e1;
        a[(2 * i + 1, 1)] = w / e2;
        for (j, &lam) in lambdas.iter().enumerate() {
            let x = w * lam;
            let d = 1.0 + x * x;
            a[(2 * i, j + 2)] = x * x / d / e1;
            a[(2 * i + 1, j + 2)] = x / d / e2;
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
        viscosity: x[1],
        branches: lambdas.iter().enumerate().filter(|(j, _)| x[j + 2] > 0.0).map(|(j, &l)| (x[j + 2], l)).collect(),
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

/// The paper's two excitation frequencies, Hz [PAPER]: the transient law is fitted at both.
pub const FIT_FREQUENCIES_HZ: [f64; 2] = [0.5, 1.0];

/// One table row of the transient law: E*(ω) = E_∞ + iωη + E_1 iωλ/(1 + iωλ), all ≥ 0 (a spring,
/// a dashpot and one Maxwell branch in parallel: a Prony series with a viscous term).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PronyRow {
    /// E_∞, Pa.
    pub e_inf: f64,
    /// η, Pa·s.
    pub viscosity: f64,
    /// E_1, Pa.
    pub e_branch: f64,
}

/// The causal law the FMU uses with `viscoelastic_law` = 1 (docs/physics.md §5c): per row of the
/// material table, the non-negative [`PronyRow`] closest (least squares of the four relative errors)
/// to the table's E′, E″ at 0.5 and 1 Hz, with one relaxation time λ shared by every row.
///
/// One branch, because the best non-negative series over 81 relaxation times does no better
/// (`one_branch_and_a_dashpot_are_as_good_as_any_passive_series`). λ shared, because the rows'
/// own optima lie within 0.58–0.72 s and a shared λ keeps the state's meaning fixed while the PCL
/// heats; the temperature dependence is in the row moduli, interpolated between rows.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PronyLaw {
    /// λ, s.
    pub relaxation_time: f64,
    pub rows: [PronyRow; 4],
}

impl PronyRow {
    /// (E′, E″) at angular frequency ω with relaxation time λ, Pa.
    pub fn complex_modulus(&self, lambda: f64, omega: f64) -> (f64, f64) {
        let x = omega * lambda;
        let d = 1.0 + x * x;
        (self.e_inf + self.e_branch * x * x / d, omega * self.viscosity + self.e_branch * x / d)
    }
}

impl PronyLaw {
    /// Fits the law to table rows (E′, E″), Pa.
    pub fn fit(storage: [f64; 4], loss: [f64; 4]) -> Self {
        let cost = |lambda: f64| -> f64 { (0..4).map(|i| fit_row(storage[i], loss[i], lambda).1).sum() };
        // a grid of 24 per decade over 1e-4…1e4 s, then golden-section search between the best
        // point's neighbours
        let grid: Vec<f64> = (0..=192).map(|i| -4.0 + i as f64 / 24.0).collect();
        // each point's cost once (a comparator would evaluate both sides at every comparison);
        // the first of equal minima, as `min_by` gives
        let costs: Vec<f64> = grid.iter().map(|&x| cost(10f64.powf(x))).collect();
        let best = (1..grid.len()).fold(0, |b, i| if costs[i].total_cmp(&costs[b]).is_lt() { i } else { b });
        let (mut lo, mut hi) = (grid[best.saturating_sub(1)], grid[(best + 1).min(grid.len() - 1)]);
        let g = 0.5 * (5f64.sqrt() - 1.0);
        for _ in 0..60 {
            let (a, b) = (hi - g * (hi - lo), lo + g * (hi - lo));
            if cost(10f64.powf(a)) <= cost(10f64.powf(b)) {
                hi = b;
            } else {
                lo = a;
            }
        }
        let lambda = 10f64.powf(0.5 * (lo + hi));
        let lambda = if cost(lambda) <= costs[best] { lambda } else { 10f64.powf(grid[best]) };
        PronyLaw { relaxation_time: lambda, rows: std::array::from_fn(|i| fit_row(storage[i], loss[i], lambda).0) }
    }

    /// The row moduli at `temperature_c`: between rows each coefficient geometrically (as the table
    /// interpolates log E), linearly where one end is 0; held at the end rows outside 22–60 °C.
    pub fn at(&self, temperature_c: f64) -> PronyRow {
        let ts = &crate::material::TABLE_TEMPERATURES_C;
        if temperature_c <= ts[0] {
            return self.rows[0];
        }
        if temperature_c >= ts[3] {
            return self.rows[3];
        }
        let i = (0..3).find(|&i| temperature_c <= ts[i + 1]).unwrap_or(2);
        let w = (temperature_c - ts[i]) / (ts[i + 1] - ts[i]);
        let mix = |a: f64, b: f64| {
            if a > 0.0 && b > 0.0 {
                (a.ln() * (1.0 - w) + b.ln() * w).exp()
            } else {
                a * (1.0 - w) + b * w
            }
        };
        let (a, b) = (&self.rows[i], &self.rows[i + 1]);
        PronyRow {
            e_inf: mix(a.e_inf, b.e_inf),
            viscosity: mix(a.viscosity, b.viscosity),
            e_branch: mix(a.e_branch, b.e_branch),
        }
    }
}

/// The non-negative (E_∞, η, E_1) at relaxation time λ whose E′, E″ at [`FIT_FREQUENCIES_HZ`] are
/// closest to (E′, E″) in relative least squares, and the sum of squared relative errors. Three
/// unknowns: every active set is tried (the best feasible one is the non-negative optimum).
fn fit_row(storage: f64, loss: f64, lambda: f64) -> (PronyRow, f64) {
    let floor = 1e-12 * storage.abs().max(loss.abs()).max(1e-300);
    let (s, l) = (storage.abs().max(floor), loss.abs().max(floor));
    let mut a = [[0.0; 3]; 4];
    let mut b = [0.0; 4];
    for (k, f) in FIT_FREQUENCIES_HZ.iter().enumerate() {
        let w = 2.0 * std::f64::consts::PI * f;
        let x = w * lambda;
        let d = 1.0 + x * x;
        a[2 * k] = [1.0 / s, 0.0, x * x / d / s];
        a[2 * k + 1] = [0.0, w / l, x / d / l];
        b[2 * k] = storage / s;
        b[2 * k + 1] = loss / l;
    }
    let residual = |c: &[f64; 3]| -> f64 {
        (0..4).map(|r| (a[r][0] * c[0] + a[r][1] * c[1] + a[r][2] * c[2] - b[r]).powi(2)).sum()
    };
    let mut best = ([0.0; 3], residual(&[0.0; 3]));
    for set in 1u8..8 {
        let cols: Vec<usize> = (0..3).filter(|j| set & (1 << j) != 0).collect();
        let n = cols.len();
        // normal equations on the active columns
        let mut m = [[0.0; 4]; 3];
        for (p, &i) in cols.iter().enumerate() {
            for (q, &j) in cols.iter().enumerate() {
                m[p][q] = (0..4).map(|r| a[r][i] * a[r][j]).sum();
            }
            m[p][n] = (0..4).map(|r| a[r][i] * b[r]).sum();
        }
        let Some(z) = solve_small(&mut m, n) else { continue };
        let mut c = [0.0; 3];
        for (p, &j) in cols.iter().enumerate() {
            c[j] = z[p];
        }
        if c.iter().all(|v| *v >= 0.0) {
            let r = residual(&c);
            if r < best.1 {
                best = (c, r);
            }
        }
    }
    let [e_inf, viscosity, e_branch] = best.0;
    (PronyRow { e_inf, viscosity, e_branch }, best.1)
}

/// Gaussian elimination with partial pivoting on an n×(n+1) augmented system (n ≤ 3); None when singular.
fn solve_small(m: &mut [[f64; 4]; 3], n: usize) -> Option<[f64; 3]> {
    for k in 0..n {
        let p = (k..n).max_by(|&i, &j| m[i][k].abs().total_cmp(&m[j][k].abs()))?;
        m.swap(k, p);
        if m[k][k].abs() < 1e-300 {
            return None;
        }
        let pivot = m[k];
        for row in m.iter_mut().take(n).skip(k + 1) {
            let f = row[k] / pivot[k];
            for (a, b) in row[k..=n].iter_mut().zip(&pivot[k..=n]) {
                *a -= f * b;
            }
        }
    }
    let mut x = [0.0; 3];
    for k in (0..n).rev() {
        let s: f64 = (k + 1..n).map(|j| m[k][j] * x[j]).sum();
        x[k] = (m[k][n] - s) / m[k][k];
    }
    x.iter().take(n).all(|v| v.is_finite()).then_some(x)
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
        let truth = PronySeries { e_inf: 3e5, viscosity: 2e3, branches: vec![(5e5, 0.01), (8e5, 0.1), (2e5, 1.0)] };
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

    /// The FMU's law (one branch, a dashpot, a spring; one λ for every row) against the best
    /// non-negative series with a dashpot over 81 relaxation times, row by row of the default
    /// table: its root-mean-square relative error is within 10 % of that optimum's (printed; the
    /// values are in docs/physics.md §5c), and, as no passive law can, above 1 %.
    #[test]
    fn one_branch_and_a_dashpot_are_as_good_as_any_passive_series() {
        let (e1, e2) = MaterialTable::RepairedExperimental.rows_kpa();
        let law = PronyLaw::fit(e1.map(|e| e * 1e3), e2.map(|e| e * 1e3));
        println!("λ = {:.4} s", law.relaxation_time);
        for (i, &t) in TABLE_TEMPERATURES_C.iter().enumerate() {
            let (s, l) = (e1[i] * 1e3, e2[i] * 1e3);
            let targets = [(TWO_PI * 0.5, s, l), (TWO_PI * 1.0, s, l)];
            let rms = |e: &[f64]| (e.iter().map(|e| e * e).sum::<f64>() / e.len() as f64).sqrt();
            let optimum = rms(&relative_errors(&fit(&targets, &log_grid(-4.0, 4.0, 81)), &targets));
            let row = law.at(t);
            let errors: Vec<f64> = targets
                .iter()
                .flat_map(|&(w, s, l)| {
                    let (fs, fl) = row.complex_modulus(law.relaxation_time, w);
                    [fs / s - 1.0, fl / l - 1.0]
                })
                .collect();
            println!(
                "{t} °C: {row:?}; errors {:?} %, rms {:.2} % (81 branches: {:.2} %)",
                errors.iter().map(|e| (e * 1000.0).round() / 10.0).collect::<Vec<_>>(),
                100.0 * rms(&errors),
                100.0 * optimum
            );
            assert!(rms(&errors) <= 1.1 * optimum, "{t} °C: {} against {optimum}", rms(&errors));
            assert!(rms(&errors) > 0.01, "{t} °C");
            assert!(row.e_inf >= 0.0 && row.viscosity >= 0.0 && row.e_branch >= 0.0, "{t} °C: {row:?}");
        }
    }
}
