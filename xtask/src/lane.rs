//! CI's second lane: the work that keeps no clock, started beside the
//! workspace's tests at the lowest priority (`nice -n 19`, in a process of
//! its own, `xtask ci-lane`).
//!
//! The test stage leaves a sixth of both cores idle (the drift tests' own
//! pace at its end, `.config/nextest.toml`), and the work after it (the
//! fuzzing smoke run, the Python package's wheel, the ninth effect's build
//! and tests) took three minutes of the whole run once the tests were done.
//! At nice 19 beside a busy core a process gets about 1.5 % of it, so the
//! lane takes the idle cycles and few the tests use: the tests that keep
//! time (a broker's outage, the emulated board at full rate, the drift
//! tests' windows) keep their cores.
//!
//! Nothing in the lane has a time limit. Python's tests do (one times an
//! interrupt, the FMU's runs have a per-run limit), so they run after it at
//! the normal priority, against the wheel it built.
//!
//! The lane writes to a log of its own, printed whole when it is done, so
//! that its lines do not interleave with the tests'.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::thread::JoinHandle;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The lane's process, seen from `cargo xtask ci`.
pub struct Lane {
    handle: JoinHandle<Result<(), String>>,
    log: PathBuf,
}

/// How the lane ended.
pub struct LaneEnd {
    pub result: Result<(), String>,
    /// The wheel is in the fresh virtualenv: Python's tests can run
    /// whatever failed after it.
    pub wheel_built: bool,
}

/// The variable that carries CI's start (seconds since the Unix epoch) to
/// the lane's process.
const CI_STARTED: &str = "XTASK_CI_STARTED";

/// The line the lane prints once the wheel is installed.
const WHEEL_BUILT: &str = "xtask: lane: the wheel is built and installed";

/// The log the lane writes to, in the target directory.
fn log_path(root: &Path) -> PathBuf {
    crate::target_dir(root).join("ci-lane.log")
}

/// Starts `nice -n 19 xtask ci-lane` with its output to [`log_path`]. The
/// workspace's test binaries must be built (the lane runs the fuzz runner
/// they built, and its cargo calls would wait for the build's lock).
pub fn start(root: &Path, ci_started: SystemTime) -> Lane {
    let log = log_path(root);
    // Emptied here, before anything can fail: an old run's log must not
    // be read as this one's.
    let file = std::fs::File::create(&log).map_err(|e| format!("{}: {e}", log.display()));
    let started = ci_started.duration_since(UNIX_EPOCH).unwrap_or_default().as_secs_f64();
    let (root, path) = (root.to_path_buf(), log.clone());
    let handle = std::thread::spawn(move || {
        let file = file?;
        let exe = std::env::current_exe().map_err(|e| format!("xtask's own path: {e}"))?;
        let err = file.try_clone().map_err(|e| format!("{}: {e}", path.display()))?;
        eprintln!(
            "xtask: ({}) nice -n 19 xtask ci-lane > {} (the fuzzing smoke run, the wheel, the ninth effect)",
            root.display(),
            path.display()
        );
        let status = Command::new("nice")
            .args(["-n", "19"])
            .arg(&exe)
            .arg("ci-lane")
            .env(CI_STARTED, format!("{started:.3}"))
            .current_dir(&root)
            .stdin(Stdio::null())
            .stdout(file)
            .stderr(err)
            .status()
            .map_err(|e| format!("cannot start nice: {e}"))?;
        if status.success() {
            Ok(())
        } else {
            Err(format!("the second lane failed ({status}): {}", path.display()))
        }
    });
    Lane { handle, log }
}

