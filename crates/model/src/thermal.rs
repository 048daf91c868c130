//! Two-node thermal network: heater + housing skin (where the thermocouple sits) and the PCL,
//! whose state is its enthalpy so that latent heat is conserved exactly (docs/physics.md §5):
//!
//!   C_h T_h' = P − G_hp (T_h − T_p) − G_ha (T_h − T_amb)
//!   H_p'     = G_hp (T_h − T_p),           T_p = h⁻¹(H_p)
//!
//! H_p = h_s(T_p) + m L χ(T_f): the sensible enthalpy h_s(T) = m [c_s (T − T_r) + (c_l − c_s) ∫χ]
//! plus the latent heat of the molten part. χ is the melting curve (a tanh step of half-width
//! `pcl_melting_width` around `pcl_melting_temperature`, the logistic CDF), and the PCL's molten
//! fraction is χ(T_f) at its structural temperature T_f ≥ T_p: the temperature at which the heating
//! branch holds the PCL's crystallinity X = X_c (1 − χ(T_f)) (docs/physics.md §5a). On heating T_f
//! follows T_p (melting is fast and rate-independent) and h_s + m L χ(T_p) = h(T_p) is the old
//! equilibrium enthalpy exactly; on cooling T_f falls only as Nakamura's kinetics crystallise the
//! melt, whose latent heat m L Δχ stays inside H_p and so is released into T_p. Heater energy and
//! the loss to ambient are integrated by the same Runge–Kutta step, which preserves the linear
//! invariant E_in = ΔU_h + ΔH_p + E_loss to rounding, latent heat included.

use super::crystallisation;
use super::params::{Crystallisation, Params, ThermalDrive, ZERO_CELSIUS};

/// Reference temperature of the enthalpy scale, K (its value cancels in every balance).
const ENTHALPY_REFERENCE: f64 = ZERO_CELSIUS;

#[derive(Clone, Debug, PartialEq)]
pub struct ThermalState {
    pub housing_temperature: f64,
    pub pcl_enthalpy: f64,
    /// T_p from pcl_enthalpy and the structural temperature, kept in step with them.
    pub pcl_temperature: f64,
    /// T_f ≥ T_p: the heating branch's temperature for the PCL's crystallinity, X = X_c (1 − χ(T_f));
    /// T_f = T_p on the heating branch (equilibrium), above it while the melt is supercooled.
    pub pcl_structural_temperature: f64,
    /// Nakamura's integral θ = ∫K dt of the crystallisation under way (α = 1 − exp(−θⁿ)); below
    /// θ(T_f) it stands for θ(T_f), and it is 0 on the heating branch
    /// ([`crystallisation::Kinetics::advance`]).
    pub pcl_crystallisation_integral: f64,
    pub heater_energy: f64,
    pub heat_lost: f64,
}

pub struct ThermalInputs {
    pub heater_power: f64,
    pub ambient_temperature: f64,
    pub housing_temperature_command: f64,
}

fn ln_cosh(x: f64) -> f64 {
    let a = x.abs();
    if a > 20.0 {
        return a - std::f64::consts::LN_2; // ln(1 + e^{−2a}) < 5e-18 is below half an ulp of a
    }
    a + (-2.0 * a).exp().ln_1p() - std::f64::consts::LN_2
}

/// Melt fraction χ(T) in [0, 1].
pub fn melt_fraction(p: &Params, t: f64) -> f64 {
    0.5 * (1.0 + ((t - p.pcl_melting_temperature) / p.pcl_melting_width).tanh())
}

/// Equilibrium PCL enthalpy relative to 0 °C (the heating branch, T_f = T), J.
pub fn pcl_enthalpy(p: &Params, t: f64) -> f64 {
    pcl_sensible_enthalpy(p, t) + melt_latent_heat(p, t)
}

/// Latent heat held by the molten part of a PCL at structural temperature T_f, m L χ(T_f), J.
pub fn melt_latent_heat(p: &Params, structural: f64) -> f64 {
    p.pcl_mass * p.pcl_latent_heat * melt_fraction(p, structural)
}

/// Sensible part h_s of the PCL enthalpy relative to 0 °C (no latent heat), J.
pub fn pcl_sensible_enthalpy(p: &Params, t: f64) -> f64 {
    let w = p.pcl_melting_width;
    let x = (t - p.pcl_melting_temperature) / w;
    let xr = (ENTHALPY_REFERENCE - p.pcl_melting_temperature) / w;
    let melt_integral = 0.5 * (t - ENTHALPY_REFERENCE) + 0.5 * w * (ln_cosh(x) - ln_cosh(xr));
    p.pcl_mass
        * (p.pcl_specific_heat_solid * (t - ENTHALPY_REFERENCE)
            + (p.pcl_specific_heat_melt - p.pcl_specific_heat_solid) * melt_integral)
}

