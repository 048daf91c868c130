//! Runs as the loops see them: temperature groups, and the device's model inputs from a measured run
//! (the motor angle smoothed, the link's initial speed). Drive runs condition their own inputs in
//! `drive::DriveInput`.

use super::data::Run;
use super::signal::{band_limited, fade_ends, noise_free, rms_frequency, smooth};

/// The fitted temperature group each held-out run uses: the one nearest its own temperature
/// (held-out runs take the moduli fitted there; nothing is fitted on them).
pub fn held_out_groups(held: &[Run], fitted_temperatures: &[f64]) -> Vec<usize> {
    let (group, temperatures) = group_runs(held);
    let nearest = |t: f64| {
        (0..fitted_temperatures.len())
            .min_by(|&a, &b| (fitted_temperatures[a] - t).abs().total_cmp(&(fitted_temperatures[b] - t).abs()))
            .unwrap_or(0)
    };
    group.into_iter().map(|g| nearest(temperatures[g])).collect()
}

/// Temperature groups: runs at one nominal temperature share E' and E''. The nominal temperature is
/// the declared `temperature_c` metadata, else the thermocouple mean, to 0.5 °C.
pub fn group_runs(runs: &[Run]) -> (Vec<usize>, Vec<f64>) {
    let mut temps: Vec<f64> = Vec::new();
    let mut group = Vec::new();
    for r in runs {
        let t = r.meta_f64("temperature_c").unwrap_or_else(|| r.mean_temperature_c());
        let t = (t * 2.0).round() / 2.0;
        let g = match temps.iter().position(|&x| x == t) {
            Some(g) => g,
            None => {
                temps.push(t);
                temps.len() - 1
            }
        };
        group.push(g);
    }
    (group, temps)
}

/// The highest frequency a run's motor angle carries: its own for a single sinusoid (`sinusoid`,
/// `fit::is_sinusoidal_signal`), else three times its RMS frequency rms(θm')/(2π rms(θm − mean)),
/// with speeds over ±10 ms.
fn top_frequency(r: &Run, sinusoid: bool) -> f64 {
    if sinusoid {
        r.frequency_hz
    } else {
        3.0 * rms_frequency(&r.time, &r.motor)
    }
}

/// A sinusoidal motor angle's band reaches at most this many times its frequency, its half-power
/// point there (`band_edge_cap`): the passband of the smoothing the band fades into at its ends (a
/// quintic Savitzky–Golay window of half-width 0.1 s over the top frequency passes up to about ten
/// times it, Schafer 2011); other runs are not capped (`MotorReading::motor`). The noise alone does not set
/// a sinusoid's edge: an encoder's error near its turns, where it dwells on a count, is no white
/// noise, and up to 13 Hz of it (a 10 000-count encoder, 0.5 Hz at 1 kHz) stood above the white
/// level; passed to a never-pulling backlash it left the fit at 2.2× its noise floor.
pub const BAND_TOP_FACTOR: f64 = 10.0;

/// The highest edge the band limit may take for a run whose top frequency is `top_hz`: the band's
/// response is flat to its edge f_c and falls as a cosine to zero at 2 f_c, so it passes half
/// the power at f_c (1 + acos(√2 − 1)/π) ≈ 1.36 f_c; that point sits at `BAND_TOP_FACTOR` times
/// the top frequency, where the smoothing's does. Capping the edge itself there let the taper
/// pass up to twice as far, 68 % of the amplitude at a 0.5 Hz sine's 6.9 Hz resonance where the
/// smoothing passes little: a lightly damped link (ζ = 0.004, tests/python/test_blind_calibration.py)
/// sat at 1.27× its floor, 1.18× smoothed, 1.16× with this cap.
pub fn band_edge_cap(top_hz: f64) -> f64 {
    let half_power = 1.0 + (std::f64::consts::SQRT_2 - 1.0).acos() / std::f64::consts::PI;
    BAND_TOP_FACTOR * top_hz / half_power
}

/// Half-width in samples of the motor angle's smoothing (`seconds`: given, or None for the
/// band limit's ends, `MotorReading::motor`): 0.1 s over the highest frequency the run carries
/// (`top_frequency`). A quintic Savitzky–Golay window of M samples passes up to about fs/M
/// (Schafer 2011), ten times that frequency. A motor angle without noise (second-difference noise
/// below 1e-12 of its swing) is not smoothed. `sinusoid`: whether the run reads as a single one
/// (`fit::is_sinusoidal_signal`, read once by the caller, which caps a sinusoid's band as well).
pub fn smoothing_half_width(r: &Run, seconds: Option<f64>, sinusoid: bool) -> usize {
    let n = r.time.len();
    let dt = (r.time[n - 1] - r.time[0]) / (n - 1).max(1) as f64;
    let seconds = match seconds {
        Some(s) => s,
        None => {
            if noise_free(&r.motor) {
                return 0;
            }
            let top = top_frequency(r, sinusoid);
            if top > 0.0 {
                0.1 / top
            } else {
                0.0
            }
        }
    };
    ((seconds / dt).round() as usize).min(n / 4)
}

