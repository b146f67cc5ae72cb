//! The FMU's variables, one table for both sides: the shared library reads
//! and writes values through it, `hammer fmu` writes modelDescription.xml
//! from it. Built from a [`SimConfig`] serialised to JSON, so a field added
//! to the configuration becomes a parameter without a list to keep: every
//! numeric leaf is a parameter named by its dotted path
//! (`hammer.piston_mass_kg`), every catalogue effect gets an on/off switch
//! (`effects.NAME.on`) and its parameters (`effects.NAME.KEY`), whatever
//! the base configuration has on. Value references are positions in the
//! table.

use hammer_sim::effects::REGISTRY;
use hammer_sim::SimConfig;
use serde_json::{Map, Value};

/// FMI 2.0 base types the table uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Real,
    Integer,
    Boolean,
}

/// A value of one variable.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Val {
    Real(f64),
    Integer(i32),
    Boolean(bool),
}

/// What a variable is bound to.
#[derive(Debug, Clone, PartialEq)]
pub enum Binding {
    /// A leaf of the configuration, by its JSON path.
    Config(Vec<String>),
    /// Effect number `.0` of the registry on or off.
    Switch(usize),
    /// Parameter `.1` of effect `.0`.
    EffectParam(usize, String),
    /// An output, by its place in [`OUTPUTS`].
    Output(usize),
    /// A law of the configuration's that has two forms (a string leaf at
    /// the path): the form `.2` when true, `.1` when false.
    Choice(Vec<String>, String, String),
}

#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    pub name: String,
    pub kind: Kind,
    pub unit: Option<String>,
    pub description: String,
    pub binding: Binding,
    /// The start value (parameters) or the value before the run (outputs).
    pub start: Val,
}

impl Variable {
    pub fn is_output(&self) -> bool {
        matches!(self.binding, Binding::Output(_))
    }
}

/// One output: name (the trace's column name where the trace has one),
/// kind, unit, description.
#[derive(Debug, Clone, Copy)]
pub struct Output {
    pub name: &'static str,
    pub kind: Kind,
    pub unit: Option<&'static str>,
    pub description: &'static str,
}

const fn out(name: &'static str, unit: &'static str, description: &'static str) -> Output {
    Output {
        name,
        kind: Kind::Real,
        unit: Some(unit),
        description,
    }
}

/// An output by its place in [`outputs`]: what a run is asked for at
/// every communication point, so by a number, not by its name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Out {
    PRearTrue,
    PFrontTrue,
    AccelTrue,
    PRear,
    PFront,
    Accel,
    X,
    V,
    Valve,
    RearMass,
    RearTemperature,
    FrontMass,
    FrontTemperature,
    ImpactCount,
    LastImpactVelocity,
    LastPeriod,
}

impl Out {
    /// In [`outputs`]' order.
    pub const ALL: [Out; 16] = [
        Out::PRearTrue,
        Out::PFrontTrue,
        Out::AccelTrue,
        Out::PRear,
        Out::PFront,
        Out::Accel,
        Out::X,
        Out::V,
        Out::Valve,
        Out::RearMass,
        Out::RearTemperature,
        Out::FrontMass,
        Out::FrontTemperature,
        Out::ImpactCount,
        Out::LastImpactVelocity,
        Out::LastPeriod,
    ];
}

/// The built-in model's outputs, in value-reference order after the parameters.
pub const OUTPUTS: [Output; 16] = outputs(out("valve_m", "m", "valve spool position (0 feeds the front)"));

/// Both families' outputs: they differ in the valve's (the second family's
/// spool position is a fraction of its travel).
pub const fn outputs(valve: Output) -> [Output; 16] {
    [
        out("p_rear_true_pa", "Pa", "rear chamber pressure, gauge, noiseless"),
        out("p_front_true_pa", "Pa", "front chamber pressure, gauge, noiseless"),
        out("accel_true_mps2", "m/s2", "piston acceleration, noiseless"),
        out(
            "p_rear_pa",
            "Pa",
            "rear chamber pressure, gauge, through the sensor chain (seeded)",
        ),
        out(
            "p_front_pa",
            "Pa",
            "front chamber pressure, gauge, through the sensor chain (seeded)",
        ),
        out(
            "accel_mps2",
            "m/s2",
            "piston acceleration through the sensor chain (seeded)",
        ),
        out("x_m", "m", "piston position"),
        out("v_mps", "m/s", "piston velocity (forward +)"),
        valve,
        out("rear_mass_kg", "kg", "air mass in the rear chamber"),
        out("rear_temperature_k", "K", "air temperature in the rear chamber"),
        out("front_mass_kg", "kg", "air mass in the front chamber"),
        out("front_temperature_k", "K", "air temperature in the front chamber"),
        Output {
            name: "impact_count",
            kind: Kind::Integer,
            unit: None,
            description: "impacts so far",
        },
        out(
            "last_impact_velocity_mps",
            "m/s",
            "piston velocity at the last impact (0 before the first)",
        ),
        out(
            "last_period_s",
            "s",
            "time between the last two impacts (0 before the second)",
        ),
    ]
}

