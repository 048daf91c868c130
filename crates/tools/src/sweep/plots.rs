//! SVG figures of a sweep (plotters, SVG backend): trajectories like the paper's Fig. 6, normalised
//! Decay like Fig. 7, moduli against temperature like Fig. 4, and the warm-up.

use std::error::Error;
use std::path::Path;

use plotters::prelude::*;

use super::rig::{self, ZERO_CELSIUS};
use super::SweepResult;
use crate::report::plot::{legend, range, thin, PALETTE};

type R = Result<(), Box<dyn Error>>;

pub fn write_all(r: &SweepResult, dir: &Path) -> Result<usize, Box<dyn Error>> {
    let mut n = 0;
    for &f in &r.args.frequencies {
        trajectories(r, f, &dir.join(format!("fig6_trajectories_{f}Hz.svg")))?;
        n += 1;
    }
    decay(r, &dir.join("fig7_decay_normalized.svg"))?;
    moduli(r, &dir.join("fig4_moduli.svg"))?;
    n += 2;
    if !r.warmups.is_empty() {
        warmup(r, &dir.join("warmup.svg"))?;
        n += 1;
    }
    if !r.cooling_cycles.is_empty() {
        cooling_cycle(r, &dir.join("heating_cooling_cycle.svg"))?;
        n += 1;
    }
    Ok(n)
}

fn trajectories(r: &SweepResult, f: f64, path: &Path) -> R {
    let conds: Vec<_> = r.conditions.iter().filter(|c| c.frequency_hz == f).collect();
    let root = SVGBackend::new(path, (1100, 260 * conds.len() as u32 + 40)).into_drawing_area();
    root.fill(&WHITE)?;
    let (title, body) = root.split_vertically(40);
    title.draw(&Text::new(
        format!("Motor and link angle at {f} Hz from rest (left), link − motor (right); shaded: analysed cycles"),
        (10, 12),
        ("sans-serif", 18),
    ))?;
    let rows = body.split_evenly((conds.len(), 2));
    for (i, c) in conds.iter().enumerate() {
        let t = &c.trace.time;
        let deg = |o: usize| c.trace.column(o).iter().map(|v| v.to_degrees()).collect::<Vec<_>>();
        let (m, l) = (deg(rig::O_MOTOR_ANGLE), deg(rig::O_LINK_ANGLE));
        let reference: Vec<f64> = c.trace.reference.iter().map(|v| v.to_degrees()).collect();
        let (y0, y1) = range(m.iter().chain(&l).cloned());
        let t_end = *t.last().unwrap_or(&1.0);
        let t_win = t[c.window.0];
        let mut ch = ChartBuilder::on(&rows[2 * i])
            .caption(format!("{} °C (PCL {:.1} °C)", c.temperature_c, c.pcl_temperature_c), ("sans-serif", 15))
            .margin(6)
            .x_label_area_size(28)
            .y_label_area_size(48)
            .build_cartesian_2d(0.0..t_end, y0..y1)?;
        ch.configure_mesh().x_desc("time (s)").y_desc("angle (°)").light_line_style(WHITE).draw()?;
        ch.draw_series(std::iter::once(Rectangle::new([(t_win, y0), (t_end, y1)], RGBColor(235, 235, 235).filled())))?;
        ch.draw_series(LineSeries::new(thin(t, &reference, 1500), PALETTE[2].stroke_width(1)))?
            .label("reference θ0 sin ωt")
            .legend(legend(PALETTE[2]));
        ch.draw_series(LineSeries::new(thin(t, &m, 1500), PALETTE[0].stroke_width(2)))?
            .label("motor θm")
            .legend(legend(PALETTE[0]));
        ch.draw_series(LineSeries::new(thin(t, &l, 1500), PALETTE[1].stroke_width(1)))?
            .label("link θl")
            .legend(legend(PALETTE[1]));
        ch.configure_series_labels().background_style(WHITE.mix(0.8)).border_style(BLACK).draw()?;

        let d: Vec<f64> = l.iter().zip(&m).map(|(a, b)| a - b).collect();
        let (d0, d1) = range(d[c.window.0..].iter().cloned());
        let (d0, d1) = (
            d0.min(range(d.iter().cloned()).0.max(3.0 * d0 - 2.0 * d1)),
            d1.max(range(d.iter().cloned()).1.min(3.0 * d1 - 2.0 * d0)),
        );
        let mut ch = ChartBuilder::on(&rows[2 * i + 1])
            .caption(
                format!("link − motor, Decay {:+.2} mrad, phase {:.3}°", c.decay_rad * 1e3, c.phase_deg),
                ("sans-serif", 15),
            )
            .margin(6)
            .x_label_area_size(28)
            .y_label_area_size(56)
            .build_cartesian_2d(0.0..t_end, d0..d1)?;
        ch.configure_mesh().x_desc("time (s)").y_desc("θl − θm (°)").light_line_style(WHITE).draw()?;
        ch.draw_series(std::iter::once(Rectangle::new([(t_win, d0), (t_end, d1)], RGBColor(235, 235, 235).filled())))?;
        ch.draw_series(LineSeries::new(
            thin(t, &d, 3000).filter(|p| p.1 >= d0 && p.1 <= d1),
            PALETTE[4].stroke_width(1),
        ))?;
    }
    root.present()?;
    Ok(())
}

