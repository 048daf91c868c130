//! SVG plots for every tool's report (plotters): one palette, one way to thin long traces and to
//! pad axis ranges, one legend style, and a general line/marker chart.

use plotters::element::PathElement;
use plotters::prelude::*;

pub struct Series<'a> {
    pub name: &'a str,
    pub points: Vec<(f64, f64)>,
    pub color: RGBColor,
    /// Draw markers instead of a line. An empty name keeps the series out of the legend.
    pub markers: bool,
}

pub const BLUE_: RGBColor = RGBColor(31, 119, 180);
pub const RED_: RGBColor = RGBColor(214, 39, 40);
pub const GREY_: RGBColor = RGBColor(120, 120, 120);
pub const GREEN_: RGBColor = RGBColor(44, 160, 44);
pub const ORANGE_: RGBColor = RGBColor(255, 127, 14);
pub const PURPLE_: RGBColor = RGBColor(148, 103, 189);
pub const BROWN_: RGBColor = RGBColor(140, 86, 75);

/// Series colours in order (matplotlib's tab10, so plots look alike across tools).
pub const PALETTE: [RGBColor; 6] = [BLUE_, RED_, GREEN_, ORANGE_, PURPLE_, BROWN_];

/// Every `k`-th point so a line has at most ~`max` points (keeps SVG files small).
pub fn thin<'a>(x: &'a [f64], y: &'a [f64], max: usize) -> impl Iterator<Item = (f64, f64)> + 'a {
    let k = (x.len() / max).max(1);
    x.iter().zip(y).step_by(k).map(|(a, b)| (*a, *b))
}

/// The finite values' range padded by 8 % (never empty; (0, 1) when nothing is finite).
pub fn range(vals: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let pad = ((hi - lo) * 0.08).max(1e-9 * hi.abs().max(1.0));
    (lo - pad, hi + pad)
}

/// A legend entry: a short line in the series' colour.
pub fn legend(color: RGBColor) -> impl Fn((i32, i32)) -> PathElement<(i32, i32)> {
    move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], color.stroke_width(2))
}

fn bounds(series: &[Series]) -> ((f64, f64), (f64, f64)) {
    let mut x = (f64::INFINITY, f64::NEG_INFINITY);
    let mut y = (f64::INFINITY, f64::NEG_INFINITY);
    for s in series {
        for &(a, b) in &s.points {
            if a.is_finite() && b.is_finite() {
                x = (x.0.min(a), x.1.max(a));
                y = (y.0.min(b), y.1.max(b));
            }
        }
    }
    let pad = |(lo, hi): (f64, f64)| {
        let d = if hi > lo { 0.05 * (hi - lo) } else { 0.5 * lo.abs().max(1.0) };
        (lo - d, hi + d)
    };
    (pad(x), pad(y))
}

/// A chart of lines and/or markers. `equal_aspect` keeps x and y scales equal (tip paths).
pub fn chart(
    path: &std::path::Path,
    title: &str,
    xlabel: &str,
    ylabel: &str,
    series: &[Series],
    equal_aspect: bool,
) -> Result<(), String> {
    let ((x0, x1), (mut y0, mut y1)) = bounds(series);
    let (w, h) = (900u32, 560u32);
    if equal_aspect {
        // plotting area is about (w-110) x (h-110) px; widen the y range to match
        let want = (x1 - x0) * (h as f64 - 110.0) / (w as f64 - 110.0);
        if want > y1 - y0 {
            let c = 0.5 * (y0 + y1);
            y0 = c - 0.5 * want;
            y1 = c + 0.5 * want;
        }
    }
    let root = SVGBackend::new(path, (w, h)).into_drawing_area();
    let e = |e: &dyn std::fmt::Display| format!("{}: {e}", path.display());
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let mut c = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(45)
        .y_label_area_size(65)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(|x| e(&x))?;
    c.configure_mesh().x_desc(xlabel).y_desc(ylabel).light_line_style(WHITE.mix(0.0)).draw().map_err(|x| e(&x))?;
    for s in series {
        let color = s.color;
        if s.markers {
            let drawn =
                c.draw_series(s.points.iter().map(|&p| Circle::new(p, 3, color.filled()))).map_err(|x| e(&x))?;
            if !s.name.is_empty() {
                drawn.label(s.name).legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()));
            }
        } else {
            c.draw_series(LineSeries::new(
                s.points.iter().copied().filter(|p| p.0.is_finite() && p.1.is_finite()),
                color.stroke_width(2),
            ))
            .map_err(|x| e(&x))?
            .label(s.name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2)));
        }
    }
    c.configure_series_labels().background_style(WHITE.mix(0.85)).border_style(BLACK).draw().map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))?;
    Ok(())
}
