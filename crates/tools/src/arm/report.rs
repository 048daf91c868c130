//! The arm's report: report.md, summary, and SVG plots.

use std::path::Path;

use super::dynamics::ArmConfig;
use super::sim::Trace;
use super::{ArmReport, TaskMetrics};
use crate::report::plot::{chart, Axes, Dash, Marker, Series, Style, BLACK_, BLUE_, GREY_, RED_};

fn ms(v: Option<f64>) -> String {
    v.map_or("none".into(), |v| format!("{:.2} ms", v * 1e3))
}
fn secs(v: Option<f64>) -> String {
    v.map_or("not reached".into(), |v| format!("{v:.1} s"))
}

pub fn summary(r: &ArmReport) -> String {
    let mut s = String::new();
    s += &format!(
        "stability limit: {} (cold {}, hot {}); step {:.2} ms\n",
        ms(Some(r.stability.limit_s)),
        ms(r.stability.limit_cold_s),
        ms(r.stability.limit_hot_s),
        r.step_s * 1e3
    );
    for e in &r.accuracy {
        s += &format!(
            "  h = {:.1} ms {:4}: tip error {:.3} mm = {:.3} % of the motion\n",
            e.step_s * 1e3,
            e.scenario,
            e.tip_error_m * 1e3,
            100.0 * e.relative_error
        );
    }
    s += &format!("error < 1 % for h ≤ {:.1} ms\n", r.step_for_one_percent_s * 1e3);
    for t in &r.tasks {
        s += &format!(
            "{}: K = {:.1} N·m/rad, impact {:.1} N, peak wall force {:.1} N, final {:.1} N, settling {}\n",
            t.scenario.name,
            t.joints[0].stiffness,
            t.impact_force_n,
            t.peak_contact_force_n,
            t.final_contact_force_n,
            secs(t.settling_time_s)
        );
    }
    let w = &r.switching;
    s += &format!(
        "switching at {} W: PCL at {} °C after {}; back to 90 % of the cold stiffness after {} of passive cooling\n",
        w.heater_power_w,
        w.hot_temperature_c,
        secs(w.heat_time_s),
        secs(w.stiffen_90_s)
    );
    s += &format!("real-time factor of the task runs (step {:.1} ms): {:.0}×", r.step_s * 1e3, r.real_time_factor);
    s
}

