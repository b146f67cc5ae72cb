//! Cycle reports and raw captures as Parquet, for analysts' engines
//! (DuckDB, Polars, pandas, Spark) rather than a reader of our own.
//!
//! A capture ([`write_trace`], `hammer capture --out X.parquet`) is the
//! trace format's columns (`t_s`, `p_rear_pa`, `p_front_pa`, `accel_mps2`,
//! DOUBLE) plus the ADC codes they came from (`rear_code`, `front_code`,
//! `accel_code`, INT32), with the sidecar's JSON in the file's key-value
//! metadata under `hammer.sidecar`.
//!
//! Cycle reports: The columns are the report's one
//! field table (`hammer_types::FIELDS`, through [`crate::records`]), so a
//! field added to `CycleReport` becomes a column here without touching this
//! file: `device`, `host_time` (UTC, µs; null where there is no host clock,
//! as in `hammer estimate`), every field under its unit-suffixed name in the
//! report's own type (u32 as INT64, f32 as FLOAT, f64 as DOUBLE), `valid`,
//! and `flags` (names joined by `|`, `-` when none, as in the CSV).
//!
//! [`PartitionedWriter`] lays files out the way those engines read a dataset
//! (hive partitions): `DIR/device=<name>/date=<YYYY-MM-DD>/part-<first host
//! time>-<first seq>.parquet`, zstd, one row group per file. A Parquet file
//! is unreadable until its footer is written, so rows are buffered and each
//! flush writes complete files: every `flush_every` of host time, at
//! `rows_per_file`, at midnight UTC and on close. A crash loses only the
//! rows since the last flush, and the monitor's `cycles.csv` has them too.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use anyhow::{bail, Context, Result};
use hammer_estimator::fields::{Value, FIELDS};
use hammer_estimator::CycleReport;
use parquet::basic::{Compression, ZstdLevel};
use parquet::data_type::{BoolType, ByteArray, ByteArrayType, DoubleType, FloatType, Int64Type};
use parquet::file::properties::WriterProperties;
use parquet::file::reader::{FileReader, SerializedFileReader};
use parquet::file::writer::SerializedFileWriter;
use parquet::record::Field as PqField;
use parquet::schema::parser::parse_message_type;

use crate::records::{flag_list, TRAILING_COLUMNS};

/// One row: a report, the device it came from and when the host received it.
#[derive(Debug, Clone)]
pub struct Row {
    pub device: String,
    /// Microseconds since the Unix epoch, UTC; `None` without a host clock.
    pub host_time_us: Option<i64>,
    pub report: CycleReport,
}

/// The Parquet message type, from the field table.
pub fn schema_text() -> String {
    let mut s = String::from(
        "message cycle_report {\n  REQUIRED BYTE_ARRAY device (UTF8);\n  OPTIONAL INT64 host_time (TIMESTAMP(MICROS,true));\n",
    );
    let r = CycleReport::default();
    for f in &FIELDS {
        let kind = match f.value(&r) {
            Value::U32(_) => "INT64",
            Value::F32(_) => "FLOAT",
            Value::F64(_) => "DOUBLE",
        };
        s += &format!("  REQUIRED {kind} {};\n", f.name);
    }
    let [valid, flags] = TRAILING_COLUMNS;
    s += &format!("  REQUIRED BOOLEAN {valid};\n  REQUIRED BYTE_ARRAY {flags} (UTF8);\n}}\n");
    s
}

fn properties() -> Arc<WriterProperties> {
    Arc::new(
        WriterProperties::builder()
            .set_compression(Compression::ZSTD(ZstdLevel::try_new(3).expect("3 is a zstd level")))
            .set_created_by(format!("hammer-monitor {}", env!("CARGO_PKG_VERSION")))
            .build(),
    )
}

