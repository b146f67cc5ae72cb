//! A foreign FMU's modelDescription.xml, as far as the import needs it:
//! identity (name, GUID, FMI version, generation tool), the co-simulation
//! capabilities (model identifier, `canBeInstantiatedOnlyOncePerProcess`),
//! the default experiment and the scalar variables (causality,
//! variability, initial, type, start). A small element scanner rather than
//! an XML library: the description is flat attributes, and the tools that
//! write it (FMI 2.0, section 2.2) use no DTD, CDATA or namespaces there.

use std::collections::HashMap;

/// A variable's base type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum VarKind {
    Real,
    Integer,
    Boolean,
    String,
    Enumeration,
}

#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    pub name: String,
    pub vr: u32,
    pub kind: VarKind,
    /// FMI 2.0 defaults when absent: causality `local`, variability `continuous`.
    pub causality: String,
    pub variability: String,
    pub initial: Option<String>,
    pub unit: Option<String>,
    pub start: Option<String>,
}

impl Variable {
    /// Why the import cannot set this variable before initialisation
    /// (a parameter) or during the run (`during_run`: an input), if it
    /// cannot.
    pub fn not_settable(&self, during_run: bool) -> Option<String> {
        let c = self.causality.as_str();
        let v = self.variability.as_str();
        if c == "calculatedParameter" || self.initial.as_deref() == Some("calculated") {
            return Some(format!("{} is calculated by the FMU", self.name));
        }
        if v == "constant" {
            return Some(format!("{} is a constant", self.name));
        }
        if during_run {
            if c != "input" && !(c == "parameter" && v == "tunable") {
                return Some(format!(
                    "{} is fixed after initialisation (causality {c}, variability {v}): it must be an input",
                    self.name
                ));
            }
        } else if c != "parameter" && c != "input" {
            return Some(format!("{} is not a parameter (causality {c})", self.name));
        }
        if self.kind == VarKind::String {
            return Some(format!("{} is a string", self.name));
        }
        None
    }
}

/// What modelDescription.xml says.
#[derive(Debug, Clone, PartialEq)]
pub struct Description {
    pub fmi_version: String,
    pub model_name: String,
    pub guid: String,
    pub generation_tool: Option<String>,
    /// The co-simulation interface's model identifier (names the binary);
    /// None when the FMU has no co-simulation interface.
    pub model_identifier: Option<String>,
    pub once_per_process: bool,
    pub default_step_s: Option<f64>,
    pub default_stop_s: Option<f64>,
    pub variables: Vec<Variable>,
    /// The co-simulation interface's `SourceFiles` (a source-code FMU's,
    /// relative to `sources/`), in order.
    pub source_files: Vec<String>,
}

