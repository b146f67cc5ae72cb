//! The architecture's rules, checked on the source tree (issue 11):
//! - outside tests, docs and the effect's own files, no source names an
//!   effect as a string literal (everything goes through the registry);
//! - no function of the diagnosis longer than 120 lines, and no source file
//!   longer than 700 lines of code (its test module excluded);
//! - the wire crate does not depend on the estimator; the app's tests do not
//!   pull in the host's terminal, plotting or serial-port crates;
//! - the `hammer` binary sits on the library crates (issue 32): no crate's
//!   `src` holds more than 25 % of the project's lines of Rust, the
//!   diagnosis library has no argument parser, terminal or plotting, and its
//!   stages do not import the engine that runs them; the simulator's
//!   configuration does not import the run, the sensor chain or the
//!   estimation path built on it.

use std::path::{Path, PathBuf};
use std::process::Command;

use hammer_sim::effects::EFFECT_NAMES;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// Every `.rs` file of the workspace's crates and the firmware, outside
/// `tests/` folders, benches, examples and build output.
fn sources() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else { return };
        for e in entries.flatten() {
            let p = e.path();
            let name = e.file_name().to_string_lossy().to_string();
            if p.is_dir() {
                if !matches!(
                    name.as_str(),
                    "target" | "tests" | "benches" | "examples" | "fixtures" | ".git" | "fuzz"
                ) {
                    walk(&p, out);
                }
            } else if name.ends_with(".rs") {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    for top in ["types", "estimator", "wire", "app", "host-tools", "firmware", "xtask"] {
        walk(&root().join(top), &mut out);
    }
    assert!(out.len() > 50, "found {} sources", out.len());
    out
}

/// The code of a file: what comes before its `#[cfg(test)]` module.
fn code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    match text.find("\n#[cfg(test)]") {
        Some(at) => text[..at].to_string(),
        None => text,
    }
}

fn rel(path: &Path) -> String {
    path.strip_prefix(root()).unwrap().display().to_string()
}

#[test]
fn no_source_names_an_effect_outside_its_own_files() {
    let mut found = vec![];
    // The crates below the simulator cannot know the catalogue (the
    // estimator's `accel_zero_shift` is its flag's name, not the effect's).
    for path in sources().into_iter().filter(|p| {
        let r = rel(p);
        r.starts_with("host-tools") || r.starts_with("xtask")
    }) {
        let stem = path.file_stem().unwrap().to_string_lossy().to_string();
        let in_effects = path.parent().is_some_and(|d| d.ends_with("effects"));
        let text = code(&path);
        for name in EFFECT_NAMES {
            if in_effects && stem == name {
                continue;
            }
            if text.contains(&format!("\"{name}\"")) || text.contains(&format!("\"{name}:")) {
                found.push(format!("{}: \"{name}\"", rel(&path)));
            }
        }
    }
    assert!(
        found.is_empty(),
        "effect names as string literals:\n{}",
        found.join("\n")
    );
}

/// (length in lines, name) of every `fn` in `text`, by rustfmt's layout: a
/// function ends at the first `}` line at its own indentation.
fn functions(text: &str) -> Vec<(usize, String)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = vec![];
    for (i, l) in lines.iter().enumerate() {
        let t = l.trim_start();
        let indent = l.len() - t.len();
        let after_vis = t
            .strip_prefix("pub ")
            .or_else(|| t.strip_prefix("pub(crate) "))
            .or_else(|| t.strip_prefix("pub(super) "))
            .or_else(|| t.strip_prefix("pub(in crate::diagnose) "))
            .unwrap_or(t);
        let Some(sig) = after_vis.strip_prefix("fn ") else {
            continue;
        };
        if l.trim_end().ends_with(';') {
            continue; // a trait's declaration
        }
        let name: String = sig.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        let close = format!("{}}}", " ".repeat(indent));
        if t.contains('{') && t.trim_end().ends_with('}') {
            out.push((1, name));
            continue;
        }
        let end = lines[i..]
            .iter()
            .position(|x| x.trim_end() == close)
            .map_or(lines.len(), |k| i + k);
        out.push((end - i + 1, name));
    }
    out
}

