//! Signal processing shared by the calibration's parts (data conditioning, the equation error,
//! diagnosis, the references, the report, the drive loop): smoothing and differentiation, noise
//! level, harmonics and spectra. Plain functions of sampled signals: no model in them.

use nalgebra::{Complex, DMatrix, DVector};

use super::fit::spd_inverse;

/// Centre weights of a Savitzky–Golay smoother: least-squares polynomial of `order` over
/// i = −m..m, evaluated at 0 (Savitzky & Golay 1964).
fn savitzky_golay_weights(m: usize, order: usize) -> Vec<f64> {
    let rows = 2 * m + 1;
    let cols = (order + 1).min(rows);
    // abscissae scaled to [-1, 1] keep XᵀX well conditioned (the weights do not depend on it)
    let x = DMatrix::from_fn(rows, cols, |i, j| ((i as f64 - m as f64) / m as f64).powi(j as i32));
    let pinv = (x.transpose() * &x).pseudo_inverse(1e-14).expect("small SPD matrix") * x.transpose();
    (0..rows).map(|i| pinv[(0, i)]).collect()
}

/// Zero-phase quintic Savitzky–Golay smoothing over 2m+1 samples, by sample index (uneven
/// sampling is smoothed as if even; the window shrinks
/// symmetrically at the ends). Quintics pass unchanged, so a 0.5–1 Hz sinusoid keeps its
/// amplitude to O((ω m Δt)⁶).
pub fn savitzky_golay(x: &[f64], half: usize) -> Vec<f64> {
    let n = x.len();
    let mut cache: Vec<Option<Vec<f64>>> = vec![None; half + 1];
    (0..n)
        .map(|k| {
            let m = half.min(k).min(n - 1 - k);
            if m < 3 {
                return x[k];
            }
            let w = cache[m].get_or_insert_with(|| savitzky_golay_weights(m, 5));
            w.iter().enumerate().map(|(i, wi)| wi * x[k + i - m]).sum()
        })
        .collect()
}

/// The rms speed, in units per sample period, that white noise of unit σ leaves after quintic
/// Savitzky–Golay smoothing over 2·half+1 samples (`savitzky_golay`) and a central difference
/// (x[k+1] − x[k−1])/2: √Σ d_i² over the difference of the smoother's impulse response.
pub fn smoothed_speed_gain(half: usize) -> f64 {
    let centre = 2 * half + 1;
    let mut impulse = vec![0.0; 2 * centre + 1];
    impulse[centre] = 1.0;
    let h = savitzky_golay(&impulse, half);
    h.windows(3).map(|w| (0.5 * (w[2] - w[0])).powi(2)).sum::<f64>().sqrt()
}

/// Whether `t` is an even grid: every interval within 1e-3 of the median (CSV rounding passes,
/// a logger's jitter does not).
pub fn is_even_grid(t: &[f64]) -> bool {
    if t.len() < 3 {
        return true;
    }
    let median = super::quality::median_period(t);
    t.windows(2).all(|w| ((w[1] - w[0]) - median).abs() <= 1e-3 * median)
}

/// Zero-phase quintic smoothing over 2m+1 samples on any grid: Savitzky–Golay on an even grid,
/// else the same local least-squares quintic fitted in the samples' own times (a logger's jitter
/// would otherwise read as noise of the size speed × jitter). From `SLIDING_FROM` samples each side
/// the windows' moments slide along the run (`sliding_quintic`): the same fit, up to rounding, at a
/// cost that does not grow with the window.
pub fn smooth(t: &[f64], x: &[f64], half: usize) -> Vec<f64> {
    let n = x.len();
    if half >= SLIDING_FROM && t.len() == n && n > 2 * half + 1 {
        if let Some(s) = sliding_quintic(t, x, half) {
            return s;
        }
    }
    if is_even_grid(t) {
        return savitzky_golay(x, half);
    }
    (0..n).map(|k| local_quintic(t, x, k, half.min(k).min(n - 1 - k))).collect()
}

/// The half width from which `smooth` slides its windows' moments instead of summing each window
/// afresh (2·half+1 samples × 11 powers per sample). The equation error's windows reach 1 % of a
/// run each side: on fresh rig 1047 (three jittered runs of 168 000 samples, windows of ±1 680)
/// the fresh sums took about 45 % of the calibration's CPU time (perf). Below it the windows are short:
/// an even grid's Savitzky–Golay weights (2·half+1 multiply-adds a sample) cost less than the slide's
/// origin shift and solve, and short windows keep the arithmetic they always had.
const SLIDING_FROM: usize = 32;

/// The quintic fitted by least squares to the 2m+1 samples around `k`, in their own times, at t_k
/// (x_k itself for m < 3, or where the fit is singular).
fn local_quintic(t: &[f64], x: &[f64], k: usize, m: usize) -> f64 {
    if m < 3 {
        return x[k];
    }
    let span = (t[k + m] - t[k - m]).max(f64::MIN_POSITIVE);
    // moments Σu^j (j ≤ 10) and Σx u^j (j ≤ 5) of u = (t − t_k)/span in [−1, 1]
    let mut moments = WindowMoments::default();
    for i in k - m..=k + m {
        moments.add((t[i] - t[k]) / span, x[i], 1.0);
    }
    moments.centre().unwrap_or(x[k])
}

/// Binomial coefficients C(j, l) for j, l ≤ 10 (Pascal's triangle), as floats (exact: at most 252)
/// for the slide's origin shift.
const BINOMIAL: [[f64; 11]; 11] = {
    let mut c = [[0.0f64; 11]; 11];
    let mut j = 0;
    while j < 11 {
        c[j][0] = 1.0;
        let mut l = 1;
        while l <= j {
            c[j][l] = c[j - 1][l - 1] + c[j - 1][l];
            l += 1;
        }
        j += 1;
    }
    c
};

/// A window's moments about an origin: Σu^j (j ≤ 10) and Σx·u^j (j ≤ 5), u the samples' times
/// from the origin in some fixed unit; what a local least-squares quintic needs.
#[derive(Clone, Copy, Default)]
struct WindowMoments {
    u: [f64; 11],
    xu: [f64; 6],
}

impl WindowMoments {
    /// Adds (sign 1) or removes (sign −1) the sample x at u.
    fn add(&mut self, u: f64, x: f64, sign: f64) {
        let mut p = sign;
        for j in 0..11 {
            self.u[j] += p;
            if j < 6 {
                self.xu[j] += x * p;
            }
            p *= u;
        }
    }

    /// Moves the origin forward by δ: Σ(u − δ)^j = Σ_l C(j, l) (−δ)^(j−l) Σu^l.
    fn shift(&mut self, delta: f64) {
        let mut d = [1.0f64; 11];
        for j in 1..11 {
            d[j] = -delta * d[j - 1];
        }
        shift_sums(&mut self.u, &d);
        shift_sums(&mut self.xu, &d);
    }

    /// The least-squares quintic's value at the origin (None where the fit is singular): the
    /// first unknown of the normal equations H β = Σx·u^j, H the Hankel matrix of Σu^(i+j), by an
    /// LDLᵀ factorisation written out for 6×6 (H is symmetric positive definite wherever the
    /// window holds six distinct times; nalgebra's general LU took half of a jittered run's
    /// smoothing, perf).
    fn centre(&self) -> Option<f64> {
        let h = &self.u;
        let mut l = [[0.0f64; 6]; 6];
        let (mut d, mut inv) = ([0.0f64; 6], [0.0f64; 6]);
        for i in 0..6 {
            for j in 0..i {
                let mut sum = h[i + j];
                for k in 0..j {
                    sum -= l[i][k] * l[j][k] * d[k];
                }
                l[i][j] = sum * inv[j];
            }
            let mut pivot = h[2 * i];
            for k in 0..i {
                pivot -= l[i][k] * l[i][k] * d[k];
            }
            if !(pivot > 0.0) {
                return None;
            }
            (d[i], inv[i]) = (pivot, 1.0 / pivot);
        }
        // L z = b, then Lᵀ β = D⁻¹ z, back to β₀
        let mut z = self.xu;
        for i in 0..6 {
            for k in 0..i {
                z[i] -= l[i][k] * z[k];
            }
        }
        for i in (0..6).rev() {
            z[i] *= inv[i];
            for k in i + 1..6 {
                z[i] -= l[k][i] * z[k];
            }
        }
        Some(z[0]).filter(|v| v.is_finite())
    }
}

/// Power sums Σu^j moved to a new origin in place, `d[k]` = (−δ)^k: each new sum reads only the
/// old sums of lower or equal order, so the orders are taken from the highest down.
fn shift_sums(sums: &mut [f64], d: &[f64; 11]) {
    for j in (0..sums.len()).rev() {
        let mut sum = 0.0;
        for l in 0..=j {
            sum += BINOMIAL[j][l] * d[j - l] * sums[l];
        }
        sums[j] = sum;
    }
}

/// `smooth` with the window's moments carried from one sample to the next (one sample out, one
/// in, the origin moved to the new sample by the binomial theorem) and summed afresh once every
/// window length, so rounding cannot build up along a run. The angles are taken about their mean
/// and the times in units of half a window, which keeps the sums' rounding at the size of a fresh
/// sum's. The ends, where the window shrinks, are fitted one by one. None for a grid with no
/// positive span or angles that are not finite (the fresh sums then say what they can).
fn sliding_quintic(t: &[f64], x: &[f64], half: usize) -> Option<Vec<f64>> {
    let n = x.len();
    let unit = (t[n - 1] - t[0]) / (n - 1) as f64 * half as f64;
    let offset = x.iter().sum::<f64>() / n as f64;
    if !(unit.is_finite() && unit > 0.0 && offset.is_finite()) {
        return None;
    }
    let mut out = Vec::with_capacity(n);
    out.extend((0..half).map(|k| local_quintic(t, x, k, k)));
    let window = 2 * half + 1;
    let mut moments = WindowMoments::default();
    for k in half..n - half {
        if (k - half).is_multiple_of(window) {
            moments = WindowMoments::default();
            for i in k - half..=k + half {
                moments.add((t[i] - t[k]) / unit, x[i] - offset, 1.0);
            }
        } else {
            let origin = t[k - 1];
            moments.add((t[k - 1 - half] - origin) / unit, x[k - 1 - half] - offset, -1.0);
            moments.add((t[k + half] - origin) / unit, x[k + half] - offset, 1.0);
            moments.shift((t[k] - origin) / unit);
        }
        out.push(moments.centre().map_or(x[k], |c| c + offset));
    }
    out.extend((n - half..n).map(|k| local_quintic(t, x, k, n - 1 - k)));
    Some(out)
}

