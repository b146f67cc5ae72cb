//! Lumped-parameter simulator of the paper's small pneumatic hammer.

pub mod effects;
pub mod gas;
pub mod model;
pub mod params;
pub mod run;
pub mod sensor;
pub mod solver;

pub use effects::{Effects, EFFECT_NAMES};
pub use params::SimConfig;
pub use run::{simulate_truth, CycleTruth, SimRun, TruthTrace};
