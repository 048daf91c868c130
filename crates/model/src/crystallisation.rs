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
use super::params::{Crystallisation, Params, ZERO_CELSIUS};

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

/// The structural temperature after crystallising for `h` s at PCL temperature `t` (Nakamura:
/// θ += K(t) h), never below `floor` (the PCL temperature the step ends at).
pub fn crystallise(p: &Params, structural: f64, t: f64, h: f64, floor: f64) -> f64 {
    if p.crystallisation == Crystallisation::Equilibrium || structural <= floor {
        return floor;
    }
    let k = nakamura_rate(p, t);
    if k == 0.0 {
        return structural;
    }
    let (tm, w, n) = (p.pcl_melting_temperature, p.pcl_melting_width, p.avrami_exponent);
    // θⁿ = −ln χ(T_f) = ln(1 + e^{−2x})
    let g = softplus(-2.0 * (structural - tm) / w);
    let theta = g.powf(1.0 / n) + k * h;
    let g = theta.powf(n);
    // χ = e^{−g} = 1/(1 + e^{−2x})  ⇒  x = −ln(e^g − 1)/2
    let ln_expm1 = if g > 40.0 { g } else { g.exp_m1().ln() };
    (tm - 0.5 * w * ln_expm1).max(floor)
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

    #[test]
    fn isothermal_crystallisation_is_half_done_at_the_half_time() {
        let p = Params::default();
        let t = ZERO_CELSIUS + 40.0;
        let t_half = half_time(&p, t);
        // from a melt so hot that the melting curve's tail leaves no crystal (α = e^-194)
        let mut tf = ZERO_CELSIUS + 300.0;
        let steps = 10_000;
        for _ in 0..steps {
            tf = crystallise(&p, tf, t, t_half / steps as f64, t);
        }
        let alpha = crystallinity(&p, tf) / ultimate_crystallinity(&p);
        assert!((alpha - 0.5).abs() < 1e-9, "α(t½) = {alpha}");
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