/// In-place radix-2 FFT (Cooley–Tukey, iterative); `buf.len()` a power of two. The inverse is
/// unscaled (divide by the length).
fn fft(buf: &mut [Complex<f64>], inverse: bool) {
    let n = buf.len();
    let mut j = 0;
    for i in 1..n {
        let mut bit = n >> 1;
        while j & bit != 0 {
            j ^= bit;
            bit >>= 1;
        }
        j |= bit;
        if i < j {
            buf.swap(i, j);
        }
    }
    let mut len = 2;
    while len <= n {
        let angle = if inverse { 2.0 } else { -2.0 } * std::f64::consts::PI / len as f64;
        let w_len = Complex::new(angle.cos(), angle.sin());
        for start in (0..n).step_by(len) {
            let mut w = Complex::new(1.0, 0.0);
            for k in 0..len / 2 {
                let (a, b) = (buf[start + k], buf[start + k + len / 2] * w);
                buf[start + k] = a + b;
                buf[start + k + len / 2] = a - b;
                w *= w_len;
            }
        }
        len <<= 1;
    }
}

/// Linear interpolation of (t, x) at `at` (t increasing, `at` too for speed; constant beyond its
/// ends; x's one value, or NaN for none, with fewer than two samples).
pub fn interpolate(t: &[f64], x: &[f64], at: &[f64]) -> Vec<f64> {
    if t.len() < 2 {
        return vec![x.first().copied().unwrap_or(f64::NAN); at.len()];
    }
    let mut i = 0;
    at.iter()
        .map(|&u| {
            while i + 2 < t.len() && t[i + 1] < u {
                i += 1;
            }
            let (t0, t1) = (t[i], t[i + 1]);
            let a = if t1 > t0 { ((u - t0) / (t1 - t0)).clamp(0.0, 1.0) } else { 0.0 };
            x[i] + a * (x[i + 1] - x[i])
        })
        .collect()
}

/// Value and half curvature at t[0] of a least-squares quadratic over the first `n` samples.
fn end_quadratic(t: &[f64], x: &[f64], n: usize) -> Option<(f64, f64)> {
    let (beta, _, _) = leading_quadratic(t, x, n)?;
    (beta[0].is_finite() && beta[2].is_finite()).then_some((beta[0], beta[2]))
}

/// The least-squares quadratic in t − t[0] over the first `n` samples: its coefficients, the
/// inverse of the normal matrix and the residual's variance; None with fewer than 4 samples.
fn leading_quadratic(t: &[f64], x: &[f64], n: usize) -> Option<(DVector<f64>, DMatrix<f64>, f64)> {
    if n < 4 || n > t.len() {
        return None;
    }
    let a = DMatrix::from_fn(n, 3, |i, j| (t[i] - t[0]).powi(j as i32));
    let y = DVector::from_column_slice(&x[..n]);
    let ainv = spd_inverse(&(a.transpose() * &a));
    let beta = &ainv * (a.transpose() * &y);
    let sigma2 = (&y - &a * &beta).norm_squared() / (n - 3).max(1) as f64;
    Some((beta, ainv, sigma2))
}

/// Whether a signal carries no noise: its second-difference noise below 1e-12 of its swing (a
/// simulation's output; a smoothing or band limit has nothing to take out of it).
pub fn noise_free(x: &[f64]) -> bool {
    let swing = x.iter().fold(0.0f64, |a, &b| a.max(b.abs())).max(f64::MIN_POSITIVE);
    second_difference_noise(x) <= 1e-12 * swing
}

/// How far above white noise the motor angle's spectrum must stand, as variance above a frequency,
/// for that band to count as motion (`band_limited`).
pub const BAND_NOISE_FACTOR: f64 = 2.0;

/// Half-width, as a fraction of a bin's frequency, of the neighbourhood whose power sets the bin's
/// Wiener gain above the band's edge (`band_limited`): a periodogram's bin scatters by its own
/// size, and ±20 % averages a few hundred bins at a 10 Hz edge on a 20 s run.
pub const WIENER_SPAN: f64 = 0.2;

/// A measured angle with the noise above its motion's band taken out, and the band's edge (Hz):
/// zero phase, on a uniform grid at the median period (linear interpolation there and back, so
/// jittered stamps keep their times), the line through the ends taken out first. The edge f_c is
/// the lowest frequency above which the signal's variance is at most `BAND_NOISE_FACTOR` times
/// what white noise of the signal's second-difference noise (`second_difference_noise`) puts
/// there; the response is flat to f_c and falls as a cosine to zero at 2 f_c, or, without a cap
/// (steps, multisines) on an encoder its noise dithers, keeps above f_c the Wiener gain of the
/// bins where the motion still stands out of the noise, whichever passes more. (Not the robust
/// noise with its resolution floor q/√12: an encoder that dwells between steps is off by a
/// constant while it dwells, which is no white noise, and that floor put the edge of campaign rig
/// 29's steps at 4.8 Hz, below the motion that rings its 8.9 Hz link; C came out 91 % low.)
/// Why: the model is driven by this angle, and the encoder's steps and noise it carries near the
/// link's resonance are amplified there by the model (by its Q), which the fit then damps: on a
/// 3000-count encoder at 200 Hz, C came out 100–490 % high with a quintic smoothing of
/// 0.1 s over the excitation's top frequency, within 5 % band-limited (campaign rig 5).
/// `most_hz` caps the edge. Within one period of the edge of either end the reflection is a guess
/// (`fade_ends`). None when the run is too short (16 samples) or its times do not increase; a
/// noise-free angle (second-difference noise below 1e-12 of its swing) comes back unchanged, its
/// edge the Nyquist frequency.
pub fn band_limited(t: &[f64], x: &[f64], most_hz: Option<f64>) -> Option<(Vec<f64>, f64)> {
    band_limited_over(t, x, most_hz, false)
}

/// [`band_limited`] with the white level taken as at least the count's whole error, q²/12 of the
/// signal's quantum (`quantisation_floor`), and no Wiener gain above the edge: the band where the
/// motion stands out of everything a count the noise does not dither can hold, the rule
/// `band_limited` does not use alone (campaign rig 29's steps lost the motion that rang their link
/// under it). `calibrate` fits the baseline with both and keeps the lower BIC.
pub fn band_limited_to_count(t: &[f64], x: &[f64]) -> Option<(Vec<f64>, f64)> {
    band_limited_over(t, x, None, true)
}

fn band_limited_over(t: &[f64], x: &[f64], most_hz: Option<f64>, count: bool) -> Option<(Vec<f64>, f64)> {
    let n = x.len();
    if n < 16 || t.windows(2).any(|w| !(w[1] > w[0])) {
        return None;
    }
    let dt = super::quality::median_period(t);
    let n_u = (((t[n - 1] - t[0]) / dt).round() as usize + 1).max(2);
    let grid: Vec<f64> = (0..n_u).map(|k| t[0] + k as f64 * dt).collect();
    let xu = interpolate(t, x, &grid);
    let line = |k: usize| xu[0] + (xu[n_u - 1] - xu[0]) * k as f64 / (n_u - 1) as f64;
    let size = n_u.next_power_of_two();
    let mut buf: Vec<Complex<f64>> =
        (0..size).map(|k| Complex::new(if k < n_u { xu[k] - line(k) } else { 0.0 }, 0.0)).collect();
    fft(&mut buf, false);
    let bins = size / 2 + 1;
    let freq = |k: usize| k as f64 / (size as f64 * dt);
    let nyquist = freq(bins - 1);
    // each one-sided bin's share of the variance (Parseval over the padded length)
    let share = |k: usize| if k == 0 || k == bins - 1 { 1.0 } else { 2.0 } * buf[k].norm_sqr() / (n_u * size) as f64;
    if noise_free(x) {
        return Some((x.to_vec(), nyquist));
    }
    let white2 = second_difference_noise(x).powi(2);
    let count2 = quantisation_floor(x).powi(2);
    let sigma2 = if count { white2.max(count2) } else { white2 };
    // the variance above each bin, and the lowest bin above which it is noise's
    let mut above = vec![0.0; bins + 1];
    for k in (0..bins).rev() {
        above[k] = above[k + 1] + share(k);
    }
    let edge = (1..bins)
        .find(|&k| above[k] <= BAND_NOISE_FACTOR * sigma2 * (nyquist - freq(k)) / nyquist)
        .map_or(nyquist, freq);
    let edge = most_hz.map_or(edge, |most| edge.min(most)).max(freq(1));
    // Above a noise-set edge the motion can still stand out of the noise (a step's harmonics near
    // the link's resonance): each bin keeps the Wiener gain 1 − N/P of its neighbourhood's power P
    // (bins within ±WIENER_SPAN of its frequency) over white noise's N, the estimate of the motion
    // that leaves the least error, where P is at least BAND_NOISE_FACTOR N (as the motion must
    // stand out below the edge); the cosine taper where that passes more. The taper alone cut it
    // all, and a 14 Hz link driven by steps whose edge read 9.2 Hz was damped 25 % too little
    // (campaign rig 271; the raw samples' noise damped it 19 % too much). P is read through a
    // Hann window: without one, a multisine's lines leaked into the bins around its link's 11 Hz
    // resonance at 3.5 N (rig 5, 1.2 N windowed), and C came out 58 % high. Not for a sinusoid
    // (a cap): all it has above its frequency is its encoder's dwell error.
    // Nor for an encoder its noise does not dither (second-difference noise under its quantum's
    // q/√12): it dwells on a count, an error that stands above the white level at every frequency
    // (rig 299: 14 900 counts, noise 1.4e-5 rad; 2–10 N from 25 Hz to 200 Hz, and C 536 % high at
    // its 32 Hz link).
    let dithered = sigma2 >= count2;
    let gains: Option<Vec<f64>> = (most_hz.is_none() && dithered && !count).then(|| {
        let hann = |k: usize| 0.5 - 0.5 * (2.0 * std::f64::consts::PI * k as f64 / (n_u - 1) as f64).cos();
        let weight: f64 = (0..n_u).map(|k| hann(k).powi(2)).sum();
        let mut windowed: Vec<Complex<f64>> =
            (0..size).map(|k| Complex::new(if k < n_u { (xu[k] - line(k)) * hann(k) } else { 0.0 }, 0.0)).collect();
        fft(&mut windowed, false);
        let noise_bin = 2.0 * sigma2 / size as f64;
        let mut prefix = vec![0.0; bins + 1];
        for k in 0..bins {
            prefix[k + 1] = prefix[k] + 2.0 * windowed[k].norm_sqr() / (size as f64 * weight);
        }
        (0..bins)
            .map(|k| {
                let lo = ((k as f64 * (1.0 - WIENER_SPAN)).floor() as usize).min(k.saturating_sub(2));
                let hi = ((k as f64 * (1.0 + WIENER_SPAN)).ceil() as usize).max(k + 2).min(bins - 1);
                let power = (prefix[hi + 1] - prefix[lo]) / (hi + 1 - lo) as f64;
                if power >= BAND_NOISE_FACTOR * noise_bin {
                    1.0 - noise_bin / power
                } else {
                    0.0
                }
            })
            .collect()
    });
    // filtered with each end reflected oddly about the end's value a as a quadratic over a
    // quarter period of the band's edge reads it (x(−τ) = 2a − x(τ)), its curvature c put back
    // near the end (+2cτ², faded out over one period of the edge): value, slope and curvature run
    // on through the ends, so the filter sees no kink there. Zero padding's kink read as 6 mrad
    // at a run's first sample; reflected about the first sample, its noise was pinned there; and
    // without the curvature, a run starting in a fast turn was off by 8 mrad (campaign rig 5)
    let quarter = ((0.25 / (edge * dt)).round() as usize).clamp(4, n_u);
    let period = 1.0 / edge;
    let from_end: Vec<f64> = (0..n_u).map(|k| k as f64 * dt).collect();
    let rev: Vec<f64> = xu.iter().rev().copied().collect();
    let (a_start, c_start) = end_quadratic(&from_end, &xu, quarter).unwrap_or((xu[0], 0.0));
    let (a_end, c_end) = end_quadratic(&from_end, &rev, quarter).unwrap_or((xu[n_u - 1], 0.0));
    let curvature = |c: f64, k: usize| {
        let tau = k as f64 * dt;
        let fade = if tau < period { 0.5 * (1.0 + (std::f64::consts::PI * tau / period).cos()) } else { 0.0 };
        2.0 * c * tau * tau * fade
    };
    let reflect = n_u - 1;
    let extended: Vec<f64> = (0..n_u + 2 * reflect)
        .map(|i| match i {
            i if i < reflect => 2.0 * a_start - xu[reflect - i] + curvature(c_start, reflect - i),
            i if i < reflect + n_u => xu[i - reflect],
            i => {
                let k = i - reflect - n_u + 1;
                2.0 * a_end - xu[n_u - 1 - k] + curvature(c_end, k)
            }
        })
        .collect();
    let m = extended.len();
    let trend = |k: usize| extended[0] + (extended[m - 1] - extended[0]) * k as f64 / (m - 1) as f64;
    let size = m.next_power_of_two();
    let mut buf: Vec<Complex<f64>> =
        (0..size).map(|k| Complex::new(if k < m { extended[k] - trend(k) } else { 0.0 }, 0.0)).collect();
    fft(&mut buf, false);
    let freqs: Vec<f64> = (0..=size / 2).map(|k| k as f64 / (size as f64 * dt)).collect();
    // the gains, read on this transform's bins
    let wiener = gains.map(|g| interpolate(&(0..bins).map(freq).collect::<Vec<_>>(), &g, &freqs));
    for (k, &f) in freqs.iter().enumerate() {
        let w = if f <= edge {
            1.0
        } else {
            let taper = 0.5 * (1.0 + (std::f64::consts::PI * ((f - edge) / edge).min(1.0)).cos());
            wiener.as_ref().map_or(taper, |g| g[k].max(taper))
        };
        buf[k] *= w;
        if k > 0 && k < size - k {
            buf[size - k] *= w;
        }
    }
    fft(&mut buf, true);
    let yu: Vec<f64> = (0..n_u).map(|k| buf[k + reflect].re / size as f64 + trend(k + reflect)).collect();
    Some((interpolate(&grid, &yu, t), edge))
}

