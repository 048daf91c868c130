//! The actuator's physics in plain Rust: no FFI, no I/O. `Model::step(h)` advances every state by
//! one communication step with internal sub-steps of at most `max_internal_step`.

#![forbid(unsafe_code)]

pub mod crystallisation;
pub mod material;
pub mod mechanics;
pub mod params;
pub mod prony;
pub mod thermal;

use std::sync::Arc;

use mechanics::{
    Coefficients, Contact, Coupling, Drive, EtdStep, FineCell, LinearStep, PropagatorTable, State, Tabulated,
};
pub use params::{
    BacklashLaw, Crystallisation, LinkDrive, MotorDrive, Params, ThermalDrive, Transmission, ViscoelasticLaw,
};
use thermal::{ThermalInputs, ThermalState};

#[derive(Clone, Debug, PartialEq)]
pub struct Inputs {
    pub heater_power: f64,
    pub motor_torque: f64,
    pub load_torque: f64,
    pub ambient_temperature: f64,
    pub motor_angle_command: f64,
    pub motor_speed_command: f64,
    pub housing_temperature_command: f64,
    /// Link angle at the start of the step and its speed over the step (`LinkDrive::Prescribed`).
    pub link_angle_command: f64,
    pub link_speed_command: f64,
}

impl Default for Inputs {
    fn default() -> Self {
        let room = params::ZERO_CELSIUS + 22.0;
        Inputs {
            heater_power: 0.0,
            motor_torque: 0.0,
            load_torque: 0.0,
            ambient_temperature: room,
            motor_angle_command: 0.0,
            motor_speed_command: 0.0,
            housing_temperature_command: room,
            link_angle_command: 0.0,
            link_speed_command: 0.0,
        }
    }
}

/// Why a step could not be completed; the model is left as it was before the step.
#[derive(Debug, Clone, PartialEq)]
pub enum StepFailure {
    /// The adaptive solver could not meet its tolerance (a state ran away or the ODE is too stiff).
    SolverStalled { at_time_in_step: f64 },
    /// A state became NaN or infinite.
    NonFinite,
    /// `h / max_internal_step` sub-steps are more than [`MAX_SUBSTEPS_PER_STEP`]; nothing was done.
    TooManySubsteps { needed: f64 },
    /// The adaptive solver used [`MAX_SOLVER_ATTEMPTS_PER_STEP`] attempts before the step's end.
    SolverBudget { at_time_in_step: f64 },
    /// The step is shorter than [`MIN_RESOLVABLE_STEP`]; nothing was done.
    StepTooSmall { h: f64 },
    /// A temperature fell to 0 K or below: the thermal network's explicit stages are unstable for
    /// these parameters at this sub-step (a heat capacity far below its conductances' h).
    TemperatureNotPositive { which: &'static str, kelvin: f64 },
}

/// The shortest step the model integrates: the square root of the smallest normal double, so that
/// h² (which the exponential stages and the propagator series form) is still a normal number.
/// Below it those terms underflow and overflow into NaN (measured: 1e-295 s steps, 1e-300 s fails).
pub const MIN_RESOLVABLE_STEP: f64 = 1.4916681462400413e-154;

/// Work budget of one `Model::step`, so that every call returns in bounded time (about a second on
/// a 2020s core in the worst case measured; see the README's reliability section): at most this many
/// internal sub-steps...
pub const MAX_SUBSTEPS_PER_STEP: f64 = 100_000.0;
/// ...and at most this many attempted exponential Runge–Kutta and Dormand–Prince steps over all sub-steps.
pub const MAX_SOLVER_ATTEMPTS_PER_STEP: u64 = 1_000_000;

/// The work one [`Model::step`] did: internal sub-steps taken and adaptive-solver steps attempted
/// (exponential Runge–Kutta and Dormand–Prince). The budget above bounds both, so a step's time is
/// bounded by work the model counts, which a test can assert where a wall clock would be noise.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct StepWork {
    pub substeps: u64,
    pub solver_attempts: u64,
}

impl std::fmt::Display for StepFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StepFailure::SolverStalled { at_time_in_step } => {
                write!(f, "the adaptive solver could not meet solver_tolerance {at_time_in_step} s into the step")
            }
            StepFailure::NonFinite => write!(f, "a state became NaN or infinite"),
            StepFailure::TemperatureNotPositive { which, kelvin } => write!(
                f,
                "the {which} temperature would be {kelvin:e} K: the thermal network is unstable at this sub-step for \
                 these parameters (a heat capacity too small for its conductances); lower max_internal_step"
            ),
            StepFailure::StepTooSmall { h } => write!(
                f,
                "the step {h:e} s is too small to resolve (the shortest is {MIN_RESOLVABLE_STEP:e} s, where h² \
                 stays a normal number); take a longer communication step"
            ),
            StepFailure::TooManySubsteps { needed } => write!(
                f,
                "the step needs {needed:e} internal sub-steps of max_internal_step, more than the budget of \
                 {MAX_SUBSTEPS_PER_STEP:e}; take shorter communication steps or raise max_internal_step"
            ),
            StepFailure::SolverBudget { at_time_in_step } => write!(
                f,
                "the adaptive solver used its budget of {MAX_SOLVER_ATTEMPTS_PER_STEP} attempts {at_time_in_step} s \
                 into the step; take shorter communication steps, or loosen solver_tolerance or the friction smoothing"
            ),
        }
    }
}

/// Relative amount by which an internal sub-step may exceed `max_internal_step` (see
/// [`Model::step`]), far below anything the sub-step length changes physically.
pub const SUBSTEP_SLACK: f64 = 1e-9;

/// Finest exponential Runge–Kutta sub-step: the communication sub-step / 2^MAX_ETD_LEVEL.
const MAX_ETD_LEVEL: u32 = 10;

/// Linearised steps kept at most ([`linearised_etd`]); beyond, the cache starts again. A link
/// crossing the friction's zone at speed meets slopes all over the grid; a held one returns to the
/// same ones.
const MAX_LINEARISED_STEPS: usize = 4096;

/// What a linearised step is built from besides the parameters: its length, the coupling, the
/// moduli (bit patterns) and its damping's multiple of the grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
struct LinearisedKey {
    len: u64,
    coupling: Coupling,
    moduli: [u64; 3],
    multiple: u64,
}

impl LinearisedKey {
    fn new(c: &Coefficients, len: f64, coupling: Coupling, multiple: u64) -> Self {
        LinearisedKey {
            len: len.to_bits(),
            coupling,
            moduli: [c.stiffness.to_bits(), c.damping.to_bits(), c.maxwell_stiffness.to_bits()],
            multiple,
        }
    }
}

