//! Parquet: the project's own capture (`hammer capture --out X.parquet`) and
//! what pyarrow, pandas or Polars write (Snappy by default, also zstd).
//! Every numeric leaf column becomes a channel named by its full path, so a
//! struct's fields read as `meta.a`, `meta.b`. Read column by column (each
//! leaf's own reader), never by pairing a row's top-level fields with the
//! schema's leaves: a struct column would shift every later column's data
//! under another's name. The capture's sidecar comes back from the file's
//! key-value metadata.

use parquet::basic::{ConvertedType, LogicalType, Type as PhysicalType};
use parquet::column::reader::{get_typed_column_reader, ColumnReader};
use parquet::data_type::{DataType, DoubleType, FloatType, Int32Type, Int64Type};
use parquet::file::reader::{FileReader, SerializedFileReader};
use parquet::schema::types::ColumnDescriptor;

use crate::import::columns::Channel;

/// Where `hammer capture` keeps the sidecar's JSON in a Parquet file.
pub const SIDECAR_KEY: &str = "hammer.sidecar";
/// Values read per call of a column reader.
const BATCH: usize = 1 << 16;

/// Whether `head` starts a Parquet file.
pub fn is_parquet(head: &[u8]) -> bool {
    head.starts_with(b"PAR1")
}

/// What a Parquet file holds for the trace.
pub struct Read {
    /// Every numeric leaf column (a null reads as NaN, refused later if a signal holds one).
    pub channels: Vec<Channel>,
    /// Columns not read, each with why (text, timestamps, lists).
    pub skipped: Vec<String>,
    /// The sidecar's JSON, if the file carries one.
    pub sidecar: Option<String>,
}

/// Reads the file's numeric columns.
pub fn read(bytes: Vec<u8>) -> Result<Read, String> {
    // A panic inside the decoder on a malformed file is that file's error,
    // not the tool's end (the crate is not ours to fix).
    std::panic::catch_unwind(move || read_inner(bytes))
        .unwrap_or_else(|_| Err("the Parquet decoder failed on this file (malformed)".into()))
}

/// How a leaf's stored values become numbers.
#[derive(Clone, Copy)]
enum Kind {
    Double,
    Float,
    /// An integer (unsigned when stored so), times 10^-scale for a decimal.
    Int32 {
        unsigned: bool,
        scale: i32,
    },
    Int64 {
        unsigned: bool,
        scale: i32,
    },
}

/// The leaf's kind, or why it is not read as a signal.
fn kind(c: &ColumnDescriptor) -> Result<Kind, &'static str> {
    if c.max_rep_level() > 0 {
        return Err("a list");
    }
    let (mut unsigned, mut scale) = (false, 0);
    match c.logical_type_ref() {
        Some(LogicalType::Integer(i)) => unsigned = !i.is_signed,
        Some(LogicalType::Decimal(d)) => scale = d.scale,
        Some(LogicalType::Date | LogicalType::Time(_) | LogicalType::Timestamp(_)) => return Err("a date or time"),
        Some(LogicalType::Float16) => return Err("float16"),
        Some(_) => return Err("not numeric"),
        None => match c.converted_type() {
            ConvertedType::UINT_8 | ConvertedType::UINT_16 | ConvertedType::UINT_32 | ConvertedType::UINT_64 => {
                unsigned = true
            }
            ConvertedType::DECIMAL => scale = c.type_scale(),
            ConvertedType::NONE
            | ConvertedType::INT_8
            | ConvertedType::INT_16
            | ConvertedType::INT_32
            | ConvertedType::INT_64 => {}
            ConvertedType::DATE
            | ConvertedType::TIME_MILLIS
            | ConvertedType::TIME_MICROS
            | ConvertedType::TIMESTAMP_MILLIS
            | ConvertedType::TIMESTAMP_MICROS => return Err("a date or time"),
            _ => return Err("not numeric"),
        },
    }
    match c.physical_type() {
        PhysicalType::DOUBLE => Ok(Kind::Double),
        PhysicalType::FLOAT => Ok(Kind::Float),
        PhysicalType::INT32 => Ok(Kind::Int32 { unsigned, scale }),
        PhysicalType::INT64 => Ok(Kind::Int64 { unsigned, scale }),
        PhysicalType::BOOLEAN => Err("booleans"),
        _ => Err("not numeric"),
    }
}