/// Waits for the lane, prints its log and adds its tests to `totals`.
pub fn finish(lane: Lane, totals: &mut (u64, u64)) -> LaneEnd {
    let mut result = lane
        .handle
        .join()
        .unwrap_or_else(|_| Err("the second lane's thread panicked".into()));
    // A lossy read: a child's stray bytes must not cost the log.
    let text = std::fs::read(&lane.log)
        .map(|bytes| String::from_utf8_lossy(&bytes).into_owned())
        .unwrap_or_default();
    println!("---- the second lane ({}) ----", lane.log.display());
    print!("{text}");
    println!("---- end of the second lane ----");
    match text.lines().rev().find_map(closing_counts) {
        Some((passed, failed)) => {
            totals.0 += passed;
            totals.1 += failed;
        }
        None if result.is_ok() => result = Err(format!("{}: no closing line", lane.log.display())),
        None => {}
    }
    let wheel_built = text.lines().any(|l| l == WHEEL_BUILT);
    LaneEnd { result, wheel_built }
}

/// The lane's closing line, as [`run`] prints it.
const CLOSING: &str = "xtask: the second lane: ";

/// Passed and failed off the lane's closing line, `None` off any other.
fn closing_counts(line: &str) -> Option<(u64, u64)> {
    let rest = line.strip_prefix(CLOSING)?;
    let (passed, failed) = rest.split_once(" passed, ")?;
    Some((passed.parse().ok()?, failed.strip_suffix(" failed")?.parse().ok()?))
}

/// `xtask ci-lane`, the lane's body: the smoke run in a thread beside the
/// wheel's build and then the ninth effect (one after the other: both
/// compile into the workspace's build directory, and the wheel's build
/// counts what it compiled there).
pub fn run(root: &Path) -> Result<(), String> {
    // CI's clock if `ci` started the lane, else the lane's own.
    let t0 = std::env::var(CI_STARTED)
        .ok()
        .and_then(|s| s.parse::<f64>().ok())
        .map_or_else(SystemTime::now, |s| UNIX_EPOCH + Duration::from_secs_f64(s));
    let at = move |stage: &str| {
        let s = SystemTime::now().duration_since(t0).unwrap_or_default().as_secs_f64();
        eprintln!("xtask: lane: {stage} done at {s:.0} s");
    };
    let runner = crate::target_dir(root).join(crate::CI_PROFILE).join("hammer-fuzz");
    let smoke = std::thread::spawn(move || {
        let smoked = fuzz_smoke(&runner);
        at("the fuzzing smoke run");
        smoked
    });
    let mut totals = (0, 0);
    let mut result = crate::python::build(root);
    if result.is_ok() {
        eprintln!("{WHEEL_BUILT}");
        at("the Python package's wheel");
        result = crate::ninth_effect::run(root, &mut totals);
        at("the ninth effect");
    }
    let smoked = smoke
        .join()
        .unwrap_or_else(|_| Err("the smoke run's thread panicked".into()));
    println!("{CLOSING}{} passed, {} failed", totals.0, totals.1);
    result.and(smoked)
}

/// The fuzzing smoke run, 1,000,000 executions a target, with the runner
/// the workspace's tests built (its crate's tests need it), run straight
/// from the target directory: a `cargo` call would wait for the lane's
/// builds. The estimator's overflow checks need no run of their own: CI's
/// profile builds the estimator with them for every test (Cargo.toml,
/// `[profile.ci.package.hammer-estimator]`).
fn fuzz_smoke(runner: &Path) -> Result<(), String> {
    eprintln!("xtask: {} smoke --execs 1000000", runner.display());
    let out = Command::new(runner)
        .args(["smoke", "--execs", "1000000"])
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("cannot start {}: {e}", runner.display()))?;
    print!("{}", String::from_utf8_lossy(&out.stdout));
    eprint!("{}", String::from_utf8_lossy(&out.stderr));
    if out.status.success() {
        Ok(())
    } else {
        Err(format!("the fuzzing smoke run failed ({})", out.status))
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_lanes_closing_line_is_counted_and_nothing_else() {
        let line = format!("{}12 passed, 1 failed", super::CLOSING);
        assert_eq!(super::closing_counts(&line), Some((12, 1)));
        assert_eq!(super::closing_counts("test result: ok. 3 passed; 0 failed"), None);
        assert_eq!(super::closing_counts(&format!("{}3 passed", super::CLOSING)), None);
    }
}
