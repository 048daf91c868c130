//! One source of truth: the checked-in modelDescription, the README table and the packaged FMU all
//! equal what the variable table generates, and the binary uses the start values it declares.

mod common;

use std::io::Read;

use thermovia_fmu::description::{guid, model_description};
use thermovia_fmu::variables::{markdown_table, Causality, VARIABLES};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
const REFRESH: &str = "run `cargo run -p fmu-build -- --sync-docs` and commit the result";

#[test]
fn checked_in_model_description_equals_the_generated_one() {
    let path = format!("{ROOT}/modelDescription/ThermoVIA.xml");
    let on_disk = std::fs::read_to_string(&path).unwrap();
    assert!(on_disk == model_description(), "{path} differs from the code: {REFRESH}");
}

#[test]
fn readme_variable_table_equals_the_generated_one() {
    let readme = std::fs::read_to_string(format!("{ROOT}/README.md")).unwrap();
    let begin = readme.find("<!-- variables:begin").expect("README marker");
    let body_start = begin + readme[begin..].find('\n').unwrap() + 1;
    let end = readme.find("<!-- variables:end -->").expect("README marker");
    assert!(readme[body_start..end] == markdown_table(), "README variable table differs from the code: {REFRESH}");
}

#[test]
fn packaged_archive_has_the_standard_layout_and_this_builds_description() {
    let file = std::fs::File::open(common::fmu_path()).expect("cargo run --release -p fmu-build");
    let mut zip = zip::ZipArchive::new(file).unwrap();
    let names: Vec<String> = zip.file_names().map(str::to_string).collect();
    for needed in ["modelDescription.xml", "binaries/linux64/ThermoVIA.so", "documentation/index.html"] {
        assert!(names.iter().any(|n| n == needed), "{needed} missing from {names:?}");
    }
    let mut xml = String::new();
    zip.by_name("modelDescription.xml").unwrap().read_to_string(&mut xml).unwrap();
    assert!(xml == model_description(), "the packaged FMU is stale: rerun `cargo run --release -p fmu-build`");
    assert!(xml.contains(&format!("guid=\"{}\"", guid())));
}

#[test]
fn structure_indices_point_at_outputs_and_every_unit_is_defined() {
    let fmu = common::fmu();
    let md = &fmu.description;
    let xml = model_description();
    let outputs: Vec<usize> =
        md.variables.iter().enumerate().filter(|(_, v)| v.causality == "output").map(|(i, _)| i + 1).collect();
    let section = &xml[xml.find("<Outputs>").unwrap()..xml.find("</Outputs>").unwrap()];
    let listed: Vec<usize> =
        section.split("index=\"").skip(1).map(|s| s[..s.find('"').unwrap()].parse().unwrap()).collect();
    assert_eq!(listed, outputs);
    // FMI 2.0: InitialUnknowns are exactly the outputs and the calculated parameters
    let initial: Vec<usize> = md
        .variables
        .iter()
        .enumerate()
        .filter(|(_, v)| v.causality == "output" || v.causality == "calculatedParameter")
        .map(|(i, _)| i + 1)
        .collect();
    assert!(initial.len() > outputs.len(), "the FMU declares calculated parameters");
    let section = &xml[xml.find("<InitialUnknowns>").unwrap()..xml.find("</InitialUnknowns>").unwrap()];
    let listed: Vec<usize> =
        section.split("index=\"").skip(1).map(|s| s[..s.find('"').unwrap()].parse().unwrap()).collect();
    assert_eq!(listed, initial);
    for v in &md.variables {
        if let Some(u) = &v.unit {
            assert!(xml.contains(&format!("<Unit name=\"{u}\">")), "unit {u} of {} is not defined", v.name);
        }
    }
}

#[test]
fn start_values_are_what_the_binary_uses() {
    let fmu = common::fmu();
    let mut inst = fmu.instantiate(None).unwrap();
    inst.initialize(0.0, None, &[]).unwrap();
    for v in
        fmu.description.variables.iter().filter(|v| v.causality != "output" && v.causality != "calculatedParameter")
    {
        let declared: f64 = v.start.as_ref().unwrap_or_else(|| panic!("{} has no start", v.name)).parse().unwrap();
        let used = inst.get(&v.name).unwrap();
        assert_eq!(declared, used, "{}", v.name);
    }
    assert_eq!(VARIABLES.iter().filter(|v| v.causality == Causality::Output).count(), 17);
}

#[test]
fn the_binary_needs_nothing_beyond_the_system_c_library() {
    let so = std::env::temp_dir().join(format!("thermovia-needed-{}.so", std::process::id()));
    let mut zip = zip::ZipArchive::new(std::fs::File::open(common::fmu_path()).unwrap()).unwrap();
    let mut bytes = Vec::new();
    zip.by_name("binaries/linux64/ThermoVIA.so").unwrap().read_to_end(&mut bytes).unwrap();
    std::fs::write(&so, bytes).unwrap();
    let out = std::process::Command::new("readelf").arg("-d").arg(&so).output().expect("readelf (binutils)");
    let _ = std::fs::remove_file(&so);
    let text = String::from_utf8_lossy(&out.stdout);
    let needed: Vec<&str> = text
        .lines()
        .filter(|l| l.contains("(NEEDED)"))
        .filter_map(|l| l.split('[').nth(1)?.split(']').next())
        .collect();
    assert!(!needed.is_empty(), "readelf found no NEEDED entries: {text}");
    for lib in needed {
        assert!(
            ["libc.so.6", "libm.so.6", "libgcc_s.so.1", "libpthread.so.0", "libdl.so.2", "ld-linux-x86-64.so.2"]
                .contains(&lib),
            "unexpected runtime dependency {lib}"
        );
    }
}