/// The linearised step ([`EtdStep::with_link_damping`]) `key` names, its damping `damping` (the
/// grid's, [`EtdStep::linearised_damping_on_grid`]), kept in `cache` once built; None where the
/// caller should build it and not keep it. The key holds everything the step is built from
/// besides the parameters (a parameter change clears the cache), so a kept step is the step built
/// afresh, bit for bit, and a restored state continues as it would have. Steps of other moduli are
/// not met again while the PCL heats or cools: the cache holds the moduli of the last linearised
/// step only (`last_moduli`), and a step whose moduli differ from the last one's is not kept (a
/// heating link's steps, kept, cost 4–7 % of its step time in hashing and memory for no reuse).
#[inline(never)]
fn linearised_etd<'c>(
    cache: &'c mut std::collections::HashMap<LinearisedKey, EtdStep>,
    last_moduli: &mut [u64; 3],
    p: &Params,
    key: LinearisedKey,
    c: &Coefficients,
    damping: f64,
) -> Option<&'c EtdStep> {
    if std::mem::replace(last_moduli, key.moduli) != key.moduli {
        if !cache.is_empty() {
            cache.clear(); // O(capacity) even when empty
        }
        return None;
    }
    if cache.len() >= MAX_LINEARISED_STEPS && !cache.contains_key(&key) {
        cache.clear();
    }
    Some(
        cache
            .entry(key)
            .or_insert_with(|| EtdStep::with_link_damping(p, c, f64::from_bits(key.len), key.coupling, damping)),
    )
}

/// The exponential Runge–Kutta level nearest the last accepted step: round(log2(key/last)) in
/// 0..=MAX_ETD_LEVEL (0 without a last step), from the binary exponent of √2·key/last (the
/// ratio is a power of two whenever the last step was exponential; no libm call).
fn etd_level(key: f64, last: f64) -> u32 {
    if last.is_nan() || last <= 0.0 {
        return 0;
    }
    let r = std::f64::consts::SQRT_2 * (key / last);
    if r.is_nan() || r < 1.0 {
        return 0;
    }
    if r >= (1u64 << (MAX_ETD_LEVEL + 1)) as f64 {
        return MAX_ETD_LEVEL;
    }
    // 1 ≤ r < 2^11: a normal number, exponent = floor(log2 r).
    (((r.to_bits() >> 52) & 0x7ff) as u32 - 1023).min(MAX_ETD_LEVEL)
}

/// Length of [`Model::state`].
pub const STATE_LEN: usize = mechanics::N_STATE + 12;

/// Spacing of the temperature lattice on which the Dormand–Prince path (backlash, or a fallback)
/// and the outputs read the moduli, K.
pub const MODULUS_TEMPERATURE_LATTICE: f64 = 1e-5;

/// Where the Dormand–Prince path (backlash, or a fallback) and the outputs (transmitted torque,
/// effective stiffness and damping) evaluate the moduli: the PCL temperature rounded to a 10 µK
/// lattice, so a PCL drifting by micro-kelvins reuses one evaluation. The moduli change by at most
/// 23 %/K (E'' between 50 and 60 °C, Table 2's steepest segment), so the ≤ 5 µK rounding moves
/// them by ≤ 1.2e-6 relative, and the link angle by < 1e-7 rad at the largest transmission
/// deflection (~0.05 rad). The exact linear step and the exponential Runge–Kutta step take the
/// unrounded temperature (interpolated propagator tables, `mechanics::PropagatorTable`). Depends
/// on the state alone, so a restored state continues bit-identically.
fn on_temperature_lattice(t: f64) -> f64 {
    (t / MODULUS_TEMPERATURE_LATTICE).round() * MODULUS_TEMPERATURE_LATTICE
}

/// The last read of one propagator table: the step at PCL temperature `t` (as clamped by
/// [`mechanics::table_temperature`]), read through the fine cell `cell`.
#[derive(Clone, Debug)]
struct TableRead<N: Tabulated> {
    t: f64,
    cell: FineCell<N>,
    step: N,
}

impl<N: Tabulated> Default for TableRead<N> {
    fn default() -> Self {
        TableRead { t: f64::NAN, cell: FineCell::default(), step: N::ZERO }
    }
}

#[derive(Clone, Debug)]
pub struct Model {
    params: Params,
    pub inputs: Inputs,
    /// Mechanical state [θm, θm', θl, θl', q].
    pub mechanics: State,
    pub thermal: ThermalState,
    /// Last accepted step of the adaptive solver (part of the state: restoring it makes a
    /// restored run continue bit-identically).
    pub adaptive_step: f64,
    /// Gravity's sine and cosine at an angle near the link's (part of the state
    /// for the same reason, see [`mechanics::SineAnchor`]).
    pub sine_anchor: mechanics::SineAnchor,
    /// The transmission's torque on the link averaged over the last step (its impulse over the
    /// step divided by the step; 0 before the first step). Part of the state.
    pub transmitted_torque_mean: f64,
    coefficients: Option<(f64, Coefficients)>,
    /// Propagator tables of the last two step lengths (shared with clones until one adds a node).
    tables: Vec<Arc<PropagatorTable<LinearStep>>>,
    /// Keys of step lengths ([`mechanics::StepKeys`]).
    step_keys: mechanics::StepKeys,
    /// The last linear step used: (step key, its table's read).
    linear_step: Option<(f64, TableRead<LinearStep>)>,
    /// Exponential Runge–Kutta coefficient tables, one per step key and level (sub-steps of
    /// key / 2^level): (key, level, table). The levels of one key share each node's exponential
    /// ([`mechanics::phi_chain`]).
    etd_tables: Vec<(f64, u32, Arc<PropagatorTable<EtdStep>>)>,
    /// The last coefficients used at each key and level: (key, level, the table's read).
    etd_steps: Vec<(f64, u32, TableRead<EtdStep>)>,
    /// Exact steps of the backlash's free and clipped states (no transmission torque, so no
    /// dependence on the PCL temperature): (length, coupling, step).
    contact_steps: Vec<(f64, Coupling, LinearStep)>,
    /// Exponential Runge–Kutta coefficients of those states: (length, coupling, step).
    contact_etd: Vec<(f64, Coupling, EtdStep)>,
    /// Linearised steps of a link near rest under friction, by what they are built from
    /// ([`linearised_etd`]).
    linearised_etd: std::collections::HashMap<LinearisedKey, EtdStep>,
    /// The moduli (bit patterns) of the last linearised step ([`linearised_etd`]).
    linearised_moduli: [u64; 3],
    /// The enthalpy's inverse series about the PCL temperature's current anchor.
    inversion: thermal::InversionCache,
    /// Bounds of the transmission's stiffness, damping and Maxwell stiffness over every PCL
    /// temperature ([`Model::transmitted_torque_is_finite`]).
    torque_bounds: Option<[f64; 3]>,
}

