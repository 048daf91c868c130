//! A two-joint planar arm whose joints are ThermoVIA FMU instances (issue 5).

pub mod dynamics;
pub mod reference;
pub mod sim;
pub mod stability;

/// `thermovia arm` options.
#[derive(clap::Args, Debug, Clone)]
pub struct ArmArgs {
    /// Folder for the report and plots.
    #[arg(long, default_value = "out/arm")]
    pub out: std::path::PathBuf,
}

pub fn run(_args: &ArmArgs) -> Result<(), Box<dyn std::error::Error>> {
    Err("not implemented yet".into())
}
