//! The paper's experiment in co-simulation: 0.5 Hz and 1 Hz sweeps across temperature (issue 3).

/// `thermovia sweep` options.
#[derive(clap::Args, Debug, Clone)]
pub struct SweepArgs {
    /// Folder for summary.json, the report, CSVs and plots.
    #[arg(long, default_value = "out/sweep")]
    pub out: std::path::PathBuf,
}

pub fn run(_args: &SweepArgs) -> Result<(), Box<dyn std::error::Error>> {
    Err("not implemented yet".into())
}
