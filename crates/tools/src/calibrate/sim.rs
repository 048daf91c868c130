//! Simulating runs through the packaged FMU (the C API, via the harness): the measured motor angle
//! drives the link (motor_drive = 1, piecewise linear between samples), the measured housing
//! temperature drives the PCL (thermal_drive = 1). Several instances run in parallel threads.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use thermovia_importer::{Fmu, Handle, HarnessError, Instance};

/// g, m/s² (the FMU uses the same standard gravity).
pub use crate::report::STANDARD_GRAVITY;

/// What drives one simulated run.
#[derive(Clone, Debug)]
pub struct SimInput {
    pub time: Vec<f64>,
    pub motor: Vec<f64>,
    /// Housing temperature per sample, K.
    pub housing_k: Vec<f64>,
    pub frequency_hz: f64,
    pub link_inertia: Option<f64>,
    pub link0: f64,
    /// Centre-of-mass distance used to turn m·g·d into the FMU's `gravity_link_mass`, m.
    pub com_distance: f64,
    /// θl' at the first sample (a run need not start at rest), rad/s.
    pub initial_link_speed: f64,
    /// The run is a segment after a gap in its file: the link is moving at its first sample, at a
    /// speed the calibration fits (`search::fit_initial_speeds`).
    pub after_gap: bool,
    /// The housing thermocouple before the first sample, for a segment after a gap
    /// (`data::Run::thermocouple_before`): the PCL starts where its lag behind that history left it.
    /// Empty: the PCL starts level with the thermocouple.
    pub housing_before: super::data::HousingHistory,
    /// FMU steps per sample interval (`motor_substeps`): the motor angle follows the cubic through
    /// the samples, in straight pieces between the substeps, where one straight line per interval
    /// would err by more than the noise allows. 1: the straight line between the samples.
    pub substeps: usize,
}

/// The most FMU steps `motor_substeps` puts in one sample interval: 8 take a chord's error down
/// 64-fold at 8× the simulation's cost.
pub const MAX_SUBSTEPS: usize = 8;

/// FMU steps per sample interval for a motor angle `motor` sampled at `time` whose link reads with
/// noise `noise` (rad): the fewest m ≤ `MAX_SUBSTEPS` whose chords, m to an interval, err by at most a
/// quarter of the noise in rms (adding at most 3 % to the rms the noise sets). A chord through a
/// motion of curvature θ'' errs by up to θ''h²/8 over its interval h, so m = ⌈√(4 E₁/σ)⌉ with E₁
/// the rms of |θ''|h²/8 over the run (θ'' the second divided difference of the conditioned angle).
/// The campaign's device rig 852 (a 5 Hz sine logged at 200 Hz, 9.5e-5 rad of noise) read 8.0e-4
/// rad between its truth's own replay on straight lines and the measured link: the fit then bent
/// its friction by 15 % to take up that error.
pub fn motor_substeps(time: &[f64], motor: &[f64], noise: f64) -> usize {
    let n = time.len().min(motor.len());
    if n < 3 || !(noise > 0.0) {
        return 1;
    }
    let (mut sum, mut count) = (0.0, 0usize);
    for k in 1..n - 1 {
        let Some(curvature) = super::signal::second_divided_difference(time, motor, k) else { continue };
        let h1 = time[k + 1] - time[k];
        let chord = curvature * h1 * h1 / 8.0;
        if chord.is_finite() {
            sum += chord * chord;
            count += 1;
        }
    }
    if count == 0 {
        return 1;
    }
    let chord_rms = (sum / count as f64).sqrt();
    ((4.0 * chord_rms / noise).sqrt().ceil() as usize).clamp(1, MAX_SUBSTEPS)
}