impl Description {
    /// Parses the description's text (errors say what is missing).
    pub fn parse(xml: &str) -> Result<Self, String> {
        let mut root: Option<HashMap<String, String>> = None;
        let mut cosim: Option<HashMap<String, String>> = None;
        let mut experiment: Option<HashMap<String, String>> = None;
        let mut variables = Vec::new();
        let mut open: Option<HashMap<String, String>> = None;
        let mut source_files = Vec::new();
        // Which interface a `File` belongs to: the last one opened (end
        // tags are not seen, and files appear only inside an interface).
        let mut in_cosim = false;
        for (name, mut attrs) in elements(xml)? {
            match name.as_str() {
                "fmiModelDescription" => root = Some(attrs),
                "ModelExchange" => in_cosim = false,
                "CoSimulation" => {
                    in_cosim = true;
                    cosim = Some(attrs)
                }
                "File" if in_cosim => source_files.extend(attrs.remove("name")),
                "DefaultExperiment" => experiment = Some(attrs),
                "ScalarVariable" => open = Some(attrs),
                "Real" | "Integer" | "Boolean" | "String" | "Enumeration" => {
                    let Some(sv) = open.take() else { continue };
                    variables.push(variable(&name, sv, &attrs)?);
                }
                _ => {}
            }
        }
        let mut root = root.ok_or("no fmiModelDescription element")?;
        let mut take = |k: &str| root.remove(k).ok_or(format!("fmiModelDescription has no {k}"));
        let fmi_version = take("fmiVersion")?;
        let model_name = take("modelName")?;
        // FMI 3.0 names it instantiationToken: such an FMU is read far
        // enough to be refused by its version, not for a missing guid.
        let guid = match take("guid") {
            Ok(g) => g,
            Err(_) if !fmi_version.starts_with("2.") => root.remove("instantiationToken").unwrap_or_default(),
            Err(e) => return Err(e),
        };
        let generation_tool = root.remove("generationTool");
        let flag = |m: &Option<HashMap<String, String>>, k: &str| {
            m.as_ref().and_then(|m| m.get(k)).is_some_and(|v| v == "true")
        };
        let num = |k: &str| experiment.as_ref().and_then(|m| m.get(k)).and_then(|v| v.parse().ok());
        Ok(Description {
            fmi_version,
            model_name,
            guid,
            generation_tool,
            model_identifier: cosim.as_ref().and_then(|m| m.get("modelIdentifier").cloned()),
            once_per_process: flag(&cosim, "canBeInstantiatedOnlyOncePerProcess"),
            default_step_s: num("stepSize"),
            default_stop_s: num("stopTime"),
            variables,
            source_files,
        })
    }

    /// The description of the FMU unpacked in `dir`, as the import runs
    /// it: FMI 2.0 with a co-simulation interface, whose model identifier
    /// (naming its binary) comes with it. Errors say which it is not.
    pub fn read_cosim(dir: &std::path::Path) -> Result<(Self, String), String> {
        let xml = std::fs::read_to_string(dir.join("modelDescription.xml"))
            .map_err(|_| "no modelDescription.xml in it".to_string())?;
        let desc = Self::parse(&xml).map_err(|e| format!("modelDescription.xml: {e}"))?;
        if !desc.fmi_version.starts_with("2.") {
            return Err(format!(
                "FMI version {}: the import runs FMI 2.0 co-simulation; export the model as FMI 2.0 (docs/your-model.md)",
                desc.fmi_version
            ));
        }
        let id = desc
            .model_identifier
            .clone()
            .ok_or("no co-simulation interface (model exchange only)")?;
        Ok((desc, id))
    }

    pub fn variable(&self, name: &str) -> Option<&Variable> {
        self.variables.iter().find(|v| v.name == name)
    }
}

/// What a source-code FMU's `sources/buildDescription.xml` says to build
/// for one model identifier (FMI 3.0's build description, which FMI 2.0
/// FMUs may carry too): the first `BuildConfiguration` for it.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Build {
    pub sources: Vec<String>,
    /// `(name, value)`: `-Dname=value` (`-Dname` without a value).
    pub definitions: Vec<(String, Option<String>)>,
    pub include_dirs: Vec<String>,
}

impl Build {
    /// The configuration for `model_identifier` (one that names none fits
    /// any); None when there is none.
    pub fn parse(xml: &str, model_identifier: &str) -> Result<Option<Self>, String> {
        let mut found: Option<Build> = None;
        let mut current: Option<Build> = None;
        for (name, mut attrs) in elements(xml)? {
            match name.as_str() {
                "BuildConfiguration" => {
                    if found.is_none() {
                        found = current.take();
                    }
                    let fits = attrs.get("modelIdentifier").is_none_or(|id| id == model_identifier);
                    current = fits.then(Build::default);
                }
                "SourceFile" => current.iter_mut().for_each(|b| b.sources.extend(attrs.remove("name"))),
                "PreprocessorDefinition" => {
                    if let (Some(b), Some(n)) = (current.as_mut(), attrs.remove("name")) {
                        b.definitions.push((n, attrs.remove("value")));
                    }
                }
                "IncludeDirectory" => current
                    .iter_mut()
                    .for_each(|b| b.include_dirs.extend(attrs.remove("name"))),
                _ => {}
            }
        }
        Ok(found.or(current))
    }
}

