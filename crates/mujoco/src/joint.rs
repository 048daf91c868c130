//! One ThermoVIA joint in MuJoCo, in safe Rust: its `plugin_state` layout, the step of the
//! link-driven model, and the coupling's stability limit.
//!
//! The coupling is the FMU co-simulation's (examples/mujoco), moved inside MuJoCo's step. For the
//! step [t, t + h], `compute` steps a scratch copy of the joint with the link on the line
//! q(t) + q'(t) s (the link-driven mode) under the motor torque (ctrl) and heater power, and hands
//! MuJoCo the transmission's mean torque over that step: its impulse divided by h, from the motor's
//! momentum balance. MuJoCo integrates the link with it; `advance` then commits the scratch step to
//! `plugin_state`. `compute` never writes `plugin_state`, so calling it again (mj_forward, finite
//! differences) changes nothing.
//!
//! The transmission's damping on a light link can be stiffer than the step (C/J ≈ 2000 1/s on the
//! example's base joint). A joint `damping` D in the MJCF is taken implicitly by MuJoCo (Euler and
//! implicit integrators); with `implicit_damping` = D the plugin adds D q'(t) back, so the link
//! receives the mean torque less D (q'(t + h) − q'(t)): the co-simulation's scheme with D in place
//! of its per-step C_eff.

use thermovia_model::thermal::ThermalState;
use thermovia_model::{Model, Params, STATE_LEN};
use thermovia_variables::by_name;

use crate::config::Setup;

/// `plugin_state`, in order: the model's state ([`Model::state`]), whether the motor has been
/// placed since the last reset, then what the last step (or the reset) computed for reading.
pub const STATE_NAMES: [&str; STATE_LEN + 1 + OUTPUTS] = [
    "motor_angle",
    "motor_speed",
    "link_angle",
    "link_speed",
    "maxwell_deflection",
    "housing_temperature",
    "pcl_enthalpy",
    "pcl_temperature",
    "heater_energy",
    "heat_lost",
    "adaptive_step",
    "sine_anchor_angle",
    "sine_anchor_sin",
    "sine_anchor_cos",
    "pcl_structural_temperature",
    "pcl_crystallisation_integral",
    "transmitted_torque_mean",
    "motor_placed",
    "effective_stiffness",
    "effective_damping",
    "pcl_crystallinity",
    "pcl_melt_fraction",
    "transmitted_torque",
];
const OUTPUTS: usize = 5;
pub const STATE_SIZE: usize = STATE_NAMES.len();
pub const MOTOR_PLACED: usize = STATE_LEN;
/// Where the step's mean torque on the link sits in `plugin_state`.
pub const TORQUE_MEAN: usize = STATE_LEN - 1;

/// What MuJoCo gives the joint for one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepInputs {
    /// q(t), rad
    pub angle: f64,
    /// q'(t), rad/s, held over the step
    pub speed: f64,
    /// the actuator's ctrl, N·m
    pub motor_torque: f64,
    /// the heater actuator's ctrl, W
    pub heater_power: f64,
    /// MuJoCo's timestep, s
    pub step: f64,
}

/// A step computed by `compute`, waiting for `advance`.
#[derive(Clone, Debug)]
struct Pending {
    before: [f64; STATE_SIZE],
    inputs: StepInputs,
    after: [f64; STATE_SIZE],
    torque: f64,
}

#[derive(Clone, Debug)]
pub struct Joint {
    model: Model,
    ambient_temperature: f64,
    implicit_damping: f64,
    motor_torque_range: Range,
    heater_power_range: Range,
    pending: Option<Pending>,
}

/// An input's range from the variable table, looked up once per joint.
#[derive(Clone, Copy, Debug)]
struct Range(f64, f64);

impl Range {
    fn of(name: &str) -> Range {
        let v = by_name(name).expect("an input of the table");
        Range(v.min.unwrap_or(f64::MIN), v.max.unwrap_or(f64::MAX))
    }

    /// Into the range; a non-finite value counts as 0.
    fn clamp(self, x: f64) -> f64 {
        (if x.is_finite() { x } else { 0.0 }).clamp(self.0, self.1)
    }
}

