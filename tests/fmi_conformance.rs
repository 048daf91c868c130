//! FMI 2.0 behaviour of the packaged FMU, exercised through its C API as an importer would
//! (the archive is unpacked and the binary loaded with libloading by the harness).

mod common;

use std::ptr;

use thermovia_fmi2::*;
use thermovia_importer::loader::RawInstance;
use thermovia_importer::model_description::VariableType;
use thermovia_importer::{Fmu, HarnessError, Instance};

fn vr(inst: &Instance, name: &str) -> u32 {
    inst.handle(name).unwrap().value_reference
}

fn last_log(raw: &RawInstance) -> String {
    raw.take_log().into_iter().map(|r| r.message).collect::<Vec<_>>().join(" | ")
}

fn initialized(fmu: &Fmu) -> Instance {
    let mut i = fmu.instantiate(None).unwrap();
    i.initialize(0.0, None, &[]).unwrap();
    i
}

#[test]
fn platform_version_and_all_symbols() {
    let f = common::fmu(); // loading resolves all 34 functions or fails naming the missing one
    assert_eq!(f.library().version(), "2.0");
    assert_eq!(f.library().types_platform(), "default");
}

#[test]
fn wrong_guid_and_bad_arguments_to_instantiate_return_null_with_a_reason() {
    let f = common::fmu();
    let err = RawInstance::instantiate(f.library(), "a", "{00000000-0000-0000-0000-000000000000}", None, false)
        .err()
        .unwrap();
    assert!(err.contains("GUID"), "{err}");
    let guid = f.description.guid.clone();
    let err = RawInstance::instantiate(f.library(), "", &guid, None, false).err().unwrap();
    assert!(err.contains("instanceName"), "{err}");
    let err = RawInstance::instantiate(f.library(), "a", &guid, Some("http://example/x"), false).err().unwrap();
    assert!(err.contains("not a file: URI"), "{err}");
    for uri in ["file:///tmp/x/resources", "file:/tmp/x/resources/", "file:///tmp/a%20b/resources"] {
        assert!(RawInstance::instantiate(f.library(), "a", &guid, Some(uri), false).is_ok(), "{uri}");
    }
    // No callback struct at all: NULL, no crash.
    let api = f.library().api;
    let c =
        unsafe { (api.instantiate)(c"x".as_ptr(), FMI2_CO_SIMULATION, c"g".as_ptr(), ptr::null(), ptr::null(), 0, 0) };
    assert!(c.is_null());
}

#[test]
fn illegal_call_sequences_are_errors_with_a_reason() {
    let f = common::fmu();
    let mut i = f.instantiate(None).unwrap();
    let link = vr(&i, "link_angle");
    let raw = i.raw_mut();
    assert_eq!(raw.do_step(0.0, 1e-3), FMI2_ERROR, "doStep before initialisation");
    assert!(last_log(raw).contains("fmi2DoStep: not allowed in state Instantiated"));
    // After an error only Get*, Reset, FreeInstance and SetFMUstate: initialisation is refused.
    assert_eq!(raw.enter_initialization_mode(), FMI2_ERROR);
    assert!(last_log(raw).contains("state Error"));
    assert_eq!(raw.reset(), FMI2_OK);
    let mut out = [0.0];
    assert_eq!(raw.get_real(&[link], &mut out), FMI2_ERROR, "GetReal before initialisation mode");
    raw.take_log();
    raw.reset();
    assert_eq!(raw.setup_experiment(None, 0.0, None), FMI2_OK);
    assert_eq!(raw.enter_initialization_mode(), FMI2_OK);
    assert_eq!(raw.get_real(&[link], &mut out), FMI2_OK, "GetReal in initialisation mode");
    assert_eq!(raw.setup_experiment(None, 0.0, None), FMI2_ERROR, "setup after enter");
    raw.reset();
    raw.setup_experiment(None, 0.0, None);
    raw.enter_initialization_mode();
    raw.exit_initialization_mode();
    assert_eq!(raw.do_step(0.5, 1e-3), FMI2_ERROR, "t does not match the FMU's time");
    assert!(last_log(raw).contains("does not match"));
    raw.reset();
    raw.setup_experiment(None, 0.0, None);
    raw.enter_initialization_mode();
    raw.exit_initialization_mode();
    assert_eq!(raw.do_step(0.0, 0.0), FMI2_ERROR, "h = 0");
    assert!(last_log(raw).contains("communicationStepSize"));
    raw.reset();
    raw.setup_experiment(None, 0.0, None);
    raw.enter_initialization_mode();
    raw.exit_initialization_mode();
    assert_eq!(raw.terminate(), FMI2_OK);
    assert_eq!(raw.do_step(0.0, 1e-3), FMI2_ERROR, "doStep after terminate");
}

