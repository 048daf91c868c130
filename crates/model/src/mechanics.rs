//! Motor inertia, transmission (spring bank ∥ Kelvin–Voigt PCL ∥ optional Maxwell branch) and
//! output link (docs/physics.md §2):
//!
//!   J_m θm'' + B_m θm' = τ_motor − τ_t
//!   J_l θl'' + B_l θl' = τ_t + τ_load + τ_friction + τ_gravity
//!   τ_t = (K_s r_s² + K'(T)) Δ + C(T) Δ' + K_M (Δ − q),   q' = (Δ − q)/λ,   Δ = θm − θl
//!
//! State x = [θm, θm', θl, θl', q]. With every effect linear the system is x' = A x + B u with u
//! held over a step (FMI co-simulation inputs are), so the step is exact: x⁺ = e^{Ah} x + Γ u, with
//! both blocks from one matrix exponential. A depends on the PCL temperature, so the exponentials
//! are tabulated on a 1/8 K lattice and interpolated ([`PropagatorTable`]): no exponential is
//! rebuilt while the PCL heats or cools. Gravity and friction are smooth nonlinear link torques:
//! an exponential Runge–Kutta step ([`EtdStep`]) keeps the linear part exact and treats them
//! explicitly, with error control on dyadic sub-steps. Backlash switches the transmission between
//! three linear states ([`Contact`]: free, engaged, clipped; ElastoBacklash adds capped); a step
//! takes the exact (or exponential Runge–Kutta) step of the state it starts in, and one that may
//! hold a contact event ([`may_leave`]) or starts capped is integrated by an adaptive
//! Dormand–Prince 5(4) step with error control.

use nalgebra::{SMatrix, SVector};

use super::material::TABLE_TEMPERATURES_C;
use super::params::{BacklashLaw, LinkDrive, MotorDrive, Params, Transmission, ViscoelasticLaw};

pub const N_STATE: usize = 5;
pub type State = SVector<f64, N_STATE>;
pub const MOTOR_ANGLE: usize = 0;
pub const MOTOR_SPEED: usize = 1;
pub const LINK_ANGLE: usize = 2;
pub const LINK_SPEED: usize = 3;
pub const MAXWELL_DEFLECTION: usize = 4;

/// Transmission coefficients at one PCL temperature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coefficients {
    /// E'(T), Pa.
    pub storage_modulus: f64,
    /// E''(T), Pa.
    pub loss_modulus: f64,
    /// K_s r_s² + K'(T), N·m/rad.
    pub stiffness: f64,
    /// C(T) = K''(T)/ω at the excitation frequency (hysteretic law), or the Prony law's dashpot ηκ,
    /// N·m·s/rad.
    pub damping: f64,
    /// K_M of the relaxing branch: the Maxwell effect's, or the Prony law's E_1(T)κ, N·m/rad. Its
    /// relaxation time is [`Params::branch_relaxation_time`].
    pub maxwell_stiffness: f64,
}

impl Coefficients {
    pub const ZERO: Coefficients =
        Coefficients { storage_modulus: 0.0, loss_modulus: 0.0, stiffness: 0.0, damping: 0.0, maxwell_stiffness: 0.0 };

    pub fn at(p: &Params, pcl_temperature_k: f64) -> Self {
        let kappa = p.modulus_to_torsion();
        let omega = 2.0 * std::f64::consts::PI * p.excitation_frequency;
        let temperature_c = pcl_temperature_k - super::params::ZERO_CELSIUS;
        match p.viscoelastic_law {
            ViscoelasticLaw::Hysteretic => {
                let (e1, e2) = p.material_table.moduli_pa(temperature_c);
                let (e1, e2) = (e1 * p.storage_modulus_scale, e2 * p.loss_modulus_scale);
                Coefficients {
                    storage_modulus: e1,
                    loss_modulus: e2,
                    stiffness: p.spring_torsional_stiffness() + e1 * kappa,
                    damping: e2 * kappa / omega,
                    maxwell_stiffness: p.maxwell_stiffness,
                }
            }
            ViscoelasticLaw::Prony => {
                let law = p.prony_law();
                let row = law.at(temperature_c);
                let (e1, e2) = row.complex_modulus(law.relaxation_time, omega);
                Coefficients {
                    storage_modulus: e1,
                    loss_modulus: e2,
                    stiffness: p.spring_torsional_stiffness() + row.e_inf * kappa,
                    damping: row.viscosity * kappa,
                    maxwell_stiffness: row.e_branch * kappa,
                }
            }
        }
    }

    /// Re and Im/ω of the transmission's complex stiffness at the excitation frequency,
    /// including the relaxing branch: the K_eff and C_eff the paper estimates.
    pub fn effective(&self, p: &Params) -> (f64, f64) {
        let w = 2.0 * std::f64::consts::PI * p.excitation_frequency;
        let lambda = p.branch_relaxation_time();
        let wl = w * lambda;
        let d = 1.0 + wl * wl;
        (self.stiffness + self.maxwell_stiffness * wl * wl / d, self.damping + self.maxwell_stiffness * lambda / d)
    }
}

/// Inputs held over a step: motor torque and load torque, N·m.
pub type Drive = SVector<f64, 2>;

const N_AUG: usize = N_STATE + 2;

/// e^{Ah} and Γ = ∫₀ʰ e^{As} ds B for one step length and coefficient set.
#[derive(Clone, Debug)]
pub struct Propagator {
    pub phi: SMatrix<f64, N_STATE, N_STATE>,
    pub gamma: SMatrix<f64, N_STATE, 2>,
}

/// How the transmission couples motor and link over a stretch of time: engaged (springs, PCL and
/// Maxwell branch, the nominal model), or, with backlash, free inside the play or clipped at its
/// edge (the spring–damper would pull). In every case the mechanics is linear; with backlash the
/// engaged and clipped states are linear in coordinates shifted by the play's half-width on θm
/// (see [`Contact`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Coupling {
    Engaged,
    /// No torque; the branch relaxes (q' = −q/λ here: built without moduli; with a relaxing branch
    /// the element rests at r q and q recovers as [`recover_unloaded`], applied after the step).
    Free,
    /// No torque; the Maxwell branch follows the deflection beyond the play (q' = (Δ̃ − q)/λ).
    Clipped,
    /// ElastoBacklash with the damper's torque capped by the spring's: τ = 2τ_c, twice the springs
    /// (K and K_M) and no damping.
    Capped,
}

/// A and B of the linear system (valid when `Params::mechanics_is_linear`).
pub fn linear_system(p: &Params, c: &Coefficients) -> (SMatrix<f64, N_STATE, N_STATE>, SMatrix<f64, N_STATE, 2>) {
    linear_system_with(p, c, Coupling::Engaged)
}

/// A and B of the mechanics with the transmission coupled as `coupling` (free and clipped: the
/// link torque alone, without the transmission's).
pub fn linear_system_with(
    p: &Params,
    c: &Coefficients,
    coupling: Coupling,
) -> (SMatrix<f64, N_STATE, N_STATE>, SMatrix<f64, N_STATE, 2>) {
    let (k, d, km, lam) = match coupling {
        Coupling::Engaged => (c.stiffness, c.damping, c.maxwell_stiffness, p.branch_relaxation_time()),
        Coupling::Capped => (2.0 * c.stiffness, 0.0, 2.0 * c.maxwell_stiffness, p.branch_relaxation_time()),
        Coupling::Free | Coupling::Clipped => (0.0, 0.0, 0.0, p.branch_relaxation_time()),
    };
    let mut a = SMatrix::<f64, N_STATE, N_STATE>::zeros();
    let mut b = SMatrix::<f64, N_STATE, 2>::zeros();
    if p.transmission == Transmission::Rigid {
        // one body: both angle rows integrate the same speed, both speed rows the same law
        let (j, damping) = (p.motor_inertia + p.link_inertia, p.motor_damping + p.link_damping);
        let driven = p.motor_drive == MotorDrive::Torque;
        for (angle, speed) in [(MOTOR_ANGLE, MOTOR_SPEED), (LINK_ANGLE, LINK_SPEED)] {
            a[(angle, MOTOR_SPEED)] = 1.0;
            if driven {
                a[(speed, MOTOR_SPEED)] = -damping / j;
                b[(speed, 0)] = 1.0 / j;
                b[(speed, 1)] = 1.0 / j;
            }
        }
        a[(MAXWELL_DEFLECTION, MAXWELL_DEFLECTION)] = -1.0 / lam;
        return (a, b);
    }
    // τ_t = (k + km) θm + d ωm − (k + km) θl − d ωl − km q
    let tau_row = [k + km, d, -(k + km), -d, -km];
    a[(MOTOR_ANGLE, MOTOR_SPEED)] = 1.0;
    if p.motor_drive == MotorDrive::Torque {
        for (j, t) in tau_row.iter().enumerate() {
            a[(MOTOR_SPEED, j)] = -t / p.motor_inertia;
        }
        a[(MOTOR_SPEED, MOTOR_SPEED)] -= p.motor_damping / p.motor_inertia;
        b[(MOTOR_SPEED, 0)] = 1.0 / p.motor_inertia;
    }
    a[(LINK_ANGLE, LINK_SPEED)] = 1.0;
    for (j, t) in tau_row.iter().enumerate() {
        a[(LINK_SPEED, j)] = p.per_link_inertia(*t);
    }
    a[(LINK_SPEED, LINK_SPEED)] -= p.per_link_inertia(p.link_damping);
    b[(LINK_SPEED, 1)] = p.per_link_inertia(1.0);
    if coupling != Coupling::Free {
        a[(MAXWELL_DEFLECTION, MOTOR_ANGLE)] = 1.0 / lam;
        a[(MAXWELL_DEFLECTION, LINK_ANGLE)] = -1.0 / lam;
    }
    a[(MAXWELL_DEFLECTION, MAXWELL_DEFLECTION)] = -1.0 / lam;
    (a, b)
}

impl Propagator {
    pub fn new(p: &Params, c: &Coefficients, h: f64) -> Self {
        Propagator::with(p, c, h, Coupling::Engaged)
    }

    pub fn with(p: &Params, c: &Coefficients, h: f64, coupling: Coupling) -> Self {
        let (a, b) = linear_system_with(p, c, coupling);
        let mut m = SMatrix::<f64, N_AUG, N_AUG>::zeros();
        m.fixed_view_mut::<N_STATE, N_STATE>(0, 0).copy_from(&(a * h));
        m.fixed_view_mut::<N_STATE, 2>(0, N_STATE).copy_from(&(b * h));
        let e = m.exp();
        Propagator {
            phi: e.fixed_view::<N_STATE, N_STATE>(0, 0).into_owned(),
            gamma: e.fixed_view::<N_STATE, 2>(0, N_STATE).into_owned(),
        }
    }
}

/// Spacing of the temperature lattice on which [`PropagatorTable`] tabulates propagators, K. A
/// binary fraction, so the material table's rows (22, 40, 50, 60 °C), where the moduli's log-linear
/// pieces meet, fall on nodes and no interpolation stencil straddles a kink.
pub const PROPAGATOR_LATTICE: f64 = 0.125;

/// Significant decimal digits of the step length that key the propagator cache, see
/// [`canonical_step`].
const STEP_KEY_DIGITS: i32 = 10;

/// Rounds step lengths to [`STEP_KEY_DIGITS`] significant decimal digits within one decade
/// [lo, hi) of powers of ten; a cache of the last two decades makes the common case a multiply, a
/// round and a divide (two: fmpy's steps t(k+1) − t(k) straddle 1 ms, a power of ten).
#[derive(Clone, Copy, Debug)]
pub struct StepKeys {
    decades: [Decade; 2],
}

#[derive(Clone, Copy, Debug)]
struct Decade {
    lo: f64,
    hi: f64,
    /// 10^digits: key = round(h·scale)/scale (digits ≥ 0) or round(h/scale)·scale (digits < 0).
    scale: f64,
    below_one_digit: bool,
}

impl Default for StepKeys {
    fn default() -> Self {
        let empty = Decade { lo: f64::NAN, hi: f64::NAN, scale: 1.0, below_one_digit: false };
        StepKeys { decades: [empty; 2] }
    }
}

impl StepKeys {
    /// The step length a propagator is built for: `h` rounded to 10 significant decimal digits
    /// (relative change ≤ 5e-10), so 1 ms keys as exactly 1e-3. A function of `h` alone (the
    /// decade cache only saves work), so a restored run keys its cache as the original did.
    /// Masters that pass h as t(k+1) − t(k) (fmpy) send steps that differ from 1 ms in the last
    /// bits (by up to 3e-11 relative at t = 200 s); they all land on the key 1e-3, and
    /// [`Model::step`](crate::Model::step) covers the remainder h − key to first order (an Euler
    /// step of ≤ 5e-13 s, error ~ (h − key)² |A|² |x|).
    pub fn key(&mut self, h: f64) -> f64 {
        let in_decade = |d: &Decade| h >= d.lo && h < d.hi;
        if !in_decade(&self.decades[0]) {
            if !(h > 0.0 && h.is_finite()) {
                return h;
            }
            if !in_decade(&self.decades[1]) {
                self.decades[1] = Decade::of(h);
            }
            self.decades.swap(0, 1);
        }
        let d = &self.decades[0];
        // h·scale < 10^STEP_KEY_DIGITS < 2^52: adding and taking away 2^52 rounds it to an
        // integer (ties to even) without a libm call.
        const SHIFT: f64 = 4_503_599_627_370_496.0;
        if d.below_one_digit {
            ((h / d.scale + SHIFT) - SHIFT) * d.scale
        } else {
            ((h * d.scale + SHIFT) - SHIFT) / d.scale
        }
    }
}

impl Decade {
    #[inline(never)]
    fn of(h: f64) -> Self {
        let mut e = h.log10().floor() as i32;
        // log10 may be an ulp off at powers of ten: settle the decade by comparison.
        while 10f64.powi(e) > h {
            e -= 1;
        }
        while 10f64.powi(e + 1) <= h {
            e += 1;
        }
        let digits = STEP_KEY_DIGITS - 1 - e;
        Decade {
            lo: 10f64.powi(e),
            hi: 10f64.powi(e + 1),
            scale: 10f64.powi(digits.abs()),
            below_one_digit: digits < 0,
        }
    }
}

/// [`StepKeys::key`] without a cache.
pub fn canonical_step(h: f64) -> f64 {
    StepKeys::default().key(h)
}

const N_PROP: usize = N_STATE * N_AUG;
const N_NODE: usize = N_PROP + 3;

/// [Φ | Γ] (5×7, row-major) of one step, followed by the transmission's stiffness and damping it
/// was built for.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearStep {
    v: [f64; N_NODE],
}

impl LinearStep {
    pub const ZERO: LinearStep = LinearStep { v: [0.0; N_NODE] };

    pub fn new(p: &Params, c: &Coefficients, h: f64) -> Self {
        LinearStep::with(p, c, h, Coupling::Engaged)
    }

    pub fn with(p: &Params, c: &Coefficients, h: f64, coupling: Coupling) -> Self {
        let pr = Propagator::with(p, c, h, coupling);
        let mut v = [0.0; N_NODE];
        for i in 0..N_STATE {
            for j in 0..N_STATE {
                v[i * N_AUG + j] = pr.phi[(i, j)];
            }
            v[i * N_AUG + N_STATE] = pr.gamma[(i, 0)];
            v[i * N_AUG + N_STATE + 1] = pr.gamma[(i, 1)];
        }
        v[N_PROP] = c.stiffness;
        v[N_PROP + 1] = c.damping;
        v[N_PROP + 2] = c.maxwell_stiffness;
        LinearStep { v }
    }

