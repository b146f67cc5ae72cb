//! Fuzz targets of hammer-monitor and a stable-Rust runner for them.
//!
//! Every target takes arbitrary bytes and checks the invariants of the code
//! under test; a violation panics, which is the finding. The same target
//! functions run under two engines:
//! - [`smoke`]: an in-process, seeded mutational runner (no instrumentation,
//!   stable Rust, deterministic): CI's smoke run, `cargo xtask fuzz`;
//! - AFL++ through cargo-afl (`src/bin/afl_target.rs`, feature `afl`):
//!   coverage-guided long runs, `cargo xtask fuzz --afl`.
//!
//! Module map:
//! - [`targets`]: one file per target, and the [`targets::TARGETS`] list;
//! - [`mutate`]: the byte-level mutator with per-target dictionaries;
//! - [`smoke`]: the runner (corpus, feedback on new outcomes, panics caught
//!   and their input saved).
//!
//! Seed corpora live in `fuzz/corpus/<target>/`, written by
//! `cargo run --release -p hammer-fuzz -- seeds`.

pub mod mutate;
pub mod smoke;
pub mod targets;
