//! A bench engineer's FMU as a [`Plant`] (issue 46): the map says which FMU
//! parameters carry the nuisance and each catalogue effect; the import
//! (`hammer_fmu::import`) runs the foreign code in worker processes behind
//! a time limit, so a crash or a hang costs an error, never the diagnosis'
//! process.

use std::sync::{Arc, Mutex};

use super::plant::{Impact, Keep, ModelTrace, Motion, NuisanceParam, Plant};
use hammer_fmu::import::map::Coverage;
use hammer_fmu::import::{FailKind, FmuError, FmuModel, Signals};
use hammer_sim::effects::{entry, Effects};

/// An opened FMU with its map, fitted by the diagnosis.
pub struct FmuPlant {
    model: Arc<FmuModel>,
    /// Set before every run, after the map's own fixed values: a
    /// benchmark case's drawn structure ([`FmuPlant::with_fixed`]).
    fixed: Vec<(String, f64)>,
    nuisance: Vec<NuisanceParam>,
    coverage: Vec<(&'static str, Coverage)>,
    /// The first failure that ends the diagnosis.
    fatal: Mutex<Option<String>>,
}

impl std::fmt::Debug for FmuPlant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FmuPlant")
            .field("fmu", &self.model.identity().name)
            .finish_non_exhaustive()
    }
}

impl FmuPlant {
    /// `model`, opened with a map (without one nothing can be run).
    pub fn new(model: FmuModel) -> Result<Self, String> {
        let map = model
            .map()
            .ok_or("the diagnosis runs an FMU through its model map: give --model-map")?;
        let nuisance = map
            .nuisance
            .iter()
            .map(|n| NuisanceParam {
                name: n.parameter.clone(),
                nominal: n.nominal,
                relative_uncertainty: Some(n.relative_uncertainty),
            })
            .collect();
        let coverage = map.coverage();
        Ok(Self {
            model: Arc::new(model),
            fixed: Vec::new(),
            nuisance,
            coverage,
            fatal: Mutex::new(None),
        })
    }

    /// The same FMU (its worker processes shared) with `fixed` set before
    /// every run: parameters a case sets and the diagnosis does not fit.
    pub fn with_fixed(&self, fixed: Vec<(String, f64)>) -> Self {
        Self {
            model: Arc::clone(&self.model),
            fixed,
            nuisance: self.nuisance.clone(),
            coverage: self.coverage.clone(),
            fatal: Mutex::new(None),
        }
    }

    /// The settings that give the FMU the second family's `structure`:
    /// each `structure.<variant>` parameter it has (`hammer fmu --family
    /// variants` exports them), 1 where the structure has the variant.
    /// None of them on an FMU of another form: it stays as it is.
    pub fn structure_settings(&self, structure: &hammer_variants::Structure) -> Vec<(String, f64)> {
        let has = structure.variants();
        hammer_variants::Structure::singles()
            .iter()
            .filter_map(|s| s.variants().first().copied())
            .map(|v| (format!("structure.{v}"), f64::from(u8::from(has.contains(&v)))))
            .filter(|(name, _)| self.model.description().variable(name).is_some())
            .collect()
    }

    pub fn model(&self) -> &FmuModel {
        &self.model
    }

    fn coverage_of(&self, name: &str) -> Coverage {
        self.coverage
            .iter()
            .find(|(n, _)| *n == name)
            .map_or(Coverage::NotModelled, |(_, c)| *c)
    }

