//! The project's trace format: a CSV of uniformly sampled channels plus a
//! JSON sidecar with the operating point (see `docs/trace-format.md`).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::rows::{RowReader, Uniform};

pub const REQUIRED_COLUMNS: [&str; 4] = ["t_s", "p_rear_pa", "p_front_pa", "accel_mps2"];
pub const SIDECAR_FORMAT: &str = "hammer-trace";
/// 2: the simulator's sensor noise comes from a ziggurat instead of
/// Box–Muller (issue 31), so a seed gives other noise, hence other
/// measured samples and codes, than in a version-1 simulated trace (its
/// truth columns are the same); the layout is unchanged and version-1
/// sidecars read as before.
pub const SIDECAR_VERSION: u32 = 2;

#[derive(Debug, Clone, Default, PartialEq)]
pub struct Trace {
    pub dt_s: f64,
    pub t_s: Vec<f64>,
    pub p_rear_pa: Vec<f64>,
    pub p_front_pa: Vec<f64>,
    pub accel_mps2: Vec<f64>,
    /// Any further columns, by name (a non-numeric field reads as NaN).
    pub extra: BTreeMap<String, Vec<f64>>,
    /// Where rows are missing (whole sample periods with no row), in order.
    pub gaps: Vec<Gap>,
}

/// `missing` sample periods with no row just before sample `before`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Gap {
    pub before: usize,
    pub missing: u64,
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
    #[error("{path}:{line}: time goes backwards at this row ({t_s} s after {previous_s} s)")]
    TimeBackwards {
        path: String,
        line: usize,
        t_s: f64,
        previous_s: f64,
    },
    #[error("{path}:{line}: line longer than {max} bytes")]
    LineTooLong { path: String, line: usize, max: usize },
    #[error("{path}:{line}: not UTF-8 text")]
    NotUtf8 { path: String, line: usize },
    #[error("{path}: needs at least 2 samples")]
    TooShort { path: String },
    /// A recorder's file that cannot be read as a trace (`crate::import`).
    #[error("{path}: {message}")]
    Import { path: String, message: String },
    #[error("{path}: sidecar: {message}")]
    Sidecar { path: String, message: String },
}

pub fn write_csv(path: &Path, trace: &Trace) -> Result<(), TraceError> {
    let names: Vec<&str> = trace.extra.keys().map(String::as_str).collect();
    let mut w = CsvWriter::create(path, &names)?;
    for i in 0..trace.len() {
        w.row(
            trace.t_s[i],
            trace.p_rear_pa[i],
            trace.p_front_pa[i],
            trace.accel_mps2[i],
            trace.extra.values().map(|col| col[i]),
        )?;
    }
    w.finish()
}

/// A trace CSV written row by row, so a producer that streams (a long
/// simulation) needs no whole trace in memory; [`write_csv`] goes through it,
/// so both write the same bytes.
pub struct CsvWriter {
    path: String,
    w: BufWriter<File>,
    extra_columns: usize,
    /// Rows written so far (the header is line 1).
    rows: usize,
    line: String,
}

impl CsvWriter {
    /// Creates `path` and writes the header: the required columns, then `extra` in the order given.
    pub fn create(path: &Path, extra: &[&str]) -> Result<Self, TraceError> {
        let p = path.display().to_string();
        let file = File::create(path).map_err(|error| TraceError::Io { path: p.clone(), error })?;
        let mut w = Self {
            path: p,
            w: BufWriter::new(file),
            extra_columns: extra.len(),
            rows: 0,
            line: String::with_capacity(256),
        };
        let mut header = REQUIRED_COLUMNS.join(",");
        for k in extra {
            header.push(',');
            header.push_str(k);
        }
        writeln!(w.w, "{header}").map_err(|e| w.io(e))?;
        Ok(w)
    }

    fn io(&self, error: std::io::Error) -> TraceError {
        TraceError::Io {
            path: self.path.clone(),
            error,
        }
    }

