//! report.json (interfaces.md), report.md and SVG plots, all built in memory and written at once.

use super::signal::amplitude_spectrum;
use plotters::prelude::*;
use serde_json::{json, Map, Value};

use super::data::Run;
use super::diagnose::Signatures;
use super::fit::{standard_deviation, Effect, Fit, Problem};
use super::quality::short;
use super::search::Outcome;
use crate::report::plot::{
    chart_svg, draw, figure, log_axis, log_range, panel, thin, Axes, Dash, Marker, Series, Style, BLACK_, BLUE_, GREY_,
    RED_,
};

/// Error metrics of a fit over every sample used.
pub fn metrics(prob: &Problem, fit: &Fit) -> Value {
    let y: Vec<f64> = prob.measured.iter().flatten().copied().collect();
    let n = y.len() as f64;
    let mean = y.iter().sum::<f64>() / n;
    let spread = y.iter().map(|v| (v - mean).powi(2)).sum::<f64>().sqrt();
    let err = fit.sse.sqrt();
    let norm = y.iter().map(|v| v * v).sum::<f64>().sqrt();
    json!({
        "relerr_percent": 100.0 * err / norm,
        "rmse_rad": fit.rmse(),
        "nrmse": fit.rmse() / (spread / n.sqrt()),
        "fit_percent": 100.0 * (1.0 - err / spread),
        "bic": fit.bic(),
        "parameters": fit.p.len(),
        "samples": fit.n,
    })
}

