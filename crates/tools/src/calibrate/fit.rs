//! Nonlinear least squares through the FMU: Levenberg–Marquardt with forward-difference Jacobians
//! (each run depends only on its temperature group's two moduli and the effect parameters, so a
//! Jacobian costs Σ_runs (2 + n_effect) simulations), and parameter covariance σ²(JᵀJ)⁻¹.

use super::signal::smooth;
use nalgebra::{DMatrix, DVector};

use super::sim::{EffectValues, RunModel, SimInput, Simulator, TransmissionTable, STANDARD_GRAVITY};

/// The effect library (names as in interfaces.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    CoulombFriction,
    Backlash,
    Gravity,
    LinkDamping,
    ThermalLag,
    FrequencyDependentModulus,
    /// Static friction above Coulomb that fades with speed (Modelica BearingFriction's Stribeck
    /// curve): (Fs, v_s), on top of `CoulombFriction` when that is in.
    StribeckFriction,
    /// Coulomb and viscous levels per direction: half-differences (a_c, a_v) added to
    /// `CoulombFriction` and `LinkDamping` (reported as the four levels).
    AsymmetricFriction,
    /// A constant torque on the link (a payload offset, a cable, a biased sensor zero).
    ConstantLoad,
}

/// A stiffness within this factor of its bound is near it (`Problem::stiffness_near_bound`):
/// a natural frequency within a factor 2.
pub const NEAR_BOUND: f64 = 4.0;

/// Whether the log-parameter `x` sits on the bound `lo` or `hi` (not logs).
pub(crate) fn on_bound(x: f64, lo: f64, hi: f64) -> bool {
    x <= lo.ln() + 1e-9 || x >= hi.ln() - 1e-9
}

/// The loss factor C·ω/K above which a transmission drags the link through its damper
/// ([`Problem::transmission_dragging`]): half again the largest of the PCL table's (1.9, at
/// 50 °C; 0.3–1.6 at 22, 40 and 60 °C), where a fitted transmission has left the material's
/// behaviour behind. The campaign's rigs that pass end at 0.6 or less; their baselines reach 3e3.
pub const DRAGGING_LOSS_FACTOR: f64 = 3.0;

/// Relaxation times tried for the Maxwell branch before its own fit (its λ is not identifiable
/// while K_M = 0), s.
pub const MAXWELL_TIME_GRID: [f64; 3] = [0.03, 0.1, 0.3];

/// Effects the equation error can estimate (the rest need a simulation): those whose torque on the
/// link is linear in their parameters, as regressors, and backlash, whose width is profiled (for a
/// given width the transmission's torque is linear in K and C again).
pub const EQUATION_ERROR_EFFECTS: [Effect; 6] = [
    Effect::Gravity,
    Effect::CoulombFriction,
    Effect::LinkDamping,
    Effect::ConstantLoad,
    Effect::AsymmetricFriction,
    Effect::Backlash,
];

/// One sample of the equation error: the smoothed link angle, relative angle φ = θm − θl and its
/// rate, the link speed, the inertial torque J θl'', and the damping column's weight w.
struct EquationSample {
    group: usize,
    w: f64,
    angle: f64,
    phi: f64,
    dphi: f64,
    v: f64,
    inertial: f64,
}

/// What the runs can show of a torque on the link (`Problem::torque_scale`).
#[derive(Clone, Copy, Debug)]
pub struct TorqueScale {
    pub transmission_nm: f64,
    pub inertial_nm: f64,
    pub speed: f64,
    pub relative_angle: f64,
}

/// An effect's torque on the link may reach this multiple of the largest transmission plus inertial
/// torque the runs show (`Problem::plausible_limits`): a loose physical bound, not a prior.
pub const PLAUSIBLE_TORQUE_FACTOR: f64 = 2.0;

/// Regression columns an equation-error effect takes (a profiled width takes none).
pub fn regressor_columns(e: Effect) -> usize {
    if e == Effect::Backlash {
        0
    } else {
        e.params().len()
    }
}

/// Points of the coarse backlash-width grid of the equation error, log-spaced over fractions of the
/// largest relative angle the runs show (`Problem::backlash_width_grid`).
pub const BACKLASH_GRID_POINTS: usize = 12;
/// Golden-section steps that refine the best grid width between its neighbours.
pub const BACKLASH_REFINE_STEPS: usize = 10;

/// One equation-error regression (`Problem::equation_error`).
#[derive(Clone, Debug)]
pub struct EquationError {
    /// [ln K, ln C per group] ++ the effects' parameters.
    pub p: Vec<f64>,
    /// Groups whose K or C came out unphysical and took the table's value instead.
    pub repaired: Vec<usize>,
}

/// AᵀA, Aᵀb and bᵀb of an equation error: any subset of its columns is solved from them alone.
#[derive(Clone, Debug)]
pub struct NormalEquations {
    pub ata: DMatrix<f64>,
    pub atb: DVector<f64>,
    pub btb: f64,
    pub samples: usize,
    /// About how many of the rows are independent (one per smoothing window).
    pub independent: f64,
}

impl NormalEquations {
    /// Least squares on `columns` only: (β over those columns, SSE).
    pub fn solve(&self, columns: &[usize]) -> Option<(DVector<f64>, f64)> {
        let k = columns.len();
        let a = DMatrix::from_fn(k, k, |i, j| self.ata[(columns[i], columns[j])]);
        let b = DVector::from_fn(k, |i, _| self.atb[columns[i]]);
        let beta = spd_inverse(&a) * &b;
        if beta.iter().any(|x| !x.is_finite()) {
            return None;
        }
        // SSE = bᵀb − 2βᵀAᵀb + βᵀAᵀAβ
        let sse = (self.btb - 2.0 * beta.dot(&b) + (beta.transpose() * &a * &beta)[(0, 0)]).max(0.0);
        Some((beta, sse))
    }

    /// BIC of a solution with residual `sse` and `parameters` columns, on the independent rows
    /// (the smoothing correlates the rest).
    pub fn bic(&self, sse: f64, parameters: usize) -> f64 {
        let n = self.independent.max(1.0);
        n * (sse / self.samples as f64).max(1e-300).ln() + parameters as f64 * n.ln()
    }
}

impl Effect {
    pub const ALL: [Effect; 9] = [
        Effect::CoulombFriction,
        Effect::Backlash,
        Effect::Gravity,
        Effect::LinkDamping,
        Effect::ThermalLag,
        Effect::FrequencyDependentModulus,
        Effect::StribeckFriction,
        Effect::AsymmetricFriction,
        Effect::ConstantLoad,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Effect::CoulombFriction => "coulomb_friction",
            Effect::Backlash => "backlash",
            Effect::Gravity => "gravity",
            Effect::LinkDamping => "link_damping",
            Effect::ThermalLag => "thermal_lag",
            Effect::FrequencyDependentModulus => "frequency_dependent_modulus",
            Effect::StribeckFriction => "stribeck_friction",
            Effect::AsymmetricFriction => "asymmetric_friction",
            Effect::ConstantLoad => "constant_load",
        }
    }

    pub fn from_name(s: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == s)
    }

    /// The effect this one stands in for, never beside it: while the link moves, asymmetric
    /// friction's Coulomb half-difference is a constant torque, so it and a constant load are one
    /// column (docs/interfaces.md, the equivalent forms); asymmetric friction, the physical form,
    /// takes the load's place.
    pub fn takes_place_of(self) -> Option<Effect> {
        match self {
            Effect::AsymmetricFriction => Some(Effect::ConstantLoad),
            _ => None,
        }
    }

    /// The effect this one is defined over: the Stribeck excess is BearingFriction's curve above a
    /// Coulomb level (alone, at a high speed scale, it only mimics Coulomb friction and blocks the
    /// real one), so it is ranked only once Coulomb friction is in, and paired with it before.
    pub fn defined_over(self) -> Option<Effect> {
        match self {
            Effect::StribeckFriction => Some(Effect::CoulombFriction),
            _ => None,
        }
    }

    /// The effects whose levels this one splits per direction: asymmetric friction's half-differences
    /// are over Coulomb friction's and link damping's levels, and without them one direction's level
    /// is below zero (a friction that pushes, where friction levels are ≥ 0). A refit of it brings in
    /// whichever of them the model lacks, from zero (`DeviceRig::screened_refit`).
    pub fn levels_over(self) -> &'static [Effect] {
        match self {
            Effect::AsymmetricFriction => &[Effect::CoulombFriction, Effect::LinkDamping],
            _ => &[],
        }
    }

    /// The lighter effect that does much of what this one does on runs that show little more of it,
    /// with fewer parameters: a gravity whose link angle barely moves is a constant torque, and an
    /// asymmetric friction whose viscous levels are alike is (Coulomb and link damping besides) a
    /// constant load (the equivalent forms). The backward check tries it (`stepwise::Rig::lighter`).
    pub fn lighter_form(self) -> Option<Effect> {
        match self {
            Effect::Gravity | Effect::AsymmetricFriction => Some(Effect::ConstantLoad),
            _ => None,
        }
    }

    /// An effect with no typical size to start a refit from, only the ranking's: a thermal lag. Its
    /// size is the runs' (the PCL falls behind by the drift rate times the lag, and the lag's effect
    /// changes shape with its size, `diagnose::THERMAL_LAG_SHARES`), and a short lag is a valley of
    /// its own at no lag: the K and C fitted without it take in the offset a short lag makes. From
    /// the difference step's 0.5 s, which is nearest the current model and so the cheapest start,
    /// the refit of a 10 s lag on 20 s heating runs went to no lag (from 1 s or more it found 9.9 s).
    pub fn started_from_ranking_only(self) -> bool {
        self == Effect::ThermalLag
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
            Effect::StribeckFriction => {
                &[("torque_nm", 0.02, Some(0.0)), ("ln_velocity", 0.2, Some(-9.210340371976182))]
            } /* ln 1e-4 rad/s */,
            Effect::AsymmetricFriction => {
                &[("coulomb_asymmetry_nm", 0.01, None), ("viscous_asymmetry_nms", 0.005, None)]
            }
            Effect::ConstantLoad => &[("torque_nm", 0.02, None)],
        }
    }

    pub fn apply(self, v: &[f64], e: &mut EffectValues) {
        match self {
            Effect::CoulombFriction => e.coulomb_friction += v[0],
            Effect::Backlash => e.backlash_width = v[0],
            Effect::Gravity => {
                e.gravity_a = v[0];
                e.gravity_b = v[1];
            }
            Effect::LinkDamping => e.link_damping += v[0],
            Effect::ThermalLag => e.thermal_lag = v[0],
            Effect::FrequencyDependentModulus => {
                e.maxwell_stiffness = v[0];
                e.maxwell_time = v[1].exp();
            }
            Effect::StribeckFriction => {
                e.stribeck_friction = v[0];
                e.stribeck_velocity = v[1].exp();
            }
            Effect::AsymmetricFriction => {
                e.coulomb_asymmetry = v[0];
                e.viscous_asymmetry = v[1];
            }
            Effect::ConstantLoad => e.constant_load = v[0],
        }
    }

    /// Whether the outputs move about in proportion to the effect's levels, so that the Jacobian
    /// times the levels measures what the effect does. A torque level does. A thermal lag's time
    /// constant does not: the PCL's lag behind a drift saturates as the constant nears the run's
    /// length, and there the slope times the constant reads about half of what the lag does (fresh
    /// rig 1261: a 51 s lag over 59 s runs, kept at a BIC 16 000 lower, then dropped as unseen).
    pub fn level_is_linear(self) -> bool {
        self != Effect::ThermalLag
    }

    /// Nonlinear effects switch the FMU to its adaptive solver.
    pub fn is_nonlinear(self) -> bool {
        matches!(
            self,
            Effect::CoulombFriction
                | Effect::Backlash
                | Effect::Gravity
                | Effect::StribeckFriction
                | Effect::AsymmetricFriction
        )
    }
}

