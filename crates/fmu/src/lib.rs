//! The ThermoVIA FMU: the cdylib that FMI 2.0 importers load.
//!
//! - [`variables`]: the one table of FMU variables, which generates `modelDescription.xml`, the
//!   value-reference dispatch, the start values and the README's variable table.
//! - [`description`]: `modelDescription.xml` and its GUID, written from the table.
//! - [`documentation`]: `documentation/index.html`, the FMU's front page, written from the table.
//! - [`component`]: one FMU instance in safe Rust: the FMI 2.0 co-simulation state machine,
//!   argument checks, dispatch, FMU-state bytes.
//! - `export`: the 34 `fmi2*` C functions. This module is the only place in the workspace's
//!   exporter where `unsafe` and `extern "C"` are allowed; the crate denies them elsewhere, and
//!   the physics (`thermovia-model`) forbids them outright.

#![deny(unsafe_code)]
// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod component;
pub mod description;
pub mod documentation;
#[allow(unsafe_code)]
mod export;
/// The variable table, in its own crate so the MuJoCo plugin reads it without linking the FMI layer.
pub use thermovia_variables as variables;
