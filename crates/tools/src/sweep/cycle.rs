//! Heating–cooling cycle (issue 20): the heater at constant power until the PCL reaches the
//! target, then off; the device cools passively. With crystallisation kinetics (the FMU's default)
//! the melt supercools and the stiffness returns only when it recrystallises, well below the
//! melting range; with the equilibrium law (the model before issue 20) it returns on the melting
//! curve. Both run through the FMU side by side, motor at rest (the stiffness is the FMU's
//! `effective_stiffness` output, K_eff at the excitation frequency).

use thermovia_importer::{Fmu, HarnessError};

use super::rig::ZERO_CELSIUS;

/// One cycle's samples (every `record_every` s).
#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct CycleTrace {
    pub time_s: Vec<f64>,
    pub pcl_c: Vec<f64>,
    pub housing_c: Vec<f64>,
    pub k_eff: Vec<f64>,
    pub crystallinity: Vec<f64>,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct CycleResult {
    /// "nakamura" or "equilibrium" (the FMU's `crystallisation` parameter).
    pub law: &'static str,
    pub power_w: f64,
    pub target_c: f64,
    /// When the PCL reached the target and the heater went off, s.
    pub heater_off_s: Option<f64>,
    pub heater_energy_j: f64,
    /// K_eff cold (at the start), and its least value over the cycle, N·m/rad.
    pub cold_k_eff: f64,
    pub min_k_eff: f64,
    /// First time after the heater went off at which K_eff is back to 90 % of the cold value
    /// (min + 0.9 (cold − min) would hide a partial recovery; this is of the cold stiffness), s
    /// after heater off; and the PCL temperature then.
    pub regain_90_after_off_s: Option<f64>,
    pub regain_90_pcl_c: Option<f64>,
    /// Largest rise of the PCL temperature once it has cooled 0.5 K below its peak after heater off
    /// (the crystallisation exotherm; 0 when the cooling curve is monotone), K.
    pub exotherm_rise_k: f64,
    /// PCL temperature of the fastest crystallisation on cooling, °C.
    pub crystallisation_peak_c: Option<f64>,
    pub final_crystallinity: f64,
    pub duration_s: f64,
    #[serde(skip)]
    pub trace: CycleTrace,
}

/// Runs one cycle with `law` (0 equilibrium, 1 Nakamura) at `power_w` until the PCL is at
/// `target_c`, then cools for at most `max_s` in total, stopping once K_eff has regained 99 % of
/// its cold value. Step `h` (the motor at rest, so the mechanics stays exactly at rest).
pub fn cycle_study(
    fmu: &Fmu,
    law: i32,
    power_w: f64,
    target_c: f64,
    h: f64,
    max_s: f64,
    record_every: f64,
) -> Result<CycleResult, HarnessError> {
    let mut inst = fmu.instantiate(None)?;
    inst.initialize(0.0, None, &[("max_internal_step", h), ("crystallisation", law as f64)])?;
    let mut trace = CycleTrace::default();
    let cold = inst.get("effective_stiffness")?;
    let mut r = CycleResult {
        law: if law == 0 { "equilibrium" } else { "nakamura" },
        power_w,
        target_c,
        heater_off_s: None,
        heater_energy_j: 0.0,
        cold_k_eff: cold,
        min_k_eff: cold,
        regain_90_after_off_s: None,
        regain_90_pcl_c: None,
        exotherm_rise_k: 0.0,
        crystallisation_peak_c: None,
        final_crystallinity: 0.0,
        duration_s: 0.0,
        trace: CycleTrace::default(),
    };
    inst.set("heater_power", power_w)?;
    let n = (max_s / h).round() as usize;
    let every = ((record_every / h).round() as usize).max(1);
    let (mut x_last, mut peak_rate) = (inst.get("pcl_crystallinity")?, 0.0);
    let (mut peak_after_off, mut low_since_cooling) = (f64::NEG_INFINITY, f64::INFINITY);
    // resolved once: one fmi2GetReal per step, not a lookup by name per value
    let read = ["pcl_temperature", "effective_stiffness", "pcl_crystallinity", "housing_temperature"]
        .map(|name| inst.handle(name).map(|v| v.value_reference));
    let read = read.into_iter().collect::<Result<Vec<u32>, _>>()?;
    let mut values = [0.0; 4];
    for k in 0..=n {
        let t = k as f64 * h;
        inst.get_reals(&read, &mut values)?;
        let [pcl_k, k_eff, x, housing_k] = values;
        let pcl = pcl_k - ZERO_CELSIUS;
        r.min_k_eff = r.min_k_eff.min(k_eff);
        if k % every == 0 {
            trace.time_s.push(t);
            trace.pcl_c.push(pcl);
            trace.housing_c.push(housing_k - ZERO_CELSIUS);
            trace.k_eff.push(k_eff);
            trace.crystallinity.push(x);
        }
        if r.heater_off_s.is_none() && pcl >= target_c {
            r.heater_off_s = Some(t);
            r.heater_energy_j = inst.get("heater_energy")?;
            inst.set("heater_power", 0.0)?;
        }
        if let Some(off) = r.heater_off_s {
            if k > 0 && (x - x_last) / h > peak_rate {
                peak_rate = (x - x_last) / h;
                r.crystallisation_peak_c = Some(pcl);
            }
            peak_after_off = peak_after_off.max(pcl);
            if pcl < peak_after_off - 0.5 {
                low_since_cooling = low_since_cooling.min(pcl);
                r.exotherm_rise_k = r.exotherm_rise_k.max(pcl - low_since_cooling);
            }
            if r.regain_90_after_off_s.is_none() && k_eff >= 0.9 * cold && t > off {
                r.regain_90_after_off_s = Some(t - off);
                r.regain_90_pcl_c = Some(pcl);
            }
            if k_eff >= 0.99 * cold && t > off {
                r.duration_s = t;
                break;
            }
        }
        x_last = x;
        r.duration_s = t;
        if k < n {
            inst.step(h)?;
        }
    }
    r.final_crystallinity = inst.get("pcl_crystallinity")?;
    r.trace = trace;
    Ok(r)
}