/// Range of the fitted transmission stiffness, N·m/rad: from a soft elastomer coupling to a stiff
/// gear train (real rigs span about 0.1 to 1e7; issue 10), with a decade of margin each side.
pub const STIFFNESS_RANGE: (f64, f64) = (1e-2, 1e8);
/// Range of the fitted transmission damping at the group's reference frequency, N·m·s/rad: down to
/// a lightly damped metal link (ζ ≈ 1e-3 on 1e-4 kg·m²) and up to a rigid-looking viscous coupling.
pub const DAMPING_RANGE: (f64, f64) = (1e-7, 1e6);

/// How the transmission's damping depends on the excitation (issue 10, item 2), chosen by evidence
/// in `mod.rs`: both are fitted when some temperature has runs at two frequencies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DampingLaw {
    /// C constant in frequency: a viscous damper between motor and link.
    Viscous,
    /// C = K''/ω with K'' constant (the PCL's loss modulus as the paper reads it): defined only
    /// for single-frequency sinusoidal runs, since it needs "the excitation frequency".
    Hysteretic,
}

impl DampingLaw {
    pub fn name(self) -> &'static str {
        match self {
            DampingLaw::Viscous => "viscous",
            DampingLaw::Hysteretic => "hysteretic",
        }
    }
}

/// How a fitted stiffness is shared between the spring bank and the PCL, which matters only when
/// the temperature moves within a run (the PCL's E'(T) moves, the springs do not).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpringBank {
    /// Springs and PCL scaled together (the table's share at the group's temperature): reaches any
    /// stiffness, below the nominal springs too.
    Scaled,
    /// The nominal springs stay; the PCL carries the rest (the paper's device, K above the springs).
    Nominal,
}

impl SpringBank {
    pub fn name(self) -> &'static str {
        match self {
            SpringBank::Scaled => "scaled_with_pcl",
            SpringBank::Nominal => "nominal",
        }
    }
}

/// A run's smoothed link and motor angles, the smoothing's half window (samples), and the link
/// speed at or below which the equation error reads the link as at rest (`for_each_sample`).
type Smoothed = (Vec<f64>, Vec<f64>, usize, f64);

/// The data as the fit sees it.
pub struct Problem<'a> {
    pub sim: &'a Simulator,
    pub inputs: Vec<SimInput>,
    pub measured: Vec<Vec<f64>>,
    /// Temperature group of each run (its own stiffness and damping).
    pub group: Vec<usize>,
    pub n_groups: usize,
    pub solver_tolerance: f64,
    /// The FMU's transmission with the table's moduli at each group's temperature and reference
    /// frequency: the fitted K and C scale its springs, E' and E'' (so a heating run keeps the
    /// table's shape in temperature).
    pub tables: Vec<TransmissionTable>,
    /// Savitzky–Golay-smoothed (link, motor) angles per run for the equation error, computed once.
    /// Per run: the smoothed link and motor angles and the smoothing's half window.
    smoothed: std::sync::OnceLock<Vec<Smoothed>>,
    /// What the runs show of torques on the link, computed once (`Problem::torque_scale`).
    torque_scale: std::sync::OnceLock<Option<TorqueScale>>,
    /// Whether each run's motor angle is one sinusoid, computed once.
    sinusoidal: std::sync::OnceLock<Vec<bool>>,
    /// Each sinusoidal run's (K, C) from its frequency response when physical, computed once.
    responses: std::sync::OnceLock<Vec<Option<(f64, f64)>>>,
    /// Each run's link encoder (`diagnose::LinkCount`), measured once.
    link_counts: std::sync::OnceLock<Vec<Option<super::diagnose::LinkCount>>>,
}

/// Parameter vector: [ln K_g, ln C_g for each temperature group] (the transmission's stiffness,
/// N·m/rad, and damping at the group's reference frequency, N·m·s/rad) ++ effect parameters in
/// `effects` order.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelSpec {
    pub effects: Vec<Effect>,
    pub law: DampingLaw,
    pub springs: SpringBank,
    /// With backlash among the effects: Modelica's ElastoBacklash instead of the clipped law
    /// (chosen after the search, [`super::search::choose_backlash_law`]).
    pub elasto_backlash: bool,
}

impl ModelSpec {
    /// The effects as the report names them: with an asymmetry in, Coulomb friction and link
    /// damping are part of its four levels.
    pub fn reported_effects(&self) -> Vec<Effect> {
        let asymmetric = self.effects.contains(&Effect::AsymmetricFriction);
        let folded = |e: &Effect| asymmetric && matches!(e, Effect::CoulombFriction | Effect::LinkDamping);
        self.effects.iter().copied().filter(|e| !folded(e)).collect()
    }
    /// (asymmetry's index, its level's index) for the asymmetric friction's Coulomb and viscous
    /// asymmetries: each level ± its asymmetry must stay ≥ 0.
    pub fn friction_level_pairs(&self, n_groups: usize) -> Vec<(usize, Option<usize>)> {
        let at = |e: Effect| self.offset_of(e, n_groups);
        match at(Effect::AsymmetricFriction) {
            Some(a) => vec![(a, at(Effect::CoulombFriction)), (a + 1, at(Effect::LinkDamping))],
            None => Vec::new(),
        }
    }
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
    /// Start index of effect `e`'s parameters; None where `e` is not in the model.
    pub fn offset_of(&self, e: Effect, n_groups: usize) -> Option<usize> {
        self.offsets(n_groups).into_iter().find(|&(_, x)| x == e).map(|(o, _)| o)
    }
    pub fn typical(&self, n_groups: usize) -> Vec<f64> {
        let mut t = vec![1.0; 2 * n_groups];
        for e in &self.effects {
            t.extend(e.params().iter().map(|p| p.1));
        }
        t
    }
    /// Lower bounds of the effects' parameters, in `effects` order (the transmission's bounds depend
    /// on the data: `Problem::bounds`).
    pub fn effect_lower(&self) -> Vec<Option<f64>> {
        self.effects.iter().flat_map(|e| e.params().iter().map(|p| p.2)).collect()
    }
    /// Upper bounds of the effects' parameters, in `effects` order.
    pub fn effect_upper(&self) -> Vec<Option<f64>> {
        self.effects
            .iter()
            .flat_map(|e| {
                e.params().iter().map(|p| match p.0 {
                    "ln_relaxation_time" | "ln_velocity" => Some(10f64.ln()),
                    _ => None,
                })
            })
            .collect()
    }
    pub fn names(&self, group_names: &[String]) -> Vec<String> {
        let mut v = Vec::new();
        for g in group_names {
            v.push(format!("ln_stiffness[{g}]"));
            v.push(format!("ln_damping[{g}]"));
        }
        for e in &self.effects {
            v.extend(e.params().iter().map(|p| format!("{}.{}", e.name(), p.0)));
        }
        v
    }
}

/// Least-squares sinusoid x ≈ c + a cos ωt + b sin ωt over the samples from `from` on: (c, a, b,
/// share of the variance it explains).
pub fn sinusoid(t: &[f64], x: &[f64], frequency_hz: f64, from: usize) -> (f64, f64, f64, f64) {
    let w = 2.0 * std::f64::consts::PI * frequency_hz;
    let n = t.len() - from;
    let m = DMatrix::from_fn(n, 3, |i, j| match j {
        0 => 1.0,
        1 => (w * t[from + i]).cos(),
        _ => (w * t[from + i]).sin(),
    });
    let y = DVector::from_column_slice(&x[from..]);
    let beta = spd_inverse(&(m.transpose() * &m)) * (m.transpose() * &y);
    let mean = y.mean();
    let total: f64 = y.iter().map(|v| (v - mean).powi(2)).sum();
    let left: f64 = (&y - &m * &beta).iter().map(|v| v * v).sum();
    (beta[0], beta[1], beta[2], if total > 0.0 { 1.0 - left / total } else { 0.0 })
}

/// A motor angle this close to one sinusoid (share of variance) is a single-frequency run.
pub const SINUSOID_SHARE: f64 = 0.98;

