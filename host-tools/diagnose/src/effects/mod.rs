//! The diagnosis behaviour of each catalogued effect, one file per effect:
//! the free parameters the fit moves and how they set the catalogue's
//! parameters, start values, the evidence sentence, and the benchmark's
//! random draw and magnitude error.
//!
//! [`DIAGNOSIS`] lists them in the simulator's catalogue order
//! ([`hammer_sim::effects::REGISTRY`]), generated from the same list
//! (`hammer_sim::with_catalogue!`): an effect without a diagnosis file does not
//! compile. Nothing else in the diagnosis names an effect.

use std::marker::PhantomData;

use super::features::Extractor;
use super::fit::ParamSpec;
use super::fitset::FitSet;
use super::model::{Builtin, ModelRunner, Plant, SensorReads};
use hammer_sim::effects::{Effect, Effects, N_EFFECTS};
use hammer_sim::params::HammerParams;
use hammer_sim::sensor::Rng;
use hammer_sim::SimConfig;
use std::sync::Arc;

/// One module per effect (`NAME.rs`, an `impl Diagnosed`), and [`DIAGNOSIS`],
/// from the simulator's catalogue list.
macro_rules! diagnosis_catalogue {
    ($($name:ident: $ty:path),* $(,)?) => {
        $(mod $name;)*

        /// Every effect's diagnosis, in catalogue order.
        pub(super) static DIAGNOSIS: [&dyn DiagnosisEntry; N_EFFECTS] = [$(&Entry::<$ty>(PhantomData)),*];
    };
}

hammer_sim::with_catalogue!(diagnosis_catalogue);

/// The free parameters the diagnosis fits for an effect (see
/// [`super::effects`]); none for an unknown name.
pub fn free_params(name: &str, distinct_pressures: usize) -> Vec<ParamSpec> {
    diagnosis(name).map_or_else(Vec::new, |d| d.free_params(distinct_pressures))
}

/// Writes fitted values `theta` of `name` into `effects`. `pressures` are the
/// lowest and highest supply pressures of the fit set, bar.
pub fn apply(effects: &mut Effects, name: &str, theta: &[f64], pressures: (f64, f64)) {
    if let Some(d) = diagnosis(name) {
        d.apply(effects, theta, pressures);
    }
}

/// The catalogue parameters of an effect as they would go in a config file.
pub fn catalogue_params(effects: &Effects, name: &str) -> serde_json::Value {
    let v = serde_json::to_value(effects).unwrap_or_default();
    v.get(name).cloned().unwrap_or(serde_json::Value::Null)
}

/// The catalogue's sensor effects, as the model reads through them.
#[derive(Debug)]
struct CatalogueReads;

impl SensorReads for CatalogueReads {
    fn pressure_reading_factors(&self, effects: &Effects) -> (f64, f64) {
        pressure_reading_factors(effects)
    }
    fn shift_expected_features(&self, effects: &Effects, mean: &mut [f64]) {
        shift_expected_features(effects, mean)
    }
}

impl ModelRunner {
    /// The built-in model of `base`, read by `extractor` through the
    /// catalogue's sensor effects.
    pub fn new(base: SimConfig, extractor: Extractor) -> Self {
        let hammer = base.hammer.clone();
        Self::with_plant(Arc::new(Builtin::new(base)), hammer, extractor)
    }

    /// `plant` at its nominal values, for a hammer of geometry `hammer`,
    /// read by `extractor` through the catalogue's sensor effects.
    pub fn with_plant(plant: Arc<dyn Plant>, hammer: HammerParams, extractor: Extractor) -> Self {
        Self {
            nuisance: plant.nuisance().iter().map(|p| p.nominal).collect(),
            plant,
            hammer,
            extractor,
            reads: &CatalogueReads,
            duration_s: 0.45,
            settle_s: crate::model::SETTLE_S,
        }
    }
}

/// The diagnosis of effect `name`.
pub(super) fn diagnosis(name: &str) -> Option<&'static dyn DiagnosisEntry> {
    DIAGNOSIS.iter().copied().find(|d| d.name() == name)
}

/// Every effect's force-balance reading at one point ([`Diagnosed::force_balance_reading`]),
/// keyed `effect.quantity`, in catalogue order.
pub(crate) fn force_balance_readings(change: &dyn Fn(usize) -> (f64, f64)) -> Vec<(String, f64, f64)> {
    DIAGNOSIS
        .iter()
        .flat_map(|d| {
            d.force_balance_reading(change)
                .into_iter()
                .map(|(k, v, u)| (format!("{}.{k}", d.name()), v, u))
        })
        .collect()
}

