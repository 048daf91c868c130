//! A black-box fuzzer of an FMI 2.0 co-simulation FMU through its C API, as the reliability audit
//! (issue 13) drove it: random call sequences over all 34 functions with legal, extreme and wrong
//! arguments, and invariant probes after the calls:
//!
//! - every status is one of fmi2OK … fmi2Fatal, and never fmi2Fatal (this FMU has no fatal path
//!   except a caught panic, which is a bug);
//! - whenever fmi2GetReal returns OK, every value is finite; after an OK or discarded fmi2DoStep
//!   every output is finite;
//! - fmi2SetReal / fmi2SetInteger are all-or-nothing: a refused set changes no value;
//! - time advances exactly: after an OK step LastSuccessfulTime = max(t + h, the FMU's time), after a
//!   discard it lies in [the FMU's time, t + h];
//! - an FMU state round-trips: serialize, deserialize, restore gives bit-identical outputs and bytes;
//! - every state the FMU writes restores: each fmi2GetFMUstate is serialized, deserialized into a
//!   fresh instance and restored there, and both instances continue bit-identically through a step
//!   (issue 31: starts at odd times, communication points within the time tolerance, denormal and
//!   tiny steps, discards at offset times and legal input edits are drawn on purpose);
//! - damaged or forged buffers (flipped bytes, truncation, a recomputed checksum over changed values)
//!   are refused, or, if accepted, leave an instance that keeps every other invariant;
//! - unsupported functions and NULL pointers return fmi2Error, never crash;
//! - no call runs longer than the watchdog (a hang) and no sequence kills its process (a crash).
//!
//! Each sequence runs in a child process (this crate's binary in `--child` mode) so that a crash or
//! a hang is contained and classified; the child's watchdog thread ends it when one call takes
//! longer than [`WATCHDOG`]. A failing sequence is shrunk by delta debugging to a few calls.
//! Everything is deterministic in the seed: sequence `k` of campaign seed `s` uses seed
//! `sequence_seed(s, k)`, and op `i` of a sequence is drawn from `(sequence seed, i)` alone, so
//! any subset of a sequence's ops replays exactly.

#![forbid(unsafe_code)]

use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use thermovia_fmi2::*;
use thermovia_importer::loader::{FmuState, Library, NullArg, RawInstance};
use thermovia_importer::model_description::{ModelDescription, VariableType};

/// Longest a single FMI call may take before the child reports a hang (default; `Launcher::watchdog`
/// sets another). The FMU's own budget keeps a step under about a second; the margin covers a
/// loaded CI machine.
pub const WATCHDOG: Duration = Duration::from_secs(10);

/// The child learns its watchdog from this environment variable (milliseconds).
const WATCHDOG_ENV: &str = "THERMOVIA_FUZZ_WATCHDOG_MS";

/// Ops per sequence (each op is one to a dozen calls).
pub const OPS_PER_SEQUENCE: usize = 120;

// ---- deterministic randomness ----

/// SplitMix64: small, fast, and good enough to pick calls.
#[derive(Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Rng {
        Rng(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
    pub fn chance(&mut self, p: f64) -> bool {
        self.unit() < p
    }
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn pick<'a, T>(&mut self, xs: &'a [T]) -> &'a T {
        &xs[self.below(xs.len())]
    }
}

pub fn sequence_seed(campaign_seed: u64, k: u64) -> u64 {
    Rng::new(campaign_seed ^ k.wrapping_mul(0xd134_2543_de82_ef95)).next_u64()
}

fn op_rng(seq_seed: u64, i: usize) -> Rng {
    Rng::new(sequence_seed(seq_seed, i as u64 + 1))
}

// ---- what the fuzzer knows of the FMU: its description ----

#[derive(Clone, Debug)]
pub struct Var {
    pub name: String,
    pub vr: u32,
    pub real: bool,
    pub settable: bool,
    pub input: bool,
    pub min: Option<f64>,
    pub max: Option<f64>,
}

pub struct Target {
    pub lib: Arc<Library>,
    pub guid: String,
    pub resource_uri: String,
    pub vars: Vec<Var>,
}

impl Target {
    /// Loads the binary and reads the description of an unpacked FMU folder.
    pub fn load(dir: &Path) -> Result<Target, String> {
        let xml = std::fs::read_to_string(dir.join("modelDescription.xml")).map_err(|e| e.to_string())?;
        let md = ModelDescription::parse(&xml)?;
        let so = dir.join("binaries").join("linux64").join(format!("{}.so", md.model_identifier));
        let lib = Library::load(&so)?;
        let num = |s: &Option<String>| s.as_deref().and_then(|x| x.parse::<f64>().ok());
        let vars = md
            .variables
            .iter()
            .map(|v| Var {
                name: v.name.clone(),
                vr: v.value_reference,
                real: v.ty == VariableType::Real,
                settable: matches!(v.causality.as_str(), "parameter" | "input"),
                input: v.causality == "input",
                min: num(&v.min),
                max: num(&v.max),
            })
            .collect();
        Ok(Target {
            lib,
            guid: md.guid.clone(),
            resource_uri: format!("file://{}", dir.join("resources").display()),
            vars,
        })
    }
}

// ---- the child: one sequence ----

/// Why a sequence failed, as the child reports it on its last line.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Outcome {
    Ok {
        calls: u64,
    },
    /// An invariant did not hold: which, at which op.
    Violation(String),
    /// A call did not return within the watchdog.
    Hang(String),
    /// The child died (signal or unexpected exit): a crash.
    Crash(String),
}

impl Outcome {
    pub fn kind(&self) -> &'static str {
        match self {
            Outcome::Ok { .. } => "ok",
            Outcome::Violation(_) => "violation",
            Outcome::Hang(_) => "hang",
            Outcome::Crash(_) => "crash",
        }
    }
}

/// The call in flight, for the watchdog: (op index, start time in ms since the child started, label).
struct Watch {
    started: Instant,
    op: AtomicU64,
    since_ms: AtomicU64,
    label: std::sync::Mutex<String>,
}

struct Driver<'a> {
    t: &'a Target,
    inst: Option<RawInstance>,
    states: Vec<(FmuState, f64)>,
    time: f64,
    calls: u64,
    watch: Arc<Watch>,
    op: usize,
    /// A call returned fmi2Error since the last reset: most calls are now refused.
    errored: bool,
    /// Instantiated or reset, not yet in initialisation: fmi2GetReal would be illegal.
    before_init: bool,
    /// THERMOVIA_FUZZ_TRACE=1: every call on stderr (shown by `--replay`).
    trace: bool,
}

type Check = Result<(), String>;

fn status_ok(s: Fmi2Status, what: &str) -> Check {
    if (FMI2_OK..=FMI2_ERROR).contains(&s) {
        Ok(())
    } else {
        Err(format!("{what} returned status {s} (fmi2Fatal or unknown)"))
    }
}

