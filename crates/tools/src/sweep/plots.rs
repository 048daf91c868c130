//! SVG figures of a sweep (plotters, SVG backend): trajectories like the paper's Fig. 6, Decay like
//! Fig. 7, moduli against temperature like Fig. 4, and the warm-up. Layout, tick labels, legends and
//! styles come from [`crate::report::plot`].

use std::error::Error;
use std::path::Path;

use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use super::rig::{self, ZERO_CELSIUS};
use super::SweepResult;
use crate::report::plot::{
    draw, figure, figure_rows, log_axis, log_range, number, panel, plot_pixels, range, thin, wrap, Dash, Entry, Marker,
    Style, BLACK_, BLUE_, GREY_, PALETTE, PURPLE_, RED_,
};

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

/// The i-th frequency's (or target's, or law's) style: its colour and its marker.
fn nth(i: usize) -> Style {
    Style::nth(i)
}

/// Light grey over the analysed cycles (translucent, so the grid shows through).
fn shade_analysed<DB: DrawingBackend, X: Ranged<ValueType = f64>, Y: Ranged<ValueType = f64>>(
    ch: &mut ChartContext<'_, DB, Cartesian2d<X, Y>>,
    (t0, t1): (f64, f64),
    (y0, y1): (f64, f64),
) -> R
where
    DB::ErrorType: 'static,
{
    ch.draw_series(std::iter::once(Rectangle::new([(t0, y0), (t1, y1)], BLACK.mix(0.07).filled())))?;
    Ok(())
}

fn trajectories(r: &SweepResult, f: f64, path: &Path) -> R {
    let conds: Vec<_> = r.conditions.iter().filter(|c| c.frequency_hz == f).collect();
    let root = SVGBackend::new(path, (1200, 290 * conds.len() as u32 + 90)).into_drawing_area();
    // the three angles coincide to a fraction of a degree: a wide motor line under a thin link
    // line, a dashed reference, and markers at staggered places tell them apart where they overlap
    let reference = Style::line(BLACK_).width(1).dash(Dash::Dashed);
    let motor = Style::line(BLUE_).width(4);
    let link = Style::line(RED_).width(1).marker(Marker::Triangle);
    let diff = Style::line(PURPLE_).width(1);
    let legend: Vec<Entry> = vec![
        ("reference θ0 sin ωt".into(), reference),
        ("motor θm".into(), motor),
        ("link θl".into(), link),
        ("link − motor (right)".into(), diff),
    ];
    let body = figure(
        &root,
        &format!("Motor and link angle at {f} Hz from rest (left), link − motor (right); shaded: the analysed cycles"),
        &legend,
    )?;
    let rows = body.split_evenly((conds.len(), 2));
    for (i, c) in conds.iter().enumerate() {
        let t = &c.trace.time;
        let deg = |o: usize| c.trace.column(o).iter().map(|v| v.to_degrees()).collect::<Vec<_>>();
        let (m, l) = (deg(rig::O_MOTOR_ANGLE), deg(rig::O_LINK_ANGLE));
        let reference_deg: Vec<f64> = c.trace.reference.iter().map(|v| v.to_degrees()).collect();
        let (y0, y1) = range(m.iter().chain(&l).cloned());
        let t_end = *t.last().unwrap_or(&1.0);
        let t_win = t[c.window.0];
        let steady = c.window.0..(c.window.0 + c.window.1).min(t.len());
        let worst = |a: &[f64], b: &[f64]| {
            a[steady.clone()].iter().zip(&b[steady.clone()]).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
        };
        // say on the panel how close the curves are: the reader cannot see 0.1° at this scale
        let caption = format!(
            "{} °C (PCL {:.1} °C): |θl − θm| ≤ {}°, |θm − ref| ≤ {}°",
            c.temperature_c,
            c.pcl_temperature_c,
            number(worst(&l, &m), 2),
            number(worst(&m, &reference_deg), 2)
        );
        let mut ch = panel(&rows[2 * i], &caption, "time (s)", "angle (°)", 0.0..t_end, y0..y1)?;
        shade_analysed(&mut ch, (t_win, t_end), (y0, y1))?;
        // the wide motor line first, the thin link on it, the dashed reference on top of both
        draw(&mut ch, &thin(t, &m, 1500).collect::<Vec<_>>(), motor)?;
        draw(&mut ch, &thin(t, &l, 1500).collect::<Vec<_>>(), link)?;
        draw(&mut ch, &thin(t, &reference_deg, 1500).collect::<Vec<_>>(), reference)?;

        let d: Vec<f64> = l.iter().zip(&m).map(|(a, b)| a - b).collect();
        let (d0, d1) = range(d[c.window.0..].iter().cloned());
        let (d0, d1) = (
            d0.min(range(d.iter().cloned()).0.max(3.0 * d0 - 2.0 * d1)),
            d1.max(range(d.iter().cloned()).1.min(3.0 * d1 - 2.0 * d0)),
        );
        let clipped = d.iter().any(|v| *v < d0 || *v > d1);
        let caption = format!(
            "link − motor: Decay {:+.2} mrad, phase {:.3}°{}",
            c.decay_rad * 1e3,
            c.phase_deg,
            if clipped { " (start-up off scale)" } else { "" }
        );
        let mut ch = panel(&rows[2 * i + 1], &caption, "time (s)", "θl − θm (°)", 0.0..t_end, d0..d1)?;
        shade_analysed(&mut ch, (t_win, t_end), (d0, d1))?;
        let kept: Vec<(f64, f64)> = thin(t, &d, 3000).filter(|p| p.1 >= d0 && p.1 <= d1).collect();
        draw(&mut ch, &kept, diff)?;
    }
    root.present()?;
    Ok(())
}

