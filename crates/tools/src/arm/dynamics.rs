//! Master-side models of the arm: rigid-body dynamics of a planar two-link arm in a vertical plane,
//! the tip contact (a compliant wall), the motion plan and the joint controller. Plain functions of
//! the state, shared by the co-simulation master and the monolithic reference so both integrate the
//! same equations.
//!
//! Angles: q1 of link 1 from the horizontal x axis, q2 of link 2 relative to link 1 (the joint
//! angles the FMUs' links report); gravity along −y. Link i is a uniform rod (mass m_i, length l_i)
//! plus the actuator's output hub (inertia `hub_inertia`) turning with it; the elbow actuator's mass
//! sits at the elbow on link 1; the payload is a point mass at the tip.
//!
//!   M(q) q'' + c(q, q') + g(q) = τ_t + Jᵀ(q) F_tip

/// Geometry, masses, controller, contact and task of the arm example. SI units.
#[derive(Clone, Debug, serde::Serialize)]
pub struct ArmConfig {
    pub l1: f64,
    pub l2: f64,
    pub m1: f64,
    pub m2: f64,
    /// Mass of the elbow actuator, carried by link 1 at the elbow (the paper's device: 0.86 kg).
    pub elbow_mass: f64,
    /// Point mass at the tip (0 = no payload).
    pub payload_mass: f64,
    /// Inertia of each actuator's output hub, turning with its link.
    pub hub_inertia: f64,
    pub gravity: f64,
    /// FMU parameters of both joints.
    pub motor_inertia: f64,
    pub motor_damping: f64,
    pub excitation_frequency: f64,
    /// The FMU's `viscoelastic_law`: 0 hysteretic (C = K''/ω at `excitation_frequency`), 1 Prony
    /// (causal at every frequency; docs/physics.md §5c).
    pub viscoelastic_law: u8,
    /// Joint PD on the motor angle: τ_m = kp (θm* − θm) + kd (θm*' − θm') + g_i(q*).
    pub kp: f64,
    pub kd: f64,
    /// Vertical wall x = wall_x; pushes back on the tip with k·pen + d·pen' (never pulls).
    pub wall_x: f64,
    pub wall_stiffness: f64,
    pub wall_damping: f64,
    /// Tip start and goal (the goal lies behind the wall, so the tip strikes it and then presses).
    pub start_tip: [f64; 2],
    pub goal_tip: [f64; 2],
    pub move_start: f64,
    pub move_duration: f64,
    pub duration: f64,
    /// Leave at its default: joint angles of start and goal, cached with the values they come from.
    #[serde(skip)]
    pub plan_cache: PlanCache,
}

impl Default for ArmConfig {
    fn default() -> Self {
        ArmConfig {
            l1: 0.25,
            l2: 0.20,
            m1: 0.30,
            m2: 0.20,
            elbow_mass: 0.86,
            payload_mass: 0.30,
            hub_inertia: 1e-3,
            gravity: crate::report::STANDARD_GRAVITY,
            motor_inertia: 0.005,
            motor_damping: 0.01,
            excitation_frequency: 0.5,
            viscoelastic_law: 0,
            kp: 150.0,
            kd: 1.5,
            wall_x: 0.36,
            wall_stiffness: 3000.0,
            wall_damping: 30.0,
            start_tip: [0.22, -0.18],
            goal_tip: [0.40, 0.02],
            move_start: 0.2,
            move_duration: 0.6,
            duration: 3.0,
            plan_cache: PlanCache::default(),
        }
    }
}

pub type V2 = [f64; 2];

/// The plan is evaluated every step; inverse kinematics of start and goal at each call would
/// dominate the master's work, so they are cached with the lengths and tips they were computed
/// from (a changed value recomputes them).
#[derive(Clone, Debug, Default)]
pub struct PlanCache(std::cell::Cell<Option<([f64; 6], V2, V2)>>);
pub type M2 = [[f64; 2]; 2];

