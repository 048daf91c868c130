//! The PCL's crystallinity as a state (docs/physics.md §5a).
//!
//! The state is the structural temperature T_f: the temperature at which the heating branch (the
//! melting curve χ, the logistic CDF 0.5 (1 + tanh((T − T_m)/w))) holds the PCL's crystallinity,
//!
//!   X = X_c (1 − χ(T_f)),   X_c = L / ΔH₁₀₀,   T_f ≥ T.
//!
//! Melting is rate-independent: T_f follows T upwards (X = X_c (1 − χ(T)), the old equilibrium).
//! Crystallisation is Nakamura's non-isothermal law for the relative crystallinity α = X/X_c:
//!
//!   α = 1 − exp(−θⁿ),   θ' = K(T),   K(T) = (ln 2)^{1/n} / t½(T),
//!
//! with the isothermal half-time from Hoffman–Lauritzen's growth law,
//!
//!   1/t½(T) ∝ exp(−(U*/R) / (T − T∞)) · exp(−K_g / (T ΔT f)),   ΔT = T_m⁰ − T,  f = 2T/(T + T_m⁰),
//!
//! scaled to `crystallisation_half_time` at `crystallisation_reference_temperature`; K = 0 at and
//! above T_m⁰ and at and below T∞ = T_g − 30 K. Since 1 − α = χ(T_f), θⁿ = −ln χ(T_f): advancing θ
//! by K h and mapping back gives the new T_f, capped at T (the crystallinity never exceeds the
//! heating branch's at the current temperature).

use super::material::TABLE_TEMPERATURES_C;
use super::params::{Params, ZERO_CELSIUS};

/// ln(1 + eˣ) without overflow or loss of digits.
fn softplus(x: f64) -> f64 {
    if x > 0.0 {
        x + (-x).exp().ln_1p()
    } else {
        x.exp().ln_1p()
    }
}

/// ln(1/t½(T)) less its value at the reference temperature: Hoffman–Lauritzen's exponent.
fn hl_exponent(p: &Params, t: f64) -> f64 {
    let t_inf = p.pcl_glass_transition_temperature - 30.0;
    let tm0 = p.pcl_equilibrium_melting_temperature;
    -p.crystallisation_activation_temperature / (t - t_inf)
        - p.crystallisation_nucleation_constant * (t + tm0) / (2.0 * t * t * (tm0 - t))
}

/// Isothermal half-time t½(T), s (infinite where the rate vanishes).
pub fn half_time(p: &Params, t: f64) -> f64 {
    let t_inf = p.pcl_glass_transition_temperature - 30.0;
    if t >= p.pcl_equilibrium_melting_temperature || t <= t_inf {
        return f64::INFINITY;
    }
    p.crystallisation_half_time * (hl_exponent(p, p.crystallisation_reference_temperature) - hl_exponent(p, t)).exp()
}

/// Nakamura's rate K(T), 1/s.
pub fn nakamura_rate(p: &Params, t: f64) -> f64 {
    let t_half = half_time(p, t);
    if !t_half.is_finite() {
        return 0.0;
    }
    std::f64::consts::LN_2.powf(1.0 / p.avrami_exponent) / t_half
}

/// Ultimate crystallinity X_c = L / ΔH₁₀₀ (the heating branch's when cold).
pub fn ultimate_crystallinity(p: &Params) -> f64 {
    p.pcl_latent_heat / p.pcl_perfect_crystal_latent_heat
}

/// Crystallinity X at structural temperature `structural`.
pub fn crystallinity(p: &Params, structural: f64) -> f64 {
    // 1 − χ = 1/(1 + e^{2x})
    let x = (structural - p.pcl_melting_temperature) / p.pcl_melting_width;
    ultimate_crystallinity(p) * (-softplus(2.0 * x)).exp()
}

