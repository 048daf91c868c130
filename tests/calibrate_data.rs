//! The run reader: every malformed file gets an error naming file, line and column, and the
//! command exits non-zero without writing anything into --out.

use std::path::{Path, PathBuf};

use thermovia_tools::calibrate::data::{parse_run, read_inputs, read_inputs_with, DataError, ReadOptions};

const GOOD: &str = "# temperature_c=40\n# source=test\n# frequency_hz=0.5\ntime_s,motor_angle_rad,link_angle_rad,extra\n0.000,0.0,0.0,a\n0.001,0.001,0.0005,b\n0.002,0.002,0.0011,c\n0.003,0.003,0.0016,d\n";

fn err(text: &str) -> DataError {
    parse_run(Path::new("bad.csv"), text).unwrap_err()
}

#[test]
fn a_good_file_reads_with_its_metadata_and_ignores_other_columns() {
    let r = parse_run(Path::new("good.csv"), GOOD).unwrap();
    assert_eq!(r.time.len(), 4);
    assert_eq!(r.link[2], 0.0011);
    assert_eq!(r.temperature_c, vec![40.0; 4]);
    assert_eq!(r.frequency_hz, 0.5);
    assert_eq!(r.meta.get("source").map(String::as_str), Some("test"));
}

#[test]
fn the_temperature_column_wins_over_metadata() {
    let text = "# temperature_c=40\ntime_s,temperature_c,motor_angle_rad,link_angle_rad\n0,50.5,0,0\n1,51,0.1,0\n2,52,0.2,0.1\n3,53,0.3,0.2\n";
    let r = parse_run(Path::new("t.csv"), text).unwrap();
    assert_eq!(r.temperature_c, vec![50.5, 51.0, 52.0, 53.0]);
}

#[test]
fn missing_column_names_file_line_and_column() {
    let e = err("# temperature_c=40\ntime_s,motor_angle_rad\n0,0\n");
    let s = e.to_string();
    assert_eq!(e.line, Some(2));
    assert!(s.starts_with("bad.csv:2"), "{s}");
    assert!(s.contains("link_angle_rad"), "{s}");
}

/// Issue 30: a mistyped column name gets the did-you-mean `thermovia simulate` gives a variable
/// name, at the header's line and the mistyped cell's column.
#[test]
fn a_mistyped_column_name_gets_a_suggestion_at_its_line_and_column() {
    let e = err(&GOOD.replace("link_angle_rad", "link_angel_rad"));
    assert_eq!((e.line, e.column.clone()), (Some(4), Some((3, "link_angel_rad".into()))), "{e}");
    let s = e.to_string();
    assert!(
        s.starts_with("bad.csv:4:3 (column \"link_angel_rad\"): missing required column \"link_angle_rad\""),
        "{s}"
    );
    assert!(s.contains("did you mean link_angle_rad for \"link_angel_rad\"?"), "{s}");
    // an optional column the run then lacks: the temperature
    let e = err(&GOOD.replace("# temperature_c=40\n", "").replace(",extra", ",temprature_c"));
    assert_eq!((e.line, e.column.clone()), (Some(3), Some((4, "temprature_c".into()))), "{e}");
    assert!(e.to_string().contains("did you mean temperature_c for \"temprature_c\"?"), "{e}");
    // nothing close: no suggestion, and a known column is never offered for another
    let e = err(&GOOD.replace("link_angle_rad", "zzz"));
    assert!(!e.to_string().contains("did you mean") && e.column.is_none(), "{e}");
    let e = err("# temperature_c=40\ntime_s,motor_angle_rad,motor_torque_nm\n0,0,0\n");
    assert!(!e.to_string().contains("did you mean"), "{e}");
}

/// A value of 1e300 is echoed with an exponent, not as its 301 digits.
#[test]
fn huge_values_are_echoed_short() {
    let e = err(&GOOD.replace("0.001,0.001,0.0005", "1e300,0.001,0.0005"));
    assert_eq!((e.line, e.column.as_ref().map(|c| c.0)), (Some(7), Some(1)), "{e}");
    assert!(e.to_string().contains("previous sample 1e300 s") && e.to_string().len() < 150, "{e}");
    let e = err(&GOOD.replace("0.001,0.001,0.0005", "0.001,1e300,0.0005"));
    assert!(e.to_string().contains("1.0000e300 is an angle beyond"), "{e}");
    // a temperature in the metadata gets the column's range, at its line
    let e = err(&GOOD.replace("# temperature_c=40", "# temperature_c=1e300"));
    assert_eq!(e.line, Some(1), "{e}");
    assert!(e.to_string().contains("temperature_c=1e300 is a temperature outside 1 K"), "{e}");
    let e = err(&GOOD.replace("# temperature_c=40", "# temperature_c=-300"));
    assert_eq!(e.line, Some(1), "{e}");
}