#[test]
fn null_pointers_nan_unknown_references_and_outputs_are_refused() {
    let f = common::fmu();
    let mut i = initialized(&f);
    let heater = vr(&i, "heater_power");
    let inertia = vr(&i, "link_inertia");
    let link = vr(&i, "link_angle");
    let raw = i.raw_mut();
    let (c, api) = raw.raw();
    let api = *api;
    unsafe {
        assert_eq!((api.get_real)(c, [link].as_ptr(), 1, ptr::null_mut()), FMI2_ERROR);
        assert_eq!((api.set_real)(c, ptr::null(), 1, [1.0].as_ptr()), FMI2_ERROR);
        assert_eq!((api.do_step)(ptr::null_mut(), 0.0, 1e-3, 0), FMI2_ERROR);
        assert_eq!((api.get_real_status)(c, FMI2_LAST_SUCCESSFUL_TIME, ptr::null_mut()), FMI2_ERROR);
        (api.free_instance)(ptr::null_mut()); // must not crash
                                              // zero-length requests with null arrays are legal
        assert_eq!((api.get_boolean)(ptr::null_mut(), ptr::null(), 0, ptr::null_mut()), FMI2_ERROR);
    }
    assert!(last_log(raw).contains("null pointer"));
    for (name, vr, value, expect) in [
        ("heater_power", heater, f64::NAN, "not a finite number"),
        ("heater_power", heater, -1.0, "below its minimum"),
        ("link_inertia", inertia, 0.03, "fixed parameter"),
        ("link_angle", link, 1.0, "is an output"),
    ] {
        raw.reset();
        raw.setup_experiment(None, 0.0, None);
        raw.enter_initialization_mode();
        raw.exit_initialization_mode();
        raw.take_log();
        assert_eq!(raw.set_real(&[vr], &[value]), FMI2_ERROR, "{name} = {value}");
        let log = last_log(raw);
        assert!(log.contains(name) && log.contains(expect), "{log}");
    }
    raw.reset();
    raw.setup_experiment(None, 0.0, None);
    let mut out = [0.0];
    raw.enter_initialization_mode();
    assert_eq!(raw.get_real(&[4242], &mut out), FMI2_ERROR);
    assert!(last_log(raw).contains("unknown value reference 4242"));
    raw.reset();
    raw.setup_experiment(None, 0.0, None);
    // A negative inertia is refused before initialisation too, and nothing is half-set.
    let v0 = {
        raw.enter_initialization_mode();
        let mut v = [0.0];
        raw.get_real(&[inertia], &mut v);
        v[0]
    };
    assert_eq!(raw.set_real(&[heater, inertia], &[2.0, -0.1]), FMI2_ERROR);
    assert!(last_log(raw).contains("link_inertia"));
    raw.reset();
    raw.setup_experiment(None, 0.0, None);
    raw.enter_initialization_mode();
    let mut v = [0.0, 0.0];
    raw.get_real(&[heater, inertia], &mut v);
    assert_eq!(v, [0.0, v0]);
}

#[test]
fn a_percent_sign_in_a_message_is_not_a_format() {
    let f = common::fmu();
    let mut i = initialized(&f);
    let raw = i.raw_mut();
    assert_eq!(raw.set_debug_logging(true, &["%s%n%d"]), FMI2_ERROR);
    assert!(last_log(raw).contains("\"%s%n%d\""));
}

#[test]
fn stop_time_discards_the_overshooting_step_and_reports_it() {
    let f = common::fmu();
    let mut i = f.instantiate(None).unwrap();
    i.initialize(0.0, Some(0.0105), &[]).unwrap();
    for _ in 0..10 {
        i.step(1e-3).unwrap();
    }
    match i.step(1e-3) {
        Err(HarnessError::Discarded { time, log }) => {
            assert!((time - 0.0105).abs() < 1e-15, "{time}");
            assert!(log.join(" ").contains("stopTime"));
        }
        other => panic!("expected a discard, got {other:?}"),
    }
    let raw = i.raw_mut();
    assert_eq!(raw.get_boolean_status_terminated(), (FMI2_OK, true));
    assert_eq!(raw.get_real_status_last_successful_time(), (FMI2_OK, 0.0105));
    assert_eq!(raw.terminate(), FMI2_OK);
}