    /// K_s r_s² + K'(T) and C(T) this step was built (or interpolated) for.
    pub fn coefficients(&self) -> Coefficients {
        Coefficients {
            stiffness: self.v[N_PROP],
            damping: self.v[N_PROP + 1],
            maxwell_stiffness: self.v[N_PROP + 2],
            ..Coefficients::ZERO
        }
    }

    pub fn apply(&self, x: &State, u: &Drive) -> State {
        let v = [x[0], x[1], x[2], x[3], x[4], u[0], u[1]];
        let mut y = State::zeros();
        for i in 0..N_STATE {
            let row = &self.v[i * N_AUG..(i + 1) * N_AUG];
            y[i] = row.iter().zip(v).map(|(a, b)| a * b).sum();
        }
        y
    }
}

/// What a [`PropagatorTable`] holds at each node: values built for one coefficient set and step,
/// interpolated entry by entry.
pub trait Tabulated: Clone + std::fmt::Debug {
    /// Every value zero (a [`FineCell`]'s entries before its first read).
    const ZERO: Self;
    fn build(p: &Params, c: &Coefficients, h: f64) -> Self;
    fn values(&self) -> &[f64];
    fn values_mut(&mut self) -> &mut [f64];
}

impl Tabulated for LinearStep {
    const ZERO: Self = LinearStep::ZERO;
    fn build(p: &Params, c: &Coefficients, h: f64) -> Self {
        LinearStep::new(p, c, h)
    }
    fn values(&self) -> &[f64] {
        &self.v
    }
    fn values_mut(&mut self) -> &mut [f64] {
        &mut self.v
    }
}

// An ETDRK4 step needs the whole state only at its end; its stages feed the link torque alone,
// which reads the link angle and speed. So the half-step blocks are kept for those two rows only
// ("link rows": θl, θl'), and the second stage's e^{Ah/2}(e^{Ah/2}x + Γ(h/2)u + q n) comes from
// e^{Ah}x + Γ(h)u and r = e^{Ah/2} q: 73 entries to interpolate instead of 98, and a third of the
// arithmetic.
const E_FULL: usize = 0; // e^{Ah}, 5×5
const G_FULL: usize = 25; // Γ(h), 5×2
const E_HALF_LINK: usize = 35; // e^{Ah/2}, link rows, 2×5
const G_HALF_LINK: usize = 45; // Γ(h/2), link rows, 2×2
const Q_HALF_LINK: usize = 49; // q = (h/2) φ1(Ah/2) b, link rows
const R_HALF_LINK: usize = 51; // r = e^{Ah/2} q, link rows
const P1_LINK: usize = 53; // h φ1(Ah) b, link rows
const F1: usize = 55; // h (φ1 − 3φ2 + 4φ3)(Ah) b
const F2: usize = 60; // h (φ2 − 2φ3)(Ah) b
const F3: usize = 65; // h (−φ2 + 4φ3)(Ah) b
const COEFFS: usize = 70; // stiffness, damping, Maxwell stiffness
const LENGTH: usize = 73; // h
const N_ETD: usize = 74;
/// The state's link rows, in the order the link-row blocks hold them.
const LINK_ROWS: [usize; 2] = [LINK_ANGLE, LINK_SPEED];

/// Coefficients of one exponential Runge–Kutta step (Cox–Matthews ETDRK4 with the ETDRK3 of the
/// same family as its embedded error estimate) for x' = A x + B u + b n(x), where the linear
/// transmission is A, B (exact) and the smooth nonlinear link torque n (gravity, tanh-smoothed
/// friction) enters through b = e_θl'/J_l. Built from the matrix exponential of a 10×10
/// augmented matrix (e^{Ah}, Γ and the φ-functions applied to b) at h/2, squared for h.
#[derive(Clone, Debug, PartialEq)]
pub struct EtdStep {
    v: [f64; N_ETD],
}

/// The 10×10 augmented matrix [`phi_blocks`] exponentiates, whole: [[Ah, Bh, h b, 0, 0], [0, S]].
/// For references and benchmarks that take its exponential with a general routine.
pub fn phi_augmented(
    a: &SMatrix<f64, N_STATE, N_STATE>,
    b: &SMatrix<f64, N_STATE, 2>,
    link: f64,
    h: f64,
) -> SMatrix<f64, 10, 10> {
    let mut m = SMatrix::<f64, 10, 10>::zeros();
    m.fixed_view_mut::<N_STATE, N_STATE>(0, 0).copy_from(&(a * h));
    m.fixed_view_mut::<N_STATE, 2>(0, N_STATE).copy_from(&(b * h));
    m[(LINK_SPEED, 7)] = link * h;
    m[(7, 8)] = 1.0;
    m[(8, 9)] = 1.0;
    m
}

/// The first [`N_STATE`] rows of [e^{Ah}, Γ(h), h φ1(Ah) b, h φ2(Ah) b, h φ3(Ah) b]: the
/// exponential of the 10×10 augmented matrix M = [[Ah, Bh, h b, 0, 0], [0, S]] whose last five
/// rows are zero but for the φ-chain's shift S (unit entries (7, 8) and (8, 9)).
///
/// By scaling and squaring a Taylor series on those rows alone: M's lower rows are known, so a
/// product R·M of top rows costs a 5×5 by 5×10 product plus two column shifts, and the squaring is
/// [`doubled`]. A general exponential of the whole 10×10 matrix (nalgebra's Padé 13, with its norm
/// estimates, an LU solve and full 10×10 squarings) did the same work without the structure; it
/// was most of the cost of a linearised friction step, which is built afresh for each new friction
/// slope. The series runs at h/2^s with η = max(‖(Ah)²‖₁^{1/2}, ‖(Ah)³‖₁^{1/3})/2^s ≤
/// [`TAYLOR_SCALED_NORM`] (Al-Mohy and Higham's norms of powers: ‖Ah‖₁ alone, which the motor's
/// K/J_m inflates far past the spectral radius, asks for more squarings, each doubling the error;
/// on a capped spell of 20 ms it erred by 2.9e-13 where η errs by 2.3e-14) and stops once a term
/// no longer moves any column's largest entry.
fn phi_blocks(a: &SMatrix<f64, N_STATE, N_STATE>, b: &SMatrix<f64, N_STATE, 2>, link: f64, h: f64) -> PhiRows {
    let one_norm =
        |m: &SMatrix<f64, N_STATE, N_STATE>| (0..N_STATE).map(|j| m.column(j).abs().sum()).fold(0.0, f64::max);
    let ah = a * h;
    let ah2 = ah * ah;
    let eta = one_norm(&ah2).sqrt().max(one_norm(&(ah2 * ah)).cbrt());
    // Halving h is exact (a power of two); a non-finite η leaves the series to carry the
    // non-finite entries to the caller's checks, as the general routine's did.
    let doublings =
        if eta.is_finite() && eta > TAYLOR_SCALED_NORM { (eta / TAYLOR_SCALED_NORM).log2().ceil() as i32 } else { 0 };
    let top: PhiRows = phi_augmented(a, b, link, h * 0.5f64.powi(doublings)).fixed_rows::<N_STATE>(0).into_owned();
    let mut sum = PhiRows::zeros();
    let mut term = PhiRows::zeros();
    for i in 0..N_STATE {
        sum[(i, i)] = 1.0;
        term[(i, i)] = 1.0;
    }
    for k in 1..=TAYLOR_TERMS_MAX {
        // term·M/k: the top rows through M's top rows, the chain's columns through S.
        let square = term.fixed_columns::<N_STATE>(0) * top;
        let mut next = square;
        for i in 0..N_STATE {
            next[(i, 8)] += term[(i, 7)];
            next[(i, 9)] += term[(i, 8)];
        }
        term = next / k as f64;
        sum += term;
        let settled = (0..10).all(|j| {
            let largest = sum.column(j).amax();
            term.column(j).amax() <= largest * f64::EPSILON * 0.5
        });
        if settled && k >= 2 {
            break;
        }
    }
    (0..doublings).fold(sum, |rows, _| doubled(&rows))
}

/// η at which [`phi_blocks`] sums its series. Measured against a 60-digit exponential (mpmath) on
/// the 216 cases of `phi_blocks_equal_the_general_exponential` (2026-12-07): the largest column-
/// relative error at ½, 1, 2, 3 and 4 was 1.2e-13, 4.2e-14, 2.3e-14, 2.3e-14 and 1.5e-14 without
/// a stiff friction slope (nalgebra's: 8.6e-14), and 1.1e-11, 5.3e-12, 2.6e-12, 1.6e-12 and
/// 1.6e-12 with one (nalgebra's: 2.2e-12). Past 2 the errors shrink little, while each doubling of
/// η lengthens the series.
const TAYLOR_SCALED_NORM: f64 = 2.0;

/// A cap on [`phi_blocks`]' Taylor terms: at η = 2 the 40th is 2^40/40! ≈ 1e-36 of the first.
const TAYLOR_TERMS_MAX: usize = 40;

/// The first [`N_STATE`] rows of [`phi_blocks`] at 2h from those at h, by squaring (a product
/// instead of a second exponential). With the chain's unit entries written as 1/h, the augmented
/// matrix is h·N for one N, so its exponential at 2h is the square of that at h; undoing the
/// scaling divides the φ2 and φ3 columns by 2 and 4. The other rows of the exponential are known:
/// identity rows for the inputs, and e^S = [[1, 1, ½], [0, 1, 1], [0, 0, 1]] for the chain's shift S.
fn doubled(half: &PhiRows) -> PhiRows {
    let mut h = [[0.0; 10]; N_STATE];
    for (i, row) in h.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = half[(i, j)];
        }
    }
    let mut full = PhiRows::zeros();
    for (i, r) in h.iter().enumerate() {
        let mut acc = [0.0; 10];
        for (k, hk) in h.iter().enumerate() {
            let a = r[k];
            for j in 0..10 {
                acc[j] += a * hk[j];
            }
        }
        acc[5] += r[5];
        acc[6] += r[6];
        acc[7] += r[7];
        acc[8] += r[7] + r[8];
        acc[9] += 0.5 * r[7] + r[8] + r[9];
        acc[8] *= 0.5;
        acc[9] *= 0.25;
        for (j, v) in acc.iter().enumerate() {
            full[(i, j)] = *v;
        }
    }
    full
}

impl Tabulated for EtdStep {
    const ZERO: Self = EtdStep::ZERO;
    fn build(p: &Params, c: &Coefficients, h: f64) -> Self {
        EtdStep::with(p, c, h, Coupling::Engaged)
    }
    fn values(&self) -> &[f64] {
        &self.v
    }
    fn values_mut(&mut self) -> &mut [f64] {
        &mut self.v
    }
}

impl EtdStep {
    /// The step for the mechanics coupled as `coupling`.
    pub fn with(p: &Params, c: &Coefficients, h: f64, coupling: Coupling) -> Self {
        let (a, b) = linear_system_with(p, c, coupling);
        let half = phi_blocks(&a, &b, p.per_link_inertia(1.0), 0.5 * h);
        EtdStep::from_rows(&half, &doubled(&half), c, h)
    }

    /// The step for the mechanics coupled as `coupling` with `damping` more link damping in its
    /// linear part (an exponential Rosenbrock step: the friction's slope at the step's start,
    /// [`friction_linearisation`], taken out of the explicit stages). Built afresh, one matrix
    /// exponential, for the step it is used in.
    pub fn with_link_damping(p: &Params, c: &Coefficients, h: f64, coupling: Coupling, damping: f64) -> Self {
        let (mut a, b) = linear_system_with(p, c, coupling);
        a[(LINK_SPEED, LINK_SPEED)] -= p.per_link_inertia(damping);
        let half = phi_blocks(&a, &b, p.per_link_inertia(1.0), 0.5 * h);
        EtdStep::from_rows(&half, &doubled(&half), c, h)
    }

    /// [`EtdStep::with_link_damping`]'s damping on a grid: the nearest multiple of
    /// [`LINEARISED_DAMPING_GRID`]·J_l/h (at least one), as (multiple, damping). Steps on the same
    /// grid point share one matrix exponential ([`crate::Model`] keeps them). The friction slope's
    /// distance from the grid point, at most half a spacing, goes to the explicit stages, as the
    /// slope's change within the step already does. None for a link whose speed is prescribed (no
    /// inertia to scale by).
    pub fn linearised_damping_on_grid(p: &Params, h: f64, damping: f64) -> Option<(u64, f64)> {
        let spacing = LINEARISED_DAMPING_GRID / (h * p.per_link_inertia(1.0));
        let multiple = (damping / spacing).round().max(1.0);
        (spacing.is_finite() && spacing > 0.0 && multiple.is_finite() && multiple < u64::MAX as f64)
            .then_some((multiple as u64, multiple * spacing))
    }

    /// The step of length h from the first [`N_STATE`] rows of [`phi_blocks`] at h/2 and h.
    pub fn from_rows(half: &PhiRows, full: &PhiRows, c: &Coefficients, h: f64) -> Self {
        let mut v = [0.0; N_ETD];
        for i in 0..N_STATE {
            for j in 0..N_STATE {
                v[E_FULL + i * N_STATE + j] = full[(i, j)];
            }
            for j in 0..2 {
                v[G_FULL + i * 2 + j] = full[(i, N_STATE + j)];
            }
            let (p1, p2, p3) = (full[(i, 7)], full[(i, 8)], full[(i, 9)]);
            v[F1 + i] = p1 - 3.0 * p2 + 4.0 * p3;
            v[F2 + i] = p2 - 2.0 * p3;
            v[F3 + i] = -p2 + 4.0 * p3;
        }
        for (r, &i) in LINK_ROWS.iter().enumerate() {
            for j in 0..N_STATE {
                v[E_HALF_LINK + r * N_STATE + j] = half[(i, j)];
            }
            for j in 0..2 {
                v[G_HALF_LINK + r * 2 + j] = half[(i, N_STATE + j)];
            }
            v[Q_HALF_LINK + r] = half[(i, 7)];
            v[R_HALF_LINK + r] = (0..N_STATE).map(|j| half[(i, j)] * half[(j, 7)]).sum::<f64>();
            v[P1_LINK + r] = full[(i, 7)];
        }
        v[COEFFS] = c.stiffness;
        v[COEFFS + 1] = c.damping;
        v[COEFFS + 2] = c.maxwell_stiffness;
        v[LENGTH] = h;
        EtdStep { v }
    }
}

/// The first [`N_STATE`] rows of [`phi_blocks`] (the rest are known: identity rows for the inputs,
/// e^N of the φ-chain's shift N).
pub type PhiRows = SMatrix<f64, N_STATE, 10>;

/// The engaged transmission's [`phi_blocks`] rows at key/2^ℓ for ℓ = 0..=levels + 1, from one
/// exponential at key/2^(levels+1), doubled level by level ([`doubled`]): every level of one
/// node for one exponential. The numbers are a function of (p, c, key, levels) alone, so a table
/// filled from them does not depend on which of its levels were built first.
pub fn phi_chain(p: &Params, c: &Coefficients, key: f64, levels: u32) -> Vec<PhiRows> {
    let (a, b) = linear_system_with(p, c, Coupling::Engaged);
    let deepest = phi_blocks(&a, &b, p.per_link_inertia(1.0), key / (1u64 << (levels + 1)) as f64);
    let mut rows = vec![PhiRows::zeros(); levels as usize + 2];
    rows[levels as usize + 1] = deepest;
    for l in (0..=levels as usize).rev() {
        rows[l] = doubled(&rows[l + 1]);
    }
    rows
}