/// The motor angle's slope at each sample: the derivative of the parabola through it and its two
/// neighbours, in their own times (one-sided at the ends); with the samples, it sets the cubic
/// Hermite pieces `simulate` takes substeps on.
fn motor_slopes(time: &[f64], motor: &[f64]) -> Vec<f64> {
    let n = time.len();
    let chord = |k: usize| (motor[k + 1] - motor[k]) / (time[k + 1] - time[k]);
    (0..n)
        .map(|k| {
            if n < 2 {
                0.0
            } else if k == 0 {
                chord(0)
            } else if k == n - 1 {
                chord(n - 2)
            } else {
                let (h0, h1) = (time[k] - time[k - 1], time[k + 1] - time[k]);
                (chord(k - 1) * h1 + chord(k) * h0) / (h0 + h1)
            }
        })
        .collect()
}

/// Values of the effect library, in the FMU's own terms except gravity, which is held as
/// a = m g d cos(offset), b = m g d sin(offset) so that τ_g = −a sin θ + b cos θ is linear in both.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EffectValues {
    pub coulomb_friction: f64,
    pub backlash_width: f64,
    pub gravity_a: f64,
    pub gravity_b: f64,
    pub link_damping: f64,
    pub thermal_lag: f64,
    pub maxwell_stiffness: f64,
    pub maxwell_time: f64,
    pub stribeck_friction: f64,
    pub stribeck_velocity: f64,
    pub coulomb_asymmetry: f64,
    pub viscous_asymmetry: f64,
    /// Constant torque on the link (the FMU's `load_torque` input, held), N·m.
    pub constant_load: f64,
    /// Backlash by Modelica's ElastoBacklash (`backlash_law` = 1) instead of the clipped law.
    pub elasto_backlash: bool,
}

impl EffectValues {
    pub fn gravity_mgl(&self) -> f64 {
        self.gravity_a.hypot(self.gravity_b)
    }
    pub fn gravity_offset(&self) -> f64 {
        self.gravity_b.atan2(self.gravity_a)
    }
}

/// Everything the fit varies for one run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunModel {
    pub storage_scale: f64,
    pub loss_scale: f64,
    /// Stiffness of each spring, N/m; None = the FMU's default. The fit scales springs and PCL
    /// storage together, so the transmission's stiffness can go wherever real rigs go while the
    /// table keeps its shape in temperature.
    pub spring_stiffness: Option<f64>,
    /// The frequency at which the PCL's loss modulus becomes a damping C = K''/ω; None = the run's
    /// own (hysteretic law). A fixed one makes the damping viscous, the same at every frequency.
    pub excitation_frequency: Option<f64>,
    pub effects: EffectValues,
    pub solver_tolerance: f64,
}

impl Default for RunModel {
    fn default() -> Self {
        RunModel {
            storage_scale: 1.0,
            loss_scale: 1.0,
            spring_stiffness: None,
            excitation_frequency: None,
            effects: EffectValues::default(),
            solver_tolerance: 1e-8,
        }
    }
}

/// The FMU's transmission at one temperature and frequency with the table's moduli (factors 1):
/// what the fitted stiffness and damping are scaled against.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransmissionTable {
    /// K_eff = spring bank + E'κ, N·m/rad.
    pub stiffness: f64,
    /// C_eff = E''κ/ω at `frequency_hz`, N·m·s/rad.
    pub damping: f64,
    pub frequency_hz: f64,
    /// The FMU's default stiffness of one spring, N/m (scaled by `RunModel::spring_scale`).
    pub spring_stiffness: f64,
    /// The FMU's default link inertia, kg·m² (used when a run declares none).
    pub link_inertia: f64,
    /// The nominal spring bank's torsional stiffness, N·m/rad (part of `stiffness`).
    pub spring_bank: f64,
}

/// Steps within this relative amount of the nominal step are taken as the nominal step, so the FMU's
/// cached propagator stays valid: CSV times carry rounding in their last digits, and loggers jitter
/// (2e-5 of a step rebuilt the propagator every step: 11 s instead of 1.3 s). The simulated time
/// then differs from the logged time by the jitter itself (timestamps jitter around a grid, they do
/// not drift), at most 1e-3 of a step; the motor command is re-anchored to the measured angle at
/// every sample.
pub const STEP_SNAP: f64 = 1e-3;

