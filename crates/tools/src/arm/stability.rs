//! Stability limit of the co-simulation's communication step.
//!
//! Over one step each FMU integrates its own linear joint exactly (motor J_m, transmission K, C,
//! link with the coupling inertia J_i) with its inputs held; the master's law v_n = f(x_n) closes
//! the loop once per step. Linearised about a static rest state (plan frozen, wall included), with
//! x = [θm, θm', q, q'] of both joints,
//!
//!   x_{n+1} = (e^{A h} + Γ(h) F) x_n,      F = ∂f/∂x (finite differences of `master_law`),
//!
//! and the scheme is stable about that rest state iff the spectral radius of this map is below 1. The limit
//! is the smallest h at which that fails over poses sampled along the motion (contact included).
//! Closed forms estimate the mechanisms (see `estimates`); the nonlinear co-simulation through
//! the FMU checks the limit from both sides (`thermovia arm` report).

use nalgebra::{SMatrix, SVector};

use super::dynamics::{ArmConfig, V2};
use super::sim::{master_law, JointOutputs, JointProps};

type A8 = SMatrix<f64, 8, 8>;

fn continuous(cfg: &ArmConfig, props: &[JointProps; 2]) -> (A8, SMatrix<f64, 8, 4>) {
    let mut a = A8::zeros();
    let mut b = SMatrix::<f64, 8, 4>::zeros();
    for i in 0..2 {
        let o = 4 * i;
        let (k, c, jl) = (props[i].stiffness, props[i].damping, props[i].coupling_inertia);
        let (jm, bm) = (cfg.motor_inertia, cfg.motor_damping);
        let tau = [k, c, -k, -c]; // τ = k θm + c θm' − k q − c q'
        a[(o, o + 1)] = 1.0;
        a[(o + 2, o + 3)] = 1.0;
        for j in 0..4 {
            a[(o + 1, o + j)] = -tau[j] / jm;
            a[(o + 3, o + j)] = tau[j] / jl;
        }
        a[(o + 1, o + 1)] -= bm / jm;
        b[(o + 1, 2 * i)] = 1.0 / jm;
        b[(o + 3, 2 * i + 1)] = 1.0 / jl;
    }
    (a, b)
}

fn law(cfg: &ArmConfig, props: &[JointProps; 2], t: f64, x: &SVector<f64, 8>) -> SVector<f64, 4> {
    let th = [x[0], x[4]];
    let thd = [x[1], x[5]];
    let q = [x[2], x[6]];
    let qd = [x[3], x[7]];
    let tau = [0, 1].map(|i| props[i].stiffness * (th[i] - q[i]) + props[i].damping * (thd[i] - qd[i]));
    let stiffness = [props[0].stiffness, props[1].stiffness];
    let y = JointOutputs { q, qd, motor_angle: th, motor_speed: thd, tau, stiffness, pcl_temperature_c: [0.0; 2] };
    let (u, l) = master_law(cfg, props, t, &y);
    SVector::<f64, 4>::from([u[0], l[0], u[1], l[1]])
}

/// Static equilibrium with the plan frozen at `t` (speeds 0): the arm rests where transmission,
/// gravity and wall balance, and each motor where its PD balances the transmission. Newton on q.
/// `guess`: the link angles to start from (continuation along the motion finds the rest state the
/// arm actually reaches; the frictionless wall also has unstable rest states further along it).
pub fn equilibrium(cfg: &ArmConfig, props: &[JointProps; 2], t: f64, guess: V2) -> SVector<f64, 8> {
    let (qd, _) = cfg.plan(t);
    let gd = cfg.gravity_torque(qd);
    let k = [props[0].stiffness, props[1].stiffness];
    // motor angle that balances the PD against the transmission for a link at q
    let motor = |q: V2| [0, 1].map(|i| (cfg.kp * (qd[i] + gd[i] / k[i]) + gd[i] + k[i] * q[i]) / (cfg.kp + k[i]));
    let residual = |q: V2| {
        let m = motor(q);
        let tau = [0, 1].map(|i| k[i] * (m[i] - q[i]));
        let a = cfg.acceleration(q, [0.0, 0.0], tau);
        super::dynamics::mul(cfg.mass_matrix(q), a)
    };
    let mut q = guess;
    for _ in 0..200 {
        let r = residual(q);
        let mut jac = [[0.0; 2]; 2];
        for j in 0..2 {
            let mut qp = q;
            qp[j] += 1e-7;
            let rp = residual(qp);
            for i in 0..2 {
                jac[i][j] = (rp[i] - r[i]) / 1e-7;
            }
        }
        let dq = super::dynamics::solve(jac, r);
        // backtracking: the wall makes the residual kinked, so a full step can overshoot
        let norm = |r: V2| r[0].hypot(r[1]);
        let mut alpha = 1.0;
        while alpha > 1e-6 && norm(residual([q[0] - alpha * dq[0], q[1] - alpha * dq[1]])) >= norm(r) {
            alpha *= 0.5;
        }
        q = [q[0] - alpha * dq[0], q[1] - alpha * dq[1]];
        if norm(r) < 1e-12 || alpha * (dq[0].abs() + dq[1].abs()) < 1e-14 {
            break;
        }
    }
    let m = motor(q);
    SVector::<f64, 8>::from([m[0], 0.0, q[0], 0.0, m[1], 0.0, q[1], 0.0])
}