/// The embedded estimate measures the third-order solution. With Stribeck friction it has been
/// seen to pass steps whose error is larger (tests/physics.rs, torque-driven at 60 °C: 2.6e-6
/// rad over 20 s at `solver_tolerance`, under 1e-7 at 1/100 of it), so the exponential
/// integrator asks 100× more of it then (and not [`ETD_ESTIMATE_FACTOR`]); gravity and Coulomb
/// friction alone stay under 1e-7 rad at 2·`solver_tolerance`.
const STRIBECK_TOLERANCE_FACTOR: f64 = 0.01;

/// Without Stribeck friction an exponential Runge–Kutta step is accepted when its embedded
/// estimate |x4 − x3| is at most this many times `solver_tolerance` (relative to 1 + |x|). The
/// estimate is the third-order solution's local error, while the step keeps the fourth-order one
/// (local extrapolation), so it overstates the kept solution's error. 2 lets most millisecond
/// steps of the bench's "all three while heating" pass whole instead of as two 0.5 ms steps
/// (4 626 → 3 850 instructions per doStep over 200 s); tests/physics.rs measured every regime
/// as before (gravity 5.0e-11 → 5.4e-11 rad, Coulomb friction 2.6e-8 → 3.9e-8 rad, the rest
/// unchanged to three digits). 16 was measured too: friction moved to 2.9e-7 rad for 1 % fewer
/// instructions, so the factor stays at 2.
const ETD_ESTIMATE_FACTOR: f64 = 2.0;

/// The smooth nonlinear link torque the exponential integrator treats explicitly, N·m.
pub fn smooth_link_torque(p: &Params, x: &State) -> f64 {
    link_friction(p, x[LINK_SPEED]) + link_gravity(p, x[LINK_ANGLE])
}

/// [`smooth_link_torque`] at the stages of one step: gravity's sine by angle addition from the
/// step's start angle θ0, sin(θ0 + d) = sin θ0 cos d + cos θ0 sin d, with Taylor series of the
/// small offset d ([`sin_cos_small`], for |d| < 0.05 rad, where the stages of a millisecond step
/// lie), so a step takes at most one `sin_cos` instead of five sines. The friction's parameters
/// are borrowed: a start is copied from step to step, and only its angle, sine and cosine change.
#[derive(Clone, Copy, Debug)]
struct StageTorque<'a> {
    friction: &'a Friction,
    theta0: f64,
    sin0: f64,
    cos0: f64,
    amplitude: f64,
    offset: f64,
    /// The friction's slope the step's linear part carries as link damping (N·m·s/rad; 0 but in a
    /// linearised step, [`EtdStep::with_link_damping`]): the stages then see n(x) + d·θl'.
    linearised: f64,
}

/// Where an exponential Runge–Kutta step starts: the stage torque about the link angle there and
/// its value n(x) ([`smooth_link_torque`], to the bit). An accepted step's end is the next step's
/// start, so the caller builds it once for both: the next step's first stage and the contact
/// checks' rates ([`derivative_with_link_torque`]).
#[derive(Clone, Copy, Debug)]
pub struct StepStart<'a> {
    torque: StageTorque<'a>,
    n: f64,
}

impl<'a> StepStart<'a> {
    /// `friction` is [`Friction::new`] of `p`.
    pub fn new(p: &Params, x: &State, friction: &'a Friction) -> Self {
        let torque = StageTorque::new(p, x[LINK_ANGLE], friction);
        let n = torque.at_theta0(x[LINK_SPEED]);
        StepStart { torque, n }
    }

    /// [`StepStart::new`] with gravity's sine and cosine from `anchor` ([`SineAnchor::sin_cos`]),
    /// which moves to x.
    pub fn anchored(p: &Params, x: &State, anchor: &mut SineAnchor, friction: &'a Friction) -> Self {
        let mut torque = StageTorque::new_without_gravity(x[LINK_ANGLE], friction);
        if p.gravity_link_mass != 0.0 {
            torque = torque.with_gravity(p, anchor.sin_cos(x[LINK_ANGLE] - p.gravity_offset));
        }
        let n = torque.at_theta0(x[LINK_SPEED]);
        StepStart { torque, n }
    }

    /// n(x): gravity and friction on the link at the step's start, N·m.
    pub fn link_torque(&self) -> f64 {
        self.n
    }

    /// This start for a step whose linear part carries `damping` of the friction's slope
    /// ([`EtdStep::with_link_damping`]): its stages see the rest, n(x) + damping·θl'. `link_speed`
    /// is the start's.
    pub fn linearised(&self, damping: f64, link_speed: f64) -> Self {
        let torque = StageTorque { linearised: damping, ..self.torque };
        StepStart { torque, n: self.n + damping * link_speed }
    }

    /// The start of the next step, at the end x1 of this one: gravity's sine and cosine there by
    /// angle addition from this start's (the series [`StageTorque::at`] uses; rounding apart the
    /// same numbers as [`StepStart::new`], without a `sin_cos`), or afresh beyond its range.
    pub fn advanced(&self, p: &Params, x1: &State) -> Self {
        let t = &self.torque;
        let d = x1[LINK_ANGLE] - t.theta0;
        if t.amplitude == 0.0 || d.is_nan() || d.abs() >= 0.05 {
            return StepStart::new(p, x1, t.friction);
        }
        let (sin_d, cos_d) = sin_cos_small(d);
        let torque = StageTorque {
            theta0: x1[LINK_ANGLE],
            sin0: t.sin0 * cos_d + t.cos0 * sin_d,
            cos0: t.cos0 * cos_d - t.sin0 * sin_d,
            ..*t
        };
        let n = torque.at_theta0(x1[LINK_SPEED]);
        StepStart { torque, n }
    }
}

/// Gravity's sine and cosine (libm's) at an angle φa near where exponential Runge–Kutta sub-steps
/// start (the link angle less `gravity_offset`). A sub-step starting within 0.1 rad of it takes
/// its sine and cosine by one angle addition from it ([`sin_cos_medium`]) instead of a libm
/// `sin_cos`, the largest single cost of a sub-step's set-up; beyond, libm's, and the anchor moves
/// there. One addition from a libm value, never a chain of them, so the error stays an ulp or two
/// however long the run. Part of the model's state (as the adaptive step is): the numbers depend
/// on where the anchor is, so a restored state must restore it to continue bit-identically.
#[derive(Clone, Copy, Debug)]
pub struct SineAnchor {
    pub angle: f64,
    pub sin: f64,
    pub cos: f64,
}

impl PartialEq for SineAnchor {
    /// Bit for bit: [`SineAnchor::NONE`] is NaN and equals itself.
    fn eq(&self, o: &Self) -> bool {
        [self.angle, self.sin, self.cos].map(f64::to_bits) == [o.angle, o.sin, o.cos].map(f64::to_bits)
    }
}

impl SineAnchor {
    /// No anchor yet: the next sub-step takes libm's sine.
    pub const NONE: SineAnchor = SineAnchor { angle: f64::NAN, sin: f64::NAN, cos: f64::NAN };

    /// sin φ and cos φ (the anchor moves to φ when it is 0.1 rad or more away, or none).
    pub fn sin_cos(&mut self, phi: f64) -> (f64, f64) {
        let d = phi - self.angle;
        if d.abs() < 0.1 {
            let (sin_d, cos_d) = sin_cos_medium(d);
            return (self.sin * cos_d + self.cos * sin_d, self.cos * cos_d - self.sin * sin_d);
        }
        let (sin, cos) = phi.sin_cos();
        *self = SineAnchor { angle: phi, sin, cos };
        (sin, cos)
    }

    /// Whether the anchor is none, or an angle with its sine and cosine (to 1e-9: a saved state's check).
    pub fn is_consistent(&self) -> bool {
        if *self == SineAnchor::NONE {
            return true;
        }
        let (s, c) = self.angle.sin_cos();
        self.angle.is_finite() && (s - self.sin).abs() <= 1e-9 && (c - self.cos).abs() <= 1e-9
    }
}

/// sin d and cos d by their Taylor series to d⁹ and d¹⁰: for |d| < 0.1 rad the next terms are
/// < 3e-19 and < 3e-21.
fn sin_cos_medium(d: f64) -> (f64, f64) {
    let d2 = d * d;
    let d4 = d2 * d2;
    let d8 = d4 * d4;
    let sin_d = d * (((1.0 - d2 * (1.0 / 6.0)) + d4 * (1.0 / 120.0 - d2 * (1.0 / 5040.0))) + d8 * (1.0 / 362_880.0));
    let cos_d =
        ((1.0 - d2 * 0.5) + d4 * (1.0 / 24.0 - d2 * (1.0 / 720.0))) + d8 * (1.0 / 40_320.0 - d2 * (1.0 / 3_628_800.0));
    (sin_d, cos_d)
}

/// sin d and cos d by their Taylor series to d⁷ and d⁸: for |d| < 0.05 rad the next terms are
/// < 6e-18 and < 3e-20, under a tenth of an ulp of the unit-sized sines and cosines they are
/// combined with. Summed in Estrin's order (d², d⁴ side by side rather than nested): the stages of
/// an exponential Runge–Kutta step wait on these in turn, so the chain's depth is the cost.
fn sin_cos_small(d: f64) -> (f64, f64) {
    let d2 = d * d;
    let d4 = d2 * d2;
    let sin_d = d * ((1.0 - d2 * (1.0 / 6.0)) + d4 * (1.0 / 120.0 - d2 * (1.0 / 5040.0)));
    let cos_d = (1.0 - d2 * 0.5) + d4 * ((1.0 / 24.0 - d2 * (1.0 / 720.0)) + d4 * (1.0 / 40_320.0));
    (sin_d, cos_d)
}

impl<'a> StageTorque<'a> {
    fn new(p: &Params, theta0: f64, friction: &'a Friction) -> Self {
        let torque = StageTorque::new_without_gravity(theta0, friction);
        if p.gravity_link_mass == 0.0 {
            return torque;
        }
        torque.with_gravity(p, (theta0 - p.gravity_offset).sin_cos())
    }

    /// With gravity, given the sine and cosine of θ0 less `gravity_offset`.
    fn with_gravity(self, p: &Params, (sin0, cos0): (f64, f64)) -> Self {
        StageTorque { sin0, cos0, amplitude: p.gravity_torque_amplitude(), offset: p.gravity_offset, ..self }
    }

    /// Friction alone (gravity's amplitude 0), about θ0.
    fn new_without_gravity(theta0: f64, friction: &'a Friction) -> Self {
        StageTorque { friction, theta0, sin0: 0.0, cos0: 0.0, amplitude: 0.0, offset: 0.0, linearised: 0.0 }
    }

    /// [`StageTorque::at`] at the link angle θ0 itself (offset d = 0: the series give sin d = 0
    /// and cos d = 1 exactly, so this is the same number but for the sign of a zero).
    #[inline(always)]
    fn at_theta0(&self, link_speed: f64) -> f64 {
        let friction = self.friction_at(link_speed);
        if self.amplitude == 0.0 {
            return friction;
        }
        friction - self.amplitude * self.sin0
    }

    /// The friction less what the linear part carries of it.
    #[inline(always)]
    fn friction_at(&self, speed: f64) -> f64 {
        let f = self.friction.at(speed);
        if self.linearised == 0.0 {
            return f;
        }
        f + self.linearised * speed
    }

    /// At the link angle and speed `[θl, θl']`.
    #[inline(always)]
    fn at(&self, [angle, speed]: [f64; 2]) -> f64 {
        let friction = self.friction_at(speed);
        if self.amplitude == 0.0 {
            return friction;
        }
        let d = angle - self.theta0;
        if d.is_nan() || d.abs() >= 0.05 {
            // link_gravity
            return friction + -self.amplitude * (angle - self.offset).sin();
        }
        let (sin_d, cos_d) = sin_cos_small(d);
        friction - self.amplitude * (self.sin0 * cos_d + self.cos0 * sin_d)
    }
}

impl EtdStep {
    pub const ZERO: EtdStep = EtdStep { v: [0.0; N_ETD] };

    /// The step's length, s.
    pub fn length(&self) -> f64 {
        self.v[LENGTH]
    }

    /// K_s r_s² + K'(T) and C(T) this step was built (or interpolated) for.
    pub fn coefficients(&self) -> Coefficients {
        Coefficients {
            stiffness: self.v[COEFFS],
            damping: self.v[COEFFS + 1],
            maxwell_stiffness: self.v[COEFFS + 2],
            ..Coefficients::ZERO
        }
    }

    /// Row `i` of M x + G u for the 5-column block at `m` and the 2-column block at `g`.
    #[inline(always)]
    fn row(&self, m: usize, g: usize, i: usize, x: &State, u: &Drive) -> f64 {
        let v = &self.v;
        let row = &v[m + i * N_STATE..m + (i + 1) * N_STATE];
        let mut acc = v[g + 2 * i] * u[0] + v[g + 2 * i + 1] * u[1];
        for j in 0..N_STATE {
            acc += row[j] * x[j];
        }
        acc
    }

    fn column(&self, col: usize) -> State {
        State::from_column_slice(&self.v[col..col + N_STATE])
    }

    /// A link-row pair (θl, θl'): `base` plus the link-row column at `col` times `s`.
    #[inline(always)]
    fn link_plus(&self, base: [f64; 2], col: usize, s: f64) -> [f64; 2] {
        [base[0] + self.v[col] * s, base[1] + self.v[col + 1] * s]
    }

