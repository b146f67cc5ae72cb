//! Reading a trace CSV row by row, so that a trace of any length is read in
//! bounded memory: `hammer estimate` of an hour at 100 kS/s streams through
//! here, and [`crate::trace::read_csv`] builds its in-memory trace on top.
//!
//! The time base comes from the first rows (the median of the first
//! [`LOOKAHEAD`] intervals), so a consumer knows the sample rate before the
//! first sample. A later interval that is a whole number of sample periods
//! is a gap (samples lost by the recorder), reported as such: the estimator
//! takes gaps and flags the cycle they fall in. Anything else is an error that
//! names its line.

use std::collections::VecDeque;
use std::io::BufRead;

use crate::trace::{TraceError, REQUIRED_COLUMNS};

/// Longest accepted line, terminator included. A real row is well under
/// 1 KiB; without a bound a file with no newline (`/dev/zero`) is read whole.
pub const MAX_LINE_BYTES: usize = 64 * 1024;
/// Intervals from which the sample period is taken.
pub const LOOKAHEAD: usize = 64;
/// Rows from which the period is taken when the time stamps are rounded
/// coarser than [`UNIFORM_TOLERANCE`] (1 µs stamps at 48 kS/s): the period
/// is then good to about resolution / this many periods.
pub const QUANTIZED_LOOKAHEAD: usize = 4096;
/// Relative deviation of an interval from a whole number of sample periods
/// that still counts as uniform sampling.
pub const UNIFORM_TOLERANCE: f64 = 1e-3;

/// The four required channels of one row.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Row {
    pub t_s: f64,
    pub p_rear_pa: f64,
    pub p_front_pa: f64,
    pub accel_mps2: f64,
}

/// Where [`Uniform`] takes its rows from: the project's CSV ([`RowReader`]),
/// or a recorder's file through [`crate::import`]. One time-base layer over
/// every source, so a foreign file's samples reach the estimator exactly as
/// the same samples in the native CSV would.
pub trait RowSource {
    /// The next row, `None` at the end.
    fn next_row(&mut self) -> Result<Option<Row>, TraceError>;
    /// Names the input in errors (its path).
    fn label(&self) -> &str;
    /// Where the latest row is, for errors (a line, or a sample number).
    fn line(&self) -> usize;
    /// The further channels' values of the latest row (see [`RowReader::extra`]).
    fn extra(&self) -> &[f64] {
        &[]
    }
    /// Resolution of the time stamps read so far, s (0 when exact): a
    /// recorder that stamps in whole µs at 48 kS/s writes intervals of 20 and
    /// 21 µs, which is uniform sampling, not jitter.
    fn time_resolution_s(&self) -> f64 {
        0.0
    }
    /// A sample period stated besides the time stamps (a map's rate, a
    /// format's header), with what states both: the stamps are read, and a
    /// period that contradicts them is refused rather than either one
    /// silently winning.
    fn stated_period_s(&self) -> Option<(f64, String)> {
        None
    }
}

impl<R: BufRead> RowSource for RowReader<R> {
    fn next_row(&mut self) -> Result<Option<Row>, TraceError> {
        RowReader::next_row(self)
    }
    fn label(&self) -> &str {
        &self.label
    }
    fn line(&self) -> usize {
        self.line_no
    }
    fn extra(&self) -> &[f64] {
        &self.extra
    }
    fn time_resolution_s(&self) -> f64 {
        resolution_of(self.time_decimals)
    }
}

/// Decimals a number is written with: `0.000021` → 6, `42` → 0; an
/// exponent form counts as exact (`EXACT_DECIMALS`). The finest over a
/// column is its resolution: a recorder writes a fixed count, and a
/// shortest-form writer's longest value shows its precision.
pub fn decimals(text: &str) -> i32 {
    let t = text.trim();
    if t.contains(['e', 'E']) {
        return EXACT_DECIMALS;
    }
    match t.find(['.', ',']) {
        Some(i) => (t.len() - i - 1).min(EXACT_DECIMALS as usize) as i32,
        None => 0,
    }
}

/// Decimals that stand for an exact value (beyond f64's precision anyway).
pub const EXACT_DECIMALS: i32 = 30;

/// The resolution of a column written with at most `decimals` decimals, in its unit.
pub fn resolution_of(decimals: Option<i32>) -> f64 {
    match decimals {
        Some(d) if d < EXACT_DECIMALS => 10f64.powi(-d),
        _ => 0.0,
    }
}