/// The model's inputs from a measured run. The motor angle is band-limited to its motion
/// (`MotorReading::motor`), or smoothed with `smoothing_seconds` (its half-width, 0 the raw samples),
/// because it sets the commanded speed of every step: encoder steps of 2π/10000 at 1 kHz make the
/// raw slope jitter by ~0.6 rad/s, which the PCL damper (C = E''κr_p²/ω, ~20 N·m·s/rad at 40 °C
/// and 0.5 Hz) passes to the link as torque noise, and which a never-pulling backlash contact
/// rectifies into bias. Returns how the motor angle was conditioned too, for the report.
/// `count_edge`: a run that is not a single sinusoid has its band's edge where the motion stands out
/// of the count's whole error (`signal::band_limited_to_count`; `calibrate` fits the baseline both
/// ways and keeps the lower BIC).
pub fn sim_input(
    r: &Run,
    smoothing_seconds: Option<f64>,
    count_edge: bool,
) -> (super::sim::SimInput, MotorConditioning) {
    let reading = MotorReading::of(r, smoothing_seconds);
    let (motor, conditioning) = reading.motor(r, count_edge);
    (input_of(r, motor, reading.link_noise), conditioning)
}

/// [`sim_input`] by the noise's band edge, and the run's reading, which gives the count's edge
/// without reading the run again ([`MotorReading::by_count`]).
pub fn sim_input_and_reading(
    r: &Run,
    smoothing_seconds: Option<f64>,
) -> ((super::sim::SimInput, MotorConditioning), MotorReading) {
    let reading = MotorReading::of(r, smoothing_seconds);
    let (motor, conditioning) = reading.motor(r, false);
    ((input_of(r, motor, reading.link_noise), conditioning), reading)
}

fn input_of(r: &Run, motor: Vec<f64>, link_noise: f64) -> super::sim::SimInput {
    let substeps = super::sim::motor_substeps(&r.time, &motor, link_noise);
    super::sim::SimInput {
        time: r.time.clone(),
        motor,
        housing_k: r.temperature_c.iter().map(|t| t + crate::report::ZERO_CELSIUS).collect(),
        frequency_hz: r.frequency_hz,
        link_inertia: r.link_inertia,
        link0: r.link[0],
        com_distance: r.meta_f64("link_length_m").unwrap_or(0.14),
        initial_link_speed: initial_speed(&r.time, &r.link),
        after_gap: r.segment.is_some_and(|(k, _)| k > 1),
        housing_before: r.thermocouple_before.clone(),
        substeps,
    }
}

/// How the motor angle that drives the model was conditioned: the band's edge (Hz) or the
/// smoothing's half-width (s), for the report.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MotorConditioning {
    BandLimited { edge_hz: f64 },
    Smoothed { half_width_s: f64 },
}

/// A run's motor angle read once for [`MotorReading::motor`]: whether it is a single sinusoid,
/// and its smoothing (both band edges need them).
pub struct MotorReading {
    /// whether the band limit reads the run as a single sinusoid (asked only without a smoothing)
    sinusoid: bool,
    /// the link angle's noise, which sets the model's substeps (`sim::motor_substeps`)
    link_noise: f64,
    smoothing_seconds: Option<f64>,
    half: usize,
    smoothed: Vec<f64>,
}

impl MotorReading {
    fn of(r: &Run, smoothing_seconds: Option<f64>) -> Self {
        let sinusoid =
            smoothing_seconds.is_none() && super::fit::is_sinusoidal_signal(&r.time, &r.motor, r.frequency_hz);
        let half = smoothing_half_width(r, smoothing_seconds, sinusoid);
        let link_noise = super::signal::robust_noise(&r.time, &r.link);
        MotorReading { sinusoid, link_noise, smoothing_seconds, half, smoothed: smooth(&r.time, &r.motor, half) }
    }

    /// [`sim_input`] by the count's band edge, where the run is band-limited and not a single
    /// sinusoid; None where the count's rule does not reach it.
    pub fn by_count(&self, r: &Run) -> Option<(super::sim::SimInput, MotorConditioning)> {
        (self.smoothing_seconds.is_none() && !self.sinusoid).then(|| {
            let (motor, conditioning) = self.motor(r, true);
            (input_of(r, motor, self.link_noise), conditioning)
        })
    }