const REAL_STEPS: [f64; 14] = [1e-300, 1e-12, 1e-6, 1e-4, 1e-3, 1e-3, 1e-3, 0.01, 0.01, 0.05, 0.2, 1.0, 1e6, 1e300];

impl<'a> Driver<'a> {
    /// Checks a status and records what it says about the phase.
    fn st(&mut self, s: Fmi2Status, what: &str) -> Check {
        if s >= FMI2_ERROR {
            self.errored = true;
        }
        status_ok(s, what)
    }

    fn begin(&mut self, label: &str) {
        if self.trace {
            eprintln!("op {:>3}  {label}", self.op);
        }
        self.calls += 1;
        self.watch.op.store(self.op as u64, Ordering::Relaxed);
        if let Ok(mut l) = self.watch.label.lock() {
            l.clear();
            l.push_str(label);
        }
        self.watch.since_ms.store(self.watch.started.elapsed().as_millis() as u64 + 1, Ordering::Release);
    }
    fn end(&self) {
        self.watch.since_ms.store(0, Ordering::Release);
    }

    fn inst(&mut self) -> &mut RawInstance {
        self.inst.as_mut().expect("instantiated")
    }

    /// The instance and its state `k`, borrowed together.
    fn with_state(&mut self, k: usize) -> (&mut RawInstance, &mut FmuState) {
        (self.inst.as_mut().expect("instantiated"), &mut self.states[k].0)
    }

    fn instantiate(&mut self, rng: &mut Rng) -> Check {
        self.states.clear();
        if let Some(mut old) = self.inst.take() {
            if rng.chance(0.5) {
                // Leave the states to fmi2FreeInstance, which must free them.
                old.forget_fmu_states();
            }
            self.begin("fmi2FreeInstance");
            drop(old);
            self.end();
        }
        // Sometimes first a bad instantiation that must return NULL.
        if rng.chance(0.2) {
            let long = "x".repeat(1 + rng.below(300_000));
            let (name, guid) = match rng.below(3) {
                0 => ("", self.t.guid.clone()),
                1 => ("fuzz", long.clone()),
                _ => ("fuzz", "{00000000-0000-0000-0000-000000000000}".to_string()),
            };
            self.begin("fmi2Instantiate (bad)");
            let r = RawInstance::instantiate(&self.t.lib, name, &guid, None, rng.chance(0.5));
            self.end();
            match r {
                Ok(_) => return Err(format!("fmi2Instantiate accepted name {name:?} / a bad GUID")),
                Err(e) if e.len() > 4_000 => return Err(format!("fmi2Instantiate's message is {} bytes", e.len())),
                Err(_) => {}
            }
        }
        let name = if rng.chance(0.1) { "n".repeat(rng.below(100_000) + 1) } else { "fuzz".into() };
        self.begin("fmi2Instantiate");
        let r = RawInstance::instantiate(&self.t.lib, &name, &self.t.guid, Some(&self.t.resource_uri), rng.chance(0.5));
        self.end();
        self.inst = Some(r.map_err(|e| format!("fmi2Instantiate failed: {e}"))?);
        self.time = 0.0;
        self.errored = false;
        self.before_init = true;
        Ok(())
    }

    /// A value for `v`: mostly inside its range (bounds, log-uniform, the bounds' neighbours), sometimes
    /// outside it or not a number.
    fn value(rng: &mut Rng, v: &Var) -> f64 {
        let (lo, hi) = (v.min.unwrap_or(-1e6), v.max.unwrap_or(1e6));
        match rng.below(12) {
            0 => lo,
            1 => hi,
            2 => lo.next_down(),
            3 => hi.next_up(),
            4 => *rng.pick(&[f64::NAN, f64::INFINITY, f64::NEG_INFINITY, f64::MAX, -f64::MAX, 1e102, 2.55e88]),
            5 => 0.0,
            6 | 7 if lo > 0.0 => (lo.ln() + rng.unit() * (hi.ln() - lo.ln())).exp(),
            _ => lo + rng.unit() * (hi - lo),
        }
    }

    fn reals(&self) -> Vec<u32> {
        self.t.vars.iter().filter(|v| v.real).map(|v| v.vr).collect()
    }

    /// GetReal of every Real: if OK, all finite. Returns the values (None when not OK).
    fn probe_reals(&mut self, why: &str) -> Result<Option<Vec<f64>>, String> {
        if self.before_init {
            return Ok(None);
        }
        let vrs = self.reals();
        let mut out = vec![0.0; vrs.len()];
        self.begin("fmi2GetReal (probe)");
        let s = self.inst().get_real(&vrs, &mut out);
        self.end();
        self.st(s, "fmi2GetReal")?;
        if s != FMI2_OK {
            return Ok(None);
        }
        for (v, x) in vrs.iter().zip(&out) {
            if !x.is_finite() {
                let name = self.t.vars.iter().find(|w| w.real && w.vr == *v).map_or("?", |w| w.name.as_str());
                return Err(format!("fmi2GetReal returned OK with {name} = {x} ({why})"));
            }
        }
        Ok(Some(out))
    }

    fn revive(&mut self, rng: &mut Rng) -> Check {
        self.begin("fmi2Reset");
        let s = self.inst().reset();
        self.end();
        self.st(s, "fmi2Reset")?;
        if s != FMI2_OK {
            return Err(format!("fmi2Reset returned {s} on a live instance"));
        }
        self.errored = false;
        self.before_init = true;
        let start = Self::start_time(rng);
        let stop = if rng.chance(0.3) { Some(start + 0.05 + rng.unit()) } else { None };
        self.begin("fmi2SetupExperiment");
        let s = self.inst().setup_experiment(None, start, stop);
        self.end();
        self.st(s, "fmi2SetupExperiment")?;
        // A few extreme legal parameter values before initialisation (a refused one is undone by
        // a reset).
        for _ in 0..rng.below(4) {
            let settable: Vec<Var> = self.t.vars.iter().filter(|v| v.settable).cloned().collect();
            let v = rng.pick(&settable).clone();
            let x = if v.real {
                match rng.below(3) {
                    0 => v.min.unwrap_or(0.0),
                    1 => v.max.unwrap_or(0.0),
                    _ => Self::value(rng, &v),
                }
            } else {
                v.min.unwrap_or(0.0) + rng.below(2) as f64
            };
            self.set_one(&v, x)?;
            if self.errored {
                self.begin("fmi2Reset");
                let s = self.inst().reset();
                self.end();
                self.st(s, "fmi2Reset")?;
                self.errored = false;
            }
        }
        self.begin("fmi2EnterInitializationMode");
        let s = self.inst().enter_initialization_mode();
        self.end();
        self.st(s, "fmi2EnterInitializationMode")?;
        self.before_init = s != FMI2_OK;
        self.begin("fmi2ExitInitializationMode");
        let s = self.inst().exit_initialization_mode();
        self.end();
        self.st(s, "fmi2ExitInitializationMode")?;
        if s != FMI2_OK {
            return Err(format!("initialisation after a reset returned {s}"));
        }
        self.time = start;
        Ok(())
    }