/// The CSV layer: header, lines, fields. No time-base logic.
pub struct RowReader<R> {
    input: R,
    label: String,
    names: Vec<String>,
    /// Column index of each of [`REQUIRED_COLUMNS`].
    required: [usize; 4],
    keep_extra: bool,
    extra: Vec<f64>,
    line_no: usize,
    buf: Vec<u8>,
    /// The most decimals a time stamp was written with (see [`RowSource::time_resolution_s`]).
    time_decimals: Option<i32>,
}

impl<R: BufRead> RowReader<R> {
    /// Reads the header. `label` names the input in errors (its path).
    /// With `keep_extra`, the values of the other columns of the latest row
    /// are available from [`RowReader::extra`].
    pub fn new(input: R, label: &str, keep_extra: bool) -> Result<Self, TraceError> {
        let mut r = Self {
            input,
            label: label.to_string(),
            names: Vec::new(),
            required: [0; 4],
            keep_extra,
            extra: Vec::new(),
            line_no: 0,
            buf: Vec::with_capacity(256),
            time_decimals: None,
        };
        if !r.read_line()? {
            return Err(TraceError::Empty { path: r.label });
        }
        let header = text(&r.buf, &r.label, r.line_no)?;
        let names: Vec<String> = header
            .trim()
            .trim_start_matches('\u{feff}')
            .split(',')
            .map(|s| s.trim().to_string())
            .collect();
        for (i, n) in names.iter().enumerate() {
            if names[..i].contains(n) {
                return Err(TraceError::DuplicateColumn {
                    path: r.label,
                    column: n.clone(),
                });
            }
        }
        for (k, c) in REQUIRED_COLUMNS.iter().enumerate() {
            r.required[k] = names
                .iter()
                .position(|n| n == c)
                .ok_or_else(|| TraceError::MissingColumn {
                    path: r.label.clone(),
                    column: c.to_string(),
                })?;
        }
        r.names = names;
        Ok(r)
    }

    pub fn label(&self) -> &str {
        &self.label
    }

    /// Every column name, in file order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Names of the columns beyond the required four, in file order.
    pub fn extra_names(&self) -> impl Iterator<Item = &str> {
        self.names
            .iter()
            .enumerate()
            .filter(|(j, _)| !self.required.contains(j))
            .map(|(_, n)| n.as_str())
    }

    /// The extra columns' values of the latest row, in [`RowReader::extra_names`]
    /// order (empty unless constructed with `keep_extra`). A field that is not
    /// a number reads as NaN: further columns may hold text.
    pub fn extra(&self) -> &[f64] {
        &self.extra
    }

    /// Line number (1-based) of the latest row.
    pub fn line(&self) -> usize {
        self.line_no
    }

    /// The next non-blank row, `None` at the end of the input.
    pub fn next_row(&mut self) -> Result<Option<Row>, TraceError> {
        loop {
            if !self.read_line()? {
                return Ok(None);
            }
            let buf = std::mem::take(&mut self.buf);
            let parsed = self.parse(&buf);
            self.buf = buf;
            match parsed? {
                Some(row) => return Ok(Some(row)),
                None => continue,
            }
        }
    }

    /// One line's required values; `None` for a blank line.
    fn parse(&mut self, buf: &[u8]) -> Result<Option<Row>, TraceError> {
        let line = text(buf, &self.label, self.line_no)?;
        if line.trim().is_empty() {
            return Ok(None);
        }
        let mut values = [0.0f64; 4];
        self.extra.clear();
        let mut found = 0;
        for (j, f) in line.split(',').enumerate() {
            found += 1;
            if j >= self.names.len() {
                continue;
            }
            match self.required.iter().position(|&r| r == j) {
                Some(k) => {
                    if k == 0 {
                        let d = decimals(f);
                        self.time_decimals = Some(self.time_decimals.map_or(d, |m| m.max(d)));
                    }
                    values[k] =
                        f.trim()
                            .parse()
                            .ok()
                            .filter(|v: &f64| v.is_finite())
                            .ok_or_else(|| TraceError::BadNumber {
                                path: self.label.clone(),
                                line: self.line_no,
                                column: self.names[j].clone(),
                                text: f.trim().to_string(),
                            })?;
                }
                None if self.keep_extra => self.extra.push(f.trim().parse().unwrap_or(f64::NAN)),
                None => {}
            }
        }
        if found != self.names.len() {
            return Err(TraceError::FieldCount {
                path: self.label.clone(),
                line: self.line_no,
                expected: self.names.len(),
                found,
            });
        }
        Ok(Some(Row {
            t_s: values[0],
            p_rear_pa: values[1],
            p_front_pa: values[2],
            accel_mps2: values[3],
        }))
    }