struct Handles {
    motor_cmd: u32,
    speed_cmd: u32,
    housing_cmd: u32,
    link: u32,
    link_speed: u32,
}

fn handles(inst: &Instance) -> Result<Handles, HarnessError> {
    let vr = |n: &str| inst.handle(n).map(|h: Handle| h.value_reference);
    Ok(Handles {
        motor_cmd: vr("motor_angle_command")?,
        speed_cmd: vr("motor_speed_command")?,
        housing_cmd: vr("housing_temperature_command")?,
        link: vr("link_angle")?,
        link_speed: vr("link_speed")?,
    })
}

/// Why a simulation stopped short: the FMU refused a call, or the calibration's deadline passed
/// while it ran.
#[derive(Debug)]
pub enum SimError {
    Fmu(HarnessError),
    Deadline,
}

impl std::fmt::Display for SimError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SimError::Fmu(e) => write!(f, "{e}"),
            SimError::Deadline => f.write_str(DEADLINE_PASSED),
        }
    }
}

impl std::error::Error for SimError {}

impl From<HarnessError> for SimError {
    fn from(e: HarnessError) -> Self {
        SimError::Fmu(e)
    }
}

/// Steps between two looks at the clock while a run is simulated: a look costs ~20 ns, a step
/// microseconds, and a stiff run's steps (a backlash contact with friction) still end within
/// milliseconds of the deadline.
const STEPS_PER_CLOCK_LOOK: usize = 64;

/// Err(Deadline) once `until` has passed, looked at every `STEPS_PER_CLOCK_LOOK` steps: a simulation
/// in progress stops too, not only one about to start (a stiff run of 27 000 samples took seconds,
/// and a fit's simulations in flight at the deadline ran the calibration 2–6 s past its budget:
/// campaign rig 19).
pub fn check_deadline(step: usize, until: Option<std::time::Instant>) -> Result<(), SimError> {
    match until {
        Some(at) if step.is_multiple_of(STEPS_PER_CLOCK_LOOK) && std::time::Instant::now() >= at => {
            Err(SimError::Deadline)
        }
        _ => Ok(()),
    }
}