    /// One ETDRK4 step from x; returns the new state and the scaled error estimate (≤ 1: accept).
    /// `start` is [`StepStart::new`] at x (its link angle and speed: the motor angle may be shifted).
    pub fn step(&self, p: &Params, x: &State, u: &Drive, start: &StepStart) -> (State, f64) {
        let (torque, n_x) = (&start.torque, start.n);
        // e^{Ah}x + Γ(h)u, every row
        let mut ex0 = State::zeros();
        for i in 0..N_STATE {
            ex0[i] = self.row(E_FULL, G_FULL, i, x, u);
        }
        let ex0_link = [ex0[LINK_ANGLE], ex0[LINK_SPEED]];
        // a = e^{Ah/2}x + Γ(h/2)u + q n_x
        let a0 = [self.row(E_HALF_LINK, G_HALF_LINK, 0, x, u), self.row(E_HALF_LINK, G_HALF_LINK, 1, x, u)];
        let a = self.link_plus(a0, Q_HALF_LINK, n_x);
        let n_a = torque.at(a);
        // b = e^{Ah/2}x + Γ(h/2)u + q n_a: a with the forcing swapped.
        let b = self.link_plus(a0, Q_HALF_LINK, n_a);
        let n_b = torque.at(b);
        // c = e^{Ah/2}a + Γ(h/2)u + q (2n_b − n_x) = e^{Ah}x + Γ(h)u + r n_x + q (2n_b − n_x)
        let c = self.link_plus(self.link_plus(ex0_link, R_HALF_LINK, n_x), Q_HALF_LINK, 2.0 * n_b - n_x);
        let n_c = torque.at(c);
        let x4 = ex0 + self.column(F1) * n_x + self.column(F2) * (2.0 * (n_a + n_b)) + self.column(F3) * n_c;
        // ETDRK3: b3 = e^{Ah}x + Γu + hφ1 b (2 n_a − n_x); x3 = e^{Ah}x + Γu + f1 n_x + 4 f2 n_a + f3 n(b3)
        let b3 = self.link_plus(ex0_link, P1_LINK, 2.0 * n_a - n_x);
        let n_b3 = torque.at(b3);
        // the embedded estimate x4 − x3
        let diff = self.column(F2) * (2.0 * (n_b - n_a)) + self.column(F3) * (n_c - n_b3);
        // Smoothed friction is steep near zero link speed (slope (F_c + F_s)/v_s): where a stage
        // sees that zone, or the speed changes sign, the step must resolve it (h·slope/J_l ≤ ½)
        // before the embedded estimate means anything.
        if p.coulomb_friction != 0.0 || p.stribeck_friction != 0.0 {
            let zone = SIGN_SATURATION * p.friction_smoothing_velocity;
            let speeds = [x[LINK_SPEED], a[1], b[1], c[1], x4[LINK_SPEED], b3[1]];
            let slope = steepest_friction_slope(p);
            if torque.linearised != 0.0 {
                // a linearised step: what the stages still see explicitly is the slope's change
                // from the start's; it must keep h·|Δslope|/J_l within LINEARISED_SLOPE_LIMIT
                let h_per_j = p.per_link_inertia(self.length());
                let off = speeds.iter().any(|&v| {
                    let change = torque.friction.slope(v) - torque.linearised;
                    let moved = h_per_j * change.abs();
                    moved.is_nan() || moved > LINEARISED_SLOPE_LIMIT
                });
                if off {
                    return (x4, f64::INFINITY);
                }
            } else {
                let near =
                    speeds.iter().any(|v| v.abs() < zone) || speeds.iter().any(|v| v.signum() != speeds[0].signum());
                if near && self.length() * slope > 0.1 {
                    return (x4, f64::INFINITY);
                }
            }
        }
        // a linearised step's estimate sees only the remainder's variation: held to the tighter
        // tolerance as Stribeck friction's is (measured with every near-rest step linearised: the
        // torque-driven Coulomb regime of tests/physics.rs 8.0e-6 rad at 2·tolerance, 6.9e-7 at
        // 1/100; it is explicit now, 3.9e-8)
        let tol = if p.stribeck_friction != 0.0 || torque.linearised != 0.0 {
            STRIBECK_TOLERANCE_FACTOR
        } else {
            ETD_ESTIMATE_FACTOR
        } * p.solver_tolerance;
        let mut err: f64 = 0.0;
        for i in 0..N_STATE {
            let scale = tol * (1.0 + x[i].abs().max(x4[i].abs()));
            err = err.max((diff[i] / scale).abs());
        }
        if !err.is_finite() || !x4.iter().all(|v| v.is_finite()) {
            err = f64::INFINITY;
        }
        (x4, err)
    }
}

/// x' = A x + B u of the linear mechanics (what [`derivative`] gives with every nonlinear effect
/// off), for the last sliver of a step whose length differs from its propagator's key.
pub fn linear_rate(p: &Params, c: &Coefficients, x: &State, u: &Drive) -> State {
    if p.transmission == Transmission::Rigid {
        // one body: with every nonlinear effect off, `derivative` is the linear law
        return derivative(p, c, x, u);
    }
    let delta = x[MOTOR_ANGLE] - x[LINK_ANGLE];
    let rate = x[MOTOR_SPEED] - x[LINK_SPEED];
    let q = x[MAXWELL_DEFLECTION];
    let tau = element_torque(c, delta, rate, q);
    let motor_accel = match p.motor_drive {
        MotorDrive::Torque => (u[0] - p.motor_damping * x[MOTOR_SPEED] - tau) / p.motor_inertia,
        MotorDrive::PrescribedAngle => 0.0,
    };
    let link_accel = p.per_link_inertia(tau + u[1] - p.link_damping * x[LINK_SPEED]);
    State::from([x[MOTOR_SPEED], motor_accel, x[LINK_SPEED], link_accel, (delta - q) / p.branch_relaxation_time()])
}

/// Exact linear steps of one length tabulated on a lattice of the PCL temperature
/// ([`PROPAGATOR_LATTICE`]) between the material table's first and last rows, nodes built lazily
/// (one matrix exponential each, never again while the parameters and the step stay). A read
/// evaluates a cubic through four nodes of the same log-linear piece at the two ends of the fine
/// cell ([`FINE_CELLS_PER_NODE`] per lattice spacing) holding the temperature, and interpolates
/// linearly between them; the two ends are kept ([`FineCell`]), so a PCL heating or cooling
/// through a cell pays two multiply-adds per entry instead of the cubic's seven. Outside the
/// table's rows the moduli are held, so the end nodes are exact there. The cubic's error is
/// O(Δ⁴), below 1e-9 of the entries; the linear read's is δ²/8 times the entries' second
/// derivative in temperature, ≈ (δ·α)²/8 relative with α ≤ 0.23/K the moduli's steepest
/// log-slope (E'' between 50 and 60 °C, Table 2), 1.0e-7 at δ = 1/256 K: under the 10 µK lattice
/// rounding the Dormand–Prince path takes (1.2e-6), and tests/physics.rs measures the whole step
/// against a fine reference while heating and cooling.
#[derive(Clone, Debug)]
pub struct PropagatorTable<N: Tabulated> {
    h: f64,
    nodes: Vec<Option<N>>,
}

/// Fine cells per [`PROPAGATOR_LATTICE`] spacing: a power of two, so every fine node's position on
/// the lattice (m/32) is exact and the material table's rows are fine nodes too.
pub const FINE_CELLS_PER_NODE: usize = 32;

/// One fine cell of a [`PropagatorTable`] as read last: the cubic's values at its lower and upper
/// fine nodes and their difference. Functions of the cell index alone, so a read is the same
/// number whatever was read before (a restored state continues bit-identically).
#[derive(Clone, Debug)]
pub struct FineCell<N> {
    /// Index of the lower fine node; `usize::MAX` before the first read.
    m: usize,
    lo: N,
    hi: N,
    diff: N,
}

impl<N: Tabulated> Default for FineCell<N> {
    fn default() -> Self {
        FineCell { m: usize::MAX, lo: N::ZERO, hi: N::ZERO, diff: N::ZERO }
    }
}

/// The PCL temperature clamped to the tables' range (the material table's rows, 22–60 °C): the
/// moduli are held beyond it, so a table reads the same there; a cache keyed by this temperature
/// then stays valid while a PCL above 60 °C heats on. NaN stays NaN.
pub fn table_temperature(t_kelvin: f64) -> f64 {
    let lo = super::params::ZERO_CELSIUS + TABLE_TEMPERATURES_C[0];
    let hi = super::params::ZERO_CELSIUS + TABLE_TEMPERATURES_C[3];
    if t_kelvin < lo {
        lo
    } else if t_kelvin > hi {
        hi
    } else {
        t_kelvin
    }
}

fn node_celsius(n: usize) -> f64 {
    TABLE_TEMPERATURES_C[0] + n as f64 * PROPAGATOR_LATTICE
}

/// The PCL temperature of a [`PropagatorTable`]'s node `n`, K.
pub fn node_temperature(n: usize) -> f64 {
    super::params::ZERO_CELSIUS + node_celsius(n)
}

/// Node index of each material table row (exact: the rows are whole multiples of the lattice
/// apart, checked by a test).
const ROW_NODES: [usize; 4] = {
    let mut r = [0; 4];
    let mut i = 0;
    while i < 4 {
        r[i] = ((TABLE_TEMPERATURES_C[i] - TABLE_TEMPERATURES_C[0]) / PROPAGATOR_LATTICE) as usize;
        i += 1;
    }
    r
};

/// Where a [`PropagatorTable`] is read: one node (at or beyond the table's ends), or the fine cell
/// from fine node `m` to `m + 1`, a fraction `frac` into it.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Position {
    Node(usize),
    Fine { m: usize, frac: f64 },
}

/// A cubic through four nodes from the first, with these weights.
#[derive(Clone, Copy, Debug)]
struct Stencil {
    j: usize,
    w: [f64; 4],
}

impl<N: Tabulated> PropagatorTable<N> {
    pub fn new(h: f64) -> Self {
        PropagatorTable { h, nodes: vec![None; ROW_NODES[3] + 1] }
    }

    pub fn step_length(&self) -> f64 {
        self.h
    }

    fn position(t_kelvin: f64) -> Position {
        let t = t_kelvin - super::params::ZERO_CELSIUS;
        let x = (t - TABLE_TEMPERATURES_C[0]) / PROPAGATOR_LATTICE;
        if x.is_nan() || x <= 0.0 {
            return Position::Node(0);
        }
        if x >= ROW_NODES[3] as f64 {
            return Position::Node(ROW_NODES[3]);
        }
        let xf = x * FINE_CELLS_PER_NODE as f64;
        // xf > 0, so truncation is floor; m + 1 ≤ the last row's fine node since x < rows[3].
        let m = xf as usize;
        let frac = xf - m as f64;
        // Exactly on a node (a PCL held at 40 or 50 °C), the fine read is that node itself: its
        // stencil's weights are one 1 and three 0 (a Lagrange cubic at its own node) and the
        // fraction 0, so the same numbers (but for the sign of a zero) from one node instead of the
        // four or five the two fine ends need. A step length met once (a logger's jittered
        // timestamps) builds a table per step.
        if frac == 0.0 && m.is_multiple_of(FINE_CELLS_PER_NODE) {
            return Position::Node(m / FINE_CELLS_PER_NODE);
        }
        Position::Fine { m, frac }
    }

    /// The cubic at fine node `m`: four nodes of the log-linear piece [rows[k], rows[k+1]] that
    /// holds the lattice interval [i, i+1] above it (at a row, the piece above; the moduli are
    /// continuous there, so either piece's cubic gives the row's node to rounding).
    fn stencil(m: usize) -> Stencil {
        let rows = ROW_NODES;
        let x = m as f64 / FINE_CELLS_PER_NODE as f64;
        let i = m / FINE_CELLS_PER_NODE;
        let k = if i < rows[1] {
            0
        } else if i < rows[2] {
            1
        } else {
            2
        };
        let j = i.saturating_sub(1).clamp(rows[k], rows[k + 1] - 3);
        let s = x - j as f64;
        let (s1, s2, s3) = (s - 1.0, s - 2.0, s - 3.0);
        const SIXTH: f64 = 1.0 / 6.0;
        Stencil { j, w: [-s1 * s2 * s3 * SIXTH, 0.5 * s * s2 * s3, -0.5 * s * s1 * s3, s * s1 * s2 * SIXTH] }
    }

    /// The nodes a read at `t_kelvin` needs: the node itself, or both fine ends' stencils.
    fn needed(t_kelvin: f64) -> std::ops::Range<usize> {
        match Self::position(t_kelvin) {
            Position::Node(j) => j..j + 1,
            Position::Fine { m, .. } => Self::stencil(m).j..Self::stencil(m + 1).j + 4,
        }
    }

    /// The nodes a read at `t_kelvin` needs that are not built yet.
    pub fn missing(&self, t_kelvin: f64) -> Vec<usize> {
        Self::needed(t_kelvin).filter(|&k| self.nodes[k].is_none()).collect()
    }

    pub fn has(&self, n: usize) -> bool {
        self.nodes[n].is_some()
    }

    /// Sets node `n`, built for the moduli at [`node_temperature`]`(n)` and this table's step.
    pub fn insert(&mut self, n: usize, node: N) {
        self.nodes[n] = Some(node);
    }

    /// Builds the nodes a read at `t_kelvin` needs (parameters as the table was built with).
    pub fn build(&mut self, p: &Params, t_kelvin: f64) {
        let h = self.h;
        for n in Self::needed(t_kelvin) {
            self.nodes[n].get_or_insert_with(|| N::build(p, &Coefficients::at(p, node_temperature(n)), h));
        }
    }

    /// The step at PCL temperature `t_kelvin` into `out`, through `cell` (the fine cell read last,
    /// updated when the temperature has left it). False, `out` unchanged, when a node it needs is
    /// not built: reads the table only, so a table shared with clones is not copied.
    pub fn try_at(&self, t_kelvin: f64, cell: &mut FineCell<N>, out: &mut N) -> bool {
        let (m, frac) = match Self::position(t_kelvin) {
            Position::Node(j) => {
                return match &self.nodes[j] {
                    Some(n) => {
                        out.clone_from(n);
                        true
                    }
                    None => false,
                };
            }
            Position::Fine { m, frac } => (m, frac),
        };
        if cell.m != m && !self.fill(m, cell) {
            return false;
        }
        let out = out.values_mut();
        let n = out.len();
        let (lo, diff) = (&cell.lo.values()[..n], &cell.diff.values()[..n]);
        for i in 0..n {
            out[i] = lo[i] + frac * diff[i];
        }
        true
    }

    /// Sets `cell` to the fine cell from fine node `m`, reusing its shared end when it was a
    /// neighbour; false, `cell` unchanged, when a node is missing.
    #[inline(never)]
    fn fill(&self, m: usize, cell: &mut FineCell<N>) -> bool {
        let (a, b) = (Self::stencil(m), Self::stencil(m + 1));
        if !self.nodes[a.j..b.j + 4].iter().all(Option::is_some) {
            return false;
        }
        if cell.m.checked_add(1) == Some(m) {
            std::mem::swap(&mut cell.lo, &mut cell.hi);
            self.eval(&b, &mut cell.hi);
        } else if m.checked_add(1) == Some(cell.m) {
            std::mem::swap(&mut cell.lo, &mut cell.hi);
            self.eval(&a, &mut cell.lo);
        } else {
            self.eval(&a, &mut cell.lo);
            self.eval(&b, &mut cell.hi);
        }
        let (lo, hi, diff) = (cell.lo.values(), cell.hi.values(), cell.diff.values_mut());
        for ((d, h), l) in diff.iter_mut().zip(hi).zip(lo) {
            *d = h - l;
        }
        cell.m = m;
        true
    }

    /// The cubic `stencil` of built nodes into `out`.
    fn eval(&self, stencil: &Stencil, out: &mut N) {
        let node = |k: usize| match &self.nodes[k] {
            Some(n) => n,
            None => unreachable!("built before"),
        };
        let (j, w) = (stencil.j, stencil.w);
        let out = out.values_mut();
        let n = out.len();
        // Equal lengths up front, so the loop below has no bounds checks and vectorises.
        let (n0, n1, n2, n3) = (
            &node(j).values()[..n],
            &node(j + 1).values()[..n],
            &node(j + 2).values()[..n],
            &node(j + 3).values()[..n],
        );
        for i in 0..n {
            out[i] = w[0] * n0[i] + w[1] * n1[i] + w[2] * n2[i] + w[3] * n3[i];
        }
    }
}

impl PropagatorTable<EtdStep> {
    /// The transmission coefficients the step at `t_kelvin` holds (what [`PropagatorTable::try_at`]
    /// gives them, to the bit), from the built nodes alone: two entries instead of the whole step.
    /// None when a node it needs is not built.
    pub fn coefficients_at(&self, t_kelvin: f64) -> Option<Coefficients> {
        let entry = |k: usize, i: usize| self.nodes[k].as_ref().map(|n| n.v[i]);
        let cubic = |s: &Stencil, i: usize| {
            let (j, w) = (s.j, s.w);
            Some(w[0] * entry(j, i)? + w[1] * entry(j + 1, i)? + w[2] * entry(j + 2, i)? + w[3] * entry(j + 3, i)?)
        };
        let value = |i: usize| match Self::position(t_kelvin) {
            Position::Node(j) => entry(j, i),
            Position::Fine { m, frac } => {
                let lo = cubic(&Self::stencil(m), i)?;
                let hi = cubic(&Self::stencil(m + 1), i)?;
                Some(lo + frac * (hi - lo))
            }
        };
        Some(Coefficients {
            stiffness: value(COEFFS)?,
            damping: value(COEFFS + 1)?,
            maxwell_stiffness: value(COEFFS + 2)?,
            ..Coefficients::ZERO
        })
    }
}

