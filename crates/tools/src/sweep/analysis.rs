//! Signal analysis over whole steady cycles: first harmonics by a DFT at the drive frequency.
//!
//! With uniform samples and a window of whole periods, the DFT bin at ω is exact for a sinusoid and
//! blind to a constant offset and to the other harmonics, so amplitude and phase need no fitting.

use complex::C64;

/// A minimal complex number (no extra crate for four operations).
pub mod complex {
    #[derive(Clone, Copy, Debug, PartialEq)]
    pub struct C64 {
        pub re: f64,
        pub im: f64,
    }

    impl C64 {
        pub const fn new(re: f64, im: f64) -> C64 {
            C64 { re, im }
        }
        pub fn norm(self) -> f64 {
            self.re.hypot(self.im)
        }
        pub fn arg(self) -> f64 {
            self.im.atan2(self.re)
        }
        pub fn from_polar(r: f64, th: f64) -> C64 {
            C64::new(r * th.cos(), r * th.sin())
        }
        pub fn scale(self, k: f64) -> C64 {
            C64::new(self.re * k, self.im * k)
        }
    }

    impl std::ops::Add for C64 {
        type Output = C64;
        fn add(self, o: C64) -> C64 {
            C64::new(self.re + o.re, self.im + o.im)
        }
    }
    impl std::ops::Sub for C64 {
        type Output = C64;
        fn sub(self, o: C64) -> C64 {
            C64::new(self.re - o.re, self.im - o.im)
        }
    }
    impl std::ops::Mul for C64 {
        type Output = C64;
        fn mul(self, o: C64) -> C64 {
            C64::new(self.re * o.re - self.im * o.im, self.re * o.im + self.im * o.re)
        }
    }
    impl std::ops::Div for C64 {
        type Output = C64;
        fn div(self, o: C64) -> C64 {
            let d = o.re * o.re + o.im * o.im;
            C64::new((self.re * o.re + self.im * o.im) / d, (self.im * o.re - self.re * o.im) / d)
        }
    }
}

pub use complex::C64 as Complex;

/// Samples per period for communication step `h` at `frequency_hz`, if it is a whole number.
pub fn samples_per_period(frequency_hz: f64, h: f64) -> Option<usize> {
    let n = 1.0 / (frequency_hz * h);
    let r = n.round();
    ((n - r).abs() <= 1e-6 * r && r >= 8.0).then_some(r as usize)
}

/// Complex amplitude c of the first harmonic of `x` over the samples `[start, start + cycles·n)`,
/// with `x ≈ |c| sin(ωt + arg c)` for t = time of each sample (the DFT uses the absolute times, so
/// phases of different signals in the same window compare directly).
pub fn first_harmonic(time: &[f64], x: &[f64], omega: f64, start: usize, len: usize) -> C64 {
    let mut acc = C64::new(0.0, 0.0);
    for k in start..start + len {
        let (s, c) = (omega * time[k]).sin_cos();
        // x = A sin(ωt + φ) = A (sin ωt cos φ + cos ωt sin φ): project on sin and cos
        acc.re += x[k] * s;
        acc.im += x[k] * c;
    }
    acc.scale(2.0 / len as f64)
}

/// Amplitude of the residual after removing mean and first harmonic, relative to the harmonic:
/// how far the steady signal is from a sinusoid (distortion + leftover transient).
pub fn non_sinusoidal_fraction(time: &[f64], x: &[f64], omega: f64, start: usize, len: usize) -> f64 {
    let c = first_harmonic(time, x, omega, start, len);
    let mean = x[start..start + len].iter().sum::<f64>() / len as f64;
    let mut rss = 0.0;
    for k in start..start + len {
        let fit = mean + c.norm() * (omega * time[k] + c.arg()).sin();
        rss += (x[k] - fit).powi(2);
    }
    (2.0 * rss / len as f64).sqrt() / c.norm()
}

/// Last time at which `x` departs from its steady sinusoid (mean + first harmonic over the window
/// `[start, start + len)`, extended back to t = 0) by more than `threshold`: the length of the
/// start-up transient. 0 if it never does.
pub fn transient_end(time: &[f64], x: &[f64], omega: f64, start: usize, len: usize, threshold: f64) -> f64 {
    let c = first_harmonic(time, x, omega, start, len);
    let mean = x[start..start + len].iter().sum::<f64>() / len as f64;
    (0..x.len())
        .rev()
        .find(|&k| (x[k] - mean - c.norm() * (omega * time[k] + c.arg()).sin()).abs() > threshold)
        .map_or(0.0, |k| time[k])
}

/// Mean, min and max of a slice.
pub fn stats(x: &[f64]) -> (f64, f64, f64) {
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    let min = x.iter().cloned().fold(f64::INFINITY, f64::min);
    let max = x.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    (mean, min, max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_harmonic_of_a_shifted_sinusoid_with_offset_and_harmonic() {
        let w = std::f64::consts::PI;
        let n = 2000;
        let t: Vec<f64> = (0..3 * n).map(|k| k as f64 * 1e-3).collect();
        let x: Vec<f64> = t.iter().map(|&t| 0.3 + 0.5 * (w * t - 0.2).sin() + 0.05 * (3.0 * w * t).sin()).collect();
        let c = first_harmonic(&t, &x, w, n, 2 * n);
        assert!((c.norm() - 0.5).abs() < 1e-12, "{c:?}");
        assert!((c.arg() + 0.2).abs() < 1e-12, "{c:?}");
    }
}
