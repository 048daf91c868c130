//! Reads the parts of any FMI 2.0 modelDescription.xml that an importer needs.

use quick_xml::events::Event;
use quick_xml::Reader;

use super::HarnessError;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VariableType {
    Real,
    Integer,
    Boolean,
    String,
    Enumeration,
}

#[derive(Clone, Debug)]
pub struct VariableInfo {
    pub name: String,
    pub value_reference: u32,
    pub ty: VariableType,
    pub causality: String,
    pub variability: String,
    pub start: Option<String>,
    pub unit: Option<String>,
    pub min: Option<String>,
    pub max: Option<String>,
    /// The `declaredType` of the type element (an Enumeration's item list lives there).
    pub declared_type: Option<String>,
    pub description: String,
}

/// `<DefaultExperiment>`: each attribute is optional.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DefaultExperiment {
    pub start_time: Option<f64>,
    pub stop_time: Option<f64>,
    pub tolerance: Option<f64>,
    pub step_size: Option<f64>,
}

/// One `<Item>` of an Enumeration `<SimpleType>`.
#[derive(Clone, Debug, PartialEq)]
pub struct EnumerationItem {
    pub name: String,
    pub value: i32,
    pub description: String,
}

#[derive(Clone, Debug)]
pub struct ModelDescription {
    pub guid: String,
    pub model_name: String,
    pub model_identifier: String,
    pub fmi_version: String,
    pub description: String,
    pub generation_tool: String,
    pub variables: Vec<VariableInfo>,
    pub default_experiment: DefaultExperiment,
    /// The `<CoSimulation>` element's attributes other than modelIdentifier (capability flags).
    pub capabilities: Vec<(String, String)>,
    /// Enumeration `<SimpleType>`s by name, with their items.
    pub enumerations: Vec<(String, Vec<EnumerationItem>)>,
}

