//! `map.toml`: how a foreign FMU's variables stand for the project's
//! quantities (issue 46, item 2). One format, read here and written by
//! `hammer fmu` for the project's own FMUs ([`crate::package`] builds a
//! [`ModelMap`] and serialises it), so the export's map is a valid map by
//! construction and by test.
//!
//! - `[signals]`: the outputs for the rear and front chamber pressures and
//!   the piston acceleration (unit, gauge or absolute, sign), optionally
//!   position, velocity and an impact counter;
//! - `[supply]`: the supply-pressure parameter or input;
//! - `[[nuisance]]`: nominal parameters the engineer is unsure of, with a
//!   relative uncertainty;
//! - `[fixed]`: parameters set per case and not fitted;
//! - `[effects.NAME]`: per catalogue effect, the FMU parameters that carry
//!   it (unit, range, nominal, off value) and its switch, or a `law`: one
//!   FMU force parameter given the effect's friction law evaluated at each
//!   run's supply pressure;
//! - `[outside]`: what the project applies itself (the sensor effects;
//!   friction through a piston-force input).
//!
//! Effect names are checked against the catalogue's registry; an effect
//! the map does not carry is "not modelled".

use std::collections::BTreeMap;
use std::path::Path;

use hammer_sim::effects::{entry, EffectEntry, REGISTRY};
use serde::{Deserialize, Serialize};

use super::units::{same_unit, Quantity};

/// A signal output: which FMU output, in which unit, gauge or absolute,
/// and its sign (the project's convention: forward +, gauge pressure).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Signal {
    pub output: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub unit: Option<String>,
    /// `"gauge"` or `"absolute"` (pressures only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pressure: Option<Reference>,
    /// +1 or −1.
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub sign: f64,
}

fn one() -> f64 {
    1.0
}

fn is_one(x: &f64) -> bool {
    *x == 1.0
}

/// Gauge or absolute pressure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Reference {
    Gauge,
    Absolute,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Signals {
    pub p_rear: Signal,
    pub p_front: Signal,
    pub accel: Signal,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<Signal>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub velocity: Option<Signal>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub impact_counter: Option<Signal>,
}

/// The supply pressure: a parameter (set before initialisation) or an
/// input (held constant over the run).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Supply {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parameter: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub input: Option<String>,
    pub unit: String,
    pub pressure: Reference,
}

impl Supply {
    /// The FMU variable that carries the supply pressure.
    pub fn variable(&self) -> &str {
        self.parameter.as_deref().or(self.input.as_deref()).unwrap_or("")
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Nuisance {
    pub parameter: String,
    pub nominal: f64,
    pub relative_uncertainty: f64,
}

/// One FMU parameter carrying a catalogue parameter: the FMU's value is
/// `scale` × the catalogue's (in the catalogue's unit) when `unit` is not
/// the catalogue's.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectParam {
    pub parameter: String,
    pub unit: String,
    pub lo: f64,
    pub hi: f64,
    pub nominal: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub off: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
}

/// A friction law evaluated at each run's supply pressure into one FMU
/// force parameter (the catalogue effect's force at full sliding speed).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Law {
    pub parameter: String,
    pub unit: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub off: Option<f64>,
}

#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EffectCarrier {
    /// A Boolean parameter that switches the effect on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub switch: Option<String>,
    /// Catalogue parameter key → FMU parameter.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub params: BTreeMap<String, EffectParam>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub law: Option<Law>,
}

/// A piston-force input the project drives (friction from outside).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceInput {
    pub input: String,
    pub unit: String,
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub sign: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Outside {
    /// The project applies the catalogue's sensor effects (gain, zero
    /// shift) to the FMU's outputs.
    #[serde(default = "yes")]
    pub sensor_effects: bool,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub piston_force: Option<ForceInput>,
}

fn yes() -> bool {
    true
}

impl Default for Outside {
    fn default() -> Self {
        Self {
            sensor_effects: true,
            piston_force: None,
        }
    }
}

/// A model map.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModelMap {
    /// The FMU's file name, for the reader's information.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fmu: Option<String>,
    /// The communication step (default: the FMU's DefaultExperiment stepSize).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step_s: Option<f64>,
    pub signals: Signals,
    pub supply: Supply,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub nuisance: Vec<Nuisance>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub fixed: BTreeMap<String, f64>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub effects: BTreeMap<String, EffectCarrier>,
    #[serde(default)]
    pub outside: Outside,
}

