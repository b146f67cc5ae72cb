//! Delimited text from a recorder: any delimiter, a decimal comma, preamble
//! lines, columns by name or position in any unit. Streamed row by row in
//! bounded memory like the project's own CSV (`crate::rows`).
//!
//! Fields follow RFC 4180: a field in double quotes may hold the delimiter
//! (pandas' `to_csv(decimal=",")` writes `"1,5"` under `,`); every row has
//! the header's count of fields, so a split number never shifts the columns.
//! Without `decimal` in the map, the decimal separator is found from the
//! first rows: numbers written with commas and none with points are read
//! with a decimal comma.

use std::io::BufRead;

use crate::import::mapping::{ColumnRef, ImportMap, Resolved};
use crate::rows::{decimals, resolution_of, Row, RowSource, MAX_LINE_BYTES};
use crate::trace::TraceError;

/// Lines searched for the header row when the map gives no `skip_lines`.
pub const HEADER_SEARCH_LINES: usize = 64;
/// Rows read ahead to tell a decimal comma from a decimal point (and,
/// without a header, the delimiter).
const DECIMAL_SEARCH_ROWS: usize = 64;
/// Delimiters tried, in order, when the map gives none.
const DELIMITERS: [char; 4] = [';', '\t', ',', '|'];

pub struct Delimited<R> {
    input: R,
    label: String,
    delimiter: char,
    decimal_comma: bool,
    /// The header's names (empty without a header).
    pub names: Vec<String>,
    /// Column index of t (None: from the rate), p_rear, p_front, accel.
    cols: [Option<usize>; 4],
    signals: [Resolved; 4],
    increment_s: Option<f64>,
    /// A rate the map gives besides the time column: checked against it.
    stated: Option<(f64, String)>,
    atmosphere_pa: f64,
    line_no: usize,
    /// Line of the latest row.
    current: usize,
    samples: usize,
    buf: Vec<u8>,
    /// Lines read ahead while looking for the header, to be parsed as rows.
    pending: std::collections::VecDeque<(usize, Vec<u8>)>,
    time_decimals: Option<i32>,
    /// The header line (1-based), 0 without one.
    pub header_line: usize,
    field: String,
    /// Fields of the latest row, as byte ranges of its line.
    ranges: Vec<(usize, usize)>,
    /// Fields every row has: the header's, or the first row's without one.
    width: Option<usize>,
}

