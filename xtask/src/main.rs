//! Project automation. `cargo xtask ci` is the one command that runs every
//! test: host tests, the no_std estimator built for the target, the firmware.
//! Its stages and their measured times: docs/ci.md.
//!
//! - `main.rs`: the commands, the stages of `ci`, the firmware's build and
//!   budgets;
//! - `lane.rs`: CI's second lane, the work without a clock beside the tests;
//! - `python.rs`: the Python package's wheel and its tests;
//! - `ninth_effect.rs`: a test effect added through the registry alone;
//! - `elf.rs`: sizes and symbols read off the firmware's ELF files.

mod elf;
mod lane;
mod ninth_effect;
mod python;

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

/// The workspace's target directory: `CARGO_TARGET_DIR` if set.
pub(crate) fn target_dir(root: &Path) -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR").map_or_else(|| root.join("target"), PathBuf::from)
}

pub(crate) fn run(dir: &Path, program: &str, args: &[&str]) -> Result<(), String> {
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
pub(crate) fn cargo_test(dir: &Path, args: &[&str], totals: &mut (u64, u64)) -> Result<(), String> {
    counted(dir, args, &[], Stream::Stdout, totals, &mut test_result)
}

/// [`cargo_test`] with `envs` set for cargo alone (never in xtask's own
/// environment, which other threads' commands inherit).
pub(crate) fn cargo_test_with(
    dir: &Path,
    args: &[&str],
    envs: &[(&str, &Path)],
    totals: &mut (u64, u64),
) -> Result<(), String> {
    counted(dir, args, envs, Stream::Stdout, totals, &mut test_result)
}

/// Passed and failed off a `test result: ok. N passed; M failed; …` line.
fn test_result(line: &str) -> Option<(u64, u64)> {
    let rest = line.strip_prefix("test result: ")?;
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
    Some((count("passed"), count("failed")))
}

/// The stream a test runner writes its results to.
enum Stream {
    Stdout,
    Stderr,
}

/// Runs `cargo args` in `dir` passing `stream`
/// through, and adds to `totals` what `count` reads off its lines (passed,
/// failed), whether or not the run fails.
fn counted(
    dir: &Path,
    args: &[&str],
    envs: &[(&str, &Path)],
    stream: Stream,
    totals: &mut (u64, u64),
    count: &mut dyn FnMut(&str) -> Option<(u64, u64)>,
) -> Result<(), String> {
    eprintln!("xtask: ({}) cargo {}", dir.display(), args.join(" "));
    let mut cmd = Command::new("cargo");
    cmd.args(args).current_dir(dir).envs(envs.iter().copied());
    match stream {
        Stream::Stdout => cmd.stdout(Stdio::piped()),
        Stream::Stderr => cmd.stderr(Stdio::piped()),
    };
    let mut child = cmd.spawn().map_err(|e| format!("cannot start cargo: {e}"))?;
    let out: Box<dyn std::io::Read> = match stream {
        Stream::Stdout => Box::new(child.stdout.take().expect("piped")),
        Stream::Stderr => Box::new(child.stderr.take().expect("piped")),
    };
    // Lossy lines: a test's stray bytes must not stop the reading (and with
    // it the count) before cargo is done.
    let mut reader = BufReader::new(out);
    let mut bytes = vec![];
    loop {
        bytes.clear();
        if reader.read_until(b'\n', &mut bytes).map_err(|e| e.to_string())? == 0 {
            break;
        }
        let text = String::from_utf8_lossy(&bytes);
        let line = text.trim_end_matches(['\n', '\r']);
        match stream {
            Stream::Stdout => println!("{line}"),
            Stream::Stderr => eprintln!("{line}"),
        }
        if let Some((passed, failed)) = count(line) {
            totals.0 += passed;
            totals.1 += failed;
        }
    }
    let status = child.wait().map_err(|e| e.to_string())?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`cargo {}` failed ({status})", args.join(" ")))
    }
}

/// The cargo profile CI builds the workspace in (Cargo.toml's
/// `[profile.ci]`): release, with other people's crates unoptimised (half
/// of the build's time, none of the physics' hot path). Its artifacts land
/// in `target/ci/`; the Python step and the ninth effect build in it too,
/// so that nothing is compiled twice.
pub const CI_PROFILE: &str = "ci";

