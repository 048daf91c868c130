//! The loop on the paper's own measurements, which exist only in summary form
//! (`data/paper-reported.json`, docs/physics.md §7): Decay D = θ0 − Θ at 60 °C "nearly five
//! times" that at 22 °C at 0.5 Hz, the temperature effect "less pronounced" at 1 Hz, phase delay
//! "minimal". The fit happens in summary space: the FMU is swept at the paper's conditions (motor
//! θ0 sin ωt, steady cycles), the same summary numbers are computed from it, and each effect of the
//! library gets the one parameter that makes the 0.5 Hz Decay ratio 5; the secondary claims then
//! say whether that explanation holds.

use serde_json::{json, Value};

use super::fit::Effect;
use super::sim::{EffectValues, RunModel, SimInput, Simulator};

/// The paper's reported numbers as the repository keeps them, the default of `calibrate --paper`.
pub const REPORTED_JSON: &str = include_str!("../../../../data/paper-reported.json");

/// Motor amplitude of the sweeps, rad. The paper's is not recoverable from our copy
/// (paper-reported.json: "amplitude not recoverable"); 0.3 rad is an assumption, stated in the report.
pub const AMPLITUDE: f64 = 0.3;
/// "Minimal" phase read as at most this many degrees [EST reading of the paper's word].
pub const MINIMAL_PHASE_DEG: f64 = 5.0;
/// Cycles simulated per condition; the last two whole cycles are analysed.
const CYCLES: f64 = 6.0;

#[derive(Clone, Debug, serde::Serialize)]
pub struct Condition {
    pub temperature_c: f64,
    pub frequency_hz: f64,
    pub decay_rad: f64,
    pub phase_deg: f64,
}

#[derive(Clone, Debug, serde::Serialize)]
pub struct Summary {
    pub conditions: Vec<Condition>,
    /// D(60 °C)/D(22 °C) at 0.5 and 1 Hz (NaN when D(22 °C) ≤ 0).
    pub ratio_half_hz: f64,
    pub ratio_one_hz: f64,
    pub max_abs_phase_deg: f64,
    /// ln(ratio at 0.5 Hz / 5): the summary-space residual (NaN when the model has no positive Decay).
    pub log_ratio_error: f64,
    pub positive_decay: bool,
    pub less_pronounced_at_1hz: bool,
    pub minimal_phase: bool,
}

/// Amplitude and phase of A sin(wt + φ) fitted to the samples from `from` on (the sweep's DFT over
/// whole cycles).
fn fundamental(t: &[f64], x: &[f64], w: f64, from: f64) -> (f64, f64) {
    let start = t.partition_point(|&tt| tt < from);
    let c = crate::sweep::analysis::first_harmonic(t, x, w, start, t.len() - start);
    (c.norm(), c.arg())
}

/// Sweeps 22/60 °C at 0.5 and 1 Hz with `effects` and summarises as the paper does.
pub fn summarise(sim: &Simulator, effects: EffectValues, temps: &[f64], freqs: &[f64]) -> Result<Summary, String> {
    let mut inputs = Vec::new();
    let mut keys = Vec::new();
    for &tc in temps {
        for &f in freqs {
            let n = (CYCLES / f * 1000.0).round() as usize + 1;
            let time: Vec<f64> = (0..n).map(|k| k as f64 * 1e-3).collect();
            let w = 2.0 * std::f64::consts::PI * f;
            inputs.push(SimInput {
                initial_link_speed: 0.0,
                motor: time.iter().map(|t| AMPLITUDE * (w * t).sin()).collect(),
                housing_k: vec![tc + crate::report::ZERO_CELSIUS; n],
                time,
                frequency_hz: f,
                link_inertia: None,
                link0: 0.0,
                com_distance: 0.14,
                after_gap: false,
                housing_before: Default::default(),
                substeps: 1,
            });
            keys.push((tc, f));
        }
    }
    let model = RunModel { effects, ..RunModel::default() };
    let jobs: Vec<_> = (0..inputs.len()).map(|i| (i, model)).collect();
    let outs = sim.run_jobs(&inputs, &jobs);
    let mut conditions = Vec::new();
    for ((inp, out), (tc, f)) in inputs.iter().zip(outs).zip(keys) {
        let y = out?;
        let w = 2.0 * std::f64::consts::PI * f;
        let from = (CYCLES - 2.0) / f;
        let (am, pm) = fundamental(&inp.time, &inp.motor, w, from);
        let (al, pl) = fundamental(&inp.time, &y, w, from);
        conditions.push(Condition {
            temperature_c: tc,
            frequency_hz: f,
            decay_rad: am - al,
            phase_deg: (pm - pl).to_degrees(),
        });
    }
    let d = |t: f64, f: f64| {
        conditions.iter().find(|c| c.temperature_c == t && c.frequency_hz == f).map(|c| c.decay_rad).unwrap_or(f64::NAN)
    };
    let ratio = |f: f64| if d(22.0, f) > 0.0 { d(60.0, f) / d(22.0, f) } else { f64::NAN };
    let (r05, r1) = (ratio(0.5), ratio(1.0));
    let max_abs_phase_deg = conditions.iter().map(|c| c.phase_deg.abs()).fold(0.0, f64::max);
    let positive_decay = conditions.iter().all(|c| c.decay_rad > 0.0);
    Ok(Summary {
        log_ratio_error: if r05 > 0.0 { (r05 / 5.0).ln() } else { f64::NAN },
        less_pronounced_at_1hz: r1 < r05,
        minimal_phase: max_abs_phase_deg <= MINIMAL_PHASE_DEG,
        positive_decay,
        ratio_half_hz: r05,
        ratio_one_hz: r1,
        max_abs_phase_deg,
        conditions,
    })
}

