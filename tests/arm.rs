//! The two-joint arm example (issue 5): coupling accuracy against the monolithic reference, the
//! stability limit, refusal of bad input, cold vs heated joints, switching times, the command.
//! Everything runs through the packaged FMU (`cargo run --release -p fmu-build` first).

mod common;

use thermovia_tools::arm::dynamics::ArmConfig;
use thermovia_tools::arm::sim::{cosimulate, probe, Scenario};
use thermovia_tools::arm::{compare, reference, stability, thermal, ArmArgs};

/// The bound: at a 1 ms communication step the co-simulated tip stays within 1 % of the
/// tip's travel of the monolithic solution, cold and hot; and the error behaves as a first-order
/// scheme's should (halving the step roughly halves it), so the bound is not luck.
#[test]
fn coupling_error_at_1ms_is_under_one_percent_and_first_order() {
    let fmu = common::fmu();
    let cfg = ArmConfig::default();
    let ref_dt = 5e-4;
    for sc in [Scenario::cold(), Scenario::hot()] {
        let props = probe(&fmu, &cfg, &sc).unwrap();
        let (r, _) = reference::simulate(&cfg, &props, ref_dt, 1e-10).unwrap();
        let limit = stability::limit(&cfg, &props);
        let e = |h: f64| compare(&cosimulate(&fmu, &cfg, &sc, h, limit, |_| {}).unwrap(), &r, h, ref_dt, &sc.name);
        let (e05, e1, e2) = (e(5e-4), e(1e-3), e(2e-3));
        assert!(e1.relative_error < 0.01, "{}: {:.3} % at 1 ms", sc.name, 100.0 * e1.relative_error);
        for (a, b) in [(&e05, &e1), (&e1, &e2)] {
            let ratio = b.relative_error / a.relative_error;
            assert!(
                (1.5..3.0).contains(&ratio),
                "{}: error ratio {ratio} from {} to {} s",
                sc.name,
                a.step_s,
                b.step_s
            );
        }
        // the reference is an independent solution, not the co-simulation again
        assert!(e1.tip_error_m > 0.0, "{e1:?}");
    }
}

/// At rest (goal = start), both the co-simulation and the reference stay exactly where they start:
/// the initial motor offset g/K, the gravity feed-forward and the coupling torque balance.
#[test]
fn a_held_pose_stays_put_in_both_simulations() {
    let fmu = common::fmu();
    let cfg = ArmConfig { goal_tip: ArmConfig::default().start_tip, duration: 1.0, ..ArmConfig::default() };
    let sc = Scenario::hot();
    let props = probe(&fmu, &cfg, &sc).unwrap();
    let co = cosimulate(&fmu, &cfg, &sc, 1e-3, None, |_| {}).unwrap();
    let (r, _) = reference::simulate(&cfg, &props, 1e-3, 1e-10).unwrap();
    for tr in [&co, &r] {
        for (k, q) in tr.q.iter().enumerate() {
            for (i, (qi, q0)) in q.iter().zip(&tr.q[0]).enumerate() {
                assert!((qi - q0).abs() < 1e-9, "t = {}: q{i} drifted {} rad", tr.t[k], qi - q0);
            }
        }
    }
}

