//! One variant case end to end: the hammer, its sensors, a trace in the
//! project's format with a sidecar that says no more than a bench would
//! (the supply pressure), and the truth kept apart for the scorer.

use std::path::{Path, PathBuf};

use hammer_sim::effects::Effects;
use hammer_trace::trace::{write_csv, write_sidecar, Sidecar, Trace, TraceError};
use serde::{Deserialize, Serialize};

use crate::integrate::{run, VariantCycle};
use crate::plant::Plant;
use crate::sensors::{Channels, FrontEndState};
use crate::structure::{Structure, VariantParams};

/// Integration step: 100 steps per contact period, 10 per output sample.
pub const STEP_S: f64 = 1e-6;
pub const OUTPUT_EVERY: usize = 10;

/// Everything a scorer may know about a generated case.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VariantTruth {
    pub family: String,
    pub structure: Structure,
    pub variants: Vec<String>,
    pub params: VariantParams,
    pub supply_pressure_bar: f64,
    /// What was hidden, in the effect catalogue's terms.
    pub effects: Effects,
    pub sensors: Channels,
    pub seed: u64,
    pub duration_s: f64,
    pub cycles: Vec<VariantCycle>,
    pub energy_residual_j: f64,
    pub pressure_work_j: f64,
}

impl VariantTruth {
    /// Means over the cycles after the first `skip` (start-up).
    pub fn steady(&self, skip: usize, f: impl Fn(&VariantCycle) -> f64) -> Option<f64> {
        let c = self.cycles.get(skip..)?;
        (!c.is_empty()).then(|| c.iter().map(f).sum::<f64>() / c.len() as f64)
    }
}

pub struct Generated {
    pub trace: Trace,
    pub truth: VariantTruth,
}

pub fn generate(
    params: &VariantParams,
    structure: Structure,
    effects: &Effects,
    supply_bar: f64,
    duration_s: f64,
    seed: u64,
) -> Generated {
    let plant = Plant::new(params.clone(), structure, effects.clone(), supply_bar);
    let fe = FrontEndState::new(structure.front_end, seed);
    let sensors = fe.ch;
    let r = run(plant, fe, seed, duration_s, STEP_S, OUTPUT_EVERY);
    let mut trace = Trace {
        dt_s: r.dt_s,
        t_s: r.t_s,
        p_rear_pa: r.p_rear_pa,
        p_front_pa: r.p_front_pa,
        accel_mps2: r.accel_mps2,
        extra: Default::default(),
        gaps: Vec::new(),
    };
    // Truth columns as a bench with a position sensor would have them; the
    // diagnosis reads the four measured channels only.
    trace.extra.insert("x_m".into(), r.x_m);
    trace.extra.insert("v_mps".into(), r.v_mps);
    // The same names as the simulator's truth columns, and the spool.
    trace.extra.insert("p_rear_true_pa".into(), r.p_rear_true_pa);
    trace.extra.insert("p_front_true_pa".into(), r.p_front_true_pa);
    trace.extra.insert("spool".into(), r.spool);
    Generated {
        trace,
        truth: VariantTruth {
            family: "hammer-variants".into(),
            structure,
            variants: structure.variants().into_iter().map(String::from).collect(),
            params: params.clone(),
            supply_pressure_bar: supply_bar,
            effects: effects.clone(),
            sensors,
            seed,
            duration_s,
            cycles: r.cycles,
            energy_residual_j: r.energy_residual_j,
            pressure_work_j: r.pressure_work_j,
        },
    }
}

/// `run.csv` → `run.truth.json`.
pub fn truth_path(trace: &Path) -> PathBuf {
    trace.with_extension("truth.json")
}

impl Generated {
    /// Writes the trace, a bench-like sidecar (operating point, source
    /// `variant`) and the truth file beside them.
    pub fn write(&self, path: &Path) -> Result<(), TraceError> {
        write_csv(path, &self.trace)?;
        let side: Sidecar = Sidecar::new(Some(self.truth.supply_pressure_bar), "variant");
        write_sidecar(path, &side)?;
        let tp = truth_path(path);
        let text = serde_json::to_string_pretty(&self.truth).map_err(|e| TraceError::Sidecar {
            path: tp.display().to_string(),
            message: e.to_string(),
        })?;
        std::fs::write(&tp, text).map_err(|error| TraceError::Io {
            path: tp.display().to_string(),
            error,
        })
    }
}