/// Largest lag of the structural temperature behind Nakamura's integral θ: T_f (and with it the
/// crystallinity, its latent heat and the moduli) is recomputed from θ once θ has moved this far
/// past θ(T_f), so a slowly crystallising melt (near T_m⁰ the rate is 1e-7/s) costs one rate
/// evaluation per step. The crystallinity lags by at most n θ^{n−1} e^{−θⁿ} · 1e-5 ≤ 1.3e-5 of X_c
/// (n = 2.5), its latent heat by 3 mJ (energy is conserved regardless: the latent heat stays in
/// the enthalpy until T_f moves); at the peak of crystallisation θ moves this far in about one
/// 1 ms step. (1e-6 cost 10 ns more per cooling step, measured on the model alone.)
pub const THETA_LAG: f64 = 1e-5;

/// The kinetics' constants from the parameters, and the quantities of one structural temperature
/// (pure functions of it, so keeping them never changes a result: a restored state continues
/// bit-identically).
#[derive(Clone, Debug)]
pub struct Kinetics {
    log_rate_ref: f64,
    n: f64,
    inv_n: f64,
    t_inf: f64,
    tm0: f64,
    ua: f64,
    kg: f64,
    tm: f64,
    w: f64,
    /// m L, J.
    latent: f64,
    /// The structural temperature of χ and 1 − χ below (NaN: none yet)...
    at: f64,
    chi: f64,
    solid: f64,
    /// ...and of θ(T_f) (needed only where the PCL crystallises).
    theta_at: f64,
    theta: f64,
    /// The rate and e^{2x} about the PCL temperature's anchor ([`RateAnchor`]).
    anchor: RateAnchor,
}

/// Spacing of the anchors of [`RateAnchor`], K (a binary fraction: exact).
const RATE_LATTICE: f64 = 1.0 / 128.0;

/// Nakamura's rate K and e^{2(T − T_m)/w} (the moduli's mixing) as Taylor series about the anchor
/// T0 nearest the PCL temperature on a 1/128 K lattice, so a cooling step needs no exponential:
/// K(T0 + d) = K0 exp(s1 d + s2 d²/2 + s3 d³/6), the exponential by its quartic (|d| ≤ 1/256 K: relative
/// error below 1e-9, a unit test); e^{2x} likewise. Pure functions of the anchor, which is one of T.
#[derive(Clone, Debug)]
struct RateAnchor {
    t0: f64,
    k0: f64,
    s1: f64,
    s2: f64,
    s3: f64,
    e0: f64,
    /// |s1| ≤ 5/K: the exponent's step stays below 0.02 and the series' truncation (s4 d⁴/24,
    /// a⁵/120) below 1e-9; steeper (within a few K of T_m⁰, where crystallisation is 1e-6 of its
    /// peak) K is evaluated exactly.
    series: bool,
}

/// exp(a) for |a| ≲ 4e-3 by its quartic (error a⁵/120 < 1e-14).
#[inline]
fn exp_small(a: f64) -> f64 {
    1.0 + a * (1.0 + a * (0.5 + a * (1.0 / 6.0 + a * (1.0 / 24.0))))
}

impl Kinetics {
    pub fn new(p: &Params) -> Self {
        let n = p.avrami_exponent;
        Kinetics {
            log_rate_ref: (std::f64::consts::LN_2.ln() / n - p.crystallisation_half_time.ln())
                - hl_exponent(p, p.crystallisation_reference_temperature),
            n,
            inv_n: 1.0 / n,
            t_inf: p.pcl_glass_transition_temperature - 30.0,
            tm0: p.pcl_equilibrium_melting_temperature,
            ua: p.crystallisation_activation_temperature,
            kg: p.crystallisation_nucleation_constant,
            tm: p.pcl_melting_temperature,
            w: p.pcl_melting_width,
            latent: p.pcl_mass * p.pcl_latent_heat,
            at: f64::NAN,
            chi: 0.0,
            solid: 0.0,
            theta_at: f64::NAN,
            theta: 0.0,
            anchor: RateAnchor { t0: f64::NAN, k0: 0.0, s1: 0.0, s2: 0.0, s3: 0.0, e0: 0.0, series: false },
        }
    }