#[test]
fn the_diagnosis_has_no_function_over_120_lines_and_no_file_over_700() {
    let mut long = vec![];
    for path in sources() {
        let text = code(&path);
        let n = text.lines().count();
        if n > 700 {
            long.push(format!("{}: {n} lines", rel(&path)));
        }
        let r = rel(&path);
        if r.starts_with("host-tools/diagnose/src") || r.starts_with("host-tools/src/diagnose") {
            for (len, name) in functions(&text) {
                if len > 120 {
                    long.push(format!("{}: fn {name} has {len} lines", rel(&path)));
                }
            }
        }
    }
    assert!(long.is_empty(), "too long:\n{}", long.join("\n"));
}

#[test]
fn the_function_measure_counts_what_rustfmt_wrote() {
    let text = "fn a() {\n    x;\n}\n    fn c() -> u8 { 1 }\n\npub fn b(\n    y: u8,\n) -> u8 {\n    if y > 0 {\n        1\n    } else {\n        2\n    }\n}\n";
    assert_eq!(
        functions(text),
        vec![(3, "a".to_string()), (1, "c".to_string()), (9, "b".to_string())]
    );
}

/// The packages a package depends on (normal edges, plus dev edges if asked), by name.
fn dependencies(package: &str, dev: bool) -> Vec<String> {
    let edges = if dev { "normal,dev" } else { "normal" };
    let out = Command::new(env!("CARGO"))
        .args([
            "tree",
            "--offline",
            "-p",
            package,
            "-e",
            edges,
            "--prefix",
            "none",
            "--format",
            "{p}",
        ])
        .current_dir(root())
        .output()
        .expect("cargo tree runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(String::from))
        .collect()
}

#[test]
fn the_wire_stands_apart_from_the_estimator_and_the_app_from_the_host() {
    let wire = dependencies("hammer-wire", false);
    assert!(wire.iter().any(|d| d == "postcard"), "{wire:?}");
    assert!(
        !wire.iter().any(|d| d == "hammer-estimator"),
        "hammer-wire depends on the estimator: {wire:?}"
    );
    let app = dependencies("hammer-app", true);
    assert!(app.iter().any(|d| d == "hammer-sim"), "{app:?}");
    for host_only in ["ratatui", "plotters", "serialport", "hammer-host"] {
        assert!(
            !app.iter().any(|d| d == host_only),
            "hammer-app's tests pull in {host_only}"
        );
    }
}

/// Every tracked `.rs` file of the repository with its line count, counted as
/// `git ls-files '*.rs' | xargs cat | wc -l` counts them.
fn rust_lines() -> Vec<(String, usize)> {
    let out = Command::new("git")
        .args(["ls-files", "-z", "*.rs"])
        .current_dir(root())
        .output()
        .expect("git runs");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout)
        .split('\0')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let text = std::fs::read_to_string(root().join(p)).unwrap_or_default();
            (p.to_string(), text.lines().count())
        })
        .collect()
}

#[test]
fn no_crate_source_holds_more_than_a_quarter_of_the_rust() {
    let files = rust_lines();
    let total: usize = files.iter().map(|(_, n)| n).sum();
    assert!(total > 10_000, "counted {total} lines of Rust");
    let mut per_src = std::collections::BTreeMap::<String, usize>::new();
    for (path, n) in &files {
        // A crate's sources: the path up to its `src` folder.
        let src = if path.starts_with("src/") {
            Some("src".to_string())
        } else {
            path.find("/src/").map(|at| path[..at + 4].to_string())
        };
        if let Some(src) = src {
            *per_src.entry(src).or_default() += n;
        }
    }
    assert!(per_src.contains_key("host-tools/src"), "{per_src:?}");
    assert!(per_src.contains_key("host-tools/diagnose/src"), "{per_src:?}");
    let over: Vec<String> = per_src
        .iter()
        .filter(|(_, &n)| 4 * n > total)
        .map(|(src, n)| {
            format!(
                "{src}: {n} of {total} lines ({:.1} %)",
                100.0 * *n as f64 / total as f64
            )
        })
        .collect();
    assert!(over.is_empty(), "over a quarter of the Rust:\n{}", over.join("\n"));
}

