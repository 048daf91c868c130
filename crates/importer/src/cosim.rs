//! A fixed-step co-simulation master for several FMU instances (of one or several `.fmu` files).
//!
//! Scheme: Jacobi with zero-order hold. At every communication point t_n the master reads each
//! participant's declared outputs, calls the user's `exchange` with them (the place for the
//! master-side models: rigid-body dynamics, controllers, contact, schedules), writes the inputs it
//! returns, and steps every instance from t_n to t_n + h. Inputs are held over the step (FMI
//! co-simulation semantics), so anything computed from outputs at t_n reaches the FMUs with a delay
//! of one communication step. No participant sees another's t_{n+1} outputs before its own step.
//!
//! ```no_run
//! use thermovia_importer::{Fmu, cosim::Master};
//! let fmu = Fmu::open("target/fmu/ThermoVIA.fmu")?;
//! let mut master = Master::new(0.0, None);
//! let j = master.add(&fmu, "joint", &[("link_inertia", 0.05)], &["motor_torque"], &["motor_angle"])?;
//! let (u, y) = (master.input(j, "motor_torque")?, master.output(j, "motor_angle")?);
//! master.run(1e-3, 1000, |_t, io| {
//!     let e = 0.3 - io.get(y);
//!     io.set(u, 20.0 * e);
//!     Ok(())
//! })?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use super::{Fmu, HarnessError, Instance};

/// An input or output of one participant, resolved once (no name lookups in the loop).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Port {
    participant: usize,
    index: usize,
}

/// One FMU instance with the variables the master exchanges with it.
pub struct Participant {
    pub name: String,
    pub instance: Instance,
    input_names: Vec<String>,
    output_names: Vec<String>,
    input_vrs: Vec<u32>,
    output_vrs: Vec<u32>,
    inputs: Vec<f64>,
    outputs: Vec<f64>,
    /// Inputs as last written to the FMU; only changed ones are sent (each value crosses the C API).
    sent: Vec<f64>,
    changed_vrs: Vec<u32>,
    changed_values: Vec<f64>,
    /// Outputs read after every step (positions in `outputs`, value references), and those read
    /// only every `slow_every` steps (quantities on a slower time scale, e.g. temperatures).
    fast: (Vec<usize>, Vec<u32>),
    slow: (Vec<usize>, Vec<u32>),
    slow_every: u64,
    scratch: Vec<f64>,
}

impl Participant {
    fn read(&mut self, slow_too: bool) -> Result<(), HarnessError> {
        for (group, wanted) in [(&self.fast, true), (&self.slow, slow_too)] {
            if !wanted || group.1.is_empty() {
                continue;
            }
            self.scratch.resize(group.1.len(), 0.0);
            self.instance.get_reals(&group.1, &mut self.scratch)?;
            for (k, &pos) in group.0.iter().enumerate() {
                self.outputs[pos] = self.scratch[k];
            }
        }
        Ok(())
    }
}

/// What `exchange` sees at a communication point: every participant's outputs at t_n (read-only)
/// and the inputs to hold over [t_n, t_n + h] (initialised with the previous step's values).
pub struct Exchange<'a> {
    participants: &'a mut [Participant],
}

impl Exchange<'_> {
    /// Output value at the current communication point.
    pub fn get(&self, p: Port) -> f64 {
        self.participants[p.participant].outputs[p.index]
    }
    /// Input value for the coming step (it keeps its last value unless set).
    pub fn set(&mut self, p: Port, value: f64) {
        self.participants[p.participant].inputs[p.index] = value;
    }
    /// The input's value as last set.
    pub fn input(&self, p: Port) -> f64 {
        self.participants[p.participant].inputs[p.index]
    }
}

/// Error from a user's exchange function or from an FMU, with the time it happened.
#[derive(Debug)]
pub enum CosimError {
    Fmu { participant: String, time: f64, source: HarnessError },
    Exchange { time: f64, reason: String },
}

impl std::fmt::Display for CosimError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CosimError::Fmu { participant, time, source } => write!(f, "{participant} at t = {time} s: {source}"),
            CosimError::Exchange { time, reason } => write!(f, "master at t = {time} s: {reason}"),
        }
    }
}

impl std::error::Error for CosimError {}

/// The master: participants, the communication clock, the Jacobi step.
pub struct Master {
    participants: Vec<Participant>,
    start_time: f64,
    stop_time: Option<f64>,
    steps: u64,
    time: f64,
}

impl Master {
    /// A master whose participants start at `start_time` (stop time passed to fmi2SetupExperiment).
    pub fn new(start_time: f64, stop_time: Option<f64>) -> Self {
        Master { participants: Vec::new(), start_time, stop_time, steps: 0, time: start_time }
    }

