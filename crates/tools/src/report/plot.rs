//! SVG plots for every tool's report (plotters). One look for every figure, so a reader trusts it
//! at a glance:
//!
//! - tick labels by [`tick`] and [`number`]: no float noise (`9.999999999999999e-5` is `1e-4`), no
//!   `-0`, no `20.0`; scientific only outside 0.001–99 999;
//! - label areas and margins sized from the labels they hold ([`panel`]), so nothing is clipped
//!   and no tick label runs into an axis title;
//! - legends above the panels ([`figure`]), never over the data;
//! - series told apart by colour (Okabe–Ito, safe for colour-blind readers) and by marker or dash
//!   ([`Style`]), so curves that lie on each other, or a grey print, still show which is which.

use std::error::Error;
use std::path::Path;

use plotters::coord::combinators::WithKeyPoints;
use plotters::coord::ranged1d::{AsRangedCoord, BoldPoints, ValueFormatter};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::Shift;
use plotters::element::PathElement;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

pub type Res<T = ()> = Result<T, Box<dyn Error>>;

// Okabe & Ito (2008), "Color Universal Design": told apart with any colour-vision deficiency.
pub const BLUE_: RGBColor = RGBColor(0, 114, 178);
/// Okabe–Ito vermillion: the palette's red.
pub const RED_: RGBColor = RGBColor(213, 94, 0);
/// Okabe–Ito bluish green.
pub const GREEN_: RGBColor = RGBColor(0, 158, 115);
pub const ORANGE_: RGBColor = RGBColor(230, 159, 0);
/// Okabe–Ito reddish purple.
pub const PURPLE_: RGBColor = RGBColor(204, 121, 167);
pub const SKY_: RGBColor = RGBColor(86, 180, 233);
/// For references (plans, walls, thresholds): recedes behind the data.
pub const GREY_: RGBColor = RGBColor(120, 120, 120);
pub const BLACK_: RGBColor = RGBColor(0, 0, 0);

/// Series colours in order.
pub const PALETTE: [RGBColor; 6] = [BLUE_, RED_, GREEN_, ORANGE_, PURPLE_, SKY_];

/// Font sizes as plotters takes them (its SVG writes size / 1.24 px): figure title, panel caption,
/// tick labels and legend, axis titles; 15, 13.7, 12.1 and 12.9 px in the SVG.
const TITLE: u32 = 19;
const CAPTION: u32 = 17;
const LABEL: u32 = 15;
const DESC: u32 = 16;
/// Tick labels per axis at most (plotters' hint).
const X_LABELS: usize = 10;
const Y_LABELS: usize = 8;

// ----------------------------------------------------------------------------------------------
// Numbers

/// `v` to `sig` significant digits, trailing zeros dropped: plain decimals from 0.001 to 99 999,
/// scientific outside (`1e-4`, `2.5e5`); zero and `-0` are `0`.
pub fn number(v: f64, sig: usize) -> String {
    let (mag_lo, mag_hi) = (-3, 5);
    format_sig(v, sig, |exp| !(mag_lo..mag_hi).contains(&exp))
}

/// A tick label for `v` on a linear axis from `lo` to `hi`: digits down to a thousandth of the
/// span (finer than any tick step, coarser than float noise), values within 1e-9 of the span from
/// zero are `0` (so `-0.0` and `5.6e-17` are), and one notation for the whole axis: scientific when
/// the axis' magnitude is outside 0.001–99 999, plain otherwise.
pub fn tick(v: f64, lo: f64, hi: f64) -> String {
    let span = (hi - lo).abs();
    if !v.is_finite() || !span.is_finite() || span == 0.0 {
        return number(v, 4);
    }
    if v.abs() <= span * 1e-9 {
        return "0".into();
    }
    let resolution = span / 1000.0;
    let sig = (v.abs().log10().floor() - resolution.log10().floor()) as i64 + 1;
    let magnitude = lo.abs().max(hi.abs());
    let sci = !(1e-3..1e5).contains(&magnitude);
    format_sig(v, sig.clamp(1, 12) as usize, |_| sci)
}

