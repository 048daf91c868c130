//! Writes `documentation/index.html`, the FMU's front page, from the variable table, as
//! [`description`](crate::description) writes modelDescription.xml, so the two cannot disagree. It is
//! XHTML (every element closed, text escaped, no entities beyond XML's) so an XML parser reads it: the
//! tests parse it with quick-xml.

use std::io;

use quick_xml::escape::partial_escape;
use quick_xml::events::{BytesText, Event};
use quick_xml::Writer;

use crate::description::{guid, DEFAULT_STEP_SIZE, MODEL_IDENTIFIER};
use crate::variables::{by_name, Causality, Variability, Variable, VARIABLES};

/// The one platform the archive ships a binary for: `binaries/linux64/ThermoVIA.so`.
pub const PLATFORM: &str = "linux64";

/// The page's fmpy example, the README's quick start with a start value; the tests find it in the
/// packaged page, and tests/python/test_fmpy.py runs it and compares what it prints with its last comment.
pub const FMPY_EXAMPLE: &str = r#"import numpy as np
from fmpy import simulate_fmu

t = np.arange(0.0, 60.0, 0.01)
inputs = np.array([(x, 10.0, 0.2 * np.sin(2 * np.pi * x)) for x in t],           # 10 W heater, 0.2 N·m at 1 Hz
                  dtype=[("time", float), ("heater_power", float), ("motor_torque", float)])
r = simulate_fmu("ThermoVIA.fmu", start_values={"excitation_frequency": 1.0},   # K_eff, C_eff at the drive's 1 Hz
                 input=inputs, stop_time=60.0, step_size=1e-3, output_interval=0.01,
                 output=["pcl_temperature", "effective_stiffness"])
print(f"PCL {r['pcl_temperature'][-1] - 273.15:.1f} °C, K_eff {r['effective_stiffness'][0]:.1f} → "
      f"{r['effective_stiffness'][-1]:.1f} N·m/rad")        # PCL 60.4 °C, K_eff 34.0 → 11.8 N·m/rad
"#;