/// One run through one instance; returns the model's link angle at every sample. Stops with
/// `SimError::Deadline` once `until` passes.
pub fn simulate(
    inst: &mut Instance,
    input: &SimInput,
    m: &RunModel,
    until: Option<std::time::Instant>,
) -> Result<Vec<f64>, SimError> {
    let h = handles(inst)?;
    inst.reset()?;
    let e = &m.effects;
    let mgl = e.gravity_mgl();
    let mut params: Vec<(&str, f64)> = vec![
        ("motor_drive", 1.0),
        ("thermal_drive", 1.0),
        ("initial_motor_angle", input.motor[0]),
        ("initial_link_angle", input.link0),
        ("initial_housing_temperature", input.housing_k[0]),
        (
            "initial_pcl_temperature",
            lagged_pcl(input.housing_before.samples(), (input.time[0], input.housing_k[0]), e.thermal_lag),
        ),
        ("excitation_frequency", m.excitation_frequency.unwrap_or(input.frequency_hz)),
        ("storage_modulus_scale", m.storage_scale),
        ("loss_modulus_scale", m.loss_scale),
        ("coulomb_friction", e.coulomb_friction.max(0.0)),
        ("backlash_width", e.backlash_width.max(0.0)),
        ("link_damping", e.link_damping.max(0.0)),
        ("thermal_lag_time_constant", e.thermal_lag.max(0.0)),
        ("maxwell_stiffness", e.maxwell_stiffness.max(0.0)),
        ("solver_tolerance", m.solver_tolerance),
    ];
    if e.maxwell_time > 0.0 {
        params.push(("maxwell_relaxation_time", e.maxwell_time));
    }
    if e.elasto_backlash {
        params.push(("backlash_law", 1.0));
    }
    if e.stribeck_friction > 0.0 {
        params.push(("stribeck_friction", e.stribeck_friction));
        params.push(("stribeck_velocity", e.stribeck_velocity));
    }
    if e.coulomb_asymmetry != 0.0 || e.viscous_asymmetry != 0.0 {
        params.push(("coulomb_friction_asymmetry", e.coulomb_asymmetry));
        params.push(("viscous_friction_asymmetry", e.viscous_asymmetry));
    }
    if let Some(k) = m.spring_stiffness {
        params.push(("spring_stiffness", k));
    }
    if input.initial_link_speed != 0.0 {
        params.push(("initial_link_speed", input.initial_link_speed));
    }
    if mgl > 0.0 {
        params.push(("gravity_com_distance", input.com_distance));
        params.push(("gravity_link_mass", mgl / (STANDARD_GRAVITY * input.com_distance)));
        params.push(("gravity_offset", e.gravity_offset()));
    }
    if let Some(j) = input.link_inertia {
        params.push(("link_inertia", j));
    }
    inst.initialize(input.time[0], None, &params)?;
    if e.constant_load != 0.0 {
        inst.set("load_torque", e.constant_load)?;
    }
    let n = input.time.len();
    let nominal = (input.time[n - 1] - input.time[0]) / (n - 1) as f64;
    let substeps = input.substeps.clamp(1, MAX_SUBSTEPS);
    if nominal > 0.0 && input.time.windows(2).any(|w| (w[1] - w[0] - nominal).abs() > STEP_SNAP * nominal) {
        return simulate_on_grid(inst, input, &h, nominal / substeps as f64, until);
    }
    let mut out = Vec::with_capacity(n);
    out.push(input.link0);
    let vrs = [h.motor_cmd, h.speed_cmd, h.housing_cmd];
    let mut y = [0.0];
    let slopes = if substeps > 1 { motor_slopes(&input.time, &input.motor) } else { Vec::new() };
    for k in 0..n - 1 {
        check_deadline(k, until)?;
        let mut dt = input.time[k + 1] - input.time[k];
        if (dt - nominal).abs() <= STEP_SNAP * nominal {
            dt = nominal;
        }
        let housing = 0.5 * (input.housing_k[k] + input.housing_k[k + 1]);
        // the cubic Hermite piece through (m0, slope) and (m1, slope) on the logged interval, taken
        // in equal substeps of the (snapped) step; one substep is the straight line m0 → m1
        let (m0, m1) = (input.motor[k], input.motor[k + 1]);
        let span = input.time[k + 1] - input.time[k];
        let h_sub = dt / substeps as f64;
        let mut at = m0;
        for j in 1..=substeps {
            let next = if j == substeps {
                m1
            } else {
                hermite(j as f64 / substeps as f64, m0, slopes[k] * span, m1, slopes[k + 1] * span)
            };
            inst.set_reals(&vrs, &[at, (next - at) / h_sub, housing])?;
            inst.step(h_sub)?;
            at = next;
        }
        inst.get_reals(&[h.link], &mut y)?;
        out.push(y[0]);
    }
    Ok(out)
}

/// The cubic Hermite piece from (x0, d0) to (x1, d1) at a fraction `s` into it (slopes `d` per
/// piece, not per second).
fn hermite(s: f64, x0: f64, d0: f64, x1: f64, d1: f64) -> f64 {
    let (s2, s3) = (s * s, s * s * s);
    (2.0 * s3 - 3.0 * s2 + 1.0) * x0 + (s3 - 2.0 * s2 + s) * d0 + (-2.0 * s3 + 3.0 * s2) * x1 + (s3 - s2) * d1
}

