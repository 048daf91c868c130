//! The paper's estimator (docs/physics.md §6) and its closed form, with conditioning.
//!
//! Measured: H = Θ e^{−iφ} / θ0, the link's first harmonic over the motor's (φ = phase delay).
//! - Closed form for a spring ∥ damper between motor and link, no force to ground:
//!   J_l θl'' = K*(θm − θl)  ⇒  H = K*/(K* − J_l ω²)  ⇒  K* = J_l ω² H/(H − 1), K* = K_eff + iωC_eff.
//! - The paper's Eq. 15–16, iterated to a fixed point:
//!   K ← J_l ω² + √(K²/M² − (Cω)²),  C ← (K − J_l ω²) tan φ / ω,  M = |H|.
//!   Eq. 15 is the amplitude of a base-excited oscillator whose damper goes to ground
//!   (M = K/|K − Jω² + iωC|); with the damper between motor and link, as in the device, the true
//!   numerator is |K + iωC|, so the iteration is biased when ωC is not small against K.
//!
//! E' = (K_eff − K_s r_s²)/(κ r_p²), E'' = ω C_eff/(κ r_p²).
//!
//! Conditioning: dK*/K* = −dH/(H (H − 1)), so a relative error in H is amplified by
//! 1/(|H| |H − 1|); the link following the motor closely (|H − 1| small) is the bad case, at any
//! stiffness. E' and E'' then inherit |K*|/K' and |K*|/(ωC) on top.

use super::analysis::Complex;

/// What is known about the device besides the measurement.
#[derive(Clone, Copy, Debug)]
pub struct Known {
    pub link_inertia: f64,
    /// K_s r_s², N·m/rad.
    pub spring_stiffness: f64,
    /// κ r_p², m³ (Pa → N·m/rad).
    pub modulus_to_torsion: f64,
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Estimate {
    pub k_eff: f64,
    pub c_eff: f64,
    /// Pa
    pub e_storage: f64,
    /// Pa
    pub e_loss: f64,
}

impl Estimate {
    fn from_kc(k: &Known, omega: f64, k_eff: f64, c_eff: f64) -> Estimate {
        Estimate {
            k_eff,
            c_eff,
            e_storage: (k_eff - k.spring_stiffness) / k.modulus_to_torsion,
            e_loss: omega * c_eff / k.modulus_to_torsion,
        }
    }
}

/// Error amplification from H to K*, and the relative errors it implies for E' and E'' given an
/// uncertainty `dh` (absolute) in H.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Conditioning {
    pub h_minus_1: f64,
    /// 1/(|H| |H − 1|): relative error of K* per relative error of H.
    pub amplification: f64,
    /// The assumed uncertainty of H (absolute).
    pub h_uncertainty: f64,
    pub rel_error_e_storage: f64,
    pub rel_error_e_loss: f64,
}

impl Conditioning {
    pub fn of(h: Complex, k_star: Complex, k: &Known, dh: f64) -> Conditioning {
        let hm1 = (h - Complex::new(1.0, 0.0)).norm();
        let amplification = 1.0 / (h.norm() * hm1);
        let rel_k = amplification * dh / h.norm();
        let k_storage = k_star.re - k.spring_stiffness;
        Conditioning {
            h_minus_1: hm1,
            amplification,
            h_uncertainty: dh,
            rel_error_e_storage: rel_k * k_star.norm() / k_storage.abs(),
            rel_error_e_loss: rel_k * k_star.norm() / k_star.im.abs(),
        }
    }

    pub fn worst(&self) -> f64 {
        self.rel_error_e_storage.max(self.rel_error_e_loss)
    }
}

#[derive(Clone, Debug, PartialEq)]
pub enum EstimateError {
    /// |H − 1| is not above the uncertainty of H: the data carry no information on K*.
    IllConditioned { h_minus_1: f64, h_uncertainty: f64 },
    /// The estimate exists but its predicted error exceeds the limit.
    TooUncertain { estimate: Estimate, conditioning: Conditioning, limit: f64 },
    /// The result is not a passive transmission (negative damping or spring-only stiffness below
    /// the springs): the data do not fit the model.
    NotPhysical { estimate: Estimate },
    /// Eq. 15 has no real solution (K²/M² < (Cω)²) or the iteration did not converge.
    NoFixedPoint { reason: String },
}

impl std::fmt::Display for EstimateError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EstimateError::IllConditioned { h_minus_1, h_uncertainty } => write!(
                f,
                "ill-conditioned: |H − 1| = {h_minus_1:.3e} is not above the uncertainty of H ({h_uncertainty:.1e})"
            ),
            EstimateError::TooUncertain { conditioning, limit, .. } => write!(
                f,
                "ill-conditioned: predicted error of E'/E'' {:.1} % / {:.1} % exceeds {:.0} % (amplification {:.0})",
                100.0 * conditioning.rel_error_e_storage,
                100.0 * conditioning.rel_error_e_loss,
                100.0 * limit,
                conditioning.amplification
            ),
            EstimateError::NotPhysical { estimate } => {
                write!(f, "not physical: K_eff {:.3} N·m/rad, C_eff {:.3} N·m·s/rad", estimate.k_eff, estimate.c_eff)
            }
            EstimateError::NoFixedPoint { reason } => write!(f, "no fixed point: {reason}"),
        }
    }
}

