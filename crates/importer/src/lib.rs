//! A safe importer for any packaged FMI 2.0 co-simulation FMU: open the `.fmu` as any importer
//! would (unzip, read modelDescription.xml, load `binaries/linux64/<id>.so`), list its variables,
//! make any number of instances, set/get by name, step, save and restore state. It knows nothing
//! of ThermoVIA: what it drives is the binary users load.
//!
//! - [`loader`]: the only module with `unsafe`: resolve the 34 symbols, wrap one instance's calls.
//! - [`model_description`]: read the parts of modelDescription.xml an importer needs.
//! - [`cosim`]: a master for several instances with exchanged signals.
//! - [`simulate`], [`info`]: `fmpy simulate` and `fmpy info` in Rust; [`table`]: numeric CSV.

#![deny(unsafe_code)]
// `!(x > 0.0)` is used on purpose: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod cosim;
pub mod info;
#[allow(unsafe_code)]
pub mod loader;
pub mod model_description;
pub mod simulate;
pub mod table;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

pub use model_description::{
    did_you_mean, DefaultExperiment, EnumerationItem, ModelDescription, VariableInfo, VariableType,
};

use crate::loader::{FmuState, Library, LogRecord, RawInstance};
use thermovia_fmi2::{FMI2_DISCARD, FMI2_OK, FMI2_WARNING};

/// What went wrong, with enough context to act on.
#[derive(Debug)]
pub enum HarnessError {
    /// The file could not be read or unpacked.
    Archive { path: PathBuf, reason: String },
    /// modelDescription.xml is missing or not understood.
    Description { path: PathBuf, reason: String },
    /// The binary could not be loaded, or a symbol is missing.
    Library { reason: String },
    /// No variable of that name; `close` lists similar names.
    UnknownVariable { name: String, close: Vec<String> },
    /// A call returned something other than fmi2OK; `log` holds what the FMU said.
    Call { call: String, status: i32, log: Vec<String> },
    /// The FMU refused or discarded a step.
    Discarded { time: f64, log: Vec<String> },
}

impl std::fmt::Display for HarnessError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            HarnessError::Archive { path, reason } => write!(f, "{}: {reason}", path.display()),
            HarnessError::Description { path, reason } => {
                write!(f, "{}: modelDescription.xml: {reason}", path.display())
            }
            HarnessError::Library { reason } => write!(f, "{reason}"),
            HarnessError::UnknownVariable { name, close } if close.is_empty() => {
                write!(f, "the FMU has no variable named {name:?}")
            }
            HarnessError::UnknownVariable { name, close } => {
                write!(f, "the FMU has no variable named {name:?} (did you mean {}?)", close.join(", "))
            }
            HarnessError::Call { call, status, log } => {
                write!(f, "{call} returned {}", status_name(*status))?;
                if !log.is_empty() {
                    write!(f, ": {}", log.join("; "))?;
                }
                Ok(())
            }
            HarnessError::Discarded { time, log } => {
                write!(f, "fmi2DoStep discarded at t = {time}: {}", log.join("; "))
            }
        }
    }
}

impl std::error::Error for HarnessError {}

pub fn status_name(s: i32) -> &'static str {
    ["fmi2OK", "fmi2Warning", "fmi2Discard", "fmi2Error", "fmi2Fatal", "fmi2Pending"]
        .get(s as usize)
        .copied()
        .unwrap_or("an unknown status")
}

/// An unpacked FMU with its binary loaded. The unpacked folder is removed on drop.
pub struct Fmu {
    pub path: PathBuf,
    pub description: Arc<ModelDescription>,
    lib: Arc<Library>,
    unpacked: PathBuf,
    resource_uri: String,
    instance_counter: AtomicU64,
}

impl Drop for Fmu {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.unpacked);
    }
}

fn unpack(path: &Path, into: &Path) -> Result<(), HarnessError> {
    let archive_err = |reason: String| HarnessError::Archive { path: path.to_path_buf(), reason };
    let file = std::fs::File::open(path).map_err(|e| {
        archive_err(if e.kind() == std::io::ErrorKind::NotFound {
            "no such file (build it with `cargo run --release -p fmu-build`)".into()
        } else {
            e.to_string()
        })
    })?;
    let mut zip = zip::ZipArchive::new(file).map_err(|e| archive_err(format!("not a valid FMU (zip) archive: {e}")))?;
    zip.extract(into).map_err(|e| archive_err(format!("cannot unpack: {e}")))
}

