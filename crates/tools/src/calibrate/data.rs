//! Measured runs in the data format of `docs/interfaces.md`: one CSV per run, `# key=value`
//! metadata lines before the header, required `time_s`, `motor_angle_rad`, `link_angle_rad`.
//! Every error names the file, the line and (for cells) the column.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

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
}

impl Run {
    pub fn name(&self) -> String {
        self.file.file_name().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()
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
            let mut files: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| file_error(p, format!("cannot list the folder: {e}")))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| f.extension().is_some_and(|x| x.eq_ignore_ascii_case("csv")))
                .collect();
            files.sort();
            if files.is_empty() {
                return Err(file_error(p, "the folder holds no .csv run files".into()));
            }
            out.extend(files);
        } else {
            out.push(p.clone());
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

fn file_error(file: &Path, message: String) -> DataError {
    DataError::file(file, message)
}

pub fn read_run(path: &Path) -> Result<Run, DataError> {
    let text = std::fs::read_to_string(path).map_err(|e| file_error(path, format!("cannot read: {e}")))?;
    parse_run(path, &text)
}

/// Parses one run from its text (`path` only names it in errors).
pub fn parse_run(path: &Path, text: &str) -> Result<Run, DataError> {
    const COLUMNS: [(&str, bool); 4] =
        [("time_s", true), ("motor_angle_rad", true), ("link_angle_rad", true), ("temperature_c", false)];
    let table = thermovia_importer::table::parse(path, text, thermovia_importer::table::Columns::Named(&COLUMNS))?;
    let (meta, last_line) = (table.meta, table.last_line);
    let has_temperature_column = table.columns[3].is_some();
    let mut cols: Vec<Vec<f64>> = table.columns.into_iter().map(Option::unwrap_or_default).collect();
    let n = cols[0].len();
    if n < 3 {
        return Err(DataError::line(path, last_line, format!("only {n} data rows; a run needs at least 3")));
    }
    let temperature_c = if has_temperature_column {
        std::mem::take(&mut cols[3])
    } else if let Some(v) = meta.get("temperature_c") {
        let t: f64 = v
            .parse()
            .ok()
            .filter(|t: &f64| t.is_finite())
            .ok_or_else(|| file_error(path, format!("metadata temperature_c={v:?} is not a number")))?;
        vec![t; n]
    } else {
        return Err(file_error(
            path,
            "the run has no temperature: neither a temperature_c column nor `# temperature_c=` metadata".into(),
        ));
    };
    let mut run = Run {
        file: path.to_path_buf(),
        time: std::mem::take(&mut cols[0]),
        motor: std::mem::take(&mut cols[1]),
        link: std::mem::take(&mut cols[2]),
        temperature_c,
        frequency_hz: 0.0,
        frequency_declared: false,
        link_inertia: None,
        meta,
    };
    for key in ["frequency_hz", "link_inertia_kgm2", "link_mass_kg", "link_length_m", "motor_amplitude_rad"] {
        if let Some(v) = run.meta.get(key) {
            match v.parse::<f64>() {
                Ok(x) if x.is_finite() && x > 0.0 => {}
                _ => return Err(file_error(path, format!("metadata {key}={v:?} is not a positive number"))),
            }
        }
    }
    run.link_inertia = run.meta_f64("link_inertia_kgm2");
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
    Ok(run)
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

/// Reads every input; the first error stops everything.
pub fn read_inputs(inputs: &[PathBuf]) -> Result<Vec<Run>, DataError> {
    expand_inputs(inputs)?.iter().map(|f| read_run(f)).collect()
}
