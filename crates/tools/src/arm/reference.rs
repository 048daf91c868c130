//! Monolithic reference: the same arm as one ODE, integrated by an adaptive Dormand–Prince 5(4) at a
//! tight tolerance. It never calls the FMU: the joint transmissions are written out here,
//!
//!   J_m θm_i'' = u_i − B_m θm_i' − τ_i,    τ_i = K_i (θm_i − q_i) + C_i (θm_i' − q_i')
//!   M(q) q''   = τ − c(q, q') − g(q) + Jᵀ F_wall
//!
//! with K_i, C_i read from the FMU's outputs at the joint's (constant) temperature, and the joint
//! controller acting continuously (no sampling, no hold). What differs from the co-simulation is
//! exactly the coupling: exchange at communication points, inputs held, one-step delay.

use super::dynamics::ArmConfig;
use super::sim::{JointOutputs, JointProps, Trace};

type Y = [f64; 8]; // θm1, θm2, θm1', θm2', q1, q2, q1', q2'

fn rhs(cfg: &ArmConfig, props: &[JointProps; 2], t: f64, y: &Y) -> Y {
    let (th, thd, q, qd) = ([y[0], y[1]], [y[2], y[3]], [y[4], y[5]], [y[6], y[7]]);
    let tau = [0, 1].map(|i| props[i].stiffness * (th[i] - q[i]) + props[i].damping * (thd[i] - qd[i]));
    let u = cfg.motor_torque(t, th, thd, [props[0].stiffness, props[1].stiffness]);
    let a = cfg.acceleration(q, qd, tau);
    let jm = cfg.motor_inertia;
    [
        thd[0],
        thd[1],
        (u[0] - cfg.motor_damping * thd[0] - tau[0]) / jm,
        (u[1] - cfg.motor_damping * thd[1] - tau[1]) / jm,
        qd[0],
        qd[1],
        a[0],
        a[1],
    ]
}

fn axpy(y: &Y, terms: &[(f64, &Y)]) -> Y {
    let mut out = *y;
    for (c, k) in terms {
        for i in 0..8 {
            out[i] += c * k[i];
        }
    }
    out
}

/// Integrates from the rest state to `cfg.duration`, sampling every `dt_out` seconds.
/// Returns the trace and the number of accepted steps.
pub fn simulate(
    cfg: &ArmConfig,
    props: &[JointProps; 2],
    dt_out: f64,
    tolerance: f64,
) -> Result<(Trace, usize), String> {
    cfg.validate()?;
    let (q0, m0) = cfg.initial_angles([props[0].stiffness, props[1].stiffness]);
    let mut y: Y = [m0[0], m0[1], 0.0, 0.0, q0[0], q0[1], 0.0, 0.0];
    let n_out = (cfg.duration / dt_out).round() as usize;
    let mut trace = Trace::default();
    let record = |trace: &mut Trace, t: f64, y: &Y| {
        let (th, thd, q, qd) = ([y[0], y[1]], [y[2], y[3]], [y[4], y[5]], [y[6], y[7]]);
        let tau = [0, 1].map(|i| props[i].stiffness * (th[i] - q[i]) + props[i].damping * (thd[i] - qd[i]));
        let stiffness = [props[0].stiffness, props[1].stiffness];
        let u = cfg.motor_torque(t, th, thd, stiffness);
        let y =
            JointOutputs { q, qd, motor_angle: th, motor_speed: thd, tau, stiffness, pcl_temperature_c: [f64::NAN; 2] };
        trace.push(t, &y, u);
    };
    record(&mut trace, 0.0, &y);
    let mut dt = 1e-4;
    let mut accepted = 0usize;
    for k in 0..n_out {
        let (t0, t1) = (k as f64 * dt_out, (k + 1) as f64 * dt_out);
        let mut t = t0;
        let mut rejected = 0;
        while t < t1 {
            let last = t + dt >= t1;
            let h = if last { t1 - t } else { dt };
            let k1 = rhs(cfg, props, t, &y);
            let k2 = rhs(cfg, props, t + h / 5.0, &axpy(&y, &[(h / 5.0, &k1)]));
            let k3 = rhs(cfg, props, t + 0.3 * h, &axpy(&y, &[(h * 3.0 / 40.0, &k1), (h * 9.0 / 40.0, &k2)]));
            let k4 = rhs(
                cfg,
                props,
                t + 0.8 * h,
                &axpy(&y, &[(h * 44.0 / 45.0, &k1), (-h * 56.0 / 15.0, &k2), (h * 32.0 / 9.0, &k3)]),
            );
            let k5 = rhs(
                cfg,
                props,
                t + 8.0 / 9.0 * h,
                &axpy(
                    &y,
                    &[
                        (h * 19372.0 / 6561.0, &k1),
                        (-h * 25360.0 / 2187.0, &k2),
                        (h * 64448.0 / 6561.0, &k3),
                        (-h * 212.0 / 729.0, &k4),
                    ],
                ),
            );
            let k6 = rhs(
                cfg,
                props,
                t + h,
                &axpy(
                    &y,
                    &[
                        (h * 9017.0 / 3168.0, &k1),
                        (-h * 355.0 / 33.0, &k2),
                        (h * 46732.0 / 5247.0, &k3),
                        (h * 49.0 / 176.0, &k4),
                        (-h * 5103.0 / 18656.0, &k5),
                    ],
                ),
            );
            let y5 = axpy(
                &y,
                &[
                    (h * 35.0 / 384.0, &k1),
                    (h * 500.0 / 1113.0, &k3),
                    (h * 125.0 / 192.0, &k4),
                    (-h * 2187.0 / 6784.0, &k5),
                    (h * 11.0 / 84.0, &k6),
                ],
            );
            let k7 = rhs(cfg, props, t + h, &y5);
            // error = 5th − 4th order solution
            let e =
                [71.0 / 57600.0, 0.0, -71.0 / 16695.0, 71.0 / 1920.0, -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0];
            let ks = [&k1, &k2, &k3, &k4, &k5, &k6, &k7];
            let mut err: f64 = 0.0;
            for i in 0..8 {
                let ei: f64 = (0..7).map(|j| e[j] * ks[j][i]).sum::<f64>() * h;
                err = err.max(ei.abs() / (tolerance * (1.0 + y[i].abs().max(y5[i].abs()))));
            }
            if !err.is_finite() {
                err = 1e10;
            }
            if err <= 1.0 {
                t = if last { t1 } else { t + h };
                y = y5;
                accepted += 1;
                rejected = 0;
                let grow = if err == 0.0 { 5.0 } else { (0.9 * err.powf(-0.2)).clamp(0.2, 5.0) };
                if !last {
                    dt = h * grow;
                }
            } else {
                rejected += 1;
                if rejected > 100 || h < 1e-14 {
                    return Err(format!("the reference integrator stalled at t = {t} s"));
                }
                dt = h * (0.9 * err.powf(-0.2)).clamp(0.1, 0.9);
            }
        }
        record(&mut trace, t1, &y);
    }
    trace.finish(cfg);
    Ok((trace, accepted))
}