/// Transmitted torque τ_t and the relaxing branch's rate q', with backlash when enabled.
/// Backlash: no torque inside the play, and the spring–damper never pulls at its edges; under
/// [`BacklashLaw::ElastoBacklash`] the damping torque is also capped by the spring torque, as
/// Modelica's ElastoBacklash has it (docs/physics.md §10).
/// With a relaxing branch the play is centred on the unloaded element's rest deflection
/// ([`play_centre`]), so contact begins at zero spring torque.
pub fn transmission(p: &Params, c: &Coefficients, x: &State) -> (f64, f64) {
    let delta = x[MOTOR_ANGLE] - x[LINK_ANGLE];
    let q = x[MAXWELL_DEFLECTION];
    let lam = p.branch_relaxation_time();
    if p.backlash_width <= 0.0 {
        let rate = x[MOTOR_SPEED] - x[LINK_SPEED];
        let tau = element_torque(c, delta, rate, q);
        return (tau, (delta - q) / lam);
    }
    let Some(positive) = beyond_play(p, c, x) else {
        return (0.0, (play_centre(c, x) - q) / lam);
    };
    let (engaged, tau) = engaged_torque(p, c, x, positive);
    let tau = match p.backlash_law {
        BacklashLaw::Clipped => {
            if positive {
                tau.max(0.0)
            } else {
                tau.min(0.0)
            }
        }
        BacklashLaw::ElastoBacklash => {
            let (spring, damper) = spring_and_damper(c, engaged, x);
            elasto_backlash_torque(spring, damper, positive)
        }
    };
    (tau, (engaged - q) / lam)
}

/// Beyond the play, the element's spring torque τ_c = K Δ̃ + K_M (Δ̃ − q) and damper torque
/// τ_d = C Δ̃' at deflection Δ̃ = `engaged`.
fn spring_and_damper(c: &Coefficients, engaged: f64, x: &State) -> (f64, f64) {
    let spring = c.stiffness * engaged + c.maxwell_stiffness * (engaged - x[MAXWELL_DEFLECTION]);
    (spring, c.damping * (x[MOTOR_SPEED] - x[LINK_SPEED]))
}

/// Modelica's `Rotational.Components.ElastoBacklash` beyond the play: on the positive side
/// τ_c + min(τ_c, τ_d) while τ_c + τ_d > 0, else 0; on the negative τ_c + max(τ_c, τ_d) while
/// τ_c + τ_d < 0, else 0. (The MSL's special case of a play below 1e-10 rad is not reproduced.)
pub fn elasto_backlash_torque(spring: f64, damper: f64, positive: bool) -> f64 {
    if positive {
        if spring + damper <= 0.0 {
            0.0
        } else {
            spring + spring.min(damper)
        }
    } else if spring + damper >= 0.0 {
        0.0
    } else {
        spring + spring.max(damper)
    }
}

/// The element's torque K e + C e' + K_M (e − q) at deflection e (Δ, or Δ ∓ b/2 beyond a play)
/// and its rate e'.
#[inline(always)]
fn element_torque(c: &Coefficients, deflection: f64, rate: f64, q: f64) -> f64 {
    c.stiffness * deflection + c.damping * rate + c.maxwell_stiffness * (deflection - q)
}

/// The share r = K_M/(K + K_M) of the relaxing branch's deflection q at which the element rests
/// unloaded: inside the play no torque passes, K e + K_M (e − q) = 0, so e = r q (its own dashpot's
/// lag C/(K + K_M) neglected: docs/physics.md §10). 0 without a branch.
pub fn unloaded_share(c: &Coefficients) -> f64 {
    if c.maxwell_stiffness == 0.0 {
        0.0
    } else {
        branch_share(c)
    }
}

/// K_M/(K + K_M). Out of line: inlined, the compiler hoisted this division out of the contact
/// checks to the top of the exponential step, where it ran on every step of every regime, on the
/// bits of whatever coefficients were there (perf: the gravity regime 155 -> 185 ns per doStep).
#[inline(never)]
fn branch_share(c: &Coefficients) -> f64 {
    c.maxwell_stiffness / (c.stiffness + c.maxwell_stiffness)
}

/// The play's centre r q: the relative angle at which the unloaded element rests ([`unloaded_share`]).
/// The play is |Δ − r q| ≤ b/2; beyond it the element's deflection is Δ ∓ b/2, which equals r q at
/// the edges, where K (r q) + K_M (r q − q) = 0.
pub fn play_centre(c: &Coefficients, x: &State) -> f64 {
    unloaded_share(c) * x[MAXWELL_DEFLECTION]
}

/// The branch's deflection after `len` seconds inside the play from `q0`: q' = (r q − q)/λ, exactly
/// q0 e^{−(1−r) len/λ}. Inside the play q drives nothing else, so this replaces the free
/// propagator's q (built without moduli: e^{−len/λ}). Out of line, as [`branch_share`].
#[inline(never)]
pub fn recover_unloaded(p: &Params, c: &Coefficients, q0: f64, len: f64) -> f64 {
    q0 * (-(1.0 - unloaded_share(c)) * len / p.branch_relaxation_time()).exp()
}

/// The backlash's state at x (as [`transmission`] computes it): free inside the
/// play (|Δ − r q| ≤ b/2, [`play_centre`]), engaged beyond it while the spring–damper pushes (τ ≥ 0 on the positive side,
/// ≤ 0 on the negative), clipped while it would pull. Engaged and clipped are linear in
/// x̃ = x − [`Contact::offset`]·e_θm (Δ̃ = Δ ∓ b/2 is then θ̃m − θl), so between contact events a
/// step is exact: the engaged propagator, or the free or clipped one, applied to x̃ (free: with
/// q's recovery after it, [`recover_unloaded`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Contact {
    Free,
    Engaged {
        positive: bool,
    },
    Clipped {
        positive: bool,
    },
    /// ElastoBacklash only: pushing, with the damper's torque above the spring's (τ = 2τ_c).
    Capped {
        positive: bool,
    },
}

impl Contact {
    /// The shift of θm that makes the state linear: ±b/2 beyond the play, 0 inside it.
    pub fn offset(self, p: &Params) -> f64 {
        match self {
            Contact::Free => 0.0,
            Contact::Engaged { positive } | Contact::Clipped { positive } | Contact::Capped { positive } => {
                if positive {
                    0.5 * p.backlash_width
                } else {
                    -0.5 * p.backlash_width
                }
            }
        }
    }

    pub fn coupling(self) -> Coupling {
        match self {
            Contact::Free => Coupling::Free,
            Contact::Engaged { .. } => Coupling::Engaged,
            Contact::Clipped { .. } => Coupling::Clipped,
            Contact::Capped { .. } => Coupling::Capped,
        }
    }
}

/// Whether x lies inside the backlash's play (the transmission passes no torque, whatever the
/// moduli); `c` places the play ([`play_centre`]): without a relaxing branch any coefficients do.
pub fn in_play(p: &Params, c: &Coefficients, x: &State) -> bool {
    beyond_play(p, c, x).is_none()
}

/// None inside the play; beyond it, whether on its positive side (Δ past the centre).
fn beyond_play(p: &Params, c: &Coefficients, x: &State) -> Option<bool> {
    let from_centre = x[MOTOR_ANGLE] - x[LINK_ANGLE] - play_centre(c, x);
    (from_centre.abs() > 0.5 * p.backlash_width).then_some(from_centre > 0.0)
}

/// For x beyond the play on the side `positive`: the element's deflection Δ̃ = Δ ∓ b/2 and the
/// unclipped transmission torque there.
fn engaged_torque(p: &Params, c: &Coefficients, x: &State, positive: bool) -> (f64, f64) {
    let delta = x[MOTOR_ANGLE] - x[LINK_ANGLE];
    let half = 0.5 * p.backlash_width;
    let engaged = if positive { delta - half } else { delta + half };
    let rate = x[MOTOR_SPEED] - x[LINK_SPEED];
    let tau = element_torque(c, engaged, rate, x[MAXWELL_DEFLECTION]);
    (engaged, tau)
}

/// The backlash's [`Contact`] state at x with the moduli `c` (`backlash_width` > 0).
pub fn contact(p: &Params, c: &Coefficients, x: &State) -> Contact {
    let Some(positive) = beyond_play(p, c, x) else {
        return Contact::Free;
    };
    let (engaged, tau) = engaged_torque(p, c, x, positive);
    // as transmission() decides: the clipped law's τ.max(0) on the positive side (τ.min(0) on the
    // negative); ElastoBacklash's τ_c + τ_d > 0 (< 0) and which of τ_c, τ_d is the smaller
    let (pushes, capped) = match p.backlash_law {
        BacklashLaw::Clipped => (if positive { tau >= 0.0 } else { tau <= 0.0 }, false),
        BacklashLaw::ElastoBacklash => {
            let (spring, damper) = spring_and_damper(c, engaged, x);
            let sum = spring + damper;
            if positive {
                (sum > 0.0, damper > spring)
            } else {
                (sum < 0.0, damper < spring)
            }
        }
    };
    match (pushes, capped) {
        (false, _) => Contact::Clipped { positive },
        (true, true) => Contact::Capped { positive },
        (true, false) => Contact::Engaged { positive },
    }
}

/// Whether a step from x0 to x1 (length h, both in the contact state `mode`; each with its rate
/// r from [`derivative`], needed beyond the play only) may have left `mode` and come back within it: the functions whose sign changes
/// mark contact events (Δ − r q ∓ b/2 at the play's edges; the unclipped torque beyond them), checked on
/// the cubic Hermite interpolant of their end values and slopes. A trajectory grazing the edge of
/// the play inside one step is invisible at its ends; the caller then integrates the step
/// through the event instead. Conservative: an interior minimum within 1e-3 of the slopes' scale
/// of zero counts (the interpolant is exact for cubics; its error is O(h⁴), ~1e-6 of that scale at
/// 1 ms and the transmission's ~10 Hz).
pub fn may_leave(
    p: &Params,
    c: &Coefficients,
    mode: Contact,
    (x0, r0): (&State, &State),
    (x1, r1): (&State, &State),
    h: f64,
) -> bool {
    let rate = |x: &State| x[MOTOR_SPEED] - x[LINK_SPEED];
    let accel = |r: &State| r[MOTOR_SPEED] - r[LINK_SPEED];
    let half = 0.5 * p.backlash_width;
    let (mut d0, mut d1) = (x0[MOTOR_ANGLE] - x0[LINK_ANGLE], x1[MOTOR_ANGLE] - x1[LINK_ANGLE]);
    let (mut v0, mut v1) = (rate(x0), rate(x1));
    let share = unloaded_share(c);
    if share != 0.0 {
        // the edges move with the play's centre r q ([`play_centre`])
        let lam = p.branch_relaxation_time();
        let q_rate = |x: &State, r: &State| match mode {
            Contact::Free => (share - 1.0) * x[MAXWELL_DEFLECTION] / lam,
            _ => r[MAXWELL_DEFLECTION],
        };
        (d0, d1) = (d0 - share * x0[MAXWELL_DEFLECTION], d1 - share * x1[MAXWELL_DEFLECTION]);
        (v0, v1) = (v0 - share * q_rate(x0, r0), v1 - share * q_rate(x1, r1));
    }
    match mode {
        Contact::Free => {
            hermite_dips(half - d0, -h * v0, half - d1, -h * v1) || hermite_dips(half + d0, h * v0, half + d1, h * v1)
        }
        Contact::Engaged { positive } | Contact::Clipped { positive } | Contact::Capped { positive } => {
            let s = if positive { 1.0 } else { -1.0 };
            let off = s * half;
            if hermite_dips(s * (d0 - off), s * h * v0, s * (d1 - off), s * h * v1) {
                return true;
            }
            let (e0, t0) = engaged_torque(p, c, x0, positive);
            let (e1, t1) = engaged_torque(p, c, x1, positive);
            let km = c.maxwell_stiffness;
            let slope =
                |x: &State, r: &State| (c.stiffness + km) * rate(x) + c.damping * accel(r) - km * r[MAXWELL_DEFLECTION];
            // inside: s·τ ≥ 0 engaged and capped, s·τ < 0 clipped
            let g = if matches!(mode, Contact::Clipped { .. }) { -s } else { s };
            if hermite_dips(g * t0, g * h * slope(x0, r0), g * t1, g * h * slope(x1, r1)) {
                return true;
            }
            if p.backlash_law != BacklashLaw::ElastoBacklash || matches!(mode, Contact::Clipped { .. }) {
                return false;
            }
            // ElastoBacklash: τ_c − τ_d keeps its sign between engaged (s·(τ_c − τ_d) ≥ 0) and capped
            let (sp0, da0) = spring_and_damper(c, e0, x0);
            let (sp1, da1) = spring_and_damper(c, e1, x1);
            let cap_rate =
                |x: &State, r: &State| (c.stiffness + km) * rate(x) - c.damping * accel(r) - km * r[MAXWELL_DEFLECTION];
            let g = if matches!(mode, Contact::Capped { .. }) { -s } else { s };
            hermite_dips(g * (sp0 - da0), g * h * cap_rate(x0, r0), g * (sp1 - da1), g * h * cap_rate(x1, r1))
        }
    }
}

/// Whether the cubic p on [0, 1] with p(0) = g0 ≥ 0, p'(0) = m0, p(1) = g1 ≥ 0, p'(1) = m1 has an
/// interior minimum below 1e-3·(|m0| + |m1|).
fn hermite_dips(g0: f64, m0: f64, g1: f64, m1: f64) -> bool {
    if m0 >= 0.0 && m1 <= 0.0 {
        return false; // at most a maximum inside
    }
    // In the Hermite basis p = g0 h00 + g1 h01 + m0 h10 + m1 h11 with h00 + h01 = 1 and |h10|,
    // |h11| ≤ 4/27 on [0, 1]: p ≥ min(g0, g1) − 4/27 (|m0| + |m1|), so far from zero (the common
    // case: an edge or a torque sign not approached) no minimum needs finding.
    if g0.min(g1) > 0.16 * (m0.abs() + m1.abs()) {
        return false;
    }
    // p(s) = g0 + m0 s + b s² + c s³
    let b = 3.0 * (g1 - g0) - 2.0 * m0 - m1;
    let c = 2.0 * (g0 - g1) + m0 + m1;
    let margin = 1e-3 * (m0.abs() + m1.abs());
    let low = |s: f64| s > 0.0 && s < 1.0 && g0 + s * (m0 + s * (b + s * c)) < margin;
    // p'(s) = m0 + 2 b s + 3 c s²
    if c == 0.0 {
        return b != 0.0 && low(-m0 / (2.0 * b));
    }
    let disc = b * b - 3.0 * c * m0;
    if disc < 0.0 {
        return false;
    }
    // The roots of 3c s² + 2b s + m0 without cancellation (c may be tiny next to b: a cubic
    // that is nearly a parabola), from q = −(b + sign(b)·√disc): q/(3c) and m0/q.
    let q = -(b + disc.sqrt().copysign(b));
    low(q / (3.0 * c)) || low(m0 / q)
}