pub(super) fn write_report(
    dir: &Path,
    cfg: &ArmConfig,
    r: &ArmReport,
    traces: &[Trace],
    prony_traces: &[Trace],
    refs: &[Trace],
) -> Result<(), String> {
    let w = |name: &str, text: &str| std::fs::write(dir.join(name), text).map_err(|e| format!("{name}: {e}"));
    w("report.json", &serde_json::to_string_pretty(r).map_err(|e| e.to_string())?)?;

    // plots
    let plan: Vec<(f64, f64)> = (0..=200)
        .map(|k| {
            let p = cfg.tip(cfg.plan(cfg.move_start + cfg.move_duration * k as f64 / 200.0).0);
            (p[0], p[1])
        })
        .collect();
    let ys = traces.iter().flat_map(|t| t.tip.iter().map(|p| p[1])).chain(plan.iter().map(|p| p.1));
    let (ylo, yhi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| (a.min(y), b.max(y)));
    let tip = |t: &Trace| t.tip.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>();
    // one look across the arm's plots: blue cold, vermillion heated; the plan and the wall in grey
    // and black without markers
    let (cold, hot) = (Style::line(BLUE_).marker(Marker::Circle), Style::line(RED_).marker(Marker::Square));
    let planned = Style::line(GREY_).dash(Dash::Dashed);
    let wall = Style::line(BLACK_).dash(Dash::Dotted);
    chart(
        &dir.join("tip_path.svg"),
        &Axes::new("Tip path: cold vs heated joints, same move into the same wall", "x (m)", "y (m)").equal_aspect(),
        &[
            Series::new("planned", plan, planned),
            Series::new("wall", vec![(cfg.wall_x, ylo), (cfg.wall_x, yhi)], wall),
            Series::new("cold joints (22 °C)", tip(&traces[0]), cold),
            Series::new("heated joints", tip(&traces[1]), hot),
        ],
    )?;
    let ts = |t: &Trace, f: &dyn Fn(usize) -> f64| (0..t.t.len()).map(|k| (t.t[k], f(k))).collect::<Vec<_>>();
    // light marks, so the co-simulated lines show through where they agree
    let reference = Style::points(BLACK_, Marker::Diamond).hollow().width(1).size(3);
    chart(
        &dir.join("tip_x.svg"),
        &Axes::new("Tip x against time", "t (s)", "x (m)"),
        &[
            Series::new("planned", ts(&traces[0], &|k| cfg.tip(cfg.plan(traces[0].t[k]).0)[0]), planned),
            Series::new("wall", vec![(0.0, cfg.wall_x), (cfg.duration, cfg.wall_x)], wall),
            Series::new("cold", ts(&traces[0], &|k| traces[0].tip[k][0]), cold),
            Series::new("heated", ts(&traces[1], &|k| traces[1].tip[k][0]), hot),
            Series::new("monolithic reference (cold, heated)", reference_points(&refs[0]), reference),
            Series::new("", reference_points(&refs[1]), reference),
        ],
    )?;
    chart(
        &dir.join("contact_force.svg"),
        &Axes::new("Interaction force at the wall", "t (s)", "force (N)"),
        &[
            Series::new("cold", ts(&traces[0], &|k| traces[0].contact_force[k]), cold),
            Series::new("heated", ts(&traces[1], &|k| traces[1].contact_force[k]), hot),
        ],
    )?;
    // colour by temperature, dash and marker by joint
    let elbow = |s: Style| s.dash(Dash::Dashed).marker(Marker::Triangle);
    chart(
        &dir.join("joint_torques.svg"),
        &Axes::new("Transmitted joint torques τ_t", "t (s)", "torque (N·m)"),
        &[
            Series::new("shoulder, cold", ts(&traces[0], &|k| traces[0].transmitted_torque[k][0]), cold),
            Series::new("elbow, cold", ts(&traces[0], &|k| traces[0].transmitted_torque[k][1]), elbow(cold)),
            Series::new("shoulder, heated", ts(&traces[1], &|k| traces[1].transmitted_torque[k][0]), hot),
            Series::new("elbow, heated", ts(&traces[1], &|k| traces[1].transmitted_torque[k][1]), elbow(hot)),
        ],
    )?;
    let err = |sc: &str| {
        r.accuracy
            .iter()
            .filter(|e| e.scenario == sc)
            .map(|e| (e.step_s * 1e3, 100.0 * e.relative_error))
            .collect::<Vec<_>>()
    };
    let hs: Vec<f64> = r.accuracy.iter().map(|e| e.step_s * 1e3).collect();
    let (hlo, hhi) = hs.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)));
    // log axes in their own units: a reader reads "2 ms, 1.6 %", not log10 values
    chart(
        &dir.join("coupling_error.svg"),
        &Axes::new(
            "Co-simulation vs monolithic: max tip error / tip travel",
            "communication step (ms)",
            "max tip error (% of travel)",
        )
        .log_x()
        .log_y(),
        &[
            Series::new("cold", err("cold"), cold),
            Series::new("heated", err("hot"), hot),
            Series::new("1 %", vec![(hlo, 1.0), (hhi, 1.0)], planned),
        ],
    )?;
    let sw = &r.switching;
    let col = |i: usize| sw.samples.iter().map(|s| (s[0], s[i])).collect::<Vec<_>>();
    chart(
        &dir.join("impedance_switch_temperature.svg"),
        &Axes::new(format!("Heating at {} W, then passive cooling", sw.heater_power_w), "t (s)", "temperature (°C)"),
        &[
            Series::new("PCL (model)", col(1), hot),
            Series::new(
                "housing (thermocouple)",
                col(2),
                Style::line(BLUE_).dash(Dash::Dashed).marker(Marker::Triangle),
            ),
        ],
    )?;
    chart(
        &dir.join("impedance_switch_stiffness.svg"),
        &Axes::new("Joint stiffness K_eff while heating and cooling", "t (s)", "K_eff (N·m/rad)"),
        &[Series::new("K_eff", col(3), cold)],
    )?;
    // the impact under both damping laws: from 50 ms before the first contact to 0.5 s after it
    let first = r.tasks.iter().chain(&r.prony.tasks).filter_map(|t| t.first_contact_s).fold(f64::INFINITY, f64::min);
    if first.is_finite() {
        let window = |tr: &Trace| -> Vec<(f64, f64)> {
            tr.t.iter()
                .zip(&tr.contact_force)
                .filter(|(t, _)| **t >= first - 0.05 && **t <= first + 0.5)
                .map(|(t, f)| (*t, *f))
                .collect()
        };
        // colour by temperature, dash and marker by damping law
        let prony = |s: Style| s.dash(Dash::Dashed).marker(Marker::Triangle);
        chart(
            &dir.join("impact_damping_law.svg"),
            &Axes::new("Wall force at the impact: hysteretic vs Prony damping", "t (s)", "force (N)"),
            &[
                Series::new("cold, hysteretic", window(&traces[0]), cold),
                Series::new("cold, Prony", window(&prony_traces[0]), prony(cold)),
                Series::new("heated, hysteretic", window(&traces[1]), hot),
                Series::new("heated, Prony", window(&prony_traces[1]), prony(hot)),
            ],
        )?;
    }
    w("report.md", &markdown(cfg, r))
}