impl PartialEq for Model {
    fn eq(&self, o: &Self) -> bool {
        self.params == o.params
            && self.inputs == o.inputs
            && self.mechanics == o.mechanics
            && self.thermal == o.thermal
            && self.adaptive_step == o.adaptive_step
            && self.sine_anchor == o.sine_anchor
            && self.transmitted_torque_mean.to_bits() == o.transmitted_torque_mean.to_bits()
    }
}

impl Default for Model {
    fn default() -> Self {
        Model::new(Params::default())
    }
}

/// Which momentum balance gives the transmission's mean torque over a step
/// ([`Model::step_mean_torque`]), and so what it needs from the step's start
/// ([`Model::step_start_torque`]).
#[derive(Clone, Copy, PartialEq, Eq)]
enum MeanTorqueBasis {
    /// A torque-driven motor: its own balance (nothing from the start).
    Motor,
    /// A prescribed motor on a rigid transmission: no transmission torque to report.
    Nothing,
    /// A prescribed motor and an integrated link: the link's balance, with its nonlinear law's
    /// torque (friction, gravity) at both ends when it has one.
    Link { nonlinear: bool },
    /// Both sides prescribed: the mean of the transmission's torques at both ends.
    Ends,
}

impl MeanTorqueBasis {
    fn of(p: &Params) -> Self {
        match (p.motor_drive, p.transmission, p.link_drive) {
            (MotorDrive::Torque, _, _) => MeanTorqueBasis::Motor,
            (MotorDrive::PrescribedAngle, Transmission::Rigid, _) => MeanTorqueBasis::Nothing,
            (MotorDrive::PrescribedAngle, Transmission::Compliant, LinkDrive::Prescribed) => MeanTorqueBasis::Ends,
            (MotorDrive::PrescribedAngle, Transmission::Compliant, LinkDrive::Integrated) => {
                MeanTorqueBasis::Link { nonlinear: !p.link_torque_is_linear() }
            }
        }
    }
}

impl Model {
    pub fn new(params: Params) -> Self {
        let mut m = Model::with_params_only(params);
        m.initialize();
        m
    }

    /// A model holding `params`, its states not yet set from them ([`Model::initialize`] does
    /// that): for trying parameter writes through the variable table's setters.
    pub fn with_params_only(params: Params) -> Self {
        Model {
            thermal: ThermalState::initial(&params),
            params,
            inputs: Inputs::default(),
            mechanics: State::zeros(),
            adaptive_step: 0.0,
            sine_anchor: mechanics::SineAnchor::NONE,
            transmitted_torque_mean: 0.0,
            coefficients: None,
            tables: Vec::new(),
            step_keys: mechanics::StepKeys::default(),
            linear_step: None,
            etd_tables: Vec::new(),
            etd_steps: Vec::new(),
            contact_steps: Vec::new(),
            contact_etd: Vec::new(),
            linearised_etd: std::collections::HashMap::new(),
            linearised_moduli: [0; 3],
            inversion: thermal::InversionCache::default(),
            torque_bounds: None,
        }
    }

    /// Fits the Prony law once per parameter set, when it is the law in use and not yet fitted
    /// (parameters changed through [`Model::params_mut`] drop the fit).
    fn fit_viscoelastic_law(&mut self) {
        if self.params.viscoelastic_law == ViscoelasticLaw::Prony && self.params.prony.is_none() {
            self.params.prony = Some(self.params.fit_prony_law());
        }
    }

    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Mutable parameters; cached coefficients are dropped so they are rebuilt from the new values.
    pub fn params_mut(&mut self) -> &mut Params {
        self.coefficients = None;
        self.tables.clear();
        self.linear_step = None;
        self.etd_tables.clear();
        self.etd_steps.clear();
        self.contact_steps.clear();
        self.contact_etd.clear();
        self.linearised_etd.clear();
        self.inversion = thermal::InversionCache::default();
        self.torque_bounds = None;
        self.params.prony = None;
        // anchored at the link angle less gravity_offset, which may change
        self.sine_anchor = mechanics::SineAnchor::NONE;
        &mut self.params
    }

    /// Sets every state from the `initial_*` parameters (start of a run).
    pub fn initialize(&mut self) {
        self.fit_viscoelastic_law();
        let p = &self.params;
        self.mechanics = if p.transmission == Transmission::Rigid {
            State::from([
                p.initial_motor_angle,
                p.initial_motor_speed,
                p.initial_motor_angle,
                p.initial_motor_speed,
                0.0,
            ])
        } else {
            State::from([p.initial_motor_angle, p.initial_motor_speed, p.initial_link_angle, p.initial_link_speed, 0.0])
        };
        self.thermal = ThermalState::initial(p);
        self.adaptive_step = 0.0;
        self.sine_anchor = mechanics::SineAnchor::NONE;
    }

    /// Transmission coefficients at the current PCL temperature (on the same lattice the
    /// mechanics uses, so outputs and steps share one cached evaluation).
    pub fn coefficients(&mut self) -> Coefficients {
        self.coefficients_at(on_temperature_lattice(self.thermal.modulus_temperature(&self.params)))
    }

    fn coefficients_at(&mut self, pcl_temperature: f64) -> Coefficients {
        match self.coefficients {
            Some((t, c)) if t == pcl_temperature => c,
            _ => {
                self.fit_viscoelastic_law();
                let c = Coefficients::at(&self.params, pcl_temperature);
                self.coefficients = Some((pcl_temperature, c));
                c
            }
        }
    }

