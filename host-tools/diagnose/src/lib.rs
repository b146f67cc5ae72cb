//! `hammer-diagnose`, the sim-to-real gap diagnosis (issue 6): *where* simulation and measurement
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
//! | confirm | `pipeline::confirm` | the ranking's profile is linear in the nominal values; this checks a waveform-only name with them refitted on the model |
//! | floors | `pipeline::floor` | what the verdict cannot exclude: each unseen effect's weakest nameable magnitude |
//! | held-out | `pipeline::held_out` | the claim: the shrink on unseen data, against a recalibration-only control |
//! | where | `pipeline::where_` | where to look next; changes no number of the ranking |
//!
//! Around the pipeline, in layers: each row imports only the rows above it
//! (the rows of one layer may import each other, as noted), so the stages
//! never import the engine that runs them:
//!
//! 1. [`stages`], [`fit`], `parallel`, [`options`], [`record`], [`input`],
//!    [`steady`]: the cycle's stages (a)–(f), the optimiser, the thread
//!    pool, the tunables, the commissioning record's format, what the
//!    diagnosis is given (traces or commissioning folders, progress,
//!    refusals), and the start-up rule;
//! 2. [`report`]: the schema of `report.json` (the candidate models
//!    included), apart so a schema change is one diff;
//! 3. [`gap`], [`features`], [`valve_timing`]: what is compared — cycles
//!    cut from traces and their waveforms, per-cycle features and the
//!    extractor for a config; a valve's timing read off any hammer with a
//!    true position, and its front port's true opening (a valve delay's
//!    size in physical terms);
//! 4. [`model`], then `fitset`, then `effects`: the candidate models, the
//!    statistics (weights, nuisance profile, recalibration) in one place so
//!    every stage weighs a residual the same way, and the catalogue's
//!    diagnosis hooks (free parameters, start values, evidence), which read
//!    the fit set and run the model. The model reads a candidate's sensor
//!    effects through [`model::SensorReads`], which the catalogue supplies
//!    (`ModelRunner::new` is defined with the hooks), so it imports neither;
//! 5. `pipeline`: the stages above;
//! 6. [`engine`]: the entry point, re-exporting the vocabulary of rows 1–3;
//! 7. [`bench`](mod@bench), [`isolability`]: proving it on generated data.
//!
//! No terminal, plotting or argument parsing: the `hammer` CLI
//! (`hammer-host`) renders the report for people (Markdown, terminal,
//! figures) and owns `hammer diagnose`'s arguments.

pub mod bench;
mod effects;
pub mod engine;
pub mod features;
pub mod fit;
mod fitset;
pub mod gap;
pub mod input;
pub mod isolability;
pub mod model;
pub mod options;
mod parallel;
mod pipeline;
pub mod record;
pub mod report;
pub mod stages;
pub mod steady;
pub mod valve_timing;
