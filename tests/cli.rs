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

/// Issue 30: every list option of the tools takes its values comma- or space-separated, and its
/// help shows the default in the comma form (both work; one form everywhere).
#[test]
fn list_options_take_commas_or_spaces_and_show_defaults_that_work() {
    use clap::{Args, Command};
    let commands = [
        thermovia_tools::sweep::SweepArgs::augment_args(Command::new("sweep")),
        thermovia_tools::calibrate::SynthArgs::augment_args(Command::new("synth")),
        thermovia_tools::calibrate::CalibrateArgs::augment_args(Command::new("calibrate")),
        thermovia_tools::arm::ArmArgs::augment_args(Command::new("arm")),
    ];
    let mut lists = Vec::new();
    for cmd in &commands {
        for a in cmd.get_arguments().filter(|a| a.get_value_delimiter().is_some()) {
            let id = format!("{} --{}", cmd.get_name(), a.get_long().unwrap_or("?"));
            assert!(a.get_num_args().is_some_and(|n| n.max_values() > 1), "{id} takes one value after the option");
            assert!(a.get_default_values().len() <= 1, "{id}: the help would show its default space-separated");
            lists.push(id);
        }
    }
    assert_eq!(
        lists,
        [
            "sweep --temperatures",
            "sweep --frequencies",
            "sweep --heating-powers",
            "synth --temperatures",
            "synth --frequencies"
        ]
    );
    for cmd in ["sweep", "synth"] {
        let o = thermovia(&[cmd, "--help"]);
        let help = String::from_utf8_lossy(&o.stdout);
        assert!(help.contains("comma- or space-separated) [default: 22,40,50,60]"), "{help}");
    }
    // both spellings, mixed, through the binary's own parser
    let dir = scratch("lists");
    let o = thermovia(&[
        "synth",
        "--out",
        dir.to_str().unwrap(),
        "--temperatures",
        "22",
        "60",
        "--frequencies",
        "0.5,1",
        "--duration",
        "0.5",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut files: Vec<String> =
        std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    files.sort();
    assert_eq!(files, ["run_22C_0.5Hz.csv", "run_22C_1Hz.csv", "run_60C_0.5Hz.csv", "run_60C_1Hz.csv", "truth.json"]);
    // negative values still reach the tool's own check, after a space as after a comma
    for frequencies in [&["1", "-2"][..], &["1,-2"]] {
        let mut args = vec!["sweep", "--frequencies"];
        args.extend_from_slice(frequencies);
        let e = error_line(&thermovia(&args));
        assert!(e.contains("--frequencies -2: each frequency must be a finite number > 0 Hz"), "{e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 30: `sweep` and `synth` take the motor amplitude in radians, as every angle of the command
/// line, under one name that says so; a value in degrees is caught.
#[test]
fn sweep_and_synth_take_the_amplitude_in_radians_under_one_name() {
    let dir = scratch("amplitude");
    for cmd in ["sweep", "synth"] {
        let help = String::from_utf8_lossy(&thermovia(&[cmd, "--help"]).stdout).into_owned();
        assert!(help.contains("--amplitude-rad <AMPLITUDE_RAD>"), "{help}");
        assert!(!help.contains("--amplitude-deg") && !help.contains("--amplitude <"), "{help}");
        let e = error_line(&thermovia(&[cmd, "--amplitude-rad", "30", "--out", dir.join(cmd).to_str().unwrap()]));
        assert!(
            e.contains("--amplitude-rad 30: must be a number > 0 and ≤ π rad (in degrees? 30° is 0.523599 rad)"),
            "{e}"
        );
        let e = error_line(&thermovia(&[cmd, "--amplitude-deg", "30"]));
        assert!(e.contains("--amplitude-rad"), "{e}");
    }
    let out = dir.join("synth");
    let o = thermovia(&[
        "synth",
        "--out",
        out.to_str().unwrap(),
        "--amplitude-rad",
        "0.2",
        "--temperatures",
        "22",
        "--frequencies",
        "1",
        "--duration",
        "0.5",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run = std::fs::read_to_string(out.join("run_22C_1Hz.csv")).unwrap();
    assert!(run.contains("# motor_amplitude_rad=0.2\n"), "{run}");
    let _ = std::fs::remove_dir_all(&dir);
}