fn with(effect: Effect, v: f64) -> EffectValues {
    let mut e = EffectValues::default();
    match effect {
        Effect::CoulombFriction => e.coulomb_friction = v,
        Effect::Backlash => e.backlash_width = v,
        Effect::Gravity => e.gravity_a = v, // hanging straight down: offset 0
        Effect::LinkDamping => e.link_damping = v,
        Effect::ThermalLag => e.thermal_lag = v,
        Effect::FrequencyDependentModulus => {
            e.maxwell_stiffness = v;
            e.maxwell_time = 0.1;
        }
        Effect::StribeckFriction => {
            e.stribeck_friction = v;
            e.stribeck_velocity = 0.05;
        }
        Effect::AsymmetricFriction => e.coulomb_asymmetry = v,
        Effect::ConstantLoad => e.constant_load = v,
    }
    e
}

/// Parameter scan range of each effect (log-spaced), SI; None for effects that cannot act alone
/// (an asymmetry needs friction to be asymmetric) or that a symmetric sweep cannot show (a
/// constant load shifts the centre, not the amplitude ratio the paper reports).
fn range(effect: Effect) -> Option<(f64, f64, &'static str)> {
    Some(match effect {
        Effect::CoulombFriction => (1e-3, 5.0, "torque_nm"),
        Effect::Backlash => (1e-4, 0.3, "width_rad"),
        Effect::Gravity => (1e-2, 10.0, "mgl_nm"),
        Effect::LinkDamping => (1e-3, 5.0, "damping_nms"),
        Effect::ThermalLag => (0.1, 10.0, "time_constant_s"),
        Effect::FrequencyDependentModulus => (1e-2, 100.0, "stiffness_nm_per_rad"),
        Effect::StribeckFriction => (1e-3, 5.0, "torque_nm"),
        Effect::AsymmetricFriction | Effect::ConstantLoad => return None,
    })
}

fn summary_json(s: &Summary) -> Value {
    serde_json::to_value(s).unwrap_or(Value::Null)
}

type Scan = (Vec<Value>, Option<(Effect, f64, Summary)>, Option<(Effect, f64, f64)>);

