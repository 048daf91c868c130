//! How long it takes to switch a joint's impedance: heat at constant power from room temperature
//! until the PCL reaches the hot temperature, then switch the heater off and let the joint cool
//! passively (there is no active cooling on the device). Runs one FMU instance at rest.

use thermovia_importer::Fmu;

use super::sim::{ROOM_K, ZERO_CELSIUS};

#[derive(Clone, Debug, Default, serde::Serialize)]
pub struct SwitchResult {
    pub heater_power_w: f64,
    pub hot_temperature_c: f64,
    pub stiffness_cold: f64,
    pub stiffness_hot: f64,
    /// From heater on: PCL reaches the hot temperature (heater switched off then).
    pub heat_time_s: Option<f64>,
    /// From heater on: K_eff has made 50 % / 90 % of the way from cold to hot.
    pub soften_50_s: Option<f64>,
    pub soften_90_s: Option<f64>,
    /// Peak housing temperature while heating (the thermocouple's reading).
    pub peak_housing_c: f64,
    /// From heater off: K_eff has recovered 50 % / 90 % of the way back to cold.
    pub stiffen_50_s: Option<f64>,
    pub stiffen_90_s: Option<f64>,
    /// How long cooling was simulated (the 90 % recovery may lie beyond it).
    pub cooling_simulated_s: f64,
    /// Samples (time s, PCL °C, housing °C, K_eff N·m/rad) every `sample_s`.
    pub samples: Vec<[f64; 4]>,
}

/// `dt`: communication step; the joint is at rest, so the FMU's internal step is raised to `dt`
/// too (the thermal network's time constants are seconds; mechanics stays exactly at rest).
pub fn switching(
    fmu: &Fmu,
    heater_power: f64,
    hot_c: f64,
    cooling_limit_s: f64,
    dt: f64,
    mut progress: impl FnMut(f64),
) -> Result<SwitchResult, String> {
    if !(heater_power.is_finite() && heater_power > 0.0) {
        return Err(format!("the heater power must be positive, got {heater_power} W"));
    }
    let e = |e: thermovia_importer::HarnessError| e.to_string();
    let stiffness_at = |c: f64| -> Result<f64, String> {
        let mut p = fmu.instantiate(Some("probe")).map_err(e)?;
        p.initialize(
            0.0,
            None,
            &[("initial_pcl_temperature", ZERO_CELSIUS + c), ("initial_housing_temperature", ZERO_CELSIUS + c)],
        )
        .map_err(e)?;
        p.get("effective_stiffness").map_err(e)
    };
    let mut r = SwitchResult {
        heater_power_w: heater_power,
        hot_temperature_c: hot_c,
        stiffness_cold: stiffness_at(ROOM_K - ZERO_CELSIUS)?,
        stiffness_hot: stiffness_at(hot_c)?,
        ..Default::default()
    };
    let mut inst = fmu.instantiate(Some("switch")).map_err(e)?;
    inst.initialize(0.0, None, &[("max_internal_step", dt)]).map_err(e)?;
    let [hp, tp, th, k] =
        ["heater_power", "pcl_temperature", "housing_temperature", "effective_stiffness"].map(|n| inst.handle(n));
    let (hp, tp, th, k) = (hp.map_err(e)?, tp.map_err(e)?, th.map_err(e)?, k.map_err(e)?);
    let (kc, kh) = (r.stiffness_cold, r.stiffness_hot);
    let softened = |kv: f64, frac: f64| kv <= kc - frac * (kc - kh);
    let stiffened = |kv: f64, frac: f64| kv >= kh + frac * (kc - kh);
    inst.set_handle(hp, heater_power).map_err(e)?;
    let heat_limit = 600.0;
    let mut off_at = None;
    let sample_every = (1.0 / dt).round().max(1.0) as u64;
    let mut n = 0u64;
    loop {
        inst.step(dt).map_err(e)?;
        n += 1;
        let t = n as f64 * dt;
        let (pcl, housing, kv) =
            (inst.get_handle(tp).map_err(e)?, inst.get_handle(th).map_err(e)?, inst.get_handle(k).map_err(e)?);
        if n.is_multiple_of(sample_every) {
            r.samples.push([t, pcl - ZERO_CELSIUS, housing - ZERO_CELSIUS, kv]);
        }
        match off_at {
            None => {
                r.peak_housing_c = r.peak_housing_c.max(housing - ZERO_CELSIUS);
                if r.soften_50_s.is_none() && softened(kv, 0.5) {
                    r.soften_50_s = Some(t);
                }
                if r.soften_90_s.is_none() && softened(kv, 0.9) {
                    r.soften_90_s = Some(t);
                }
                if pcl - ZERO_CELSIUS >= hot_c {
                    r.heat_time_s = Some(t);
                    off_at = Some(t);
                    inst.set_handle(hp, 0.0).map_err(e)?;
                } else if t >= heat_limit {
                    return Err(format!("{heater_power} W did not bring the PCL to {hot_c} °C within {heat_limit} s"));
                }
                progress(0.1 * t / heat_limit);
            }
            Some(t_off) => {
                let since = t - t_off;
                if r.stiffen_50_s.is_none() && stiffened(kv, 0.5) {
                    r.stiffen_50_s = Some(since);
                }
                if r.stiffen_90_s.is_none() && stiffened(kv, 0.9) {
                    r.stiffen_90_s = Some(since);
                }
                progress(0.1 + 0.9 * since / cooling_limit_s);
                if r.stiffen_90_s.is_some() || since >= cooling_limit_s {
                    r.cooling_simulated_s = since;
                    break;
                }
            }
        }
    }
    Ok(r)
}