/// dh_s/dT, J/K.
pub fn pcl_sensible_heat_capacity(p: &Params, t: f64) -> f64 {
    let chi = melt_fraction(p, t);
    p.pcl_mass * (p.pcl_specific_heat_solid + (p.pcl_specific_heat_melt - p.pcl_specific_heat_solid) * chi)
}

/// Apparent heat capacity dh/dT, J/K (sensible + latent).
pub fn pcl_heat_capacity(p: &Params, t: f64) -> f64 {
    let w = p.pcl_melting_width;
    let sech = 1.0 / ((t - p.pcl_melting_temperature) / w).cosh();
    let chi = melt_fraction(p, t);
    p.pcl_mass
        * (p.pcl_specific_heat_solid
            + (p.pcl_specific_heat_melt - p.pcl_specific_heat_solid) * chi
            + p.pcl_latent_heat * 0.5 * sech * sech / w)
}

/// Inverts the equilibrium enthalpy by Newton's method kept inside a bracket (h is monotone,
/// h' ≥ m·min c).
pub fn pcl_temperature_from_enthalpy(p: &Params, enthalpy: f64, guess: f64) -> f64 {
    invert(p, false, enthalpy, guess)
}

/// The PCL temperature of enthalpy H at structural temperature T_f: h_s⁻¹(H − m L χ(T_f)) while
/// that lies below T_f, else (the melt caught up: the heating branch) h⁻¹(H).
pub fn pcl_temperature_at(p: &Params, enthalpy: f64, structural: f64, guess: f64) -> f64 {
    let t = invert(p, true, enthalpy - melt_latent_heat(p, structural), guess);
    if t < structural {
        t
    } else {
        invert(p, false, enthalpy, guess)
    }
}

/// Newton in a bracket on h (`sensible` false) or h_s (true).
fn invert(p: &Params, sensible: bool, enthalpy: f64, guess: f64) -> f64 {
    type Curve = fn(&Params, f64) -> f64;
    let (h, dh): (Curve, Curve) =
        if sensible { (pcl_sensible_enthalpy, pcl_sensible_heat_capacity) } else { (pcl_enthalpy, pcl_heat_capacity) };
    let c_min = p.pcl_mass * p.pcl_specific_heat_solid.min(p.pcl_specific_heat_melt);
    let r0 = enthalpy - h(p, guess);
    if r0 == 0.0 {
        return guess;
    }
    let span = r0.abs() / c_min;
    let (mut lo, mut hi) = if r0 > 0.0 { (guess, guess + span) } else { (guess - span, guess) };
    let mut t = guess;
    for _ in 0..100 {
        let r = enthalpy - h(p, t);
        if r > 0.0 {
            lo = t
        } else {
            hi = t
        }
        let mut next = t + r / dh(p, t);
        if !(next > lo && next < hi) {
            next = 0.5 * (lo + hi);
        }
        if (next - t).abs() <= 1e-13 * t.abs() || hi - lo <= 1e-13 * t.abs() {
            return next;
        }
        t = next;
    }
    t
}

/// The enthalpy curve h(T) and its first five derivatives from one `exp_m1` and one `ln_1p`
/// (tanh, sech² and ln cosh of the melt step share exp(−2|x|)).
struct EnthalpyCurve {
    mass: f64,
    c_solid: f64,
    c_delta: f64,
    latent: f64,
    melt_t: f64,
    width: f64,
    inv_width: f64,
    /// ln cosh at the reference temperature.
    ln_cosh_ref: f64,
}

impl EnthalpyCurve {
    /// h_s (`sensible`) or h.
    fn of(p: &Params, sensible: bool) -> Self {
        let mut c = Self::new(p);
        if sensible {
            c.latent = 0.0;
        }
        c
    }

    fn new(p: &Params) -> Self {
        EnthalpyCurve {
            mass: p.pcl_mass,
            c_solid: p.pcl_specific_heat_solid,
            c_delta: p.pcl_specific_heat_melt - p.pcl_specific_heat_solid,
            latent: p.pcl_latent_heat,
            melt_t: p.pcl_melting_temperature,
            width: p.pcl_melting_width,
            inv_width: 1.0 / p.pcl_melting_width,
            ln_cosh_ref: ln_cosh((ENTHALPY_REFERENCE - p.pcl_melting_temperature) / p.pcl_melting_width),
        }
    }

