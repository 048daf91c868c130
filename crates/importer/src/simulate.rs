//! A plain simulation through any loaded FMU, the way `fmpy.simulate_fmu` runs one: inputs from a
//! table (linearly interpolated at each communication point, held beyond its ends), parameters set
//! before initialisation, a fixed communication step, outputs recorded at the start and after every
//! step, written as CSV in fmpy's result layout.

use std::error::Error;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use super::{Fmu, HarnessError, ModelDescription, VariableType};

/// Input signals: a strictly increasing `time` and one column per FMU input.
#[derive(Clone, Debug)]
pub struct InputTable {
    pub names: Vec<String>,
    pub time: Vec<f64>,
    pub columns: Vec<Vec<f64>>,
}

impl InputTable {
    /// Reads `time,<input>,<input>...` (header names may be quoted, as fmpy writes them). Errors
    /// name the file, line and column.
    pub fn read_csv(path: &Path) -> Result<InputTable, String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let table = crate::table::parse(path, &text, crate::table::Columns::All).map_err(|e| e.to_string())?;
        if table.names[0] != "time" {
            return Err(format!(
                "{}:{}:1: the first column must be \"time\", found {:?}",
                path.display(),
                table.header_line,
                table.names[0]
            ));
        }
        let mut columns: Vec<Vec<f64>> = table.columns.into_iter().map(Option::unwrap_or_default).collect();
        let time = columns.remove(0);
        if time.is_empty() {
            return Err(format!("{}: no data rows", path.display()));
        }
        Ok(InputTable { names: table.names[1..].to_vec(), time, columns })
    }

    /// Column `j` at time `t`: linear between samples, held beyond the ends.
    pub fn value_at(&self, j: usize, t: f64) -> f64 {
        let (ts, ys) = (&self.time, &self.columns[j]);
        let i = ts.partition_point(|&x| x <= t);
        if i == 0 {
            return ys[0];
        }
        if i == ts.len() {
            return ys[ts.len() - 1];
        }
        let w = (t - ts[i - 1]) / (ts[i] - ts[i - 1]);
        ys[i - 1] + w * (ys[i] - ys[i - 1])
    }
}

pub struct SimulateOptions {
    pub start_time: f64,
    pub stop_time: f64,
    /// Communication step: the `h` of every fmi2DoStep.
    pub step: f64,
    /// Time between recorded rows: a whole multiple of `step`.
    pub output_interval: f64,
    /// Start values and parameters, set before initialisation (see [`parse_value`]).
    pub parameters: Vec<(String, f64)>,
    pub input: Option<InputTable>,
    /// Variables to record (any causality).
    pub outputs: Vec<String>,
}

impl SimulateOptions {
    /// fmpy's defaults where the caller gave none: start and stop from the FMU's
    /// DefaultExperiment (else 0 and start + 1 s), the step from its stepSize (else 1/500 of the
    /// run), the output interval equal to the step, every output variable recorded.
    pub fn with_defaults(
        md: &ModelDescription,
        start_time: Option<f64>,
        stop_time: Option<f64>,
        step: Option<f64>,
        output_interval: Option<f64>,
        outputs: Option<Vec<String>>,
    ) -> SimulateOptions {
        let de = &md.default_experiment;
        let start_time = start_time.or(de.start_time).unwrap_or(0.0);
        let stop_time = stop_time.or(de.stop_time).unwrap_or(start_time + 1.0);
        let step = step.or(de.step_size).unwrap_or((stop_time - start_time) / 500.0);
        let outputs = outputs.unwrap_or_else(|| {
            md.variables
                .iter()
                .filter(|v| v.causality == "output" && v.ty != VariableType::String)
                .map(|v| v.name.clone())
                .collect()
        });
        SimulateOptions {
            start_time,
            stop_time,
            step,
            output_interval: output_interval.unwrap_or(step),
            parameters: Vec::new(),
            input: None,
            outputs,
        }
    }

    /// Steps between recorded rows, or why the numbers are unusable (naming the option).
    fn steps_per_output(&self) -> Result<usize, String> {
        if !(self.step > 0.0) || !self.step.is_finite() {
            return Err(format!("--step {}: must be a finite number > 0 s", self.step));
        }
        if !(self.stop_time > self.start_time) || !self.stop_time.is_finite() || !self.start_time.is_finite() {
            return Err(format!(
                "--stop-time {}: must be finite and greater than the start time {}",
                self.stop_time, self.start_time
            ));
        }
        let ratio = self.output_interval / self.step;
        if !(ratio >= 1.0 - 1e-9) || (ratio - ratio.round()).abs() > 1e-9 * ratio || !ratio.is_finite() {
            return Err(format!(
                "--output-interval {}: must be a whole multiple (≥ 1) of the step {} s",
                self.output_interval, self.step
            ));
        }
        Ok(ratio.round() as usize)
    }
}

