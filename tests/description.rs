//! One source of truth: the checked-in modelDescription, the README table and the packaged FMU all
//! equal what the variable table generates, and the binary uses the start values it declares.

mod common;

use std::io::Read;

use thermovia_fmu::description::{guid, model_description};
use thermovia_fmu::documentation::{index_html, FMPY_EXAMPLE, PLATFORM};
use thermovia_fmu::variables::{markdown_table, Causality, VARIABLES};

const ROOT: &str = env!("CARGO_MANIFEST_DIR");
const REFRESH: &str = "run `cargo run -p fmu-build -- --sync-docs` and commit the result";

#[test]
fn checked_in_model_description_equals_the_generated_one() {
    let path = format!("{ROOT}/modelDescription/ThermoVIA.xml");
    let on_disk = std::fs::read_to_string(&path).unwrap();
    assert!(on_disk == model_description(), "{path} differs from the code: {REFRESH}");
}

#[test]
fn readme_variable_table_equals_the_generated_one() {
    let readme = std::fs::read_to_string(format!("{ROOT}/README.md")).unwrap();
    let begin = readme.find("<!-- variables:begin").expect("README marker");
    let body_start = begin + readme[begin..].find('\n').unwrap() + 1;
    let end = readme.find("<!-- variables:end -->").expect("README marker");
    assert!(readme[body_start..end] == markdown_table(), "README variable table differs from the code: {REFRESH}");
}

#[test]
fn packaged_archive_has_the_standard_layout_and_this_builds_description() {
    let file = std::fs::File::open(common::fmu_path()).expect("cargo run --release -p fmu-build");
    let mut zip = zip::ZipArchive::new(file).unwrap();
    let names: Vec<String> = zip.file_names().map(str::to_string).collect();
    for needed in ["modelDescription.xml", "binaries/linux64/ThermoVIA.so", "documentation/index.html"] {
        assert!(names.iter().any(|n| n == needed), "{needed} missing from {names:?}");
    }
    let mut xml = String::new();
    zip.by_name("modelDescription.xml").unwrap().read_to_string(&mut xml).unwrap();
    assert!(xml == model_description(), "the packaged FMU is stale: rerun `cargo run --release -p fmu-build`");
    assert!(xml.contains(&format!("guid=\"{}\"", guid())));
}

#[test]
fn structure_indices_point_at_outputs_and_every_unit_is_defined() {
    let fmu = common::fmu();
    let md = &fmu.description;
    let xml = model_description();
    let outputs: Vec<usize> =
        md.variables.iter().enumerate().filter(|(_, v)| v.causality == "output").map(|(i, _)| i + 1).collect();
    let section = &xml[xml.find("<Outputs>").unwrap()..xml.find("</Outputs>").unwrap()];
    let listed: Vec<usize> =
        section.split("index=\"").skip(1).map(|s| s[..s.find('"').unwrap()].parse().unwrap()).collect();
    assert_eq!(listed, outputs);
    // FMI 2.0: InitialUnknowns are exactly the outputs and the calculated parameters
    let initial: Vec<usize> = md
        .variables
        .iter()
        .enumerate()
        .filter(|(_, v)| v.causality == "output" || v.causality == "calculatedParameter")
        .map(|(i, _)| i + 1)
        .collect();
    assert!(initial.len() > outputs.len(), "the FMU declares calculated parameters");
    let section = &xml[xml.find("<InitialUnknowns>").unwrap()..xml.find("</InitialUnknowns>").unwrap()];
    let listed: Vec<usize> =
        section.split("index=\"").skip(1).map(|s| s[..s.find('"').unwrap()].parse().unwrap()).collect();
    assert_eq!(listed, initial);
    for v in &md.variables {
        if let Some(u) = &v.unit {
            assert!(xml.contains(&format!("<Unit name=\"{u}\">")), "unit {u} of {} is not defined", v.name);
        }
    }
}

#[test]
fn start_values_are_what_the_binary_uses() {
    let fmu = common::fmu();
    let mut inst = fmu.instantiate(None).unwrap();
    inst.initialize(0.0, None, &[]).unwrap();
    for v in
        fmu.description.variables.iter().filter(|v| v.causality != "output" && v.causality != "calculatedParameter")
    {
        let declared: f64 = v.start.as_ref().unwrap_or_else(|| panic!("{} has no start", v.name)).parse().unwrap();
        let used = inst.get(&v.name).unwrap();
        assert_eq!(declared, used, "{}", v.name);
    }
    assert_eq!(VARIABLES.iter().filter(|v| v.causality == Causality::Output).count(), 17);
}