/// Writes `rows` as one Parquet file (one row group) to `out`.
pub fn write<W: Write + Send>(out: W, rows: &[Row]) -> Result<()> {
    let schema = Arc::new(parse_message_type(&schema_text()).context("the cycle report's Parquet schema")?);
    let mut writer = SerializedFileWriter::new(out, schema, properties())?;
    let mut group = writer.next_row_group()?;
    let mut column = 0usize;
    while let Some(mut col) = group.next_column()? {
        match column {
            0 => {
                let v: Vec<ByteArray> = rows.iter().map(|r| ByteArray::from(r.device.as_str())).collect();
                col.typed::<ByteArrayType>().write_batch(&v, None, None)?;
            }
            1 => {
                let v: Vec<i64> = rows.iter().filter_map(|r| r.host_time_us).collect();
                let def: Vec<i16> = rows.iter().map(|r| i16::from(r.host_time_us.is_some())).collect();
                col.typed::<Int64Type>().write_batch(&v, Some(&def), None)?;
            }
            c if c - 2 < FIELDS.len() => {
                let f = &FIELDS[c - 2];
                match f.value(&CycleReport::default()) {
                    Value::U32(_) => {
                        let v: Vec<i64> = rows.iter().map(|r| f.f64(&r.report) as i64).collect();
                        col.typed::<Int64Type>().write_batch(&v, None, None)?;
                    }
                    Value::F32(_) => {
                        let v: Vec<f32> = rows
                            .iter()
                            .map(|r| match f.value(&r.report) {
                                Value::F32(x) => x,
                                other => other.as_f64() as f32,
                            })
                            .collect();
                        col.typed::<FloatType>().write_batch(&v, None, None)?;
                    }
                    Value::F64(_) => {
                        let v: Vec<f64> = rows.iter().map(|r| f.f64(&r.report)).collect();
                        col.typed::<DoubleType>().write_batch(&v, None, None)?;
                    }
                }
            }
            c if c - 2 == FIELDS.len() => {
                let v: Vec<bool> = rows.iter().map(|r| r.report.is_valid()).collect();
                col.typed::<BoolType>().write_batch(&v, None, None)?;
            }
            _ => {
                let v: Vec<ByteArray> = rows
                    .iter()
                    .map(|r| ByteArray::from(flag_list(r.report.flags).as_str()))
                    .collect();
                col.typed::<ByteArrayType>().write_batch(&v, None, None)?;
            }
        }
        col.close()?;
        column += 1;
    }
    group.close()?;
    writer.close()?;
    Ok(())
}

/// The key of a capture's sidecar JSON in the file's key-value metadata
/// (the trace reader's, which reads it back).
pub use hammer_trace::import::parquet::SIDECAR_KEY;

/// A capture: its samples in physical units and the ADC codes, with the
/// sidecar's JSON, as one Parquet file (row groups of 2^20 samples).
pub fn write_trace<W: Write + Send>(
    out: W,
    trace: &hammer_trace::trace::Trace,
    codes: &[[u16; 3]],
    sidecar_json: &str,
) -> Result<()> {
    let n = trace.t_s.len();
    if codes.len() != n {
        bail!("{} sample-sets of codes for {n} samples", codes.len());
    }
    let schema = Arc::new(parse_message_type(
        "message capture {\n  REQUIRED DOUBLE t_s;\n  REQUIRED DOUBLE p_rear_pa;\n  REQUIRED DOUBLE p_front_pa;\n  \
         REQUIRED DOUBLE accel_mps2;\n  REQUIRED INT32 rear_code;\n  REQUIRED INT32 front_code;\n  REQUIRED INT32 accel_code;\n}\n",
    )?);
    let props = WriterProperties::builder()
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(3).expect("3 is a zstd level")))
        .set_created_by(format!("hammer-monitor {}", env!("CARGO_PKG_VERSION")))
        .set_key_value_metadata(Some(vec![parquet::file::metadata::KeyValue::new(
            SIDECAR_KEY.to_string(),
            sidecar_json.to_string(),
        )]))
        .build();
    let mut writer = SerializedFileWriter::new(out, schema, Arc::new(props))?;
    const GROUP: usize = 1 << 20;
    for start in (0..n.max(1)).step_by(GROUP) {
        let range = start..(start + GROUP).min(n);
        let mut group = writer.next_row_group()?;
        let mut column = 0usize;
        while let Some(mut col) = group.next_column()? {
            let doubles = [&trace.t_s, &trace.p_rear_pa, &trace.p_front_pa, &trace.accel_mps2];
            if column < 4 {
                col.typed::<DoubleType>()
                    .write_batch(&doubles[column][range.clone()], None, None)?;
            } else {
                let v: Vec<i32> = codes[range.clone()].iter().map(|c| i32::from(c[column - 4])).collect();
                col.typed::<parquet::data_type::Int32Type>()
                    .write_batch(&v, None, None)?;
            }
            col.close()?;
            column += 1;
        }
        group.close()?;
    }
    writer.close()?;
    Ok(())
}

