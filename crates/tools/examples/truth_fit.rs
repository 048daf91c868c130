//! A campaign rig's truth effect set fitted to its runs, from the truth's values: tells a search
//! that missed a better model (the truth's BIC lower than the report's) from runs that cannot tell
//! the two apart. `cargo run --release -p thermovia-tools --example truth_fit -- RIG_FOLDER`
//! (a campaign rig: RIG_FOLDER/runs with truth.json, RIG_FOLDER/calibration/report.json).
//! Arguments after the folder, `INDEX=VALUE`, replace entries of the start (the printed `fitted p`'s
//! order): how far from the truth a refit still finds it; `speeds=V1,V2,...` sets every run's (or
//! segment's) initial link speed, rad/s, before the fit (the search's debug output prints its own).
//! `TRUTH_FIT_SHARE=0.35` fits on that share of every run's start, as the search screens its
//! candidates; `TRUTH_FIT_ITERATIONS=N` caps the first fit's iterations (4: a screening refit's cap).
//! Prints the first fit (before the initial speeds are chosen again), the final one and the speeds.
use std::path::{Path, PathBuf};

use serde_json::Value;
use thermovia_tools::calibrate::{conditioning, data, fit, search, sim};

type Error = Box<dyn std::error::Error>;

fn main() {
    if let Err(e) = run() {
        eprintln!("truth_fit: {e}");
        std::process::exit(1);
    }
}

fn read_json(path: &Path) -> Result<Value, Error> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?)
}

fn number(v: &Value, what: &str) -> Result<f64, Error> {
    Ok(v.as_f64().ok_or_else(|| format!("truth.json: {what} is not a number"))?)
}