impl<R: BufRead> Delimited<R> {
    pub fn new(mut input: R, label: &str, map: &ImportMap) -> Result<Self, TraceError> {
        let err = |message: String| TraceError::Import {
            path: label.to_string(),
            message,
        };
        map.validate().map_err(|e| err(e.to_string()))?;
        let signals = [
            map.resolve("t").map_err(|e| err(e.to_string()))?,
            map.resolve("p_rear").map_err(|e| err(e.to_string()))?,
            map.resolve("p_front").map_err(|e| err(e.to_string()))?,
            map.resolve("accel").map_err(|e| err(e.to_string()))?,
        ];
        // A rate with no time column named: the time from the rate, unless
        // the header has the time column anyway (then checked against it).
        let rate = if map.has_time_column() {
            None
        } else {
            map.sample_rate_hz
        };
        let header = map.header.unwrap_or(true);
        // Read the lines up to the header (or the first row). The skipped
        // lines are read and dropped (bounded memory whatever the count):
        // `lines` starts at the header, or the first row.
        let mut lines: Vec<(usize, Vec<u8>)> = Vec::new();
        let skip = map.skip_lines.unwrap_or(0);
        let want = if map.skip_lines.is_some() || !header {
            1
        } else {
            HEADER_SEARCH_LINES
        };
        let mut line_no = 0;
        let mut buf = Vec::new();
        while lines.len() < want {
            if !read_line(&mut input, &mut buf, label, line_no + 1)? {
                break;
            }
            line_no += 1;
            if line_no > skip {
                lines.push((line_no, std::mem::take(&mut buf)));
            }
        }
        if skip > 0 && lines.is_empty() {
            return Err(err(format!(
                "import.skip_lines = {skip} skips past the end of the file (it has {line_no} lines)"
            )));
        }
        let text_of = |b: &[u8], n: usize| -> Result<String, TraceError> {
            std::str::from_utf8(b)
                .map(|s| {
                    s.trim_end_matches(['\n', '\r'])
                        .trim_start_matches('\u{feff}')
                        .to_string()
                })
                .map_err(|_| TraceError::NotUtf8 {
                    path: label.to_string(),
                    line: n,
                })
        };
        let named: Vec<&str> = signals
            .iter()
            .enumerate()
            .filter(|(k, _)| *k > 0 || rate.is_none())
            .filter_map(|(_, s)| match &s.column {
                ColumnRef::Name(n) => Some(n.as_str()),
                ColumnRef::Index(_) => None,
            })
            .collect();
        let configured = map.delimiter().map_err(|e| err(e.to_string()))?;
        // The header: the given line, or the first holding every named column.
        let mut header_at: Option<usize> = None;
        let mut delimiter = configured.unwrap_or(',');
        if header {
            match map.skip_lines {
                Some(_) => {
                    if lines.is_empty() {
                        return Err(TraceError::Empty { path: label.into() });
                    }
                    let text = text_of(&lines[0].1, lines[0].0)?;
                    delimiter = configured.unwrap_or_else(|| guess_delimiter(&text, &named));
                    header_at = Some(0);
                }
                None => {
                    'search: for (j, (n, b)) in lines.iter().enumerate() {
                        let Ok(text) = text_of(b, *n) else { continue };
                        let candidates: Vec<char> = configured.map_or(DELIMITERS.to_vec(), |d| vec![d]);
                        for d in candidates {
                            let fields = split(&text, d);
                            if !named.is_empty() && named.iter().all(|w| fields.iter().any(|f| f == w)) {
                                delimiter = d;
                                header_at = Some(j);
                                break 'search;
                            }
                        }
                    }
                    if header_at.is_none() {
                        if lines.is_empty() {
                            return Err(TraceError::Empty { path: label.into() });
                        }
                        // The file's own lines are not quoted: it may be anything.
                        return Err(err(format!(
                            "no header row with the columns {} in the first {HEADER_SEARCH_LINES} lines; name the columns in the mapping ([import.p_rear] column = ..., docs/trace-format.md), or give import.skip_lines",
                            named.iter().map(|n| format!("`{n}`")).collect::<Vec<_>>().join(", "),
                        )));
                    }
                }
            }
        }
        let (names, rest_from) = match header_at {
            Some(j) => {
                let text = text_of(&lines[j].1, lines[j].0)?;
                (split(&text, delimiter), j + 1)
            }
            None => (Vec::new(), 0),
        };
        let header_line = header_at.map_or(0, |j| lines[j].0);
        let mut pending: std::collections::VecDeque<(usize, Vec<u8>)> = lines.into_iter().skip(rest_from).collect();
        // The first rows, to find the delimiter (no header) and the decimal separator.
        while pending.len() < DECIMAL_SEARCH_ROWS {
            let mut buf = Vec::new();
            if !read_line(&mut input, &mut buf, label, line_no + 1)? {
                break;
            }
            line_no += 1;
            pending.push_back((line_no, buf));
        }
        if header_at.is_none() && configured.is_none() {
            if let Some((n, b)) = pending.front() {
                delimiter = guess_delimiter(&text_of(b, *n)?, &[]);
            }
        }
        let mut cols = [None; 4];
        for (k, s) in signals.iter().enumerate() {
            let by_name = |n: &str| {
                let at: Vec<usize> = (0..names.len()).filter(|&i| names[i] == n).collect();
                match at[..] {
                    [] => Ok(None),
                    [i] => Ok(Some(i)),
                    _ => Err(err(format!(
                        "the header names `{n}` {} times (columns {}): rename them apart, or map the one meant by its position ([import.{}] column = {})",
                        at.len(),
                        at.iter().map(|i| (i + 1).to_string()).collect::<Vec<_>>().join(", "),
                        s.signal,
                        at[0] + 1
                    ))),
                }
            };
            let c = match &s.column {
                ColumnRef::Index(i) => Some(i - 1),
                ColumnRef::Name(n) => by_name(n)?,
            };
            if k == 0 && rate.is_some() {
                // No time column mapped: the header's own `t_s`, if it has
                // one, is read and the rate checked against it.
                cols[0] = c;
                continue;
            }
            let c = c.ok_or_else(|| {
                err(format!(
                    "no column {} for {} (columns: {}); name it in the mapping ([import.{}] column = ...)",
                    s.column,
                    s.signal,
                    names.join(", "),
                    s.signal
                ))
            })?;
            if !names.is_empty() && c >= names.len() {
                return Err(err(format!(
                    "column #{} for {}: the header has {} columns",
                    c + 1,
                    s.signal,
                    names.len()
                )));
            }
            cols[k] = Some(c);
        }
        let stated = match (map.sample_rate_hz, cols[0]) {
            (Some(fs), Some(_)) => Some((1.0 / fs, format!("import.sample_rate_hz = {fs}"))),
            _ => None,
        };
        let decimal_comma = match &map.decimal {
            Some(_) => map.decimal_comma(),
            None => comma_decimals(&pending, delimiter, &cols),
        };
        let width = (!names.is_empty()).then_some(names.len());
        Ok(Self {
            input,
            label: label.to_string(),
            delimiter,
            decimal_comma,
            names,
            cols,
            signals,
            increment_s: rate.filter(|_| cols[0].is_none()).map(|r| 1.0 / r),
            stated,
            atmosphere_pa: map.atmosphere_pa(),
            line_no,
            current: 0,
            samples: 0,
            buf: Vec::with_capacity(256),
            pending,
            time_decimals: None,
            header_line,
            field: String::new(),
            ranges: Vec::new(),
            width,
        })
    }

    pub fn delimiter(&self) -> char {
        self.delimiter
    }

    /// Whether numbers are read with a decimal comma (the map's, or found).
    pub fn decimal_comma(&self) -> bool {
        self.decimal_comma
    }

    /// The column each signal comes from (`t` is None with a sample rate).
    pub fn columns(&self) -> [(Option<usize>, &Resolved); 4] {
        [0, 1, 2, 3].map(|k| (self.cols[k], &self.signals[k]))
    }

    fn parse(&mut self, line: usize, buf: &[u8]) -> Result<Option<Row>, TraceError> {
        let text = std::str::from_utf8(buf).map_err(|_| TraceError::NotUtf8 {
            path: self.label.clone(),
            line,
        })?;
        let text = text.trim_end_matches(['\n', '\r']);
        if text.trim().is_empty() {
            return Ok(None);
        }
        if !field_ranges(text, self.delimiter, &mut self.ranges) {
            return Err(TraceError::Import {
                path: self.label.clone(),
                message: format!(
                    "line {line}: a quoted field is not closed on its line, or text follows its closing quote (RFC 4180; a field spanning lines is not read)"
                ),
            });
        }
        let found = self.ranges.len();
        let expected = *self.width.get_or_insert(found);
        if found != expected {
            return Err(TraceError::FieldCount {
                path: self.label.clone(),
                line,
                expected,
                found,
            });
        }
        let mut v = [f64::NAN; 4];
        for k in 0..4 {
            let Some(c) = self.cols[k] else { continue };
            let Some(&(a, b)) = self.ranges.get(c) else {
                return Err(TraceError::FieldCount {
                    path: self.label.clone(),
                    line,
                    expected: c + 1,
                    found,
                });
            };
            let f = text[a..b].trim();
            self.field.clear();
            if self.decimal_comma {
                self.field.extend(f.chars().map(|c| if c == ',' { '.' } else { c }));
            } else {
                self.field.push_str(f);
            }
            let Some(raw) = self.field.parse::<f64>().ok().filter(|x| x.is_finite()) else {
                return Err(self.bad_number(line, k, f));
            };
            if k == 0 {
                let d = decimals(f);
                self.time_decimals = Some(self.time_decimals.map_or(d, |m| m.max(d)));
            }
            if self.signals[k].below_vacuum(raw) {
                return Err(TraceError::Import {
                    path: self.label.clone(),
                    message: format!(
                        "line {line}: {}",
                        self.signals[k].vacuum_message(&self.column_name(k), raw)
                    ),
                });
            }
            v[k] = self.signals[k].si(raw, self.atmosphere_pa);
        }
        if self.cols[0].is_none() {
            v[0] = self.samples as f64 * self.increment_s.unwrap_or(f64::NAN);
        }
        for (k, x) in v.iter().enumerate() {
            if !x.is_finite() {
                return Err(TraceError::BadNumber {
                    path: self.label.clone(),
                    line,
                    column: self.column_name(k),
                    text: x.to_string(),
                });
            }
        }
        self.samples += 1;
        Ok(Some(Row {
            t_s: v[0],
            p_rear_pa: v[1],
            p_front_pa: v[2],
            accel_mps2: v[3],
        }))
    }

    /// A field that is not a number; one written with a decimal comma says
    /// how to read it so.
    fn bad_number(&self, line: usize, k: usize, f: &str) -> TraceError {
        if !self.decimal_comma && f.contains(',') && f.replace(',', ".").parse::<f64>().is_ok() {
            return TraceError::Import {
                path: self.label.clone(),
                message: format!(
                    "line {line}: column `{}`: `{f}` has a decimal comma, other rows a decimal point; for a decimal comma throughout set `decimal = \",\"` under [import]",
                    self.column_name(k)
                ),
            };
        }
        TraceError::BadNumber {
            path: self.label.clone(),
            line,
            column: self.column_name(k),
            text: f.to_string(),
        }
    }

    fn column_name(&self, k: usize) -> String {
        match self.cols[k].and_then(|c| self.names.get(c)) {
            Some(n) => n.clone(),
            None => match self.cols[k] {
                Some(c) => format!("#{} ({})", c + 1, self.signals[k].signal),
                None => self.signals[k].signal.to_string(),
            },
        }
    }
}