#[test]
fn the_binary_sits_on_the_library_crates_and_the_diagnosis_has_no_interface() {
    let host = dependencies("hammer-host", false);
    for lib in [
        "hammer-diagnose",
        "hammer-fleet",
        "hammer-link",
        "hammer-sim",
        "hammer-trace",
    ] {
        assert!(
            host.iter().any(|d| d == lib),
            "hammer-host does not use {lib}: {host:?}"
        );
    }
    let diagnose = dependencies("hammer-diagnose", false);
    assert!(diagnose.iter().any(|d| d == "hammer-sim"), "{diagnose:?}");
    for ui in ["clap", "ratatui", "plotters", "indicatif", "hammer-host"] {
        assert!(!diagnose.iter().any(|d| d == ui), "hammer-diagnose depends on {ui}");
    }
    for lib in ["hammer-fleet", "hammer-link"] {
        let deps = dependencies(lib, false);
        for ui in ["ratatui", "plotters", "hammer-host", "hammer-diagnose"] {
            assert!(!deps.iter().any(|d| d == ui), "{lib} depends on {ui}");
        }
    }
}

#[test]
fn the_diagnosis_stages_do_not_import_the_engine() {
    let dir = root().join("host-tools/diagnose/src");
    let mut found = vec![];
    for path in sources().into_iter().filter(|p| p.starts_with(&dir)) {
        let r = rel(&path);
        let name = path.file_stem().unwrap().to_string_lossy().to_string();
        // Imports, not the doc comments' links.
        let text: String = code(&path)
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        // Everything but the engine and what proves it (the benchmarks) sits below the engine.
        if !matches!(name.as_str(), "engine" | "bench" | "isolability" | "lib")
            && (text.contains("crate::engine") || text.contains("super::engine"))
        {
            found.push(format!("{r} imports the engine"));
        }
        // The bottom rows import no stage, statistics or model.
        if matches!(name.as_str(), "report" | "options" | "input" | "stages" | "fit") {
            for above in ["pipeline", "fitset", "model", "effects", "features", "gap"] {
                if text.contains(&format!("super::{above}")) || text.contains(&format!("crate::{above}")) {
                    found.push(format!("{r} imports {above}"));
                }
            }
        }
        // The candidate models, then the statistics, then the effects'
        // hooks (which read the fit set and run the model): one way.
        let above: &[&str] = match name.as_str() {
            "model" => &["fitset", "effects", "pipeline"],
            "fitset" => &["effects", "pipeline"],
            _ => &[],
        };
        for a in above {
            if text.contains(&format!("super::{a}")) || text.contains(&format!("crate::{a}")) {
                found.push(format!("{r} imports {a}"));
            }
        }
    }
    assert!(found.is_empty(), "imports against the layers:\n{}", found.join("\n"));
}

#[test]
fn the_simulators_configuration_sits_below_its_run() {
    let dir = root().join("host-tools/sim/src");
    let mut found = vec![];
    for name in ["params", "sensor_model", "effects/mod", "gas", "config"] {
        let path = dir.join(format!("{name}.rs"));
        if !path.exists() {
            continue;
        }
        let text: String = code(&path)
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        for above in ["run", "sensor", "estimation", "simulate", "model"] {
            for prefix in ["crate::", "super::"] {
                if text.contains(&format!("{prefix}{above}::")) || text.contains(&format!("{prefix}{above};")) {
                    found.push(format!("{name}.rs imports {above}"));
                }
            }
        }
    }
    assert!(found.is_empty(), "imports against the layers:\n{}", found.join("\n"));
}