/// The limit from the linearised one-step map agrees with the closed-form estimate of the mode that
/// limits it (hot joints: motor PD derivative against the PCL's weak damping, before the
/// proportional term's own limit), and with the nonlinear co-simulation through the FMU: bounded
/// just below, diverging just above. A step at the limit is refused, saying why.
#[test]
fn stability_limit_is_predicted_checked_and_enforced() {
    let fmu = common::fmu();
    let cfg = ArmConfig { duration: 3.5, ..ArmConfig::default() };
    let sc = Scenario::hot();
    let props = probe(&fmu, &cfg, &sc).unwrap();
    let limit = stability::limit(&cfg, &props).expect("the hot arm has a limit");
    let est = stability::estimates(&cfg, &props);
    let motor = est.motor_loop[0].expect("kd above the hot PCL damping");
    assert!(limit < motor && limit > 0.5 * motor, "limit {limit} vs motor-loop estimate {motor}");
    assert!(limit < est.motor_proportional.unwrap());

    let amplitude = |h: f64| match cosimulate(&fmu, &cfg, &sc, h, None, |_| {}) {
        Err(_) => f64::INFINITY,
        Ok(tr) => {
            tr.t.iter()
                .zip(&tr.qd)
                .filter(|(t, _)| **t > 3.0)
                .map(|(_, v)| v[0].abs().max(v[1].abs()))
                .fold(0.0, f64::max)
        }
    };
    let below = amplitude(0.95 * limit);
    let above = amplitude(1.05 * limit);
    assert!(below < 1e-3, "0.95 × limit: speed amplitude {below} rad/s at the end");
    assert!(above > 1e3 * below.max(1e-9), "1.05 × limit: amplitude {above} rad/s does not grow");

    let e = cosimulate(&fmu, &cfg, &sc, limit, Some(limit), |_| {}).unwrap_err();
    assert!(e.contains("stability limit"), "{e}");
}

/// Nonsense configurations are refused before anything runs, naming what is wrong.
#[test]
fn bad_arm_configurations_are_refused_with_the_reason() {
    let base = ArmConfig::default();
    let cases: Vec<(ArmConfig, &str)> = vec![
        (ArmConfig { l1: 0.0, ..base.clone() }, "l1"),
        (ArmConfig { l2: -0.1, ..base.clone() }, "l2"),
        (ArmConfig { m1: 0.0, ..base.clone() }, "m1"),
        (ArmConfig { m2: -1.0, ..base.clone() }, "m2"),
        (ArmConfig { payload_mass: -0.2, ..base.clone() }, "payload"),
        (ArmConfig { elbow_mass: f64::NAN, ..base.clone() }, "elbow_mass"),
        (ArmConfig { goal_tip: [0.6, 0.0], ..base.clone() }, "out of reach"),
        (ArmConfig { wall_x: 0.1, ..base.clone() }, "wall"),
    ];
    for (cfg, word) in cases {
        let e = cfg.validate().unwrap_err();
        assert!(e.contains(word), "expected {word:?} in {e:?}");
    }
    assert!(base.validate().is_ok());

    let fmu = common::fmu();
    let e =
        cosimulate(&fmu, &ArmConfig { m1: 0.0, ..base.clone() }, &Scenario::cold(), 1e-3, None, |_| {}).unwrap_err();
    assert!(e.contains("m1"), "{e}");
    let e = cosimulate(&fmu, &base, &Scenario::cold(), -1e-3, None, |_| {}).unwrap_err();
    assert!(e.contains("positive"), "{e}");
}

/// Why the joint exists: the same move into the same wall. Heated (soft) joints press with a lower
/// peak and final force.
#[test]
fn heated_joints_hit_the_wall_softer() {
    let fmu = common::fmu();
    let cfg = ArmConfig::default();
    let mut peaks = Vec::new();
    for sc in [Scenario::cold(), Scenario::hot()] {
        let props = probe(&fmu, &cfg, &sc).unwrap();
        let tr = cosimulate(&fmu, &cfg, &sc, 1e-3, stability::limit(&cfg, &props), |_| {}).unwrap();
        let m = thermovia_tools::arm::task_metrics(&cfg, &sc, props, &tr);
        assert!(m.first_contact_s.is_some(), "{}: the tip never reached the wall", sc.name);
        peaks.push((m.peak_contact_force_n, m.final_contact_force_n, props[0].stiffness));
    }
    let (cold, hot) = (peaks[0], peaks[1]);
    assert!(hot.2 < 0.5 * cold.2, "hot K {} vs cold K {}", hot.2, cold.2);
    assert!(hot.0 < 0.7 * cold.0, "peak force hot {} N vs cold {} N", hot.0, cold.0);
    assert!(hot.1 < cold.1, "final force hot {} N vs cold {} N", hot.1, cold.1);
}