fn run() -> Result<(), Error> {
    let rig = PathBuf::from(std::env::args().nth(1).ok_or("usage: truth_fit RIG_FOLDER")?);
    let truth = read_json(&rig.join("runs/truth.json"))?;
    let report = read_json(&rig.join("calibration/report.json"))?;
    let runs = data::read_inputs_with(&[rig.join("runs")], data::ReadOptions { repair_samples: false, threads: 2 })?;
    let (group, temperatures) = conditioning::group_runs(&runs);
    let inputs = runs.iter().map(|r| conditioning::sim_input(r, None, false).0).collect();
    let measured = runs.iter().map(|r| r.link.clone()).collect();
    let fmu = thermovia_tools::open_fmu(None)?;
    let simulator = sim::Simulator::new(fmu, 2)?;
    let mut prob = fit::Problem::new(&simulator, inputs, measured, group, &temperatures)?;
    // the transmission: each temperature's truth K and C (viscous, as the truth model's)
    let truth_runs = truth["runs"].as_array().ok_or("truth.json: no runs")?;
    let mut p = Vec::new();
    for t in &temperatures {
        let run = truth_runs
            .iter()
            .find(|r| r["temperature_c"].as_f64() == Some(*t))
            .ok_or_else(|| format!("truth.json: no run at {t} °C"))?;
        p.push(number(&run["stiffness"], "stiffness")?.ln());
        p.push(number(&run["damping"], "damping")?.ln());
    }
    let mut effects = Vec::new();
    let empty = serde_json::Map::new();
    for (name, values) in truth["effects"].as_object().unwrap_or(&empty) {
        let v = |k: &str| number(&values[k], &format!("{name}.{k}"));
        match name.as_str() {
            "coulomb_friction" => push(&mut effects, &mut p, fit::Effect::CoulombFriction, &[v("torque_nm")?]),
            "backlash" => push(&mut effects, &mut p, fit::Effect::Backlash, &[v("width_rad")?]),
            "link_damping" => push(&mut effects, &mut p, fit::Effect::LinkDamping, &[v("damping_nms")?]),
            "thermal_lag" => push(&mut effects, &mut p, fit::Effect::ThermalLag, &[v("time_constant_s")?]),
            "constant_load" => push(&mut effects, &mut p, fit::Effect::ConstantLoad, &[v("torque_nm")?]),
            "gravity" => {
                let (m, o) = (v("mgl_nm")?, v("offset_rad")?);
                push(&mut effects, &mut p, fit::Effect::Gravity, &[m * o.cos(), m * o.sin()])
            }
            "stribeck_friction" => {
                push(&mut effects, &mut p, fit::Effect::StribeckFriction, &[v("torque_nm")?, v("velocity")?.ln()])
            }
            "asymmetric_friction" => {
                let (cp, cn) = (v("coulomb_positive")?, v("coulomb_negative")?);
                let (vp, vn) = (v("viscous_positive")?, v("viscous_negative")?);
                push(&mut effects, &mut p, fit::Effect::CoulombFriction, &[(cp + cn) / 2.0]);
                push(&mut effects, &mut p, fit::Effect::LinkDamping, &[(vp + vn) / 2.0]);
                push(&mut effects, &mut p, fit::Effect::AsymmetricFriction, &[(cp - cn) / 2.0, (vp - vn) / 2.0]);
            }
            other => return Err(format!("truth effect {other} is not mapped to the loop's parameters").into()),
        }
    }
    let spec = fit::ModelSpec {
        effects,
        law: fit::DampingLaw::Viscous,
        springs: fit::SpringBank::Scaled,
        elasto_backlash: false,
    };
    let mut start = p.clone();
    for arg in std::env::args().skip(2) {
        let (i, v) = arg.split_once('=').ok_or_else(|| format!("{arg}: expected INDEX=VALUE"))?;
        if i == "speeds" {
            let speeds: Result<Vec<f64>, _> = v.split(',').map(str::parse).collect();
            let speeds = speeds.map_err(|_| format!("{arg}: expected speeds=V1,V2,... (rad/s)"))?;
            if speeds.len() != prob.inputs.len() {
                return Err(format!("{arg}: {} runs, {} speeds", prob.inputs.len(), speeds.len()).into());
            }
            prob.set_initial_speeds(&speeds);
            continue;
        }
        let i: usize = i.parse().map_err(|_| format!("{arg}: INDEX is not a number"))?;
        let v: f64 = v.parse().map_err(|_| format!("{arg}: VALUE is not a number"))?;
        let n = start.len();
        *start.get_mut(i).ok_or_else(|| format!("{arg}: the start has {n} entries"))? = v;
    }
    if let Some(share) = std::env::var("TRUTH_FIT_SHARE").ok().and_then(|s| s.parse::<f64>().ok()) {
        prob = prob.truncated(share);
    }
    let iterations =
        std::env::var("TRUTH_FIT_ITERATIONS").ok().and_then(|s| s.parse().ok()).unwrap_or(search::MAX_ITERATIONS);
    let at_truth = fit::Fit::evaluate(&prob, spec.clone(), p).ok_or("could not simulate the truth")?;
    let fitted = fit::levenberg_marquardt(&prob, spec, start, iterations)?;
    println!(
        "LM: {} iterations, bic {:.1}, p {:?}",
        fitted.iterations,
        fitted.bic(),
        fitted.p.iter().map(|x| format!("{x:.4}")).collect::<Vec<_>>()
    );
    let fitted = search::resolve_initial_speeds(&mut prob, fitted);
    let fitted = search::fit_initial_speeds(&mut prob, fitted);
    let final_bic = report["final"]["bic"].as_f64().unwrap_or(f64::NAN);
    let final_rmse = report["final"]["rmse_rad"].as_f64().unwrap_or(f64::NAN);
    println!(
        "truth set at truth: rmse {:.4e} bic {:.1}; fitted: rmse {:.4e} bic {:.1} ({} it); report final: rmse {:.4e} bic {:.1}; truth - report {:+.1}",
        at_truth.rmse(),
        at_truth.bic(),
        fitted.rmse(),
        fitted.bic(),
        fitted.iterations,
        final_rmse,
        final_bic,
        fitted.bic() - final_bic
    );
    println!("fitted p: {:?}", fitted.p.iter().map(|x| format!("{x:.4}")).collect::<Vec<_>>());
    println!("initial speeds: {:?}", prob.initial_speeds().iter().map(|x| format!("{x:.4}")).collect::<Vec<_>>());
    Ok(())
}

fn push(effects: &mut Vec<fit::Effect>, p: &mut Vec<f64>, e: fit::Effect, v: &[f64]) {
    effects.push(e);
    p.extend_from_slice(v);
}
