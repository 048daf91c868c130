//! Residual analysis as a system-identification engineer does it, and ranking of the effect
//! library (docs/physics.md §8).
//!
//! Two kinds of evidence: (1) signatures of the residual e = y − ŷ itself: harmonic content over
//! whole cycles (DC, 1ω, 2ω, 3ω, 5ω), whiteness (autocorrelation; low-frequency structure against
//! the noise floor), correlation with candidate regressors (sign of link speed, sin and cos of the
//! link angle, the dead-zone signature sign of motor speed, time within the run), and patterns
//! across frequency and temperature; (2) a score test per effect: the FMU's sensitivity of the
//! link angle to the effect's parameters at the current fit, projected on the residual orthogonal
//! to the parameters already fitted. That projection predicts how much of the residual the effect
//! can explain and with what value (one Gauss–Newton step from "off"), which ranks the candidates.

use super::signal::harmonics;
use nalgebra::DMatrix;

use super::fit::{Effect, Fit, ModelSpec, Problem, MAXWELL_TIME_GRID};

/// Stribeck velocities tried before the Stribeck excess's own fit (its velocity is not
/// identifiable while the excess is 0), as shares of the motion's speed scale
/// ([`Problem::speed_scale`]): the excess shows only where the link's speeds span its velocity,
/// so the grid moves with the rig. (It was 0.01, 0.05 and 0.2 rad/s, about 1–20 % of the
/// paper's bench's 1 rad/s; fresh campaign rig 121 has 0.8 rad/s at 3.1 rad/s.)
pub const STRIBECK_VELOCITY_SHARES: [f64; 4] = [0.02, 0.06, 0.2, 0.6];

/// The Stribeck velocities tried for `prob`'s runs, rad/s (the paper's bench's scale, 1 rad/s,
/// where the runs are too short to tell theirs).
pub fn stribeck_velocity_grid(prob: &Problem) -> [f64; STRIBECK_VELOCITY_SHARES.len()] {
    let scale = prob.speed_scale().unwrap_or(1.0);
    STRIBECK_VELOCITY_SHARES.map(|share| share * scale)
}

/// Thermal lags probed before the lag's own fit, as shares of the runs' median span. The PCL starts
/// level with the thermocouple and falls behind it by its drift rate times the lag, so the lag's
/// effect on a run changes shape with its size, not only its scale: one secant of 0.5 s projected
/// campaign rig 55's 2.5 s lag (a 5 K heating over 17 s) on the wrong sign, and it was never refitted.
/// (A lag as long as the run is plausible: the paper heats its PCL over 30–90 s.) Lags longer
/// than the span change the shape again: the PCL barely leaves its start, where a short lag's PCL
/// follows the thermocouple. Rig 1526's 13.2 s lag over two 6.5 s segments (screened on their
/// first 2.4 s) projected on the wrong sign from every probe up to 2.4 s (−1.7 to −2.2 s), and
/// from 7 and 24 s projected at +10 and +20 s.
pub const THERMAL_LAG_SHARES: [f64; 7] = [0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0];

/// The thermal lags probed for `prob`'s runs, s (`THERMAL_LAG_SHARES` of their median span).
pub fn thermal_lag_grid(prob: &Problem) -> [f64; THERMAL_LAG_SHARES.len()] {
    let mut spans: Vec<f64> =
        prob.inputs.iter().filter(|i| i.time.len() > 1).map(|i| i.time[i.time.len() - 1] - i.time[0]).collect();
    spans.sort_by(f64::total_cmp);
    let span = spans.get(spans.len() / 2).copied().unwrap_or(1.0);
    THERMAL_LAG_SHARES.map(|share| share * span)
}

/// Window of the moving average that exposes low-frequency structure, samples.
pub const STRUCTURE_WINDOW: usize = 25;
/// Smoothed residual above this many times the white-noise expectation is "structure".
pub const STRUCTURE_LIMIT: f64 = 3.0;

/// Per-run residual statistics.
#[derive(Clone, Debug, serde::Serialize)]
pub struct RunResidual {
    pub rmse: f64,
    /// Amplitudes of DC, 1ω, 2ω, 3ω, 5ω over whole cycles after the first, rad.
    pub harmonics: [f64; 5],
    /// 1ω component in phase with the motor's fundamental and in quadrature (leading), rad.
    pub fundamental_in_phase: f64,
    pub fundamental_quadrature: f64,
    /// RMS of the residual over the first and last third of the run (after the first cycle).
    pub early_rms: f64,
    pub late_rms: f64,
}

