//! Measured runs in the data format of `docs/interfaces.md`: one CSV per run, `# key=value`
//! metadata lines before the header, required `time_s`, `motor_angle_rad`, `link_angle_rad`.
//! Every error names the file, the line and (for cells) the column.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// How a run was driven (`# drive=`, docs/interfaces.md "Runs from other rigs and drives").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DriveKind {
    /// The measured motor angle drives the model; the link angle is predicted.
    MotorAngle,
    /// The measured motor torque (force) drives the model; motor and link positions are predicted.
    MotorTorque,
    /// The reference is replayed through the rig's controller; the positions are predicted.
    Reference,
}

impl DriveKind {
    pub fn name(self) -> &'static str {
        match self {
            DriveKind::MotorAngle => "motor_angle",
            DriveKind::MotorTorque => "motor_torque",
            DriveKind::Reference => "reference",
        }
    }
}

/// `# axis=`: rotary (rad, N·m, kg·m²) or linear (m, N, kg).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Axis {
    Rotary,
    Linear,
}

impl Axis {
    /// (position, speed, torque, inertia, viscous) units as the reports print them.
    pub fn units(self) -> (&'static str, &'static str, &'static str, &'static str, &'static str) {
        match self {
            Axis::Rotary => ("rad", "rad/s", "N.m", "kg.m2", "N.m.s/rad"),
            Axis::Linear => ("m", "m/s", "N", "kg", "N.s/m"),
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Axis::Rotary => "rotary",
            Axis::Linear => "linear",
        }
    }
}

/// The rig's position controller (`drive=reference`), in the file's units:
/// τ = sat(kp (r − q) − kd q̇), applied every `period` s and held in between.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Controller {
    pub kp: f64,
    pub kd: f64,
    pub saturation: f64,
    pub period: f64,
}

/// One measured run, as read.
#[derive(Clone, Debug)]
pub struct Run {
    pub file: PathBuf,
    pub meta: BTreeMap<String, String>,
    pub time: Vec<f64>,
    pub motor: Vec<f64>,
    pub link: Vec<f64>,
    /// Housing thermocouple per sample, °C (constant when only the metadata gives it).
    pub temperature_c: Vec<f64>,
    /// Declared `frequency_hz`, else measured from the motor angle.
    pub frequency_hz: f64,
    pub frequency_declared: bool,
    pub link_inertia: Option<f64>,
    /// The inertia is a point mass m·l² from `link_mass_kg` and `link_length_m` (an estimate: a
    /// real link's own inertia adds to it).
    pub inertia_from_mass: bool,
    pub drive: DriveKind,
    pub axis: Axis,
    /// `# transmission=rigid`: motor and link one body; `link` then repeats `motor`.
    pub rigid: bool,
    /// False when the file has no link column (rigid drives).
    pub link_measured: bool,
    pub reference: Option<Vec<f64>>,
    /// Measured motor torque (force on a linear axis), when the file has it.
    pub motor_torque: Option<Vec<f64>>,
    /// External torque (force) on the link, when the file has it.
    pub load: Option<Vec<f64>>,
    pub controller: Option<Controller>,
    /// The file's line of each sample (for messages and the report).
    pub lines: Vec<usize>,
    /// Samples repaired on `--repair-samples` (spikes, encoder wraps), by line and column.
    pub repairs: Vec<super::quality::Repair>,
    /// Gaps in the file's time base; the run is split there into segments (`segment`).
    pub gaps: Vec<super::quality::Gap>,
    /// (this segment, of how many) when the file was split at its gaps; None for a whole file.
    pub segment: Option<(usize, usize)>,
    /// The file's thermocouple before this segment's first sample: every earlier sample, the dropped
    /// stretches' too. A PCL that lags its thermocouple carries its lag across a gap; a whole file,
    /// or the first stretch, has none.
    pub thermocouple_before: HousingHistory,
    /// What was done with an uneven time base, when it was uneven (for the report).
    pub time_base: Option<String>,
}

/// (time s, housing K) logged before a segment's first sample: a prefix of its file's log, which
/// every segment of the file shares. Empty for a whole file or its first stretch.
#[derive(Clone, Debug, Default)]
pub struct HousingHistory {
    log: Arc<[(f64, f64)]>,
    len: usize,
}

impl HousingHistory {
    /// The first `len` samples of `log`.
    pub fn prefix(log: &Arc<[(f64, f64)]>, len: usize) -> Self {
        HousingHistory { log: Arc::clone(log), len: len.min(log.len()) }
    }