impl Fmu {
    /// Opens a `.fmu`: unpacks it to a private temporary folder, reads its description and loads
    /// its linux64 binary.
    pub fn open(path: impl AsRef<Path>) -> Result<Fmu, HarnessError> {
        static COUNTER: AtomicU64 = AtomicU64::new(0);
        let path = path.as_ref().to_path_buf();
        let unpacked = std::env::temp_dir().join(format!(
            "thermovia-fmu-{}-{}",
            std::process::id(),
            COUNTER.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&unpacked);
        let result = (|| {
            unpack(&path, &unpacked)?;
            let xml_path = unpacked.join("modelDescription.xml");
            let xml = std::fs::read_to_string(&xml_path).map_err(|e| HarnessError::Description {
                path: path.clone(),
                reason: format!("cannot read it from the archive: {e}"),
            })?;
            let description = ModelDescription::parse(&xml)
                .map_err(|reason| HarnessError::Description { path: path.clone(), reason })?;
            let so = unpacked.join("binaries").join("linux64").join(format!("{}.so", description.model_identifier));
            if !so.exists() {
                return Err(HarnessError::Archive {
                    path: path.clone(),
                    reason: format!("no binaries/linux64/{}.so in the archive", description.model_identifier),
                });
            }
            let lib = Library::load(&so).map_err(|reason| HarnessError::Library { reason })?;
            Ok((description, lib))
        })();
        match result {
            Ok((description, lib)) => Ok(Fmu {
                resource_uri: format!("file://{}", unpacked.join("resources").display()),
                path,
                description: Arc::new(description),
                lib,
                unpacked,
                instance_counter: AtomicU64::new(0),
            }),
            Err(e) => {
                let _ = std::fs::remove_dir_all(&unpacked);
                Err(e)
            }
        }
    }

    pub fn variable(&self, name: &str) -> Result<&VariableInfo, HarnessError> {
        self.description.variable(name)
    }

    pub fn library(&self) -> &Arc<Library> {
        &self.lib
    }

    /// The folder the archive was unpacked into (removed when the `Fmu` is dropped).
    pub fn unpacked_dir(&self) -> &Path {
        &self.unpacked
    }

    /// A new instance, named `<identifier>_<n>` unless `name` is given.
    pub fn instantiate(&self, name: Option<&str>) -> Result<Instance, HarnessError> {
        let n = self.instance_counter.fetch_add(1, Ordering::Relaxed);
        let name = name.map(str::to_string).unwrap_or_else(|| format!("{}_{n}", self.description.model_identifier));
        let raw = RawInstance::instantiate(&self.lib, &name, &self.description.guid, Some(&self.resource_uri), false)
            .map_err(|reason| HarnessError::Library { reason })?;
        Ok(Instance { raw, description: self.description.clone(), time: 0.0, name })
    }
}

/// A resolved variable: set/get without a name lookup in hot loops.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Handle {
    pub value_reference: u32,
    pub ty: VariableType,
}

/// One FMU instance. Every call is checked; failures carry the FMU's own log messages.
pub struct Instance {
    raw: RawInstance,
    description: Arc<ModelDescription>,
    time: f64,
    pub name: String,
}

impl Instance {
    #[inline]
    fn check(&mut self, call: &str, status: i32) -> Result<(), HarnessError> {
        if status == FMI2_OK || status == FMI2_WARNING {
            Ok(())
        } else {
            Err(self.failed(call, status))
        }
    }

    #[cold]
    #[inline(never)]
    fn failed(&mut self, call: &str, status: i32) -> HarnessError {
        let log = self.raw.take_log().into_iter().map(|r: LogRecord| r.message).collect();
        HarnessError::Call { call: format!("{call} on {}", self.name), status, log }
    }

    pub fn handle(&self, name: &str) -> Result<Handle, HarnessError> {
        let v = self.description.variable(name)?;
        Ok(Handle { value_reference: v.value_reference, ty: v.ty })
    }

    pub fn time(&self) -> f64 {
        self.time
    }

    /// fmi2SetupExperiment + enter and exit initialisation, after `parameters` are set by name.
    pub fn initialize(
        &mut self,
        start_time: f64,
        stop_time: Option<f64>,
        parameters: &[(&str, f64)],
    ) -> Result<(), HarnessError> {
        let s = self.raw.setup_experiment(None, start_time, stop_time);
        self.check("fmi2SetupExperiment", s)?;
        for (name, value) in parameters {
            self.set(name, *value)?;
        }
        let s = self.raw.enter_initialization_mode();
        self.check("fmi2EnterInitializationMode", s)?;
        let s = self.raw.exit_initialization_mode();
        self.check("fmi2ExitInitializationMode", s)?;
        self.time = start_time;
        Ok(())
    }

    pub fn set_handle(&mut self, h: Handle, value: f64) -> Result<(), HarnessError> {
        let s = match h.ty {
            VariableType::Real => self.raw.set_real(&[h.value_reference], &[value]),
            VariableType::Integer | VariableType::Enumeration => {
                if value.fract() != 0.0 {
                    return Err(HarnessError::Call {
                        call: format!("fmi2SetInteger on {}", self.name),
                        status: 3,
                        log: vec![format!("{value} is not an integer")],
                    });
                }
                self.raw.set_integer(&[h.value_reference], &[value as i32])
            }
            VariableType::Boolean => self.raw.set_boolean(&[h.value_reference], &[i32::from(value != 0.0)]),
            other => {
                return Err(HarnessError::Call {
                    call: format!("set on {}", self.name),
                    status: 3,
                    log: vec![format!("{other:?} variables are not supported by the harness")],
                })
            }
        };
        self.check("fmi2SetReal/Integer/Boolean", s)
    }