/// Residual signatures pooled over runs.
#[derive(Clone, Debug, serde::Serialize)]
pub struct Signatures {
    pub rmse: f64,
    /// Noise floor estimated from the data alone: what a perfect model leaves of the measured link
    /// angle, the larger of the white noise (`signal::cubic_noise`'s mean square) and an encoder's
    /// q/√12 (`signal::quantisation_floor`: none on a signal that is not quantised). The white
    /// noise alone misses a coarse encoder's error: while the link holds still it reads zero,
    /// yet the reading is off by up to q/2 (campaign rigs 7 and 18, steps with noise ≪ q: 0.78 and
    /// 0.52 of q/√12).
    pub noise_floor: f64,
    /// RMS of the 25-sample moving average of e over what a right model's residual leaves there
    /// (≈ 1 for one): white noise's σ̂/√25, or through a count the noise does not dither, the
    /// count's error on the model's angle (`LinkCount::right_model_error`) where that is more.
    pub structure_ratio: f64,
    pub autocorrelation: Vec<(usize, f64)>,
    pub corr_sign_link_speed: f64,
    pub corr_sin_link_angle: f64,
    pub corr_cos_link_angle: f64,
    pub corr_dead_zone: f64,
    pub corr_time: f64,
    pub runs: Vec<RunResidual>,
}

/// A residual harmonic at 2ω, 3ω or 5ω this many times what white noise at the floor leaves in a
/// least-squares harmonic over the run's samples (σ √(2/N)), or what the link encoder's count
/// leaves there where that is more ([`count_overtones`]), is structure, not noise.
pub const NONLINEAR_HARMONIC_LIMIT: f64 = 10.0;

impl Signatures {
    /// The nonlinear reference (issue 18): the harmonics at 2ω, 3ω and 5ω left in the residual of
    /// the sinusoidal runs, over what noise would leave there: white noise at the floor (σ √(2/N)
    /// for N samples) or, where larger, the run's link encoder (`count`, from [`count_overtones`]);
    /// the median over those runs; None without a sinusoidal run. The transmission's K and C are
    /// linear and leave the 1ω alone: what remains above at the harmonics is a nonlinearity the
    /// model lacks, the library's or another (a hardening spring, a stiffness that depends on the
    /// link angle).
    pub fn leftover_harmonics(&self, lengths: &[usize], sinusoidal: &[bool], count: &[f64]) -> Option<f64> {
        let mut ratios: Vec<f64> = self
            .runs
            .iter()
            .zip(lengths)
            .zip(sinusoidal)
            .enumerate()
            .filter(|(_, (_, &s))| s)
            .map(|(i, ((r, &n), _))| {
                let white = self.noise_floor * (2.0 / n.max(1) as f64).sqrt();
                let noise = white.max(count.get(i).copied().unwrap_or(0.0));
                r.harmonics[2..].iter().fold(0.0_f64, |m, &h| m.max(h)) / noise.max(1e-300)
            })
            .collect();
        if ratios.is_empty() {
            return None;
        }
        ratios.sort_by(f64::total_cmp);
        Some(ratios[ratios.len() / 2])
    }

    pub fn white(&self) -> bool {
        self.structure_ratio < STRUCTURE_LIMIT
    }
}

/// Where a run's harmonics are read: whole cycles after the first, at the orders 1, 2, 3 and 5 below
/// the Nyquist frequency (above it they alias onto others: never evidence).
struct HarmonicWindow {
    w0: f64,
    orders: Vec<usize>,
    t0: f64,
    t1: f64,
}

impl HarmonicWindow {
    fn of(t: &[f64], f: f64) -> Self {
        let n = t.len();
        let span = t[n - 1] - t[0];
        let period = 1.0 / f;
        let cycles = ((span - period) / period).floor().max(0.0);
        let nyquist = 0.5 * (n - 1) as f64 / span;
        HarmonicWindow {
            w0: 2.0 * std::f64::consts::PI * f,
            orders: [1, 2, 3, 5].into_iter().filter(|&k| (k as f64) * f < nyquist).collect(),
            t0: t[0] + period,
            t1: t[0] + period * (1.0 + cycles),
        }
    }

    /// The largest amplitude at 2ω, 3ω or 5ω of `e`.
    fn largest_overtone(&self, t: &[f64], e: &[f64]) -> f64 {
        let (_, hs) = harmonics(t, e, self.w0, &self.orders, self.t0, self.t1);
        self.orders.iter().zip(hs).filter(|(&k, _)| k > 1).fold(0.0_f64, |m, (_, (c, s))| m.max(c.hypot(s)))
    }
}