/// `v` rounded to `sig` significant digits, in scientific notation when `sci(exponent)` says so.
/// The exponent is taken after rounding, so 99 999.7 to 3 digits is `1e5`, not `100000`.
fn format_sig(v: f64, sig: usize, sci: impl Fn(i32) -> bool) -> String {
    if !v.is_finite() {
        return format!("{v}");
    }
    if v == 0.0 {
        return "0".into();
    }
    let sig = sig.clamp(1, 17);
    let e = format!("{:.*e}", sig - 1, v);
    let (mantissa, exp) = e.split_once('e').expect("`{:e}` has an exponent");
    let exp: i32 = exp.parse().expect("`{:e}` has an integer exponent");
    if sci(exp) {
        format!("{}e{exp}", trim_zeros(mantissa))
    } else {
        let decimals = (sig as i32 - 1 - exp).max(0) as usize;
        trim_zeros(&format!("{v:.decimals$}")).to_string()
    }
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

/// How an axis from lo to hi labels its ticks: linear axes by [`tick`]; log axes to 3 digits (their
/// ticks are 1, 2, 3, 5 or 7 times a power of ten), in one notation for the axis like [`tick`]:
/// `1e-8 … 1e0 … 1e2` when it reaches outside 0.001–99 999, `0.01 … 1 … 100` when not.
#[derive(Clone, Copy, Debug)]
pub enum Ticks {
    Linear(f64, f64),
    Log(f64, f64),
}

impl Ticks {
    pub fn label(self, v: f64) -> String {
        match self {
            Ticks::Linear(lo, hi) => tick(v, lo, hi),
            Ticks::Log(lo, hi) => {
                let sci = lo < 1e-3 || hi >= 1e5;
                format_sig(v, 3, |exp| sci || !(-3..5).contains(&exp))
            }
        }
    }
}

/// An axis whose tick labels this module writes.
pub trait TickAxis: Ranged<ValueType = f64> + ValueFormatter<f64> {
    fn ticks(&self) -> Ticks;
}

impl TickAxis for RangedCoordf64 {
    fn ticks(&self) -> Ticks {
        let r = self.range();
        Ticks::Linear(r.start, r.end)
    }
}

// not plain `LogCoord`: its own key points repeat 10 (as 9.999999999999998 and 10); use `log_axis`
impl TickAxis for WithKeyPoints<LogCoord<f64>> {
    fn ticks(&self) -> Ticks {
        let r = self.range();
        Ticks::Log(r.start, r.end)
    }
}

/// Every `k`-th point so a line has at most ~`max` points (keeps SVG files small).
pub fn thin<'a>(x: &'a [f64], y: &'a [f64], max: usize) -> impl Iterator<Item = (f64, f64)> + 'a {
    let k = (x.len() / max).max(1);
    x.iter().zip(y).step_by(k).map(|(a, b)| (*a, *b))
}

/// The smallest and largest finite value (None when there is none).
fn finite_span(vals: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    vals.filter(|v| v.is_finite()).fold(None, |span, v| match span {
        None => Some((v, v)),
        Some((lo, hi)) => Some((v.min(lo), v.max(hi))),
    })
}

/// The finite values' range padded by 8 % (never empty; (0, 1) when nothing is finite).
pub fn range(vals: impl Iterator<Item = f64>) -> (f64, f64) {
    let Some((lo, hi)) = finite_span(vals) else { return (0.0, 1.0) };
    let pad = ((hi - lo) * 0.08).max(1e-9 * hi.abs().max(1.0));
    (lo - pad, hi + pad)
}

/// The positive finite values' range for a log axis: padded by a factor 1.4 each way (so markers
/// clear the frame), and at least a factor of 4 wide so that [`log_axis`] has ticks to label.
/// (1, 10) when nothing is positive.
pub fn log_range(vals: impl Iterator<Item = f64>) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for v in vals.filter(|v| v.is_finite() && *v > 0.0) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return (1.0, 10.0);
    }
    let (lo, hi) = (lo / 1.4, hi * 1.4);
    let widen = (4.0 / (hi / lo)).max(1.0).sqrt();
    (lo / widen, hi * widen)
}

/// `m`·10^`k`, parsed from its decimal text: the nearest double, where plotters' log axis,
/// multiplying by ten from one tick to the next, drifts by an ulp (its 9.999999999999999e-5).
fn decimal(m: u32, k: i32) -> f64 {
    format!("{m}e{k}").parse().expect("a decimal literal")
}

/// Tick values of a log axis over [lo, hi]: (labelled, grid-only). 1, 2, 3, 5, 7 times the powers
/// of ten within a decade, 1, 2, 5 within 2.5 decades, the powers of ten within 8, every k-th power
/// beyond; the grid at 1…9 times each power, or at the powers over more than 8 decades.
pub fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    let decades = (hi / lo).log10();
    let (k0, k1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let within = |v: &f64| *v >= lo * (1.0 - 1e-9) && *v <= hi * (1.0 + 1e-9);
    let every = |ms: &[u32], step: i32| -> Vec<f64> {
        (k0..=k1)
            .filter(|k| k.rem_euclid(step) == 0)
            .flat_map(|k| ms.iter().map(move |&m| decimal(m, k)))
            .filter(within)
            .collect()
    };
    let all: Vec<u32> = (1..=9).collect();
    let bold = if decades <= 1.0 {
        every(&[1, 2, 3, 5, 7], 1)
    } else if decades <= 2.5 {
        every(&[1, 2, 5], 1)
    } else if decades <= 8.0 {
        every(&[1], 1)
    } else {
        every(&[1], (decades / 8.0).ceil() as i32)
    };
    let light = if decades <= 8.0 { every(&all, 1) } else { every(&[1], 1) };
    (bold, light)
}