    /// The exact linear step of length `key` with the moduli at PCL temperature `t` (interpolated
    /// in the propagator table; reused while t and key stay).
    fn prepare_linear_step(&mut self, t: f64, key: f64) {
        let t = mechanics::table_temperature(t);
        if matches!(&self.linear_step, Some((k0, read)) if read.t == t && *k0 == key) {
            return;
        }
        let i = match self.tables.iter().position(|tb| tb.step_length() == key) {
            Some(i) => i,
            None => {
                self.tables.truncate(1);
                self.tables.insert(0, Arc::new(PropagatorTable::new(key)));
                0
            }
        };
        let (k0, read) = self.linear_step.get_or_insert_with(|| (key, TableRead::default()));
        if *k0 != key {
            // another table: its cells are not this one's
            (*k0, *read) = (key, TableRead::default());
        }
        if !self.tables[i].try_at(t, &mut read.cell, &mut read.step) {
            let table = Arc::make_mut(&mut self.tables[i]);
            table.build(&self.params, t);
            let built = table.try_at(t, &mut read.cell, &mut read.step);
            debug_assert!(built, "the nodes were built");
        }
        read.t = t;
    }

    /// Index in `etd_steps` of the exponential Runge–Kutta coefficients for sub-steps of
    /// key / 2^level at PCL temperature `t`.
    fn prepare_etd(&mut self, t: f64, key: f64, level: u32) -> usize {
        let t = mechanics::table_temperature(t);
        let i = match self.etd_steps.iter().position(|(k, l, _)| *k == key && *l == level) {
            Some(i) if self.etd_steps[i].2.t == t => return i,
            Some(i) => i,
            None => {
                // Bounded like the tables: a master varying h would otherwise grow it without end.
                if self.etd_steps.len() >= 2 * (MAX_ETD_LEVEL as usize + 1) {
                    self.etd_steps.remove(0);
                }
                self.etd_steps.push((key, level, TableRead::default()));
                self.etd_steps.len() - 1
            }
        };
        let k = match self.etd_tables.iter().position(|(k, l, _)| *k == key && *l == level) {
            Some(k) => k,
            None => {
                if self.etd_tables.len() >= 2 * (MAX_ETD_LEVEL as usize + 1) {
                    self.etd_tables.remove(0);
                }
                let len = key / (1u64 << level) as f64;
                self.etd_tables.push((key, level, Arc::new(PropagatorTable::new(len))));
                self.etd_tables.len() - 1
            }
        };
        let read = &mut self.etd_steps[i].2;
        if !self.etd_tables[k].2.try_at(t, &mut read.cell, &mut read.step) {
            self.build_etd_nodes(key, k, t);
            let read = &mut self.etd_steps[i].2;
            let built = self.etd_tables[k].2.try_at(t, &mut read.cell, &mut read.step);
            debug_assert!(built, "the stencil's nodes were built");
        }
        self.etd_steps[i].2.t = t;
        i
    }

    /// Builds the nodes table `k` (of step key `key`) lacks at PCL temperature `t`, and the same
    /// nodes of the key's other levels' tables where missing: one exponential per node for every
    /// level ([`mechanics::phi_chain`]), the same numbers whichever level asks first.
    #[inline(never)]
    fn build_etd_nodes(&mut self, key: f64, k: usize, t: f64) {
        for n in self.etd_tables[k].2.missing(t) {
            let c = Coefficients::at(&self.params, mechanics::node_temperature(n));
            let rows = mechanics::phi_chain(&self.params, &c, key, MAX_ETD_LEVEL);
            for (table_key, level, table) in self.etd_tables.iter_mut() {
                if *table_key == key && !table.has(n) {
                    let l = *level as usize;
                    let len = key / (1u64 << l) as f64;
                    Arc::make_mut(table).insert(n, EtdStep::from_rows(&rows[l + 1], &rows[l], &c, len));
                }
            }
        }
    }

    /// Index in `contact_steps` of the exact step of length `len` for the backlash state `coupling`.
    fn contact_step(&mut self, len: f64, coupling: Coupling) -> usize {
        if let Some(i) = self.contact_steps.iter().position(|(l, c, _)| *l == len && *c == coupling) {
            return i;
        }
        if self.contact_steps.len() >= 8 {
            self.contact_steps.remove(0);
        }
        let step = LinearStep::with(&self.params, &Coefficients::ZERO, len, coupling);
        self.contact_steps.push((len, coupling, step));
        self.contact_steps.len() - 1
    }

    /// Index in `contact_etd` of the exponential Runge–Kutta coefficients of length `len` for the
    /// backlash state `coupling`.
    fn contact_etd(&mut self, len: f64, coupling: Coupling) -> usize {
        if let Some(i) = self.contact_etd.iter().position(|(l, c, _)| *l == len && *c == coupling) {
            return i;
        }
        if self.contact_etd.len() >= 4 * (MAX_ETD_LEVEL as usize + 1) {
            self.contact_etd.remove(0);
        }
        let step = EtdStep::with(&self.params, &Coefficients::ZERO, len, coupling);
        self.contact_etd.push((len, coupling, step));
        self.contact_etd.len() - 1
    }

    /// One sub-step of length `key` (plus the sliver hs − key to first order) with backlash and
    /// otherwise linear mechanics: exact between contact events, by the propagator of the contact
    /// state the step starts in (in coordinates shifted by the play, see [`Contact`]). False,
    /// state unchanged, when the step may hold an event: its end is in another state, or the
    /// trajectory may have touched an edge and come back ([`mechanics::may_leave`]); the caller then
    /// integrates through it.
    fn advance_contact_linear(&mut self, t: f64, key: f64, hs: f64, u: &Drive) -> bool {
        let x = self.mechanics;
        let (mode, c) = if self.in_fixed_play() {
            (Contact::Free, Coefficients::ZERO)
        } else {
            self.prepare_linear_step(t, key);
            let c = self.linear_step.as_ref().expect("prepared").1.step.coefficients();
            (mechanics::contact(&self.params, &c, &x), c)
        };
        if matches!(mode, Contact::Capped { .. }) {
            // ElastoBacklash's capped spell: Dormand–Prince (its springs double, tabulated nowhere)
            return false;
        }
        let offset = mode.offset(&self.params);
        let mut shifted = x;
        shifted[mechanics::MOTOR_ANGLE] -= offset;
        let mut y = match mode {
            Contact::Engaged { .. } => self.linear_step.as_ref().expect("prepared").1.step.apply(&shifted, u),
            _ => {
                let i = self.contact_step(key, mode.coupling());
                self.contact_steps[i].2.apply(&shifted, u)
            }
        };
        y[mechanics::MOTOR_ANGLE] += offset;
        let p = &self.params;
        if mode == Contact::Free && p.has_relaxing_branch() {
            y[mechanics::MAXWELL_DEFLECTION] =
                mechanics::recover_unloaded(p, &c, x[mechanics::MAXWELL_DEFLECTION], key);
        }
        let same = match mode {
            Contact::Free => mechanics::in_play(p, &c, &y),
            _ => mechanics::contact(p, &c, &y) == mode,
        };
        if !same {
            return false;
        }
        let leaves = match mode {
            Contact::Free => mechanics::may_leave(p, &c, mode, (&x, &x), (&y, &y), hs),
            _ => {
                let (r0, r1) = (mechanics::derivative(p, &c, &x, u), mechanics::derivative(p, &c, &y, u));
                mechanics::may_leave(p, &c, mode, (&x, &r0), (&y, &r1), hs)
            }
        };
        if leaves {
            return false;
        }
        if hs != key {
            y += mechanics::derivative(p, &c, &y, u) * (hs - key);
        }
        self.mechanics = y;
        true
    }