/// How the diagnosis can meet a catalogue effect with this map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Coverage {
    /// FMU parameters carry it.
    InFmu,
    /// The project applies it to the FMU's outputs (sensor effects).
    OnOutputs,
    /// The project drives it through the FMU's piston-force input.
    ForceInput,
    /// Left out of the run; its detection floor reads "not modelled".
    NotModelled,
}

impl Coverage {
    pub fn label(self) -> &'static str {
        match self {
            Coverage::InFmu => "in the FMU",
            Coverage::OnOutputs => "applied to the outputs",
            Coverage::ForceInput => "through the piston-force input",
            Coverage::NotModelled => "not modelled",
        }
    }
}

/// The force of `effect`'s supply-pressure law at `supply_bar` with
/// `params` (its config table), N; None when it has no such law.
pub fn law_force_n(effect: &dyn EffectEntry, params: toml::Value, supply_bar: f64) -> Option<f64> {
    effect.supply_law_n(params, supply_bar).filter(|f| f.is_finite())
}

/// A friction force on the piston: what a piston-force input can carry.
/// Asked of the built-in plant (its friction with the effect on at its
/// defaults), so a new friction effect needs no list here.
pub fn is_piston_force(e: &dyn EffectEntry) -> bool {
    if e.has_piston_drag() {
        return true;
    }
    let mut cfg = hammer_sim::SimConfig::default();
    if e.sensor() || e.set(&mut cfg.effects, e.default_params()).is_err() {
        return false;
    }
    hammer_sim::model::HammerModel::new(&cfg).friction_n(0.0, 1.0) != 0.0
}

impl ModelMap {
    /// Reads and checks `path` (the format, the catalogue's names, the
    /// units, ranges and uncertainties): errors name the file.
    pub fn read(path: &Path) -> Result<(Self, String), String> {
        let text = std::fs::read_to_string(path).map_err(|e| format!("model map {}: {e}", path.display()))?;
        let map = Self::parse(&text).map_err(|e| format!("model map {}: {e}", path.display()))?;
        Ok((map, text))
    }

    /// Parses and checks a map's text.
    pub fn parse(text: &str) -> Result<Self, String> {
        let map: ModelMap = toml::from_str(text).map_err(|e| format!("not a model map: {}", e.message()))?;
        map.validate()?;
        Ok(map)
    }

    /// The map as TOML (what `hammer fmu` writes).
    pub fn to_toml(&self) -> Result<String, String> {
        toml::to_string(self).map_err(|e| e.to_string())
    }

    /// Checks what the map says on its own (not against an FMU).
    pub fn validate(&self) -> Result<(), String> {
        let s = &self.signals;
        for (name, sig, q) in [
            ("p_rear", Some(s.p_rear.clone()), Quantity::Pressure),
            ("p_front", Some(s.p_front.clone()), Quantity::Pressure),
            ("accel", Some(s.accel.clone()), Quantity::Acceleration),
            ("position", s.position.clone(), Quantity::Length),
            ("velocity", s.velocity.clone(), Quantity::Velocity),
        ] {
            let Some(sig) = sig else { continue };
            let unit = sig.unit.as_deref().unwrap_or(q.si());
            q.to_si(unit)
                .ok_or_else(|| format!("signals.{name}: unit {unit:?} is not a {} unit", q.what()))?;
            if sig.sign != 1.0 && sig.sign != -1.0 {
                return Err(format!("signals.{name}: sign is {} (1 or -1)", sig.sign));
            }
            if q == Quantity::Pressure && sig.pressure.is_none() {
                return Err(format!("signals.{name}: say pressure = \"gauge\" or \"absolute\""));
            }
        }
        match (&self.supply.parameter, &self.supply.input) {
            (Some(_), None) | (None, Some(_)) => {}
            _ => return Err("supply: give exactly one of parameter or input".into()),
        }
        Quantity::Pressure
            .to_si(&self.supply.unit)
            .ok_or_else(|| format!("supply: unit {:?} is not a pressure unit", self.supply.unit))?;
        if let Some(step) = self.step_s {
            if !(step > 0.0 && step.is_finite()) {
                return Err(format!("step_s = {step}: a positive communication step, s"));
            }
        }
        for n in &self.nuisance {
            if !(n.relative_uncertainty > 0.0 && n.relative_uncertainty < 1.0) || !n.nominal.is_finite() {
                return Err(format!(
                    "nuisance {}: relative_uncertainty {} must lie in (0, 1), nominal finite",
                    n.parameter, n.relative_uncertainty
                ));
            }
        }
        for (p, v) in &self.fixed {
            if !v.is_finite() {
                return Err(format!("fixed.{p} = {v} is not a finite number"));
            }
        }
        for (name, carrier) in &self.effects {
            self.validate_effect(name, carrier)?;
        }
        if let Some(f) = &self.outside.piston_force {
            if !same_unit(&f.unit, "N") {
                return Err(format!("outside.piston_force: unit {:?} (N)", f.unit));
            }
            if self.signals.velocity.is_none() {
                return Err("outside.piston_force needs a velocity signal (the force opposes the motion)".into());
            }
        }
        Ok(())
    }