/// `simulate` for a run whose sample intervals differ by more than `STEP_SNAP` (a logger's jitter):
/// the FMU steps a uniform grid of `step` (the mean interval over `substeps`) instead of from sample
/// to sample. The FMU keys its propagator tables by step length, so a length met once built a table
/// per step: device rig 1249 (14 % jitter, 5 kHz) spent 82 % of its calibration building them
/// (perf). The motor angle at the grid's times is the cubic Hermite through the samples
/// (`motor_slopes`), the housing temperature the straight line; the link angle at each sample is
/// the cubic Hermite through the FMU's link angle and speed at the grid times either side of it.
/// For a motion of frequency ω that cubic errs by at most (ωH)⁴/384 of its amplitude, below
/// π²/48 of the chord error `substeps` bounds for the same motion wherever ωH ≤ π (the grid
/// resolves it).
fn simulate_on_grid(
    inst: &mut Instance,
    input: &SimInput,
    h: &Handles,
    step: f64,
    until: Option<std::time::Instant>,
) -> Result<Vec<f64>, SimError> {
    let (time, motor) = (&input.time, &input.motor);
    let n = time.len();
    let slopes = motor_slopes(time, motor);
    // the sample interval [time[k], time[k + 1]] that holds `t`, searched on from `k`
    let interval = |mut k: usize, t: f64| {
        while k + 2 < n && time[k + 1] < t {
            k += 1;
        }
        k
    };
    let motor_at = |k: usize, t: f64| {
        let span = time[k + 1] - time[k];
        let s = ((t - time[k]) / span).clamp(0.0, 1.0);
        hermite(s, motor[k], slopes[k] * span, motor[k + 1], slopes[k + 1] * span)
    };
    let housing_at = |k: usize, t: f64| {
        let s = ((t - time[k]) / (time[k + 1] - time[k])).clamp(0.0, 1.0);
        input.housing_k[k] + s * (input.housing_k[k + 1] - input.housing_k[k])
    };
    let vrs = [h.motor_cmd, h.speed_cmd, h.housing_cmd];
    let mut link = [0.0; 2];
    inst.get_reals(&[h.link, h.link_speed], &mut link)?;
    let mut out = Vec::with_capacity(n);
    out.push(input.link0);
    let t0 = time[0];
    let (mut k_mid, mut k_end) = (0, 0);
    let mut at = motor[0];
    let mut i = 0usize;
    while out.len() < n {
        check_deadline(i, until)?;
        let (start, end) = (t0 + i as f64 * step, t0 + (i + 1) as f64 * step);
        k_mid = interval(k_mid, start + 0.5 * step);
        k_end = interval(k_end, end);
        let next = motor_at(k_end, end);
        inst.set_reals(&vrs, &[at, (next - at) / step, housing_at(k_mid, start + 0.5 * step)])?;
        inst.step(step)?;
        let before = link;
        inst.get_reals(&[h.link, h.link_speed], &mut link)?;
        while out.len() < n && time[out.len()] <= end {
            let s = ((time[out.len()] - start) / step).clamp(0.0, 1.0);
            out.push(hermite(s, before[0], before[1] * step, link[0], link[1] * step));
        }
        at = next;
        i += 1;
    }
    Ok(out)
}

/// The PCL's temperature at `now` (time s, housing K) behind the housing temperatures `before` it,
/// through a first-order lag of `tau` s that starts level with the first of them: the FMU's
/// `thermal_lag_time_constant`, integrated exactly over each interval with the housing linear
/// between samples (a gap's too: the thermocouple is not logged there). Without a lag or a history,
/// the housing temperature at `now`.
///
/// Only the last `LAG_MEMORY` time constants of the history are walked: what the PCL lagged before
/// them has decayed by e^−40 (below a double's resolution of the lag), so a late segment of a long
/// log costs the same as an early one.
pub fn lagged_pcl(before: &[(f64, f64)], now: (f64, f64), tau: f64) -> f64 {
    if before.is_empty() || tau <= 0.0 {
        return now.1;
    }
    let first = before.partition_point(|&(t, _)| t < now.0 - LAG_MEMORY * tau).saturating_sub(1);
    let before = &before[first..];
    // e = T_pcl − T_housing follows e' = −e/τ − s on an interval where the housing rises at s
    let mut e = 0.0;
    for w in before.windows(2).map(|w| (w[0], w[1])).chain(before.last().map(|&l| (l, now))) {
        let ((t0, h0), (t1, h1)) = w;
        let dt = t1 - t0;
        if dt <= 0.0 {
            continue;
        }
        let s = (h1 - h0) / dt;
        e = -s * tau + (e + s * tau) * (-dt / tau).exp();
    }
    now.1 + e
}