/// The workspace's tests. With cargo-nextest on the machine, every test
/// binary runs side by side, the slowest first (`.config/nextest.toml`),
/// after the doc-tests (which nextest does not run), and `started_tests` is
/// called once nextest's build is done; without it, `cargo test` runs the
/// binaries one after another.
fn workspace_tests(root: &Path, totals: &mut (u64, u64), started_tests: &mut dyn FnMut()) -> Result<(), String> {
    let started = std::time::Instant::now();
    let has_nextest = Command::new("cargo")
        .args(["nextest", "--version"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    let result = if has_nextest {
        // The doc-tests first: their cargo call takes the build's lock,
        // which the second lane's builds hold once it has started.
        let docs = cargo_test(root, &["test", "--workspace", "--profile", CI_PROFILE, "--doc"], totals);
        // nextest's own cargo call is done when it says it is starting.
        let mut count = |line: &str| {
            if nextest_started(line) {
                started_tests();
            }
            nextest_summary(line)
        };
        // Without colour: the lines read here must start with their words.
        let run = counted(
            root,
            &[
                "nextest",
                "run",
                "--workspace",
                "--cargo-profile",
                CI_PROFILE,
                "--no-fail-fast",
                "--color",
                "never",
            ],
            &[],
            Stream::Stderr,
            totals,
            &mut count,
        );
        docs.and(run)
    } else {
        eprintln!("xtask: cargo-nextest not found: the test binaries run one after another");
        cargo_test(root, &["test", "--workspace", "--profile", CI_PROFILE], totals)
    };
    eprintln!(
        "xtask: the workspace's tests took {:.0} s",
        started.elapsed().as_secs_f64()
    );
    result
}

/// nextest's line before its first test, `Starting 445 tests across 58
/// binaries (2 tests skipped)`: its cargo call is done by then.
fn nextest_started(line: &str) -> bool {
    line.trim_start()
        .strip_prefix("Starting ")
        .is_some_and(|rest| rest.contains(" tests across ") || rest.contains(" test across "))
}

/// Passed and failed (timed out counted as failed) off nextest's closing
/// line, `Summary [ 631.051s] 419 tests run: 417 passed (3 slow), 1
/// failed, 1 timed out, 2 skipped`.
fn nextest_summary(line: &str) -> Option<(u64, u64)> {
    let (_, rest) = line.trim_start().strip_prefix("Summary [")?.split_once(" run:")?;
    let mut sum = (0, 0);
    for part in rest.split(',') {
        let mut words = part.split_whitespace();
        let n = words.next().and_then(|n| n.parse::<u64>().ok()).unwrap_or(0);
        match words.next() {
            Some("passed") => sum.0 += n,
            Some("failed") | Some("timed") => sum.1 += n,
            _ => {}
        }
    }
    Some(sum)
}

/// Builds the firmware from its own folder: cargo reads `.cargo/config.toml`
/// (target, linker scripts) from the directory it runs in.
/// Its own target folder whatever `CARGO_TARGET_DIR` says: the benches and
/// tests find the images there (`firmware_elves`, `hammer_host::emulator`).
fn firmware(args: &[&str]) -> Result<(), String> {
    let dir = root().join("firmware");
    let target_dir = dir.join("target");
    let mut with_dir: Vec<&str> = args.to_vec();
    let target_dir = target_dir.to_string_lossy();
    with_dir.extend(["--target-dir", &target_dir]);
    run(&dir, "cargo", &with_dir)
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
    // The reference board links with flip-link (firmware/.cargo/config.toml).
    // (It has no --version of its own: it hands every argument to the linker.)
    let on_path =
        std::env::var_os("PATH").is_some_and(|p| std::env::split_paths(&p).any(|d| d.join("flip-link").is_file()));
    if !on_path {
        return Err("flip-link is not installed: `cargo install flip-link --locked` (.ci/run does this)".into());
    }
    let remap = remap_paths();
    for board in ["hammer-firmware", "hammer-firmware-emu"] {
        firmware(&["build", "--release", "-p", board, "--config", &remap])?;
    }
    size()
}

/// Source paths as the image stores them, relative: a panic's location names
/// its file, and `/root/.cargo/registry/src/index.crates.io-…/embassy-stm32-
/// 0.6.0/src/…` costs ~90 bytes of flash per file (1.4 KB in all), where
/// `embassy-stm32-0.6.0/src/…` says the same. The image then no longer
/// depends on where the checkout or the cargo home is. Passed on the command
/// line because a config file cannot name the cargo home; cargo appends it to
/// the rustflags of `firmware/.cargo/config.toml`.
fn remap_paths() -> String {
    let home = std::env::var_os("CARGO_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| Path::new(&h).join(".cargo")))
        .unwrap_or_default();
    let mut prefixes = vec![root()];
    if let Ok(dirs) = std::fs::read_dir(home.join("registry/src")) {
        prefixes.extend(dirs.filter_map(Result::ok).map(|d| d.path()));
    }
    let flags: Vec<String> = prefixes
        .iter()
        .map(|p| format!("\"--remap-path-prefix={}/=\"", p.display()))
        .collect();
    format!("target.{TARGET}.rustflags=[{}]", flags.join(","))
}

/// The budgets (issue 47): 128 KiB of flash and 96 KiB of static RAM on
/// the reference board's G474RE (512 KiB, 128 KiB), the rest of its RAM
/// left to the stack. They were 64 and 48 KiB, set as discipline for a
/// smaller part no board of the project uses; the valve's and chambers'
/// characteristics in every report need the room.
const FLASH_AIM: u64 = 128 * 1024;
const RAM_AIM: u64 = 96 * 1024;

fn size() -> Result<(), String> {
    let (mut over, mut soft_double) = (vec![], vec![]);
    for (name, path) in firmware_elves() {
        let s = elf::sizes(&path)?;
        let verdict = |v: u64, aim: u64| if v <= aim { "within" } else { "OVER" };
        println!(
            "{name}: flash {} bytes ({:.1} KiB, {} the {} KiB aim), static RAM {} bytes ({:.1} KiB, {} the {} KiB aim)",
            s.flash,
            s.flash as f64 / 1024.0,
            verdict(s.flash, FLASH_AIM),
            FLASH_AIM / 1024,
            s.ram,
            s.ram as f64 / 1024.0,
            verdict(s.ram, RAM_AIM),
            RAM_AIM / 1024
        );
        if s.flash > FLASH_AIM || s.ram > RAM_AIM {
            over.push(name);
        }
        // The FPU is single precision: a double-precision operation pulls
        // in ~2.6 KB of software routines (and is slow).
        for routine in SOFT_DOUBLE {
            if elf::symbol(&path, routine)?.is_some() {
                soft_double.push(format!("{name}: {routine}"));
            }
        }
    }
    let mut errors = vec![];
    if !over.is_empty() {
        errors.push(format!("over the budget: {}", over.join(", ")));
    }
    if !soft_double.is_empty() {
        errors.push(format!(
            "double-precision arithmetic in the firmware ({}): keep it in f32 or integers",
            soft_double.join(", ")
        ));
    }
    if errors.is_empty() {
        Ok(())
    } else {
        Err(errors.join("; "))
    }
}

/// compiler-builtins' software double-precision arithmetic.
const SOFT_DOUBLE: [&str; 3] = ["__aeabi_dadd", "__aeabi_dmul", "__aeabi_ddiv"];

/// The stack region of a board's ELF, bytes: flip-link puts it below the
/// statics, from `_stack_end` (its lowest word) up to `_stack_start`.
fn stack_region(path: &Path) -> Result<u32, String> {
    let top = elf::symbol(path, "_stack_start")?;
    let bottom = elf::symbol(path, "_stack_end")?;
    match (top, bottom) {
        (Some(t), Some(b)) if t > b => Ok(t - b),
        _ => Err(format!("{}: no _stack_start/_stack_end symbols", path.display())),
    }
}

/// `cargo xtask size`: the sizes, then each board's stack region from its
/// ELF and the high-water mark the emulated board measures on itself (its
/// painted stack) over 20 s of hammer time at full rate through the soak.
/// The reference board reports its own in every `Status` (the dashboard's
/// Device panel); it runs the same app tasks, so its mark is the emulated
/// one plus what its board layer adds (embassy-stm32's interrupt handlers,
/// nested on the same stack), which only a board can measure.
fn size_and_stack() -> Result<(), String> {
    size()?;
    let [(ref_name, ref_elf), (emu_name, emu_elf)] = firmware_elves();
    let (ref_region, emu_region) = (stack_region(&ref_elf)?, stack_region(&emu_elf)?);
    eprintln!("xtask: measuring the emulated board's stack (hammer soak, 20 s of hammer time)");
    let out = Command::new("cargo")
        .args([
            "run",
            "--release",
            "-q",
            "-p",
            "hammer-host",
            "--bin",
            "hammer",
            "--",
            "soak",
        ])
        .args(["--minutes", "0.334"])
        .current_dir(root())
        .stderr(Stdio::inherit())
        .output()
        .map_err(|e| format!("cannot start cargo: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "the soak failed ({}): is qemu-system-arm installed?",
            out.status
        ));
    }
    let text = String::from_utf8_lossy(&out.stdout);
    // "  stack: <used> B at the deepest of <reserved> B reserved ..." (host-tools/src/soak.rs).
    let used: u32 = text
        .lines()
        .find_map(|l| l.trim().strip_prefix("stack: "))
        .and_then(|l| l.split(' ').next())
        .and_then(|n| n.parse().ok())
        .ok_or_else(|| format!("no stack line in the soak's output:\n{text}"))?;
    let pct = |a: u32, b: u32| 100.0 * f64::from(a) / f64::from(b);
    println!(
        "{emu_name}: stack {used} B at the deepest of a {emu_region} B region (measured), margin {} B ({:.0} % free)",
        emu_region.saturating_sub(used),
        pct(emu_region.saturating_sub(used), emu_region)
    );
    println!(
        "{ref_name}: stack region {ref_region} B; the same app measured {used} B on the emulated board, \
         margin {} B ({:.0} % free) before the board layer's interrupt frames; the board's own mark is in its Status",
        ref_region.saturating_sub(used),
        pct(ref_region.saturating_sub(used), ref_region)
    );
    Ok(())
}

fn ci() -> Result<(), String> {
    let root = root();
    let started = std::time::Instant::now();
    // The lane's process says when its stages are done on this clock.
    let ci_started = std::time::SystemTime::now();
    let at = |stage: &str| eprintln!("xtask: {stage} done at {:.0} s", started.elapsed().as_secs_f64());
    run(&root, "cargo", &["fmt", "--all", "--", "--check"])?;
    run(&root.join("firmware"), "cargo", &["fmt", "--all", "--", "--check"])?;
    // The estimator must stay no_std and build for the Cortex-M4F.
    run(
        &root,
        "cargo",
        &["build", "--release", "-p", "hammer-estimator", "--target", TARGET],
    )?;
    // The firmware's images build beside the workspace's test binaries: the
    // firmware is a workspace and a target folder of its own, so neither
    // build waits for the other's lock, and embassy-stm32's long compile
    // leaves a core free at times. The tests need the images when they run.
    let firmware = std::thread::spawn(build_firmware);
    let built = run(
        &root,
        "cargo",
        &["test", "--workspace", "--profile", CI_PROFILE, "--no-run"],
    );
    firmware
        .join()
        .unwrap_or_else(|_| Err("the firmware's build thread panicked".into()))?;
    built?;
    at("formatting, the firmware's and the test binaries' builds");
    let mut totals = (0, 0);
    // The second lane (`lane.rs`): the fuzzing smoke run, the wheel and the
    // ninth effect, at the lowest priority beside the tests.
    let mut beside = None;
    let mut result = workspace_tests(&root, &mut totals, &mut || {
        beside.get_or_insert_with(|| lane::start(&root, ci_started));
    });
    at("the workspace's tests");
    // Without nextest, or if nextest never said it was starting, the lane
    // starts now and runs alone.
    let beside = beside.unwrap_or_else(|| {
        eprintln!("xtask: the second lane starts after the tests");
        lane::start(&root, ci_started)
    });
    let lane_end = lane::finish(beside, &mut totals);
    at("the second lane (the fuzzing smoke run, the wheel, the ninth effect)");
    // The Python package's tests against the lane's wheel
    // (python/tests, docs/python.md), whatever else failed, if it built.
    if lane_end.wheel_built {
        result = result.and(python::test(&root, &mut totals));
        at("the Python package's tests");
    } else {
        eprintln!("xtask: the Python package's wheel did not build: its tests did not run");
    }
    result = result.and(lane_end.result);
    // The closing line CI reads.
    println!("xtask: {} passed, {} failed", totals.0, totals.1);
    result
}

/// `cargo xtask fuzz`: the smoke runner, or with `--afl` AFL++ in a target
/// directory of its own (its instrumentation flags must not reach the
/// workspace's). CI runs the runner its tests built (`lane.rs`).
fn fuzz(args: &[&str]) -> Result<(), String> {
    let root = root();
    if let Some(i) = args.iter().position(|a| *a == "--afl") {
        let target = args.get(i + 1).ok_or("--afl needs a target name")?;
        let minutes: u64 = match args.iter().position(|a| *a == "--minutes") {
            Some(j) => args
                .get(j + 1)
                .and_then(|m| m.parse().ok())
                .ok_or("--minutes needs a number")?,
            None => 10,
        };
        return afl(target, minutes);
    }
    let mut cmd = vec![
        "run",
        "--release",
        "-p",
        "hammer-fuzz",
        "--bin",
        "hammer-fuzz",
        "--",
        "smoke",
    ];
    cmd.extend_from_slice(args);
    run(&root, "cargo", &cmd)
}

/// A coverage-guided run of one target with AFL++ (installs cargo-afl from
/// crates.io if missing). Findings land in `fuzz/afl/<target>/`.
fn afl(target: &str, minutes: u64) -> Result<(), String> {
    let root = root();
    let fuzz_dir = root.join("fuzz");
    let have = Command::new("cargo")
        .args(["afl", "--version"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !have {
        run(&root, "cargo", &["install", "cargo-afl", "--locked"])?;
    }
    // A target directory of its own: AFL's instrumentation flags would
    // otherwise rebuild (and replace) the workspace's artifacts.
    std::env::set_var("CARGO_TARGET_DIR", fuzz_dir.join("target"));
    run(
        &fuzz_dir,
        "cargo",
        &["afl", "build", "--release", "--features", "afl", "--bin", "afl-target"],
    )?;
    let corpus = format!("corpus/{target}");
    let out = format!("afl/{target}");
    let secs = (minutes * 60).to_string();
    std::fs::create_dir_all(fuzz_dir.join("afl")).map_err(|e| format!("fuzz/afl: {e}"))?;
    // No core dumps to wait for and no CPU governor to ask about on a CI machine.
    std::env::set_var("AFL_I_DONT_CARE_ABOUT_MISSING_CRASHES", "1");
    std::env::set_var("AFL_SKIP_CPUFREQ", "1");
    std::env::set_var("AFL_NO_UI", "1");
    run(
        &fuzz_dir,
        "cargo",
        &[
            "afl",
            "fuzz",
            "-i",
            &corpus,
            "-o",
            &out,
            "-V",
            &secs,
            "--",
            "target/release/afl-target",
            target,
        ],
    )?;
    // AFL's own account of the run, for docs/fuzzing.md.
    let stats_path = fuzz_dir.join(&out).join("default/fuzzer_stats");
    let stats = std::fs::read_to_string(&stats_path).map_err(|e| format!("{}: {e}", stats_path.display()))?;
    let field = |k: &str| {
        stats
            .lines()
            .find_map(|l| {
                l.split_once(':')
                    .filter(|(n, _)| n.trim() == k)
                    .map(|(_, v)| v.trim().to_string())
            })
            .unwrap_or_else(|| "?".into())
    };
    println!(
        "afl {target}: {} executions in {} s ({} exec/s), corpus {} ({} found), edge coverage {}, {} crashes, {} hangs",
        field("execs_done"),
        field("run_time"),
        field("execs_per_sec"),
        field("corpus_count"),
        field("corpus_found"),
        field("bitmap_cvg"),
        field("saved_crashes"),
        field("saved_hangs")
    );
    if field("saved_crashes") != "0" {
        return Err(format!("afl {target}: crashes saved in fuzz/{out}/default/crashes"));
    }
    Ok(())
}

const USAGE: &str = "usage: cargo xtask <command>
  ci              every test: formatting, firmware build, host and emulator tests, the Python package
  python          the Python package: the wheel built into a fresh virtualenv, imported, pytest against it (in CI's profile: after `cargo xtask ci` has built target/ci/hammer)
  firmware        build both firmware binaries and print their flash and RAM
  size            flash and static RAM of the built firmware binaries, each board's stack region and high-water mark (a 20 s soak)
  bench-firmware  the sampling loop's instructions per sample-set on the Cortex-M4 ISA under QEMU (-icount),
                  the same on every run, with the per-function split (a QEMU plugin) and sizes
  bench-chambers  the chamber characteristics at a cycle's close (chambers::at_close) on the Cortex-M4 ISA
                  under QEMU (-icount): instructions per reading of a 4 bar cycle, each reading checked
                  bit for bit against the host's, with the per-function split
  soak [--minutes N] [hammer soak options]
                  the emulated board at the full 100 kS/s x 3 for N minutes of hammer time (default 10):
                  overruns, lost frames, parity with the host estimator, CPU duty, worst latency
  ninth-effect    adds a test effect to a copy of the workspace through the registry alone
                  (xtask/fixtures/ninth-effect) and runs its tests: drawn, simulated, fitted
  fuzz [--execs N | --minutes M] [--seed S] [--target NAME]
                  the in-process fuzz runner over every target (CI runs 1,000,000 executions each)
  fuzz --afl NAME [--minutes M]
                  a coverage-guided AFL++ run of one target (installs cargo-afl)";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("ci") => ci(),
        Some("python") => python::run(&root(), &mut (0, 0)),
        Some("fuzz") => fuzz(&args[1..].iter().map(String::as_str).collect::<Vec<_>>()),
        Some("firmware") => build_firmware(),
        Some("size") => size_and_stack(),
        Some("ninth-effect") => ninth_effect::run(&root(), &mut (0, 0)),
        // CI's second lane, which `ci` starts (lane.rs); not for people.
        Some("ci-lane") => lane::run(&root()),
        Some("soak") => build_firmware().and_then(|_| {
            let mut cmd = vec!["run", "--release", "-p", "hammer-host", "--bin", "hammer", "--", "soak"];
            let rest: Vec<&str> = args[1..].iter().map(String::as_str).collect();
            if !rest.contains(&"--minutes") {
                cmd.extend(["--minutes", "10"]);
            }
            cmd.extend(rest);
            run(&root(), "cargo", &cmd)
        }),
        // The profiling plugin lands beside the bench, where it looks for it.
        Some("bench-firmware") => build_firmware()
            .and_then(|_| run(&root(), "cargo", &["build", "--release", "-p", "qemu-profile"]))
            .and_then(|_| run(&root(), "cargo", &["bench", "-p", "hammer-host", "--bench", "firmware"])),
        // The chamber characteristics' cost at a cycle's close (the emulated
        // board's bench binary, hammer-chambers-bench), checked against the host's.
        Some("bench-chambers") => build_firmware()
            .and_then(|_| run(&root(), "cargo", &["build", "--release", "-p", "qemu-profile"]))
            .and_then(|_| {
                run(
                    &root(),
                    "cargo",
                    &["bench", "-p", "hammer-host", "--bench", "chambers_close"],
                )
            }),
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

#[cfg(test)]
mod tests {
    /// nextest's closing line is counted, slow tests, time-outs and skips
    /// included; its other lines are not.
    #[test]
    fn nextests_closing_line_is_counted() {
        let line = "     Summary [ 631.051s] 419 tests run: 416 passed (3 slow), 2 failed, 1 timed out, 2 skipped";
        assert_eq!(super::nextest_summary(line), Some((416, 3)));
        let all = "     Summary [  15.531s] 1 test run: 1 passed, 2 skipped";
        assert_eq!(super::nextest_summary(all), Some((1, 0)));
        assert_eq!(
            super::nextest_summary("        PASS [   1.2s] (1/419) a::b summary"),
            None
        );
    }

    /// The second lane starts on nextest's line before its first test, and
    /// not on a test's own output that starts with the same word.
    #[test]
    fn nextests_start_is_its_starting_line() {
        assert!(super::nextest_started(
            "    Starting 445 tests across 58 binaries (2 tests skipped)"
        ));
        assert!(super::nextest_started("    Starting 1 test across 1 binary"));
        assert!(!super::nextest_started("Starting the broker on port 1883"));
        assert!(!super::nextest_started("        PASS [   1.2s] (1/419) a::b starting"));
    }
}
