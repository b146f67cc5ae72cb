//! What ties the package to the binary: the configuration in
//! `resources/config.json` (the start values; the binary reads it at
//! instantiation), the GUID (a hash of that file, so a description and a
//! configuration that do not belong together are refused), and
//! modelDescription.xml, written from the same [`Table`] the binary uses.

use std::fmt::Write as _;

use hammer_sim::SimConfig;

use crate::instance::Model;
use crate::table::{Kind, Table, Val};
use crate::variants::VariantsConfig;

/// The configuration file inside the FMU, under `resources/`: the
/// built-in model's, or the second family's.
pub const CONFIG_RESOURCE: &str = "config.json";
pub const VARIANTS_RESOURCE: &str = "variants.json";

/// The FMU's GUID: FNV-1a over the configuration file and the crate's
/// version, shaped as a GUID.
pub fn guid(config_json: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut h2: u64 = 0x8422_2325_cbf2_9ce4;
    for b in config_json.bytes().chain(env!("CARGO_PKG_VERSION").bytes()) {
        h = (h ^ u64::from(b)).wrapping_mul(0x0100_0000_01b3);
        h2 = (h2 ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3 ^ 0x10);
    }
    format!(
        "{{{:08x}-{:04x}-{:04x}-{:04x}-{:012x}}}",
        h >> 32,
        (h >> 16) & 0xffff,
        h & 0xffff,
        h2 >> 48,
        h2 & 0xffff_ffff_ffff
    )
}

/// The configuration text `hammer fmu` puts in the package.
pub fn config_json(cfg: &SimConfig) -> Result<String, String> {
    serde_json::to_string_pretty(cfg).map_err(|e| e.to_string())
}

/// The resource file of `model` and its text.
pub fn resource(model: &Model) -> Result<(&'static str, String), String> {
    match model {
        Model::Hammer(cfg) => Ok((CONFIG_RESOURCE, config_json(cfg)?)),
        Model::Variants(cfg) => Ok((
            VARIANTS_RESOURCE,
            serde_json::to_string_pretty(cfg).map_err(|e| e.to_string())?,
        )),
    }
}