/// For every effect, the one parameter that makes D60/D22 at 0.5 Hz equal `target` (log scan, then
/// bisection), and whether the secondary claims then hold.
fn scan(sim: &Simulator, temps: &[f64], freqs: &[f64], target: f64) -> Result<Scan, String> {
    let mut rows = Vec::new();
    let mut best: Option<(Effect, f64, Summary)> = None;
    let mut closest: Option<(Effect, f64, f64)> = None;
    for effect in Effect::ALL {
        if effect == Effect::ThermalLag {
            // steady temperatures: a lag behind a constant thermocouple changes nothing
            rows.push(json!({"effect": effect.name(), "explains": false, "why": "runs at steady temperature: no lag can show"}));
            continue;
        }
        let Some((lo, hi, pname)) = range(effect) else {
            rows.push(json!({"effect": effect.name(), "explains": false, "why": "not a single-parameter effect on a symmetric sweep's amplitude ratio"}));
            continue;
        };
        // scan for the ratio crossing the target, then bisect in log space
        let grid: Vec<f64> = (0..=16).map(|k| lo * (hi / lo).powf(k as f64 / 16.0)).collect();
        let mut prev: Option<(f64, f64)> = None;
        let mut found = None;
        let mut scanned = Vec::new();
        for &v in &grid {
            let s = summarise(sim, with(effect, v), temps, freqs)?;
            scanned.push((v, s.ratio_half_hz, s.positive_decay));
            let e = if s.positive_decay { (s.ratio_half_hz / target).ln() } else { f64::NAN };
            if let (Some((pv, pe)), true) = (prev, e.is_finite()) {
                if pe.is_finite() && pe.signum() != e.signum() {
                    found = Some((pv, v));
                    break;
                }
            }
            prev = Some((v, e));
        }
        let Some((mut a, mut b)) = found else {
            // the scanned value whose ratio comes nearest the target (in log)
            let miss = |r: f64| (r / target).ln().abs();
            let top = scanned.iter().filter(|x| x.2 && x.1 > 0.0).cloned().fold(
                None,
                |m: Option<(f64, f64, bool)>, x| match m {
                    Some(y) if miss(y.1) <= miss(x.1) => Some(y),
                    _ => Some(x),
                },
            );
            let why = match top {
                Some((v, r, _)) => format!(
                    "no value in [{lo}, {hi}] reaches D60/D22 = {target} at 0.5 Hz; closest {r:.2} at {pname} = {v:.3}"
                ),
                None => format!("no value in [{lo}, {hi}] gives a positive Decay at every condition"),
            };
            if let Some((v, r, _)) = top {
                if closest.as_ref().is_none_or(|c: &(Effect, f64, f64)| miss(r) < miss(c.2)) {
                    closest = Some((effect, v, r));
                }
            }
            rows.push(json!({"effect": effect.name(), "explains": false, "closest_ratio": top.map(|t| t.1), "closest_value": top.map(|t| t.0), "why": why}));
            continue;
        };
        let ea = (summarise(sim, with(effect, a), temps, freqs)?.ratio_half_hz / target).ln();
        for _ in 0..14 {
            let m = (a * b).sqrt();
            let em = (summarise(sim, with(effect, m), temps, freqs)?.ratio_half_hz / target).ln();
            if em.signum() == ea.signum() {
                a = m
            } else {
                b = m
            }
        }
        let v = (a * b).sqrt();
        let s = summarise(sim, with(effect, v), temps, freqs)?;
        let explains = s.positive_decay && s.less_pronounced_at_1hz && s.minimal_phase;
        rows.push(json!({"effect": effect.name(), "parameters": {pname: v}, "summary": summary_json(&s), "explains": explains,
            "why": format!("D60/D22 = {:.2} at 0.5 Hz, {:.2} at 1 Hz ({}), max |phase| {:.1}° ({})",
                s.ratio_half_hz, s.ratio_one_hz, if s.less_pronounced_at_1hz { "less pronounced at 1 Hz, as reported" } else { "NOT less pronounced at 1 Hz" },
                s.max_abs_phase_deg, if s.minimal_phase { "minimal" } else { "not minimal" })}));
        if explains && best.as_ref().is_none_or(|bst| s.max_abs_phase_deg < bst.2.max_abs_phase_deg) {
            best = Some((effect, v, s));
        }
    }
    Ok((rows, best, closest))
}

/// The whole summary-space loop; returns (report.json value, Markdown).
/// K = K_springs + E'(T)·κr², the transmission's stiffness with the PCL at `t_c`, as the FMU
/// computes it (its calculated parameters and its storage-modulus output).
fn transmission_stiffness(sim: &Simulator, t_c: f64) -> Result<f64, String> {
    let e = |e: thermovia_importer::HarnessError| e.to_string();
    let mut inst = sim.fmu.instantiate(None).map_err(e)?;
    let t_k = t_c + crate::report::ZERO_CELSIUS;
    inst.initialize(0.0, None, &[("initial_pcl_temperature", t_k), ("initial_housing_temperature", t_k)]).map_err(e)?;
    Ok(inst.get("spring_bank_stiffness").map_err(e)?
        + inst.get("storage_modulus").map_err(e)? * inst.get("modulus_to_torsion").map_err(e)?)
}

