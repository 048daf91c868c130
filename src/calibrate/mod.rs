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

pub fn run(args: &CalibrateArgs) -> Result<(), Box<dyn std::error::Error>> {
    let runs = data::read_inputs(&args.inputs)?;
    let fmu = match &args.fmu {
        Some(p) => crate::harness::Fmu::open(p)?,
        None => crate::harness::Fmu::open_default()?,
    };
    let sim = sim::Simulator::new(fmu, args.threads)?;
    let (group, temps) = group_runs(&runs);
    let prob = fit::Problem {
        sim: &sim,
        inputs: runs.iter().map(sim_input).collect(),
        measured: runs.iter().map(|r| r.link.clone()).collect(),
        group,
        n_groups: temps.len(),
        solver_tolerance: 1e-8,
    };
    let t0 = std::time::Instant::now();
    let o = search::calibrate(&prob)?;
    eprintln!("baseline rmse {:.3e} bic {:.0} struct {:.2} noise {:.3e}", o.baseline.rmse(), o.baseline.bic(), o.baseline_signatures.structure_ratio, o.baseline_signatures.noise_floor);
    for r in &o.rounds {
        for c in &r.candidates { eprintln!("  {} {:.3} {:.0} {:?}", c.effect.name(), c.score, c.predicted_delta_bic, c.start); }
        for a in &r.attempts { eprintln!("  attempt {:?}", a); }
    }
    eprintln!("final {:?} rmse {:.3e} struct {:.2} p {:?} in {:?} sims {}", diagnose::spec_names(&o.final_fit.spec), o.final_fit.rmse(), o.final_signatures.structure_ratio, o.final_fit.p, t0.elapsed(), sim.simulations.load(std::sync::atomic::Ordering::Relaxed));
    Ok(())
}

pub fn synth(args: &SynthArgs) -> Result<(), Box<dyn std::error::Error>> {
    synthetic::run(args)
}