    /// One row; `extra` must hold one value per extra column of the header.
    pub fn row(
        &mut self,
        t_s: f64,
        p_rear_pa: f64,
        p_front_pa: f64,
        accel_mps2: f64,
        extra: impl IntoIterator<Item = f64>,
    ) -> Result<(), TraceError> {
        use std::fmt::Write as _;
        self.line.clear();
        let _ = write!(self.line, "{t_s:.9},{p_rear_pa},{p_front_pa},{accel_mps2}");
        let mut n = 0;
        for v in extra {
            let _ = write!(self.line, ",{v}");
            n += 1;
        }
        self.rows += 1;
        if n != self.extra_columns {
            return Err(TraceError::FieldCount {
                path: self.path.clone(),
                line: self.rows + 1,
                expected: REQUIRED_COLUMNS.len() + self.extra_columns,
                found: REQUIRED_COLUMNS.len() + n,
            });
        }
        writeln!(self.w, "{}", self.line).map_err(|e| self.io(e))
    }

    /// Flushes the buffer: a full disk shows here, not as a silently short file.
    pub fn finish(mut self) -> Result<(), TraceError> {
        self.w.flush().map_err(|e| self.io(e))
    }
}

/// Reads a whole trace into memory (report and diagnose need it whole;
/// `hammer estimate` streams with [`crate::rows`] instead).
pub fn read_csv(path: &Path) -> Result<Trace, TraceError> {
    let p = path.display().to_string();
    let file = File::open(path).map_err(|error| TraceError::Io { path: p.clone(), error })?;
    read_csv_from(BufReader::new(file), &p)
}

/// [`read_csv`] from any reader; `label` names it in errors.
pub fn read_csv_from(input: impl BufRead, label: &str) -> Result<Trace, TraceError> {
    let rows = RowReader::new(input, label, true)?;
    let extra_names: Vec<String> = rows.extra_names().map(str::to_string).collect();
    crate::import::collect(Uniform::new(rows)?, extra_names)
}

/// `S` is what the writer knew about the trace's origin: the simulator types
/// it as its own record; a tool that does not know the simulator reads it as
/// plain JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(bound(deserialize = "S: Deserialize<'de>"))]
pub struct Sidecar<S = serde_json::Value> {
    /// Optional when reading: an outside user naturally writes only the operating point.
    #[serde(default = "default_format")]
    pub format: String,
    #[serde(default = "default_version")]
    pub version: u32,
    /// Gauge supply pressure: the operating point (null when unknown, e.g. a device capture).
    #[serde(default)]
    pub supply_pressure_bar: Option<f64>,
    /// Where the trace came from: "simulator", "device", "import", ...
    #[serde(default = "default_source")]
    pub source: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub simulation: Option<S>,
    /// CRC-32 of the board's channel calibrations, for a device's capture:
    /// a record made before a recalibration is told from one made after.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration_hash: Option<u32>,
    /// What `hammer import` understood of a recorder's file: format, each
    /// signal's column, unit, gauge or absolute, sign, the mapping used,
    /// rails found (`docs/trace-format.md`, "Recorders' files").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub import: Option<serde_json::Value>,
}

fn default_format() -> String {
    SIDECAR_FORMAT.into()
}

fn default_version() -> u32 {
    SIDECAR_VERSION
}

fn default_source() -> String {
    "import".into()
}

impl<S> Sidecar<S> {
    pub fn new(supply_pressure_bar: Option<f64>, source: &str) -> Self {
        Self {
            format: SIDECAR_FORMAT.into(),
            version: SIDECAR_VERSION,
            supply_pressure_bar,
            source: source.into(),
            simulation: None,
            calibration_hash: None,
            import: None,
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
    parse_sidecar_as(&text, &p).map(Some)
}

/// A sidecar from its text; `label` names it in errors.
pub fn parse_sidecar_as<S: serde::de::DeserializeOwned>(text: &str, label: &str) -> Result<Sidecar<S>, TraceError> {
    let err = |message: String| TraceError::Sidecar {
        path: label.to_string(),
        message,
    };
    let s: Sidecar<S> = serde_json::from_str(text).map_err(|e| err(e.to_string()))?;
    if s.format != SIDECAR_FORMAT {
        return Err(err(format!("format is `{}`, expected `{SIDECAR_FORMAT}`", s.format)));
    }
    if s.version > SIDECAR_VERSION {
        return Err(err(format!(
            "version {} is newer than this tool's {SIDECAR_VERSION}",
            s.version
        )));
    }
    Ok(s)
}