    /// ln K(t) and its first three derivatives in t.
    fn log_rate(&self, t: f64) -> [f64; 4] {
        let u = t - self.t_inf;
        let (tp, tm) = (t + self.tm0, self.tm0 - t);
        // f = (T + T_m⁰)/(2T²(T_m⁰ − T)), g = f'/f
        let f = tp / (2.0 * t * t * tm);
        let g = 1.0 / tp - 2.0 / t + 1.0 / tm;
        let g1 = -1.0 / (tp * tp) + 2.0 / (t * t) + 1.0 / (tm * tm);
        let g2 = 2.0 / (tp * tp * tp) - 4.0 / (t * t * t) + 2.0 / (tm * tm * tm);
        // f' = f g, f'' = f (g² + g'), f''' = f (g³ + 3 g g' + g'')
        [
            self.log_rate_ref - self.ua / u - self.kg * f,
            self.ua / (u * u) - self.kg * f * g,
            -2.0 * self.ua / (u * u * u) - self.kg * f * (g * g + g1),
            6.0 * self.ua / (u * u * u * u) - self.kg * f * (g * g * g + 3.0 * g * g1 + g2),
        ]
    }

    /// Moves the anchor to the lattice point nearest `t`.
    #[inline]
    fn anchor_at(&mut self, t: f64) -> bool {
        // x + 2^52 − 2^52 rounds x to an integer (|x| < 2^51) without a libm call.
        const SHIFT: f64 = 4_503_599_627_370_496.0;
        let t0 = ((t / RATE_LATTICE + SHIFT) - SHIFT) * RATE_LATTICE;
        // the series needs K's derivatives moderate: not within 2 K of where K vanishes
        if t0 >= self.tm0 - 2.0 || t0 <= self.t_inf + 2.0 {
            return false;
        }
        if self.anchor.t0 != t0 {
            let [l0, s1, s2, s3] = self.log_rate(t0);
            let e0 = (2.0 * (t0 - self.tm) / self.w).exp();
            self.anchor = RateAnchor { t0, k0: l0.exp(), s1, s2, s3, e0, series: s1.abs() <= 5.0 };
        }
        true
    }

    /// K(t) from the anchor's series where it holds, else exactly.
    #[inline]
    fn rate_fast(&mut self, t: f64) -> f64 {
        if !self.anchor_at(t) || !self.anchor.series {
            return self.rate(t);
        }
        let a = &self.anchor;
        let d = t - a.t0;
        a.k0 * exp_small(d * (a.s1 + d * (0.5 * a.s2 + d * (1.0 / 6.0) * a.s3)))
    }

    fn at(&mut self, structural: f64) {
        if self.at == structural {
            return;
        }
        let x = (structural - self.tm) / self.w;
        self.chi = 0.5 * (1.0 + x.tanh());
        // 1 − χ = 1/(1 + e^{2x}) without cancellation when χ → 1
        self.solid = if x < 300.0 { 1.0 / (1.0 + (2.0 * x).exp()) } else { 0.0 };
        self.at = structural;
    }

    fn theta_of(&mut self, structural: f64) -> f64 {
        if self.theta_at != structural {
            self.theta = softplus(-2.0 * (structural - self.tm) / self.w).powf(self.inv_n);
            self.theta_at = structural;
        }
        self.theta
    }

    /// Nakamura's rate K(T), 1/s (as [`nakamura_rate`]).
    #[inline]
    pub fn rate(&self, t: f64) -> f64 {
        if t >= self.tm0 || t <= self.t_inf {
            return 0.0;
        }
        self.log_rate(t)[0].exp()
    }

    /// Latent heat held by the melt at structural temperature `structural`, m L χ(T_f), J.
    pub fn latent_heat(&mut self, structural: f64) -> f64 {
        self.at(structural);
        self.latent * self.chi
    }