impl Joint {
    pub fn new(setup: &Setup) -> Joint {
        let mut model = Model::new(setup.params.clone());
        model.inputs.ambient_temperature = setup.ambient_temperature;
        Joint {
            model,
            ambient_temperature: setup.ambient_temperature,
            implicit_damping: setup.implicit_damping,
            motor_torque_range: Range::of("motor_torque"),
            heater_power_range: Range::of("heater_power"),
            pending: None,
        }
    }

    /// The state after a reset: the model's initial state from its parameters, the motor not yet
    /// placed, and the outputs at that state.
    pub fn reset(&mut self, state: &mut [f64]) {
        self.pending = None;
        self.model.initialize();
        self.model.transmitted_torque_mean = 0.0;
        let x = self.model.state();
        state[..STATE_LEN].copy_from_slice(&x);
        state[MOTOR_PLACED] = 0.0;
        self.write_outputs(state);
    }

    fn write_outputs(&mut self, state: &mut [f64]) {
        let m = &mut self.model;
        let outputs = [
            m.effective_stiffness(),
            m.effective_damping(),
            m.crystallinity(),
            m.melt_fraction(),
            m.transmitted_torque(),
        ];
        state[MOTOR_PLACED + 1..].copy_from_slice(&outputs);
    }

    /// The torque MuJoCo applies on the joint over the step [t, t + h]: the transmission's mean
    /// torque over the step, plus `implicit_damping` q'(t) (given back for MuJoCo's implicit share).
    /// `state` is read, never written; the step waits for [`Joint::advance`]. An error (the model
    /// refused the step) leaves nothing pending: the joint keeps its state.
    pub fn compute(&mut self, state: &[f64], u: StepInputs) -> Result<f64, String> {
        let u = StepInputs {
            motor_torque: self.motor_torque_range.clamp(u.motor_torque),
            heater_power: self.heater_power_range.clamp(u.heater_power),
            ..u
        };
        if let Some(p) = &self.pending {
            if p.inputs == u && same_bits(&p.before, state) {
                return Ok(p.torque);
            }
        }
        self.pending = None;
        let before: [f64; STATE_SIZE] =
            state.try_into().map_err(|_| format!("plugin_state holds {} numbers, not {STATE_SIZE}", state.len()))?;
        let after = self.step(&before, &u)?;
        let torque = after[TORQUE_MEAN] + self.implicit_damping * u.speed;
        if !torque.is_finite() {
            return Err(format!("the transmission's torque is {torque}"));
        }
        self.pending = Some(Pending { before, inputs: u, after, torque });
        Ok(torque)
    }

    fn step(&mut self, before: &[f64; STATE_SIZE], u: &StepInputs) -> Result<[f64; STATE_SIZE], String> {
        let mut x: [f64; STATE_LEN] = before[..STATE_LEN].try_into().expect("STATE_LEN <= STATE_SIZE");
        if before[MOTOR_PLACED] == 0.0 {
            // aligned with the joint: the transmission unloaded
            x[0] = u.angle;
            x[1] = u.speed;
        }
        x[2] = u.angle;
        x[3] = u.speed;
        self.model.set_state(&x);
        let inputs = &mut self.model.inputs;
        inputs.motor_torque = u.motor_torque;
        inputs.heater_power = u.heater_power;
        inputs.ambient_temperature = self.ambient_temperature;
        inputs.link_angle_command = u.angle;
        inputs.link_speed_command = u.speed;
        self.model.step(u.step).map_err(|f| format!("the model refused the step: {f:?}"))?;
        let mut after = [0.0; STATE_SIZE];
        after[..STATE_LEN].copy_from_slice(&self.model.state());
        after[MOTOR_PLACED] = 1.0;
        self.write_outputs(&mut after);
        // gravity's sine anchor is NaN until a sub-step needs it (Model::state)
        let anchor = STATE_NAMES.iter().position(|n| *n == "sine_anchor_angle").expect("named");
        let finite = |i: &usize| !(anchor..anchor + 3).contains(i);
        if let Some(i) = (0..STATE_SIZE).filter(finite).find(|&i| !after[i].is_finite()) {
            return Err(format!("{} became {}", STATE_NAMES[i], after[i]));
        }
        Ok(after)
    }