    /// h(t) and its first five derivatives (J, J/K, …, J/K⁵): the function [`pcl_enthalpy`].
    fn eval(&self, t: f64) -> [f64; 6] {
        // One division for the whole evaluation (divisions are the slow instructions here).
        let w = self.width;
        let x = (t - self.melt_t) * self.inv_width;
        let a = x.abs();
        let em = (-2.0 * a).exp_m1(); // exp(−2|x|) − 1, accurate near x = 0
        let inv = 1.0 / (2.0 + em);
        let tanh = (-em * inv).copysign(x);
        let sech2 = 4.0 * (1.0 + em) * inv * inv;
        let ln_cosh = a + (1.0 + em).ln_1p() - std::f64::consts::LN_2;
        let iw = self.inv_width;
        let chi = 0.5 * (1.0 + tanh);
        let chi1 = 0.5 * sech2 * iw;
        let chi2 = -tanh * sech2 * iw * iw;
        let chi3 = (2.0 * tanh * tanh * sech2 - sech2 * sech2) * iw * iw * iw;
        // d^k tanh/dx^k: s, −2ts, 4t²s − 2s², 16ts² − 8t³s, 16s³ − 88t²s² + 16t⁴s (s = sech²)
        let (th, s2) = (tanh, sech2);
        let chi4 = (8.0 * th * s2 * s2 - 4.0 * th * th * th * s2) * (iw * iw) * (iw * iw);
        let chi5 =
            (8.0 * s2 * s2 * s2 - 44.0 * th * th * s2 * s2 + 8.0 * th * th * th * th * s2) * (iw * iw) * (iw * iw) * iw;
        let melt_integral = 0.5 * (t - ENTHALPY_REFERENCE) + 0.5 * w * (ln_cosh - self.ln_cosh_ref);
        let m = self.mass;
        [
            m * (self.c_solid * (t - ENTHALPY_REFERENCE) + self.c_delta * melt_integral + self.latent * chi),
            m * (self.c_solid + self.c_delta * chi + self.latent * chi1),
            m * (self.c_delta * chi1 + self.latent * chi2),
            m * (self.c_delta * chi2 + self.latent * chi3),
            m * (self.c_delta * chi3 + self.latent * chi4),
            m * (self.c_delta * chi4 + self.latent * chi5),
        ]
    }
}

/// Largest |ΔH/h'| (K) for which [`Inversion`] uses its series: the truncation error is O(ΔT⁶)
/// and stays below 1e-12 K up to here (unit test below); beyond it Newton runs. The anchors are
/// [`ANCHOR_LATTICE`] apart and a 1 ms step moves the PCL by < 3 mK even at 15 W.
const SERIES_LIMIT: f64 = 1e-2;

/// ...and no more than this fraction of the melting width: the series' radius is set by the melt
/// step's width, so the default 2.5 K keeps 1e-2 K, while a step 1e-3 K wide would put 1e-2 K ten
/// widths out, where the series diverges (a state 2.4e-3 K off its enthalpy, found by the fuzzer).
const SERIES_WIDTH_FRACTION: f64 = 4e-3;

/// Spacing of the anchor temperatures of the inverse series, K (a binary fraction: exact).
const ANCHOR_LATTICE: f64 = 1.0 / 128.0;

/// h⁻¹ near an anchor temperature T0: the inverse series of h to fifth order around T0, anchored
/// on h(T0) evaluated afresh (so no error carries from step to step); Newton beyond its limit.
#[derive(Clone, Debug)]
pub struct Inversion {
    t0: f64,
    h0: f64,
    inv_slope: f64,
    c: [f64; 4],
    /// Of h_s instead of h (the supercooled melt: latent heat held at m L χ(T_f)).
    sensible: bool,
}

/// The inverse series of the enthalpy about the anchor nearest the PCL temperature, kept while
/// the PCL stays near that anchor. A cache: the anchor is a function of the PCL temperature alone
/// (rounded to [`ANCHOR_LATTICE`]), so a step gives the same result whether or not it was kept
/// (a restored state continues bit-identically).
#[derive(Clone, Debug, Default)]
pub struct InversionCache {
    inversion: Option<Inversion>,
    /// The same for h_s (cooling off the heating branch).
    sensible: Option<Inversion>,
    /// The crystallisation kinetics' constants and the current structural temperature's quantities.
    kinetics: Option<crystallisation::Kinetics>,
}

