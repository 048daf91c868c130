//! The importer's side of the C API: load an FMI 2.0 co-simulation binary with libloading, resolve
//! its 34 functions, and wrap one instance's calls so that code outside this module needs no
//! `unsafe`. Used by the harness, the sweeps, the calibration and the tests.

use std::ffi::{CStr, CString};
use std::os::raw::c_void;
use std::path::Path;
use std::sync::{Arc, Mutex};

use thermovia_fmi2::*;

macro_rules! api {
    ($($field:ident : $sym:literal => fn($($arg:ty),*) $(-> $ret:ty)?;)*) => {
        /// Every function of the FMI 2.0 common + co-simulation API, resolved from one library.
        #[derive(Clone, Copy)]
        pub struct Api {
            $(pub $field: unsafe extern "C" fn($($arg),*) $(-> $ret)?,)*
        }

        impl Api {
            /// Resolves all 34 symbols; the error names the first missing one.
            unsafe fn resolve(lib: &libloading::Library) -> Result<Api, String> {
                Ok(Api {
                    $($field: *lib
                        .get::<unsafe extern "C" fn($($arg),*) $(-> $ret)?>(concat!($sym, "\0").as_bytes())
                        .map_err(|e| format!("missing symbol {}: {e}", $sym))?,)*
                })
            }
        }
    };
}

api! {
    get_types_platform: "fmi2GetTypesPlatform" => fn() -> *const std::os::raw::c_char;
    get_version: "fmi2GetVersion" => fn() -> *const std::os::raw::c_char;
    set_debug_logging: "fmi2SetDebugLogging" => fn(Fmi2Component, Fmi2Boolean, usize, *const Fmi2String) -> Fmi2Status;
    instantiate: "fmi2Instantiate" => fn(Fmi2String, Fmi2Type, Fmi2String, Fmi2String, *const Fmi2CallbackFunctions, Fmi2Boolean, Fmi2Boolean) -> Fmi2Component;
    free_instance: "fmi2FreeInstance" => fn(Fmi2Component);
    setup_experiment: "fmi2SetupExperiment" => fn(Fmi2Component, Fmi2Boolean, Fmi2Real, Fmi2Real, Fmi2Boolean, Fmi2Real) -> Fmi2Status;
    enter_initialization_mode: "fmi2EnterInitializationMode" => fn(Fmi2Component) -> Fmi2Status;
    exit_initialization_mode: "fmi2ExitInitializationMode" => fn(Fmi2Component) -> Fmi2Status;
    terminate: "fmi2Terminate" => fn(Fmi2Component) -> Fmi2Status;
    reset: "fmi2Reset" => fn(Fmi2Component) -> Fmi2Status;
    get_real: "fmi2GetReal" => fn(Fmi2Component, *const u32, usize, *mut f64) -> Fmi2Status;
    get_integer: "fmi2GetInteger" => fn(Fmi2Component, *const u32, usize, *mut Fmi2Integer) -> Fmi2Status;
    get_boolean: "fmi2GetBoolean" => fn(Fmi2Component, *const u32, usize, *mut Fmi2Boolean) -> Fmi2Status;
    get_string: "fmi2GetString" => fn(Fmi2Component, *const u32, usize, *mut Fmi2String) -> Fmi2Status;
    set_real: "fmi2SetReal" => fn(Fmi2Component, *const u32, usize, *const f64) -> Fmi2Status;
    set_integer: "fmi2SetInteger" => fn(Fmi2Component, *const u32, usize, *const Fmi2Integer) -> Fmi2Status;
    set_boolean: "fmi2SetBoolean" => fn(Fmi2Component, *const u32, usize, *const Fmi2Boolean) -> Fmi2Status;
    set_string: "fmi2SetString" => fn(Fmi2Component, *const u32, usize, *const Fmi2String) -> Fmi2Status;
    get_fmu_state: "fmi2GetFMUstate" => fn(Fmi2Component, *mut Fmi2FmuState) -> Fmi2Status;
    set_fmu_state: "fmi2SetFMUstate" => fn(Fmi2Component, Fmi2FmuState) -> Fmi2Status;
    free_fmu_state: "fmi2FreeFMUstate" => fn(Fmi2Component, *mut Fmi2FmuState) -> Fmi2Status;
    serialized_fmu_state_size: "fmi2SerializedFMUstateSize" => fn(Fmi2Component, Fmi2FmuState, *mut usize) -> Fmi2Status;
    serialize_fmu_state: "fmi2SerializeFMUstate" => fn(Fmi2Component, Fmi2FmuState, *mut Fmi2Byte, usize) -> Fmi2Status;
    deserialize_fmu_state: "fmi2DeSerializeFMUstate" => fn(Fmi2Component, *const Fmi2Byte, usize, *mut Fmi2FmuState) -> Fmi2Status;
    get_directional_derivative: "fmi2GetDirectionalDerivative" => fn(Fmi2Component, *const u32, usize, *const u32, usize, *const f64, *mut f64) -> Fmi2Status;
    set_real_input_derivatives: "fmi2SetRealInputDerivatives" => fn(Fmi2Component, *const u32, usize, *const Fmi2Integer, *const f64) -> Fmi2Status;
    get_real_output_derivatives: "fmi2GetRealOutputDerivatives" => fn(Fmi2Component, *const u32, usize, *const Fmi2Integer, *mut f64) -> Fmi2Status;
    do_step: "fmi2DoStep" => fn(Fmi2Component, f64, f64, Fmi2Boolean) -> Fmi2Status;
    cancel_step: "fmi2CancelStep" => fn(Fmi2Component) -> Fmi2Status;
    get_status: "fmi2GetStatus" => fn(Fmi2Component, Fmi2StatusKind, *mut Fmi2Status) -> Fmi2Status;
    get_real_status: "fmi2GetRealStatus" => fn(Fmi2Component, Fmi2StatusKind, *mut f64) -> Fmi2Status;
    get_integer_status: "fmi2GetIntegerStatus" => fn(Fmi2Component, Fmi2StatusKind, *mut Fmi2Integer) -> Fmi2Status;
    get_boolean_status: "fmi2GetBooleanStatus" => fn(Fmi2Component, Fmi2StatusKind, *mut Fmi2Boolean) -> Fmi2Status;
    get_string_status: "fmi2GetStringStatus" => fn(Fmi2Component, Fmi2StatusKind, *mut Fmi2String) -> Fmi2Status;
}

