//! A benchmark run's finished cases, one JSON line each in `DIR/cases.jsonl`,
//! so that a run of hours survives being stopped: `diagnose-bench --out DIR
//! --resume` reads the log and runs only the cases it lacks.
//!
//! Why this is sound: a case is drawn from the seed and its index alone
//! (`bench::run_case_with`), so a case run later is the case a run from the
//! start would have run, and a run of 120 cases begun as 40 and resumed is
//! the run of 120. What could make it unsound is a log written under other
//! options (another seed, jitter, FMU or map) mixed into this run's counts:
//! the log's first line holds the options, and a log whose options differ is
//! refused, naming the file and what differs. A line cut short by a stop in
//! the middle of a write is dropped and written again; any other line that
//! is not a case refuses the log, by its line number, never quoted.

use std::collections::BTreeMap;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

use super::bench::{BenchOptions, CaseResult};

/// The log's name in the run's output folder.
pub const FILE: &str = "cases.jsonl";

/// One line of the log.
#[derive(Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
enum Line {
    /// The first line: the run's options.
    Options(BenchOptions),
    Case(Box<CaseResult>),
    /// A generated hammer that did not run (left out of the counts).
    NotRun {
        index: usize,
        why: String,
    },
}

/// What a log already holds, by case index.
#[derive(Default)]
pub struct Done {
    pub cases: BTreeMap<usize, CaseResult>,
    pub not_run: BTreeMap<usize, String>,
}

impl Done {
    pub fn contains(&self, index: usize) -> bool {
        self.cases.contains_key(&index) || self.not_run.contains_key(&index)
    }

