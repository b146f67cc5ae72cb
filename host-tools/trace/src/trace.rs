//! The project's trace format: a CSV of uniformly sampled channels plus a
//! JSON sidecar with the operating point (see `docs/trace-format.md`).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

pub const REQUIRED_COLUMNS: [&str; 4] = ["t_s", "p_rear_pa", "p_front_pa", "accel_mps2"];
pub const SIDECAR_FORMAT: &str = "hammer-trace";
pub const SIDECAR_VERSION: u32 = 1;
/// Relative deviation of a sample interval from the mean that is still "uniform".
const UNIFORM_TOLERANCE: f64 = 1e-3;

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    pub dt_s: f64,
    pub t_s: Vec<f64>,
    pub p_rear_pa: Vec<f64>,
    pub p_front_pa: Vec<f64>,
    pub accel_mps2: Vec<f64>,
    /// Any further columns, in file order of their names.
    pub extra: BTreeMap<String, Vec<f64>>,
}

impl Trace {
    pub fn len(&self) -> usize {
        self.t_s.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t_s.is_empty()
    }
}

#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    /// The OS error is part of the message, not a `source`: printed once.
    #[error("{path}: {error}")]
    Io { path: String, error: std::io::Error },
    #[error("{path}: empty file (expected a header row with {cols})", cols = REQUIRED_COLUMNS.join(","))]
    Empty { path: String },
    #[error("{path}: missing column `{column}` (required: {cols})", cols = REQUIRED_COLUMNS.join(","))]
    MissingColumn { path: String, column: String },
    #[error("{path}: duplicate column `{column}`")]
    DuplicateColumn { path: String, column: String },
    #[error("{path}:{line}: expected {expected} fields, found {found}")]
    FieldCount {
        path: String,
        line: usize,
        expected: usize,
        found: usize,
    },
    #[error("{path}:{line}: column `{column}`: `{text}` is not a finite number")]
    BadNumber {
        path: String,
        line: usize,
        column: String,
        text: String,
    },
    #[error("{path}:{line}: sampling is not uniform (interval {got_s} s, expected {expected_s} s)")]
    NotUniform {
        path: String,
        line: usize,
        got_s: f64,
        expected_s: f64,
    },
    #[error("{path}: needs at least 2 samples")]
    TooShort { path: String },
    #[error("{path}: sidecar: {message}")]
    Sidecar { path: String, message: String },
}

pub fn write_csv(path: &Path, trace: &Trace) -> Result<(), TraceError> {
    let io = |error| TraceError::Io {
        path: path.display().to_string(),
        error,
    };
    let mut w = BufWriter::new(File::create(path).map_err(io)?);
    let mut header = REQUIRED_COLUMNS.join(",");
    for k in trace.extra.keys() {
        header.push(',');
        header.push_str(k);
    }
    writeln!(w, "{header}").map_err(io)?;
    let mut line = String::with_capacity(256);
    for i in 0..trace.len() {
        line.clear();
        use std::fmt::Write as _;
        let _ = write!(
            line,
            "{:.9},{},{},{}",
            trace.t_s[i], trace.p_rear_pa[i], trace.p_front_pa[i], trace.accel_mps2[i]
        );
        for col in trace.extra.values() {
            let _ = write!(line, ",{}", col[i]);
        }
        writeln!(w, "{line}").map_err(io)?;
    }
    w.flush().map_err(io)
}