/// One `added_effects` entry, the same for every rig: {"effect", "parameters", "standard_errors"}.
pub fn effect_entry(name: &str, params: &[(&'static str, f64, f64)]) -> Value {
    let mut values = Map::new();
    let mut errors = Map::new();
    for &(n, v, s) in params {
        values.insert(n.into(), json!(v));
        errors.insert(n.into(), json!(s));
    }
    json!({"effect": name, "parameters": values, "standard_errors": errors})
}

/// (name, value, standard error) of an effect's parameters in the SI units of interfaces.md.
pub fn effect_parameters(fit: &Fit, effect: Effect) -> Vec<(&'static str, f64, f64)> {
    let offsets =
        fit.spec.offsets((fit.p.len() - fit.spec.effects.iter().map(|e| e.params().len()).sum::<usize>()) / 2);
    let offset_of = |e: Effect| offsets.iter().find(|(_, x)| *x == e).map(|&(i, _)| i);
    let o = offset_of(effect).expect("effect in the fit");
    let v = &fit.p[o..];
    let c = |i: usize, j: usize| fit.covariance_at(o + i, o + j);
    let sd = |i: usize| standard_deviation(c(i, i));
    match effect {
        Effect::CoulombFriction => vec![("torque_nm", v[0], sd(0))],
        Effect::Backlash => vec![("width_rad", v[0], sd(0))],
        Effect::LinkDamping => vec![("damping_nms", v[0], sd(0))],
        Effect::ThermalLag => vec![("time_constant_s", v[0], sd(0))],
        Effect::Gravity => {
            let (a, b) = (v[0], v[1]);
            let m = a.hypot(b).max(1e-300);
            // delta method through (a, b) → (|·|, atan2)
            let gm = [a / m, b / m];
            let go = [-b / (m * m), a / (m * m)];
            let var = |g: [f64; 2]| g[0] * g[0] * c(0, 0) + 2.0 * g[0] * g[1] * c(0, 1) + g[1] * g[1] * c(1, 1);
            vec![("mgl_nm", m, standard_deviation(var(gm))), ("offset_rad", b.atan2(a), standard_deviation(var(go)))]
        }
        Effect::FrequencyDependentModulus => {
            let lam = v[1].exp();
            vec![("stiffness_nm_per_rad", v[0], sd(0)), ("relaxation_time_s", lam, lam * sd(1))]
        }
        Effect::StribeckFriction => {
            let vs = v[1].exp();
            vec![("torque_nm", v[0], sd(0)), ("velocity", vs, vs * sd(1))]
        }
        Effect::ConstantLoad => vec![("torque_nm", v[0], sd(0))],
        Effect::AsymmetricFriction => {
            // the four levels of interfaces.md: the symmetric parts (Coulomb, link damping, when in
            // the model) ± the half-differences; errors through the covariance of each sum
            let combo = |sym: Option<usize>, asym: usize, sign: f64| {
                let value = sym.map_or(0.0, |i| fit.p[i]) + sign * fit.p[asym];
                let var = fit.covariance_at(asym, asym)
                    + sym.map_or(0.0, |i| fit.covariance_at(i, i) + 2.0 * sign * fit.covariance_at(i, asym));
                (value, standard_deviation(var))
            };
            let (cp, cn) =
                (combo(offset_of(Effect::CoulombFriction), o, 1.0), combo(offset_of(Effect::CoulombFriction), o, -1.0));
            let (bp, bn) =
                (combo(offset_of(Effect::LinkDamping), o + 1, 1.0), combo(offset_of(Effect::LinkDamping), o + 1, -1.0));
            vec![
                ("coulomb_positive", cp.0, cp.1),
                ("coulomb_negative", cn.0, cn.1),
                ("viscous_positive", bp.0, bp.1),
                ("viscous_negative", bn.0, bn.1),
            ]
        }
    }
}

/// The paper's quantities per temperature (interfaces.md `identified`): the transmission's
/// stiffness and damping (± block-sandwich standard errors through the log), the inertia used,
/// natural frequency and damping ratio of the link on the transmission, and damping to ground.
pub fn identified(prob: &Problem, fit: &Fit, temps: &[f64]) -> Value {
    let ground = fit
        .spec
        .effects
        .contains(&Effect::LinkDamping)
        .then(|| effect_parameters(fit, Effect::LinkDamping)[0])
        .map_or((0.0, 0.0), |(_, v, s)| (v, s));
    Value::Array(
        (0..prob.n_groups)
            .map(|g| {
                let runs: Vec<usize> = (0..prob.inputs.len()).filter(|&r| prob.group[r] == g).collect();
                let inertia = runs.iter().map(|&r| prob.inertia(r)).sum::<f64>() / runs.len().max(1) as f64;
                let declared = runs.iter().all(|&r| prob.inputs[r].link_inertia.is_some());
                let (k, c) = (fit.p[2 * g].exp(), fit.p[2 * g + 1].exp());
                let t = &prob.tables[g];
                let ((k_lo, k_hi), (c_lo, c_hi)) = prob.transmission_range(g);
                let (deflection, count) = deflection_and_count(prob, fit, &runs, k);
                json!({
                    "temperature_c": temps[g],
                    "stiffness": k,
                    "stiffness_std": k * fit.std_err(2 * g),
                    "damping": c,
                    "damping_std": c * fit.std_err(2 * g + 1),
                    "damping_law": fit.spec.law.name(),
                    "spring_bank": fit.spec.springs.name(),
                    "nominal_spring_bank_stiffness": t.spring_bank,
                    "damping_reference_frequency_hz": t.frequency_hz,
                    "loss_stiffness": c * 2.0 * std::f64::consts::PI * t.frequency_hz,
                    "inertia": inertia,
                    "inertia_declared": declared,
                    "natural_frequency_hz": (k / inertia).sqrt() / (2.0 * std::f64::consts::PI),
                    "damping_ratio": c / (2.0 * (k * inertia).sqrt()),
                    "viscous_damping": ground.0,
                    "viscous_damping_std": ground.1,
                    "identified_as": if declared { "physical values (inertia declared)" } else { "K/J and C/J only: the inertia is the FMU's default, not declared; natural frequency and damping ratio are identified, K and C scale with the true inertia" },
                    "at_bound": prob.transmission_at_bound(g, &fit.p),
                    "stiffness_range": [k_lo, k_hi],
                    "damping_range": [c_lo, c_hi],
                    "table_stiffness": t.stiffness,
                    "table_damping": t.damping,
                    "inertial_deflection_rad": deflection,
                    "undithered_link_count_rad": count,
                })
            })
            .collect(),
    )
}

/// The transmission's deflection that carries the link's inertial torque, J·â/K with â = √2 times
/// the rms of the model's link acceleration over `runs` (a sinusoid's amplitude; a start's transient
/// does not set it): the part of the deflection K is read from. And the coarsest count among the
/// runs' link encoders that the noise does not dither (`LinkCount::dithered`; None where every
/// run's is dithered or there is none).
fn deflection_and_count(prob: &Problem, fit: &Fit, runs: &[usize], stiffness: f64) -> (f64, Option<f64>) {
    let (mut sum, mut n, mut inertia) = (0.0, 0usize, 0.0f64);
    for &r in runs {
        let (Some(y), t) = (fit.outputs.get(r), &prob.inputs[r].time) else { continue };
        inertia = inertia.max(prob.inertia(r));
        for k in 1..y.len().min(t.len()).saturating_sub(1) {
            if let Some(a) = super::signal::second_divided_difference(t, y, k).filter(|a| a.is_finite()) {
                sum += a * a;
                n += 1;
            }
        }
    }
    let deflection = inertia * (2.0 * sum / n.max(1) as f64).sqrt() / stiffness;
    let counts = prob.link_counts(&fit.outputs);
    let count =
        runs.iter().filter_map(|&r| counts.get(r)?.as_ref().filter(|c| !c.dithered()).map(|c| c.q)).reduce(f64::max);
    (deflection, count)
}

/// The same fit as factors on the FMU's material table (springs and E' scaled together).
fn moduli(prob: &Problem, fit: &Fit, temps: &[f64]) -> Value {
    Value::Array(
        (0..prob.n_groups)
            .map(|g| {
                let t = &prob.tables[g];
                let (s1, s2) = (fit.p[2 * g].exp() / t.stiffness, fit.p[2 * g + 1].exp() / t.damping);
                json!({
                    "temperature_c": temps[g],
                    "storage_modulus_scale": s1,
                    "storage_modulus_scale_std": s1 * fit.std_err(2 * g),
                    "spring_stiffness_scale": s1,
                    "loss_modulus_scale": s2,
                    "loss_modulus_scale_std": s2 * fit.std_err(2 * g + 1),
                })
            })
            .collect(),
    )
}

fn signature_json(s: &Signatures) -> Value {
    serde_json::to_value(s).unwrap_or(Value::Null)
}

/// Words for what is left in a residual that no effect explained.
pub fn remaining_structure(s: &Signatures) -> String {
    let h = |i: usize| s.runs.iter().map(|r| r.harmonics[i]).sum::<f64>() / s.runs.len() as f64;
    format!(
        "residual RMS {:.2e} rad against a noise floor of {:.2e} rad; low-frequency structure {:.1}× white noise (limit {}); \
         mean harmonics DC {:.1e}, 1ω {:.1e}, 2ω {:.1e}, 3ω {:.1e}, 5ω {:.1e} rad; corr with sign θl' {:+.2}, sin θl {:+.2}, \
         sign θm' {:+.2}, time {:+.2}; lag-1 autocorrelation {:+.2}",
        s.rmse,
        s.noise_floor,
        s.structure_ratio,
        super::diagnose::STRUCTURE_LIMIT,
        h(0),
        h(1),
        h(2),
        h(3),
        h(4),
        s.corr_sign_link_speed,
        s.corr_sin_link_angle,
        s.corr_dead_zone,
        s.corr_time,
        s.autocorrelation.first().map(|a| a.1).unwrap_or(0.0)
    )
}

pub fn report_json(runs: &[Run], prob: &Problem, o: &Outcome, temps: &[f64], seconds: f64) -> Value {
    let runs_json: Vec<Value> = runs
        .iter()
        .map(|r| json!({"file": r.name(), "temperature_c": r.mean_temperature_c(), "frequency_hz": r.frequency_hz, "samples": r.time.len()}))
        .collect();
    let diagnosis: Vec<Value> = o.record.rounds.first().map_or(vec![], |r| {
        r.candidates.iter().map(|c| json!({"effect": c.effect.name(), "score": c.score, "predicted_delta_bic": c.predicted_delta_bic, "evidence": c.evidence})).collect()
    });
    let added: Vec<Value> = o
        .final_fit
        .spec
        .reported_effects()
        .into_iter()
        .map(|e| {
            let mut entry = effect_entry(e.name(), &effect_parameters(&o.final_fit, e));
            let limits = plausible(prob, &o.final_fit, e);
            entry["plausible_limits"] =
                Value::Object(limits.iter().map(|&(n, l, _)| (n.to_string(), json!(l))).collect());
            // at the limit to 1e-6 relative
            entry["at_plausible_limit"] = json!(limits.iter().any(|&(_, l, x)| x.abs() >= l * (1.0 - 1e-6)));
            entry
        })
        .collect();
    let record = record_json(o);
    let mut forms = equivalent_forms(&added);
    let softest = prob.softest_stiffness(&o.final_fit.p);
    let links: Vec<&[f64]> = runs.iter().map(|r| &r.link[..]).collect();
    let floor = o.final_signatures.noise_floor;
    if let (Some(form), Value::Array(list)) = (gravity_offset_form(&added, &links, softest, floor), &mut forms) {
        let chained = through_the_load(&added, &form);
        list.push(form);
        list.extend(chained);
    }
    if let (Some(form), Value::Array(list)) = (equal_levels_form(&added), &mut forms) {
        list.push(form);
    }
    json!({
        "runs": runs_json,
        "baseline": metrics(prob, &o.baseline),
        "diagnosis": diagnosis,
        "added_effects": added,
        "final": metrics(prob, &o.final_fit),
        "pruned_effects": record["pruned_effects"],
        "equivalent_forms": forms,
        "noise_floor_rad": o.final_signatures.noise_floor,
        "plausibility": prob.torque_scale().map(|t| json!({
            "transmission_torque_nm": t.transmission_nm, "inertial_torque_nm": t.inertial_nm, "link_speed_rad_s": t.speed,
            "relative_angle_rad": t.relative_angle, "factor": super::fit::PLAUSIBLE_TORQUE_FACTOR,
            "note": "each effect's torque on the link is bounded by factor × (transmission + inertial torque) the runs show (equation error with every linear effect), a backlash by twice the largest relative angle; gravity is not bounded",
        })),
        "moduli": {"baseline": moduli(prob, &o.baseline, temps), "final": moduli(prob, &o.final_fit, temps)},
        "identified": identified(prob, &o.final_fit, temps),
        "damping_law": {
            "chosen": o.final_fit.spec.law.name(),
            "reason": o.law_reason,
            "spring_bank": o.final_fit.spec.springs.name(),
            "compared": o.laws.iter().map(|r| json!({"stage": r.stage, "law": r.structure.0.name(), "spring_bank": r.structure.1.name(), "rmse_rad": r.rmse, "bic": r.bic})).collect::<Vec<_>>(),
        },
        "backlash_law": o.backlash_laws.as_ref().map(|b| json!({
            "chosen": if b.elasto { "elasto_backlash" } else { "clipped" },
            "compared": b.compared.iter().map(|(law, rmse, bic)| json!({"law": law, "rmse_rad": rmse, "bic": bic})).collect::<Vec<_>>(),
            "width_scan": b.width_scan.map(|(from, to)| json!({"from_rad": from, "to_rad": to})),
            "rule": format!("with backlash in the final model, the clipped spring-damper (the search's) and Modelica's ElastoBacklash (the damper capped by the spring) are both fitted from the search's parameters on the fitting runs; ElastoBacklash is kept when it lowers the BIC by more than {}", super::stepwise::BIC_MARGIN),
        })),
        "identified_baseline": identified(prob, &o.baseline, temps),
        "rounds": record["rounds"],
        "searched_again": record["searched_again"],
        "search_budget": record["search_budget"],
        "combinations": record["combinations"],
        "signatures": {"baseline": signature_json(&o.baseline_signatures), "final": signature_json(&o.final_signatures)},
        "method": {
            "fit": "per temperature the transmission's stiffness K and damping C (log-parameters; springs and PCL scaled together), plus the effects' parameters; the baseline starts from the best of a closed form (frequency response K* = Jω²H/(H−1) for sinusoidal runs, equation error otherwise), the material table and a mix, then Levenberg–Marquardt on every sample, the FMU simulated through the harness with the measured motor angle as input; forward-difference Jacobians",
            "standard_errors": format!("block sandwich: (JᵀJ)⁻¹ Σ_b s_b s_bᵀ (JᵀJ)⁻¹ over {} contiguous blocks per run, so residuals correlated within a block do not shrink them", super::fit::COVARIANCE_BLOCKS),
            "acceptance": format!("ΔBIC < −{} and at least {:.0}% of the residual's low-frequency structure over white noise removed; where nothing in a round does and the model's rms is over {} times its noise floor, the round's refit with the lowest BIC that lowered the BIC by the margin and the structure at all is ranked in its turn and its best candidates refitted beside it, kept where the two together meet the same rule against the model before both (stage `after a partial gain`); stop when the residual is white (structure ratio < {}), after one round there that refits the best-ranked candidate alone where it predicts a gain, judged by the same rule", super::stepwise::BIC_MARGIN, 100.0 * super::search::STRUCTURE_DROP, super::search::FAR_ABOVE_FLOOR, super::diagnose::STRUCTURE_LIMIT),
            "simulations": prob.sim.simulations.load(std::sync::atomic::Ordering::Relaxed),
            "seconds": seconds,
        },
    })
}

/// The device search's record (`stepwise::record_json`): rounds with the screened residual's
/// structure ratio, refits with the structure ratio before and after.
fn record_json(o: &Outcome) -> Value {
    super::stepwise::record_json(
        &o.record,
        Effect::name,
        |s: &super::diagnose::Signatures| json!({"structure_ratio": s.structure_ratio}),
        |d: &super::search::Evidence| {
            let mut j = json!({"structure_before": d.structure.0, "structure_after": d.structure.1});
            if let Some(n) = d.newly_near_bound {
                j["stiffness_newly_near_bound"] = json!(n);
            }
            j
        },
    )
}

/// What a reader of the device loop's numbers must know: an inertia taken from the FMU's default
/// rather than declared, and material factors stopped at their bounds. Never silent: report.json
/// `warnings`, report.md and the console.
pub fn device_warnings(runs: &[Run], report: &serde_json::Value) -> Vec<String> {
    let mut warnings = Vec::new();
    let from_mass: Vec<String> = runs.iter().filter(|r| r.inertia_from_mass).map(|r| r.name()).collect();
    if !from_mass.is_empty() {
        warnings.push(format!(
            "the link inertia of {} is the point mass m·l² from link_mass_kg and link_length_m (the link's own \
             inertia about its centre is not in it): declare link_inertia_kgm2 when it is known",
            from_mass.join(", ")
        ));
    }
    let undeclared: Vec<String> = runs.iter().filter(|r| r.link_inertia.is_none()).map(|r| r.name()).collect();
    if !undeclared.is_empty() {
        warnings.push(format!(
            "link_inertia_kgm2 is not declared in {} of {} runs ({}): the FMU's default link_inertia is used, so the \
             fitted stiffness and damping are known only relative to it (K/J and C/J); declare the inertia for \
             physical values",
            undeclared.len(),
            runs.len(),
            undeclared.join(", ")
        ));
    }
    for e in report["added_effects"].as_array().into_iter().flatten().filter(|e| e["at_plausible_limit"] == true) {
        warnings.push(format!(
            "{} sits at its plausible limit {} (its torque on the link at {}× the largest transmission plus inertial \
             torque the runs show, or a play twice the largest relative angle): the data cannot show it that large, \
             and it is likely standing in for an effect the library lacks",
            e["effect"].as_str().unwrap_or("?"),
            e["plausible_limits"],
            super::fit::PLAUSIBLE_TORQUE_FACTOR
        ));
    }
    for g in report["identified"].as_array().into_iter().flatten() {
        let (Some(deflection), Some(count)) =
            (g["inertial_deflection_rad"].as_f64(), g["undithered_link_count_rad"].as_f64())
        else {
            continue;
        };
        if deflection < count {
            warnings.push(format!(
                "at {} °C the transmission's deflection under the link's inertial torque, J·â/K, is {deflection:.2e} \
                 rad, under one count ({count:.2e} rad) of a link encoder its noise does not dither: where the counts \
                 fall at the motion's turns (the motor's, which drives the model, most) can move K and C by more than \
                 their standard errors hold (over the campaign's sine rigs, 19 of 36 temperatures under one count read \
                 K more than 10 % off, 3 of 277 above it; on fresh rigs, 7 of 18 read C more than 10 % off, 5 of 78 \
                 above it; docs/calibration.md). A finer encoder, or a motion that loads the link more (faster, or \
                 nearer its natural frequency), shows more",
                g["temperature_c"].as_f64().unwrap_or(f64::NAN),
            ));
        }
    }
    for (stage, key) in [("baseline", "identified_baseline"), ("final", "identified")] {
        for g in report[key].as_array().into_iter().flatten() {
            if g["at_bound"].as_bool() == Some(true) && (stage == "final" || baseline_bound_matters(report, g)) {
                warnings.push(format!(
                "{stage} fit at {} °C: the transmission stopped at a bound (K = {:.4e} N·m/rad within {:.0e}–{:.2e}, C = \
                 {:.4e} N·m·s/rad within {:.0e}–{:.2e}; the upper ends are what the sample rate can show for this \
                 inertia): the structure cannot reach what these data want, and what the loop adds may be filling \
                 that gap",
                g["temperature_c"].as_f64().unwrap_or(f64::NAN),
                g["stiffness"].as_f64().unwrap_or(f64::NAN),
                g["stiffness_range"][0].as_f64().unwrap_or(f64::NAN),
                g["stiffness_range"][1].as_f64().unwrap_or(f64::NAN),
                g["damping"].as_f64().unwrap_or(f64::NAN),
                g["damping_range"][0].as_f64().unwrap_or(f64::NAN),
                g["damping_range"][1].as_f64().unwrap_or(f64::NAN),
            ));
            }
        }
    }
    warnings
}

/// Whether a baseline stopped at a bound (`identified_baseline` entry `g`) is worth a warning: when
/// the final model still sits at a bound at that temperature, or does not fit (unexplained, or a
/// residual that is not white), the added effects may be standing in for the transmission. A
/// baseline that only lacked an effect the loop then found (gravity pulls a rigid-looking link)
/// often goes rigid; the final fit, inside its bounds and white, shows nothing was filled in.
fn baseline_bound_matters(report: &Value, g: &Value) -> bool {
    let final_at_bound = report["identified"]
        .as_array()
        .into_iter()
        .flatten()
        .any(|f| f["temperature_c"] == g["temperature_c"] && f["at_bound"] != false);
    final_at_bound || report["unexplained"] != false || report["residual_white"] == false
}

/// The baseline's temperatures whose bound was no warning (`baseline_bound_matters`), for report.md.
fn baseline_bounds_resolved(report: &Value) -> Vec<String> {
    report["identified_baseline"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|g| g["at_bound"] == true && !baseline_bound_matters(report, g))
        .map(|g| g["temperature_c"].to_string())
        .collect()
}

/// (internal name, plausible limit, fitted value) of each parameter of effect `e` in `fit` that has
/// a limit (`Problem::plausible_limits`).
fn plausible(prob: &Problem, fit: &Fit, e: Effect) -> Vec<(&'static str, f64, f64)> {
    let limits = prob.plausible_limits(&fit.spec);
    let o = fit.spec.offset_of(e, prob.n_groups).expect("effect in the fit");
    let first = o - 2 * prob.n_groups;
    e.params().iter().enumerate().filter_map(|(i, p)| limits[first + i].map(|l| (p.0, l, fit.p[o + i]))).collect()
}

fn fmt_params(fit: &Fit, e: Effect) -> String {
    effect_parameters(fit, e)
        .iter()
        .map(|(n, v, s)| format!("{n} = {v:.4} {}", plus_minus(*s)))
        .collect::<Vec<_>>()
        .join(", ")
}

pub fn report_markdown(j: &Value, o: &Outcome) -> String {
    let m = |k: &str, f: &str| j[k][f].as_f64().unwrap_or(f64::NAN);
    let mut s = String::from("# Calibration report\n\n");
    s += &format!(
        "{} runs, {} samples. Noise floor estimated from the data (second differences): {:.3e} rad.\n\n",
        j["runs"].as_array().map_or(0, |a| a.len()),
        o.baseline.n,
        j["noise_floor_rad"].as_f64().unwrap_or(0.0)
    );
    if let Some(w) = j["warnings"].as_array().filter(|w| !w.is_empty()) {
        s += "## Warnings\n\n";
        for line in w {
            s += &format!("- {}\n", line.as_str().unwrap_or_default());
        }
        s += "\n";
    }
    s += "| model | RMSE (rad) | NRMSE | fit % | BIC |\n|---|---|---|---|---|\n";
    for k in ["baseline", "final"] {
        s += &format!(
            "| {k} | {:.3e} | {:.4} | {:.2} | {:.0} |\n",
            m(k, "rmse_rad"),
            m(k, "nrmse"),
            m(k, "fit_percent"),
            m(k, "bic")
        );
    }
    if let Some(v) = j.get("validation") {
        s += &format!(
            "\nHeld-out runs ({}), simulated with the parameters fitted above: RMSE {:.3e} → {:.3e} rad, relerr \
             {:.4} → {:.4} %.\n",
            v["runs"].as_array().map_or(0, Vec::len),
            v["baseline"]["rmse_rad"].as_f64().unwrap_or(f64::NAN),
            v["final"]["rmse_rad"].as_f64().unwrap_or(f64::NAN),
            v["baseline"]["relerr_percent"].as_f64().unwrap_or(f64::NAN),
            v["final"]["relerr_percent"].as_f64().unwrap_or(f64::NAN)
        );
    }
    if j["held_out"].is_object() {
        s += &held_out_markdown(&j["held_out"]);
    }
    s += "\n## Chain of evidence\n\n";
    s += &super::stepwise::record_markdown(
        &record_json(o),
        |r| format!(" (residual structure {:.1}× white noise)", r["structure_ratio"].as_f64().unwrap_or(f64::NAN)),
        |a| {
            let newly = a["stiffness_newly_near_bound"].as_u64().unwrap_or(0);
            format!(
                ", structure {:.1} → {:.1}{}",
                a["structure_before"].as_f64().unwrap_or(f64::NAN),
                a["structure_after"].as_f64().unwrap_or(f64::NAN),
                if newly > 0 {
                    format!(", the stiffness taken to or near a bound at {newly} temperatures")
                } else {
                    String::new()
                }
            )
        },
    );
    s += "## Added effects\n\n";
    if o.final_fit.spec.effects.is_empty() {
        s += "None.\n";
    }
    let at_limit: Vec<&str> = j["added_effects"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|e| e["at_plausible_limit"] == true)
        .filter_map(|e| e["effect"].as_str())
        .collect();
    for &e in &o.final_fit.spec.effects {
        let limit = if at_limit.contains(&e.name()) {
            " (**at its plausible limit**: the data cannot show it larger; suspect a missing effect it stands in for)"
        } else {
            ""
        };
        s += &format!("- **{}**: {}{limit}\n", e.name(), fmt_params(&o.final_fit, e));
    }
    for form in j["equivalent_forms"].as_array().into_iter().flatten() {
        s += &format!("\n{}\n", form["note"].as_str().unwrap_or_default());
    }
    s += &identified_markdown(j);
    let resolved = baseline_bounds_resolved(j);
    if !resolved.is_empty() {
        s += &format!(
            "\nThe baseline's transmission stopped at a bound at {} °C (`identified_baseline`); the final model is \
             inside its bounds there and fits, so what the loop added filled no gap of the transmission.\n",
            resolved.join(", ")
        );
    }
    if let Some(t) = j.get("truth_comparison") {
        s += &truth_markdown(t);
    }
    s += &format!(
        "\n## Residual\n\n{}\n\nAgainst a flexible reference fitted to the same runs: {}.\n\nunexplained: **{}**{} ({})\n\n",
        remaining_structure(&o.final_signatures),
        j["reference"]["words"].as_str().unwrap_or("no reference computed"),
        o.unexplained,
        unexplained_by(&j["reference"]["unexplained_by"]),
        j["reference"]["rule"].as_str().unwrap_or("")
    );
    s += "Plots: `plots/identified.svg` (stiffness and damping per temperature), `plots/fit_*.svg` (measured vs model \
          before and after), `plots/residual_*.svg`, `plots/residual_spectrum.svg`.\n";
    s
}

/// Which branches of the `unexplained` rule held, in words (" by …"; empty where none did).
fn unexplained_by(by: &Value) -> String {
    let words: Vec<&str> = by
        .as_array()
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
        .map(|name| super::UNEXPLAINED_BRANCHES.iter().find(|(n, _)| *n == name).map_or(name, |(_, words)| words))
        .collect();
    if words.is_empty() {
        String::new()
    } else {
        format!(", as {}", words.join(" and "))
    }
}

/// The held-out fold's errors, "not measured" where the budget left the fold out (null).
fn held_out_markdown(h: &Value) -> String {
    let rad =
        |v: &Value| v.as_f64().filter(|x| x.is_finite()).map_or("not measured".into(), |x| format!("{x:.3e} rad"));
    let mut s = format!(
        "\n**Held-out error** ({}): baseline {} → final {}. An effect stays only if it lowers it.\n",
        h["method"].as_str().unwrap_or(""),
        rad(&h["baseline_rmse_rad"]),
        rad(&h["final_rmse_rad"])
    );
    for n in h["notes"].as_array().into_iter().flatten() {
        s += &format!("- {}\n", n.as_str().unwrap_or_default());
    }
    s
}

/// "± σ" for a standard error, "± unknown" where the fit has none (a model the budget left without
/// its covariance: `Fit::covariance_at`).
fn plus_minus(std: f64) -> String {
    if std.is_finite() {
        format!("± {std:.2e}")
    } else {
        "± unknown".into()
    }
}

/// The `identified` table (the paper's quantities) and the damping law's evidence.
fn identified_markdown(j: &Value) -> String {
    let mut s = String::from(
        "\n## Identified transmission (final fit; ± block-sandwich standard error)\n\n\
         | T (°C) | K (N·m/rad) | C (N·m·s/rad) | J (kg·m²) | f_n (Hz) | ζ | to ground (N·m·s/rad) |\n|---|---|---|---|---|---|---|\n",
    );
    let f = |g: &Value, k: &str| g[k].as_f64().unwrap_or(f64::NAN);
    for g in j["identified"].as_array().into_iter().flatten() {
        s += &format!(
            "| {} | {:.4} {} | {:.4e} {} | {:.4e}{} | {:.3} | {:.4} | {:.3e} |\n",
            g["temperature_c"],
            f(g, "stiffness"),
            plus_minus(f(g, "stiffness_std")),
            f(g, "damping"),
            plus_minus(f(g, "damping_std")),
            f(g, "inertia"),
            if g["inertia_declared"].as_bool() == Some(true) { "" } else { " (default, not declared)" },
            f(g, "natural_frequency_hz"),
            f(g, "damping_ratio"),
            f(g, "viscous_damping"),
        );
    }
    if let Some(law) = j["damping_law"].as_object() {
        s += &format!(
            "\nDamping law: **{}** ({}). Damping is given at {:.4} Hz.\n",
            law["chosen"].as_str().unwrap_or("?"),
            law["reason"].as_str().unwrap_or(""),
            j["identified"][0]["damping_reference_frequency_hz"].as_f64().unwrap_or(f64::NAN)
        );
    }
    if let Some(law) = j["backlash_law"].as_object() {
        let rows: Vec<String> = law["compared"]
            .as_array()
            .into_iter()
            .flatten()
            .map(|r| {
                format!(
                    "{} RMSE {:.4e} rad, BIC {:.1}",
                    r["law"].as_str().unwrap_or("?"),
                    f(r, "rmse_rad"),
                    f(r, "bic")
                )
            })
            .collect();
        s += &format!("\nBacklash law: **{}** ({}).\n", law["chosen"].as_str().unwrap_or("?"), rows.join("; "));
        if let Some(scan) = law.get("width_scan").and_then(Value::as_object) {
            let rad = |k: &str| scan.get(k).and_then(Value::as_f64).unwrap_or(f64::NAN);
            let factors = super::search::WIDTH_SCAN;
            s += &format!(
                "The final backlash width was scanned at {}–{} of itself and refitted from the best: \
                 {:.4e} → {:.4e} rad (the cost is rugged at a difference step's scale, docs/calibration.md).\n",
                factors[0],
                factors[factors.len() - 1],
                rad("from_rad"),
                rad("to_rad")
            );
        }
    }
    s
}

/// The paper's quantities against temperature (report.json `identified` and `identified_baseline`):
/// stiffness and damping on log axes, the final fit with ±2σ bars, the baseline beside it. A value
/// at its fit bound (`stiffness_range`, `damping_range`) is a limit, not an estimate: it is drawn
/// as a cross, and kept out of the axis's range (at the axis's edge where it would be off it), so
/// that a limp baseline at 1e-2 N·m/rad does not squash the estimates into a corner.
pub fn identified_plot(j: &Value) -> Result<String, Box<dyn std::error::Error>> {
    struct Point {
        t: f64,
        v: f64,
        std: f64,
        at_bound: bool,
    }
    let points = |key: &str, what: &str| -> Vec<Point> {
        j[key]
            .as_array()
            .into_iter()
            .flatten()
            .map(|g| {
                let f = |k: &str| g[k].as_f64().unwrap_or(f64::NAN);
                let v = f(what);
                // the fit's own rule (report.json's `at_bound`, for K or C alone)
                let range = &g[format!("{what}_range")];
                let at_bound = match (range[0].as_f64(), range[1].as_f64()) {
                    (Some(lo), Some(hi)) => super::fit::on_bound(v.ln(), lo, hi),
                    _ => false,
                };
                Point { t: f("temperature_c"), v, std: f(&format!("{what}_std")), at_bound }
            })
            .filter(|p| p.t.is_finite() && p.v > 0.0)
            .collect()
    };
    // the bar's lower end on a log axis: 2σ below, but never at or below zero
    let low = |p: &Point| (p.v - 2.0 * p.std).max(p.v / 10.0);
    let high = |p: &Point| p.v + 2.0 * p.std.max(0.0);
    let baseline_style = Style::points(RED_, Marker::Square).hollow();
    let final_style = Style::points(BLUE_, Marker::Circle);
    let bound_style = |color| Style::points(color, Marker::Cross);
    // (final, baseline) per panel, read once
    let quantities = [("stiffness", "K (N·m/rad)"), ("damping", "C (N·m·s/rad)")];
    let series: Vec<(Vec<Point>, Vec<Point>)> =
        quantities.iter().map(|(what, _)| (points("identified", what), points("identified_baseline", what))).collect();
    let any_bound = series.iter().any(|(fin, base)| fin.iter().chain(base).any(|p| p.at_bound));
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (1100, 480)).into_drawing_area();
        let mut legend = vec![
            ("final fit (± 2σ bars where wider than the marker)".to_string(), final_style),
            ("baseline".to_string(), baseline_style),
        ];
        if any_bound {
            legend.push((
                "at a fit bound: a limit, not an estimate (at the axis's edge if off it)".into(),
                bound_style(BLACK_),
            ));
        }
        let body = figure(&root, "Identified transmission per temperature", &legend)?;
        let panels = body.split_evenly((1, 2));
        for ((panel_area, (what, unit)), (fin, base)) in panels.iter().zip(quantities).zip(&series) {
            let all: Vec<&Point> = fin.iter().chain(base).collect();
            if all.is_empty() {
                continue;
            }
            let (t0, t1) = all.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| (a.min(p.t), b.max(p.t)));
            // the estimates set the range; bounds only where nothing else is left
            let estimates: Vec<&&Point> = all.iter().filter(|p| !p.at_bound).collect();
            let (v0, v1) = if estimates.is_empty() {
                log_range(all.iter().map(|p| p.v))
            } else {
                log_range(estimates.iter().flat_map(|p| [low(p), high(p)]))
            };
            let on_scale = |v: f64| v.clamp(v0 * 1.1, v1 / 1.1);
            let mut ch = panel(panel_area, what, "temperature (°C)", unit, (t0 - 5.0)..(t1 + 5.0), log_axis(v0, v1))?;
            // the baseline a little to the right, so a baseline on the final value stays visible
            let shifted = |ps: &[Point], bound: bool, dx: f64| -> Vec<(f64, f64)> {
                ps.iter().filter(|p| p.at_bound == bound).map(|p| (p.t + dx, on_scale(p.v))).collect()
            };
            draw(&mut ch, &shifted(base, false, 0.8), baseline_style)?;
            draw(&mut ch, &shifted(base, true, 0.8), bound_style(RED_))?;
            ch.draw_series(
                fin.iter()
                    .filter(|p| !p.at_bound)
                    .map(|p| ErrorBar::new_vertical(p.t, low(p), p.v, high(p), BLUE_.stroke_width(2), 10)),
            )?;
            draw(&mut ch, &shifted(fin, false, 0.0), final_style)?;
            draw(&mut ch, &shifted(fin, true, 0.0), bound_style(BLUE_))?;
        }
        root.present()?;
    }
    Ok(svg)
}

