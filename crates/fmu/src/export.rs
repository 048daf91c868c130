//! The exported C API. Each function checks its pointers, catches any panic (none may cross the C
//! boundary: a panic is reported as fmi2Fatal) and delegates to the safe [`Component`].
//!
//! Safety contract of every function: the FMI 2.0 standard's (pointers valid for the sizes given,
//! a component from this library's fmi2Instantiate, not used concurrently).
#![allow(clippy::missing_safety_doc)]

use std::ffi::{CStr, CString};
use std::os::raw::c_char;
use std::panic::{catch_unwind, AssertUnwindSafe};

use crate::component::{self, Component, Function, Snapshot, Status};
use thermovia_fmi2::*;

/// Boxed FMU states carry a tag so a stray pointer is refused rather than trusted.
struct StateBox {
    tag: u64,
    snapshot: Snapshot,
}
const STATE_TAG: u64 = 0x5456_4941_5354_4154; // "TVIASTAT"

fn status(s: Status) -> Fmi2Status {
    s as Fmi2Status
}

/// Runs `f` on the instance behind `c` if `function` may be called in its phase (the one check of
/// the state machine, on entry); null → fmi2Error, panic → fmi2Fatal.
unsafe fn with_instance(c: Fmi2Component, function: Function, f: impl FnOnce(&mut Component) -> Status) -> Fmi2Status {
    if c.is_null() {
        return FMI2_ERROR;
    }
    let inst = &mut *(c as *mut Component);
    let (name, mask) = function.entry();
    match catch_unwind(AssertUnwindSafe(|| match inst.check(name, mask) {
        Ok(()) => f(&mut *inst),
        Err(s) => s,
    })) {
        Ok(s) => status(s),
        Err(panic) => {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            // The logger itself may have panicked; swallow a second one.
            let _ = catch_unwind(AssertUnwindSafe(|| inst.fatal(&format!("internal error (panic): {what}"))));
            FMI2_FATAL
        }
    }
}

/// Slice from a C array; `n == 0` accepts a null pointer.
unsafe fn slice<'a, T>(p: *const T, n: usize) -> Option<&'a [T]> {
    if n == 0 {
        Some(&[])
    } else if p.is_null() {
        None
    } else {
        Some(std::slice::from_raw_parts(p, n))
    }
}

unsafe fn slice_mut<'a, T>(p: *mut T, n: usize) -> Option<&'a mut [T]> {
    if n == 0 {
        Some(&mut [])
    } else if p.is_null() {
        None
    } else {
        Some(std::slice::from_raw_parts_mut(p, n))
    }
}

unsafe fn str_arg<'a>(p: Fmi2String) -> Option<&'a str> {
    if p.is_null() {
        None
    } else {
        CStr::from_ptr(p).to_str().ok()
    }
}

fn null_arg(inst: &mut Component, function: &str, arg: &str) -> Status {
    inst.error(&format!("{function}: argument {arg} is a null pointer"))
}

/// Longest message passed to the logger, in bytes: caller strings are quoted and cut before
/// they reach a message (`component::quoted`); this is the last line of defence.
const LOG_MAX_BYTES: usize = 2048;

/// `s` cut to at most `max` bytes on a character boundary, NULs replaced.
fn bounded(s: &str, max: usize) -> CString {
    let mut end = s.len().min(max);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    let cut = if end < s.len() { format!("{}… [cut]", &s[..end]) } else { s.to_string() };
    CString::new(cut.replace('\0', " ")).unwrap_or_default()
}

/// Wraps the importer's logger: messages go through "%s" so a '%' in them is never a format.
unsafe fn log_sink(functions: &Fmi2CallbackFunctions, name: &str) -> component::LogSink {
    let logger = functions.logger;
    let env = functions.component_environment;
    let name = bounded(name, component::QUOTE_MAX_CHARS);
    Box::new(move |s: Status, category: &str, message: &str| {
        if let Some(log) = logger {
            let cat = bounded(category, 64);
            let msg = bounded(message, LOG_MAX_BYTES);
            log(env, name.as_ptr(), s as Fmi2Status, cat.as_ptr(), c"%s".as_ptr(), msg.as_ptr());
        }
    })
}

#[no_mangle]
pub extern "C" fn fmi2GetTypesPlatform() -> *const c_char {
    c"default".as_ptr()
}

