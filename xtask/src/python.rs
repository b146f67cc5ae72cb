//! `cargo xtask ci`'s Python step (issue 32): the package in `python/`
//! built once, by `pip install ./python`, into a fresh virtualenv, imported,
//! and tested with pytest (`python/tests`, which also runs every block of
//! docs/python.md) against the `hammer` CLI the workspace's tests built.
//!
//! The virtualenv sees the system's site-packages, where `.ci/run` put the
//! pinned maturin, pytest, matplotlib, numpy and pyarrow: nothing is
//! downloaded here, and the wheel is built by the pinned maturin
//! (`--no-build-isolation`).

use std::io::{BufRead, BufReader};
use std::path::Path;
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

pub fn run(root: &Path, totals: &mut (u64, u64)) -> Result<(), String> {
    let target = std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root.join("target"), Into::into);
    let hammer = target.join("release/hammer");
    if !hammer.is_file() {
        return Err(format!(
            "{}: no hammer binary (the workspace's tests build it)",
            hammer.display()
        ));
    }
    let venv = root.join("target/python-venv");
    if venv.exists() {
        std::fs::remove_dir_all(&venv).map_err(|e| format!("{}: {e}", venv.display()))?;
    }
    let venv_arg = venv.to_string_lossy().into_owned();
    crate::run(root, "python3", &["-m", "venv", "--system-site-packages", &venv_arg])?;
    let python = venv.join("bin/python").to_string_lossy().into_owned();
    // The extension's final artifacts in a directory of its own (python/
    // has its own Cargo.lock), its intermediate ones in the workspace's
    // build directory: the dependencies both resolve alike, with the same
    // release profile, are built once.
    std::env::set_var("CARGO_TARGET_DIR", root.join("target/python"));
    std::env::set_var("CARGO_BUILD_BUILD_DIR", &target);
    let built = crate::run(
        root,
        &python,
        &["-m", "pip", "install", "--no-build-isolation", "--quiet", "./python"],
    );
    std::env::set_var("CARGO_TARGET_DIR", &target);
    std::env::remove_var("CARGO_BUILD_BUILD_DIR");
    built?;
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
}
