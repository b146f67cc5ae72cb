//! The fuzz targets: one file each, all listed in [`TARGETS`].

pub mod app;
pub mod commission;
pub mod config;
pub mod frame;
pub mod import;
pub mod sidecar;
pub mod trace_csv;

/// A fuzz target: what it runs, the tokens that help a mutator past its
/// parser, and its seed inputs.
pub struct Target {
    pub name: &'static str,
    /// Runs one input and checks the invariants (panics on a violation).
    /// Returns which way the input went (an outcome signature): the smoke
    /// runner keeps inputs with an outcome it has not seen.
    pub run: fn(&[u8]) -> u64,
    pub dict: &'static [&'static [u8]],
    /// Seed inputs, made from the project's own writers (`seeds` writes them
    /// to `fuzz/corpus/<name>/`).
    pub seeds: fn() -> Vec<Vec<u8>>,
}

/// The slowest first: the smoke runner's workers take the next target in
/// this order, so the file readers (about 11 000 executions a second, the
/// others 33 000 to a million) start at once and the rest share the other
/// core (`cargo xtask fuzz`: 87 s for the longest alone, 118 s in all when
/// it came sixth; 2 cores, 2026-11-29).
pub const TARGETS: &[Target] = &[
    import::TARGET,
    frame::TARGET,
    app::TARGET,
    trace_csv::TARGET,
    sidecar::TARGET,
    config::TARGET,
    commission::TARGET,
];

pub fn by_name(name: &str) -> Option<&'static Target> {
    TARGETS.iter().find(|t| t.name == name)
}

/// Folds a small outcome code into a signature (order-independent set).
pub(crate) fn bit(code: u32) -> u64 {
    1u64 << (code % 64)
}