impl<R: BufRead> RowSource for Delimited<R> {
    fn next_row(&mut self) -> Result<Option<Row>, TraceError> {
        loop {
            let (line, buf) = match self.pending.pop_front() {
                Some(p) => p,
                None => {
                    let mut buf = std::mem::take(&mut self.buf);
                    if !read_line(&mut self.input, &mut buf, &self.label, self.line_no + 1)? {
                        self.buf = buf;
                        return Ok(None);
                    }
                    self.line_no += 1;
                    (self.line_no, buf)
                }
            };
            self.current = line;
            let r = self.parse(line, &buf);
            self.buf = buf;
            if let Some(row) = r? {
                return Ok(Some(row));
            }
        }
    }

    fn label(&self) -> &str {
        &self.label
    }

    fn line(&self) -> usize {
        self.current
    }

    fn time_resolution_s(&self) -> f64 {
        if self.cols[0].is_none() {
            return 0.0;
        }
        resolution_of(self.time_decimals) * self.signals[0].factor
    }

    fn stated_period_s(&self) -> Option<(f64, String)> {
        let c = self.cols[0]?;
        let (p, from) = self.stated.as_ref()?;
        let name = self.names.get(c).map_or(format!("#{}", c + 1), |n| format!("`{n}`"));
        Some((*p, format!("the time column {name} and {from}")))
    }
}

