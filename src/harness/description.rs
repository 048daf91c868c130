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
    pub description: String,
}

#[derive(Clone, Debug)]
pub struct ModelDescription {
    pub guid: String,
    pub model_name: String,
    pub model_identifier: String,
    pub fmi_version: String,
    pub variables: Vec<VariableInfo>,
    pub default_step_size: Option<f64>,
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
            variables: Vec::new(),
            default_step_size: None,
        };
        let mut current: Option<VariableInfo> = None;
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
                Event::Eof => break,
                _ => continue,
            };
            let mut attrs = std::collections::HashMap::new();
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
                    if md.fmi_version != "2.0" {
                        return Err(format!("fmiVersion {:?}: only FMI 2.0 is supported", md.fmi_version));
                    }
                }
                b"CoSimulation" => {
                    md.model_identifier = get("modelIdentifier").ok_or("CoSimulation has no modelIdentifier")?;
                }
                b"DefaultExperiment" => {
                    md.default_step_size = get("stepSize").and_then(|s| s.parse().ok());
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
        self.variables.iter().find(|v| v.name == name).ok_or_else(|| {
            let stem: String = name.chars().take(4).collect();
            let close = self
                .variables
                .iter()
                .filter(|v| v.name.contains(&stem) || name.contains(&v.name))
                .map(|v| v.name.clone())
                .take(5)
                .collect();
            HarnessError::UnknownVariable { name: name.to_string(), close }
        })
    }
}