fn read_inner(bytes: Vec<u8>) -> Result<Read, String> {
    let reader = SerializedFileReader::new(bytes::Bytes::from(bytes)).map_err(|e| format!("Parquet: {e}"))?;
    let meta = reader.metadata().file_metadata();
    let sidecar = meta
        .key_value_metadata()
        .and_then(|kv| kv.iter().find(|k| k.key == SIDECAR_KEY))
        .and_then(|k| k.value.clone());
    let schema = meta.schema_descr();
    let mut columns = Vec::new();
    let mut skipped = Vec::new();
    for (j, c) in schema.columns().iter().enumerate() {
        let name = c.path().string();
        match kind(c) {
            Ok(k) => columns.push((j, k, c.max_def_level(), Channel::new(name, Vec::new()))),
            Err(why) => skipped.push(format!("`{name}` ({why})")),
        }
    }
    let rows = usize::try_from(meta.num_rows()).unwrap_or(0);
    for g in 0..reader.num_row_groups() {
        let group = reader.get_row_group(g).map_err(|e| format!("Parquet: {e}"))?;
        for (j, k, max_def, ch) in columns.iter_mut() {
            let col = group
                .get_column_reader(*j)
                .map_err(|e| format!("Parquet column `{}`: {e}", ch.name))?;
            let before = ch.values.len();
            let read = match *k {
                Kind::Double => leaf::<DoubleType>(col, *max_def, &mut ch.values, |v| v),
                Kind::Float => {
                    ch.float32 = true;
                    leaf::<FloatType>(col, *max_def, &mut ch.values, f64::from)
                }
                Kind::Int32 { unsigned, scale } => {
                    let f = 10f64.powi(-scale);
                    leaf::<Int32Type>(col, *max_def, &mut ch.values, |v| {
                        f * if unsigned { v as u32 as f64 } else { v as f64 }
                    })
                }
                Kind::Int64 { unsigned, scale } => {
                    let f = 10f64.powi(-scale);
                    leaf::<Int64Type>(col, *max_def, &mut ch.values, |v| {
                        f * if unsigned { v as u64 as f64 } else { v as f64 }
                    })
                }
            };
            read.map_err(|e| format!("Parquet column `{}`: {e}", ch.name))?;
            let want = usize::try_from(group.metadata().num_rows()).unwrap_or(usize::MAX);
            if ch.values.len() - before != want {
                return Err(format!(
                    "Parquet column `{}`: {} values in row group {}, which has {want} rows",
                    ch.name,
                    ch.values.len() - before,
                    g + 1
                ));
            }
        }
    }
    let channels: Vec<Channel> = columns.into_iter().map(|(_, _, _, c)| c).collect();
    if let Some(c) = channels.iter().find(|c| c.values.len() != rows) {
        return Err(format!(
            "Parquet column `{}`: {} values, the file claims {rows} rows",
            c.name,
            c.values.len()
        ));
    }
    Ok(Read {
        channels,
        skipped,
        sidecar,
    })
}

/// One leaf column of a row group into `out`, a null as NaN.
fn leaf<T: DataType>(
    col: ColumnReader,
    max_def: i16,
    out: &mut Vec<f64>,
    conv: impl Fn(T::T) -> f64,
) -> Result<(), parquet::errors::ParquetError>
where
    T::T: Copy,
{
    let mut r = get_typed_column_reader::<T>(col);
    let mut values: Vec<T::T> = Vec::with_capacity(BATCH);
    let mut defs: Vec<i16> = Vec::with_capacity(BATCH);
    loop {
        values.clear();
        defs.clear();
        let (records, _, levels) = r.read_records(BATCH, (max_def > 0).then_some(&mut defs), None, &mut values)?;
        if records == 0 {
            return Ok(());
        }
        if max_def == 0 {
            out.extend(values.iter().map(|&v| conv(v)));
        } else {
            let mut it = values.iter();
            for &d in &defs[..levels] {
                out.push(if d == max_def {
                    it.next().map_or(f64::NAN, |&v| conv(v))
                } else {
                    f64::NAN
                });
            }
        }
    }
}