    /// Reads one line into `buf`, bounded by [`MAX_LINE_BYTES`]; false at the end.
    fn read_line(&mut self) -> Result<bool, TraceError> {
        self.buf.clear();
        let limit = MAX_LINE_BYTES as u64;
        let n = std::io::Read::take(&mut self.input, limit)
            .read_until(b'\n', &mut self.buf)
            .map_err(|error| TraceError::Io {
                path: self.label.clone(),
                error,
            })?;
        if n == 0 {
            return Ok(false);
        }
        self.line_no += 1;
        if n as u64 == limit && self.buf.last() != Some(&b'\n') {
            return Err(TraceError::LineTooLong {
                path: self.label.clone(),
                line: self.line_no,
                max: MAX_LINE_BYTES,
            });
        }
        Ok(true)
    }
}

fn text<'a>(buf: &'a [u8], label: &str, line: usize) -> Result<&'a str, TraceError> {
    std::str::from_utf8(buf)
        .map(|s| s.trim_end_matches(['\n', '\r']))
        .map_err(|_| TraceError::NotUtf8 {
            path: label.to_string(),
            line,
        })
}

/// One step of a uniformly sampled trace.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Item {
    Sample(Row),
    /// `missing` sample periods with no row, before the next sample.
    Gap {
        missing: u64,
    },
}

/// The time-base layer over a [`RowSource`]: a sample period known up front,
/// gaps found, irregular timing refused with its line. An interval may miss
/// a whole number of periods by the tolerance, or by the time stamps'
/// resolution when that is coarser.
pub struct Uniform<S> {
    rows: S,
    /// Rows read ahead to find the period, with their line and extra values.
    ahead: VecDeque<(Row, usize, Vec<f64>)>,
    dt_s: f64,
    last_t_s: Option<f64>,
    pending: Option<Row>,
    extra: Vec<f64>,
    line: usize,
    /// Sample periods from the first row to the latest (gaps included).
    slots: u64,
    first_t_s: f64,
    /// How far an interval may miss a whole number of periods: the
    /// tolerance, or the stamps' resolution when they are rounded coarser.
    allowed_s: f64,
}

impl<S: RowSource> Uniform<S> {
    pub fn new(mut rows: S) -> Result<Self, TraceError> {
        let mut ahead = VecDeque::new();
        while ahead.len() <= LOOKAHEAD {
            match rows.next_row()? {
                Some(r) => ahead.push_back((r, rows.line(), rows.extra().to_vec())),
                None => break,
            }
        }
        if ahead.len() < 2 {
            return Err(TraceError::TooShort {
                path: rows.label().to_string(),
            });
        }
        let mut dt_s = period(ahead.iter().map(|(r, _, _)| r.t_s));
        let resolution = rows.time_resolution_s();
        // Rounding explains the spread of the first intervals (each within one
        // resolution step of a whole number of periods), and exceeds the tolerance.
        let rounded = dt_s > 0.0
            && resolution > UNIFORM_TOLERANCE * dt_s
            && ahead.iter().zip(ahead.iter().skip(1)).all(|((a, _, _), (b, _, _))| {
                let d = b.t_s - a.t_s;
                (d - (d / dt_s).round() * dt_s).abs() <= resolution * (1.0 + 1e-9)
            });
        if rounded {
            // Stamps rounded coarser than the tolerance: the period from a
            // longer span, so the rounding of its ends weighs little.
            while ahead.len() <= QUANTIZED_LOOKAHEAD {
                match rows.next_row()? {
                    Some(r) => ahead.push_back((r, rows.line(), rows.extra().to_vec())),
                    None => break,
                }
            }
            let slots: f64 = ahead
                .iter()
                .zip(ahead.iter().skip(1))
                .map(|((a, _, _), (b, _, _))| ((b.t_s - a.t_s) / dt_s).round().max(0.0))
                .sum();
            let span = ahead[ahead.len() - 1].0.t_s - ahead[0].0.t_s;
            if slots >= 1.0 && span > 0.0 {
                dt_s = span / slots;
            }
        }
        if !(dt_s > 0.0 && dt_s.is_finite()) {
            if let Some(w) = ahead.iter().zip(ahead.iter().skip(1)).find(|(a, b)| b.0.t_s < a.0.t_s) {
                return Err(backwards(rows.label(), w.1 .1, w.1 .0.t_s, w.0 .0.t_s));
            }
            let (r1, line, _) = &ahead[1];
            return Err(TraceError::NotUniform {
                path: rows.label().to_string(),
                line: *line,
                got_s: r1.t_s - ahead[0].0.t_s,
                expected_s: dt_s,
            });
        }
        let first_t_s = ahead[0].0.t_s;
        let allowed_s = if rounded {
            resolution * (1.0 + 1e-9)
        } else {
            UNIFORM_TOLERANCE * dt_s
        };
        if let Some((stated, what)) = rows.stated_period_s() {
            if !((dt_s / stated - 1.0).abs() <= UNIFORM_TOLERANCE) {
                return Err(TraceError::Import {
                    path: rows.label().to_string(),
                    message: format!(
                        "{what} disagree: the time stamps run at {} Hz, the rate says {} Hz; drop the wrong one (the time stamps are read when both agree)",
                        fmt_hz(1.0 / dt_s),
                        fmt_hz(1.0 / stated)
                    ),
                });
            }
        }
        Ok(Self {
            allowed_s,
            rows,
            ahead,
            dt_s,
            last_t_s: None,
            pending: None,
            extra: Vec::new(),
            line: 0,
            slots: 0,
            first_t_s,
        })
    }