/// A capture read back: (t_s, p_rear_pa, p_front_pa, accel_mps2, codes) and the sidecar's JSON.
pub type Capture = (Vec<[f64; 4]>, Vec<[u16; 3]>, Option<String>);

/// Reads a file [`write_trace`] wrote.
pub fn read_trace(path: &Path) -> Result<Capture> {
    let file = File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let reader = SerializedFileReader::new(file).with_context(|| format!("{} is not Parquet", path.display()))?;
    let sidecar = reader
        .metadata()
        .file_metadata()
        .key_value_metadata()
        .and_then(|kv| kv.iter().find(|k| k.key == SIDECAR_KEY))
        .and_then(|k| k.value.clone());
    let (mut samples, mut codes) = (vec![], vec![]);
    for row in reader.get_row_iter(None)? {
        let row = row?;
        let (mut s, mut c) = ([f64::NAN; 4], [0u16; 3]);
        for (k, (name, field)) in row.get_column_iter().enumerate() {
            match (k, field) {
                (0..=3, PqField::Double(v)) => s[k] = *v,
                (4..=6, PqField::Int(v)) => {
                    c[k - 4] = u16::try_from(*v).with_context(|| format!("{name}: {v} is not an ADC code"))?
                }
                _ => bail!("{}: column {name} holds an unexpected {field:?}", path.display()),
            }
        }
        samples.push(s);
        codes.push(c);
    }
    Ok((samples, codes, sidecar))
}

/// One row read back: device, host time, and every column after them as
/// [`Value`]s in field-table order, then `valid` and `flags`.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadRow {
    pub device: String,
    pub host_time_us: Option<i64>,
    pub values: Vec<Value>,
    pub valid: bool,
    pub flags: String,
}

impl ReadRow {
    /// True when this row holds `r`'s numbers exactly (NaN equal to NaN).
    pub fn holds(&self, r: &CycleReport) -> bool {
        let same = |a: Value, b: Value| match (a, b) {
            (Value::F32(x), Value::F32(y)) => x.to_bits() == y.to_bits(),
            (Value::F64(x), Value::F64(y)) => x.to_bits() == y.to_bits(),
            (a, b) => a == b,
        };
        self.values.len() == FIELDS.len()
            && FIELDS.iter().zip(&self.values).all(|(f, &v)| same(f.value(r), v))
            && self.valid == r.is_valid()
            && self.flags == flag_list(r.flags)
    }
}

/// Reads a file [`write`] wrote (any Parquet file with its columns, in fact).
pub fn read(path: &Path) -> Result<Vec<ReadRow>> {
    let file = File::open(path).with_context(|| format!("opening {}", path.display()))?;
    let reader = SerializedFileReader::new(file).with_context(|| format!("{} is not Parquet", path.display()))?;
    let mut rows = vec![];
    for row in reader.get_row_iter(None)? {
        let row = row?;
        let mut device = None;
        let mut host_time_us = None;
        let mut values = vec![];
        let (mut valid, mut flags) = (None, None);
        for (name, field) in row.get_column_iter() {
            match (name.as_str(), field) {
                ("device", PqField::Str(s)) => device = Some(s.clone()),
                ("host_time", PqField::TimestampMicros(t)) => host_time_us = Some(*t),
                ("host_time", PqField::Null) => {}
                ("valid", PqField::Bool(b)) => valid = Some(*b),
                ("flags", PqField::Str(s)) => flags = Some(s.clone()),
                (_, PqField::Long(v)) => {
                    values.push(Value::U32(u32::try_from(*v).context("a u32 column out of range")?))
                }
                (_, PqField::Float(v)) => values.push(Value::F32(*v)),
                (_, PqField::Double(v)) => values.push(Value::F64(*v)),
                (name, other) => bail!("{}: column {name} holds an unexpected {other:?}", path.display()),
            }
        }
        rows.push(ReadRow {
            device: device.context("no device column")?,
            host_time_us,
            values,
            valid: valid.context("no valid column")?,
            flags: flags.context("no flags column")?,
        });
    }
    Ok(rows)
}