/// Configuration subtrees that are not parameters: the estimator's reading
/// (it does not change the model's outputs), the import map (not a model
/// value), the effects (taken from the registry) and the run's duration
/// (the experiment's stop time sets it).
const NOT_PARAMETERS: [&str; 4] = ["estimator", "import", "effects", "solver.duration_s"];

/// A family's configuration as the table sees it.
pub struct Family<'a> {
    /// The configuration serialised.
    pub json: Value,
    /// Subtrees (dotted) that are not parameters.
    pub skip: &'a [&'a str],
    pub outputs: &'static [Output],
    /// Laws with two forms, each a Boolean parameter (the family's
    /// structure: set per run, as a benchmark's drawn structure is).
    pub choices: Vec<Choice>,
}

/// A Boolean parameter `name` that puts `off` or `on` at the
/// configuration's string leaf `path`.
#[derive(Debug, Clone, PartialEq)]
pub struct Choice {
    pub name: String,
    pub path: Vec<String>,
    pub off: String,
    pub on: String,
    pub description: String,
}

/// The unit a configuration key's suffix names (`docs`: units in names).
pub fn unit_of_key(path: &[String]) -> Option<&'static str> {
    let key = path.last()?.as_str();
    if path.first().is_some_and(|p| p == "sensors") && path.len() == 3 {
        // A channel's values are in the channel's unit.
        let channel_unit = if path[1] == "accel" { "m/s2" } else { "Pa" };
        return match key {
            "range_min" | "range_max" | "noise_std" | "offset" => Some(channel_unit),
            "bandwidth_hz" => Some("Hz"),
            _ => None,
        };
    }
    const SUFFIXES: [(&str, &str); 17] = [
        ("_n_s_per_m", "N.s/m"),
        ("_n_per_m", "N/m"),
        ("_mps2", "m/s2"),
        ("_mps", "m/s"),
        ("_m3", "m3"),
        ("_m2", "m2"),
        ("_kg", "kg"),
        ("_pa", "Pa"),
        ("_bar", "bar"),
        ("_deg", "deg"),
        ("_hz", "Hz"),
        ("_k", "K"),
        ("_s", "s"),
        ("_n", "N"),
        ("_m", "m"),
        ("_j", "J"),
        ("_w", "W"),
    ];
    SUFFIXES.iter().find(|(s, _)| key.ends_with(s)).map(|(_, u)| *u)
}

/// The table of a base configuration (its values are the start values).
#[derive(Debug, Clone)]
pub struct Table {
    pub vars: Vec<Variable>,
    /// The base configuration as JSON: what values are written into.
    base: Value,
    pub outputs: &'static [Output],
}

impl Table {
    /// The built-in model's table.
    pub fn new(base: &SimConfig) -> Result<Self, String> {
        let json = serde_json::to_value(base).map_err(|e| e.to_string())?;
        Self::of(Family {
            choices: Vec::new(),
            json,
            skip: &NOT_PARAMETERS,
            outputs: &OUTPUTS,
        })
    }

