//! Lumped-parameter simulator of the paper's small pneumatic hammer, with the
//! catalogue of effects the nominal model leaves out and the sensor chain
//! that turns its solution into what a bench would record.
//!
//! Module map (data flows down the list):
//! - [`params`]: every model parameter, [`SimConfig`] (the TOML root of a run);
//! - [`effects`]: the effect catalogue, all off in the nominal model;
//! - [`gas`], [`model`]: the equations (`docs/model.md`), [`solver`]: Dormand–Prince 5(4);
//! - [`run`]: one solution with events, per-cycle truth and balances, handed to a sink as it is produced;
//! - [`stepper`]: that solution advanced from outside, communication point by communication point;
//! - [`rng`]: the seeded random numbers (xoshiro256++, ziggurat normal deviates);
//! - [`sensor`]: bandwidth, noise, clipping, quantisation and the sensor-side effects
//!   (the channels' settings in [`sensor_model`], below [`params`], which holds them);
//! - [`simulate`]: a complete simulated measurement as a trace plus sidecar, kept in memory or streamed to disk;
//! - [`estimation`]: the one path from any trace to the estimator's ADC codes and calibration;
//! - [`board_reading`]: a file's codes as a board reports them (the estimator, then the chambers' reader);
//! - [`characteristics`]: per-cycle chamber characteristics of a trace, measured or true.

use hammer_trace::config;

pub mod board_reading;
pub mod characteristics;
pub mod effects;
pub mod estimation;
pub mod gas;
pub mod model;
pub mod params;
pub mod rng;
pub mod run;
pub mod sensor;
pub mod sensor_model;
pub mod simulate;
pub mod solver;
pub mod stepper;

pub use effects::{Effects, EFFECT_NAMES, REGISTRY};
pub use params::SimConfig;
pub use run::{simulate_truth, CycleTruth, SimRun, TruthTrace};
pub use simulate::{
    simulate, simulate_to_file, simulate_trace, stream_codes, SimulateError, Simulation, SimulationInfo,
};