/// A loaded FMU binary. Instances hold an `Arc` to it, so it outlives them.
pub struct Library {
    pub api: Api,
    _lib: libloading::Library,
}

impl Library {
    pub fn load(path: &Path) -> Result<Arc<Library>, String> {
        // SAFETY: loading runs the library's initialisers; an FMU binary is trusted code by nature.
        unsafe {
            let lib = libloading::Library::new(path).map_err(|e| format!("cannot load {}: {e}", path.display()))?;
            let api = Api::resolve(&lib).map_err(|e| format!("{}: {e}", path.display()))?;
            Ok(Arc::new(Library { api, _lib: lib }))
        }
    }

    pub fn version(&self) -> String {
        // SAFETY: both return static C strings.
        unsafe { CStr::from_ptr((self.api.get_version)()).to_string_lossy().into_owned() }
    }

    pub fn types_platform(&self) -> String {
        // SAFETY: as above.
        unsafe { CStr::from_ptr((self.api.get_types_platform)()).to_string_lossy().into_owned() }
    }
}

/// One logged message.
#[derive(Clone, Debug)]
pub struct LogRecord {
    pub status: Fmi2Status,
    pub category: String,
    pub message: String,
}

type LogBuffer = Mutex<Vec<LogRecord>>;

/// The importer's logger. C declares it variadic; stable Rust cannot define variadic functions, so
/// it takes the first variadic argument as a sixth pointer argument, which is where the x86-64
/// System V ABI (linux64, the platform shipped) passes it. Messages are read as `"%s", text`
/// (what this crate's FMU sends); any other format is kept verbatim, unformatted.
unsafe extern "C" fn collect_log(
    env: Fmi2ComponentEnvironment,
    _instance_name: Fmi2String,
    status: Fmi2Status,
    category: Fmi2String,
    format: Fmi2String,
    first_arg: *const std::os::raw::c_char,
) {
    if env.is_null() {
        return;
    }
    let text = |p: *const std::os::raw::c_char| {
        if p.is_null() {
            String::new()
        } else {
            CStr::from_ptr(p).to_string_lossy().into_owned()
        }
    };
    let fmt = text(format);
    let message = if fmt == "%s" { text(first_arg) } else { fmt };
    let buffer = &*(env as *const LogBuffer);
    if let Ok(mut b) = buffer.lock() {
        b.push(LogRecord { status, category: text(category), message });
    }
}

