//! The second model family (`hammer-variants`: other valve, port, chamber,
//! supply, anvil and sensor laws, fixed-step RK4) as an FMU, for a
//! diagnosis that must fit a model that is not its own (issue 46).
//!
//! Its numerics are its own: a 1 µs step, a sample every 10 steps (the
//! output grid, 10 µs), no event location (an impact is placed inside its
//! step by linear interpolation). A communication point runs every step that
//! starts at or before it, so the impact outputs count the impacts located
//! up to one step (1 µs) past it; the signals are the grid sample at or
//! just before it, as for the built-in model. The structure (the laws) is
//! fixed when the FMU is written (`--config`), the parameters are not.

use hammer_sim::effects::Effects;
use hammer_sim::params::SUPPLY_BAR_RANGE;
use hammer_variants::generate::{OUTPUT_EVERY, STEP_S};
use hammer_variants::integrate::{Sample, Stepper};
use hammer_variants::plant::Plant;
use hammer_variants::sensors::FrontEndState;
use hammer_variants::{Structure, VariantParams};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::instance::Runner;
use crate::table::{outputs, Choice, Family, Out, Output, Table, Val};

/// The second family's outputs: its valve is a spool position, 0 feeds the
/// front, 1 the rear.
pub const VARIANT_OUTPUTS: [Output; 16] = outputs(Output {
    name: "spool",
    kind: crate::table::Kind::Real,
    unit: None,
    description: "valve spool position, fraction of its travel (0 feeds the front)",
});

/// What `hammer fmu --family variants [--config FILE]` exports: the
/// family's parameters, its structure, the supply, the hidden effects, the
/// seed of its sensor noise, and the default experiment's length.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VariantsConfig {
    pub params: VariantParams,
    pub structure: Structure,
    pub supply: Supply,
    pub effects: Effects,
    pub seed: u64,
    /// The default experiment's stop time, s (not a parameter: the
    /// experiment's stop time sets the run's length).
    pub duration_s: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Supply {
    /// Gauge supply pressure, bar.
    pub pressure_bar: f64,
}

impl Default for VariantsConfig {
    fn default() -> Self {
        Self {
            params: VariantParams::default(),
            structure: Structure::BASE,
            supply: Supply { pressure_bar: 4.0 },
            effects: Effects::default(),
            seed: 0,
            duration_s: 0.5,
        }
    }
}

impl VariantsConfig {
    /// The supply in the simulator's range, the effects in theirs; the
    /// family has no ranges of its own, so each of its numbers must be
    /// finite and positive.
    pub fn validate(&self) -> Result<(), String> {
        let (lo, hi) = SUPPLY_BAR_RANGE;
        let p = self.supply.pressure_bar;
        if !(lo..=hi).contains(&p) {
            return Err(format!(
                "supply.pressure_bar = {p} is out of range: allowed {lo} ..= {hi}"
            ));
        }
        self.effects.validate().map_err(|e| e.to_string())?;
        let Ok(Value::Object(params)) = serde_json::to_value(&self.params) else {
            return Err("the parameters cannot be read".into());
        };
        for (k, v) in params {
            match v.as_f64() {
                Some(x) if x.is_finite() && x > 0.0 => {}
                _ => return Err(format!("params.{k} = {v}: must be a finite positive number")),
            }
        }
        Ok(())
    }
}

/// The second family's table.
pub fn table(cfg: &VariantsConfig) -> Result<Table, String> {
    let json = serde_json::to_value(cfg).map_err(|e| e.to_string())?;
    Table::of(Family {
        json,
        skip: &["duration_s", "structure"],
        outputs: &VARIANT_OUTPUTS,
        choices: structure_choices()?,
    })
}

/// The family's structure as parameters: each law with its two forms a
/// Boolean `structure.<variant>` (`structure.position_latched_valve`, …),
/// named and valued as `hammer_variants` names them, so a benchmark sets
/// each case's drawn structure by the names its cases carry.
fn structure_choices() -> Result<Vec<Choice>, String> {
    let form = |s: &Structure| serde_json::to_value(s).map_err(|e| e.to_string());
    let base = form(&Structure::BASE)?;
    let mut out = Vec::new();
    for single in Structure::singles() {
        let name = single
            .variants()
            .first()
            .copied()
            .ok_or("a single structure names no variant")?;
        let other = form(&single)?;
        let (Value::Object(b), Value::Object(o)) = (&base, &other) else {
            return Err("the structure is not a table".into());
        };
        for (law, off) in b {
            let on = &o[law];
            if on != off {
                out.push(Choice {
                    name: format!("structure.{name}"),
                    path: vec!["structure".into(), law.clone()],
                    off: off.as_str().unwrap_or_default().to_string(),
                    on: on.as_str().unwrap_or_default().to_string(),
                    description: format!(
                        "the {law} law: {} when true, else {}",
                        on.as_str().unwrap_or("?"),
                        off.as_str().unwrap_or("?")
                    ),
                });
            }
        }
    }
    Ok(out)
}

/// A run of the second family, to `duration_s`, not yet at its start.
pub fn start(table: &Table, values: &[Val], duration_s: f64) -> Result<VariantRun, String> {
    let cfg: VariantsConfig = serde_json::from_value(table.json(values)?).map_err(|e| format!("refused: {e}"))?;
    cfg.validate()?;
    Ok(VariantRun::new(&cfg, duration_s))
}