fn variable(kind: &str, mut sv: HashMap<String, String>, attrs: &HashMap<String, String>) -> Result<Variable, String> {
    let name = sv.remove("name").ok_or("a ScalarVariable has no name")?;
    let vr = sv
        .get("valueReference")
        .and_then(|v| v.parse().ok())
        .ok_or_else(|| format!("ScalarVariable {name} has no valueReference"))?;
    Ok(Variable {
        vr,
        kind: match kind {
            "Real" => VarKind::Real,
            "Integer" => VarKind::Integer,
            "Boolean" => VarKind::Boolean,
            "String" => VarKind::String,
            _ => VarKind::Enumeration,
        },
        causality: sv.remove("causality").unwrap_or_else(|| "local".into()),
        variability: sv.remove("variability").unwrap_or_else(|| "continuous".into()),
        initial: sv.remove("initial"),
        unit: attrs.get("unit").cloned(),
        start: attrs.get("start").cloned(),
        name,
    })
}

/// Every element's name and attributes, in document order (end tags,
/// comments, processing instructions and declarations skipped).
fn elements(xml: &str) -> Result<Vec<(String, HashMap<String, String>)>, String> {
    let mut out = Vec::new();
    let mut rest = xml;
    while let Some(at) = rest.find('<') {
        rest = &rest[at + 1..];
        if let Some(r) = rest.strip_prefix("!--") {
            let end = r.find("-->").ok_or("an unterminated comment")?;
            rest = &r[end + 3..];
            continue;
        }
        if rest.starts_with('?') || rest.starts_with('!') || rest.starts_with('/') {
            rest = &rest[rest.find('>').ok_or("an unterminated tag")? + 1..];
            continue;
        }
        let name_end = rest
            .find(|c: char| c.is_whitespace() || c == '>' || c == '/')
            .ok_or("an unterminated tag")?;
        let name = rest[..name_end].to_string();
        rest = &rest[name_end..];
        let mut attrs = HashMap::new();
        loop {
            rest = rest.trim_start();
            if let Some(r) = rest.strip_prefix("/>").or_else(|| rest.strip_prefix('>')) {
                rest = r;
                break;
            }
            let eq = rest.find('=').ok_or_else(|| format!("a bad attribute in <{name}>"))?;
            let key = rest[..eq].trim().to_string();
            let r = rest[eq + 1..].trim_start();
            let quote = r.chars().next().filter(|c| *c == '"' || *c == '\'');
            let quote = quote.ok_or_else(|| format!("an unquoted attribute {key} in <{name}>"))?;
            let end = r[1..]
                .find(quote)
                .ok_or_else(|| format!("an unterminated attribute {key} in <{name}>"))?;
            attrs.insert(key, unescape(&r[1..1 + end]));
            rest = &r[end + 2..];
        }
        out.push((name, attrs));
    }
    Ok(out)
}