impl InversionCache {
    fn kinetics(&mut self, p: &Params) -> &mut crystallisation::Kinetics {
        self.kinetics.get_or_insert_with(|| crystallisation::Kinetics::new(p))
    }

    fn anchored<'a>(slot: &'a mut Option<Inversion>, p: &Params, t: f64, sensible: bool) -> &'a Inversion {
        // x + 2^52 − 2^52 rounds x to an integer (|x| < 2^51) without a libm call.
        const SHIFT: f64 = 4_503_599_627_370_496.0;
        let anchor = ((t / ANCHOR_LATTICE + SHIFT) - SHIFT) * ANCHOR_LATTICE;
        if !matches!(slot, Some(inv) if inv.t0 == anchor) {
            *slot = Some(Inversion::at(&EnthalpyCurve::of(p, sensible), anchor, sensible));
        }
        slot.as_ref().expect("set above")
    }
}

impl Inversion {
    fn at(curve: &EnthalpyCurve, t0: f64, sensible: bool) -> Self {
        let [h0, d1, d2, d3, d4, d5] = curve.eval(t0);
        let inv_slope = 1.0 / d1;
        // h(T0 + δ) − h0 = d1 (δ + b2 δ² + b3 δ³ + b4 δ⁴ + b5 δ⁵ + …); its reversion:
        let (b2, b3) = (d2 * inv_slope / 2.0, d3 * inv_slope / 6.0);
        let (b4, b5) = (d4 * inv_slope / 24.0, d5 * inv_slope / 120.0);
        let c = [
            -b2,
            2.0 * b2 * b2 - b3,
            -5.0 * b2 * b2 * b2 + 5.0 * b2 * b3 - b4,
            14.0 * b2 * b2 * b2 * b2 - 21.0 * b2 * b2 * b3 + 6.0 * b2 * b4 + 3.0 * b3 * b3 - b5,
        ];
        Inversion { t0, h0, inv_slope, c, sensible }
    }

    #[cfg(test)]
    fn temperature(&self, p: &Params, enthalpy: f64) -> f64 {
        self.temperature_at(p, (enthalpy - self.h0) * self.inv_slope)
    }

    /// h⁻¹ at the enthalpy h0 + a·h'(T0) (a in K).
    #[inline]
    fn temperature_at(&self, p: &Params, a: f64) -> f64 {
        if a.abs() <= SERIES_LIMIT.min(SERIES_WIDTH_FRACTION * p.pcl_melting_width) {
            let c = &self.c;
            // Estrin's order: each Runge–Kutta stage waits on this, so its depth is the cost.
            let a2 = a * a;
            self.t0 + a * ((1.0 + a * c[0]) + a2 * ((c[1] + a * c[2]) + a2 * c[3]))
        } else {
            self.newton(p, a)
        }
    }

    #[inline(never)]
    fn newton(&self, p: &Params, a: f64) -> f64 {
        invert(p, self.sensible, self.h0 + a / self.inv_slope, self.t0 + a)
    }
}

/// T_p at enthalpy `start_h + offset` with the structural temperature held (a cooling or
/// supercooled PCL): from h_s while below T_f, else the heating branch's. Out of line: the heating
/// step never calls it.
#[inline(never)]
#[allow(clippy::too_many_arguments)]
fn off_branch(
    p: &Params,
    eq: &Inversion,
    base: f64,
    sensible: Option<&(&Inversion, f64, f64)>,
    start_h: f64,
    offset: f64,
    structural: f64,
    start_t: f64,
) -> f64 {
    let t = match sensible {
        Some((si, bs, _)) => si.temperature_at(p, bs + offset * si.inv_slope),
        None => pcl_temperature_at(p, start_h + offset, structural, start_t),
    };
    if t < structural {
        t
    } else {
        eq.temperature_at(p, base + offset * eq.inv_slope)
    }
}

impl ThermalState {
    pub fn initial(p: &Params) -> Self {
        let t_p = p.initial_pcl_temperature;
        ThermalState {
            housing_temperature: p.initial_housing_temperature,
            pcl_enthalpy: pcl_enthalpy(p, t_p),
            pcl_temperature: t_p,
            pcl_structural_temperature: t_p,
            pcl_crystallisation_integral: 0.0,
            heater_energy: 0.0,
            heat_lost: 0.0,
        }
    }