    pub fn get_handle(&mut self, h: Handle) -> Result<f64, HarnessError> {
        match h.ty {
            VariableType::Real => {
                let mut v = [0.0];
                let s = self.raw.get_real(&[h.value_reference], &mut v);
                self.check("fmi2GetReal", s)?;
                Ok(v[0])
            }
            VariableType::Boolean => {
                let mut v = [0];
                let s = self.raw.get_boolean(&[h.value_reference], &mut v);
                self.check("fmi2GetBoolean", s)?;
                Ok(if v[0] != 0 { 1.0 } else { 0.0 })
            }
            VariableType::String => Err(HarnessError::Call {
                call: format!("get on {}", self.name),
                status: 3,
                log: vec!["String variables are not supported by the harness".into()],
            }),
            VariableType::Integer | VariableType::Enumeration => {
                let mut v = [0];
                let s = self.raw.get_integer(&[h.value_reference], &mut v);
                self.check("fmi2GetInteger", s)?;
                Ok(v[0] as f64)
            }
        }
    }

    /// Sets a Real, Integer, Enumeration or Boolean (≠ 0 is true) variable by name.
    pub fn set(&mut self, name: &str, value: f64) -> Result<(), HarnessError> {
        let h = self.handle(name)?;
        self.set_handle(h, value)
    }

    pub fn get(&mut self, name: &str) -> Result<f64, HarnessError> {
        let h = self.handle(name)?;
        self.get_handle(h)
    }

    /// Several Real variables in one call (value references from `handle`).
    pub fn get_reals(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), HarnessError> {
        let s = self.raw.get_real(vrs, out);
        self.check("fmi2GetReal", s)
    }

    pub fn set_reals(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), HarnessError> {
        let s = self.raw.set_real(vrs, values);
        self.check("fmi2SetReal", s)
    }

    /// One communication step from the current time.
    pub fn step(&mut self, h: f64) -> Result<(), HarnessError> {
        let s = self.raw.do_step(self.time, h);
        if s == FMI2_DISCARD {
            let log = self.raw.take_log().into_iter().map(|r| r.message).collect();
            let (_, t) = self.raw.get_real_status_last_successful_time();
            return Err(HarnessError::Discarded { time: t, log });
        }
        self.check("fmi2DoStep", s)?;
        self.time += h;
        Ok(())
    }

    pub fn terminate(&mut self) -> Result<(), HarnessError> {
        let s = self.raw.terminate();
        self.check("fmi2Terminate", s)
    }

    pub fn reset(&mut self) -> Result<(), HarnessError> {
        let s = self.raw.reset();
        self.time = 0.0;
        self.check("fmi2Reset", s)
    }

    /// Saves the complete state (with the harness's clock).
    pub fn save_state(&mut self) -> Result<SavedState, HarnessError> {
        let st = self.raw.get_fmu_state(None).map_err(|s| self.call_error("fmi2GetFMUstate", s))?;
        Ok(SavedState { state: st, time: self.time })
    }

    pub fn restore_state(&mut self, saved: &SavedState) -> Result<(), HarnessError> {
        let s = self.raw.set_fmu_state(&saved.state);
        self.check("fmi2SetFMUstate", s)?;
        self.time = saved.time;
        Ok(())
    }

    pub fn serialize_state(&mut self, saved: &SavedState) -> Result<Vec<u8>, HarnessError> {
        self.raw.serialize_fmu_state(&saved.state).map_err(|s| self.call_error("fmi2SerializeFMUstate", s))
    }

    /// Reads a serialized state; `time` is the communication time it was taken at.
    pub fn deserialize_state(&mut self, bytes: &[u8], time: f64) -> Result<SavedState, HarnessError> {
        let st = self.raw.deserialize_fmu_state(bytes).map_err(|s| self.call_error("fmi2DeSerializeFMUstate", s))?;
        Ok(SavedState { state: st, time })
    }

    fn call_error(&mut self, call: &str, status: i32) -> HarnessError {
        let log = self.raw.take_log().into_iter().map(|r| r.message).collect();
        HarnessError::Call { call: format!("{call} on {}", self.name), status, log }
    }

    /// The underlying instance, for conformance tests that need raw calls.
    pub fn raw_mut(&mut self) -> &mut RawInstance {
        &mut self.raw
    }
}

/// A saved FMU state; freed with its instance.
pub struct SavedState {
    state: FmuState,
    pub time: f64,
}