/// An FMU state object owned by the instance that made it.
pub struct FmuState(Fmi2FmuState);

/// One instance of a loaded FMU. Freed (with its FMU states) on drop.
pub struct RawInstance {
    lib: Arc<Library>,
    c: Fmi2Component,
    log: Box<LogBuffer>,
    _callbacks: Box<Fmi2CallbackFunctions>,
    states: Vec<Fmi2FmuState>,
}

// SAFETY: an FMI 2.0 instance may be used from any thread as long as calls on it are not
// concurrent, which `&mut self` on every call guarantees.
unsafe impl Send for RawInstance {}

impl RawInstance {
    pub fn instantiate(
        lib: &Arc<Library>,
        name: &str,
        guid: &str,
        resource_uri: Option<&str>,
        logging_on: bool,
    ) -> Result<RawInstance, String> {
        let log: Box<LogBuffer> = Box::new(Mutex::new(Vec::new()));
        // SAFETY: the logger's real signature is variadic; see `collect_log`.
        let logger: Fmi2CallbackLogger = unsafe {
            Some(std::mem::transmute::<
                unsafe extern "C" fn(
                    Fmi2ComponentEnvironment,
                    Fmi2String,
                    Fmi2Status,
                    Fmi2String,
                    Fmi2String,
                    *const std::os::raw::c_char,
                ),
                unsafe extern "C" fn(Fmi2ComponentEnvironment, Fmi2String, Fmi2Status, Fmi2String, Fmi2String, ...),
            >(collect_log))
        };
        let callbacks = Box::new(Fmi2CallbackFunctions {
            logger,
            allocate_memory: None,
            free_memory: None,
            step_finished: None,
            component_environment: &*log as *const LogBuffer as *mut c_void,
        });
        let cname = CString::new(name).map_err(|_| "instance name contains NUL".to_string())?;
        let cguid = CString::new(guid).map_err(|_| "GUID contains NUL".to_string())?;
        let curi = resource_uri.map(CString::new).transpose().map_err(|_| "resource URI contains NUL".to_string())?;
        // SAFETY: all pointers are valid for the call; callbacks and log outlive the instance.
        let c = unsafe {
            (lib.api.instantiate)(
                cname.as_ptr(),
                FMI2_CO_SIMULATION,
                cguid.as_ptr(),
                curi.as_ref().map_or(std::ptr::null(), |u| u.as_ptr()),
                &*callbacks,
                0,
                logging_on as Fmi2Boolean,
            )
        };
        if c.is_null() {
            let msgs: Vec<String> =
                log.lock().map(|l| l.iter().map(|r| r.message.clone()).collect()).unwrap_or_default();
            return Err(format!("fmi2Instantiate returned NULL: {}", msgs.join("; ")));
        }
        Ok(RawInstance { lib: lib.clone(), c, log, _callbacks: callbacks, states: Vec::new() })
    }

    /// The raw component pointer and API, for conformance tests that must pass bad arguments.
    pub fn raw(&self) -> (Fmi2Component, &Api) {
        (self.c, &self.lib.api)
    }

    /// Messages logged since the last call.
    pub fn take_log(&self) -> Vec<LogRecord> {
        self.log.lock().map(|mut l| std::mem::take(&mut *l)).unwrap_or_default()
    }

    pub fn set_debug_logging(&mut self, on: bool, categories: &[&str]) -> Fmi2Status {
        let owned: Vec<CString> = categories.iter().map(|c| CString::new(*c).unwrap_or_default()).collect();
        let ptrs: Vec<Fmi2String> = owned.iter().map(|c| c.as_ptr()).collect();
        // SAFETY: `ptrs` holds `len` valid C strings for the call.
        unsafe { (self.lib.api.set_debug_logging)(self.c, on as Fmi2Boolean, ptrs.len(), ptrs.as_ptr()) }
    }

    pub fn setup_experiment(&mut self, tolerance: Option<f64>, start: f64, stop: Option<f64>) -> Fmi2Status {
        // SAFETY: plain values.
        unsafe {
            (self.lib.api.setup_experiment)(
                self.c,
                tolerance.is_some() as Fmi2Boolean,
                tolerance.unwrap_or(0.0),
                start,
                stop.is_some() as Fmi2Boolean,
                stop.unwrap_or(0.0),
            )
        }
    }

