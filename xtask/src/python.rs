//! `cargo xtask ci`'s Python step (issue 32): the package in `python/`
//! built once, by `pip install ./python`, into a fresh virtualenv, imported,
//! and tested with pytest (`python/tests`, which also runs every block of
//! docs/python.md) against the `hammer` CLI the workspace's tests built.
//!
//! The virtualenv sees the system's site-packages, where `.ci/run` put the
//! pinned maturin, pytest, matplotlib, numpy and pyarrow: nothing is
//! downloaded here, and the wheel is built by the pinned maturin
//! (`--no-build-isolation`).

use std::collections::BTreeSet;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

/// Adds pytest's closing counts (`3 failed, 12 passed in 4.2s`) to `totals`.
fn count(line: &str, totals: &mut (u64, u64)) {
    let words: Vec<&str> = line
        .trim_matches(|c: char| c == '=' || c.is_whitespace())
        .split([',', ' '])
        .collect();
    for w in words.windows(2) {
        let n = w[0].parse::<u64>().unwrap_or(0);
        match w[1] {
            "passed" => totals.0 += n,
            "failed" | "error" | "errors" => totals.1 += n,
            _ => {}
        }
    }
}

/// The compiled crates in CI's profile's dependency directory, by
/// file name (`libserde-<hash>.rlib`): each name is one unit of the build.
fn deps(target: &Path) -> BTreeSet<String> {
    std::fs::read_dir(target.join(crate::CI_PROFILE).join("deps"))
        .map(|dir| {
            dir.filter_map(Result::ok)
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".rlib") || n.ends_with(".so"))
                .collect()
        })
        .unwrap_or_default()
}

/// The crates the wheel's build compiled (files in `after` and not in
/// `before`), and those of them compiled apart from the workspace's build:
/// besides the extension and pyo3, each one is a feature host-tools/unify
/// does not yet even out, and costs CI its compile.
fn compiled_apart(before: &BTreeSet<String>, after: &BTreeSet<String>) -> (BTreeSet<String>, Vec<String>) {
    let crate_of = |n: &str| {
        let stem = n.strip_prefix("lib").unwrap_or(n);
        stem.rsplit_once('-').map_or(stem, |(c, _)| c).to_string()
    };
    let new: BTreeSet<String> = after.difference(before).map(|n| crate_of(n)).collect();
    let own = |c: &str| {
        c.starts_with("pyo3") || c.starts_with("_native") || matches!(c, "hammer_monitor_py" | "target_lexicon")
    };
    let apart = new.iter().filter(|c| !own(c)).cloned().collect();
    (new, apart)
}

fn report_compiled(before: &BTreeSet<String>, after: &BTreeSet<String>) {
    let (new, apart) = compiled_apart(before, after);
    let named = if apart.is_empty() {
        String::new()
    } else {
        format!(" ({}): host-tools/unify/Cargo.toml can even them out", apart.join(", "))
    };
    eprintln!(
        "xtask: the wheel's build compiled {} crates, {} of them apart from the workspace's build{named}",
        new.len(),
        apart.len()
    );
}

/// `cargo xtask python`: the wheel built, then its tests.
pub fn run(root: &Path, totals: &mut (u64, u64)) -> Result<(), String> {
    build(root)?;
    test(root, totals)
}

/// The fresh virtualenv the wheel is installed into.
fn venv(root: &Path) -> PathBuf {
    root.join("target/python-venv")
}

/// The virtualenv's interpreter.
fn venv_python(root: &Path) -> String {
    venv(root).join("bin/python").to_string_lossy().into_owned()
}

/// The `hammer` CLI the workspace's tests built, which pytest runs.
fn hammer(root: &Path) -> Result<PathBuf, String> {
    let hammer = crate::target_dir(root).join(crate::CI_PROFILE).join("hammer");
    if hammer.is_file() {
        Ok(hammer)
    } else {
        Err(format!(
            "{}: no hammer binary (the workspace's tests build it)",
            hammer.display()
        ))
    }
}