/// A log axis over [lo, hi] with [`log_ticks`]: pass it to [`panel`] as `x` or `y`.
pub fn log_axis(lo: f64, hi: f64) -> WithKeyPoints<LogCoord<f64>> {
    let (bold, light) = log_ticks(lo, hi);
    (lo..hi).log_scale().with_key_points(bold).with_light_points(light)
}

// ----------------------------------------------------------------------------------------------
// Styles

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dash {
    Solid,
    Dashed,
    Dotted,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Marker {
    None,
    Circle,
    Square,
    Triangle,
    Diamond,
    Cross,
}

const MARKERS: [Marker; 5] = [Marker::Circle, Marker::Square, Marker::Triangle, Marker::Diamond, Marker::Cross];
const DASHES: [Dash; 3] = [Dash::Solid, Dash::Dashed, Dash::Dotted];

/// How a series is drawn. A line carries a few markers along it (staggered by marker shape, so
/// coinciding curves show each of theirs); a point series is markers only.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Style {
    pub color: RGBColor,
    pub width: u32,
    pub dash: Dash,
    pub marker: Marker,
    pub line: bool,
    pub filled: bool,
    /// Marker radius, px.
    pub size: i32,
}

impl Style {
    /// A solid 2 px line with no markers.
    pub const fn line(color: RGBColor) -> Style {
        Style { color, width: 2, dash: Dash::Solid, marker: Marker::None, line: true, filled: true, size: 4 }
    }
    /// Markers only.
    pub const fn points(color: RGBColor, marker: Marker) -> Style {
        Style { color, width: 2, dash: Dash::Solid, marker, line: false, filled: true, size: 4 }
    }
    /// The `i`-th series' colour, marker and dash: any two of the first 15 differ in at least two.
    pub fn nth(i: usize) -> Style {
        Style {
            color: PALETTE[i % PALETTE.len()],
            marker: MARKERS[i % MARKERS.len()],
            dash: DASHES[(i / MARKERS.len()) % DASHES.len()],
            ..Style::line(BLACK_)
        }
    }
    pub const fn dash(self, dash: Dash) -> Style {
        Style { dash, ..self }
    }
    pub const fn marker(self, marker: Marker) -> Style {
        Style { marker, ..self }
    }
    pub const fn width(self, width: u32) -> Style {
        Style { width, ..self }
    }
    /// Marker radius, px (4 by default): concentric markers of two sizes show two series that
    /// share their points.
    pub const fn size(self, size: i32) -> Style {
        Style { size, ..self }
    }
    pub const fn hollow(self) -> Style {
        Style { filled: false, ..self }
    }
    fn stroke(&self) -> ShapeStyle {
        self.color.stroke_width(self.width)
    }
}

/// Runs `$body` with `$mk`, a closure from a coordinate (data or pixels) to the marker of `$style`
/// there. A macro, not a function returning a boxed element: plotters' `DynElement` would need a
/// `'static` backend, which an SVG written to a string is not.
macro_rules! with_marker {
    ($style:expr, |$mk:ident| $body:expr) => {{
        let style: &Style = $style;
        let r = style.size;
        let stroke = style.color.stroke_width(style.width.clamp(1, 2));
        let fill = if style.filled { style.color.filled() } else { stroke };
        let diamond = vec![(0, -r - 1), (r + 1, 0), (0, r + 1), (-r - 1, 0), (0, -r - 1)];
        match style.marker {
            Marker::None => Ok(()),
            Marker::Circle => {
                let $mk = |p| EmptyElement::at(p) + Circle::new((0, 0), r, fill);
                $body
            }
            Marker::Square => {
                let $mk = |p| EmptyElement::at(p) + Rectangle::new([(-r, -r), (r, r)], fill);
                $body
            }
            Marker::Triangle => {
                let $mk = |p| EmptyElement::at(p) + TriangleMarker::new((0, 0), r + 1, fill);
                $body
            }
            Marker::Diamond if style.filled => {
                let $mk = |p| EmptyElement::at(p) + Polygon::new(diamond.clone(), fill);
                $body
            }
            Marker::Diamond => {
                let $mk = |p| EmptyElement::at(p) + PathElement::new(diamond.clone(), stroke);
                $body
            }
            Marker::Cross => {
                let $mk = |p| EmptyElement::at(p) + Cross::new((0, 0), r, stroke);
                $body
            }
        }
    }};
}