/// Time constants of history that `lagged_pcl` walks.
const LAG_MEMORY: f64 = 40.0;

/// One simulated link-angle trace, or why the simulation failed.
pub type JobResult = Result<Vec<f64>, String>;

/// A pool of FMU instances for simulating many (run, model) jobs in parallel.
pub struct Simulator {
    pub fmu: Fmu,
    instances: Vec<Mutex<Instance>>,
    /// Number of FMU simulations done (for reporting the cost of a fit).
    pub simulations: AtomicUsize,
    /// Past this instant every simulation fails at once: the backstop that bounds a whole
    /// calibration's wall time (`--search-budget`), whatever fit is running.
    deadline: Mutex<Option<std::time::Instant>>,
    /// Why the latest simulation failed: the fit's own error ("could not simulate …") says only
    /// that one did, and a user needs the FMU's reason (an input out of range, a solver stall).
    last_failure: Mutex<Option<String>>,
}

/// The message of a simulation refused past the deadline.
pub const DEADLINE_PASSED: &str = "the calibration's time budget ran out (--search-budget)";

impl Simulator {
    pub fn new(fmu: Fmu, threads: usize) -> Result<Self, HarnessError> {
        let instances = (0..threads.max(1)).map(|_| fmu.instantiate(None).map(Mutex::new)).collect::<Result<_, _>>()?;
        Ok(Simulator {
            fmu,
            instances,
            simulations: AtomicUsize::new(0),
            deadline: Mutex::new(None),
            last_failure: Mutex::new(None),
        })
    }

    /// Every simulation started after `at` fails with [`DEADLINE_PASSED`], and one running then
    /// stops with it.
    pub fn set_deadline(&self, at: std::time::Instant) {
        *self.deadline.lock().unwrap_or_else(|p| p.into_inner()) = Some(at);
    }

    /// Moves the deadline to `at` where that is earlier (never later).
    pub fn tighten_deadline(&self, at: std::time::Instant) {
        let mut d = self.deadline.lock().unwrap_or_else(|p| p.into_inner());
        *d = Some(d.map_or(at, |d| d.min(at)));
    }

    /// Runs `f` with the deadline moved to `at` where that is earlier (as [`Simulator::tighten_deadline`];
    /// None leaves it), then puts it back as it was: a stage of the calibration held to a share of
    /// its time, or one after the deadline was lifted bounded again.
    pub fn within<T>(&self, at: Option<std::time::Instant>, f: impl FnOnce() -> T) -> T {
        let before = self.deadline();
        if let Some(at) = at {
            self.tighten_deadline(at);
        }
        let out = f();
        *self.deadline.lock().unwrap_or_else(|p| p.into_inner()) = before;
        out
    }

    /// Lifts the deadline: the simulations that write the report of a model already chosen.
    pub fn clear_deadline(&self) {
        *self.deadline.lock().unwrap_or_else(|p| p.into_inner()) = None;
    }

    /// The deadline, if one is set.
    pub fn deadline(&self) -> Option<std::time::Instant> {
        *self.deadline.lock().unwrap_or_else(|p| p.into_inner())
    }

    pub fn past_deadline(&self) -> bool {
        self.deadline().is_some_and(|d| std::time::Instant::now() >= d)
    }

    pub fn threads(&self) -> usize {
        self.instances.len()
    }