impl ArmConfig {
    /// Refuses configurations that make no sense, saying why.
    pub fn validate(&self) -> Result<(), String> {
        if self.viscoelastic_law > 1 {
            return Err(format!("viscoelastic_law {}: 0 (hysteretic) or 1 (Prony)", self.viscoelastic_law));
        }
        let positive = [
            ("l1 (link 1 length, m)", self.l1),
            ("l2 (link 2 length, m)", self.l2),
            ("m1 (link 1 mass, kg)", self.m1),
            ("m2 (link 2 mass, kg)", self.m2),
            ("hub_inertia (kg·m²)", self.hub_inertia),
            ("motor_inertia (kg·m²)", self.motor_inertia),
            ("excitation_frequency (Hz)", self.excitation_frequency),
            ("move_duration (s)", self.move_duration),
            ("duration (s)", self.duration),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} must be a positive number, got {v}"));
            }
        }
        let non_negative = [
            ("elbow_mass (kg)", self.elbow_mass),
            ("payload_mass (kg; 0 = no payload)", self.payload_mass),
            ("gravity (m/s²)", self.gravity),
            ("motor_damping (N·m·s/rad)", self.motor_damping),
            ("kp (N·m/rad)", self.kp),
            ("kd (N·m·s/rad)", self.kd),
            ("wall_stiffness (N/m)", self.wall_stiffness),
            ("wall_damping (N·s/m)", self.wall_damping),
            ("move_start (s)", self.move_start),
        ];
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} must be ≥ 0 and finite, got {v}"));
            }
        }
        if !self.wall_x.is_finite() {
            return Err(format!("wall_x must be finite, got {}", self.wall_x));
        }
        for (name, p) in [("start tip", self.start_tip), ("goal tip", self.goal_tip)] {
            self.inverse_kinematics(p).map_err(|e| format!("{name} {p:?}: {e}"))?;
        }
        if self.start_tip[0] >= self.wall_x {
            return Err(format!(
                "the start tip x = {} m is already at or behind the wall x = {} m",
                self.start_tip[0], self.wall_x
            ));
        }
        if self.move_start + self.move_duration > self.duration {
            return Err(format!(
                "the move ends at {} s, after the end of the run ({} s)",
                self.move_start + self.move_duration,
                self.duration
            ));
        }
        Ok(())
    }

    /// Body 1 (rod + elbow actuator + hub 1): mass, centre-of-mass distance from the shoulder,
    /// inertia about its centre of mass.
    fn body1(&self) -> (f64, f64, f64) {
        let m = self.m1 + self.elbow_mass;
        let lc = (self.m1 * 0.5 * self.l1 + self.elbow_mass * self.l1) / m;
        let i = self.m1 * self.l1 * self.l1 / 12.0
            + self.m1 * (0.5 * self.l1 - lc).powi(2)
            + self.elbow_mass * (self.l1 - lc).powi(2)
            + self.hub_inertia;
        (m, lc, i)
    }

    /// Body 2 (rod + payload + hub 2), as body 1 but from the elbow.
    fn body2(&self) -> (f64, f64, f64) {
        let m = self.m2 + self.payload_mass;
        let lc = (self.m2 * 0.5 * self.l2 + self.payload_mass * self.l2) / m;
        let i = self.m2 * self.l2 * self.l2 / 12.0
            + self.m2 * (0.5 * self.l2 - lc).powi(2)
            + self.payload_mass * (self.l2 - lc).powi(2)
            + self.hub_inertia;
        (m, lc, i)
    }

    pub fn mass_matrix(&self, q: V2) -> M2 {
        let (m1, lc1, i1) = self.body1();
        let (m2, lc2, i2) = self.body2();
        let c2 = q[1].cos();
        let m11 = i1 + m1 * lc1 * lc1 + i2 + m2 * (self.l1 * self.l1 + lc2 * lc2 + 2.0 * self.l1 * lc2 * c2);
        let m12 = i2 + m2 * (lc2 * lc2 + self.l1 * lc2 * c2);
        let m22 = i2 + m2 * lc2 * lc2;
        [[m11, m12], [m12, m22]]
    }

    /// Coriolis and centrifugal torques c(q, q').
    pub fn coriolis(&self, q: V2, qd: V2) -> V2 {
        let (m2, lc2, _) = self.body2();
        let hh = m2 * self.l1 * lc2 * q[1].sin();
        [-hh * (2.0 * qd[0] * qd[1] + qd[1] * qd[1]), hh * qd[0] * qd[0]]
    }

    /// Gravity torques g(q) = ∂V/∂q.
    pub fn gravity_torque(&self, q: V2) -> V2 {
        let (m1, lc1, _) = self.body1();
        let (m2, lc2, _) = self.body2();
        let c12 = (q[0] + q[1]).cos();
        [self.gravity * ((m1 * lc1 + m2 * self.l1) * q[0].cos() + m2 * lc2 * c12), self.gravity * m2 * lc2 * c12]
    }

    pub fn tip(&self, q: V2) -> V2 {
        let s = q[0] + q[1];
        [self.l1 * q[0].cos() + self.l2 * s.cos(), self.l1 * q[0].sin() + self.l2 * s.sin()]
    }

    /// Tip Jacobian ∂tip/∂q.
    pub fn jacobian(&self, q: V2) -> M2 {
        let s = q[0] + q[1];
        [
            [-self.l1 * q[0].sin() - self.l2 * s.sin(), -self.l2 * s.sin()],
            [self.l1 * q[0].cos() + self.l2 * s.cos(), self.l2 * s.cos()],
        ]
    }

    pub fn tip_velocity(&self, q: V2, qd: V2) -> V2 {
        let j = self.jacobian(q);
        mul(j, qd)
    }

    /// Elbow-down joint angles for a tip position.
    pub fn inverse_kinematics(&self, p: V2) -> Result<V2, String> {
        let r2 = p[0] * p[0] + p[1] * p[1];
        let c2 = (r2 - self.l1 * self.l1 - self.l2 * self.l2) / (2.0 * self.l1 * self.l2);
        if !(c2.abs() < 1.0 - 1e-9) {
            return Err(format!(
                "out of reach of links {} m + {} m (distance {:.4} m from the shoulder)",
                self.l1,
                self.l2,
                r2.sqrt()
            ));
        }
        let q2 = -(1.0 - c2 * c2).sqrt().atan2(c2);
        let q1 = p[1].atan2(p[0]) - (self.l2 * q2.sin()).atan2(self.l1 + self.l2 * q2.cos());
        Ok([q1, q2])
    }

    /// Wall force on the tip (only pushes, along −x).
    pub fn contact_force(&self, q: V2, qd: V2) -> V2 {
        let x = self.l1 * q[0].cos() + self.l2 * (q[0] + q[1]).cos();
        let pen = x - self.wall_x;
        if pen <= 0.0 {
            return [0.0, 0.0];
        }
        let v = self.tip_velocity(q, qd);
        [-(self.wall_stiffness * pen + self.wall_damping * v[0]).max(0.0), 0.0]
    }

    /// Joint accelerations of the arm under transmission torques τ_t (with contact):
    /// M⁻¹(τ − c − g + JᵀF). The same terms as `mass_matrix`, `coriolis`, `gravity_torque`,
    /// `contact_force` and `jacobian`, fused so the master evaluates two sin/cos pairs per step
    /// instead of a dozen trigonometric calls (a test keeps both forms equal).
    pub fn acceleration(&self, q: V2, qd: V2, tau: V2) -> V2 {
        let (m1, lc1, i1) = self.body1();
        let (m2, lc2, i2) = self.body2();
        let (s1, c1) = q[0].sin_cos();
        let (s2, c2) = q[1].sin_cos();
        let (s12, c12) = (s1 * c2 + c1 * s2, c1 * c2 - s1 * s2);
        let m11 = i1 + m1 * lc1 * lc1 + i2 + m2 * (self.l1 * self.l1 + lc2 * lc2 + 2.0 * self.l1 * lc2 * c2);
        let m12 = i2 + m2 * (lc2 * lc2 + self.l1 * lc2 * c2);
        let m22 = i2 + m2 * lc2 * lc2;
        let hh = m2 * self.l1 * lc2 * s2;
        let cor = [-hh * (2.0 * qd[0] * qd[1] + qd[1] * qd[1]), hh * qd[0] * qd[0]];
        let grav = [self.gravity * ((m1 * lc1 + m2 * self.l1) * c1 + m2 * lc2 * c12), self.gravity * m2 * lc2 * c12];
        let mut rhs = [tau[0] - cor[0] - grav[0], tau[1] - cor[1] - grav[1]];
        let pen = self.l1 * c1 + self.l2 * c12 - self.wall_x;
        if pen > 0.0 {
            // ∂x_tip/∂q: the only Jacobian row a wall normal to x needs
            let jx = [-self.l1 * s1 - self.l2 * s12, -self.l2 * s12];
            let vx = jx[0] * qd[0] + jx[1] * qd[1];
            let fx = -(self.wall_stiffness * pen + self.wall_damping * vx).max(0.0);
            rhs[0] += jx[0] * fx;
            rhs[1] += jx[1] * fx;
        }
        solve([[m11, m12], [m12, m22]], rhs)
    }

    /// `acceleration` written from the separate terms (the readable form; a test compares them).
    pub fn acceleration_from_terms(&self, q: V2, qd: V2, tau: V2) -> V2 {
        let m = self.mass_matrix(q);
        let c = self.coriolis(q, qd);
        let g = self.gravity_torque(q);
        let f = self.contact_force(q, qd);
        let j = self.jacobian(q);
        let ext = [j[0][0] * f[0] + j[1][0] * f[1], j[0][1] * f[0] + j[1][1] * f[1]];
        solve(m, [tau[0] - c[0] - g[0] + ext[0], tau[1] - c[1] - g[1] + ext[1]])
    }

    /// Smallest effective inertia 1/(M⁻¹)_ii each joint shows over every elbow angle: the constant
    /// link_inertia given to the FMUs (see the coupling notes in `arm/mod.rs`).
    pub fn coupling_inertia(&self) -> V2 {
        let mut out = [f64::INFINITY; 2];
        for k in 0..720 {
            let q2 = -std::f64::consts::PI + k as f64 * std::f64::consts::PI / 360.0;
            let m = self.mass_matrix([0.0, q2]);
            let det = m[0][0] * m[1][1] - m[0][1] * m[0][1];
            out[0] = out[0].min(det / m[1][1]);
            out[1] = out[1].min(det / m[0][0]);
        }
        out
    }

    /// Joint-space plan: minimum-jerk from the start to the goal pose (elbow down).
    pub fn plan(&self, t: f64) -> (V2, V2) {
        let key = [self.l1, self.l2, self.start_tip[0], self.start_tip[1], self.goal_tip[0], self.goal_tip[1]];
        let (a, b) = match self.plan_cache.0.get() {
            Some((k, a, b)) if k == key => (a, b),
            _ => {
                let a = self.inverse_kinematics(self.start_tip).expect("validated");
                let b = self.inverse_kinematics(self.goal_tip).expect("validated");
                self.plan_cache.0.set(Some((key, a, b)));
                (a, b)
            }
        };
        let s = ((t - self.move_start) / self.move_duration).clamp(0.0, 1.0);
        let pos = s * s * s * (10.0 - 15.0 * s + 6.0 * s * s);
        let vel = if s <= 0.0 || s >= 1.0 { 0.0 } else { 30.0 * s * s * (1.0 - s) * (1.0 - s) / self.move_duration };
        ([a[0] + (b[0] - a[0]) * pos, a[1] + (b[1] - a[1]) * pos], [(b[0] - a[0]) * vel, (b[1] - a[1]) * vel])
    }

    /// Motor torques of the joint controllers. The motor set-point is the planned joint angle plus
    /// the transmission's deflection under gravity, g_i(q*)/K_i (K_i the joint's current effective
    /// stiffness), so the link, not the motor, lands on the plan; gravity is fed forward.
    pub fn motor_torque(&self, t: f64, motor_angle: V2, motor_speed: V2, stiffness: V2) -> V2 {
        let (qd, qdd) = self.plan(t);
        let g = self.gravity_torque(qd);
        let mut u = [0.0; 2];
        for i in 0..2 {
            let target = qd[i] + g[i] / stiffness[i];
            u[i] = self.kp * (target - motor_angle[i]) + self.kd * (qdd[i] - motor_speed[i]) + g[i];
        }
        u
    }

    /// Rest state at the start pose: link on the plan, motor ahead by the gravity deflection.
    pub fn initial_angles(&self, stiffness: V2) -> (V2, V2) {
        let q = self.inverse_kinematics(self.start_tip).expect("validated");
        let g = self.gravity_torque(q);
        (q, [q[0] + g[0] / stiffness[0], q[1] + g[1] / stiffness[1]])
    }
}

