//! The tools around the ThermoVIA FMU: the paper's sweeps, the calibration loop and the arm
//! example. They drive the packaged FMU only through its C API (`thermovia-importer`); this crate
//! does not link the model or the FMU crate, so that rule is the compiler's. Options are plain
//! structs; the command line (clap, progress bars) lives in the `thermovia` binary.

#![forbid(unsafe_code)]
// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use std::path::{Path, PathBuf};

pub mod arm;
pub mod calibrate;
pub mod output;
pub mod report;
pub mod sweep;

/// Default location of the packaged FMU: `<workspace>/target/fmu/ThermoVIA.fmu`, where
/// `cargo run --release -p fmu-build` writes it.
pub fn default_fmu_path() -> PathBuf {
    let workspace =
        Path::new(env!("CARGO_MANIFEST_DIR")).ancestors().nth(2).expect("crates/tools sits two levels down");
    workspace.join("target").join("fmu").join("ThermoVIA.fmu")
}

/// Opens the packaged FMU at `path`, or at [`default_fmu_path`].
pub fn open_fmu(path: Option<&Path>) -> Result<thermovia_importer::Fmu, thermovia_importer::HarnessError> {
    thermovia_importer::Fmu::open(path.map_or_else(default_fmu_path, Path::to_path_buf))
}
