//! Measured data → fit → residual → missing effect → refit (issue 4).

/// `thermovia calibrate` options.
#[derive(clap::Args, Debug, Clone)]
pub struct CalibrateArgs {
    /// Run files (CSV, docs: interfaces.md) or folders of them.
    pub inputs: Vec<std::path::PathBuf>,
    /// Folder for report.json, the Markdown report and plots.
    #[arg(long, default_value = "out/calibrate")]
    pub out: std::path::PathBuf,
}

/// `thermovia synth` options.
#[derive(clap::Args, Debug, Clone)]
pub struct SynthArgs {
    /// Folder to write the run files to.
    #[arg(long, default_value = "out/synth")]
    pub out: std::path::PathBuf,
}

pub fn run(_args: &CalibrateArgs) -> Result<(), Box<dyn std::error::Error>> {
    Err("not implemented yet".into())
}

pub fn synth(_args: &SynthArgs) -> Result<(), Box<dyn std::error::Error>> {
    Err("not implemented yet".into())
}
