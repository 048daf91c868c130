//! The ThermoVIA command line: every subcommand drives the packaged FMU
//! (`target/fmu/ThermoVIA.fmu`, built by `cargo run --release -p fmu-build`) through its C API.

use clap::{Parser, Subcommand};

#[derive(Parser)]
#[command(name = "thermovia", version, about = "Thermo-active variable impedance actuator: FMU tools", long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Reproduce the paper's 0.5 Hz and 1 Hz sweeps at 22, 40, 50 and 60 °C (report, JSON, CSVs, plots).
    Sweep(thermovia::sweep::SweepArgs),
    /// Fit measured runs, diagnose the residual, add the effect it points to, report before/after.
    Calibrate(thermovia::calibrate::CalibrateArgs),
    /// Write realistic synthetic measured runs from a truth model with chosen effects.
    Synth(thermovia::calibrate::SynthArgs),
    /// A two-link arm in a vertical plane with two ThermoVIA joints (co-simulation example).
    Arm(thermovia::arm::ArmArgs),
    /// Simulate any FMI 2.0 CS FMU like `fmpy simulate`: inputs from CSV, results as CSV.
    Simulate(SimulateArgs),
}

/// Options of `thermovia simulate`.
#[derive(clap::Args)]
struct SimulateArgs {
    /// The FMU to load [default: target/fmu/ThermoVIA.fmu].
    #[arg(long)]
    fmu: Option<std::path::PathBuf>,
    /// Input signals: CSV with "time" first and one column per FMU input, linearly interpolated
    /// at each communication point (fmpy's convention) and held beyond the last row.
    #[arg(long)]
    input: Option<std::path::PathBuf>,
    /// Results: CSV in fmpy's layout ("time" first, one column per --output).
    #[arg(long)]
    out: std::path::PathBuf,
    /// Start time, s.
    #[arg(long, default_value_t = 0.0)]
    start_time: f64,
    /// Stop time, s.
    #[arg(long, default_value_t = 20.0)]
    stop_time: f64,
    /// Communication step, s.
    #[arg(long, default_value_t = 1e-3)]
    step: f64,
    /// Variables to record, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "motor_angle,link_angle,housing_temperature,pcl_temperature")]
    output: Vec<String>,
    /// Parameter or start value, NAME=VALUE (repeatable), set before initialisation.
    #[arg(long = "set", value_parser = parse_assignment)]
    set: Vec<(String, f64)>,
}

fn parse_assignment(s: &str) -> Result<(String, f64), String> {
    let (name, value) = s.split_once('=').ok_or_else(|| format!("{s:?}: expected NAME=VALUE"))?;
    let v = value.trim().parse().map_err(|_| format!("{s:?}: {value:?} is not a number"))?;
    Ok((name.trim().to_string(), v))
}

fn simulate(a: &SimulateArgs) -> Result<(), Box<dyn std::error::Error>> {
    use thermovia::harness::simulate::{simulate, InputTable, SimulateOptions};
    let path = a.fmu.clone().unwrap_or_else(thermovia::harness::default_fmu_path);
    let fmu = thermovia::harness::Fmu::open(&path)?;
    let input = a.input.as_deref().map(InputTable::read_csv).transpose()?;
    let options = SimulateOptions {
        start_time: a.start_time,
        stop_time: a.stop_time,
        step: a.step,
        parameters: a.set.clone(),
        input,
        outputs: a.output.clone(),
    };
    let trajectory = simulate(&fmu, &options)?;
    // Written beside the target and renamed: never a half-written result file.
    let tmp = a.out.with_extension("csv.partial");
    trajectory.write_csv(&tmp)?;
    std::fs::rename(&tmp, &a.out)?;
    Ok(())
}

fn main() {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Sweep(a) => thermovia::sweep::run(a),
        Command::Calibrate(a) => thermovia::calibrate::run(a),
        Command::Synth(a) => thermovia::calibrate::synth(a),
        Command::Arm(a) => thermovia::arm::run(a),
        Command::Simulate(a) => simulate(a),
    };
    if let Err(e) = result {
        eprintln!("thermovia: error: {e}");
        std::process::exit(1);
    }
}
