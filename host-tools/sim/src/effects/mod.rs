//! The catalogue of effects the nominal model leaves out.
//!
//! Every effect is off by default. The names are the project's vocabulary:
//! the CLI, config files, sidecars and the diagnosis all use them verbatim.
//!
//! One file per effect (its parameter struct, default, parameter ranges and
//! units, an [`Effect`] impl); the [`catalogue!`] list below is the one
//! registry: it declares the [`Effects`] field (and so the config/JSON key),
//! [`EFFECT_NAMES`] and [`REGISTRY`], in catalogue order.

use std::marker::PhantomData;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::config::{check_range, ConfigError};

/// One parameter of an effect: its key (as in configs and specs), unit and valid range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Param {
    pub key: &'static str,
    pub unit: &'static str,
    pub lo: f64,
    pub hi: f64,
}

impl Param {
    pub const fn new(key: &'static str, unit: &'static str, lo: f64, hi: f64) -> Self {
        Self { key, unit, lo, hi }
    }
}

/// Where an effect lives in [`Effects`]; implemented by [`catalogue!`].
pub trait EffectSlot: Sized {
    /// The effect's name: its field in [`Effects`] and its config table.
    const NAME: &'static str;
    fn get(effects: &Effects) -> Option<&Self>;
    fn slot(effects: &mut Effects) -> &mut Option<Self>;
}

/// A catalogued effect: its parameters (every field of the struct, all f64,
/// in field order) and whether it acts on the sensors rather than the physics.
pub trait Effect:
    EffectSlot + Default + Clone + PartialEq + Serialize + DeserializeOwned + Send + Sync + 'static
{
    const PARAMS: &'static [Param];
    /// Acts on the sensor output, not on the simulated solution.
    const SENSOR: bool = false;
    /// Has a [`Effect::piston_drag_n`] force.
    const PISTON_DRAG: bool = false;

    /// The simulator hook of an effect that is a force on the piston against
    /// its motion (negative opposes forward motion; it counts as friction in
    /// the truth and the friction work), at time `t_s`, velocity `v_mps` and
    /// supply pressure `supply_bar`. Every plant adds the active ones, so an
    /// effect of this kind needs no edit of the simulator. The effects older
    /// than the hook are wired into the plants by hand (their forms are
    /// plant-specific: smoothing, port geometry).
    fn piston_drag_n(&self, _t_s: f64, _v_mps: f64, _supply_bar: f64) -> f64 {
        0.0
    }

    /// The force of a friction law that depends on the supply pressure
    /// alone, N, at `supply_bar`: what a foreign model that takes friction
    /// as one force parameter is given per run (`hammer_fmu::import::map`'s
    /// `law`). None for an effect without such a law.
    fn supply_law_n(&self, _supply_bar: f64) -> Option<f64> {
        None
    }

    /// Checks every parameter against its range; errors name `effects.NAME.key`.
    fn validate(&self) -> Result<(), ConfigError> {
        let table = toml::Value::try_from(self).ok();
        for p in Self::PARAMS {
            let v = table
                .as_ref()
                .and_then(|t| t.get(p.key))
                .and_then(|v| v.as_float())
                .unwrap_or(f64::NAN);
            check_range(&format!("effects.{}.{}", Self::NAME, p.key), v, p.lo, p.hi)?;
        }
        Ok(())
    }
}

/// A registry entry: an [`Effect`] seen without its type.
pub trait EffectEntry: Sync {
    fn name(&self) -> &'static str;
    fn params(&self) -> &'static [Param];
    fn sensor(&self) -> bool;
    fn is_on(&self, effects: &Effects) -> bool;
    fn turn_off(&self, effects: &mut Effects);
    /// Switches the effect on with `table`'s keys (the others keep their defaults).
    fn set(&self, effects: &mut Effects, table: toml::Value) -> Result<(), toml::de::Error>;
    fn validate(&self, effects: &Effects) -> Result<(), ConfigError>;
    /// The default parameters, as in a config file.
    fn default_params(&self) -> toml::Value;
    fn has_piston_drag(&self) -> bool;
    /// [`Effect::piston_drag_n`] if the effect is on, else 0.
    fn piston_drag_n(&self, effects: &Effects, t_s: f64, v_mps: f64, supply_bar: f64) -> f64;
    /// [`Effect::supply_law_n`] with `params` (as in a config file); None
    /// when the effect has no such law or the parameters do not read.
    fn supply_law_n(&self, params: toml::Value, supply_bar: f64) -> Option<f64>;
}