pub fn run(sim: &Simulator, source: &Value) -> Result<(Value, String), String> {
    let temps = [22.0, 60.0];
    let freqs = [0.5, 1.0];
    let target = source["decay"][0]["ratio_60_vs_22"].as_f64().unwrap_or(5.0);
    let nominal = summarise(sim, EffectValues::default(), &temps, &freqs)?;
    let (rows, best, closest) = scan(sim, &temps, &freqs, target)?;
    // the paper's other figure: "a 30 % increase in Decay" at higher temperatures
    let alt_target = 1.3;
    let (alt_rows, alt_best, _) = scan(sim, &temps, &freqs, alt_target)?;
    // the device's own load: 0.91 kg at 0.14 m (PAPER), hanging straight
    let paper_mgl = 0.91 * super::sim::STANDARD_GRAVITY * 0.14;
    let paper_gravity = summarise(sim, with(Effect::Gravity, paper_mgl), &temps, &freqs)?;
    // without a full explanation, "after" is the closest effect (reported as such, unexplained)
    let after = match (&best, &closest) {
        (Some(b), _) => b.2.clone(),
        (None, Some(c)) => summarise(sim, with(c.0, c.1), &temps, &freqs)?,
        (None, None) => nominal.clone(),
    };
    // quasi-static bound: any ground-referenced effect gives D ≈ θ0 k_g/(K + k_g), so the ratio
    // tends to K(22 °C)/K(60 °C) of the transmission, springs included
    let stiffness_ratio = transmission_stiffness(sim, 22.0)? / transmission_stiffness(sim, 60.0)?;
    let j = json!({
        "source": source["source"],
        "assumptions": {"motor_amplitude_rad": AMPLITUDE, "minimal_phase_deg": MINIMAL_PHASE_DEG, "moduli": "material table (repaired experimental) as in the FMU", "target_ratio_60_vs_22_half_hz": target},
        "baseline": summary_json(&nominal),
        "candidates": rows,
        "explained_by": best.as_ref().map(|b| json!({"effect": b.0.name(), "value": b.1})),
        "closest": closest.as_ref().map(|c| json!({"effect": c.0.name(), "value": c.1, "ratio_half_hz": c.2})),
        "stiffness_ratio_22_vs_60": stiffness_ratio,
        "final": summary_json(&after),
        "paper_load_gravity": {"mgl_nm": paper_mgl, "summary": summary_json(&paper_gravity)},
        "unexplained": best.is_none(),
        "alternative_reading": {"target_ratio": alt_target, "claim": "a 30% increase in Decay (results text; conflicts with the five-fold figure)",
            "candidates": alt_rows, "explained_by": alt_best.as_ref().map(|b| json!({"effect": b.0.name(), "value": b.1, "summary": summary_json(&b.2)}))},
    });
    let mut md = String::from("## The paper's summary measurements\n\n");
    md += &format!("Motor amplitude {AMPLITUDE} rad (assumed: the paper's is lost), steady cycles, table moduli. Target: D(60 °C)/D(22 °C) = {target} at 0.5 Hz, smaller at 1 Hz, |phase| ≤ {MINIMAL_PHASE_DEG}°.\n\n");
    md += "| model | D22 0.5 Hz (mrad) | D60 0.5 Hz (mrad) | ratio 0.5 Hz | ratio 1 Hz | max abs phase (°) | ln(ratio/5) |\n|---|---|---|---|---|---|---|\n";
    let line = |name: &str, s: &Summary| {
        let d = |t: f64, f: f64| {
            s.conditions
                .iter()
                .find(|c| c.temperature_c == t && c.frequency_hz == f)
                .map(|c| c.decay_rad * 1e3)
                .unwrap_or(f64::NAN)
        };
        // A ratio of Decays is only defined for positive Decays: the nominal model has none.
        let num =
            |x: f64, digits: usize| if x.is_finite() { format!("{x:.digits$}") } else { "— (Decay < 0)".to_string() };
        format!(
            "| {name} | {:+.2} | {:+.2} | {} | {} | {:.2} | {} |\n",
            d(22.0, 0.5),
            d(60.0, 0.5),
            num(s.ratio_half_hz, 2),
            num(s.ratio_one_hz, 2),
            s.max_abs_phase_deg,
            num(s.log_ratio_error, 3)
        )
    };
    md += &line("nominal (before)", &nominal);
    if let Some((e, v, s)) = &best {
        md += &line(&format!("+ {} = {:.4} (after)", e.name(), v), s);
    }
    if let (None, Some((e, v, _))) = (&best, &closest) {
        md += &line(&format!("+ {} = {:.4} (after: closest, not a full explanation)", e.name(), v), &after);
    }
    md += &line(&format!("+ gravity, paper's load m g d = {paper_mgl:.3} N·m"), &paper_gravity);
    md += "\n| effect | explains the summary? | evidence |\n|---|---|---|\n";
    for r in &rows {
        md += &format!(
            "| {} | {} | {} |\n",
            r["effect"].as_str().unwrap_or(""),
            r["explains"],
            r["why"].as_str().unwrap_or("")
        );
    }
    md += &format!("\nThe paper's other figure, a 30 % increase (D60/D22 = {alt_target}):\n\n| effect | explains it? | evidence |\n|---|---|---|\n");
    for r in &alt_rows {
        md += &format!(
            "| {} | {} | {} |\n",
            r["effect"].as_str().unwrap_or(""),
            r["explains"],
            r["why"].as_str().unwrap_or("")
        );
    }
    md += &format!(
        "\nTransmission stiffness K(22 °C)/K(60 °C) = {stiffness_ratio:.2} with the table's moduli and the 6.86 N·m/rad springs: \
         a ground-referenced effect makes D ≈ θ0 k_g/(K + k_g), so its Decay ratio tends to this stiffness ratio quasi-statically; \
         the link's inertia raises it at 0.5 Hz. unexplained: **{}**.\n",
        best.is_none()
    );
    Ok((j, md))
}