/// `band` faded into `ends` within one period of `edge_hz` of either end of `t` (a raised cosine):
/// there the band limit's reflection is a guess.
pub fn fade_ends(t: &[f64], band: &[f64], ends: &[f64], edge_hz: f64) -> Vec<f64> {
    let n = t.len();
    let period = 1.0 / edge_hz;
    (0..n)
        .map(|k| {
            let from_end = (t[k] - t[0]).min(t[n - 1] - t[k]);
            let weight = 0.5 * (1.0 - (std::f64::consts::PI * (from_end / period).min(1.0)).cos());
            ends[k] + weight * (band[k] - ends[k])
        })
        .collect()
}

/// The widest quintic smoothing, up to `cap` samples each side, that takes out no more than the
/// signal's noise (the discrepancy principle): half windows from 5 up by factors of 2 while the rms
/// of x − smooth(x) stays within 1.25× its noise; a window that takes more has started to flatten
/// the signal (a link ringing at its natural frequency, a step's edge). The noise is the larger of
/// the white noise (`cubic_noise`) and the reading's quantisation (`quantisation_floor`), as the
/// noise floor is: the cubic counts a count held still as nothing, and a coarse encoder's staircase
/// smoothed only to the white noise under it keeps its steps, which the equation error's
/// derivatives read as accelerations (fresh rig 1032: 5 mrad counts under 85 µrad of noise, an
/// inertial torque read 1 200× the swing's, and a combination started from those levels ended with
/// every torque 300× the truth's).
/// Returns (half window, smoothed signal, the noise measured).
pub fn smooth_to_noise(t: &[f64], x: &[f64], cap: usize) -> (usize, Vec<f64>, f64) {
    let noise = cubic_noise(t, x).max(quantisation_floor(x));
    let mut half = 5.min(cap);
    let mut best = smooth(t, x, half);
    while half < cap {
        let next = (2 * half).min(cap);
        let s = smooth(t, x, next);
        let rms = (x.iter().zip(&s).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / x.len().max(1) as f64).sqrt();
        if rms > 1.25 * noise {
            break;
        }
        (half, best) = (next, s);
    }
    (half, best, noise)
}

/// The second divided difference of `x` sampled at `t` at sample k (0 < k < len − 1): x'' on an
/// uneven grid, from the slopes either side over the mean of their intervals. None where an
/// interval either side is not positive.
pub fn second_divided_difference(t: &[f64], x: &[f64], k: usize) -> Option<f64> {
    let (h0, h1) = (t[k] - t[k - 1], t[k + 1] - t[k]);
    (h0 > 0.0 && h1 > 0.0).then(|| ((x[k + 1] - x[k]) / h1 - (x[k] - x[k - 1]) / h0) / (0.5 * (h0 + h1)))
}

/// Noise of a sampled signal from its second differences: √(var(Δ²x)/6) (white noise of σ gives
/// var(Δ²x) = 6σ²; a smooth signal sampled fast contributes almost nothing).
pub fn second_difference_noise(x: &[f64]) -> f64 {
    if x.len() < 3 {
        return 0.0;
    }
    let s: f64 = x.windows(3).map(|w| (w[2] - 2.0 * w[1] + w[0]).powi(2)).sum();
    (s / (6.0 * (x.len() - 2) as f64)).sqrt()
}

/// rms(x')/(2π rms(x − mean)), x' by differences over ±10 ms (the power-weighted frequency).
pub fn rms_frequency(t: &[f64], x: &[f64]) -> f64 {
    let n = x.len();
    let Some(v2) = mean_square_speed(t, x) else { return 0.0 };
    let mean = x.iter().sum::<f64>() / n as f64;
    let x2: f64 = x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n as f64;
    if x2 <= 0.0 {
        0.0
    } else {
        v2.sqrt() / (2.0 * std::f64::consts::PI * x2.sqrt())
    }
}

/// The mean of x'² by differences over ±10 ms (a quantised angle's slope from one sample to the
/// next is mostly its counts); None for a record shorter than that window.
pub fn mean_square_speed(t: &[f64], x: &[f64]) -> Option<f64> {
    let n = x.len().min(t.len());
    if n < 3 {
        return None;
    }
    let dt = (t[n - 1] - t[0]) / (n - 1) as f64;
    let lag = ((0.01 / dt).round() as usize).max(1);
    if n <= 2 * lag || !dt.is_finite() || dt <= 0.0 {
        return None;
    }
    let v2 = (lag..n - lag).map(|k| ((x[k + lag] - x[k - lag]) / (t[k + lag] - t[k - lag])).powi(2)).sum::<f64>();
    Some(v2 / (n - 2 * lag) as f64)
}

/// Least-squares harmonics of `e` on [t0, t1) at multiples of `w`: returns (DC, [(cos, sin) per harmonic]).
pub fn harmonics(t: &[f64], e: &[f64], w: f64, orders: &[usize], t0: f64, t1: f64) -> (f64, Vec<(f64, f64)>) {
    let idx: Vec<usize> = (0..t.len()).filter(|&k| t[k] >= t0 && t[k] < t1).collect();
    let m = 1 + 2 * orders.len();
    if idx.len() <= m {
        return (0.0, vec![(0.0, 0.0); orders.len()]);
    }
    let x = DMatrix::from_fn(idx.len(), m, |i, j| {
        let tt = t[idx[i]];
        if j == 0 {
            1.0
        } else {
            let k = orders[(j - 1) / 2] as f64;
            if (j - 1) % 2 == 0 {
                (k * w * tt).cos()
            } else {
                (k * w * tt).sin()
            }
        }
    });
    let y = DVector::from_iterator(idx.len(), idx.iter().map(|&k| e[k]));
    let a = x.transpose() * &x;
    let beta = spd_inverse(&a) * (x.transpose() * y);
    (beta[0], orders.iter().enumerate().map(|(i, _)| (beta[1 + 2 * i], beta[2 + 2 * i])).collect())
}

/// Amplitude spectrum of `e` sampled at `t` (one-sided, rad), on `freqs`.
pub fn amplitude_spectrum(t: &[f64], e: &[f64], freqs: &[f64]) -> Vec<f64> {
    let step = (t.len() / 4000).max(1);
    let idx: Vec<usize> = (0..t.len()).step_by(step).collect();
    let n = idx.len() as f64;
    freqs
        .iter()
        .map(|&f| {
            let w = 2.0 * std::f64::consts::PI * f;
            let (mut c, mut s) = (0.0, 0.0);
            for &k in &idx {
                let (sn, cs) = (w * t[k]).sin_cos();
                c += e[k] * cs;
                s += e[k] * sn;
            }
            2.0 * (c * c + s * s).sqrt() / n
        })
        .collect()
}

