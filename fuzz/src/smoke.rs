//! The in-process runner: seeded mutations of the committed corpus, inputs
//! with an outcome not seen before kept (a cheap feedback without
//! instrumentation), panics caught, reported with their input saved. It is
//! deterministic for a given seed, so a CI finding reproduces locally.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use crate::mutate::{mutate, Rng};
use crate::targets::Target;

/// Most inputs kept per target (the seeds plus new outcomes).
const POOL: usize = 512;

#[derive(Debug, Clone)]
pub struct Finding {
    pub message: String,
    pub input_path: PathBuf,
}

#[derive(Debug, Clone)]
pub struct RunStats {
    pub target: &'static str,
    pub executions: u64,
    pub elapsed: Duration,
    /// Distinct outcome signatures seen (how many ways through the target).
    pub outcomes: usize,
    pub pool: usize,
    pub findings: Vec<Finding>,
}

/// Reads `corpus_dir/<target>/*` (sorted by name, so runs are reproducible).
pub fn load_corpus(corpus_dir: &Path, target: &Target) -> std::io::Result<Vec<Vec<u8>>> {
    let dir = corpus_dir.join(target.name);
    let mut names: Vec<PathBuf> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    names.sort();
    names.iter().map(std::fs::read).collect()
}

/// Runs `target` for `executions` inputs (or until `deadline`), starting
/// from `corpus`. A panicking input is written to `artifacts/<target>/`.
pub fn run(
    target: &Target,
    corpus: Vec<Vec<u8>>,
    executions: u64,
    deadline: Option<Duration>,
    seed: u64,
    artifacts: &Path,
) -> RunStats {
    let start = Instant::now();
    let mut rng = Rng::new(seed ^ fnv(target.name.as_bytes()));
    let mut pool = if corpus.is_empty() { vec![Vec::new()] } else { corpus };
    let mut seen = std::collections::HashSet::new();
    let mut findings: Vec<Finding> = Vec::new();
    let mut n = 0u64;
    // Seeds first, unmutated: a seed that fails is a finding too.
    let seeds = pool.clone();
    let mut input = Vec::new();
    while n < executions {
        if n % 1024 == 0 && deadline.is_some_and(|d| start.elapsed() >= d) {
            break;
        }
        input.clear();
        if (n as usize) < seeds.len() {
            input.extend_from_slice(&seeds[n as usize]);
        } else {
            input.extend_from_slice(&pool[rng.below(pool.len())]);
            let other = &pool[rng.below(pool.len())];
            mutate(&mut rng, &mut input, other, target.dict);
        }
        n += 1;
        match catch_unwind(AssertUnwindSafe(|| (target.run)(&input))) {
            Ok(sig) => {
                if seen.insert(sig) && pool.len() < POOL {
                    pool.push(input.clone());
                }
            }
            Err(payload) => {
                let message = payload
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_else(|| "panic".into());
                if findings.iter().any(|f| f.message == message) {
                    continue;
                }
                let dir = artifacts.join(target.name);
                let _ = std::fs::create_dir_all(&dir);
                let input_path = dir.join(format!("crash-{:016x}", fnv(&input)));
                let _ = std::fs::write(&input_path, &input);
                findings.push(Finding { message, input_path });
            }
        }
    }
    RunStats {
        target: target.name,
        executions: n,
        elapsed: start.elapsed(),
        outcomes: seen.len(),
        pool: pool.len(),
        findings,
    }
}

/// FNV-1a: names crash files by content and salts the seed per target.
fn fnv(b: &[u8]) -> u64 {
    b.iter().fold(0xcbf2_9ce4_8422_2325, |h, &x| {
        (h ^ x as u64).wrapping_mul(0x100_0000_01b3)
    })
}