    /// A start time: mostly 0, often an arbitrary time of a long run (where the time tolerance is
    /// wider than the shortest steps), sometimes a large one.
    fn start_time(rng: &mut Rng) -> f64 {
        match rng.below(4) {
            0 | 1 => 0.0,
            2 => 100.0 * rng.unit(),
            _ => 1e6 * rng.unit(),
        }
    }

    /// The FMU's time tolerance at `now` (documented: a relative 1e-9, absolute below 1 s).
    fn tolerance(now: f64) -> f64 {
        1e-9 * now.abs().max(1.0)
    }

    /// Sets one value; a refused set must leave every value as it was.
    fn set_one(&mut self, v: &Var, x: f64) -> Check {
        self.set_many(&[(v.clone(), x)])
    }

    /// fmi2SetReal and fmi2SetInteger with the Real and the Integer pairs: each call is
    /// all-or-nothing, so a refused one must leave every value as it was.
    fn set_many(&mut self, pairs: &[(Var, f64)]) -> Check {
        type Pairs<'p> = Vec<&'p (Var, f64)>;
        let (reals, ints): (Pairs, Pairs) = pairs.iter().partition(|(v, _)| v.real);
        for (group, real) in [(reals, true), (ints, false)] {
            if group.is_empty() {
                continue;
            }
            if self.trace {
                let shown: Vec<String> = group.iter().map(|(v, x)| format!("{} = {x:e}", v.name)).collect();
                eprintln!("         {}", shown.join(", "));
            }
            let before = self.probe_reals("before a set")?;
            let vrs: Vec<u32> = group.iter().map(|(v, _)| v.vr).collect();
            let s = if real {
                let xs: Vec<f64> = group.iter().map(|(_, x)| *x).collect();
                self.begin("fmi2SetReal");
                let s = self.inst().set_real(&vrs, &xs);
                self.end();
                self.st(s, "fmi2SetReal")?;
                s
            } else {
                let xs: Vec<i32> = group.iter().map(|(_, x)| x.clamp(-1e9, 1e9) as i32).collect();
                self.begin("fmi2SetInteger");
                let s = self.inst().set_integer(&vrs, &xs);
                self.end();
                self.st(s, "fmi2SetInteger")?;
                s
            };
            if s == FMI2_OK && real {
                for (v, x) in &group {
                    if !x.is_finite() || v.min.is_some_and(|m| *x < m) || v.max.is_some_and(|m| *x > m) {
                        return Err(format!(
                            "fmi2SetReal accepted {} = {x} outside [{:?}, {:?}]",
                            v.name, v.min, v.max
                        ));
                    }
                }
            }
            if s != FMI2_OK {
                if let (Some(b), Some(a)) = (before, self.probe_reals("after a refused set")?) {
                    if a.iter().zip(&b).any(|(x, y)| x.to_bits() != y.to_bits()) {
                        return Err("a refused set changed values (not all-or-nothing)".into());
                    }
                }
                return Ok(());
            }
        }
        Ok(())
    }

    fn do_step(&mut self, rng: &mut Rng) -> Check {
        let tol = Self::tolerance(self.time);
        let h = match rng.below(10) {
            0 => *rng.pick(&[0.0, -1e-3, f64::NAN, f64::INFINITY, f64::MAX, f64::MIN_POSITIVE]),
            // denormal and tiny steps, some shorter than the time tolerance
            1 => *rng.pick(&[5e-324, 5.7e-322, 1e-154, 1e-15, 0.5 * tol, 2.0 * tol]),
            _ => *rng.pick(&REAL_STEPS),
        };
        // 1e-12 and the draws within ±tol: accepted (issue 19: a discard there must keep the FMU's
        // own time as the last successful one; issue 31: a point below the FMU's time by more than
        // a tiny h must not end the step before it)
        let t = match rng.below(10) {
            0 => self.time + *rng.pick(&[1e-3, -1.0, f64::NAN, 1e300, 1e-12]),
            1 => self.time + tol * (2.0 * rng.unit() - 1.0),
            2 => self.time + *rng.pick(&[-tol, tol]),
            _ => self.time,
        };
        self.begin("fmi2DoStep");
        let s = self.inst().do_step_with(t, h, rng.chance(0.5));
        self.end();
        if self.trace {
            eprintln!("         fmi2DoStep({t}, {h}) -> {s}");
        }
        self.st(s, "fmi2DoStep")?;
        if s == FMI2_OK || s == FMI2_DISCARD {
            let within_tolerance = (t - self.time).abs() <= 1e-9 * self.time.abs().max(1.0);
            if !(h > 0.0 && h.is_finite() && within_tolerance) {
                return Err(format!("fmi2DoStep({t}, {h}) at time {} returned {s}", self.time));
            }
            self.begin("fmi2GetRealStatus");
            let (s2, lst) = self.inst().get_real_status(FMI2_LAST_SUCCESSFUL_TIME);
            self.end();
            self.st(s2, "fmi2GetRealStatus")?;
            if s2 != FMI2_OK {
                return Err(format!("fmi2GetRealStatus refused after a step that returned {s}"));
            }
            let end = (t + h).max(self.time);
            if s == FMI2_OK && lst != end {
                return Err(format!("step ({t}, {h}) OK but LastSuccessfulTime {lst} ≠ {end}"));
            }
            // a discard ends at the FMU's own time (the step failed) or at the stop time on the way
            if s == FMI2_DISCARD && !(lst >= self.time && lst <= end) {
                return Err(format!(
                    "step ({t}, {h}) discarded with LastSuccessfulTime {lst} outside [{}, {end}]",
                    self.time
                ));
            }
            self.time = lst;
            if self.probe_reals("after a step")?.is_none() {
                return Err(format!("fmi2GetReal refused after a step that returned {s}"));
            }
        }
        Ok(())
    }

