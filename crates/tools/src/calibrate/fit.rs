//! Nonlinear least squares through the FMU: Levenberg–Marquardt with forward-difference Jacobians
//! (each run depends only on its temperature group's two moduli and the effect parameters, so a
//! Jacobian costs Σ_runs (2 + n_effect) simulations), and parameter covariance σ²(JᵀJ)⁻¹.

use nalgebra::{DMatrix, DVector};

use super::sim::{EffectValues, RunModel, SimInput, Simulator};

/// The effect library (names as in interfaces.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    CoulombFriction,
    Backlash,
    Gravity,
    LinkDamping,
    ThermalLag,
    FrequencyDependentModulus,
}

/// Relaxation times tried for the Maxwell branch before its own fit (its λ is not identifiable
/// while K_M = 0), s.
pub const MAXWELL_TIME_GRID: [f64; 3] = [0.03, 0.1, 0.3];

impl Effect {
    pub const ALL: [Effect; 6] = [
        Effect::CoulombFriction,
        Effect::Backlash,
        Effect::Gravity,
        Effect::LinkDamping,
        Effect::ThermalLag,
        Effect::FrequencyDependentModulus,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Effect::CoulombFriction => "coulomb_friction",
            Effect::Backlash => "backlash",
            Effect::Gravity => "gravity",
            Effect::LinkDamping => "link_damping",
            Effect::ThermalLag => "thermal_lag",
            Effect::FrequencyDependentModulus => "frequency_dependent_modulus",
        }
    }

    pub fn from_name(s: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == s)
    }

    /// Internal parameters: (name, typical size used for difference steps, lower bound).
    /// Gravity is (a, b) = m g d (cos, sin) of the offset; the Maxwell time is fitted as ln λ.
    pub fn params(self) -> &'static [(&'static str, f64, Option<f64>)] {
        match self {
            Effect::CoulombFriction => &[("torque_nm", 0.02, Some(0.0))],
            Effect::Backlash => &[("width_rad", 2e-3, Some(0.0))],
            Effect::Gravity => &[("a_nm", 0.1, None), ("b_nm", 0.1, None)],
            Effect::LinkDamping => &[("damping_nms", 0.02, Some(0.0))],
            Effect::ThermalLag => &[("time_constant_s", 0.5, Some(0.0))],
            Effect::FrequencyDependentModulus => {
                &[("stiffness_nm_per_rad", 0.5, Some(0.0)), ("ln_relaxation_time", 0.2, Some(-6.907755278982137))]
            } /* ln 1 ms */,
        }
    }

    pub fn apply(self, v: &[f64], e: &mut EffectValues) {
        match self {
            Effect::CoulombFriction => e.coulomb_friction = v[0],
            Effect::Backlash => e.backlash_width = v[0],
            Effect::Gravity => {
                e.gravity_a = v[0];
                e.gravity_b = v[1];
            }
            Effect::LinkDamping => e.link_damping = v[0],
            Effect::ThermalLag => e.thermal_lag = v[0],
            Effect::FrequencyDependentModulus => {
                e.maxwell_stiffness = v[0];
                e.maxwell_time = v[1].exp();
            }
        }
    }

    /// Nonlinear effects switch the FMU to its adaptive solver.
    pub fn is_nonlinear(self) -> bool {
        matches!(self, Effect::CoulombFriction | Effect::Backlash | Effect::Gravity)
    }
}

/// |ln| of the modulus factors: the fit keeps E', E'' within a factor 20 of the table. Beyond that
/// the sensitivity of a log-parameter vanishes and a fit that wanders there cannot come back.
pub const MODULUS_SCALE_LIMIT: f64 = 3.0;

/// The data as the fit sees it.
pub struct Problem<'a> {
    pub sim: &'a Simulator,
    pub inputs: Vec<SimInput>,
    pub measured: Vec<Vec<f64>>,
    /// Temperature group of each run (its own E', E'').
    pub group: Vec<usize>,
    pub n_groups: usize,
    pub solver_tolerance: f64,
}

/// Parameter vector: [ln s'_g, ln s''_g for each group] ++ effect parameters in `effects` order.
#[derive(Clone, Debug)]
pub struct ModelSpec {
    pub effects: Vec<Effect>,
}

