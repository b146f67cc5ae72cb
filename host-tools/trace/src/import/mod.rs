//! Recorders' files, read as the project's trace: delimited text with a
//! mapping, NI TDMS, MATLAB MAT v5, multi-channel WAV, Parquet. Every tool
//! that takes a trace opens it through [`open`] (via
//! `hammer_sim::estimation`), so a format read here is read everywhere; the
//! rows then go through the same time-base layer as the project's CSV
//! ([`crate::rows::Uniform`]), so the same samples give the same result
//! whatever file held them. See `docs/trace-format.md`, "Recorders' files".
//!
//! Module map:
//! - [`mapping`]: the `[import]` table (columns, units, gauge/absolute, sign, text layout);
//! - [`delimited`]: delimited text, streamed;
//! - [`inspect`]: what a trace holds: rate, gaps, ranges, rails a recorder clipped, absolute pressure;
//! - [`columns`]: the binary formats' channels picked, converted and handed out as rows;
//! - [`tdms`], [`mat`], [`wav`], [`parquet`]: one reader per format.

pub mod columns;
pub mod delimited;
pub mod inspect;
pub mod mapping;
pub mod mat;
pub mod parquet;
pub mod tdms;
pub mod wav;

use std::io::{BufRead, BufReader};
use std::path::Path;

use serde::Serialize;

use crate::rows::{Item, Row, RowReader, RowSource, Uniform};
use crate::trace::{Gap, Trace, TraceError, REQUIRED_COLUMNS};
pub use mapping::ImportMap;

/// The file formats read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Format {
    /// The project's own CSV (`docs/trace-format.md`).
    Native,
    Delimited,
    Tdms,
    Mat,
    Wav,
    Parquet,
}

impl Format {
    pub fn name(self) -> &'static str {
        match self {
            Format::Native => "the project's trace CSV",
            Format::Delimited => "delimited text",
            Format::Tdms => "NI TDMS",
            Format::Mat => "MATLAB MAT v5",
            Format::Wav => "WAV",
            Format::Parquet => "Parquet",
        }
    }
}

/// Where one signal came from, as understood.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SignalSource {
    pub signal: String,
    /// The column, channel or variable.
    pub column: String,
    pub unit: String,
    /// Pressures: `gauge` or `absolute`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference: Option<String>,
    pub sign: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub full_scale: Option<f64>,
}

/// What [`open`] understood of a file: the record `hammer import` prints
/// and keeps in its sidecar.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Understood {
    pub format: Format,
    /// Signals in the order t, p_rear, p_front, accel.
    pub signals: Vec<SignalSource>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub delimiter: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub decimal: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub header_line: Option<usize>,
    /// The mapping used (none for a file in the project's names).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mapping: Option<ImportMap>,
}

/// A file opened: rows to read, what was understood, and a sidecar the file
/// carried inside (a Parquet capture's).
pub struct Opened {
    pub source: Box<dyn RowSource + Send>,
    pub understood: Understood,
    pub embedded_sidecar: Option<String>,
    /// Names of the further columns (the native CSV with `keep_extra`).
    pub extra_names: Vec<String>,
}

impl<T: RowSource + ?Sized> RowSource for Box<T> {
    fn next_row(&mut self) -> Result<Option<Row>, TraceError> {
        (**self).next_row()
    }
    fn label(&self) -> &str {
        (**self).label()
    }
    fn line(&self) -> usize {
        (**self).line()
    }
    fn extra(&self) -> &[f64] {
        (**self).extra()
    }
    fn time_resolution_s(&self) -> f64 {
        (**self).time_resolution_s()
    }
    fn stated_period_s(&self) -> Option<(f64, String)> {
        (**self).stated_period_s()
    }
}

/// Bytes looked at to tell the format.
const HEAD_BYTES: usize = 1024;

fn io(path: &str, error: std::io::Error) -> TraceError {
    TraceError::Io {
        path: path.to_string(),
        error,
    }
}

fn import_err(path: &str, message: String) -> TraceError {
    TraceError::Import {
        path: path.to_string(),
        message,
    }
}

/// Tells the format from the file's first bytes.
pub fn detect(head: &[u8]) -> Format {
    if tdms::is_tdms(head) {
        Format::Tdms
    } else if mat::is_mat(head) {
        Format::Mat
    } else if wav::is_wav(head) {
        Format::Wav
    } else if parquet::is_parquet(head) {
        Format::Parquet
    } else if is_native(head) {
        Format::Native
    } else {
        Format::Delimited
    }
}