#[test]
fn the_binary_needs_nothing_beyond_the_system_c_library() {
    let so = std::env::temp_dir().join(format!("thermovia-needed-{}.so", std::process::id()));
    let mut zip = zip::ZipArchive::new(std::fs::File::open(common::fmu_path()).unwrap()).unwrap();
    let mut bytes = Vec::new();
    zip.by_name("binaries/linux64/ThermoVIA.so").unwrap().read_to_end(&mut bytes).unwrap();
    std::fs::write(&so, bytes).unwrap();
    let out = std::process::Command::new("readelf").arg("-d").arg(&so).output().expect("readelf (binutils)");
    let _ = std::fs::remove_file(&so);
    let text = String::from_utf8_lossy(&out.stdout);
    let needed: Vec<&str> = text
        .lines()
        .filter(|l| l.contains("(NEEDED)"))
        .filter_map(|l| l.split('[').nth(1)?.split(']').next())
        .collect();
    assert!(!needed.is_empty(), "readelf found no NEEDED entries: {text}");
    for lib in needed {
        assert!(
            ["libc.so.6", "libm.so.6", "libgcc_s.so.1", "libpthread.so.0", "libdl.so.2", "ld-linux-x86-64.so.2"]
                .contains(&lib),
            "unexpected runtime dependency {lib}"
        );
    }
}

/// One entry of the packaged FMU, as text.
fn packaged(entry: &str) -> String {
    let mut zip = zip::ZipArchive::new(std::fs::File::open(common::fmu_path()).unwrap()).unwrap();
    let mut text = String::new();
    zip.by_name(entry).unwrap_or_else(|e| panic!("{entry}: {e}")).read_to_string(&mut text).unwrap();
    text
}

/// documentation/index.html read as XML.
#[derive(Default)]
struct Page {
    /// Every table row: its id, and its cells' text with whitespace collapsed.
    rows: Vec<(Option<String>, Vec<String>)>,
    /// The text of every <pre>, as written.
    pres: Vec<String>,
    /// (id of an h2/h3, the text from it to the next such heading)
    sections: Vec<(String, String)>,
}