impl ModelSpec {
    pub fn n_params(&self, n_groups: usize) -> usize {
        2 * n_groups + self.effects.iter().map(|e| e.params().len()).sum::<usize>()
    }
    /// (start index, effect) of each effect's parameters.
    pub fn offsets(&self, n_groups: usize) -> Vec<(usize, Effect)> {
        let mut i = 2 * n_groups;
        self.effects
            .iter()
            .map(|&e| {
                let o = i;
                i += e.params().len();
                (o, e)
            })
            .collect()
    }
    pub fn typical(&self, n_groups: usize) -> Vec<f64> {
        let mut t = vec![1.0; 2 * n_groups];
        for e in &self.effects {
            t.extend(e.params().iter().map(|p| p.1));
        }
        t
    }
    pub fn lower(&self, n_groups: usize) -> Vec<Option<f64>> {
        let mut t = vec![Some(-MODULUS_SCALE_LIMIT); 2 * n_groups];
        for e in &self.effects {
            t.extend(e.params().iter().map(|p| p.2));
        }
        t
    }
    pub fn upper(&self, n_groups: usize) -> Vec<Option<f64>> {
        let mut t = vec![Some(MODULUS_SCALE_LIMIT); 2 * n_groups];
        for e in &self.effects {
            t.extend(e.params().iter().map(|p| if p.0 == "ln_relaxation_time" { Some(10f64.ln()) } else { None }));
        }
        t
    }
    pub fn names(&self, group_names: &[String]) -> Vec<String> {
        let mut v = Vec::new();
        for g in group_names {
            v.push(format!("ln_storage_scale[{g}]"));
            v.push(format!("ln_loss_scale[{g}]"));
        }
        for e in &self.effects {
            v.extend(e.params().iter().map(|p| format!("{}.{}", e.name(), p.0)));
        }
        v
    }
}

impl<'a> Problem<'a> {
    pub fn n_samples(&self) -> usize {
        self.measured.iter().map(|m| m.len()).sum()
    }

    pub fn run_model(&self, spec: &ModelSpec, p: &[f64], run: usize) -> RunModel {
        let g = self.group[run];
        let mut e = EffectValues::default();
        for (o, eff) in spec.offsets(self.n_groups) {
            eff.apply(&p[o..o + eff.params().len()], &mut e);
        }
        RunModel {
            storage_scale: p[2 * g].exp(),
            loss_scale: p[2 * g + 1].exp(),
            effects: e,
            solver_tolerance: self.solver_tolerance,
        }
    }

    /// Indices of the parameters run `r` depends on.
    pub fn local_params(&self, spec: &ModelSpec, run: usize) -> Vec<usize> {
        let g = self.group[run];
        let mut v = vec![2 * g, 2 * g + 1];
        v.extend(2 * self.n_groups..spec.n_params(self.n_groups));
        v
    }

    /// Model outputs of every run at `p` (None when a simulation fails).
    pub fn outputs(&self, spec: &ModelSpec, p: &[f64]) -> Option<Vec<Vec<f64>>> {
        let jobs: Vec<_> = (0..self.inputs.len()).map(|r| (r, self.run_model(spec, p, r))).collect();
        self.sim.run_jobs(&self.inputs, &jobs).into_iter().collect::<Result<Vec<_>, _>>().ok()
    }

    /// Residual y − ŷ of every run, flattened.
    pub fn residual(&self, out: &[Vec<f64>]) -> Vec<f64> {
        self.measured.iter().zip(out).flat_map(|(y, m)| y.iter().zip(m).map(|(a, b)| a - b)).collect()
    }

    /// ∂ŷ/∂p by forward differences (only local columns are simulated; others are zero).
    pub fn jacobian(&self, spec: &ModelSpec, p: &[f64], base: &[Vec<f64>]) -> Option<DMatrix<f64>> {
        // forward steps (backward at an upper bound), so every trial stays inside the bounds
        let typical = spec.typical(self.n_groups);
        let upper = spec.upper(self.n_groups);
        let mut jobs = Vec::new();
        let mut meta = Vec::new();
        for r in 0..self.inputs.len() {
            for j in self.local_params(spec, r) {
                let mut q = p.to_vec();
                let mut h = 1e-3 * typical[j].max(p[j].abs());
                if upper[j].is_some_and(|u| p[j] + h > u) {
                    h = -h;
                }
                q[j] += h;
                jobs.push((r, self.run_model(spec, &q, r)));
                meta.push((r, j, h));
            }
        }
        let res = self.sim.run_jobs(&self.inputs, &jobs);
        let offsets: Vec<usize> = self
            .measured
            .iter()
            .scan(0, |s, m| {
                let o = *s;
                *s += m.len();
                Some(o)
            })
            .collect();
        let mut jac = DMatrix::zeros(self.n_samples(), p.len());
        for ((r, j, h), out) in meta.into_iter().zip(res) {
            let out = out.ok()?;
            for (k, (a, b)) in out.iter().zip(&base[r]).enumerate() {
                jac[(offsets[r] + k, j)] = (a - b) / h;
            }
        }
        Some(jac)
    }
}