/// Spectral radius of the one-step map about rest state `x` with the plan frozen at `t`.
pub fn spectral_radius(cfg: &ArmConfig, props: &[JointProps; 2], t: f64, x: &SVector<f64, 8>, h: f64) -> f64 {
    let (a, b) = continuous(cfg, props);
    let x = *x;
    let mut f = SMatrix::<f64, 4, 8>::zeros();
    for j in 0..8 {
        let d = 1e-6 * (1.0 + x[j].abs());
        let mut xp = x;
        let mut xm = x;
        xp[j] += d;
        xm[j] -= d;
        let col = (law(cfg, props, t, &xp) - law(cfg, props, t, &xm)) / (2.0 * d);
        f.set_column(j, &col);
    }
    let mut m = SMatrix::<f64, 12, 12>::zeros();
    m.fixed_view_mut::<8, 8>(0, 0).copy_from(&(a * h));
    m.fixed_view_mut::<8, 4>(0, 8).copy_from(&(b * h));
    let e = m.exp();
    let phi = e.fixed_view::<8, 8>(0, 0).into_owned() + e.fixed_view::<8, 4>(0, 8).into_owned() * f;
    phi.complex_eigenvalues().iter().map(|z| z.norm()).fold(0.0, f64::max)
}

/// Rest states with the plan frozen at times along the whole move (those against the wall
/// included), found by continuation from the start pose.
pub fn rest_states(cfg: &ArmConfig, props: &[JointProps; 2]) -> Vec<(f64, SVector<f64, 8>)> {
    let mut guess = cfg.plan(0.0).0;
    (0..=40)
        .map(|k| {
            let t = cfg.move_start + cfg.move_duration * k as f64 / 40.0;
            let x = equilibrium(cfg, props, t, guess);
            guess = [x[2], x[6]];
            (t, x)
        })
        .collect()
}

/// Largest spectral radius over the sampled poses.
pub fn worst_radius(cfg: &ArmConfig, props: &[JointProps; 2], rest: &[(f64, SVector<f64, 8>)], h: f64) -> f64 {
    rest.iter().map(|(t, x)| spectral_radius(cfg, props, *t, x, h)).fold(0.0, f64::max)
}

/// Smallest communication step at which the linearised scheme becomes unstable at some sampled
/// pose (scan on a log grid from 0.05 ms to 200 ms, then bisection). None if stable throughout.
pub fn limit(cfg: &ArmConfig, props: &[JointProps; 2]) -> Option<f64> {
    let rest = rest_states(cfg, props);
    let worst_radius = |c: &ArmConfig, p: &[JointProps; 2], h: f64| worst_radius(c, p, &rest, h);
    let mut prev = 5e-5;
    if worst_radius(cfg, props, prev) >= 1.0 {
        return Some(prev);
    }
    for k in 1..=120 {
        let h = 5e-5 * (4000f64).powf(k as f64 / 120.0);
        if worst_radius(cfg, props, h) >= 1.0 {
            let (mut lo, mut hi) = (prev, h);
            for _ in 0..40 {
                let mid = 0.5 * (lo + hi);
                if worst_radius(cfg, props, mid) >= 1.0 {
                    hi = mid
                } else {
                    lo = mid
                }
            }
            return Some(lo);
        }
        prev = h;
    }
    None
}

/// Closed-form estimates of the two fast explicit loops, seconds (None: no limit from it).
#[derive(Clone, Debug, serde::Serialize)]
pub struct Estimates {
    /// Motor PD derivative held over the step against the transmission damping the FMU integrates
    /// exactly: θm'_{n+1} = [e^{−ch} − (kd/C')(1 − e^{−ch})] θm'_n with C' = C + B_m, c = C'/J_m,
    /// unstable when the factor passes −1: h = (J_m/C') ln((kd + C')/(kd − C')) if kd > C'.
    pub motor_loop: [Option<f64>; 2],
    /// Motor PD proportional term held over the step on the bare motor inertia (the transmission
    /// ignored): the held-spring map loses stability at kp h²/J_m = 4, h = 2 √(J_m/kp).
    pub motor_proportional: Option<f64>,
    /// Wall spring and damper held over the step on the tip's effective mass m:
    /// stable iff h < 2d/k and h < 2m/d.
    pub contact: Option<f64>,
}

pub fn estimates(cfg: &ArmConfig, props: &[JointProps; 2]) -> Estimates {
    let motor_loop = [0, 1].map(|i| {
        let c = props[i].damping + cfg.motor_damping;
        (cfg.kd > c).then(|| cfg.motor_inertia / c * ((cfg.kd + c) / (cfg.kd - c)).ln())
    });
    let contact = if cfg.wall_stiffness > 0.0 {
        // effective mass of the tip along x at the goal pose: 1 / (J M⁻¹ Jᵀ)_xx
        let q = cfg.plan(cfg.move_start + cfg.move_duration).0;
        let j = cfg.jacobian(q);
        let mi = super::dynamics::solve(cfg.mass_matrix(q), [j[0][0], j[0][1]]);
        let m = 1.0 / (j[0][0] * mi[0] + j[0][1] * mi[1]);
        let a = 2.0 * cfg.wall_damping / cfg.wall_stiffness;
        let b = if cfg.wall_damping > 0.0 { 2.0 * m / cfg.wall_damping } else { f64::INFINITY };
        Some(a.min(b))
    } else {
        None
    };
    let motor_proportional = (cfg.kp > 0.0).then(|| 2.0 * (cfg.motor_inertia / cfg.kp).sqrt());
    Estimates { motor_loop, motor_proportional, contact }
}