    fn state_roundtrip(&mut self, rng: &mut Rng) -> Check {
        if self.states.is_empty() {
            return Ok(());
        }
        let k = rng.below(self.states.len());
        self.begin("fmi2SerializedFMUstateSize");
        let (inst, st) = self.with_state(k);
        let (s, size) = inst.serialized_fmu_state_size(st);
        self.end();
        self.st(s, "fmi2SerializedFMUstateSize")?;
        if s != FMI2_OK {
            return Ok(());
        }
        if size > 1 << 20 {
            return Err(format!("serialized state size {size}"));
        }
        if rng.chance(0.2) && size > 0 {
            let mut small = vec![0u8; size - 1];
            self.begin("fmi2SerializeFMUstate (short buffer)");
            let (inst, st) = self.with_state(k);
            let s = inst.serialize_fmu_state_into(st, &mut small);
            self.end();
            self.st(s, "fmi2SerializeFMUstate")?;
            if s == FMI2_OK {
                return Err("fmi2SerializeFMUstate wrote into a buffer one byte short".into());
            }
            return Ok(());
        }
        let mut bytes = vec![0u8; size];
        self.begin("fmi2SerializeFMUstate");
        let (inst, st) = self.with_state(k);
        let s = inst.serialize_fmu_state_into(st, &mut bytes);
        self.end();
        self.st(s, "fmi2SerializeFMUstate")?;
        if s != FMI2_OK {
            return Ok(());
        }
        let damaged = rng.chance(0.5);
        let buffer = if damaged { damage(rng, &bytes) } else { bytes.clone() };
        self.begin("fmi2DeSerializeFMUstate");
        let r = self.inst().deserialize_fmu_state(&buffer);
        self.end();
        match r {
            Err(s) => {
                self.st(s, "fmi2DeSerializeFMUstate")?;
                if !damaged {
                    return Err(format!("an undamaged serialized state was refused ({s})"));
                }
                Ok(())
            }
            Ok(copy) => {
                let saved_time = self.states[k].1;
                if !damaged {
                    // Round trip: the copy serializes to the same bytes.
                    self.begin("fmi2SerializeFMUstate (copy)");
                    let again = self.inst().serialize_fmu_state(&copy);
                    self.end();
                    if let Ok(again) = again {
                        if again != bytes {
                            return Err("a deserialized state serializes to other bytes".into());
                        }
                    }
                    // Restoring either gives the same values.
                    self.begin("fmi2SetFMUstate (original)");
                    let (inst, st) = self.with_state(k);
                    let s1 = inst.set_fmu_state(st);
                    self.end();
                    let a = self.probe_reals("restored original")?;
                    self.begin("fmi2SetFMUstate (copy)");
                    let s2 = self.inst().set_fmu_state(&copy);
                    self.end();
                    let b = self.probe_reals("restored copy")?;
                    self.st(s1, "fmi2SetFMUstate")?;
                    self.st(s2, "fmi2SetFMUstate")?;
                    if s1 != s2 {
                        return Err(format!("restoring a state and its copy returned {s1} and {s2}"));
                    }
                    if let (Some(a), Some(b)) = (a, b) {
                        if a.iter().zip(&b).any(|(x, y)| x.to_bits() != y.to_bits()) {
                            return Err("a state and its deserialized copy restore different values".into());
                        }
                    }
                    if s2 == FMI2_OK {
                        self.time = saved_time;
                    }
                } else {
                    // A damaged buffer accepted: restoring it must still leave a sane instance.
                    self.begin("fmi2SetFMUstate (accepted damaged)");
                    let s = self.inst().set_fmu_state(&copy);
                    self.end();
                    self.st(s, "fmi2SetFMUstate")?;
                    self.probe_reals("restored an accepted damaged state")?;
                    self.begin("fmi2GetRealStatus");
                    let (s, lst) = self.inst().get_real_status(FMI2_LAST_SUCCESSFUL_TIME);
                    self.end();
                    if s == FMI2_OK {
                        if !lst.is_finite() {
                            return Err(format!("an accepted state has LastSuccessfulTime {lst}"));
                        }
                        self.time = lst;
                    }
                    // a forged buffer may carry another time than the state it was made from: the
                    // copy restores to the time it holds, which the FMU just reported
                    self.states.push((copy, self.time));
                    return Ok(());
                }
                self.states.push((copy, saved_time));
                Ok(())
            }
        }
    }

    /// A legal value for an input (inside its range), set, then the state written and checked.
    fn legal_input_edit_then_state(&mut self, rng: &mut Rng) -> Check {
        let inputs: Vec<Var> = self.t.vars.iter().filter(|v| v.input && v.real).cloned().collect();
        if inputs.is_empty() || self.before_init || self.errored {
            return Ok(());
        }
        let v = rng.pick(&inputs).clone();
        let (lo, hi) = (v.min.unwrap_or(-1e3), v.max.unwrap_or(1e3));
        let x = match rng.below(4) {
            0 => lo,
            1 => hi,
            _ => lo + rng.unit() * (hi - lo),
        };
        self.set_one(&v, x)?;
        self.begin("fmi2GetFMUstate");
        let r = self.inst().get_fmu_state(None);
        self.end();
        match r {
            Ok(st) => {
                self.states.push((st, self.time));
                self.check_written_state(self.states.len() - 1, rng)
            }
            Err(s) => self.st(s, "fmi2GetFMUstate"),
        }
    }

    /// Every state the FMU writes must restore: state `k`, serialized, is deserialized into a
    /// fresh instance and restored there; the two instances then hold the same values and continue
    /// bit-identically through one step (statuses, values, LastSuccessfulTime).
    fn check_written_state(&mut self, k: usize, rng: &mut Rng) -> Check {
        self.begin("fmi2SerializeFMUstate (written state)");
        let (inst, st) = self.with_state(k);
        let r = inst.serialize_fmu_state(st);
        self.end();
        let bytes = r.map_err(|s| format!("a state the FMU just wrote could not be serialized ({s})"))?;
        self.begin("fmi2Instantiate (fresh instance)");
        let r = RawInstance::instantiate(&self.t.lib, "fresh", &self.t.guid, Some(&self.t.resource_uri), false);
        self.end();
        let mut fresh = r.map_err(|e| format!("fmi2Instantiate (fresh instance) failed: {e}"))?;
        self.begin("fmi2DeSerializeFMUstate (fresh instance)");
        let r = fresh.deserialize_fmu_state(&bytes);
        self.end();
        let copy = r.map_err(|s| {
            let why: Vec<String> = fresh.take_log().into_iter().map(|l| l.message).collect();
            format!("a fresh instance refused a state the FMU wrote ({s}): {}", why.join("; "))
        })?;
        self.begin("fmi2SetFMUstate (fresh instance)");
        let s = fresh.set_fmu_state(&copy);
        self.end();
        if s != FMI2_OK {
            return Err(format!("a fresh instance could not restore a state the FMU wrote ({s})"));
        }
        if self.before_init {
            return Ok(()); // no values to read before initialisation, and no step to take
        }
        // The state is the instance's current one: restore it there too, so both start alike.
        self.begin("fmi2SetFMUstate (written state)");
        let (inst, st) = self.with_state(k);
        let s = inst.set_fmu_state(st);
        self.end();
        self.st(s, "fmi2SetFMUstate")?;
        self.time = self.states[k].1;
        let vrs = self.reals();
        let read = |i: &mut RawInstance| {
            let mut out = vec![0.0; vrs.len()];
            let s = i.get_real(&vrs, &mut out);
            (s, out.iter().map(|x| x.to_bits()).collect::<Vec<u64>>())
        };
        self.begin("fmi2GetReal (both)");
        let (a, b) = (read(self.inst()), read(&mut fresh));
        self.end();
        if a != b {
            return Err("a state restored in a fresh instance reads other values".into());
        }
        let tol = Self::tolerance(self.time);
        let h = *rng.pick(&[1e-3, 0.01, 0.2, 5.7e-322, 0.5 * tol, 1e6]);
        let t = self.time + *rng.pick(&[0.0, 0.0, -tol, tol]);
        self.begin("fmi2DoStep (both)");
        let (s1, s2) = (self.inst().do_step(t, h), fresh.do_step(t, h));
        self.end();
        self.st(s1, "fmi2DoStep")?;
        if s1 != s2 {
            return Err(format!("after the same step ({t}, {h}) the instance returned {s1}, the fresh one {s2}"));
        }
        self.begin("fmi2GetReal (both)");
        let (a, b) = (read(self.inst()), read(&mut fresh));
        self.end();
        if a != b {
            return Err(format!("a state restored in a fresh instance continues differently through ({t}, {h})"));
        }
        self.begin("fmi2GetRealStatus (both)");
        let (l1, l2) =
            (self.inst().get_real_status(FMI2_LAST_SUCCESSFUL_TIME), fresh.get_real_status(FMI2_LAST_SUCCESSFUL_TIME));
        self.end();
        if l1.0 != l2.0 || l1.1.to_bits() != l2.1.to_bits() {
            return Err(format!("LastSuccessfulTime differs after the same step: {l1:?} and {l2:?}"));
        }
        if s1 == FMI2_OK || s1 == FMI2_DISCARD {
            self.time = l1.1;
        }
        self.begin("fmi2FreeInstance (fresh instance)");
        drop(fresh);
        self.end();
        Ok(())
    }

