//! The paper's rig around the FMU: a motor position loop (PD + feedforward)
//! that makes the torque-driven motor follow θ0 sin ωt, and a heater loop (PI on the housing
//! thermocouple only, as on the device) that brings the housing to a target and holds it.
//! Everything goes through the packaged FMU's C API via `thermovia_importer`.

use thermovia_importer::{HarnessError, Instance};

pub use crate::report::ZERO_CELSIUS;

/// Motor position loop: τ = J_m θr'' + B_m θr' + kp (θr − θm) + kd (θr' − θm').
///
/// The feedforward is the motor's own inertia and viscous loss (nominal values read from the FMU);
/// the transmission torque is a disturbance the PD rejects, as on a device without a torque sensor.
#[derive(Clone, Copy, Debug)]
pub struct MotorLoop {
    pub amplitude: f64,
    pub omega: f64,
    pub kp: f64,
    pub kd: f64,
    pub motor_inertia: f64,
    pub motor_damping: f64,
}

impl MotorLoop {
    /// Reference angle, speed and acceleration at `t` (s from the start of the run).
    pub fn reference(&self, t: f64) -> (f64, f64, f64) {
        let (s, c) = (self.omega * t).sin_cos();
        let a = self.amplitude;
        (a * s, a * self.omega * c, -a * self.omega * self.omega * s)
    }

    pub fn torque(&self, t: f64, angle: f64, speed: f64) -> f64 {
        let (r, rd, rdd) = self.reference(t);
        self.motor_inertia * rdd + self.motor_damping * rd + self.kp * (r - angle) + self.kd * (rd - speed)
    }
}

/// Heater loop: P = clamp(kp e + I, 0, p_max), e = T_target − T_housing, with the integral frozen
/// while the output saturates (no wind-up during the full-power heat-up).
#[derive(Clone, Copy, Debug)]
pub struct HeaterLoop {
    pub target_k: f64,
    pub kp: f64,
    pub ki: f64,
    pub p_max: f64,
    pub integral: f64,
}

impl HeaterLoop {
    pub fn power(&mut self, housing_k: f64, h: f64) -> f64 {
        let e = self.target_k - housing_k;
        let raw = self.kp * e + self.integral;
        let p = raw.clamp(0.0, self.p_max);
        // integrate only when not pushing further into saturation
        if (raw < self.p_max || e < 0.0) && (raw > 0.0 || e > 0.0) {
            self.integral += self.ki * e * h;
        }
        p
    }
}

/// Value references of the variables the master reads and writes.
#[derive(Clone, Copy, Debug)]
pub struct Vrs {
    pub motor_torque: u32,
    pub heater_power: u32,
    /// motor_angle, motor_speed, link_angle, link_speed, housing_temperature, pcl_temperature,
    /// effective_stiffness, effective_damping, storage_modulus, loss_modulus, heater_energy
    pub outputs: [u32; 11],
}

pub const OUTPUT_NAMES: [&str; 11] = [
    "motor_angle",
    "motor_speed",
    "link_angle",
    "link_speed",
    "housing_temperature",
    "pcl_temperature",
    "effective_stiffness",
    "effective_damping",
    "storage_modulus",
    "loss_modulus",
    "heater_energy",
];
pub const O_MOTOR_ANGLE: usize = 0;
pub const O_MOTOR_SPEED: usize = 1;
pub const O_LINK_ANGLE: usize = 2;
pub const O_HOUSING: usize = 4;
pub const O_PCL: usize = 5;
pub const O_K_EFF: usize = 6;
pub const O_C_EFF: usize = 7;
pub const O_E1: usize = 8;
pub const O_E2: usize = 9;
pub const O_ENERGY: usize = 10;

impl Vrs {
    pub fn resolve(inst: &Instance) -> Result<Vrs, HarnessError> {
        let mut outputs = [0; 11];
        for (o, n) in outputs.iter_mut().zip(OUTPUT_NAMES) {
            *o = inst.handle(n)?.value_reference;
        }
        Ok(Vrs {
            motor_torque: inst.handle("motor_torque")?.value_reference,
            heater_power: inst.handle("heater_power")?.value_reference,
            outputs,
        })
    }
}

/// One recorded sample: time, inputs applied over the step that ends here, and outputs.
#[derive(Clone, Debug, Default)]
pub struct Trace {
    pub time: Vec<f64>,
    pub reference: Vec<f64>,
    pub motor_torque: Vec<f64>,
    pub heater_power: Vec<f64>,
    /// One column per name in [`OUTPUT_NAMES`].
    pub outputs: Vec<Vec<f64>>,
}