    /// Runs `f` on every job with an instance of the pool, in parallel; results in job order.
    pub fn map<T: Sync, R: Send>(&self, jobs: &[T], f: impl Fn(&mut Instance, &T) -> R + Sync) -> Vec<R> {
        let out = super::parallel::map_with(&self.instances, jobs, f);
        self.simulations.fetch_add(jobs.len(), Ordering::Relaxed);
        out
    }

    /// The FMU's transmission with the table's moduli at a housing (and PCL) temperature and an
    /// excitation frequency, read from its `effective_stiffness` and `effective_damping` outputs.
    pub fn transmission_table(&self, temperature_k: f64, frequency_hz: f64) -> Result<TransmissionTable, HarnessError> {
        let mut inst = self.instances[0].lock().unwrap_or_else(|p| p.into_inner());
        inst.reset()?;
        inst.initialize(
            0.0,
            None,
            &[
                ("thermal_drive", 1.0),
                ("initial_housing_temperature", temperature_k),
                ("initial_pcl_temperature", temperature_k),
                ("excitation_frequency", frequency_hz),
            ],
        )?;
        Ok(TransmissionTable {
            stiffness: inst.get("effective_stiffness")?,
            damping: inst.get("effective_damping")?,
            frequency_hz,
            spring_stiffness: inst.get("spring_stiffness")?,
            link_inertia: inst.get("link_inertia")?,
            spring_bank: inst.get("spring_bank_stiffness")?,
        })
    }

    /// Runs every job; results in job order. A failed simulation (e.g. the solver stalls for an
    /// absurd trial parameter) is returned as an error for that job only.
    pub fn run_jobs(&self, inputs: &[SimInput], jobs: &[(usize, RunModel)]) -> Vec<JobResult> {
        // `simulate` refuses a job already past the deadline at its first step, and stops one that
        // reaches it
        let until = self.deadline();
        self.map(jobs, |inst, (run, model)| {
            simulate(inst, &inputs[*run], model, until).map_err(|e| {
                let why = e.to_string();
                *self.last_failure.lock().unwrap_or_else(|p| p.into_inner()) = Some(why.clone());
                why
            })
        })
    }

    /// The reason the latest failed simulation gave, if any failed.
    pub fn last_failure(&self) -> Option<String> {
        self.last_failure.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lag's recurrence over every sample of the history, from the first.
    fn walked_from_the_first(before: &[(f64, f64)], now: (f64, f64), tau: f64) -> f64 {
        let mut e = 0.0;
        for w in before.windows(2).map(|w| (w[0], w[1])).chain(before.last().map(|&l| (l, now))) {
            let ((t0, h0), (t1, h1)) = w;
            let s = (h1 - h0) / (t1 - t0);
            e = -s * tau + (e + s * tau) * (-(t1 - t0) / tau).exp();
        }
        now.1 + e
    }

    #[test]
    fn a_long_history_is_walked_only_as_far_as_the_lag_remembers() {
        // 200 s at 1 kHz of a heating with a slow swing, and a gap of 0.3 s before `now`
        let housing = |t: f64| 313.15 + 8.0 * (1.0 - (-t / 30.0).exp()) + 0.5 * (0.1 * t).sin();
        let before: Vec<(f64, f64)> = (0..200_000).map(|k| k as f64 * 1e-3).map(|t| (t, housing(t))).collect();
        let now = (200.3, housing(200.3));
        for tau in [0.05, 0.5, 3.0, 10.0] {
            let (windowed, whole) = (lagged_pcl(&before, now, tau), walked_from_the_first(&before, now, tau));
            assert!((windowed - whole).abs() < 1e-9, "τ {tau} s: {windowed} K against {whole} K");
            assert!((now.1 - whole).abs() > 1e-3, "τ {tau} s: no lag to carry ({} K)", now.1 - whole);
        }
        // a history shorter than the lag's memory is walked whole: the same number
        assert_eq!(lagged_pcl(&before, now, 10.0), walked_from_the_first(&before, now, 10.0));
    }
}
