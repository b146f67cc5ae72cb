//! `--parquet DIR` and `--influx DEST`: every report of every device, to the
//! engines analysts and condition-monitoring people already run. One
//! [`Exports`] is shared by the devices' readers (one dataset, one
//! connection); each reader keeps its device's [`DeviceExport`] state (its
//! name, the time anchor, the configured supply pressure).
//!
//! An export that fails does not stop the monitor or the logs: it says so
//! (a note on screen, at most every [`NOTE_EVERY`]) and counts the rows it
//! could not deliver, shown when the monitor stops.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::Result;
use hammer_wire::DeviceMsg;

use super::event::{Event, Stamped};
use crate::influx::{self, Anchor, Destination};
use crate::parquet_files::PartitionedWriter;

/// A failing export says so at most this often.
pub const NOTE_EVERY: Duration = Duration::from_secs(10);

/// Where reports go besides the screen and the logs.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ExportArgs {
    /// Write cycle reports as Parquet into DIR, partitioned
    /// device=<name>/date=<YYYY-MM-DD>/ (docs/fleet.md).
    #[arg(long, value_name = "DIR")]
    pub parquet: Option<PathBuf>,
    /// Write cycle reports as InfluxDB line protocol to a FILE (appended),
    /// udp://HOST:PORT or http://HOST:PORT/PATH (a write endpoint; gzip;
    /// token from INFLUX_TOKEN).
    #[arg(long, value_name = "DEST")]
    pub influx: Option<String>,
    /// Site name: a tag on every exported report.
    #[arg(long)]
    pub site: Option<String>,
}

impl ExportArgs {
    pub fn any(&self) -> bool {
        self.parquet.is_some() || self.influx.is_some()
    }
}

/// The shared writers.
pub struct Exports {
    parquet: Option<PartitionedWriter>,
    influx: Option<influx::Writer>,
    site: Option<String>,
}

impl Exports {
    /// Opens what `args` asks for; an unusable destination is an error now,
    /// before any device is watched.
    pub fn open(args: &ExportArgs) -> Result<Option<Arc<Mutex<Self>>>> {
        if !args.any() {
            return Ok(None);
        }
        let parquet = args.parquet.as_deref().map(PartitionedWriter::new).transpose()?;
        let influx = args
            .influx
            .as_deref()
            .map(|d| Destination::parse(d).and_then(influx::Writer::open))
            .transpose()?;
        Ok(Some(Arc::new(Mutex::new(Self {
            parquet,
            influx,
            site: args.site.clone(),
        }))))
    }

    /// What was exported and what could not be, for the closing summary.
    pub fn summary(&self) -> String {
        let mut parts = vec![];
        if let Some(p) = &self.parquet {
            let s = p.stats();
            parts.push(format!(
                "parquet: {} reports in {} files, {} not written",
                s.rows, s.files, s.rows_failed
            ));
        }
        if let Some(w) = &self.influx {
            parts.push(format!(
                "influx: {} lines written, {} not delivered",
                w.lines, w.lines_failed
            ));
        }
        parts.join("; ")
    }

    /// Writes everything pending (Parquet files, the line batch).
    pub fn flush(&mut self) -> Result<()> {
        let p = self.parquet.as_mut().map_or(Ok(()), PartitionedWriter::flush);
        let i = self.influx.as_mut().map_or(Ok(()), influx::Writer::flush);
        p.and(i)
    }
}

/// One device's view of the shared exports.
pub struct DeviceExport {
    device: String,
    exports: Arc<Mutex<Exports>>,
    anchor: Anchor,
    supply_bar: Option<f64>,
    last_note: Option<Instant>,
    last_flush: Instant,
}

impl DeviceExport {
    pub fn new(device: &str, exports: Arc<Mutex<Exports>>) -> Self {
        Self {
            device: device.to_string(),
            exports,
            anchor: Anchor::default(),
            supply_bar: None,
            last_note: None,
            last_flush: Instant::now(),
        }
    }

    /// Takes in one event; returns a note to show when an export failed.
    pub fn event(&mut self, ev: &Stamped) -> Option<String> {
        let result = match &ev.event {
            Event::Connected { .. } => {
                self.anchor.reset();
                Ok(())
            }
            Event::Msg(DeviceMsg::Config(c)) => {
                let p = f64::from(c.supply_pressure_pa) / 1e5;
                self.supply_bar = p.is_finite().then_some(p);
                Ok(())
            }
            Event::Msg(DeviceMsg::Report(r)) => {
                let mut x = self.exports.lock().unwrap_or_else(|e| e.into_inner());
                let t_us = ev.t_us as i64;
                let p = match x.parquet.as_mut() {
                    Some(p) => p.push(&self.device, t_us, r),
                    None => Ok(()),
                };
                let site = x.site.clone();
                let i = match x.influx.as_mut() {
                    Some(w) => {
                        let t_ns = self.anchor.stamp_ns(r, t_us);
                        w.push(influx::line(&self.device, site.as_deref(), self.supply_bar, r, t_ns))
                    }
                    None => Ok(()),
                };
                p.and(i)
            }
            _ => Ok(()),
        };
        let result = if self.last_flush.elapsed() >= super::log::FLUSH_EVERY {
            self.last_flush = Instant::now();
            let mut x = self.exports.lock().unwrap_or_else(|e| e.into_inner());
            // The line batch goes out at the logs' pace; Parquet keeps its own.
            let i = x.influx.as_mut().map_or(Ok(()), influx::Writer::flush);
            result.and(i)
        } else {
            result
        };
        match result {
            Ok(()) => None,
            Err(e) if self.last_note.is_none_or(|t| t.elapsed() >= NOTE_EVERY) => {
                self.last_note = Some(Instant::now());
                Some(format!("export failed (counted, the logs are complete): {e:#}"))
            }
            Err(_) => None,
        }
    }
}