impl Trace {
    fn with_capacity(n: usize) -> Trace {
        Trace {
            time: Vec::with_capacity(n),
            reference: Vec::with_capacity(n),
            motor_torque: Vec::with_capacity(n),
            heater_power: Vec::with_capacity(n),
            outputs: (0..OUTPUT_NAMES.len()).map(|_| Vec::with_capacity(n)).collect(),
        }
    }

    fn push(&mut self, t: f64, r: f64, tau: f64, p: f64, y: &[f64; 11]) {
        self.time.push(t);
        self.reference.push(r);
        self.motor_torque.push(tau);
        self.heater_power.push(p);
        for (c, v) in self.outputs.iter_mut().zip(y) {
            c.push(*v);
        }
    }

    pub fn len(&self) -> usize {
        self.time.len()
    }

    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }

    pub fn column(&self, output: usize) -> &[f64] {
        &self.outputs[output]
    }

    /// Columns in fmpy's result layout: time first, then one column per variable.
    pub fn columns(&self) -> Vec<(&'static str, &[f64])> {
        let mut cols: Vec<(&'static str, &[f64])> = vec![
            ("time", &self.time),
            ("motor_angle_reference", &self.reference),
            ("motor_torque", &self.motor_torque),
            ("heater_power", &self.heater_power),
        ];
        for (n, c) in OUTPUT_NAMES.iter().zip(&self.outputs) {
            cols.push((n, c));
        }
        cols
    }
}

/// Samples the state at the current time (before any step), with the inputs last applied.
fn sample(inst: &mut Instance, vrs: &Vrs, y: &mut [f64; 11]) -> Result<(), HarnessError> {
    inst.get_reals(&vrs.outputs, y)
}

/// What the warm-up achieved, read from the FMU's outputs.
#[derive(Clone, Debug, serde::Serialize)]
pub struct WarmupResult {
    pub target_c: f64,
    /// First time the housing thermocouple is within `tolerance_k` of the target, s.
    pub housing_reached_s: Option<f64>,
    pub housing_reached_energy_j: Option<f64>,
    /// First time the PCL (the model's estimate, no sensor on the device) is within `tolerance_k`.
    pub pcl_reached_s: Option<f64>,
    pub pcl_reached_energy_j: Option<f64>,
    pub tolerance_k: f64,
    pub duration_s: f64,
    pub energy_j: f64,
    pub final_housing_c: f64,
    pub final_pcl_c: f64,
}

/// Heats from the current state (motor at rest, zero torque, so the mechanics stays exactly at
/// rest) with communication step `h` for `duration` s, recording every `record_every` steps.
/// Returns the heater loop with its integral, to continue holding during the sweep.
pub fn warm_up(
    inst: &mut Instance,
    vrs: &Vrs,
    mut heater: HeaterLoop,
    h: f64,
    duration: f64,
    tolerance_k: f64,
) -> Result<(HeaterLoop, WarmupResult, Trace), HarnessError> {
    let n = (duration / h).round() as usize;
    let mut trace = Trace::with_capacity(n + 1);
    let mut y = [0.0; 11];
    let t0 = inst.time();
    sample(inst, vrs, &mut y)?;
    trace.push(0.0, 0.0, 0.0, 0.0, &y);
    inst.set_reals(&[vrs.motor_torque], &[0.0])?;
    let mut res = WarmupResult {
        target_c: heater.target_k - ZERO_CELSIUS,
        housing_reached_s: None,
        housing_reached_energy_j: None,
        pcl_reached_s: None,
        pcl_reached_energy_j: None,
        tolerance_k,
        duration_s: n as f64 * h,
        energy_j: 0.0,
        final_housing_c: y[O_HOUSING] - ZERO_CELSIUS,
        final_pcl_c: y[O_PCL] - ZERO_CELSIUS,
    };
    for _ in 0..n {
        let p = heater.power(y[O_HOUSING], h);
        inst.set_reals(&[vrs.heater_power], &[p])?;
        inst.step(h)?;
        sample(inst, vrs, &mut y)?;
        let t = inst.time() - t0;
        trace.push(t, 0.0, 0.0, p, &y);
        if res.housing_reached_s.is_none() && (heater.target_k - y[O_HOUSING]).abs() <= tolerance_k {
            res.housing_reached_s = Some(t);
            res.housing_reached_energy_j = Some(y[O_ENERGY]);
        }
        if res.pcl_reached_s.is_none() && (heater.target_k - y[O_PCL]).abs() <= tolerance_k {
            res.pcl_reached_s = Some(t);
            res.pcl_reached_energy_j = Some(y[O_ENERGY]);
        }
    }
    res.energy_j = y[O_ENERGY];
    res.final_housing_c = y[O_HOUSING] - ZERO_CELSIUS;
    res.final_pcl_c = y[O_PCL] - ZERO_CELSIUS;
    Ok((heater, res, trace))
}