    /// Inside a play that no relaxing branch moves: free, with no moduli needed to say so.
    fn in_fixed_play(&self) -> bool {
        !self.params.has_relaxing_branch() && mechanics::in_play(&self.params, &Coefficients::ZERO, &self.mechanics)
    }

    /// The backlash's contact state at the start of a sub-step and the moduli it was classified
    /// with (the exponential Runge–Kutta coefficients' at `t`; none needed inside the play).
    fn contact_at_start(&mut self, t: f64, key: f64) -> (Contact, Coefficients) {
        if self.in_fixed_play() {
            return (Contact::Free, Coefficients::ZERO);
        }
        // A step that starts at level 0 (most do) interpolates the level's whole table anyway:
        // once, here, and the step finds it prepared.
        if etd_level(key, self.adaptive_step) == 0 {
            let i = self.prepare_etd(t, key, 0);
            let c = self.etd_steps[i].2.step.coefficients();
            return (mechanics::contact(&self.params, &c, &self.mechanics), c);
        }
        // Otherwise only the two coefficients where the nodes exist (the step itself is taken at
        // another level); the same numbers the whole step would hold.
        let table = self.etd_tables.iter().find(|(k, l, _)| *k == key && *l == 0);
        let c = match table.and_then(|(_, _, tb)| tb.coefficients_at(mechanics::table_temperature(t))) {
            Some(c) => c,
            None => {
                let i = self.prepare_etd(t, key, 0);
                self.etd_steps[i].2.step.coefficients()
            }
        };
        (mechanics::contact(&self.params, &c, &self.mechanics), c)
    }

    /// Advances the mechanics over one sub-step of length `key` by exponential Runge–Kutta
    /// steps of key/2^level, the level adapted by the embedded error estimate (kept in
    /// `adaptive_step` as the last accepted length); returns the transmission coefficients at `t`.
    /// None (state unchanged) when even key/2^MAX_ETD_LEVEL fails the tolerance.
    /// Every attempted step costs one of `attempts_left` (the step's work budget, shared with
    /// Dormand–Prince); None when the budget or the finest level runs out.
    /// With backlash, `contact` is the state the sub-step starts in and the moduli it was
    /// classified with: the steps are those of that state, and None also when a step may hold a
    /// contact event (as in [`Model::advance_contact_linear`]).
    fn advance_exponential(
        &mut self,
        t: f64,
        key: f64,
        u: &Drive,
        attempts_left: &mut u64,
        contact: Option<(Contact, Coefficients)>,
    ) -> Option<(Coefficients, Option<State>)> {
        if matches!(contact, Some((Contact::Capped { .. }, _))) {
            return None; // ElastoBacklash's capped spell: Dormand–Prince, as above
        }
        let full: u64 = 1 << MAX_ETD_LEVEL;
        let mut level = etd_level(key, self.adaptive_step);
        let mut x = self.mechanics;
        let mut pos = 0u64;
        let mut coefficients = Coefficients::ZERO;
        let (offset, coupling) = match contact {
            Some((mode, _)) => (mode.offset(&self.params), mode.coupling()),
            None => (0.0, Coupling::Engaged),
        };
        // The rate at x (for the contact events' slopes), carried from one accepted step to the next
        // (and returned: the caller's first-order remainder uses it).
        let mut rate: Option<State> = None;
        // The stage torque at x, carried from one accepted step's end to the next step.
        let friction = mechanics::Friction::new(&self.params);
        let mut start: Option<mechanics::StepStart> = None;
        while pos < full {
            if *attempts_left == 0 {
                return None;
            }
            *attempts_left -= 1;
            let len = key / (1u64 << level) as f64;
            let mut shifted = x;
            shifted[mechanics::MOTOR_ANGLE] -= offset;
            let s0 = start.get_or_insert_with(|| {
                mechanics::StepStart::anchored(&self.params, &x, &mut self.sine_anchor, &friction)
            });
            let linearised = mechanics::friction_linearisation(&self.params, &friction, x[mechanics::LINK_SPEED], key);
            // engaged: this level's tabulated step, whose coefficients a linearised step takes too
            let table = (coupling == Coupling::Engaged).then(|| self.prepare_etd(t, key, level));
            if let Some(i) = table {
                coefficients = self.etd_steps[i].2.step.coefficients();
            }
            let (mut x_new, err) = match (table, linearised) {
                (Some(i), None) => self.etd_steps[i].2.step.step(&self.params, &shifted, u, s0),
                (None, None) => {
                    let i = self.contact_etd(len, coupling);
                    self.contact_etd[i].2.step(&self.params, &shifted, u, s0)
                }
                // a link at or near rest under friction: its slope in the linear part
                (table, Some(damping)) => {
                    let c = if table.is_some() { coefficients } else { Coefficients::ZERO };
                    let on_grid = EtdStep::linearised_damping_on_grid(&self.params, len, damping);
                    let damping = on_grid.map_or(damping, |(_, d)| d);
                    let kept = on_grid.and_then(|(multiple, _)| {
                        let key = LinearisedKey::new(&c, len, coupling, multiple);
                        let cache = &mut self.linearised_etd;
                        linearised_etd(cache, &mut self.linearised_moduli, &self.params, key, &c, damping)
                    });
                    let built;
                    let step = match kept {
                        Some(step) => step,
                        None => {
                            built = EtdStep::with_link_damping(&self.params, &c, len, coupling, damping);
                            &built
                        }
                    };
                    step.step(&self.params, &shifted, u, &s0.linearised(damping, x[mechanics::LINK_SPEED]))
                }
            };
            x_new[mechanics::MOTOR_ANGLE] += offset;
            if err <= 1.0 {
                let n0 = s0.link_torque();
                let mut next = None;
                if let Some((mode, c)) = contact {
                    let p = &self.params;
                    match mode {
                        Contact::Free => {
                            if p.has_relaxing_branch() {
                                x_new[mechanics::MAXWELL_DEFLECTION] =
                                    mechanics::recover_unloaded(p, &c, x[mechanics::MAXWELL_DEFLECTION], len);
                            }
                            if !mechanics::in_play(p, &c, &x_new)
                                || mechanics::may_leave(p, &c, mode, (&x, &x), (&x_new, &x_new), len)
                            {
                                return None;
                            }
                        }
                        _ => {
                            if mechanics::contact(p, &c, &x_new) != mode {
                                return None;
                            }
                            let s1 = s0.advanced(p, &x_new);
                            let r0 = rate.unwrap_or_else(|| mechanics::derivative_with_link_torque(p, &c, &x, u, n0));
                            let r1 = mechanics::derivative_with_link_torque(p, &c, &x_new, u, s1.link_torque());
                            if mechanics::may_leave(p, &c, mode, (&x, &r0), (&x_new, &r1), len) {
                                return None;
                            }
                            rate = Some(r1);
                            next = Some(s1);
                        }
                    }
                    coefficients = c;
                }
                x = x_new;
                pos += full >> level;
                // the next step starts where this one ended (built above for the contact checks)
                start = match next {
                    None if pos < full => Some(s0.advanced(&self.params, &x)),
                    next => next,
                };
                // A fourth-order step twice as long has ~16× the estimate: coarsen when that passes.
                if err < 1.0 / 16.0 && level > 0 && pos.is_multiple_of(full >> (level - 1)) {
                    level -= 1;
                }
            } else if level == MAX_ETD_LEVEL {
                return None;
            } else {
                level += 1;
            }
        }
        self.mechanics = x;
        self.adaptive_step = key / (1u64 << level) as f64;
        Some((coefficients, rate))
    }