/// A run of the second family: its stepper (which owns the plant and the
/// front end) and the last sample handed out.
pub struct VariantRun {
    stepper: Stepper,
    last: Option<Sample>,
    time_s: f64,
    t_end_s: f64,
}

impl VariantRun {
    fn new(cfg: &VariantsConfig, duration_s: f64) -> Self {
        let plant = Plant::new(
            cfg.params.clone(),
            cfg.structure,
            cfg.effects.clone(),
            cfg.supply.pressure_bar,
        );
        let front_end = FrontEndState::new(cfg.structure.front_end, cfg.seed);
        Self {
            stepper: Stepper::new(plant, front_end, cfg.seed, duration_s, STEP_S, OUTPUT_EVERY),
            last: None,
            time_s: 0.0,
            t_end_s: duration_s,
        }
    }
}

impl Runner for VariantRun {
    fn advance_to(&mut self, t_s: f64) -> Result<(), String> {
        let snap = t_s + 1e-6 * self.dt_s();
        let last = &mut self.last;
        self.stepper.advance_to(snap, &mut |s| *last = Some(s));
        let y = self.stepper.state();
        if !y.iter().all(|v| v.is_finite()) {
            return Err(format!("the second family's state is not finite at t = {t_s} s"));
        }
        self.time_s = t_s;
        Ok(())
    }

    fn output(&self, which: Out) -> Val {
        let Some(s) = &self.last else {
            return Val::Real(0.0);
        };
        let (count, last, period) = self.stepper.impacts();
        let x = match which {
            Out::PRearTrue => s.p_rear_true_pa,
            Out::PFrontTrue => s.p_front_true_pa,
            Out::AccelTrue => s.accel_true_mps2,
            Out::Accel => s.accel_mps2,
            Out::PRear => s.p_rear_pa,
            Out::PFront => s.p_front_pa,
            Out::X => s.x_m,
            Out::V => s.v_mps,
            Out::Valve => s.spool,
            Out::RearMass => s.m_rear_kg,
            Out::FrontMass => s.m_front_kg,
            Out::RearTemperature => s.t_rear_k,
            Out::FrontTemperature => s.t_front_k,
            Out::ImpactCount => return Val::Integer(i32::try_from(count).unwrap_or(i32::MAX)),
            Out::LastImpactVelocity => last.map_or(0.0, |(_, v)| v),
            Out::LastPeriod => period,
        };
        Val::Real(x)
    }

    fn time_s(&self) -> f64 {
        self.time_s
    }

    fn dt_s(&self) -> f64 {
        STEP_S * OUTPUT_EVERY as f64
    }

    fn t_end_s(&self) -> f64 {
        self.t_end_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::instance::{Instance, Model};
    use crate::table::Kind;

    /// Stepped at its output grid, the second family's FMU gives its own
    /// run's trace sample for sample and its cycles' impacts; a reset
    /// reruns it bit for bit.
    #[test]
    fn the_outputs_are_the_familys_own_run_and_reset_repeats_them() {
        let mut cfg = VariantsConfig::default();
        cfg.supply.pressure_bar = 6.0;
        cfg.seed = 4;
        let stop = 0.2;
        let g = hammer_variants::generate(&cfg.params, cfg.structure, &cfg.effects, 6.0, stop, 4);
        let mut inst = Instance::new(Model::Variants(cfg)).unwrap();
        let vr = |inst: &Instance, n: &str| inst.vr(n).unwrap();
        let real = |inst: &Instance, n: &str| match inst.get(vr(inst, n), Kind::Real).unwrap() {
            Val::Real(x) => x,
            _ => unreachable!(),
        };
        for _ in 0..2 {
            inst.setup_experiment(0.0, Some(stop)).unwrap();
            inst.enter_initialization().unwrap();
            inst.exit_initialization().unwrap();
            let h = 1e-5;
            let mut velocities = Vec::new();
            let mut count = 0;
            for i in 0..g.trace.t_s.len() {
                if i > 0 {
                    inst.do_step((i - 1) as f64 * h, i as f64 * h - (i - 1) as f64 * h)
                        .unwrap();
                }
                assert_eq!(
                    real(&inst, "p_rear_pa").to_bits(),
                    g.trace.p_rear_pa[i].to_bits(),
                    "{i}"
                );
                assert_eq!(
                    real(&inst, "accel_mps2").to_bits(),
                    g.trace.accel_mps2[i].to_bits(),
                    "{i}"
                );
                let Val::Integer(n) = inst.get(vr(&inst, "impact_count"), Kind::Integer).unwrap() else {
                    unreachable!()
                };
                if n > count {
                    count = n;
                    velocities.push(real(&inst, "last_impact_velocity_mps"));
                }
            }
            // The truth's cycles start at the second impact.
            let truth: Vec<f64> = g.truth.cycles.iter().map(|c| c.impact_velocity_mps).collect();
            assert!(truth.len() >= 3);
            assert_eq!(velocities[velocities.len() - truth.len()..], truth[..]);
            inst.terminate().unwrap();
            inst.reset();
        }
    }
}
