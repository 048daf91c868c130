//! One FMU instance as safe Rust: the FMI 2.0 co-simulation state machine, argument checks,
//! variable dispatch through the variable table, and logging. The C entry points in `export`
//! only convert pointers and delegate here.

use crate::description::guid;
use crate::variables::{by_reference, Access, BaseType, Causality, Variability, Variable, VARIABLES};
use thermovia_model::{Model, STATE_LEN};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(i32)]
pub enum Status {
    Ok = 0,
    Warning = 1,
    Discard = 2,
    Error = 3,
    Fatal = 4,
    Pending = 5,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    Instantiated = 1,
    InitializationMode = 2,
    StepComplete = 4,
    StepFailed = 8,
    Terminated = 16,
    Error = 32,
    Fatal = 64,
}

impl Phase {
    fn from_bits(b: u8) -> Option<Phase> {
        [
            Phase::Instantiated,
            Phase::InitializationMode,
            Phase::StepComplete,
            Phase::StepFailed,
            Phase::Terminated,
            Phase::Error,
            Phase::Fatal,
        ]
        .into_iter()
        .find(|p| *p as u8 == b)
    }
}

/// Where each function may be called (FMI 2.0 §4.2.4 state machine, as in the Reference FMUs).
pub mod allowed {
    use super::Phase::*;
    const fn m(p: super::Phase) -> u8 {
        p as u8
    }
    pub const ANY_BUT_FATAL: u8 =
        m(Instantiated) | m(InitializationMode) | m(StepComplete) | m(StepFailed) | m(Terminated) | m(Error);
    pub const SETUP: u8 = m(Instantiated);
    pub const ENTER_INIT: u8 = m(Instantiated);
    pub const EXIT_INIT: u8 = m(InitializationMode);
    pub const TERMINATE: u8 = m(StepComplete) | m(StepFailed);
    pub const GET: u8 = m(InitializationMode) | m(StepComplete) | m(StepFailed) | m(Terminated) | m(Error);
    pub const SET: u8 = m(Instantiated) | m(InitializationMode) | m(StepComplete);
    pub const DO_STEP: u8 = m(StepComplete);
    pub const STATUS: u8 = m(StepComplete) | m(StepFailed) | m(Terminated);
    pub const FMU_STATE: u8 = ANY_BUT_FATAL;
}

/// Every function that takes an instance, with the phases it may be called in: one table, checked in
/// one place on entry (`export::with_instance`), as the Reference FMUs' fmi2Functions.c does. The
/// methods below assume the check was made.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Function {
    SetDebugLogging,
    SetupExperiment,
    EnterInitializationMode,
    ExitInitializationMode,
    Terminate,
    Reset,
    GetReal,
    GetInteger,
    GetBoolean,
    GetString,
    SetReal,
    SetInteger,
    SetBoolean,
    SetString,
    GetFmuState,
    SetFmuState,
    FreeFmuState,
    SerializedFmuStateSize,
    SerializeFmuState,
    DeSerializeFmuState,
    GetDirectionalDerivative,
    SetRealInputDerivatives,
    GetRealOutputDerivatives,
    DoStep,
    CancelStep,
    GetStatus,
    GetRealStatus,
    GetIntegerStatus,
    GetBooleanStatus,
    GetStringStatus,
}

impl Function {
    /// (C name, allowed phases)
    pub fn entry(self) -> (&'static str, u8) {
        use allowed::*;
        use Function::*;
        match self {
            SetDebugLogging => ("fmi2SetDebugLogging", ANY_BUT_FATAL),
            SetupExperiment => ("fmi2SetupExperiment", SETUP),
            EnterInitializationMode => ("fmi2EnterInitializationMode", ENTER_INIT),
            ExitInitializationMode => ("fmi2ExitInitializationMode", EXIT_INIT),
            Terminate => ("fmi2Terminate", TERMINATE),
            Reset => ("fmi2Reset", ANY_BUT_FATAL),
            GetReal => ("fmi2GetReal", GET),
            GetInteger => ("fmi2GetInteger", GET),
            GetBoolean => ("fmi2GetBoolean", GET),
            GetString => ("fmi2GetString", GET),
            SetReal => ("fmi2SetReal", SET),
            SetInteger => ("fmi2SetInteger", SET),
            SetBoolean => ("fmi2SetBoolean", SET),
            SetString => ("fmi2SetString", SET),
            GetFmuState => ("fmi2GetFMUstate", FMU_STATE),
            SetFmuState => ("fmi2SetFMUstate", FMU_STATE),
            FreeFmuState => ("fmi2FreeFMUstate", FMU_STATE),
            SerializedFmuStateSize => ("fmi2SerializedFMUstateSize", FMU_STATE),
            SerializeFmuState => ("fmi2SerializeFMUstate", FMU_STATE),
            DeSerializeFmuState => ("fmi2DeSerializeFMUstate", FMU_STATE),
            GetDirectionalDerivative => ("fmi2GetDirectionalDerivative", ANY_BUT_FATAL),
            SetRealInputDerivatives => ("fmi2SetRealInputDerivatives", ANY_BUT_FATAL),
            GetRealOutputDerivatives => ("fmi2GetRealOutputDerivatives", ANY_BUT_FATAL),
            DoStep => ("fmi2DoStep", DO_STEP),
            CancelStep => ("fmi2CancelStep", ANY_BUT_FATAL),
            GetStatus => ("fmi2GetStatus", STATUS),
            GetRealStatus => ("fmi2GetRealStatus", STATUS),
            GetIntegerStatus => ("fmi2GetIntegerStatus", STATUS),
            GetBooleanStatus => ("fmi2GetBooleanStatus", STATUS),
            GetStringStatus => ("fmi2GetStringStatus", STATUS),
        }
    }
}

