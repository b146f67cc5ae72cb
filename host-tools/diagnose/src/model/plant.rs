//! The seam between the diagnosis and the model it fits: a [`Plant`] runs
//! at an operating point with given nuisance values and catalogue effects,
//! and returns the three sensor signals (and what else it offers). The
//! pipeline knows nothing else of the model, so the built-in simulator and
//! a bench engineer's FMU are fitted alike (issues 45 and 46).

use hammer_sim::effects::Effects;

/// A nominal parameter the model's owner is unsure of: the diagnosis lets
/// it move within a Gaussian prior rather than blame an effect for what it
/// explains.
#[derive(Debug, Clone, PartialEq)]
pub struct NuisanceParam {
    /// The model's own name for it (a config key or an FMU variable).
    pub name: String,
    /// Its nominal value, in the model's units.
    pub nominal: f64,
    /// Its prior's relative standard deviation; None: the diagnosis'
    /// `nominal_uncertainty` (the built-in model's parameters are all known
    /// to the same few percent).
    pub relative_uncertainty: Option<f64>,
}

/// What a run must keep: the three signals the extractor reads, or with
/// them what the stage labels and the figures read (position, velocity,
/// the impacts).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Keep {
    Signals,
    All,
}

/// The piston's position and velocity, sample by sample.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Motion {
    pub x_m: Vec<f64>,
    pub v_mps: Vec<f64>,
}

/// One impact the model located: when, and the period of the cycle it ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Impact {
    pub t_impact_s: f64,
    pub period_s: f64,
}

/// A model run: samples at t = 0, dt, 2 dt, … (SI, gauge pressures,
/// forward positive), with no sensor effect applied.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ModelTrace {
    pub dt_s: f64,
    pub p_rear_pa: Vec<f64>,
    pub p_front_pa: Vec<f64>,
    pub accel_mps2: Vec<f64>,
    /// None when the model offers no position and velocity (or the run
    /// kept only the signals).
    pub motion: Option<Motion>,
    /// Empty when the model does not locate its impacts.
    pub impacts: Vec<Impact>,
}

impl ModelTrace {
    pub fn len(&self) -> usize {
        self.p_rear_pa.len()
    }

    pub fn is_empty(&self) -> bool {
        self.p_rear_pa.is_empty()
    }
}

/// A model the diagnosis can fit.
///
/// `run` is called from several threads at once. A failure of one run is
/// that candidate's (its fit is skipped); a failure that makes the whole
/// diagnosis meaningless (a foreign library that crashed or hung) is kept
/// by the plant and returned by [`Plant::fatal`], which the engine checks
/// after every stage.
pub trait Plant: Send + Sync + std::fmt::Debug {
    /// The nuisance parameters, in the order `run` takes their values.
    fn nuisance(&self) -> &[NuisanceParam];

    /// Whether the model carries catalogue effect `name` (in itself, or the
    /// project applies it to its outputs or inputs). An effect it cannot
    /// carry is left out of the ranking, and its detection floor reads
    /// "not modelled".
    fn carries(&self, name: &str) -> bool;

    /// Runs from rest for `duration_s` at `supply_bar` (gauge), the nuisance
    /// parameters at `nuisance` (one value each, in [`Plant::nuisance`]'s
    /// order) and `effects`' physical effects on. The sensor effects are
    /// the diagnosis' to apply.
    fn run(
        &self,
        supply_bar: f64,
        nuisance: &[f64],
        effects: &Effects,
        duration_s: f64,
        keep: Keep,
    ) -> Result<ModelTrace, String>;

    /// The first failure that ends the diagnosis, if any.
    fn fatal(&self) -> Option<String> {
        None
    }

    /// What `report.json` says the model is (None: the built-in simulator).
    fn identity(&self) -> Option<serde_json::Value> {
        None
    }
}