/// Decay against temperature as the paper's Fig. 7 shows it, normalised to the first temperature,
/// but with its sign: D(T) / |D(first)|. The paper's Decay is positive (the link swings less than
/// the motor); the model's is negative (the link overshoots). A plain ratio D(60)/D(22) of two
/// negative numbers is positive and would sit beside the paper's "5×" as if it agreed.
fn decay(r: &SweepResult, path: &Path) -> R {
    let temps = &r.args.temperatures;
    let (first, last) = (temps[0], *temps.last().unwrap_or(&temps[0]));
    let root = SVGBackend::new(path, (900, 640)).into_drawing_area();
    let paper = Style::points(BLACK_, Marker::Triangle).hollow();
    // the frequencies' curves nearly coincide: hollow markers and a dash keep both visible
    let model = |i: usize| nth(i).hollow().dash(if i == 0 { Dash::Solid } else { Dash::Dashed });
    let mut legend: Vec<Entry> =
        r.args.frequencies.iter().enumerate().map(|(i, f)| (format!("model, {f} Hz"), model(i))).collect();
    legend.push(("paper, 0.5 Hz (Fig. 7: “nearly five times” at 60 °C)".into(), paper));
    let body = figure(
        &root,
        &format!("Decay D = θ0 − Θ relative to its size at {first} °C, sign kept (cf. the paper's Fig. 7)"),
        &legend,
    )?;
    let (plot_area, note_area) = body.split_vertically(body.dim_in_pixel().1 - 92);

    let series: Vec<Vec<(f64, f64)>> = r
        .args
        .frequencies
        .iter()
        .map(|&f| {
            let of_f = || r.conditions.iter().filter(move |c| c.frequency_hz == f);
            let reference = of_f().find(|c| c.temperature_c == first).map(|c| c.decay_rad.abs());
            of_f().filter_map(|c| Some((c.temperature_c, c.decay_rad / reference.filter(|d| *d > 0.0)?))).collect()
        })
        .collect();
    let paper_pts = [(first, 1.0), (last, super::report::PAPER_DECAY_RATIO_60_22_HALF_HZ)];
    let (x0, x1) = range(temps.iter().cloned());
    let (y0, y1) = range(series.iter().flatten().chain(&paper_pts).map(|p| p.1).chain([0.0]));
    let mut ch = panel(&plot_area, "", "housing temperature (°C)", &format!("D / |D at {first} °C|"), x0..x1, y0..y1)?;
    ch.draw_series(LineSeries::new([(x0, 0.0), (x1, 0.0)], BLACK.stroke_width(1)))?;
    for (i, pts) in series.iter().enumerate() {
        draw(&mut ch, pts, model(i))?;
    }
    draw(&mut ch, &paper_pts, paper)?;
    // which side of zero means what, at the right end of the zero line (the curves leave it there)
    let ((_, _), (px1, _)) = plot_pixels(&ch);
    let zero_y = ch.backend_coord(&(x0, 0.0)).1;
    let side = |text: &str, dy: i32, v: VPos| -> R {
        let style = TextStyle::from(("sans-serif", 13).into_font()).color(&GREY_).pos(Pos::new(HPos::Right, v));
        root.draw_text(text, &style, (px1 - 6, zero_y + dy))?;
        Ok(())
    };
    side("↑ D > 0: the link swings less than the motor", -4, VPos::Bottom)?;
    side("↓ D < 0: the link overshoots the motor", 4, VPos::Top)?;

    // the comparison in words, under the axes
    let sign = |f: f64| {
        let ds: Vec<f64> = r.conditions.iter().filter(|c| c.frequency_hz == f).map(|c| c.decay_rad).collect();
        if ds.iter().all(|d| *d < 0.0) {
            "negative"
        } else if ds.iter().all(|d| *d > 0.0) {
            "positive"
        } else {
            "of mixed sign"
        }
    };
    // the paper's claim is at 0.5 Hz: quote the model there (or at its first frequency)
    let fi = r.args.frequencies.iter().position(|&f| f == 0.5).unwrap_or(0);
    let at_last = series.get(fi).and_then(|s| s.iter().find(|p| p.0 == last)).map(|p| p.1);
    let note = if r.args.frequencies.iter().all(|&f| sign(f) == "negative") {
        format!(
            "The model's Decay is negative at every temperature (the link overshoots); the paper's is positive. \
             Their ratios are not comparable: the model's D({last} °C) / D({first} °C) at {} Hz is {}, a ratio of two \
             negative numbers; with its sign it is {} here. (The paper's text also says “30 % increase”.)",
            r.args.frequencies[fi],
            at_last.map_or("?".into(), |v| number(-v, 3)),
            at_last.map_or("?".into(), |v| number(v, 3)),
        )
    } else {
        let signs: Vec<String> = r.args.frequencies.iter().map(|&f| format!("{} at {f} Hz", sign(f))).collect();
        format!(
            "The model's Decay is {}; the paper's is positive. Only points on the same side of zero compare. \
             (The paper's text also says “30 % increase”.)",
            signs.join(", ")
        )
    };
    let (nw, _) = note_area.dim_in_pixel();
    for (k, line) in wrap(&note, nw - 40, 14).iter().enumerate() {
        let style = TextStyle::from(("sans-serif", 14).into_font()).color(&BLACK).pos(Pos::new(HPos::Left, VPos::Top));
        note_area.draw_text(line, &style, (20, 14 + 20 * k as i32))?;
    }
    root.present()?;
    Ok(())
}