impl<'a> Problem<'a> {
    /// The problem for `inputs` grouped by temperature: reads the FMU's table transmission at each
    /// group's temperature and reference frequency (the lowest run frequency of its sinusoidal runs,
    /// else 1 Hz).
    pub fn new(
        sim: &'a Simulator,
        inputs: Vec<SimInput>,
        measured: Vec<Vec<f64>>,
        group: Vec<usize>,
        temperatures_c: &[f64],
    ) -> Result<Self, String> {
        let sinusoidal: Vec<bool> = inputs.iter().map(is_sinusoidal).collect();
        let mut tables = Vec::new();
        for (g, t) in temperatures_c.iter().enumerate() {
            let f = (0..inputs.len())
                .filter(|&r| group[r] == g && sinusoidal[r])
                .map(|r| inputs[r].frequency_hz)
                .fold(f64::INFINITY, f64::min);
            let f = if f.is_finite() { f } else { 1.0 };
            tables.push(
                sim.transmission_table(t + crate::report::ZERO_CELSIUS, f)
                    .map_err(|e| format!("the FMU's transmission at {} °C: {e}", super::quality::short(*t)))?,
            );
        }
        Ok(Problem {
            sim,
            inputs,
            measured,
            group,
            n_groups: temperatures_c.len(),
            solver_tolerance: 1e-8,
            tables,
            smoothed: std::sync::OnceLock::new(),
            torque_scale: std::sync::OnceLock::new(),
            sinusoidal: sinusoidal.into(),
            responses: std::sync::OnceLock::new(),
            link_counts: std::sync::OnceLock::new(),
        })
    }