/// One line into `buf`, bounded by [`MAX_LINE_BYTES`]; false at the end.
fn read_line(input: &mut impl BufRead, buf: &mut Vec<u8>, label: &str, line: usize) -> Result<bool, TraceError> {
    buf.clear();
    let limit = MAX_LINE_BYTES as u64;
    let n = std::io::Read::take(&mut *input, limit)
        .read_until(b'\n', buf)
        .map_err(|error| TraceError::Io {
            path: label.to_string(),
            error,
        })?;
    if n == 0 {
        return Ok(false);
    }
    if n as u64 == limit && buf.last() != Some(&b'\n') {
        return Err(TraceError::LineTooLong {
            path: label.to_string(),
            line,
            max: MAX_LINE_BYTES,
        });
    }
    Ok(true)
}

/// The fields of `text` split at `d` by RFC 4180, as byte ranges (a quoted
/// field's range is inside its quotes; spaces around the quotes are
/// allowed). False for a quote not closed on the line, or text after a
/// closing quote.
pub fn field_ranges(text: &str, d: char, out: &mut Vec<(usize, usize)>) -> bool {
    out.clear();
    let pad = |s: &str| {
        if d == ' ' {
            s.len()
        } else {
            s.trim_start_matches(' ').len()
        }
    };
    let mut i = 0;
    loop {
        let rest = &text[i..];
        let lead = rest.len() - pad(rest);
        if !rest[lead..].starts_with('"') {
            match rest.find(d) {
                Some(k) => {
                    out.push((i, i + k));
                    i += k + d.len_utf8();
                }
                None => {
                    out.push((i, text.len()));
                    return true;
                }
            }
            continue;
        }
        let start = i + lead + 1;
        let mut k = start;
        let end = loop {
            let Some(q) = text[k..].find('"') else {
                return false;
            };
            let q = k + q;
            if text[q + 1..].starts_with('"') {
                k = q + 2;
            } else {
                break q;
            }
        };
        out.push((start, end));
        let after = &text[end + 1..];
        let after = &after[after.len() - pad(after)..];
        if after.is_empty() {
            return true;
        }
        if !after.starts_with(d) {
            return false;
        }
        i = text.len() - after.len() + d.len_utf8();
    }
}

