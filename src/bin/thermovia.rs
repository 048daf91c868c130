//! The ThermoVIA command line: every subcommand drives the packaged FMU
//! (`target/fmu/ThermoVIA.fmu`, built by `cargo run --release -p fmu-build`) through its C API.
//! The parsers come from the tools' options structs (their `cli` feature); progress bars and
//! clap live here, not in the libraries.

use std::path::PathBuf;

use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};

#[derive(Parser)]
#[command(name = "thermovia", version, about = "Thermo-active variable impedance actuator: FMU tools", long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Reproduce the paper's 0.5 Hz and 1 Hz sweeps at 22, 40, 50 and 60 °C (report, JSON, CSVs, plots).
    Sweep(thermovia_tools::sweep::SweepArgs),
    /// Fit measured runs, diagnose the residual, add the effect it points to, report before/after.
    Calibrate(thermovia_tools::calibrate::CalibrateArgs),
    /// Write realistic synthetic measured runs from a truth model with chosen effects.
    Synth(thermovia_tools::calibrate::SynthArgs),
    /// A two-link arm in a vertical plane with two ThermoVIA joints (co-simulation example).
    Arm(thermovia_tools::arm::ArmArgs),
    /// Simulate any FMI 2.0 co-simulation FMU like `fmpy simulate`: inputs from CSV, results as CSV.
    ///
    /// Start, stop and step default to the FMU's DefaultExperiment; every output variable is
    /// recorded unless --output names others. Example:
    ///   thermovia simulate target/fmu/ThermoVIA.fmu --set heater_power=10 --set motor_drive=prescribed_angle
    Simulate(SimulateArgs),
    /// Describe any FMI 2.0 co-simulation FMU like `fmpy info`: its variables (causality, type,
    /// start value, unit), capabilities and DefaultExperiment.
    Info(InfoArgs),
}

/// Options of `thermovia simulate`.
#[derive(clap::Args)]
struct SimulateArgs {
    /// The FMU to simulate (any FMI 2.0 co-simulation FMU; ThermoVIA's is target/fmu/ThermoVIA.fmu).
    fmu: PathBuf,
    /// Input signals: CSV with "time" first and one column per FMU input, linearly interpolated
    /// at each communication point (fmpy's convention) and held beyond the last row.
    #[arg(long)]
    input: Option<PathBuf>,
    /// Results: CSV in fmpy's layout ("time" first, one column per recorded variable)
    /// [default: <modelName>_out.csv, as fmpy].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Start time, s [default: the FMU's DefaultExperiment startTime, else 0].
    #[arg(long)]
    start_time: Option<f64>,
    /// Stop time, s [default: DefaultExperiment stopTime, else start + 1].
    #[arg(long)]
    stop_time: Option<f64>,
    /// Communication step (the h of every fmi2DoStep), s [default: DefaultExperiment stepSize,
    /// else 1/500 of the run].
    #[arg(long)]
    step: Option<f64>,
    /// Time between recorded rows, s: a whole multiple of the step [default: the step].
    #[arg(long)]
    output_interval: Option<f64>,
    /// Variables to record, comma-separated [default: every output of the FMU].
    #[arg(long, value_delimiter = ',')]
    output: Option<Vec<String>>,
    /// Parameter or start value NAME=VALUE (repeatable), set before initialisation. VALUE is read
    /// by the variable's type: a number, an integer, true/false, or an Enumeration item's name.
    #[arg(long = "set", value_name = "NAME=VALUE", value_parser = parse_assignment)]
    set: Vec<(String, String)>,
}

/// Options of `thermovia info`.
#[derive(clap::Args)]
struct InfoArgs {
    /// The FMU to describe.
    fmu: PathBuf,
}

fn parse_assignment(s: &str) -> Result<(String, String), String> {
    let (name, value) = s.split_once('=').ok_or_else(|| format!("{s:?}: expected NAME=VALUE"))?;
    Ok((name.trim().to_string(), value.trim().to_string()))
}

fn simulate(a: &SimulateArgs) -> Result<(), Box<dyn std::error::Error>> {
    use thermovia_importer::simulate::{parse_value, simulate, InputTable, SimulateOptions};
    let fmu = thermovia_importer::Fmu::open(&a.fmu)?;
    let md = &fmu.description;
    let mut options =
        SimulateOptions::with_defaults(md, a.start_time, a.stop_time, a.step, a.output_interval, a.output.clone());
    options.parameters = a
        .set
        .iter()
        .map(|(name, text)| parse_value(md, name, text).map(|v| (name.clone(), v)).map_err(|e| format!("--set {e}")))
        .collect::<Result<_, _>>()?;
    options.input = a.input.as_deref().map(InputTable::read_csv).transpose()?;
    let out = a.out.clone().unwrap_or_else(|| PathBuf::from(format!("{}_out.csv", md.model_name)));
    let trajectory = simulate(&fmu, &options)?;
    thermovia_tools::output::write_file(&out, |path| trajectory.write_csv(path))?;
    eprintln!(
        "thermovia: {} rows × {} variables, t = {} … {} s, written to {}",
        trajectory.columns[0].len(),
        trajectory.names.len() - 1,
        options.start_time,
        options.stop_time,
        out.display()
    );
    Ok(())
}