/// Where the markers of a line of `n` points go: 10 of them, offset by the marker's shape so that
/// curves lying on each other show every marker.
fn marker_indices(n: usize, m: Marker) -> Vec<usize> {
    let count = 10;
    if n == 0 || m == Marker::None {
        return Vec::new();
    }
    let phase = MARKERS.iter().position(|&k| k == m).unwrap_or(0) as f64 / MARKERS.len() as f64;
    let mut idx: Vec<usize> =
        (0..count).map(|j| (((j as f64 + 0.25 + 0.5 * phase) / count as f64) * n as f64) as usize).collect();
    idx.retain(|&i| i < n);
    idx.dedup();
    idx
}

/// Draws `points` (non-finite ones dropped) in `style` on a chart.
pub fn draw<DB, X, Y>(ch: &mut ChartContext<'_, DB, Cartesian2d<X, Y>>, points: &[(f64, f64)], style: Style) -> Res
where
    DB: DrawingBackend,
    DB::ErrorType: 'static,
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
{
    let pts: Vec<(f64, f64)> = points.iter().copied().filter(|p| p.0.is_finite() && p.1.is_finite()).collect();
    if style.line {
        match style.dash {
            Dash::Solid => {
                ch.draw_series(LineSeries::new(pts.iter().copied(), style.stroke()))?;
            }
            Dash::Dashed => {
                ch.draw_series(DashedLineSeries::new(pts.iter().copied(), 9, 5, style.stroke()))?;
            }
            Dash::Dotted => {
                ch.draw_series(DashedLineSeries::new(pts.iter().copied(), 2, 4, style.stroke()))?;
            }
        }
    }
    let at: Vec<(f64, f64)> =
        if style.line { marker_indices(pts.len(), style.marker).into_iter().map(|i| pts[i]).collect() } else { pts };
    with_marker!(&style, |mk| {
        ch.draw_series(at.iter().map(|&p| mk(p)))?;
        Ok(())
    })
}

// ----------------------------------------------------------------------------------------------
// Layout

/// Width in px of `s` in plotters' sans-serif font of `size` (drawn at size / 1.24 px): 0.6 em a
/// character (DejaVu Sans, which rsvg and most browsers pick, averages a little less), so layouts
/// err on the side of room.
pub fn text_width(s: &str, size: u32) -> u32 {
    (s.chars().count() as f64 * 0.6 * size as f64 / 1.24).ceil() as u32
}

/// Height in px of a line of text of plotters' `size`.
fn text_height(size: u32) -> u32 {
    (size as f64 / 1.24 * 1.2).ceil() as u32
}

fn font(size: u32) -> TextStyle<'static> {
    TextStyle::from(("sans-serif", size).into_font()).color(&BLACK)
}

/// `text` broken at spaces into lines at most `width` px wide.
pub fn wrap(text: &str, width: u32, size: u32) -> Vec<String> {
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for word in text.split(' ') {
        let candidate = if line.is_empty() { word.to_string() } else { format!("{line} {word}") };
        if !line.is_empty() && text_width(&candidate, size) > width {
            lines.push(std::mem::replace(&mut line, word.to_string()));
        } else {
            line = candidate;
        }
    }
    lines.push(line);
    lines
}

/// A legend entry: its text and how its series is drawn.
pub type Entry = (String, Style);

const SAMPLE: i32 = 36;
const ROW: u32 = 20;

/// The legend's entries in rows that fit `width` px.
fn legend_rows(entries: &[Entry], width: u32) -> Vec<Vec<usize>> {
    let mut rows: Vec<Vec<usize>> = Vec::new();
    let mut used = 0;
    // (a group's rows; `figure_rows` starts each group on its own row)
    for (i, (label, _)) in entries.iter().enumerate() {
        let w = entry_width(label);
        if rows.is_empty() || used + w > width.saturating_sub(24) {
            rows.push(Vec::new());
            used = 0;
        }
        rows.last_mut().expect("a row was pushed").push(i);
        used += w;
    }
    rows
}

fn entry_width(label: &str) -> u32 {
    SAMPLE as u32 + 8 + text_width(label, LABEL) + 24
}

/// A legend's sample: a short stretch of the line with its marker, or the marker alone.
fn sample<DB: DrawingBackend>(area: &DrawingArea<DB, Shift>, (x, y): (i32, i32), s: &Style) -> Res
where
    DB::ErrorType: 'static,
{
    if s.line {
        let (on, off) = match s.dash {
            Dash::Solid => (SAMPLE, 0),
            Dash::Dashed => (9, 5),
            Dash::Dotted => (2, 4),
        };
        let mut a = x;
        while a < x + SAMPLE {
            let b = (a + on).min(x + SAMPLE);
            area.draw(&PathElement::new(vec![(a, y), (b, y)], s.stroke()))?;
            a = b + off;
        }
    }
    with_marker!(s, |mk| {
        area.draw(&mk((x + SAMPLE / 2, y)))?;
        Ok(())
    })
}