    /// One sub-step of the mechanics with a nonlinear effect: exact steps between backlash
    /// contact events, exponential Runge–Kutta for gravity and friction, Dormand–Prince where
    /// those cannot (a rigid drive, an event inside the step, a tolerance the exponential step
    /// cannot meet). False when Dormand–Prince fails too (the caller restores the state).
    /// Kept out of line so the linear path of [`Model::step`] stays small.
    #[inline(never)]
    fn nonlinear_substep(&mut self, t_mid: f64, hs: f64, drive: &Drive, attempts_left: &mut u64) -> bool {
        let compliant = self.params.transmission == Transmission::Compliant;
        let backlash = self.params.backlash_width > 0.0;
        if compliant && backlash && self.params.link_torque_is_linear() {
            // Backlash alone: exact steps between contact events.
            let key = self.step_keys.key(hs);
            if self.advance_contact_linear(t_mid, key, hs, drive) {
                return true;
            }
        } else if compliant && (backlash || self.params.backlash_width == 0.0) {
            // Gravity and friction are smooth: exponential Runge–Kutta on the exact linear part
            // (its forcing acts on the link alone, so a rigid drive takes Dormand–Prince below),
            // with backlash that of the contact state the step starts in.
            let key = self.step_keys.key(hs);
            let contact = if backlash { Some(self.contact_at_start(t_mid, key)) } else { None };
            if let Some((c, rate)) = self.advance_exponential(t_mid, key, drive, attempts_left, contact) {
                if hs != key {
                    // the rate at the end, if the contact checks computed it
                    let rate = rate.unwrap_or_else(|| mechanics::derivative(&self.params, &c, &self.mechanics, drive));
                    self.mechanics += rate * (hs - key);
                }
                return true;
            }
        }
        let c = self.coefficients_at(on_temperature_lattice(t_mid));
        mechanics::integrate_adaptive(
            &self.params,
            &c,
            &mut self.mechanics,
            drive,
            hs,
            &mut self.adaptive_step,
            attempts_left,
        )
        .is_some()
    }

    /// Advances the model by `h` seconds with inputs held. On failure nothing changes.
    pub fn step(&mut self, h: f64) -> Result<(), StepFailure> {
        self.step_counting(h, &mut StepWork::default())
    }