/// A fitted model.
#[derive(Clone, Debug)]
pub struct Fit {
    pub spec: ModelSpec,
    pub p: Vec<f64>,
    pub outputs: Vec<Vec<f64>>,
    pub residual: Vec<f64>,
    pub sse: f64,
    pub n: usize,
    /// Jacobian at (or one small step before) the optimum.
    pub jacobian: DMatrix<f64>,
    pub covariance: DMatrix<f64>,
    pub iterations: usize,
}

impl Fit {
    pub fn rmse(&self) -> f64 {
        (self.sse / self.n as f64).sqrt()
    }
    /// Bayesian information criterion for Gaussian errors: N ln(SSE/N) + k ln N.
    pub fn bic(&self) -> f64 {
        let n = self.n as f64;
        n * (self.sse / n).ln() + self.p.len() as f64 * n.ln()
    }
    pub fn std_err(&self, j: usize) -> f64 {
        self.covariance[(j, j)].max(0.0).sqrt()
    }
}

fn sse(r: &[f64]) -> f64 {
    r.iter().map(|x| x * x).sum()
}

/// A with its diagonal scaled to one, S = D⁻¹ A D⁻¹, and D: keeps the normal equations'
/// conditioning independent of the parameters' units.
fn diagonally_scaled(a: &DMatrix<f64>) -> (DMatrix<f64>, Vec<f64>) {
    let n = a.nrows();
    let d: Vec<f64> = (0..n).map(|i| a[(i, i)].max(1e-300).sqrt()).collect();
    (DMatrix::from_fn(n, n, |i, j| a[(i, j)] / (d[i] * d[j])), d)
}

/// Solves (A + μ diag A) δ = g with column scaling; falls back to a pseudo-inverse.
fn lm_solve(a: &DMatrix<f64>, g: &DVector<f64>, mu: f64) -> DVector<f64> {
    let n = a.nrows();
    let (mut s, d) = diagonally_scaled(a);
    for i in 0..n {
        s[(i, i)] += mu;
    }
    let rhs = DVector::from_iterator(n, (0..n).map(|i| g[i] / d[i]));
    let x = match s.clone().cholesky() {
        Some(c) => c.solve(&rhs),
        None => s.svd(true, true).solve(&rhs, 1e-12).unwrap_or_else(|_| DVector::zeros(n)),
    };
    DVector::from_iterator(n, (0..n).map(|i| x[i] / d[i]))
}

/// Pseudo-inverse of a symmetric positive semi-definite matrix with diagonal scaling.
pub fn spd_inverse(a: &DMatrix<f64>) -> DMatrix<f64> {
    let n = a.nrows();
    let (s, d) = diagonally_scaled(a);
    let inv = s.pseudo_inverse(1e-12).unwrap_or_else(|_| DMatrix::zeros(n, n));
    DMatrix::from_fn(n, n, |i, j| inv[(i, j)] / (d[i] * d[j]))
}

/// Levenberg–Marquardt from `p0`.
/// ∂ŷ/∂p at p, given the model's evaluation there (None when a difference step fails).
pub type JacobianFn<'f, S> = dyn Fn(&[f64], &S) -> Option<DMatrix<f64>> + 'f;

/// What Levenberg–Marquardt needs of a least-squares problem whose model is simulated: `S` is
/// one evaluation's simulation output (shared by the device and the drive loops).
pub struct LeastSquares<'f, S> {
    /// The model at p (None when a simulation fails: the step is rejected).
    pub simulate: &'f dyn Fn(&[f64]) -> Option<S>,
    /// y − ŷ of an evaluation, flattened.
    pub residual: &'f dyn Fn(&S) -> Vec<f64>,
    /// ∂ŷ/∂p at p, given the evaluation there.
    pub jacobian: &'f JacobianFn<'f, S>,
    /// Projects p onto the parameters' bounds.
    pub clamp: &'f dyn Fn(&mut [f64]),
    /// Whether a move of parameter j from `old` to `new` is negligible.
    pub negligible: &'f dyn Fn(usize, f64, f64) -> bool,
    /// Converged when an accepted step lowers the cost by less than this fraction.
    pub relative_tolerance: f64,
}

