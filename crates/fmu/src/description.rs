//! Writes `modelDescription.xml` from the variable table, and derives the GUID from it.

use quick_xml::events::{BytesDecl, BytesEnd, BytesStart, Event};
use quick_xml::Writer;

use crate::variables::{format_number, Access, Causality, Enumeration, T_MIN, VARIABLES};

pub const MODEL_IDENTIFIER: &str = "ThermoVIA";

/// The DefaultExperiment; its step is the communication step the documentation recommends.
pub const DEFAULT_STOP_TIME: f64 = 20.0;
pub const DEFAULT_STEP_SIZE: f64 = 1e-3;

pub const LOG_CATEGORIES: [(&str, &str); 6] = [
    ("logEvents", "Initialisation, termination, reset and FMU-state events"),
    ("logStatusWarning", "Calls that returned fmi2Warning"),
    ("logStatusDiscard", "Calls that returned fmi2Discard"),
    ("logStatusError", "Calls that returned fmi2Error"),
    ("logStatusFatal", "Calls that returned fmi2Fatal"),
    ("logAll", "Everything"),
];

/// SI base-unit exponents (kg, m, s, K, rad) of every unit used in the table.
fn base_unit(unit: &str) -> [i32; 5] {
    match unit {
        "rad" => [0, 0, 0, 0, 1],
        "rad/s" => [0, 0, -1, 0, 1],
        "N.m" | "J" => [1, 2, -2, 0, 0],
        "N.m/rad" => [1, 2, -2, 0, -1],
        "N.m.s/rad" => [1, 2, -1, 0, -1],
        "K" => [0, 0, 0, 1, 0],
        "K2" => [0, 0, 0, 2, 0],
        "W" => [1, 2, -3, 0, 0],
        "Pa" => [1, -1, -2, 0, 0],
        "J/K" => [1, 2, -2, -1, 0],
        "W/K" => [1, 2, -3, -1, 0],
        "J/(kg.K)" => [0, 2, -2, -1, 0],
        "J/kg" => [0, 2, -2, 0, 0],
        "kg" => [1, 0, 0, 0, 0],
        "kg.m2" => [1, 2, 0, 0, 0],
        "m" => [0, 1, 0, 0, 0],
        "m3/rad" => [0, 3, 0, 0, -1],
        "N/m" => [1, 0, -2, 0, 0],
        "s" => [0, 0, 1, 0, 0],
        "Hz" => [0, 0, -1, 0, 0],
        other => panic!("unit {other} has no base-unit definition: add it to base_unit()"),
    }
}