/// A run's link encoder as a reading of the model's angle: its count `q` on its `grid` (a reading
/// is grid + q·n) and the sensor's noise `sigma` under the count, chosen so that the model's angle
/// with that noise added, read to the counts, has the measured column's cubic-residual noise (noise
/// dithers the count and takes the period out of its error; none where the count alone reads as
/// noisy as the column). Measured once per problem, against the first model judged
/// (`Problem::link_counts`): the noise under a count hardly depends on the model's angle.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkCount {
    pub q: f64,
    pub grid: f64,
    pub sigma: f64,
    /// The standard normal draws of the sensor's noise, one per sample, from `seed`: drawn once,
    /// read by every whiteness test of the problem (a draw costs a log, a root and a cosine).
    draws: Vec<f64>,
    seed: u64,
}

impl LinkCount {
    /// None for a column that is not quantised.
    pub fn of(time: &[f64], measured: &[f64], model: &[f64], seed: u64) -> Option<LinkCount> {
        let q = super::signal::quantum(measured);
        if q == 0.0 || measured.len() != model.len() || time.len() != model.len() || time.len() < 5 {
            return None;
        }
        let grid = measured[0] - q * (measured[0] / q).round();
        let draws = normal_draws(model.len(), seed);
        // at least 5 samples: the cubic residuals are never empty, so this is their rms
        let cubic_noise = |x: &[f64]| super::signal::cubic_noise(time, x);
        let target = cubic_noise(measured);
        let at = |sigma: f64| LinkCount { q, grid, sigma, draws: Vec::new(), seed };
        // bisection on σ (the reading's cubic-residual noise grows with it)
        let sigma = if cubic_noise(&at(0.0).reading(model, &draws)) >= target {
            0.0
        } else {
            let (mut lo, mut hi) = (0.0, 2.0 * target.max(q));
            for _ in 0..16 {
                let mid = 0.5 * (lo + hi);
                if cubic_noise(&at(mid).reading(model, &draws)) < target {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            0.5 * (lo + hi)
        };
        Some(LinkCount { draws, ..at(sigma) })
    }

    /// `model` with the sensor's noise (`draws` of a standard normal) added, read to the counts.
    fn reading(&self, model: &[f64], draws: &[f64]) -> Vec<f64> {
        let read = |x: f64| self.grid + self.q * ((x - self.grid) / self.q).round();
        model.iter().zip(draws).map(|(m, z)| read(m + self.sigma * z)).collect()
    }

    /// What the residual of a model that is right would hold: `model` read through this encoder
    /// (its noise the draws it was measured with, or as many from the same seed for a model of
    /// another length), less `model`.
    pub fn right_model_error(&self, model: &[f64]) -> Vec<f64> {
        let redrawn;
        let draws = if model.len() == self.draws.len() {
            &self.draws
        } else {
            redrawn = normal_draws(model.len(), self.seed);
            &redrawn
        };
        self.reading(model, draws).iter().zip(model).map(|(a, m)| a - m).collect()
    }

    /// Whether the sensor's noise dithers the count (σ ≥ q/√12, as `signal`'s band limit reads it):
    /// its error is then near white; below, a link held still dwells on one count, an error that
    /// stays while the link does.
    pub fn dithered(&self) -> bool {
        self.sigma >= self.q / 12f64.sqrt()
    }
}

fn normal_draws(n: usize, seed: u64) -> Vec<f64> {
    let mut rng = super::synthetic::SplitMix::new(seed);
    (0..n).map(|_| rng.normal()).collect()
}

/// The seed of run `r`'s simulated sensor noise (`LinkCount`), the same in every call.
pub(crate) fn count_seed(r: usize) -> u64 {
    0x9E37_79B9_7F4A_7C15 ^ (r as u64 + 1)
}

/// What a perfect model leaves at 2ω, 3ω or 5ω through each run's link encoder (the largest of
/// the three, rad; 0 for a column that is not quantised). A count's error on a periodic angle is
/// itself periodic and lands on the harmonics, where white noise would spread: rig 267 (the truth's
/// effects within 1 %, 1.02× its floor) left 24× what white noise at its floor leaves there, and
/// rig 297 41× (docs/calibration.md). Read through `LinkCount::right_model_error` on the sinusoidal
/// runs only, as the harmonic test is (0 for the others).
pub fn count_overtones(prob: &Problem, fit: &Fit) -> Vec<f64> {
    let sinusoidal = prob.sinusoidal();
    let counts = prob.link_counts(&fit.outputs);
    (0..prob.inputs.len())
        .map(|r| match (sinusoidal.get(r), counts.get(r), fit.outputs.get(r)) {
            (Some(true), Some(Some(count)), Some(model)) => {
                let inp = &prob.inputs[r];
                let error = count.right_model_error(model);
                HarmonicWindow::of(&inp.time, inp.frequency_hz).largest_overtone(&inp.time, &error)
            }
            _ => 0.0,
        })
        .collect()
}

/// The sum of squares of `e`'s `w`-sample moving average over every full window, and the windows'
/// count.
fn smoothed_squares(e: &[f64], w: usize) -> (f64, f64) {
    let (mut acc, mut sum, mut count) = (0.0, 0.0, 0.0);
    for k in 0..e.len() {
        acc += e[k];
        if k >= w {
            acc -= e[k - w];
        }
        if k + 1 >= w {
            sum += (acc / w as f64).powi(2);
            count += 1.0;
        }
    }
    (sum, count)
}

/// Pearson correlation of two equally long series (0 when either is constant).
pub(crate) fn corr(a: &[f64], b: &[f64]) -> f64 {
    weighted_corr(a, b, None)
}

/// Pearson's correlation of `a` and `b` with each pair weighted by `w` (every weight 1 for None);
/// 0 where either is constant.
pub(crate) fn weighted_corr(a: &[f64], b: &[f64], w: Option<&[f64]>) -> f64 {
    let weight = |i: usize| w.map_or(1.0, |w| w[i]);
    let total: f64 = (0..a.len()).map(weight).sum();
    let mean = |x: &[f64]| x.iter().enumerate().map(|(i, x)| x * weight(i)).sum::<f64>() / total;
    let (ma, mb) = (mean(a), mean(b));
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        sab += weight(i) * (x - ma) * (y - mb);
        saa += weight(i) * (x - ma).powi(2);
        sbb += weight(i) * (y - mb).powi(2);
    }
    if saa <= 0.0 || sbb <= 0.0 {
        0.0
    } else {
        sab / (saa * sbb).sqrt()
    }
}

fn sign_of_slope(x: &[f64], k: usize, half: usize) -> f64 {
    let a = x[k.saturating_sub(half)];
    let b = x[(k + half).min(x.len() - 1)];
    (b - a).signum()
}

pub fn signatures(prob: &Problem, fit: &Fit) -> Signatures {
    let mut offset = 0;
    let (mut all_e, mut speed, mut sinl, mut cosl, mut dead, mut time) =
        (vec![], vec![], vec![], vec![], vec![], vec![]);
    let mut runs = Vec::new();
    let mut noise_num = 0.0f64;
    let mut noise_den = 0.0f64;
    let mut smooth_sq = 0.0;
    let mut smooth_n = 0.0f64;
    let mut acf: Vec<(usize, f64, f64)> = [1usize, 2, 5, 10, 50].iter().map(|&l| (l, 0.0, 0.0)).collect();
    let counts = prob.link_counts(&fit.outputs);
    // per run: its windows and, through a count the noise does not dither, the smoothed squares a
    // right model's residual would leave
    let mut dwell: Vec<(f64, Option<f64>)> = Vec::new();
    for (r, inp) in prob.inputs.iter().enumerate() {
        let y = &prob.measured[r];
        let n = y.len();
        let e = &fit.residual[offset..offset + n];
        offset += n;
        let model = &fit.outputs[r];
        let t = &inp.time;
        for r in super::signal::cubic_residuals(&inp.time, y) {
            noise_num += r * r;
            noise_den += 1.0;
        }
        let span = t[n - 1] - t[0];
        for k in 0..n {
            all_e.push(e[k]);
            speed.push(sign_of_slope(model, k, 1));
            sinl.push(y[k].sin());
            cosl.push(y[k].cos());
            dead.push(sign_of_slope(&inp.motor, k, 5));
            time.push((t[k] - t[0]) / span);
        }
        let (sq, windows) = smoothed_squares(e, STRUCTURE_WINDOW);
        smooth_sq += sq;
        smooth_n += windows;
        // what a right model's residual leaves through a count the noise does not dither (None:
        // white noise's share, below)
        let count = counts.get(r).and_then(Option::as_ref).filter(|c| !c.dithered());
        dwell.push((windows, count.map(|c| smoothed_squares(&c.right_model_error(model), STRUCTURE_WINDOW).0)));
        let var: f64 = e.iter().map(|x| x * x).sum::<f64>();
        for (lag, num, den) in acf.iter_mut() {
            if *lag < n {
                *num += (0..n - *lag).map(|k| e[k] * e[k + *lag]).sum::<f64>();
                *den += var;
            }
        }
        let HarmonicWindow { w0, orders, t0, t1 } = HarmonicWindow::of(t, inp.frequency_hz);
        let (dc, hs_below) = harmonics(t, e, w0, &orders, t0, t1);
        let hs: Vec<(f64, f64)> = [1, 2, 3, 5]
            .iter()
            .map(|k| orders.iter().position(|o| o == k).map_or((0.0, 0.0), |i| hs_below[i]))
            .collect();
        let (_, motor_h) = harmonics(t, &inp.motor, w0, &[1], t0, t1);
        // phase of the residual's fundamental relative to the motor's
        let (mc, ms) = motor_h[0];
        let mamp = mc.hypot(ms).max(1e-300);
        let (ec, es) = hs[0];
        // motor ≈ A sin(wt + φ) with (cos, sin) coefficients (mc, ms): in-phase unit (ms, mc)/A
        let in_phase = (es * ms + ec * mc) / mamp;
        let quadrature = (ec * ms - es * mc) / mamp;
        let third = (t1 - t0) / 3.0;
        let rms_between = |a: f64, b: f64| {
            let v: Vec<f64> = (0..n).filter(|&k| t[k] >= a && t[k] < b).map(|k| e[k] * e[k]).collect();
            if v.is_empty() {
                0.0
            } else {
                (v.iter().sum::<f64>() / v.len() as f64).sqrt()
            }
        };
        runs.push(RunResidual {
            rmse: (e.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt(),
            harmonics: [
                dc.abs(),
                hs[0].0.hypot(hs[0].1),
                hs[1].0.hypot(hs[1].1),
                hs[2].0.hypot(hs[2].1),
                hs[3].0.hypot(hs[3].1),
            ],
            fundamental_in_phase: in_phase,
            fundamental_quadrature: quadrature,
            early_rms: rms_between(t0, t0 + third),
            late_rms: rms_between(t1 - third, t1),
        });
    }
    // the whiteness test compares with white noise of the cubic residuals' size (a second
    // difference's, without the motion's curvature): quantisation held still is not white, and
    // counting it there would hide structure
    let white_noise = (noise_num / noise_den.max(1.0)).sqrt();
    let noise_floor = white_noise.max(super::signal::pooled_quantisation_floor(prob.measured.iter().map(|y| &y[..])));
    let smooth_rms = (smooth_sq / smooth_n.max(1.0)).sqrt();
    // A right model's smoothed residual: white noise's, or where a count dwells while the link
    // holds still, what that count leaves (a constant error per hold, up to q/2, which the moving
    // average keeps whole). CI rig 3 (steps, 1 700 counts a turn under 2.9e-4 rad of noise) read
    // 4.1× white noise with the truth's friction and damping in, and took a Maxwell branch for it.
    let white_sq = white_noise.powi(2) / STRUCTURE_WINDOW as f64;
    let expected_sq =
        dwell.iter().map(|&(windows, sq)| sq.map_or(windows * white_sq, |sq| sq.max(windows * white_sq))).sum::<f64>();
    let expected_rms = (expected_sq / smooth_n.max(1.0)).sqrt();
    Signatures {
        rmse: fit.rmse(),
        noise_floor,
        structure_ratio: smooth_rms / expected_rms,
        autocorrelation: acf.into_iter().map(|(l, a, b)| (l, if b > 0.0 { a / b } else { 0.0 })).collect(),
        corr_sign_link_speed: corr(&all_e, &speed),
        corr_sin_link_angle: corr(&all_e, &sinl),
        corr_cos_link_angle: corr(&all_e, &cosl),
        corr_dead_zone: corr(&all_e, &dead),
        corr_time: corr(&all_e, &time),
        runs,
    }
}

/// One ranked candidate (the ranking every rig shares: `stepwise::Linearised`).
pub type Candidate = super::stepwise::Ranked<Effect>;

/// Score test of every effect not yet in the model; best first.
/// An effect `unseen` names (one these runs cannot show: a lag behind a thermocouple that holds
/// still, a Maxwell branch at one frequency per temperature) is listed, not probed: no simulation
/// is needed to know that it changes nothing the fit does not already have.
pub fn rank(prob: &Problem, fit: &Fit, sig: &Signatures, unseen: impl Fn(Effect) -> bool) -> Vec<Candidate> {
    let lin = super::stepwise::Linearised::new(&fit.jacobian, &fit.residual);
    let sse_now = lin.sse;
    let mut out = Vec::new();
    for effect in Effect::ALL {
        if fit.spec.effects.contains(&effect) {
            continue;
        }
        let mut spec = fit.spec.clone();
        spec.effects.push(effect);
        let base = fit.p.len();
        let k = effect.params().len();
        // Secant probes: the effect "off" against the effect at a few sizes (one Gauss–Newton
        // step would be blind to effects that are not smooth at zero, such as a dead zone);
        // the Maxwell branch's λ is scanned over a grid with K_M probed.
        let mut settings: Vec<(f64, f64)> = Vec::new(); // (size factor, λ)
        match effect {
            e if unseen(e) => {}
            Effect::FrequencyDependentModulus => settings.extend(MAXWELL_TIME_GRID.iter().map(|&l| (1.0, l))),
            Effect::CoulombFriction | Effect::Backlash => settings.extend([1.0, 5.0].map(|f| (f, f64::NAN))),
            // an excess is ranked only over its base (`Effect::defined_over`); the search pairs them
            e if e.defined_over().is_some_and(|b| !fit.spec.effects.contains(&b)) => {}
            Effect::StribeckFriction => settings.extend(stribeck_velocity_grid(prob).map(|v| (1.0, v))),
            Effect::ThermalLag => {
                let typical = effect.params()[0].1;
                settings.extend(thermal_lag_grid(prob).map(|lag| (lag / typical, f64::NAN)))
            }
            // an asymmetry shows only on top of friction the model already has
            Effect::AsymmetricFriction
                if !fit.spec.effects.iter().any(|e| matches!(e, Effect::CoulombFriction | Effect::LinkDamping)) => {}
            // never beside the effect that took its place (`Effect::takes_place_of`)
            e if fit.spec.effects.iter().any(|x| x.takes_place_of() == Some(e)) => {}
            Effect::Gravity | Effect::LinkDamping | Effect::AsymmetricFriction | Effect::ConstantLoad => {
                settings.push((1.0, f64::NAN))
            }
        }
        let mut best: Option<(f64, Vec<f64>, Vec<f64>)> = None;
        for (size, lam) in settings {
            let mut p0 = fit.p.clone();
            p0.extend(std::iter::repeat_n(0.0, k));
            let probe_cols: Vec<usize> =
                if matches!(effect, Effect::FrequencyDependentModulus | Effect::StribeckFriction) {
                    p0[base + 1] = lam.ln();
                    vec![base]
                } else {
                    (base..base + k).collect()
                };
            let step = |j: usize| size * effect.params()[j - base].1;
            let jobs: Vec<_> = probe_cols
                .iter()
                .flat_map(|&j| {
                    let mut q = p0.clone();
                    q[j] += step(j);
                    let spec = &spec;
                    (0..prob.inputs.len()).map(move |run| (run, prob.run_model(spec, &q, run))).collect::<Vec<_>>()
                })
                .collect();
            let res = prob.sim.run_jobs(&prob.inputs, &jobs);
            if res.iter().any(|r| r.is_err()) {
                continue;
            }
            let mut s = DMatrix::zeros(fit.n, probe_cols.len());
            for (ci, &j) in probe_cols.iter().enumerate() {
                let h = step(j);
                let mut row = 0;
                for run in 0..prob.inputs.len() {
                    let out = res[ci * prob.inputs.len() + run].as_ref().unwrap();
                    for (a, b) in out.iter().zip(&fit.outputs[run]) {
                        s[(row, ci)] = (a - b) / h;
                        row += 1;
                    }
                }
            }
            let (sse_aug, beta) = lin.with(&s);
            let mut start = p0[base..].to_vec();
            let mut physical = true;
            for (ci, &j) in probe_cols.iter().enumerate() {
                start[j - base] = p0[j] + beta[base + ci];
                if effect.params()[j - base].2.is_some_and(|b| start[j - base] < b) {
                    physical = false;
                }
            }
            let gain = if physical { (sse_now - sse_aug).max(0.0) } else { 0.0 };
            super::stepwise::debug(format_args!(
                "probe {effect:?} × {size:.3}: linearised start {start:?}, SSE {sse_now:.4e} → {sse_aug:.4e}"
            ));
            if best.as_ref().is_none_or(|b| gain > b.0) {
                best = Some((gain, start, beta.rows(0, base).iter().copied().collect()));
            }
        }
        let (gain, start, moved) = best.unwrap_or((0.0, vec![0.0; k], Vec::new()));
        let score = gain / sse_now.max(1e-300);
        let predicted_delta_bic = super::stepwise::predicted_delta_bic(fit.n, sse_now, gain, k);
        let evidence = if effect == Effect::FrequencyDependentModulus && unseen(effect) {
            MAXWELL_UNSEEN.to_string()
        } else {
            evidence_text(prob, effect, sig, score, predicted_delta_bic, &start)
        };
        out.push(Candidate { effect, score, predicted_delta_bic, start, moved, evidence });
    }
    out.sort_by(|a, b| b.score.partial_cmp(&a.score).unwrap_or(std::cmp::Ordering::Equal));
    out
}

/// Why a Maxwell branch is not tried on sinusoids at one frequency per temperature.
pub const MAXWELL_UNSEEN: &str =
    "not tried: every run is a sinusoid at its temperature's one frequency, where a Maxwell \
    branch's steady state is a change of that temperature's K and C, which the fit already has (only start transients \
    and the harmonics of other effects could show it, and those are what it would stand in for)";

/// True when some run's thermocouple moves by more than 0.05 K.
pub fn thermocouple_varies(prob: &Problem) -> bool {
    prob.inputs.iter().any(|i| i.housing_k.iter().any(|&t| (t - i.housing_k[0]).abs() > 0.05))
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    if n == 0 {
        0.0
    } else {
        s / n as f64
    }
}

fn evidence_text(prob: &Problem, effect: Effect, sig: &Signatures, score: f64, dbic: f64, start: &[f64]) -> String {
    let runs = &sig.runs;
    let h = |i: usize| mean(runs.iter().map(|r| r.harmonics[i]));
    let ratio3 = h(3) / h(1).max(1e-300);
    let head = format!(
        "explains {:.1}% of the residual sum of squares (FMU sensitivity projected on the residual; predicted ΔBIC {:+.0}); ",
        100.0 * score,
        dbic
    );
    let body = match effect {
        Effect::CoulombFriction => format!(
            "corr(e, sign θl') = {:+.2}; odd harmonics 3ω/1ω = {:.2}, 5ω = {:.2e} rad; linearised torque {:.3} N·m",
            sig.corr_sign_link_speed, ratio3, h(4), start[0]
        ),
        Effect::Backlash => format!(
            "dead-zone signature corr(e, sign θm') = {:+.2}; 3ω/1ω = {:.2}; linearised width {:.2e} rad",
            sig.corr_dead_zone, ratio3, start[0]
        ),
        Effect::Gravity => format!(
            "corr(e, sin θl) = {:+.2}, corr(e, cos θl) = {:+.2}; DC {:.2e} rad; 3ω/1ω = {:.2}; linearised m·g·d = {:.3} N·m, offset {:+.3} rad",
            sig.corr_sin_link_angle, sig.corr_cos_link_angle, h(0), ratio3, start[0].hypot(start[1]), start[1].atan2(start[0])
        ),
        Effect::LinkDamping => format!(
            "1ω quadrature residual mean {:+.2e} rad (in phase {:+.2e}); linearised damping {:.3} N·m·s/rad",
            mean(runs.iter().map(|r| r.fundamental_quadrature)),
            mean(runs.iter().map(|r| r.fundamental_in_phase)),
            start[0]
        ),
        Effect::ThermalLag => {
            let drift = mean(runs.iter().map(|r| r.early_rms / r.late_rms.max(1e-300)));
            let heating = thermocouple_varies(prob);
            format!(
                "corr(e, time in run) = {:+.2}; early/late residual RMS = {:.2}; thermocouple {} within runs; linearised time constant {:.2} s",
                sig.corr_time, drift, if heating { "varies" } else { "is constant (no lag can show)" }, start[0]
            )
        }
        Effect::StribeckFriction => format!(
            "corr(e, sign θl') = {:+.2}; linearised static excess {:.3} N·m fading over {:.3} rad/s",
            sig.corr_sign_link_speed,
            start[0],
            start[1].exp()
        ),
        Effect::AsymmetricFriction => format!(
            "DC {:.2e} rad, corr(e, sign θl') = {:+.2}; linearised Coulomb half-difference {:+.3} N·m, viscous {:+.3} N·m·s/rad",
            h(0),
            sig.corr_sign_link_speed,
            start[0],
            start[1]
        ),
        Effect::ConstantLoad => format!("DC {:.2e} rad; linearised torque {:+.3} N·m", h(0), start[0]),
        Effect::FrequencyDependentModulus => {
            let mut pairs = Vec::new();
            for g in 0..prob.n_groups {
                let ip: Vec<(f64, f64)> = (0..prob.inputs.len())
                    .filter(|&r| prob.group[r] == g)
                    .map(|r| (prob.inputs[r].frequency_hz, runs[r].fundamental_in_phase))
                    .collect();
                if ip.len() > 1 {
                    pairs.push(ip.iter().map(|(f, v)| format!("{f:.3} Hz {v:+.1e}")).collect::<Vec<_>>().join(" / "));
                }
            }
            let text = if pairs.is_empty() { "only one frequency per temperature: cannot separate".to_string() } else { pairs.join("; ") };
            format!("1ω in-phase residual across frequencies at each temperature: {text}; linearised K_M = {:.3} N·m/rad at λ = {:.3} s", start[0], start[1].exp())
        }
    };
    head + &body
}

/// Report-friendly spec of a model.
pub fn spec_names(spec: &ModelSpec) -> Vec<&'static str> {
    spec.effects.iter().map(|e| e.name()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::synthetic::SplitMix;
    use std::f64::consts::PI;

    /// `count_overtones` for one run: its link encoder found against `model` and its error on it.
    fn count_overtone(time: &[f64], measured: &[f64], model: &[f64], frequency_hz: f64, seed: u64) -> f64 {
        LinkCount::of(time, measured, model, seed)
            .map_or(0.0, |c| HarmonicWindow::of(time, frequency_hz).largest_overtone(time, &c.right_model_error(model)))
    }

    /// A 0.5 Hz sine read at 1 kHz by a 2 000-count encoder with 2e-5 rad of noise under the count:
    /// the count's error on the true angle lands on the harmonics, far above what white noise at
    /// the floor (q/√12) leaves there; the reference read off the model's own angle takes it as
    /// noise, and still sees a third harmonic the model lacks.
    #[test]
    fn a_count_on_a_periodic_angle_is_noise_at_the_harmonics_and_a_missing_overtone_is_not() {
        let (f, amplitude, q) = (0.5, 0.05, 2.0 * PI / 2000.0);
        let time: Vec<f64> = (0..20_000).map(|k| k as f64 * 1e-3).collect();
        let sine: Vec<f64> = time.iter().map(|t| amplitude * (2.0 * PI * f * t).sin()).collect();
        let mut rng = SplitMix::new(7);
        let read = |x: &[f64], rng: &mut SplitMix| -> Vec<f64> {
            x.iter().map(|a| q * ((a + 2e-5 * rng.normal()) / q).round() + 0.3 * q).collect()
        };
        let white = q / 12f64.sqrt() * (2.0 / time.len() as f64).sqrt();
        let window = HarmonicWindow::of(&time, f);
        let overtone_left = |measured: &[f64], model: &[f64]| {
            let residual: Vec<f64> = measured.iter().zip(model).map(|(y, m)| y - m).collect();
            window.largest_overtone(&time, &residual)
        };

        // the right model: its residual is the count's error alone
        let measured = read(&sine, &mut rng);
        let left = overtone_left(&measured, &sine);
        let count = count_overtone(&time, &measured, &sine, f, 1);
        assert!(
            left / white > NONLINEAR_HARMONIC_LIMIT,
            "the count's error reads as structure to white noise's test: {}",
            left / white
        );
        assert!(
            left / white.max(count) < NONLINEAR_HARMONIC_LIMIT / 2.0,
            "the count's reference takes it as noise: {} ({left:.2e} against {count:.2e})",
            left / white.max(count)
        );

        // a third harmonic of about one count the model lacks stays structure
        let truth: Vec<f64> = time.iter().zip(&sine).map(|(t, s)| s + 3e-3 * (6.0 * PI * f * t).sin()).collect();
        let measured = read(&truth, &mut rng);
        let left = overtone_left(&measured, &sine);
        let count = count_overtone(&time, &measured, &sine, f, 1);
        assert!(
            left / white.max(count) > NONLINEAR_HARMONIC_LIMIT,
            "a missing overtone: {} ({left:.2e} against {count:.2e})",
            left / white.max(count)
        );

        // a column that is not quantised has no count to leave anything
        let smooth: Vec<f64> = sine.iter().map(|s| s + 1e-4 * rng.normal()).collect();
        assert_eq!(count_overtone(&time, &smooth, &sine, f, 1), 0.0);
    }
}
