//! `hammer-fuzz`: the smoke runner and the seed writer.
//!
//! ```text
//! hammer-fuzz smoke [--execs N] [--minutes M] [--seed S] [--target NAME]
//! hammer-fuzz seeds            # (re)writes fuzz/corpus/<target>/seed-*
//! hammer-fuzz replay FILE --target NAME
//! ```
//! Exit status 1 when any target panicked (the inputs are in `fuzz/artifacts/`).

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

use hammer_fuzz::smoke;
use hammer_fuzz::targets::{by_name, Target, TARGETS};

fn fuzz_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn usage() -> ExitCode {
    eprintln!("usage: hammer-fuzz smoke [--execs N] [--minutes M] [--seed S] [--target NAME] | seeds | replay FILE --target NAME");
    eprintln!(
        "targets: {}",
        TARGETS.iter().map(|t| t.name).collect::<Vec<_>>().join(", ")
    );
    ExitCode::from(2)
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let targets: Vec<&'static Target> = match value("--target") {
        Some(n) => match by_name(&n) {
            Some(t) => vec![t],
            None => return usage(),
        },
        None => TARGETS.iter().collect(),
    };
    // Quiet: a caught panic is reported once in the summary, not as a backtrace per input.
    std::panic::set_hook(Box::new(|_| {}));
    match args.first().map(String::as_str) {
        Some("seeds") => seeds(&targets),
        Some("replay") => {
            let (Some(file), [t]) = (args.get(1), &targets[..]) else {
                return usage();
            };
            let data = match std::fs::read(file) {
                Ok(d) => d,
                Err(e) => {
                    eprintln!("{file}: {e}");
                    return ExitCode::from(2);
                }
            };
            let _ = std::panic::take_hook();
            println!("outcome {:#x}", (t.run)(&data));
            ExitCode::SUCCESS
        }
        Some("smoke") => {
            let parse = |f: &str| value(f).map(|v| v.parse::<u64>().map_err(|_| f.to_string()));
            let (execs, minutes, seed) = match (parse("--execs"), parse("--minutes"), parse("--seed")) {
                (Some(Err(f)), _, _) | (_, Some(Err(f)), _) | (_, _, Some(Err(f))) => {
                    eprintln!("{f}: expected a whole number");
                    return usage();
                }
                (e, m, s) => (
                    e.map(Result::unwrap),
                    m.map(Result::unwrap),
                    s.map(Result::unwrap).unwrap_or(1),
                ),
            };
            let execs = execs.unwrap_or(if minutes.is_some() { u64::MAX } else { 1_000_000 });
            smoke_run(&targets, execs, minutes, seed)
        }
        _ => usage(),
    }
}

fn seeds(targets: &[&Target]) -> ExitCode {
    for t in targets {
        let dir = fuzz_dir().join("corpus").join(t.name);
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("corpus dir");
        let seeds = (t.seeds)();
        for (i, s) in seeds.iter().enumerate() {
            std::fs::write(dir.join(format!("seed-{i:02}")), s).expect("writes seed");
        }
        println!("{}: {} seeds in {}", t.name, seeds.len(), dir.display());
    }
    ExitCode::SUCCESS
}

/// The targets side by side, one a core (each run is seeded per target, so
/// the order they run in changes nothing); the table in the list's order.
/// `minutes` is the whole run's budget, shared out between the targets.
fn smoke_run(targets: &[&Target], execs: u64, minutes: Option<u64>, seed: u64) -> ExitCode {
    let mut corpora = Vec::with_capacity(targets.len());
    for t in targets {
        match smoke::load_corpus(&fuzz_dir().join("corpus"), t) {
            Ok(c) if !c.is_empty() => corpora.push(c),
            Ok(_) | Err(_) => {
                eprintln!(
                    "{}: no seed corpus in fuzz/corpus/{} (run `hammer-fuzz seeds`)",
                    t.name, t.name
                );
                return ExitCode::from(2);
            }
        }
    }
    let next = std::sync::atomic::AtomicUsize::new(0);
    let workers = std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(targets.len());
    let rounds = targets.len().div_ceil(workers.max(1)).max(1) as u64;
    let deadline = minutes.map(|m| Duration::from_secs(m * 60 / rounds));
    let artifacts = fuzz_dir().join("artifacts");
    // Each worker takes the next target until none is left; the results
    // come back with their index and are put in the list's order.
    let mut results: Vec<(usize, smoke::RunStats)> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers)
            .map(|_| {
                scope.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(t) = targets.get(i) else { break done };
                        done.push((i, smoke::run(t, corpora[i].clone(), execs, deadline, seed, &artifacts)));
                    }
                })
            })
            .collect();
        handles.into_iter().flat_map(|h| h.join().unwrap_or_default()).collect()
    });
    results.sort_by_key(|(i, _)| *i);
    if results.len() != targets.len() {
        eprintln!("a fuzz worker stopped before its targets were run");
        return ExitCode::from(2);
    }
    let (mut total, mut failed) = (0u64, 0usize);
    println!(
        "{:<10} {:>12} {:>9} {:>11} {:>9} {:>5}  findings",
        "target", "executions", "seconds", "exec/s", "outcomes", "pool"
    );
    for (_, s) in &results {
        let secs = s.elapsed.as_secs_f64();
        println!(
            "{:<10} {:>12} {:>9.1} {:>11.0} {:>9} {:>5}  {}",
            s.target,
            s.executions,
            secs,
            s.executions as f64 / secs.max(1e-9),
            s.outcomes,
            s.pool,
            s.findings.len()
        );
        for f in &s.findings {
            println!("  PANIC {}: {}", f.input_path.display(), f.message);
        }
        total += s.executions;
        failed += s.findings.len();
    }
    println!("fuzz smoke: {total} executions, {failed} findings");
    if failed > 0 {
        ExitCode::from(1)
    } else {
        ExitCode::SUCCESS
    }
}