/// A fresh virtualenv with the wheel built and installed into it: no clock
/// in it, so CI builds it in its second lane (`lane.rs`).
pub fn build(root: &Path) -> Result<(), String> {
    let target = crate::target_dir(root);
    hammer(root)?;
    let venv = venv(root);
    if venv.exists() {
        std::fs::remove_dir_all(&venv).map_err(|e| format!("{}: {e}", venv.display()))?;
    }
    let venv_arg = venv.to_string_lossy().into_owned();
    crate::run(root, "python3", &["-m", "venv", "--system-site-packages", &venv_arg])?;
    let python = venv_python(root);
    // python/ is a workspace member and host-tools/unify evens out its
    // features: maturin's cargo finds the workspace's artifacts in the same
    // target directory and compiles little more than the extension itself.
    // maturin's build backend takes cargo's options from the environment:
    // the wheel is built in CI's profile, beside the workspace's artifacts.
    let before = deps(&target);
    let pep517_args = format!("--profile {}", crate::CI_PROFILE);
    eprintln!(
        "xtask: ({}) MATURIN_PEP517_ARGS=\"{pep517_args}\" {python} -m pip install ./python",
        root.display()
    );
    let status = Command::new(&python)
        .args(["-m", "pip", "install", "--no-build-isolation", "--quiet", "./python"])
        .env("MATURIN_PEP517_ARGS", &pep517_args)
        .current_dir(root)
        .status()
        .map_err(|e| format!("cannot start {python}: {e}"))?;
    if !status.success() {
        return Err(format!("the Python package's wheel did not build ({status})"));
    }
    report_compiled(&before, &deps(&target));
    Ok(())
}

/// The package imported and pytest against it, at the normal priority: a
/// test times an interrupt, and the FMU's runs have a time limit.
pub fn test(root: &Path, totals: &mut (u64, u64)) -> Result<(), String> {
    let hammer = hammer(root)?;
    let python = venv_python(root);
    crate::run(root, &python, &["-c", "import hammer_monitor"])?;
    eprintln!("xtask: ({}) {python} -m pytest python/tests", root.display());
    let mut child = Command::new(&python)
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider", "python/tests"])
        .env("HAMMER_BIN", &hammer)
        .env("MPLBACKEND", "Agg")
        .current_dir(root)
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start pytest: {e}"))?;
    let stdout = child.stdout.take().expect("piped");
    let mut last = String::new();
    for line in BufReader::new(stdout).lines() {
        let line = line.map_err(|e| e.to_string())?;
        println!("{line}");
        if line.contains(" passed") || line.contains(" failed") || line.contains(" error") {
            last = line;
        }
    }
    count(&last, totals);
    let status = child.wait().map_err(|e| e.to_string())?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("pytest python/tests failed ({status})"))
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn pytests_closing_line_is_counted() {
        let mut t = (0, 0);
        super::count("1 failed, 15 passed, 2 warnings in 40.12s", &mut t);
        assert_eq!(t, (15, 1));
        super::count("=== 16 passed in 3.1s ===", &mut t);
        assert_eq!(t, (31, 1));
        super::count("2 errors in 0.4s", &mut t);
        assert_eq!(t, (31, 3));
    }

    #[test]
    fn a_shared_crate_compiled_again_is_named_and_pyo3_is_not() {
        let set = |names: &[&str]| names.iter().map(|n| n.to_string()).collect();
        let before = set(&["libserde-1a2b.rlib", "libhammer_sim-3c4d.rlib"]);
        let after = set(&[
            "libserde-1a2b.rlib",
            "libhammer_sim-3c4d.rlib",
            "libhammer_sim-9f9f.rlib",
            "libpyo3-5e6f.rlib",
            "libpyo3_macros-7a7a.so",
            "lib_native.so",
        ]);
        let (new, apart) = super::compiled_apart(&before, &after);
        assert_eq!(new.len(), 4, "{new:?}");
        assert_eq!(apart, vec!["hammer_sim".to_string()]);
        assert!(super::compiled_apart(&after, &after).0.is_empty());
    }
}