    pub fn enter_initialization_mode(&mut self) -> Fmi2Status {
        // SAFETY: valid component.
        unsafe { (self.lib.api.enter_initialization_mode)(self.c) }
    }
    pub fn exit_initialization_mode(&mut self) -> Fmi2Status {
        // SAFETY: valid component.
        unsafe { (self.lib.api.exit_initialization_mode)(self.c) }
    }
    pub fn terminate(&mut self) -> Fmi2Status {
        // SAFETY: valid component.
        unsafe { (self.lib.api.terminate)(self.c) }
    }
    pub fn reset(&mut self) -> Fmi2Status {
        // SAFETY: valid component.
        unsafe { (self.lib.api.reset)(self.c) }
    }
    pub fn do_step(&mut self, t: f64, h: f64) -> Fmi2Status {
        // SAFETY: valid component.
        unsafe { (self.lib.api.do_step)(self.c, t, h, 0) }
    }

    pub fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Fmi2Status {
        assert_eq!(vrs.len(), out.len(), "one value per value reference");
        // SAFETY: both slices have `len` elements.
        unsafe { (self.lib.api.get_real)(self.c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr()) }
    }
    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Fmi2Status {
        assert_eq!(vrs.len(), values.len(), "one value per value reference");
        // SAFETY: both slices have `len` elements.
        unsafe { (self.lib.api.set_real)(self.c, vrs.as_ptr(), vrs.len(), values.as_ptr()) }
    }
    pub fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Fmi2Status {
        assert_eq!(vrs.len(), out.len(), "one value per value reference");
        // SAFETY: both slices have `len` elements.
        unsafe { (self.lib.api.get_integer)(self.c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr()) }
    }
    pub fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Fmi2Status {
        assert_eq!(vrs.len(), values.len(), "one value per value reference");
        // SAFETY: both slices have `len` elements.
        unsafe { (self.lib.api.set_integer)(self.c, vrs.as_ptr(), vrs.len(), values.as_ptr()) }
    }

    pub fn get_boolean(&mut self, vrs: &[u32], out: &mut [Fmi2Boolean]) -> Fmi2Status {
        assert_eq!(vrs.len(), out.len(), "one value per value reference");
        // SAFETY: both slices have `len` elements.
        unsafe { (self.lib.api.get_boolean)(self.c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr()) }
    }
    pub fn set_boolean(&mut self, vrs: &[u32], values: &[Fmi2Boolean]) -> Fmi2Status {
        assert_eq!(vrs.len(), values.len(), "one value per value reference");
        // SAFETY: both slices have `len` elements.
        unsafe { (self.lib.api.set_boolean)(self.c, vrs.as_ptr(), vrs.len(), values.as_ptr()) }
    }

    pub fn get_real_status_last_successful_time(&mut self) -> (Fmi2Status, f64) {
        let mut t = f64::NAN;
        // SAFETY: `t` is a valid out pointer.
        let s = unsafe { (self.lib.api.get_real_status)(self.c, FMI2_LAST_SUCCESSFUL_TIME, &mut t) };
        (s, t)
    }

    pub fn get_boolean_status_terminated(&mut self) -> (Fmi2Status, bool) {
        let mut b: Fmi2Boolean = 0;
        // SAFETY: `b` is a valid out pointer.
        let s = unsafe { (self.lib.api.get_boolean_status)(self.c, FMI2_TERMINATED, &mut b) };
        (s, b != 0)
    }

    /// fmi2GetFMUstate into a new state, or into `reuse`.
    pub fn get_fmu_state(&mut self, reuse: Option<&mut FmuState>) -> Result<FmuState, Fmi2Status> {
        let mut p: Fmi2FmuState = reuse.as_ref().map_or(std::ptr::null_mut(), |s| s.0);
        // SAFETY: `p` is null or a state this instance made.
        let s = unsafe { (self.lib.api.get_fmu_state)(self.c, &mut p) };
        if s != FMI2_OK {
            return Err(s);
        }
        if !self.states.contains(&p) {
            self.states.push(p);
        }
        Ok(FmuState(p))
    }