pub fn mul(m: M2, v: V2) -> V2 {
    [m[0][0] * v[0] + m[0][1] * v[1], m[1][0] * v[0] + m[1][1] * v[1]]
}

pub fn solve(m: M2, b: V2) -> V2 {
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    [(m[1][1] * b[0] - m[0][1] * b[1]) / det, (m[0][0] * b[1] - m[1][0] * b[0]) / det]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inverse_kinematics_round_trips() {
        let c = ArmConfig::default();
        for p in [c.start_tip, c.goal_tip, [0.3, 0.1]] {
            let q = c.inverse_kinematics(p).unwrap();
            let back = c.tip(q);
            assert!((back[0] - p[0]).abs() < 1e-12 && (back[1] - p[1]).abs() < 1e-12, "{p:?} -> {back:?}");
        }
    }

    /// Gravity torques are the gradient of the potential energy (checked by finite differences).
    #[test]
    fn gravity_is_the_gradient_of_potential_energy() {
        let c = ArmConfig::default();
        let potential = |q: V2| {
            let (m1, lc1, _) = c.body1();
            let (m2, lc2, _) = c.body2();
            c.gravity * (m1 * lc1 * q[0].sin() + m2 * (c.l1 * q[0].sin() + lc2 * (q[0] + q[1]).sin()))
        };
        let q = [0.3, -0.7];
        let g = c.gravity_torque(q);
        for i in 0..2 {
            let mut a = q;
            let mut b = q;
            a[i] += 1e-6;
            b[i] -= 1e-6;
            let fd = (potential(a) - potential(b)) / 2e-6;
            assert!((fd - g[i]).abs() < 1e-7, "{i}: {fd} vs {}", g[i]);
        }
    }

    #[test]
    fn fused_acceleration_equals_the_separate_terms() {
        let c = ArmConfig::default();
        let mut worst: f64 = 0.0;
        let mut in_contact = 0;
        for k in 0..400 {
            let f = k as f64;
            let q = [-0.5 + 0.9 * (0.37 * f).sin(), -2.0 + 1.8 * (0.23 * f).cos()];
            let qd = [3.0 * (0.71 * f).sin(), -2.0 * (0.13 * f).cos()];
            let tau = [5.0 * (0.05 * f).cos(), -3.0 * (0.11 * f).sin()];
            if c.contact_force(q, qd)[0] != 0.0 {
                in_contact += 1;
            }
            let (a, b) = (c.acceleration(q, qd, tau), c.acceleration_from_terms(q, qd, tau));
            for i in 0..2 {
                worst = worst.max((a[i] - b[i]).abs() / (1.0 + b[i].abs()));
            }
        }
        assert!(in_contact > 10, "the samples must include contact ({in_contact})");
        assert!(worst < 1e-12, "{worst}");
    }

    /// Without gravity and torques, kinetic energy ½ q'ᵀ M q' is conserved by M q'' + c = 0: checks
    /// that the Coriolis terms belong to the mass matrix.
    #[test]
    fn free_motion_conserves_kinetic_energy() {
        let c = ArmConfig { gravity: 0.0, wall_x: 10.0, ..ArmConfig::default() };
        let energy = |q: V2, v: V2| 0.5 * (v[0] * mul(c.mass_matrix(q), v)[0] + v[1] * mul(c.mass_matrix(q), v)[1]);
        let (mut q, mut v) = ([0.1, 0.5], [2.0, -3.0]);
        let e0 = energy(q, v);
        let h = 1e-5;
        for _ in 0..20000 {
            // RK2 midpoint is enough for a 1e-5 check at this step
            let a = c.acceleration(q, v, [0.0, 0.0]);
            let qm = [q[0] + 0.5 * h * v[0], q[1] + 0.5 * h * v[1]];
            let vm = [v[0] + 0.5 * h * a[0], v[1] + 0.5 * h * a[1]];
            let am = c.acceleration(qm, vm, [0.0, 0.0]);
            q = [q[0] + h * vm[0], q[1] + h * vm[1]];
            v = [v[0] + h * am[0], v[1] + h * am[1]];
        }
        let e1 = energy(q, v);
        assert!((e1 - e0).abs() < 1e-5 * e0, "{e0} -> {e1}");
    }
}