    pub fn samples(&self) -> &[(f64, f64)] {
        &self.log[..self.len]
    }
}

impl From<Vec<(f64, f64)>> for HousingHistory {
    fn from(samples: Vec<(f64, f64)>) -> Self {
        let len = samples.len();
        HousingHistory { log: samples.into(), len }
    }
}

/// How runs are read.
#[derive(Clone, Copy, Debug, Default)]
pub struct ReadOptions {
    /// Repair isolated spikes and encoder wraps (listed in the report) instead of refusing them.
    pub repair_samples: bool,
    /// Files read at once (0 or 1: one at a time).
    pub threads: usize,
}

impl Run {
    /// The file's name, with the segment when the file was split at its gaps.
    pub fn name(&self) -> String {
        let file = self.file.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        match self.segment {
            Some((k, n)) => {
                format!("{file} (segment {k} of {n}, from line {})", self.lines.first().copied().unwrap_or(0))
            }
            None => file,
        }
    }

    /// A file-name-safe stem for this run's plots: the file's stem, `_segment_K` for a segment.
    pub fn plot_stem(&self) -> String {
        let stem = self.file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        match self.segment {
            Some((k, _)) => format!("{stem}_segment_{k}"),
            None => stem,
        }
    }

    /// Run temperature for reporting and grouping: mean of the thermocouple, °C.
    pub fn mean_temperature_c(&self) -> f64 {
        self.temperature_c.iter().sum::<f64>() / self.temperature_c.len() as f64
    }

    pub fn meta_f64(&self, key: &str) -> Option<f64> {
        self.meta.get(key).and_then(|v| v.trim().parse().ok())
    }
}

pub use thermovia_importer::table::DataError;

/// Expands folders into their `*.csv` files (sorted), keeps files as given.
pub fn expand_inputs(inputs: &[PathBuf]) -> Result<Vec<PathBuf>, DataError> {
    let mut out = Vec::new();
    for p in inputs {
        if p.is_dir() {
            let files = csv_files(p).map_err(|e| file_error(p, format!("cannot list the folder: {e}")))?;
            if files.is_empty() {
                // sub-folders are not searched (a folder is one rig's runs): say where runs are
                let mut below: Vec<String> = std::fs::read_dir(p)
                    .into_iter()
                    .flatten()
                    .filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|d| d.is_dir() && csv_files(d).is_ok_and(|f| !f.is_empty()))
                    .map(|d| d.display().to_string())
                    .collect();
                below.sort();
                let hint = if below.is_empty() {
                    String::new()
                } else {
                    format!(" (sub-folders are not searched; these hold runs: {})", below.join(", "))
                };
                return Err(file_error(p, format!("the folder holds no .csv run files{hint}")));
            }
            out.extend(files);
        } else {
            out.push(p.clone());
        }
    }
    // the same run twice would count its samples twice: every uncertainty too small
    let mut seen = std::collections::HashMap::new();
    for f in &out {
        let key = std::fs::canonicalize(f).unwrap_or_else(|_| f.clone());
        if let Some(first) = seen.insert(key, f.clone()) {
            return Err(file_error(
                f,
                format!("this run is named twice (also as {}): its samples would count twice", first.display()),
            ));
        }
    }
    if out.is_empty() {
        return Err(DataError {
            file: PathBuf::from("(command line)"),
            line: None,
            column: None,
            message: "no run files given: name run files or folders of them (or use --paper)".into(),
        });
    }
    Ok(out)
}

/// The `.csv` files directly in `dir`, sorted.
fn csv_files(dir: &Path) -> std::io::Result<Vec<PathBuf>> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|f| f.extension().is_some_and(|x| x.eq_ignore_ascii_case("csv")))
        .collect();
    files.sort();
    Ok(files)
}

fn file_error(file: &Path, message: String) -> DataError {
    DataError::file(file, message)
}

pub fn read_run(path: &Path) -> Result<Run, DataError> {
    read_run_with(path, ReadOptions::default())
}

pub fn read_run_with(path: &Path, options: ReadOptions) -> Result<Run, DataError> {
    let text = std::fs::read_to_string(path).map_err(|e| file_error(path, format!("cannot read: {e}")))?;
    parse_run_with(path, &text, options)
}