/// How the report draws the measured signal, the baseline model and the final one (also the drive
/// rig's plots): the measured trace wide and grey under the models, each model in its colour with
/// its marker.
pub(crate) const MEASURED: Style = Style::line(GREY_).width(4);
pub(crate) const BASELINE: Style = Style::line(RED_).width(1).marker(Marker::Triangle);
pub(crate) const FINAL: Style = Style::line(BLUE_).width(1).marker(Marker::Circle);

pub(crate) fn line_plot(
    title: &str,
    ylabel: &str,
    t: &[f64],
    series: &[(&str, &[f64], Style)],
) -> Result<String, Box<dyn std::error::Error>> {
    let series: Vec<Series> =
        series.iter().map(|(name, y, style)| Series::new(*name, thin(t, y, 4000).collect(), *style)).collect();
    chart_svg(&Axes::new(title, "time (s)", ylabel).size(1000, 460), &series)
}

pub fn plots(runs: &[Run], prob: &Problem, o: &Outcome) -> Result<crate::output::Files, Box<dyn std::error::Error>> {
    let mut files = Vec::new();
    let mut offset = 0;
    let freqs: Vec<f64> = (1..=400).map(|k| k as f64 * 0.025).collect();
    let mut spec_before = vec![0.0; freqs.len()];
    let mut spec_after = vec![0.0; freqs.len()];
    for (r, run) in runs.iter().enumerate() {
        let n = run.time.len();
        let e0: Vec<f64> = o.baseline.residual[offset..offset + n].to_vec();
        let e1: Vec<f64> = o.final_fit.residual[offset..offset + n].to_vec();
        offset += n;
        let stem = run.plot_stem();
        let svg = line_plot(
            &format!("{}: measured link angle and the model before/after", run.name()),
            "link angle (rad)",
            &run.time,
            &[
                ("measured", &prob.measured[r], MEASURED),
                ("baseline", &o.baseline.outputs[r], BASELINE.dash(Dash::Dashed)),
                ("final", &o.final_fit.outputs[r], FINAL),
            ],
        )?;
        files.push((format!("plots/fit_{stem}.svg"), svg.into_bytes()));
        let svg = line_plot(
            &format!("{}: residual before and after", run.name()),
            "measured − model (rad)",
            &run.time,
            &[("baseline", &e0, BASELINE), ("final", &e1, FINAL)],
        )?;
        files.push((format!("plots/residual_{stem}.svg"), svg.into_bytes()));
        for (acc, e) in [(&mut spec_before, &e0), (&mut spec_after, &e1)] {
            for (a, v) in acc.iter_mut().zip(amplitude_spectrum(&run.time, e, &freqs)) {
                *a += v / runs.len() as f64;
            }
        }
    }
    let spectrum = |y: &[f64]| freqs.iter().copied().zip(y.iter().copied()).collect::<Vec<_>>();
    let svg = chart_svg(
        &Axes::new("Residual amplitude spectrum, mean over runs", "frequency (Hz)", "amplitude (rad)")
            .log_y()
            .size(1000, 460),
        &[
            Series::new("baseline", spectrum(&spec_before), BASELINE),
            Series::new("final", spectrum(&spec_after), FINAL),
        ],
    )?;
    files.push(("plots/residual_spectrum.svg".into(), svg.into_bytes()));
    Ok(files)
}