/// Fills `root` white, writes `title` (wrapped) and the legend under it, and returns the area left
/// for the panels: a legend above the panels never hides data.
pub fn figure<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    legend: &[Entry],
) -> Res<DrawingArea<DB, Shift>>
where
    DB::ErrorType: 'static,
{
    figure_rows(root, title, &[legend.to_vec()])
}

/// [`figure`] with the legend in groups, each starting a row (a row per frequency, say).
pub fn figure_rows<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    groups: &[Vec<Entry>],
) -> Res<DrawingArea<DB, Shift>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (w, _) = root.dim_in_pixel();
    let lines = if title.is_empty() { Vec::new() } else { wrap(title, w - 24, TITLE) };
    let line_h = text_height(TITLE) + 4;
    let title_h = if lines.is_empty() { 4 } else { 10 + line_h * lines.len() as u32 };
    for (k, line) in lines.iter().enumerate() {
        let style = font(TITLE).pos(Pos::new(HPos::Center, VPos::Top));
        root.draw_text(line, &style, (w as i32 / 2, 8 + (line_h * k as u32) as i32))?;
    }
    let legend: Vec<Entry> = groups.concat();
    let mut rows: Vec<Vec<usize>> = Vec::new();
    for (g, group) in groups.iter().enumerate() {
        let before: usize = groups[..g].iter().map(Vec::len).sum();
        rows.extend(legend_rows(group, w).into_iter().map(|r| r.into_iter().map(|i| i + before).collect()));
    }
    let legend_h = if legend.is_empty() { 0 } else { ROW * rows.len() as u32 + 8 };
    for (r, row) in rows.iter().enumerate() {
        let total: u32 = row.iter().map(|&i| entry_width(&legend[i].0)).sum();
        let mut x = (w.saturating_sub(total) / 2) as i32;
        let y = (title_h + ROW * r as u32 + ROW / 2) as i32;
        for &i in row {
            let (label, style) = &legend[i];
            sample(root, (x, y), style)?;
            let style_t = font(LABEL).pos(Pos::new(HPos::Left, VPos::Center));
            root.draw_text(label, &style_t, (x + SAMPLE + 8, y))?;
            x += entry_width(label) as i32;
        }
    }
    Ok(root.split_vertically(title_h + legend_h).1)
}

/// Sizes of a panel's frame, in px.
struct Frame {
    y_area: u32,
    x_area: u32,
    right: u32,
    top: u32,
}

/// The label areas and margins that hold `x` and `y`'s tick labels and titles without clipping
/// or overlap: y labels right-aligned 10 px off the axis (plotters' distance), the y title beyond
/// the widest; the last x label centred on the frame's right edge needs half its width there.
fn frame<X: TickAxis, Y: TickAxis>(x: &X, y: &Y, ydesc: &str) -> Frame {
    let labels = |r: &dyn Fn(BoldPoints) -> Vec<f64>, t: Ticks, n| -> Vec<String> {
        r(BoldPoints(n)).into_iter().map(|v| t.label(v)).collect()
    };
    let yl = labels(&|h| y.key_points(h), y.ticks(), Y_LABELS);
    let xl = labels(&|h| x.key_points(h), x.ticks(), X_LABELS);
    let widest = yl.iter().map(|s| text_width(s, LABEL)).max().unwrap_or(0);
    let desc = if ydesc.is_empty() { 0 } else { text_height(DESC) + 8 };
    let last = xl.last().map_or(0, |s| text_width(s, LABEL));
    Frame {
        y_area: 10 + widest + 6 + desc,
        x_area: 10 + text_height(LABEL) + 8 + text_height(DESC) + 4,
        right: (last / 2 + 6).max(16),
        top: 10,
    }
}

/// A chart on `area` with `caption` over it, axes `x` and `y` (`a..b`, or [`log_axis`])
/// titled `xdesc` and `ydesc`, its tick labels by [`Ticks::label`] and its frame sized to them, the
/// mesh drawn; draw the data with [`draw`].
#[allow(clippy::type_complexity)]
pub fn panel<'a, DB, XR, YR>(
    area: &'a DrawingArea<DB, Shift>,
    caption: &str,
    xdesc: &str,
    ydesc: &str,
    x: XR,
    y: YR,
) -> Res<ChartContext<'a, DB, Cartesian2d<XR::CoordDescType, YR::CoordDescType>>>
where
    DB: DrawingBackend,
    DB::ErrorType: 'static,
    XR: AsRangedCoord<Value = f64>,
    YR: AsRangedCoord<Value = f64>,
    XR::CoordDescType: TickAxis,
    YR::CoordDescType: TickAxis,
{
    let (xc, yc): (XR::CoordDescType, YR::CoordDescType) = (x.into(), y.into());
    let f = frame(&xc, &yc, ydesc);
    let (xt, yt) = (xc.ticks(), yc.ticks());
    let mut b = ChartBuilder::on(area);
    b.margin_left(6).margin_right(f.right).margin_top(f.top).margin_bottom(4);
    b.x_label_area_size(f.x_area).y_label_area_size(f.y_area);
    if !caption.is_empty() {
        b.caption(caption, ("sans-serif", CAPTION));
    }
    let mut ch = b.build_cartesian_2d(xc, yc)?;
    let (xf, yf) = (move |v: &f64| xt.label(*v), move |v: &f64| yt.label(*v));
    ch.configure_mesh()
        .x_labels(X_LABELS)
        .y_labels(Y_LABELS)
        .x_label_formatter(&xf)
        .y_label_formatter(&yf)
        .label_style(("sans-serif", LABEL))
        .axis_desc_style(("sans-serif", DESC))
        .x_desc(xdesc)
        .y_desc(ydesc)
        .bold_line_style(BLACK.mix(0.15))
        .light_line_style(BLACK.mix(0.05))
        .draw()?;
    Ok(ch)
}

