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

use serde_json::json;

use super::event::{describe, firmware_version, rfc3339, Event, Stamped};
use crate::influx::{self, Anchor, Destination};
use crate::mqtt;
use crate::parquet_files::PartitionedWriter;

/// A failing export says so at most this often.
pub const NOTE_EVERY: Duration = Duration::from_secs(10);

/// Where reports go besides the screen and the logs.
#[derive(clap::Args, Debug, Clone)]
pub struct ExportArgs {
    /// Write cycle reports as Parquet into DIR, partitioned
    /// device=<name>/date=<YYYY-MM-DD>/ (docs/fleet.md).
    #[arg(long, value_name = "DIR")]
    pub parquet: Option<PathBuf>,
    /// Write cycle reports as InfluxDB line protocol to a FILE (appended),
    /// udp://HOST:PORT or http(s)://HOST:PORT/PATH (a write endpoint; gzip;
    /// token from INFLUX_TOKEN or --influx-token-file).
    #[arg(long, value_name = "DEST")]
    pub influx: Option<String>,
    #[command(flatten)]
    pub influx_http: influx::HttpArgs,
    /// Publish every report, status, alarm and link event to an MQTT
    /// broker, mqtt://HOST[:PORT] or over TLS mqtts://HOST[:PORT], under
    /// hammer/<site>/<device>/ (docs/fleet.md).
    #[arg(long, value_name = "URL")]
    pub mqtt: Option<String>,
    #[command(flatten)]
    pub broker: mqtt::BrokerArgs,
    /// The MQTT outage buffer's directory (default: the user's own,
    /// $XDG_STATE_HOME/hammer/mqtt-buffer or ~/.local/state/hammer/mqtt-buffer);
    /// used only if private to this user. A buffer left by an earlier run is replayed.
    #[arg(long, value_name = "DIR")]
    pub mqtt_buffer: Option<PathBuf>,
    /// The outage buffer's cap per device, MB; beyond it the oldest
    /// messages are dropped and counted.
    #[arg(long, value_name = "MB", default_value_t = crate::mqtt::DEFAULT_BUFFER_MB)]
    pub mqtt_buffer_mb: f64,
    /// Site name: the MQTT topics' second level (default `lab`) and a tag
    /// on every line-protocol point.
    #[arg(long)]
    pub site: Option<String>,
}

impl Default for ExportArgs {
    fn default() -> Self {
        Self {
            parquet: None,
            influx: None,
            influx_http: Default::default(),
            mqtt: None,
            broker: Default::default(),
            mqtt_buffer: None,
            mqtt_buffer_mb: crate::mqtt::DEFAULT_BUFFER_MB,
            site: None,
        }
    }
}

impl ExportArgs {
    pub fn any(&self) -> bool {
        self.parquet.is_some() || self.influx.is_some() || self.mqtt.is_some()
    }
}

