//! The committed seed corpus is there for every target and passes every
//! target's invariants; a short seeded run finds nothing.

use std::path::Path;

use hammer_fuzz::smoke::{load_corpus, run};
use hammer_fuzz::targets::TARGETS;

#[test]
fn every_target_has_seeds_that_pass_its_invariants() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus");
    for t in TARGETS {
        let corpus = load_corpus(&dir, t).unwrap_or_else(|e| panic!("{}: {e}", t.name));
        assert!(!corpus.is_empty(), "{}: no seeds", t.name);
        for seed in &corpus {
            (t.run)(seed);
        }
    }
}

#[test]
fn a_short_run_explores_and_finds_nothing() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus");
    let artifacts = std::env::temp_dir().join("hammer-fuzz-test-artifacts");
    for t in TARGETS {
        let s = run(t, load_corpus(&dir, t).unwrap(), 5_000, None, 7, &artifacts);
        assert_eq!(s.executions, 5_000);
        assert!(s.findings.is_empty(), "{}: {:?}", t.name, s.findings);
        // The mutator reaches more than one way through every target.
        assert!(s.outcomes >= 3, "{}: {} outcomes", t.name, s.outcomes);
    }
}