/// Link friction: Coulomb plus a Stribeck excess that fades above `stribeck_velocity`, with sign
/// smoothed by tanh over `friction_smoothing_velocity` (keeps the ODE Lipschitz).
/// Asymmetric friction (`coulomb_friction_asymmetry` a_c, `viscous_friction_asymmetry` a_v) adds
/// −a_c s² − a_v s v with s the smoothed sign: levels F_c ± a_c and B_l ± a_v for θl' ≷ 0.
pub fn link_friction(p: &Params, link_speed: f64) -> f64 {
    Friction::new(p).at(link_speed)
}

/// [`link_friction`]'s parameters, copied out of the parameter set.
#[derive(Clone, Copy, Debug)]
pub struct Friction {
    coulomb: f64,
    stribeck: f64,
    stribeck_velocity: f64,
    smoothing_velocity: f64,
    /// 20 smoothing velocities: beyond, the smoothed sign is ±1 ([`smooth_sign`]), no division needed.
    sign_zone: f64,
    coulomb_asymmetry: f64,
    viscous_asymmetry: f64,
    /// Some friction at all; asymmetric friction.
    active: bool,
    asymmetric: bool,
}

impl Friction {
    pub fn new(p: &Params) -> Self {
        Friction {
            coulomb: p.coulomb_friction,
            stribeck: p.stribeck_friction,
            stribeck_velocity: p.stribeck_velocity,
            smoothing_velocity: p.friction_smoothing_velocity,
            sign_zone: if p.friction_smoothing_velocity > 0.0 {
                SIGN_SATURATION * p.friction_smoothing_velocity
            } else {
                f64::INFINITY // the division's own ±inf or NaN below
            },
            coulomb_asymmetry: p.coulomb_friction_asymmetry,
            viscous_asymmetry: p.viscous_friction_asymmetry,
            active: p.coulomb_friction != 0.0
                || p.stribeck_friction != 0.0
                || p.coulomb_friction_asymmetry != 0.0
                || p.viscous_friction_asymmetry != 0.0,
            asymmetric: p.coulomb_friction_asymmetry != 0.0 || p.viscous_friction_asymmetry != 0.0,
        }
    }

    #[inline(always)]
    fn at(&self, link_speed: f64) -> f64 {
        if !self.active {
            return 0.0;
        }
        let level = if self.stribeck == 0.0 {
            self.coulomb
        } else {
            let s = link_speed / self.stribeck_velocity;
            self.coulomb + self.stribeck * (-s * s).exp()
        };
        let sign = if link_speed.abs() >= self.sign_zone {
            1.0_f64.copysign(link_speed) // what smooth_sign gives there, without the division
        } else {
            smooth_sign(link_speed / self.smoothing_velocity)
        };
        if !self.asymmetric {
            return -level * sign; // the terms below are +0 then
        }
        -level * sign - self.coulomb_asymmetry * sign * sign - self.viscous_asymmetry * sign * link_speed
    }

    /// −dτ_f/dθl' of the friction at `v`, N·m·s/rad (a damping where positive):
    /// −d[`Friction::at`]/dv in closed form, one tanh (a central difference took two): with the
    /// smoothed sign S = tanh(v/v_s), S' = (1 − S²)/v_s (0 beyond the sign's zone, where S is ±1
    /// exactly), and the level L = F_c + F_s e^{−(v/v_st)²},
    /// τ_f = −L S − a S² − b S v, so −τ_f' = L' S + L S' + 2a S S' + b (S' v + S).
    fn slope(&self, v: f64) -> f64 {
        if !self.active {
            return 0.0;
        }
        let (level, level_rate) = if self.stribeck == 0.0 {
            (self.coulomb, 0.0)
        } else {
            let s = v / self.stribeck_velocity;
            let e = self.stribeck * (-s * s).exp();
            (self.coulomb + e, -2.0 * s * e / self.stribeck_velocity)
        };
        let (sign, sign_rate) = if v.abs() >= self.sign_zone {
            (1.0_f64.copysign(v), 0.0)
        } else {
            let t = smooth_sign(v / self.smoothing_velocity);
            (t, (1.0 - t * t) / self.smoothing_velocity)
        };
        let symmetric = level_rate * sign + level * sign_rate;
        if !self.asymmetric {
            return symmetric;
        }
        symmetric + 2.0 * self.coulomb_asymmetry * sign * sign_rate + self.viscous_asymmetry * (sign_rate * v + sign)
    }
}

/// |s| beyond which tanh(s) rounds to ±1 ([`smooth_sign`]).
const SIGN_SATURATION: f64 = 20.0;

/// |s| below which [`smooth_sign`] takes tanh's series s − s³/3 (its next term is 2s⁵/15, a
/// relative 5e-16 here), where (1 − e)/(1 + e) would lose digits to the subtraction.
const SIGN_SERIES: f64 = 1.0 / 4096.0;

/// tanh(s), the friction's smoothed sign. For |s| ≥ 20, 1 − tanh|s| < 1e-17 is below half an ulp
/// of 1: ±1 exactly, as libm returns (the speeds of a moving link are thousands of smoothing
/// velocities). Elsewhere (1 − e)/(1 + e) with e = e^{−2|s|}: one `exp` where libm's tanh calls
/// expm1, which took 30 % of a calibration's time on a sticking link (perf, campaign
/// rig 252); within 1e-12 of tanh relative and 3e-16 absolute (`smooth_sign_is_tanh`).
fn smooth_sign(s: f64) -> f64 {
    let a = s.abs();
    if a >= SIGN_SATURATION {
        1.0_f64.copysign(s)
    } else if a < SIGN_SERIES {
        s * (1.0 - s * s / 3.0)
    } else {
        let e = (-2.0 * a).exp();
        ((1.0 - e) / (1.0 + e)).copysign(s)
    }
}

/// The smoothed friction's steepest slope over the link's inertia, (F_c + F_s)/(v_s J_l), 1/s (0
/// for a link whose speed is held: friction cannot flip it).
fn steepest_friction_slope(p: &Params) -> f64 {
    if p.link_drive == LinkDrive::Prescribed {
        return 0.0;
    }
    (p.coulomb_friction + p.stribeck_friction) / (p.friction_smoothing_velocity * p.link_inertia)
}

/// The link damping the exponential steps of a sub-step `substep` long take into their linear
/// part where one starts at link speed `v0` (an exponential Rosenbrock step), or None where the
/// explicit stages do. Near zero speed a friction F/v_s steep holds explicit stages to
/// h ≤ v_s J_l/(10 F) ([`EtdStep::step`]): a newton-metre on a light link is microseconds, a
/// thousand explicit steps per millisecond sub-step while the link sticks (campaign rigs spent
/// minutes per fit there). Linearised where the link is in the sign's zone and a sub-step would
/// need more than [`EXPLICIT_STEPS_BEFORE_LINEARISING`] explicit steps, or more than
/// [`EXPLICIT_STEPS_BEFORE_LINEARISING_HELD`] where the friction holds the link; the explicit
/// path keeps the rest (tests/physics.rs measures both against a fine reference).
pub fn friction_linearisation(p: &Params, friction: &Friction, v0: f64, substep: f64) -> Option<f64> {
    let vs = p.friction_smoothing_velocity;
    // no Coulomb or Stribeck level, or a prescribed link speed: the steepest slope is 0, no step is needed
    let explicit_steps = substep * steepest_friction_slope(p) / 0.1;
    let threshold = if v0.abs() < HELD_SPEED * vs {
        EXPLICIT_STEPS_BEFORE_LINEARISING_HELD
    } else {
        EXPLICIT_STEPS_BEFORE_LINEARISING
    };
    let explicit_is_cheaper = explicit_steps.is_nan() || explicit_steps <= threshold;
    if vs.is_nan() || vs <= 0.0 || v0.abs() >= SIGN_SATURATION * vs || explicit_is_cheaper {
        return None;
    }
    // A slope at or below zero (a Stribeck level falling faster than the sign rises, a few v_s out)
    // is linearised at nothing: the grid's least damping, the rest explicit within
    // LINEARISED_SLOPE_LIMIT. Left explicit, the zone's rule held a link sticking under a Stribeck
    // excess to 13 explicit steps per millisecond (20.6 attempts; 5.3 linearised).
    let slope = friction.slope(v0);
    slope.is_finite().then_some(slope.max(0.0))
}

/// Explicit steps a sub-step may need before the friction's slope goes into the linear part. A
/// linearised step builds a matrix exponential of its own (kept for the next step that meets the
/// same slope, [`LINEARISED_DAMPING_GRID`]: a link crossing the zone at speed meets a new one
/// each step) and is held to the tighter tolerance, so it pays only where the explicit steps are
/// many (before the exponentials were kept): measured on a 0.52 Hz prescribed sine,
/// 2 ms steps, J_l = 0.023 kg·m², 10.4 s, the model alone (2026-11-27): 0.2 N·m (87 explicit
/// steps a sub-step) 7.4 ms explicit, 16.8 ms linearised; 1.7 N·m (739) 432 ms explicit (2.2e6
/// attempted steps), 71–80 ms linearised (3e4–6e4).
const EXPLICIT_STEPS_BEFORE_LINEARISING: f64 = 256.0;

/// The same for a link its friction holds (|θl'| < [`HELD_SPEED`]·v_s), where the frozen slope stays
/// right for the whole sub-step. A link at rest between steps of a prescribed motor sits there for
/// seconds. Measured on campaign rig 99's 40 °C run (random steps, 0.23 N·m on 0.019 kg·m², 1 ms
/// steps, 3220 samples, 80 explicit steps a sub-step), the model alone (2026-11-27): 239 ms and
/// 7.2e5 attempted steps explicit, 95 ms and 1.5e4 with this at 16; with a 3.7 mrad backlash
/// 772 → 39 ms; the final link angle the same to 1e-9 rad. At 16 for every link in the zone (not
/// only a held one), the torque-driven Coulomb regime of tests/physics.rs went from 3.9e-8 to
/// 7.0e-7 rad (its reversals cross the zone at speed); with the hold condition it is 3.7e-8.
const EXPLICIT_STEPS_BEFORE_LINEARISING_HELD: f64 = 16.0;

/// A held link creeps at v_s·atanh(τ/F) under a torque τ the friction F holds: below 5 v_s for every
/// τ up to 0.9999 F. (At 1·v_s, τ ≤ 0.76 F only: tests/physics.rs's held link still took 189
/// attempted steps per communication step, 18 at 5·v_s.)
const HELD_SPEED: f64 = 5.0;

/// How far a linearised step's stages may move the friction's slope from the one its linear part
/// carries: h·|Δslope|/J_l at most this (the explicit stages' rule allows 0.1 of the whole slope;
/// what the linear part does not carry is treated explicitly, and the embedded estimate at the
/// tighter tolerance decides the rest). Measured: with every near-rest step linearised at the
/// normal tolerance, the torque-driven Coulomb regime of tests/physics.rs gave 8.0e-6 rad both with
/// this limit at 0.1 and with a cruder speed bound in its place (the tolerance, not the limit, set
/// its error); the heavy-friction regime, linearised now, holds 2.1e-7 rad with it at 0.5.
const LINEARISED_SLOPE_LIMIT: f64 = 0.5;

/// Spacing of the grid a linearised step's damping is rounded to, in h·damping/J_l: 1/128. The
/// grid names the dampings a step meets again (a link its friction holds creeps, and its slope
/// moves with the torque it holds); the rounding's share goes to the explicit stages at the tight
/// tolerance and costs attempted steps. Measured (2026-11-29): on campaign rigs 2 and 3 (each run
/// alone, the whole calibration) 38.5 and 38.7 s before; with the grid at 1/16 –, 13.8 s; 1/64
/// 13.6, 11.4 s; 1/128 14.3, 13.0 s; 1/256 15.6, 14.5 s; 2^-20 (no reuse there) –, 42.1 s. On
/// examples/sticking.rs (a link at rest under 1.7 N·m) 8.1 µs a step before; 1/16 3.8, 1/64 2.7,
/// 1/128 2.1, 1/256 1.6 and 2^-20 0.96 µs.
pub const LINEARISED_DAMPING_GRID: f64 = 1.0 / 128.0;

/// Gravity on a link in a vertical plane, hanging at `gravity_offset`.
pub fn link_gravity(p: &Params, link_angle: f64) -> f64 {
    if p.gravity_link_mass == 0.0 {
        return 0.0;
    }
    -p.gravity_torque_amplitude() * (link_angle - p.gravity_offset).sin()
}

/// Right-hand side of the full (possibly nonlinear) mechanics.
pub fn derivative(p: &Params, c: &Coefficients, x: &State, u: &Drive) -> State {
    if p.transmission == Transmission::Rigid {
        let v = x[MOTOR_SPEED];
        let accel = match p.motor_drive {
            MotorDrive::Torque => {
                let torque = u[0] + u[1] - (p.motor_damping + p.link_damping) * v
                    + link_friction(p, v)
                    + link_gravity(p, x[MOTOR_ANGLE]);
                torque / (p.motor_inertia + p.link_inertia)
            }
            MotorDrive::PrescribedAngle => 0.0,
        };
        return State::from([v, accel, v, accel, -x[MAXWELL_DEFLECTION] / p.branch_relaxation_time()]);
    }
    let (tau, q_rate) = transmission(p, c, x);
    let motor_accel = match p.motor_drive {
        MotorDrive::Torque => (u[0] - p.motor_damping * x[MOTOR_SPEED] - tau) / p.motor_inertia,
        MotorDrive::PrescribedAngle => 0.0,
    };
    let link_torque =
        tau + u[1] - p.link_damping * x[LINK_SPEED] + link_friction(p, x[LINK_SPEED]) + link_gravity(p, x[LINK_ANGLE]);
    State::from([x[MOTOR_SPEED], motor_accel, x[LINK_SPEED], p.per_link_inertia(link_torque), q_rate])
}

/// [`derivative`] of the compliant transmission with the smooth link torque (gravity and friction,
/// [`smooth_link_torque`]) given: `smooth` from a [`StepStart`] saves its sine and tanh.
pub fn derivative_with_link_torque(p: &Params, c: &Coefficients, x: &State, u: &Drive, smooth: f64) -> State {
    let (tau, q_rate) = transmission(p, c, x);
    let motor_accel = match p.motor_drive {
        MotorDrive::Torque => (u[0] - p.motor_damping * x[MOTOR_SPEED] - tau) / p.motor_inertia,
        MotorDrive::PrescribedAngle => 0.0,
    };
    let link_torque = tau + u[1] - p.link_damping * x[LINK_SPEED] + smooth;
    State::from([x[MOTOR_SPEED], motor_accel, x[LINK_SPEED], p.per_link_inertia(link_torque), q_rate])
}