/// Microseconds since the epoch of `t` (0 before it).
pub fn unix_us(t: SystemTime) -> i64 {
    t.duration_since(UNIX_EPOCH).map_or(0, |d| d.as_micros() as i64)
}

/// `YYYY-MM-DD` (UTC) of a time in µs since the epoch (civil from days, H. Hinnant's algorithm).
pub fn utc_date(us: i64) -> String {
    let days = us.div_euclid(86_400_000_000);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}

/// A directory name safe on every file system, from a device's name: what
/// is not ASCII alphanumeric, `-`, `_` or `.` becomes `_`.
fn partition_value(device: &str) -> String {
    let s: String = device
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() || s.starts_with('.') {
        format!("_{s}")
    } else {
        s
    }
}

/// What a [`PartitionedWriter`] has done, for the monitor's summary.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WriterStats {
    pub rows: u64,
    pub files: u64,
    /// Rows a failed write could not store (the error was reported).
    pub rows_failed: u64,
}

/// Cycle reports of any number of devices into a hive-partitioned dataset.
pub struct PartitionedWriter {
    dir: PathBuf,
    rows_per_file: usize,
    flush_every: Duration,
    last_flush_us: Option<i64>,
    /// Buffered rows by (device partition, date).
    pending: BTreeMap<(String, String), Vec<Row>>,
    stats: WriterStats,
}

impl PartitionedWriter {
    /// Row groups of 10 000 rows at most (about 8 min of one hammer at
    /// 21 Hz, ~1 MB before compression), flushed every 5 min.
    pub fn new(dir: &Path) -> Result<Self> {
        Self::with_limits(dir, 10_000, Duration::from_secs(300))
    }