/// A header row holding the project's four columns, comma-separated, and
/// no quotes: a file with quoted fields (pandas' `to_csv(decimal=",")`)
/// is read as delimited text, which honours them.
fn is_native(head: &[u8]) -> bool {
    if head.contains(&b'"') {
        return false;
    }
    let line = head.split(|&b| b == b'\n').next().unwrap_or(&[]);
    let Ok(text) = std::str::from_utf8(line) else {
        // The head may end inside a character: only a complete first line counts.
        return false;
    };
    let names: Vec<&str> = text
        .trim()
        .trim_start_matches('\u{feff}')
        .split(',')
        .map(str::trim)
        .collect();
    REQUIRED_COLUMNS.iter().all(|c| names.contains(c))
}

/// Opens any trace file for reading row by row. `map` says what a
/// recorder's file means; a file in the project's names needs none (and a
/// map without signal tables leaves the project's CSV as it is).
/// `keep_extra` keeps the native CSV's further columns.
pub fn open(path: &Path, map: Option<&ImportMap>, keep_extra: bool) -> Result<Opened, TraceError> {
    let label = path.display().to_string();
    let file = std::fs::File::open(path).map_err(|e| io(&label, e))?;
    let mut input = BufReader::with_capacity(1 << 16, file);
    let head = input.fill_buf().map_err(|e| io(&label, e))?;
    let head = &head[..head.len().min(HEAD_BYTES)];
    let mut format = detect(head);
    // The project's CSV read through a mapping that says something of its
    // columns (absolute pressure, a sign, a unit): the mapping applies.
    if format == Format::Native && map.is_some_and(ImportMap::maps_signals) {
        format = Format::Delimited;
    }
    open_from(input, &label, format, map, keep_extra)
}

/// [`open`] from a reader whose format is known; `label` names it in errors.
pub fn open_from(
    mut input: impl BufRead + Send + 'static,
    label: &str,
    format: Format,
    map: Option<&ImportMap>,
    keep_extra: bool,
) -> Result<Opened, TraceError> {
    let default_map = ImportMap::default();
    let m = map.unwrap_or(&default_map);
    let mapping = map.cloned();
    match format {
        Format::Native => {
            let rows = RowReader::new(input, label, keep_extra)?;
            let extra_names = rows.extra_names().map(str::to_string).collect();
            Ok(Opened {
                source: Box::new(rows),
                understood: Understood {
                    format,
                    signals: default_signals(&default_map)?,
                    delimiter: Some(",".into()),
                    decimal: Some(".".into()),
                    header_line: Some(1),
                    mapping: None,
                },
                embedded_sidecar: None,
                extra_names,
            })
        }
        Format::Delimited => {
            let d = delimited::Delimited::new(input, label, m)?;
            let signals = d
                .columns()
                .iter()
                .map(|(col, r)| {
                    let column = match col {
                        None => format!("rate {} Hz", m.sample_rate_hz.unwrap_or(f64::NAN)),
                        Some(c) => d.names.get(*c).cloned().unwrap_or_else(|| format!("#{}", c + 1)),
                    };
                    source_of(r, column)
                })
                .collect();
            let understood = Understood {
                format,
                signals,
                delimiter: Some(d.delimiter().to_string()),
                decimal: Some(if d.decimal_comma() { "," } else { "." }.into()),
                header_line: (d.header_line > 0).then_some(d.header_line),
                mapping,
            };
            Ok(Opened {
                source: Box::new(d),
                understood,
                embedded_sidecar: None,
                extra_names: Vec::new(),
            })
        }
        _ => {
            let mut bytes = Vec::new();
            input.read_to_end(&mut bytes).map_err(|e| io(label, e))?;
            let (channels, rate, embedded, skipped) = match format {
                Format::Tdms => (tdms::read(&bytes, m.group.as_deref()), None, None, Vec::new()),
                Format::Mat => match mat::read(&bytes) {
                    Ok((ch, skipped)) => {
                        let rate = mat_rate(&ch);
                        (Ok(ch), rate, None, skipped)
                    }
                    Err(e) => (Err(e), None, None, Vec::new()),
                },
                Format::Wav => match wav::read(&bytes, m) {
                    Ok((ch, fs)) => (
                        Ok(ch),
                        Some((0.0, 1.0 / fs, format!("the WAV header's {fs} Hz"))),
                        None,
                        Vec::new(),
                    ),
                    Err(e) => (Err(e), None, None, Vec::new()),
                },
                _ => match parquet::read(bytes) {
                    Ok(r) => (Ok(r.channels), None, r.sidecar, r.skipped),
                    Err(e) => (Err(e), None, None, Vec::new()),
                },
            };
            let channels = channels.map_err(|e| import_err(label, format!("{}: {e}", format.name())))?;
            let cols = columns::Columns::new(label, channels, m, rate, &skipped)?;
            let mut signals = Vec::new();
            signals.push(match cols.time() {
                columns::TimeBase::Column(_, r) => source_of(r, column_text(&r.column)),
                columns::TimeBase::Rate { increment_s, from, .. } => SignalSource {
                    signal: "t".into(),
                    column: format!("{from} ({} Hz)", 1.0 / increment_s),
                    unit: "s".into(),
                    reference: None,
                    sign: 1.0,
                    full_scale: None,
                },
            });
            for (r, name) in cols.signals() {
                signals.push(source_of(r, name.to_string()));
            }
            Ok(Opened {
                source: Box::new(cols),
                understood: Understood {
                    format,
                    signals,
                    delimiter: None,
                    decimal: None,
                    header_line: None,
                    mapping,
                },
                embedded_sidecar: embedded,
                extra_names: Vec::new(),
            })
        }
    }
}