/// The factors the sensor effects put on the rear and front pressure
/// readings (1 without one).
pub(crate) fn pressure_reading_factors(effects: &Effects) -> (f64, f64) {
    DIAGNOSIS.iter().fold((1.0, 1.0), |(a, b), d| {
        let (x, y) = d.pressure_reading_factors(effects);
        (a * x, b * y)
    })
}

/// Adds the sensor effects' expected contributions to a model's mean features.
pub(crate) fn shift_expected_features(effects: &Effects, mean: &mut [f64]) {
    DIAGNOSIS.iter().for_each(|d| d.shift_expected_features(effects, mean));
}

pub(super) fn between(rng: &mut Rng, lo: f64, hi: f64) -> f64 {
    lo + (hi - lo) * rng.uniform()
}

/// The force balance's reading of quantity `q` of effect `T` at every fit
/// point, pooled by inverse variance: its value and standard error; `None`
/// where a point cannot read it.
pub(super) fn pooled<T: Diagnosed>(fs: &FitSet, q: usize) -> Option<(f64, f64)> {
    let (mut sum, mut weight) = (0.0, 0.0);
    for k in 0..fs.points.len() {
        let (_, v, u) = *T::force_balance_reading(&|j| fs.change(k, j)).get(q)?;
        if !(v.is_finite() && u.is_finite()) {
            return None;
        }
        // A point without scatter (one cycle) weighs as the floor's noise would.
        let w = 1.0 / (u * u).max(1e-300);
        sum += w * v;
        weight += w;
    }
    (weight > 0.0).then(|| (sum / weight, weight.recip().sqrt()))
}

/// The force balance's reading of every quantity of `T`, pooled over the
/// fit points ([`pooled`]), each within its free parameter's range; `None`
/// if one falls outside it (then it is not this effect's size).
pub(super) fn pooled_size<T: Diagnosed>(fs: &FitSet) -> Option<(Vec<f64>, Vec<f64>)> {
    let specs = T::free_params(fs.distinct);
    let (values, sds): (Vec<f64>, Vec<f64>) = (0..specs.len())
        .map(|q| pooled::<T>(fs, q))
        .collect::<Option<Vec<_>>>()?
        .into_iter()
        .unzip();
    specs
        .iter()
        .zip(&values)
        .all(|(s, v)| (s.lo..=s.hi).contains(v))
        .then_some((values, sds))
}

pub(super) fn rel(a: f64, b: f64) -> f64 {
    ((a - b) / b).abs()
}

/// How the diagnosis fits, explains and benchmarks a catalogued effect.
pub(super) trait Diagnosed: Effect {
    /// The free parameters the diagnosis fits. Every other key keeps its
    /// default (documented in docs/diagnosis.md).
    fn free_params(distinct_pressures: usize) -> Vec<ParamSpec>;

    /// The effect with fitted values `theta`; `pressures` are the lowest and
    /// highest supply pressures of the fit set, bar.
    fn from_fit(theta: &[f64], pressures: (f64, f64)) -> Self;

    /// Start values from what the measurement shows directly; by default the
    /// catalogue's defaults (the range's low end for a key it lacks).
    fn start_values(_fs: &FitSet, specs: &[ParamSpec]) -> Vec<f64> {
        let v = serde_json::to_value(Self::default()).unwrap_or_default();
        specs
            .iter()
            .map(|s| v.get(s.key).and_then(|x| x.as_f64()).unwrap_or(s.lo))
            .collect()
    }

    /// Its signature in the measurement's force balance, if it has one.
    fn evidence(_fs: &FitSet) -> Option<String> {
        None
    }

    /// How many standard errors the effect's signature in the force balance
    /// stands off the nominal model's, in the direction the effect moves it;
    /// `None` if the force balance cannot see it.
    fn model_free_z(_fs: &FitSet) -> Option<f64> {
        None
    }

    /// Whether its model-free signature is in the chamber characteristics
    /// (against a reference) rather than the force balance. Such a
    /// signature moves with other effects too (heat exchange delays the
    /// valve's switching; friction moves the piston and with it the feed's
    /// onset, by the hammer's form, not the model's), so it is not enough
    /// to try the effect as a pair's second where its waveforms do not.
    fn seen_in_chambers() -> bool {
        false
    }