pub const LOG_EVENTS: u8 = 1;
pub const LOG_WARNING: u8 = 2;
pub const LOG_DISCARD: u8 = 4;
pub const LOG_ERROR: u8 = 8;
pub const LOG_FATAL: u8 = 16;
const LOG_ALL: u8 = 31;

fn category_bit(name: &str) -> Option<u8> {
    Some(match name {
        "logEvents" => LOG_EVENTS,
        "logStatusWarning" => LOG_WARNING,
        "logStatusDiscard" => LOG_DISCARD,
        "logStatusError" => LOG_ERROR,
        "logStatusFatal" => LOG_FATAL,
        "logAll" => LOG_ALL,
        _ => return None,
    })
}

/// Receives (status, category, message); the C layer forwards it to the importer's logger.
pub type LogSink = Box<dyn Fn(Status, &str, &str)>;

/// Everything an FMU state holds: restoring it makes a run continue bit-identically.
///
/// What a state may hold is defined once, here and in [`validate`], and the runtime keeps it:
/// - `start_time ≤ time`, and `time ≤ stop_time + time_tolerance(stop_time)` when there is a stop time;
/// - `time` never decreases (a step ends at `max(t + h, time)`, a stop at `max(stop, time)`);
/// - in phase Instantiated, `time == start_time`;
/// - fmi2LastSuccessfulTime is `time`, on every path (an OK step, a discarded step, a refused step,
///   a step too short to resolve): a step that fails leaves the state, time included, as it was, so
///   no second clock is stored that could disagree with the first.
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    pub model: Model,
    pub phase: Phase,
    pub time: f64,
    pub start_time: f64,
    pub stop_time: Option<f64>,
    pub terminated: bool,
}

/// How far a communication point may be from the FMU's time `now` and still be accepted as `now`
/// (and how far a time may pass the stop time): a relative 1e-9, absolute below 1 s. The step check
/// and the state check both use it.
pub fn time_tolerance(now: f64) -> f64 {
    1e-9 * now.abs().max(1.0)
}

impl Snapshot {
    /// The state right after fmi2Instantiate (and after fmi2Reset).
    pub fn initial() -> Snapshot {
        Snapshot {
            model: Model::default(),
            phase: Phase::Instantiated,
            time: 0.0,
            start_time: 0.0,
            stop_time: None,
            terminated: false,
        }
    }
}

pub struct Component {
    pub name: String,
    log: LogSink,
    initial_logging_on: bool,
    logging_on: bool,
    categories: u8,
    pub(crate) s: Snapshot,
    last_step_status: Status,
    /// Addresses of the FMU states this instance allocated and has not freed: the C layer
    /// trusts a state pointer only if it is here, and fmi2FreeInstance frees what is left.
    pub(crate) live_states: std::collections::HashSet<usize>,
}

/// Longest part of a caller's string that a log message quotes.
pub const QUOTE_MAX_CHARS: usize = 200;

/// A caller's string as a log message shows it: quoted with escapes, cut to
/// [`QUOTE_MAX_CHARS`] characters (saying how long it was), so no input makes a message long.
pub fn quoted(s: &str) -> String {
    let n = s.chars().count();
    if n <= QUOTE_MAX_CHARS {
        format!("{s:?}")
    } else {
        let head: String = s.chars().take(QUOTE_MAX_CHARS).collect();
        format!("{head:?}… ({n} characters)")
    }
}

/// Decodes an `fmuResourceLocation` URI (`file:///abs`, `file:/abs`, `file://localhost/abs`,
/// percent-escapes, trailing slash) into a path.
pub fn resource_path_from_uri(uri: &str) -> Result<std::path::PathBuf, String> {
    let rest = uri
        .strip_prefix("file://localhost/")
        .map(|r| format!("/{r}"))
        .or_else(|| uri.strip_prefix("file:///").map(|r| format!("/{r}")))
        .or_else(|| uri.strip_prefix("file:/").map(|r| format!("/{r}")))
        .ok_or_else(|| format!("fmuResourceLocation {} is not a file: URI", quoted(uri)))?;
    let bytes = rest.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = rest.get(i + 1..i + 3).ok_or_else(|| format!("truncated %-escape in {}", quoted(uri)))?;
            out.push(
                u8::from_str_radix(hex, 16).map_err(|_| format!("bad %-escape {} in {}", quoted(hex), quoted(uri)))?,
            );
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    let s = String::from_utf8(out).map_err(|_| format!("{} is not UTF-8 after decoding", quoted(uri)))?;
    Ok(std::path::PathBuf::from(s.trim_end_matches('/').to_string()))
}

impl Component {
    /// `fmi2Instantiate` after the C layer has read its strings. Err carries the reason, already
    /// suitable for the logger.
    pub fn new(
        name: &str,
        fmu_type: i32,
        fmu_guid: &str,
        resource_location: Option<&str>,
        log: LogSink,
        logging_on: bool,
    ) -> Result<Component, String> {
        if name.is_empty() {
            return Err("fmi2Instantiate: instanceName is empty".into());
        }
        if fmu_type != 1 {
            return Err(format!(
                "fmi2Instantiate: fmuType {fmu_type} requested, but this FMU supports only fmi2CoSimulation (1)"
            ));
        }
        if fmu_guid != guid() {
            return Err(format!(
                "fmi2Instantiate: GUID {} does not match this binary's {:?} (modelDescription.xml from another build?)",
                quoted(fmu_guid),
                guid()
            ));
        }
        if let Some(uri) = resource_location {
            // The model needs no resources; a malformed location is still worth a word.
            resource_path_from_uri(uri).map_err(|e| format!("fmi2Instantiate: {e}"))?;
        }
        Ok(Component {
            name: name.chars().take(QUOTE_MAX_CHARS).collect(),
            log,
            initial_logging_on: logging_on,
            logging_on,
            categories: LOG_ALL,
            s: Snapshot::initial(),
            last_step_status: Status::Ok,
            live_states: Default::default(),
        })
    }