fn moduli(r: &SweepResult, path: &Path) -> R {
    let root = SVGBackend::new(path, (1200, 560)).into_drawing_area();
    // colour and dash by frequency, marker by source
    let used_style =
        |i: usize| Style::line(PALETTE[i % PALETTE.len()]).dash(if i == 0 { Dash::Solid } else { Dash::Dashed });
    // the frequencies' estimates often coincide: concentric markers, the first frequency's largest
    let size = |i: usize| 6 - 2 * (i as i32 % 2);
    let closed_style = |i: usize| Style::points(PALETTE[i % PALETTE.len()], Marker::Circle).hollow().size(size(i));
    let paper_style = |i: usize| Style::points(PALETTE[i % PALETTE.len()], Marker::Cross).size(size(i));
    let legend: Vec<Vec<Entry>> = r
        .args
        .frequencies
        .iter()
        .enumerate()
        .map(|(i, f)| {
            vec![
                (format!("used by the FMU, {f} Hz runs"), used_style(i)),
                (format!("closed form, {f} Hz"), closed_style(i)),
                (format!("paper Eq. 15–16, {f} Hz"), paper_style(i)),
            ]
        })
        .collect();
    let body =
        figure_rows(&root, "PCL moduli used by the FMU vs estimated from the runs (cf. the paper's Fig. 4)", &legend)?;
    let panels = body.split_evenly((1, 2));
    let (x0, x1) = range(r.args.temperatures.iter().cloned());
    for (k, name) in ["E' (storage)", "E'' (loss)"].iter().enumerate() {
        let used = |c: &super::Condition| if k == 0 { c.model_e_storage_kpa } else { c.model_e_loss_kpa };
        let closed = |c: &super::Condition| if k == 0 { c.e_storage_kpa } else { c.e_loss_kpa };
        let paper = |c: &super::Condition| {
            c.paper_method.map(|p| if k == 0 { p.estimate.e_storage } else { p.estimate.e_loss } / 1e3)
        };
        let (lo, hi) =
            log_range(r.conditions.iter().flat_map(|c| [Some(used(c)), Some(closed(c)), paper(c)]).flatten());
        let mut ch = panel(&panels[k], name, "housing temperature (°C)", "kPa", x0..x1, log_axis(lo, hi))?;
        for (i, &f) in r.args.frequencies.iter().enumerate() {
            let cs: Vec<_> = r.conditions.iter().filter(|c| c.frequency_hz == f).collect();
            let positive = |p: &(f64, f64)| p.1 > 0.0;
            draw(&mut ch, &cs.iter().map(|c| (c.temperature_c, used(c))).collect::<Vec<_>>(), used_style(i))?;
            let pts: Vec<_> = cs.iter().map(|c| (c.temperature_c, closed(c))).filter(positive).collect();
            draw(&mut ch, &pts, closed_style(i))?;
            let pts: Vec<_> = cs.iter().filter_map(|c| Some((c.temperature_c, paper(c)?))).filter(positive).collect();
            draw(&mut ch, &pts, paper_style(i))?;
        }
    }
    root.present()?;
    Ok(())
}