    fn op(&mut self, rng: &mut Rng) -> Check {
        let n_states = self.states.len();
        match rng.below(26) {
            0 | 1 => self.revive(rng),
            24 | 25 => self.legal_input_edit_then_state(rng),
            2..=6 => self.do_step(rng),
            7 => {
                let settable: Vec<Var> = self.t.vars.to_vec();
                let n = 1 + rng.below(4);
                let pairs: Vec<(Var, f64)> = (0..n)
                    .map(|_| {
                        let v = rng.pick(&settable).clone();
                        let x = Self::value(rng, &v);
                        (v, x)
                    })
                    .collect();
                self.set_many(&pairs)
            }
            8 => self.probe_reals("fuzz").map(|_| ()),
            9 => {
                let ints: Vec<u32> = self.t.vars.iter().filter(|v| !v.real).map(|v| v.vr).collect();
                let mut vrs = ints.clone();
                if rng.chance(0.3) {
                    vrs.push(rng.next_u64() as u32);
                }
                let mut out = vec![0; vrs.len()];
                self.begin("fmi2GetInteger");
                let s = self.inst().get_integer(&vrs, &mut out);
                self.end();
                self.st(s, "fmi2GetInteger")
            }
            10 => {
                let n = rng.below(2);
                let vrs: Vec<u32> = (0..n).map(|_| rng.next_u64() as u32 % 400).collect();
                let s = match rng.below(4) {
                    0 => {
                        let mut out = vec![0; n];
                        self.begin("fmi2GetBoolean");
                        let s = self.inst().get_boolean(&vrs, &mut out);
                        self.end();
                        s
                    }
                    1 => {
                        self.begin("fmi2SetBoolean");
                        let s = self.inst().set_boolean(&vrs, &vec![1; n]);
                        self.end();
                        s
                    }
                    2 => {
                        self.begin("fmi2GetString");
                        let s = self.inst().get_string(&vrs);
                        self.end();
                        s
                    }
                    _ => {
                        self.begin("fmi2SetString");
                        let s = self.inst().set_string(&vrs, &vec!["%s%n"; n]);
                        self.end();
                        s
                    }
                };
                self.st(s, "Boolean/String access")?;
                if n > 0 && s == FMI2_OK {
                    return Err("a Boolean/String access to a variable this FMU does not have returned OK".into());
                }
                Ok(())
            }
            11 | 12 => {
                let reuse = n_states > 0 && rng.chance(0.3);
                self.begin("fmi2GetFMUstate");
                let r = if reuse {
                    let k = rng.below(n_states);
                    let (inst, st) = self.with_state(k);
                    let r = inst.get_fmu_state(Some(st));
                    if r.is_ok() {
                        self.states[k].1 = self.time;
                    }
                    r.map(|_| None)
                } else {
                    self.inst().get_fmu_state(None).map(Some)
                };
                self.end();
                match r {
                    Ok(Some(st)) => {
                        self.states.push((st, self.time));
                        self.check_written_state(self.states.len() - 1, rng)?;
                    }
                    Ok(None) => {}
                    Err(s) => self.st(s, "fmi2GetFMUstate")?,
                }
                Ok(())
            }
            13 if n_states > 0 => {
                let k = rng.below(n_states);
                self.begin("fmi2SetFMUstate");
                let (inst, st) = self.with_state(k);
                let s = inst.set_fmu_state(st);
                self.end();
                self.st(s, "fmi2SetFMUstate")?;
                if s == FMI2_OK {
                    self.time = self.states[k].1;
                    self.probe_reals("after fmi2SetFMUstate")?;
                }
                Ok(())
            }
            14 if n_states > 0 => {
                let (st, _) = self.states.swap_remove(rng.below(n_states));
                self.begin("fmi2FreeFMUstate");
                let s = self.inst().free_fmu_state(st);
                self.end();
                self.st(s, "fmi2FreeFMUstate")
            }
            15 | 16 => self.state_roundtrip(rng),
            17 => {
                let kind = rng.below(6) as Fmi2StatusKind - 1;
                let s = match rng.below(5) {
                    0 => {
                        self.begin("fmi2GetStatus");
                        let (s, v) = self.inst().get_status(kind);
                        self.end();
                        if s == FMI2_OK && !(FMI2_OK..=FMI2_FATAL + 1).contains(&v) {
                            return Err(format!("fmi2GetStatus gave value {v}"));
                        }
                        s
                    }
                    1 => {
                        self.begin("fmi2GetRealStatus");
                        let (s, v) = self.inst().get_real_status(kind);
                        self.end();
                        if s == FMI2_OK && !v.is_finite() {
                            return Err(format!("fmi2GetRealStatus gave {v}"));
                        }
                        s
                    }
                    2 => {
                        self.begin("fmi2GetIntegerStatus");
                        let s = self.inst().get_integer_status(kind);
                        self.end();
                        s
                    }
                    3 => {
                        self.begin("fmi2GetBooleanStatus");
                        let (s, _) = self.inst().get_boolean_status(kind);
                        self.end();
                        s
                    }
                    _ => {
                        self.begin("fmi2GetStringStatus");
                        let s = self.inst().get_string_status(kind);
                        self.end();
                        s
                    }
                };
                self.st(s, "a status query")
            }
            18 => {
                let (label, s) = match rng.below(4) {
                    0 => {
                        self.begin("fmi2GetDirectionalDerivative");
                        ("fmi2GetDirectionalDerivative", self.inst().get_directional_derivative(&[106], &[1], &[1.0]))
                    }
                    1 => {
                        self.begin("fmi2SetRealInputDerivatives");
                        ("fmi2SetRealInputDerivatives", self.inst().set_real_input_derivatives(&[1], &[1], &[1.0]))
                    }
                    2 => {
                        self.begin("fmi2GetRealOutputDerivatives");
                        ("fmi2GetRealOutputDerivatives", self.inst().get_real_output_derivatives(&[106], &[1]))
                    }
                    _ => {
                        self.begin("fmi2CancelStep");
                        ("fmi2CancelStep", self.inst().cancel_step())
                    }
                };
                self.end();
                self.st(s, label)?;
                if s != FMI2_ERROR {
                    return Err(format!("{label} (unsupported) returned {s}, not fmi2Error"));
                }
                Ok(())
            }
            19 => {
                let which = *rng.pick(&NullArg::ALL);
                self.begin("a NULL argument");
                let s = self.inst().call_with_null(which);
                self.end();
                self.st(s, "a call with a NULL argument")?;
                let harmless = matches!(which, NullArg::FreeFmuStateOut);
                if s == FMI2_OK && !harmless {
                    return Err(format!("{which:?} with NULL returned OK"));
                }
                Ok(())
            }
            20 => {
                let cats = ["logEvents", "logStatusWarning", "logStatusDiscard", "logStatusError", "logAll", "%s%n"];
                let long = "c".repeat(rng.below(200_000) + 1);
                let mut chosen: Vec<&str> = (0..rng.below(3)).map(|_| *rng.pick(&cats)).collect();
                if rng.chance(0.2) {
                    chosen.push(&long);
                }
                self.begin("fmi2SetDebugLogging");
                let s = self.inst().set_debug_logging(rng.chance(0.5), &chosen);
                self.end();
                self.st(s, "fmi2SetDebugLogging")?;
                let longest = self.inst().take_log().iter().map(|r| r.message.len()).max().unwrap_or(0);
                if longest > 4_000 {
                    return Err(format!("a log message of {longest} bytes"));
                }
                Ok(())
            }
            21 => {
                let (label, s) = match rng.below(3) {
                    0 => {
                        self.begin("fmi2Terminate");
                        ("fmi2Terminate", self.inst().terminate())
                    }
                    1 => {
                        self.begin("fmi2EnterInitializationMode");
                        ("fmi2EnterInitializationMode", self.inst().enter_initialization_mode())
                    }
                    _ => {
                        self.begin("fmi2ExitInitializationMode");
                        ("fmi2ExitInitializationMode", self.inst().exit_initialization_mode())
                    }
                };
                self.end();
                if label == "fmi2EnterInitializationMode" && s == FMI2_OK {
                    self.before_init = false;
                }
                self.st(s, label)
            }
            22 => {
                let tol = if rng.chance(0.5) { Some(*rng.pick(&[1e-6, 0.0, -1.0, f64::NAN])) } else { None };
                let start = *rng.pick(&[0.0, 1.0, -1.0, f64::NAN, 1e300]);
                let stop = if rng.chance(0.5) {
                    Some(*rng.pick(&[0.0, 0.5, 2.0, f64::NAN, -5.0, f64::INFINITY]))
                } else {
                    None
                };
                self.begin("fmi2SetupExperiment");
                let s = self.inst().setup_experiment(tol, start, stop);
                self.end();
                self.st(s, "fmi2SetupExperiment")?;
                if s == FMI2_OK {
                    self.time = start;
                }
                Ok(())
            }
            23 => {
                self.begin("fmi2GetVersion / fmi2GetTypesPlatform");
                let ok = self.t.lib.version() == "2.0" && self.t.lib.types_platform() == "default";
                self.end();
                if rng.chance(0.3) {
                    self.instantiate(rng)?;
                }
                if ok {
                    Ok(())
                } else {
                    Err("fmi2GetVersion / fmi2GetTypesPlatform changed".into())
                }
            }
            _ => self.do_step(rng),
        }
    }
}