/// Tip x of a reference trace every 50 ms (markers over the co-simulated lines).
fn reference_points(r: &Trace) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut next = 0.0;
    for (k, &t) in r.t.iter().enumerate() {
        if t >= next - 1e-12 {
            out.push((t, r.tip[k][0]));
            next += 0.05;
        }
    }
    out
}

fn markdown(cfg: &ArmConfig, r: &ArmReport) -> String {
    let st = &r.stability;
    let mut m = String::new();
    m += "# ThermoVIA two-joint arm\n\n";
    m += &format!(
        "Planar two-link arm in a vertical plane: l1 = {} m, l2 = {} m, rods of {} kg and {} kg, elbow actuator {} kg at the elbow, \
         payload {} kg at the tip, output hubs {} kg·m². Each joint is a ThermoVIA FMU instance (two instances of one `.fmu`). \
         Joint PD on the motor angle kp = {} N·m/rad, kd = {} N·m·s/rad, gravity fed forward, set-point shifted by the gravity \
         deflection g_i/K_i. The tip moves (minimum jerk in joint space, {} s from t = {} s) towards a goal {:.0} mm behind a wall at \
         x = {} m (k = {} N/m, d = {} N·s/m), strikes it and keeps pressing.\n\n",
        cfg.l1, cfg.l2, cfg.m1, cfg.m2, cfg.elbow_mass, cfg.payload_mass, cfg.hub_inertia, cfg.kp, cfg.kd, cfg.move_duration,
        cfg.move_start, (cfg.goal_tip[0] - cfg.wall_x) * 1e3, cfg.wall_x, cfg.wall_stiffness, cfg.wall_damping
    );
    m += "## Coupling scheme\n\n";
    m += "Jacobi with zero-order hold. At each communication point the master reads from both FMUs the link angle and speed, \
          the motor angle and speed, the transmitted torque τ_i (every step) and the effective stiffness and PCL temperature \
          (every 10 ms: they change over seconds); solves the arm's forward dynamics \
          a = M(q)⁻¹(τ − c − g + JᵀF_wall); sends `load_torque_i = J_i a_i − τ_i` (so the FMU's link, of inertia J_i, accelerates \
          as the arm's joint would if τ stayed constant), the PD's `motor_torque_i` and the `heater_power_i`; then steps both FMUs \
          over [t_n, t_n + h] with these inputs held. Delay: one communication step for everything the master computes \
          (the arm's reaction to the change of τ within a step, the controller, the wall).\n\n";
    m += &format!(
        "FMU `link_inertia` = J_i = min over elbow angles of 1/(M⁻¹)_ii: {:.5} and {:.5} kg·m² (the hub inertia is in M(q); J_i \
         is a coupling choice, not extra mass).\n\n",
        r.coupling_inertia[0], r.coupling_inertia[1]
    );
    m += "## Stability limit\n\n";
    m += &format!(
        "Spectral radius of the linearised one-step map (FMU joints exact over the step, master law held), about rest states along \
         the move and against the wall: limit **{}** (cold joints {}, heated joints {}). `--step` at or above it is refused.\n\n",
        ms(Some(st.limit_s)),
        ms(st.limit_cold_s),
        ms(st.limit_hot_s)
    );
    m += "| closed-form estimate | cold | heated |\n|---|---|---|\n";
    m += &format!(
        "| motor PD derivative vs PCL damping, (J_m/C') ln((kd+C')/(kd−C')) | {} / {} | {} / {} |\n",
        ms(st.estimates_cold.motor_loop[0]),
        ms(st.estimates_cold.motor_loop[1]),
        ms(st.estimates_hot.motor_loop[0]),
        ms(st.estimates_hot.motor_loop[1])
    );
    m += &format!(
        "| motor PD proportional on the bare motor, 2√(J_m/kp) | {} | {} |\n",
        ms(st.estimates_cold.motor_proportional),
        ms(st.estimates_hot.motor_proportional)
    );
    m += &format!(
        "| wall spring–damper held, min(2d/k, 2m/d) | {} | {} |\n\n",
        ms(st.estimates_cold.contact),
        ms(st.estimates_hot.contact)
    );
    m += &format!(
        "Check through the FMU (nonlinear, limiting scenario, run 3 s past the move): at {} the speed amplitude grows by ×{:.3e} \
         ({}); at {} by ×{:.3e} ({}).\n\n",
        ms(Some(st.check_below.0)),
        st.check_below.1,
        if st.check_below.2 { "diverges" } else { "decays" },
        ms(Some(st.check_above.0)),
        st.check_above.1,
        if st.check_above.2 { "diverges" } else { "decays" }
    );
    m += "## Accuracy against a monolithic simulation\n\n";
    m += &format!(
        "Reference: the same equations as one ODE (motors, transmissions K_i, C_i read from the FMU's outputs, rigid arm, wall, \
         continuous controller), adaptive Dormand–Prince 5(4), tolerance 1e-10 ({} accepted steps for both runs). Error: largest \
         tip distance between co-simulation and reference, over the tip's travel.\n\n",
        r.reference_steps
    );
    m += "| step | joints | tip error (mm) | % of the motion | joint error (% of range) | peak-force error (N) |\n|---|---|---|---|---|---|\n";
    for e in r.accuracy.iter().chain(r.one_percent_check.iter()) {
        m += &format!(
            "| {:.1} ms | {} | {:.3} | {:.3} | {:.3} | {:.3} |\n",
            e.step_s * 1e3,
            e.scenario,
            e.tip_error_m * 1e3,
            100.0 * e.relative_error,
            100.0 * e.relative_joint_error,
            e.peak_force_error_n
        );
    }
    m += &format!(
        "\nThe error is first order in h. It stays under 1 % of the motion for steps up to **{:.1} ms** (last rows: that step, checked).\n\n",
        r.step_for_one_percent_s * 1e3
    );
    m += "## Cold vs heated joints: the same move, the same wall\n\n";
    m += "| | cold | heated |\n|---|---|---|\n";
    let (c, h) = (&r.tasks[0], &r.tasks[1]);
    let row = |name: &str, f: &dyn Fn(&TaskMetrics) -> String| format!("| {name} | {} | {} |\n", f(c), f(h));
    m += &row("PCL temperature (°C)", &|t| format!("{}", t.scenario.pcl_temperature_c[0]));
    m += &row("joint stiffness K_eff (N·m/rad)", &|t| format!("{:.2}", t.joints[0].stiffness));
    m += &row("joint damping C_eff (N·m·s/rad)", &|t| format!("{:.2}", t.joints[0].damping));
    m += &row("heater power to hold (W per joint)", &|t| format!("{:.2}", t.joints[0].holding_power));
    m += &row("tip tracking error before contact (mm)", &|t| format!("{:.1}", t.max_tracking_error_mm));
    m += &row("first contact (s)", &|t| t.first_contact_s.map_or("none".into(), |v| format!("{v:.3}")));
    m += &row("impact force, first 50 ms of contact (N)", &|t| format!("{:.1}", t.impact_force_n));
    m += &row("**peak interaction force (N)**", &|t| format!("**{:.1}**", t.peak_contact_force_n));
    m += &row("time of the peak (s)", &|t| format!("{:.3}", t.peak_contact_force_time_s));
    m += &row("final pressing force (N)", &|t| format!("{:.1}", t.final_contact_force_n));
    m += &row("rebounds off the wall", &|t| format!("{}", t.rebounds));
    m += &row("settling after contact (tip within 1 mm)", &|t| secs(t.settling_time_s));
    m += &row("peak transmitted torque shoulder / elbow (N·m)", &|t| {
        format!("{:.2} / {:.2}", t.peak_transmitted_torque_nm[0], t.peak_transmitted_torque_nm[1])
    });
    m += &row("peak motor torque shoulder / elbow (N·m)", &|t| {
        format!("{:.2} / {:.2}", t.peak_motor_torque_nm[0], t.peak_motor_torque_nm[1])
    });
    m += "\nPlots: `tip_path.svg`, `tip_x.svg`, `contact_force.svg`, `joint_torques.svg`, `coupling_error.svg`.\n\n";
    m += &impact_markdown(r);
    let sw = &r.switching;
    m += "## Switching the impedance\n\n";
    m += &format!(
        "One joint at rest, from 22 °C: heater at {} W until the PCL (model estimate) reaches {} °C, then off; passive cooling only \
         (the device has no active cooling). K_eff: {:.2} N·m/rad cold, {:.2} hot.\n\n",
        sw.heater_power_w, sw.hot_temperature_c, sw.stiffness_cold, sw.stiffness_hot
    );
    m += "| | time |\n|---|---|\n";
    m += &format!("| heating: PCL reaches {} °C | {} |\n", sw.hot_temperature_c, secs(sw.heat_time_s));
    m += &format!(
        "| heating: K_eff 50 % / 90 % of the way to hot | {} / {} |\n",
        secs(sw.soften_50_s),
        secs(sw.soften_90_s)
    );
    m += &format!("| peak housing (thermocouple) temperature while heating | {:.1} °C |\n", sw.peak_housing_c);
    m += &format!(
        "| passive cooling: K_eff back 50 % / 90 % of the way to cold | {} / {} (simulated {:.0} s) |\n\n",
        secs(sw.stiffen_50_s),
        secs(sw.stiffen_90_s),
        sw.cooling_simulated_s
    );
    m += "The PCL melts on its melting curve but recrystallises by Nakamura's kinetics (`crystallisation` = 1, \
          docs/physics.md §5a): the supercooled melt stays soft well below the 58 °C melting point, so the stiffness comes back \
          only as it crystallises, around 40 °C. Plots: `impedance_switch_temperature.svg`, `impedance_switch_stiffness.svg`.\n\n";
    m += &format!(
        "## Speed\n\nTask runs (two FMU instances, {:.1} ms step, master in Rust): real-time factor {:.0}× (wall clock including \
         instantiation; `cargo bench --bench arm` measures the stepping loop).\n",
        r.step_s * 1e3,
        r.real_time_factor
    );
    m
}