#[test]
fn metadata_beyond_what_a_rig_or_its_log_can_be_is_refused_at_its_line() {
    // a frequency the log cannot carry: above half its sample rate (1 kHz here)
    let e = err(&GOOD.replace("# frequency_hz=0.5", "# frequency_hz=1e300"));
    assert_eq!(e.line, Some(3), "{e}");
    assert!(e.to_string().contains("above half the sample rate (500 Hz)"), "{e}");
    assert!(err(&GOOD.replace("# frequency_hz=0.5", "# frequency_hz=501"))
        .to_string()
        .contains("half the sample rate"));
    parse_run(Path::new("ok.csv"), &GOOD.replace("# frequency_hz=0.5", "# frequency_hz=499")).unwrap();
    let e = err(&GOOD.replace("# source=test", "# link_inertia_kgm2=1e300"));
    assert_eq!(e.line, Some(2), "{e}");
    assert!(e.to_string().contains("link_inertia_kgm2=1e300 is above 1e3"), "{e}");
    // below the FMU's smallest inertia: refused here, not by the FMU in the middle of a fit
    let e = err(&GOOD.replace("# source=test", "# link_inertia_kgm2=1e-30"));
    assert_eq!(e.line, Some(2), "{e}");
    assert!(e.to_string().contains("link_inertia_kgm2=1e-30 is below 1e-9"), "{e}");
    parse_run(Path::new("ok.csv"), &GOOD.replace("# source=test", "# link_inertia_kgm2=1e-9")).unwrap();
}

/// Times logged in milliseconds under `time_s` make a 1 Hz swing a 1 mHz one, below the FMU's
/// lowest excitation frequency: refused as the file is read, with the unit slip named.
#[test]
fn a_run_slower_than_the_fmus_lowest_frequency_is_refused() {
    let ms = sine_run(2000, 1000.0, |k| k as f64).replace("# frequency_hz=0.5\n", "");
    let e = err(&ms);
    assert!(e.message.contains("below the FMU's 1e-3 Hz: are the times in seconds?"), "{e}");
    let e = err(&GOOD.replace("# frequency_hz=0.5", "# frequency_hz=1e-4"));
    assert_eq!(e.line, Some(3), "a declared frequency is named at its line: {e}");
}

/// A run named twice (a file and its folder) is refused, as its samples would count twice; a folder
/// of sub-folders says which of them hold runs.
#[test]
fn a_run_named_twice_is_refused_and_sub_folders_are_named() {
    use thermovia_tools::calibrate::data::expand_inputs;
    let d = tmp("calib-data-twice");
    std::fs::write(d.join("a.csv"), GOOD).unwrap();
    let e = expand_inputs(&[d.clone(), d.join("a.csv")]).unwrap_err();
    assert!(e.to_string().contains("named twice"), "{e}");
    let top = tmp("calib-data-nested");
    std::fs::create_dir_all(top.join("day1")).unwrap();
    std::fs::write(top.join("day1").join("a.csv"), GOOD).unwrap();
    let e = expand_inputs(std::slice::from_ref(&top)).unwrap_err();
    assert!(e.to_string().contains("sub-folders are not searched") && e.to_string().contains("day1"), "{e}");
}

/// A byte-order mark (as Windows tools write) before the first line is not part of its text.
#[test]
fn a_byte_order_mark_is_read_past() {
    let r = parse_run(Path::new("bom.csv"), &format!("\u{feff}{GOOD}")).unwrap();
    assert_eq!((r.time.len(), r.temperature_c[0]), (4, 40.0));
}