    pub fn set_fmu_state(&mut self, state: &FmuState) -> Fmi2Status {
        // SAFETY: the state was made by this instance and is not freed (freeing consumes it).
        unsafe { (self.lib.api.set_fmu_state)(self.c, state.0) }
    }

    pub fn free_fmu_state(&mut self, state: FmuState) -> Fmi2Status {
        let mut p = state.0;
        self.states.retain(|&q| q != p);
        // SAFETY: as above; the pointer is nulled by the FMU.
        unsafe { (self.lib.api.free_fmu_state)(self.c, &mut p) }
    }

    pub fn serialize_fmu_state(&mut self, state: &FmuState) -> Result<Vec<u8>, Fmi2Status> {
        let mut size = 0usize;
        // SAFETY: valid out pointers and a buffer of the announced size.
        unsafe {
            let s = (self.lib.api.serialized_fmu_state_size)(self.c, state.0, &mut size);
            if s != FMI2_OK {
                return Err(s);
            }
            let mut buf = vec![0u8; size];
            let s = (self.lib.api.serialize_fmu_state)(self.c, state.0, buf.as_mut_ptr() as *mut Fmi2Byte, size);
            if s != FMI2_OK {
                return Err(s);
            }
            Ok(buf)
        }
    }

    pub fn deserialize_fmu_state(&mut self, bytes: &[u8]) -> Result<FmuState, Fmi2Status> {
        let mut p: Fmi2FmuState = std::ptr::null_mut();
        // SAFETY: `bytes` is valid for its length.
        let s = unsafe {
            (self.lib.api.deserialize_fmu_state)(self.c, bytes.as_ptr() as *const Fmi2Byte, bytes.len(), &mut p)
        };
        if s != FMI2_OK {
            return Err(s);
        }
        self.states.push(p);
        Ok(FmuState(p))
    }
}

/// Which pointer argument a deliberately bad call passes as NULL (with a non-zero count where the
/// function takes one): the conformance tests and the fuzzer check that each is refused, not
/// dereferenced.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NullArg {
    GetRealValues,
    SetRealValues,
    GetIntegerValues,
    SetIntegerValues,
    GetBooleanValues,
    SetBooleanValues,
    GetStringValues,
    SetStringValues,
    SetDebugLoggingCategories,
    GetFmuStateOut,
    SetFmuState,
    FreeFmuStateOut,
    SerializedSizeOut,
    SerializeBuffer,
    DeserializeBuffer,
    GetStatusOut,
    GetRealStatusOut,
    GetBooleanStatusOut,
}

impl NullArg {
    pub const ALL: [NullArg; 18] = [
        NullArg::GetRealValues,
        NullArg::SetRealValues,
        NullArg::GetIntegerValues,
        NullArg::SetIntegerValues,
        NullArg::GetBooleanValues,
        NullArg::SetBooleanValues,
        NullArg::GetStringValues,
        NullArg::SetStringValues,
        NullArg::SetDebugLoggingCategories,
        NullArg::GetFmuStateOut,
        NullArg::SetFmuState,
        NullArg::FreeFmuStateOut,
        NullArg::SerializedSizeOut,
        NullArg::SerializeBuffer,
        NullArg::DeserializeBuffer,
        NullArg::GetStatusOut,
        NullArg::GetRealStatusOut,
        NullArg::GetBooleanStatusOut,
    ];
}