/// A damaged copy of a serialized state: a flipped byte, a truncation, trailing bytes, or a forgery
/// with a recomputed checksum (FNV-1a 64 over everything before it, as ThermoVIA documents) over
/// changed values.
pub fn damage(rng: &mut Rng, bytes: &[u8]) -> Vec<u8> {
    let mut b = bytes.to_vec();
    let n = b.len();
    if n < 9 {
        return b;
    }
    match rng.below(5) {
        0 => {
            let i = rng.below(n);
            b[i] ^= 1 << rng.below(8);
        }
        1 => b.truncate(rng.below(n)),
        2 => b.extend_from_slice(&[0; 8]),
        _ => {
            // Forge: overwrite an aligned f64 (or a byte) of the payload, recompute the checksum.
            let body = n - 8;
            for _ in 0..1 + rng.below(3) {
                if rng.chance(0.3) {
                    let i = rng.below(body);
                    b[i] = rng.next_u64() as u8;
                } else {
                    let i = rng.below(body.saturating_sub(8));
                    let x = *rng.pick(&[f64::NAN, f64::INFINITY, -1.0, 0.0, 1e300, -1e300, 1e-300, 64.0]);
                    b[i..i + 8].copy_from_slice(&x.to_le_bytes());
                }
            }
            let mut h: u64 = 0xcbf29ce484222325;
            for &x in &b[..body] {
                h ^= x as u64;
                h = h.wrapping_mul(0x100000001b3);
            }
            b[body..].copy_from_slice(&h.to_le_bytes());
        }
    }
    b
}

/// Runs the ops `indices` of sequence `seq_seed` (the child's work). Returns the outcome and the
/// number of FMI calls made.
pub fn run_sequence(target: &Target, seq_seed: u64, indices: &[usize]) -> Outcome {
    let limit =
        std::env::var(WATCHDOG_ENV).ok().and_then(|ms| ms.parse().ok()).map(Duration::from_millis).unwrap_or(WATCHDOG);
    let watch = Arc::new(Watch {
        started: Instant::now(),
        op: AtomicU64::new(0),
        since_ms: AtomicU64::new(0),
        label: std::sync::Mutex::new(String::new()),
    });
    {
        let watch = watch.clone();
        std::thread::spawn(move || loop {
            std::thread::sleep(Duration::from_millis(100));
            let since = watch.since_ms.load(Ordering::Acquire);
            if since > 0 {
                let now = watch.started.elapsed().as_millis() as u64;
                if now.saturating_sub(since) > limit.as_millis() as u64 {
                    let label = watch.label.lock().map(|l| l.clone()).unwrap_or_default();
                    println!("HANG op {} ({label}) ran over {limit:?}", watch.op.load(Ordering::Relaxed));
                    let _ = std::io::stdout().flush();
                    std::process::exit(3);
                }
            }
        });
    }
    let mut d = Driver {
        t: target,
        inst: None,
        states: Vec::new(),
        time: 0.0,
        calls: 0,
        watch: watch.clone(),
        op: 0,
        errored: false,
        before_init: true,
        trace: std::env::var_os("THERMOVIA_FUZZ_TRACE").is_some(),
    };
    let mut rng = op_rng(seq_seed, usize::MAX);
    if let Err(e) = d.instantiate(&mut rng).and_then(|()| d.revive(&mut rng)) {
        return Outcome::Violation(format!("setup: {e}"));
    }
    for &i in indices {
        d.op = i;
        let mut rng = op_rng(seq_seed, i);
        // Most wrong calls leave the instance in Error, where little else is legal: usually start
        // over, so that the sequence keeps reaching deep states.
        let result = if d.errored && rng.chance(0.85) { d.revive(&mut rng) } else { Ok(()) };
        if let Err(e) = result.and_then(|()| d.op(&mut rng)) {
            return Outcome::Violation(format!("op {i}: {e}"));
        }
    }
    d.begin("fmi2FreeInstance");
    drop(d.inst.take());
    d.end();
    Outcome::Ok { calls: d.calls }
}