fn decay(r: &SweepResult, path: &Path) -> R {
    let root = SVGBackend::new(path, (800, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let temps = &r.args.temperatures;
    let (x0, x1) = range(temps.iter().cloned());
    let vals = r.conditions.iter().filter_map(|c| c.decay_normalized);
    let (y0, y1) = range(vals.chain([0.0, super::report::PAPER_DECAY_RATIO_60_22_HALF_HZ, 1.0]));
    let mut ch = ChartBuilder::on(&root)
        .caption("Decay normalised to the first temperature (cf. the paper's Fig. 7)", ("sans-serif", 17))
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(50)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    ch.configure_mesh().x_desc("housing temperature (°C)").y_desc("Decay / Decay(first)").draw()?;
    for (i, &f) in r.args.frequencies.iter().enumerate() {
        let pts: Vec<(f64, f64)> = r
            .conditions
            .iter()
            .filter(|c| c.frequency_hz == f)
            .filter_map(|c| Some((c.temperature_c, c.decay_normalized?)))
            .collect();
        let col = PALETTE[i % PALETTE.len()];
        ch.draw_series(LineSeries::new(pts.clone(), col.stroke_width(2)))?
            .label(format!(
                "model, {f} Hz (Decay sign: {})",
                if r.conditions.iter().any(|c| c.frequency_hz == f && c.decay_rad < 0.0) {
                    "negative, overshoot"
                } else {
                    "positive"
                }
            ))
            .legend(legend(col));
        ch.draw_series(pts.iter().map(|&p| Circle::new(p, 4, col.filled())))?;
    }
    let paper_pt = (*temps.last().unwrap_or(&60.0), super::report::PAPER_DECAY_RATIO_60_22_HALF_HZ);
    ch.draw_series(std::iter::once(TriangleMarker::new(paper_pt, 8, BLACK.filled())))?
        .label("paper, 0.5 Hz: “nearly five times” (positive Decay)")
        .legend(|(x, y)| TriangleMarker::new((x + 9, y), 6, BLACK.filled()));
    ch.configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

fn moduli(r: &SweepResult, path: &Path) -> R {
    let root = SVGBackend::new(path, (1100, 480)).into_drawing_area();
    root.fill(&WHITE)?;
    let panels = root.split_evenly((1, 2));
    let (x0, x1) = range(r.args.temperatures.iter().cloned());
    for (k, name) in ["E' (storage)", "E'' (loss)"].iter().enumerate() {
        let used = |c: &super::Condition| if k == 0 { c.model_e_storage_kpa } else { c.model_e_loss_kpa };
        let closed = |c: &super::Condition| if k == 0 { c.e_storage_kpa } else { c.e_loss_kpa };
        let paper = |c: &super::Condition| {
            c.paper_method.map(|p| if k == 0 { p.estimate.e_storage } else { p.estimate.e_loss } / 1e3)
        };
        let all: Vec<f64> = r
            .conditions
            .iter()
            .flat_map(|c| [Some(used(c)), Some(closed(c)), paper(c)])
            .flatten()
            .filter(|v| v.is_finite() && *v > 0.0)
            .collect();
        let lo = all.iter().cloned().fold(f64::INFINITY, f64::min) / 2.0;
        let hi = all.iter().cloned().fold(0.0, f64::max) * 2.0;
        let (lo, hi) = if lo.is_finite() && hi > lo { (lo, hi) } else { (1.0, 1e4) };
        let mut ch = ChartBuilder::on(&panels[k])
            .caption(format!("{name}: used by the FMU vs estimated (cf. Fig. 4)"), ("sans-serif", 16))
            .margin(10)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(x0..x1, (lo..hi).log_scale())?;
        ch.configure_mesh().x_desc("housing temperature (°C)").y_desc("kPa").draw()?;
        for (i, &f) in r.args.frequencies.iter().enumerate() {
            let cs: Vec<_> = r.conditions.iter().filter(|c| c.frequency_hz == f).collect();
            let col = PALETTE[i % PALETTE.len()];
            ch.draw_series(LineSeries::new(cs.iter().map(|c| (c.temperature_c, used(c))), col.stroke_width(2)))?
                .label(format!("used by the FMU, {f} Hz runs"))
                .legend(legend(col));
            ch.draw_series(
                cs.iter()
                    .filter(|c| closed(c) > 0.0)
                    .map(|c| Circle::new((c.temperature_c, closed(c)), 5, col.stroke_width(2))),
            )?
            .label(format!("closed form, {f} Hz"))
            .legend(move |(x, y)| Circle::new((x + 9, y), 4, col.stroke_width(2)));
            ch.draw_series(
                cs.iter()
                    .filter_map(|c| Some((c.temperature_c, paper(c)?)))
                    .filter(|p| p.1 > 0.0)
                    .map(|p| Cross::new(p, 6, col.stroke_width(2))),
            )?
            .label(format!("paper Eq. 15–16, {f} Hz"))
            .legend(move |(x, y)| Cross::new((x + 9, y), 5, col.stroke_width(2)));
        }
        ch.configure_series_labels()
            .position(SeriesLabelPosition::LowerLeft)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}

fn warmup(r: &SweepResult, path: &Path) -> R {
    let root = SVGBackend::new(path, (1000, 700)).into_drawing_area();
    root.fill(&WHITE)?;
    let (top, bottom) = root.split_vertically(430);
    let t_end = r.warmups.iter().map(|(_, t)| *t.time.last().unwrap_or(&1.0)).fold(1.0, f64::max);
    let temps = r.warmups.iter().flat_map(|(_, t)| {
        t.column(rig::O_HOUSING).iter().chain(t.column(rig::O_PCL)).map(|v| v - ZERO_CELSIUS).collect::<Vec<_>>()
    });
    let (y0, y1) = range(temps);
    let mut ch = ChartBuilder::on(&top)
        .caption(
            "Warm-up: housing (thick: the thermocouple) and PCL (thin: the model's estimate, no sensor)",
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(32)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..t_end, y0..y1)?;
    ch.configure_mesh().x_desc("time (s)").y_desc("temperature (°C)").draw()?;
    for (i, (w, t)) in r.warmups.iter().enumerate() {
        let col = PALETTE[i % PALETTE.len()];
        let c = |o: usize| t.column(o).iter().map(|v| v - ZERO_CELSIUS).collect::<Vec<_>>();
        let (h, p) = (c(rig::O_HOUSING), c(rig::O_PCL));
        ch.draw_series(LineSeries::new(thin(&t.time, &h, 2000), col.stroke_width(2)))?
            .label(format!("target {} °C: housing", w.target_c))
            .legend(legend(col));
        ch.draw_series(LineSeries::new(thin(&t.time, &p, 2000), col.stroke_width(1)))?
            .label(format!("target {} °C: PCL", w.target_c))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], col.stroke_width(1)));
    }
    ch.configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()?;
    let (p0, p1) = range(r.warmups.iter().flat_map(|(_, t)| t.heater_power.clone()).chain([0.0]));
    let mut ch = ChartBuilder::on(&bottom)
        .caption("Heater power", ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(32)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..t_end, p0..p1)?;
    ch.configure_mesh().x_desc("time (s)").y_desc("W").draw()?;
    for (i, (_, t)) in r.warmups.iter().enumerate() {
        let col = PALETTE[i % PALETTE.len()];
        ch.draw_series(LineSeries::new(thin(&t.time, &t.heater_power, 2000), col.stroke_width(1)))?;
    }
    root.present()?;
    Ok(())
}

/// The heating–cooling cycle: K_eff and crystallinity against time and against PCL temperature,
/// crystallisation kinetics (thick) and the equilibrium law (thin).
fn cooling_cycle(r: &SweepResult, path: &Path) -> R {
    let root = SVGBackend::new(path, (1200, 820)).into_drawing_area();
    root.fill(&WHITE)?;
    let (title, body) = root.split_vertically(36);
    title.draw(&Text::new(
        format!(
            "Heating–cooling cycle: {} W until the PCL reaches {} °C, then heater off (thick: Nakamura kinetics, thin: equilibrium law)",
            r.cooling_cycles[0].power_w, r.cooling_cycles[0].target_c
        ),
        (10, 10),
        ("sans-serif", 16),
    ))?;
    let panels = body.split_evenly((2, 2));
    let t_end = r.cooling_cycles.iter().map(|c| *c.trace.time_s.last().unwrap_or(&1.0)).fold(1.0, f64::max);
    let (k0, k1) = range(r.cooling_cycles.iter().flat_map(|c| c.trace.k_eff.clone()));
    let (x0, x1) = range(r.cooling_cycles.iter().flat_map(|c| c.trace.crystallinity.clone()).chain([0.0]));
    let (p0, p1) = range(r.cooling_cycles.iter().flat_map(|c| c.trace.pcl_c.clone()));
    type Pick = fn(&super::cycle::CycleTrace) -> &Vec<f64>;
    type Panel = (&'static str, &'static str, Pick, Pick, (f64, f64), (f64, f64));
    let specs: [Panel; 4] = [
        ("K_eff against time", "time (s)", |t| &t.time_s, |t| &t.k_eff, (0.0, t_end), (k0, k1)),
        ("crystallinity X against time", "time (s)", |t| &t.time_s, |t| &t.crystallinity, (0.0, t_end), (x0, x1)),
        ("K_eff against PCL temperature", "PCL temperature (°C)", |t| &t.pcl_c, |t| &t.k_eff, (p0, p1), (k0, k1)),
        (
            "crystallinity X against PCL temperature",
            "PCL temperature (°C)",
            |t| &t.pcl_c,
            |t| &t.crystallinity,
            (p0, p1),
            (x0, x1),
        ),
    ];
    for (panel, (caption, xdesc, fx, fy, (xa, xb), (ya, yb))) in panels.iter().zip(specs) {
        let mut ch = ChartBuilder::on(panel)
            .caption(caption, ("sans-serif", 15))
            .margin(8)
            .x_label_area_size(30)
            .y_label_area_size(56)
            .build_cartesian_2d(xa..xb, ya..yb)?;
        let ydesc = if caption.starts_with("K_eff") { "N·m/rad" } else { "X" };
        ch.configure_mesh().x_desc(xdesc).y_desc(ydesc).draw()?;
        for (i, c) in r.cooling_cycles.iter().enumerate() {
            let col = PALETTE[i % PALETTE.len()];
            let width = if c.law == "nakamura" { 2 } else { 1 };
            ch.draw_series(LineSeries::new(thin(fx(&c.trace), fy(&c.trace), 3000), col.stroke_width(width)))?
                .label(c.law)
                .legend(legend(col));
        }
        ch.configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
    }
    root.present()?;
    Ok(())
}