    /// The sample period, from the first rows.
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// Where the rows come from.
    pub fn source(&self) -> &S {
        &self.rows
    }

    /// Extra column values of the latest sample (see [`RowReader::extra`]).
    pub fn extra(&self) -> &[f64] {
        &self.extra
    }

    /// Time of the first sample.
    pub fn first_t_s(&self) -> f64 {
        self.first_t_s
    }

    /// Sample periods between the first and the latest sample, gaps included.
    pub fn slots(&self) -> u64 {
        self.slots
    }

    pub fn next_item(&mut self) -> Result<Option<Item>, TraceError> {
        if let Some(r) = self.pending.take() {
            return Ok(Some(Item::Sample(r)));
        }
        let (row, line) = match self.ahead.pop_front() {
            Some((r, line, extra)) => {
                self.extra = extra;
                (r, line)
            }
            None => match self.rows.next_row()? {
                Some(r) => {
                    self.extra.clear();
                    self.extra.extend_from_slice(self.rows.extra());
                    (r, self.rows.line())
                }
                None => return Ok(None),
            },
        };
        self.line = line;
        let Some(last) = self.last_t_s.replace(row.t_s) else {
            return Ok(Some(Item::Sample(row)));
        };
        let d = row.t_s - last;
        if d < 0.0 {
            return Err(backwards(self.rows.label(), line, row.t_s, last));
        }
        let k = (d / self.dt_s).round();
        // A step that overflows, or a "gap" longer than the estimator can count
        // (hours at full rate), is not a gap in one recording: refuse it here.
        if !(k >= 1.0 && k <= MAX_GAP_SLOTS) || (d - k * self.dt_s).abs() > self.allowed_s {
            return Err(TraceError::NotUniform {
                path: self.rows.label().to_string(),
                line,
                got_s: d,
                expected_s: self.dt_s,
            });
        }
        let k = k as u64;
        self.slots = self.slots.saturating_add(k);
        if k > 1 {
            self.pending = Some(row);
            return Ok(Some(Item::Gap { missing: k - 1 }));
        }
        Ok(Some(Item::Sample(row)))
    }

    /// Line number of the latest sample.
    pub fn line(&self) -> usize {
        self.line
    }
}

fn backwards(label: &str, line: usize, t_s: f64, previous_s: f64) -> TraceError {
    TraceError::TimeBackwards {
        path: label.to_string(),
        line,
        t_s,
        previous_s,
    }
}

/// A rate for a message: whole hertz when it is one, else six significant digits.
fn fmt_hz(hz: f64) -> String {
    if (hz - hz.round()).abs() < 1e-6 * hz {
        format!("{}", hz.round())
    } else {
        format!("{hz:.6}")
    }
}

/// The longest step between two rows, in sample periods, taken as a gap.
const MAX_GAP_SLOTS: f64 = u32::MAX as f64;

/// The sample period from the first intervals: their median, then the mean
/// of those within tolerance of it (a gap among them does not bias it).
fn period(t: impl Iterator<Item = f64>) -> f64 {
    let t: Vec<f64> = t.collect();
    // Time runs forward: a backward step is an error found at its line later.
    let mut d: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).filter(|&x| x > 0.0).collect();
    if d.is_empty() {
        return f64::NAN;
    }
    let mut sorted = d.clone();
    sorted.sort_by(f64::total_cmp);
    let median = sorted[(sorted.len() - 1) / 2];
    d.retain(|x| (x - median).abs() <= UNIFORM_TOLERANCE * median.abs());
    if d.is_empty() {
        return median;
    }
    let n = d.len() as f64;
    let sum = d.iter().sum::<f64>();
    if sum.is_finite() {
        sum / n
    } else {
        // Intervals near f64's range: each divided first, so none overflows.
        d.iter().map(|x| x / n).sum::<f64>()
    }
}