    /// Commits the step `compute` made for this state. If `plugin_state` was written in between,
    /// the step is made again from what it holds now, with the same inputs.
    pub fn advance(&mut self, state: &mut [f64]) -> Result<(), String> {
        let Some(p) = self.pending.take() else { return Ok(()) };
        if same_bits(&p.before, state) {
            state.copy_from_slice(&p.after);
            return Ok(());
        }
        let before: [f64; STATE_SIZE] =
            (&*state).try_into().map_err(|_| "plugin_state has the wrong size".to_string())?;
        let after = self.step(&before, &p.inputs)?;
        state.copy_from_slice(&after);
        Ok(())
    }

    /// `mj_copyData`: the copy continues exactly as the source would.
    pub fn copy_from(&mut self, src: &Joint) {
        self.pending = src.pending.clone();
    }
}

fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

/// The transmission's largest instantaneous stiffness (springs, PCL and a relaxing branch's spring)
/// and damping over the PCL temperatures the joint can reach: from the coldest of its initial
/// temperatures and the ambient to 100 K above, in 2 K steps (the moduli fall as the PCL warms; the
/// sweep also covers a loss peak in the melting range).
pub fn transmission_bounds(params: &Params, ambient_temperature: f64) -> (f64, f64) {
    let mut model = Model::new(params.clone());
    let coldest = params.initial_pcl_temperature.min(params.initial_housing_temperature).min(ambient_temperature);
    let (mut k, mut c) = (0.0_f64, 0.0_f64);
    for i in 0..=50 {
        let mut p = params.clone();
        p.initial_pcl_temperature = coldest + 2.0 * i as f64;
        p.initial_housing_temperature = p.initial_pcl_temperature;
        model.thermal = ThermalState::initial(&p);
        let co = model.coefficients();
        k = k.max(co.stiffness + co.maxwell_stiffness);
        c = c.max(co.damping);
    }
    (k, c)
}