    /// The motor angle that drives the model, and how it was conditioned (`sim_input`): with
    /// `smoothing_seconds`, smoothed; else band-limited to its motion (`signal::band_limited`, a
    /// sinusoid's edge capped by `band_edge_cap`) and faded into the smoothing within one period of the edge of either
    /// end, where the band limit's reflection is a guess (raw samples there let a never-pulling
    /// backlash take a kick that stays in its play: 3.7× the noise floor on a synthetic backlash rig).
    /// Band-limited rather than smoothed by default: on the campaign's CI subset, device rigs inside
    /// the library 17/28 → 19/28, held-out seeds 51–90 12/22 → 15/22, none lost (docs/calibration.md).
    fn motor(&self, r: &Run, count_edge: bool) -> (Vec<f64>, MotorConditioning) {
        let n = r.time.len();
        let dt = (r.time[n - 1] - r.time[0]) / (n - 1).max(1) as f64;
        if self.smoothing_seconds.is_none() {
            // A sinusoid's edge is capped where its smoothing's passband ends (`band_edge_cap`): at its
            // turns the encoder dwells on a count, an error the white-noise rule cannot see. Steps and
            // multisines have no top frequency to cap at: three times the rms frequency put the edge
            // under the motion that rings the link (campaign rig 243, steps: 7.3 Hz on a 7.3 Hz link,
            // 1.24× the floor with every parameter within 0.4 %; uncapped 1.02×), so theirs is the noise's.
            // With `count_edge`, theirs is where the motion stands out of the count's whole error
            // (`signal::band_limited_to_count`): the noise's edge can pass an encoder's count the noise
            // does not dither (fresh rig 1292, a 0.2–3 Hz multisine on 1 580 counts a turn: its edge at
            // 120 Hz drove an 18 Hz link with the count's steps, C +628 %; capped at 4 Hz, C within 10 %
            // and the BIC 11 900 lower). Which of the two holds is the fit's to say.
            let cap = self.sinusoid.then(|| band_edge_cap(r.frequency_hz)).filter(|&cap| cap > 0.0);
            let limited = if count_edge && !self.sinusoid {
                super::signal::band_limited_to_count(&r.time, &r.motor)
            } else {
                band_limited(&r.time, &r.motor, cap)
            };
            if let Some((limited, edge_hz)) = limited {
                return (
                    fade_ends(&r.time, &limited, &self.smoothed, edge_hz),
                    MotorConditioning::BandLimited { edge_hz },
                );
            }
        }
        (self.smoothed.clone(), MotorConditioning::Smoothed { half_width_s: self.half as f64 * dt })
    }
}

/// Speed at the first sample when the data show one (a run need not start at rest): the slope of
/// the start's quadratic over the first 20 ms (at least 10 samples), shortened where the motion is
/// not quadratic over it (`signal::start_speed`), kept only when it stands out of its own standard
/// error by 3 (at rest, encoder noise alone must not set the link moving) and only where the start
/// reads as motion rather than as a link at rest set off (`signal::moving_start_speed`). A link
/// that starts at rest and catches up with the motor within a millisecond looks the same over
/// 20 ms, so `search::resolve_initial_speeds` lets the baseline fit decide.
pub fn initial_speed(t: &[f64], x: &[f64]) -> f64 {
    let most = t.iter().take_while(|&&ti| ti - t[0] <= 0.02).count().max(10);
    match super::signal::moving_start_speed(t, x, most) {
        Some((v, se)) if v.abs() > 3.0 * se => v,
        _ => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibrate::signal::rms_frequency;

    /// A run read from a file as `calibrate` reads it: the motor angle `motor(t)` on a 20 000-count
    /// encoder at 2 kHz for 20 s, the link at rest.
    fn run_of(name: &str, motor: impl Fn(f64) -> f64) -> Run {
        let q = 2.0 * std::f64::consts::PI / 20_000.0;
        let mut text = String::from("# temperature_c=22\ntime_s,motor_angle_rad,link_angle_rad\n");
        for k in 0..40_000 {
            let t = k as f64 * 5e-4;
            text += &format!("{t},{},0\n", (motor(t) / q).round() * q);
        }
        let path = std::env::temp_dir().join(format!("thermovia-conditioning-{}-{name}.csv", std::process::id()));
        std::fs::write(&path, text).unwrap();
        let run = super::super::data::read_run(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        run
    }

    fn edge(r: &Run) -> f64 {
        match sim_input(r, None, false).1 {
            MotorConditioning::BandLimited { edge_hz } => edge_hz,
            other => panic!("not band-limited: {other:?}"),
        }
    }

    #[test]
    fn only_a_sinusoids_band_is_capped_at_its_smoothings_passband() {
        // steps of 0.3 rad every 2 s, each a first-order approach over 50 ms: their content reaches
        // far past three times their rms frequency, where the cap of a sinusoid would put the edge
        let steps = run_of("steps", |t| {
            let (k, s) = ((t / 2.0).floor(), t % 2.0);
            let level = |k: f64| if k as i64 % 2 == 0 { 0.3 } else { -0.3 };
            level(k - 1.0) + (level(k) - level(k - 1.0)) * (1.0 - (-s / 0.05).exp())
        });
        let old_cap = band_edge_cap(3.0 * rms_frequency(&steps.time, &steps.motor));
        assert!(edge(&steps) > 2.0 * old_cap, "steps' edge {} Hz against {old_cap} Hz", edge(&steps));
        // a sine's edge stays at its cap, whatever the encoder's dwell error leaves above the noise
        let sine = run_of("sine", |t| 0.3 * (2.0 * std::f64::consts::PI * 0.5 * t).sin());
        assert!(edge(&sine) <= band_edge_cap(sine.frequency_hz) * (1.0 + 1e-9), "sine's edge {}", edge(&sine));
    }
}