/// A line's fields, trimmed and unquoted (a line whose quotes do not
/// follow RFC 4180 is split at every delimiter, its quotes dropped).
pub fn split(text: &str, d: char) -> Vec<String> {
    let mut r = Vec::new();
    if field_ranges(text, d, &mut r) {
        r.iter()
            .map(|&(a, b)| text[a..b].trim().replace("\"\"", "\""))
            .collect()
    } else {
        text.split(d)
            .map(|f| f.trim().trim_matches('"').trim().to_string())
            .collect()
    }
}

/// Whether the first rows write their numbers with a decimal comma: some
/// signal field holds a comma and none a point.
fn comma_decimals(rows: &std::collections::VecDeque<(usize, Vec<u8>)>, d: char, cols: &[Option<usize>; 4]) -> bool {
    let (mut comma, mut point) = (false, false);
    let mut r = Vec::new();
    for (_, b) in rows {
        let Ok(text) = std::str::from_utf8(b) else { continue };
        if !field_ranges(text.trim_end_matches(['\n', '\r']), d, &mut r) {
            continue;
        }
        for &(a, b) in cols.iter().flatten().filter_map(|&c| r.get(c)) {
            let f = text[a..b].trim();
            point |= f.contains('.');
            comma |= f.contains(',') && f.replace(',', ".").parse::<f64>().is_ok();
        }
    }
    comma && !point
}