/// Where, as a fraction of the step from x0 to x1, the contact function that x1 has crossed out of
/// the state `mode` reaches zero (secant on its end values): the play's edge leaving or entering
/// it, the unclipped torque's sign between engaged and clipped. None when x1 is in `mode`, or
/// in a state not next to it (through the whole play in one step).
fn event_fraction(p: &Params, c: &Coefficients, mode: Contact, x0: &State, x1: &State) -> Option<f64> {
    let to = contact(p, c, x1);
    let half = 0.5 * p.backlash_width;
    let depth = |x: &State| (x[MOTOR_ANGLE] - x[LINK_ANGLE] - play_centre(c, x)).abs() - half; // ≤ 0 in the play
                                                                                               // τ_c − τ_d on the side `a`: its sign parts engaged from capped (ElastoBacklash)
    let cap = |a: bool, x: &State| {
        let (spring, damper) = spring_and_damper(c, engaged_torque(p, c, x, a).0, x);
        spring - damper
    };
    let (g0, g1) = match (mode, to) {
        (Contact::Free, Contact::Free) => return None,
        (Contact::Free, _) | (_, Contact::Free) => (depth(x0), depth(x1)),
        (Contact::Engaged { positive: a } | Contact::Capped { positive: a }, Contact::Clipped { positive: b })
        | (Contact::Clipped { positive: a }, Contact::Engaged { positive: b } | Contact::Capped { positive: b })
            if a == b =>
        {
            (engaged_torque(p, c, x0, a).1, engaged_torque(p, c, x1, a).1)
        }
        (Contact::Engaged { positive: a }, Contact::Capped { positive: b })
        | (Contact::Capped { positive: a }, Contact::Engaged { positive: b })
            if a == b =>
        {
            (cap(a, x0), cap(a, x1))
        }
        _ => return None,
    };
    let theta = g0 / (g0 - g1);
    (theta > 0.0 && theta < 1.0).then_some(theta)
}

