//! Project automation. `cargo xtask ci` is the one command that runs every
//! test: host tests, the no_std estimator built for the target, the firmware.

mod elf;

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

/// The firmware binaries: (name, ELF path).
fn firmware_elves() -> [(&'static str, PathBuf); 2] {
    let dir = root().join("firmware/target").join(TARGET).join("release");
    [
        ("reference board (Nucleo-G474RE)", dir.join("hammer-firmware")),
        ("emulated board (QEMU mps2-an386)", dir.join("hammer-firmware-emu")),
    ]
}

/// Both boards, one cargo run each: built together, cargo would unify the
/// reference board's defmt features into the emulated board's dependencies.
fn build_firmware() -> Result<(), String> {
    firmware(&["build", "--release", "-p", "hammer-firmware"])?;
    firmware(&["build", "--release", "-p", "hammer-firmware-emu"])?;
    size()
}

fn size() -> Result<(), String> {
    for (name, path) in firmware_elves() {
        let s = elf::sizes(&path)?;
        println!(
            "{name}: flash {} bytes ({:.1} KiB), static RAM {} bytes ({:.1} KiB)",
            s.flash,
            s.flash as f64 / 1024.0,
            s.ram,
            s.ram as f64 / 1024.0
        );
    }
    Ok(())
}

fn ci() -> Result<(), String> {
    let root = root();
    run(&root, "cargo", &["fmt", "--all", "--", "--check"])?;
    run(&root.join("firmware"), "cargo", &["fmt", "--all", "--", "--check"])?;
    // The estimator must stay no_std and build for the Cortex-M4F.
    run(
        &root,
        "cargo",
        &["build", "--release", "-p", "hammer-estimator", "--target", TARGET],
    )?;
    build_firmware()?;
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

const USAGE: &str = "usage: cargo xtask <command>
  ci              every test: formatting, firmware build, host and emulator tests
  firmware        build both firmware binaries and print their flash and RAM
  size            flash and static RAM of the built firmware binaries
  bench-firmware  estimator cost on the Cortex-M4 ISA under QEMU (-icount), with sizes";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("ci") => ci(),
        Some("firmware") => build_firmware(),
        Some("size") => size(),
        Some("bench-firmware") => {
            build_firmware().and_then(|_| run(&root(), "cargo", &["bench", "-p", "hammer-host", "--bench", "firmware"]))
        }
        _ => Err(USAGE.into()),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}