/// The remaining calls of the API as safe methods (the fuzzer reaches all 34 functions).
impl RawInstance {
    pub fn get_string(&mut self, vrs: &[u32]) -> Fmi2Status {
        let mut out: Vec<Fmi2String> = vec![std::ptr::null(); vrs.len()];
        // SAFETY: both arrays have `len` elements.
        unsafe { (self.lib.api.get_string)(self.c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr()) }
    }
    pub fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Fmi2Status {
        assert_eq!(vrs.len(), values.len(), "one value per value reference");
        let owned: Vec<CString> = values.iter().map(|v| CString::new(*v).unwrap_or_default()).collect();
        let ptrs: Vec<Fmi2String> = owned.iter().map(|c| c.as_ptr()).collect();
        // SAFETY: both arrays have `len` elements; the strings outlive the call.
        unsafe { (self.lib.api.set_string)(self.c, vrs.as_ptr(), vrs.len(), ptrs.as_ptr()) }
    }
    pub fn get_directional_derivative(&mut self, unknown: &[u32], known: &[u32], dv_known: &[f64]) -> Fmi2Status {
        assert_eq!(known.len(), dv_known.len(), "one seed per known");
        let mut dv_unknown = vec![0.0; unknown.len()];
        // SAFETY: every array has the length passed with it.
        unsafe {
            (self.lib.api.get_directional_derivative)(
                self.c,
                unknown.as_ptr(),
                unknown.len(),
                known.as_ptr(),
                known.len(),
                dv_known.as_ptr(),
                dv_unknown.as_mut_ptr(),
            )
        }
    }
    pub fn set_real_input_derivatives(&mut self, vrs: &[u32], orders: &[i32], values: &[f64]) -> Fmi2Status {
        assert!(orders.len() == vrs.len() && values.len() == vrs.len(), "one order and value per reference");
        // SAFETY: every array has `len` elements.
        unsafe {
            (self.lib.api.set_real_input_derivatives)(self.c, vrs.as_ptr(), vrs.len(), orders.as_ptr(), values.as_ptr())
        }
    }
    pub fn get_real_output_derivatives(&mut self, vrs: &[u32], orders: &[i32]) -> Fmi2Status {
        assert_eq!(orders.len(), vrs.len(), "one order per reference");
        let mut out = vec![0.0; vrs.len()];
        // SAFETY: every array has `len` elements.
        unsafe {
            (self.lib.api.get_real_output_derivatives)(
                self.c,
                vrs.as_ptr(),
                vrs.len(),
                orders.as_ptr(),
                out.as_mut_ptr(),
            )
        }
    }
    pub fn cancel_step(&mut self) -> Fmi2Status {
        // SAFETY: valid component.
        unsafe { (self.lib.api.cancel_step)(self.c) }
    }
    pub fn get_status(&mut self, kind: Fmi2StatusKind) -> (Fmi2Status, Fmi2Status) {
        let mut v: Fmi2Status = -1;
        // SAFETY: valid out pointer.
        let s = unsafe { (self.lib.api.get_status)(self.c, kind, &mut v) };
        (s, v)
    }
    pub fn get_real_status(&mut self, kind: Fmi2StatusKind) -> (Fmi2Status, f64) {
        let mut v = f64::NAN;
        // SAFETY: valid out pointer.
        let s = unsafe { (self.lib.api.get_real_status)(self.c, kind, &mut v) };
        (s, v)
    }
    pub fn get_integer_status(&mut self, kind: Fmi2StatusKind) -> Fmi2Status {
        let mut v: Fmi2Integer = 0;
        // SAFETY: valid out pointer.
        unsafe { (self.lib.api.get_integer_status)(self.c, kind, &mut v) }
    }
    pub fn get_boolean_status(&mut self, kind: Fmi2StatusKind) -> (Fmi2Status, Fmi2Boolean) {
        let mut v: Fmi2Boolean = -1;
        // SAFETY: valid out pointer.
        let s = unsafe { (self.lib.api.get_boolean_status)(self.c, kind, &mut v) };
        (s, v)
    }
    pub fn get_string_status(&mut self, kind: Fmi2StatusKind) -> Fmi2Status {
        let mut v: Fmi2String = std::ptr::null();
        // SAFETY: valid out pointer.
        unsafe { (self.lib.api.get_string_status)(self.c, kind, &mut v) }
    }
    pub fn do_step_with(&mut self, t: f64, h: f64, no_set_prior: bool) -> Fmi2Status {
        // SAFETY: valid component.
        unsafe { (self.lib.api.do_step)(self.c, t, h, no_set_prior as Fmi2Boolean) }
    }
    /// fmi2SerializedFMUstateSize alone.
    pub fn serialized_fmu_state_size(&mut self, state: &FmuState) -> (Fmi2Status, usize) {
        let mut size = 0usize;
        // SAFETY: valid out pointer; the state is live.
        let s = unsafe { (self.lib.api.serialized_fmu_state_size)(self.c, state.0, &mut size) };
        (s, size)
    }
    /// fmi2SerializeFMUstate into a buffer of the caller's size (too small must be refused).
    pub fn serialize_fmu_state_into(&mut self, state: &FmuState, buf: &mut [u8]) -> Fmi2Status {
        // SAFETY: the buffer is valid for its length; the state is live.
        unsafe { (self.lib.api.serialize_fmu_state)(self.c, state.0, buf.as_mut_ptr() as *mut Fmi2Byte, buf.len()) }
    }
    /// fmi2DeSerializeFMUstate into an existing state object (reused, as FMI allows).
    pub fn deserialize_fmu_state_into(&mut self, bytes: &[u8], state: &FmuState) -> Fmi2Status {
        let mut p = state.0;
        // SAFETY: `bytes` is valid for its length; the state is live and stays the same object.
        unsafe { (self.lib.api.deserialize_fmu_state)(self.c, bytes.as_ptr() as *const Fmi2Byte, bytes.len(), &mut p) }
    }
    /// Forgets the instance's FMU states without freeing them, so that dropping the instance calls
    /// fmi2FreeInstance with states still allocated (which must then free them).
    pub fn forget_fmu_states(&mut self) {
        self.states.clear();
    }
    /// Number of FMU states this instance holds.
    pub fn fmu_state_count(&self) -> usize {
        self.states.len()
    }
    /// Calls the function behind `which` with that pointer NULL.
    pub fn call_with_null(&mut self, which: NullArg) -> Fmi2Status {
        let api = self.lib.api;
        let c = self.c;
        let vr = [0u32];
        let null_mut_f64: *mut f64 = std::ptr::null_mut();
        // SAFETY: the FMU must check each NULL; every other pointer is valid.
        unsafe {
            match which {
                NullArg::GetRealValues => (api.get_real)(c, vr.as_ptr(), 1, null_mut_f64),
                NullArg::SetRealValues => (api.set_real)(c, vr.as_ptr(), 1, std::ptr::null()),
                NullArg::GetIntegerValues => (api.get_integer)(c, vr.as_ptr(), 1, std::ptr::null_mut()),
                NullArg::SetIntegerValues => (api.set_integer)(c, vr.as_ptr(), 1, std::ptr::null()),
                NullArg::GetBooleanValues => (api.get_boolean)(c, vr.as_ptr(), 1, std::ptr::null_mut()),
                NullArg::SetBooleanValues => (api.set_boolean)(c, vr.as_ptr(), 1, std::ptr::null()),
                NullArg::GetStringValues => (api.get_string)(c, vr.as_ptr(), 1, std::ptr::null_mut()),
                NullArg::SetStringValues => (api.set_string)(c, vr.as_ptr(), 1, std::ptr::null()),
                NullArg::SetDebugLoggingCategories => (api.set_debug_logging)(c, 1, 2, std::ptr::null()),
                NullArg::GetFmuStateOut => (api.get_fmu_state)(c, std::ptr::null_mut()),
                NullArg::SetFmuState => (api.set_fmu_state)(c, std::ptr::null_mut()),
                NullArg::FreeFmuStateOut => (api.free_fmu_state)(c, std::ptr::null_mut()),
                NullArg::SerializedSizeOut => (api.serialized_fmu_state_size)(
                    c,
                    self.states.first().copied().unwrap_or(std::ptr::null_mut()),
                    std::ptr::null_mut(),
                ),
                NullArg::SerializeBuffer => (api.serialize_fmu_state)(
                    c,
                    self.states.first().copied().unwrap_or(std::ptr::null_mut()),
                    std::ptr::null_mut(),
                    4096,
                ),
                NullArg::DeserializeBuffer => {
                    let mut p: Fmi2FmuState = std::ptr::null_mut();
                    let s = (api.deserialize_fmu_state)(c, std::ptr::null(), 64, &mut p);
                    if !p.is_null() {
                        self.states.push(p);
                    }
                    s
                }
                NullArg::GetStatusOut => (api.get_status)(c, FMI2_DO_STEP_STATUS, std::ptr::null_mut()),
                NullArg::GetRealStatusOut => (api.get_real_status)(c, FMI2_LAST_SUCCESSFUL_TIME, null_mut_f64),
                NullArg::GetBooleanStatusOut => (api.get_boolean_status)(c, FMI2_TERMINATED, std::ptr::null_mut()),
            }
        }
    }
}

impl Drop for RawInstance {
    fn drop(&mut self) {
        // SAFETY: states and the component were made by this library and are freed once.
        unsafe {
            for mut p in std::mem::take(&mut self.states) {
                (self.lib.api.free_fmu_state)(self.c, &mut p);
            }
            (self.lib.api.free_instance)(self.c);
        }
    }
}