    /// Its free parameters (values, standard deviations) read from its
    /// model-free signature alone, where that signature measures the
    /// parameter itself rather than through the model's law; `None` if it
    /// does not, or does not stand.
    fn measured_size(_fs: &FitSet) -> Option<(Vec<f64>, Vec<f64>)> {
        None
    }

    /// What the force balance reads of it at one operating point, from
    /// `change(j)`, feature `j`'s change there and its standard error
    /// ([`crate::fitset::change_of`]): a (key, value, standard uncertainty)
    /// per quantity; empty where the force balance does not see it. The
    /// force balance measures these directly (no valve or port law), so
    /// their size is taken from it in both modes ([`Diagnosed::measured_size`]).
    fn force_balance_reading(_change: &dyn Fn(usize) -> (f64, f64)) -> Vec<(&'static str, f64, f64)> {
        Vec::new()
    }

    /// Whether its model-free signature, standing where another effect's
    /// does not, parts the two (see `rank::close_call`). True of the force
    /// balance's and of the front feed's shift, which no other effect makes.
    fn signature_parts() -> bool {
        true
    }

    /// The test, outside the waveforms, that tells it from an effect they
    /// cannot part it from, in words; `None` for an effect the force
    /// balance sees (it parts it already).
    fn parting_test() -> Option<&'static str> {
        None
    }

    /// A measured change since the reference record that the effect cannot
    /// make, in words; `None` where there is none (or no reference). Such
    /// an effect is not named alone, however its waveforms score: the
    /// model's law for it may well fit a change of another cause.
    fn contradicted(_fs: &FitSet) -> Option<String> {
        None
    }

    /// The magnitude (a catalogue key and its value) at which its
    /// force-balance signature stands `z_min` standard errors off nominal:
    /// below it, the verdict cannot exclude the effect. `None` if the force
    /// balance cannot see it.
    fn model_free_floor(_fs: &FitSet, _z_min: f64) -> Option<(&'static str, f64)> {
        None
    }

    /// A sensor effect on the pressure readings: the factors on the rear and
    /// front channels (reading = factor·true).
    fn pressure_reading_factors(&self) -> (f64, f64) {
        (1.0, 1.0)
    }

    /// A sensor effect's expected contribution to the model's mean features
    /// (what the extractor cannot see in an ideal, noiseless solution).
    fn shift_expected_features(&self, _mean: &mut [f64]) {}

    /// A random magnitude over the range a bench would meet.
    fn draw(rng: &mut Rng) -> Self;

    /// Relative error of a fitted magnitude against the truth.
    fn magnitude_error(truth: &Self, fitted: &Self, points: &[f64]) -> f64;
}