/// MAT: the time as scalar variables `dt_s` (and `t0_s`) instead of a `t_s` vector.
fn mat_rate(channels: &[columns::Channel]) -> Option<(f64, f64, String)> {
    let scalar = |n: &str| {
        channels
            .iter()
            .find(|c| c.name == n && c.values.len() == 1)
            .map(|c| c.values[0])
    };
    scalar("dt_s").map(|dt| {
        (
            scalar("t0_s").unwrap_or(0.0),
            dt,
            "the variables dt_s, t0_s".to_string(),
        )
    })
}

fn column_text(c: &mapping::ColumnRef) -> String {
    match c {
        mapping::ColumnRef::Index(i) => format!("#{i}"),
        mapping::ColumnRef::Name(n) => n.clone(),
    }
}

fn source_of(r: &mapping::Resolved, column: String) -> SignalSource {
    SignalSource {
        signal: r.signal.to_string(),
        column,
        unit: r.unit.clone(),
        reference: (r.signal.starts_with("p_")).then(|| if r.absolute { "absolute" } else { "gauge" }.to_string()),
        sign: r.sign,
        full_scale: r.scale,
    }
}

fn default_signals(m: &ImportMap) -> Result<Vec<SignalSource>, TraceError> {
    mapping::SIGNALS
        .iter()
        .map(|(k, name, _)| {
            m.resolve(k)
                .map(|r| source_of(&r, name.to_string()))
                .map_err(|e| import_err("import", e.to_string()))
        })
        .collect()
}

/// A whole trace in memory from any row source (the native reader's
/// [`crate::trace::read_csv`] goes through here too).
pub fn collect<S: RowSource>(mut u: Uniform<S>, extra_names: Vec<String>) -> Result<Trace, TraceError> {
    let mut trace = Trace::default();
    let mut extra: Vec<Vec<f64>> = vec![Vec::new(); extra_names.len()];
    while let Some(item) = u.next_item()? {
        match item {
            Item::Gap { missing } => trace.gaps.push(Gap {
                before: trace.t_s.len(),
                missing,
            }),
            Item::Sample(r) => {
                trace.t_s.push(r.t_s);
                trace.p_rear_pa.push(r.p_rear_pa);
                trace.p_front_pa.push(r.p_front_pa);
                trace.accel_mps2.push(r.accel_mps2);
                for (col, v) in extra.iter_mut().zip(u.extra()) {
                    col.push(*v);
                }
            }
        }
    }
    // The mean interval over the whole file: the most accurate period there is.
    // (Divided first where the span itself would overflow: times near f64's range.)
    let (first, last, slots) = (trace.t_s[0], trace.t_s[trace.t_s.len() - 1], u.slots() as f64);
    let span = last - first;
    trace.dt_s = if span.is_finite() {
        span / slots
    } else {
        last / slots - first / slots
    };
    trace.extra = extra_names.into_iter().zip(extra).collect();
    Ok(trace)
}

/// A trace from channels held in memory (a script's arrays), read by `map`
/// (none: the project's column names, SI units, gauge) through the same
/// time-base layer as a file: gaps found, irregular timing refused, each
/// refusal naming `label`.
pub fn trace_from_channels(
    label: &str,
    channels: Vec<columns::Channel>,
    map: Option<&ImportMap>,
) -> Result<Trace, TraceError> {
    let default = ImportMap::default();
    let source = columns::Columns::new(label, channels, map.unwrap_or(&default), None, &[])?;
    collect(Uniform::new(source)?, Vec::new())
}

/// Reads any trace file whole: the samples, and what was understood.
pub fn read_trace(path: &Path, map: Option<&ImportMap>) -> Result<(Trace, Understood, Option<String>), TraceError> {
    let opened = open(path, map, true)?;
    let u = Uniform::new(opened.source)?;
    let trace = collect(u, opened.extra_names)?;
    Ok((trace, opened.understood, opened.embedded_sidecar))
}