struct Entry<T>(PhantomData<fn() -> T>);

impl<T: Effect> EffectEntry for Entry<T> {
    fn name(&self) -> &'static str {
        T::NAME
    }
    fn params(&self) -> &'static [Param] {
        T::PARAMS
    }
    fn sensor(&self) -> bool {
        T::SENSOR
    }
    fn is_on(&self, effects: &Effects) -> bool {
        T::get(effects).is_some()
    }
    fn turn_off(&self, effects: &mut Effects) {
        *T::slot(effects) = None;
    }
    fn set(&self, effects: &mut Effects, table: toml::Value) -> Result<(), toml::de::Error> {
        *T::slot(effects) = Some(table.try_into()?);
        Ok(())
    }
    fn validate(&self, effects: &Effects) -> Result<(), ConfigError> {
        T::get(effects).map_or(Ok(()), |e| e.validate())
    }
    fn default_params(&self) -> toml::Value {
        toml::Value::try_from(T::default()).unwrap_or(toml::Value::Table(Default::default()))
    }
    fn has_piston_drag(&self) -> bool {
        T::PISTON_DRAG
    }
    fn piston_drag_n(&self, effects: &Effects, t_s: f64, v_mps: f64, supply_bar: f64) -> f64 {
        T::get(effects).map_or(0.0, |e| e.piston_drag_n(t_s, v_mps, supply_bar))
    }
    fn supply_law_n(&self, params: toml::Value, supply_bar: f64) -> Option<f64> {
        params.try_into::<T>().ok()?.supply_law_n(supply_bar)
    }
}

/// Declares the catalogue: `name: Type` per effect, in catalogue order (the
/// order fixes the benchmark's case plan). The module `name.rs` holds `Type`.
macro_rules! catalogue {
    ($d:tt $($name:ident: $ty:ident),* $(,)?) => {
        $(
            mod $name;
            pub use $name::$ty;

            impl EffectSlot for $ty {
                const NAME: &'static str = stringify!($name);
                fn get(effects: &Effects) -> Option<&Self> {
                    effects.$name.as_ref()
                }
                fn slot(effects: &mut Effects) -> &mut Option<Self> {
                    &mut effects.$name
                }
            }
        )*

        /// Number of catalogued effects.
        pub const N_EFFECTS: usize = [$(stringify!($name)),*].len();

        /// Names of every effect, in catalogue order.
        pub const EFFECT_NAMES: [&str; N_EFFECTS] = [$(stringify!($name)),*];

        /// Every effect, in catalogue order.
        pub static REGISTRY: [&dyn EffectEntry; N_EFFECTS] = [$(&Entry::<$ty>(PhantomData)),*];

        /// Calls the macro `m` with the catalogue, `m! { name: path::to::Type, ... }`
        /// in catalogue order: a crate above the simulator (the diagnosis)
        /// declares one item per effect without repeating the list.
        #[macro_export]
        macro_rules! with_catalogue {
            ($d m:ident) => {
                $d m! { $($name: $crate::effects::$ty),* }
            };
        }

        /// The active effects: `None` is off.
        #[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
        #[serde(deny_unknown_fields, default)]
        pub struct Effects {
            $(
                #[serde(skip_serializing_if = "Option::is_none")]
                pub $name: Option<$ty>,
            )*
        }
    };
}

// The leading `$` is passed through to `with_catalogue!`, a macro the list defines.
catalogue! {
    $
    coulomb_friction: CoulombFriction,
    viscous_friction: ViscousFriction,
    leakage: Leakage,
    valve_delay: ValveDelay,
    heat_transfer: HeatTransfer,
    supply_restriction: SupplyRestriction,
    accel_zero_shift: AccelZeroShift,
    pressure_gain_error: PressureGainError,
}