#[test]
fn text_in_a_number_column_names_line_and_column() {
    let e = err(&GOOD.replace("0.002,0.002,0.0011", "0.002,abc,0.0011"));
    assert_eq!(e.line, Some(7));
    assert_eq!(e.column, Some((2, "motor_angle_rad".into())));
    let s = e.to_string();
    assert!(s.starts_with("bad.csv:7:2"), "{s}");
    assert!(s.contains("abc"), "{s}");
}

#[test]
fn nan_and_empty_and_missing_cells_are_errors() {
    let e = err(&GOOD.replace("0.001,0.001,0.0005", "0.001,0.001,NaN"));
    assert_eq!((e.line, e.column.as_ref().map(|c| c.0)), (Some(6), Some(3)), "{e}");
    let e = err(&GOOD.replace("0.001,0.001,0.0005", "0.001,,0.0005"));
    assert_eq!((e.line, e.column.as_ref().map(|c| c.0)), (Some(6), Some(2)), "{e}");
    let e = err(&GOOD.replace("0.003,0.003,0.0016,d", "0.003,0.003"));
    assert_eq!((e.line, e.column.as_ref().map(|c| c.0)), (Some(8), Some(3)), "{e}");
    assert!(e.to_string().contains("missing cell"), "{e}");
}

#[test]
fn time_must_increase_strictly() {
    let e = err(&GOOD.replace("0.002,0.002", "0.001,0.002"));
    assert_eq!((e.line, e.column.as_ref().map(|c| c.0)), (Some(7), Some(1)), "{e}");
    assert!(e.to_string().contains("does not increase"), "{e}");
}

#[test]
fn a_run_without_a_temperature_is_an_error_naming_the_file() {
    let e = err(&GOOD.replace("# temperature_c=40\n", ""));
    assert!(e.to_string().starts_with("bad.csv: "), "{e}");
    assert!(e.to_string().contains("temperature"), "{e}");
}

/// Issue 18: a run that cannot support a fit gets a one-line reason naming the file.
#[test]
fn a_run_that_does_not_move_is_an_error_naming_the_file() {
    let still = "# temperature_c=40\ntime_s,motor_angle_rad,link_angle_rad\n0,0.1,0.1\n0.001,0.1,0.1\n0.002,0.1,0.1\n";
    let e = err(still).to_string();
    assert!(e.starts_with("bad.csv: "), "{e}");
    assert!(e.contains("does not move"), "{e}");
    assert_eq!(e.lines().count(), 1, "{e}");
    // the motor moving and the link at rest is motion (a link stuck behind friction or play)
    let motor_only = still
        .replace("0.002,0.1,0.1", "0.002,0.2,0.1")
        .replace("# temperature_c=40", "# temperature_c=40\n# frequency_hz=0.5");
    if let Err(e) = parse_run(Path::new("ok.csv"), &motor_only) {
        panic!("{e}");
    }
}

#[test]
fn an_empty_file_is_an_error() {
    let e = err("");
    assert!(e.to_string().contains("empty"), "{e}");
    let e = err("# temperature_c=40\ntime_s,motor_angle_rad,link_angle_rad\n");
    assert!(e.to_string().contains("data rows"), "{e}");
}

#[test]
fn the_frequency_is_measured_when_not_declared() {
    let mut text = String::from("# temperature_c=22\ntime_s,motor_angle_rad,link_angle_rad\n");
    for k in 0..8000 {
        let t = k as f64 * 1e-3;
        text += &format!("{t},{},{}\n", 0.3 * (2.0 * std::f64::consts::PI * 0.75 * t).sin(), 0.0);
    }
    let r = parse_run(Path::new("f.csv"), &text).unwrap();
    assert!((r.frequency_hz - 0.75).abs() < 1e-3, "{}", r.frequency_hz);
    assert!(!r.frequency_declared);
}