    /// The FMU settings and the effects driven from outside for `effects`
    /// at `supply_bar`.
    fn settings(
        &self,
        nuisance: &[f64],
        effects: &Effects,
        supply_bar: f64,
    ) -> Result<(Vec<(String, f64)>, Effects), String> {
        let map = self.model.map().ok_or("no model map")?;
        let mut settings: Vec<(String, f64)> = self.fixed.clone();
        settings.extend(self.nuisance.iter().zip(nuisance).map(|(p, v)| (p.name.clone(), *v)));
        let mut outside = Effects::default();
        let table = serde_json::to_value(effects).map_err(|e| e.to_string())?;
        for name in effects.active() {
            match self.coverage_of(name) {
                Coverage::InFmu => {
                    let values: Vec<(String, f64)> = table
                        .get(name)
                        .and_then(|t| t.as_object())
                        .map(|o| o.iter().filter_map(|(k, v)| Some((k.clone(), v.as_f64()?))).collect())
                        .unwrap_or_default();
                    let refs: Vec<(&str, f64)> = values.iter().map(|(k, v)| (k.as_str(), *v)).collect();
                    settings.extend(map.effect_settings(name, &refs, supply_bar)?);
                }
                Coverage::ForceInput => {
                    let e = entry(name).ok_or_else(|| format!("no catalogue effect {name}"))?;
                    let params = table.get(name).cloned().unwrap_or_default();
                    let params: toml::Value = serde_json::from_value(params).map_err(|e| format!("{name}: {e}"))?;
                    e.set(&mut outside, params).map_err(|e| format!("{name}: {e}"))?;
                }
                Coverage::OnOutputs => {}
                Coverage::NotModelled => return Err(format!("{name} is not modelled by this FMU's map")),
            }
        }
        Ok((settings, outside))
    }

    /// Keeps `e` if it ends the diagnosis: the FMU could not be run at all
    /// (its process crashed or hung, a worker failed, the map does not fit).
    /// A step that fails or goes non-finite at one candidate's parameters,
    /// or a run that does not cycle, is that candidate's.
    fn note(&self, e: &FmuError) {
        let ends = !matches!(e.kind, FailKind::Step | FailKind::NonFinite | FailKind::NotCycling);
        if ends {
            let mut f = self.fatal.lock().unwrap_or_else(|p| p.into_inner());
            f.get_or_insert_with(|| e.to_string());
        }
    }
}

impl Plant for FmuPlant {
    fn nuisance(&self) -> &[NuisanceParam] {
        &self.nuisance
    }

    fn carries(&self, name: &str) -> bool {
        self.coverage_of(name) != Coverage::NotModelled
    }

    fn run(
        &self,
        supply_bar: f64,
        nuisance: &[f64],
        effects: &Effects,
        duration_s: f64,
        keep: Keep,
    ) -> Result<ModelTrace, String> {
        let (settings, outside) = self.settings(nuisance, effects, supply_bar)?;
        let s = self
            .model
            .run_keeping(supply_bar * 1e5, &settings, &outside, duration_s, keep == Keep::All)
            .inspect_err(|e| self.note(e))
            .map_err(|e| e.to_string())?;
        Ok(trace(s, keep))
    }

    fn fatal(&self) -> Option<String> {
        self.fatal.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    fn identity(&self) -> Option<serde_json::Value> {
        serde_json::to_value(self.model.identity()).ok()
    }
}

/// An FMU run as the diagnosis reads any model's: the impacts from the
/// impact counter, where the map names one.
fn trace(s: Signals, keep: Keep) -> ModelTrace {
    let all = keep == Keep::All;
    let motion = match (all, s.position_m, s.velocity_mps) {
        (true, Some(x_m), Some(v_mps)) => Some(Motion { x_m, v_mps }),
        _ => None,
    };
    let impacts = match (all, &s.impacts) {
        (true, Some(count)) => impacts_of(count, s.dt_s),
        _ => Vec::new(),
    };
    ModelTrace {
        dt_s: s.dt_s,
        p_rear_pa: s.p_rear_pa,
        p_front_pa: s.p_front_pa,
        accel_mps2: s.accel_mps2,
        motion,
        impacts,
    }
}

/// The impacts an impact counter shows (a rise between samples), each with
/// the time since the one before (the first, with none before, is left out).
fn impacts_of(count: &[f64], dt_s: f64) -> Vec<Impact> {
    let times: Vec<f64> = count
        .windows(2)
        .enumerate()
        .filter(|(_, w)| w[1] > w[0])
        .map(|(i, _)| (i + 1) as f64 * dt_s)
        .collect();
    times
        .windows(2)
        .map(|w| Impact {
            t_impact_s: w[1],
            period_s: w[1] - w[0],
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_impact_counter_gives_the_impacts_and_their_periods() {
        let count = [0.0, 0.0, 1.0, 1.0, 1.0, 2.0, 2.0, 3.0];
        let imp = impacts_of(&count, 0.5);
        assert_eq!(imp.len(), 2);
        assert_eq!((imp[0].t_impact_s, imp[0].period_s), (2.5, 1.5));
        assert_eq!((imp[1].t_impact_s, imp[1].period_s), (3.5, 1.0));
    }
}