impl std::error::Error for EstimateError {}

/// Closed form K* = J ω² H/(H − 1). `dh`: absolute uncertainty of H; `limit`: largest acceptable
/// predicted relative error of E' or E''.
pub fn closed_form(
    h: Complex,
    omega: f64,
    k: &Known,
    dh: f64,
    limit: f64,
) -> Result<(Estimate, Conditioning), EstimateError> {
    let hm1 = h - Complex::new(1.0, 0.0);
    // Below 3 standard uncertainties the sign and size of H − 1 are noise.
    if !h.re.is_finite() || !h.im.is_finite() || hm1.norm() <= 3.0 * dh {
        return Err(EstimateError::IllConditioned { h_minus_1: hm1.norm(), h_uncertainty: dh });
    }
    let k_star = (h / hm1).scale(k.link_inertia * omega * omega);
    let est = Estimate::from_kc(k, omega, k_star.re, k_star.im / omega);
    if est.c_eff < 0.0 || est.k_eff <= 0.0 {
        return Err(EstimateError::NotPhysical { estimate: est });
    }
    let cond = Conditioning::of(h, k_star, k, dh);
    if cond.worst() > limit {
        return Err(EstimateError::TooUncertain { estimate: est, conditioning: cond, limit });
    }
    Ok((est, cond))
}

/// Result of the paper's iteration.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Iterated {
    pub estimate: Estimate,
    pub iterations: usize,
}

/// The paper's Eq. 15–16 iterated from C = 0 and the springs' stiffness until the relative change
/// of K is below `tol`. Its fixed point is K = J ω² M/(M − cos φ) (eliminate C), which exists
/// with K > J ω² only when M > cos φ: a link amplitude below the motor's with little phase delay
/// has no solution.
pub fn paper_iterative(
    m: f64,
    phase_delay: f64,
    omega: f64,
    k: &Known,
    tol: f64,
    max_iter: usize,
) -> Result<Iterated, EstimateError> {
    let jw2 = k.link_inertia * omega * omega;
    if m.is_nan() || phase_delay.is_nan() || m <= phase_delay.cos() {
        return Err(EstimateError::NoFixedPoint {
            reason: format!("M = {m:.6} ≤ cos φ = {:.6}: Eq. 15 has no stiffness above J_l ω²", phase_delay.cos()),
        });
    }
    let tan = phase_delay.tan();
    let mut kk = k.spring_stiffness.max(2.0 * jw2);
    let mut c = 0.0;
    for i in 1..=max_iter {
        let disc = kk * kk / (m * m) - (c * omega).powi(2);
        if disc < 0.0 {
            return Err(EstimateError::NoFixedPoint { reason: format!("K²/M² < (Cω)² at iteration {i}") });
        }
        let k_next = jw2 + disc.sqrt();
        c = (k_next - jw2) * tan / omega;
        let done = (k_next - kk).abs() <= tol * k_next.abs();
        kk = k_next;
        if done {
            return Ok(Iterated { estimate: Estimate::from_kc(k, omega, kk, c), iterations: i });
        }
    }
    Err(EstimateError::NoFixedPoint { reason: format!("no convergence in {max_iter} iterations (K = {kk:.4})") })
}

/// The fixed point of Eq. 15–16 in closed form (to check the iteration).
pub fn paper_fixed_point(m: f64, phase_delay: f64, omega: f64, k: &Known) -> Estimate {
    let jw2 = k.link_inertia * omega * omega;
    let kk = jw2 * m / (m - phase_delay.cos());
    Estimate::from_kc(k, omega, kk, (kk - jw2) * phase_delay.tan() / omega)
}

/// The forward model of the device: H = K*/(K* − J ω²).
pub fn link_over_motor(k_eff: f64, c_eff: f64, omega: f64, link_inertia: f64) -> Complex {
    let ks = Complex::new(k_eff, omega * c_eff);
    ks / (ks - Complex::new(link_inertia * omega * omega, 0.0))
}

/// The model Eq. 15–16 assume: H = K/(K − J ω² + iωC) (damper to ground).
pub fn paper_model_link_over_motor(k_eff: f64, c_eff: f64, omega: f64, link_inertia: f64) -> Complex {
    Complex::new(k_eff, 0.0) / Complex::new(k_eff - link_inertia * omega * omega, omega * c_eff)
}