fn tmp(name: &str) -> PathBuf {
    let d = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn folders_expand_to_their_csv_files_and_the_first_bad_file_stops_everything() {
    let d = tmp("calib-data-folder");
    std::fs::write(d.join("a.csv"), GOOD).unwrap();
    std::fs::write(d.join("notes.txt"), "not a run").unwrap();
    let runs = read_inputs(std::slice::from_ref(&d)).unwrap();
    assert_eq!(runs.len(), 1);
    std::fs::write(d.join("b.csv"), GOOD.replace("0.0005", "x")).unwrap();
    let e = read_inputs(std::slice::from_ref(&d)).unwrap_err().to_string();
    assert!(e.contains("b.csv:6:3"), "{e}");
    // read on several threads, the error is still the first bad file's in the files' order
    std::fs::write(d.join("c.csv"), GOOD.replace("0.0005", "y")).unwrap();
    std::fs::write(d.join("d.csv"), GOOD).unwrap();
    for threads in [1, 2, 4] {
        let options = ReadOptions { repair_samples: false, threads };
        let e = read_inputs_with(std::slice::from_ref(&d), options).unwrap_err().to_string();
        assert!(e.contains("b.csv:6:3"), "{threads} threads: {e}");
    }
    std::fs::remove_file(d.join("b.csv")).unwrap();
    std::fs::remove_file(d.join("c.csv")).unwrap();
    let runs = read_inputs_with(std::slice::from_ref(&d), ReadOptions { repair_samples: false, threads: 2 }).unwrap();
    assert_eq!(runs.iter().map(|r| r.name()).collect::<Vec<_>>(), ["a.csv", "d.csv"], "in the files' order");
}

#[test]
fn the_cli_exits_non_zero_and_leaves_out_untouched_on_bad_input() {
    let d = tmp("calib-data-cli");
    let bad = d.join("bad.csv");
    std::fs::write(&bad, GOOD.replace("0.002,0.002,0.0011", "0.002,0.002,oops")).unwrap();
    let out = d.join("out");
    let r = std::process::Command::new(env!("CARGO_BIN_EXE_thermovia"))
        .args(["calibrate", bad.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!r.status.success());
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(stderr.contains("bad.csv:7:3"), "{stderr}");
    assert!(!out.exists(), "nothing may be written into --out");
    let leftovers: Vec<_> = std::fs::read_dir(&d).unwrap().filter_map(|e| e.ok()).map(|e| e.file_name()).collect();
    assert_eq!(leftovers.len(), 1, "no temporary folder may remain: {leftovers:?}");
}

/// `link_mass_kg` is used or refused, never silently ignored: with `link_length_m` it is the
/// point-mass inertia m·l² (a declared inertia wins); without the length the file is refused at
/// the mass's own line.
#[test]
fn a_declared_link_mass_becomes_an_inertia_or_is_refused() {
    let with_length = GOOD.replacen("# source=test\n", "# source=test\n# link_mass_kg=0.91\n# link_length_m=0.14\n", 1);
    let r = parse_run(Path::new("m.csv"), &with_length).unwrap();
    assert!((r.link_inertia.unwrap() - 0.91 * 0.14 * 0.14).abs() < 1e-15);
    assert!(r.inertia_from_mass);
    let declared = with_length.replacen("# source=test\n", "# source=test\n# link_inertia_kgm2=0.02\n", 1);
    let r = parse_run(Path::new("m.csv"), &declared).unwrap();
    assert_eq!(r.link_inertia, Some(0.02));
    assert!(!r.inertia_from_mass);
    let e = err(&GOOD.replacen("# source=test\n", "# source=test\n# link_mass_kg=0.91\n", 1));
    assert_eq!(e.line, Some(3), "{e}");
    assert!(e.to_string().contains("link_length_m"), "{e}");
}

/// A run of `n` samples at `rate` Hz of a 0.5 Hz sine through a stiff link, with small
/// deterministic noise, as CSV text (line 5 holds sample 0).
fn sine_run(n: usize, rate: f64, time_of: impl Fn(usize) -> f64) -> String {
    let mut text =
        String::from("# temperature_c=40\n# frequency_hz=0.5\n# source=test\ntime_s,motor_angle_rad,link_angle_rad\n");
    for k in 0..n {
        let t = time_of(k);
        let tk = k as f64 / rate;
        let noise = 1e-5 * ((k * 7919 % 13) as f64 - 6.0) / 6.0;
        let m = 0.3 * (std::f64::consts::TAU * 0.5 * tk).sin();
        let l = 0.29 * (std::f64::consts::TAU * 0.5 * tk - 0.05).sin() + noise;
        text += &format!("{t:.9},{m:.9},{l:.9}\n");
    }
    text
}

fn even(rate: f64) -> impl Fn(usize) -> f64 {
    move |k| k as f64 / rate
}

/// Replaces the link cell of sample `k` (file line k + 5).
fn with_link(text: &str, k: usize, value: &str) -> String {
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let cells: Vec<&str> = lines[k + 4].split(',').collect();
    lines[k + 4] = format!("{},{},{value}", cells[0], cells[1]);
    lines.join("\n") + "\n"
}

/// Issue 28's corrupt samples: 1e300 (outside any physical range), a 1e6 rad spike and an encoder
/// wrap are refused before any fit, naming file, line and column; a spike and a wrap are repaired
/// with the option and listed.
#[test]
fn corrupt_samples_are_refused_by_line_and_column_or_repaired_on_request() {
    use thermovia_tools::calibrate::data::parse_run_with;
    let good = sine_run(2000, 1000.0, even(1000.0));
    parse_run(Path::new("good.csv"), &good).expect("a clean run has no findings");
    let e = err(&with_link(&good, 700, "1e300"));
    assert_eq!((e.line, e.column.clone()), (Some(705), Some((3, "link_angle_rad".into()))), "{e}");
    assert!(e.to_string().contains("1.0000e300") && e.to_string().len() < 300, "short, not 301 digits: {e}");
    let e = err(&with_link(&good, 900, "1000000"));
    assert_eq!(e.line, Some(905), "{e}");
    assert!(e.message.contains("spike") && e.message.contains("--repair-samples"), "{e}");
    // an encoder wrap: one turn added from sample 1200 on
    let mut wrapped = good.clone();
    for k in 1200..2000 {
        let cells: Vec<String> = wrapped.lines().nth(k + 4).unwrap().split(',').map(String::from).collect();
        let v: f64 = cells[2].parse().unwrap();
        wrapped = with_link(&wrapped, k, &format!("{:.9}", v + std::f64::consts::TAU));
    }
    let e = err(&wrapped);
    assert_eq!(e.line, Some(1205), "{e}");
    assert!(e.message.contains("encoder wrap") && e.message.contains("1 turn"), "{e}");
    // repaired on request: both, by line, and the repaired run matches the clean one
    let both = with_link(&wrapped, 900, "1000000");
    let clean = parse_run(Path::new("good.csv"), &good).unwrap();
    let r = parse_run_with(Path::new("both.csv"), &both, ReadOptions { repair_samples: true, threads: 1 }).unwrap();
    let found: Vec<(usize, &str)> = r.repairs.iter().map(|p| (p.line, p.kind.name())).collect();
    assert_eq!(found, vec![(905, "spike"), (1205, "encoder_wrap")]);
    let worst = r.link.iter().zip(&clean.link).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
    assert!(worst < 1e-4, "repaired within the noise: {worst}");
}

/// A gap splits a run into segments, each from its own first sample; the gaps are listed by line.
#[test]
fn a_gap_splits_the_run_and_is_listed() {
    let d = tmp("calib-data-gap");
    // 0.25 s missing after sample 999 (samples 1000..1249 dropped)
    let text = sine_run(3000, 1000.0, even(1000.0));
    let kept: Vec<&str> = text.lines().enumerate().filter(|(i, _)| !(1004..1254).contains(i)).map(|(_, l)| l).collect();
    std::fs::write(d.join("gap.csv"), kept.join("\n") + "\n").unwrap();
    let runs = read_inputs(&[d.join("gap.csv")]).unwrap();
    assert_eq!(runs.len(), 2);
    assert_eq!((runs[0].time.len(), runs[1].time.len()), (1000, 1750));
    assert_eq!(runs[1].time[0], 1.25);
    assert_eq!(runs[1].gaps.len(), 1);
    assert_eq!(runs[1].gaps[0].line, 1005, "the first sample after the gap");
    assert!(runs[1].name().contains("segment 2 of 2"), "{}", runs[1].name());
}

/// Every segment after a gap carries the file's thermocouple before it (for a lagged PCL), in
/// kelvin, and the segments share one copy of it: a log with many gaps does not hold its past once
/// per segment.
#[test]
fn segments_share_one_copy_of_the_thermocouple_before_them() {
    let d = tmp("calib-data-gaps-history");
    // two gaps: samples 1000..1249 and 2000..2099 dropped
    let text = sine_run(3000, 1000.0, even(1000.0));
    let dropped = |i: usize| (1004..1254).contains(&i) || (2004..2104).contains(&i);
    let kept: Vec<&str> = text.lines().enumerate().filter(|&(i, _)| !dropped(i)).map(|(_, l)| l).collect();
    std::fs::write(d.join("gaps.csv"), kept.join("\n") + "\n").unwrap();
    let runs = read_inputs(&[d.join("gaps.csv")]).unwrap();
    assert_eq!(runs.len(), 3);
    let lengths: Vec<usize> = runs.iter().map(|r| r.thermocouple_before.samples().len()).collect();
    assert_eq!(lengths, vec![0, 1000, 1750], "every sample of the file before the segment");
    let (second, third) = (runs[1].thermocouple_before.samples(), runs[2].thermocouple_before.samples());
    assert_eq!(second.as_ptr(), third.as_ptr(), "one copy for the file");
    assert_eq!(&third[..1000], second);
    let file_time: Vec<f64> = runs[0].time.iter().chain(&runs[1].time).copied().collect();
    let file_c: Vec<f64> = runs[0].temperature_c.iter().chain(&runs[1].temperature_c).copied().collect();
    for (k, &(t, kelvin)) in third.iter().enumerate() {
        assert_eq!(t, file_time[k]);
        assert!((kelvin - (file_c[k] + 273.15)).abs() < 1e-9, "sample {k}: {kelvin} K against {} °C", file_c[k]);
    }
}

/// A position that jumps faster than the FMU's speed range (a unit slip, a corrupt stretch) is
/// refused at its line and column as the file is read, not by the FMU in the middle of a fit.
#[test]
fn a_jump_beyond_the_fmus_speed_range_is_refused_at_its_line() {
    let good = sine_run(2000, 1000.0, even(1000.0));
    let shifted: Vec<String> = good
        .lines()
        .enumerate()
        .map(|(i, l)| {
            let mut cells: Vec<String> = l.split(',').map(String::from).collect();
            if i >= 504 {
                cells[2] = format!("{}", cells[2].parse::<f64>().unwrap() + 50.0);
            }
            cells.join(",")
        })
        .collect();
    let e = err(&(shifted.join("\n") + "\n"));
    assert_eq!((e.line, e.column.as_ref().map(|c| c.0)), (Some(505), Some(3)), "{e}");
    assert!(e.message.contains("a speed beyond the FMU's ±1e4 per second"), "{e}");
}

/// A run whose gaps leave no stretch long enough to fit is refused by name, never passed on empty
/// (it reached the fit as no samples and panicked there).
#[test]
fn a_run_that_gaps_leave_without_a_segment_is_refused() {
    let d = tmp("calib-data-gap-all");
    // 3 samples every 50 ms at 1 kHz: every stretch between gaps is 3 samples long
    let text = sine_run(3000, 1000.0, even(1000.0));
    // the four lines of metadata and header, then the data's lines 50–52, 100–102, …
    let kept: Vec<&str> = text.lines().enumerate().filter(|(i, _)| *i < 4 || i % 50 < 3).map(|(_, l)| l).collect();
    std::fs::write(d.join("sparse.csv"), kept.join("\n") + "\n").unwrap();
    let e = read_inputs(&[d.join("sparse.csv")]).unwrap_err();
    assert!(e.to_string().contains("sparse.csv") && e.to_string().contains("no segment to fit"), "{e}");
    assert!(e.to_string().contains("at most 3 samples"), "{e}");
}

/// Timestamps that jitter around a uniform clock while the samples were taken on it: the clock is
/// used (the positions are smoother there). Samples really taken unevenly: the stamps stay.
#[test]
fn the_time_base_is_the_clock_or_the_stamps_as_the_positions_show() {
    let d = tmp("calib-data-jitter");
    let jitter = |k: usize| 0.15e-3 * (((k * 2654435761) % 1000) as f64 / 500.0 - 1.0);
    // stamps off the clock, values on it
    std::fs::write(d.join("stamps.csv"), sine_run(4000, 1000.0, |k| k as f64 / 1000.0 + jitter(k))).unwrap();
    let r = &read_inputs(&[d.join("stamps.csv")]).unwrap()[0];
    assert!(r.time_base.as_deref().unwrap_or("").contains("clock's times are used"), "{:?}", r.time_base);
    assert!((r.time[1234] - 1.234).abs() < 1e-6, "the clock to jitter/√n: {}", r.time[1234]);
    // values at the stamps: the stamps are right
    let mut text = String::from("# temperature_c=40\n# frequency_hz=0.5\ntime_s,motor_angle_rad,link_angle_rad\n");
    for k in 0..4000 {
        let t = k as f64 / 1000.0 + jitter(k);
        let m = 0.3 * (std::f64::consts::TAU * 0.5 * t).sin();
        text += &format!("{t:.9},{m:.9},{:.9}\n", 0.29 * (std::f64::consts::TAU * 0.5 * t - 0.05).sin());
    }
    std::fs::write(d.join("uneven.csv"), text).unwrap();
    let r = &read_inputs(&[d.join("uneven.csv")]).unwrap()[0];
    assert!(r.time_base.as_deref().unwrap_or("").contains("logged times are used"), "{:?}", r.time_base);
}

/// A corrupt cell stops `calibrate` while reading: the error names the cell, not the FMU (none is
/// needed to refuse it), and nothing is written.
#[test]
fn the_cli_refuses_a_corrupt_sample_before_any_fit() {
    let d = tmp("calib-data-corrupt");
    let f = d.join("spike.csv");
    std::fs::write(&f, with_link(&sine_run(2000, 1000.0, even(1000.0)), 500, "1e300")).unwrap();
    let out = d.join("out");
    let r = std::process::Command::new(env!("CARGO_BIN_EXE_thermovia"))
        .args(["calibrate", f.to_str().unwrap(), "--out", out.to_str().unwrap(), "--fmu", "/nonexistent.fmu"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&r.stderr);
    assert!(!r.status.success());
    assert!(stderr.contains("spike.csv:505:3"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "one line, no backtrace: {stderr}");
    assert!(!out.exists());
}

/// No file makes the reader panic: 400 mutations of a good run (lines dropped, repeated or swapped,
/// cells replaced by garbage, text cut short, bytes flipped), each read through `read_inputs` (the
/// split at gaps and the time base's choice included) must end in runs a fit can take or in an
/// error that names the file (on this seed about 80 end in runs, a fifth of them split at gaps).
#[test]
fn mutated_files_end_in_runs_or_an_error_naming_the_file_never_a_panic() {
    let d = tmp("calib-data-mutations");
    let good = sine_run(600, 1000.0, even(1000.0));
    let lines: Vec<&str> = good.lines().collect();
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move |n: usize| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state % n as u64) as usize
    };
    let garbage = ["", "nan", "inf", "-inf", "1e308", "-1e308", "x", "0x10", "1,2", "\"3\"", " ", "1e-320", "--1"];
    for case in 0..400 {
        let mut l: Vec<String> = lines.iter().map(|s| s.to_string()).collect();
        for _ in 0..1 + next(4) {
            let k = next(l.len());
            match next(6) {
                0 => {
                    let drop = 1 + next(60);
                    l.drain(k..(k + drop).min(l.len()));
                }
                1 => l.insert(k, l[k].clone()),
                2 => {
                    let j = next(l.len());
                    l.swap(k, j)
                }
                3 => {
                    let mut cells: Vec<String> = l[k].split(',').map(String::from).collect();
                    let c = next(cells.len());
                    cells[c] = garbage[next(garbage.len())].to_string();
                    l[k] = cells.join(",");
                }
                4 => l.truncate(k.max(1)),
                _ => {
                    let mut bytes = l[k].clone().into_bytes();
                    if !bytes.is_empty() {
                        let b = next(bytes.len());
                        bytes[b] = b"0123456789.-e#,= "[next(17)];
                    }
                    l[k] = String::from_utf8(bytes).unwrap();
                }
            }
            if l.is_empty() {
                break;
            }
        }
        let f = d.join(format!("m{case}.csv"));
        std::fs::write(&f, l.join("\n") + "\n").unwrap();
        match read_inputs(std::slice::from_ref(&f)) {
            // what is read is fit to fit: increasing times, finite values, enough samples
            Ok(runs) => assert!(
                runs.iter().all(|r| r.time.len() >= 3
                    && r.time.windows(2).all(|w| w[1] > w[0])
                    && r.motor.iter().chain(&r.link).all(|x| x.is_finite())),
                "case {case}: a run no fit can take"
            ),
            Err(e) => assert!(e.to_string().starts_with(f.to_str().unwrap()), "case {case}: {e}"),
        }
    }
}
