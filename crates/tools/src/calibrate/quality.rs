//! Data quality before any fit (docs/interfaces.md, "Data quality"): values outside any physical
//! range are refused; isolated spikes and encoder wraps are found and refused, or repaired when the
//! user asks (`--repair-samples`), always named by file, line and column; gaps in the time base
//! split a run into segments, each started from the measured state after the gap.
//!
//! Every threshold is a quantity the data define: the noise floor of the column (a robust scale of
//! its deviations from the straight line through its neighbours), the column's resolution (its
//! smallest step), the local curvature around the sample, and the run's median sample period.

use std::path::Path;

use thermovia_importer::table::DataError;

/// The FMU's input ranges, which no measured value can leave and still be simulated: angles and
/// positions within ±1e6 (rad or m), torques and forces within ±1e4 (N·m or N), temperatures within
/// 1 K … 1e4 K.
pub const POSITION_LIMIT: f64 = 1e6;
pub const TORQUE_LIMIT: f64 = 1e4;
pub const TEMPERATURE_RANGE_C: (f64, f64) = (1.0 - 273.15, 1e4 - 273.15);

/// A sample interval longer than this many median periods is a gap.
pub const GAP_PERIODS: f64 = 5.0;

/// A deviation this many times the column's noise (floor + local curvature + resolution) is not noise.
const OUTLIER_FACTOR: f64 = 10.0;

/// Segments shorter than this (samples) after a split are dropped, and say so.
pub const MIN_SEGMENT_SAMPLES: usize = 20;

/// What kind of column a check reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Quantity {
    /// An angle (rad) on a rotary axis: encoder wraps are possible.
    Angle,
    /// A position (m) on a linear axis.
    Position,
    Torque,
    TemperatureC,
}

/// A sample found corrupt.
#[derive(Clone, Debug, PartialEq)]
pub struct Finding {
    /// Sample index in the column.
    pub index: usize,
    pub kind: FindingKind,
    /// The value as logged.
    pub value: f64,
    /// What a repair puts there (for a wrap: the same sample unwrapped; later samples follow).
    pub repaired: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FindingKind {
    /// One sample far off the line through its neighbours, which agree with each other.
    Spike,
    /// A jump of a whole number of turns in one sample, the motion continuing on either side.
    EncoderWrap { turns: i64 },
}

impl FindingKind {
    pub fn name(self) -> &'static str {
        match self {
            FindingKind::Spike => "spike",
            FindingKind::EncoderWrap { .. } => "encoder_wrap",
        }
    }
}

/// A repaired sample, as the report lists it.
#[derive(Clone, Debug, PartialEq)]
pub struct Repair {
    pub line: usize,
    pub column: String,
    pub kind: FindingKind,
    pub value: f64,
    pub replaced_by: f64,
}

/// A gap in a run's time base: no sample between `from_s` and `to_s`; `line` is the first sample after it.
#[derive(Clone, Debug, PartialEq)]
pub struct Gap {
    pub line: usize,
    pub from_s: f64,
    pub to_s: f64,
}