/// Samples each side the derivatives' quintic smoothing spans.
pub const DERIVATIVE_HALF: usize = 10;

/// Central differences of a smoothed position (quintic over ±`DERIVATIVE_HALF` samples, on any
/// grid): (speed, acceleration).
pub fn derivatives(t: &[f64], x: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let s = smooth(t, x, DERIVATIVE_HALF);
    let n = s.len();
    let mut v = vec![0.0; n];
    let mut a = vec![0.0; n];
    for k in 1..n - 1 {
        let (h1, h2) = (t[k] - t[k - 1], t[k + 1] - t[k]);
        v[k] = (s[k + 1] - s[k - 1]) / (h1 + h2);
        a[k] = 2.0 * ((s[k + 1] - s[k]) / h2 - (s[k] - s[k - 1]) / h1) / (h1 + h2);
    }
    (v, a)
}

/// The speed `v` (from `derivatives`) near each clean reversal, taken from the positions
/// themselves: friction flips at a reversal, so the acceleration jumps there (by 2 Fc/M) and the
/// quintic's smoothing spans the kink; it moves the speed's zero by up to a sample and bends the
/// speeds around it (the friction's sign and every low-speed column then err where friction acts
/// most). Around each sign change of `v`, the positions are fitted by two parabolas meeting at
/// rest, x = x₀ + a±(t − t₀)²/2, over ±`DERIVATIVE_HALF` samples or, where the parabolas rise less
/// than `REVERSAL_RISE` noise levels over that (a coarse encoder, a slow reversal), over the
/// samples they need to (up to `REVERSAL_MOST`). Where the fit holds (within twice the noise
/// `noise`; or, at one clean sign change before any widening, closer than one quintic through the
/// same samples: a log finer than its own motion's curvature, where no fit holds to the noise),
/// with one sense of acceleration on both sides (a reversal, not a stop), the speeds there become
/// a±(t − t₀). A change with another within its samples (a drive at rest in its noise) is
/// left as it was. Returns how many reversals were refined.
pub fn refine_reversals(t: &[f64], x: &[f64], v: &mut [f64], noise: f64) -> usize {
    let n = x.len().min(t.len()).min(v.len());
    // sign changes between nonzero speeds (a coarse encoder's flat counts read exactly 0), at the
    // middle of the zeros between them, with the sense of the acceleration that makes them: + to −
    // decelerates on both sides (a < 0), − to + the other way
    let mut changes: Vec<(usize, f64)> = Vec::new();
    let mut last: Option<usize> = None;
    for k in 0..n {
        if v[k] == 0.0 {
            continue;
        }
        if let Some(p) = last.filter(|&p| v[p] * v[k] < 0.0) {
            changes.push(((p + k - 1) / 2, -v[p].signum()));
        }
        last = Some(k);
    }
    // a coarse encoder or the noise flickers the sign near a reversal: changes closer than the
    // smoothing's reach are one event, a reversal when its count is odd (a dwell when even)
    let mut events: Vec<(usize, usize, f64)> = Vec::new(); // (first, last, sense)
    let mut count = 0;
    for &(c, sense) in &changes {
        match events.last_mut() {
            Some(e) if c <= e.1 + 2 * DERIVATIVE_HALF => {
                e.1 = c;
                count += 1;
            }
            _ => {
                if let Some(e) = events.last_mut().filter(|_| count % 2 == 0) {
                    e.2 = 0.0;
                }
                events.push((c, c, sense));
                count = 1;
            }
        }
    }
    if let Some(e) = events.last_mut().filter(|_| count % 2 == 0) {
        e.2 = 0.0;
    }
    let mut refined = 0;
    for (i, &(first, last, sense)) in events.iter().enumerate() {
        if sense == 0.0 {
            continue;
        }
        let c = (first + last) / 2;
        let spread = (last - first) / 2 + 1;
        let mut half = DERIVATIVE_HALF + spread;
        let mut fitted = None;
        for _ in 0..3 {
            if c + 1 < half || c + half >= n {
                break;
            }
            let alone = i.checked_sub(1).is_none_or(|j| events[j].1 + 2 * half < c)
                && events.get(i + 1).is_none_or(|e| e.0 > c + 2 * half);
            if !alone {
                break;
            }
            let Some((rms, t0, before, after)) = fit_reversal(t, x, c, half, spread) else { break };
            // within the noise; or, at one clean sign change not yet widened, closer than one
            // quintic through the same samples: a log finer than its own motion's curvature, where
            // no fit holds to a noise that small (a flicker or a widening is the noise's case, and
            // a drive that sticks between its turns fits neither)
            let holds = rms <= 2.0 * noise
                || (spread == 1
                    && half == DERIVATIVE_HALF + 1
                    && quintic_rms(t, x, c + 1 - half, c + half).is_some_and(|q| rms < q));
            if !(holds && before * sense > 0.0 && after * sense > 0.0) {
                break;
            }
            fitted = Some((t0, before, after, half));
            // the samples the slower side needs to rise REVERSAL_RISE noise levels
            let slow = before.abs().min(after.abs());
            let period = (t[c + half] - t[c + 1 - half]) / (2 * half - 1) as f64;
            let needed = ((2.0 * REVERSAL_RISE * noise / slow).sqrt() / period).ceil();
            if !(needed > half as f64) || half >= REVERSAL_MOST {
                break;
            }
            half = (needed as usize).min(REVERSAL_MOST);
            fitted = None;
        }
        let Some((t0, before, after, half)) = fitted else { continue };
        for k in c + 1 - half..=c + half {
            v[k] = (t[k] - t0) * if t[k] < t0 { before } else { after };
        }
        refined += 1;
    }
    refined
}

/// Noise levels the parabolas of a reversal must rise over their samples for its time to be read.
const REVERSAL_RISE: f64 = 20.0;
/// The most samples each side a reversal's fit takes.
const REVERSAL_MOST: usize = 400;

