//! ThermoVIA: a thermo-active variable impedance actuator (springs ∥ temperature-dependent PCL)
//! exported as an FMI 2.0 Co-Simulation FMU, with the tools around it.
//!
//! - [`model`]: the physics, plain Rust.
//! - [`variables`]: the one table of FMU variables (description, dispatch, README table).
//! - [`fmi2`]: every `unsafe` and `extern "C"`: the exported C API and the importer's loader.
//! - [`harness`]: a safe importer for packaged `.fmu` files and a stepping master.

pub mod model;
pub mod fmi2;
pub mod variables;
