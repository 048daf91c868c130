//! A second, independent importer: the `fmi` crate (rust-fmi) parses modelDescription.xml with its
//! own schema and drives the binary through its own bindings. The trajectory must be bit-identical
//! to the one this crate's harness produces.

mod common;

use fmi::fmi2::import::Fmi2Import;
use fmi::fmi2::instance::{CoSimulation, Common};
use fmi::traits::FmiImport;

const STEP: f64 = 1e-3;
const STEPS: usize = 2000;

fn torque(k: usize) -> f64 {
    (2.0 * std::f64::consts::PI * 1.3 * k as f64 * STEP).sin()
}

#[test]
fn the_fmi_crate_reads_the_description_and_steps_the_binary_bit_identically() {
    let import: Fmi2Import = fmi::import::from_path(common::fmu_path()).expect("rust-fmi opens the FMU");
    let md = import.model_description();
    assert_eq!(md.fmi_version, "2.0");
    assert_eq!(md.guid, thermovia_fmu::description::guid());
    assert_eq!(md.co_simulation.as_ref().expect("CoSimulation").model_identifier, "ThermoVIA");
    let vr = |name: &str| {
        md.get_model_variables().find(|v| v.name == name).unwrap_or_else(|| panic!("{name}")).value_reference
    };
    let (torque_vr, heater_vr, link_vr) = (vr("motor_torque"), vr("heater_power"), vr("link_angle"));
    assert_eq!(md.get_model_variables().count(), thermovia_fmu::variables::VARIABLES.len());

    let mut inst = import.instantiate_cs("second_importer", false, true).expect("instantiate");
    inst.setup_experiment(None, 0.0, None).unwrap();
    inst.enter_initialization_mode().unwrap();
    inst.set_real(&[heater_vr], &[9.0]).unwrap();
    inst.exit_initialization_mode().unwrap();
    let mut theirs = Vec::with_capacity(STEPS);
    for k in 0..STEPS {
        inst.set_real(&[torque_vr], &[torque(k)]).unwrap();
        inst.do_step(k as f64 * STEP, STEP, true).unwrap();
        let mut out = [0.0];
        inst.get_real(&[link_vr], &mut out).unwrap();
        theirs.push(out[0]);
    }
    // Refused, not crashed, through their bindings too.
    assert!(inst.set_real(&[heater_vr], &[-1.0]).is_err());

    let fmu = common::fmu();
    let mut ours = fmu.instantiate(None).unwrap();
    ours.initialize(0.0, None, &[("heater_power", 9.0)]).unwrap();
    let mine: Vec<f64> = (0..STEPS)
        .map(|k| {
            ours.set("motor_torque", torque(k)).unwrap();
            ours.step(STEP).unwrap();
            ours.get("link_angle").unwrap()
        })
        .collect();
    assert!(mine.iter().any(|x| x.abs() > 0.05), "the run moves");
    if let Some(k) = (0..STEPS).find(|&k| theirs[k] != mine[k]) {
        panic!("first difference at step {k}: rust-fmi {} vs harness {}", theirs[k], mine[k]);
    }
}