    /// Crystallises for `h` s at PCL temperature `t`: advances Nakamura's integral `theta` (the
    /// state; below θ(T_f) it stands for θ(T_f)) and returns the new structural temperature, never
    /// below `floor` (the PCL temperature; there `theta` is reset to 0, the heating branch).
    pub fn advance(&mut self, theta: &mut f64, structural: f64, t: f64, h: f64, floor: f64) -> f64 {
        let k = self.rate_fast(t);
        if k == 0.0 {
            return structural;
        }
        let held = self.theta_of(structural);
        let next_theta = theta.max(held) + k * h;
        *theta = next_theta;
        if next_theta - held <= THETA_LAG {
            return structural;
        }
        // χ = e^{−θⁿ} = 1/(1 + e^{−2x})  ⇒  x = −ln(e^{θⁿ} − 1)/2
        let g = next_theta.powf(self.n);
        let ln_expm1 = if g > 40.0 { g } else { g.exp_m1().ln() };
        let next = self.tm - 0.5 * self.w * ln_expm1;
        if next <= floor {
            *theta = 0.0;
            return floor;
        }
        next
    }

    /// [`modulus_temperature`] with the structural temperature's quantities kept.
    #[inline]
    pub fn modulus_temperature(&mut self, t: f64, structural: f64) -> f64 {
        let t_am = ZERO_CELSIUS + TABLE_TEMPERATURES_C[TABLE_TEMPERATURES_C.len() - 1];
        if structural <= t || t >= t_am {
            return t;
        }
        self.at(structural);
        // r = (1 − χ(T_f)) / (1 − χ(t)); t < 60 °C keeps e^{2x} finite
        let e2x = if self.anchor_at(t) {
            self.anchor.e0 * exp_small(2.0 * (t - self.anchor.t0) / self.w)
        } else {
            (2.0 * (t - self.tm) / self.w).exp()
        };
        let r = (self.solid * (1.0 + e2x)).min(1.0);
        t + (1.0 - r) * (t_am - t)
    }
}