/// The number a `NAME=VALUE` text stands for, by the variable's type: Real as a float, Integer as
/// an integer, Boolean as true/false/1/0, Enumeration as an item's name or its integer value.
/// Errors name the variable, the value and what was expected; an unknown name gets suggestions.
pub fn parse_value(md: &ModelDescription, name: &str, text: &str) -> Result<f64, String> {
    let v = md.variable(name).map_err(|e| format!("{name}={text}: {e}"))?;
    let t = text.trim();
    let expected = |what: &str| format!("{name}={text:?}: expected {what}");
    match v.ty {
        VariableType::Real => t.parse::<f64>().map_err(|_| expected("a number (Real)")),
        VariableType::Integer => t.parse::<i32>().map(f64::from).map_err(|_| expected("an integer (Integer)")),
        VariableType::Boolean => match t {
            "true" | "1" => Ok(1.0),
            "false" | "0" => Ok(0.0),
            _ => Err(expected("true, false, 1 or 0 (Boolean)")),
        },
        VariableType::Enumeration => {
            let items = md.enumeration_items(v);
            if let Some(item) = items.iter().find(|i| i.name == t) {
                return Ok(f64::from(item.value));
            }
            if let Ok(k) = t.parse::<i32>() {
                return Ok(f64::from(k));
            }
            let list: Vec<String> = items.iter().map(|i| format!("{} ({})", i.name, i.value)).collect();
            Err(expected(&format!(
                "one of {}",
                if list.is_empty() { "the integer values".into() } else { list.join(", ") }
            )))
        }
        VariableType::String => Err(format!("{name}: String variables cannot be set here")),
    }
}

/// Recorded columns, `time` first.
pub struct Trajectory {
    pub names: Vec<String>,
    pub columns: Vec<Vec<f64>>,
}

pub fn simulate(fmu: &Fmu, o: &SimulateOptions) -> Result<Trajectory, Box<dyn Error>> {
    let every = o.steps_per_output()?;
    let mut inst = fmu.instantiate(None)?;
    let params: Vec<(&str, f64)> = o.parameters.iter().map(|(n, v)| (n.as_str(), *v)).collect();
    inst.initialize(o.start_time, Some(o.stop_time), &params)?;
    let inputs = match &o.input {
        Some(table) => table.names.iter().map(|n| inst.handle(n)).collect::<Result<Vec<_>, HarnessError>>()?,
        None => Vec::new(),
    };
    let outputs = o.outputs.iter().map(|n| inst.handle(n)).collect::<Result<Vec<_>, HarnessError>>()?;
    let mut columns = vec![Vec::new(); outputs.len() + 1];
    let mut record = |inst: &mut super::Instance, t: f64| -> Result<(), HarnessError> {
        columns[0].push(t);
        for (j, h) in outputs.iter().enumerate() {
            columns[j + 1].push(inst.get_handle(*h)?);
        }
        Ok(())
    };
    record(&mut inst, o.start_time)?;
    let n = ((o.stop_time - o.start_time) / o.step - 1e-9).ceil() as usize;
    for k in 0..n {
        let t = o.start_time + k as f64 * o.step;
        if let Some(table) = &o.input {
            for (j, h) in inputs.iter().enumerate() {
                inst.set_handle(*h, table.value_at(j, t))?;
            }
        }
        // fmpy's grid: t_k = start + k·step and h = t_(k+1) − t_k, so both drivers pass the FMU
        // the same (rounded) step sizes.
        let t_next = (o.start_time + (k + 1) as f64 * o.step).min(o.stop_time);
        inst.step(t_next - t)?;
        if (k + 1) % every == 0 || k + 1 == n {
            record(&mut inst, t_next)?;
        }
    }
    inst.terminate()?;
    let mut names = vec!["time".to_string()];
    names.extend(o.outputs.iter().cloned());
    Ok(Trajectory { names, columns })
}

/// Writes columns as CSV in fmpy's result layout: quoted names, `time` first, full precision.
pub fn write_csv(path: &Path, columns: &[(&str, &[f64])]) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    let header: Vec<String> = columns.iter().map(|(n, _)| format!("\"{n}\"")).collect();
    writeln!(out, "{}", header.join(","))?;
    let rows = columns.first().map_or(0, |(_, c)| c.len());
    let mut line = String::new();
    for i in 0..rows {
        line.clear();
        for (j, (_, c)) in columns.iter().enumerate() {
            if j > 0 {
                line.push(',');
            }
            write!(line, "{:?}", c[i]).expect("string write");
        }
        writeln!(out, "{line}")?;
    }
    out.flush()
}

impl Trajectory {
    pub fn write_csv(&self, path: &Path) -> std::io::Result<()> {
        let cols: Vec<(&str, &[f64])> =
            self.names.iter().map(String::as_str).zip(self.columns.iter().map(Vec::as_slice)).collect();
        write_csv(path, &cols)
    }
}