    pub fn phase(&self) -> Phase {
        self.s.phase
    }

    pub fn model(&self) -> &Model {
        &self.s.model
    }

    /// Debug messages honour loggingOn and the categories; discards, errors and fatals are always
    /// passed on, since they explain a return status the importer must act on.
    fn emit(&self, status: Status, category: &str, bit: u8, msg: &str) {
        if status as i32 >= Status::Discard as i32 || (self.logging_on && self.categories & bit != 0) {
            (self.log)(status, category, msg);
        }
    }

    pub fn log_event(&self, msg: &str) {
        self.emit(Status::Ok, "logEvents", LOG_EVENTS, msg);
    }

    /// Logs an error and moves to the Error state (FMI 2.0: after fmi2Error only Get*, Reset,
    /// FreeInstance and SetFMUstate are allowed).
    pub fn error(&mut self, msg: &str) -> Status {
        // Errors are always reported, even with logging off: they say why a call failed.
        (self.log)(Status::Error, "logStatusError", msg);
        if self.s.phase != Phase::Fatal {
            self.s.phase = Phase::Error;
        }
        Status::Error
    }

    pub fn fatal(&mut self, msg: &str) -> Status {
        (self.log)(Status::Fatal, "logStatusFatal", msg);
        self.s.phase = Phase::Fatal;
        Status::Fatal
    }

    /// Checks the state machine; on an illegal call logs why and returns Err(Error).
    #[inline]
    pub fn check(&mut self, function: &str, mask: u8) -> Result<(), Status> {
        if self.s.phase as u8 & mask != 0 {
            Ok(())
        } else {
            Err(self.not_allowed(function))
        }
    }

    // Error paths out of line (here and below), so the calls every step makes stay short.
    #[cold]
    #[inline(never)]
    fn not_allowed(&mut self, function: &str) -> Status {
        let phase = self.s.phase;
        self.error(&format!("{function}: not allowed in state {phase:?}"))
    }

    pub fn set_debug_logging(&mut self, on: bool, categories: &[&str]) -> Status {
        let mut mask = 0;
        for c in categories {
            match category_bit(c) {
                Some(b) => mask |= b,
                None => return self.error(&format!("fmi2SetDebugLogging: unknown log category {}", quoted(c))),
            }
        }
        self.logging_on = on;
        self.categories = if categories.is_empty() { LOG_ALL } else { mask };
        Status::Ok
    }

    pub fn setup_experiment(&mut self, tolerance: Option<f64>, start: f64, stop: Option<f64>) -> Status {
        if !start.is_finite() {
            return self.error(&format!("fmi2SetupExperiment: startTime {start} is not finite"));
        }
        if let Some(t) = stop {
            if t.is_nan() || t < start {
                return self.error(&format!("fmi2SetupExperiment: stopTime {t} is before startTime {start}"));
            }
        }
        // A stopTime of +inf bounds nothing: it is kept as "no stop time", so every state the FMU
        // saves has a finite (or no) stop time and restores (FMI 2.0 §2.1.8).
        let stop = stop.filter(|t| t.is_finite());
        if let Some(tol) = tolerance {
            if !(tol > 0.0 && tol.is_finite()) {
                return self.error(&format!("fmi2SetupExperiment: tolerance {tol} is not positive"));
            }
            self.log_event(&format!("tolerance {tol} noted; the adaptive solver uses the parameter solver_tolerance"));
        }
        self.s.start_time = start;
        self.s.time = start;
        self.s.stop_time = stop;
        Status::Ok
    }

    /// A state-machine transition: optionally re-derive initial states, move, log.
    fn transition(&mut self, to: Phase, initialize: bool, event: &str) -> Status {
        if initialize {
            self.s.model.initialize();
        }
        self.s.phase = to;
        self.log_event(event);
        Status::Ok
    }

    pub fn enter_initialization_mode(&mut self) -> Status {
        self.transition(Phase::InitializationMode, true, "entered initialization mode")
    }

    pub fn exit_initialization_mode(&mut self) -> Status {
        self.transition(Phase::StepComplete, true, "exited initialization mode")
    }

    pub fn terminate(&mut self) -> Status {
        self.transition(Phase::Terminated, false, "terminated")
    }

    pub fn reset(&mut self) -> Status {
        self.s = Snapshot::initial();
        self.logging_on = self.initial_logging_on;
        self.categories = LOG_ALL;
        self.last_step_status = Status::Ok;
        self.log_event("reset to the state after instantiation");
        Status::Ok
    }