/// A number as an error message shows it: short, in scientific notation when large or small.
pub fn short(x: f64) -> String {
    if x != 0.0 && (x.abs() >= 1e5 || x.abs() < 1e-3) {
        format!("{x:.4e}")
    } else {
        format!("{:.6}", x).trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// Refuses the first value outside `q`'s physical range, naming file, line and column.
pub fn check_range(
    path: &Path,
    lines: &[usize],
    column: (usize, &str),
    q: Quantity,
    x: &[f64],
) -> Result<(), DataError> {
    let (lo, hi, what) = match q {
        Quantity::Angle => (-POSITION_LIMIT, POSITION_LIMIT, "an angle beyond ±1e6 rad (160,000 turns)"),
        Quantity::Position => (-POSITION_LIMIT, POSITION_LIMIT, "a position beyond ±1e6 m"),
        Quantity::Torque => (-TORQUE_LIMIT, TORQUE_LIMIT, "a torque or force beyond ±1e4"),
        Quantity::TemperatureC => (TEMPERATURE_RANGE_C.0, TEMPERATURE_RANGE_C.1, "a temperature outside 1 K … 1e4 K"),
    };
    match x.iter().position(|v| !(*v >= lo && *v <= hi)) {
        None => Ok(()),
        Some(k) => Err(DataError {
            file: path.to_path_buf(),
            line: lines.get(k).copied(),
            column: Some((column.0, column.1.to_string())),
            message: format!("{} is {what}: a corrupt sample, not a measurement", short(x[k])),
        }),
    }
}

/// The FMU's speed range (its `motor_speed_command`, rad/s or m/s): a position that moves faster
/// between two samples is a unit slip or a corrupt sample, and the FMU would refuse it mid-fit.
pub const SPEED_LIMIT: f64 = 1e4;

/// Refuses the first pair of samples of a measured position that moves faster than
/// [`SPEED_LIMIT`], at the later sample's line (checked after spikes and wraps are found, so a
/// wrap is named as one).
pub fn check_speed(path: &Path, lines: &[usize], column: (usize, &str), t: &[f64], x: &[f64]) -> Result<(), DataError> {
    let fast = (1..x.len().min(t.len())).find(|&k| (x[k] - x[k - 1]).abs() > SPEED_LIMIT * (t[k] - t[k - 1]));
    match fast {
        None => Ok(()),
        Some(k) => Err(DataError {
            file: path.to_path_buf(),
            line: lines.get(k).copied(),
            column: Some((column.0, column.1.to_string())),
            message: format!(
                "{} after {} in {} s is a speed beyond the FMU's ±1e4 per second: a unit slip or a corrupt sample",
                short(x[k]),
                short(x[k - 1]),
                short(t[k] - t[k - 1])
            ),
        }),
    }
}

/// Median of a copy of `v` (0 when empty).
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let m = v.len() / 2;
    *v.select_nth_unstable_by(m, f64::total_cmp).1
}

/// The run's median sample period.
pub fn median_period(t: &[f64]) -> f64 {
    median(t.windows(2).map(|w| w[1] - w[0]).collect())
}

/// Index ranges [a, b) of the stretches between gaps (intervals longer than `GAP_PERIODS` median
/// periods).
pub fn stretches(t: &[f64]) -> Vec<(usize, usize)> {
    let dt = median_period(t);
    let mut out = Vec::new();
    let mut a = 0;
    for k in 1..t.len() {
        if t[k] - t[k - 1] > GAP_PERIODS * dt {
            out.push((a, k));
            a = k;
        }
    }
    out.push((a, t.len()));
    out
}

/// The uniform grid a + b·k nearest `t` in least squares, when `t` is uneven but stays within half a
/// period of that grid (a logger's timestamps jittering around its clock, not drifting or gapped).
pub fn nearest_grid(t: &[f64]) -> Option<Vec<f64>> {
    let n = t.len();
    if n < 3 || crate::calibrate::signal::is_even_grid(t) {
        return None;
    }
    let nf = n as f64;
    let (mk, mt) = ((nf - 1.0) / 2.0, t.iter().sum::<f64>() / nf);
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (k, &tk) in t.iter().enumerate() {
        let dk = k as f64 - mk;
        sxy += dk * (tk - mt);
        sxx += dk * dk;
    }
    let b = sxy / sxx;
    let a = mt - b * mk;
    let grid: Vec<f64> = (0..n).map(|k| a + b * k as f64).collect();
    let worst = t.iter().zip(&grid).map(|(x, g)| (x - g).abs()).fold(0.0, f64::max);
    (b > 0.0 && worst < 0.5 * b).then_some(grid)
}

/// How rough the columns look on the time base `t`: the sum over columns of the mean deviation
/// from the line through each sample's neighbours (the mean, not the median, which an encoder's
/// steps pin to 0 or one count). On the wrong time base a moving signal gains speed × timing error.
pub fn roughness(t: &[f64], columns: &[&[f64]]) -> f64 {
    columns
        .iter()
        .map(|x| {
            let n = x.len().saturating_sub(2).max(1) as f64;
            (1..x.len().saturating_sub(1)).map(|k| deviation(t, x, k).abs()).sum::<f64>() / n
        })
        .sum()
}

/// A grid is taken over the logged times when the positions are smoother on it: whichever time
/// base is wrong adds speed × timing error to the roughness, and where the noise hides that, either
/// is as good.
pub const GRID_PREFERENCE: f64 = 1.0;

/// x[k] minus the straight line through its neighbours at t[k]: the local deviation, on any grid.
fn deviation(t: &[f64], x: &[f64], k: usize) -> f64 {
    let (h1, h2) = (t[k] - t[k - 1], t[k + 1] - t[k]);
    x[k] - (x[k - 1] * h2 + x[k + 1] * h1) / (h1 + h2)
}

/// Spikes and (on an angle) encoder wraps in one column, stretch by stretch (never across a gap).
/// Where a stretch's times jitter around a clock (`nearest_grid`), a sample is corrupt only when it
/// is so on both time bases: a logger that samples on its clock and stamps late or early moves a
/// fast sample off the line through its neighbours by speed × timing error, which the clock's
/// times do not (fresh drive rigs 109, 161 and 191, jitter 11–19 %: samples on the straight line
/// through their neighbours' values were refused as spikes).
pub fn find_corrupt(t: &[f64], x: &[f64], q: Quantity) -> Vec<Finding> {
    let mut out = Vec::new();
    for (a, b) in stretches(t) {
        if b - a >= 9 {
            let mut found = Vec::new();
            find_in_stretch(&t[a..b], &x[a..b], q, a, &mut found);
            if let (false, Some(grid)) = (found.is_empty(), nearest_grid(&t[a..b])) {
                let mut on_grid = Vec::new();
                find_in_stretch(&grid, &x[a..b], q, a, &mut on_grid);
                found.retain(|f| on_grid.iter().any(|g| g.index == f.index && g.kind == f.kind));
            }
            out.extend(found);
        }
    }
    out.sort_by_key(|f| f.index);
    out
}

/// The noise scale of a column at each sample: its noise floor (robust, so a few corrupt samples do
/// not move it), the local curvature's scale around the sample (from samples a corrupt one does not
/// touch) and its resolution (the smallest step it takes).
fn noise_scales(t: &[f64], x: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let n = x.len();
    let e: Vec<f64> = (0..n).map(|k| if k == 0 || k == n - 1 { 0.0 } else { deviation(t, x, k) }).collect();
    let floor = 1.4826 * median(e[1..n - 1].iter().map(|v| v.abs()).collect());
    let resolution = super::signal::resolution(x);
    let scale = (0..n)
        .map(|k| {
            let around: Vec<f64> = [k.wrapping_sub(4), k.wrapping_sub(3), k.wrapping_sub(2), k + 2, k + 3, k + 4]
                .into_iter()
                .filter(|&j| j >= 1 && j < n - 1)
                .map(|j| e[j].abs())
                .collect();
            floor + median(around) + resolution
        })
        .collect();
    (e, scale)
}

fn find_in_stretch(t: &[f64], x: &[f64], q: Quantity, offset: usize, out: &mut Vec<Finding>) {
    let n = x.len();
    // Pass 1, spikes: an isolated spike of A deviates by A at k and by about −A/2 at each neighbour.
    let (e, scale) = noise_scales(t, x);
    let mut y = x.to_vec();
    let mut k = 1;
    while k + 1 < n {
        let s = scale[k];
        let half = -0.5 * e[k];
        let spike = e[k].abs() > OUTLIER_FACTOR * s
            && (e[k - 1] - half).abs() < 0.25 * e[k].abs() + s
            && (e[k + 1] - half).abs() < 0.25 * e[k].abs() + s;
        if spike {
            let (h1, h2) = (t[k] - t[k - 1], t[k + 1] - t[k]);
            y[k] = (x[k - 1] * h2 + x[k + 1] * h1) / (h1 + h2);
            out.push(Finding { index: offset + k, kind: FindingKind::Spike, value: x[k], repaired: y[k] });
            k += 2;
        } else {
            k += 1;
        }
    }
    if q != Quantity::Angle {
        return;
    }
    // Pass 2, on the column with its spikes repaired: a jump of whole turns from k−1 to k, against
    // the speeds on either side.
    let (_, scale) = noise_scales(t, &y);
    for k in 2..n - 1 {
        let v_before = (y[k - 1] - y[k - 2]) / (t[k - 1] - t[k - 2]);
        let v_after = (y[k + 1] - y[k]) / (t[k + 1] - t[k]);
        let jump = (y[k] - y[k - 1]) - 0.5 * (v_before + v_after) * (t[k] - t[k - 1]);
        let turns = (jump / std::f64::consts::TAU).round();
        if turns != 0.0 && jump.abs() > std::f64::consts::PI {
            let rest = jump - turns * std::f64::consts::TAU;
            if rest.abs() < OUTLIER_FACTOR * scale[k] + 1e-6 * jump.abs() {
                out.push(Finding {
                    index: offset + k,
                    kind: FindingKind::EncoderWrap { turns: turns as i64 },
                    value: x[k],
                    repaired: y[k] - turns * std::f64::consts::TAU,
                });
            }
        }
    }
}

/// Applies the findings to `x`: every spike takes its neighbours' line, then every wrap shifts its
/// sample and every later one by its turns.
pub fn repair(x: &mut [f64], findings: &[Finding]) {
    for f in findings.iter().filter(|f| f.kind == FindingKind::Spike) {
        x[f.index] = f.repaired;
    }
    for f in findings {
        if let FindingKind::EncoderWrap { turns } = f.kind {
            let shift = turns as f64 * std::f64::consts::TAU;
            for v in &mut x[f.index..] {
                *v -= shift;
            }
        }
    }
}

/// The refusal for a column's findings: the first one by file, line and column, with the count.
pub fn refusal(path: &Path, lines: &[usize], column: (usize, &str), x: &[f64], found: &[Finding]) -> DataError {
    let f = &found[0];
    let k = f.index;
    let what = match f.kind {
        // the deviation itself, as the neighbours' values can agree with the spike's to every digit shown
        FindingKind::Spike => format!(
            "an isolated spike: {}, {} off the line through its neighbours ({} and {})",
            short(f.value),
            short(f.value - f.repaired),
            short(x[k - 1]),
            short(x[k + 1])
        ),
        FindingKind::EncoderWrap { turns } => format!(
            "an encoder wrap: the angle jumps by {turns} turn{} in one sample ({} → {}) while the motion goes on \
             either side",
            if turns.abs() == 1 { "" } else { "s" },
            short(x[k - 1]),
            short(f.value)
        ),
    };
    let more = match found.len() {
        1 => String::new(),
        n => format!(" ({} more in this column)", n - 1),
    };
    DataError {
        file: path.to_path_buf(),
        line: lines.get(k).copied(),
        column: Some((column.0, column.1.to_string())),
        message: format!(
            "{what}{more}; pass --repair-samples to replace spikes by their neighbours' line and unwrap wraps (the \
             report lists every repair)"
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform draws on [0, 1), seeded (a linear congruential generator's top 53 bits).
    fn uniforms(seed: u64) -> impl FnMut() -> f64 {
        let mut s = seed;
        move || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// A jittered sine with white noise, seeded.
    fn signal(n: usize, dt: f64, f: f64, noise: f64, jitter: f64, seed: u64) -> (Vec<f64>, Vec<f64>) {
        let mut u = uniforms(seed);
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt + jitter * dt * (2.0 * u() - 1.0)).collect();
        let x = t
            .iter()
            .map(|&tt| 0.5 * (std::f64::consts::TAU * f * tt).sin() + noise * (u() + u() + u() - 1.5))
            .collect();
        (t, x)
    }

    #[test]
    fn clean_signals_at_any_rate_frequency_noise_and_jitter_have_no_findings() {
        for (i, &(dt, f, noise, jitter)) in [
            (1e-3, 0.5, 1e-4, 0.0),
            (2e-4, 5.0, 1e-5, 0.2),
            (5e-3, 5.0, 1e-3, 0.2),
            (1e-3, 2.0, 0.0, 0.15),
            (5e-3, 0.2, 1e-5, 0.0),
        ]
        .iter()
        .enumerate()
        {
            let (t, x) = signal(4000, dt, f, noise, jitter, i as u64 + 1);
            let found = find_corrupt(&t, &x, Quantity::Angle);
            assert!(found.is_empty(), "case {i}: {found:?}");
        }
    }

    #[test]
    fn a_spike_and_a_wrap_are_found_where_they_are_and_repaired() {
        for (i, &(dt, f, noise, jitter)) in
            [(1e-3, 0.5, 1e-4, 0.0), (2e-4, 5.0, 1e-5, 0.2), (5e-3, 2.0, 1e-3, 0.1)].iter().enumerate()
        {
            let (t, clean) = signal(3000, dt, f, noise, jitter, 10 + i as u64);
            let mut x = clean.clone();
            x[700] += 0.3;
            for v in &mut x[2000..] {
                *v += std::f64::consts::TAU;
            }
            let found = find_corrupt(&t, &x, Quantity::Angle);
            assert_eq!(found.len(), 2, "case {i}: {found:?}");
            assert_eq!((found[0].index, found[0].kind), (700, FindingKind::Spike), "case {i}");
            assert_eq!((found[1].index, found[1].kind), (2000, FindingKind::EncoderWrap { turns: 1 }), "case {i}");
            repair(&mut x, &found);
            let worst = x.iter().zip(&clean).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
            assert!(worst < 10.0 * noise.max(1e-6) + 1e-3 * 0.5, "case {i}: repaired within the noise, worst {worst}");
            // a position on a linear axis has no wraps: the jump stays
            let mut y = clean.clone();
            for v in &mut y[2000..] {
                *v += std::f64::consts::TAU;
            }
            assert!(find_corrupt(&t, &y, Quantity::Position).is_empty(), "case {i}");
        }
    }

    /// A spike too small for the values' six digits to differ: the refusal names its size, which the
    /// values cannot show (a noise-free column once read "-0.112133 where its neighbours read
    /// -0.112133 and -0.112133").
    #[test]
    fn a_spike_below_the_digits_shown_is_refused_with_its_size() {
        // a noise-free 0.5 Hz sine at 10 kHz, the spike at its turn, where neighbours move by 5e-9
        let t: Vec<f64> = (0..20_000).map(|k| k as f64 * 1e-4).collect();
        let mut x: Vec<f64> = t.iter().map(|&t| -0.112133 + 0.1 * (std::f64::consts::PI * t).sin()).collect();
        x[5000] += 2e-7;
        let found = find_corrupt(&t, &x, Quantity::Angle);
        assert_eq!(found.len(), 1, "{found:?}");
        let lines: Vec<usize> = (0..20_000).map(|k| k + 3).collect();
        let message = refusal(Path::new("run.csv"), &lines, (2, "motor_angle_rad"), &x, &found).message;
        assert!(message.contains(", 2.0493e-7 off the line through its neighbours"), "{message}");
    }

    #[test]
    fn a_logger_that_samples_on_its_clock_and_stamps_with_jitter_has_no_spikes_but_a_real_one() {
        // fresh drive rig 191's shape: samples taken on a 400 Hz clock and stamped off it by up to 19 %
        // of the period, a servo at rest that sets off at 40 rad/s, an encoder of 1e-5 rad counts.
        // Stamped late, a sample on the move sits 40 rad/s × its timing error off its neighbours'
        // line on the logged times, in a spike's pattern; on the clock it sits on the line
        let (dt, n) = (2.5e-3, 400);
        let mut u = uniforms(191);
        let clock: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        // one stamp 19 % of a period late, on the move
        let mut t = clock.clone();
        t[370] += 0.19 * dt;
        let x: Vec<f64> = clock
            .iter()
            .map(|&c| {
                let position = 40.0 * (c - 0.85).max(0.0) + 1e-5 * (u() + u() + u() - 1.5);
                (position / 1e-5).round() * 1e-5
            })
            .collect();
        let on_logged_times = {
            let mut found = Vec::new();
            find_in_stretch(&t, &x, Quantity::Angle, 0, &mut found);
            found.len()
        };
        assert!(on_logged_times > 0, "the logged times alone make spikes of the timing errors");
        assert!(find_corrupt(&t, &x, Quantity::Angle).is_empty());
        let mut y = x.clone();
        y[300] += 0.5;
        let found = find_corrupt(&t, &y, Quantity::Angle);
        assert_eq!(found.iter().map(|f| (f.index, f.kind)).collect::<Vec<_>>(), vec![(300, FindingKind::Spike)]);
    }

    #[test]
    fn a_step_in_a_torque_log_is_no_spike_and_gaps_split_the_stretches() {
        let t: Vec<f64> = (0..1000).map(|k| k as f64 * 1e-3).collect();
        let x: Vec<f64> = t.iter().map(|&tt| if tt < 0.5 { 0.0 } else { 0.05 }).collect();
        assert!(find_corrupt(&t, &x, Quantity::Torque).is_empty());
        let mut t2 = t.clone();
        for v in &mut t2[400..] {
            *v += 0.25;
        }
        assert_eq!(stretches(&t2), vec![(0, 400), (400, 1000)]);
        assert_eq!(stretches(&t), vec![(0, 1000)]);
    }

    #[test]
    fn ranges_refuse_with_line_and_column() {
        let lines: Vec<usize> = (5..10).collect();
        let e =
            check_range(Path::new("r.csv"), &lines, (3, "link_angle_rad"), Quantity::Angle, &[0.0, 0.1, 1e300, 0.0])
                .unwrap_err();
        assert_eq!((e.line, e.column.clone()), (Some(7), Some((3, "link_angle_rad".into()))));
        assert!(e.message.contains("1.0000e300"), "{}", e.message);
        assert!(
            check_range(Path::new("r.csv"), &lines, (1, "temperature_c"), Quantity::TemperatureC, &[-300.0]).is_err()
        );
    }
}
