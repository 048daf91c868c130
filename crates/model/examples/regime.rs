//! The bench's "all three while heating" loop on the model alone (no FMU), for callgrind:
//!   cargo run --release -p thermovia-model --example regime -- [steps] [all|heating|cooling]
use thermovia_model::{Model, Params};

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let steps: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(200_000);
    let which = args.get(2).map(String::as_str).unwrap_or("all");
    let (start_c, ambient_c, heater) = match which {
        "cooling" => (60.0, 22.0, 0.0),
        _ => (22.0, 22.0, 8.0),
    };
    let mut p = Params {
        initial_housing_temperature: 273.15 + start_c,
        initial_pcl_temperature: 273.15 + start_c,
        ..Params::default()
    };
    if which == "all" {
        p.gravity_link_mass = 0.91;
        p.coulomb_friction = 0.05;
        p.backlash_width = 0.01;
    }
    let mut m = Model::new(p);
    m.inputs.ambient_temperature = 273.15 + ambient_c;
    m.inputs.heater_power = heater;
    let w = 2.0 * std::f64::consts::PI * 0.5;
    let mut sum = 0.0;
    for k in 0..steps {
        let t = k as f64 * 1e-3;
        let h = (k + 1) as f64 * 1e-3 - t;
        m.inputs.motor_torque = 2.0 * (w * t).sin();
        m.step(h).unwrap();
        sum += m.link_angle();
    }
    println!("{which}: link angle {} mean {}", m.link_angle(), sum / steps as f64);
}