    /// Held-out runs judged with this problem's fitted groups (nothing is fitted on them).
    pub fn held_out(&self, inputs: Vec<SimInput>, measured: Vec<Vec<f64>>, group: Vec<usize>) -> Problem<'a> {
        Problem {
            sim: self.sim,
            inputs,
            measured,
            group,
            n_groups: self.n_groups,
            solver_tolerance: self.solver_tolerance,
            tables: self.tables.clone(),
            smoothed: std::sync::OnceLock::new(),
            torque_scale: std::sync::OnceLock::new(),
            sinusoidal: std::sync::OnceLock::new(),
            responses: std::sync::OnceLock::new(),
            link_counts: std::sync::OnceLock::new(),
        }
    }

    /// Range of group g's transmission: the absolute ranges, capped by what its sampling can show
    /// (issue 10, "never use harmonics at or above Nyquist as evidence"): a natural frequency
    /// √(K/J) above the Nyquist frequency π f_s and a velocity time constant J/C below 1/(4π f_s)
    /// are invisible in the samples, and fits that wander there only slow every simulation down
    /// (a stiff velocity coupling under Coulomb friction).
    pub fn transmission_range(&self, g: usize) -> ((f64, f64), (f64, f64)) {
        let runs: Vec<usize> = (0..self.inputs.len()).filter(|&r| self.group[r] == g).collect();
        let inertia = runs.iter().map(|&r| self.inertia(r)).fold(f64::INFINITY, f64::min);
        let rate = runs
            .iter()
            .map(|&r| {
                let t = &self.inputs[r].time;
                (t.len() - 1) as f64 / (t[t.len() - 1] - t[0])
            })
            .fold(f64::INFINITY, f64::min);
        let pi = std::f64::consts::PI;
        let k_hi = STIFFNESS_RANGE.1.min(inertia * (pi * rate).powi(2)).max(10.0 * STIFFNESS_RANGE.0);
        let c_hi = DAMPING_RANGE.1.min(4.0 * pi * inertia * rate).max(10.0 * DAMPING_RANGE.0);
        ((STIFFNESS_RANGE.0, k_hi), (DAMPING_RANGE.0, c_hi))
    }

    /// The smallest K of the temperature groups in `p`, N·m/rad: what a torque on the link deflects
    /// it through at the least (the report's and the backward check's quasi-static convention).
    pub fn softest_stiffness(&self, p: &[f64]) -> f64 {
        (0..self.n_groups).map(|g| p[2 * g].exp()).fold(f64::INFINITY, f64::min)
    }

    /// Whether group g's stiffness or damping in `p` sits on its bound.
    pub fn transmission_at_bound(&self, g: usize, p: &[f64]) -> bool {
        let ((k_lo, k_hi), (c_lo, c_hi)) = self.transmission_range(g);
        on_bound(p[2 * g], k_lo, k_hi) || on_bound(p[2 * g + 1], c_lo, c_hi)
    }

    /// Whether group g's stiffness in `p` is within [`NEAR_BOUND`] of a bound, as the samples
    /// see it: a natural frequency within a factor 2 of the Nyquist limit (a link as rigid as the
    /// rate can show) or of the limp end. A fit heading for the bound stops short of it when the
    /// iterations are capped (fresh rig 114's screening fit: 3 % below the rigid bound).
    /// -1 near the limp end, +1 near the rigid one, 0 elsewhere.
    pub fn stiffness_near_bound(&self, g: usize, p: &[f64]) -> i8 {
        let ((k_lo, k_hi), _) = self.transmission_range(g);
        if p[2 * g] <= (k_lo * NEAR_BOUND).ln() {
            -1
        } else if p[2 * g] >= (k_hi / NEAR_BOUND).ln() {
            1
        } else {
            0
        }
    }

    /// Whether group g's transmission in `p` carries the motion through its damper rather than
    /// its spring: a loss factor C·ω/K above [`DRAGGING_LOSS_FACTOR`] at the table's frequency
    /// (the runs'). The shape a structure without friction or a load takes to follow the motor
    /// with a lag (a limp spring, a damper far past the PCL's): like a bound, no start for a refit
    /// that brings the friction in.
    pub fn transmission_dragging(&self, g: usize, p: &[f64]) -> bool {
        let w = 2.0 * std::f64::consts::PI * self.tables[g].frequency_hz;
        (p[2 * g + 1] - p[2 * g]).exp() * w > DRAGGING_LOSS_FACTOR
    }

    /// Lower and upper bounds of every parameter of `spec` (log-parameters for K and C).
    pub fn bounds(&self, spec: &ModelSpec) -> (Vec<Option<f64>>, Vec<Option<f64>>) {
        let (mut lower, mut upper) = (Vec::new(), Vec::new());
        for g in 0..self.n_groups {
            let ((k_lo, k_hi), (c_lo, c_hi)) = self.transmission_range(g);
            lower.extend([Some(k_lo.ln()), Some(c_lo.ln())]);
            upper.extend([Some(k_hi.ln()), Some(c_hi.ln())]);
        }
        let mut plausible = self.plausible_limits(spec);
        // the FMU refuses a gravity_link_mass above its declared maximum: the gravity's components
        // stay where their norm m·g·d cannot pass it, on every run's centre-of-mass distance
        if let Some(limit) = self.gravity_torque_limit() {
            let names = spec.effects.iter().flat_map(|e| e.params().iter().map(move |p| (*e, p.0)));
            for (lim, (e, _)) in plausible.iter_mut().zip(names) {
                if e == Effect::Gravity {
                    *lim = Some(lim.map_or(limit, |l| l.min(limit)));
                }
            }
        }
        // a signed parameter is bounded both ways by its plausible size
        lower.extend(spec.effect_lower().into_iter().zip(&plausible).map(|(lo, lim)| lo.or(lim.map(|l| -l))));
        upper.extend(spec.effect_upper().into_iter().zip(&plausible).map(|(hi, lim)| match (hi, lim) {
            (Some(h), Some(l)) => Some(h.min(*l)),
            (h, l) => h.or(*l),
        }));
        (lower, upper)
    }

    /// The largest size of each gravity component (a, b) whose norm m·g·d the FMU accepts on every
    /// run: its `gravity_link_mass` maximum × g × the shortest centre-of-mass distance, over √2.
    fn gravity_torque_limit(&self) -> Option<f64> {
        let max_kg: f64 = self.sim.fmu.variable("gravity_link_mass").ok()?.max.as_deref()?.parse().ok()?;
        let d = self.inputs.iter().map(|i| i.com_distance).fold(f64::INFINITY, f64::min);
        (d.is_finite() && max_kg.is_finite()).then(|| max_kg * STANDARD_GRAVITY * d / std::f64::consts::SQRT_2)
    }

    /// [ln K, ln C] of group g clamped into its range.
    fn clamp_transmission(&self, g: usize, k: f64, c: f64) -> [f64; 2] {
        let ((k_lo, k_hi), (c_lo, c_hi)) = self.transmission_range(g);
        [k.clamp(k_lo, k_hi).ln(), c.clamp(c_lo, c_hi).ln()]
    }

    /// The first `share` of every run (a blocked fold, a cheaper screening), same groups and tables.
    pub fn truncated(&self, share: f64) -> Problem<'a> {
        let cut = |v: &[f64]| v[..((v.len() as f64 * share) as usize).clamp(2, v.len())].to_vec();
        self.held_out(
            self.inputs
                .iter()
                .map(|i| SimInput {
                    time: cut(&i.time),
                    motor: cut(&i.motor),
                    housing_k: cut(&i.housing_k),
                    ..i.clone()
                })
                .collect(),
            self.measured.iter().map(|m| cut(m)).collect(),
            self.group.clone(),
        )
    }

    /// Inertia the simulation of run `r` uses: declared, else the FMU's default.
    pub fn inertia(&self, r: usize) -> f64 {
        self.inputs[r].link_inertia.unwrap_or(self.tables[self.group[r]].link_inertia)
    }

    /// The table's transmission as a starting point: [ln K, ln C] per group.
    pub fn table_start(&self) -> Vec<f64> {
        self.tables.iter().flat_map(|t| [t.stiffness.ln(), t.damping.ln()]).collect()
    }

    /// Closed-form transmission per group (issue 10, item 3), [ln K, ln C]: for a sinusoidal run the
    /// frequency response at its frequency, K* = J ω² H/(H − 1) with H the link's complex amplitude
    /// over the motor's; otherwise equation error, J θl'' = K φ + C φ' + b by least squares on
    /// smoothed derivatives. Runs are combined by geometric means; a group without a physical
    /// estimate keeps the table's values.
    pub fn closed_form_start(&self, law: DampingLaw) -> Vec<f64> {
        let mut acc = vec![(0.0, 0.0, 0usize); self.n_groups];
        for (r, response) in self.responses().iter().enumerate() {
            let Some((k, c)) = *response else { continue };
            let g = self.group[r];
            // the group's parameter is the damping at its reference frequency
            let c = match law {
                DampingLaw::Hysteretic => c * self.inputs[r].frequency_hz / self.tables[g].frequency_hz,
                DampingLaw::Viscous => c,
            };
            let [lk, lc] = self.clamp_transmission(g, k, c);
            acc[g].0 += lk;
            acc[g].1 += lc;
            acc[g].2 += 1;
        }
        // groups without a sinusoidal run take the equation error's (computed only then)
        let fallback = if acc.iter().any(|a| a.2 == 0) {
            self.equation_error_start(law, None).unwrap_or_else(|| self.table_start())
        } else {
            Vec::new()
        };
        (0..self.n_groups)
            .flat_map(|g| {
                let (k, c, n) = acc[g];
                if n == 0 {
                    [fallback[2 * g], fallback[2 * g + 1]]
                } else {
                    [k / n as f64, c / n as f64]
                }
            })
            .collect()
    }

    /// Equation error over every run at once: J θl'' = K_g φ + C_g w φ' + Σ θ_i x_i, with φ = θm − θl,
    /// w = f_ref/f_run under the hysteretic law (else 1), and x_i the torque regressors of `effect`
    /// (gravity −sin θl and cos θl, Coulomb −sign θl', link damping −θl'; effects that are not
    /// linear in their parameters have none). Returns [ln K, ln C per group] ++ the effect's
    /// parameters, or None when a group's K or C comes out unphysical. Cheap (no simulation): a
    /// start for Levenberg–Marquardt, not a fit.
    pub fn equation_error_start(&self, law: DampingLaw, effect: Option<Effect>) -> Option<Vec<f64>> {
        let e = self.equation_error(law, effect.as_slice())?;
        e.repaired.is_empty().then_some(e.p)
    }

    /// The equation error above with the regressors of several effects at once (each in
    /// [`EQUATION_ERROR_EFFECTS`]; None for any other). A group whose K or C comes out unphysical
    /// (≤ 0: an effect the regression lacks, absorbed by that group) is repaired on its own: it
    /// takes the material table's value for it, and the start is kept. Derivatives are central
    /// differences of Savitzky–Golay-smoothed angles (a window of 2 % of the run, at least 5
    /// samples each side).
    pub fn equation_error(&self, law: DampingLaw, effects: &[Effect]) -> Option<EquationError> {
        // with a friction among the effects no row at rest holds (`for_each_sample`); without one
        // they do, and a link hanging at rest is where gravity and a play read best
        let moving_only = effects.iter().any(|e| matches!(e, Effect::CoulombFriction | Effect::AsymmetricFriction));
        let solve = |normal: &NormalEquations| normal.solve(&(0..normal.atb.len()).collect::<Vec<_>>());
        // the sums of squares at several widths from one pass (`normal_equations_at`)
        let sse_at = |widths: &[f64]| match self.normal_equations_at(law, effects, widths, moving_only) {
            Some(normals) => normals.iter().map(|n| solve(n).map_or(f64::INFINITY, |(_, sse)| sse)).collect(),
            None => vec![f64::INFINITY; widths.len()],
        };
        let width = if effects.contains(&Effect::Backlash) { self.profile_backlash_width(sse_at)? } else { 0.0 };
        let (beta, _) = solve(&self.normal_equations(law, effects, width, moving_only)?)?;
        let table = self.table_start();
        let mut p = Vec::with_capacity(beta.len());
        let mut repaired = Vec::new();
        for g in 0..self.n_groups {
            let (k, c) = (beta[2 * g], beta[2 * g + 1]);
            let [lk, lc] = self.clamp_transmission(g, k.max(f64::MIN_POSITIVE), c.max(f64::MIN_POSITIVE));
            if !(k > 0.0 && c > 0.0) {
                repaired.push(g);
            }
            p.push(if k > 0.0 { lk } else { table[2 * g] });
            p.push(if c > 0.0 { lc } else { table[2 * g + 1] });
        }
        let mut column = 2 * self.n_groups;
        for &e in effects {
            if e == Effect::Backlash {
                p.push(width);
            } else {
                p.extend(beta.iter().skip(column).take(regressor_columns(e)));
            }
            column += regressor_columns(e);
        }
        Some(EquationError { p, repaired })
    }

    /// Backlash widths worth trying: log-spaced from 2 % to 90 % of twice the largest |θm − θl| of
    /// the smoothed runs (a play wider than the relative motion would never engage).
    pub fn backlash_width_grid(&self) -> Vec<f64> {
        let reach = self
            .smoothed()
            .iter()
            .flat_map(|(l, m, ..)| l.iter().zip(m).map(|(a, b)| (b - a).abs()))
            .fold(0.0, f64::max);
        let (lo, hi) = (0.04 * reach, 1.8 * reach);
        let n = BACKLASH_GRID_POINTS;
        (0..n).map(|i| lo * (hi / lo).powf(i as f64 / (n - 1) as f64)).collect()
    }

    /// The width of least sum of squares over the grid (`sse_at`: the sums at several widths,
    /// the grid's at once), refined by golden section between its neighbours; None when the runs
    /// show no relative motion.
    pub fn profile_backlash_width(&self, sse_at: impl Fn(&[f64]) -> Vec<f64>) -> Option<f64> {
        let grid = self.backlash_width_grid();
        if !(grid[0] > 0.0) {
            return None;
        }
        let sse = |w: f64| sse_at(&[w])[0];
        let values: Vec<f64> = sse_at(&grid);
        let best = (0..grid.len()).min_by(|&a, &b| values[a].total_cmp(&values[b]))?;
        if !values[best].is_finite() {
            return None;
        }
        let (mut a, mut b) = (grid[best.saturating_sub(1)], grid[(best + 1).min(grid.len() - 1)]);
        let phi = 0.5 * (5f64.sqrt() - 1.0);
        let (mut x1, mut x2) = (b - phi * (b - a), a + phi * (b - a));
        let (mut f1, mut f2) = (sse(x1), sse(x2));
        for _ in 0..BACKLASH_REFINE_STEPS {
            if f1 < f2 {
                (b, x2, f2) = (x2, x1, f1);
                x1 = b - phi * (b - a);
                f1 = sse(x1);
            } else {
                (a, x1, f1) = (x1, x2, f2);
                x2 = a + phi * (b - a);
                f2 = sse(x2);
            }
        }
        let (x, f) = if f1 < f2 { (x1, f1) } else { (x2, f2) };
        Some(if f < values[best] { x } else { grid[best] })
    }

    /// The equation error's normal equations with the regressors of `effects` (each in
    /// [`EQUATION_ERROR_EFFECTS`]; None for any other): columns [K, C per group] ++ the effects'.
    /// With a backlash `width` > 0, the transmission's columns are the FMU's clipped spring–damper
    /// without its clip: the spring on the relative angle beyond ±width/2, the damper in contact only.
    /// `moving_only`: the rows where the link moves (`for_each_sample`), for choosing effects and
    /// for a start with friction among them; a start without friction takes every row (a link
    /// hanging at rest against its play, or under gravity, is where the regression reads them best:
    /// CI rig 7's gravity and play started from moving rows alone ended at 18.5× white noise, from
    /// every row at 7.1×).
    pub fn normal_equations(
        &self,
        law: DampingLaw,
        effects: &[Effect],
        width: f64,
        moving_only: bool,
    ) -> Option<NormalEquations> {
        self.normal_equations_at(law, effects, &[width], moving_only)?.pop()
    }

    /// [`Problem::normal_equations`] at each of `widths`, from one pass over the samples: only a
    /// group's two transmission columns depend on the width, so the effects' columns against each
    /// other and the torque are summed once for them all (the backlash grid's twelve widths cost
    /// about one). Every entry is the same sum, in the same order, as a pass of its own would make
    /// (a column that is zero on a sample adds nothing exactly), so the equations are identical.
    pub fn normal_equations_at(
        &self,
        law: DampingLaw,
        effects: &[Effect],
        widths: &[f64],
        moving_only: bool,
    ) -> Option<Vec<NormalEquations>> {
        if effects.iter().any(|e| !EQUATION_ERROR_EFFECTS.contains(e)) {
            return None;
        }
        let (n_groups, n_t) = (self.n_groups, 2 * self.n_groups);
        let n_eff: usize = effects.iter().map(|&e| regressor_columns(e)).sum();
        let cols = n_t + n_eff;
        // shared by every width: the effects' columns (upper triangle) and their products with the torque
        let mut eff_ata = vec![0.0; n_eff * n_eff];
        let mut eff_atb = vec![0.0; n_eff];
        let (mut btb, mut samples) = (0.0, 0usize);
        // per width and group: its two transmission columns against themselves, each effect column
        // and the torque
        let mut tt = vec![[0.0; 3]; widths.len() * n_groups];
        let mut te = vec![0.0; widths.len() * n_groups * 2 * n_eff];
        let mut tb = vec![[0.0; 2]; widths.len() * n_groups];
        let mut eff = vec![0.0; n_eff];
        let independent = self.for_each_sample(law, moving_only, |s| {
            let g = s.group;
            let mut c = 0;
            // the model's smooth sign s = tanh(v / 1 mm/s)
            let sign = (s.v / 1e-3).tanh();
            for e in effects {
                match e {
                    Effect::Gravity => {
                        eff[c] = -s.angle.sin();
                        eff[c + 1] = s.angle.cos();
                    }
                    Effect::CoulombFriction => eff[c] = -sign,
                    Effect::LinkDamping => eff[c] = -s.v,
                    Effect::ConstantLoad => eff[c] = 1.0,
                    Effect::AsymmetricFriction => {
                        // −a_c s² − a_v s v
                        eff[c] = -sign * sign;
                        eff[c + 1] = -sign * s.v;
                    }
                    Effect::Backlash => {}
                    _ => unreachable!("checked above"),
                }
                c += regressor_columns(*e);
            }
            let b = s.inertial;
            for i in 0..n_eff {
                for j in i..n_eff {
                    eff_ata[i * n_eff + j] += eff[i] * eff[j];
                }
                eff_atb[i] += b * eff[i];
            }
            btb += b * b;
            samples += 1;
            for (k, &width) in widths.iter().enumerate() {
                let half_play = 0.5 * width;
                let beyond = s.phi - s.phi.clamp(-half_play, half_play);
                let t = [beyond, if beyond != 0.0 || half_play == 0.0 { s.w * s.dphi } else { 0.0 }];
                let at = k * n_groups + g;
                tt[at][0] += t[0] * t[0];
                tt[at][1] += t[0] * t[1];
                tt[at][2] += t[1] * t[1];
                tb[at][0] += b * t[0];
                tb[at][1] += b * t[1];
                let te = &mut te[at * 2 * n_eff..(at + 1) * 2 * n_eff];
                for (i, &x) in eff.iter().enumerate() {
                    te[i] += t[0] * x;
                    te[n_eff + i] += t[1] * x;
                }
            }
        });
        if samples <= cols {
            return None;
        }
        let normal = |k: usize| {
            let mut ata = DMatrix::<f64>::zeros(cols, cols);
            let mut atb = DVector::<f64>::zeros(cols);
            for i in 0..n_eff {
                for j in i..n_eff {
                    ata[(n_t + i, n_t + j)] = eff_ata[i * n_eff + j];
                    ata[(n_t + j, n_t + i)] = eff_ata[i * n_eff + j];
                }
                atb[n_t + i] = eff_atb[i];
            }
            for g in 0..n_groups {
                let at = k * n_groups + g;
                let (kc, cc) = (2 * g, 2 * g + 1);
                ata[(kc, kc)] = tt[at][0];
                ata[(kc, cc)] = tt[at][1];
                ata[(cc, kc)] = tt[at][1];
                ata[(cc, cc)] = tt[at][2];
                atb[kc] = tb[at][0];
                atb[cc] = tb[at][1];
                for i in 0..n_eff {
                    let (a, b) = (te[at * 2 * n_eff + i], te[at * 2 * n_eff + n_eff + i]);
                    ata[(kc, n_t + i)] = a;
                    ata[(n_t + i, kc)] = a;
                    ata[(cc, n_t + i)] = b;
                    ata[(n_t + i, cc)] = b;
                }
            }
            NormalEquations { ata, atb, btb, samples, independent }
        };
        Some((0..widths.len()).map(normal).collect())
    }

    /// Calls `f` with every usable sample of the equation error (runs of at least 40 samples,
    /// away from the smoothing's ends); returns about how many of them are independent (the
    /// smoothing correlates the residual over its window: about one independent sample per window).
    /// With `moving`, only samples whose link speed stands out of its noise (three times what the
    /// smoothing and difference leave of it, `signal::smoothed_speed_gain`): at rest a friction's
    /// torque is anything up to its level, not its level times the sign of a speed the noise sets,
    /// so no row there holds for any friction level, and a play that leaves the transmission slack
    /// fits the stuck link's deflection in its place (CI rig 3 without its coarse encoder: the
    /// subsets chose link damping and a play for a 1.65 N·m friction holding the link between
    /// steps, and the search never left that valley). Inverse-model identification leaves rest out
    /// for the same reason (the drive's `at_rest`).
    fn for_each_sample(&self, law: DampingLaw, moving: bool, mut f: impl FnMut(&EquationSample)) -> f64 {
        let mut independent = 0.0;
        for (r, inp) in self.inputs.iter().enumerate() {
            let n = inp.time.len();
            if n < 40 {
                continue;
            }
            let g = self.group[r];
            let j = self.inertia(r);
            let w = match law {
                DampingLaw::Hysteretic if self.sinusoidal()[r] => self.tables[g].frequency_hz / inp.frequency_hz,
                _ => 1.0,
            };
            let (l, m, half, rest_speed) = &self.smoothed()[r];
            let half = *half;
            let t = &inp.time;
            let d = |x: &[f64], k: usize| (x[k + 1] - x[k - 1]) / (t[k + 1] - t[k - 1]);
            let mut used = 0usize;
            for k in half + 2..n - half - 2 {
                let v = d(l, k);
                if moving && v.abs() <= *rest_speed {
                    continue;
                }
                used += 1;
                let acc = ((l[k + 1] - l[k]) / (t[k + 1] - t[k]) - (l[k] - l[k - 1]) / (t[k] - t[k - 1]))
                    / (0.5 * (t[k + 1] - t[k - 1]));
                f(&EquationSample {
                    group: g,
                    w,
                    angle: l[k],
                    phi: m[k] - l[k],
                    dphi: d(m, k) - v,
                    v,
                    inertial: j * acc,
                });
            }
            independent += used as f64 / (2 * half + 1) as f64;
        }
        independent
    }

    /// What the runs can show of a torque on the link (issue 18, item 3): the largest transmission
    /// torque |K φ + C φ'| of the equation error with every linear effect in (cheap, and pinned at no
    /// bound), the largest inertial torque |J θl''|, the largest link speed and relative angle, and
    /// each run's half swing of the link angle. Computed once.
    pub fn torque_scale(&self) -> Option<TorqueScale> {
        *self.torque_scale.get_or_init(|| {
            let law = DampingLaw::Viscous;
            let normal = self.normal_equations(law, &EQUATION_ERROR_EFFECTS, 0.0, false)?;
            let (beta, _) = normal.solve(&(0..normal.atb.len()).collect::<Vec<_>>())?;
            let mut scale = TorqueScale { transmission_nm: 0.0, inertial_nm: 0.0, speed: 0.0, relative_angle: 0.0 };
            // every sample: a stuck link's deflection is a torque the runs show
            self.for_each_sample(law, false, |s| {
                let tau = beta[2 * s.group].abs() * s.phi.abs() + beta[2 * s.group + 1].abs() * s.dphi.abs();
                scale.transmission_nm = scale.transmission_nm.max(tau);
                scale.inertial_nm = scale.inertial_nm.max(s.inertial.abs());
                scale.speed = scale.speed.max(s.v.abs());
                scale.relative_angle = scale.relative_angle.max(s.phi.abs());
            });
            (scale.transmission_nm > 0.0 && scale.speed > 0.0).then_some(scale)
        })
    }

    /// Largest size each effect parameter of `spec` may take (None: unbounded), from
    /// [`Problem::torque_scale`]: an effect's torque on the link at most `PLAUSIBLE_TORQUE_FACTOR`
    /// times the largest the transmission and the link's inertia show (friction larger than that
    /// would hold the link still; a damping or load larger would need a torque the transmission
    /// never transmits), a backlash no wider than twice the largest relative angle (it would never
    /// engage). Gravity is not bounded: a hanging link's transmission torque is only mgl times the
    /// sine of its swing.
    pub fn plausible_limits(&self, spec: &ModelSpec) -> Vec<Option<f64>> {
        let scale = self.torque_scale();
        spec.effects
            .iter()
            .flat_map(|&e| e.params().iter().map(move |p| (e, p.0)))
            .map(|(e, name)| {
                let s = scale?;
                let torque = PLAUSIBLE_TORQUE_FACTOR * (s.transmission_nm + s.inertial_nm);
                match (e, name) {
                    (Effect::CoulombFriction | Effect::StribeckFriction | Effect::ConstantLoad, "torque_nm") => {
                        Some(torque)
                    }
                    (Effect::AsymmetricFriction, "coulomb_asymmetry_nm") => Some(torque),
                    (Effect::LinkDamping, _) | (Effect::AsymmetricFriction, "viscous_asymmetry_nms") => {
                        Some(torque / s.speed)
                    }
                    (Effect::Backlash, _) => Some(2.0 * s.relative_angle),
                    _ => None,
                }
            })
            .collect()
    }

    /// The equation error's smoothed (link, motor) angles of every run and their half window: the
    /// widest that takes out no more than the link angle's noise or count (`signal::smooth_to_noise`), at
    /// most 1 % of the run each side, at least 5 samples (against encoder steps).
    fn smoothed(&self) -> &[Smoothed] {
        self.smoothed.get_or_init(|| {
            self.inputs
                .iter()
                .zip(&self.measured)
                .map(|(inp, y)| {
                    let (half, link, noise) = super::signal::smooth_to_noise(&inp.time, y, (y.len() / 100).max(5));
                    let period = super::quality::median_period(&inp.time);
                    let rest = 3.0 * noise * super::signal::smoothed_speed_gain(half) / period;
                    (link, smooth(&inp.time, &inp.motor, half), half, rest)
                })
                .collect()
        })
    }

    /// Each run's link encoder (`diagnose::LinkCount`; None where the column is not quantised),
    /// measured against `outputs`, the model's link angles, on the first call only.
    pub fn link_counts(&self, outputs: &[Vec<f64>]) -> &[Option<super::diagnose::LinkCount>] {
        self.link_counts.get_or_init(|| {
            (0..self.inputs.len())
                .map(|r| {
                    let model = outputs.get(r)?;
                    super::diagnose::LinkCount::of(
                        &self.inputs[r].time,
                        &self.measured[r],
                        model,
                        super::diagnose::count_seed(r),
                    )
                })
                .collect()
        })
    }

    /// Whether each run's motor angle is one sinusoid at its frequency (`is_sinusoidal`).
    pub fn sinusoidal(&self) -> &[bool] {
        self.sinusoidal.get_or_init(|| self.inputs.iter().map(is_sinusoidal).collect())
    }

    /// Each sinusoidal run's (K, C) from its frequency response, when K comes out positive
    /// ([`physical_response`]).
    fn responses(&self) -> &[Option<(f64, f64)>] {
        self.responses.get_or_init(|| {
            (0..self.inputs.len())
                .map(|r| {
                    if !self.sinusoidal()[r] {
                        return None;
                    }
                    frequency_response(&self.inputs[r], &self.measured[r], self.inertia(r)).and_then(physical_response)
                })
                .collect()
        })
    }

    /// Sample counts of the runs, in order.
    pub fn lengths(&self) -> Vec<usize> {
        self.measured.iter().map(Vec::len).collect()
    }

    /// Each run's sum of squares of a flattened residual (runs in order).
    pub fn run_sse(&self, residual: &[f64]) -> Vec<f64> {
        let mut offset = 0;
        self.measured
            .iter()
            .map(|m| {
                let s = residual[offset..offset + m.len()].iter().map(|e| e * e).sum();
                offset += m.len();
                s
            })
            .collect()
    }

    /// Every run's initial link speed, in order.
    pub fn initial_speeds(&self) -> Vec<f64> {
        self.inputs.iter().map(|i| i.initial_link_speed).collect()
    }

    /// Sets every run's initial link speed.
    pub fn set_initial_speeds(&mut self, speeds: &[f64]) {
        self.inputs.iter_mut().zip(speeds).for_each(|(i, &v)| i.initial_link_speed = v);
    }

    /// The motion's speed scale, rad/s: √2 × the rms speed of the motor over every run (the
    /// amplitude × ω of a sine), which the link follows below its resonance. None for runs too
    /// short to tell.
    pub fn speed_scale(&self) -> Option<f64> {
        let (mut sum, mut n) = (0.0, 0usize);
        for input in &self.inputs {
            if let Some(v2) = super::signal::mean_square_speed(&input.time, &input.motor) {
                sum += v2 * input.time.len() as f64;
                n += input.time.len();
            }
        }
        let scale = (2.0 * sum / n as f64).sqrt();
        (n > 0 && scale.is_finite() && scale > 0.0).then_some(scale)
    }

    pub fn n_samples(&self) -> usize {
        self.measured.iter().map(|m| m.len()).sum()
    }

    pub fn run_model(&self, spec: &ModelSpec, p: &[f64], run: usize) -> RunModel {
        let g = self.group[run];
        let mut e = EffectValues::default();
        for (o, eff) in spec.offsets(self.n_groups) {
            eff.apply(&p[o..o + eff.params().len()], &mut e);
        }
        e.elasto_backlash = spec.elasto_backlash;
        let t = &self.tables[g];
        let k = p[2 * g].exp();
        let (storage_scale, spring_stiffness) = match spec.springs {
            SpringBank::Scaled => (k / t.stiffness, Some(t.spring_stiffness * k / t.stiffness)),
            // below the springs the PCL cannot go negative: the model stays at the springs there
            SpringBank::Nominal => (((k - t.spring_bank) / (t.stiffness - t.spring_bank)).max(1e-12), None),
        };
        RunModel {
            storage_scale,
            spring_stiffness,
            loss_scale: p[2 * g + 1].exp() / t.damping,
            excitation_frequency: match spec.law {
                DampingLaw::Viscous => Some(t.frequency_hz),
                DampingLaw::Hysteretic => None,
            },
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

    /// Sum of squared residuals at `p` (infinite when the FMU cannot simulate it).
    pub fn cost(&self, spec: &ModelSpec, p: &[f64]) -> f64 {
        self.outputs(spec, p).map(|o| sse(&self.residual(&o))).unwrap_or(f64::INFINITY)
    }

    /// ∂ŷ/∂p by forward differences (only local columns are simulated; others are zero).
    pub fn jacobian(&self, spec: &ModelSpec, p: &[f64], base: &[Vec<f64>]) -> Option<DMatrix<f64>> {
        // forward steps (backward at an upper bound), so every trial stays inside the bounds
        let typical = spec.typical(self.n_groups);
        let (_, upper) = self.bounds(spec);
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
    /// The model at `p` without fitting (no Jacobian, no covariance): `spec` judged on other data.
    pub fn evaluate(prob: &Problem, spec: ModelSpec, p: Vec<f64>) -> Option<Fit> {
        let outputs = prob.outputs(&spec, &p)?;
        let residual = prob.residual(&outputs);
        let sse = sse(&residual);
        let n = residual.len();
        Some(Fit {
            spec,
            p,
            outputs,
            residual,
            sse,
            n,
            jacobian: DMatrix::zeros(0, 0),
            covariance: DMatrix::zeros(0, 0),
            iterations: 0,
        })
    }

    /// `evaluate` with the Jacobian at `p` (what the ranking's projections need).
    pub fn evaluate_with_jacobian(prob: &Problem, spec: ModelSpec, p: Vec<f64>) -> Option<Fit> {
        let mut f = Fit::evaluate(prob, spec, p)?;
        f.jacobian = prob.jacobian(&f.spec, &f.p, &f.outputs)?;
        Some(f)
    }

    pub fn rmse(&self) -> f64 {
        (self.sse / self.n as f64).sqrt()
    }
    /// Bayesian information criterion for Gaussian errors: N ln(SSE/N) + k ln N.
    pub fn bic(&self) -> f64 {
        let n = self.n as f64;
        n * (self.sse / n).ln() + self.p.len() as f64 * n.ln()
    }
    /// The standard error of parameter j; NaN (null in the report) for a fit without a covariance:
    /// one only evaluated, where the budget ran out before a refit (fresh campaign rig 501 panicked
    /// writing its report).
    pub fn std_err(&self, j: usize) -> f64 {
        standard_deviation(self.covariance_at(j, j))
    }

    /// The covariance of parameters i and j; NaN where the fit has none.
    pub fn covariance_at(&self, i: usize, j: usize) -> f64 {
        covariance_entry(&self.covariance, i, j)
    }
}

/// Element (i, j) of a fit's covariance; NaN (unknown) where it has none, as a fit only evaluated
/// (an empty matrix) has none.
pub fn covariance_entry(covariance: &DMatrix<f64>, i: usize, j: usize) -> f64 {
    covariance.get((i, j)).copied().unwrap_or(f64::NAN)
}

/// √variance, a rounding's negative variance read as 0; NaN (unknown) stays NaN, where `f64::max`
/// would turn it into 0.
pub fn standard_deviation(variance: f64) -> f64 {
    if variance.is_nan() {
        variance
    } else {
        variance.max(0.0).sqrt()
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
    if a.iter().chain(g.iter()).any(|x| !x.is_finite()) {
        return DVector::zeros(n); // no finite information: no step (nalgebra's SVD panics on a NaN)
    }
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
    if n == 0 || a.iter().any(|x| !x.is_finite()) {
        // nalgebra's SVD panics on an empty matrix and on a NaN: a matrix without finite information gives none (zero)
        return DMatrix::zeros(n, n);
    }
    let (s, d) = diagonally_scaled(a);
    let inv = s.pseudo_inverse(1e-12).unwrap_or_else(|_| DMatrix::zeros(n, n));
    DMatrix::from_fn(n, n, |i, j| inv[(i, j)] / (d[i] * d[j]))
}

/// Contiguous blocks per run for the sandwich covariance: residual correlation inside a block is
/// kept whole, blocks are taken as independent.
pub const COVARIANCE_BLOCKS: usize = 20;

/// (JᵀJ)⁻¹ (Σ_b s_b s_bᵀ) (JᵀJ)⁻¹ with s_b = Σ_{t∈b} J_tᵀ e_t over `COVARIANCE_BLOCKS` contiguous
/// blocks of each run (`lengths` samples each, in order), scaled by B/(B − p): standard errors
/// that hold up when residuals are correlated within a block (σ²(JᵀJ)⁻¹ assumes white residuals
/// and shrinks with every extra correlated sample).
pub fn block_sandwich(jac: &DMatrix<f64>, r: &[f64], lengths: &[usize]) -> DMatrix<f64> {
    let mut cluster = Vec::with_capacity(r.len());
    for &len in lengths {
        let b = COVARIANCE_BLOCKS.min(len);
        let first = cluster.last().map_or(0, |c| c + 1);
        for i in 0..b {
            cluster.extend(std::iter::repeat_n(first + i, (i + 1) * len / b - i * len / b));
        }
    }
    cluster_sandwich(jac, r, &cluster)
}

/// (JᵀJ)⁻¹ (Σ_c s_c s_cᵀ) (JᵀJ)⁻¹ with s_c = Σ_{t∈c} J_tᵀ e_t over the clusters `cluster[t]`
/// names, scaled by C/(C − p): residuals correlated within a cluster count once, clusters are
/// taken as independent.
pub fn cluster_sandwich(jac: &DMatrix<f64>, r: &[f64], cluster: &[usize]) -> DMatrix<f64> {
    let np = jac.ncols();
    let ainv = spd_inverse(&(jac.transpose() * jac));
    let clusters = cluster.iter().map(|c| c + 1).max().unwrap_or(0);
    let mut sums = vec![DVector::<f64>::zeros(np); clusters];
    let mut members = vec![0usize; clusters];
    for (t, &c) in cluster.iter().enumerate() {
        members[c] += 1;
        for j in 0..np {
            sums[c][j] += jac[(t, j)] * r[t];
        }
    }
    let used = members.iter().filter(|m| **m > 0).count();
    let meat = sums.iter().fold(DMatrix::<f64>::zeros(np, np), |m, s| m + s * s.transpose());
    let scale = used as f64 / (used.saturating_sub(np).max(1)) as f64;
    &ainv * meat * &ainv * scale
}

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
    /// Update the Jacobian by Broyden's rank-one formula after an accepted step instead of
    /// differencing it again (at most `MAX_BROYDEN_UPDATES` in a row; refreshed when a step
    /// fails, and at the optimum so the covariance uses a differenced one).
    pub broyden: bool,
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
    // whether `jac` is a finite-difference Jacobian at p (else a Broyden update of one)
    let mut fresh = false;
    let mut broyden_run = 0;
    let mut iterations = 0;
    for it in 0..max_iter {
        iterations = it + 1;
        if !fresh && (jac.ncols() == 0 || !ls.broyden || broyden_run >= MAX_BROYDEN_UPDATES) {
            match (ls.jacobian)(&p, &simulated) {
                Some(j) => jac = j,
                // out of time (or a difference step the FMU refuses) after some progress: the best
                // point so far stands, with the last Jacobian it had
                None if jac.ncols() == p.len() => break,
                None => return Err("the FMU could not simulate a difference step".into()),
            }
            fresh = true;
            broyden_run = 0;
        }
        let a = jac.transpose() * &jac;
        let g = jac.transpose() * DVector::from_column_slice(&r);
        let mut accepted: Option<(Vec<f64>, S, Vec<f64>, f64)> = None;
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
                    accepted = Some((q, out, rq, cq));
                    mu = (mu / 3.0).max(1e-9);
                    break;
                }
            }
            if small {
                converged = true;
                break;
            }
            mu *= 5.0;
        }
        match accepted {
            Some((q, out, rq, cq)) => {
                if ls.broyden {
                    // J ← J + (Δŷ − J δ) δᵀ / δᵀδ, with Δŷ = −Δr (r = y − ŷ)
                    let delta = DVector::from_iterator(q.len(), q.iter().zip(&p).map(|(a, b)| a - b));
                    let dd = delta.norm_squared();
                    if dd > 0.0 {
                        let dy = DVector::from_iterator(r.len(), r.iter().zip(&rq).map(|(old, new)| old - new));
                        let u = (dy - &jac * &delta) / dd;
                        jac += u * delta.transpose();
                    }
                    fresh = false;
                    broyden_run += 1;
                }
                (p, simulated, r, cost) = (q, out, rq, cq);
                if converged {
                    break;
                }
            }
            // an updated Jacobian that finds no descent is refreshed before giving up
            None if !fresh => broyden_run = MAX_BROYDEN_UPDATES,
            None => break,
        }
    }
    if !fresh {
        match (ls.jacobian)(&p, &simulated) {
            Some(j) => jac = j,
            None if jac.ncols() == p.len() => {}
            None => return Err("the FMU could not simulate a difference step".into()),
        }
    }
    Ok(Minimum { p, simulated, residual: r, cost, jacobian: jac, iterations })
}