/// Two parabolas meeting at rest at t₀ through the samples c + 1 − half ..= c + half:
/// (rms residual, t₀, acceleration before, after). t₀ is searched within half a window, or a
/// flicker's spread and one sample, of the change (the wider), by a grid of 120, then refined once
/// on a grid of 20 around the best.
fn fit_reversal(t: &[f64], x: &[f64], c: usize, half: usize, spread: usize) -> Option<(f64, f64, f64, f64)> {
    let (lo, hi) = (c + 1 - half, c + half);
    let origin = x[c];
    // (1, (t − t₀)²/2 before, (t − t₀)²/2 after): the columns of x₀, a− and a+
    let row = |k: usize, t0: f64| {
        let u = 0.5 * (t[k] - t0).powi(2);
        if t[k] < t0 {
            nalgebra::Vector3::new(1.0, u, 0.0)
        } else {
            nalgebra::Vector3::new(1.0, 0.0, u)
        }
    };
    let fit_at = |t0: f64| -> Option<(f64, f64, f64)> {
        let mut a = nalgebra::Matrix3::<f64>::zeros();
        let mut b = nalgebra::Vector3::<f64>::zeros();
        for (k, xk) in (lo..=hi).zip(&x[lo..=hi]) {
            let r = row(k, t0);
            a += r * r.transpose();
            b += r * (xk - origin);
        }
        let beta = a.lu().solve(&b)?;
        let sse: f64 = (lo..=hi).map(|k| (x[k] - origin - row(k, t0).dot(&beta)).powi(2)).sum();
        Some((sse, beta[1], beta[2]))
    };
    let reach = (half / 2).max(spread + 1);
    let (from, to) = (t[c.saturating_sub(reach).max(lo)], t[(c + 1 + reach).min(hi)]);
    let best_on = |from: f64, to: f64, steps: usize| {
        (0..=steps)
            .filter_map(|j| {
                let t0 = from + (to - from) * j as f64 / steps as f64;
                fit_at(t0).map(|(sse, before, after)| (sse, t0, before, after))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
    };
    let coarse = best_on(from, to, 120)?;
    let step = (to - from) / 120.0;
    let (sse, t0, before, after) = best_on(coarse.1 - step, coarse.1 + step, 20)?;
    Some(((sse / (hi - lo + 1) as f64).sqrt(), t0, before, after))
}

/// The rms residual of one least-squares quintic through the samples lo..=hi (None when singular).
fn quintic_rms(t: &[f64], x: &[f64], lo: usize, hi: usize) -> Option<f64> {
    let (mid, span) = (0.5 * (t[lo] + t[hi]), 0.5 * (t[hi] - t[lo]));
    if span <= 0.0 {
        return None;
    }
    let m = hi - lo + 1;
    let a = nalgebra::DMatrix::from_fn(m, 6, |i, j| ((t[lo + i] - mid) / span).powi(j as i32));
    let b = nalgebra::DVector::from_iterator(m, (lo..=hi).map(|k| x[k] - x[lo]));
    let beta = (a.transpose() * &a).lu().solve(&(a.transpose() * &b))?;
    Some(((&b - &a * beta).norm_squared() / m as f64).sqrt())
}

/// Slope at t[0] of a least-squares quadratic over the first `n` samples, with its standard error
/// and the fit's residual rms; None with fewer than 4 samples.
fn start_quadratic(t: &[f64], x: &[f64], n: usize) -> Option<(f64, f64, f64)> {
    let (beta, ainv, sigma2) = leading_quadratic(t, x, n)?;
    Some((beta[1], (sigma2 * ainv[(1, 1)]).max(0.0).sqrt(), sigma2.sqrt()))
}

/// Speed at t[0], with its standard error: the slope of a least-squares quadratic over the longest
/// start, from `most` samples down to 4, that the quadratic follows to within twice the signal's
/// noise. A fixed window fails where the motion is not quadratic over it: a servo that starts
/// saturated reverses its acceleration within a few samples, and 11 samples read that as speed
/// (3.5 rad/s on a drive starting at rest, measured). None with fewer than 4 samples.
pub fn start_speed(t: &[f64], x: &[f64], most: usize) -> Option<(f64, f64)> {
    start_speed_over(t, x, most).map(|(v, se, _, _)| (v, se))
}

/// [`start_speed`] with its quadratic's residual rms and the number of samples it took.
fn start_speed_over(t: &[f64], x: &[f64], most: usize) -> Option<(f64, f64, f64, usize)> {
    let noise = robust_noise(t, x);
    let mut n = x.len().min(most);
    while n > 4 {
        match start_quadratic(t, x, n) {
            Some((v, se, rms)) if rms <= 2.0 * noise => return Some((v, se, rms, n)),
            _ => n -= 1,
        }
    }
    start_quadratic(t, x, 4).map(|(v, se, rms)| (v, se, rms, 4))
}

/// [`start_speed`] where the start reads as motion rather than as rest: its quadratic
/// (x₀ + v t + c t²) follows the samples more closely than a start from rest with the same number
/// of parameters (x₀ + c t² + d t³, the acceleration free to grow). A link at rest that the motor
/// sets off builds its acceleration through the transmission, and a quadratic reads that t³ as a
/// speed of the wrong sign that turns within the window (fresh rig 1314: −0.06 to −0.19 rad/s on
/// links at rest, each turning within 1.5 ms of a 20 ms window; moving, the start held a Stribeck
/// excess out of the model, 1.38× its floor).
pub fn moving_start_speed(t: &[f64], x: &[f64], most: usize) -> Option<(f64, f64)> {
    let (v, se, rms, n) = start_speed_over(t, x, most)?;
    // the quadratic's sum of squares, from its residual variance over n − 3 degrees of freedom
    let moving = rms * rms * (n - 3) as f64;
    let a = DMatrix::from_fn(n, 3, |i, j| (t[i] - t[0]).powi([0, 2, 3][j]));
    let y = DVector::from_column_slice(&x[..n]);
    let rest = (a.transpose() * &a).lu().solve(&(a.transpose() * &y)).map(|beta| (&y - &a * beta).norm_squared());
    match rest {
        Some(rest) if rest <= moving => Some((0.0, se)),
        _ => Some((v, se)),
    }
}

/// Noise of a sampled signal robust to its fast moves, and at least what its quantum (`quantum`:
/// an encoder's count) leaves, q/√12. Each sample's residual against the cubic through its two
/// neighbours on either side, in the samples' own times: white noise of σ gives it variance
/// σ²(1 + Σw²) (w the cubic's weights; 1 + 17/18 on an even grid), so σ is 1.4826 × the median of
/// |residual|/√(1 + Σw²). The cubic passes the motion's curvature, which a second difference counts as
/// noise: on drive rig 31 (a 117 rad/s multisine at 500 Hz) median|Δ²x|/√6 read 1.6e-3 rad for
/// 9.5e-5 rad of noise. Fewer than 5 samples: the second difference's.
///
/// The median's 1.4826 holds for Gaussian residuals only. A moving encoder whose counts dwarf its
/// noise leaves residuals of a few discrete sizes, and the median then lands on one of them: drive
/// rig 88 (3e-3 rad counts, 5e-5 rad of noise) read 1.15–1.38e-3 rad for the 0.87e-3 its counts
/// leave (q/√12, which the residuals' mean square gave). Each estimate errs only upward (the mean
/// square counts fast moves, the median a quantum's discrete residuals), so the smaller is taken.
pub fn robust_noise(t: &[f64], x: &[f64]) -> f64 {
    if x.len() < 3 {
        return 0.0;
    }
    let floor = quantisation_floor(x);
    let residuals: Vec<f64> = cubic_residuals(t, x).collect();
    if residuals.is_empty() {
        return median_second_difference_noise(x).max(floor);
    }
    let mean_square = (residuals.iter().map(|r| r * r).sum::<f64>() / residuals.len() as f64).sqrt();
    let median = 1.4826 * super::quality::median(residuals.into_iter().map(f64::abs).collect());
    median.min(mean_square).max(floor)
}

/// White noise's σ from each sample's residual against the cubic through its four neighbours
/// (`cubic_residuals`), as a mean square: quantisation held still counts as nothing, as in a second
/// difference, but a fast motion's curvature does not count either (a 5 Hz sine at 200 Hz: its
/// second difference read twice the noise of campaign rig 48, the cubic's 0.98×). Fewer than 5
/// samples: `second_difference_noise`.
pub fn cubic_noise(t: &[f64], x: &[f64]) -> f64 {
    let (sum, count) = cubic_residuals(t, x).fold((0.0, 0usize), |(s, c), r| (s + r * r, c + 1));
    if count == 0 {
        return second_difference_noise(x);
    }
    (sum / count as f64).sqrt()
}

/// Each interior sample's residual against the cubic through its two neighbours on either side, in
/// the samples' own times, over its white-noise spread √(1 + Σw²) (w the cubic's weights; on an even
/// grid Σw² = 17/18): white noise of σ gives residuals of σ. Nothing with fewer than 5 samples, or
/// times that do not match the samples.
pub fn cubic_residuals<'a>(t: &'a [f64], x: &'a [f64]) -> impl Iterator<Item = f64> + 'a {
    let n = if t.len() == x.len() && x.len() >= 5 { x.len() } else { 4 };
    (2..n - 2).filter_map(move |k| {
        let nodes = [k - 2, k - 1, k + 1, k + 2];
        let w =
            nodes.map(|i| nodes.iter().filter(|&&j| j != i).map(|&j| (t[k] - t[j]) / (t[i] - t[j])).product::<f64>());
        let residual = x[k] - w.iter().zip(nodes).map(|(w, i)| w * x[i]).sum::<f64>();
        let r = residual / (1.0 + w.iter().map(|w| w * w).sum::<f64>()).sqrt();
        r.is_finite().then_some(r)
    })
}

/// The quantum of a quantised signal: its resolution where at least nine steps in ten are whole
/// multiples of it (an encoder's counts, a logger's last digit), else 0. A continuous signal's
/// smallest step is chance: a 117 rad/s multisine at 500 Hz steps by no less than 5e-4 rad near its
/// reversals, which taken for a quantum read 1.6e-4 rad of noise for 1e-4.
pub fn quantum(x: &[f64]) -> f64 {
    let q = resolution(x);
    if q == 0.0 {
        return 0.0;
    }
    let steps: Vec<f64> = x.windows(2).map(|w| (w[1] - w[0]).abs() / q).filter(|r| *r > 0.0).collect();
    let whole = steps.iter().filter(|r| (*r - r.round()).abs() <= 1e-3).count();
    if 10 * whole >= 9 * steps.len() {
        q
    } else {
        0.0
    }
}

/// What a quantised reading adds to a perfect model's error: q/√12 with q the signal's `quantum`,
/// 0 for a signal that is not quantised (its smallest step is chance, not a resolution).
pub fn quantisation_floor(x: &[f64]) -> f64 {
    quantum(x) / 12f64.sqrt()
}

/// [`quantisation_floor`] over several signals, each run's q²/12 weighted by its samples.
pub fn pooled_quantisation_floor<'a>(signals: impl IntoIterator<Item = &'a [f64]>) -> f64 {
    let (sum, n) = signals
        .into_iter()
        .fold((0.0, 0usize), |(sum, n), x| (sum + x.len() as f64 * quantisation_floor(x).powi(2), n + x.len()));
    (sum / n.max(1) as f64).sqrt()
}

/// The resolution of a sampled signal: the smallest step it takes between neighbours (an encoder's
/// count, a logger's last digit; 0 for a constant signal).
pub fn resolution(x: &[f64]) -> f64 {
    let step = x.windows(2).map(|w| (w[1] - w[0]).abs()).filter(|d| *d > 0.0).fold(f64::INFINITY, f64::min);
    if step.is_finite() {
        step
    } else {
        0.0
    }
}

/// 1.4826 × median|Δ²x| / √6: white noise's σ from its second differences, robust to the steps
/// and fast moves a mean square would count as noise (0 with fewer than 3 samples).
pub fn median_second_difference_noise(x: &[f64]) -> f64 {
    let d2: Vec<f64> = x.windows(3).map(|w| (w[2] - 2.0 * w[1] + w[0]).abs()).collect();
    1.4826 * super::quality::median(d2) / 6f64.sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sine's speed scale √(2·mean x'²) is its amplitude × ω at any rate and through a coarse
    /// encoder's counts (differences over ±10 ms, not from one sample to the next).
    #[test]
    fn a_sines_mean_square_speed_gives_amplitude_times_omega_through_its_counts() {
        let q = 2.0 * std::f64::consts::PI / 2000.0;
        for (rate, f, a) in [(200.0, 0.3, 0.4), (1000.0, 1.0, 0.2), (5000.0, 4.0, 0.05)] {
            let t: Vec<f64> = (0..(10.0 * rate) as usize).map(|k| k as f64 / rate).collect();
            let w = 2.0 * std::f64::consts::PI * f;
            let x: Vec<f64> = t.iter().map(|&t| (a * (w * t).sin() / q).round() * q).collect();
            let scale = (2.0 * mean_square_speed(&t, &x).expect("10 s of samples")).sqrt();
            assert!((scale / (a * w) - 1.0).abs() < 0.03, "{rate} Hz, {f} Hz: {scale} against {}", a * w);
        }
        assert_eq!(mean_square_speed(&[0.0, 1e-3], &[0.0, 1.0]), None);
    }

    /// The speed noise the equation error's rest test assumes is what smoothing and a central
    /// difference leave of white noise, measured, at a narrow and a wide window.
    #[test]
    fn the_smoothed_speed_gain_is_what_white_noise_leaves() {
        let mut rng = crate::calibrate::synthetic::SplitMix::new(3);
        let noise: Vec<f64> = (0..200_000).map(|_| rng.normal()).collect();
        for half in [5, 40] {
            let s = savitzky_golay(&noise, half);
            let d: Vec<f64> = s[half..s.len() - half].windows(3).map(|w| 0.5 * (w[2] - w[0])).collect();
            let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
            let gain = smoothed_speed_gain(half);
            assert!((rms / gain - 1.0).abs() < 0.02, "half {half}: measured {rms:.4e}, gain {gain:.4e}");
            // smoothing takes noise out: a raw central difference leaves 1/√2
            assert!(gain < 0.5f64.sqrt(), "half {half}: {gain}");
        }
        assert!(smoothed_speed_gain(40) < smoothed_speed_gain(5), "a wider window leaves less");
    }

    #[test]
    fn the_pooled_floor_is_each_count_weighted_by_samples() {
        let q = 2.0 * std::f64::consts::PI / 4096.0;
        let sine = |n: usize| (0..n).map(|k| 0.3 * (k as f64 * 0.01).sin()).collect::<Vec<f64>>();
        let quantised: Vec<f64> = sine(3000).iter().map(|x| (x / q).round() * q).collect();
        let smooth = sine(1000);
        let floor = pooled_quantisation_floor([&quantised[..], &smooth[..]]);
        // three quarters of the samples carry q²/12, the smooth run none
        let expected = (0.75 * q * q / 12.0).sqrt();
        assert!((floor - expected).abs() < 1e-3 * expected, "{floor} against {expected}");
        assert_eq!(pooled_quantisation_floor([&smooth[..]]), 0.0);
    }

    /// A servo's move: from rest, accelerates at `a` for `k_turn` samples, brakes at −a as long,
    /// then holds (most of the record, as a positioning servo's is).
    fn bang_bang(a: f64, dt: f64, k_turn: usize, n: usize) -> (Vec<f64>, Vec<f64>) {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let t1 = k_turn as f64 * dt;
        let x = t
            .iter()
            .map(|&t| {
                let s = t.min(2.0 * t1);
                if s <= t1 {
                    0.5 * a * s * s
                } else {
                    0.5 * a * t1 * t1 + a * t1 * (s - t1) - 0.5 * a * (s - t1).powi(2)
                }
            })
            .collect();
        (t, x)
    }

    /// A rotor driven by torque steps that reverse it, with Coulomb friction: the acceleration
    /// jumps by 2 Fc/M at each reversal. (times, true positions, true speeds) at `rate` Hz with
    /// jitter of ±`jitter` periods, integrated at 1 µs.
    fn reversing_rotor(rate: f64, jitter: f64, seconds: f64) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
        let (inertia, coulomb, torque) = (1e-3, 0.05, 0.08);
        let offsets = normals(7, (seconds * rate) as usize + 1);
        let times: Vec<f64> = (0..offsets.len())
            .map(|k| (k as f64 + jitter * (2.0 * (0.5 + 0.5 * offsets[k].tanh()) - 1.0)) / rate)
            .collect();
        let (mut q, mut v, mut now) = (0.0f64, 0.0f64, 0.0f64);
        let h = 1e-6;
        let (mut x, mut speed) = (Vec::new(), Vec::new());
        for &tk in &times {
            while now < tk {
                let u = if (now / 0.4) as i64 % 2 == 0 { torque } else { -torque };
                let a = (u - coulomb * v.signum()) / inertia;
                q += v * h + 0.5 * a * h * h;
                v += a * h;
                now += h;
            }
            x.push(q);
            speed.push(v);
        }
        (times, x, speed)
    }

    /// Near a reversal the refined speeds hold the friction's sign and the speed's size where the
    /// smoothed derivative's do not: on an even grid, a jittered one, through a coarse encoder
    /// (whose flat counts read exactly 0 and flicker the sign) and without noise (where no fit holds
    /// to a noise that small, but two parabolas follow the kink closer than one quintic).
    #[test]
    fn reversals_take_their_speed_from_the_positions_kink() {
        for (jitter, quantum, sigma) in [(0.0, 0.0, 1e-5), (0.2, 0.0, 1e-5), (0.0, 2e-3, 1e-5), (0.0, 0.0, 0.0)] {
            let (t, truth, speed) = reversing_rotor(1000.0, jitter, 4.0);
            let noise = normals(11, t.len());
            let x: Vec<f64> = truth
                .iter()
                .zip(&noise)
                .map(|(q, e)| {
                    let m = q + sigma * e;
                    if quantum > 0.0 {
                        (m / quantum).round() * quantum
                    } else {
                        m
                    }
                })
                .collect();
            let smoothed = derivatives(&t, &x).0;
            let mut refined = smoothed.clone();
            let count = refine_reversals(&t, &x, &mut refined, robust_noise(&t, &x));
            // the slow samples: below the speed the rotor reaches 20 samples from a reversal
            let slow: Vec<usize> = (20..t.len() - 20).filter(|&k| speed[k].abs() < 30.0 * 20e-3).collect();
            let score = |v: &[f64]| {
                let wrong = slow.iter().filter(|&&k| v[k].signum() != speed[k].signum()).count();
                let rms = (slow.iter().map(|&k| (v[k] - speed[k]).powi(2)).sum::<f64>() / slow.len() as f64).sqrt();
                (wrong, rms)
            };
            let ((wrong_before, rms_before), (wrong_after, rms_after)) = (score(&smoothed), score(&refined));
            let case = format!("jitter {jitter}, quantum {quantum}: {count} refined, sign wrong at {wrong_before} → {wrong_after} samples, speed rms {rms_before:.4} → {rms_after:.4} rad/s");
            // nine reversals; the coarse encoder's fit widens to the samples its parabolas need,
            // which the first reversal, 0.4 s into the record, may not have
            assert!(count == 9 || (quantum > 0.0 && count == 8), "{case}");
            assert!(wrong_after <= count && wrong_after < wrong_before, "{case}");
            assert!(rms_after < 0.5 * rms_before, "{case}");
        }
    }

    /// Deterministic standard normals (Box–Muller on a 64-bit LCG).
    fn normals(seed: u64, n: usize) -> Vec<f64> {
        let mut state = seed;
        let mut u = || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        (0..n).map(|_| (-2.0 * u().ln()).sqrt() * (2.0 * std::f64::consts::PI * u()).cos()).collect()
    }

    #[test]
    fn a_start_that_reverses_its_acceleration_reads_as_rest_not_as_speed() {
        // (acceleration, sample period, samples to the turn, noise, encoder step)
        for (i, &(a, dt, k_turn, sigma, q)) in
            [(2500.0, 2.5e-3, 6, 2.4e-4, 9.3e-5), (40.0, 1e-3, 5, 1e-6, 1e-6), (1e4, 2e-4, 8, 1e-5, 6e-5)]
                .iter()
                .enumerate()
        {
            let (t, x) = bang_bang(a, dt, k_turn, 60);
            let x: Vec<f64> =
                x.iter().zip(normals(i as u64 + 1, 60)).map(|(x, e)| q * ((x + sigma * e) / q).round()).collect();
            let (v, se) = start_speed(&t, &x, 11).unwrap();
            // a fixed 11-sample quadratic reads the reversal as speed at t0
            let fixed = start_quadratic(&t, &x, 11).unwrap().0;
            let scale = a * k_turn as f64 * dt; // the speed at the turn
            assert!(v.abs() < 4.0 * se && v.abs() < 0.02 * scale, "start speed {v} ± {se} (fixed window {fixed})");
            assert!(fixed.abs() > 0.05 * scale, "the case must defeat a fixed window: {fixed}");
        }
    }

    #[test]
    fn a_start_that_moves_is_read_through_its_noise() {
        let n = 30;
        let (dt, v0, sigma) = (1e-3, 3.0, 1e-4);
        let noise = normals(7, n);
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let x: Vec<f64> = t.iter().zip(&noise).map(|(&t, e)| v0 * t + 20.0 * t * t + sigma * e).collect();
        let (v, se) = start_speed(&t, &x, 11).unwrap();
        assert!((v - v0).abs() < 4.0 * se && se < 0.1 * v0, "speed {v} ± {se}, truth {v0}");
    }

    /// A link at rest that a spring sets off (x ∝ t³ at first) reads as rest; one that moves reads as
    /// its speed, at any rate and through an encoder's counts.
    #[test]
    fn a_start_from_rest_whose_acceleration_grows_is_no_speed_and_a_moving_one_is() {
        for (i, &(dt, jerk, v0, sigma, q)) in
            [(2e-4, 2e4, 0.5, 2.4e-5, 1.5e-4), (1e-3, 500.0, 0.05, 1e-5, 6e-6), (5e-3, 200.0, 0.2, 1e-4, 1e-4)]
                .iter()
                .enumerate()
        {
            // the window `conditioning::initial_speed` takes: 20 ms, at least 10 samples
            let n = ((0.02 / dt) as usize + 1).max(10);
            let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
            let read = |x: Vec<f64>, seed: u64| -> Vec<f64> {
                x.iter().zip(normals(seed, n)).map(|(x, e)| q * ((x + sigma * e) / q).round()).collect()
            };
            let at_rest = read(t.iter().map(|&t| jerk * t.powi(3) / 6.0).collect(), 20 + i as u64);
            let (quadratic, se) = start_speed(&t, &at_rest, n).unwrap();
            assert!(quadratic.abs() > 3.0 * se, "case {i}: the quadratic must read a speed ({quadratic} ± {se})");
            assert_eq!(moving_start_speed(&t, &at_rest, n).unwrap().0, 0.0, "case {i}");
            // moving, its speed doubling over the window
            let moving = read(t.iter().map(|&t| v0 * t + 0.5 * (v0 / 0.02) * t * t).collect(), 30 + i as u64);
            let (v, se) = moving_start_speed(&t, &moving, n).unwrap();
            assert!((v - v0).abs() < 4.0 * se + 0.1 * v0, "case {i}: {v} ± {se}, truth {v0}");
        }
    }

    #[test]
    fn robust_noise_ignores_fast_moves_and_keeps_the_resolution() {
        // a servo's moves with white noise: the moves' curvature is not noise
        let sigma = 1e-5;
        let (_, x) = bang_bang(2500.0, 2.5e-3, 6, 400);
        let x: Vec<f64> = x.iter().zip(normals(3, 400)).map(|(x, e)| x + sigma * e).collect();
        let t: Vec<f64> = (0..400).map(|k| k as f64 * 2.5e-3).collect();
        let robust = robust_noise(&t, &x);
        assert!((robust / sigma - 1.0).abs() < 0.2, "robust {robust}, truth {sigma}");
        assert!(second_difference_noise(&x) > 10.0 * sigma, "the plain estimate takes the moves for noise");
        // a held encoder with a few steps and no noise: only the resolution remains
        let q = 1e-3;
        let x: Vec<f64> = (0..1000).map(|k| (k / 100) as f64 * q).collect();
        let t: Vec<f64> = (0..1000).map(|k| k as f64).collect();
        assert!((robust_noise(&t, &x) - q / 12f64.sqrt()).abs() < 1e-12, "{}", robust_noise(&t, &x));
    }

    #[test]
    fn robust_noise_reads_a_coarse_moving_encoder_at_its_resolution() {
        // drive rig 88's shape: 3e-3 rad counts, 5e-5 rad of noise, a 2 Hz swing of 0.4 rad at 2 kHz
        let (q, sigma, n) = (3e-3, 5e-5, 20_000);
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 5e-4).collect();
        let x: Vec<f64> = t
            .iter()
            .zip(normals(21, n))
            .map(|(&t, e)| q * ((0.4 * (2.0 * std::f64::consts::PI * 2.0 * t).sin() + sigma * e) / q).round())
            .collect();
        let floor = q / 12f64.sqrt();
        let median = 1.4826 * super::super::quality::median(cubic_residuals(&t, &x).map(f64::abs).collect());
        assert!(median > 1.2 * floor, "the median alone reads the counts' discrete residuals high: {median}");
        let robust = robust_noise(&t, &x);
        assert!((robust / floor - 1.0).abs() < 0.05, "robust {robust}, the counts leave {floor}");
    }

    #[test]
    fn robust_noise_ignores_a_fast_multisines_curvature_on_any_grid() {
        // drive rig 31's shape: 117 rad/s peak at 0.3-5 Hz, 500 Hz, 1e-4 rad of noise
        let sigma = 1e-4;
        let n = 5000;
        let e = normals(11, n);
        let u = normals(12, n);
        let motion = |t: f64| {
            [(0.3, 1.0), (1.3, 0.5), (5.0, 0.25)]
                .iter()
                .map(|(f, a)| 40.0 * a / f * (2.0 * std::f64::consts::PI * f * t).sin())
                .sum::<f64>()
        };
        for jitter in [0.0, 0.15] {
            // samples really taken off the clock, stamped where they were taken
            let t: Vec<f64> = (0..n).map(|k| (k as f64 + jitter * (u[k] % 1.0)) * 2e-3).collect();
            let x: Vec<f64> = t.iter().zip(&e).map(|(&t, e)| motion(t) + sigma * e).collect();
            let robust = robust_noise(&t, &x);
            assert!((robust / sigma - 1.0).abs() < 0.15, "jitter {jitter}: robust {robust}, truth {sigma}");
            assert!(median_second_difference_noise(&x) > 5.0 * sigma, "the second difference takes the curvature");
            let mean_square = cubic_noise(&t, &x);
            assert!((mean_square / sigma - 1.0).abs() < 0.15, "jitter {jitter}: mean square {mean_square}");
            assert!(second_difference_noise(&x) > 5.0 * sigma);
        }
    }

    #[test]
    fn only_a_quantised_signal_has_a_quantisation_floor() {
        // a 2500-line encoder's counts on a slow sine, and the same sine unquantised at 200 Hz
        let q = 2.0 * std::f64::consts::PI / 10_000.0;
        let x: Vec<f64> =
            (0..2000).map(|k| 0.3 * (2.0 * std::f64::consts::PI * 0.5 * k as f64 / 200.0).sin()).collect();
        let counts: Vec<f64> = x.iter().map(|v| (v / q).round() * q).collect();
        assert!((quantisation_floor(&counts) - q / 12f64.sqrt()).abs() < 1e-15);
        assert!(resolution(&x) > 0.0, "a continuous signal still has a smallest step");
        assert_eq!(quantisation_floor(&x), 0.0, "but no quantum");
    }

    /// Fresh rig 1032's link encoder: 1 238 counts a turn (5 mrad) on a 0.43 Hz swing of 0.29 rad at
    /// 2 kHz, 85 µrad of noise under it. The cubic reads the noise and not the counts held still, so
    /// smoothed only to the noise (the narrowest window) the staircase kept its steps, which a second
    /// difference reads as accelerations off by hundreds of times the swing's (rms). Smoothed to the
    /// count the error is a hundredth of that (measured: 1 794 → 16.9 rad/s², the swing's 2.07).
    #[test]
    fn a_coarse_count_is_smoothed_to_its_quantisation_not_to_the_noise_under_it() {
        let (q, rate, f, a) = (2.0 * std::f64::consts::PI / 1238.0, 2000.0, 0.4257, 0.29);
        let w = 2.0 * std::f64::consts::PI * f;
        let mut rng = super::super::synthetic::SplitMix::new(1032);
        let t: Vec<f64> = (0..(rate * 17.4) as usize).map(|k| k as f64 / rate).collect();
        let x: Vec<f64> = t.iter().map(|t| ((a * (w * t).sin() + 8.5e-5 * rng.normal()) / q).round() * q).collect();
        // rms of the second difference's error against the swing's own acceleration, in the middle
        let acceleration_error = |s: &[f64]| {
            let n = s.len();
            let e: Vec<f64> = (n / 10..n - n / 10)
                .map(|k| (s[k + 1] - 2.0 * s[k] + s[k - 1]) * rate * rate + a * w * w * (w * t[k]).sin())
                .collect();
            super::super::fit::rms(&e)
        };
        let cap = x.len() / 100;
        assert!(cubic_noise(&t, &x) < 0.5 * quantisation_floor(&x), "the case: the cubic misses the count");
        let (half, smoothed, noise) = smooth_to_noise(&t, &x, cap);
        assert_eq!(noise, quantisation_floor(&x));
        let swing = a * w * w;
        let (narrow, wide) = (acceleration_error(&smooth(&t, &x, 5)), acceleration_error(&smoothed));
        assert!(narrow > 100.0 * swing, "the narrowest smoothing keeps the steps: {narrow:.1} rad/s² for {swing:.2}");
        assert!(wide < narrow / 30.0, "half window {half}: {wide:.2} rad/s² against the narrowest's {narrow:.1}");
    }

    /// What the slid moments (`sliding_quintic`) change: a log like fresh rig 1047's (5 kHz with
    /// ±20 % jitter, a swing of 0.13 rad, 0.47 mrad of noise), its clock far from zero, smoothed
    /// over ±40 and ±600 samples. Against every window fitted afresh the angles differ by far less
    /// than the noise, and their second difference, the equation error's acceleration, by far less
    /// than the swing's own; on an even grid the same holds against Savitzky–Golay's weights.
    #[test]
    fn sliding_moments_fit_what_each_window_fitted_afresh_fits() {
        let (rate, f, a, sigma) = (5000.0, 0.7856, 0.13, 4.7e-4);
        let w = 2.0 * std::f64::consts::PI * f;
        let mut rng = super::super::synthetic::SplitMix::new(1047);
        let n = 30_000;
        let jittered: Vec<f64> =
            (0..n).map(|k| 1000.0 + (k as f64 + 0.2 * (2.0 * rng.uniform() - 1.0)) / rate).collect();
        let even: Vec<f64> = (0..n).map(|k| 1000.0 + k as f64 / rate).collect();
        let swing = a * w * w;
        for (grid, t) in [("jittered", &jittered), ("even", &even)] {
            let x: Vec<f64> =
                t.iter().map(|t| a * (w * t).sin() + 0.02 * (5.0 * w * t).cos() + sigma * rng.normal()).collect();
            for half in [40, 600] {
                let slid = smooth(t, &x, half);
                let fresh: Vec<f64> = if grid == "even" {
                    savitzky_golay(&x, half)
                } else {
                    (0..n).map(|k| local_quintic(t, &x, k, half.min(k).min(n - 1 - k))).collect()
                };
                let d: Vec<f64> = slid.iter().zip(&fresh).map(|(s, f)| s - f).collect();
                let largest = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                let acceleration: Vec<f64> = (1..n - 1)
                    .map(|k| {
                        ((d[k + 1] - d[k]) / (t[k + 1] - t[k]) - (d[k] - d[k - 1]) / (t[k] - t[k - 1]))
                            / (0.5 * (t[k + 1] - t[k - 1]))
                    })
                    .collect();
                let acceleration = super::super::fit::rms(&acceleration);
                eprintln!("{grid} ±{half}: largest {largest:.3e} rad, acceleration {acceleration:.3e} rad/s²");
                assert!(largest < 1e-6 * sigma, "{grid} ±{half}: the angles differ by {largest:.3e} rad");
                assert!(
                    acceleration < 1e-4 * swing,
                    "{grid} ±{half}: accelerations differ by {acceleration:.3e} rad/s²"
                );
            }
        }
    }

    /// The written-out LDLᵀ solve gives the quintic nalgebra's LU gives, to rounding, on windows
    /// narrow and wide, even and jittered; a window of one time has none.
    #[test]
    fn the_window_quintic_solves_as_a_general_lu_does() {
        let mut rng = super::super::synthetic::SplitMix::new(28);
        for (m, jitter) in [(3usize, 0.0), (3, 0.2), (40, 0.2), (600, 0.2), (600, 0.0)] {
            let mut moments = WindowMoments::default();
            for i in 0..=2 * m {
                let u = (i as f64 - m as f64 + jitter * (2.0 * rng.uniform() - 1.0)) / m as f64;
                moments.add(u, (3.0 * u).sin() + 0.01 * rng.normal(), 1.0);
            }
            let a = nalgebra::SMatrix::<f64, 6, 6>::from_fn(|i, j| moments.u[i + j]);
            let b = nalgebra::SVector::<f64, 6>::from_column_slice(&moments.xu);
            let lu = a.lu().solve(&b).unwrap()[0];
            let ldl = moments.centre().unwrap();
            assert!((ldl - lu).abs() <= 1e-9 * lu.abs().max(1.0), "±{m}, jitter {jitter}: {ldl} against {lu}");
        }
        assert_eq!(WindowMoments::default().centre(), None, "an empty window");
        let mut one = WindowMoments::default();
        one.add(0.0, 1.0, 1.0);
        assert_eq!(one.centre(), None, "one time");
    }

    #[test]
    fn the_fft_matches_the_dft_and_inverts() {
        let n = 64;
        let x: Vec<f64> = normals(21, n);
        let mut buf: Vec<Complex<f64>> = x.iter().map(|&v| Complex::new(v, 0.0)).collect();
        fft(&mut buf, false);
        for k in [0, 1, 5, 31, 32, 63] {
            let dft: Complex<f64> = (0..n)
                .map(|j| {
                    let a = -2.0 * std::f64::consts::PI * (j * k) as f64 / n as f64;
                    Complex::new(a.cos(), a.sin()) * x[j]
                })
                .sum();
            assert!((dft - buf[k]).norm() < 1e-9, "bin {k}: {} against {}", buf[k], dft);
        }
        fft(&mut buf, true);
        for j in 0..n {
            assert!((buf[j].re / n as f64 - x[j]).abs() < 1e-12 && buf[j].im.abs() < 1e-9);
        }
    }

    #[test]
    fn band_limiting_keeps_the_motion_and_takes_out_the_encoder_steps() {
        // a 0.5 Hz swing at 200 Hz on a 3000-count encoder, with an uneven start speed
        let (n, dt, q) = (4001, 5e-3, 2.0 * std::f64::consts::PI / 3000.0);
        let w = 2.0 * std::f64::consts::PI * 0.5;
        let jitter = normals(31, n);
        // on an even grid and with a logger's ±15 % jitter (its stamps are the samples' times)
        for spread in [0.0, 0.05] {
            let t: Vec<f64> = (0..n).map(|k| (k as f64 + spread * jitter[k].clamp(-3.0, 3.0)) * dt).collect();
            let truth: Vec<f64> = t.iter().map(|&t| 0.3 * (w * t + 0.7).sin() + 0.1 * t).collect();
            let x: Vec<f64> = truth.iter().map(|v| q * (v / q).round()).collect();
            let (y, edge) = band_limited(&t, &x, None).unwrap();
            let rms = |a: &[f64], b: &[f64]| {
                (a.iter().zip(b).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
            };
            assert!(edge > 0.5 && edge < 5.0, "edge {edge} Hz");
            // beyond one period of the edge from the ends (within it, callers fade to another
            // estimate: `fade_ends`)
            let inner = ((1.0 / (edge * dt)).ceil() as usize)..n - ((1.0 / (edge * dt)).ceil() as usize);
            let worst = inner.clone().map(|k| (y[k] - truth[k]).abs()).fold(0.0, f64::max);
            let (y_in, x_in, truth_in) = (&y[inner.clone()], &x[inner.clone()], &truth[inner]);
            assert!(
                rms(y_in, truth_in) < 0.3 * rms(x_in, truth_in),
                "band-limited {:e} against raw {:e}",
                rms(y_in, truth_in),
                rms(x_in, truth_in)
            );
            assert!(worst < q, "worst {worst:e} against a step of {q:e}");
        }
    }

    #[test]
    fn steps_keep_their_motion_above_the_band_edge_where_it_stands_out_of_the_noise() {
        // steps between levels within ±0.19 rad every 0.5–1.3 s, each a tanh over 50 ms, read with
        // 2.2e-4 rad of noise on a 9 500-count encoder at 500 Hz for 18 s (campaign rig 271's motor):
        // the motion's variance above its edge is less than the noise's there, spread to Nyquist,
        // but per bin it stands out of the noise up to about 1.6 times the edge, where that rig's
        // 14 Hz link rings
        let (n, dt, q) = (9001usize, 2e-3, 2.0 * std::f64::consts::PI / 9529.0);
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let draws = normals(5, 64);
        let (mut at, mut times, mut levels) = (0.4, vec![], vec![0.0]);
        for d in draws.chunks(2) {
            times.push(at);
            levels.push(0.1 * d[0].clamp(-1.9, 1.9));
            at += 0.9 + 0.2 * d[1].clamp(-2.0, 2.0);
        }
        let truth: Vec<f64> = t
            .iter()
            .map(|&t| {
                (0..times.len())
                    .map(|i| 0.5 * (levels[i + 1] - levels[i]) * (1.0 + ((t - times[i]) / 0.05).tanh()))
                    .sum()
            })
            .collect();
        let noise = normals(6, n);
        let x: Vec<f64> = truth.iter().zip(&noise).map(|(v, e)| q * ((v + 2.2e-4 * e) / q).round()).collect();
        let (y, edge) = band_limited(&t, &x, None).unwrap();
        // the part of a signal between two frequencies (an ideal band pass), less the line through
        // its ends (whose jump in the transform's periodic extension would leak into every band)
        let line = |s: &[f64], k: usize| s[0] + (s[n - 1] - s[0]) * k as f64 / (n - 1) as f64;
        let band = |s: &[f64], lo: f64, hi: f64| {
            let size = n.next_power_of_two();
            let mut buf: Vec<Complex<f64>> =
                (0..size).map(|k| Complex::new(if k < n { s[k] - line(s, k) } else { 0.0 }, 0.0)).collect();
            fft(&mut buf, false);
            for (k, c) in buf.iter_mut().enumerate() {
                let f = k.min(size - k) as f64 / (size as f64 * dt);
                if f < lo || f > hi {
                    *c = Complex::new(0.0, 0.0);
                }
            }
            fft(&mut buf, true);
            buf[..n].iter().map(|c| c.re / size as f64).collect::<Vec<f64>>()
        };
        let inner = |s: &[f64]| s[1000..n - 1000].to_vec();
        let dot = |u: &[f64], v: &[f64]| inner(u).iter().zip(inner(v)).map(|(a, b)| a * b).sum::<f64>();
        let rms = |a: &[f64]| (dot(a, a) / (n - 2000) as f64).sqrt();
        // the share of the motion between 1.3 and 1.6 times the edge that passes (its projection)
        let (lo, hi) = (1.3 * edge, 1.6 * edge);
        let motion = band(&truth, lo, hi);
        let passed = |y: &[f64]| dot(&band(y, lo, hi), &motion) / dot(&motion, &motion);
        // the cosine taper alone (what a cap leaves) passes 70 % of it
        let (tapered, _) = band_limited(&t, &x, Some(f64::MAX)).unwrap();
        assert!(
            passed(&y) > 0.85 && passed(&y) > passed(&tapered) + 0.1,
            "edge {edge} Hz: {} of the motion passes between {lo} and {hi} Hz, {} tapered",
            passed(&y),
            passed(&tapered)
        );
        // and the encoder's steps and noise are still taken out
        let error: Vec<f64> = y.iter().zip(&truth).map(|(a, b)| a - b).collect();
        let raw: Vec<f64> = x.iter().zip(&truth).map(|(a, b)| a - b).collect();
        assert!(rms(&error) < 0.5 * rms(&raw), "{:e} against the raw samples' {:e}", rms(&error), rms(&raw));
        // an encoder its noise does not dither dwells on its counts, which is no white noise: the
        // same steps read with 1e-5 rad of noise keep the taper alone
        let undithered: Vec<f64> = truth.iter().zip(&noise).map(|(v, e)| q * ((v + 1e-5 * e) / q).round()).collect();
        assert_eq!(band_limited(&t, &undithered, None), band_limited(&t, &undithered, Some(f64::MAX)));
    }

    /// A multisine of 0.2–3 Hz read through a count its noise does not dither (fresh rig 1292: 1 580
    /// counts a turn, 1.4e-4 rad of noise, 5 kHz): the noise's rule leaves the count's dwell in the
    /// band far above the motion; taken against the count's whole error, the edge sits just above
    /// the motion and the angle it leaves is nearer the truth.
    #[test]
    fn a_band_read_against_the_count_ends_where_a_slow_motion_does() {
        let n = 100_000;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * 2e-4).collect();
        let freqs = [0.2, 0.4, 0.8, 1.6, 3.0];
        let truth: Vec<f64> = t
            .iter()
            .map(|&t| {
                freqs
                    .iter()
                    .enumerate()
                    .map(|(i, f)| 0.06 * (2.0 * std::f64::consts::PI * f * t + i as f64).sin())
                    .sum()
            })
            .collect();
        let q = 2.0 * std::f64::consts::PI / 1580.0;
        let noise = normals(41, n);
        let x: Vec<f64> = truth.iter().zip(&noise).map(|(v, e)| q * ((v + 1.4e-4 * e) / q).round()).collect();
        let (by_noise, noise_edge) = band_limited(&t, &x, None).unwrap();
        let (by_count, count_edge) = band_limited_to_count(&t, &x).unwrap();
        assert!(noise_edge > 20.0, "the noise's edge {noise_edge} Hz: the case");
        assert!(count_edge > 3.0 && count_edge < 9.0, "the count's edge {count_edge} Hz");
        let rms = |y: &[f64]| {
            let inner = 5000..n - 5000;
            (inner.clone().map(|k| (y[k] - truth[k]).powi(2)).sum::<f64>() / inner.len() as f64).sqrt()
        };
        assert!(
            rms(&by_count) < 0.5 * rms(&by_noise),
            "against the truth: {:e} by the count's edge, {:e} by the noise's",
            rms(&by_count),
            rms(&by_noise)
        );
    }

    #[test]
    fn a_noise_free_angle_is_not_band_limited() {
        let t: Vec<f64> = (0..2000).map(|k| k as f64 * 1e-3).collect();
        // a ramp (no second differences at all) comes back as it is
        let ramp: Vec<f64> = t.iter().map(|&t| 0.3 * t - 0.1).collect();
        let (y, edge) = band_limited(&t, &ramp, None).unwrap();
        assert_eq!(y, ramp);
        assert!((edge - 500.0).abs() < 1.0, "edge {edge}");
        // a smooth swing's second differences are its curvature, not noise: it passes the band
        let swing: Vec<f64> = t.iter().map(|&t| 0.2 * (2.0 * std::f64::consts::PI * 0.5 * t).sin()).collect();
        let (y, _) = band_limited(&t, &swing, None).unwrap();
        let worst = y.iter().zip(&swing).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(worst < 1e-6 * 0.2, "worst {worst:e}");
    }

    #[test]
    fn the_band_passes_half_the_power_where_its_cap_puts_it() {
        // a 0.5 Hz swing with white noise and a tone at 10× (the cap's half-power point) or at
        // 13.8× (a lightly damped link's resonance, docs/calibration.md), large enough that the
        // edge is the cap's. The band limit is linear once its edge is set: the tone's share of
        // the output is the output with the tone less the output without it
        use crate::calibrate::conditioning::{band_edge_cap, BAND_TOP_FACTOR};
        let (n, dt, f0) = (20_001, 1e-3, 0.5);
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let noise = normals(7, n);
        let tone = |f: f64, t: f64| (2.0 * std::f64::consts::PI * f * t).sin();
        let cap = band_edge_cap(f0);
        let band = |f: Option<f64>| {
            let x: Vec<f64> = (0..n)
                .map(|k| 0.3 * tone(f0, t[k]) + f.map_or(0.0, |f| 1e-3 * tone(f, t[k])) + 1e-5 * noise[k])
                .collect();
            band_limited(&t, &x, Some(cap)).unwrap()
        };
        let (without, _) = band(None);
        let passed = |f: f64| {
            let (y, edge) = band(Some(f));
            assert!((edge - cap).abs() < 0.01, "edge {edge} Hz against the cap's {cap} Hz");
            let inner = 2000..n - 2000;
            let (mut s, mut c) = (0.0, 0.0);
            for k in inner.clone() {
                let phase = 2.0 * std::f64::consts::PI * f * t[k];
                s += (y[k] - without[k]) * phase.sin();
                c += (y[k] - without[k]) * phase.cos();
            }
            2.0 * (s * s + c * c).sqrt() / inner.len() as f64 / 1e-3
        };
        let at_cap = passed(BAND_TOP_FACTOR * f0);
        assert!((at_cap - std::f64::consts::FRAC_1_SQRT_2).abs() < 0.03, "{at_cap} of the tone at the cap");
        // the edge at the cap itself would have passed 68 % of it
        let at_resonance = passed(6.9);
        assert!(at_resonance < 0.1, "{at_resonance} of the tone at the resonance");
    }
}