    /// [`Model::step`], adding the work it did to `work` (also when it fails).
    pub fn step_counting(&mut self, h: f64, work: &mut StepWork) -> Result<(), StepFailure> {
        if h < MIN_RESOLVABLE_STEP {
            return Err(StepFailure::StepTooSmall { h });
        }
        self.fit_viscoelastic_law();
        let substeps = if h <= self.params.max_internal_step {
            1
        } else {
            // Sub-steps may exceed max_internal_step by [`SUBSTEP_SLACK`]: fmpy's steps
            // t(k+1) − t(k) exceed 1 ms by a few ulps on about half of them, which would otherwise
            // be cut in two half-length sub-steps (twice the work, and tables of their own).
            let needed = (h / self.params.max_internal_step * (1.0 - SUBSTEP_SLACK)).ceil().max(1.0);
            if needed.is_nan() || needed > MAX_SUBSTEPS_PER_STEP {
                return Err(StepFailure::TooManySubsteps { needed });
            }
            needed as usize
        };
        let mut attempts_left = MAX_SOLVER_ATTEMPTS_PER_STEP;
        let hs = h / substeps as f64;
        let before = self.state();
        if self.params.motor_drive == MotorDrive::PrescribedAngle {
            self.mechanics[mechanics::MOTOR_ANGLE] = self.inputs.motor_angle_command;
            self.mechanics[mechanics::MOTOR_SPEED] = self.inputs.motor_speed_command;
            if self.params.transmission == Transmission::Rigid {
                self.mechanics[mechanics::LINK_ANGLE] = self.inputs.motor_angle_command;
                self.mechanics[mechanics::LINK_SPEED] = self.inputs.motor_speed_command;
            }
        }
        let link_prescribed = self.params.link_drive == LinkDrive::Prescribed;
        let rigid = self.params.transmission == Transmission::Rigid;
        if link_prescribed {
            self.mechanics[mechanics::LINK_ANGLE] = self.inputs.link_angle_command;
            self.mechanics[mechanics::LINK_SPEED] = self.inputs.link_speed_command;
            if rigid {
                self.mechanics[mechanics::MOTOR_ANGLE] = self.inputs.link_angle_command;
                self.mechanics[mechanics::MOTOR_SPEED] = self.inputs.link_speed_command;
            }
        }
        let (motor_start, link_start, torque_start) = (
            [self.mechanics[mechanics::MOTOR_ANGLE], self.mechanics[mechanics::MOTOR_SPEED]],
            [self.mechanics[mechanics::LINK_ANGLE], self.mechanics[mechanics::LINK_SPEED]],
            self.step_start_torque(),
        );
        let drive = Drive::new(self.inputs.motor_torque, self.inputs.load_torque);
        let thermal_inputs = ThermalInputs {
            heater_power: self.inputs.heater_power,
            ambient_temperature: self.inputs.ambient_temperature,
            housing_temperature_command: self.inputs.housing_temperature_command,
        };
        let linear = self.params.mechanics_is_linear();
        for i in 0..substeps {
            work.substeps += 1;
            // Thermal first, then mechanics with the moduli at the sub-step's midpoint PCL
            // temperature: the thermal time scale (s) is far above the sub-step (ms).
            let t_mid = self.thermal.advance_cached(&self.params, &thermal_inputs, hs, &mut self.inversion);
            if link_prescribed && rigid {
                // one body, and the engine moves it
                let v = self.inputs.link_speed_command;
                self.mechanics[mechanics::MOTOR_ANGLE] += v * hs;
                self.mechanics[mechanics::LINK_ANGLE] += v * hs;
                continue;
            }
            if linear {
                let key = self.step_keys.key(hs);
                self.prepare_linear_step(t_mid, key);
                let step = &self.linear_step.as_ref().expect("prepared").1.step;
                let mut x = step.apply(&self.mechanics, &drive);
                if hs != key {
                    // The last ≤ 5e-10·h: x' = A x + B u, first order (error ~ (h − key)² |A|² |x|).
                    x += mechanics::linear_rate(&self.params, &step.coefficients(), &x, &drive) * (hs - key);
                }
                self.mechanics = x;
                continue;
            }
            let left_before = attempts_left;
            let advanced = self.nonlinear_substep(t_mid, hs, &drive, &mut attempts_left);
            work.solver_attempts += left_before - attempts_left;
            if !advanced {
                self.set_state(&before);
                let at_time_in_step = i as f64 * hs;
                return Err(if attempts_left == 0 {
                    StepFailure::SolverBudget { at_time_in_step }
                } else {
                    StepFailure::SolverStalled { at_time_in_step }
                });
            }
        }
        let finite = self.mechanics.iter().all(|v| v.is_finite())
            && self.thermal.housing_temperature.is_finite()
            && self.thermal.pcl_temperature.is_finite();
        if !finite {
            self.set_state(&before);
            return Err(StepFailure::NonFinite);
        }
        for (which, kelvin) in [("PCL", self.thermal.pcl_temperature), ("housing", self.thermal.housing_temperature)] {
            if kelvin <= 0.0 {
                self.set_state(&before);
                return Err(StepFailure::TemperatureNotPositive { which, kelvin });
            }
        }
        self.transmitted_torque_mean = self.step_mean_torque(h, motor_start, link_start, torque_start);
        Ok(())
    }

    /// What [`Model::step_mean_torque`] needs from the start of a step where neither side's momentum
    /// balance is exact: both sides prescribed, the transmission's torque; a prescribed motor and a
    /// link under a nonlinear law, that law's torque on the link (friction, gravity: cheap, no moduli).
    fn step_start_torque(&mut self) -> f64 {
        match MeanTorqueBasis::of(&self.params) {
            MeanTorqueBasis::Ends => self.transmitted_torque(),
            MeanTorqueBasis::Link { nonlinear: true } => self.link_law_torque(),
            _ => 0.0,
        }
    }

    /// Friction and gravity on the link, the nonlinear part of its law.
    fn link_law_torque(&self) -> f64 {
        let x = &self.mechanics;
        mechanics::link_friction(&self.params, x[mechanics::LINK_SPEED])
            + mechanics::link_gravity(&self.params, x[mechanics::LINK_ANGLE])
    }

    /// The transmission's torque on the link averaged over a step of `h` that started with motor
    /// and link states `motor_start`, `link_start` (`start`: [`Model::step_start_torque`]). From a
    /// momentum balance, exact whatever the transmission (backlash, Maxwell branch, a moving PCL
    /// temperature): the motor's, J_m Δθm' = ∫(τ_m − B_m θm' − τ) dt, when it is torque-driven; else
    /// the link's, J_l Δθl' = ∫(τ + τ_load − B_l θl' + f) dt, when it is integrated, with the
    /// nonlinear part f (friction, gravity) by the trapezoid rule. With both sides prescribed, the
    /// mean of the transmission's torques at both ends: exact for springs and Kelvin–Voigt PCL at a
    /// steady temperature, whose torque is then linear over the step.
    fn step_mean_torque(&mut self, h: f64, motor_start: [f64; 2], link_start: [f64; 2], start: f64) -> f64 {
        let p = &self.params;
        let x = &self.mechanics;
        match MeanTorqueBasis::of(p) {
            MeanTorqueBasis::Ends => 0.5 * (start + self.transmitted_torque()),
            MeanTorqueBasis::Motor => {
                self.inputs.motor_torque
                    - p.motor_damping * (x[mechanics::MOTOR_ANGLE] - motor_start[0]) / h
                    - p.motor_inertia * (x[mechanics::MOTOR_SPEED] - motor_start[1]) / h
            }
            MeanTorqueBasis::Nothing => 0.0,
            MeanTorqueBasis::Link { nonlinear } => {
                let nonlinear = if nonlinear { 0.5 * (start + self.link_law_torque()) } else { 0.0 };
                p.link_inertia * (x[mechanics::LINK_SPEED] - link_start[1]) / h
                    + p.link_damping * (x[mechanics::LINK_ANGLE] - link_start[0]) / h
                    - self.inputs.load_torque
                    - nonlinear
            }
        }
    }

    /// Every number of the model's state as one flat vector, what an FMU state saves: the mechanical
    /// state [θm, θm', θl, θl', q], the thermal state [T_h, H_p, T_p, E_heater, E_lost] and the
    /// adaptive solver's last step, gravity's sine anchor [φa, sin φa, cos φa]
    /// ([`mechanics::SineAnchor`]; NaN before the first sub-step), and the PCL's structural
    /// temperature T_f, which holds its crystallinity X = X_c (1 − χ(T_f)), with Nakamura's integral θ
    /// of the crystallisation under way, and the transmission's mean torque over the last step.
    /// Parameters and inputs are not in it.
    pub fn state(&self) -> [f64; STATE_LEN] {
        let m = &self.mechanics;
        let th = &self.thermal;
        [
            m[0],
            m[1],
            m[2],
            m[3],
            m[4],
            th.housing_temperature,
            th.pcl_enthalpy,
            th.pcl_temperature,
            th.heater_energy,
            th.heat_lost,
            self.adaptive_step,
            self.sine_anchor.angle,
            self.sine_anchor.sin,
            self.sine_anchor.cos,
            th.pcl_structural_temperature,
            th.pcl_crystallisation_integral,
            self.transmitted_torque_mean,
        ]
    }