    pub fn len(&self) -> usize {
        self.cases.len() + self.not_run.len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The open log: each finished case is appended as it finishes.
pub struct CaseLog {
    path: PathBuf,
    file: Mutex<File>,
}

/// The options two runs must share for their cases to be one run's: all of
/// them but the number of cases.
fn comparable(opts: &BenchOptions) -> Result<serde_json::Map<String, serde_json::Value>> {
    let serde_json::Value::Object(mut m) = serde_json::to_value(opts)? else {
        bail!("the benchmark's options are not a JSON object");
    };
    m.remove("cases");
    Ok(m)
}

impl CaseLog {
    /// Opens `dir/cases.jsonl` for this run. With `resume`, what it holds is
    /// read (and refused if it was written under other options), and the
    /// run goes on appending to it; without, a new log replaces any old one.
    pub fn open(dir: &Path, opts: &BenchOptions, resume: bool) -> Result<(Self, Done)> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let path = dir.join(FILE);
        let (done, keep) = if resume && path.exists() {
            read(&path, opts)?
        } else {
            (Done::default(), 0)
        };
        let file = OpenOptions::new()
            .create(true)
            .write(true)
            .truncate(false)
            .open(&path)
            .with_context(|| format!("opening {}", path.display()))?;
        // What follows the last whole line (a torn write, or all of an old
        // log when not resuming) goes.
        file.set_len(keep)
            .with_context(|| format!("writing {}", path.display()))?;
        let log = Self {
            path,
            file: Mutex::new(file),
        };
        if keep == 0 {
            log.append(&Line::Options(opts.clone()))?;
        }
        Ok((log, done))
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Appends a finished case.
    pub fn case(&self, case: &CaseResult) -> Result<()> {
        self.append(&Line::Case(Box::new(case.clone())))
    }

    /// Appends a case whose hammer did not run.
    pub fn not_run(&self, index: usize, why: &str) -> Result<()> {
        self.append(&Line::NotRun {
            index,
            why: why.to_string(),
        })
    }

    fn append(&self, line: &Line) -> Result<()> {
        let mut text = serde_json::to_string(line)?;
        text.push('\n');
        let mut file = self.file.lock().unwrap_or_else(|p| p.into_inner());
        // One write a line, at the end of the file: a stop can only cut
        // the line being written, which a resume drops.
        use std::io::Seek;
        file.seek(std::io::SeekFrom::End(0))
            .and_then(|_| file.write_all(text.as_bytes()))
            .and_then(|_| file.flush())
            .with_context(|| format!("writing {}", self.path.display()))
    }
}

/// The cases a log holds and the length of its whole lines, in bytes.
fn read(path: &Path, opts: &BenchOptions) -> Result<(Done, u64)> {
    let text = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut done = Done::default();
    let mut keep = 0u64;
    let want = comparable(opts)?;
    let mut lines = text.split_inclusive(|b| *b == b'\n').enumerate().peekable();
    while let Some((n, raw)) = lines.next() {
        let whole = raw.ends_with(b"\n");
        let parsed = std::str::from_utf8(raw)
            .ok()
            .and_then(|s| serde_json::from_str::<Line>(s.trim_end()).ok());
        let line = match parsed {
            Some(l) if whole => l,
            // The last line, cut short by a stop: written again.
            _ if !whole && lines.peek().is_none() => break,
            _ => bail!(
                "{}: line {} is not a case of a `diagnose-bench` run; the log cannot be resumed (move it away to start afresh)",
                path.display(),
                n + 1
            ),
        };
        match (n, line) {
            (0, Line::Options(o)) => {
                let had = comparable(&o)?;
                if had != want {
                    let differs: Vec<&str> = want
                        .keys()
                        .chain(had.keys())
                        .filter(|k| want.get(*k) != had.get(*k))
                        .map(String::as_str)
                        .collect::<std::collections::BTreeSet<_>>()
                        .into_iter()
                        .collect();
                    bail!(
                        "{}: written by a run with other options ({}); resume it with the same options, or give another --out",
                        path.display(),
                        differs.join(", ")
                    );
                }
            }
            (0, _) => bail!(
                "{}: does not begin with a `diagnose-bench` run's options; the log cannot be resumed",
                path.display()
            ),
            (_, Line::Options(_)) => bail!("{}: line {}: a second run's options", path.display(), n + 1),
            (_, Line::Case(c)) => {
                let index = c.index;
                if done.contains(index) {
                    bail!("{}: line {}: case {index} a second time", path.display(), n + 1);
                }
                done.cases.insert(index, *c);
            }
            (_, Line::NotRun { index, why }) => {
                if done.contains(index) {
                    bail!("{}: line {}: case {index} a second time", path.display(), n + 1);
                }
                done.not_run.insert(index, why);
            }
        }
        keep += raw.len() as u64;
    }
    Ok((done, keep))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn opts(seed: u64) -> BenchOptions {
        BenchOptions {
            cases: 4,
            seed,
            ..BenchOptions::default()
        }
    }

    fn case(index: usize, energy_error_after: f64) -> CaseResult {
        serde_json::from_value(serde_json::json!({
            "index": index,
            "hidden": { "One": "leakage" },
            "hidden_params": { "leakage": { "gap_m": 1.23456789e-5 } },
            "named": ["leakage"],
            "correct": true,
            "param_errors": { "leakage": 0.0123 },
            "score": 42.0,
            "energy_error_before": 0.1,
            "energy_error_after": energy_error_after,
            "frequency_error_before": 0.05,
            "frequency_error_after": 0.001,
            "diagnose_s": 3.0,
        }))
        .unwrap()
    }

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("hammer-case-log-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn a_resumed_log_gives_back_its_cases_to_the_bit() {
        let d = dir("resume");
        let (log, done) = CaseLog::open(&d, &opts(7), true).unwrap();
        assert!(done.is_empty());
        log.case(&case(2, 0.1 + 0.2)).unwrap();
        log.not_run(3, "no complete cycle").unwrap();
        log.case(&case(0, 1.0 / 3.0)).unwrap();
        drop(log);
        // More cases asked for: the same run, longer.
        let more = BenchOptions { cases: 120, ..opts(7) };
        let (log, done) = CaseLog::open(&d, &more, true).unwrap();
        assert_eq!(done.cases.keys().copied().collect::<Vec<_>>(), vec![0, 2]);
        assert_eq!(done.cases[&2].energy_error_after, 0.1 + 0.2);
        assert_eq!(done.cases[&0].energy_error_after, 1.0 / 3.0);
        assert_eq!(done.cases[&0].hidden_params["leakage"]["gap_m"], 1.23456789e-5);
        assert_eq!(done.not_run[&3], "no complete cycle");
        log.case(&case(1, 0.5)).unwrap();
        drop(log);
        let (_, done) = CaseLog::open(&d, &more, true).unwrap();
        assert_eq!(done.len(), 4);
        // Without --resume the run starts afresh.
        let (_, done) = CaseLog::open(&d, &more, false).unwrap();
        assert!(done.is_empty());
        let (_, done) = CaseLog::open(&d, &more, true).unwrap();
        assert!(done.is_empty());
    }

    #[test]
    fn a_log_of_other_options_is_refused_by_name() {
        let d = dir("other");
        let (log, _) = CaseLog::open(&d, &opts(7), true).unwrap();
        log.case(&case(0, 0.1)).unwrap();
        drop(log);
        let err = CaseLog::open(&d, &opts(8), true).err().unwrap().to_string();
        assert!(err.contains(FILE) && err.contains("seed"), "{err}");
        let jittered = BenchOptions { jitter: 0.2, ..opts(7) };
        let err = CaseLog::open(&d, &jittered, true).err().unwrap().to_string();
        assert!(err.contains("jitter") && !err.contains("seed"), "{err}");
        // The refused log is left as it was.
        assert_eq!(CaseLog::open(&d, &opts(7), true).unwrap().1.len(), 1);
    }

    #[test]
    fn a_line_cut_by_a_stop_is_written_again_and_a_foreign_line_refuses_the_log() {
        let d = dir("torn");
        let (log, _) = CaseLog::open(&d, &opts(7), true).unwrap();
        log.case(&case(0, 0.1)).unwrap();
        log.case(&case(1, 0.2)).unwrap();
        drop(log);
        let path = d.join(FILE);
        let whole = std::fs::read(&path).unwrap();
        // Stopped halfway through case 1's line.
        std::fs::write(&path, &whole[..whole.len() - 40]).unwrap();
        let (log, done) = CaseLog::open(&d, &opts(7), true).unwrap();
        assert_eq!(done.cases.keys().copied().collect::<Vec<_>>(), vec![0]);
        log.case(&case(1, 0.2)).unwrap();
        drop(log);
        assert_eq!(
            std::fs::read(&path).unwrap(),
            whole,
            "the torn line replaced, not appended to"
        );
        // A line that is not a case, in the middle: refused, by number.
        let text = String::from_utf8(whole).unwrap();
        let mut lines: Vec<&str> = text.lines().collect();
        lines.insert(2, "secret-token=hunter2");
        std::fs::write(&path, lines.join("\n") + "\n").unwrap();
        let err = CaseLog::open(&d, &opts(7), true).err().unwrap().to_string();
        assert!(err.contains("line 3") && !err.contains("hunter2"), "{err}");
    }
}