/// The temperature at which the material table is read for a PCL at `t` with structural
/// temperature `structural` (docs/physics.md §5b): log-linear mixing of the heating branch's
/// moduli at t (crystallinity X_eq(t)) and the amorphous moduli, taken as the table's hottest row,
/// done along the table's own temperature axis,
///
///   T* = t + (1 − r)(T_am − t),   r = X / X_eq(t) = (1 − χ(T_f)) / (1 − χ(t)) ∈ [0, 1].
///
/// On the heating branch (T_f = t) r = 1 and T* = t exactly: the paper's tables are unchanged.
pub fn modulus_temperature(p: &Params, t: f64, structural: f64) -> f64 {
    let t_am = ZERO_CELSIUS + TABLE_TEMPERATURES_C[TABLE_TEMPERATURES_C.len() - 1];
    if structural <= t || t >= t_am {
        return t;
    }
    let (tm, w) = (p.pcl_melting_temperature, p.pcl_melting_width);
    let r = (softplus(2.0 * (t - tm) / w) - softplus(2.0 * (structural - tm) / w)).exp().min(1.0);
    t + (1.0 - r) * (t_am - t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn half_time_meets_its_reference_and_vanishing_rate_at_the_equilibrium_melting_point() {
        let p = Params::default();
        let t_ref = p.crystallisation_reference_temperature;
        assert!((half_time(&p, t_ref) / p.crystallisation_half_time - 1.0).abs() < 1e-12);
        // The default K_g was fitted to t½(45 °C) = 1200 s [EST]: the second anchor.
        let t45 = half_time(&p, ZERO_CELSIUS + 45.0);
        assert!((t45 / 1200.0 - 1.0).abs() < 1e-3, "t½(45 °C) = {t45} s");
        assert_eq!(nakamura_rate(&p, p.pcl_equilibrium_melting_temperature), 0.0);
        // rate falls monotonically from 20 °C towards T_m⁰ (its maximum lies below 20 °C)
        let mut last = f64::INFINITY;
        for k in 0..450 {
            let r = nakamura_rate(&p, ZERO_CELSIUS + 20.0 + 0.1 * k as f64);
            assert!(r < last && r > 0.0);
            last = r;
        }
    }

    /// The anchored series against the exact rate and e^{2x}, 20–67 °C at odd offsets.
    #[test]
    fn anchored_series_match_the_exact_rate_and_exponential() {
        let p = Params::default();
        let mut k = Kinetics::new(&p);
        let (mut worst_k, mut worst_e): (f64, f64) = (0.0, 0.0);
        for i in 0..47_000 {
            let t = ZERO_CELSIUS + 20.0 + 0.001 * i as f64 + 0.000_37;
            let exact = k.rate(t);
            worst_k = worst_k.max((k.rate_fast(t) / exact - 1.0).abs());
            if k.anchor_at(t) {
                let e = k.anchor.e0 * exp_small(2.0 * (t - k.anchor.t0) / k.w);
                worst_e = worst_e.max((e / (2.0 * (t - k.tm) / k.w).exp() - 1.0).abs());
            }
        }
        println!("rate {worst_k:e}, e^2x {worst_e:e}");
        assert!(worst_k < 1e-9 && worst_e < 1e-12, "{worst_k:e} {worst_e:e}");
    }

    #[test]
    fn isothermal_crystallisation_is_half_done_at_the_half_time() {
        let p = Params::default();
        let t = ZERO_CELSIUS + 40.0;
        let t_half = half_time(&p, t);
        let mut k = Kinetics::new(&p);
        assert!((k.rate(t) / nakamura_rate(&p, t) - 1.0).abs() < 1e-12);
        // from a melt so hot that the melting curve's tail leaves no crystal (α = e^-194)
        let (mut tf, mut theta) = (ZERO_CELSIUS + 300.0, 0.0);
        let steps = 10_000;
        for _ in 0..steps {
            tf = k.advance(&mut theta, tf, t, t_half / steps as f64, t);
        }
        let alpha = crystallinity(&p, tf) / ultimate_crystallinity(&p);
        assert!((alpha - 0.5).abs() < 1e-9, "α(t½) = {alpha}");
    }

    /// Far below its rate's scale the structural temperature waits for θ to move THETA_LAG, then
    /// catches up: it never lags the exact Nakamura solution by more than that.
    #[test]
    fn the_structural_temperature_lags_nakamura_by_at_most_theta_lag() {
        let p = Params::default();
        let t = ZERO_CELSIUS + 55.0;
        let mut k = Kinetics::new(&p);
        let (mut tf, mut theta) = (ZERO_CELSIUS + 60.0, 0.0);
        let theta0 =
            softplus(-2.0 * (tf - p.pcl_melting_temperature) / p.pcl_melting_width).powf(1.0 / p.avrami_exponent);
        let (h, steps) = (1e-3, 200_000);
        let mut moves = 0;
        for _ in 0..steps {
            let next = k.advance(&mut theta, tf, t, h, t);
            moves += usize::from(next != tf);
            tf = next;
        }
        let exact = theta0 + nakamura_rate(&p, t) * h * steps as f64;
        let held =
            softplus(-2.0 * (tf - p.pcl_melting_temperature) / p.pcl_melting_width).powf(1.0 / p.avrami_exponent);
        println!("θ {theta} exact {exact}; T_f's θ {held}; {moves} moves in {steps} steps");
        assert!((theta - exact).abs() < 1e-9 * exact);
        assert!(exact - held <= THETA_LAG * 1.001 && exact >= held, "{exact} {held}");
        assert!(moves > 0 && moves < steps / 10);
    }

    #[test]
    fn modulus_temperature_is_the_temperature_on_the_heating_branch() {
        let p = Params::default();
        for k in 0..100 {
            let t = ZERO_CELSIUS + 10.0 + 0.7 * k as f64;
            assert_eq!(modulus_temperature(&p, t, t), t);
        }
        // a supercooled melt at 30 °C reads the amorphous (60 °C) row
        let t = ZERO_CELSIUS + 30.0;
        let am = modulus_temperature(&p, t, ZERO_CELSIUS + 90.0);
        assert!((am - (ZERO_CELSIUS + 60.0)).abs() < 1e-4, "{am}");
    }
}