fn unescape(s: &str) -> String {
    s.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&apos;", "'")
        .replace("&amp;", "&")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_fmi_3_description_reads_as_far_as_its_version() {
        // As the Reference FMUs write it: an instantiationToken, no guid.
        let xml = r#"<fmiModelDescription fmiVersion="3.0" modelName="BouncingBall" instantiationToken="{1AE5}">
  <CoSimulation modelIdentifier="BouncingBall"/></fmiModelDescription>"#;
        let d = Description::parse(xml).unwrap();
        assert_eq!((d.fmi_version.as_str(), d.guid.as_str()), ("3.0", "{1AE5}"));
        // FMI 2.0 without its guid is still refused for it.
        let e = Description::parse(&xml.replace("3.0", "2.0")).unwrap_err();
        assert!(e.contains("no guid"), "{e}");
    }

    #[test]
    fn a_source_fmus_files_are_the_co_simulation_interfaces() {
        let xml = r#"<fmiModelDescription fmiVersion="2.0" modelName="m" guid="{1}">
  <ModelExchange modelIdentifier="m"><SourceFiles><File name="me.c"/></SourceFiles></ModelExchange>
  <CoSimulation modelIdentifier="m"><SourceFiles><File name="all.c"/><File name="extra.c"/></SourceFiles></CoSimulation>
</fmiModelDescription>"#;
        assert_eq!(Description::parse(xml).unwrap().source_files, ["all.c", "extra.c"]);
        // The build description: the configuration for this identifier.
        let build = r#"<fmiBuildDescription fmiVersion="3.0">
  <BuildConfiguration modelIdentifier="other"><SourceFileSet><SourceFile name="o.c"/></SourceFileSet></BuildConfiguration>
  <BuildConfiguration modelIdentifier="m"><SourceFileSet language="C99">
    <SourceFile name="a.c"/><SourceFile name="b.c"/>
    <PreprocessorDefinition name="FMI_VERSION" value="2"/><PreprocessorDefinition name="NDEBUG"/>
    <IncludeDirectory name="include"/>
  </SourceFileSet></BuildConfiguration>
</fmiBuildDescription>"#;
        let b = Build::parse(build, "m").unwrap().unwrap();
        assert_eq!(b.sources, ["a.c", "b.c"]);
        assert_eq!(
            b.definitions,
            [
                ("FMI_VERSION".to_string(), Some("2".to_string())),
                ("NDEBUG".to_string(), None)
            ]
        );
        assert_eq!(b.include_dirs, ["include"]);
        assert_eq!(Build::parse(build, "nope").unwrap(), None);
    }

    #[test]
    fn a_description_reads_and_settability_is_judged() {
        let xml = r#"<?xml version="1.0"?>
<!-- a comment with <b>tags</b> -->
<fmiModelDescription fmiVersion="2.0" modelName="m &amp; n" guid="{1}" generationTool='Tool 1'>
  <CoSimulation modelIdentifier="m" canBeInstantiatedOnlyOncePerProcess="true"/>
  <DefaultExperiment stopTime="1.5" stepSize="1e-4"/>
  <ModelVariables>
    <ScalarVariable name="k" valueReference="3" causality="parameter" variability="fixed" initial="exact"><Real unit="N" start="2"/></ScalarVariable>
    <ScalarVariable name="d" valueReference="4" causality="calculatedParameter" variability="fixed"><Real/></ScalarVariable>
    <ScalarVariable name="u" valueReference="5" causality="input"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="6" causality="output"><Integer/></ScalarVariable>
  </ModelVariables>
</fmiModelDescription>"#;
        let d = Description::parse(xml).unwrap();
        assert_eq!((d.model_name.as_str(), d.guid.as_str()), ("m & n", "{1}"));
        assert_eq!(d.generation_tool.as_deref(), Some("Tool 1"));
        assert_eq!(d.model_identifier.as_deref(), Some("m"));
        assert!(d.once_per_process);
        assert_eq!((d.default_step_s, d.default_stop_s), (Some(1e-4), Some(1.5)));
        assert_eq!(d.variables.len(), 4);
        assert!(d.source_files.is_empty());
        let k = d.variable("k").unwrap();
        assert_eq!((k.vr, k.kind, k.unit.as_deref()), (3, VarKind::Real, Some("N")));
        assert_eq!(k.not_settable(false), None);
        assert!(k.not_settable(true).unwrap().contains("fixed after initialisation"));
        assert!(d
            .variable("d")
            .unwrap()
            .not_settable(false)
            .unwrap()
            .contains("calculated"));
        assert_eq!(d.variable("u").unwrap().not_settable(true), None);
        assert!(d.variable("y").unwrap().not_settable(false).is_some());
        assert_eq!(d.variable("y").unwrap().kind, VarKind::Integer);
        assert!(Description::parse("<fmiModelDescription modelName=\"x\"/>").is_err());
        assert!(Description::parse("<a b=c>").is_err());
    }
}