    pub fn with_limits(dir: &Path, rows_per_file: usize, flush_every: Duration) -> Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            rows_per_file: rows_per_file.max(1),
            flush_every,
            last_flush_us: None,
            pending: BTreeMap::new(),
            stats: WriterStats::default(),
        })
    }

    pub fn stats(&self) -> WriterStats {
        self.stats
    }

    /// Buffers one report received at `host_time_us`; writes whatever is due.
    pub fn push(&mut self, device: &str, host_time_us: i64, report: &CycleReport) -> Result<()> {
        // The column holds the partition's value, so an engine that reads
        // both (hive partitioning) sees one name.
        let device = partition_value(device);
        let key = (device.clone(), utc_date(host_time_us));
        let rows = self.pending.entry(key).or_default();
        rows.push(Row {
            device,
            host_time_us: Some(host_time_us),
            report: *report,
        });
        let full = rows.len() >= self.rows_per_file;
        let last = *self.last_flush_us.get_or_insert(host_time_us);
        let due = host_time_us.saturating_sub(last) >= self.flush_every.as_micros() as i64;
        // A new date closes yesterday's partitions at once.
        let new_day = self.pending.len() > 1 && self.pending.keys().any(|(_, d)| *d != utc_date(host_time_us));
        if full || due || new_day {
            self.last_flush_us = Some(host_time_us);
            self.flush()?;
        }
        Ok(())
    }

    /// Writes every buffered row, one file per partition.
    pub fn flush(&mut self) -> Result<()> {
        let mut first_error = None;
        for ((device, date), rows) in std::mem::take(&mut self.pending) {
            if rows.is_empty() {
                continue;
            }
            let dir = self.dir.join(format!("device={device}")).join(format!("date={date}"));
            let first = &rows[0];
            let name = format!(
                "part-{}-{:010}.parquet",
                first.host_time_us.unwrap_or(0),
                first.report.seq
            );
            let result = std::fs::create_dir_all(&dir)
                .with_context(|| format!("creating {}", dir.display()))
                .and_then(|_| write_atomically(&dir.join(&name), &rows));
            match result {
                Ok(()) => {
                    self.stats.rows += rows.len() as u64;
                    self.stats.files += 1;
                }
                Err(e) => {
                    self.stats.rows_failed += rows.len() as u64;
                    first_error.get_or_insert(e);
                }
            }
        }
        match first_error {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

impl Drop for PartitionedWriter {
    fn drop(&mut self) {
        if let Err(e) = self.flush() {
            eprintln!("parquet: {e:#}");
        }
    }
}

/// A reader never sees a half-written file, and a failed one leaves no
/// temporary file behind ([`crate::private_files::write_complete`]).
fn write_atomically(path: &Path, rows: &[Row]) -> Result<()> {
    crate::private_files::write_complete(path, 0o644, |out| write(out, rows))
}

#[cfg(test)]
mod tests {
    use super::*;
    use hammer_estimator::Flags;

    fn report(seq: u32, friction_n: f32) -> CycleReport {
        CycleReport {
            seq,
            t_impact_us: 47_000 * u64::from(seq) + 1,
            friction_n,
            impact_energy_j: 3.5,
            drift_score: f32::NAN,
            calibration_hash: 0xDEAD_BEEF,
            flags: if seq % 3 == 0 {
                Flags::IMPLAUSIBLE
            } else {
                Flags::default()
            },
            ..Default::default()
        }
    }

    #[test]
    fn the_schema_has_a_column_per_field_in_table_order() {
        let text = schema_text();
        let schema = parse_message_type(&text).unwrap();
        let names: Vec<&str> = schema.get_fields().iter().map(|f| f.name()).collect();
        let mut expected = vec!["device", "host_time"];
        expected.extend(FIELDS.iter().map(|f| f.name));
        expected.extend(TRAILING_COLUMNS);
        assert_eq!(names, expected);
    }

    #[test]
    fn rows_read_back_bit_for_bit() {
        let dir = std::env::temp_dir().join(format!("hammer-parquet-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("one.parquet");
        let rows: Vec<Row> = (0..50)
            .map(|k| Row {
                device: "bench-a".into(),
                host_time_us: (k % 7 != 0).then_some(1_700_000_000_000_000 + i64::from(k) * 47_000),
                report: report(k, 10.0 + k as f32 / 8.0),
            })
            .collect();
        write(File::create(&path).unwrap(), &rows).unwrap();
        let back = read(&path).unwrap();
        assert_eq!(back.len(), rows.len());
        for (b, r) in back.iter().zip(&rows) {
            assert!(b.holds(&r.report), "{b:?} vs {:?}", r.report);
            assert_eq!(b.host_time_us, r.host_time_us);
            assert_eq!(b.device, "bench-a");
        }
        assert_eq!(back[3].flags, "implausible");
        assert!(!back[3].valid);
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// The chambers' columns, FLOAT like every f32 field; unread (NaN) they
    /// hold NaN, as every NaN field does, and read back to the bit.
    #[test]
    fn the_chambers_are_columns_and_read_back_read_or_not() {
        use crate::records::tests::{read_front, CHAMBERS};
        let schema = parse_message_type(&schema_text()).unwrap();
        for (name, _) in CHAMBERS {
            let f = schema.get_fields().iter().find(|f| f.name() == name);
            let f = f.unwrap_or_else(|| panic!("no column {name}"));
            assert_eq!(f.get_physical_type(), parquet::basic::Type::FLOAT, "{name}");
        }
        let path = std::env::temp_dir().join(format!("hammer-parquet-chambers-{}.parquet", std::process::id()));
        let mut unread = report(1, 10.0);
        unread.mark_chambers_unread();
        let reports = [unread, read_front(report(2, 11.0))];
        let rows: Vec<Row> = reports
            .iter()
            .map(|r| Row {
                device: "d".into(),
                host_time_us: None,
                report: *r,
            })
            .collect();
        write(File::create(&path).unwrap(), &rows).unwrap();
        let back = read(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert_eq!(back.len(), 2);
        let at = |name: &str| FIELDS.iter().position(|f| f.name == name).unwrap();
        for (b, r) in back.iter().zip(&reports) {
            assert!(b.holds(r), "{b:?} vs {r:?}");
            for (name, _) in CHAMBERS {
                assert!(
                    b.values[at(name)].same(FIELDS[at(name)].value(r)),
                    "{name}: {:?}",
                    b.values[at(name)]
                );
            }
        }
        assert!(matches!(back[0].values[at("front_feed_s")], Value::F32(v) if v.is_nan()));
        assert_eq!(back[1].values[at("front_feed_s")], Value::F32(1.57e-3));
        assert!(matches!(back[1].values[at("rear_feed_s")], Value::F32(v) if v.is_nan()));
        assert_eq!(back[0].flags, "chambers_unread");
        assert_eq!(back[1].flags, "-");
    }

    #[test]
    fn a_partitioned_dataset_splits_by_device_and_date_and_loses_nothing() {
        let dir = std::env::temp_dir().join(format!("hammer-parquet-ds-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        // 23:59:58 UTC: the day changes two seconds in.
        let t0 = 1_700_006_398_000_000i64;
        assert_eq!(utc_date(t0), "2023-11-14");
        assert_eq!(utc_date(t0 + 2_000_000), "2023-11-15");
        let mut w = PartitionedWriter::with_limits(&dir, 40, Duration::from_secs(3600)).unwrap();
        for k in 0..100u32 {
            let t = t0 + i64::from(k) * 47_000;
            w.push("bench/a", t, &report(k, 10.0)).unwrap();
            w.push("b", t + 1, &report(k, 12.0)).unwrap();
        }
        drop(w);
        let mut files = vec![];
        let mut stack = vec![dir.clone()];
        while let Some(d) = stack.pop() {
            for e in std::fs::read_dir(&d).unwrap() {
                let p = e.unwrap().path();
                if p.is_dir() {
                    stack.push(p);
                } else {
                    files.push(p);
                }
            }
        }
        files.sort();
        assert!(files.iter().all(|f| f.extension().unwrap() == "parquet"), "{files:?}");
        let rel: Vec<String> = files
            .iter()
            .map(|f| f.parent().unwrap().strip_prefix(&dir).unwrap().display().to_string())
            .collect();
        assert!(rel.contains(&"device=bench_a/date=2023-11-14".to_string()), "{rel:?}");
        assert!(rel.contains(&"device=b/date=2023-11-15".to_string()), "{rel:?}");
        for device in ["bench_a", "b"] {
            let mut seqs: Vec<u32> = files
                .iter()
                .flat_map(|f| read(f).unwrap())
                .filter(|r| r.device == device)
                .map(|r| match r.values[0] {
                    Value::U32(s) => s,
                    v => panic!("{v:?}"),
                })
                .collect();
            seqs.sort_unstable();
            assert_eq!(seqs, (0..100).collect::<Vec<_>>(), "{device}: every report once");
        }
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_capture_reads_back_with_its_codes_and_sidecar() {
        let n = 1000;
        let trace = hammer_trace::trace::Trace {
            dt_s: 1e-5,
            t_s: (0..n).map(|i| i as f64 * 1e-5).collect(),
            p_rear_pa: (0..n).map(|i| 1e5 + i as f64).collect(),
            p_front_pa: (0..n).map(|i| 2e5 - i as f64).collect(),
            accel_mps2: (0..n).map(|i| (i as f64).sin()).collect(),
            ..Default::default()
        };
        let codes: Vec<[u16; 3]> = (0..n).map(|i| [i as u16, 4095 - i as u16, 2048]).collect();
        let mut bytes = vec![];
        write_trace(&mut bytes, &trace, &codes, "{\"supply_bar\":4}").unwrap();
        let path = std::env::temp_dir().join(format!("hammer-capture-{}.parquet", std::process::id()));
        std::fs::write(&path, &bytes).unwrap();
        let (samples, back_codes, sidecar) = read_trace(&path).unwrap();
        assert_eq!(back_codes, codes);
        assert_eq!(sidecar.as_deref(), Some("{\"supply_bar\":4}"));
        for (i, s) in samples.iter().enumerate() {
            assert_eq!(
                *s,
                [
                    trace.t_s[i],
                    trace.p_rear_pa[i],
                    trace.p_front_pa[i],
                    trace.accel_mps2[i]
                ]
            );
        }
        assert!(
            write_trace(&mut vec![], &trace, &codes[1..], "{}").is_err(),
            "codes and samples must agree"
        );
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn a_garbage_file_is_an_error_not_a_panic() {
        let path = std::env::temp_dir().join(format!("hammer-parquet-bad-{}.parquet", std::process::id()));
        std::fs::write(&path, b"PAR1 not really").unwrap();
        let e = read(&path).unwrap_err();
        assert!(format!("{e:#}").contains("not Parquet"), "{e:#}");
        let _ = std::fs::remove_file(&path);
    }
}