fn parse_page(html: &str) -> Result<Page, String> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_str(html);
    let mut page = Page::default();
    let (mut cell, mut pre): (Option<String>, Option<String>) = (None, None);
    // The reader checks that end tags match; an element left open at the end it does not notice.
    let mut open = 0usize;
    loop {
        let at = reader.buffer_position();
        let event = reader.read_event().map_err(|e| format!("not well-formed XML at byte {at}: {e}"))?;
        match event {
            Event::Start(e) => {
                open += 1;
                let id = match e.try_get_attribute("id").map_err(|e| format!("byte {at}: {e}"))? {
                    Some(a) => Some(a.unescape_value().map_err(|e| format!("byte {at}: {e}"))?.into_owned()),
                    None => None,
                };
                match e.name().as_ref() {
                    b"tr" => page.rows.push((id, Vec::new())),
                    b"td" | b"th" => cell = Some(String::new()),
                    b"pre" => pre = Some(String::new()),
                    b"h2" | b"h3" => page.sections.extend(id.map(|id| (id, String::new()))),
                    _ => {}
                }
            }
            Event::End(e) => {
                open = open.checked_sub(1).ok_or(format!("byte {at}: a closing tag without an opening one"))?;
                match e.name().as_ref() {
                    b"td" | b"th" => {
                        let text = cell.take().unwrap_or_default().split_whitespace().collect::<Vec<_>>().join(" ");
                        page.rows.last_mut().ok_or(format!("byte {at}: a cell outside a row"))?.1.push(text);
                    }
                    b"pre" => page.pres.extend(pre.take()),
                    _ => {}
                }
            }
            Event::Text(t) => {
                let t = t.unescape().map_err(|e| format!("byte {at}: {e}"))?;
                for sink in
                    [cell.as_mut(), pre.as_mut(), page.sections.last_mut().map(|(_, text)| text)].into_iter().flatten()
                {
                    sink.push_str(&t);
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    if open != 0 {
        return Err(format!("{open} elements are not closed"));
    }
    Ok(page)
}

/// What is wrong with a documentation page: empty when every variable has its row (name, causality,
/// unit), every mode its section with its items, and the platform and the fmpy example are there.
fn page_problems(html: &str) -> Vec<String> {
    let page = match parse_page(html) {
        Ok(page) => page,
        Err(e) => return vec![e],
    };
    let section = |id: &str| page.sections.iter().find(|(i, _)| i == id).map(|(_, text)| text.as_str());
    let mut problems = Vec::new();
    for v in VARIABLES {
        let rows: Vec<&Vec<String>> = page
            .rows
            .iter()
            .map(|(_, cells)| cells)
            .filter(|cells| cells.first().is_some_and(|c| c == v.name))
            .collect();
        let [cells] = rows.as_slice() else {
            problems.push(format!("{} has {} rows in the tables, not one", v.name, rows.len()));
            continue;
        };
        // A tunable parameter reads "parameter, tunable".
        let causality = cells.get(1).and_then(|c| c.split(',').next());
        if causality != Some(v.causality.as_str()) {
            problems.push(format!("{}: causality {causality:?}, not {}", v.name, v.causality.as_str()));
        }
        if cells.get(2).map(String::as_str) != Some(v.unit) {
            problems.push(format!("{}: unit {:?}, not {:?}", v.name, cells.get(2), v.unit));
        }
        if let Some(e) = v.enumeration {
            let Some(text) = section(&format!("mode-{}", v.name)) else {
                problems.push(format!("the mode {} has no section", v.name));
                continue;
            };
            for (value, name, _) in e.items {
                for (place, text) in [("row", cells.join(" ")), ("section", text.to_string())] {
                    if !text.contains(&format!("{value} = {name}")) {
                        problems.push(format!("{}'s {place} lacks the item {value} = {name}", v.name));
                    }
                }
            }
        }
    }
    let rows = page.rows.iter().filter(|(id, _)| id.as_deref().is_some_and(|id| id.starts_with("var-"))).count();
    if rows != VARIABLES.len() {
        problems.push(format!("{rows} variable rows for {} variables", VARIABLES.len()));
    }
    let platforms = section("platforms").unwrap_or_default();
    for needed in [format!("binaries/{PLATFORM}/ThermoVIA.so"), "x86_64 Linux".to_string()] {
        if !platforms.contains(&needed) {
            problems.push(format!("the platforms section does not say {needed}"));
        }
    }
    if !section("step").is_some_and(|text| text.contains("max_internal_step")) {
        problems.push("no communication-step section on max_internal_step".into());
    }
    if !page.pres.iter().any(|p| p == FMPY_EXAMPLE) {
        problems.push("the fmpy example is missing".into());
    }
    problems
}

#[test]
fn packaged_documentation_lists_every_variable_and_mode_the_platform_and_an_fmpy_example() {
    let html = packaged("documentation/index.html");
    assert!(html == index_html(), "the packaged FMU is stale: rerun `cargo run --release -p fmu-build`");
    let problems = page_problems(&html);
    assert!(problems.is_empty(), "documentation/index.html:\n{}", problems.join("\n"));
    for needed in ["simulate_fmu(", "heater_power", "motor_torque", "effective_stiffness", "ThermoVIA.fmu"] {
        assert!(FMPY_EXAMPLE.contains(needed), "the fmpy example lacks {needed}");
    }
    // The page names the one platform the archive has a binary for.
    let zip = zip::ZipArchive::new(std::fs::File::open(common::fmu_path()).unwrap()).unwrap();
    let binaries: Vec<&str> = zip.file_names().filter(|n| n.starts_with("binaries/")).collect();
    assert_eq!(binaries, [format!("binaries/{PLATFORM}/ThermoVIA.so")]);
}

#[test]
fn the_documentation_check_fails_on_a_missing_row_or_a_broken_tag() {
    let html = index_html();
    for v in VARIABLES {
        let start = html.find(&format!("<tr id=\"var-{}\">", v.name)).unwrap_or_else(|| panic!("{}'s row", v.name));
        let end = start + html[start..].find("</tr>").unwrap() + "</tr>".len();
        let problems = page_problems(&format!("{}{}", &html[..start], &html[end..]));
        assert!(problems.iter().any(|p| p.starts_with(v.name)), "without {}'s row: {problems:?}", v.name);
    }
    for broken in [html.replacen("</td>", "", 1), html.replacen("</body>", "", 1), html.replacen("&gt;", "&", 1)] {
        assert!(!page_problems(&broken).is_empty(), "a malformed page passes");
    }
}