    /// The table of any family whose configuration holds `effects` as the
    /// simulator's does.
    pub fn of(family: Family) -> Result<Self, String> {
        let json = family.json;
        let effects: hammer_sim::Effects = match json.get("effects") {
            Some(e) => serde_json::from_value(e.clone()).map_err(|e| e.to_string())?,
            None => Default::default(),
        };
        let mut vars = Vec::new();
        leaves(&json, &mut Vec::new(), family.skip, &mut vars);
        for c in family.choices {
            let mut at = &json;
            for key in &c.path {
                at = &at[key.as_str()];
            }
            let on = match at.as_str() {
                Some(v) if v == c.on => true,
                Some(v) if v == c.off => false,
                _ => return Err(format!("{}: neither {} nor {}", c.path.join("."), c.off, c.on)),
            };
            vars.push(Variable {
                name: c.name,
                kind: Kind::Boolean,
                unit: None,
                description: c.description,
                binding: Binding::Choice(c.path, c.off, c.on),
                start: Val::Boolean(on),
            });
        }
        for (k, e) in REGISTRY.iter().enumerate() {
            let on = e.is_on(&effects);
            vars.push(Variable {
                name: format!("effects.{}.on", e.name()),
                kind: Kind::Boolean,
                unit: None,
                description: format!("effect {} on (its parameters below act only when on)", e.name()),
                binding: Binding::Switch(k),
                start: Val::Boolean(on),
            });
            let current = json.get("effects").and_then(|x| x.get(e.name())).cloned();
            let params = match current {
                Some(v) => v,
                None => serde_json::to_value(e.default_params()).map_err(|e| e.to_string())?,
            };
            for p in e.params() {
                let v = params.get(p.key).and_then(Value::as_f64).unwrap_or(f64::NAN);
                vars.push(Variable {
                    name: format!("effects.{}.{}", e.name(), p.key),
                    kind: Kind::Real,
                    unit: (p.unit != "1").then(|| p.unit.to_string()),
                    description: format!("range {} ..= {}", p.lo, p.hi),
                    binding: Binding::EffectParam(k, p.key.to_string()),
                    start: Val::Real(v),
                });
            }
        }
        for (i, o) in family.outputs.iter().enumerate() {
            vars.push(Variable {
                name: o.name.to_string(),
                kind: o.kind,
                unit: o.unit.map(str::to_string),
                description: o.description.to_string(),
                binding: Binding::Output(i),
                start: match o.kind {
                    Kind::Integer => Val::Integer(0),
                    _ => Val::Real(0.0),
                },
            });
        }
        Ok(Self {
            vars,
            base: json,
            outputs: family.outputs,
        })
    }

    /// The start values, by value reference.
    pub fn starts(&self) -> Vec<Val> {
        self.vars.iter().map(|v| v.start).collect()
    }

    /// The built-in model's configuration `values` give (by value
    /// reference), validated: an error says which value was refused, in
    /// the configuration's terms.
    pub fn config(&self, values: &[Val]) -> Result<SimConfig, String> {
        let cfg: SimConfig = serde_json::from_value(self.json(values)?).map_err(|e| format!("refused: {e}"))?;
        cfg.validate().map_err(|e| e.to_string())?;
        Ok(cfg)
    }

    /// The configuration `values` give, as JSON (for the family to read).
    pub fn json(&self, values: &[Val]) -> Result<Value, String> {
        let mut json = self.base.clone();
        let mut effects = Map::new();
        for (v, val) in self.vars.iter().zip(values) {
            let leaf = match *val {
                Val::Real(x) => match serde_json::Number::from_f64(x) {
                    Some(n) => Value::Number(n),
                    None => return Err(format!("{} = {x} is not a finite number", v.name)),
                },
                Val::Integer(i) => Value::from(i),
                Val::Boolean(b) => Value::Bool(b),
            };
            match &v.binding {
                Binding::Config(path) => {
                    let mut at = &mut json;
                    for key in path {
                        at = &mut at[key.as_str()];
                    }
                    *at = leaf;
                }
                Binding::Choice(path, off, on) => {
                    let mut at = &mut json;
                    for key in path {
                        at = &mut at[key.as_str()];
                    }
                    *at = Value::String(if leaf == Value::Bool(true) { on } else { off }.clone());
                }
                Binding::Switch(k) if leaf == Value::Bool(true) => {
                    effects.insert(REGISTRY[*k].name().to_string(), Value::Object(Map::new()));
                }
                Binding::EffectParam(k, key) => {
                    if let Some(Value::Object(m)) = effects.get_mut(REGISTRY[*k].name()) {
                        m.insert(key.clone(), leaf);
                    }
                }
                _ => {}
            }
        }
        json["effects"] = Value::Object(effects);
        Ok(json)
    }
}

