//! Parquet: the project's own capture (`hammer capture --out X.parquet`) and
//! what pyarrow, pandas or Polars write (Snappy by default, also zstd).
//! Every numeric column becomes a channel; the capture's sidecar comes back
//! from the file's key-value metadata.

use parquet::file::reader::{FileReader, SerializedFileReader};
use parquet::record::Field;

use crate::import::columns::Channel;

/// Where `hammer capture` keeps the sidecar's JSON in a Parquet file.
pub const SIDECAR_KEY: &str = "hammer.sidecar";

/// Whether `head` starts a Parquet file.
pub fn is_parquet(head: &[u8]) -> bool {
    head.starts_with(b"PAR1")
}

/// Every numeric column (a null reads as NaN, refused later if a signal
/// holds one), and the sidecar's JSON if the file carries one.
pub fn read(bytes: Vec<u8>) -> Result<(Vec<Channel>, Option<String>), String> {
    // A panic inside the decoder on a malformed file is that file's error,
    // not the tool's end (the crate is not ours to fix).
    std::panic::catch_unwind(move || read_inner(bytes))
        .unwrap_or_else(|_| Err("the Parquet decoder failed on this file (malformed)".into()))
}

fn read_inner(bytes: Vec<u8>) -> Result<(Vec<Channel>, Option<String>), String> {
    let reader = SerializedFileReader::new(bytes::Bytes::from(bytes)).map_err(|e| format!("Parquet: {e}"))?;
    let meta = reader.metadata().file_metadata();
    let sidecar = meta
        .key_value_metadata()
        .and_then(|kv| kv.iter().find(|k| k.key == SIDECAR_KEY))
        .and_then(|k| k.value.clone());
    let names: Vec<String> = meta
        .schema_descr()
        .columns()
        .iter()
        .map(|c| c.path().string())
        .collect();
    let mut values: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
    let mut numeric = vec![true; names.len()];
    let rows = reader.get_row_iter(None).map_err(|e| format!("Parquet: {e}"))?;
    for (i, row) in rows.enumerate() {
        let row = row.map_err(|e| format!("Parquet row {}: {e}", i + 1))?;
        for (k, (_, f)) in row.get_column_iter().enumerate().take(names.len()) {
            let v = match f {
                Field::Double(v) => *v,
                Field::Float(v) => *v as f64,
                Field::Byte(v) => *v as f64,
                Field::Short(v) => *v as f64,
                Field::Int(v) => *v as f64,
                Field::Long(v) => *v as f64,
                Field::UByte(v) => *v as f64,
                Field::UShort(v) => *v as f64,
                Field::UInt(v) => *v as f64,
                Field::ULong(v) => *v as f64,
                Field::Null => f64::NAN,
                _ => {
                    numeric[k] = false;
                    f64::NAN
                }
            };
            if numeric[k] {
                values[k].push(v);
            }
        }
    }
    let channels = names
        .into_iter()
        .zip(values)
        .zip(numeric)
        .filter(|(_, n)| *n)
        .map(|((name, v), _)| Channel::new(name, v))
        .collect();
    Ok((channels, sidecar))
}