impl ModelDescription {
    pub fn parse(xml: &str) -> Result<ModelDescription, String> {
        let mut r = Reader::from_str(xml);
        r.config_mut().trim_text(true);
        let mut md = ModelDescription {
            guid: String::new(),
            model_name: String::new(),
            model_identifier: String::new(),
            fmi_version: String::new(),
            description: String::new(),
            generation_tool: String::new(),
            variables: Vec::new(),
            default_experiment: DefaultExperiment::default(),
            capabilities: Vec::new(),
            enumerations: Vec::new(),
        };
        let mut current: Option<VariableInfo> = None;
        // The SimpleType being read, if it is an Enumeration.
        let mut simple_type: Option<String> = None;
        loop {
            let ev = r.read_event().map_err(|e| format!("XML error at byte {}: {e}", r.buffer_position()))?;
            let (e, is_empty) = match &ev {
                Event::Start(e) => (e, false),
                Event::Empty(e) => (e, true),
                Event::End(e) if e.name().as_ref() == b"ScalarVariable" => {
                    let v = current.take().ok_or("unbalanced ScalarVariable")?;
                    md.variables.push(v);
                    continue;
                }
                Event::End(e) if e.name().as_ref() == b"SimpleType" => {
                    simple_type = None;
                    continue;
                }
                Event::Eof => break,
                _ => continue,
            };
            let mut attrs = std::collections::BTreeMap::new();
            for a in e.attributes() {
                let a = a.map_err(|e| format!("bad attribute: {e}"))?;
                let key = String::from_utf8_lossy(a.key.as_ref()).into_owned();
                let val = a.unescape_value().map_err(|e| format!("bad attribute value: {e}"))?.into_owned();
                attrs.insert(key, val);
            }
            let get = |k: &str| attrs.get(k).cloned();
            match e.name().as_ref() {
                b"fmiModelDescription" => {
                    md.guid = get("guid").ok_or("fmiModelDescription has no guid")?;
                    md.model_name = get("modelName").unwrap_or_default();
                    md.fmi_version = get("fmiVersion").unwrap_or_default();
                    md.description = get("description").unwrap_or_default();
                    md.generation_tool = get("generationTool").unwrap_or_default();
                    if md.fmi_version != "2.0" {
                        return Err(format!("fmiVersion {:?}: only FMI 2.0 is supported", md.fmi_version));
                    }
                }
                b"CoSimulation" => {
                    md.model_identifier = get("modelIdentifier").ok_or("CoSimulation has no modelIdentifier")?;
                    md.capabilities = attrs
                        .iter()
                        .filter(|(k, _)| k.as_str() != "modelIdentifier")
                        .map(|(k, v)| (k.clone(), v.clone()))
                        .collect();
                }
                b"DefaultExperiment" => {
                    let number = |k: &str| -> Result<Option<f64>, String> {
                        get(k)
                            .map(|v| {
                                v.trim().parse().map_err(|_| format!("DefaultExperiment {k}={v:?} is not a number"))
                            })
                            .transpose()
                    };
                    md.default_experiment = DefaultExperiment {
                        start_time: number("startTime")?,
                        stop_time: number("stopTime")?,
                        tolerance: number("tolerance")?,
                        step_size: number("stepSize")?,
                    };
                }
                b"SimpleType" => {
                    simple_type = get("name");
                }
                b"Enumeration" if current.is_none() => {
                    if let Some(name) = simple_type.clone() {
                        md.enumerations.push((name, Vec::new()));
                    }
                }
                b"Item" => {
                    if let (Some(_), Some((type_name, items))) = (&simple_type, md.enumerations.last_mut()) {
                        let name = get("name").ok_or_else(|| format!("an Item of {type_name} has no name"))?;
                        let value = get("value")
                            .and_then(|v| v.trim().parse().ok())
                            .ok_or_else(|| format!("Item {name:?} of {type_name} has no integer value"))?;
                        items.push(EnumerationItem {
                            name,
                            value,
                            description: get("description").unwrap_or_default(),
                        });
                    }
                }
                b"ScalarVariable" => {
                    let name = get("name").ok_or("a ScalarVariable has no name")?;
                    let vr = get("valueReference")
                        .ok_or_else(|| format!("{name} has no valueReference"))?
                        .parse()
                        .map_err(|_| format!("{name}: valueReference is not an unsigned integer"))?;
                    let v = VariableInfo {
                        name,
                        value_reference: vr,
                        ty: VariableType::Real,
                        causality: get("causality").unwrap_or_else(|| "local".into()),
                        variability: get("variability").unwrap_or_else(|| "continuous".into()),
                        start: None,
                        unit: None,
                        min: None,
                        max: None,
                        declared_type: None,
                        description: get("description").unwrap_or_default(),
                    };
                    if is_empty {
                        return Err(format!("{} has no type element", v.name));
                    }
                    current = Some(v);
                }
                tag @ (b"Real" | b"Integer" | b"Boolean" | b"String" | b"Enumeration") => {
                    if let Some(v) = current.as_mut() {
                        v.ty = match tag {
                            b"Real" => VariableType::Real,
                            b"Integer" => VariableType::Integer,
                            b"Boolean" => VariableType::Boolean,
                            b"String" => VariableType::String,
                            _ => VariableType::Enumeration,
                        };
                        v.start = get("start");
                        v.unit = get("unit");
                        v.min = get("min");
                        v.max = get("max");
                        v.declared_type = get("declaredType");
                    }
                }
                _ => {}
            }
        }
        if md.model_identifier.is_empty() {
            return Err("no CoSimulation element: not a co-simulation FMU".into());
        }
        Ok(md)
    }

    pub fn variable(&self, name: &str) -> Result<&VariableInfo, HarnessError> {
        self.variables.iter().find(|v| v.name == name).ok_or_else(|| HarnessError::UnknownVariable {
            name: name.to_string(),
            close: did_you_mean(name, self.variables.iter().map(|v| v.name.as_str())),
        })
    }

    /// The items of a variable's Enumeration type (empty for other types).
    pub fn enumeration_items(&self, v: &VariableInfo) -> &[EnumerationItem] {
        let declared = v.declared_type.as_deref().unwrap_or_default();
        self.enumerations.iter().find(|(n, _)| n == declared).map_or(&[], |(_, items)| items.as_slice())
    }
}

/// Up to five candidates close to `name`: by Jaro–Winkler similarity (clap's own measure for
/// subcommand suggestions), or containing it, best first.
pub fn did_you_mean<'a>(name: &str, candidates: impl Iterator<Item = &'a str>) -> Vec<String> {
    let mut scored: Vec<(f64, &str)> = candidates
        .map(|c| {
            let contains = !name.is_empty() && (c.contains(name) || name.contains(c));
            (strsim::jaro_winkler(name, c).max(if contains { 0.9 } else { 0.0 }), c)
        })
        .filter(|(score, _)| *score > 0.8)
        .collect();
    scored.sort_by(|a, b| b.0.total_cmp(&a.0));
    scored.into_iter().take(5).map(|(_, c)| c.to_string()).collect()
}
