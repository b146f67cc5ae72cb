//! Sim-to-real gap diagnosis (issue 6): *where* simulation and measurement
//! differ (by signal and stage of the cycle), *which* unmodelled effect of
//! the catalogue explains it, and *how far* the gap shrinks on held-out data
//! once that effect is in the model.

pub mod bench;
pub mod command;
mod effects;
pub mod engine;
pub mod features;
pub mod fit;
pub mod gap;
pub mod isolability;
pub mod model;
pub mod output;
pub mod stages;