    #[inline]
    fn lookup(&mut self, function: &str, ty: BaseType, vr: u32) -> Result<&'static Variable, Status> {
        match by_reference(ty, vr) {
            Some(v) => Ok(v),
            None => Err(self.unknown_reference(function, ty, vr)),
        }
    }

    #[cold]
    #[inline(never)]
    fn unknown_reference(&mut self, function: &str, ty: BaseType, vr: u32) -> Status {
        self.error(&format!("{function}: unknown value reference {vr} for type {ty:?}"))
    }

    pub fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Status {
        for (vr, slot) in vrs.iter().zip(out.iter_mut()) {
            match self.lookup("fmi2GetReal", BaseType::Real, *vr) {
                Ok(v) => match v.access {
                    Access::Real { get, .. } => {
                        *slot = get(&mut self.s.model);
                        if !slot.is_finite() {
                            // Never reached by a state this FMU computed (fmi2DoStep discards a step
                            // that would make an output non-finite); the guard keeps the promise.
                            return self.nonfinite_output(v, *slot);
                        }
                    }
                    Access::Integer { .. } => unreachable!("looked up as Real"),
                },
                Err(s) => return s,
            }
        }
        Status::Ok
    }

    #[cold]
    #[inline(never)]
    fn nonfinite_output(&mut self, v: &Variable, x: f64) -> Status {
        self.error(&format!("fmi2GetReal: {} is {x}, not a finite number", v.name))
    }

    pub fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Status {
        for (vr, slot) in vrs.iter().zip(out.iter_mut()) {
            match self.lookup("fmi2GetInteger", BaseType::Integer, *vr) {
                Ok(v) => match v.access {
                    Access::Integer { get, .. } => *slot = get(&mut self.s.model),
                    Access::Real { .. } => unreachable!("looked up as Integer"),
                },
                Err(s) => return s,
            }
        }
        Status::Ok
    }

    /// Types with no variables: any value reference is unknown.
    pub fn no_variables_of_type(&mut self, function: &str, vrs: &[u32]) -> Status {
        match vrs.first() {
            None => Status::Ok,
            Some(vr) => {
                self.error(&format!("{function}: unknown value reference {vr}: this FMU has no variables of that type"))
            }
        }
    }

    /// Checks that `v` may be written now, with value `x`.
    #[inline]
    fn check_write(&mut self, function: &str, v: &Variable, x: f64) -> Result<(), Status> {
        let writable = match v.causality {
            Causality::Output | Causality::CalculatedParameter => false,
            Causality::Parameter => !(v.variability == Variability::Fixed && self.s.phase == Phase::StepComplete),
            _ => true,
        };
        if writable && v.check_range(x).is_ok() {
            if v.causality == Causality::Parameter {
                if let Some(why) = self.parameter_conflict(v, x) {
                    return Err(self.error(&format!("{function}: {why}; nothing was set")));
                }
            }
            return Ok(());
        }
        Err(self.refused_write(function, v, x))
    }

    /// Why writing `x` to parameter `v` would leave parameters that cannot run together
    /// ([`thermovia_model::Params::conflict`]), refused at the write so that every accepted set of
    /// parameters initialises. The write is tried through the variable's own setter on a copy of
    /// the model's parameters, so no parameter's meaning is repeated here.
    #[cold]
    fn parameter_conflict(&self, v: &Variable, x: f64) -> Option<String> {
        let mut m = thermovia_model::Model::with_params_only(self.s.model.params().clone());
        match v.access {
            Access::Real { set: Some(set), .. } => set(&mut m, x),
            Access::Integer { set: Some(set), .. } => set(&mut m, x as i32),
            _ => return None,
        }
        m.params().conflict()
    }

    #[cold]
    #[inline(never)]
    fn refused_write(&mut self, function: &str, v: &Variable, x: f64) -> Status {
        let phase = self.s.phase;
        let why = match (v.causality, v.variability, phase) {
            (Causality::Output, _, _) => Some(format!("{} is an output and cannot be set", v.name)),
            (Causality::CalculatedParameter, _, _) => {
                Some(format!("{} is a calculated parameter: set the parameters it is derived from", v.name))
            }
            (Causality::Parameter, Variability::Fixed, Phase::StepComplete) => Some(format!(
                "{} is a fixed parameter: set it before fmi2ExitInitializationMode (or after fmi2Reset)",
                v.name
            )),
            _ => None,
        };
        if let Some(why) = why {
            return self.error(&format!("{function}: {why}"));
        }
        match v.check_range(x) {
            Err(e) => self.error(&format!("{function}: {e}; nothing was set")),
            // check_write's fast path and these cases agree; kept total all the same
            Ok(()) => self.error(&format!("{function}: {} cannot be set now", v.name)),
        }
    }

    /// Sets values, all or none: every value is checked before any is written.
    fn set_values(&mut self, function: &str, ty: BaseType, vrs: &[u32], values: &[f64]) -> Status {
        for (vr, x) in vrs.iter().zip(values) {
            let v = match self.lookup(function, ty, *vr) {
                Ok(v) => v,
                Err(s) => return s,
            };
            if let Err(s) = self.check_write(function, v, *x) {
                return s;
            }
        }
        let mut parameter_written = false;
        for (vr, x) in vrs.iter().zip(values) {
            let v = by_reference(ty, *vr).expect("checked in the first pass");
            match v.access {
                Access::Real { set: Some(set), .. } => set(&mut self.s.model, *x),
                Access::Integer { set: Some(set), .. } => set(&mut self.s.model, *x as i32),
                _ => unreachable!("outputs refused in check_write"),
            }
            parameter_written |= v.causality == Causality::Parameter;
        }
        if parameter_written && matches!(self.s.phase, Phase::Instantiated | Phase::InitializationMode) {
            // Initial states follow their parameters until initialisation ends.
            self.s.model.initialize();
        }
        Status::Ok
    }

    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Status {
        self.set_values("fmi2SetReal", BaseType::Real, vrs, values)
    }

    pub fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Status {
        let as_f64: Vec<f64> = values.iter().map(|&v| v as f64).collect();
        self.set_values("fmi2SetInteger", BaseType::Integer, vrs, &as_f64)
    }

    pub fn do_step(&mut self, t: f64, h: f64) -> Status {
        if !(h > 0.0 && h.is_finite()) {
            return self.error(&format!("fmi2DoStep: communicationStepSize {h} must be positive and finite"));
        }
        let now = self.s.time;
        if !t.is_finite() || (t - now).abs() > time_tolerance(now) {
            return self
                .error(&format!("fmi2DoStep: currentCommunicationPoint {t} does not match the FMU's time {now}"));
        }
        // The step ends where the master's clock says, t + h, so the FMU's time never drifts from
        // the master's; but never before `now` (t may lie below `now` within the tolerance, by more
        // than a tiny h), so time never runs backwards and never falls below the start time. The
        // model advances by exactly the h the master passed ((t + h) − t may differ from h in the
        // last bit), unless stopTime cuts the step short.
        let (mut end, mut advance) = ((t + h).max(now), h);
        let mut status = Status::Ok;
        if let Some(stop) = self.s.stop_time {
            if end > stop + time_tolerance(stop) {
                (end, advance) = (stop.max(now), stop - now);
                status = Status::Discard;
            }
        }
        // A stop time closer than the model resolves is reached without integrating.
        let stop_within_resolution = status == Status::Discard && advance < thermovia_model::MIN_RESOLVABLE_STEP;
        if advance > 0.0 && !stop_within_resolution {
            // The states alone (the caches follow them): cheap enough for every step.
            let m = &self.s.model;
            let before = m.state();
            let outcome =
                self.s.model.step(advance).map_err(|f| f.to_string()).and_then(|()| {
                    match nonfinite_after_step(&mut self.s.model) {
                        Some((name, x)) => Err(format!("output {name} would be {x}")),
                        None => Ok(()),
                    }
                });
            if let Err(why) = outcome {
                let m = &mut self.s.model;
                m.set_state(&before);
                // The state and its time stay as they were: the last successful time is `now`.
                self.s.phase = Phase::StepFailed;
                self.last_step_status = Status::Discard;
                self.emit(
                    Status::Discard,
                    "logStatusDiscard",
                    LOG_DISCARD,
                    &format!("fmi2DoStep: step from t = {t} by {h} discarded: {why}; state kept at t = {now}"),
                );
                return Status::Discard;
            }
        }
        self.s.time = end;
        if status == Status::Discard {
            self.s.phase = Phase::StepFailed;
            self.s.terminated = true;
            self.emit(
                Status::Discard,
                "logStatusDiscard",
                LOG_DISCARD,
                &format!("fmi2DoStep: step to {} passes stopTime {end}; stopped there (fmi2Terminated = true)", t + h),
            );
        }
        self.last_step_status = status;
        status
    }

    pub fn last_step_status(&self) -> Status {
        self.last_step_status
    }

    /// fmi2LastSuccessfulTime: the FMU's time, on every path (see [`Snapshot`]).
    pub fn last_successful_time(&self) -> f64 {
        self.s.time
    }

    pub fn terminated(&self) -> bool {
        self.s.terminated
    }

    pub fn unsupported(&mut self, function: &str, why: &str) -> Status {
        self.error(&format!("{function}: {why}"))
    }

    pub fn get_state(&self) -> Snapshot {
        self.s.clone()
    }

    pub fn set_state(&mut self, snapshot: &Snapshot) -> Status {
        self.s = snapshot.clone();
        self.log_event(&format!("FMU state restored at t = {}", self.s.time));
        Status::Ok
    }
}

