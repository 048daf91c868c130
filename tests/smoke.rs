mod common;

#[test]
fn packaged_fmu_steps_through_the_c_api() {
    let fmu = common::fmu();
    let mut a = fmu.instantiate(None).unwrap();
    a.initialize(0.0, None, &[("link_inertia", 0.02)]).unwrap();
    a.set("motor_torque", 0.5).unwrap();
    for _ in 0..1000 {
        a.step(1e-3).unwrap();
    }
    let th = a.get("link_angle").unwrap();
    assert!(th > 0.0, "{th}");
    let e = a.set("link_inertia", -1.0).unwrap_err().to_string();
    assert!(e.contains("link_inertia"), "{e}");
}