/// Broyden updates in a row before the Jacobian is differenced again.
pub const MAX_BROYDEN_UPDATES: usize = 3;

/// How far an effect shows in a fit's outputs, from its linearised share s (`linearised_shares`):
/// sample by sample against the noise (rms s over `noise`) and at its own time scale against the
/// fit's residual (`own_time_scale_share`), the larger. Above 1 the samples, or their averages over
/// the time the effect holds, show it. A stiff loop's friction offset, or a friction's asymmetry
/// under a coarse encoder, moves the output by less than the noise sample by sample but holds for
/// a whole stroke; averaged over it white noise falls by its square root and the effect does not,
/// while a coloured residual (a controller's dither, a model error) keeps its slow part.
pub fn visibility(share: &[f64], noise: f64, residual: &[f64], lengths: &[usize], parameters: usize) -> f64 {
    (rms(share) / noise).max(own_time_scale_share(share, residual, lengths, parameters))
}

/// The part of an effect's linearised share that the model's other parameters cannot take over:
/// `share` less its least-squares projection on the Jacobian's columns outside `own` (every
/// parameter the effect brings). A gravity beside a constant load shares its mean with the load and
/// its slope with the stiffness; what is left is what only the gravity does. The share itself where
/// the projection is singular.
pub fn share_beyond_the_rest(jacobian: &DMatrix<f64>, share: &[f64], own: &[usize]) -> Vec<f64> {
    let others: Vec<usize> = (0..jacobian.ncols()).filter(|j| !own.contains(j)).collect();
    if others.is_empty() || jacobian.nrows() != share.len() {
        return share.to_vec();
    }
    // the normal equations over the other columns, each scaled to unit norm (the parameters' units
    // differ by orders of magnitude), without copying the Jacobian
    let k = others.len();
    let norms: Vec<f64> = others.iter().map(|&j| jacobian.column(j).norm()).collect();
    if norms.iter().any(|&n| !(n > 0.0 && n.is_finite())) {
        return share.to_vec();
    }
    let s = DVector::from_column_slice(share);
    let gram = DMatrix::from_fn(k, k, |a, b| {
        jacobian.column(others[a]).dot(&jacobian.column(others[b])) / (norms[a] * norms[b])
    });
    let rhs = DVector::from_fn(k, |a, _| jacobian.column(others[a]).dot(&s) / norms[a]);
    let Some(beta) = gram.cholesky().map(|ch| ch.solve(&rhs)) else {
        return share.to_vec();
    };
    let mut left = s;
    for (a, &j) in others.iter().enumerate() {
        left.axpy(-beta[a] / norms[a], &jacobian.column(j), 1.0);
    }
    left.iter().copied().collect()
}