/// Runs the motor loop from rest for `steps` communication steps of `h`, holding the housing with
/// `heater` (None: heater off). Time in the trace starts at 0 with the run.
pub fn harmonic_run(
    inst: &mut Instance,
    vrs: &Vrs,
    motor: &MotorLoop,
    mut heater: Option<HeaterLoop>,
    h: f64,
    steps: usize,
) -> Result<Trace, HarnessError> {
    let mut trace = Trace::with_capacity(steps + 1);
    let mut y = [0.0; 11];
    sample(inst, vrs, &mut y)?;
    trace.push(0.0, 0.0, 0.0, 0.0, &y);
    for k in 0..steps {
        let t = k as f64 * h;
        let tau = motor.torque(t, y[O_MOTOR_ANGLE], y[O_MOTOR_SPEED]);
        let p = heater.as_mut().map_or(0.0, |ht| ht.power(y[O_HOUSING], h));
        inst.set_reals(&[vrs.motor_torque, vrs.heater_power], &[tau, p])?;
        inst.step(h)?;
        sample(inst, vrs, &mut y)?;
        let t1 = (k + 1) as f64 * h;
        trace.push(t1, motor.reference(t1).0, tau, p, &y);
    }
    Ok(trace)
}

/// Heating from the current state at up to `power` W, either holding the housing at the target
/// (`hold`, the sweep's protocol) or at constant power `heater.p_max` (the housing overshoots),
/// until the PCL reaches the target or `max_s` passes.
#[derive(Clone, Debug, serde::Serialize)]
pub struct HeatingResult {
    pub power_w: f64,
    pub mode: &'static str,
    pub target_c: f64,
    pub housing_reached_s: Option<f64>,
    pub housing_reached_energy_j: Option<f64>,
    pub pcl_reached_s: Option<f64>,
    pub pcl_reached_energy_j: Option<f64>,
    pub peak_housing_c: f64,
}

#[allow(clippy::too_many_arguments)]
pub fn heating_study(
    inst: &mut Instance,
    vrs: &Vrs,
    mut heater: HeaterLoop,
    hold: bool,
    tolerance_k: f64,
    h: f64,
    max_s: f64,
) -> Result<HeatingResult, HarnessError> {
    let (power, target_k) = (heater.p_max, heater.target_k);
    let mut y = [0.0; 11];
    sample(inst, vrs, &mut y)?;
    inst.set_reals(&[vrs.motor_torque], &[0.0])?;
    let mut r = HeatingResult {
        power_w: power,
        mode: if hold { "housing held at the target" } else { "constant power" },
        target_c: target_k - ZERO_CELSIUS,
        housing_reached_s: None,
        housing_reached_energy_j: None,
        pcl_reached_s: None,
        pcl_reached_energy_j: None,
        peak_housing_c: y[O_HOUSING] - ZERO_CELSIUS,
    };
    let t0 = inst.time();
    while r.pcl_reached_s.is_none() && inst.time() - t0 < max_s {
        let p = if hold { heater.power(y[O_HOUSING], h) } else { power };
        inst.set_reals(&[vrs.heater_power], &[p])?;
        inst.step(h)?;
        sample(inst, vrs, &mut y)?;
        let t = inst.time() - t0;
        r.peak_housing_c = r.peak_housing_c.max(y[O_HOUSING] - ZERO_CELSIUS);
        if r.housing_reached_s.is_none() && y[O_HOUSING] >= target_k - tolerance_k {
            r.housing_reached_s = Some(t);
            r.housing_reached_energy_j = Some(y[O_ENERGY]);
        }
        if y[O_PCL] >= target_k - tolerance_k {
            r.pcl_reached_s = Some(t);
            r.pcl_reached_energy_j = Some(y[O_ENERGY]);
        }
    }
    Ok(r)
}