/// A pixel rectangle of a chart's plotting area, in the root area's pixels: where annotations go.
pub fn plot_pixels<DB: DrawingBackend, X: Ranged, Y: Ranged>(
    ch: &ChartContext<'_, DB, Cartesian2d<X, Y>>,
) -> ((i32, i32), (i32, i32)) {
    let (xr, yr) = ch.plotting_area().get_pixel_range();
    ((xr.start, yr.start), (xr.end, yr.end))
}

// ----------------------------------------------------------------------------------------------
// The general chart

/// A named series of a [`chart`]; an empty name keeps it out of the legend.
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    pub style: Style,
}

impl Series {
    pub fn new(name: impl Into<String>, points: Vec<(f64, f64)>, style: Style) -> Series {
        Series { name: name.into(), points, style }
    }
}

/// A chart's title, axis titles and scales.
#[derive(Clone, Debug)]
pub struct Axes {
    pub title: String,
    pub x: String,
    pub y: String,
    pub x_log: bool,
    pub y_log: bool,
    /// Keep x and y scales equal (tip paths).
    pub equal_aspect: bool,
    pub size: (u32, u32),
}

impl Axes {
    pub fn new(title: impl Into<String>, x: impl Into<String>, y: impl Into<String>) -> Axes {
        Axes {
            title: title.into(),
            x: x.into(),
            y: y.into(),
            x_log: false,
            y_log: false,
            equal_aspect: false,
            size: (900, 560),
        }
    }
    pub fn log_x(self) -> Axes {
        Axes { x_log: true, ..self }
    }
    pub fn log_y(self) -> Axes {
        Axes { y_log: true, ..self }
    }
    pub fn equal_aspect(self) -> Axes {
        Axes { equal_aspect: true, ..self }
    }
    pub fn size(self, w: u32, h: u32) -> Axes {
        Axes { size: (w, h), ..self }
    }
}

fn bounds(series: &[Series], pick: impl Fn(&(f64, f64)) -> f64, log: bool) -> (f64, f64) {
    let vals = series.iter().flat_map(|s| s.points.iter().map(&pick));
    if log {
        return log_range(vals);
    }
    let Some((lo, hi)) = finite_span(vals) else { return (0.0, 1.0) };
    let d = if hi > lo { 0.05 * (hi - lo) } else { 0.5 * lo.abs().max(1.0) };
    (lo - d, hi + d)
}

/// A chart of lines and/or markers written to `path`.
pub fn chart(path: &Path, axes: &Axes, series: &[Series]) -> Result<(), String> {
    let e = |x: &dyn std::fmt::Display| format!("{}: {x}", path.display());
    let root = SVGBackend::new(path, axes.size).into_drawing_area();
    chart_on(&root, axes, series).map_err(|x| e(&x))?;
    root.present().map_err(|x| e(&x))
}

/// A chart of lines and/or markers as SVG text.
pub fn chart_svg(axes: &Axes, series: &[Series]) -> Res<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, axes.size).into_drawing_area();
        chart_on(&root, axes, series)?;
        root.present()?;
    }
    Ok(svg)
}