/// Metrics of simulated held-out link angles against the measured ones (no BIC: nothing was fitted).
pub fn held_out_metrics(measured: &[Vec<f64>], outputs: &[Vec<f64>]) -> Value {
    let y: Vec<f64> = measured.iter().flatten().copied().collect();
    let e: Vec<f64> = measured.iter().zip(outputs).flat_map(|(a, b)| a.iter().zip(b).map(|(x, z)| x - z)).collect();
    let n = y.len() as f64;
    let mean = y.iter().sum::<f64>() / n;
    let spread = y.iter().map(|v| (v - mean).powi(2)).sum::<f64>().sqrt();
    let norm = y.iter().map(|v| v * v).sum::<f64>().sqrt();
    let err = e.iter().map(|v| v * v).sum::<f64>().sqrt();
    let rmse = err / n.sqrt();
    json!({
        "rmse_rad": rmse,
        "nrmse": rmse / (spread / n.sqrt()),
        "fit_percent": 100.0 * (1.0 - err / spread),
        "relerr_percent": 100.0 * err / norm,
        "samples": y.len(),
    })
}

/// The `truth.json` beside the runs (what `thermovia synth` and tests/truth/truth_model.py write):
/// one file shared by every input's folder, else None (inputs from several truths are not compared).
pub fn truth_file(inputs: &[std::path::PathBuf]) -> Option<std::path::PathBuf> {
    let mut candidates = inputs.iter().map(|p| {
        let dir = if p.is_dir() { p.as_path() } else { p.parent().unwrap_or(std::path::Path::new("")) };
        dir.join("truth.json")
    });
    let first = candidates.next()?;
    (first.is_file() && candidates.all(|c| c == first)).then_some(first)
}