/// Every numeric or Boolean leaf of `v` under `path`, as a parameter.
fn leaves(v: &Value, path: &mut Vec<String>, skip: &[&str], out: &mut Vec<Variable>) {
    let dotted = path.join(".");
    if skip.contains(&dotted.as_str()) || dotted == "effects" {
        return;
    }
    let (kind, start) = match v {
        Value::Object(m) => {
            for (k, x) in m {
                path.push(k.clone());
                leaves(x, path, skip, out);
                path.pop();
            }
            return;
        }
        Value::Number(n) if n.is_f64() => (Kind::Real, Val::Real(n.as_f64().unwrap_or(f64::NAN))),
        Value::Number(n) => match n.as_i64().and_then(|i| i32::try_from(i).ok()) {
            Some(i) => (Kind::Integer, Val::Integer(i)),
            // An integer past FMI's 32 bits (a seed) keeps its base value.
            None => return,
        },
        Value::Bool(b) => (Kind::Boolean, Val::Boolean(*b)),
        // Strings (the contact law) and arrays are not FMI 2.0 parameters here.
        _ => return,
    };
    out.push(Variable {
        name: dotted,
        kind,
        unit: if kind == Kind::Real {
            unit_of_key(path).map(str::to_string)
        } else {
            None
        },
        description: String::new(),
        binding: Binding::Config(path.clone()),
        start,
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each output's number names the output of that name, in both families.
    #[test]
    fn each_output_is_its_number() {
        let by_name = |name: &str| match name {
            "p_rear_true_pa" => Out::PRearTrue,
            "p_front_true_pa" => Out::PFrontTrue,
            "accel_true_mps2" => Out::AccelTrue,
            "p_rear_pa" => Out::PRear,
            "p_front_pa" => Out::PFront,
            "accel_mps2" => Out::Accel,
            "x_m" => Out::X,
            "v_mps" => Out::V,
            "valve_m" | "spool" => Out::Valve,
            "rear_mass_kg" => Out::RearMass,
            "rear_temperature_k" => Out::RearTemperature,
            "front_mass_kg" => Out::FrontMass,
            "front_temperature_k" => Out::FrontTemperature,
            "impact_count" => Out::ImpactCount,
            "last_impact_velocity_mps" => Out::LastImpactVelocity,
            "last_period_s" => Out::LastPeriod,
            other => panic!("an output without a number: {other}"),
        };
        for family in [&OUTPUTS, &crate::variants::VARIANT_OUTPUTS] {
            for (k, o) in family.iter().enumerate() {
                assert_eq!(Out::ALL[k], by_name(o.name), "{}", o.name);
            }
        }
    }

    /// The default configuration's table gives back the default
    /// configuration; a refused value is named.
    #[test]
    fn the_table_round_trips_and_names_refusals() {
        let mut base = SimConfig::default();
        base.effects.apply_spec("leakage").unwrap();
        let t = Table::new(&base).unwrap();
        assert_eq!(t.config(&t.starts()).unwrap(), base);
        let names: Vec<&str> = t.vars.iter().map(|v| v.name.as_str()).collect();
        for n in [
            "hammer.piston_mass_kg",
            "supply.pressure_bar",
            "seed",
            "effects.coulomb_friction.on",
            "effects.coulomb_friction.f0_n",
            "sensors.enabled",
            "p_rear_pa",
        ] {
            assert!(names.contains(&n), "{n}");
        }
        assert!(!names.contains(&"solver.duration_s"));
        let vr = |n: &str| names.iter().position(|x| *x == n).unwrap();
        assert_eq!(t.vars[vr("hammer.piston_mass_kg")].unit.as_deref(), Some("kg"));
        assert_eq!(t.vars[vr("valve.damping_n_s_per_m")].unit.as_deref(), Some("N.s/m"));
        let mut vals = t.starts();
        vals[vr("effects.coulomb_friction.on")] = Val::Boolean(true);
        vals[vr("effects.coulomb_friction.f0_n")] = Val::Real(3.0);
        vals[vr("effects.leakage.on")] = Val::Boolean(false);
        let cfg = t.config(&vals).unwrap();
        assert_eq!(cfg.effects.active(), vec!["coulomb_friction"]);
        assert_eq!(cfg.effects.coulomb_friction.unwrap().f0_n, 3.0);
        vals[vr("supply.pressure_bar")] = Val::Real(99.0);
        let e = t.config(&vals).unwrap_err();
        assert!(e.contains("supply.pressure_bar"), "{e}");
        vals[vr("supply.pressure_bar")] = Val::Real(4.0);
        vals[vr("hammer.outlet_count")] = Val::Integer(-1);
        assert!(t.config(&vals).is_err());
    }
}
