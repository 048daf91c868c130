//! The importer harness on the packaged FMU: clear errors for broken archives, missing symbols and
//! unknown names; several independent instances side by side.

mod common;

use std::io::Write;
use std::path::{Path, PathBuf};

use thermovia_importer::{Fmu, HarnessError};

fn packaged() -> Fmu {
    common::fmu()
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("thermovia-harness-test-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

/// A zip holding the given (archive path, bytes) entries.
fn write_zip(path: &Path, entries: &[(&str, Vec<u8>)]) {
    let mut z = zip::ZipWriter::new(std::fs::File::create(path).unwrap());
    for (name, bytes) in entries {
        z.start_file(*name, zip::write::SimpleFileOptions::default()).unwrap();
        z.write_all(bytes).unwrap();
    }
    z.finish().unwrap();
}

fn description_xml() -> Vec<u8> {
    std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("modelDescription/ThermoVIA.xml")).unwrap()
}

fn open_err(path: &Path) -> HarnessError {
    let r = Fmu::open(path);
    let _ = std::fs::remove_file(path);
    match r {
        Ok(_) => panic!("{} opened", path.display()),
        Err(e) => e,
    }
}

#[test]
fn missing_file_is_reported_with_the_build_command() {
    let p = scratch("does-not-exist.fmu");
    let e = open_err(&p);
    assert!(matches!(e, HarnessError::Archive { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.contains("does-not-exist.fmu") && msg.contains("no such file") && msg.contains("fmu-build"), "{msg}");
}

#[test]
fn a_file_that_is_not_a_zip_is_reported_as_not_an_fmu() {
    let p = scratch("corrupt.fmu");
    std::fs::write(&p, b"this is not a zip archive at all").unwrap();
    let e = open_err(&p);
    assert!(matches!(e, HarnessError::Archive { .. }), "{e:?}");
    assert!(e.to_string().contains("not a valid FMU (zip) archive"), "{e}");
}

#[test]
fn a_truncated_fmu_is_reported() {
    let bytes = std::fs::read(common::fmu_path()).expect("packaged FMU");
    let p = scratch("truncated.fmu");
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    let e = open_err(&p);
    assert!(matches!(e, HarnessError::Archive { .. }), "{e:?}");
}

#[test]
fn a_zip_without_the_binary_names_the_missing_file() {
    let p = scratch("no-binary.fmu");
    write_zip(&p, &[("modelDescription.xml", description_xml())]);
    let e = open_err(&p);
    assert!(e.to_string().contains("no binaries/linux64/ThermoVIA.so"), "{e}");
}

#[test]
fn a_zip_without_model_description_is_reported() {
    let p = scratch("no-description.fmu");
    write_zip(&p, &[("resources/readme.txt", b"nothing".to_vec())]);
    let e = open_err(&p);
    assert!(matches!(e, HarnessError::Description { .. }), "{e:?}");
    assert!(e.to_string().contains("modelDescription.xml"), "{e}");
}

#[test]
fn a_binary_without_the_fmi_symbols_names_the_missing_symbol() {
    // Any real shared library that is not an FMU: the C maths library.
    let libm = ["/lib/x86_64-linux-gnu/libm.so.6", "/usr/lib/x86_64-linux-gnu/libm.so.6", "/lib64/libm.so.6"]
        .iter()
        .find(|p| Path::new(p).exists())
        .expect("libm present on linux64");
    let p = scratch("no-symbols.fmu");
    write_zip(
        &p,
        &[("modelDescription.xml", description_xml()), ("binaries/linux64/ThermoVIA.so", std::fs::read(libm).unwrap())],
    );
    let e = open_err(&p);
    assert!(matches!(e, HarnessError::Library { .. }), "{e:?}");
    assert!(e.to_string().contains("missing symbol fmi2"), "{e}");
}

#[test]
fn unknown_variable_names_are_errors_with_suggestions() {
    let fmu = packaged();
    assert!(fmu.variable("link_inertia").is_ok());
    let mut inst = fmu.instantiate(None).unwrap();
    let e = inst.set("link_inertai", 0.02).unwrap_err();
    match &e {
        HarnessError::UnknownVariable { name, close } => {
            assert_eq!(name, "link_inertai");
            assert!(close.iter().any(|c| c == "link_inertia"), "{close:?}");
        }
        other => panic!("{other:?}"),
    }
    assert!(e.to_string().contains("did you mean"), "{e}");
    inst.initialize(0.0, None, &[]).unwrap();
    assert!(matches!(inst.get("no_such_output"), Err(HarnessError::UnknownVariable { .. })));
    assert!(matches!(inst.handle("motor_angel"), Err(HarnessError::UnknownVariable { .. })));
}

#[test]
fn variables_are_listed_by_name_from_the_description() {
    let fmu = packaged();
    let names: Vec<&str> = fmu.description.variables.iter().map(|v| v.name.as_str()).collect();
    for n in ["heater_power", "motor_torque", "load_torque", "link_angle", "housing_temperature", "effective_stiffness"]
    {
        assert!(names.contains(&n), "{n} missing from {names:?}");
    }
    assert_eq!(fmu.variable("motor_torque").unwrap().causality, "input");
}

/// Runs an instance with a torque step and returns the link angle trajectory.
fn torque_step(inst: &mut thermovia_importer::Instance, steps: usize) -> Vec<f64> {
    let vr = inst.handle("link_angle").unwrap();
    inst.set("motor_torque", 0.4).unwrap();
    (0..steps)
        .map(|_| {
            inst.step(1e-3).unwrap();
            inst.get_handle(vr).unwrap()
        })
        .collect()
}

#[test]
fn two_instances_side_by_side_keep_their_own_parameters_and_state() {
    let fmu = packaged();
    let mut a = fmu.instantiate(Some("light")).unwrap();
    let mut b = fmu.instantiate(Some("heavy")).unwrap();
    a.initialize(0.0, None, &[("link_inertia", 0.018)]).unwrap();
    b.initialize(
        0.0,
        None,
        &[("link_inertia", 0.072), ("initial_pcl_temperature", 333.15), ("initial_housing_temperature", 333.15)],
    )
    .unwrap();
    assert_eq!(a.get("link_inertia").unwrap(), 0.018);
    assert_eq!(b.get("link_inertia").unwrap(), 0.072);
    // interleaved stepping
    let (va, vb) = (a.handle("link_angle").unwrap(), b.handle("link_angle").unwrap());
    a.set("motor_torque", 0.4).unwrap();
    b.set("motor_torque", 0.4).unwrap();
    let mut ta = Vec::new();
    let mut tb = Vec::new();
    for _ in 0..300 {
        a.step(1e-3).unwrap();
        b.step(1e-3).unwrap();
        ta.push(a.get_handle(va).unwrap());
        tb.push(b.get_handle(vb).unwrap());
    }
    // B cools slowly towards the 22 °C ambient; A stays at room temperature
    assert!((b.get("pcl_temperature").unwrap() - 333.15).abs() < 0.05);
    assert!((a.get("pcl_temperature").unwrap() - 295.15).abs() < 1e-6);
    assert!(b.get("effective_stiffness").unwrap() < 0.5 * a.get("effective_stiffness").unwrap());
    // the heavier, softer link lags behind
    assert!(tb[299] < ta[299], "{} vs {}", tb[299], ta[299]);
    // each equals the same instance run alone: no shared state between instances
    let mut solo = fmu.instantiate(None).unwrap();
    solo.initialize(0.0, None, &[("link_inertia", 0.018)]).unwrap();
    assert_eq!(torque_step(&mut solo, 300), ta);
    let mut solo_b = fmu.instantiate(None).unwrap();
    solo_b
        .initialize(
            0.0,
            None,
            &[("link_inertia", 0.072), ("initial_pcl_temperature", 333.15), ("initial_housing_temperature", 333.15)],
        )
        .unwrap();
    assert_eq!(torque_step(&mut solo_b, 300), tb);
}

#[test]
fn two_fmus_opened_at_once_are_independent() {
    let f1 = packaged();
    let f2 = packaged();
    let mut a = f1.instantiate(None).unwrap();
    let mut b = f2.instantiate(None).unwrap();
    a.initialize(0.0, None, &[]).unwrap();
    b.initialize(0.0, None, &[("motor_inertia", 0.01)]).unwrap();
    let ta = torque_step(&mut a, 100);
    let tb = torque_step(&mut b, 100);
    assert_ne!(ta, tb);
    drop(f1);
    // the second FMU still works after the first is dropped (its own unpacked folder)
    b.step(1e-3).unwrap();
}

#[test]
fn save_and_restore_replays_bit_identically() {
    let fmu = packaged();
    let mut a = fmu.instantiate(None).unwrap();
    a.initialize(0.0, None, &[]).unwrap();
    a.set("heater_power", 8.0).unwrap();
    torque_step(&mut a, 50);
    let saved = a.save_state().unwrap();
    let first = torque_step(&mut a, 200);
    a.restore_state(&saved).unwrap();
    assert!((a.time() - 0.05).abs() < 1e-12);
    let again = torque_step(&mut a, 200);
    assert_eq!(first, again);
}