/// The causal law (`viscoelastic_law` = 1) in the same task: fitted at 0.5 and 1 Hz it has no static
/// PCL modulus at 22 °C (E_∞ = 0, docs/physics.md §5c), so the cold joint pressing the wall at rest
/// relaxes towards the springs' stiffness and presses with well under half the hysteretic law's
/// force, which keeps K'(T) at every frequency, 0 Hz included. Both runs stay stable and reach the wall.
#[test]
fn the_prony_law_relaxes_under_a_held_load() {
    let fmu = common::fmu();
    let sc = Scenario::cold();
    let mut finals = Vec::new();
    for law in [0, 1] {
        let cfg = ArmConfig { viscoelastic_law: law, ..ArmConfig::default() };
        let props = probe(&fmu, &cfg, &sc).unwrap();
        let tr = cosimulate(&fmu, &cfg, &sc, 1e-3, stability::limit(&cfg, &props), |_| {}).unwrap();
        let m = thermovia_tools::arm::task_metrics(&cfg, &sc, props, &tr);
        assert!(m.first_contact_s.is_some(), "law {law}: the tip never reached the wall");
        finals.push(m.final_contact_force_n);
    }
    assert!(finals[1] < 0.5 * finals[0], "held wall force: Prony {} N, hysteretic {} N", finals[1], finals[0]);
}

/// Switching: at 10 W the PCL reaches 60 °C within the paper's 30–90 s; passive cooling back to
/// 90 % of the cold stiffness takes far longer than heating.
#[test]
fn heating_is_fast_and_passive_cooling_is_much_slower() {
    let fmu = common::fmu();
    let r = thermal::switching(&fmu, 10.0, 60.0, 3600.0, 0.01, |_| {}).unwrap();
    let heat = r.heat_time_s.unwrap();
    assert!((30.0..=90.0).contains(&heat), "heating took {heat} s");
    assert!(r.soften_50_s.unwrap() < r.soften_90_s.unwrap());
    let cool = r.stiffen_90_s.expect("recovers within an hour");
    assert!(cool > 5.0 * heat, "cooling {cool} s vs heating {heat} s");
    assert!(r.stiffness_hot < r.stiffness_cold);
}

/// `thermovia arm` writes its report and plots, atomically replacing an older report, and refuses
/// a step above the stability limit without touching the old report.
#[test]
fn the_command_writes_report_and_plots() {
    let out = std::env::temp_dir().join(format!("thermovia-arm-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(out.join("stale.txt"), "old").unwrap();
    let args = |step: f64| ArmArgs {
        out: out.clone(),
        fmu: None,
        step,
        l1: 0.25,
        l2: 0.20,
        m1: 0.30,
        m2: 0.20,
        elbow_mass: 0.86,
        payload: 0.30,
        kp: 150.0,
        kd: 1.5,
        wall_x: 0.36,
        wall_stiffness: 3000.0,
        wall_damping: 30.0,
        duration: 3.0,
        hot_c: 60.0,
        heater_power: 10.0,
        cooling_limit: 3600.0,
    };
    let e = thermovia_tools::arm::run(&args(0.05), &thermovia_tools::output::Silent).unwrap_err().to_string();
    assert!(e.contains("stability limit"), "{e}");
    assert!(out.join("stale.txt").exists(), "a refused run must leave the old report alone");

    thermovia_tools::arm::run(&args(1e-3), &thermovia_tools::output::Silent).unwrap();
    assert!(!out.join("stale.txt").exists(), "the folder was not replaced as a whole");
    for f in [
        "report.md",
        "report.json",
        "tip_path.svg",
        "joint_torques.svg",
        "contact_force.svg",
        "coupling_error.svg",
        "impedance_switch_stiffness.svg",
        "impact_damping_law.svg",
    ] {
        let meta = std::fs::metadata(out.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(meta.len() > 200, "{f} is nearly empty");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let h1 = json["step_for_one_percent_s"].as_f64().unwrap();
    assert!(h1 >= 1e-3, "1 % step {h1}");
    assert_eq!(json["tasks"].as_array().unwrap().len(), 2);
    let _ = std::fs::remove_dir_all(&out);
}
