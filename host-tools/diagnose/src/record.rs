//! The hammer's reference record: what `hammer commission` writes into its
//! folder (`commission.json` beside one trace per captured cycle), read by
//! the diagnosis' inputs ([`crate::input::read_request`]: `hammer diagnose
//! --reference`, the Python package) and by the monitor's drift since
//! commissioning.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

/// The record's file in a commissioning folder.
pub const RECORD_FILE: &str = "commission.json";
pub const RECORD_FORMAT: &str = "hammer-commission";
pub const RECORD_VERSION: u32 = 1;

/// What `commission.json` holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Record {
    pub format: String,
    pub version: u32,
    /// `major.minor.patch` as the board reports it.
    pub firmware_version: String,
    pub board: String,
    /// CRC-32 of the channel calibrations the captures were read with.
    pub calibration_hash: u32,
    pub points: Vec<PointRecord>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PointRecord {
    pub supply_bar: f64,
    /// Trace files, relative to the folder.
    pub traces: Vec<String>,
}

impl Record {
    /// The record of `dir`, if it is a commissioning folder.
    pub fn load(dir: &Path) -> Result<Record> {
        let path = dir.join(RECORD_FILE);
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!(
                "{}: not a commissioning folder (no readable {RECORD_FILE})",
                dir.display()
            )
        })?;
        let r: Record =
            serde_json::from_str(&text).with_context(|| format!("{}: not a commissioning record", path.display()))?;
        if r.format != RECORD_FORMAT || r.version > RECORD_VERSION {
            bail!(
                "{}: format {} version {}, this tool reads {RECORD_FORMAT} up to version {RECORD_VERSION}",
                path.display(),
                r.format,
                r.version
            );
        }
        Ok(r)
    }

    /// Every trace of the record with its supply pressure.
    pub fn traces(&self, dir: &Path) -> Vec<(PathBuf, f64)> {
        self.points
            .iter()
            .flat_map(|p| p.traces.iter().map(|t| (dir.join(t), p.supply_bar)))
            .collect()
    }
}

/// Whether `path` is a commissioning folder.
pub fn is_record(path: &Path) -> bool {
    path.is_dir() && path.join(RECORD_FILE).is_file()
}
