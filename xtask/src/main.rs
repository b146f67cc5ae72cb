//! Project automation. `cargo xtask ci` is the one command that runs every
//! test: host tests, the no_std estimator built for the target, the firmware.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};

const TARGET: &str = "thumbv7em-none-eabihf";

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("xtask lives in the workspace")
        .to_path_buf()
}

fn run(dir: &Path, program: &str, args: &[&str]) -> Result<(), String> {
    eprintln!("xtask: ({}) {program} {}", dir.display(), args.join(" "));
    let status = Command::new(program)
        .args(args)
        .current_dir(dir)
        .status()
        .map_err(|e| format!("cannot start {program}: {e}"))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{program} {}` failed ({status})", args.join(" ")))
    }
}

/// Runs `cargo test` passing its output through and adds up its `test result` lines.
fn cargo_test(dir: &Path, args: &[&str], totals: &mut (u64, u64)) -> Result<(), String> {
    eprintln!("xtask: ({}) cargo {}", dir.display(), args.join(" "));
    let mut child = Command::new("cargo")
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::piped())
        .spawn()
        .map_err(|e| format!("cannot start cargo: {e}"))?;
    let stdout = child.stdout.take().expect("piped");
    for line in BufReader::new(stdout).lines() {
        let line = line.map_err(|e| e.to_string())?;
        println!("{line}");
        if let Some(rest) = line.strip_prefix("test result: ") {
            let count = |word: &str| {
                rest.split(';')
                    .find_map(|part| {
                        part.trim().strip_suffix(word).map(|n| {
                            n.trim()
                                .trim_start_matches("ok. ")
                                .trim_start_matches("FAILED. ")
                                .parse::<u64>()
                                .unwrap_or(0)
                        })
                    })
                    .unwrap_or(0)
            };
            totals.0 += count("passed");
            totals.1 += count("failed");
        }
    }
    let status = child.wait().map_err(|e| e.to_string())?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`cargo {}` failed ({status})", args.join(" ")))
    }
}

/// Builds the firmware from its own folder: cargo reads `.cargo/config.toml`
/// (target, linker scripts) from the directory it runs in.
fn firmware(args: &[&str]) -> Result<(), String> {
    run(&root().join("firmware"), "cargo", args)
}

fn ci() -> Result<(), String> {
    let root = root();
    run(&root, "cargo", &["fmt", "--all", "--", "--check"])?;
    run(&root.join("firmware"), "cargo", &["fmt", "--", "--check"])?;
    // The estimator must stay no_std and build for the Cortex-M4F.
    run(
        &root,
        "cargo",
        &["build", "--release", "-p", "hammer-estimator", "--target", TARGET],
    )?;
    firmware(&["build", "--release"])?;
    let mut totals = (0, 0);
    let mut result = cargo_test(&root, &["test", "--workspace", "--release"], &mut totals);
    // Once more with overflow checks on (the test profile): arithmetic that
    // would wrap on bad input must not hide behind release mode.
    if result.is_ok() {
        result = cargo_test(&root, &["test", "-p", "hammer-estimator"], &mut totals);
    }
    // The closing line CI reads.
    println!("xtask: {} passed, {} failed", totals.0, totals.1);
    result
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("ci") => ci(),
        Some("firmware") => firmware(&["build", "--release"]),
        _ => Err("usage: cargo xtask <ci|firmware>\n  ci        every test: fmt, host tests, no_std target build, firmware build\n  firmware  build the firmware for the reference board".into()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}