/// The optimum Levenberg–Marquardt reached, with the Jacobian there (for the covariance).
pub struct Minimum<S> {
    pub p: Vec<f64>,
    pub simulated: S,
    pub residual: Vec<f64>,
    pub cost: f64,
    pub jacobian: DMatrix<f64>,
    pub iterations: usize,
}

/// Levenberg–Marquardt with a diagonally scaled damping μ (÷3 after a success, ×5 after a
/// failure, 8 tries per iteration): stops when no try lowers the cost, or an accepted step is
/// negligible in every parameter or in the cost.
pub fn minimize<S>(ls: &LeastSquares<S>, p0: Vec<f64>, max_iter: usize) -> Result<Minimum<S>, String> {
    let mut p = p0;
    (ls.clamp)(&mut p);
    let mut simulated = (ls.simulate)(&p).ok_or("the FMU could not simulate the starting model")?;
    let mut r = (ls.residual)(&simulated);
    let mut cost = sse(&r);
    let mut mu = 1e-3;
    let mut jac = DMatrix::zeros(0, 0);
    let mut iterations = 0;
    for it in 0..max_iter {
        iterations = it + 1;
        jac = (ls.jacobian)(&p, &simulated).ok_or("the FMU could not simulate a difference step")?;
        let a = jac.transpose() * &jac;
        let g = jac.transpose() * DVector::from_column_slice(&r);
        let mut improved = false;
        let mut converged = false;
        for _ in 0..8 {
            let delta = lm_solve(&a, &g, mu);
            let mut q: Vec<f64> = p.iter().zip(delta.iter()).map(|(a, b)| a + b).collect();
            (ls.clamp)(&mut q);
            let small = q.iter().zip(&p).enumerate().all(|(j, (new, old))| (ls.negligible)(j, *old, *new));
            if let Some(out) = (ls.simulate)(&q) {
                let rq = (ls.residual)(&out);
                let cq = sse(&rq);
                if cq < cost {
                    converged = small || (cost - cq) / cost < ls.relative_tolerance;
                    (p, simulated, r, cost) = (q, out, rq, cq);
                    mu = (mu / 3.0).max(1e-9);
                    improved = true;
                    break;
                }
            }
            if small {
                converged = true;
                break;
            }
            mu *= 5.0;
        }
        if !improved || converged {
            break;
        }
    }
    Ok(Minimum { p, simulated, residual: r, cost, jacobian: jac, iterations })
}

pub fn levenberg_marquardt(prob: &Problem, spec: ModelSpec, p0: Vec<f64>, max_iter: usize) -> Result<Fit, String> {
    let lower = spec.lower(prob.n_groups);
    let upper = spec.upper(prob.n_groups);
    let typical = spec.typical(prob.n_groups);
    let clamp = |p: &mut [f64]| {
        for ((x, lo), hi) in p.iter_mut().zip(&lower).zip(&upper) {
            if let Some(b) = lo {
                *x = x.max(*b);
            }
            if let Some(b) = hi {
                *x = x.min(*b);
            }
        }
    };
    let m = minimize(
        &LeastSquares {
            simulate: &|p| prob.outputs(&spec, p),
            residual: &|out| prob.residual(out),
            jacobian: &|p, out| prob.jacobian(&spec, p, out),
            clamp: &clamp,
            negligible: &|j, old, new| (new - old).abs() <= 1e-6 * typical[j].max(old.abs()),
            relative_tolerance: 1e-7,
        },
        p0,
        max_iter,
    )?;
    let n = m.residual.len();
    let a = m.jacobian.transpose() * &m.jacobian;
    let sigma2 = m.cost / (n.saturating_sub(m.p.len()).max(1)) as f64;
    let covariance = spd_inverse(&a) * sigma2;
    Ok(Fit {
        spec,
        p: m.p,
        outputs: m.simulated,
        residual: m.residual,
        sse: m.cost,
        n,
        jacobian: m.jacobian,
        covariance,
        iterations: m.iterations,
    })
}