/// A `file:` URI's path (`file:///a%20b`, `file:/a`, `file://localhost/a`).
fn uri_path(uri: &str) -> Result<String, String> {
    let rest = uri
        .strip_prefix("file://localhost")
        .or_else(|| uri.strip_prefix("file://"))
        .or_else(|| uri.strip_prefix("file:"))
        .ok_or_else(|| format!("resource location {uri} is not a file: URI"))?;
    let bytes = rest.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = bytes.get(i + 1..i + 3).and_then(|h| std::str::from_utf8(h).ok());
        match (bytes[i], hex.and_then(|h| u8::from_str_radix(h, 16).ok())) {
            (b'%', Some(v)) => {
                out.push(v);
                i += 3;
            }
            (b, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8(out).map_err(|_| format!("resource location {uri} is not UTF-8"))
}

/// The model in the resources folder at `location` (a URI), and its
/// configuration's text.
pub fn read_resources(location: &str) -> Result<(Model, String), String> {
    let dir = std::path::PathBuf::from(uri_path(location)?);
    let variants = dir.join(VARIANTS_RESOURCE);
    let path = if variants.is_file() {
        variants
    } else {
        dir.join(CONFIG_RESOURCE)
    };
    let json = std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    let bad = |e: String| format!("{}: not this FMU's configuration: {e}", path.display());
    let model = if path.ends_with(VARIANTS_RESOURCE) {
        let cfg: VariantsConfig = serde_json::from_str(&json).map_err(|e| bad(e.to_string()))?;
        cfg.validate().map_err(bad)?;
        Model::Variants(cfg)
    } else {
        let cfg: SimConfig = serde_json::from_str(&json).map_err(|e| bad(e.to_string()))?;
        cfg.validate().map_err(|e| bad(e.to_string()))?;
        Model::Hammer(cfg)
    };
    Ok((model, json))
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

fn start_text(v: Val) -> String {
    match v {
        // Rust's shortest round-trip form is a valid xs:double.
        Val::Real(x) => format!("{x:?}"),
        Val::Integer(i) => i.to_string(),
        Val::Boolean(b) => b.to_string(),
    }
}

/// modelDescription.xml of `table` (`model_identifier` names the binary).
pub fn model_description(
    table: &Table,
    model_identifier: &str,
    description: &str,
    guid: &str,
    stop_time_s: f64,
    step_s: f64,
) -> String {
    let mut x = String::new();
    let _ = writeln!(x, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        x,
        r#"<fmiModelDescription fmiVersion="2.0" modelName="{model_identifier}" guid="{guid}" description="{}" generationTool="hammer-monitor {}" variableNamingConvention="structured" numberOfEventIndicators="0">"#,
        escape(description),
        env!("CARGO_PKG_VERSION")
    );
    let _ = writeln!(
        x,
        r#"  <CoSimulation modelIdentifier="{model_identifier}" canHandleVariableCommunicationStepSize="true" canGetAndSetFMUstate="false" canSerializeFMUstate="false" providesDirectionalDerivative="false" canNotUseMemoryManagementFunctions="true" canBeInstantiatedOnlyOncePerProcess="false" needsExecutionTool="false"/>"#
    );
    let mut units: Vec<&str> = table.vars.iter().filter_map(|v| v.unit.as_deref()).collect();
    units.sort_unstable();
    units.dedup();
    let _ = writeln!(x, "  <UnitDefinitions>");
    for u in units {
        let _ = writeln!(x, r#"    <Unit name="{}"/>"#, escape(u));
    }
    let _ = writeln!(x, "  </UnitDefinitions>");
    // The categories the library logs under (crate::ffi).
    let _ = writeln!(
        x,
        r#"  <LogCategories><Category name="logStatusError"/><Category name="logAll"/></LogCategories>"#
    );
    let _ = writeln!(
        x,
        r#"  <DefaultExperiment startTime="0.0" stopTime="{stop_time_s:?}" stepSize="{step_s:?}"/>"#
    );
    let _ = writeln!(x, "  <ModelVariables>");
    for (vr, v) in table.vars.iter().enumerate() {
        let attrs = if v.is_output() {
            let variability = if v.kind == Kind::Real { "continuous" } else { "discrete" };
            format!(r#"causality="output" variability="{variability}" initial="calculated""#)
        } else {
            r#"causality="parameter" variability="fixed" initial="exact""#.to_string()
        };
        let _ = writeln!(
            x,
            r#"    <ScalarVariable name="{}" valueReference="{vr}" description="{}" {attrs}>"#,
            escape(&v.name),
            escape(&v.description)
        );
        let kind = match v.kind {
            Kind::Real => "Real",
            Kind::Integer => "Integer",
            Kind::Boolean => "Boolean",
        };
        let unit = v
            .unit
            .as_deref()
            .map_or(String::new(), |u| format!(r#" unit="{}""#, escape(u)));
        let start = if v.is_output() {
            String::new()
        } else {
            format!(r#" start="{}""#, start_text(v.start))
        };
        let _ = writeln!(x, "      <{kind}{unit}{start}/>");
        let _ = writeln!(x, "    </ScalarVariable>");
    }
    let _ = writeln!(x, "  </ModelVariables>");
    let _ = writeln!(x, "  <ModelStructure>");
    for section in ["Outputs", "InitialUnknowns"] {
        let _ = writeln!(x, "    <{section}>");
        // Indices are 1-based positions in ModelVariables; no dependencies
        // listed: each depends on every known (the parameters).
        for (vr, _) in table.vars.iter().enumerate().filter(|(_, v)| v.is_output()) {
            let _ = writeln!(x, r#"      <Unknown index="{}"/>"#, vr + 1);
        }
        let _ = writeln!(x, "    </{section}>");
    }
    let _ = writeln!(x, "  </ModelStructure>");
    let _ = writeln!(x, "</fmiModelDescription>");
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn resource_uris_are_decoded() {
        assert_eq!(uri_path("file:///tmp/a%20b/resources").unwrap(), "/tmp/a b/resources");
        assert_eq!(uri_path("file:/tmp/x").unwrap(), "/tmp/x");
        assert_eq!(uri_path("file://localhost/tmp/x").unwrap(), "/tmp/x");
        assert!(uri_path("http://x").is_err());
        assert_ne!(guid("a"), guid("b"));
    }
}