/// rms(s̄) / rms(r̄) for `share` s and `residual` r averaged over blocks of the lag at which s's
/// autocorrelation falls to ½, runs (`lengths`) apart. The block is at most the length that leaves
/// ten blocks per fitted parameter (`parameters`): a fit nulls its residual's slowest blocks (the
/// initial speeds, a load), and over a few long blocks any residual would read as no noise.
pub fn own_time_scale_share(share: &[f64], residual: &[f64], lengths: &[usize], parameters: usize) -> f64 {
    let runs: Vec<std::ops::Range<usize>> = lengths
        .iter()
        .scan(0, |start, &l| {
            *start += l;
            Some(*start - l..*start)
        })
        .collect();
    let autocorrelation = |lag: usize| {
        let (mut lagged, mut energy) = (0.0, 0.0);
        for run in &runs {
            let x = &share[run.clone()];
            energy += x.iter().map(|v| v * v).sum::<f64>();
            lagged += x.iter().zip(x.iter().skip(lag)).map(|(a, b)| a * b).sum::<f64>();
        }
        if energy > 0.0 {
            lagged / energy
        } else {
            0.0
        }
    };
    let longest = (share.len() / (10 * parameters.max(1))).max(1);
    let mut block = 1;
    while block < longest && autocorrelation(block) > 0.5 {
        block = (block + block.div_ceil(4)).min(longest);
    }
    let block_rms = |x: &[f64]| {
        let means: Vec<f64> = runs
            .iter()
            .flat_map(|run| x[run.clone()].chunks_exact(block).map(|c| c.iter().sum::<f64>() / block as f64))
            .collect();
        rms(&means)
    };
    let (signal, noise) = (block_rms(share), block_rms(residual));
    if noise > 0.0 {
        signal / noise
    } else if signal > 0.0 {
        f64::INFINITY
    } else {
        0.0
    }
}