/// A registry entry: a [`Diagnosed`] effect seen without its type.
pub(super) trait DiagnosisEntry: Sync {
    fn name(&self) -> &'static str;
    fn free_params(&self, distinct_pressures: usize) -> Vec<ParamSpec>;
    fn apply(&self, effects: &mut Effects, theta: &[f64], pressures: (f64, f64));
    fn start_values(&self, fs: &FitSet) -> Vec<f64>;
    fn evidence(&self, fs: &FitSet) -> Option<String>;
    fn model_free_z(&self, fs: &FitSet) -> Option<f64>;
    fn model_free_floor(&self, fs: &FitSet, z_min: f64) -> Option<(&'static str, f64)>;
    fn seen_in_chambers(&self) -> bool;
    fn measured_size(&self, fs: &FitSet) -> Option<(Vec<f64>, Vec<f64>)>;
    fn force_balance_reading(&self, change: &dyn Fn(usize) -> (f64, f64)) -> Vec<(&'static str, f64, f64)>;
    fn signature_parts(&self) -> bool;
    fn parting_test(&self) -> Option<&'static str>;
    fn contradicted(&self, fs: &FitSet) -> Option<String>;
    fn pressure_reading_factors(&self, effects: &Effects) -> (f64, f64);
    fn shift_expected_features(&self, effects: &Effects, mean: &mut [f64]);
    fn draw(&self, effects: &mut Effects, rng: &mut Rng);
    /// `fitted` is the effect's catalogue parameters as in report.json.
    fn magnitude_error(&self, truth: &Effects, fitted: &serde_json::Value, points: &[f64]) -> Option<f64>;
}

struct Entry<T>(PhantomData<fn() -> T>);

impl<T: Diagnosed> DiagnosisEntry for Entry<T> {
    fn name(&self) -> &'static str {
        T::NAME
    }
    fn free_params(&self, distinct_pressures: usize) -> Vec<ParamSpec> {
        T::free_params(distinct_pressures)
    }
    fn apply(&self, effects: &mut Effects, theta: &[f64], pressures: (f64, f64)) {
        *T::slot(effects) = Some(T::from_fit(theta, pressures));
    }
    fn start_values(&self, fs: &FitSet) -> Vec<f64> {
        T::start_values(fs, &T::free_params(fs.distinct))
    }
    fn evidence(&self, fs: &FitSet) -> Option<String> {
        T::evidence(fs)
    }
    fn model_free_z(&self, fs: &FitSet) -> Option<f64> {
        T::model_free_z(fs)
    }
    fn model_free_floor(&self, fs: &FitSet, z_min: f64) -> Option<(&'static str, f64)> {
        T::model_free_floor(fs, z_min)
    }
    fn seen_in_chambers(&self) -> bool {
        T::seen_in_chambers()
    }
    fn measured_size(&self, fs: &FitSet) -> Option<(Vec<f64>, Vec<f64>)> {
        T::measured_size(fs)
    }
    fn force_balance_reading(&self, change: &dyn Fn(usize) -> (f64, f64)) -> Vec<(&'static str, f64, f64)> {
        T::force_balance_reading(change)
    }
    fn signature_parts(&self) -> bool {
        T::signature_parts()
    }
    fn parting_test(&self) -> Option<&'static str> {
        T::parting_test()
    }
    fn contradicted(&self, fs: &FitSet) -> Option<String> {
        T::contradicted(fs)
    }
    fn pressure_reading_factors(&self, effects: &Effects) -> (f64, f64) {
        T::get(effects).map_or((1.0, 1.0), |e| e.pressure_reading_factors())
    }
    fn shift_expected_features(&self, effects: &Effects, mean: &mut [f64]) {
        if let Some(e) = T::get(effects) {
            e.shift_expected_features(mean);
        }
    }
    fn draw(&self, effects: &mut Effects, rng: &mut Rng) {
        *T::slot(effects) = Some(T::draw(rng));
    }
    fn magnitude_error(&self, truth: &Effects, fitted: &serde_json::Value, points: &[f64]) -> Option<f64> {
        let fitted: T = serde_json::from_value(fitted.clone()).ok()?;
        Some(T::magnitude_error(T::get(truth)?, &fitted, points))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hammer_sim::effects::REGISTRY;

    #[test]
    fn the_diagnosis_follows_the_catalogue_order() {
        let names: Vec<&str> = DIAGNOSIS.iter().map(|d| d.name()).collect();
        let catalogue: Vec<&str> = REGISTRY.iter().map(|e| e.name()).collect();
        assert_eq!(names, catalogue);
    }

    /// docs/diagnosis.md's effect tables (free parameters, bench ranges) list
    /// the registry, in order.
    #[test]
    fn diagnosis_md_tables_list_the_registry() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../docs/diagnosis.md");
        let md = std::fs::read_to_string(path).unwrap();
        let mut tables = 0;
        let mut lines = md.lines().peekable();
        while let Some(line) = lines.next() {
            if !line.starts_with("| effect |") {
                continue;
            }
            tables += 1;
            let mut names = Vec::new();
            while let Some(row) = lines.next_if(|l| l.starts_with('|')) {
                if let Some(name) = row.split('|').nth(1).map(str::trim).filter(|c| c.starts_with('`')) {
                    names.push(name.trim_matches('`'));
                }
            }
            let catalogue: Vec<&str> = REGISTRY.iter().map(|e| e.name()).collect();
            assert_eq!(names, catalogue, "docs/diagnosis.md, table under `{line}`");
        }
        assert_eq!(
            tables, 2,
            "docs/diagnosis.md: the free-parameter and bench-range tables"
        );
    }

    #[test]
    fn free_params_are_catalogue_keys_or_documented_reparametrisations() {
        for d in DIAGNOSIS {
            let e = hammer_sim::effects::entry(d.name()).unwrap();
            for distinct in [1, 2] {
                let specs = d.free_params(distinct);
                assert!(!specs.is_empty(), "{}", d.name());
                let theta: Vec<f64> = specs.iter().map(|s| 0.5 * (s.lo + s.hi)).collect();
                let mut effects = Effects::default();
                d.apply(&mut effects, &theta, (4.0, 7.0));
                assert_eq!(effects.active(), vec![d.name()]);
                assert!(e.is_on(&effects));
            }
        }
    }
}