/// The first output (in table order) that is not a finite number, with its value.
pub fn nonfinite_output(m: &mut Model) -> Option<(&'static str, f64)> {
    VARIABLES.iter().filter(|v| v.causality != Causality::Input && !v.has_start()).find_map(|v| {
        let x = match v.access {
            Access::Real { get, .. } => get(m),
            Access::Integer { get, .. } => get(m) as f64,
        };
        (!x.is_finite()).then_some((v.name, x))
    })
}

/// The outputs a successful `Model::step` can still leave non-finite, checked on every step (the
/// hot path: a few ns). `Model::step` has checked the mechanical states and the temperatures; the
/// moduli, the effective stiffness and damping and the melt fraction are bounded functions of the
/// PCL temperature whose bounds the parameter ranges keep finite (at most about 1e12 Pa, 2e15 N·m/rad
/// and 3e17 N·m·s/rad); what remains is the torque (a product with the states, which may overflow)
/// and the two energy integrals. `fmi2GetReal` refuses a non-finite value as the backstop.
fn nonfinite_after_step(m: &mut Model) -> Option<(&'static str, f64)> {
    if !m.transmitted_torque_is_finite() {
        return Some(("transmitted_torque", m.transmitted_torque()));
    }
    [("heater_energy", m.thermal.heater_energy), ("heat_lost", m.thermal.heat_lost)]
        .into_iter()
        .find(|(_, x)| !x.is_finite())
}