    fn validate_effect(&self, name: &str, c: &EffectCarrier) -> Result<(), String> {
        let e = entry(name).ok_or_else(|| {
            let names: Vec<&str> = REGISTRY.iter().map(|e| e.name()).collect();
            format!("effects.{name}: no such catalogue effect (one of {})", names.join(", "))
        })?;
        let at = |k: &str| format!("effects.{name}.{k}");
        if c.params.is_empty() && c.law.is_none() {
            return Err(format!("effects.{name}: give params or a law"));
        }
        for (key, p) in &c.params {
            let cat = e
                .params()
                .iter()
                .find(|q| q.key == key)
                .ok_or_else(|| format!("{}: {name} has no parameter {key}", at("params")))?;
            if p.scale.is_none() && !same_unit(&p.unit, cat.unit) {
                return Err(format!(
                    "{}: unit {:?} is not the catalogue's {:?}: give scale (FMU value per catalogue value)",
                    at(key),
                    p.unit,
                    cat.unit
                ));
            }
            if !(p.lo <= p.nominal && p.nominal <= p.hi) || !p.lo.is_finite() || !p.hi.is_finite() {
                return Err(format!(
                    "{}: nominal {} outside lo..hi {}..{}",
                    at(key),
                    p.nominal,
                    p.lo,
                    p.hi
                ));
            }
            if c.switch.is_none() && p.off.is_none() {
                return Err(format!(
                    "{}: without a switch every parameter needs an off value",
                    at(key)
                ));
            }
        }
        if let Some(law) = &c.law {
            if law_force_n(e, e.default_params(), 1.0).is_none() {
                return Err(format!(
                    "{}: {name} has no piston-force law of supply pressure",
                    at("law")
                ));
            }
            if !same_unit(&law.unit, "N") {
                return Err(format!("{}: unit {:?} (N)", at("law"), law.unit));
            }
            if c.switch.is_none() && law.off.is_none() {
                return Err(format!("{}: without a switch the law needs an off value", at("law")));
            }
        }
        Ok(())
    }

    /// How each catalogue effect is met, in catalogue order.
    pub fn coverage(&self) -> Vec<(&'static str, Coverage)> {
        REGISTRY
            .iter()
            .map(|e| {
                let c = if self.effects.contains_key(e.name()) {
                    Coverage::InFmu
                } else if e.sensor() && self.outside.sensor_effects {
                    Coverage::OnOutputs
                } else if is_piston_force(*e) && self.outside.piston_force.is_some() {
                    Coverage::ForceInput
                } else {
                    Coverage::NotModelled
                };
                (e.name(), c)
            })
            .collect()
    }

    /// Every FMU parameter the map sets (supply parameter, nuisance,
    /// fixed, effect switches, parameters and laws), with where it is named.
    pub fn parameters(&self) -> Vec<(String, String)> {
        let mut out = Vec::new();
        if let Some(p) = &self.supply.parameter {
            out.push((p.clone(), "supply.parameter".into()));
        }
        for n in &self.nuisance {
            out.push((n.parameter.clone(), "nuisance".into()));
        }
        for p in self.fixed.keys() {
            out.push((p.clone(), "fixed".into()));
        }
        for (name, c) in &self.effects {
            if let Some(s) = &c.switch {
                out.push((s.clone(), format!("effects.{name}.switch")));
            }
            for (k, p) in &c.params {
                out.push((p.parameter.clone(), format!("effects.{name}.params.{k}")));
            }
            if let Some(l) = &c.law {
                out.push((l.parameter.clone(), format!("effects.{name}.law")));
            }
        }
        out
    }