/// Line (1-based) of the `# key=` metadata line, for errors.
fn meta_line(text: &str, key: &str) -> Option<usize> {
    for (i, l) in text.lines().enumerate() {
        let t = l.trim_start();
        if !t.starts_with('#') {
            if t.is_empty() {
                continue;
            }
            return None;
        }
        if let Some((k, _)) = t.trim_start_matches('#').trim().split_once('=') {
            if k.trim() == key {
                return Some(i + 1);
            }
        }
    }
    None
}

fn meta_error(path: &Path, text: &str, key: &str, message: String) -> DataError {
    match meta_line(text, key) {
        Some(l) => DataError::line(path, l, message),
        None => file_error(path, message),
    }
}

/// Parses one run from its text (`path` only names it in errors), refusing corrupt samples.
pub fn parse_run(path: &Path, text: &str) -> Result<Run, DataError> {
    parse_run_with(path, text, ReadOptions::default())
}

/// Parses one run from its text (`path` only names it in errors).
pub fn parse_run_with(path: &Path, text: &str, options: ReadOptions) -> Result<Run, DataError> {
    // a byte-order mark (Windows tools write one) is not part of the first line's text
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    // the metadata decides which columns the file must have: read it first (with the header's names)
    let head_table = thermovia_importer::table::parse(path, text, thermovia_importer::table::Columns::Named(&[])).ok();
    let head = head_table.as_ref().map(|t| t.meta.clone()).unwrap_or_default();
    let word = |key: &str, allowed: &[&str], default: &str| -> Result<String, DataError> {
        match head.get(key) {
            None => Ok(default.to_string()),
            Some(v) if allowed.contains(&v.as_str()) => Ok(v.clone()),
            Some(v) => {
                Err(meta_error(path, text, key, format!("metadata {key}={v:?} is not one of {}", allowed.join(", "))))
            }
        }
    };
    let drive = match word("drive", &["motor_angle", "motor_torque", "reference"], "motor_angle")?.as_str() {
        "motor_torque" => DriveKind::MotorTorque,
        "reference" => DriveKind::Reference,
        _ => DriveKind::MotorAngle,
    };
    let axis = if word("axis", &["rotary", "linear"], "rotary")? == "linear" { Axis::Linear } else { Axis::Rotary };
    let rigid = word("transmission", &["compliant", "rigid"], "compliant")? == "rigid";
    if rigid && drive == DriveKind::MotorAngle {
        return Err(meta_error(
            path,
            text,
            "transmission",
            "transmission=rigid with drive=motor_angle leaves nothing to predict (the measured motor angle is the \
             whole motion); declare `# drive=motor_torque` or `# drive=reference`"
                .into(),
        ));
    }
    let (pos, torque_col, link_col, ref_col, load_col) = match axis {
        Axis::Rotary => {
            ("motor_angle_rad", "motor_torque_nm", "link_angle_rad", "reference_angle_rad", "load_torque_nm")
        }
        Axis::Linear => {
            ("motor_position_m", "motor_force_n", "link_position_m", "reference_position_m", "load_force_n")
        }
    };
    let columns: [(&str, bool); 7] = [
        ("time_s", true),
        (pos, true),
        (link_col, !rigid),
        ("temperature_c", false),
        (ref_col, drive == DriveKind::Reference),
        (torque_col, drive == DriveKind::MotorTorque),
        (load_col, false),
    ];
    let table = thermovia_importer::table::parse(path, text, thermovia_importer::table::Columns::Named(&columns))
        .map_err(|mut e| {
            if e.message.starts_with("missing required column") {
                let declared = format!(
                    " (axis={}, drive={}, transmission={})",
                    axis.name(),
                    drive.name(),
                    if rigid { "rigid" } else { "compliant" }
                );
                let known: Vec<&str> = columns.iter().map(|c| c.0).chain(["heater_power_w"]).collect();
                let header = head_table.as_ref().map_or(&[][..], |h| &h.names[..]);
                if let Some((c, cell, wanted)) = misspelled_column(header, &columns, &known) {
                    // point at the header cell that is most likely the missing column, mistyped
                    e.column = Some((c + 1, cell.clone()));
                    e.message = format!(
                        "missing required column {wanted:?} (did you mean {wanted} for {cell:?}? header has: {}){declared}",
                        header.join(", ")
                    );
                } else {
                    e.message += &declared;
                }
            }
            e
        })?;
    let (meta, last_line) = (table.meta, table.last_line);
    let lines = table.row_lines;
    let mut repairs = Vec::new();
    let mut table_columns = table.columns;
    {
        use super::quality::{check_range, check_speed, find_corrupt, refusal, repair, Quantity, Repair};
        let position = if axis == Axis::Rotary { Quantity::Angle } else { Quantity::Position };
        let kinds = [
            None,
            Some(position),
            Some(position),
            Some(Quantity::TemperatureC),
            Some(position),
            Some(Quantity::Torque),
            Some(Quantity::Torque),
        ];
        let time = table_columns[0].clone().unwrap_or_default();
        for (slot, kind) in kinds.iter().enumerate() {
            let (Some(q), Some(at)) = (kind, table.positions[slot]) else { continue };
            let name = columns[slot].0;
            let x = table_columns[slot].as_mut().expect("a present column");
            check_range(path, &lines, (at + 1, name), *q, x)?;
            // measured positions and temperatures; commands (reference) and torques may step
            if !matches!(slot, 1..=3) || time.len() < 9 {
                continue;
            }
            let found = find_corrupt(&time, x, *q);
            if !found.is_empty() {
                if !options.repair_samples {
                    return Err(refusal(path, &lines, (at + 1, name), x, &found));
                }
                repairs.extend(found.iter().map(|f| Repair {
                    line: lines[f.index],
                    column: name.to_string(),
                    kind: f.kind,
                    value: f.value,
                    replaced_by: f.repaired,
                }));
                repair(x, &found);
            }
            if slot != 3 {
                check_speed(path, &lines, (at + 1, name), &time, x)?;
            }
        }
    }
    let has_temperature_column = table_columns[3].is_some();
    let link_measured = table_columns[2].is_some();
    let mut cols: Vec<Option<Vec<f64>>> = table_columns;
    let n = cols[0].as_ref().map_or(0, Vec::len);
    if n < 3 {
        return Err(DataError::line(path, last_line, format!("only {n} data rows; a run needs at least 3")));
    }
    // the metadata's temperature groups the runs even beside a column: it gets the column's range
    let meta_temperature = match meta.get("temperature_c") {
        None => None,
        Some(v) => {
            let t: f64 = v.parse().ok().filter(|t: &f64| t.is_finite()).ok_or_else(|| {
                meta_error(path, text, "temperature_c", format!("metadata temperature_c={v:?} is not a number"))
            })?;
            let (lo, hi) = super::quality::TEMPERATURE_RANGE_C;
            if !(lo..=hi).contains(&t) {
                return Err(meta_error(
                    path,
                    text,
                    "temperature_c",
                    format!("metadata temperature_c={v} is a temperature outside 1 K … 1e4 K"),
                ));
            }
            Some(t)
        }
    };
    let temperature_c = if has_temperature_column {
        cols[3].take().unwrap_or_default()
    } else if let Some(t) = meta_temperature {
        vec![t; n]
    } else if rigid {
        // a rigid drive has no PCL: the temperature only labels the run
        vec![22.0; n]
    } else {
        let mut e = file_error(
            path,
            "the run has no temperature: neither a temperature_c column nor `# temperature_c=` metadata".into(),
        );
        let header = head_table.as_ref().map_or(&[][..], |h| &h.names[..]);
        let known: Vec<&str> = columns.iter().map(|c| c.0).chain(["heater_power_w"]).collect();
        if let Some((c, cell, _)) = misspelled_column(header, &[("temperature_c", true)], &known) {
            e.line = head_table.as_ref().map(|h| h.header_line);
            e.column = Some((c + 1, cell.clone()));
            e.message += &format!(" (did you mean temperature_c for {cell:?}?)");
        }
        return Err(e);
    };
    let time = cols[0].take().unwrap_or_default();
    let gaps = gaps_of(&lines, &time);
    let motor = cols[1].take().unwrap_or_default();
    let link = cols[2].take().unwrap_or_else(|| motor.clone());
    let mut run = Run {
        file: path.to_path_buf(),
        time,
        motor,
        link,
        temperature_c,
        frequency_hz: 0.0,
        frequency_declared: false,
        link_inertia: None,
        inertia_from_mass: false,
        drive,
        axis,
        rigid,
        link_measured,
        reference: cols[4].take(),
        motor_torque: cols[5].take(),
        load: cols[6].take(),
        controller: None,
        meta,
        gaps,
        lines,
        repairs,
        segment: None,
        thermocouple_before: HousingHistory::default(),
        time_base: None,
    };
    let inertia_key = match axis {
        Axis::Rotary => "link_inertia_kgm2",
        Axis::Linear => "inertia_kg",
    };
    // positive, and physical: an inertia within the FMU's range, a mass or length within its input
    // ranges' ±1e6, an amplitude within the positions', a frequency below half the sample rate (the log
    // cannot carry more). Each key: (least, what it is) where more than positive is asked, (most, what).
    let nyquist = 0.5 / super::quality::median_period(&run.time).max(f64::MIN_POSITIVE);
    let half_rate = format!("half the sample rate ({} Hz)", thermovia_importer::table::compact(nyquist));
    let inertia_least = (INERTIA_RANGE.0, "1e-9 (the FMU's smallest inertia or mass)");
    for (key, least, most, what) in [
        ("frequency_hz", None, nyquist, half_rate.as_str()),
        (inertia_key, Some(inertia_least), INERTIA_RANGE.1, "1e3 (the FMU's largest inertia or mass)"),
        ("link_mass_kg", None, 1e6, "1e6"),
        ("link_length_m", None, 1e6, "1e6"),
        ("motor_amplitude_rad", None, 1e6, "1e6"),
    ] {
        let Some(v) = run.meta.get(key) else { continue };
        let x = match v.parse::<f64>() {
            Ok(x) if x.is_finite() && x > 0.0 => x,
            _ => return Err(meta_error(path, text, key, format!("metadata {key}={v:?} is not a positive number"))),
        };
        let beyond = match least {
            Some((lo, lo_what)) if x < lo => Some(format!("below {lo_what}")),
            _ if x > most => Some(format!("above {what}")),
            _ => None,
        };
        if let Some(beyond) = beyond {
            let shown = thermovia_importer::table::compact(x);
            return Err(meta_error(
                path,
                text,
                key,
                format!("metadata {key}={shown} is {beyond}: a typo or a unit slip, not this rig"),
            ));
        }
    }
    if axis == Axis::Linear && run.meta.contains_key("link_inertia_kgm2") {
        return Err(meta_error(
            path,
            text,
            "link_inertia_kgm2",
            "link_inertia_kgm2 on a linear axis: declare the moving mass as `# inertia_kg=`".into(),
        ));
    }
    run.link_inertia = run.meta_f64(inertia_key);
    if run.meta.contains_key("link_mass_kg") {
        // a declared mass is used, never silently dropped: with the centre-of-mass distance it is
        // a point-mass inertia m·l² when no inertia is declared (the gravity effect uses l too)
        if axis == Axis::Linear {
            return Err(meta_error(
                path,
                text,
                "link_mass_kg",
                "link_mass_kg on a linear axis: declare the moving mass as `# inertia_kg=`".into(),
            ));
        }
        match (run.link_inertia, run.meta_f64("link_length_m")) {
            (Some(_), _) => {}
            (None, Some(l)) => {
                run.link_inertia = Some(run.meta_f64("link_mass_kg").unwrap_or(0.0) * l * l);
                run.inertia_from_mass = true;
            }
            (None, None) => return Err(meta_error(
                path,
                text,
                "link_mass_kg",
                "link_mass_kg without link_length_m: the mass becomes an inertia m·l² only with the centre-of-mass \
                     distance (`# link_length_m=`); or declare `# link_inertia_kgm2=`"
                    .into(),
            )),
        }
    }
    if drive == DriveKind::Reference {
        let get = |key: &str, what: &str| -> Result<f64, DataError> {
            match run.meta.get(key) {
                None => Err(file_error(
                    path,
                    format!("drive=reference needs the controller: missing `# {key}=` ({what}, in the file's units)"),
                )),
                Some(v) => v.parse::<f64>().ok().filter(|x| x.is_finite() && *x > 0.0).ok_or_else(|| {
                    meta_error(path, text, key, format!("metadata {key}={v:?} is not a positive number ({what})"))
                }),
            }
        };
        let controller = Controller {
            kp: get("controller_kp", "torque or force per position error")?,
            kd: get("controller_kd", "torque or force per velocity")?,
            saturation: get("controller_saturation", "largest torque or force")?,
            period: get("controller_period_s", "controller period, s")?,
        };
        // the controller acts once per sample: the log must be at its period (the median interval,
        // which gaps do not move), to within 1e-3 or what a logger's jitter leaves of the median
        // (three of its standard errors: 1.2533 × 1.4826 MAD / √n)
        let mean_dt = super::quality::median_period(&run.time);
        let intervals: Vec<f64> = run.time.windows(2).map(|w| w[1] - w[0]).collect();
        let mad = super::quality::median(intervals.iter().map(|d| (d - mean_dt).abs()).collect());
        let jitter_tolerance = 3.0 * 1.2533 * 1.4826 * mad / (intervals.len().max(1) as f64).sqrt();
        if (mean_dt - controller.period).abs() > (1e-3 * controller.period).max(jitter_tolerance) {
            return Err(meta_error(
                path,
                text,
                "controller_period_s",
                format!(
                    "controller_period_s={} but the samples are {mean_dt:.6} s apart (median): drive=reference \
                     replays one controller update per sample",
                    thermovia_importer::table::compact(controller.period)
                ),
            ));
        }
        run.controller = Some(controller);
    }
    // the transmission and every effect show only while something moves: a still run supports no fit
    let still = |x: &[f64]| {
        let (lo, hi) = x.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
        hi - lo <= 1e-12 * lo.abs().max(hi.abs()).max(1.0)
    };
    if still(&run.motor) && still(&run.link) {
        return Err(file_error(
            path,
            format!(
                "the run does not move: every position column is constant over its {n} samples (at {} {}); a fit \
                 needs motion, since the transmission and every effect show only while something moves",
                super::quality::short(run.motor[0]),
                run.axis.units().0
            ),
        ));
    }
    if run.rigid || drive != DriveKind::MotorAngle {
        // no harmonic excitation to measure; the PCL's hysteretic damping reads it (compliant only)
        run.frequency_hz = run.meta_f64("frequency_hz").unwrap_or(0.5);
        run.frequency_declared = run.meta.contains_key("frequency_hz");
        if !run.rigid && !run.frequency_declared {
            if let Some(f) = dominant_frequency(&run.time, &run.motor) {
                run.frequency_hz = f;
            }
        }
        return Ok(run);
    }
    match run.meta_f64("frequency_hz") {
        Some(f) => {
            run.frequency_hz = f;
            run.frequency_declared = true;
        }
        None => {
            run.frequency_hz = dominant_frequency(&run.time, &run.motor).ok_or_else(|| {
                file_error(
                    path,
                    "cannot measure the excitation frequency from the motor angle (declare `# frequency_hz=`)".into(),
                )
            })?
        }
    }
    if run.frequency_hz < LOWEST_FREQUENCY_HZ {
        let what = format!(
            "the excitation frequency {} Hz ({}) is below the FMU's 1e-3 Hz: are the times in seconds? (the run \
             spans {} s)",
            super::quality::short(run.frequency_hz),
            if run.frequency_declared { "declared" } else { "measured from the motor angle" },
            super::quality::short(run.time[run.time.len() - 1] - run.time[0])
        );
        return Err(if run.frequency_declared {
            meta_error(path, text, "frequency_hz", what)
        } else {
            file_error(path, what)
        });
    }
    Ok(run)
}