fn chart_on<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, axes: &Axes, series: &[Series]) -> Res
where
    DB::ErrorType: 'static,
{
    let mut legend: Vec<Entry> =
        series.iter().filter(|s| !s.name.is_empty()).map(|s| (s.name.clone(), s.style)).collect();
    if series.len() == 1 {
        legend.clear(); // one series: the axis title names it
    }
    let body = figure(root, &axes.title, &legend)?;
    let (x0, x1) = bounds(series, |p| p.0, axes.x_log);
    let (mut y0, mut y1) = bounds(series, |p| p.1, axes.y_log);
    if axes.equal_aspect && !axes.x_log && !axes.y_log {
        // widen y so that a metre is as long on both axes, from the frame the labels will need
        let (w, h) = body.dim_in_pixel();
        let f = frame(&RangedCoordf64::from(x0..x1), &RangedCoordf64::from(y0..y1), &axes.y);
        let (pw, ph) = ((w - f.y_area - f.right - 6) as f64, (h - f.x_area - f.top - 4) as f64);
        let want = (x1 - x0) * ph / pw;
        if want > y1 - y0 {
            let c = 0.5 * (y0 + y1);
            (y0, y1) = (c - 0.5 * want, c + 0.5 * want);
        }
    }
    fn go<DB: DrawingBackend, X: TickAxis, Y: TickAxis>(
        mut ch: ChartContext<'_, DB, Cartesian2d<X, Y>>,
        series: &[Series],
    ) -> Res
    where
        DB::ErrorType: 'static,
    {
        for s in series {
            draw(&mut ch, &s.points, s.style)?;
        }
        Ok(())
    }
    let (xd, yd) = (axes.x.as_str(), axes.y.as_str());
    match (axes.x_log, axes.y_log) {
        (false, false) => go(panel(&body, "", xd, yd, x0..x1, y0..y1)?, series),
        (true, false) => go(panel(&body, "", xd, yd, log_axis(x0, x1), y0..y1)?, series),
        (false, true) => go(panel(&body, "", xd, yd, x0..x1, log_axis(y0, y1))?, series),
        (true, true) => go(panel(&body, "", xd, yd, log_axis(x0, x1), log_axis(y0, y1))?, series),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_rounded_to_their_digits_without_float_noise() {
        assert_eq!(number(9.999999999999999e-5, 3), "1e-4");
        assert_eq!(number(1000.0000000000001, 3), "1000");
        assert_eq!(number(0.30000000000000004, 3), "0.3");
        assert_eq!(number(20.0, 3), "20");
        assert_eq!(number(-0.0, 3), "0");
        assert_eq!(number(0.001, 3), "0.001");
        assert_eq!(number(0.00025, 3), "2.5e-4");
        assert_eq!(number(99_999.7, 3), "1e5");
        assert_eq!(number(123_456.0, 3), "1.23e5");
        assert_eq!(number(-2.5, 3), "-2.5");
        assert_eq!(number(f64::NAN, 3), "NaN");
    }

    #[test]
    fn ticks_drop_negative_zero_and_noise_and_keep_the_digits_the_span_needs() {
        assert_eq!(tick(-0.0, -1.0, 1.0), "0");
        assert_eq!(tick(5.551115123125783e-17, -0.3, 0.3), "0");
        assert_eq!(tick(20.0, 0.0, 20.0), "20");
        assert_eq!(tick(0.1 + 0.2, 0.0, 1.0), "0.3");
        assert_eq!(tick(-0.15000000000000002, -0.3, 0.3), "-0.15");
        assert_eq!(tick(20.049999999999997, 19.9, 20.1), "20.05");
        assert_eq!(tick(9.999999999999999e-5, 0.0, 5e-4), "1e-4");
        assert_eq!(tick(2.5e-4, 0.0, 5e-4), "2.5e-4");
        // one notation per axis: not "50000" beside "1.5e5"
        assert_eq!(tick(50_000.0, 0.0, 2e5), "5e4");
        assert_eq!(tick(150_000.0, 0.0, 2e5), "1.5e5");
        assert_eq!(tick(0.0, 0.0, 2e5), "0");
        assert_eq!(tick(1500.0, 0.0, 2000.0), "1500");
    }

    /// Every label plotters asks for on awkward axes is short, unique and free of noise and "-0".
    #[test]
    fn the_labels_of_real_axes_are_clean() {
        let linear = [(-0.3, 0.3), (0.0, 20.0), (19.9, 20.1), (-1.4, 0.45), (0.0, 5e-4), (-35.0, 35.0), (0.0, 2.5e5)];
        for (lo, hi) in linear {
            let axis = RangedCoordf64::from(lo..hi);
            check(&axis, &format!("{lo}..{hi}"));
        }
        for (lo, hi) in [(1e-8, 100.0), (10.0, 1e6), (1e-5, 1e-2), (1.0, 10.0), (0.3, 7.0)] {
            check(&log_axis(lo, hi), &format!("log_axis {lo}..{hi}"));
        }
        fn check<A: TickAxis>(axis: &A, what: &str) {
            let labels: Vec<String> =
                axis.key_points(BoldPoints(10)).into_iter().map(|v| axis.ticks().label(v)).collect();
            assert!(labels.len() >= 2, "{what}: {labels:?}");
            for l in &labels {
                assert!(l.len() <= 7 && !l.contains("999") && !l.contains("000001") && l != "-0", "{what}: {labels:?}");
                assert!(!l.ends_with(".0") && !l.ends_with('.'), "{what}: {labels:?}");
            }
            let mut unique = labels.clone();
            unique.dedup();
            assert_eq!(unique, labels, "{what}");
        }
    }

    #[test]
    fn log_axes_have_ticks_to_label_at_any_width() {
        assert_eq!(log_ticks(9.0, 45.0).0, vec![10.0, 20.0, 30.0]);
        assert_eq!(log_ticks(0.4, 6.0).0, vec![0.5, 1.0, 2.0, 5.0]);
        assert_eq!(log_ticks(1e-4, 0.1).0, vec![1e-4, 1e-3, 0.01, 0.1]);
        assert_eq!(log_ticks(1e-8, 100.0).0, vec![1e-8, 1e-6, 1e-4, 0.01, 1.0, 100.0]);
        let labels =
            |lo, hi| -> Vec<String> { log_ticks(lo, hi).0.into_iter().map(|v| Ticks::Log(lo, hi).label(v)).collect() };
        // one notation per axis
        assert_eq!(labels(1e-4, 0.1), ["1e-4", "1e-3", "1e-2", "1e-1"]);
        assert_eq!(labels(0.004, 20.0), ["0.01", "0.1", "1", "10"]);
        assert_eq!(labels(5.0, 2e5), ["1e1", "1e2", "1e3", "1e4", "1e5"]);
        let (lo, hi) = log_range([12.0, 35.0].into_iter());
        assert!(lo < 12.0 && hi > 35.0 && hi / lo >= 4.0 - 1e-9, "{lo} {hi}");
        let (lo, hi) = log_range([100.0, -1.0, f64::NAN].into_iter());
        assert!((lo - 50.0).abs() < 1e-9 && (hi - 200.0).abs() < 1e-9, "{lo} {hi}");
        assert!(log_ticks(lo, hi).0.len() >= 2);
    }

    #[test]
    fn series_styles_differ_in_colour_and_in_marker_or_dash() {
        for i in 0..15 {
            for j in 0..i {
                let (a, b) = (Style::nth(i), Style::nth(j));
                let differ = [a.color != b.color, a.marker != b.marker, a.dash != b.dash];
                assert!(differ.iter().filter(|d| **d).count() >= 2, "{i} {j}");
            }
        }
    }

    #[test]
    fn markers_of_coinciding_curves_do_not_land_on_each_other() {
        let a = marker_indices(1000, Marker::Circle);
        let b = marker_indices(1000, Marker::Square);
        assert_eq!(a.len(), 10);
        assert!(a.iter().all(|i| !b.contains(i)));
        assert!(marker_indices(3, Marker::Circle).iter().all(|&i| i < 3));
    }

    #[test]
    fn legend_entries_wrap_into_rows_that_fit() {
        let e: Vec<Entry> = (0..6).map(|i| (format!("a legend entry number {i}"), Style::nth(i))).collect();
        let rows = legend_rows(&e, 900);
        assert!(rows.len() >= 2 && rows.iter().all(|r| !r.is_empty()));
        for r in &rows {
            assert!(r.iter().map(|&i| entry_width(&e[i].0)).sum::<u32>() <= 900 - 24);
        }
        assert_eq!(rows.concat(), (0..6).collect::<Vec<_>>());
    }

    /// A rendered chart: tick labels clean, the legend above the plotting area, and the y title
    /// clear of the widest y label.
    #[test]
    fn a_chart_keeps_labels_clean_and_its_legend_off_the_data() {
        let pts: Vec<(f64, f64)> = (0..200).map(|k| (k as f64 * 0.1, 1e-4 * (k as f64 * 0.1).sin())).collect();
        let flat: Vec<(f64, f64)> = pts.iter().map(|p| (p.0, 0.0)).collect();
        let s = [Series::new("curve", pts, Style::nth(0)), Series::new("zero", flat, Style::nth(1))];
        let svg = chart_svg(&Axes::new("title", "time (s)", "angle (rad)"), &s).unwrap();
        let texts: Vec<&str> = svg
            .split("<text")
            .skip(1)
            .map(|t| t[t.find('>').unwrap() + 1..t.find("</text>").unwrap()].trim())
            .collect();
        for t in &texts {
            assert!(!t.contains("999") && *t != "-0" && !t.ends_with(".0"), "{texts:?}");
        }
        let y_of = |label: &str| -> f64 {
            let t = svg.split("<text").find(|t| t.contains(&format!("\n{label}\n</text>"))).unwrap();
            let y = &t[t.find("y=\"").unwrap() + 3..];
            y[..y.find('"').unwrap()].parse().unwrap()
        };
        // the legend's text sits above the highest y tick label
        let top_tick = texts.iter().filter(|t| t.parse::<f64>().is_ok()).map(|t| y_of(t)).fold(f64::INFINITY, f64::min);
        assert!(y_of("curve") < top_tick, "{svg}");
    }
}