/// The piston-drag forces of the active effects ([`Effect::piston_drag_n`]);
/// empty (and free) when none is on.
#[derive(Clone)]
pub struct PistonDrags {
    on: Vec<&'static dyn EffectEntry>,
    effects: Effects,
}

impl PistonDrags {
    /// Their sum, N (negative opposes forward motion).
    pub fn force_n(&self, t_s: f64, v_mps: f64, supply_bar: f64) -> f64 {
        self.on
            .iter()
            .map(|e| e.piston_drag_n(&self.effects, t_s, v_mps, supply_bar))
            .sum()
    }

    pub fn is_empty(&self) -> bool {
        self.on.is_empty()
    }
}

impl std::fmt::Debug for PistonDrags {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.on.iter().map(|e| e.name())).finish()
    }
}

/// The registry entry of effect `name`.
pub fn entry(name: &str) -> Option<&'static dyn EffectEntry> {
    REGISTRY.iter().copied().find(|e| e.name() == name)
}

impl Effects {
    /// Names of the effects that are on.
    pub fn active(&self) -> Vec<&'static str> {
        REGISTRY.iter().filter(|e| e.is_on(self)).map(|e| e.name()).collect()
    }

    /// Switches an effect on from a CLI spec `name` or `name:key=value,key=value`.
    /// Unspecified keys keep their defaults.
    pub fn apply_spec(&mut self, spec: &str) -> Result<(), ConfigError> {
        let (name, args) = match spec.split_once(':') {
            Some((n, a)) => (n.trim(), a.trim()),
            None => (spec.trim(), ""),
        };
        let mut table = toml::Table::new();
        for pair in args.split(',').filter(|p| !p.trim().is_empty()) {
            let (k, v) = pair.split_once('=').ok_or_else(|| ConfigError::Invalid {
                field: format!("effects.{name}"),
                message: format!("expected key=value, got `{pair}`"),
            })?;
            let value: f64 = v.trim().parse().map_err(|_| ConfigError::Invalid {
                field: format!("effects.{name}.{}", k.trim()),
                message: format!("`{}` is not a number", v.trim()),
            })?;
            table.insert(k.trim().to_string(), toml::Value::Float(value));
        }
        let Some(effect) = entry(name) else {
            return Err(ConfigError::Invalid {
                field: "effect".into(),
                message: format!("unknown effect `{name}`; known: {}", EFFECT_NAMES.join(", ")),
            });
        };
        effect
            .set(self, toml::Value::Table(table))
            .map_err(|e| ConfigError::Invalid {
                field: format!("effects.{name}"),
                message: e.message().to_string(),
            })?;
        self.validate()
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        REGISTRY.iter().try_for_each(|e| e.validate(self))
    }

    /// The active effects with a piston-drag hook, for a plant to add up.
    pub fn piston_drags(&self) -> PistonDrags {
        PistonDrags {
            on: REGISTRY
                .iter()
                .copied()
                .filter(|e| e.has_piston_drag() && e.is_on(self))
                .collect(),
            effects: self.clone(),
        }
    }

    /// The effects that act on the simulated solution (sensor effects removed).
    pub fn physics(&self) -> Effects {
        let mut e = self.clone();
        REGISTRY.iter().filter(|x| x.sensor()).for_each(|x| x.turn_off(&mut e));
        e
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_switch_effects_on_and_name_bad_fields() {
        let mut e = Effects::default();
        e.apply_spec("coulomb_friction:f0_n=1.7,k_n_per_bar=2.14").unwrap();
        assert_eq!(e.coulomb_friction.as_ref().unwrap().f0_n, 1.7);
        e.apply_spec("leakage").unwrap();
        assert_eq!(e.active(), vec!["coulomb_friction", "leakage"]);
        let err = e.apply_spec("leakage:gapp_m=1e-5").unwrap_err().to_string();
        assert!(err.contains("gapp_m"), "{err}");
        let err = e.apply_spec("valve_delay:tau_s=-1").unwrap_err().to_string();
        assert!(err.contains("effects.valve_delay.tau_s"), "{err}");
        let err = e.apply_spec("magic").unwrap_err().to_string();
        assert!(err.contains("unknown effect") && err.contains("heat_transfer"), "{err}");
        let err = e.apply_spec("leakage:gap_m=abc").unwrap_err().to_string();
        assert!(err.contains("effects.leakage.gap_m"), "{err}");
    }

    /// Every field of an effect's struct is a listed parameter, in field order,
    /// and its default is valid.
    #[test]
    fn params_cover_every_field_and_defaults_are_valid() {
        for e in REGISTRY {
            let d = e.default_params();
            let keys: Vec<&str> = d.as_table().unwrap().keys().map(|k| k.as_str()).collect();
            let mut params: Vec<&str> = e.params().iter().map(|p| p.key).collect();
            let mut sorted = keys.clone();
            sorted.sort();
            params.sort();
            assert_eq!(sorted, params, "{}", e.name());
            let mut on = Effects::default();
            on.apply_spec(e.name()).unwrap();
            assert_eq!(on.active(), vec![e.name()]);
            for p in e.params() {
                let v = d.get(p.key).and_then(|v| v.as_float()).unwrap();
                assert!(v >= p.lo && v <= p.hi, "{}.{} = {v}", e.name(), p.key);
                assert!(!p.unit.is_empty());
            }
        }
    }

    /// The serialized form is the catalogue: one key per active effect, named as the effect.
    #[test]
    fn serialized_keys_are_the_effect_names() {
        let mut all = Effects::default();
        for name in EFFECT_NAMES {
            all.apply_spec(name).unwrap();
        }
        let v = serde_json::to_value(&all).unwrap();
        let keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        let mut names = EFFECT_NAMES.to_vec();
        names.sort();
        let mut keys = keys;
        keys.sort();
        assert_eq!(keys, names);
        let back: Effects = serde_json::from_value(v).unwrap();
        assert_eq!(back, all);
        assert_eq!(
            all.physics().active().len(),
            REGISTRY.iter().filter(|e| !e.sensor()).count()
        );
    }
}