/// The FMU's lowest `excitation_frequency` (its hysteretic law's C = K''/ω grows without bound as
/// ω falls): a slower run is refused as it is read, not by the FMU in the middle of a fit.
const LOWEST_FREQUENCY_HZ: f64 = 1e-3;

/// The first required column missing from `header` and the header cell closest to its name (by
/// the importer's did-you-mean, the one `thermovia simulate` uses for variable names), among the
/// cells that are no known column: (0-based position, cell, the column it should be).
fn misspelled_column<'a>(
    header: &'a [String],
    columns: &[(&'a str, bool)],
    known: &[&str],
) -> Option<(usize, &'a String, &'a str)> {
    let (wanted, _) = columns.iter().find(|(name, required)| *required && !header.iter().any(|h| h == name))?;
    let unknown = header.iter().filter(|h| !known.contains(&h.as_str())).map(String::as_str);
    let best = thermovia_importer::model_description::did_you_mean(wanted, unknown).into_iter().next()?;
    let c = header.iter().position(|h| *h == best)?;
    Some((c, &header[c], wanted))
}

/// Frequency of the largest spectral peak of `x(t)` (mean removed) between 1/T and 50 Hz: a coarse
/// grid of the DFT magnitude, then golden-section refinement on the best cell.
pub fn dominant_frequency(t: &[f64], x: &[f64]) -> Option<f64> {
    let n = t.len();
    let span = t[n - 1] - t[0];
    if span <= 0.0 {
        return None;
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    // variance explained by a least-squares sinusoid at f (exact for a pure sinusoid, unlike
    // the DFT magnitude, whose peak leaks toward the negative-frequency image on short records)
    let power_every = |f: f64, stride: usize| {
        let w = 2.0 * std::f64::consts::PI * f;
        let (mut sc, mut ss, mut scc, mut sss, mut scs, mut syc, mut sys, mut m) =
            (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
        for i in (0..n).step_by(stride) {
            let (si, ci) = (w * t[i]).sin_cos();
            let y = x[i] - mean;
            sc += ci;
            ss += si;
            scc += ci * ci;
            sss += si * si;
            scs += ci * si;
            syc += y * ci;
            sys += y * si;
            m += 1.0;
        }
        let (a, b, c) = (scc - sc * sc / m, sss - ss * ss / m, scs - sc * ss / m);
        let det = a * b - c * c;
        if det <= 1e-12 * (a * b).max(1e-300) {
            return 0.0;
        }
        (b * syc * syc - 2.0 * c * syc * sys + a * sys * sys) / det
    };
    let power = |f: f64| power_every(f, 1);
    // coarse grid on at most ~2000 samples (enough below 20 Hz), refined on all of them
    let stride = (n / 2000).max(1);
    let df = 0.25 / span;
    let f_lo = 1.0 / span;
    let f_hi = 20.0f64.min(0.25 * (n / stride) as f64 / span);
    let mut best = (0.0, f64::NEG_INFINITY);
    let mut f = f_lo;
    while f <= f_hi {
        let p = power_every(f, stride);
        if p > best.1 {
            best = (f, p);
        }
        f += df;
    }
    if !(best.1 > 0.0) {
        return None;
    }
    let (mut a, mut b) = (best.0 - df, best.0 + df);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..30 {
        let c = b - g * (b - a);
        let d = a + g * (b - a);
        if power(c) > power(d) {
            b = d
        } else {
            a = c
        }
    }
    Some(0.5 * (a + b))
}

/// The FMU's `link_inertia` range (kg·m², or kg on a linear axis): a declared inertia outside it is
/// refused as the file is read, before the FMU would refuse it mid-fit.
const INERTIA_RANGE: (f64, f64) = (1e-9, 1e3);

/// Reads every input, refusing corrupt samples; the first error stops everything.
pub fn read_inputs(inputs: &[PathBuf]) -> Result<Vec<Run>, DataError> {
    read_inputs_with(inputs, ReadOptions::default())
}

/// Reads every input, `options.threads` files at once; the first error in the files' order is the
/// answer (the one a reading in turn meets), and no file after a failed one is read. A file with
/// gaps in its time base becomes one run per segment between them (docs/interfaces.md, "Data
/// quality").
pub fn read_inputs_with(inputs: &[PathBuf], options: ReadOptions) -> Result<Vec<Run>, DataError> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let files: Vec<(usize, PathBuf)> = expand_inputs(inputs)?.into_iter().enumerate().collect();
    let first_failed = AtomicUsize::new(usize::MAX);
    let read = super::parallel::map(options.threads, &files, |(i, f)| {
        // (a file after one that failed is never needed: the loop below returns before it)
        if *i > first_failed.load(Ordering::Relaxed) {
            return Ok(Vec::new());
        }
        let segments = read_segments(f, options);
        if segments.is_err() {
            first_failed.fetch_min(*i, Ordering::Relaxed);
        }
        segments
    });
    let mut runs = Vec::new();
    for segments in read {
        runs.extend(segments?);
    }
    Ok(runs)
}

/// One file's runs: one per stretch between its gaps, each on its time base.
fn read_segments(f: &Path, options: ReadOptions) -> Result<Vec<Run>, DataError> {
    let run = read_run_with(f, options)?;
    let longest = super::quality::stretches(&run.time).iter().map(|(a, b)| b - a).max().unwrap_or(0);
    let segments = split_at_gaps(run);
    if segments.is_empty() {
        return Err(file_error(
            f,
            format!(
                "no segment to fit: gaps (intervals over {} median sample periods) cut the run into stretches \
                 of at most {longest} samples, and a segment needs {}",
                super::quality::GAP_PERIODS,
                super::quality::MIN_SEGMENT_SAMPLES
            ),
        ));
    }
    Ok(segments.into_iter().map(choose_time_base).collect())
}

/// An uneven time base is either a logger's timestamps jittering around a uniform clock (the
/// samples were taken on the clock, the stamps are off) or samples really taken unevenly (the stamps
/// are right). The positions tell which: on the wrong time base a moving signal gains speed × timing
/// error. The uniform grid nearest the stamps replaces them when the positions are smoother
/// on it (`quality::GRID_PREFERENCE`); otherwise the stamps stay, and smoothing and derivatives work
/// on the uneven grid.
pub fn choose_time_base(mut run: Run) -> Run {
    let Some(grid) = super::quality::nearest_grid(&run.time) else { return run };
    let columns: Vec<&[f64]> = if run.link_measured { vec![&run.motor, &run.link] } else { vec![&run.motor] };
    let (on_stamps, on_grid) =
        (super::quality::roughness(&run.time, &columns), super::quality::roughness(&grid, &columns));
    let spread = run.time.iter().zip(&grid).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    let period = (grid[grid.len() - 1] - grid[0]) / (grid.len() - 1) as f64;
    if on_grid < super::quality::GRID_PREFERENCE * on_stamps {
        run.time_base = Some(format!(
            "the timestamps jitter by up to {:.1} % of the {} s period around a uniform clock, and the positions \
             are smoother on the clock (roughness {} vs {}): the clock's times are used",
            100.0 * spread / period,
            super::quality::short(period),
            super::quality::short(on_grid),
            super::quality::short(on_stamps)
        ));
        run.time = grid;
    } else {
        run.time_base = Some(format!(
            "uneven sampling (up to {:.1} % of the {} s mean period off a uniform clock; the positions are not \
             smoother on the clock: roughness {} vs {}): the logged times are used, with smoothing and \
             derivatives on the uneven grid",
            100.0 * spread / period,
            super::quality::short(period),
            super::quality::short(on_grid),
            super::quality::short(on_stamps)
        ));
    }
    run
}

/// The gaps of a time base (intervals longer than `quality::GAP_PERIODS` median periods).
fn gaps_of(lines: &[usize], t: &[f64]) -> Vec<super::quality::Gap> {
    let s = super::quality::stretches(t);
    s.iter().skip(1).map(|&(a, _)| super::quality::Gap { line: lines[a], from_s: t[a - 1], to_s: t[a] }).collect()
}

/// One run per stretch between gaps, each started from its own first samples (the measured state
/// after the gap), never bridged by interpolation across it. Stretches shorter than
/// `quality::MIN_SEGMENT_SAMPLES` are dropped (the run's `gaps` still list every gap).
pub fn split_at_gaps(mut run: Run) -> Vec<Run> {
    if run.gaps.is_empty() {
        return vec![run];
    }
    let kept: Vec<(usize, usize)> = super::quality::stretches(&run.time)
        .into_iter()
        .filter(|(a, b)| b - a >= super::quality::MIN_SEGMENT_SAMPLES)
        .collect();
    let n = kept.len();
    // the samples move out, so that each segment copies its own stretch and the file's metadata,
    // not the whole file; the thermocouple's history is one copy that every segment shares
    let time = std::mem::take(&mut run.time);
    let motor = std::mem::take(&mut run.motor);
    let link = std::mem::take(&mut run.link);
    let temperature_c = std::mem::take(&mut run.temperature_c);
    let reference = run.reference.take();
    let motor_torque = run.motor_torque.take();
    let load = run.load.take();
    let lines = std::mem::take(&mut run.lines);
    let housing: Arc<[(f64, f64)]> =
        time.iter().zip(&temperature_c).map(|(&t, &c)| (t, c + crate::report::ZERO_CELSIUS)).collect();
    let cut = |x: &[f64], a: usize, b: usize| x[a..b].to_vec();
    kept.iter()
        .enumerate()
        .map(|(i, &(a, b))| Run {
            time: cut(&time, a, b),
            motor: cut(&motor, a, b),
            link: cut(&link, a, b),
            temperature_c: cut(&temperature_c, a, b),
            reference: reference.as_ref().map(|x| cut(x, a, b)),
            motor_torque: motor_torque.as_ref().map(|x| cut(x, a, b)),
            load: load.as_ref().map(|x| cut(x, a, b)),
            lines: lines[a..b].to_vec(),
            segment: Some((i + 1, n)),
            thermocouple_before: HousingHistory::prefix(&housing, a),
            ..run.clone()
        })
        .collect()
}