    /// Every FMU output the map reads, with where it is named.
    pub fn outputs(&self) -> Vec<(String, String)> {
        let s = &self.signals;
        [
            ("p_rear", Some(&s.p_rear)),
            ("p_front", Some(&s.p_front)),
            ("accel", Some(&s.accel)),
            ("position", s.position.as_ref()),
            ("velocity", s.velocity.as_ref()),
            ("impact_counter", s.impact_counter.as_ref()),
        ]
        .into_iter()
        .filter_map(|(k, s)| s.map(|s| (s.output.clone(), format!("signals.{k}"))))
        .collect()
    }

    /// The FMU settings that put catalogue effect `name` at `values`
    /// (catalogue key → value in the catalogue's unit; keys not given keep
    /// their nominal) for a run at `supply_bar`: the switch on, each
    /// parameter scaled, a law evaluated at the supply pressure.
    pub fn effect_settings(
        &self,
        name: &str,
        values: &[(&str, f64)],
        supply_bar: f64,
    ) -> Result<Vec<(String, f64)>, String> {
        let c = self
            .effects
            .get(name)
            .ok_or_else(|| format!("effect {name} is not modelled by this FMU"))?;
        let e = entry(name).ok_or_else(|| format!("no catalogue effect {name}"))?;
        let mut out = Vec::new();
        if let Some(s) = &c.switch {
            out.push((s.clone(), 1.0));
        }
        for (key, p) in &c.params {
            let v = values.iter().find(|(k, _)| k == key).map_or(p.nominal, |(_, v)| *v);
            out.push((p.parameter.clone(), v * p.scale.unwrap_or(1.0)));
        }
        if let Some(law) = &c.law {
            let mut table = e.default_params();
            if let toml::Value::Table(t) = &mut table {
                for (k, v) in values {
                    t.insert(k.to_string(), toml::Value::Float(*v));
                }
            }
            let f = law_force_n(e, table, supply_bar)
                .ok_or_else(|| format!("effects.{name}.law: the values given do not make a force law"))?;
            out.push((law.parameter.clone(), f));
        }
        Ok(out)
    }

    /// The FMU settings that turn every mapped effect off.
    pub fn effects_off(&self) -> Vec<(String, f64)> {
        let mut out = Vec::new();
        for c in self.effects.values() {
            match &c.switch {
                Some(s) => out.push((s.clone(), 0.0)),
                None => {
                    out.extend(c.params.values().filter_map(|p| Some((p.parameter.clone(), p.off?))));
                    out.extend(c.law.iter().filter_map(|l| Some((l.parameter.clone(), l.off?))));
                }
            }
        }
        out
    }
}