/// The delimiter of a line: the first of [`DELIMITERS`] that splits it into
/// fields holding every name in `named` (or, with no names, that occurs).
fn guess_delimiter(text: &str, named: &[&str]) -> char {
    DELIMITERS
        .into_iter()
        .find(|&d| {
            let f = split(text, d);
            if named.is_empty() {
                f.len() > 1
            } else {
                named.iter().all(|w| f.iter().any(|x| x == w))
            }
        })
        .unwrap_or(',')
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::mapping::{ColumnRef, Signal};

    fn sig(col: ColumnRef, unit: &str) -> Option<Signal> {
        Some(Signal {
            column: Some(col),
            unit: Some(unit.into()),
            ..Signal::default()
        })
    }

    /// Tab-separated, no header, columns by position, a sample rate instead
    /// of a time column, absolute kPa, an inverted accelerometer in g.
    #[test]
    fn positions_a_rate_absolute_pressure_and_a_sign() {
        let map = ImportMap {
            delimiter: Some("\\t".into()),
            header: Some(false),
            skip_lines: Some(1),
            sample_rate_hz: Some(50_000.0),
            p_rear: Some(Signal {
                absolute: true,
                ..sig(ColumnRef::Index(2), "kPa").unwrap()
            }),
            p_front: sig(ColumnRef::Index(3), "psi"),
            accel: Some(Signal {
                sign: Some(-1.0),
                ..sig(ColumnRef::Index(1), "g").unwrap()
            }),
            ..ImportMap::default()
        };
        let text = "logger v2 (no header below)\n1\t201.325\t0\n-2\t101.325\t14.5\n";
        let mut d = Delimited::new(text.as_bytes(), "t.tsv", &map).unwrap();
        let r0 = d.next_row().unwrap().unwrap();
        let r1 = d.next_row().unwrap().unwrap();
        assert!(d.next_row().unwrap().is_none());
        assert_eq!((r0.t_s, r1.t_s), (0.0, 2e-5));
        assert!(
            (r0.p_rear_pa - 1e5).abs() < 1e-6 && r1.p_rear_pa.abs() < 1e-6,
            "{r0:?} {r1:?}"
        );
        assert!((r1.p_front_pa - 14.5 * 6_894.757_293_168_361).abs() < 1e-6);
        assert_eq!((r0.accel_mps2, r1.accel_mps2), (-9.806_65, 2.0 * 9.806_65));
    }

    /// A unit of the wrong kind, a missing column and a bad number are
    /// named with what to do.
    #[test]
    fn mapping_errors_name_the_key_and_the_choices() {
        let map = ImportMap {
            p_rear: sig(ColumnRef::Name("P1".into()), "g"),
            ..ImportMap::default()
        };
        let e = Delimited::new("P1;p_front_pa\n".as_bytes(), "x.csv", &map)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("import.p_rear.unit") && e.contains("bar"), "{e}");
        let map = ImportMap {
            p_rear: sig(ColumnRef::Name("P1".into()), "bar"),
            ..ImportMap::default()
        };
        let e = Delimited::new("P9;p_front_pa;accel_mps2;t_s\n1;2;3;4\n".as_bytes(), "x.csv", &map)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("no header row") && e.contains("`P1`"), "{e}");
        let mut d = Delimited::new("t_s;P1;p_front_pa;accel_mps2\n0;1;2;x\n".as_bytes(), "x.csv", &map).unwrap();
        let e = d.next_row().unwrap_err().to_string();
        assert!(
            e.contains("x.csv:2") && e.contains("accel_mps2") && e.contains("`x`"),
            "{e}"
        );
    }

    /// RFC 4180: a quoted field holds the delimiter and escaped quotes; a
    /// quote left open or followed by text is malformed.
    #[test]
    fn quoted_fields_keep_their_delimiters() {
        let mut r = Vec::new();
        let line = "\"0,5\", 7 ,\"a\"\"b\",,\"x\" ";
        assert!(field_ranges(line, ',', &mut r));
        let f: Vec<&str> = r.iter().map(|&(a, b)| &line[a..b]).collect();
        assert_eq!(f, ["0,5", " 7 ", "a\"\"b", "", "x"]);
        assert_eq!(split(line, ',')[2], "a\"b");
        assert!(!field_ranges("\"1,5;2", ';', &mut r), "a quote left open");
        assert!(!field_ranges("\"1\"5;2", ';', &mut r), "text after the closing quote");
    }

    /// A decimal comma is found from the rows under `;` and inside quotes
    /// under `,`; a file with points keeps them.
    #[test]
    fn the_decimal_comma_is_found_from_the_rows() {
        let read = |text: &str| {
            let mut d = Delimited::new(text.as_bytes(), "x.csv", &ImportMap::default()).unwrap();
            (d.decimal_comma(), d.next_row().unwrap().unwrap())
        };
        let head = "t_s;p_rear_pa;p_front_pa;accel_mps2\n";
        let (comma, r) = read(&format!("{head}0;1,5;-2,25;3\n"));
        assert!(comma);
        assert_eq!((r.p_rear_pa, r.p_front_pa, r.accel_mps2), (1.5, -2.25, 3.0));
        let (comma, r) = read("t_s,p_rear_pa,p_front_pa,accel_mps2\n\"0,0\",\"1,5\",2,\"3,0\"\n");
        assert!(comma);
        assert_eq!((r.p_rear_pa, r.p_front_pa), (1.5, 2.0));
        let (comma, r) = read(&format!("{head}0;1.5;2;3\n"));
        assert!(!comma);
        assert_eq!(r.p_rear_pa, 1.5);
    }
}
