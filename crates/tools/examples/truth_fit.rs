//! A campaign rig's truth effect set fitted to its runs, from the truth's values: tells a search
//! that missed a better model (the truth's BIC lower than the report's) from runs that cannot tell
//! the two apart. `cargo run --release -p thermovia-tools --example truth_fit -- RIG_FOLDER`
//! (a campaign rig: RIG_FOLDER/runs with truth.json, RIG_FOLDER/calibration/report.json).
use std::path::PathBuf;

use thermovia_tools::calibrate::{conditioning, data, fit, search, sim};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let rig = PathBuf::from(std::env::args().nth(1).ok_or("usage: truth_fit RIG_FOLDER")?);
    let truth: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(rig.join("runs/truth.json"))?)?;
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rig.join("calibration/report.json"))?)?;
    let runs = data::read_inputs_with(&[rig.join("runs")], data::ReadOptions { repair_samples: false })?;
    let (group, temperatures) = conditioning::group_runs(&runs);
    let inputs = runs.iter().map(|r| conditioning::sim_input(r, None).0).collect();
    let measured = runs.iter().map(|r| r.link.clone()).collect();
    let fmu = thermovia_tools::open_fmu(None)?;
    let simulator = sim::Simulator::new(fmu, 2)?;
    let mut prob = fit::Problem::new(&simulator, inputs, measured, group, &temperatures)?;
    // the transmission: each temperature's truth K and C (viscous, as the truth model's)
    let mut p = Vec::new();
    for t in &temperatures {
        let run = truth["runs"].as_array().unwrap().iter().find(|r| r["temperature_c"].as_f64() == Some(*t)).unwrap();
        p.push(run["stiffness"].as_f64().unwrap().ln());
        p.push(run["damping"].as_f64().unwrap().ln());
    }
    let mut effects = Vec::new();
    let v = |e: &str, k: &str| truth["effects"][e][k].as_f64().unwrap();
    for (name, _) in truth["effects"].as_object().unwrap() {
        match name.as_str() {
            "coulomb_friction" => push(&mut effects, &mut p, fit::Effect::CoulombFriction, &[v(name, "torque_nm")]),
            "backlash" => push(&mut effects, &mut p, fit::Effect::Backlash, &[v(name, "width_rad")]),
            "link_damping" => push(&mut effects, &mut p, fit::Effect::LinkDamping, &[v(name, "damping_nms")]),
            "constant_load" => push(&mut effects, &mut p, fit::Effect::ConstantLoad, &[v(name, "torque_nm")]),
            "gravity" => {
                let (m, o) = (v(name, "mgl_nm"), v(name, "offset_rad"));
                push(&mut effects, &mut p, fit::Effect::Gravity, &[m * o.cos(), m * o.sin()])
            }
            "stribeck_friction" => push(
                &mut effects,
                &mut p,
                fit::Effect::StribeckFriction,
                &[v(name, "torque_nm"), v(name, "velocity").ln()],
            ),
            "asymmetric_friction" => {
                let (cp, cn) = (v(name, "coulomb_positive"), v(name, "coulomb_negative"));
                let (vp, vn) = (v(name, "viscous_positive"), v(name, "viscous_negative"));
                push(&mut effects, &mut p, fit::Effect::CoulombFriction, &[(cp + cn) / 2.0]);
                push(&mut effects, &mut p, fit::Effect::LinkDamping, &[(vp + vn) / 2.0]);
                push(&mut effects, &mut p, fit::Effect::AsymmetricFriction, &[(cp - cn) / 2.0, (vp - vn) / 2.0]);
            }
            other => return Err(format!("truth effect {other} not mapped").into()),
        }
    }
    let spec = fit::ModelSpec {
        effects,
        law: fit::DampingLaw::Viscous,
        springs: fit::SpringBank::Scaled,
        elasto_backlash: false,
    };
    let at_truth = fit::Fit::evaluate(&prob, spec.clone(), p.clone()).ok_or("could not simulate the truth")?;
    let fitted = fit::levenberg_marquardt(&prob, spec, p, search::MAX_ITERATIONS)?;
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
    Ok(())
}

fn push(effects: &mut Vec<fit::Effect>, p: &mut Vec<f64>, e: fit::Effect, v: &[f64]) {
    effects.push(e);
    p.extend_from_slice(v);
}