    /// Heat stored in both nodes relative to 0 °C, J (latent heat of the molten part included).
    pub fn stored_heat(&self, p: &Params) -> f64 {
        p.housing_heat_capacity * (self.housing_temperature - ENTHALPY_REFERENCE) + self.pcl_enthalpy
    }

    /// Latent heat held by the molten part of the PCL, m L χ(T_f), J.
    pub fn latent_heat(&self, p: &Params) -> f64 {
        melt_latent_heat(p, self.pcl_structural_temperature)
    }

    /// The temperature the material table is read at ([`crystallisation::modulus_temperature`]).
    pub fn modulus_temperature(&self, p: &Params) -> f64 {
        crystallisation::modulus_temperature(p, self.pcl_temperature, self.pcl_structural_temperature)
    }

    /// Advances by `h` seconds (one third-order Runge–Kutta step: the network's time constants are
    /// seconds, the internal step milliseconds).
    pub fn advance(&mut self, p: &Params, u: &ThermalInputs, h: f64) {
        self.advance_cached(p, u, h, &mut InversionCache::default());
    }

    /// [`ThermalState::advance`] keeping the enthalpy's inverse series in `cache` (same result).
    /// Returns the temperature the mechanics reads its moduli at over the step: the PCL temperature
    /// at the step's midpoint (see [`ThermalState::advance_network`]), moved towards the amorphous
    /// row by the crystallinity the PCL lacks at the step's start
    /// ([`crystallisation::modulus_temperature`]; the midpoint itself on the heating branch).
    pub fn advance_cached(&mut self, p: &Params, u: &ThermalInputs, h: f64, cache: &mut InversionCache) -> f64 {
        let structural = self.pcl_structural_temperature;
        let mid = match p.thermal_drive {
            ThermalDrive::Heater => self.advance_network(p, u, h, cache),
            ThermalDrive::PrescribedHousing => {
                let start = self.pcl_temperature;
                self.advance_prescribed(p, u, h, cache);
                0.5 * (start + self.pcl_temperature)
            }
        };
        if structural <= mid || p.crystallisation == Crystallisation::Equilibrium {
            return mid;
        }
        cache.kinetics(p).modulus_temperature(mid, structural)
    }

