//! The FMI 2.0 C ABI as Rust types: the handles, scalar types, status codes and callback table of
//! `fmi2TypesPlatform.h` and `fmi2FunctionTypes.h`. Declarations only: the exporter
//! (`thermovia-fmu`) and the importer (`thermovia-importer`) share them, and neither depends on
//! the other.

#![forbid(unsafe_code)]

use std::os::raw::{c_char, c_int, c_void};

pub type Fmi2Component = *mut c_void;
pub type Fmi2ComponentEnvironment = *mut c_void;
pub type Fmi2FmuState = *mut c_void;
pub type Fmi2ValueReference = u32;
pub type Fmi2Real = f64;
pub type Fmi2Integer = c_int;
pub type Fmi2Boolean = c_int;
pub type Fmi2String = *const c_char;
pub type Fmi2Byte = c_char;
pub type Fmi2Status = c_int;
pub type Fmi2Type = c_int;
pub type Fmi2StatusKind = c_int;

pub const FMI2_OK: Fmi2Status = 0;
pub const FMI2_WARNING: Fmi2Status = 1;
pub const FMI2_DISCARD: Fmi2Status = 2;
pub const FMI2_ERROR: Fmi2Status = 3;
pub const FMI2_FATAL: Fmi2Status = 4;
pub const FMI2_CO_SIMULATION: Fmi2Type = 1;
pub const FMI2_DO_STEP_STATUS: Fmi2StatusKind = 0;
pub const FMI2_PENDING_STATUS: Fmi2StatusKind = 1;
pub const FMI2_LAST_SUCCESSFUL_TIME: Fmi2StatusKind = 2;
pub const FMI2_TERMINATED: Fmi2StatusKind = 3;

/// `fmi2CallbackLogger`: variadic in C; the message is a printf format.
pub type Fmi2CallbackLogger =
    Option<unsafe extern "C" fn(Fmi2ComponentEnvironment, Fmi2String, Fmi2Status, Fmi2String, Fmi2String, ...)>;
pub type Fmi2CallbackAllocateMemory = Option<unsafe extern "C" fn(usize, usize) -> *mut c_void>;
pub type Fmi2CallbackFreeMemory = Option<unsafe extern "C" fn(*mut c_void)>;
pub type Fmi2StepFinished = Option<unsafe extern "C" fn(Fmi2ComponentEnvironment, Fmi2Status)>;

#[repr(C)]
pub struct Fmi2CallbackFunctions {
    pub logger: Fmi2CallbackLogger,
    pub allocate_memory: Fmi2CallbackAllocateMemory,
    pub free_memory: Fmi2CallbackFreeMemory,
    pub step_finished: Fmi2StepFinished,
    pub component_environment: Fmi2ComponentEnvironment,
}
