//! ThermoVIA joints native in MuJoCo: the actuator plugin `thermovia.joint`, a cdylib
//! (`target/release/libthermovia_mujoco.so`) loaded with `mujoco.mj_loadPluginLibrary`.
//!
//! - [`config`]: the plugin's config keys, the FMU's parameter names read through the variable
//!   table (`thermovia-variables`), with its ranges and refusals.
//! - [`joint`]: one joint in safe Rust over `thermovia-model`: the `plugin_state` layout, the step,
//!   the coupling's stability limit.
//! - `ffi`: registration and MuJoCo's callbacks, the crate's only `unsafe` and `extern "C"`; the
//!   bindings are generated from the pinned mujoco wheel's headers.

#![deny(unsafe_code)]
// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod config;
#[allow(unsafe_code)]
mod ffi;
pub mod joint;

pub use ffi::PLUGIN_NAME;