    /// The heater network's step; returns the midpoint PCL temperature as its Runge–Kutta step's
    /// second stage has it, h⁻¹(H_p + h/2·P_hp): a function of the step's start alone, ready before
    /// the rest of the step, so the mechanics that waits on it need not wait for the whole
    /// thermal step (the mean of the start and end temperatures would serialise the two). It
    /// differs from that mean by about h²/4·T_p'': at most 1.2e-7 K at 1 ms heating at 15 W
    /// through the melt (a unit test below), 3e-8 of the moduli.
    ///
    /// With crystallisation kinetics, a stage whose enthalpy lies below the heating branch's at T_f
    /// (a cooling PCL, or one still supercooled) takes its temperature from h_s with the latent heat
    /// held at m L χ(T_f); the crystallisation step follows the thermal step at fixed enthalpy, so
    /// the latent heat it releases raises T_p and no energy is made or lost.
    fn advance_network(&mut self, p: &Params, u: &ThermalInputs, h: f64, cache: &mut InversionCache) -> f64 {
        let kinetic = p.crystallisation == Crystallisation::Nakamura;
        let structural = self.pcl_structural_temperature;
        let on_branch = !kinetic || structural <= self.pcl_temperature;
        if u.heater_power == 0.0
            && self.housing_temperature == self.pcl_temperature
            && self.housing_temperature == u.ambient_temperature
            && on_branch
        {
            // Exact equilibrium: every flux is zero, so the Runge–Kutta step would change nothing.
            return self.pcl_temperature;
        }
        // Kutta's third-order Runge–Kutta on (T_h, H_p) (k2 at the midpoint, k3 at x − h k1 + 2h k2,
        // weights 1/6, 4/6, 1/6): the network's time constants are seconds (C_h/(G_hp + G_ha) =
        // 5.4 s, the PCL's 16 s and more in the melt), the step a millisecond, so its error at 1 ms
        // is 2.3e-11 K over 200 s of heating at 15 W through the melt (the unit test below, against
        // tenth-length steps), and splitting a communication step still changes the temperatures
        // by rounding alone (tests/fmi_conformance.rs), with three stages instead of classical RK4's
        // four on a chain every step waits on. (The explicit midpoint rule, two stages, was tried:
        // 8.4e-8 K, and a split step moved the temperature by 1.8e-9 K.) The PCL temperature at a
        // stage comes from the inverse series about the anchor nearest the step's start
        // temperature: with x the stage's enthalpy offset from the stored H_p, T_p = h⁻¹(H_p + x),
        // whose series argument is base + x/h'.
        let start_t = self.pcl_temperature;
        let start_h = self.pcl_enthalpy;
        // disjoint borrows of the cache's parts (no copies on the hot path)
        let InversionCache { inversion, sensible: sensible_slot, kinetics } = cache;
        let eq = InversionCache::anchored(inversion, p, start_t, false);
        let base = (start_h - eq.h0) * eq.inv_slope;
        // h_s's inverse series about the same anchor, with the latent heat held (cooling only).
        let sensible = if kinetic && (!on_branch || self.housing_temperature < start_t) {
            let latent = kinetics.get_or_insert_with(|| crystallisation::Kinetics::new(p)).latent_heat(structural);
            let si = InversionCache::anchored(sensible_slot, p, start_t, true);
            let bs = (start_h - latent - si.h0) * si.inv_slope;
            Some((si, bs, latent))
        } else {
            None
        };
        // T_p at enthalpy start_h + offset with the structural temperature held.
        let pcl_at = |offset: f64| {
            if on_branch && (offset >= 0.0 || !kinetic) {
                eq.temperature_at(p, base + offset * eq.inv_slope)
            } else {
                off_branch(p, eq, base, sensible.as_ref(), start_h, offset, structural, start_t)
            }
        };
        let (g_hp, g_ha) = (p.heater_pcl_conductance, p.housing_ambient_conductance);
        let (power, ambient) = (u.heater_power, u.ambient_temperature);
        let hc = h / p.housing_heat_capacity;
        let t0 = self.housing_temperature;
        // Stage fluxes (into the PCL, lost to ambient), W; the housing gets P minus both.
        let flux = |t_h: f64, t_p: f64| (g_hp * (t_h - t_p), g_ha * (t_h - ambient));
        let (p1, l1) = flux(t0, start_t);
        let midpoint = pcl_at(0.5 * h * p1);
        let (p2, l2) = flux(t0 + 0.5 * hc * (power - p1 - l1), midpoint);
        let (p3, l3) = flux(t0 + hc * (2.0 * (power - p2 - l2) - (power - p1 - l1)), pcl_at(h * (2.0 * p2 - p1)));
        const SIXTH: f64 = 1.0 / 6.0;
        let pcl = SIXTH * (p1 + 4.0 * p2 + p3);
        let lost = SIXTH * (l1 + 4.0 * l2 + l3);
        self.housing_temperature = t0 + hc * (power - pcl - lost);
        let new_enthalpy = start_h + h * pcl;
        if new_enthalpy != start_h {
            self.pcl_temperature = pcl_at(new_enthalpy - start_h);
            self.pcl_enthalpy = new_enthalpy;
        }
        self.heater_energy += h * power;
        self.heat_lost += h * lost;
        if kinetic {
            let t_end = self.pcl_temperature;
            if structural <= t_end {
                // on the heating branch: melting keeps up
                self.pcl_structural_temperature = t_end;
            } else {
                let kinetics = kinetics.get_or_insert_with(|| crystallisation::Kinetics::new(p));
                let next = kinetics.advance(&mut self.pcl_crystallisation_integral, structural, midpoint, h, t_end);
                if next != structural {
                    // Latent heat released at fixed enthalpy: T_p from h_s with the new latent term.
                    let released = if next > t_end { kinetics.latent_heat(next) } else { 0.0 };
                    let t = match &sensible {
                        Some((si, bs, latent)) => {
                            si.temperature_at(p, bs + (new_enthalpy - start_h + latent - released) * si.inv_slope)
                        }
                        None => invert(p, true, new_enthalpy - released, t_end),
                    };
                    if t < next {
                        self.pcl_temperature = t;
                        self.pcl_structural_temperature = next;
                    } else {
                        // crystallised up to the heating branch
                        self.pcl_temperature = pcl_temperature_from_enthalpy(p, new_enthalpy, t_end);
                        self.pcl_structural_temperature = self.pcl_temperature;
                    }
                }
            }
        } else {
            self.pcl_structural_temperature = self.pcl_temperature;
        }
        if self.pcl_structural_temperature <= self.pcl_temperature {
            self.pcl_crystallisation_integral = 0.0;
        }
        midpoint
    }