    /// Restores a vector from [`Model::state`].
    pub fn set_state(&mut self, x: &[f64; STATE_LEN]) {
        self.mechanics = State::from([x[0], x[1], x[2], x[3], x[4]]);
        self.thermal.housing_temperature = x[5];
        self.thermal.pcl_enthalpy = x[6];
        self.thermal.pcl_temperature = x[7];
        self.thermal.heater_energy = x[8];
        self.thermal.heat_lost = x[9];
        self.adaptive_step = x[10];
        self.sine_anchor = mechanics::SineAnchor { angle: x[11], sin: x[12], cos: x[13] };
        self.thermal.pcl_structural_temperature = x[14];
        self.thermal.pcl_crystallisation_integral = x[15];
        self.transmitted_torque_mean = x[16];
    }

    pub fn motor_angle(&self) -> f64 {
        self.mechanics[mechanics::MOTOR_ANGLE]
    }
    pub fn motor_speed(&self) -> f64 {
        self.mechanics[mechanics::MOTOR_SPEED]
    }
    pub fn link_angle(&self) -> f64 {
        self.mechanics[mechanics::LINK_ANGLE]
    }
    pub fn link_speed(&self) -> f64 {
        self.mechanics[mechanics::LINK_SPEED]
    }
    pub fn transmitted_torque(&mut self) -> f64 {
        if self.params.transmission == Transmission::Rigid {
            // the force the motor side passes on: τ_m − B_m θ' − J_m θ'' (0 when the angle is prescribed)
            if self.params.motor_drive == MotorDrive::PrescribedAngle {
                return 0.0;
            }
            let c = self.coefficients();
            let u = Drive::new(self.inputs.motor_torque, self.inputs.load_torque);
            let a = mechanics::derivative(&self.params, &c, &self.mechanics, &u)[mechanics::MOTOR_SPEED];
            let p = &self.params;
            return self.inputs.motor_torque
                - p.motor_damping * self.mechanics[mechanics::MOTOR_SPEED]
                - p.motor_inertia * a;
        }
        let c = self.coefficients();
        mechanics::transmission(&self.params, &c, &self.mechanics).0
    }
    /// Whether [`Model::transmitted_torque`] is finite, without evaluating the moduli where a bound
    /// settles it: the log-linear moduli never leave the range of the material table's rows, so
    /// |τ| ≤ (K_s r_s² + max E'·κ r_p² + K_M)(|Δ| + b/2) + max C·|Δ'| + K_M |q|; when that bound is
    /// finite (below 1e300) so is τ, otherwise τ itself is evaluated. Used after every step (an
    /// FMU must not return a non-finite output), where evaluating the moduli at a PCL temperature
    /// that moves every step cost more than the exact heating step itself.
    pub fn transmitted_torque_is_finite(&mut self) -> bool {
        if self.params.transmission == Transmission::Compliant {
            let p = &self.params;
            let [k, c, km] = *self.torque_bounds.get_or_insert_with(|| {
                let max = |v: [f64; 4]| v.iter().fold(0.0_f64, |a, x| a.max(x.abs()));
                let kappa = p.modulus_to_torsion().abs();
                let springs = p.spring_torsional_stiffness().abs();
                match p.viscoelastic_law {
                    ViscoelasticLaw::Hysteretic => {
                        let (e1, e2) = p.material_table.rows_kpa();
                        let omega = 2.0 * std::f64::consts::PI * p.excitation_frequency;
                        let km = p.maxwell_stiffness.abs();
                        let k = springs + max(e1) * 1e3 * p.storage_modulus_scale.abs() * kappa + km;
                        [k, max(e2) * 1e3 * p.loss_modulus_scale.abs() * kappa / omega.abs(), km]
                    }
                    // the rows' coefficients bound the geometric (and linear) mix between them
                    ViscoelasticLaw::Prony => {
                        let rows = p.prony_law().rows;
                        let km = max(rows.map(|r| r.e_branch)) * kappa;
                        [springs + max(rows.map(|r| r.e_inf)) * kappa + km, max(rows.map(|r| r.viscosity)) * kappa, km]
                    }
                }
            });
            let x = &self.mechanics;
            let delta = (x[mechanics::MOTOR_ANGLE] - x[mechanics::LINK_ANGLE]).abs() + 0.5 * p.backlash_width.abs();
            let rate = (x[mechanics::MOTOR_SPEED] - x[mechanics::LINK_SPEED]).abs();
            let bound = k * delta + c * rate + km * x[mechanics::MAXWELL_DEFLECTION].abs();
            if bound < 1e300 {
                return true;
            }
        }
        self.transmitted_torque().is_finite()
    }
    pub fn effective_stiffness(&mut self) -> f64 {
        let c = self.coefficients();
        c.effective(&self.params).0
    }
    pub fn effective_damping(&mut self) -> f64 {
        let c = self.coefficients();
        c.effective(&self.params).1
    }
    /// Molten (amorphous) share of the crystallisable PCL, 1 − X/X_c = χ(T_f).
    pub fn melt_fraction(&self) -> f64 {
        thermal::melt_fraction(&self.params, self.thermal.pcl_structural_temperature)
    }
    /// Crystallinity X of the PCL (mass fraction of crystal).
    pub fn crystallinity(&self) -> f64 {
        crystallisation::crystallinity(&self.params, self.thermal.pcl_structural_temperature)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn etd_level_rounds_log2_of_the_step_ratio() {
        let key = 1e-3;
        for level in 0..=MAX_ETD_LEVEL {
            assert_eq!(etd_level(key, key / (1u64 << level) as f64), level);
        }
        for (last, expected) in
            [(0.0, 0), (-1.0, 0), (f64::NAN, 0), (2e-3, 0), (0.8e-3, 0), (0.6e-3, 1), (1e-9, MAX_ETD_LEVEL)]
        {
            assert_eq!(etd_level(key, last), expected, "{last}");
            let old = if last > 0.0 { ((key / last).log2().round().max(0.0) as u32).min(MAX_ETD_LEVEL) } else { 0 };
            assert_eq!(etd_level(key, last), old, "{last}");
        }
    }
}