/// The description with the given GUID.
fn render(guid: &str) -> String {
    let mut w = Writer::new_with_indent(Vec::new(), b' ', 2);
    let mut put = |e: Event| w.write_event(e).expect("writing to a Vec cannot fail");
    put(Event::Decl(BytesDecl::new("1.0", Some("UTF-8"), None)));
    let mut root = BytesStart::new("fmiModelDescription");
    root.push_attribute(("fmiVersion", "2.0"));
    root.push_attribute(("modelName", MODEL_IDENTIFIER));
    root.push_attribute(("guid", guid));
    root.push_attribute((
        "description",
        "Thermo-active variable impedance actuator: DC motor, 12 springs and a temperature-dependent \
         Kelvin-Voigt PCL element between housing and output link, heated PCL (Exley et al., Sci. Rep. 2025)",
    ));
    root.push_attribute(("version", env!("CARGO_PKG_VERSION")));
    root.push_attribute(("generationTool", concat!("thermovia ", env!("CARGO_PKG_VERSION"))));
    root.push_attribute(("variableNamingConvention", "flat"));
    root.push_attribute(("numberOfEventIndicators", "0"));
    put(Event::Start(root));

    let mut cs = BytesStart::new("CoSimulation");
    for (k, v) in [
        ("modelIdentifier", MODEL_IDENTIFIER),
        ("needsExecutionTool", "false"),
        ("canHandleVariableCommunicationStepSize", "true"),
        ("canInterpolateInputs", "false"),
        ("maxOutputDerivativeOrder", "0"),
        ("canRunAsynchronuously", "false"),
        ("canBeInstantiatedOnlyOncePerProcess", "false"),
        ("canNotUseMemoryManagementFunctions", "true"),
        ("canGetAndSetFMUstate", "true"),
        ("canSerializeFMUstate", "true"),
        ("providesDirectionalDerivative", "false"),
    ] {
        cs.push_attribute((k, v));
    }
    put(Event::Empty(cs));

    put(Event::Start(BytesStart::new("UnitDefinitions")));
    let mut units: Vec<&str> = VARIABLES.iter().map(|v| v.unit).filter(|u| !u.is_empty()).collect();
    units.sort();
    units.dedup();
    for u in units {
        let mut unit = BytesStart::new("Unit");
        unit.push_attribute(("name", u));
        put(Event::Start(unit));
        let mut base = BytesStart::new("BaseUnit");
        for (name, e) in ["kg", "m", "s", "K", "rad"].iter().zip(base_unit(u)) {
            if e != 0 {
                base.push_attribute((*name, e.to_string().as_str()));
            }
        }
        put(Event::Empty(base));
        if u == "K" {
            let mut du = BytesStart::new("DisplayUnit");
            du.push_attribute(("name", "degC"));
            du.push_attribute(("offset", "-273.15"));
            put(Event::Empty(du));
        }
        put(Event::End(BytesEnd::new("Unit")));
    }
    put(Event::End(BytesEnd::new("UnitDefinitions")));

    let mut enumerations: Vec<&Enumeration> = VARIABLES.iter().filter_map(|v| v.enumeration).collect();
    enumerations.dedup_by_key(|e| e.name);
    if !enumerations.is_empty() {
        put(Event::Start(BytesStart::new("TypeDefinitions")));
        for e in enumerations {
            let mut st = BytesStart::new("SimpleType");
            st.push_attribute(("name", e.name));
            put(Event::Start(st));
            put(Event::Start(BytesStart::new("Enumeration")));
            for (value, name, description) in e.items {
                let mut item = BytesStart::new("Item");
                item.push_attribute(("name", *name));
                item.push_attribute(("value", value.to_string().as_str()));
                item.push_attribute(("description", *description));
                put(Event::Empty(item));
            }
            put(Event::End(BytesEnd::new("Enumeration")));
            put(Event::End(BytesEnd::new("SimpleType")));
        }
        put(Event::End(BytesEnd::new("TypeDefinitions")));
    }

    put(Event::Start(BytesStart::new("LogCategories")));
    for (name, desc) in LOG_CATEGORIES {
        let mut c = BytesStart::new("Category");
        c.push_attribute(("name", name));
        c.push_attribute(("description", desc));
        put(Event::Empty(c));
    }
    put(Event::End(BytesEnd::new("LogCategories")));

    let mut de = BytesStart::new("DefaultExperiment");
    de.push_attribute(("startTime", "0"));
    de.push_attribute(("stopTime", format_number(DEFAULT_STOP_TIME).as_str()));
    de.push_attribute(("stepSize", format_number(DEFAULT_STEP_SIZE).as_str()));
    put(Event::Empty(de));

    put(Event::Start(BytesStart::new("ModelVariables")));
    for v in VARIABLES {
        let mut sv = BytesStart::new("ScalarVariable");
        sv.push_attribute(("name", v.name));
        sv.push_attribute(("valueReference", v.value_reference.to_string().as_str()));
        sv.push_attribute(("description", v.description));
        sv.push_attribute(("causality", v.causality.as_str()));
        sv.push_attribute(("variability", v.variability.as_str()));
        put(Event::Start(sv));
        let (tag, is_real) = match (v.access, v.enumeration) {
            (Access::Real { .. }, _) => ("Real", true),
            (Access::Integer { .. }, None) => ("Integer", false),
            (Access::Integer { .. }, Some(_)) => ("Enumeration", false),
        };
        let mut t = BytesStart::new(tag);
        if let Some(e) = v.enumeration {
            t.push_attribute(("declaredType", e.name));
        }
        if is_real && !v.unit.is_empty() {
            t.push_attribute(("unit", v.unit));
            // degC only for thermometric temperatures (outputs, and inputs and parameters with the
            // temperature range): a melting width or U*/R shown in °C would read 2.5 K as −270.65 °C
            if v.unit == "K" && v.min.is_none_or(|m| m == T_MIN) {
                t.push_attribute(("displayUnit", "degC"));
            }
        }
        if let Some(b) = v.min {
            t.push_attribute(("min", format_number(b).as_str()));
        }
        if let Some(b) = v.max {
            t.push_attribute(("max", format_number(b).as_str()));
        }
        if v.has_start() {
            t.push_attribute(("start", format_number(v.start()).as_str()));
        }
        put(Event::Empty(t));
        put(Event::End(BytesEnd::new("ScalarVariable")));
    }
    put(Event::End(BytesEnd::new("ModelVariables")));

    put(Event::Start(BytesStart::new("ModelStructure")));
    let indices = |keep: &dyn Fn(Causality) -> bool| -> Vec<usize> {
        VARIABLES.iter().enumerate().filter(|(_, v)| keep(v.causality)).map(|(i, _)| i + 1).collect()
    };
    let outputs = indices(&|c| c == Causality::Output);
    // FMI 2.0: the initial unknowns are the outputs and the calculated parameters.
    let initial_unknowns = indices(&|c| matches!(c, Causality::Output | Causality::CalculatedParameter));
    for (section, unknowns, with_dependencies) in
        [("Outputs", &outputs, true), ("InitialUnknowns", &initial_unknowns, false)]
    {
        put(Event::Start(BytesStart::new(section)));
        for i in unknowns {
            let mut u = BytesStart::new("Unknown");
            u.push_attribute(("index", i.to_string().as_str()));
            if with_dependencies {
                // Outputs are states: none depends directly on an input at the same instant.
                u.push_attribute(("dependencies", ""));
            }
            put(Event::Empty(u));
        }
        put(Event::End(BytesEnd::new(section)));
    }
    put(Event::End(BytesEnd::new("ModelStructure")));
    put(Event::End(BytesEnd::new("fmiModelDescription")));
    let mut s = String::from_utf8(w.into_inner()).expect("utf-8 in, utf-8 out");
    s.push('\n');
    s
}

/// 128-bit FNV-1a of the description rendered without a GUID, formatted as a UUID: any change of
/// the interface changes the GUID.
pub fn guid() -> &'static str {
    use std::sync::OnceLock;
    // Kept inline, not on the heap: a process that loads and unloads the library loses nothing.
    static GUID: OnceLock<[u8; 38]> = OnceLock::new();
    let bytes = GUID.get_or_init(|| {
        let mut h: u128 = 0x6c62272e07bb014262b821756295c58d;
        for b in render("").bytes() {
            h ^= b as u128;
            h = h.wrapping_mul(0x0000000001000000000000000000013B);
        }
        let x = format!("{h:032x}");
        let g = format!("{{{}-{}-{}-{}-{}}}", &x[0..8], &x[8..12], &x[12..16], &x[16..20], &x[20..32]);
        g.as_bytes().try_into().expect("a braced GUID has 38 characters")
    });
    std::str::from_utf8(bytes).expect("ASCII")
}

/// The complete `modelDescription.xml`.
pub fn model_description() -> String {
    render(guid())
}
