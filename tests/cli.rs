//! The `thermovia` command line as a user meets it: `simulate` and `info` on the packaged FMU,
//! negative numbers reaching the tools' own checks, one-line errors that name the argument and
//! the value, nothing half-written. (`simulate`/`info` on an FMU that is not ThermoVIA: the
//! container test in tests/python/test_cli_other_fmu.py.)

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn thermovia(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_thermovia")).args(args).output().expect("thermovia runs")
}

fn fmu() -> String {
    common::fmu_path().display().to_string()
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("thermovia-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The one line a failed invocation prints.
fn error_line(o: &Output) -> String {
    assert!(!o.status.success(), "expected failure, got {:?}", String::from_utf8_lossy(&o.stdout));
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    let lines: Vec<&str> = err.lines().collect();
    assert_eq!(lines.len(), 1, "one line expected: {err:?}");
    lines[0].to_string()
}

fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let names = lines.next().unwrap().split(',').map(|s| s.trim_matches('"').to_string()).collect();
    let rows = lines.map(|l| l.split(',').map(|x| x.parse().unwrap()).collect()).collect();
    (names, rows)
}

#[test]
fn simulate_defaults_come_from_the_fmu() {
    let dir = scratch("defaults");
    let out = dir.join("r.csv");
    let o = thermovia(&["simulate", &fmu(), "--stop-time", "0.05", "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (names, rows) = read_csv(&out);
    // every output of the FMU, in description order, and nothing else
    let md = common::fmu().description.clone();
    let outputs: Vec<&str> = md.variables.iter().filter(|v| v.causality == "output").map(|v| v.name.as_str()).collect();
    assert_eq!(names[0], "time");
    assert_eq!(&names[1..], outputs.as_slice());
    // the DefaultExperiment's step (1 ms) from its start time: 0, 0.001, …, 0.05
    assert_eq!(md.default_experiment.step_size, Some(1e-3));
    assert_eq!(rows.len(), 51);
    assert!((rows[1][0] - 1e-3).abs() < 1e-15 && (rows[50][0] - 0.05).abs() < 1e-12);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn output_interval_is_separate_from_the_step() {
    let dir = scratch("interval");
    let (fine, coarse) = (dir.join("fine.csv"), dir.join("coarse.csv"));
    let common = [
        "--stop-time",
        "0.2",
        "--set",
        "heater_power=8",
        "--set",
        "motor_torque=0.1",
        "--output",
        "link_angle,pcl_temperature",
    ];
    let path = fmu();
    let run = |out: &Path, extra: &[&str]| {
        let mut a = vec!["simulate", path.as_str()];
        a.extend_from_slice(&common);
        a.extend_from_slice(extra);
        a.extend_from_slice(&["--out", out.to_str().unwrap()]);
        let o = thermovia(&a);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        read_csv(out).1
    };
    let f = run(&fine, &["--step", "0.001"]);
    let c = run(&coarse, &["--step", "0.001", "--output-interval", "0.01"]);
    assert_eq!(f.len(), 201);
    assert_eq!(c.len(), 21);
    // the same 1 ms steps underneath: every recorded row equals the fine run's row at that time
    for (k, row) in c.iter().enumerate() {
        assert_eq!(row, &f[10 * k], "row {k}");
    }
    assert!(c[20][1] > 0.0 && c[20][2] > 295.15, "the link moves and the PCL warms: {:?}", c[20]);
    let e = error_line(&thermovia(&["simulate", &fmu(), "--step", "0.001", "--output-interval", "0.0015"]));
    assert!(e.contains("--output-interval 0.0015") && e.contains("multiple"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn enumeration_items_are_set_by_name_and_unknown_names_get_suggestions() {
    let dir = scratch("enum");
    let out = dir.join("r.csv");
    let o = thermovia(&[
        "simulate",
        &fmu(),
        "--stop-time",
        "0.01",
        "--set",
        "motor_drive=prescribed_angle",
        "--output",
        "motor_drive,motor_angle",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (_, rows) = read_csv(&out);
    assert!(rows.iter().all(|r| r[1] == 1.0), "motor_drive = prescribed_angle = 1");
    let e = error_line(&thermovia(&["simulate", &fmu(), "--set", "motor_drive=prescribed"]));
    assert!(e.contains("motor_drive=\"prescribed\"") && e.contains("prescribed_angle (1)"), "{e}");
    let e = error_line(&thermovia(&["simulate", &fmu(), "--set", "heater_powr=10"]));
    assert!(e.contains("heater_powr") && e.contains("did you mean heater_power"), "{e}");
    let e = error_line(&thermovia(&["simulate", &fmu(), "--set", "heater_power=ten"]));
    assert!(e.contains("heater_power=\"ten\"") && e.contains("a number"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn negative_numbers_reach_the_tools_own_checks() {
    let e = error_line(&thermovia(&["simulate", &fmu(), "--step", "-0.001"]));
    assert!(e.contains("--step -0.001") && e.contains("> 0"), "{e}");
    let e = error_line(&thermovia(&["sweep", "--step=-1"]));
    assert!(e.contains("--step -1") && e.contains("> 0") && !e.contains("divide"), "{e}");
    let e = error_line(&thermovia(&["simulate", &fmu(), "--stop-time", "-3"]));
    assert!(e.contains("--stop-time -3"), "{e}");
    // the parser's own errors are one line too, and name the argument and the value
    let e = error_line(&thermovia(&["simulate", &fmu(), "--step", "abc"]));
    assert!(e.contains("--step") && e.contains("abc"), "{e}");
    let e = error_line(&thermovia(&["simulate", &fmu(), "--stop-tme", "1"]));
    assert!(e.contains("--stop-tme") && e.contains("--stop-time"), "{e}");
}

#[test]
fn output_paths_are_created_or_named_and_never_half_written() {
    let dir = scratch("paths");
    // a missing parent folder is created
    let nested = dir.join("a/b/r.csv");
    let o = thermovia(&["simulate", &fmu(), "--stop-time", "0.01", "--out", nested.to_str().unwrap()]);
    assert!(o.status.success() && nested.exists(), "{}", String::from_utf8_lossy(&o.stderr));
    // a parent that cannot be a folder is named in the error
    let blocker = dir.join("file");
    std::fs::write(&blocker, "x").unwrap();
    let bad = blocker.join("r.csv");
    let e = error_line(&thermovia(&["simulate", &fmu(), "--stop-time", "0.01", "--out", bad.to_str().unwrap()]));
    assert!(e.contains(blocker.to_str().unwrap()), "{e}");
    let e = error_line(&thermovia(&[
        "sweep",
        "--out",
        blocker.join("sweep").to_str().unwrap(),
        "--temperatures",
        "22",
        "--frequencies",
        "1",
    ]));
    assert!(e.contains(blocker.to_str().unwrap()), "{e}");
    // a run that fails leaves no file behind, not even a partial one
    let failed = dir.join("failed.csv");
    error_line(&thermovia(&[
        "simulate",
        &fmu(),
        "--stop-time",
        "0.01",
        "--output",
        "no_such_output",
        "--out",
        failed.to_str().unwrap(),
    ]));
    let left: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert!(!left.iter().any(|n| n.to_string_lossy().contains("failed")), "{left:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn info_lists_variables_capabilities_and_the_default_experiment() {
    let o = thermovia(&["info", &fmu()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("Model          ThermoVIA (FMI 2.0 Co-Simulation)"), "{text}");
    assert!(text.contains("stop time    20") && text.contains("step size    0.001"), "{text}");
    assert!(text.contains("canGetAndSetFMUstate                     true"), "{text}");
    let row = text.lines().find(|l| l.trim_start().starts_with("heater_power ")).expect("heater_power row");
    assert!(row.contains("input") && row.contains("Real") && row.contains(" W "), "{row}");
    let row = text.lines().find(|l| l.trim_start().starts_with("motor_drive ")).expect("motor_drive row");
    assert!(row.contains("Enumeration") && row.contains("0 (torque)"), "{row}");
    let e = error_line(&thermovia(&["info", "/nonexistent/x.fmu"]));
    assert!(e.contains("/nonexistent/x.fmu") && e.contains("no such file"), "{e}");
}