/// The child's entry point: reads `seed` and op indices from stdin, prints the outcome, exits
/// 0 (ok), 2 (violation) or 3 (hang, from the watchdog).
pub fn child_main(dir: &Path) -> ! {
    let mut line = String::new();
    let _ = std::io::stdin().lock().read_line(&mut line);
    let mut words = line.split_whitespace();
    let seed: u64 = words.next().and_then(|w| w.parse().ok()).unwrap_or(0);
    let indices: Vec<usize> = words.filter_map(|w| w.parse().ok()).collect();
    let target = match Target::load(dir) {
        Ok(t) => t,
        Err(e) => {
            println!("VIOLATION cannot load the FMU: {e}");
            std::process::exit(2);
        }
    };
    match run_sequence(&target, seed, &indices) {
        Outcome::Ok { calls } => {
            println!("OK {calls}");
            std::process::exit(0)
        }
        other => {
            println!(
                "VIOLATION {}",
                match other {
                    Outcome::Violation(m) | Outcome::Hang(m) | Outcome::Crash(m) => m,
                    Outcome::Ok { .. } => unreachable!(),
                }
            );
            std::process::exit(2)
        }
    }
}

// ---- the parent: campaigns, classification, shrinking ----

/// How to start a child: this crate's binary, and the unpacked FMU folder.
#[derive(Clone)]
pub struct Launcher {
    pub exe: PathBuf,
    pub dir: PathBuf,
    /// Per-call limit in the child.
    pub watchdog: Duration,
}

impl Launcher {
    /// Runs one sequence (or a subset of its ops) in a child process.
    pub fn run(&self, seed: u64, indices: &[usize]) -> Outcome {
        let trace = std::env::var_os("THERMOVIA_FUZZ_TRACE").is_some();
        let child = Command::new(&self.exe)
            .arg("--child")
            .arg(&self.dir)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(if trace { Stdio::inherit() } else { Stdio::null() })
            .env(WATCHDOG_ENV, self.watchdog.as_millis().to_string())
            .spawn();
        let mut child = match child {
            Ok(c) => c,
            Err(e) => return Outcome::Crash(format!("cannot start the child: {e}")),
        };
        let line = format!("{seed} {}\n", indices.iter().map(|i| i.to_string()).collect::<Vec<_>>().join(" "));
        if let Some(mut stdin) = child.stdin.take() {
            let _ = stdin.write_all(line.as_bytes());
        }
        // The parent's own backstop: the child's watchdog should always fire first.
        let deadline = Instant::now() + self.watchdog * 4 + Duration::from_secs(indices.len() as u64);
        loop {
            match child.try_wait() {
                Ok(Some(_)) => break,
                Ok(None) if Instant::now() > deadline => {
                    let _ = child.kill();
                    let _ = child.wait();
                    return Outcome::Hang("the child ran past the parent's deadline".into());
                }
                Ok(None) => std::thread::sleep(Duration::from_millis(2)),
                Err(e) => return Outcome::Crash(format!("wait: {e}")),
            }
        }
        let out = child.wait_with_output();
        let (status, stdout) = match out {
            Ok(o) => (o.status, String::from_utf8_lossy(&o.stdout).into_owned()),
            Err(e) => return Outcome::Crash(format!("wait: {e}")),
        };
        let last = stdout.lines().last().unwrap_or("").to_string();
        match status.code() {
            Some(0) => match last.strip_prefix("OK ").and_then(|n| n.trim().parse().ok()) {
                Some(calls) => Outcome::Ok { calls },
                None => Outcome::Crash(format!("exit 0 without a result line: {last:?}")),
            },
            Some(2) => Outcome::Violation(last.trim_start_matches("VIOLATION ").to_string()),
            Some(3) => Outcome::Hang(last),
            Some(c) => Outcome::Crash(format!("exit code {c}: {last}")),
            None => Outcome::Crash(format!("killed by a signal ({status}); last line {last:?}")),
        }
    }

    /// Delta debugging: the smallest subset of `indices` (found within `budget` runs and
    /// `time` seconds) that fails the same way.
    pub fn shrink(&self, seed: u64, indices: &[usize], kind: &str, budget: usize, time: Duration) -> Vec<usize> {
        let until = Instant::now() + time;
        let mut cur = indices.to_vec();
        let mut runs = 0;
        let mut chunk = cur.len().div_ceil(2);
        let more = |runs: usize| runs < budget && Instant::now() < until;
        while chunk >= 1 && more(runs) {
            let mut i = 0;
            let mut removed = false;
            while i < cur.len() && more(runs) {
                let candidate: Vec<usize> =
                    cur[..i].iter().chain(cur[(i + chunk).min(cur.len())..].iter()).copied().collect();
                runs += 1;
                if self.run(seed, &candidate).kind() == kind {
                    cur = candidate;
                    removed = true;
                } else {
                    i += chunk;
                }
            }
            if !removed {
                if chunk == 1 {
                    break;
                }
                chunk = chunk.div_ceil(2);
            }
        }
        cur
    }
}

/// A failing sequence, shrunk.
#[derive(Clone, Debug)]
pub struct Failure {
    pub seed: u64,
    pub outcome: Outcome,
    pub ops: Vec<usize>,
}

#[derive(Clone, Debug, Default)]
pub struct Report {
    pub sequences: u64,
    pub calls: u64,
    pub crashes: u64,
    pub hangs: u64,
    pub violations: u64,
    pub failures: Vec<Failure>,
    pub seconds: f64,
}

