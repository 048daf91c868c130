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
}

fn main() {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Sweep(a) => thermovia::sweep::run(a),
        Command::Calibrate(a) => thermovia::calibrate::run(a),
        Command::Synth(a) => thermovia::calibrate::synth(a),
        Command::Arm(a) => thermovia::arm::run(a),
    };
    if let Err(e) = result {
        eprintln!("thermovia: error: {e}");
        std::process::exit(1);
    }
}