/// Adaptive Dormand–Prince 5(4) over `[0, h]`; `step_guess` carries the last accepted step size
/// from call to call; every attempted step costs one of `attempts_left` (the caller's work budget).
/// Returns None when the error control cannot make progress or the budget runs out.
pub fn integrate_adaptive(
    p: &Params,
    c: &Coefficients,
    x: &mut State,
    u: &Drive,
    h: f64,
    step_guess: &mut f64,
    attempts_left: &mut u64,
) -> Option<()> {
    const A: [[f64; 6]; 6] = [
        [1.0 / 5.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        [3.0 / 40.0, 9.0 / 40.0, 0.0, 0.0, 0.0, 0.0],
        [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0, 0.0, 0.0, 0.0],
        [19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0, 0.0, 0.0],
        [9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0, -5103.0 / 18656.0, 0.0],
        [35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0],
    ];
    // 5th-order weights are A[5]; these are 5th minus 4th-order weights.
    const E: [f64; 7] =
        [71.0 / 57600.0, 0.0, -71.0 / 16695.0, 71.0 / 1920.0, -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0];
    let tol = p.solver_tolerance;
    let mut t = 0.0;
    let mut dt = if *step_guess > 0.0 { step_guess.min(h) } else { h };
    let mut k = [State::zeros(); 7];
    // Every stage lies within h of the start: gravity's sine by angle addition from the start's
    // (StageTorque, one sin_cos per call instead of one sine per stage; beyond its range it takes
    // the sine itself).
    let friction = Friction::new(p);
    let torque = StageTorque::new(p, x[LINK_ANGLE], &friction);
    let rate = |x: &State| match p.transmission {
        Transmission::Compliant => derivative_with_link_torque(p, c, x, u, torque.at([x[LINK_ANGLE], x[LINK_SPEED]])),
        Transmission::Rigid => derivative(p, c, x, u),
    };
    k[0] = rate(x);
    let mut rejected_in_a_row = 0;
    // Backlash's contact events are kinks of the right-hand side: a step across one has an error
    // estimate proportional to its length, so step-size control alone closes in on it over dozens of
    // rejections. Where a rejected step ends in another contact state, the step is cut instead to
    // where the contact function crosses zero (secant on its end values) to land just short of
    // the event, then crosses it with a step of twice the remaining distance, then resumes the step
    // size it had (the right-hand side is smooth again). At most KINK_CUTS cuts per call; then plain
    // step-size control.
    const KINK_CUTS: u32 = 16;
    let kinks = p.backlash_width > 0.0 && p.transmission == Transmission::Compliant;
    let mut mode = if kinks { Some(contact(p, c, x)) } else { None };
    let (mut cuts, mut resume): (u32, Option<f64>) = (0, None);
    // A tolerance below what rounding allows gives endless tiny steps: the caller caps the work.
    while t < h {
        if *attempts_left == 0 {
            return None;
        }
        *attempts_left -= 1;
        let last = t + dt >= h * (1.0 - 1e-12);
        if last {
            dt = h - t;
        }
        for s in 0..6 {
            let mut xs = *x;
            for (j, kj) in k.iter().enumerate().take(s + 1) {
                if A[s][j] != 0.0 {
                    xs += kj * (dt * A[s][j]);
                }
            }
            k[s + 1] = rate(&xs);
        }
        let mut x_new = *x;
        for (j, kj) in k.iter().enumerate().take(6) {
            x_new += kj * (dt * A[5][j]);
        }
        let mut err: f64 = 0.0;
        for i in 0..N_STATE {
            let e: f64 = (0..7).map(|j| E[j] * k[j][i]).sum::<f64>() * dt;
            let scale = tol * (1.0 + x[i].abs().max(x_new[i].abs()));
            err = err.max((e / scale).abs());
        }
        if !err.is_finite() || !x_new.iter().all(|v| v.is_finite()) {
            err = f64::INFINITY;
        }
        if err <= 1.0 {
            t = if last { h } else { t + dt };
            *x = x_new;
            k[0] = k[6]; // first-same-as-last
            rejected_in_a_row = 0;
            let grow = if err == 0.0 { 5.0 } else { (0.9 * err.powf(-0.2)).clamp(0.2, 5.0) };
            dt *= grow;
            if let Some(m0) = mode {
                let m1 = contact(p, c, x);
                if m1 != m0 {
                    // across the event: back to the step size from before closing in on it
                    if let Some(before) = resume.take() {
                        dt = dt.max(before);
                    }
                }
                mode = Some(m1);
            }
            if !last {
                *step_guess = dt;
            }
        } else {
            rejected_in_a_row += 1;
            if rejected_in_a_row > 60 || dt < 1e-14 * h.max(1e-300) {
                return None;
            }
            if let Some(m0) = mode.filter(|_| cuts < KINK_CUTS && err.is_finite()) {
                if let Some(theta) = event_fraction(p, c, m0, x, &x_new) {
                    cuts += 1;
                    resume.get_or_insert(dt);
                    let to_event = theta * dt;
                    // Land just short of it, or cross it once it is within 1e-9 of the step.
                    dt = if to_event > 1e-9 * h { to_event * (1.0 - 1e-6) } else { 2.0 * to_event + 1e-9 * h };
                    *step_guess = dt;
                    continue;
                }
            }
            let shrink = if err.is_finite() { (0.9 * err.powf(-0.2)).clamp(0.1, 0.9) } else { 0.1 };
            dt *= shrink;
            *step_guess = dt;
        }
    }
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_rows_fall_on_lattice_nodes() {
        for (t, n) in TABLE_TEMPERATURES_C.iter().zip(ROW_NODES) {
            assert_eq!(node_celsius(n), *t);
        }
    }

    #[test]
    fn stage_torque_equals_the_link_torque() {
        let p = Params { gravity_link_mass: 0.91, gravity_offset: 0.3, coulomb_friction: 0.05, ..Params::default() };
        for k in 0..200 {
            let theta0 = -3.0 + 0.031 * k as f64;
            let friction = Friction::new(&p);
            let torque = StageTorque::new(&p, theta0, &friction);
            for d in [-0.2, -0.049, -1e-3, 0.0, 2e-6, 0.02, 0.0499, 0.07] {
                let x = State::from([0.0, 0.0, theta0 + d, 0.3 * d, 0.0]);
                let exact = smooth_link_torque(&p, &x);
                assert!(
                    (torque.at([x[LINK_ANGLE], x[LINK_SPEED]]) - exact).abs() < 1e-15,
                    "{theta0} {d}: {} vs {exact}",
                    torque.at([x[LINK_ANGLE], x[LINK_SPEED]])
                );
            }
        }
    }

    /// A PCL held exactly at a lattice node (40 °C, 50 °C: whole lattice spacings above 22 °C) reads
    /// that node alone: one matrix exponential for a step length met once (a jittered log's), not
    /// the four or five the fine cell's two stencils need, and the same numbers the fine read
    /// approaches from just above.
    #[test]
    fn a_temperature_on_a_node_reads_that_node_alone() {
        let p = loaded_params();
        for celsius in [40.0, 41.0, 50.0, 22.125] {
            let t = crate::params::ZERO_CELSIUS + celsius;
            let n = ((celsius - TABLE_TEMPERATURES_C[0]) / PROPAGATOR_LATTICE) as usize;
            assert_eq!(node_celsius(n), celsius);
            let mut table = PropagatorTable::<EtdStep>::new(1e-3);
            assert_eq!(table.missing(t), vec![n], "{celsius} °C");
            table.build(&p, t);
            let (mut cell, mut at_node) = (FineCell::default(), EtdStep::ZERO);
            assert!(table.try_at(t, &mut cell, &mut at_node));
            let direct = EtdStep::build(&p, &Coefficients::at(&p, node_temperature(n)), 1e-3);
            assert_eq!(at_node.values(), direct.values(), "{celsius} °C");
            // a hair above the node the fine path reads, from its stencils' nodes
            let above = t + 1e-9;
            table.build(&p, above);
            let mut fine = EtdStep::ZERO;
            assert!(table.try_at(above, &mut FineCell::default(), &mut fine));
            for (a, b) in at_node.values().iter().zip(fine.values()) {
                assert!((a - b).abs() <= 1e-9 * (1.0 + a.abs()), "{celsius} °C: {a} against {b}");
            }
        }
    }

    /// Gravity and a Maxwell branch: every block of the ETD tables is non-trivial.
    fn loaded_params() -> Params {
        Params { gravity_link_mass: 0.91, maxwell_stiffness: 8.0, maxwell_relaxation_time: 0.05, ..Params::default() }
    }

    #[test]
    fn doubled_blocks_equal_the_exponential_at_twice_the_step() {
        let p = loaded_params();
        for t in [22.0, 41.3, 60.0] {
            let c = Coefficients::at(&p, crate::params::ZERO_CELSIUS + t);
            for coupling in [Coupling::Engaged, Coupling::Free, Coupling::Clipped] {
                let (a, b) = linear_system_with(&p, &c, coupling);
                let link = 1.0 / p.link_inertia;
                for h in [1e-3, 1e-3 / 1024.0, 2e-2] {
                    let direct = phi_blocks(&a, &b, link, h);
                    let squared = doubled(&phi_blocks(&a, &b, link, 0.5 * h));
                    assert_columns_close(&direct, &squared, 1e-13, &format!("{t} {coupling:?} {h}"));
                }
            }
        }
    }

    /// The augmented matrix's exponential as any general routine takes it (nalgebra's Padé 13 with
    /// scaling and squaring, on all ten rows): the reference [`phi_blocks`]' structured series is
    /// held to.
    fn general_exponential(
        a: &SMatrix<f64, N_STATE, N_STATE>,
        b: &SMatrix<f64, N_STATE, 2>,
        link: f64,
        h: f64,
    ) -> SMatrix<f64, 10, 10> {
        phi_augmented(a, b, link, h).exp()
    }

    /// The structured series against the general exponential, from steps far under ½ in norm to
    /// a stiff linearised friction (damping 1e4·J_l/h: thirteen doublings), torque- and
    /// reference-driven, rigid and compliant, at every coupling.
    #[test]
    fn phi_blocks_equal_the_general_exponential() {
        let mut rigs = vec![loaded_params(), Params { motor_drive: MotorDrive::PrescribedAngle, ..loaded_params() }];
        rigs.push(Params { transmission: Transmission::Rigid, ..loaded_params() });
        for p in rigs {
            for t in [22.0, 60.0] {
                let c = Coefficients::at(&p, crate::params::ZERO_CELSIUS + t);
                for coupling in [Coupling::Engaged, Coupling::Free, Coupling::Clipped, Coupling::Capped] {
                    for h in [1e-6, 1e-3, 2e-2] {
                        for slope in [0.0, 3.0, 1e4]
                            .into_iter()
                            .filter(|&s| s < 1e4 || p.transmission == Transmission::Compliant)
                        {
                            let (mut a, b) = linear_system_with(&p, &c, coupling);
                            a[(LINK_SPEED, LINK_SPEED)] -= slope / h;
                            let link = 1.0 / p.link_inertia;
                            let context = format!("{:?} {t} {coupling:?} {h} {slope}", p.transmission);
                            let reference = general_exponential(&a, &b, link, h);
                            // Both routines' own errors, against 60 digits: ≤ 8.6e-14 and ≤ 2.6e-12 stiff (see
                            // TAYLOR_SCALED_NORM); the tolerance is their sum.
                            let tol = if slope > 3.0 { 5e-12 } else { 1.2e-13 };
                            assert_columns_close(&reference, &phi_blocks(&a, &b, link, h), tol, &context);
                        }
                    }
                }
            }
        }
    }

    /// Every entry of the first ten columns of `other` within `tol` of its column's largest in `direct`.
    fn assert_columns_close<A, B>(direct: &A, other: &B, tol: f64, context: &str)
    where
        A: std::ops::Index<(usize, usize), Output = f64>,
        B: std::ops::Index<(usize, usize), Output = f64>,
    {
        for j in 0..10 {
            let scale = (0..N_STATE).fold(0.0_f64, |m, i| m.max(direct[(i, j)].abs()));
            for i in 0..N_STATE {
                let err = (direct[(i, j)] - other[(i, j)]).abs();
                assert!(err <= tol * scale, "{context} ({i}, {j}): {err:e} of {scale:e}");
            }
        }
    }

    #[test]
    fn chained_blocks_equal_the_exponential_at_every_level() {
        let p = loaded_params();
        for t in [22.0, 41.3, 60.0] {
            let c = Coefficients::at(&p, crate::params::ZERO_CELSIUS + t);
            let (a, b) = linear_system_with(&p, &c, Coupling::Engaged);
            let link = 1.0 / p.link_inertia;
            for key in [1e-3, 1e-3 * (1.0 + 3e-10), 2e-2] {
                let chain = phi_chain(&p, &c, key, 10);
                for (l, rows) in chain.iter().enumerate() {
                    let direct = phi_blocks(&a, &b, link, key / (1u64 << l) as f64);
                    assert_columns_close(&direct, rows, 1e-12, &format!("{t} {key} level {l}"));
                }
            }
        }
    }

    /// Along a link turning at 0–45 rad/s (1 ms apart) and one at rest, the anchored sine stays
    /// within 4e-16 of libm's: one addition from a libm value, never a chain.
    #[test]
    fn anchored_sine_follows_libm_along_a_turning_link() {
        let mut anchor = SineAnchor::NONE;
        let (mut phi, mut worst) = (0.3_f64, 0.0_f64);
        for k in 0..400_000 {
            phi += 1e-3 * 45.0 * (k as f64 * 1e-4).sin();
            let (s, c) = anchor.sin_cos(phi);
            let (s0, c0) = phi.sin_cos();
            worst = worst.max((s - s0).abs()).max((c - c0).abs());
        }
        assert!(worst < 4e-16, "turning: {worst:e}");
        assert!(anchor.is_consistent());
        let mut at_rest = SineAnchor::NONE;
        let first = at_rest.sin_cos(1.234);
        for _ in 0..100_000 {
            assert_eq!(at_rest.sin_cos(1.234), first, "a link at rest adds d = 0 exactly");
        }
        assert!(SineAnchor::NONE.is_consistent());
        assert!(!SineAnchor { angle: 1.0, sin: 0.5, cos: 0.5 }.is_consistent());
    }

    /// Dormand–Prince through a contact event (the motor side reaching the play's edge at 2 rad/s
    /// half-way through 1 ms) cuts its step at the event instead of closing in on the kink by
    /// rejections, and lands where the exact solution does: the free and engaged states are
    /// linear, so the reference is their exact propagators on either side of the event, located by
    /// bisection.
    #[test]
    fn dormand_prince_steps_to_a_contact_event() {
        let p = Params { backlash_width: 0.01, ..Params::default() };
        let c = Coefficients::at(&p, p.initial_pcl_temperature);
        let u = Drive::new(0.3, 0.0);
        let x0 = State::from([0.004, 2.0, 0.0, 0.0, 0.0]);
        let (mut x, mut guess, mut budget) = (x0, 1e-3, 10_000u64);
        integrate_adaptive(&p, &c, &mut x, &u, 1e-3, &mut guess, &mut budget).expect("integrates");
        let attempts = 10_000 - budget;
        let free = |t: f64| LinearStep::with(&p, &Coefficients::ZERO, t, Coupling::Free).apply(&x0, &u);
        let (mut lo, mut hi) = (0.0, 1e-3);
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if in_play(&p, &c, &free(mid)) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let mut at_event = free(hi);
        at_event[MOTOR_ANGLE] -= 0.5 * p.backlash_width;
        let mut exact = LinearStep::with(&p, &c, 1e-3 - hi, Coupling::Engaged).apply(&at_event, &u);
        exact[MOTOR_ANGLE] += 0.5 * p.backlash_width;
        assert_eq!(contact(&p, &c, &exact), Contact::Engaged { positive: true }, "engaged to the end");
        let worst = (0..N_STATE).map(|i| (x[i] - exact[i]).abs() / (1.0 + exact[i].abs())).fold(0.0, f64::max);
        println!("event at {hi:e} s; {attempts} attempts; max relative difference to the exact solution {worst:e}");
        assert!(worst < 1e-9, "{worst:e}");
        assert!(attempts <= 40, "{attempts} attempts");
    }

    /// With a remembering branch (q ≠ 0) the play sits about the unloaded element's rest r q:
    /// just beyond either edge, at rest, the transmission passes (K + K_M)·(the overshoot) and no
    /// more (the law before it began contact with −K_M q); just inside, nothing, and q recovers
    /// towards r q. The free step's q is the exact recovery.
    #[test]
    fn a_remembering_branch_moves_the_play_so_contact_starts_at_zero_torque() {
        let p =
            Params { backlash_width: 0.01, maxwell_stiffness: 8.0, maxwell_relaxation_time: 0.05, ..Params::default() };
        let c = Coefficients::at(&p, p.initial_pcl_temperature);
        let (r, lam, half, q) = (unloaded_share(&c), p.maxwell_relaxation_time, 0.005, 0.02);
        assert!((r - 8.0 / (c.stiffness + 8.0)).abs() < 1e-15, "r = {r}");
        let at = |delta: f64| State::from([delta, 0.0, 0.0, 0.0, q]);
        assert_eq!(play_centre(&c, &at(0.0)), r * q);
        let overshoot = 1e-9;
        for s in [1.0, -1.0] {
            let edge = r * q + s * half;
            let inside = at(edge - s * overshoot);
            assert_eq!(contact(&p, &c, &inside), Contact::Free, "side {s}");
            assert_eq!(transmission(&p, &c, &inside), (0.0, (r * q - q) / lam), "side {s}");
            let beyond = at(edge + s * overshoot);
            assert_eq!(contact(&p, &c, &beyond), Contact::Engaged { positive: s > 0.0 }, "side {s}");
            let (tau, _) = transmission(&p, &c, &beyond);
            let want = s * (c.stiffness + c.maxwell_stiffness) * overshoot;
            assert!((tau - want).abs() < 1e-6 * want.abs(), "side {s}: contact begins with {tau} N·m, not {want}");
        }
        // the old centre (0) is inside the play only because r q < b/2 here: at q = 0.1 it is not
        let far = State::from([0.0, 0.0, 0.0, 0.0, 0.1]);
        assert!(r * 0.1 > half && contact(&p, &c, &far) == Contact::Engaged { positive: false });
        let h = 1e-3;
        let mut x = LinearStep::with(&p, &Coefficients::ZERO, h, Coupling::Free).apply(&at(r * q), &Drive::zeros());
        x[MAXWELL_DEFLECTION] = recover_unloaded(&p, &c, q, h);
        assert!((x[MAXWELL_DEFLECTION] / (q * ((r - 1.0) * h / lam).exp()) - 1.0).abs() < 1e-15);
        assert_eq!([x[MOTOR_ANGLE], x[LINK_ANGLE]], [r * q, 0.0], "nothing else moves");
    }

    /// `backlash_law` = 1 is Modelica's ElastoBacklash, written here from the MSL's equations: with
    /// φ = Δ, b2 the half play, τ_c = K(φ ∓ b2), τ_d = C φ', the torque is τ_c + min(τ_c, τ_d) for
    /// φ > b2 unless τ_c + τ_d ≤ 0 (then 0), τ_c + max(τ_c, τ_d) for φ < −b2 unless τ_c + τ_d ≥ 0,
    /// and 0 inside. The contact state agrees: torque only when engaged or capped, capped exactly
    /// where the cap (τ_d beyond τ_c) acts.
    #[test]
    fn the_elasto_backlash_law_is_modelicas() {
        let p = Params { backlash_width: 0.01, backlash_law: BacklashLaw::ElastoBacklash, ..Params::default() };
        let c = Coefficients::at(&p, p.initial_pcl_temperature);
        let (k, d, b2) = (c.stiffness, c.damping, 0.005);
        let msl = |phi: f64, w: f64| {
            if phi > b2 {
                let (tc, td) = (k * (phi - b2), d * w);
                if tc + td <= 0.0 {
                    0.0
                } else {
                    tc + tc.min(td)
                }
            } else if phi < -b2 {
                let (tc, td) = (k * (phi + b2), d * w);
                if tc + td >= 0.0 {
                    0.0
                } else {
                    tc + tc.max(td)
                }
            } else {
                0.0
            }
        };
        let (mut capped, mut engaged, mut clipped) = (0, 0, 0);
        for i in -40..=40 {
            for j in -40..=40 {
                let (phi, w) = (i as f64 * 5e-4, j as f64 * 2e-3);
                let x = State::from([phi, w, 0.0, 0.0, 0.0]);
                let tau = transmission(&p, &c, &x).0;
                assert_eq!(tau, msl(phi, w), "φ {phi}, φ' {w}");
                match contact(&p, &c, &x) {
                    Contact::Capped { positive } => {
                        capped += 1;
                        assert_eq!(
                            tau,
                            2.0 * k * (phi - if positive { b2 } else { -b2 }),
                            "capped: 2τ_c at φ {phi}, φ' {w}"
                        );
                    }
                    Contact::Engaged { .. } => engaged += 1,
                    Contact::Clipped { .. } => {
                        clipped += 1;
                        assert_eq!(tau, 0.0, "clipped at φ {phi}, φ' {w}");
                    }
                    Contact::Free => assert_eq!(tau, 0.0),
                }
            }
        }
        assert!(
            capped > 100 && engaged > 100 && clipped > 100,
            "{capped} capped, {engaged} engaged, {clipped} clipped"
        );
        // the clipped law's torque jumps by C φ' at contact; ElastoBacklash's starts at 0
        let entering = State::from([b2 + 1e-9, 1.0, 0.0, 0.0, 0.0]);
        let clipped_law = Params { backlash_law: BacklashLaw::Clipped, ..p.clone() };
        assert!((transmission(&clipped_law, &c, &entering).0 - d).abs() < 1e-6 * d);
        assert!(transmission(&p, &c, &entering).0.abs() < 1e-7);
    }

    #[test]
    fn smooth_sign_is_tanh() {
        let mut s: f64 = 1e-300;
        while s < 1e3 {
            for v in [s, -s, 20.0 + s, -20.0 - s, 20.0 - s.min(1.0), -20.0 + s.min(1.0)] {
                let (got, tanh) = (smooth_sign(v), v.tanh());
                assert!((got - tanh).abs() <= 1e-12 * tanh.abs() && (got - tanh).abs() <= 3e-16, "{v}: {got} {tanh}");
                assert_eq!(smooth_sign(-v).to_bits(), (-got).to_bits(), "odd at {v}");
            }
            s *= 1.01;
        }
        // monotone across the series' edge and on to saturation
        let mut last = 0.0;
        for k in 0..=200_000 {
            let v = k as f64 * 1e-4;
            assert!(smooth_sign(v) >= last, "{v}");
            last = smooth_sign(v);
        }
        assert_eq!(smooth_sign(SIGN_SATURATION), 1.0);
        assert!(smooth_sign(f64::NAN).is_nan());
        assert_eq!(smooth_sign(f64::INFINITY), 1.0);
        assert_eq!(smooth_sign(0.0), 0.0);
    }

    #[test]
    fn advanced_start_equals_a_fresh_one() {
        let p = Params { gravity_link_mass: 0.91, gravity_offset: 0.3, coulomb_friction: 0.05, ..Params::default() };
        for k in 0..200 {
            let x0 = State::from([0.0, 0.0, -3.0 + 0.031 * k as f64, 0.7, 0.0]);
            let friction = Friction::new(&p);
            let start = StepStart::new(&p, &x0, &friction);
            for d in [-0.049, -1e-3, 0.0, 2e-6, 0.02, 0.07] {
                let x1 = State::from([0.0, 0.0, x0[LINK_ANGLE] + d, 0.3 * d, 0.0]);
                let (a, b) = (start.advanced(&p, &x1), StepStart::new(&p, &x1, &friction));
                assert!((a.link_torque() - b.link_torque()).abs() < 1e-15, "{k} {d}");
                let x2 = State::from([0.0, 0.0, x1[LINK_ANGLE] + 0.01, 0.1, 0.0]);
                let link = [x2[LINK_ANGLE], x2[LINK_SPEED]];
                assert!((a.torque.at(link) - b.torque.at(link)).abs() < 1e-15, "{k} {d}");
            }
        }
    }

    #[test]
    fn hermite_dips_finds_interior_minima_only() {
        // p = 1 − 5s + 5s²: minimum −0.25 at s = ½
        assert!(hermite_dips(1.0, -5.0, 1.0, 5.0));
        // p = 1 − 2.5s + 2.5s²: minimum 0.375
        assert!(!hermite_dips(1.0, -2.5, 1.0, 2.5));
        // monotone, and a maximum only
        assert!(!hermite_dips(1.0, -0.5, 0.5, -0.5));
        assert!(!hermite_dips(0.0, 1.0, 0.0, -1.0));
        // nearly a parabola (c ~ 1e-16, not 0): minimum −0.018 at s = ½, which the textbook root
        // formula's cancellation put at s = ⅔ (p = 0.032)
        assert!(hermite_dips(0.43200000000000005, -1.8, 0.43200000000000005, 1.8000000000000003));
        // where the bound's shortcut answers, no sample of the cubic comes near the margin
        for i in 0..40 {
            for j in 0..40 {
                for k in 0..24 {
                    let (m0, m1) = (-2.0 + 0.1 * i as f64, -2.0 + 0.1 * j as f64);
                    let g0 = 0.01 * k as f64 * (m0.abs() + m1.abs());
                    for g1 in [g0, 0.5 * g0, 2.0 * g0] {
                        let b = 3.0 * (g1 - g0) - 2.0 * m0 - m1;
                        let c = 2.0 * (g0 - g1) + m0 + m1;
                        let margin = 1e-3 * (m0.abs() + m1.abs());
                        let low = (1..1000)
                            .map(|n| n as f64 / 1000.0)
                            .any(|s| g0 + s * (m0 + s * (b + s * c)) < 2.0 * margin);
                        if g0.min(g1) > 0.16 * (m0.abs() + m1.abs()) {
                            assert!(!low && !hermite_dips(g0, m0, g1, m1), "{g0} {m0} {g1} {m1}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn contact_states_follow_the_transmission() {
        let p = Params { backlash_width: 0.01, ..Params::default() };
        let c = Coefficients::at(&p, crate::params::ZERO_CELSIUS + 22.0);
        let x = |delta: f64, rate: f64| State::from([delta, rate, 0.0, 0.0, 0.0]);
        assert_eq!(contact(&p, &c, &x(0.004, 1.0)), Contact::Free);
        assert_eq!(contact(&p, &c, &x(0.006, 0.0)), Contact::Engaged { positive: true });
        assert_eq!(contact(&p, &c, &x(-0.006, 0.0)), Contact::Engaged { positive: false });
        // leaving fast: the damper would pull
        assert_eq!(contact(&p, &c, &x(0.006, -10.0)), Contact::Clipped { positive: true });
        assert_eq!(contact(&p, &c, &x(-0.006, 10.0)), Contact::Clipped { positive: false });
        for (delta, rate) in [(0.004, 1.0), (0.006, 0.0), (-0.006, 0.0), (0.006, -10.0), (-0.006, 10.0)] {
            let s = x(delta, rate);
            let tau = transmission(&p, &c, &s).0;
            assert_eq!(tau != 0.0, contact(&p, &c, &s) == Contact::Engaged { positive: delta > 0.0 }, "{delta} {rate}");
        }
        // the link grazes the play's edge between two states inside it
        let half = 0.005;
        let a = x(half - 1e-6, 0.1);
        let b = x(half - 1e-6, -0.1);
        assert!(may_leave(&p, &c, Contact::Free, (&a, &a), (&b, &b), 1e-3));
        // ...and approaches it without touching
        let (a, b) = (x(half - 1e-4, 0.01), x(half - 9e-5, 0.01));
        assert!(!may_leave(&p, &c, Contact::Free, (&a, &a), (&b, &b), 1e-3));
    }

    #[test]
    fn the_friction_slope_is_the_derivative_of_the_friction() {
        let laws = [
            Params { coulomb_friction: 1.7, ..Params::default() },
            Params { coulomb_friction: 0.3, stribeck_friction: 0.2, stribeck_velocity: 0.004, ..Params::default() },
            Params {
                coulomb_friction: 0.3,
                stribeck_friction: 0.2,
                coulomb_friction_asymmetry: 0.05,
                viscous_friction_asymmetry: 0.7,
                ..Params::default()
            },
        ];
        for p in laws {
            let f = Friction::new(&p);
            let vs = p.friction_smoothing_velocity;
            for v in [0.0, 3e-5, -2e-4, 1e-3, -4.2e-3, 0.019, -0.5] {
                let dv = 1e-5 * vs;
                let central = -(f.at(v + dv) - f.at(v - dv)) / (2.0 * dv);
                let scale = (p.coulomb_friction + p.stribeck_friction) / vs;
                assert!((f.slope(v) - central).abs() < 1e-6 * scale, "{p:?} at {v}: {} vs {central}", f.slope(v));
            }
        }
    }

    #[test]
    fn step_keys_are_decimal_and_close() {
        assert_eq!(canonical_step(1e-3), 1e-3);
        assert_eq!(canonical_step(0.1), 0.1);
        for k in 0..1_000_000u64 {
            let h = (k + 1) as f64 * 1e-3 - k as f64 * 1e-3; // fmpy's time grid up to 1000 s
            assert_eq!(canonical_step(h), 1e-3, "{h}");
        }
        let mut h = 1.234567e-7;
        while h < 1e3 {
            let key = canonical_step(h);
            assert!((key - h).abs() <= 5e-10 * h, "{h} -> {key}");
            h *= 1.37;
        }
    }
}