/// The map's hash (SHA-256 of its text, hex): what `report.json` carries.
pub fn map_hash(text: &str) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(text.as_bytes())
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> String {
        let friction = REGISTRY
            .iter()
            .find(|e| law_force_n(**e, e.default_params(), 1.0).is_some())
            .unwrap();
        let p0 = friction.params()[0];
        format!(
            r#"
step_s = 1e-5
[signals]
p_rear = {{ output = "pr", unit = "bar", pressure = "absolute" }}
p_front = {{ output = "pf", unit = "kPa", pressure = "gauge", sign = -1 }}
accel = {{ output = "a", unit = "g" }}
velocity = {{ output = "v", unit = "m/s" }}
[supply]
input = "ps"
unit = "bar"
pressure = "absolute"
[[nuisance]]
parameter = "cd"
nominal = 0.7
relative_uncertainty = 0.2
[fixed]
mass = 0.2
[effects.{n}]
switch = "fric_on"
params.{k} = {{ parameter = "F0", unit = "{u}", lo = 0.0, hi = 10.0, nominal = 1.0 }}
law = {{ parameter = "Fc", unit = "N" }}
[outside]
piston_force = {{ input = "Fext", unit = "N" }}
"#,
            n = friction.name(),
            k = p0.key,
            u = p0.unit
        )
    }

    /// A map of every section reads; what it sets and reads is listed;
    /// its effects are covered as it says.
    #[test]
    fn a_full_map_reads_and_lists_what_it_sets() {
        let m = ModelMap::parse(&example()).unwrap();
        assert_eq!(m.signals.p_front.sign, -1.0);
        assert_eq!(m.supply.variable(), "ps");
        let params: Vec<String> = m.parameters().into_iter().map(|p| p.0).collect();
        assert_eq!(params, ["cd", "mass", "fric_on", "F0", "Fc"]);
        assert_eq!(m.outputs().len(), 4);
        let cov = m.coverage();
        assert_eq!(cov.len(), REGISTRY.len());
        for (name, c) in cov {
            let e = entry(name).unwrap();
            let expect = if m.effects.contains_key(name) {
                Coverage::InFmu
            } else if e.sensor() {
                Coverage::OnOutputs
            } else if is_piston_force(e) {
                Coverage::ForceInput
            } else {
                Coverage::NotModelled
            };
            assert_eq!(c, expect, "{name}");
        }
        // Round trip through the writer.
        assert_eq!(ModelMap::parse(&m.to_toml().unwrap()).unwrap(), m);
    }

    /// The law is the catalogue effect's force at the run's supply
    /// pressure: the coulomb law grows with supply pressure.
    #[test]
    fn a_law_is_evaluated_at_the_supply_pressure() {
        let m = ModelMap::parse(&example()).unwrap();
        let name = m.effects.keys().next().unwrap().clone();
        let e = entry(&name).unwrap();
        let keys: Vec<&str> = e.params().iter().map(|p| p.key).collect();
        let vals = [(keys[0], 3.0), (keys[1], 2.0)];
        let at = |bar: f64| {
            m.effect_settings(&name, &vals, bar)
                .unwrap()
                .into_iter()
                .find(|(p, _)| p == "Fc")
                .unwrap()
                .1
        };
        let mut t = e.default_params();
        if let toml::Value::Table(t) = &mut t {
            t.insert(keys[0].into(), 3.0.into());
            t.insert(keys[1].into(), 2.0.into());
        }
        assert_eq!(at(4.0), law_force_n(e, t.clone(), 4.0).unwrap());
        assert!(at(7.0) > at(4.0), "{} vs {}", at(7.0), at(4.0));
        assert_eq!(m.effects_off(), vec![("fric_on".to_string(), 0.0)]);
    }

    /// The map docs/your-model.md shows ("Writing the map") reads.
    #[test]
    fn the_documented_map_reads() {
        let doc = include_str!("../../../../docs/your-model.md");
        let from = doc.find("## Writing the map").unwrap();
        let block = &doc[from..];
        let start = block.find("```toml\n").unwrap() + 8;
        let end = start + block[start..].find("```").unwrap();
        let m = ModelMap::parse(&block[start..end]).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(m.signals.accel.sign, -1.0);
        assert_eq!(m.effects.len(), 2);
    }

    /// Each mistake is named where it is.
    #[test]
    fn bad_maps_are_named() {
        let good = example();
        let name = ModelMap::parse(&good).unwrap().effects.keys().next().unwrap().clone();
        for (from, to, says) in [
            (name.as_str(), "no_such_effect", "no such catalogue effect"),
            ("unit = \"g\"", "unit = \"furlong\"", "signals.accel"),
            ("sign = -1", "sign = 2", "sign"),
            (
                "relative_uncertainty = 0.2",
                "relative_uncertainty = 1.5",
                "nuisance cd",
            ),
            ("input = \"ps\"", "", "exactly one"),
            ("nominal = 1.0", "nominal = 11.0", "outside lo..hi"),
            ("mass = 0.2", "mass = 0.2\nbogus = \"x\"", "not a model map"),
            ("velocity = {", "speed = {", "not a model map"),
        ] {
            let bad = good.replacen(from, to, 1);
            let e = ModelMap::parse(&bad).unwrap_err();
            assert!(e.contains(says), "{from} -> {to}: {e}");
        }
        // Without a velocity a piston-force input cannot oppose the motion.
        let bad = good.replacen("velocity = { output = \"v\", unit = \"m/s\" }", "", 1);
        assert!(ModelMap::parse(&bad).unwrap_err().contains("velocity"));
    }
}