#[no_mangle]
pub extern "C" fn fmi2GetVersion() -> *const c_char {
    c"2.0".as_ptr()
}

#[no_mangle]
pub unsafe extern "C" fn fmi2Instantiate(
    instance_name: Fmi2String,
    fmu_type: Fmi2Type,
    fmu_guid: Fmi2String,
    fmu_resource_location: Fmi2String,
    functions: *const Fmi2CallbackFunctions,
    _visible: Fmi2Boolean,
    logging_on: Fmi2Boolean,
) -> Fmi2Component {
    if functions.is_null() {
        return std::ptr::null_mut();
    }
    let result = catch_unwind(AssertUnwindSafe(|| {
        let functions = &*functions;
        let name = str_arg(instance_name).unwrap_or("");
        let log = log_sink(functions, if name.is_empty() { "ThermoVIA" } else { name });
        let guid = match str_arg(fmu_guid) {
            Some(g) => g,
            None => {
                log(Status::Error, "logStatusError", "fmi2Instantiate: fmuGUID is null or not UTF-8");
                return std::ptr::null_mut();
            }
        };
        let resources = str_arg(fmu_resource_location).filter(|s| !s.is_empty());
        match Component::new(name, fmu_type, guid, resources, log, logging_on != 0) {
            Ok(inst) => Box::into_raw(Box::new(inst)) as Fmi2Component,
            Err(why) => {
                log_sink(functions, if name.is_empty() { "ThermoVIA" } else { name })(
                    Status::Error,
                    "logStatusError",
                    &why,
                );
                std::ptr::null_mut()
            }
        }
    }));
    result.unwrap_or(std::ptr::null_mut())
}