/// docs/model.md's effect table lists the registry: every effect in order,
/// every parameter with its default.
#[cfg(test)]
mod docs_table {
    use super::*;

    #[test]
    fn model_md_lists_the_registry() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/model.md");
        let md = std::fs::read_to_string(path).unwrap();
        let section = md
            .split("## Effect catalogue")
            .nth(1)
            .expect("an effect catalogue section");
        let section = section.split("\n## ").next().unwrap();
        let rows: Vec<Vec<&str>> = section
            .lines()
            .filter(|l| l.starts_with("| `"))
            .map(|l| l.split('|').map(str::trim).collect())
            .collect();
        let names: Vec<&str> = rows.iter().map(|r| r[1].trim_matches('`')).collect();
        assert_eq!(names, EFFECT_NAMES, "docs/model.md's effect table vs the registry");
        for (row, e) in rows.iter().zip(REGISTRY) {
            let defaults = e.default_params();
            let listed: Vec<(&str, f64)> = row[2]
                .split(", ")
                .map(|kv| {
                    let (k, v) = kv
                        .split_once(" = ")
                        .unwrap_or_else(|| panic!("`key` = value, got {kv}"));
                    (k.trim_matches('`'), v.trim().parse().unwrap_or_else(|_| panic!("{kv}")))
                })
                .collect();
            let keys: Vec<&str> = listed.iter().map(|(k, _)| *k).collect();
            let params: Vec<&str> = e.params().iter().map(|p| p.key).collect();
            assert_eq!(keys, params, "docs/model.md, {}", e.name());
            for (k, v) in listed {
                let d = defaults.get(k).and_then(|x| x.as_float()).unwrap();
                assert!(
                    (v - d).abs() <= 1e-4 * d.abs().max(1e-9),
                    "docs/model.md, {}.{k}: {v} vs {d}",
                    e.name()
                );
            }
        }
    }
}