// Inline, so the page needs nothing beside it. Written as raw text: no '<', '&' or '>' in it.
const CSS: &str = "
body { font-family: system-ui, sans-serif; max-width: 75em; margin: 2em auto; padding: 0 1em;
       line-height: 1.45; color: #222; }
h1 { margin-bottom: 0.2em; }
h2 { border-bottom: 1px solid #ccc; margin-top: 2em; }
.subtitle { color: #555; margin-top: 0; }
table { border-collapse: collapse; width: 100%; font-size: 0.9em; margin: 0.5em 0 1.5em; }
th, td { border-bottom: 1px solid #ddd; padding: 0.3em 0.5em; text-align: left; vertical-align: top; }
th { background: #f2f2f2; }
td.nowrap { white-space: nowrap; }
td ul { margin: 0.3em 0 0; padding-left: 1.2em; }
code { font-family: ui-monospace, monospace; background: #f4f4f4; padding: 0 0.2em; }
pre { background: #f6f8fa; border: 1px solid #ddd; padding: 0.8em 1em; overflow-x: auto; }
.source { color: #555; }
";

type W = Writer<Vec<u8>>;

/// A number for people: ten significant digits (213.14999999999998 → 213.15), plain between 1e-3
/// and 1e6, with an exponent outside. The description keeps the exact numbers.
fn number(v: f64) -> String {
    let v: f64 = format!("{v:.9e}").parse().expect("a formatted f64 reads back");
    if v == 0.0 {
        "0".into()
    } else if (1e-3..1e6).contains(&v.abs()) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

fn row(name: &str) -> &'static Variable {
    by_name(name).unwrap_or_else(|| panic!("the documentation names {name}, which is not in the variable table"))
}

/// An Enumeration parameter's item name for a value.
fn item_name(v: &Variable, value: f64) -> Option<&'static str> {
    v.enumeration?.items.iter().find(|(x, _, _)| *x as f64 == value).map(|(_, n, _)| *n)
}

/// A start value, with its item name if the variable is an Enumeration.
fn start_text(v: &Variable) -> String {
    let s = v.start();
    match item_name(v, s) {
        Some(item) => format!("{} = {item}", number(s)),
        None => number(s),
    }
}

fn range_text(v: &Variable) -> String {
    match (v.min, v.max) {
        (Some(lo), Some(hi)) => format!("{} … {}", number(lo), number(hi)),
        (Some(lo), None) => format!("≥ {}", number(lo)),
        (None, Some(hi)) => format!("≤ {}", number(hi)),
        (None, None) => String::new(),
    }
}

fn text(w: &mut W, s: &str) -> io::Result<()> {
    w.write_event(Event::Text(BytesText::from_escaped(partial_escape(s))))
}

/// Text with `code` spans and {variable} references; a reference must name a row of the table, so a
/// renamed variable fails packaging (and this crate's tests) instead of leaving the page behind.
fn prose(w: &mut W, s: &str) -> io::Result<()> {
    let mut rest = s;
    while let Some(i) = rest.find(['`', '{']) {
        text(w, &rest[..i])?;
        let close = if rest[i..].starts_with('`') { '`' } else { '}' };
        let j = i + 1 + rest[i + 1..].find(close).unwrap_or_else(|| panic!("unclosed {close} in {s:?}"));
        let code = &rest[i + 1..j];
        if close == '}' {
            row(code);
        }
        w.create_element("code").write_text_content(BytesText::new(code))?;
        rest = &rest[j + 1..];
    }
    text(w, rest)
}

fn para(w: &mut W, s: &str) -> io::Result<()> {
    w.create_element("p").write_inner_content(|w| prose(w, s))?;
    Ok(())
}

fn heading(w: &mut W, tag: &str, id: &str, s: &str) -> io::Result<()> {
    w.create_element(tag).with_attribute(("id", id)).write_inner_content(|w| prose(w, s))?;
    Ok(())
}

fn cell(w: &mut W, s: &str) -> io::Result<()> {
    w.create_element("td").write_text_content(BytesText::new(s))?;
    Ok(())
}

/// The items of an Enumeration parameter, as value = name: description (the default marked).
fn items(w: &mut W, v: &Variable) -> io::Result<()> {
    let Some(e) = v.enumeration else { return Ok(()) };
    let start = v.start();
    w.create_element("ul").write_inner_content(|w| {
        for (value, name, description) in e.items {
            w.create_element("li").write_inner_content(|w| {
                w.create_element("code").write_text_content(BytesText::new(&format!("{value} = {name}")))?;
                // Some items' own text already says so.
                let marked = *value as f64 == start && !description.contains("default");
                let default = if marked { " (default)" } else { "" };
                text(w, &format!("{default}: {description}"))
            })?;
        }
        Ok(())
    })?;
    Ok(())
}

/// One table per causality; which columns it has.
struct Section {
    causality: Causality,
    id: &'static str,
    title: &'static str,
    intro: &'static str,
    range: bool,
    /// The start column's heading, if the table has one.
    start: Option<&'static str>,
    source: bool,
}

const SECTIONS: [Section; 4] = [
    Section {
        causality: Causality::Input,
        id: "inputs",
        title: "Inputs",
        intro: "Set before each `fmi2DoStep` and held over the step. Which ones the FMU reads depends on the \
                modes (named in each description); with the default modes: {heater_power}, {motor_torque}, \
                {load_torque} and {ambient_temperature}.",
        range: true,
        start: Some("start"),
        source: false,
    },
    Section {
        causality: Causality::Output,
        id: "outputs",
        title: "Outputs",
        intro: "Computed by the FMU; read them after each step.",
        range: false,
        start: None,
        source: false,
    },
    Section {
        causality: Causality::Parameter,
        id: "parameters",
        title: "Parameters",
        intro: "Set until the end of initialisation; the tunable ones also between steps. A value outside its range \
                is refused with `fmi2Error` and a message naming the variable: nothing is clamped. Sources: \
                PAPER (Exley, Johnson, Jafari, Sci. Rep. 2025), LIT (literature), EST (documented estimate), \
                EFFECT (an effect the calibration can switch on; off by default), CALIBRATION, NUMERICS, MODE.",
        range: true,
        start: Some("default"),
        source: true,
    },
    Section {
        causality: Causality::CalculatedParameter,
        id: "calculated",
        title: "Calculated parameters",
        intro: "Derived from the parameters at initialisation; read-only.",
        range: false,
        start: Some("with the defaults"),
        source: true,
    },
];

fn variable_table(w: &mut W, s: &Section) -> io::Result<()> {
    heading(w, "h3", s.id, s.title)?;
    para(w, s.intro)?;
    w.create_element("table").write_inner_content(|w| {
        w.create_element("tr").write_inner_content(|w| {
            let mut headings = vec!["name", "causality", "unit"];
            if s.range {
                headings.push("range");
            }
            headings.extend(s.start);
            headings.push("description");
            if s.source {
                headings.push("source");
            }
            for h in headings {
                w.create_element("th").write_text_content(BytesText::new(h))?;
            }
            Ok(())
        })?;
        for v in VARIABLES.iter().filter(|v| v.causality == s.causality) {
            w.create_element("tr").with_attribute(("id", format!("var-{}", v.name).as_str())).write_inner_content(
                |w| {
                    w.create_element("td").write_inner_content(|w| {
                        w.create_element("code").write_text_content(BytesText::new(v.name)).map(drop)
                    })?;
                    let tunable = if v.variability == Variability::Tunable { ", tunable" } else { "" };
                    cell(w, &format!("{}{tunable}", v.causality.as_str()))?;
                    cell(w, v.unit)?;
                    if s.range {
                        w.create_element("td")
                            .with_attribute(("class", "nowrap"))
                            .write_text_content(BytesText::new(&range_text(v)))?;
                    }
                    if s.start.is_some() {
                        // A calculated parameter has no start: its value with the default parameters.
                        w.create_element("td")
                            .with_attribute(("class", "nowrap"))
                            .write_text_content(BytesText::new(&start_text(v)))?;
                    }
                    w.create_element("td").write_inner_content(|w| {
                        text(w, v.description)?;
                        items(w, v)
                    })?;
                    if s.source {
                        w.create_element("td")
                            .with_attribute(("class", "source"))
                            .write_text_content(BytesText::new(v.source))?;
                    }
                    Ok(())
                },
            )?;
        }
        Ok(())
    })?;
    Ok(())
}

fn modes(w: &mut W) -> io::Result<()> {
    heading(w, "h2", "modes", "Modes")?;
    para(
        w,
        "Integer parameters declared as FMI Enumerations, so importers that read TypeDefinitions show the \
         names; set them by number until the end of initialisation. Some importers ignore Enumeration \
         variables and run with the defaults (OSP libcosim 0.11 and ecos 0.7 do).",
    )?;
    for v in VARIABLES.iter().filter(|v| v.enumeration.is_some()) {
        let e = v.enumeration.expect("filtered");
        heading(w, "h3", &format!("mode-{}", v.name), &format!("`{}` (Enumeration {})", v.name, e.name))?;
        w.create_element("p").write_text_content(BytesText::new(v.description))?;
        items(w, v)?;
    }
    Ok(())
}

fn communication_step(w: &mut W) -> io::Result<()> {
    let mis = row("max_internal_step");
    let default = mis.start();
    let longest = thermovia_model::MAX_SUBSTEPS_PER_STEP * default;
    heading(w, "h2", "step", "Communication step")?;
    para(
        w,
        &format!(
            "Any communication step works. Each `fmi2DoStep` advances in internal sub-steps of at most \
             {{max_internal_step}} (default {} s, range {} s), whatever the communication step: exactly where \
             the mechanics is linear, with error control ({{solver_tolerance}}) where friction, backlash or \
             gravity is on. Inputs are held over the step (`canInterpolateInputs` = false), so the \
             communication step sets how often the FMU and its importer exchange values, not how accurately \
             the FMU integrates between them. The step may change from call to call \
             (`canHandleVariableCommunicationStepSize` = true).",
            number(default),
            range_text(mis),
        ),
    )?;
    para(
        w,
        &format!(
            "One step does at most {} sub-steps: with the default {{max_internal_step}}, communication steps \
             up to {} s. A longer one returns `fmi2Discard` with the reason and leaves the state as it was; \
             take shorter steps or raise {{max_internal_step}}.",
            number(thermovia_model::MAX_SUBSTEPS_PER_STEP),
            number(longest),
        ),
    )?;
    para(
        w,
        &format!(
            "Recommended: {} s ({} ms), the DefaultExperiment's `stepSize`. It matters most in co-simulation with a \
             rigid-body engine that integrates the link ({{link_drive}} = 1): the engine sends \
             {{link_angle_command}} and {{link_speed_command}} at the start of each step, the FMU returns \
             {{transmitted_torque_mean}}, which the engine applies over its next step. That coupling is \
             explicit and first order in the step h, and stable only below a limit set by the link's \
             effective inertia J and the transmission's stiffness K and damping C ({{effective_stiffness}}, \
             {{effective_damping}}): h² K/J + h C/J < 2, or h² K/J < 2 + h C/J when the engine takes C into its \
             implicit integrator. 1 ms, as the project's MuJoCo example uses, keeps a link as heavy as the \
             device's ({{link_inertia}}'s default) inside it even cold, where the transmission is stiffest and \
             most damped; a lighter link or a stiffer transmission needs a shorter step.",
            number(DEFAULT_STEP_SIZE),
            number(DEFAULT_STEP_SIZE * 1e3),
        ),
    )?;
    Ok(())
}

fn example(w: &mut W) -> io::Result<()> {
    heading(w, "h2", "example", "Example: fmpy")?;
    para(
        w,
        "With fmpy (`pip install fmpy`), next to ThermoVIA.fmu: 60 s of 10 W into the heaters and a 1 Hz \
         torque on the motor; the PCL melts and the joint softens:",
    )?;
    w.create_element("pre").with_attribute(("class", "example")).write_text_content(BytesText::new(FMPY_EXAMPLE))?;
    para(
        w,
        "Inputs the array leaves out keep their start values (fmpy warns about each); `start_values` sets \
         parameters, modes by their number. `fmpy info ThermoVIA.fmu` lists the variables.",
    )
}

fn platforms(w: &mut W) -> io::Result<()> {
    heading(w, "h2", "platforms", "Platforms")?;
    para(
        w,
        &format!(
            "The archive ships one binary, `binaries/{PLATFORM}/{MODEL_IDENTIFIER}.so`: x86_64 Linux with \
             glibc. It links only libc, libm and libgcc_s. There is no Windows, macOS \
             or ARM binary and no source code in the archive, so importers on other platforms cannot run it."
        ),
    )
}

fn head(w: &mut W) -> io::Result<()> {
    w.create_element("meta").with_attribute(("charset", "utf-8")).write_empty()?;
    let title = format!("{MODEL_IDENTIFIER}: thermo-active variable impedance actuator (FMI 2.0 co-simulation)");
    w.create_element("title").write_text_content(BytesText::new(&title))?;
    w.create_element("style").write_text_content(BytesText::from_escaped(CSS))?;
    Ok(())
}

fn introduction(w: &mut W) -> io::Result<()> {
    w.create_element("h1").write_text_content(BytesText::new(MODEL_IDENTIFIER))?;
    let subtitle = format!(
        "Thermo-active variable impedance actuator: FMI 2.0 Co-Simulation FMU, version {}, GUID {}",
        env!("CARGO_PKG_VERSION"),
        guid()
    );
    w.create_element("p").with_attribute(("class", "subtitle")).write_text_content(BytesText::new(&subtitle))?;
    let springs = number(row("spring_count").start());
    para(
        w,
        &format!(
            "A DC motor turns a housing; {springs} compression springs and a Kelvin–Voigt element of \
             polycaprolactone (PCL), whose stiffness and damping depend on its temperature, couple the housing \
             to an output link. Heaters in the housing soften the PCL near 60 °C, where it melts: heat sets the \
             joint's stiffness ({{effective_stiffness}}). The inputs are the heater power ({{heater_power}}), \
             the motor torque ({{motor_torque}}), a load torque on the link ({{load_torque}}) and the ambient \
             temperature ({{ambient_temperature}}); the modes below let the motor, the link or the housing \
             temperature follow commands instead. Model: Exley, Johnson, Jafari, Scientific Reports 2025 (doi \
             10.1038/s41598-025-30236-6); every parameter names its source."
        ),
    )?;
    w.create_element("p").write_inner_content(|w| {
        text(w, "Contents: ")?;
        let links = [
            ("variables", "variables"),
            ("modes", "modes"),
            ("step", "communication step"),
            ("example", "fmpy example"),
            ("platforms", "platforms"),
        ];
        for (i, (id, label)) in links.iter().enumerate() {
            if i > 0 {
                text(w, " · ")?;
            }
            w.create_element("a")
                .with_attribute(("href", format!("#{id}").as_str()))
                .write_text_content(BytesText::new(label))?;
        }
        Ok(())
    })?;
    Ok(())
}

fn variables(w: &mut W) -> io::Result<()> {
    heading(w, "h2", "variables", "Variables")?;
    para(
        w,
        "Names, units and ranges as in modelDescription.xml, units by their FMI names (temperatures in K; \
         importers may show °C). Numbers are rounded to ten significant digits here; modelDescription.xml has \
         them exactly.",
    )?;
    for s in &SECTIONS {
        variable_table(w, s)?;
    }
    Ok(())
}

fn body(w: &mut W) -> io::Result<()> {
    introduction(w)?;
    variables(w)?;
    modes(w)?;
    communication_step(w)?;
    example(w)?;
    platforms(w)?;
    para(w, "Generated with modelDescription.xml from the FMU's variable table by fmu-build.")
}

/// The complete `documentation/index.html`.
pub fn index_html() -> String {
    let mut w = Writer::new_with_indent(Vec::new(), b' ', 1);
    w.write_event(Event::DocType(BytesText::from_escaped("html")))
        .and_then(|()| {
            w.create_element("html")
                .with_attributes([("xmlns", "http://www.w3.org/1999/xhtml"), ("lang", "en")])
                .write_inner_content(|w| {
                    w.create_element("head").write_inner_content(head)?;
                    w.create_element("body").write_inner_content(body)?;
                    Ok(())
                })
        })
        .expect("writing to a Vec cannot fail");
    let mut s = String::from_utf8(w.into_inner()).expect("utf-8 in, utf-8 out");
    s.push('\n');
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_read_without_float_noise() {
        assert_eq!(number(213.14999999999998), "213.15");
        assert_eq!(number(9.999999999999999e-5), "1e-4");
        assert_eq!(number(0.001), "0.001");
        assert_eq!(number(97820.0), "97820");
        assert_eq!(number(1e6), "1e6");
        assert_eq!(number(-1e6), "-1e6");
        assert_eq!(number(1e-9), "1e-9");
        assert_eq!(number(0.0), "0");
    }

    #[test]
    fn the_page_renders_and_its_prose_names_only_variables_of_the_table() {
        let html = index_html();
        assert!(html.contains("<code>max_internal_step</code>"));
    }

    #[test]
    fn the_style_sheet_needs_no_escaping() {
        assert!(!CSS.contains(['<', '>', '&']), "HTML reads <style> raw: an escaped character would break it");
    }
}