fn warmup(r: &SweepResult, path: &Path) -> R {
    let root = SVGBackend::new(path, (1100, 780)).into_drawing_area();
    // colour and marker by target; solid for the housing, dashed for the PCL
    let targets: Vec<Entry> =
        r.warmups.iter().enumerate().map(|(i, (w, _))| (format!("target {} °C", w.target_c), nth(i))).collect();
    let kinds: Vec<Entry> = vec![
        ("housing (the thermocouple)".into(), Style::line(BLACK_)),
        ("PCL (the model's estimate, no sensor)".into(), Style::line(BLACK_).width(1).dash(Dash::Dashed)),
    ];
    let body = figure_rows(&root, "Warm-up to each target temperature", &[targets, kinds])?;
    let (top, bottom) = body.split_vertically(body.dim_in_pixel().1 * 62 / 100);
    let t_end = r.warmups.iter().map(|(_, t)| *t.time.last().unwrap_or(&1.0)).fold(1.0, f64::max);
    let temps = r.warmups.iter().flat_map(|(_, t)| {
        t.column(rig::O_HOUSING).iter().chain(t.column(rig::O_PCL)).map(|v| v - ZERO_CELSIUS).collect::<Vec<_>>()
    });
    let (y0, y1) = range(temps);
    let mut ch = panel(&top, "Temperatures", "time (s)", "temperature (°C)", 0.0..t_end, y0..y1)?;
    for (i, (_, t)) in r.warmups.iter().enumerate() {
        let c = |o: usize| t.column(o).iter().map(|v| v - ZERO_CELSIUS).collect::<Vec<_>>();
        let (h, p) = (c(rig::O_HOUSING), c(rig::O_PCL));
        draw(&mut ch, &thin(&t.time, &h, 2000).collect::<Vec<_>>(), nth(i))?;
        draw(&mut ch, &thin(&t.time, &p, 2000).collect::<Vec<_>>(), nth(i).width(1).dash(Dash::Dashed).hollow())?;
    }
    let (p0, p1) = range(r.warmups.iter().flat_map(|(_, t)| t.heater_power.clone()).chain([0.0]));
    let mut ch = panel(&bottom, "Heater power", "time (s)", "power (W)", 0.0..t_end, p0..p1)?;
    for (i, (_, t)) in r.warmups.iter().enumerate() {
        draw(&mut ch, &thin(&t.time, &t.heater_power, 2000).collect::<Vec<_>>(), nth(i).width(1))?;
    }
    root.present()?;
    Ok(())
}

/// The heating–cooling cycle: K_eff and crystallinity against time and against PCL temperature,
/// crystallisation kinetics and the equilibrium law.
fn cooling_cycle(r: &SweepResult, path: &Path) -> R {
    let root = SVGBackend::new(path, (1200, 860)).into_drawing_area();
    let law_style = |i: usize, law: &str| if law == "nakamura" { nth(i) } else { nth(i).dash(Dash::Dashed) };
    let law_name = |law: &str| match law {
        "nakamura" => "Nakamura crystallisation kinetics".to_string(),
        "equilibrium" => "equilibrium law".to_string(),
        other => other.to_string(),
    };
    let legend: Vec<Entry> =
        r.cooling_cycles.iter().enumerate().map(|(i, c)| (law_name(c.law), law_style(i, c.law))).collect();
    let body = figure(
        &root,
        &format!(
            "Heating–cooling cycle: {} W until the PCL reaches {} °C, then heater off",
            r.cooling_cycles[0].power_w, r.cooling_cycles[0].target_c
        ),
        &legend,
    )?;
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
    for (area, (caption, xdesc, fx, fy, (xa, xb), (ya, yb))) in panels.iter().zip(specs) {
        let ydesc = if caption.starts_with("K_eff") { "K_eff (N·m/rad)" } else { "crystallinity X" };
        let mut ch = panel(area, caption, xdesc, ydesc, xa..xb, ya..yb)?;
        for (i, c) in r.cooling_cycles.iter().enumerate() {
            draw(&mut ch, &thin(fx(&c.trace), fy(&c.trace), 3000).collect::<Vec<_>>(), law_style(i, c.law))?;
        }
    }
    root.present()?;
    Ok(())
}