/// The shared writers.
pub struct Exports {
    parquet: Option<PartitionedWriter>,
    influx: Option<influx::Writer>,
    site: Option<String>,
    /// The MQTT options but the device's name (each device has its own
    /// connection: the broker's last will is per connection).
    mqtt: Option<mqtt::Options>,
    /// The devices' MQTT summaries, as their publishers stop.
    mqtt_summaries: Vec<String>,
    /// A publisher lost messages or could not deliver them all.
    mqtt_lost: bool,
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
            .map(|d| Destination::parse(d).and_then(|d| influx::Writer::open(d, &args.influx_http)))
            .transpose()?;
        let mqtt = match &args.mqtt {
            Some(url) => {
                let endpoint = mqtt::Endpoint::resolve(url, &args.broker)?;
                let (buffer_dir, note) = mqtt::buffer_dir(args.mqtt_buffer.as_deref())?;
                if let Some(note) = note {
                    eprintln!("{note}");
                }
                if !(args.mqtt_buffer_mb.is_finite() && args.mqtt_buffer_mb > 0.0) {
                    anyhow::bail!("--mqtt-buffer-mb must be a positive number of MB");
                }
                Some(mqtt::Options {
                    endpoint,
                    site: args.site.clone().unwrap_or_else(|| "lab".into()),
                    device: String::new(),
                    buffer_dir,
                    buffer_bytes: (args.mqtt_buffer_mb * 1e6) as usize,
                })
            }
            None => None,
        };
        Ok(Some(Arc::new(Mutex::new(Self {
            parquet,
            influx,
            site: args.site.clone(),
            mqtt,
            mqtt_summaries: vec![],
            mqtt_lost: false,
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
        parts.extend(self.mqtt_summaries.iter().cloned());
        parts.join("; ")
    }

    /// What a sink lost or could not deliver, if anything: a run that lost
    /// data ends non-zero.
    pub fn loss(&self) -> Option<String> {
        let mut lost = vec![];
        if let Some(p) = &self.parquet {
            let s = p.stats();
            if s.rows_failed > 0 {
                lost.push(format!("{} reports not written to Parquet", s.rows_failed));
            }
        }
        if let Some(w) = &self.influx {
            if w.lines_failed > 0 {
                lost.push(format!("{} line-protocol points not delivered", w.lines_failed));
            }
        }
        if self.mqtt_lost {
            lost.push(
                "MQTT messages dropped, damaged or not delivered (those in the outage buffer go out with the next run)"
                    .to_string(),
            );
        }
        (!lost.is_empty()).then(|| lost.join(", "))
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
    mqtt: Option<mqtt::Publisher>,
    anchor: Anchor,
    supply_bar: Option<f64>,
    last_note: Option<Instant>,
    last_flush: Instant,
}

impl DeviceExport {
    pub fn new(device: &str, exports: Arc<Mutex<Exports>>) -> Self {
        let options = exports.lock().unwrap_or_else(|e| e.into_inner()).mqtt.clone();
        let mqtt = options.and_then(|o| {
            match mqtt::Publisher::start(mqtt::Options {
                device: device.to_string(),
                ..o
            }) {
                Ok(p) => Some(p),
                Err(e) => {
                    eprintln!("mqtt {device}: {e:#}; not publishing");
                    None
                }
            }
        });
        Self {
            device: device.to_string(),
            exports,
            mqtt,
            anchor: Anchor::default(),
            supply_bar: None,
            last_note: None,
            last_flush: Instant::now(),
        }
    }

    /// The event on the device's MQTT topics.
    fn publish(&mut self, ev: &Stamped) {
        let Some(p) = self.mqtt.as_mut() else { return };
        let host_time = rfc3339(ev.t_us);
        let (kind, body) = match &ev.event {
            Event::Device(info) => (
                mqtt::Kind::State,
                json!({
                    "online": true,
                    "board": String::from_utf8_lossy(&info.board),
                    "firmware": firmware_version(info.firmware_version),
                    "protocol": info.protocol_version,
                    "config_hash": format!("{:08x}", info.config_hash),
                }),
            ),
            Event::Msg(DeviceMsg::Report(r)) => (mqtt::Kind::Cycle, crate::records::json_record(r)),
            Event::Msg(DeviceMsg::Status(s)) => (mqtt::Kind::Status, serde_json::to_value(s).unwrap_or_default()),
            Event::Msg(DeviceMsg::Alarm(a)) => (mqtt::Kind::Alarm, serde_json::to_value(a).unwrap_or_default()),
            Event::Drift(d) => {
                let mut body = serde_json::Map::new();
                for (k, v) in d.fields() {
                    body.insert(k, serde_json::Value::from(v));
                }
                body.insert("supply_bar".into(), d.supply_bar.into());
                body.insert("alarm".into(), d.alarm().into());
                body.insert("alarms".into(), d.alarms().into());
                (mqtt::Kind::Drift, serde_json::Value::Object(body))
            }
            Event::Stats(_) | Event::Msg(_) => return,
            e => match describe(e) {
                Some((severity, text)) => (
                    mqtt::Kind::Link,
                    json!({"event": text, "severity": format!("{severity:?}").to_lowercase()}),
                ),
                None => return,
            },
        };
        p.send(kind, body, &host_time);
    }

    /// Takes in one event; returns a note to show when an export failed or
    /// the broker has something to say (a refusal, a TLS warning).
    pub fn event(&mut self, ev: &Stamped) -> Option<String> {
        self.publish(ev);
        let mqtt_notes = self.mqtt.as_ref().map(|p| p.counters.take_notes()).unwrap_or_default();
        let note = self.export_event(ev);
        let notes: Vec<String> = mqtt_notes.into_iter().chain(note).collect();
        (!notes.is_empty()).then(|| notes.join("\n"))
    }

    fn export_event(&mut self, ev: &Stamped) -> Option<String> {
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
            Event::Drift(d) => {
                let mut x = self.exports.lock().unwrap_or_else(|e| e.into_inner());
                let site = x.site.clone();
                match x.influx.as_mut() {
                    Some(w) => w.push(influx::drift_line(
                        &self.device,
                        site.as_deref(),
                        d.supply_bar,
                        &d.fields(),
                        &d.alarms(),
                        (ev.t_us as i64).saturating_mul(1_000),
                    )),
                    None => Ok(()),
                }
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
                Some(format!("export failed (counted): {e:#}"))
            }
            Err(_) => None,
        }
    }
}

impl Drop for DeviceExport {
    /// Stops the device's publisher (it sends what it can, keeps the rest
    /// on disk) and leaves its summary for the closing line.
    fn drop(&mut self) {
        if let Some(p) = self.mqtt.take() {
            let counters = p.counters.clone();
            let publisher_summary = drop_publisher(p);
            let mut x = self.exports.lock().unwrap_or_else(|e| e.into_inner());
            for n in counters.take_notes() {
                eprintln!("{n}");
            }
            x.mqtt_summaries.push(publisher_summary);
            x.mqtt_lost |= counters.undelivered();
        }
    }
}

fn drop_publisher(p: mqtt::Publisher) -> String {
    let counters = p.counters.clone();
    let device = p.device_name().to_string();
    drop(p);
    mqtt::Publisher::describe(&device, &counters)
}
