//! ThermoVIA: a thermo-active variable impedance actuator (springs ∥ temperature-dependent PCL)
//! exported as an FMI 2.0 Co-Simulation FMU, with the tools around it.
//!
//! Data flow one way: inputs → [`model::Model::step`] → outputs. Tools drive the packaged FMU only
//! through its C API, so what is tested is what users load.
//!
//! - [`model`]: the physics, plain Rust, no FFI, no I/O.
//! - [`variables`]: the one table of FMU variables (description, dispatch, README table).
//! - [`fmi2`]: every `unsafe` and `extern "C"`: the exported C API and the importer's loader.
//! - [`harness`]: a safe importer for packaged `.fmu` files.
//! - [`sweep`], [`calibrate`], [`arm`]: the paper's sweeps, the calibration loop, the arm example.

// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod arm;
pub mod calibrate;
pub mod fmi2;
pub mod harness;
pub mod model;
pub mod output;
pub mod sweep;
pub mod table;
pub mod variables;