pub fn read_csv(path: &Path) -> Result<Trace, TraceError> {
    let p = path.display().to_string();
    let file = File::open(path).map_err(|error| TraceError::Io { path: p.clone(), error })?;
    let mut lines = BufReader::new(file).lines();
    let header = match lines.next() {
        Some(l) => l.map_err(|error| TraceError::Io { path: p.clone(), error })?,
        None => return Err(TraceError::Empty { path: p }),
    };
    let names: Vec<String> = header
        .trim()
        .trim_start_matches('\u{feff}')
        .split(',')
        .map(|s| s.trim().to_string())
        .collect();
    for (i, n) in names.iter().enumerate() {
        if names[..i].contains(n) {
            return Err(TraceError::DuplicateColumn {
                path: p,
                column: n.clone(),
            });
        }
    }
    let mut cols: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let required: Vec<usize> = REQUIRED_COLUMNS
        .iter()
        .map(|c| {
            names
                .iter()
                .position(|n| n == c)
                .ok_or_else(|| TraceError::MissingColumn {
                    path: p.clone(),
                    column: c.to_string(),
                })
        })
        .collect::<Result<_, _>>()?;
    for (k, line) in lines.enumerate() {
        let line_no = k + 2;
        let line = line.map_err(|error| TraceError::Io { path: p.clone(), error })?;
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        if fields.len() != names.len() {
            return Err(TraceError::FieldCount {
                path: p,
                line: line_no,
                expected: names.len(),
                found: fields.len(),
            });
        }
        for (j, f) in fields.iter().enumerate() {
            let v: f64 = f
                .trim()
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite() || !required.contains(&j))
                .ok_or_else(|| TraceError::BadNumber {
                    path: p.clone(),
                    line: line_no,
                    column: names[j].clone(),
                    text: f.trim().to_string(),
                })?;
            cols[j].push(v);
        }
    }
    let t = &cols[required[0]];
    if t.len() < 2 {
        return Err(TraceError::TooShort { path: p });
    }
    let dt = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
    for i in 1..t.len() {
        let d = t[i] - t[i - 1];
        if !(dt > 0.0) || (d - dt).abs() > UNIFORM_TOLERANCE * dt {
            return Err(TraceError::NotUniform {
                path: p,
                line: i + 2,
                got_s: d,
                expected_s: dt,
            });
        }
    }
    let mut take = |i: usize| std::mem::take(&mut cols[i]);
    let mut trace = Trace {
        dt_s: dt,
        t_s: take(required[0]),
        p_rear_pa: take(required[1]),
        p_front_pa: take(required[2]),
        accel_mps2: take(required[3]),
        extra: BTreeMap::new(),
    };
    for (j, n) in names.iter().enumerate() {
        if !required.contains(&j) {
            trace.extra.insert(n.clone(), std::mem::take(&mut cols[j]));
        }
    }
    Ok(trace)
}

/// `S` is what the writer knew about the trace's origin: the simulator types
/// it as its own record; a tool that does not know the simulator reads it as
/// plain JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(bound(deserialize = "S: Deserialize<'de>"))]
pub struct Sidecar<S = serde_json::Value> {
    pub format: String,
    pub version: u32,
    /// Gauge supply pressure: the operating point (null when unknown, e.g. a device capture).
    pub supply_pressure_bar: Option<f64>,
    /// Where the trace came from: "simulator", "device", "import", ...
    pub source: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<S>,
}

impl<S> Sidecar<S> {
    pub fn new(supply_pressure_bar: Option<f64>, source: &str) -> Self {
        Self {
            format: SIDECAR_FORMAT.into(),
            version: SIDECAR_VERSION,
            supply_pressure_bar,
            source: source.into(),
            simulation: None,
        }
    }
}

/// `run.csv` → `run.json`.
pub fn sidecar_path(trace: &Path) -> PathBuf {
    trace.with_extension("json")
}

pub fn write_sidecar<S: Serialize>(trace: &Path, sidecar: &Sidecar<S>) -> Result<(), TraceError> {
    let path = sidecar_path(trace);
    let text = serde_json::to_string_pretty(sidecar).map_err(|e| TraceError::Sidecar {
        path: path.display().to_string(),
        message: e.to_string(),
    })?;
    std::fs::write(&path, text).map_err(|error| TraceError::Io {
        path: path.display().to_string(),
        error,
    })
}

/// Reads the sidecar beside a trace; `Ok(None)` when there is none. The
/// `simulation` object stays plain JSON (see [`read_sidecar_as`]).
pub fn read_sidecar(trace: &Path) -> Result<Option<Sidecar>, TraceError> {
    read_sidecar_as(trace)
}

/// [`read_sidecar`] with the `simulation` object typed as `S`.
pub fn read_sidecar_as<S: serde::de::DeserializeOwned>(trace: &Path) -> Result<Option<Sidecar<S>>, TraceError> {
    let path = sidecar_path(trace);
    if !path.exists() {
        return Ok(None);
    }
    let p = path.display().to_string();
    let text = std::fs::read_to_string(&path).map_err(|error| TraceError::Io { path: p.clone(), error })?;
    let s: Sidecar<S> = serde_json::from_str(&text).map_err(|e| TraceError::Sidecar {
        path: p.clone(),
        message: e.to_string(),
    })?;
    if s.format != SIDECAR_FORMAT {
        return Err(TraceError::Sidecar {
            path: p,
            message: format!("format is `{}`, expected `{SIDECAR_FORMAT}`", s.format),
        });
    }
    if s.version > SIDECAR_VERSION {
        return Err(TraceError::Sidecar {
            path: p,
            message: format!("version {} is newer than this tool's {SIDECAR_VERSION}", s.version),
        });
    }
    Ok(Some(s))
}