#[no_mangle]
pub unsafe extern "C" fn fmi2FreeInstance(c: Fmi2Component) {
    if !c.is_null() {
        let _ = catch_unwind(AssertUnwindSafe(|| {
            let inst = Box::from_raw(c as *mut Component);
            // States the importer did not free belong to the instance (FMI 2.0 §2.1.8): free them.
            for &p in &inst.live_states {
                free_state_box(p as Fmi2FmuState);
            }
            drop(inst);
        }));
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetDebugLogging(
    c: Fmi2Component,
    logging_on: Fmi2Boolean,
    n: usize,
    categories: *const Fmi2String,
) -> Fmi2Status {
    with_instance(c, Function::SetDebugLogging, |inst| {
        let Some(raw) = slice(categories, n) else { return null_arg(inst, "fmi2SetDebugLogging", "categories") };
        let mut names = Vec::with_capacity(n);
        for &p in raw {
            match str_arg(p) {
                Some(s) => names.push(s),
                None => return null_arg(inst, "fmi2SetDebugLogging", "categories[i]"),
            }
        }
        inst.set_debug_logging(logging_on != 0, &names)
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetupExperiment(
    c: Fmi2Component,
    tolerance_defined: Fmi2Boolean,
    tolerance: Fmi2Real,
    start_time: Fmi2Real,
    stop_time_defined: Fmi2Boolean,
    stop_time: Fmi2Real,
) -> Fmi2Status {
    with_instance(c, Function::SetupExperiment, |inst| {
        inst.setup_experiment(
            (tolerance_defined != 0).then_some(tolerance),
            start_time,
            (stop_time_defined != 0).then_some(stop_time),
        )
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2EnterInitializationMode(c: Fmi2Component) -> Fmi2Status {
    with_instance(c, Function::EnterInitializationMode, |inst| inst.enter_initialization_mode())
}

#[no_mangle]
pub unsafe extern "C" fn fmi2ExitInitializationMode(c: Fmi2Component) -> Fmi2Status {
    with_instance(c, Function::ExitInitializationMode, |inst| inst.exit_initialization_mode())
}

#[no_mangle]
pub unsafe extern "C" fn fmi2Terminate(c: Fmi2Component) -> Fmi2Status {
    with_instance(c, Function::Terminate, |inst| inst.terminate())
}

#[no_mangle]
pub unsafe extern "C" fn fmi2Reset(c: Fmi2Component) -> Fmi2Status {
    with_instance(c, Function::Reset, |inst| inst.reset())
}

macro_rules! getter {
    ($fname:ident, $cty:ty, $method:ident, $function:ident) => {
        #[no_mangle]
        pub unsafe extern "C" fn $fname(
            c: Fmi2Component,
            vr: *const Fmi2ValueReference,
            nvr: usize,
            value: *mut $cty,
        ) -> Fmi2Status {
            with_instance(c, Function::$function, |inst| {
                let Some(vrs) = slice(vr, nvr) else { return null_arg(inst, stringify!($fname), "vr") };
                let Some(out) = slice_mut(value, nvr) else { return null_arg(inst, stringify!($fname), "value") };
                inst.$method(vrs, out)
            })
        }
    };
}

getter!(fmi2GetReal, Fmi2Real, get_real, GetReal);
getter!(fmi2GetInteger, Fmi2Integer, get_integer, GetInteger);

#[no_mangle]
pub unsafe extern "C" fn fmi2SetReal(
    c: Fmi2Component,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    value: *const Fmi2Real,
) -> Fmi2Status {
    with_instance(c, Function::SetReal, |inst| {
        let Some(vrs) = slice(vr, nvr) else { return null_arg(inst, "fmi2SetReal", "vr") };
        let Some(values) = slice(value, nvr) else { return null_arg(inst, "fmi2SetReal", "value") };
        inst.set_real(vrs, values)
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetInteger(
    c: Fmi2Component,
    vr: *const Fmi2ValueReference,
    nvr: usize,
    value: *const Fmi2Integer,
) -> Fmi2Status {
    with_instance(c, Function::SetInteger, |inst| {
        let Some(vrs) = slice(vr, nvr) else { return null_arg(inst, "fmi2SetInteger", "vr") };
        let Some(values) = slice(value, nvr) else { return null_arg(inst, "fmi2SetInteger", "value") };
        inst.set_integer(vrs, values)
    })
}

macro_rules! no_variables {
    ($fname:ident, $ptr:ty, $function:ident) => {
        /// This FMU has no variables of this type: only an empty request succeeds.
        #[no_mangle]
        pub unsafe extern "C" fn $fname(
            c: Fmi2Component,
            vr: *const Fmi2ValueReference,
            nvr: usize,
            value: $ptr,
        ) -> Fmi2Status {
            with_instance(c, Function::$function, |inst| {
                let Some(vrs) = slice(vr, nvr) else { return null_arg(inst, stringify!($fname), "vr") };
                if nvr > 0 && value.is_null() {
                    return null_arg(inst, stringify!($fname), "value");
                }
                inst.no_variables_of_type(stringify!($fname), vrs)
            })
        }
    };
}

no_variables!(fmi2GetBoolean, *mut Fmi2Boolean, GetBoolean);
no_variables!(fmi2GetString, *mut Fmi2String, GetString);
no_variables!(fmi2SetBoolean, *const Fmi2Boolean, SetBoolean);
no_variables!(fmi2SetString, *const Fmi2String, SetString);

/// The state behind `p` if this instance allocated it and has not freed it: a stray, foreign or
/// freed pointer is refused without being read.
unsafe fn state_ref<'a>(inst: &Component, p: Fmi2FmuState) -> Option<&'a mut StateBox> {
    if p.is_null() || !inst.live_states.contains(&(p as usize)) {
        return None;
    }
    let b = &mut *(p as *mut StateBox);
    (b.tag == STATE_TAG).then_some(b)
}

/// A new state object, registered with the instance.
fn new_state(inst: &mut Component, snapshot: Snapshot) -> Fmi2FmuState {
    let p = Box::into_raw(Box::new(StateBox { tag: STATE_TAG, snapshot })) as Fmi2FmuState;
    inst.live_states.insert(p as usize);
    p
}

/// Frees a state object made by `new_state` (the caller has unregistered it).
unsafe fn free_state_box(p: Fmi2FmuState) {
    let mut b = Box::from_raw(p as *mut StateBox);
    b.tag = 0;
    drop(b);
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetFMUstate(c: Fmi2Component, state: *mut Fmi2FmuState) -> Fmi2Status {
    with_instance(c, Function::GetFmuState, |inst| {
        if state.is_null() {
            return null_arg(inst, "fmi2GetFMUstate", "FMUstate");
        }
        let snapshot = inst.get_state();
        if (*state).is_null() {
            *state = new_state(inst, snapshot);
        } else {
            match state_ref(inst, *state) {
                Some(b) => b.snapshot = snapshot, // reuse the importer's state object
                None => return inst.error("fmi2GetFMUstate: *FMUstate is not a state of this FMU"),
            }
        }
        Status::Ok
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetFMUstate(c: Fmi2Component, state: Fmi2FmuState) -> Fmi2Status {
    with_instance(c, Function::SetFmuState, |inst| match state_ref(inst, state) {
        Some(b) => inst.set_state(&b.snapshot.clone()),
        None if state.is_null() => null_arg(inst, "fmi2SetFMUstate", "FMUstate"),
        None => inst.error("fmi2SetFMUstate: FMUstate is not a state of this FMU"),
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2FreeFMUstate(c: Fmi2Component, state: *mut Fmi2FmuState) -> Fmi2Status {
    with_instance(c, Function::FreeFmuState, |inst| {
        if state.is_null() || (*state).is_null() {
            return Status::Ok;
        }
        if state_ref(inst, *state).is_none() {
            return inst.error("fmi2FreeFMUstate: FMUstate is not a live state of this instance");
        }
        // Unregistered first: a second free of the same pointer is then refused, not trusted.
        inst.live_states.remove(&(*state as usize));
        free_state_box(*state);
        *state = std::ptr::null_mut();
        Status::Ok
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SerializedFMUstateSize(
    c: Fmi2Component,
    state: Fmi2FmuState,
    size: *mut usize,
) -> Fmi2Status {
    with_instance(c, Function::SerializedFmuStateSize, |inst| {
        let Some(b) = state_ref(inst, state) else {
            return inst.error("fmi2SerializedFMUstateSize: FMUstate is null or foreign");
        };
        if size.is_null() {
            return null_arg(inst, "fmi2SerializedFMUstateSize", "size");
        }
        *size = component::serialize(&b.snapshot).len();
        Status::Ok
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SerializeFMUstate(
    c: Fmi2Component,
    state: Fmi2FmuState,
    bytes: *mut Fmi2Byte,
    size: usize,
) -> Fmi2Status {
    with_instance(c, Function::SerializeFmuState, |inst| {
        let Some(b) = state_ref(inst, state) else {
            return inst.error("fmi2SerializeFMUstate: FMUstate is null or foreign");
        };
        let data = component::serialize(&b.snapshot);
        if size < data.len() {
            return inst.error(&format!("fmi2SerializeFMUstate: buffer of {size} bytes, {} needed", data.len()));
        }
        let Some(out) = slice_mut(bytes as *mut u8, data.len()) else {
            return null_arg(inst, "fmi2SerializeFMUstate", "serializedState");
        };
        out.copy_from_slice(&data);
        Status::Ok
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2DeSerializeFMUstate(
    c: Fmi2Component,
    bytes: *const Fmi2Byte,
    size: usize,
    state: *mut Fmi2FmuState,
) -> Fmi2Status {
    with_instance(c, Function::DeSerializeFmuState, |inst| {
        if state.is_null() {
            return null_arg(inst, "fmi2DeSerializeFMUstate", "FMUstate");
        }
        let Some(data) = slice(bytes as *const u8, size) else {
            return null_arg(inst, "fmi2DeSerializeFMUstate", "serializedState");
        };
        let snapshot = match component::deserialize(data) {
            Ok(s) => s,
            Err(e) => return inst.error(&format!("fmi2DeSerializeFMUstate: {e}")),
        };
        if (*state).is_null() {
            *state = new_state(inst, snapshot);
        } else {
            match state_ref(inst, *state) {
                Some(b) => b.snapshot = snapshot,
                None => return inst.error("fmi2DeSerializeFMUstate: *FMUstate is not a state of this FMU"),
            }
        }
        Status::Ok
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetDirectionalDerivative(
    c: Fmi2Component,
    _v_unknown: *const Fmi2ValueReference,
    _n_unknown: usize,
    _v_known: *const Fmi2ValueReference,
    _n_known: usize,
    _dv_known: *const Fmi2Real,
    _dv_unknown: *mut Fmi2Real,
) -> Fmi2Status {
    with_instance(c, Function::GetDirectionalDerivative, |inst| {
        inst.unsupported("fmi2GetDirectionalDerivative", "not provided (providesDirectionalDerivative=false)")
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetRealInputDerivatives(
    c: Fmi2Component,
    _vr: *const Fmi2ValueReference,
    _nvr: usize,
    _order: *const Fmi2Integer,
    _value: *const Fmi2Real,
) -> Fmi2Status {
    with_instance(c, Function::SetRealInputDerivatives, |inst| {
        inst.unsupported(
            "fmi2SetRealInputDerivatives",
            "inputs are held over a step (canInterpolateInputs=false); use motor_speed_command for a ramp",
        )
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetRealOutputDerivatives(
    c: Fmi2Component,
    _vr: *const Fmi2ValueReference,
    _nvr: usize,
    _order: *const Fmi2Integer,
    _value: *mut Fmi2Real,
) -> Fmi2Status {
    with_instance(c, Function::GetRealOutputDerivatives, |inst| {
        inst.unsupported("fmi2GetRealOutputDerivatives", "maxOutputDerivativeOrder=0")
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2DoStep(
    c: Fmi2Component,
    current_communication_point: Fmi2Real,
    communication_step_size: Fmi2Real,
    _no_set_fmu_state_prior_to_current_point: Fmi2Boolean,
) -> Fmi2Status {
    with_instance(c, Function::DoStep, |inst| inst.do_step(current_communication_point, communication_step_size))
}

#[no_mangle]
pub unsafe extern "C" fn fmi2CancelStep(c: Fmi2Component) -> Fmi2Status {
    with_instance(c, Function::CancelStep, |inst| {
        inst.unsupported("fmi2CancelStep", "steps are synchronous (canRunAsynchronuously=false)")
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetStatus(c: Fmi2Component, kind: Fmi2StatusKind, value: *mut Fmi2Status) -> Fmi2Status {
    with_instance(c, Function::GetStatus, |inst| {
        if value.is_null() {
            return null_arg(inst, "fmi2GetStatus", "value");
        }
        if kind != FMI2_DO_STEP_STATUS {
            return inst.error(&format!("fmi2GetStatus: status kind {kind} has no fmi2Status value here"));
        }
        *value = inst.last_step_status() as Fmi2Status;
        Status::Ok
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetRealStatus(c: Fmi2Component, kind: Fmi2StatusKind, value: *mut Fmi2Real) -> Fmi2Status {
    with_instance(c, Function::GetRealStatus, |inst| {
        if value.is_null() {
            return null_arg(inst, "fmi2GetRealStatus", "value");
        }
        if kind != FMI2_LAST_SUCCESSFUL_TIME {
            return inst
                .error(&format!("fmi2GetRealStatus: only fmi2LastSuccessfulTime (2) is a Real status, not {kind}"));
        }
        *value = inst.last_successful_time();
        Status::Ok
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetIntegerStatus(
    c: Fmi2Component,
    kind: Fmi2StatusKind,
    _value: *mut Fmi2Integer,
) -> Fmi2Status {
    with_instance(c, Function::GetIntegerStatus, |inst| {
        inst.error(&format!("fmi2GetIntegerStatus: FMI 2.0 defines no Integer status (kind {kind})"))
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetBooleanStatus(
    c: Fmi2Component,
    kind: Fmi2StatusKind,
    value: *mut Fmi2Boolean,
) -> Fmi2Status {
    with_instance(c, Function::GetBooleanStatus, |inst| {
        if value.is_null() {
            return null_arg(inst, "fmi2GetBooleanStatus", "value");
        }
        if kind != FMI2_TERMINATED {
            return inst
                .error(&format!("fmi2GetBooleanStatus: only fmi2Terminated (3) is a Boolean status, not {kind}"));
        }
        *value = inst.terminated() as Fmi2Boolean;
        Status::Ok
    })
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetStringStatus(
    c: Fmi2Component,
    kind: Fmi2StatusKind,
    _value: *mut Fmi2String,
) -> Fmi2Status {
    with_instance(c, Function::GetStringStatus, |inst| {
        let why = if kind == FMI2_PENDING_STATUS {
            "no asynchronous step is ever pending"
        } else {
            "no String status of that kind"
        };
        inst.error(&format!("fmi2GetStringStatus: {why} (kind {kind})"))
    })
}
