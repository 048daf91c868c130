//! `harness::cosim::Master`: several instances of one FMU, each with its own parameters, stepped
//! with Jacobi exchange. Checked against the same loop written by hand with the plain harness.

mod common;

use thermovia_importer::cosim::Master;

/// Two instances coupled by a spring between their links (each pulls the other with the *other's*
/// t_n angle): the master must give bit-identical results to the hand-written Jacobi loop.
#[test]
fn master_matches_a_hand_written_jacobi_loop() {
    let fmu = common::fmu();
    let params =
        [[("link_inertia", 0.02), ("initial_link_angle", 0.3)], [("link_inertia", 0.05), ("initial_link_angle", -0.1)]];
    let k = 3.0;
    let (h, n) = (1e-3, 500);

    let mut master = Master::new(0.0, None);
    let a = master
        .add(&fmu, "a", &params[0], &["load_torque", "motor_torque"], &["link_angle", "pcl_temperature"])
        .unwrap();
    let b = master
        .add(&fmu, "b", &params[1], &["load_torque", "motor_torque"], &["link_angle", "pcl_temperature"])
        .unwrap();
    master.read_every(a, &["pcl_temperature"], 7).unwrap();
    let (ya, yb) = (master.output(a, "link_angle").unwrap(), master.output(b, "link_angle").unwrap());
    let (ua, ub) = (master.input(a, "load_torque").unwrap(), master.input(b, "load_torque").unwrap());
    let ma = master.input(a, "motor_torque").unwrap();
    let mut seen = Vec::new();
    master
        .run(h, n, |t, io| {
            let (qa, qb) = (io.get(ya), io.get(yb));
            seen.push((t, qa, qb));
            io.set(ua, k * (qb - qa));
            io.set(ub, k * (qa - qb));
            io.set(ma, 0.2);
            Ok(())
        })
        .unwrap();
    assert!((master.time() - n as f64 * h).abs() < 1e-12);

    let mut x = fmu.instantiate(None).unwrap();
    let mut y = fmu.instantiate(None).unwrap();
    x.initialize(0.0, None, &params[0]).unwrap();
    y.initialize(0.0, None, &params[1]).unwrap();
    for (step, &(t, qa_seen, qb_seen)) in seen.iter().enumerate() {
        let (qa, qb) = (x.get("link_angle").unwrap(), y.get("link_angle").unwrap());
        assert_eq!((qa.to_bits(), qb.to_bits()), (qa_seen.to_bits(), qb_seen.to_bits()), "step {step}, t = {t}");
        x.set("load_torque", k * (qb - qa)).unwrap();
        y.set("load_torque", k * (qa - qb)).unwrap();
        x.set("motor_torque", 0.2).unwrap();
        x.step(h).unwrap();
        y.step(h).unwrap();
    }
    assert_eq!(master.get(ya).to_bits(), x.get("link_angle").unwrap().to_bits());
    // the instances are independent: different inertias, different motions
    assert!((master.get(ya) - master.get(yb)).abs() > 1e-3);
}

#[test]
fn undeclared_ports_and_unknown_variables_are_named() {
    let fmu = common::fmu();
    let mut master = Master::new(0.0, None);
    let e = master.add(&fmu, "a", &[], &["load_torq"], &["link_angle"]).err().unwrap().to_string();
    assert!(e.contains("load_torq"), "{e}");
    let a = master.add(&fmu, "a", &[], &["load_torque"], &["link_angle"]).unwrap();
    let e = master.output(a, "motor_angle").unwrap_err().to_string();
    assert!(e.contains("motor_angle") && e.contains("not declared"), "{e}");
    let e = master.add(&fmu, "bad", &[("link_inertia", -1.0)], &[], &[]).err().unwrap().to_string();
    assert!(e.contains("link_inertia"), "{e}");
}