fn info(a: &InfoArgs) -> Result<(), Box<dyn std::error::Error>> {
    let fmu = thermovia_importer::Fmu::open(&a.fmu)?;
    print!("{}", thermovia_importer::info::describe(&fmu.description));
    Ok(())
}

/// The parsed command line. Numeric options take negative values (`--step -0.001`), so the tools'
/// own checks, which name the option and the range, judge them rather than the parser.
fn parse_command_line() -> Cli {
    fn allow_negative(cmd: clap::Command) -> clap::Command {
        cmd.mut_args(
            |a| if a.get_num_args().is_none_or(|n| n.takes_values()) { a.allow_negative_numbers(true) } else { a },
        )
        .mut_subcommands(allow_negative)
    }
    let parsed = allow_negative(Cli::command()).try_get_matches().and_then(|m| Cli::from_arg_matches(&m));
    parsed.unwrap_or_else(|e| {
        use clap::error::ErrorKind;
        if matches!(
            e.kind(),
            ErrorKind::DisplayHelp | ErrorKind::DisplayVersion | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
        ) {
            e.exit();
        }
        // One line: clap's message with its tips, without the usage block.
        let text = e.render().to_string();
        let lines: Vec<&str> = text
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && !l.starts_with("Usage:") && !l.starts_with("For more information"))
            .collect();
        eprintln!("thermovia: {} (see --help)", lines.join("; "));
        std::process::exit(2);
    })
}

/// A progress bar on stderr, hidden with --quiet, when stderr is not a terminal, or under CI.
struct Bar(indicatif::ProgressBar);

impl Bar {
    fn new(quiet: bool, template: &str) -> Bar {
        let show = !quiet
            && std::env::var("CI").map_or(true, |v| v != "true")
            && std::io::IsTerminal::is_terminal(&std::io::stderr());
        if !show {
            return Bar(indicatif::ProgressBar::hidden());
        }
        let bar = indicatif::ProgressBar::new(0);
        bar.set_style(
            indicatif::ProgressStyle::with_template(template)
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        Bar(bar)
    }
}

impl thermovia_tools::output::Progress for Bar {
    fn start(&self, total: u64) {
        self.0.set_length(total);
    }
    fn set_label(&self, label: &str) {
        self.0.set_message(label.to_string());
    }
    fn set_position(&self, position: u64) {
        self.0.set_position(position);
    }
    fn finish(&self) {
        self.0.finish_and_clear();
    }
}

fn main() {
    // A panic is a bug, never an answer to bad input (those are errors naming file and line); if one
    // is left, the user gets one line to report, and RUST_BACKTRACE=1 gives the developer the rest.
    if std::env::var_os("RUST_BACKTRACE").is_none() {
        std::panic::set_hook(Box::new(|info| {
            let at = info.location().map(|l| format!(" at {}:{}", l.file(), l.line())).unwrap_or_default();
            let what = info
                .payload()
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| info.payload().downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic".into());
            eprintln!("thermovia: internal error (a bug: please report it with the input): {what}{at}");
        }));
    }
    let cli = parse_command_line();
    let result: Result<(), Box<dyn std::error::Error>> = match &cli.command {
        Command::Sweep(a) => {
            let bar = Bar::new(a.quiet, "{spinner} sweep [{bar:30}] {pos}/{len} {msg} ({elapsed})");
            thermovia_tools::sweep::run(a, &bar).map_err(Into::into)
        }
        Command::Calibrate(a) => thermovia_tools::calibrate::run(a),
        Command::Synth(a) => thermovia_tools::calibrate::synth(a),
        Command::Arm(a) => {
            let bar = Bar::new(false, "{msg:32} [{bar:40}] {percent:>3}% {elapsed}");
            thermovia_tools::arm::run(a, &bar).map_err(Into::into)
        }
        Command::Simulate(a) => simulate(a),
        Command::Info(a) => info(a),
    };
    if let Err(e) = result {
        eprintln!("thermovia: error: {e}");
        std::process::exit(1);
    }
}
