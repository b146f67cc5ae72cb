//! Sim-to-real gap diagnosis (issue 6): *where* simulation and measurement
//! differ (by signal and stage of the cycle), *which* unmodelled effect of
//! the catalogue explains it, and *how far* the gap shrinks on held-out data
//! once that effect is in the model.
//!
//! # Module map
//!
//! The diagnosis is a pipeline; [`engine::diagnose`] runs its stages in
//! order, each needing the one before, so a reader can follow one stage at
//! a time and test it alone (`pipeline`):
//!
//! | stage | module | why it is a stage of its own |
//! |---|---|---|
//! | group | `pipeline::group` | the fit/held-out split decides what the check may claim |
//! | nominal | `pipeline::nominal` | the weights every fit shares are fixed once, before any effect |
//! | rank | `pipeline::rank`, `pipeline::effect_fit` | the decisions (named? pair?) read from scores alone |
//! | floors | `pipeline::floor` | what the verdict cannot exclude: each unseen effect's weakest nameable magnitude |
//! | held-out | `pipeline::held_out` | the claim: the shrink on unseen data, against a recalibration-only control |
//! | where | `pipeline::where_` | where to look next; changes no number of the ranking |
//!
//! Around the pipeline:
//!
//! - [`engine`]: the entry point and its vocabulary (inputs, options, outcome);
//! - [`report`]: the schema of `report.json`, apart so a schema change is one diff;
//! - `fitset`: the statistics (weights, nuisance profile, recalibration) in
//!   one place, so every stage weighs a residual the same way;
//! - [`features`], [`gap`], [`stages`]: what is compared — per-cycle features,
//!   cycles cut from traces, and the cycle's stages (a)–(f);
//! - [`model`], `effects`, [`fit`]: the candidate models, the catalogue's
//!   diagnosis hooks (start values, evidence) and the optimiser;
//! - [`output`]: the report for people (Markdown, terminal, figures);
//! - [`bench`](mod@bench), [`isolability`], [`command`]: proving it on generated data, and the CLI;
//!   [`valve_timing`]: a valve's timing read off any hammer with a true position.

pub mod bench;
pub mod command;
mod effects;
pub mod engine;
pub mod features;
pub mod fit;
mod fitset;
pub mod gap;
pub mod isolability;
pub mod model;
pub mod output;
mod parallel;
mod pipeline;
pub mod report;
pub mod stages;
pub mod valve_timing;