/// The largest stable step of the coupling for a link of effective inertia `j` on a transmission of
/// stiffness `k` and damping `c`, with `d` of it taken implicitly by MuJoCo, the motor held.
///
/// Per step the link sees the mean torque −k (q + h q'/2) − c q' (the link on its line, the motor
/// held), plus d q' − d q'(t + h); MuJoCo's semi-implicit Euler then gives the map of (q, q')
/// with determinant α and trace 1 − hβ + α, α = (1 + a(d − c) − a k h / 2)/(1 + a d),
/// β = a k /(1 + a d), a = h / j. Jury's conditions reduce to h² k / j < 2 + h (2d − c) / j: the
/// co-simulation's h² K/J < 2 + h C/J at d = c, and h² K/J + h C/J < 2 at d = 0.
pub fn stability_limit(k: f64, c: f64, j: f64, d: f64) -> f64 {
    if k <= 0.0 {
        return if 2.0 * d >= c { f64::INFINITY } else { 2.0 * j / (c - 2.0 * d) };
    }
    let b = 2.0 * d - c;
    (b + (b * b + 8.0 * k * j).sqrt()) / (2.0 * k)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::parse;

    fn joint(pairs: &[(&str, &str)]) -> Joint {
        let map: std::collections::HashMap<String, String> =
            pairs.iter().map(|(k, v)| (k.to_string(), v.to_string())).collect();
        Joint::new(&parse(&|k: &str| map.get(k).cloned()).unwrap())
    }

    fn fresh(j: &mut Joint) -> [f64; STATE_SIZE] {
        let mut s = [0.0; STATE_SIZE];
        j.reset(&mut s);
        s
    }

    fn u(angle: f64, speed: f64, torque: f64) -> StepInputs {
        StepInputs { angle, speed, motor_torque: torque, heater_power: 5.0, step: 1e-3 }
    }

    #[test]
    fn the_names_cover_the_model_state_and_the_outputs() {
        assert_eq!(STATE_NAMES[STATE_LEN - 1], "transmitted_torque_mean");
        assert_eq!(STATE_NAMES[MOTOR_PLACED], "motor_placed");
        let mut j = joint(&[]);
        let s = fresh(&mut j);
        assert_eq!(s[MOTOR_PLACED], 0.0);
        // the outputs at the reset are the model's: K_eff of the cold default transmission
        let mut m = Model::new(Params::default());
        assert_eq!(s[STATE_NAMES.iter().position(|n| *n == "effective_stiffness").unwrap()], m.effective_stiffness());
    }

    #[test]
    fn compute_does_not_write_and_advance_commits_what_compute_made() {
        let mut j = joint(&[("implicit_damping", "2")]);
        let s0 = fresh(&mut j);
        let a = j.compute(&s0, u(0.1, 0.5, 0.3)).unwrap();
        let b = j.compute(&s0, u(0.1, 0.5, 0.3)).unwrap();
        assert_eq!(a.to_bits(), b.to_bits());
        let mut s = s0;
        j.advance(&mut s).unwrap();
        assert_eq!(s[MOTOR_PLACED], 1.0);
        // the motor was placed on the joint, then moved under the torque; the heater warmed the housing
        assert!(s[0] != 0.0 && s[5] > s0[5], "{:?}", &s[..8]);
        // the torque handed over is the step's mean plus the implicit share given back
        assert_eq!(a, s[STATE_LEN - 1] + 2.0 * 0.5);
        // a second joint from the same state and inputs lands on the same bits
        let mut j2 = joint(&[("implicit_damping", "2")]);
        let mut s2 = s0;
        j2.compute(&s2.clone(), u(0.1, 0.5, 0.3)).unwrap();
        j2.advance(&mut s2).unwrap();
        assert!(same_bits(&s, &s2));
    }

    #[test]
    fn a_state_written_between_compute_and_advance_is_stepped_from_what_it_holds() {
        let mut j = joint(&[]);
        let s0 = fresh(&mut j);
        j.compute(&s0, u(0.0, 0.0, 1.0)).unwrap();
        let mut s = s0;
        s[MOTOR_PLACED] = 1.0;
        s[0] = 0.2; // the user placed the motor
        j.advance(&mut s).unwrap();
        let mut k = joint(&[]);
        let mut t = s0;
        t[MOTOR_PLACED] = 1.0;
        t[0] = 0.2;
        k.compute(&t.clone(), u(0.0, 0.0, 1.0)).unwrap();
        k.advance(&mut t).unwrap();
        assert!(same_bits(&s, &t));
        assert!(s[STATE_LEN - 1] > 1.0, "the deflected transmission pushes the link: {}", s[STATE_LEN - 1]);
    }

    #[test]
    fn inputs_outside_the_tables_ranges_are_clamped_not_propagated() {
        let mut j = joint(&[]);
        let s0 = fresh(&mut j);
        let a = j.compute(&s0, StepInputs { heater_power: f64::NAN, motor_torque: 1e9, ..u(0.0, 0.0, 0.0) }).unwrap();
        let b = j.compute(&s0, StepInputs { heater_power: 0.0, motor_torque: 1e4, ..u(0.0, 0.0, 0.0) }).unwrap();
        assert_eq!(a.to_bits(), b.to_bits());
    }

    #[test]
    fn the_stability_limit_is_the_edge_of_the_linear_maps_stability() {
        // iterate the map of the doc comment just below and just above the limit
        let grows = |h: f64, k: f64, c: f64, jl: f64, d: f64| {
            let (mut q, mut v) = (1.0_f64, 0.0_f64);
            for _ in 0..20_000 {
                let tau = -k * (q + h * v / 2.0) - c * v + d * v;
                v = (jl * v + h * tau) / (jl + h * d);
                q += h * v;
            }
            !(q.abs() + v.abs() * h <= 1.0) // NaN after an overflow counts as growth
        };
        for (k, c, jl, d) in
            [(120.0, 7.3, 0.0031, 0.0), (120.0, 7.3, 0.0031, 7.3), (34.0, 0.5, 0.02, 1.0), (10.0, 0.0, 1e-3, 0.0)]
        {
            let h = stability_limit(k, c, jl, d);
            assert!(!grows(0.98 * h, k, c, jl, d), "stable below {h}: {k} {c} {jl} {d}");
            assert!(grows(1.02 * h, k, c, jl, d), "unstable above {h}: {k} {c} {jl} {d}");
        }
    }

    #[test]
    fn the_cold_transmission_bounds_the_warm_one() {
        let p = Params::default();
        let (k, c) = transmission_bounds(&p, p.initial_pcl_temperature);
        let mut m = Model::new(p);
        let co = m.coefficients();
        assert!(k >= co.stiffness && c >= co.damping && k.is_finite() && c.is_finite());
    }
}