/// Runs sequences until `calls` FMI calls were made, on `jobs` parallel children. Failing
/// sequences are shrunk (the first few) and reported.
pub fn campaign(launcher: &Launcher, campaign_seed: u64, calls: u64, jobs: usize, progress: bool) -> Report {
    let started = Instant::now();
    let next = AtomicU64::new(0);
    let done_calls = AtomicU64::new(0);
    let report = std::sync::Mutex::new(Report::default());
    std::thread::scope(|s| {
        for _ in 0..jobs.max(1) {
            s.spawn(|| loop {
                if done_calls.load(Ordering::Relaxed) >= calls {
                    break;
                }
                let k = next.fetch_add(1, Ordering::Relaxed);
                let seed = sequence_seed(campaign_seed, k);
                let ops: Vec<usize> = (0..OPS_PER_SEQUENCE).collect();
                let outcome = launcher.run(seed, &ops);
                let mut r = report.lock().expect("report");
                r.sequences += 1;
                match &outcome {
                    Outcome::Ok { calls: c } => {
                        r.calls += c;
                        done_calls.fetch_add(*c, Ordering::Relaxed);
                    }
                    bad => {
                        // A failed sequence still made calls: count its ops as one each.
                        r.calls += OPS_PER_SEQUENCE as u64;
                        done_calls.fetch_add(OPS_PER_SEQUENCE as u64, Ordering::Relaxed);
                        match bad {
                            Outcome::Crash(_) => r.crashes += 1,
                            Outcome::Hang(_) => r.hangs += 1,
                            _ => r.violations += 1,
                        }
                        let shrink = r.failures.len() < 3;
                        drop(r);
                        let ops = if shrink {
                            launcher.shrink(seed, &ops, bad.kind(), 150, Duration::from_secs(120))
                        } else {
                            ops
                        };
                        let outcome = if shrink { launcher.run(seed, &ops) } else { outcome };
                        let failure = Failure { seed, outcome, ops };
                        if progress {
                            eprintln!("thermovia-fuzz: found {}", failure);
                        }
                        report.lock().expect("report").failures.push(failure);
                        continue;
                    }
                }
                if progress && r.sequences % 200 == 0 {
                    eprintln!(
                        "thermovia-fuzz: {} sequences, {} calls, {} crashes, {} hangs, {} violations, {:.0} s",
                        r.sequences,
                        r.calls,
                        r.crashes,
                        r.hangs,
                        r.violations,
                        started.elapsed().as_secs_f64()
                    );
                }
            });
        }
    });
    let mut r = report.into_inner().expect("report");
    r.seconds = started.elapsed().as_secs_f64();
    r
}

impl std::fmt::Display for Report {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "{} sequences, {} FMI calls in {:.1} s: {} crashes, {} hangs, {} invariant violations",
            self.sequences, self.calls, self.seconds, self.crashes, self.hangs, self.violations
        )?;
        for x in &self.failures {
            writeln!(f, "  {x}")?;
        }
        Ok(())
    }
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let ops = self.ops.iter().map(|i| i.to_string()).collect::<Vec<_>>().join(",");
        write!(
            f,
            "{} (sequence seed {}, ops {ops}): {:?}\n    rerun: THERMOVIA_FUZZ_TRACE=1 thermovia-fuzz --replay {} {ops}",
            self.outcome.kind(),
            self.seed,
            self.outcome,
            self.seed
        )
    }
}

// ---- fixed workloads for valgrind and the cross-process state round trip ----

/// `cycles` complete life cycles of the FMU in `dir`: load the library (a fresh dlopen every
/// `cycles_per_load` cycles), instantiate, set up, initialise, step, take FMU states, serialize and
/// deserialize one, leave every other cycle's states to fmi2FreeInstance, terminate, free; unload.
/// Panics on any unexpected status. Under valgrind this shows what a long-running importer loses.
pub fn life_cycles(dir: &Path, cycles: usize, cycles_per_load: usize) {
    let mut target: Option<Target> = None;
    for k in 0..cycles {
        if k % cycles_per_load.max(1) == 0 {
            drop(target.take()); // dlclose before the next dlopen
            target = Some(Target::load(dir).expect("the FMU loads"));
        }
        let t = target.as_ref().expect("loaded");
        let mut i = RawInstance::instantiate(&t.lib, "cycle", &t.guid, Some(&t.resource_uri), k % 3 == 0)
            .expect("instantiates");
        assert_eq!(i.setup_experiment(Some(1e-6), 0.0, Some(1.0)), FMI2_OK);
        assert_eq!(i.enter_initialization_mode(), FMI2_OK);
        assert_eq!(i.set_real(&[0], &[5.0]), FMI2_OK);
        assert_eq!(i.exit_initialization_mode(), FMI2_OK);
        let mut time = 0.0;
        for _ in 0..5 {
            assert_eq!(i.do_step(time, 1e-3), FMI2_OK);
            time += 1e-3;
        }
        let st = i.get_fmu_state(None).expect("state");
        let bytes = i.serialize_fmu_state(&st).expect("serializes");
        let copy = i.deserialize_fmu_state(&bytes).expect("deserializes");
        assert_eq!(i.set_fmu_state(&copy), FMI2_OK);
        let mut out = [0.0; 3];
        assert_eq!(i.get_real(&[100, 102, 106], &mut out), FMI2_OK);
        // An error and a refused forged state on the way: their messages must be freed too.
        assert_eq!(i.set_debug_logging(true, &["no such category"]), FMI2_ERROR);
        assert_eq!(i.reset(), FMI2_OK);
        assert!(i.deserialize_fmu_state(&bytes[..bytes.len() / 2]).is_err());
        if k % 2 == 0 {
            i.forget_fmu_states(); // fmi2FreeInstance must free them
        } else {
            assert_eq!(i.free_fmu_state(st), FMI2_OK);
        }
        drop(i);
    }
}

/// Restores a serialized state in this (fresh) process, steps it `steps` times by `h`, and returns
/// the outputs `vrs` after each step: the other half of the cross-process round trip.
pub fn resume(dir: &Path, state: &[u8], steps: usize, h: f64, vrs: &[u32]) -> Result<Vec<f64>, String> {
    let t = Target::load(dir)?;
    let mut i = RawInstance::instantiate(&t.lib, "resumed", &t.guid, Some(&t.resource_uri), false)?;
    let st = i.deserialize_fmu_state(state).map_err(|s| format!("fmi2DeSerializeFMUstate: {s}: {:?}", i.take_log()))?;
    if i.set_fmu_state(&st) != FMI2_OK {
        return Err(format!("fmi2SetFMUstate: {:?}", i.take_log()));
    }
    let (s, mut time) = i.get_real_status(FMI2_LAST_SUCCESSFUL_TIME);
    if s != FMI2_OK {
        return Err(format!("fmi2GetRealStatus: {s}"));
    }
    let mut out = Vec::new();
    for _ in 0..steps {
        if i.do_step(time, h) != FMI2_OK {
            return Err(format!("fmi2DoStep at {time}: {:?}", i.take_log()));
        }
        time += h;
        let mut v = vec![0.0; vrs.len()];
        if i.get_real(vrs, &mut v) != FMI2_OK {
            return Err("fmi2GetReal".into());
        }
        out.extend(v);
    }
    Ok(out)
}
