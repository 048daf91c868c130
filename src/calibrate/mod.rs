//! Measured data → fit → residual → missing effect → refit (issue 4).
//!
//! `data` reads runs (interfaces.md), `sim` drives the packaged FMU through the harness, `fit` is
//! Levenberg–Marquardt through those simulations, `diagnose` analyses residuals and ranks the
//! effect library, `search` adds and refits, `report` writes report.json, Markdown and plots,
//! `synth` writes synthetic measured runs from a truth model, `paper` runs the loop on the
//! paper's summary numbers.

pub mod data;
pub mod diagnose;
pub mod fit;
pub mod report;
pub mod search;
pub mod sim;
pub mod synthetic;

pub use synthetic::SynthArgs;

/// `thermovia calibrate` options.
#[derive(clap::Args, Debug, Clone)]
pub struct CalibrateArgs {
    /// Run files (CSV, docs: interfaces.md) or folders of them.
    pub inputs: Vec<std::path::PathBuf>,
    /// Folder for report.json, the Markdown report and plots (written atomically).
    #[arg(long, default_value = "out/calibrate")]
    pub out: std::path::PathBuf,
    /// Packaged FMU to use (default target/fmu/ThermoVIA.fmu).
    #[arg(long)]
    pub fmu: Option<std::path::PathBuf>,
    /// FMU instances simulating in parallel.
    #[arg(long, default_value_t = 2)]
    pub threads: usize,
    /// Skip the SVG plots (report.json and report.md only).
    #[arg(long)]
    pub no_plots: bool,
}

/// Temperature groups: runs at one nominal temperature share E' and E''. The nominal temperature is
/// the declared `temperature_c` metadata, else the thermocouple mean, to 0.5 °C.
pub fn group_runs(runs: &[data::Run]) -> (Vec<usize>, Vec<f64>) {
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

pub fn sim_input(r: &data::Run) -> sim::SimInput {
    sim::SimInput {
        time: r.time.clone(),
        motor: r.motor.clone(),
        housing_k: r.temperature_c.iter().map(|t| t + 273.15).collect(),
        frequency_hz: r.frequency_hz,
        link_inertia: r.link_inertia,
        link0: r.link[0],
        com_distance: r.meta_f64("link_length_m").unwrap_or(0.14),
    }
}

/// Everything `thermovia calibrate` computes, before it is written.
pub struct Calibration {
    pub runs: Vec<data::Run>,
    pub temperatures: Vec<f64>,
    pub outcome: search::Outcome,
    pub report: serde_json::Value,
    pub files: Vec<(String, Vec<u8>)>,
}

/// Reads the runs, fits, diagnoses, searches the effect library and builds the report files.
pub fn calibrate(args: &CalibrateArgs) -> Result<Calibration, Box<dyn std::error::Error>> {
    let t0 = std::time::Instant::now();
    let runs = data::read_inputs(&args.inputs)?;
    let fmu = match &args.fmu {
        Some(p) => crate::harness::Fmu::open(p)?,
        None => crate::harness::Fmu::open_default()?,
    };
    let sim = sim::Simulator::new(fmu, args.threads)?;
    let (group, temperatures) = group_runs(&runs);
    let prob = fit::Problem {
        sim: &sim,
        inputs: runs.iter().map(sim_input).collect(),
        measured: runs.iter().map(|r| r.link.clone()).collect(),
        group,
        n_groups: temperatures.len(),
        solver_tolerance: 1e-8,
    };
    let outcome = search::calibrate(&prob)?;
    let seconds = t0.elapsed().as_secs_f64();
    let report = report::report_json(&runs, &prob, &outcome, &temperatures, seconds);
    let mut files = vec![
        ("report.json".to_string(), (serde_json::to_string_pretty(&report)? + "\n").into_bytes()),
        ("report.md".to_string(), report::report_markdown(&report, &outcome).into_bytes()),
    ];
    if !args.no_plots {
        files.extend(report::plots(&runs, &prob, &outcome)?);
    }
    Ok(Calibration { runs, temperatures, outcome, report, files })
}

pub fn run(args: &CalibrateArgs) -> Result<(), Box<dyn std::error::Error>> {
    let c = calibrate(args)?;
    synthetic::write_atomically(&args.out, &c.files)?;
    let m = |k: &str| c.report[k]["rmse_rad"].as_f64().unwrap_or(f64::NAN);
    let added: Vec<&str> = c.outcome.final_fit.spec.effects.iter().map(|e| e.name()).collect();
    println!(
        "{} runs: baseline RMSE {:.3e} rad, final {:.3e} rad, added [{}], unexplained {}; report in {}",
        c.runs.len(),
        m("baseline"),
        m("final"),
        added.join(", "),
        c.outcome.unexplained,
        args.out.display()
    );
    Ok(())
}

pub fn synth(args: &SynthArgs) -> Result<(), Box<dyn std::error::Error>> {
    synthetic::run(args)
}