/// Root mean square (0 for no values).
pub fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len().max(1) as f64).sqrt()
}

/// The linearised share Σ_j J_ij p_j of the parameters `cols`, row by row.
pub fn linearised_shares(jacobian: &DMatrix<f64>, p: &[f64], cols: &[usize]) -> Vec<f64> {
    (0..jacobian.nrows()).map(|i| cols.iter().map(|&j| jacobian[(i, j)] * p[j]).sum()).collect()
}

pub fn levenberg_marquardt(prob: &Problem, spec: ModelSpec, p0: Vec<f64>, max_iter: usize) -> Result<Fit, String> {
    let (lower, upper) = prob.bounds(&spec);
    let typical = spec.typical(prob.n_groups);
    let levels = spec.friction_level_pairs(prob.n_groups);
    let clamp = |p: &mut [f64]| {
        for ((x, lo), hi) in p.iter_mut().zip(&lower).zip(&upper) {
            if let Some(b) = lo {
                *x = x.max(*b);
            }
            if let Some(b) = hi {
                *x = x.min(*b);
            }
        }
        // friction never pushes: F± = level ± asymmetry ≥ 0 (a one-sided push is a load, which
        // the library has as constant_load)
        for &(asymmetry, level) in &levels {
            let bound = level.map_or(0.0, |i| p[i].max(0.0));
            p[asymmetry] = p[asymmetry].clamp(-bound, bound);
        }
    };
    let ls = LeastSquares {
        simulate: &|p| prob.outputs(&spec, p),
        residual: &|out| prob.residual(out),
        jacobian: &|p, out| prob.jacobian(&spec, p, out),
        clamp: &clamp,
        negligible: &|j, old, new| (new - old).abs() <= 1e-6 * typical[j].max(old.abs()),
        relative_tolerance: 1e-6,
        broyden: true,
    };
    let mut m = minimize(&ls, p0, max_iter)?;
    if let Some(p) = torque_scale_probe(prob, &spec, &m.p, m.cost, &clamp) {
        if let Ok(again) = minimize(&ls, p, max_iter) {
            if again.cost < m.cost {
                m = again;
            }
        }
    }
    let n = m.residual.len();
    let covariance = block_sandwich(&m.jacobian, &m.residual, &prob.lengths());
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

/// Every torque of the model times one factor s: the transmission's K and C, and each effect
/// parameter measured in N·m (per radian, per rad/s or alone); widths, times and speeds stay.
/// Driven well below its natural frequency the link barely feels its inertia, the one torque
/// not in p, so every such s moves the link almost alike: a long curved valley (K and C are
/// logarithms, the effects' torques are not) along which Levenberg–Marquardt creeps and stops
/// (fresh rig 144: K, C, gravity and friction all 27× the truth's, 16× the noise floor).
fn scaled_torques(spec: &ModelSpec, n_groups: usize, p: &[f64], s: f64) -> Vec<f64> {
    let mut q = p.to_vec();
    for x in &mut q[..2 * n_groups] {
        *x += s.ln();
    }
    for (o, e) in spec.offsets(n_groups) {
        for (j, (name, _, _)) in e.params().iter().enumerate() {
            if name.contains("_nm") {
                q[o + j] *= s;
            }
        }
    }
    q
}

/// The best point along [`scaled_torques`]' valley from a converged `p` (cost `cost`), when one
/// is cheaper: factors 4^±1 first (two simulations where the valley's floor is here), then on
/// by 4 while the cost falls and every K and C stays within its bounds, and a factor 2 either
/// side of the best. None when no factor helps.
fn torque_scale_probe(
    prob: &Problem,
    spec: &ModelSpec,
    p: &[f64],
    cost: f64,
    clamp: &dyn Fn(&mut [f64]),
) -> Option<Vec<f64>> {
    let n_t = 2 * prob.n_groups;
    // a factor that would take a transmission past its bounds leaves the valley (a rigid or limp
    // link is another model, whose effects the clamp would leave scaled alone)
    let at = |s: f64| {
        let mut q = scaled_torques(spec, prob.n_groups, p, s);
        let unclamped = q[..n_t].to_vec();
        clamp(&mut q);
        let c = if q[..n_t] != unclamped[..] { f64::INFINITY } else { prob.cost(spec, &q) };
        (c, s, q)
    };
    let mut best: Option<(f64, f64, Vec<f64>)> = None;
    for step in [4.0, 0.25] {
        let mut s = step;
        for _ in 0..4 {
            let here = at(s);
            if here.0 >= best.as_ref().map_or(cost, |b| b.0) {
                break;
            }
            best = Some(here);
            s *= step;
        }
        if best.is_some() {
            break;
        }
    }
    let mut best = best?;
    let grid = best.1;
    for f in [0.5, 2.0] {
        let here = at(grid * f);
        if here.0 < best.0 {
            best = here;
        }
    }
    let (c, s, q) = best;
    super::stepwise::debug(format_args!("torque scale probe: ×{s:.3} lowers the cost {cost:.4e} → {c:.4e}"));
    Some(q)
}

/// Whether a run's motor angle is one sinusoid at its frequency (the hysteretic law and the
/// frequency-response start need it).
pub fn is_sinusoidal(inp: &SimInput) -> bool {
    is_sinusoidal_signal(&inp.time, &inp.motor, inp.frequency_hz)
}

/// Whether `x(t)` is one sinusoid at `frequency_hz` (share of variance ≥ `SINUSOID_SHARE`).
pub fn is_sinusoidal_signal(t: &[f64], x: &[f64], frequency_hz: f64) -> bool {
    frequency_hz > 0.0 && sinusoid(t, x, frequency_hz, 0).3 >= SINUSOID_SHARE
}

/// A frequency response's (K, C) as a start: None where K ≤ 0 (no transmission gives that response),
/// C's magnitude where C < 0. A link far stiffer than its excitation shows its damping in a quadrature
/// part buried in the noise (fresh rig 570, a 5.9 Hz link driven at 0.21 Hz: K within 3 % of the truth,
/// C −0.063 N·m·s/rad for the truth's +0.074); the magnitude is the scale of that noise, a start of the
/// right order, where dropping the run left the material table's damping, 500× the truth's, and a
/// fit that ended rigid.
fn physical_response((k, c): (f64, f64)) -> Option<(f64, f64)> {
    (k > 0.0 && c.is_finite()).then_some((k, c.abs()))
}

/// K and C from the frequency response at the run's frequency: H = L/M from least-squares
/// sinusoids over the run after its first tenth (the start-up transient), K* = J ω² H/(H − 1).
fn frequency_response(inp: &SimInput, link: &[f64], inertia: f64) -> Option<(f64, f64)> {
    let n = inp.time.len();
    let from = n / 10;
    let (_, ma, mb, _) = sinusoid(&inp.time, &inp.motor, inp.frequency_hz, from);
    let (_, la, lb, _) = sinusoid(&inp.time, link, inp.frequency_hz, from);
    // complex amplitudes of e^{iωt}: x = a cos + b sin → a − i b
    let (mr, mi, lr, li) = (ma, -mb, la, -lb);
    let den = mr * mr + mi * mi;
    if den <= 0.0 {
        return None;
    }
    let (hr, hi) = ((lr * mr + li * mi) / den, (li * mr - lr * mi) / den);
    // H/(H − 1)
    let (dr, di) = (hr - 1.0, hi);
    let dd = dr * dr + di * di;
    if dd <= 0.0 {
        return None;
    }
    let (qr, qi) = ((hr * dr + hi * di) / dd, (hi * dr - hr * di) / dd);
    let w = 2.0 * std::f64::consts::PI * inp.frequency_hz;
    let scale = inertia * w * w;
    Some((scale * qr, scale * qi / w))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A link 28× stiffer than its excitation (fresh rig 570's 40 °C run: J 5.4e-3 kg·m², K 7.28 N·m/rad,
    /// C 0.074 N·m·s/rad, 0.21 Hz at 2.5 kHz for 32 s, noise 8.4e-4 rad): its damping is a quadrature
    /// part of 4e-6 rad under the noise's 7e-6 rad. Where the estimate comes out negative the start
    /// keeps the response's stiffness and a damping of the noise's order, not the table's.
    #[test]
    fn a_stiff_links_response_keeps_its_stiffness_where_its_damping_reads_negative() {
        let (j, k, c, f, rate, seconds, amplitude, noise) =
            (5.366e-3, 7.28, 0.0743, 0.2111, 2500.0, 32.0, 0.2128, 8.4e-4);
        let w = 2.0 * std::f64::consts::PI * f;
        // the steady state's complex gain (K + iωC)/(K + iωC − Jω²)
        let (nr, ni) = (k, w * c);
        let (dr, di) = (k - j * w * w, w * c);
        let d2 = dr * dr + di * di;
        let (hr, hi) = ((nr * dr + ni * di) / d2, (ni * dr - nr * di) / d2);
        let n = (rate * seconds) as usize;
        let time: Vec<f64> = (0..n).map(|i| i as f64 / rate).collect();
        let motor: Vec<f64> = time.iter().map(|t| amplitude * (w * t).sin()).collect();
        let mut negative_seen = 0;
        for seed in 0..12 {
            let mut rng = super::super::synthetic::SplitMix::new(seed);
            let link: Vec<f64> = time
                .iter()
                .map(|t| amplitude * (hr * (w * t).sin() + hi * (w * t).cos()) + noise * rng.normal())
                .collect();
            let input = SimInput {
                time: time.clone(),
                motor: motor.clone(),
                housing_k: vec![313.15; n],
                frequency_hz: f,
                link_inertia: Some(j),
                link0: 0.0,
                com_distance: 0.0,
                initial_link_speed: 0.0,
                after_gap: false,
                housing_before: Default::default(),
                substeps: 1,
            };
            let raw = frequency_response(&input, &link, j).expect("a response");
            assert!((raw.0 / k - 1.0).abs() < 0.05, "seed {seed}: K {} for {k}", raw.0);
            let (ks, cs) = physical_response(raw).expect("a start");
            assert!(ks == raw.0 && cs > 0.0 && cs == raw.1.abs(), "seed {seed}: {raw:?} → {ks}, {cs}");
            negative_seen += usize::from(raw.1 < 0.0);
        }
        // the case this guards: some of these draws read the damping negative
        assert!(negative_seen > 0, "no draw read the damping negative");
        assert_eq!(physical_response((-2.0, 0.1)), None);
        assert_eq!(physical_response((3.0, f64::NAN)), None);
    }

    /// A gravity-like share (a constant and a slope in the angle) beside a load's and a stiffness's
    /// columns is theirs to take over: nothing is left of it. A share none of the other columns can
    /// make is left whole, and the effect's own columns are not the others.
    #[test]
    fn a_share_the_other_columns_can_make_leaves_nothing_beyond_them() {
        let n = 2000;
        let angle: Vec<f64> = (0..n).map(|i| (i as f64 * 0.01).sin()).collect();
        let sign: Vec<f64> = (0..n).map(|i| (i as f64 * 0.01).cos().signum()).collect();
        // columns: a load (1), a stiffness (the angle, in other units), the effect's level
        let jac = DMatrix::from_fn(n, 3, |i, j| [1.0, 1e4 * angle[i], 0.3 + 0.5 * angle[i]][j]);
        let share: Vec<f64> = (0..n).map(|i| 2.0 * jac[(i, 2)]).collect();
        let beyond = share_beyond_the_rest(&jac, &share, &[2]);
        assert!(rms(&beyond) < 1e-9 * rms(&share), "left {} of {}", rms(&beyond), rms(&share));
        // a friction-like share: the constant and the angle take only their projections of it
        let friction: Vec<f64> = sign.iter().map(|s| 0.1 * s).collect();
        let left = share_beyond_the_rest(&jac, &friction, &[2]);
        assert!(rms(&left) > 0.5 * rms(&friction), "left {} of {}", rms(&left), rms(&friction));
        // with every column the effect's own there is nothing to project on
        assert_eq!(share_beyond_the_rest(&jac, &share, &[0, 1, 2]), share);
    }

    /// A friction-like share that holds for each stroke (alternating sign every `stroke` samples)
    /// at `level`, and a residual of white noise of rms 1 (a fixed linear congruential stream).
    fn strokes_in_noise(level: f64, stroke: usize, n: usize) -> (Vec<f64>, Vec<f64>) {
        let share = (0..n).map(|i| if (i / stroke).is_multiple_of(2) { level } else { -level }).collect();
        let mut state = 12345u64;
        let mut uniform = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        // a sum of 12 uniforms less 6: near-Gaussian, variance 1
        let residual = (0..n).map(|_| (0..12).map(|_| uniform()).sum::<f64>() - 6.0).collect();
        (share, residual)
    }

    #[test]
    fn a_stroke_long_offset_under_the_noise_is_visible_at_its_own_time_scale() {
        // a fifth of the noise, sample by sample; strokes of 400 samples hold over a lag of 100
        // (their autocorrelation 1 − lag/200 falls to ½ there), over which the noise's block means
        // fall to a tenth of it and the offset's stay
        let (share, residual) = strokes_in_noise(0.2, 400, 40_000);
        let seen = own_time_scale_share(&share, &residual, &[20_000, 20_000], 5);
        assert!(seen > 1.6 && seen < 2.4, "own time scale share {seen}");
        // the same offset for a tenth of the samples: fewer blocks, the same answer within its spread
        let short = own_time_scale_share(&share[..4000], &residual[..4000], &[4000], 5);
        assert!(short > 1.4 && short < 2.8, "own time scale share over 4000 samples {short}");
        // a share that changes every sample has no time scale to average over: sample by sample
        let (flicker, _) = strokes_in_noise(0.2, 1, 40_000);
        let white = own_time_scale_share(&flicker, &residual, &[40_000], 5);
        assert!((white - 0.2).abs() < 0.01, "a flickering share {white}");
        // the block stops at ten per fitted parameter: a share constant over the whole record is
        // averaged over 40 000 / (10 × 400) = 10 samples, not over the record
        let constant = vec![0.2; 40_000];
        let capped = own_time_scale_share(&constant, &residual, &[40_000], 400);
        assert!(capped > 0.4 && capped < 0.9, "a constant share over capped blocks {capped}");
        // visibility takes the larger of the two readings: the flicker by its samples against the
        // noise (0.2 / 0.1 = 2), the strokes by their time scale (2 against 0.2 / 1 sample by sample)
        let lengths = [20_000, 20_000];
        let by_samples = visibility(&flicker, 0.1, &residual, &lengths, 5);
        assert!((by_samples - 2.0).abs() < 1e-9, "a flickering share over a tenth of its noise {by_samples}");
        let by_strokes = visibility(&share, 1.0, &residual, &lengths, 5);
        assert!((by_strokes - seen).abs() < 1e-12, "strokes {by_strokes} against their time scale's {seen}");
    }

    /// A mean over 10 clusters of 100 samples whose residuals share one offset per cluster: the
    /// sandwich's variance is the clusters' (about 1/9), the white σ²/n a hundred times smaller;
    /// with every sample its own cluster the two agree.
    #[test]
    fn residuals_shared_within_a_cluster_widen_the_sandwich() {
        let n = 1000;
        let jac = DMatrix::from_element(n, 1, 1.0);
        let r: Vec<f64> =
            (0..n).map(|k| if (k / 100) % 2 == 0 { 1.0 } else { -1.0 } + 0.01 * (k as f64).sin()).collect();
        let white = r.iter().map(|x| x * x).sum::<f64>() / (n as f64 * (n - 1) as f64);
        let clustered = cluster_sandwich(&jac, &r, &(0..n).map(|k| k / 100).collect::<Vec<_>>())[(0, 0)];
        let single = cluster_sandwich(&jac, &r, &(0..n).collect::<Vec<_>>())[(0, 0)];
        assert!((clustered - 1.0 / 9.0).abs() < 0.01 && clustered > 50.0 * white, "{clustered} against {white}");
        assert!((single - white).abs() < 0.01 * white, "{single} against {white}");
    }
}