    /// Instantiates `fmu` as participant `name`, sets `parameters`, initialises it at the start
    /// time, and declares which inputs the master writes and which outputs it reads. Returns the
    /// participant's index. Names are checked here, so a typo fails before the run.
    pub fn add(
        &mut self,
        fmu: &Fmu,
        name: &str,
        parameters: &[(&str, f64)],
        inputs: &[&str],
        outputs: &[&str],
    ) -> Result<usize, HarnessError> {
        let mut instance = fmu.instantiate(Some(name))?;
        let resolve = |names: &[&str]| -> Result<Vec<u32>, HarnessError> {
            names.iter().map(|n| instance.handle(n).map(|h| h.value_reference)).collect()
        };
        let input_vrs = resolve(inputs)?;
        let output_vrs = resolve(outputs)?;
        let output_vrs_fast = output_vrs.clone();
        instance.initialize(self.start_time, self.stop_time, parameters)?;
        let mut input_values = vec![0.0; inputs.len()];
        instance.get_reals(&input_vrs, &mut input_values)?; // start values of the inputs
        let mut output_values = vec![0.0; outputs.len()];
        instance.get_reals(&output_vrs, &mut output_values)?;
        self.participants.push(Participant {
            name: name.to_string(),
            instance,
            input_names: inputs.iter().map(|s| s.to_string()).collect(),
            output_names: outputs.iter().map(|s| s.to_string()).collect(),
            input_vrs,
            output_vrs,
            sent: input_values.clone(),
            inputs: input_values,
            outputs: output_values,
            changed_vrs: Vec::with_capacity(inputs.len()),
            changed_values: Vec::with_capacity(inputs.len()),
            fast: ((0..outputs.len()).collect(), output_vrs_fast),
            slow: (Vec::new(), Vec::new()),
            slow_every: 1,
            scratch: Vec::with_capacity(outputs.len()),
        });
        Ok(self.participants.len() - 1)
    }

    fn port(names: &[String], participant: usize, who: &str, name: &str, kind: &str) -> Result<Port, HarnessError> {
        names.iter().position(|n| n == name).map(|index| Port { participant, index }).ok_or_else(|| {
            HarnessError::UnknownVariable {
                name: format!("{name} (not declared as an {kind} of {who} in Master::add)"),
                close: names.to_vec(),
            }
        })
    }

    /// The port of a declared input of participant `p`.
    pub fn input(&self, p: usize, name: &str) -> Result<Port, HarnessError> {
        let part = &self.participants[p];
        Self::port(&part.input_names, p, &part.name, name, "input")
    }

    /// The port of a declared output of participant `p`.
    pub fn output(&self, p: usize, name: &str) -> Result<Port, HarnessError> {
        let part = &self.participants[p];
        Self::port(&part.output_names, p, &part.name, name, "output")
    }

    /// Number of communication steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Reads the named outputs of participant `p` only every `every` steps (and at the start):
    /// each value read crosses the C API, and quantities that change on a slow time scale (the
    /// thermal ones, seconds) need not be fetched every millisecond. `exchange` then sees the
    /// value from the last read, at most `every − 1` steps old.
    pub fn read_every(&mut self, p: usize, outputs: &[&str], every: u64) -> Result<(), HarnessError> {
        let ports: Vec<Port> = outputs.iter().map(|n| self.output(p, n)).collect::<Result<_, _>>()?;
        let part = &mut self.participants[p];
        for port in ports {
            if let Some(k) = part.fast.0.iter().position(|&i| i == port.index) {
                part.fast.0.remove(k);
                part.fast.1.remove(k);
                part.slow.0.push(port.index);
                part.slow.1.push(part.output_vrs[port.index]);
            }
        }
        part.slow_every = every.max(1);
        Ok(())
    }

    /// Current communication time.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Current value of a declared output (after the last step).
    pub fn get(&self, p: Port) -> f64 {
        self.participants[p.participant].outputs[p.index]
    }

    pub fn participant_mut(&mut self, p: usize) -> &mut Participant {
        &mut self.participants[p]
    }

    /// Reads any variable of a participant by name (outside the hot loop).
    pub fn get_by_name(&mut self, p: usize, name: &str) -> Result<f64, HarnessError> {
        self.participants[p].instance.get(name)
    }

    /// One communication step of length `h`: exchange at t_n, then every participant steps.
    pub fn step<F>(&mut self, h: f64, exchange: &mut F) -> Result<(), CosimError>
    where
        F: FnMut(f64, &mut Exchange) -> Result<(), String>,
    {
        let t = self.time;
        exchange(t, &mut Exchange { participants: &mut self.participants })
            .map_err(|reason| CosimError::Exchange { time: t, reason })?;
        for p in &mut self.participants {
            p.changed_vrs.clear();
            p.changed_values.clear();
            for i in 0..p.inputs.len() {
                if p.inputs[i].to_bits() != p.sent[i].to_bits() {
                    p.changed_vrs.push(p.input_vrs[i]);
                    p.changed_values.push(p.inputs[i]);
                }
            }
            if !p.changed_vrs.is_empty() {
                p.instance.set_reals(&p.changed_vrs, &p.changed_values).map_err(|source| CosimError::Fmu {
                    participant: p.name.clone(),
                    time: t,
                    source,
                })?;
                p.sent.copy_from_slice(&p.inputs);
            }
        }
        for p in &mut self.participants {
            p.instance.step(h).map_err(|source| CosimError::Fmu { participant: p.name.clone(), time: t, source })?;
            let slow_too = (self.steps + 1).is_multiple_of(p.slow_every);
            p.read(slow_too).map_err(|source| CosimError::Fmu { participant: p.name.clone(), time: t + h, source })?;
        }
        self.steps += 1;
        self.time += h; // the same sum each instance's clock makes, so both agree exactly
        Ok(())
    }

    /// `n` steps of length `h` with the same exchange function.
    pub fn run<F>(&mut self, h: f64, n: u64, mut exchange: F) -> Result<(), CosimError>
    where
        F: FnMut(f64, &mut Exchange) -> Result<(), String>,
    {
        for _ in 0..n {
            self.step(h, &mut exchange)?;
        }
        Ok(())
    }
}