fn run(i: &mut Instance, steps: usize) -> Vec<f64> {
    let (torque, heater, link, pcl) =
        (vr(i, "motor_torque"), vr(i, "heater_power"), vr(i, "link_angle"), vr(i, "pcl_temperature"));
    let mut out = Vec::new();
    for k in 0..steps {
        let t = i.time();
        i.set_reals(&[torque, heater], &[(3.0 * t).sin(), if k % 700 < 350 { 8.0 } else { 0.0 }]).unwrap();
        i.step(1e-3).unwrap();
        let mut v = [0.0, 0.0];
        i.get_reals(&[link, pcl], &mut v).unwrap();
        out.extend(v);
    }
    out
}

#[test]
fn reset_returns_to_the_state_after_instantiation() {
    let f = common::fmu();
    let mut fresh = f.instantiate(None).unwrap();
    fresh.initialize(0.0, None, &[]).unwrap();
    let expected = run(&mut fresh, 2000);
    let mut i = f.instantiate(None).unwrap();
    i.initialize(0.0, Some(5.0), &[("link_inertia", 0.05), ("material_table", 2.0)]).unwrap();
    run(&mut i, 1500);
    i.reset().unwrap();
    i.initialize(0.0, None, &[]).unwrap();
    assert_eq!(i.get("link_inertia").unwrap(), 0.018);
    assert_eq!(i.get("material_table").unwrap(), 1.0);
    assert_eq!(run(&mut i, 2000), expected, "bit-identical after reset");
}

#[test]
fn fmu_state_restores_and_serializes_bit_identically() {
    let f = common::fmu();
    let mut a = initialized(&f);
    run(&mut a, 1000);
    let saved = a.save_state().unwrap();
    let continued = run(&mut a, 1500);
    a.restore_state(&saved).unwrap();
    assert_eq!(run(&mut a, 1500), continued, "GetFMUstate/SetFMUstate");
    let bytes = a.serialize_state(&saved).unwrap();

    let mut b = initialized(&f);
    let restored = b.deserialize_state(&bytes, saved.time).unwrap();
    b.restore_state(&restored).unwrap();
    assert_eq!(run(&mut b, 1500), continued, "serialized into a fresh instance");

    // Truncated, altered and foreign bytes are refused with a reason.
    for (bad, why) in [
        (bytes[..bytes.len() - 3].to_vec(), "length"),
        (
            {
                let mut x = bytes.clone();
                let n = x.len();
                x[n - 20] ^= 1;
                x
            },
            "checksum",
        ),
        (b"not a state at all, just bytes".to_vec(), "magic"),
        (
            {
                let mut x = bytes.clone();
                x[20] ^= 0x20;
                x
            },
            "GUID",
        ),
    ] {
        let err = b.deserialize_state(&bad, 0.0).err().expect(why).to_string();
        assert!(err.contains(why), "{why}: {err}");
        b.reset().unwrap();
    }
}