/// The parameter whose zero means an effect is absent from a truth (`thermovia synth` writes every
/// effect, switched off at zero); None: any non-zero parameter counts.
fn magnitude_key(effect: &str) -> Option<&'static str> {
    match effect {
        "gravity" => Some("mgl_nm"),
        "asymmetric_friction" => None,
        _ => super::fit::Effect::from_name(effect).map(|e| e.params()[0].0),
    }
}

/// The value of `key` among the parameters of the added effect named `effect`, if found.
fn added_parameter(added: &[Value], effect: &str, key: &str) -> Option<f64> {
    added.iter().find(|e| e["effect"] == effect).and_then(|e| e["parameters"][key].as_f64())
}

/// Gravity hanging at an offset θ0, −A sin(θ − θ0) = −A cos θ0 sin θ + A sin θ0 cos θ, is over a
/// link's measured angles gravity of A cos θ0 hanging at 0 with a constant load of A sin θ0 times
/// the mean of cos θ there, less a torque A sin θ0 (cos θ − its mean) that a small range keeps
/// small: the form with the load has one parameter more for the same forces. Given (device
/// reports) where that torque, rms over the measured `links`, moves the link through the softest
/// fitted `stiffness` by no more than the noise `floor`: the runs cannot tell the two apart, so
/// the BIC keeps the offset, and a truth with a load and an upright link reads the same.
pub fn gravity_offset_form(added: &[Value], links: &[&[f64]], stiffness: f64, floor: f64) -> Option<Value> {
    let param = |name: &str, key: &str| added_parameter(added, name, key);
    let (mgl, offset) = (param("gravity", "mgl_nm")?, param("gravity", "offset_rad")?);
    let (upright, sideways) = (mgl * offset.cos(), mgl * offset.sin());
    let n = links.iter().map(|l| l.len()).sum::<usize>();
    if !(upright > 0.0 && sideways != 0.0 && n > 0 && stiffness > 0.0) {
        return None;
    }
    let cosines = || links.iter().flat_map(|l| l.iter().map(|t| t.cos()));
    let mean = cosines().sum::<f64>() / n as f64;
    let spread = (cosines().map(|c| (c - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    let (torque, moved) = (sideways.abs() * spread, sideways.abs() * spread / stiffness);
    if !(moved <= floor) {
        return None;
    }
    let load_now = param("constant_load", "torque_nm");
    let load = sideways * mean + load_now.unwrap_or(0.0);
    let (lo, hi) =
        links.iter().flat_map(|l| l.iter()).fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| (a.min(t), b.max(t)));
    let mut found = json!({"gravity": {"mgl_nm": mgl, "offset_rad": offset}});
    if let Some(l) = load_now {
        found["constant_load"] = json!({"torque_nm": l});
    }
    // with a load found beside it, the offset is the parameter too many
    let kept = if load_now.is_some() {
        "the search kept both the offset and a load, which over this range act as one"
    } else {
        "the search kept the form with the offset (one parameter fewer)"
    };
    let note = format!(
        "Equivalent form: gravity of {} N.m hanging at {} rad is, over the link's measured angles ({} to {} rad), gravity \
         of {} N.m hanging at 0 with a constant load of {} N.m on the link: the two differ by {} N.m rms, which moves the \
         link by about {} rad against a noise floor of {} rad. The runs cannot tell the two apart; {kept}.",
        short(mgl),
        short(offset),
        short(lo),
        short(hi),
        short(upright),
        short(load),
        short(torque),
        short(moved),
        short(floor),
    );
    Some(json!({
        "found": found,
        "equivalent": {"gravity": {"mgl_nm": upright, "offset_rad": 0.0}, "constant_load": {"torque_nm": load}},
        "note": note,
    }))
}

/// The forms that go on from `gravity_form` (`gravity_offset_form`) through the load it names: read
/// as gravity hanging at 0 with that load, the found set has the load's own forms
/// (`equivalent_forms`: a load beside friction is, while the link moves, asymmetric friction), and
/// each of them is a form of the found set too, with gravity at 0. Campaign rig 287 (asymmetric
/// friction, 0.0765 N·m forward and 0.0720 back, with gravity) was found as Coulomb friction and
/// link damping with gravity 1.7 mrad off 0, whose load of −0.0020 N·m makes it asymmetric friction
/// of 0.0764 and 0.0724 with viscous levels of 0.0406 (truth 0.0408 and 0.0410).
fn through_the_load(added: &[Value], gravity_form: &Value) -> Vec<Value> {
    let upright = &gravity_form["equivalent"]["gravity"];
    let load = &gravity_form["equivalent"]["constant_load"];
    let mut read: Vec<Value> =
        added.iter().filter(|e| e["effect"] != "gravity" && e["effect"] != "constant_load").cloned().collect();
    read.push(json!({"effect": "gravity", "parameters": upright}));
    read.push(json!({"effect": "constant_load", "parameters": load}));
    let Value::Array(forms) = equivalent_forms(&read) else { return Vec::new() };
    forms
        .into_iter()
        .map(|f| {
            let mut found = gravity_form["found"].clone();
            let mut equivalent = json!({"gravity": upright});
            // (the load is the gravity form's, already in its `found` where the search kept one)
            for (name, value) in f["found"].as_object().into_iter().flatten() {
                if name != "constant_load" {
                    found[name] = value.clone();
                }
            }
            for (name, value) in f["equivalent"].as_object().into_iter().flatten() {
                equivalent[name] = value.clone();
            }
            // (which form the search kept is the gravity form's to say)
            let then = f["note"].as_str().unwrap_or_default().trim_start_matches("Equivalent form: ");
            let then = then.split("; the search kept").next().unwrap_or(then);
            let note =
                format!("{} Read so, its load goes on: {then}.", gravity_form["note"].as_str().unwrap_or_default());
            json!({"found": found, "equivalent": equivalent, "note": note})
        })
        .collect()
}

/// Effect sets the data cannot tell apart, for `added_effects` (interfaces.md `equivalent_forms`).
/// Asymmetric Coulomb friction, levels F+ forward and F− backward, takes −F+ from a link moving
/// forward and +F− from one moving back: that is symmetric friction (F+ + F−)/2 plus a constant load
/// (F− − F+)/2, to the bit while the link moves; only at rest (stiction) could the two differ. Both
/// forms are physical (the levels are never negative: friction that pushes is refused as a load), so
/// the report gives both and names the one the search kept; the viscous asymmetry, if any, has no
/// second form.
pub fn equivalent_forms(added: &[Value]) -> Value {
    let param = |e: &Value, name: &str| e["parameters"][name].as_f64();
    let mut forms = Vec::new();
    for e in added.iter().filter(|e| e["effect"] == "asymmetric_friction") {
        let (Some(fp), Some(fm)) = (param(e, "coulomb_positive"), param(e, "coulomb_negative")) else { continue };
        let load_now = added_parameter(added, "constant_load", "torque_nm");
        let (coulomb, load) = ((fp + fm) / 2.0, (fm - fp) / 2.0 + load_now.unwrap_or(0.0));
        let viscous = match (param(e, "viscous_positive"), param(e, "viscous_negative")) {
            (Some(bp), Some(bn)) if bp != bn => format!(
                "; the viscous levels ({} forward, {} back, N.m.s/rad) stay direction-dependent",
                short(bp),
                short(bn)
            ),
            _ => String::new(),
        };
        let note = format!(
            "Equivalent form: asymmetric Coulomb friction ({} N.m forward, {} N.m back) is, while the link moves, \
             symmetric Coulomb friction of {} N.m with a constant load of {} N.m on the link{}. The runs cannot tell \
             the two apart except at rest; the search kept the asymmetric form.",
            short(fp),
            short(fm),
            short(coulomb),
            short(load),
            viscous
        );
        forms.push(json!({
            "found": {"asymmetric_friction": {"coulomb_positive": fp, "coulomb_negative": fm}},
            "equivalent": {"coulomb_friction": {"torque_nm": coulomb}, "constant_load": {"torque_nm": load}},
            "note": note,
        }));
    }
    // The same pair read the other way: friction F+ forward and F− back (symmetric: both Fc) with a
    // load L is, without the load, asymmetric friction of F+ − L forward and F− + L back; where either
    // would be < 0 there is no such form (friction that pushes). Its viscous levels are the
    // asymmetric friction's, else both the link damping's.
    let find = |name: &str, key: &str| added_parameter(added, name, key);
    let asymmetric = added.iter().find(|e| e["effect"] == "asymmetric_friction");
    let levels = match asymmetric {
        Some(e) => param(e, "coulomb_positive").zip(param(e, "coulomb_negative")),
        None => find("coulomb_friction", "torque_nm").map(|fc| (fc, fc)),
    };
    let load = find("constant_load", "torque_nm").filter(|l| *l != 0.0);
    if let (Some((fp, fm)), Some(load)) = (levels, load) {
        if fp - load >= 0.0 && fm + load >= 0.0 {
            let damping = find("link_damping", "damping_nms");
            let (bp, bn) = match asymmetric {
                Some(e) => (param(e, "viscous_positive").unwrap_or(0.0), param(e, "viscous_negative").unwrap_or(0.0)),
                None => (damping.unwrap_or(0.0), damping.unwrap_or(0.0)),
            };
            let (fp2, fm2) = (fp - load, fm + load);
            let mut found = json!({"constant_load": {"torque_nm": load}});
            let friction = match asymmetric {
                Some(e) => {
                    found["asymmetric_friction"] = e["parameters"].clone();
                    format!("asymmetric Coulomb friction of {} N.m forward and {} N.m back", short(fp), short(fm))
                }
                None => {
                    found["coulomb_friction"] = json!({"torque_nm": fp});
                    if let Some(b) = damping {
                        found["link_damping"] = json!({"damping_nms": b});
                    }
                    format!("symmetric Coulomb friction of {} N.m", short(fp))
                }
            };
            let viscous = match (asymmetric, damping) {
                (None, Some(b)) => format!(", its viscous levels both the link damping's {} N.m.s/rad", short(b)),
                _ => String::new(),
            };
            let note = format!(
                "Equivalent form: {friction} with a constant load of {} N.m on the link is, while the link moves, \
                 asymmetric Coulomb friction of {} N.m forward and {} N.m back with no load{viscous}. The runs \
                 cannot tell the two apart except at rest; the search kept the form with the load.",
                short(load),
                short(fp2),
                short(fm2),
            );
            forms.push(json!({
                "found": found,
                "equivalent": {"asymmetric_friction": {"coulomb_positive": fp2, "coulomb_negative": fm2,
                    "viscous_positive": bp, "viscous_negative": bn}},
                "note": note,
            }));
        }
    }
    Value::Array(forms)
}

/// The load form's limit at no load (interfaces.md `equivalent_forms`): symmetric friction Fc with
/// link damping b (0 without) and no load is asymmetric friction with Fc both ways and b both ways,
/// the same torque at every speed. Without it a load of 0.002 N·m beside the pair gave the
/// asymmetric form (campaign rig 287, through `through_the_load`) and no load gave none (fresh rig
/// 910, whose truth's Coulomb levels differ by 0.5 %). Listed after every other form: where a found
/// set has several readings, the more specific come first.
pub fn equal_levels_form(added: &[Value]) -> Option<Value> {
    let find = |name: &str, key: &str| added_parameter(added, name, key);
    let asymmetric = added.iter().any(|e| e["effect"] == "asymmetric_friction");
    let load = find("constant_load", "torque_nm").filter(|l| *l != 0.0);
    if let (false, None, Some(fc)) = (asymmetric, load, find("coulomb_friction", "torque_nm")) {
        let damping = find("link_damping", "damping_nms");
        let b = damping.unwrap_or(0.0);
        let mut found = json!({"coulomb_friction": {"torque_nm": fc}});
        if let Some(b) = damping {
            found["link_damping"] = json!({"damping_nms": b});
        }
        let pair = match damping {
            Some(b) => {
                format!("symmetric Coulomb friction of {} N.m with link damping of {} N.m.s/rad", short(fc), short(b))
            }
            None => format!("symmetric Coulomb friction of {} N.m", short(fc)),
        };
        let note = format!(
            "Equivalent form: {pair} is asymmetric friction with equal levels, {} N.m forward and back and viscous \
             levels of {} N.m.s/rad both ways. The search found no direction dependence worth the asymmetry's \
             parameters, so it kept the symmetric form.",
            short(fc),
            short(b),
        );
        return Some(json!({
            "found": found,
            "equivalent": {"asymmetric_friction": {"coulomb_positive": fc, "coulomb_negative": fc,
                "viscous_positive": b, "viscous_negative": b}},
            "note": note,
        }));
    }
    None
}

/// `truth_comparison` of report.json: the truth's effects and transmission against what the device
/// loop identified (`report` holds `added_effects` and `identified`). Two truths are read:
/// `thermovia synth`'s (effects at the top level, the moduli as factors on the FMU's table) and
/// tests/truth/truth_model.py's (`effects`, and `runs` with each run's stiffness and damping).
/// None when `truth` is neither.
pub fn truth_comparison(file: &std::path::Path, truth: &Value, report: &Value) -> Option<Value> {
    let library: Vec<&str> = super::fit::Effect::ALL.iter().map(|e| e.name()).collect();
    let effects: Vec<(&String, &Value)> = match truth["effects"].as_object() {
        Some(e) => e.iter().collect(),
        None => truth.as_object()?.iter().filter(|(k, v)| library.contains(&k.as_str()) && v.is_object()).collect(),
    };
    let present = |name: &str, params: &Value| match magnitude_key(name) {
        Some(k) => params[k].as_f64().is_some_and(|v| v != 0.0),
        None => params.as_object().into_iter().flatten().any(|(_, v)| v.as_f64().is_some_and(|v| v != 0.0)),
    };
    let added = report["added_effects"].as_array().cloned().unwrap_or_default();
    let identified = |effect: &str| added.iter().find(|e| e["effect"] == effect).map(|e| &e["parameters"]);
    let relative = |t: f64, i: Option<f64>| i.filter(|_| t != 0.0).map(|i| i / t - 1.0);
    let mut rows = Vec::new();
    for (name, params) in effects.iter().filter(|(n, p)| present(n, p)) {
        let found = identified(name);
        for (p, t) in params.as_object().into_iter().flatten().filter_map(|(p, v)| v.as_f64().map(|t| (p, t))) {
            let i = found.and_then(|f| f[p.as_str()].as_f64());
            rows.push(json!({"effect": name, "parameter": p, "true": t, "identified": i,
                "relative_error": relative(t, i), "absolute_error": i.map(|i| i - t),
                "status": if found.is_some() { "found" } else if library.contains(&name.as_str()) { "missed" } else { "outside the library" }}));
        }
    }
    for e in &added {
        let name = e["effect"].as_str().unwrap_or("?");
        if effects.iter().any(|(n, p)| n.as_str() == name && present(n, p)) {
            continue;
        }
        for (p, i) in e["parameters"].as_object().into_iter().flatten() {
            rows.push(json!({"effect": name, "parameter": p, "true": 0.0, "identified": i,
                "relative_error": null, "absolute_error": i, "status": "extra"}));
        }
    }
    // the transmission per temperature: the truth's own numbers, or its factors on the FMU's table
    // (synth scales the PCL's E' and E'' only; the springs stay at the table's)
    let table_truth = |g: &Value| -> Option<(f64, f64)> {
        let (se, sl) = (truth["storage_modulus_scale"].as_f64()?, truth["loss_modulus_scale"].as_f64()?);
        let (k, c, springs) = (
            g["table_stiffness"].as_f64()?,
            g["table_damping"].as_f64()?,
            g["nominal_spring_bank_stiffness"].as_f64()?,
        );
        Some((springs + se * (k - springs), sl * c))
    };
    let run_truth = |temperature: f64| -> Option<(f64, f64)> {
        let r = truth["runs"].as_array()?.iter().min_by(|a, b| {
            let d = |r: &Value| (r["temperature_c"].as_f64().unwrap_or(f64::INFINITY) - temperature).abs();
            d(a).total_cmp(&d(b))
        })?;
        // runs are grouped to the nearest 0.5 °C
        ((r["temperature_c"].as_f64()? - temperature).abs() <= 0.5)
            .then_some((r["stiffness"].as_f64()?, r["damping"].as_f64()?))
    };
    let from_runs = truth["runs"].is_array();
    let mut transmission = Vec::new();
    for g in report["identified"].as_array().into_iter().flatten() {
        let temperature = g["temperature_c"].as_f64().unwrap_or(f64::NAN);
        let Some((k, c)) = (if from_runs { run_truth(temperature) } else { table_truth(g) }) else { continue };
        let (ki, ci) = (g["stiffness"].as_f64(), g["damping"].as_f64());
        transmission.push(json!({"temperature_c": temperature,
            "stiffness_true": k, "stiffness_identified": ki, "stiffness_relative_error": relative(k, ki),
            "damping_true": c, "damping_identified": ci, "damping_relative_error": relative(c, ci)}));
    }
    if effects.is_empty() && transmission.is_empty() {
        return None;
    }
    let mut notes = vec![if from_runs {
        "the transmission's truth: each run's stiffness and damping in truth.json".to_string()
    } else {
        "the transmission's truth: truth.json's storage and loss modulus scales on the FMU's table, K = springs + \
         scale × (table K − springs), C = scale × table C at the damping reference frequency"
            .to_string()
    }];
    if report["identified"].as_array().into_iter().flatten().any(|g| g["inertia_declared"] == false) {
        notes.push(
            "the link inertia is not declared in every run: the identified K and C are relative to the FMU's default"
                .into(),
        );
    }
    Some(json!({"file": file.display().to_string(), "parameters": rows, "transmission": transmission, "notes": notes}))
}

/// report.md's section for `truth_comparison`.
fn truth_markdown(t: &Value) -> String {
    let num = |v: &Value| v.as_f64().map_or("—".to_string(), short);
    // two decimals of a percent, and an exponent below them (a fit to the noise is often closer)
    let rel = |v: &Value| {
        v.as_f64().map_or("—".to_string(), |e| match 100.0 * e {
            0.0 => "0 %".to_string(),
            p if p.abs() >= 0.01 => format!("{p:+.2} %"),
            p => format!("{p:+.1e} %"),
        })
    };
    let mut s = format!("\n## Against the truth ({})\n\n", t["file"].as_str().unwrap_or("truth.json"));
    let rows = t["parameters"].as_array().cloned().unwrap_or_default();
    if rows.is_empty() {
        s += "The truth has no effect, and none was added.\n";
    } else {
        s += "| effect | parameter | true | identified | relative error |\n|---|---|---|---|---|\n";
        for r in &rows {
            let identified = match r["status"].as_str() {
                Some("found") | Some("extra") => num(&r["identified"]),
                other => format!("{} ({})", num(&r["identified"]), other.unwrap_or("?")),
            };
            let extra = if r["status"] == "extra" { " (not in the truth)" } else { "" };
            s += &format!(
                "| {}{extra} | {} | {} | {identified} | {} |\n",
                r["effect"].as_str().unwrap_or("?"),
                r["parameter"].as_str().unwrap_or("?"),
                num(&r["true"]),
                rel(&r["relative_error"])
            );
        }
    }
    if let Some(tr) = t["transmission"].as_array().filter(|a| !a.is_empty()) {
        s += "\n| T (°C) | K true | K identified | error | C true | C identified | error |\n|---|---|---|---|---|---|---|\n";
        for g in tr {
            s += &format!(
                "| {} | {} | {} | {} | {} | {} | {} |\n",
                g["temperature_c"],
                num(&g["stiffness_true"]),
                num(&g["stiffness_identified"]),
                rel(&g["stiffness_relative_error"]),
                num(&g["damping_true"]),
                num(&g["damping_identified"]),
                rel(&g["damping_relative_error"])
            );
        }
    }
    for n in t["notes"].as_array().into_iter().flatten().filter_map(Value::as_str) {
        let mut c = n.chars();
        s += &format!("\n{}{}.\n", c.next().map(|f| f.to_uppercase().to_string()).unwrap_or_default(), c.as_str());
    }
    s
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_fit_only_evaluated_reports_unknown_errors_not_a_panic() {
        // fresh campaign rig 501: the budget ran out before the final model's refit, so it had no
        // covariance, and reading one panicked while the report was written
        use super::super::fit::{DampingLaw, Effect, Fit, ModelSpec, SpringBank};
        use nalgebra::DMatrix;
        let effects = vec![Effect::CoulombFriction, Effect::Gravity, Effect::AsymmetricFriction];
        let fit = |covariance: DMatrix<f64>| Fit {
            spec: ModelSpec {
                effects: effects.clone(),
                law: DampingLaw::Viscous,
                springs: SpringBank::Scaled,
                elasto_backlash: false,
            },
            p: vec![3.5, -1.0, 0.4, 0.2, -0.1, 0.05, 0.01],
            outputs: vec![],
            residual: vec![],
            sse: 1e-4,
            n: 100,
            jacobian: DMatrix::zeros(0, 0),
            covariance,
            iterations: 0,
        };
        let evaluated = fit(DMatrix::zeros(0, 0));
        assert!(evaluated.std_err(0).is_nan());
        for e in &effects {
            for (name, value, error) in super::effect_parameters(&evaluated, *e) {
                assert!(value.is_finite() && error.is_nan(), "{e:?} {name}: {value} ± {error}");
            }
            // report.md says so in words, not "± NaN"
            let text = super::fmt_params(&evaluated, *e);
            assert!(text.contains("± unknown") && !text.contains("NaN"), "{text}");
        }
        // with a covariance the errors are read from it
        let fitted = fit(DMatrix::from_diagonal_element(7, 7, 4e-6));
        assert_eq!(fitted.std_err(2), 2e-3);
        for e in &effects {
            for (name, _, error) in super::effect_parameters(&fitted, *e) {
                assert!(error.is_finite() && error > 0.0, "{e:?} {name}: ± {error}");
            }
        }
    }

    #[test]
    fn a_value_at_its_fit_bound_is_marked_and_does_not_set_the_axis() {
        let entry = |t: f64, k: f64| {
            json!({"temperature_c": t, "stiffness": k, "stiffness_std": 1.0, "damping": 5.0, "damping_std": 0.1,
                "stiffness_range": [1e-2, 1e5], "damping_range": [1e-7, 1e3]})
        };
        let labels = |svg: &str| -> Vec<String> {
            svg.split("<text")
                .skip(1)
                .filter_map(|t| Some(t.split_once('>')?.1.split('<').next()?.trim().to_string()))
                .collect()
        };
        let numbers = |svg: &str| labels(svg).iter().filter_map(|l| l.parse::<f64>().ok()).collect::<Vec<_>>();
        let legend = "at a fit bound";
        // a limp baseline at the stiffness's lower bound (CI rig 13's at 40 and 50 °C)
        let j = json!({"identified": [entry(22.0, 120.0), entry(40.0, 75.0), entry(60.0, 20.0)],
            "identified_baseline": [entry(22.0, 85.0), entry(40.0, 1e-2), entry(60.0, 15.0)]});
        let svg = super::identified_plot(&j).unwrap();
        assert!(labels(&svg).iter().any(|l| l.starts_with(legend)), "{:?}", labels(&svg));
        // the estimates (15–120 N·m/rad, C 5) set the axes: no tick down at the bound's decade
        assert!(numbers(&svg).iter().all(|&v| v >= 1.0), "{:?}", numbers(&svg));
        // the same baseline off its bound is an estimate: it sets the axis, and nothing is marked
        let j = json!({"identified": [entry(22.0, 120.0)], "identified_baseline": [entry(22.0, 2e-2)]});
        let svg = super::identified_plot(&j).unwrap();
        assert!(!labels(&svg).iter().any(|l| l.starts_with(legend)));
        assert!(numbers(&svg).iter().any(|&v| v < 0.1), "{:?}", numbers(&svg));
    }

    #[test]
    fn a_fold_the_budget_left_out_reads_not_measured() {
        let md = super::held_out_markdown(&json!({"method": "a blocked fold", "baseline_rmse_rad": null,
            "final_rmse_rad": null, "notes": ["the held-out fold was left out"]}));
        assert!(md.contains("baseline not measured → final not measured") && !md.contains("NaN"), "{md}");
        let md = super::held_out_markdown(&json!({"method": "a blocked fold", "baseline_rmse_rad": 2e-3,
            "final_rmse_rad": 1e-3}));
        assert!(md.contains("baseline 2.000e-3 rad → final 1.000e-3 rad"), "{md}");
    }

    #[test]
    fn a_scanned_backlash_width_is_named_in_the_report() {
        let law = |scan: Value| json!({"backlash_law": {"chosen": "clipped", "compared": [], "rule": "", "width_scan": scan}});
        let md = super::identified_markdown(&law(json!({"from_rad": 8.028e-4, "to_rad": 8.918e-4})));
        assert!(md.contains("8.0280e-4 → 8.9180e-4 rad"), "{md}");
        assert!(!super::identified_markdown(&law(Value::Null)).contains("scanned"));
    }

    #[test]
    fn asymmetric_coulomb_friction_is_reported_with_its_load_form() {
        let added = vec![
            json!({"effect": "asymmetric_friction", "parameters": {"coulomb_positive": 0.05, "coulomb_negative": 0.03,
                   "viscous_positive": 0.0, "viscous_negative": 0.0}}),
            json!({"effect": "constant_load", "parameters": {"torque_nm": 0.002}}),
        ];
        let forms = equivalent_forms(&added);
        let f = &forms[0];
        // −F+ = −c + L and F− = c + L: c = 0.04, L = −0.01 (+ the load already there)
        assert!((f["equivalent"]["coulomb_friction"]["torque_nm"].as_f64().unwrap() - 0.04).abs() < 1e-15);
        assert!((f["equivalent"]["constant_load"]["torque_nm"].as_f64().unwrap() + 0.008).abs() < 1e-15);
        assert!(f["note"].as_str().unwrap().contains("constant load of -0.008"), "{}", f["note"]);
        // and without the load: −(F+ − L) forward and F− + L back, the same forces while it moves
        let folded = &forms[1]["equivalent"]["asymmetric_friction"];
        assert!((folded["coulomb_positive"].as_f64().unwrap() - 0.048).abs() < 1e-15, "{folded}");
        assert!((folded["coulomb_negative"].as_f64().unwrap() - 0.032).abs() < 1e-15, "{folded}");
        assert_eq!(forms[1]["found"]["constant_load"]["torque_nm"], 0.002);
        assert_eq!(forms.as_array().unwrap().len(), 2);
        assert_eq!(equivalent_forms(&added[1..]).as_array().unwrap().len(), 0);
    }

    #[test]
    fn gravity_at_an_offset_is_reported_with_its_load_form_where_the_noise_hides_the_difference() {
        let added = vec![
            json!({"effect": "gravity", "parameters": {"mgl_nm": 1.0, "offset_rad": 0.2}}),
            json!({"effect": "constant_load", "parameters": {"torque_nm": 0.01}}),
        ];
        let link: Vec<f64> = (0..=100).map(|k| -0.05 + 0.001 * k as f64).collect();
        let form = gravity_offset_form(&added, &[&link], 10.0, 1e-5).expect("a small range hides the difference");
        let (mgl, load) = (
            form["equivalent"]["gravity"]["mgl_nm"].as_f64().unwrap(),
            form["equivalent"]["constant_load"]["torque_nm"].as_f64().unwrap(),
        );
        assert_eq!(form["equivalent"]["gravity"]["offset_rad"], 0.0);
        assert_eq!(form["found"]["constant_load"]["torque_nm"], 0.01);
        // the same torque on the link, −A sin(θ − θ0) + L0 against −A' sin θ + L, to the cos θ term's spread
        for &t in &link {
            let (found, equivalent) = (-(t - 0.2f64).sin() + 0.01, -mgl * t.sin() + load);
            assert!((found - equivalent).abs() < 0.2f64.sin() * 1.3e-3, "at {t}: {found} against {equivalent}");
        }
        assert!(form["note"].as_str().unwrap().contains("hanging at 0.2 rad"), "{}", form["note"]);
        assert!(form["note"].as_str().unwrap().contains("act as one"), "{}", form["note"]);
        let alone = gravity_offset_form(&added[..1], &[&link], 10.0, 1e-5).unwrap();
        assert!(alone["note"].as_str().unwrap().contains("one parameter fewer"), "{}", alone["note"]);
        // a floor under what the difference moves the link by, a link hanging at 0, or one upside down: no form
        assert!(gravity_offset_form(&added, &[&link], 10.0, 1e-6).is_none());
        let hanging =
            |offset: f64| vec![json!({"effect": "gravity", "parameters": {"mgl_nm": 1.0, "offset_rad": offset}})];
        assert!(gravity_offset_form(&hanging(0.0), &[&link], 10.0, 1e-5).is_none());
        assert!(gravity_offset_form(&hanging(3.0), &[&link], 10.0, 1e-5).is_none());
    }

    #[test]
    fn gravity_off_zero_beside_friction_is_reported_as_gravity_at_zero_with_asymmetric_friction() {
        let added = vec![
            json!({"effect": "link_damping", "parameters": {"damping_nms": 0.04}}),
            json!({"effect": "coulomb_friction", "parameters": {"torque_nm": 0.074}}),
            json!({"effect": "gravity", "parameters": {"mgl_nm": 1.15, "offset_rad": -0.0017}}),
        ];
        let link: Vec<f64> = (0..=100).map(|k| -0.136 + 0.00272 * k as f64).collect();
        let form = gravity_offset_form(&added, &[&link], 60.0, 2.7e-4).expect("the noise hides the difference");
        let load = form["equivalent"]["constant_load"]["torque_nm"].as_f64().unwrap();
        assert!(load < 0.0, "{form}");
        let chained = through_the_load(&added, &form);
        assert_eq!(chained.len(), 1, "{chained:?}");
        let c = &chained[0];
        let names = |v: &Value| v.as_object().unwrap().keys().cloned().collect::<Vec<_>>();
        assert_eq!(names(&c["found"]), ["coulomb_friction", "gravity", "link_damping"]);
        assert_eq!(names(&c["equivalent"]), ["asymmetric_friction", "gravity"]);
        assert_eq!(c["equivalent"]["gravity"]["offset_rad"], 0.0);
        let a = &c["equivalent"]["asymmetric_friction"];
        // the load's own form: F+ = c − L forward, F− = c + L back, both viscous levels the damping's
        assert!((a["coulomb_positive"].as_f64().unwrap() - (0.074 - load)).abs() < 1e-15, "{a}");
        assert!((a["coulomb_negative"].as_f64().unwrap() - (0.074 + load)).abs() < 1e-15, "{a}");
        assert_eq!((a["viscous_positive"].as_f64(), a["viscous_negative"].as_f64()), (Some(0.04), Some(0.04)));
        let note = c["note"].as_str().unwrap();
        assert!(note.contains("one parameter fewer") && note.contains("asymmetric Coulomb friction"), "{note}");
        assert!(!note.contains("kept the form with the load"), "{note}");
        // gravity alone: its load has no form of its own to go on to
        assert!(through_the_load(&added[2..], &gravity_offset_form(&added[2..], &[&link], 60.0, 2.7e-4).unwrap())
            .is_empty());
    }

    #[test]
    fn symmetric_friction_with_a_load_is_reported_with_its_asymmetric_form() {
        let with = |load: f64, damping: Option<f64>| {
            let mut added = vec![
                json!({"effect": "coulomb_friction", "parameters": {"torque_nm": 0.04}}),
                json!({"effect": "constant_load", "parameters": {"torque_nm": load}}),
            ];
            added.extend(damping.map(|b| json!({"effect": "link_damping", "parameters": {"damping_nms": b}})));
            equivalent_forms(&added)
        };
        let forms = with(-0.01, Some(0.002));
        let a = &forms[0]["equivalent"]["asymmetric_friction"];
        // the inverse of the asymmetric form's map: F+ = c − L, F− = c + L
        assert!((a["coulomb_positive"].as_f64().unwrap() - 0.05).abs() < 1e-15, "{a}");
        assert!((a["coulomb_negative"].as_f64().unwrap() - 0.03).abs() < 1e-15, "{a}");
        assert_eq!(a["viscous_positive"], 0.002);
        assert_eq!(forms[0]["found"]["link_damping"]["damping_nms"], 0.002);
        assert_eq!(with(0.01, None)[0]["equivalent"]["asymmetric_friction"]["viscous_negative"], 0.0);
        // a load larger than the friction has no friction form: it would push
        assert_eq!(with(0.05, None).as_array().unwrap().len(), 0);
    }

    #[test]
    fn symmetric_friction_without_a_load_is_reported_as_asymmetric_friction_with_equal_levels() {
        let coulomb = json!({"effect": "coulomb_friction", "parameters": {"torque_nm": 0.0425}});
        let damping = json!({"effect": "link_damping", "parameters": {"damping_nms": 0.006}});
        let forms = Value::Array(equal_levels_form(&[coulomb.clone(), damping]).into_iter().collect());
        assert_eq!(forms.as_array().unwrap().len(), 1, "{forms}");
        let a = &forms[0]["equivalent"]["asymmetric_friction"];
        assert_eq!((a["coulomb_positive"].as_f64(), a["coulomb_negative"].as_f64()), (Some(0.0425), Some(0.0425)));
        assert_eq!((a["viscous_positive"].as_f64(), a["viscous_negative"].as_f64()), (Some(0.006), Some(0.006)));
        assert_eq!(forms[0]["found"]["link_damping"]["damping_nms"], 0.006);
        assert!(forms[0]["note"].as_str().unwrap().contains("equal levels"), "{}", forms[0]["note"]);
        // Coulomb friction alone: no viscous levels; the load's limit at 0, so the same form as with one
        let alone = equal_levels_form(std::slice::from_ref(&coulomb)).unwrap();
        assert_eq!(alone["equivalent"]["asymmetric_friction"]["viscous_negative"], 0.0);
        assert_eq!(alone["found"].as_object().unwrap().len(), 1);
        // with a load the load's form speaks instead, and asymmetric friction found needs no second reading
        let loaded = [coulomb, json!({"effect": "constant_load", "parameters": {"torque_nm": 0.002}})];
        assert!(equal_levels_form(&loaded).is_none());
        assert!(equivalent_forms(&loaded)[0]["found"]["constant_load"].is_object());
        let asymmetric = json!({"effect": "asymmetric_friction", "parameters": {"coulomb_positive": 0.05,
            "coulomb_negative": 0.03, "viscous_positive": 0.0, "viscous_negative": 0.0}});
        assert!(equal_levels_form(&[asymmetric]).is_none());
    }

    use super::*;

    /// A temperature whose inertial deflection is under one count of an undithered link encoder is
    /// warned of; one over it, or a dithered count (null), is not.
    #[test]
    fn a_deflection_under_one_undithered_count_is_warned_of() {
        let warned = |deflection: f64, count: Value| {
            let mut r = report(false, false, true);
            r["identified"][0]["inertial_deflection_rad"] = json!(deflection);
            r["identified"][0]["undithered_link_count_rad"] = count;
            device_warnings(&[], &r).into_iter().filter(|w| w.contains("one count")).count()
        };
        assert_eq!(warned(3.9e-4, json!(4.8e-3)), 1);
        assert_eq!(warned(5.0e-3, json!(4.8e-3)), 0);
        assert_eq!(warned(3.9e-4, Value::Null), 0);
    }

    /// A device report's parts that the warnings and the truth comparison read.
    fn report(baseline_at_bound: bool, final_at_bound: bool, white: bool) -> Value {
        let entry = |at_bound: bool, k: f64, c: f64| {
            json!({"temperature_c": 40.0, "at_bound": at_bound, "stiffness": k, "damping": c, "inertia_declared": true,
                "stiffness_range": [1e-2, 1.78e5], "damping_range": [1e-7, 226.0], "table_stiffness": 12.0,
                "table_damping": 0.4, "nominal_spring_bank_stiffness": 2.0})
        };
        json!({
            "identified_baseline": [entry(baseline_at_bound, 1.78e5, 1e-7)],
            "identified": [entry(final_at_bound, 10.1, 0.49)],
            "added_effects": [{"effect": "gravity", "parameters": {"mgl_nm": 1.2, "offset_rad": 0.1}},
                              {"effect": "link_damping", "parameters": {"damping_nms": 0.001}}],
            "unexplained": !white,
            "residual_white": white,
        })
    }

    fn bound_warnings(r: &Value) -> Vec<String> {
        device_warnings(&[], r).into_iter().filter(|w| w.contains("stopped at a bound")).collect()
    }

    /// Issue 30: a baseline at a bound is warned about only when it matters, when the final model
    /// still sits at a bound or does not fit; otherwise report.md says it was resolved.
    #[test]
    fn a_baseline_at_a_bound_is_a_warning_only_when_the_final_fit_does_not_resolve_it() {
        assert!(bound_warnings(&report(true, false, true)).is_empty());
        let md_note = baseline_bounds_resolved(&report(true, false, true));
        assert_eq!(md_note, ["40.0"]);
        let w = bound_warnings(&report(true, true, true));
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(w[0].starts_with("baseline fit at 40 °C") && w[1].starts_with("final fit at 40 °C"), "{w:?}");
        let w = bound_warnings(&report(true, false, false));
        assert!(w.len() == 1 && w[0].starts_with("baseline fit at 40 °C"), "{w:?}");
        assert!(baseline_bounds_resolved(&report(true, false, false)).is_empty());
        assert!(bound_warnings(&report(false, false, true)).is_empty());
    }

    /// Issue 30: the truth beside synthetic runs is compared with what was identified, in either
    /// truth's form (`thermovia synth`'s, tests/truth/truth_model.py's).
    #[test]
    fn the_truth_is_compared_effect_by_effect_and_per_temperature() {
        let r = report(false, false, true);
        let synth = json!({"storage_modulus_scale": 0.8, "loss_modulus_scale": 1.25,
            "coulomb_friction": {"torque_nm": 0.03}, "backlash": {"width_rad": 0.0},
            "gravity": {"mgl_nm": 1.249, "offset_rad": 0.1},
            "frequency_dependent_modulus": {"stiffness_nm_per_rad": 0.0, "relaxation_time_s": 0.1}, "seed": 1});
        let t = truth_comparison(std::path::Path::new("d/truth.json"), &synth, &r).unwrap();
        let rows = t["parameters"].as_array().unwrap();
        let row = |e: &str, p: &str| rows.iter().find(|x| x["effect"] == e && x["parameter"] == p).unwrap().clone();
        assert_eq!(rows.len(), 4, "absent effects (zero) are not rows: {rows:?}");
        assert_eq!(row("coulomb_friction", "torque_nm")["status"], "missed");
        let g = row("gravity", "mgl_nm");
        assert_eq!((g["status"].as_str(), g["identified"].as_f64()), (Some("found"), Some(1.2)));
        assert!((g["relative_error"].as_f64().unwrap() - (1.2 / 1.249 - 1.0)).abs() < 1e-12);
        assert_eq!(row("gravity", "offset_rad")["relative_error"].as_f64(), Some(0.0));
        let extra = row("link_damping", "damping_nms");
        assert_eq!((extra["status"].as_str(), extra["true"].as_f64()), (Some("extra"), Some(0.0)));
        assert!(extra["relative_error"].is_null());
        // K = springs + 0.8 × (table − springs) = 10, C = 1.25 × 0.4 = 0.5
        let k = &t["transmission"][0];
        assert_eq!((k["stiffness_true"].as_f64(), k["damping_true"].as_f64()), (Some(10.0), Some(0.5)));
        assert!((k["stiffness_relative_error"].as_f64().unwrap() - 0.01).abs() < 1e-12);
        let md = truth_markdown(&t);
        assert!(md.contains("| gravity | mgl_nm | 1.249 | 1.2 | -3.92 % |"), "{md}");
        assert!(md.contains("| coulomb_friction | torque_nm | 0.03 | — (missed) | — |"), "{md}");
        assert!(md.contains("| 40.0 | 10 | 10.1 | +1.00 % | 0.5 | 0.49 | -2.00 % |"), "{md}");
        assert!(
            md.contains("| gravity | offset_rad | 0.1 | 0.1 | 0 % |") && md.contains("\nThe transmission's truth: "),
            "{md}"
        );
        // tests/truth/truth_model.py's form: effects under "effects", K and C per run
        let runs = json!({"effects": {"gravity": {"mgl_nm": 1.2, "offset_rad": 0.0},
            "hardening_spring": {"alpha_per_rad2": 5.0, "out_of_library": true}},
            "runs": [{"temperature_c": 22.0, "stiffness": 1.0, "damping": 0.1},
                     {"temperature_c": 40.0, "stiffness": 10.0, "damping": 0.5}]});
        let t = truth_comparison(std::path::Path::new("truth.json"), &runs, &r).unwrap();
        let rows = t["parameters"].as_array().unwrap();
        let offset = rows.iter().find(|x| x["parameter"] == "offset_rad").unwrap();
        assert!(offset["relative_error"].is_null() && offset["absolute_error"].as_f64() == Some(0.1), "{offset}");
        assert!(rows.iter().any(|x| x["effect"] == "hardening_spring" && x["status"] == "outside the library"));
        assert_eq!(t["transmission"][0]["stiffness_true"].as_f64(), Some(10.0));
        // a JSON that is no truth is not compared
        assert!(truth_comparison(std::path::Path::new("x.json"), &json!({"a": 1}), &r).is_none());
    }
}