    fn advance_prescribed(&mut self, p: &Params, u: &ThermalInputs, h: f64, cache: &mut InversionCache) {
        let t_h = u.housing_temperature_command;
        self.housing_temperature = t_h;
        let start = self.pcl_temperature;
        let t_p = if p.thermal_lag_time_constant > 0.0 {
            t_h + (start - t_h) * (-h / p.thermal_lag_time_constant).exp()
        } else {
            t_h
        };
        let structural = if p.crystallisation == Crystallisation::Equilibrium || self.pcl_structural_temperature <= t_p
        {
            self.pcl_crystallisation_integral = 0.0;
            t_p
        } else {
            let theta = &mut self.pcl_crystallisation_integral;
            cache.kinetics(p).advance(theta, self.pcl_structural_temperature, 0.5 * (start + t_p), h, t_p)
        };
        if t_p != start || structural != self.pcl_structural_temperature {
            self.pcl_temperature = t_p;
            self.pcl_structural_temperature = structural;
            // the heating branch's enthalpy where the melt has caught up (T_f ≤ T_p)
            self.pcl_enthalpy = pcl_sensible_enthalpy(p, t_p) + melt_latent_heat(p, structural.max(t_p));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Default parameters, heated at 15 W from ambient (22 °C), through the melt.
    fn heating_at_15_w() -> (Params, ThermalInputs) {
        let p = Params::default();
        let u = ThermalInputs {
            heater_power: 15.0,
            ambient_temperature: p.initial_pcl_temperature,
            housing_temperature_command: p.initial_pcl_temperature,
        };
        (p, u)
    }

    /// The midpoint the mechanics reads (the second Runge–Kutta stage's PCL temperature) against
    /// the mean of the step's start and end, heating at 15 W from 22 °C through the melt and on.
    #[test]
    fn midpoint_temperature_is_the_step_mean_to_second_order() {
        let (p, u) = heating_at_15_w();
        let mut s = ThermalState::initial(&p);
        let mut cache = InversionCache::default();
        let mut worst: f64 = 0.0;
        for _ in 0..120_000 {
            let start = s.pcl_temperature;
            let mid = s.advance_cached(&p, &u, 1e-3, &mut cache);
            worst = worst.max((mid - 0.5 * (start + s.pcl_temperature)).abs());
        }
        println!("max |midpoint − mean| = {worst:e} K, PCL at {} °C", s.pcl_temperature - ZERO_CELSIUS);
        assert!(s.pcl_temperature > ZERO_CELSIUS + 70.0, "the run crosses the melt");
        assert!(worst < 2e-7, "{worst:e} K");
    }

    /// The thermal step's own error: 1 ms steps against 0.1 ms steps (a thousandth of the error at
    /// third order) over 200 s at 15 W, from 22 °C through the melt to 266 °C.
    #[test]
    fn thermal_step_error_at_1_ms_is_below_1e10_kelvin() {
        let (p, u) = heating_at_15_w();
        let (mut coarse, mut fine) = (ThermalState::initial(&p), ThermalState::initial(&p));
        let (mut c1, mut c2) = (InversionCache::default(), InversionCache::default());
        let mut worst: f64 = 0.0;
        for _ in 0..200_000 {
            coarse.advance_cached(&p, &u, 1e-3, &mut c1);
            for _ in 0..10 {
                fine.advance_cached(&p, &u, 1e-4, &mut c2);
            }
            worst = worst
                .max((coarse.pcl_temperature - fine.pcl_temperature).abs())
                .max((coarse.housing_temperature - fine.housing_temperature).abs());
        }
        println!("max |T(1 ms) − T(0.1 ms)| = {worst:e} K, PCL at {} °C", fine.pcl_temperature - ZERO_CELSIUS);
        assert!(fine.pcl_temperature > ZERO_CELSIUS + 200.0, "the run crosses the melt");
        assert!(worst < 1e-10, "{worst:e} K");
    }

    #[test]
    fn enthalpy_inversion_round_trips_across_the_melt() {
        let p = Params::default();
        for k in 0..200 {
            let t = ZERO_CELSIUS + 10.0 + 0.4 * k as f64;
            let back = pcl_temperature_from_enthalpy(&p, pcl_enthalpy(&p, t), t - 7.0);
            assert!((back - t).abs() < 1e-9, "{t} -> {back}");
        }
    }

    #[test]
    fn enthalpy_curve_equals_pcl_enthalpy_and_its_derivatives() {
        let p = Params::default();
        let curve = EnthalpyCurve::new(&p);
        for k in 0..400 {
            let t = ZERO_CELSIUS + 10.0 + 0.2 * k as f64 + 0.013;
            let [h, d1, d2, d3, d4, d5] = curve.eval(t);
            let exact = pcl_enthalpy(&p, t);
            assert!((h - exact).abs() < 1e-13 * exact.abs().max(1.0), "{t}: {h} vs {exact}");
            assert!((d1 - pcl_heat_capacity(&p, t)).abs() < 1e-12 * d1, "{t}");
            let e = 1e-4;
            let num2 = (pcl_heat_capacity(&p, t + e) - pcl_heat_capacity(&p, t - e)) / (2.0 * e);
            assert!((d2 - num2).abs() < 1e-6 * d1, "{t}: {d2} vs {num2}");
            let num3 = (curve.eval(t + e)[2] - curve.eval(t - e)[2]) / (2.0 * e);
            assert!((d3 - num3).abs() < 1e-6 * d1, "{t}: {d3} vs {num3}");
            let num4 = (curve.eval(t + e)[3] - curve.eval(t - e)[3]) / (2.0 * e);
            assert!((d4 - num4).abs() < 1e-6 * d1, "{t}: {d4} vs {num4}");
            let num5 = (curve.eval(t + e)[4] - curve.eval(t - e)[4]) / (2.0 * e);
            assert!((d5 - num5).abs() < 1e-6 * d1, "{t}: {d5} vs {num5}");
        }
    }

    /// The series inversion finds the temperature to 1e-12 K wherever it is used (measured 5.7e-14 K,
    /// one ulp of T, at the fifth order up to 1e-2 K; Newton's stopping rule, 1e-13 relative,
    /// leaves up to 3e-11 K).
    #[test]
    fn series_inversion_matches_newton_within_its_limit() {
        let p = Params::default();
        let curve = EnthalpyCurve::new(&p);
        let mut worst: f64 = 0.0;
        for k in 0..800 {
            let t0 = ZERO_CELSIUS + 10.0 + 0.1 * k as f64 + 0.0123;
            let inv = Inversion::at(&curve, t0, false);
            for frac in [-1.0, -0.5, -0.1, 0.01, 0.3, 0.99] {
                let target = t0 + frac * SERIES_LIMIT * 0.9;
                worst = worst.max((inv.temperature(&p, pcl_enthalpy(&p, target)) - target).abs());
            }
            // beyond the limit Newton runs
            let h = pcl_enthalpy(&p, t0 + 0.05);
            assert!((inv.temperature(&p, h) - (t0 + 0.05)).abs() < 1e-10);
        }
        assert!(worst < 1e-12, "series inversion off by {worst:e} K");
    }

    #[test]
    fn heat_capacity_is_the_derivative_of_enthalpy() {
        let p = Params::default();
        for t in [300.0, 325.0, 331.15, 333.0, 340.0] {
            let d = 1e-4;
            let numeric = (pcl_enthalpy(&p, t + d) - pcl_enthalpy(&p, t - d)) / (2.0 * d);
            assert!((numeric - pcl_heat_capacity(&p, t)).abs() < 1e-5 * numeric, "{t}");
        }
    }

    /// Hand calculation: 3.3 g from 22 to 60 °C costs about 250 J sensible [PAPER] plus
    /// χ(60 °C)·m·L of latent heat.
    #[test]
    fn sensible_and_latent_heat_match_hand_calculation() {
        let p = Params::default();
        let t0 = ZERO_CELSIUS + 22.0;
        let t1 = ZERO_CELSIUS + 60.0;
        let total = pcl_enthalpy(&p, t1) - pcl_enthalpy(&p, t0);
        let latent = p.pcl_mass * p.pcl_latent_heat * (melt_fraction(&p, t1) - melt_fraction(&p, t0));
        let sensible = total - latent;
        // sensible heat lies between the all-solid and all-melt bounds
        let lo = p.pcl_mass * p.pcl_specific_heat_solid * 38.0;
        let hi = p.pcl_mass * p.pcl_specific_heat_melt * 38.0;
        assert!(sensible > lo && sensible < hi, "{sensible} not in [{lo}, {hi}]");
        assert!((sensible - 250.0).abs() < 40.0, "sensible {sensible} J vs ~250 J in the paper");
        assert!(total > 400.0 && total < 500.0, "total {total} J vs 480–500 J in the paper");
    }
}