/// Checks a state by meaning, after its bytes passed the format checks: what a forged buffer
/// with a recomputed checksum could carry and this FMU could never have saved.
pub fn validate(s: &Snapshot) -> Result<(), String> {
    let finite = |x: f64, what: &str| if x.is_finite() { Ok(()) } else { Err(format!("{what} {x} is not finite")) };
    if s.phase == Phase::Fatal {
        return Err("the state is in phase Fatal, which no FMU state may restore".into());
    }
    finite(s.start_time, "start time")?;
    finite(s.time, "time")?;
    if s.time < s.start_time {
        return Err(format!("time {} is before start time {}", s.time, s.start_time));
    }
    if s.phase == Phase::Instantiated && s.time != s.start_time {
        return Err(format!("phase Instantiated at time {}, not at start time {}", s.time, s.start_time));
    }
    if let Some(stop) = s.stop_time {
        finite(stop, "stop time")?;
        if stop < s.start_time {
            return Err(format!("stop time {stop} is before start time {}", s.start_time));
        }
        if s.time > stop + time_tolerance(stop) {
            return Err(format!("time {} is after stop time {stop}", s.time));
        }
    }
    if s.terminated
        && (s.stop_time.is_none() || !matches!(s.phase, Phase::StepFailed | Phase::Terminated | Phase::Error))
    {
        return Err(format!("terminated in phase {:?} without reaching a stop time", s.phase));
    }
    let m = &s.model;
    if let Some(why) = m.params().conflict() {
        return Err(why);
    }
    for (i, x) in m.mechanics.iter().enumerate() {
        finite(*x, &format!("mechanical state {i}"))?;
    }
    let th = &m.thermal;
    finite(th.housing_temperature, "housing temperature")?;
    finite(th.pcl_temperature, "PCL temperature")?;
    if !(th.pcl_temperature > 0.0 && th.housing_temperature > 0.0) {
        // Model::step discards a step that would leave either at or below 0 K
        return Err(format!(
            "PCL temperature {} K and housing temperature {} K: both must be above 0 K",
            th.pcl_temperature, th.housing_temperature
        ));
    }
    finite(th.pcl_enthalpy, "PCL enthalpy")?;
    finite(th.heat_lost, "heat lost")?;
    if !(th.heater_energy.is_finite() && th.heater_energy >= 0.0) {
        return Err(format!("heater energy {} is not a finite non-negative number", th.heater_energy));
    }
    finite(th.pcl_structural_temperature, "PCL structural temperature")?;
    if !(th.pcl_crystallisation_integral >= 0.0 && th.pcl_crystallisation_integral.is_finite()) {
        return Err(format!("Nakamura's integral {} is not a finite number ≥ 0", th.pcl_crystallisation_integral));
    }
    if th.pcl_structural_temperature < th.pcl_temperature {
        return Err(format!(
            "PCL structural temperature {} K is below the PCL temperature {} K (more crystal than the heating branch holds)",
            th.pcl_structural_temperature, th.pcl_temperature
        ));
    }
    // On the heating branch the runtime keeps T_f = T exactly and T is h⁻¹(H); checking it through
    // h_s⁻¹(H − m L χ(T_f)) instead would weigh T's own inversion error by the latent heat's slope,
    // which a sharp melting step (width 1e-3 K) makes 1e5 J/K: a state the runtime reached, refused.
    let back = if th.pcl_structural_temperature == th.pcl_temperature {
        thermovia_model::thermal::pcl_temperature_from_enthalpy(m.params(), th.pcl_enthalpy, th.pcl_temperature)
    } else {
        thermovia_model::thermal::pcl_temperature_at(
            m.params(),
            th.pcl_enthalpy,
            th.pcl_structural_temperature,
            th.pcl_temperature,
        )
    };
    if (back - th.pcl_temperature).abs() > 1e-6 * th.pcl_temperature.abs().max(1.0) {
        return Err(format!(
            "PCL temperature {} K does not belong to PCL enthalpy {} J ({back} K)",
            th.pcl_temperature, th.pcl_enthalpy
        ));
    }
    // The adaptive solver's step guess grows at most fivefold beyond a sub-step.
    let step_max = 5.0 * m.params().max_internal_step * (1.0 + 1e-12);
    if !(m.adaptive_step >= 0.0 && m.adaptive_step <= step_max) {
        return Err(format!("adaptive step {} is outside [0, {step_max}]", m.adaptive_step));
    }
    if !m.sine_anchor.is_consistent() {
        let a = m.sine_anchor;
        return Err(format!(
            "gravity's sine anchor ({}, {}, {}) is not an angle with its sine and cosine",
            a.angle, a.sin, a.cos
        ));
    }
    if let Some((name, x)) = nonfinite_output(&mut m.clone()) {
        return Err(format!("output {name} would be {x}"));
    }
    Ok(())
}

// ---- serialized FMU state: versioned, pointer-free, checked ----

const MAGIC: &[u8; 8] = b"TVIAFMUS";
pub const STATE_FORMAT_VERSION: u32 = 7;

fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf29ce484222325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x100000001b3);
    }
    h
}

/// Layout: magic, format version (u32), GUID (u32 length + bytes), payload length (u64),
/// payload, FNV-1a 64 of everything before it. Little-endian throughout.
/// Payload: phase (u8), terminated (u8), has-stop (u8), time, start, stop (f64), then every parameter and input as (value reference u32, f64) in table order, then the
/// model's flat state vector (`Model::state`, `STATE_LEN` f64). The FMI layer knows nothing of what
/// the vector holds.
pub fn serialize(s: &Snapshot) -> Vec<u8> {
    let mut payload = Vec::new();
    payload.push(s.phase as u8);
    payload.push(s.terminated as u8);
    payload.push(s.stop_time.is_some() as u8);
    for x in [s.time, s.start_time, s.stop_time.unwrap_or(0.0)] {
        payload.extend_from_slice(&x.to_le_bytes());
    }
    let mut m = s.model.clone();
    for v in VARIABLES.iter().filter(|v| v.has_start()) {
        let x = match v.access {
            Access::Real { get, .. } => get(&mut m),
            Access::Integer { get, .. } => get(&mut m) as f64,
        };
        payload.extend_from_slice(&v.value_reference.to_le_bytes());
        payload.extend_from_slice(&x.to_le_bytes());
    }
    for x in s.model.state() {
        payload.extend_from_slice(&x.to_le_bytes());
    }
    let mut out = Vec::with_capacity(payload.len() + 96);
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&STATE_FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&(guid().len() as u32).to_le_bytes());
    out.extend_from_slice(guid().as_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&payload);
    let sum = fnv1a64(&out);
    out.extend_from_slice(&sum.to_le_bytes());
    out
}

struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8], String> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.b.len()).ok_or_else(|| {
            format!(
                "serialized state is truncated: {what} needs {n} bytes at offset {}, {} left",
                self.at,
                self.b.len() - self.at.min(self.b.len())
            )
        })?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u8(&mut self, what: &str) -> Result<u8, String> {
        Ok(self.take(1, what)?[0])
    }
    fn u32(&mut self, what: &str) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().expect("4 bytes")))
    }
    fn u64(&mut self, what: &str) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }
    fn f64(&mut self, what: &str) -> Result<f64, String> {
        Ok(f64::from_le_bytes(self.take(8, what)?.try_into().expect("8 bytes")))
    }
}

/// Reads a serialized state back, refusing anything not written by this build's interface.
pub fn deserialize(bytes: &[u8]) -> Result<Snapshot, String> {
    let mut r = Reader { b: bytes, at: 0 };
    if r.take(8, "magic")? != MAGIC {
        return Err("not a ThermoVIA FMU state (wrong magic bytes)".into());
    }
    let version = r.u32("format version")?;
    if version != STATE_FORMAT_VERSION {
        return Err(format!("state format version {version}, this build reads {STATE_FORMAT_VERSION}"));
    }
    let glen = r.u32("GUID length")? as usize;
    let g = r.take(glen, "GUID")?;
    if g != guid().as_bytes() {
        return Err(format!(
            "state was saved by an FMU with GUID {}, this is {:?}",
            quoted(&String::from_utf8_lossy(g)),
            guid()
        ));
    }
    let plen = r.u64("payload length")? as usize;
    let header_end = r.at;
    let expected_total = header_end.checked_add(plen).and_then(|x| x.checked_add(8));
    if expected_total != Some(bytes.len()) {
        return Err(format!("state length {} does not match its header ({:?} expected)", bytes.len(), expected_total));
    }
    let sum_at = bytes.len() - 8;
    let stored = u64::from_le_bytes(bytes[sum_at..].try_into().expect("8 bytes"));
    if stored != fnv1a64(&bytes[..sum_at]) {
        return Err("state checksum mismatch: the bytes were altered".into());
    }
    let phase_bits = r.u8("phase")?;
    let phase = Phase::from_bits(phase_bits).ok_or_else(|| format!("unknown phase {phase_bits}"))?;
    let flag = |r: &mut Reader, what: &str| match r.u8(what)? {
        0 => Ok(false),
        1 => Ok(true),
        b => Err(format!("{what} flag is {b}, not 0 or 1")),
    };
    let terminated = flag(&mut r, "terminated")?;
    let has_stop = flag(&mut r, "has stop time")?;
    let time = r.f64("time")?;
    let start_time = r.f64("start time")?;
    let stop = r.f64("stop time")?;
    let mut model = Model::default();
    for v in VARIABLES.iter().filter(|v| v.has_start()) {
        let vr = r.u32("value reference")?;
        if vr != v.value_reference {
            return Err(format!(
                "expected value reference {} ({}) in the state, found {vr}",
                v.value_reference, v.name
            ));
        }
        let x = r.f64(v.name)?;
        v.check_range(x)?;
        match v.access {
            Access::Real { set: Some(set), .. } => set(&mut model, x),
            Access::Integer { set: Some(set), .. } => set(&mut model, x as i32),
            _ => return Err(format!("{} is not settable", v.name)),
        }
    }
    let mut state = [0.0; STATE_LEN];
    for x in state.iter_mut() {
        *x = r.f64("model state")?;
    }
    model.set_state(&state);
    if r.at != sum_at {
        return Err(format!("{} unread bytes in the state payload", sum_at - r.at));
    }
    let snapshot = Snapshot { model, phase, time, start_time, stop_time: has_stop.then_some(stop), terminated };
    validate(&snapshot).map_err(|e| format!("the state is well-formed but impossible: {e}"))?;
    Ok(snapshot)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resource_uris_in_every_common_spelling() {
        for (uri, path) in [
            ("file:///tmp/fmu/resources", "/tmp/fmu/resources"),
            ("file:///tmp/fmu/resources/", "/tmp/fmu/resources"),
            ("file:/tmp/fmu/resources", "/tmp/fmu/resources"),
            ("file://localhost/tmp/a%20b/resources", "/tmp/a b/resources"),
        ] {
            assert_eq!(resource_path_from_uri(uri).unwrap(), std::path::PathBuf::from(path), "{uri}");
        }
        assert!(resource_path_from_uri("http://x/y").is_err());
        assert!(resource_path_from_uri("file:///a%2").is_err());
    }

    /// A state after 0.25 s with the heaters at `heater_power`, stop time 3 s.
    fn stepped(heater_power: f64) -> Snapshot {
        let mut m = Model::default();
        m.inputs.heater_power = heater_power;
        m.step(0.25).unwrap();
        Snapshot {
            model: m,
            phase: Phase::StepComplete,
            time: 0.25,
            start_time: 0.0,
            stop_time: Some(3.0),
            terminated: false,
        }
    }

    #[test]
    fn serialized_state_round_trips_and_refuses_damage() {
        let s = stepped(7.5);
        let bytes = serialize(&s);
        assert_eq!(deserialize(&bytes).unwrap(), s);
        assert!(deserialize(&bytes[..bytes.len() - 1]).unwrap_err().contains("length"));
        let mut flipped = bytes.clone();
        let mid = flipped.len() / 2;
        flipped[mid] ^= 0x10;
        assert!(deserialize(&flipped).unwrap_err().contains("checksum"));
        let mut other_version = bytes.clone();
        other_version[8] = 99;
        assert!(deserialize(&other_version).unwrap_err().contains("version"));
        assert!(deserialize(b"PNG\x89 not a state").is_err());
    }

    /// Rewrites `bytes` with `edit` applied to the payload and a recomputed checksum, as anyone
    /// can: the checksum catches damage, not forgery, so the meaning must be checked.
    fn forge(bytes: &[u8], edit: impl Fn(&mut [u8])) -> Vec<u8> {
        let payload_at = 8 + 4 + 4 + guid().len() + 8;
        let mut b = bytes.to_vec();
        let n = b.len();
        edit(&mut b[payload_at..n - 8]);
        let sum = fnv1a64(&b[..n - 8]);
        b[n - 8..].copy_from_slice(&sum.to_le_bytes());
        b
    }

    /// The fuzzer's finds (issue 31), each a state the runtime reached and the check refused:
    /// heating into a melting step 1e-3 K wide (the check re-split the latent heat at T_f = T; the
    /// inverse series ran ten widths out, 2.4e-3 K off), and a PCL of 1e-9 kg under 5.7 kW (the
    /// explicit thermal stages blew up to −1e305 K, finite: now a discarded step). Every state the
    /// runtime keeps, steps that fail included, restores.
    #[test]
    fn states_the_fuzzer_found_refused_now_restore() {
        type Case = (&'static [(&'static str, f64)], f64, &'static [f64]);
        let cases: [Case; 3] = [
            (
                &[
                    ("pcl_specific_heat_solid", 1.0),
                    ("pcl_melting_width", 1e-3),
                    ("crystallisation_nucleation_constant", 1e8),
                ],
                1.399550829980205e3,
                &[0.2],
            ),
            (
                &[
                    ("pcl_specific_heat_solid", 1.0),
                    ("initial_housing_temperature", 8.89418101276832e3),
                    ("pcl_melting_width", 1e-3),
                ],
                0.0,
                &[0.01],
            ),
            (&[("pcl_mass", 1e-9)], 5.733507033453997e3, &[0.001, 0.05]),
        ];
        for (i, (params, heater, steps)) in cases.iter().enumerate() {
            let mut m = Model::default();
            for (name, x) in params.iter() {
                match VARIABLES.iter().find(|v| v.name == *name).unwrap().access {
                    Access::Real { set: Some(set), .. } => set(&mut m, *x),
                    _ => unreachable!(),
                }
            }
            m.initialize();
            m.inputs.heater_power = *heater;
            let mut time = 0.0;
            for h in steps.iter() {
                if m.step(*h).is_ok() {
                    time += h;
                }
            }
            let s = Snapshot {
                model: m,
                phase: Phase::StepComplete,
                time,
                start_time: 0.0,
                stop_time: None,
                terminated: false,
            };
            let back = deserialize(&serialize(&s)).unwrap_or_else(|e| panic!("case {i}: {e}"));
            assert_eq!(back, s, "case {i}");
        }
    }

    #[test]
    fn forged_states_with_a_valid_checksum_are_refused_by_meaning() {
        let s = stepped(0.0);
        let bytes = serialize(&s);
        assert_eq!(deserialize(&forge(&bytes, |_| {})).unwrap(), s, "an untouched forge is the state itself");
        let f64_at = |k: usize| 3 + 8 * k; // time, start, stop
        let put = |p: &mut [u8], at: usize, x: f64| p[at..at + 8].copy_from_slice(&x.to_le_bytes());
        let cases: Vec<(&str, Vec<u8>)> = vec![
            ("phase Fatal", forge(&bytes, |p| p[0] = Phase::Fatal as u8)),
            ("flag", forge(&bytes, |p| p[1] = 7)),
            ("time NaN", forge(&bytes, |p| put(p, f64_at(0), f64::NAN))),
            ("time after stop", forge(&bytes, |p| put(p, f64_at(2), 0.1))),
            ("time before start", forge(&bytes, |p| put(p, f64_at(1), 0.3))),
            ("terminated", forge(&bytes, |p| p[1] = 1)),
            ("state NaN", {
                // the model's state vector closes the payload
                let states_at = bytes.len() - 8 - (8 + 4 + 4 + guid().len() + 8) - 8 * STATE_LEN;
                forge(&bytes, |p| put(p, states_at + 16, f64::NAN))
            }),
            ("gravity's sine anchor", {
                // [.., adaptive step, anchor angle, sine, cosine, T_f, θ, mean torque]: a sine without its angle
                let states_at = bytes.len() - 8 - (8 + 4 + 4 + guid().len() + 8) - 8 * STATE_LEN;
                forge(&bytes, |p| put(p, states_at + 8 * (STATE_LEN - 5), 0.5))
            }),
            ("crystallinity above the heating branch's", {
                // T_f below the PCL temperature (22 °C)
                let states_at = bytes.len() - 8 - (8 + 4 + 4 + guid().len() + 8) - 8 * STATE_LEN;
                forge(&bytes, |p| put(p, states_at + 8 * (STATE_LEN - 3), 250.0))
            }),
            ("negative Nakamura integral", {
                let states_at = bytes.len() - 8 - (8 + 4 + 4 + guid().len() + 8) - 8 * STATE_LEN;
                forge(&bytes, |p| put(p, states_at + 8 * (STATE_LEN - 2), -1.0))
            }),
        ];
        for (what, forged) in cases {
            let e = deserialize(&forged).expect_err(what);
            assert!(!e.contains("checksum") && !e.contains("length"), "{what}: {e}");
        }
    }
}