#[test]
fn two_instances_with_different_parameters_in_parallel_threads_do_not_interfere() {
    let f = common::fmu();
    let configs: [&[(&str, f64)]; 2] = [&[("link_inertia", 0.018)], &[("link_inertia", 0.04), ("material_table", 3.0)]];
    let sequential: Vec<Vec<f64>> = configs
        .iter()
        .map(|p| {
            let mut i = f.instantiate(None).unwrap();
            i.initialize(0.0, None, p).unwrap();
            run(&mut i, 3000)
        })
        .collect();
    assert_ne!(sequential[0], sequential[1]);
    let parallel: Vec<Vec<f64>> = std::thread::scope(|s| {
        let handles: Vec<_> = configs
            .iter()
            .map(|p| {
                let mut i = f.instantiate(None).unwrap();
                i.initialize(0.0, None, p).unwrap();
                s.spawn(move || run(&mut i, 3000))
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert_eq!(parallel, sequential);
}

#[test]
fn unsupported_capabilities_exist_and_say_so() {
    let f = common::fmu();
    let mut i = initialized(&f);
    let raw = i.raw_mut();
    let (c, api) = raw.raw();
    let api = *api;
    let mut x = 0.0;
    unsafe {
        assert_eq!(
            (api.get_directional_derivative)(c, ptr::null(), 0, ptr::null(), 0, ptr::null(), &mut x),
            FMI2_ERROR
        );
    }
    assert!(last_log(raw).contains("providesDirectionalDerivative"));
    raw.reset();
    raw.setup_experiment(None, 0.0, None);
    raw.enter_initialization_mode();
    raw.exit_initialization_mode();
    unsafe {
        assert_eq!((api.cancel_step)(c), FMI2_ERROR);
    }
    assert!(last_log(raw).contains("synchronous"));
}

#[test]
fn variable_communication_steps_give_the_same_trajectory() {
    // Inputs held constant: splitting a step changes nothing but rounding, whatever the split.
    let f = common::fmu();
    let trace = |steps: &[f64]| -> Vec<f64> {
        let mut i = initialized(&f);
        i.set("motor_torque", 0.7).unwrap();
        i.set("heater_power", 6.0).unwrap();
        let mut out = Vec::new();
        for _ in 0..200 {
            for &h in steps {
                i.step(h).unwrap();
            }
            out.push(i.get("link_angle").unwrap());
            out.push(i.get("pcl_temperature").unwrap());
        }
        out
    };
    let uniform = trace(&[1e-3, 1e-3, 1e-3, 1e-3]);
    let uneven = trace(&[0.3e-3, 1.7e-3, 0.25e-3, 1.75e-3]);
    let coarse = trace(&[4e-3]);
    for other in [&uneven, &coarse] {
        let err = uniform.iter().zip(other.iter()).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        assert!(err < 1e-9, "max difference {err:e}");
    }
    assert!(uniform[uniform.len() - 2].abs() > 0.1, "the link moved");
}

/// Reliability (issue 13): every call returns in bounded time; a step whose work would exceed the
/// budget is discarded at once with the reason, the state kept at the last successful time.
#[test]
fn huge_steps_and_extreme_legal_values_are_refused_or_stay_in_budget() {
    let f = common::fmu();
    for h in [1e6, 1e10, 1e300, f64::MAX] {
        let mut i = initialized(&f);
        match i.step(h) {
            Err(HarnessError::Discarded { time, log }) => {
                assert_eq!(time, 0.0, "h = {h}");
                assert!(log.join(" ").contains("budget"), "h = {h}: {log:?}");
            }
            other => panic!("h = {h}: expected a discard, got {other:?}"),
        }
    }
    // The audit's hangs: the largest legal stiffness and spring count; the smallest internal step.
    // Each step completes or is discarded for its work budget (tests/physics.rs counts the work;
    // the time it takes is a benchmark's business, not a test's).
    let extremes = [("spring_count", 1e3), ("spring_stiffness", 1e7), ("max_internal_step", 1e-7)];
    for (name, x) in extremes {
        let mut i = f.instantiate(None).unwrap();
        i.initialize(0.0, None, &[(name, x)]).unwrap();
        match i.step(1.0) {
            Ok(_) => {}
            Err(HarnessError::Discarded { log, .. }) => {
                assert!(log.join(" ").contains("budget"), "{name} = {x}: {log:?}")
            }
            Err(e) => panic!("{name} = {x}: {e:?}"),
        }
    }
}

/// FMI's min and max are inclusive: the binary takes exactly the declared bounds, refuses beyond.
#[test]
fn declared_bounds_are_accepted_and_the_next_number_outside_refused() {
    let f = common::fmu();
    let real = |s: &Option<String>| s.as_deref().map(|x| x.parse::<f64>().unwrap());
    let params = f.description.variables.iter().filter(|v| v.causality == "parameter" && v.ty == VariableType::Real);
    for v in params {
        let (Some(lo), Some(hi)) = (real(&v.min), real(&v.max)) else { panic!("{} declares no range", v.name) };
        for (x, ok) in [(lo, true), (hi, true), (lo.next_down(), false), (hi.next_up(), false)] {
            let mut i = f.instantiate(None).unwrap();
            let got = i.initialize(0.0, None, &[(v.name.as_str(), x)]).is_ok();
            assert_eq!(got, ok, "{} = {x}", v.name);
        }
    }
}

#[test]
fn caller_strings_in_log_messages_are_quoted_and_cut() {
    let f = common::fmu();
    let long = "G".repeat(200_000);
    let err = RawInstance::instantiate(f.library(), "a", &long, None, false).err().unwrap();
    assert!(err.len() < 1_000, "{} bytes", err.len());
    assert!(err.contains("200000 characters"), "{err}");
    let mut i = f.instantiate(None).unwrap();
    let raw = i.raw_mut();
    assert_eq!(raw.set_debug_logging(true, &[long.as_str()]), FMI2_ERROR);
    let log = last_log(raw);
    assert!(log.len() < 1_000 && log.contains("200000 characters"), "{} bytes", log.len());
}

/// A state pointer is trusted only while the instance that made it holds it: a freed, foreign or
/// made-up pointer is refused without being read (the FMU keeps a registry, not a tag to read).
#[test]
fn freed_foreign_and_made_up_state_pointers_are_refused() {
    let f = common::fmu();
    let mut a = initialized(&f);
    let mut b = initialized(&f);
    let (ca, api) = a.raw_mut().raw();
    let (cb, _) = b.raw_mut().raw();
    let api = *api;
    let mut p: Fmi2FmuState = ptr::null_mut();
    unsafe {
        assert_eq!((api.get_fmu_state)(ca, &mut p), FMI2_OK);
        assert_eq!((api.set_fmu_state)(cb, p), FMI2_ERROR, "another instance's state");
        let mut q = p;
        assert_eq!((api.free_fmu_state)(ca, &mut q), FMI2_OK);
        assert!(q.is_null());
        assert_eq!((api.reset)(ca), FMI2_OK);
        assert_eq!((api.set_fmu_state)(ca, p), FMI2_ERROR, "a freed state");
        let mut again = p;
        assert_eq!((api.free_fmu_state)(ca, &mut again), FMI2_ERROR, "a double free");
        assert_eq!((api.reset)(ca), FMI2_OK);
        let made_up = 0x10 as Fmi2FmuState;
        assert_eq!((api.set_fmu_state)(ca, made_up), FMI2_ERROR, "a made-up pointer");
    }
}

/// Issue 19: bytes written by fmi2SerializeFMUstate restore (FMI 2.0 §2.1.8) after the two
/// sequences a fuzz campaign found refused, each as the campaign called it.
fn get_serialize_deserialize(raw: &mut RawInstance) -> Result<(), String> {
    let state = raw.get_fmu_state(None).map_err(|s| format!("get: {s:?}"))?;
    let bytes = raw.serialize_fmu_state(&state).map_err(|s| format!("serialize: {s:?} {}", last_log(raw)))?;
    let back = raw.deserialize_fmu_state(&bytes).map_err(|s| format!("deserialize: {s:?} {}", last_log(raw)))?;
    assert_eq!(raw.set_fmu_state(&back), FMI2_OK, "{}", last_log(raw));
    Ok(())
}

#[test]
fn an_infinite_stop_time_is_no_stop_time_and_its_state_restores() {
    let f = common::fmu();
    let mut i = f.instantiate(None).unwrap();
    let raw = i.raw_mut();
    assert_eq!(raw.setup_experiment(None, 0.0, Some(f64::INFINITY)), FMI2_OK);
    assert_eq!(raw.enter_initialization_mode(), FMI2_OK);
    assert_eq!(raw.exit_initialization_mode(), FMI2_OK);
    get_serialize_deserialize(raw).unwrap();
    assert_eq!(raw.do_step(0.0, 1e6), FMI2_DISCARD, "no stop time: the work budget, not the stop, ends it");
    assert!(!raw.get_boolean_status_terminated().1, "an infinite stop time is never reached");
    // stopTime still refused when NaN or before the start
    let mut j = f.instantiate(None).unwrap();
    assert_eq!(j.raw_mut().setup_experiment(None, 1.0, Some(f64::NAN)), FMI2_ERROR);
}

#[test]
fn a_discarded_step_at_an_offset_time_keeps_the_fmu_time_as_last_successful() {
    let f = common::fmu();
    let mut i = initialized(&f);
    let raw = i.raw_mut();
    // within the time tolerance of t = 0, and discarded by the work budget
    assert_eq!(raw.do_step_with(1e-12, 1000.0, true), FMI2_DISCARD);
    assert_eq!(raw.get_real_status_last_successful_time(), (FMI2_OK, 0.0), "the FMU's time, not the caller's t");
    get_serialize_deserialize(raw).unwrap();
    assert_eq!(raw.get_real_status_last_successful_time(), (FMI2_OK, 0.0), "after the restore");
}

/// Every Real's bits, or the status that refused them.
fn all_real_bits(f: &Fmu, raw: &mut RawInstance) -> Result<Vec<u64>, Fmi2Status> {
    let vrs: Vec<u32> =
        f.description.variables.iter().filter(|v| v.ty == VariableType::Real).map(|v| v.value_reference).collect();
    let mut out = vec![0.0; vrs.len()];
    match raw.get_real(&vrs, &mut out) {
        FMI2_OK => Ok(out.iter().map(|x| x.to_bits()).collect()),
        s => Err(s),
    }
}

/// Issue 31's property: the instance's current state, written by the FMU and serialized, is
/// accepted by a fresh instance, reads the same there, and both continue bit-identically through a
/// step from the FMU's time. Returns that time (fmi2LastSuccessfulTime before the step).
fn restores_in_a_fresh_instance(f: &Fmu, raw: &mut RawInstance) -> f64 {
    let state = raw.get_fmu_state(None).expect("fmi2GetFMUstate");
    let bytes = raw.serialize_fmu_state(&state).unwrap_or_else(|s| panic!("serialize: {s} {}", last_log(raw)));
    let mut fresh = RawInstance::instantiate(f.library(), "fresh", &f.description.guid, None, false).unwrap();
    let copy = fresh.deserialize_fmu_state(&bytes).unwrap_or_else(|s| panic!("refused ({s}): {}", last_log(&fresh)));
    assert_eq!(fresh.set_fmu_state(&copy), FMI2_OK, "{}", last_log(&fresh));
    assert_eq!(all_real_bits(f, raw), all_real_bits(f, &mut fresh), "the same values after the restore");
    let (s, now) = raw.get_real_status_last_successful_time();
    assert_eq!((s, now.to_bits()), (FMI2_OK, fresh.get_real_status_last_successful_time().1.to_bits()));
    let (a, b) = (raw.do_step(now, 1e-3), fresh.do_step(now, 1e-3));
    assert_eq!(a, b, "the same status after the same step");
    assert_eq!(all_real_bits(f, raw), all_real_bits(f, &mut fresh), "the same values after the same step");
    let bits = |(s, t): (Fmi2Status, f64)| (s, t.to_bits());
    assert_eq!(bits(raw.get_real_status_last_successful_time()), bits(fresh.get_real_status_last_successful_time()));
    now
}

/// An instance initialised at `start`, with `stop` if given.
fn started_at(f: &Fmu, start: f64, stop: Option<f64>) -> Instance {
    let mut i = f.instantiate(None).unwrap();
    let raw = i.raw_mut();
    assert_eq!(raw.setup_experiment(None, start, stop), FMI2_OK);
    assert_eq!(raw.enter_initialization_mode(), FMI2_OK);
    assert_eq!(raw.exit_initialization_mode(), FMI2_OK);
    i
}

/// Issue 31, sequence 1: a communication point below the start time, within the time tolerance,
/// and a step shorter than that distance: the step may not end before the FMU's time (the state
/// then held a time before its start and was refused).
#[test]
fn a_point_below_the_start_within_tolerance_and_a_tiny_step_keep_time_at_or_after_the_start() {
    let f = common::fmu();
    let start = 47.08318683198129;
    let mut i = started_at(&f, start, None);
    let raw = i.raw_mut();
    assert_eq!(raw.do_step(start - 1.5e-8, 1e-8), FMI2_OK, "{}", last_log(raw));
    assert_eq!(raw.get_real_status_last_successful_time(), (FMI2_OK, start), "max(t + h, the FMU's time)");
    assert_eq!(restores_in_a_fresh_instance(&f, raw), start);
}

/// Issue 31, sequence 2: a step of denormal length is discarded (too short to resolve) and leaves
/// the FMU's time, the last successful one, where it was; the state restores.
#[test]
fn a_denormal_step_is_discarded_and_its_state_restores() {
    let f = common::fmu();
    let mut i = started_at(&f, 0.0, None);
    let raw = i.raw_mut();
    assert_eq!(raw.do_step(0.0, 5.7e-322), FMI2_DISCARD);
    assert_eq!(raw.get_real_status_last_successful_time(), (FMI2_OK, 0.0));
    assert_eq!(restores_in_a_fresh_instance(&f, raw), 0.0);
}

/// Issue 31, sequence 3: discards at a communication point offset from the FMU's time (within the
/// tolerance): by the work budget, and by the stop time. The last successful time is the FMU's time
/// after each, and each state restores.
#[test]
fn discards_at_offset_times_leave_one_clock_and_their_states_restore() {
    let f = common::fmu();
    let start = 8.192812122039584;
    let mut i = started_at(&f, start, None);
    let raw = i.raw_mut();
    assert_eq!(raw.do_step(start + 4e-9, 1e6), FMI2_DISCARD, "the work budget");
    assert_eq!(raw.get_real_status_last_successful_time(), (FMI2_OK, start));
    assert_eq!(restores_in_a_fresh_instance(&f, raw), start);
    let mut j = started_at(&f, start, Some(start + 0.5));
    let raw = j.raw_mut();
    assert_eq!(raw.do_step(start, 0.25), FMI2_OK);
    assert_eq!(raw.do_step(start + 0.25 - 2e-9, 1.0), FMI2_DISCARD, "the stop time, from a point below the FMU's");
    assert_eq!(raw.get_real_status_last_successful_time(), (FMI2_OK, start + 0.5));
    assert!(raw.get_boolean_status_terminated().1);
    assert_eq!(restores_in_a_fresh_instance(&f, raw), start + 0.5);
}

/// Issue 31, sequence 4: a legal edit of an input (heater power, at its bounds and between) in an
/// otherwise clean state: the state restores.
#[test]
fn a_state_after_a_legal_input_edit_restores() {
    let f = common::fmu();
    for (name, x) in [("heater_power", 1e4), ("heater_power", 0.0), ("heater_power", 7.5), ("ambient_temperature", 1.0)]
    {
        let mut i = started_at(&f, 0.0, None);
        let v = vr(&i, name);
        let raw = i.raw_mut();
        assert_eq!(raw.set_real(&[v], &[x]), FMI2_OK, "{name} = {x}");
        restores_in_a_fresh_instance(&f, raw);
        assert_eq!(raw.set_real(&[v], &[x]), FMI2_OK, "{name} = {x}");
        restores_in_a_fresh_instance(&f, raw);
    }
}

/// Issue 31, sequence 5: a step that ends past the stop time but within its tolerance is OK, and
/// the next one stops without running time backwards to the stop time; each state restores.
#[test]
fn time_within_tolerance_past_the_stop_never_runs_backwards() {
    let f = common::fmu();
    let mut i = started_at(&f, 0.0, Some(1.0));
    let raw = i.raw_mut();
    let past = 1.0 + 5e-10;
    assert_eq!(raw.do_step(0.0, past), FMI2_OK, "within the stop's tolerance");
    assert_eq!(raw.get_real_status_last_successful_time(), (FMI2_OK, past));
    let state = raw.get_fmu_state(None).unwrap();
    assert_eq!(raw.do_step(past, 0.1), FMI2_DISCARD, "past the stop");
    assert_eq!(raw.get_real_status_last_successful_time(), (FMI2_OK, past), "time never runs backwards");
    assert_eq!(restores_in_a_fresh_instance(&f, raw), past);
    assert_eq!(raw.set_fmu_state(&state), FMI2_OK);
    assert_eq!(restores_in_a_fresh_instance(&f, raw), past);
}

#[test]
fn a_step_too_small_to_resolve_is_discarded_with_that_reason() {
    let f = common::fmu();
    let mut i = initialized(&f);
    let raw = i.raw_mut();
    assert_eq!(raw.do_step(0.0, 1e-300), FMI2_DISCARD);
    let log = last_log(raw);
    assert!(log.contains("too small to resolve"), "{log}");
    assert_eq!(raw.get_real_status_last_successful_time(), (FMI2_OK, 0.0));
}

/// The crystallinity is in the FMU state (issue 20): a melt cooling from 60 °C, saved while still
/// supercooled (less crystal than the heating branch holds at its temperature), continues
/// bit-identically after GetFMUstate/SetFMUstate and after serialization into a fresh instance.
#[test]
fn fmu_state_holds_the_crystallinity_of_a_supercooled_melt() {
    let f = common::fmu();
    let hot = 273.15 + 60.0;
    let start = |f: &thermovia_importer::Fmu| {
        let mut i = f.instantiate(None).unwrap();
        i.initialize(
            0.0,
            None,
            &[("initial_pcl_temperature", hot), ("initial_housing_temperature", hot), ("max_internal_step", 0.1)],
        )
        .unwrap();
        i.set("ambient_temperature", 273.15 + 22.0).unwrap();
        i
    };
    let cool = |i: &mut thermovia_importer::Instance, n: usize| -> Vec<[f64; 3]> {
        (0..n)
            .map(|_| {
                i.step(0.1).unwrap();
                [
                    i.get("pcl_temperature").unwrap(),
                    i.get("pcl_crystallinity").unwrap(),
                    i.get("effective_stiffness").unwrap(),
                ]
            })
            .collect()
    };
    let mut a = start(&f);
    cool(&mut a, 3000);
    let (t, x, tf) = (
        a.get("pcl_temperature").unwrap(),
        a.get("pcl_crystallinity").unwrap(),
        a.get("pcl_structural_temperature").unwrap(),
    );
    let xc = a.get("pcl_ultimate_crystallinity").unwrap();
    assert!(tf > t + 5.0 && x < 0.5 * xc, "supercooled at the save: T {t} K, T_f {tf} K, X {x}");
    let saved = a.save_state().unwrap();
    let continued = cool(&mut a, 6000);
    assert!(continued.last().unwrap()[1] > 0.9 * xc, "crystallised after the save");
    a.restore_state(&saved).unwrap();
    assert_eq!(a.get("pcl_crystallinity").unwrap(), x);
    assert_eq!(cool(&mut a, 6000), continued, "GetFMUstate/SetFMUstate");
    let bytes = a.serialize_state(&saved).unwrap();
    let mut b = start(&f);
    let restored = b.deserialize_state(&bytes, saved.time).unwrap();
    b.restore_state(&restored).unwrap();
    assert_eq!(b.get("pcl_crystallinity").unwrap(), x);
    assert_eq!(cool(&mut b, 6000), continued, "serialized into a fresh instance");
}

/// The Prony law's relaxing branch is the transmission's Maxwell branch: setting a Maxwell
/// stiffness beside it is refused at the write, with the reason, and sets nothing (so every
/// accepted set of parameters initialises). A Prony run's state restores bit-identically.
#[test]
fn a_maxwell_branch_beside_the_prony_law_is_refused_and_a_prony_state_restores() {
    let f = common::fmu();
    let mut i = f.instantiate(None).unwrap();
    let e = i.initialize(0.0, None, &[("viscoelastic_law", 1.0), ("maxwell_stiffness", 2.0)]).unwrap_err().to_string();
    assert!(e.contains("maxwell_stiffness must be 0"), "{e}");

    let mut i = f.instantiate(None).unwrap();
    i.initialize(0.0, None, &[("viscoelastic_law", 1.0)]).unwrap();
    i.set("motor_torque", 0.5).unwrap();
    i.set("heater_power", 10.0).unwrap();
    let run = |i: &mut Instance| -> Vec<f64> {
        (0..2000)
            .map(|_| {
                i.step(1e-3).unwrap();
                i.get("transmitted_torque").unwrap()
            })
            .collect()
    };
    run(&mut i);
    let saved = i.save_state().unwrap();
    let continued = run(&mut i);
    i.restore_state(&saved).unwrap();
    assert_eq!(run(&mut i), continued, "GetFMUstate/SetFMUstate");
}

/// With backlash the Prony law's remembered deflection moves the play (docs/physics.md §10): a
/// torque-driven run through the play, saved inside it after two contacts (the branch remembers
/// the last one, so the centre r q is off zero), continues bit-identically after
/// GetFMUstate/SetFMUstate and after serialization into a fresh instance (the centre is derived
/// from the state, never kept beside it).
#[test]
fn a_prony_run_with_backlash_restores_inside_a_moving_play() {
    let f = common::fmu();
    let start = |f: &thermovia_importer::Fmu| {
        let mut i = f.instantiate(None).unwrap();
        i.initialize(0.0, None, &[("viscoelastic_law", 1.0), ("backlash_width", 0.01)]).unwrap();
        i
    };
    let steps = |i: &mut Instance, from: usize, n: usize| -> Vec<[f64; 3]> {
        (from..from + n)
            .map(|k| {
                i.set("motor_torque", 2.0 * (std::f64::consts::PI * k as f64 * 1e-3).sin()).unwrap();
                i.step(1e-3).unwrap();
                [i.get("link_angle").unwrap(), i.get("motor_angle").unwrap(), i.get("transmitted_torque").unwrap()]
            })
            .collect()
    };
    let mut a = start(&f);
    // run until the transmission is free inside the play after at least one contact
    let (mut k, mut contacts, mut was_free) = (0, 0, true);
    loop {
        let [_, _, tau] = steps(&mut a, k, 1)[0];
        k += 1;
        let free = tau == 0.0;
        contacts += usize::from(was_free && !free);
        if free && contacts >= 2 {
            break;
        }
        was_free = free;
        assert!(k < 20_000, "no return into the play after {contacts} contacts");
    }
    let saved = a.save_state().unwrap();
    let continued = steps(&mut a, k, 3000);
    assert!(continued.iter().any(|s| s[2] != 0.0), "contact again after the save");
    a.restore_state(&saved).unwrap();
    assert_eq!(steps(&mut a, k, 3000), continued, "GetFMUstate/SetFMUstate");
    let bytes = a.serialize_state(&saved).unwrap();
    let mut b = start(&f);
    let restored = b.deserialize_state(&bytes, saved.time).unwrap();
    b.restore_state(&restored).unwrap();
    assert_eq!(steps(&mut b, k, 3000), continued, "serialized into a fresh instance");
}