/// The task's impact with the joints' two damping laws, side by side.
fn impact_markdown(r: &ArmReport) -> String {
    let mut m = String::from("## The impact with a causal damping law (Prony) against the hysteretic one\n\n");
    m += "The same task with `viscoelastic_law` = 1: each PCL a spring, a dashpot and one Maxwell branch fitted to the \
          table at 0.5 and 1 Hz (docs/physics.md §5c), instead of C = K''/ω at `excitation_frequency` = 0.5 Hz. An impact \
          excites the joints far above 0.5 Hz, where the hysteretic law's damping has no meaning and the Prony law's \
          dashpot and branch set it. K_eff and C_eff below are each law's at 0.5 Hz.\n\n";
    m += "| | cold, hysteretic | cold, Prony | heated, hysteretic | heated, Prony |\n|---|---|---|---|---|\n";
    let runs = [&r.tasks[0], &r.prony.tasks[0], &r.tasks[1], &r.prony.tasks[1]];
    let row = |name: &str, f: &dyn Fn(&TaskMetrics) -> String| {
        format!("| {name} | {} |\n", runs.iter().map(|t| f(t)).collect::<Vec<_>>().join(" | "))
    };
    m += &row("K_eff / C_eff at 0.5 Hz", &|t| format!("{:.2} / {:.2}", t.joints[0].stiffness, t.joints[0].damping));
    m += &row("impact force, first 50 ms of contact (N)", &|t| format!("{:.2}", t.impact_force_n));
    m += &row("peak wall force (N)", &|t| format!("{:.2}", t.peak_contact_force_n));
    m += &row("rebounds", &|t| t.rebounds.to_string());
    m += &row("settling after contact", &|t| secs(t.settling_time_s));
    m += &row("final wall force (N)", &|t| format!("{:.2}", t.final_contact_force_n));
    m += &row("peak transmitted torque shoulder / elbow (N·m)", &|t| {
        format!("{:.2} / {:.2}", t.peak_transmitted_torque_nm[0], t.peak_transmitted_torque_nm[1])
    });
    m += &format!(
        "\nStability limit of the coupling with the Prony law: {} cold, {} hot. Plot: `impact_damping_law.svg`.\n\n",
        ms(r.prony.limit_cold_s),
        ms(r.prony.limit_hot_s)
    );
    m
}
