//! A second model family of the paper's hammer, written apart from
//! `hammer-sim` so that a benchmark's generator is not the model under test
//! (the "inverse crime"). It shares the paper's geometry and the effect
//! catalogue's parameters (the vocabulary of what a benchmark hides) and
//! nothing else: other valve, port, chamber, supply, anvil and sensor laws,
//! another flow law (ISO 6358 with its own critical ratio), another
//! integrator (fixed-step RK4, no event location).
//!
//! Module map:
//! - [`structure`]: the structural choices and their parameters, drawn per case;
//! - [`flow`]: compressible flow (ISO 6358), laminar gap leakage, port areas;
//! - [`plant`]: the state and its derivative;
//! - [`integrate`]: the time loop (a [`integrate::Stepper`] a caller can advance piece by piece), the discrete valve logic, per-cycle truth;
//! - [`sensors`]: the front ends (first-order, resonant, clipping ranges);
//! - [`generate`]: one case end to end: trace, sidecar, truth file.

pub mod flow;
pub mod generate;
pub mod integrate;
pub mod plant;
pub mod sensors;
pub mod structure;

pub use generate::{generate, Generated, VariantTruth};
pub use structure::{Structure, VariantParams};
