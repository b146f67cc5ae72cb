//! `hammer monitor`: the live dashboard of a device's per-cycle reports, and
//! `hammer replay`: the same dashboard fed from a recorded `frames.bin`.
//!
//! One reader thread owns the port ([`reader`]): it decodes frames, checks
//! report sequence numbers, shakes hands on every (re)connect, reconnects
//! when the port goes away and writes the logs ([`log`]), so logging never
//! waits for the screen. The screen side ([`app`] state, [`ui`] drawing, or
//! one line per report in headless mode) only consumes [`event::Stamped`]
//! events from a channel. Replay ([`replay`]) produces the same events from
//! the recorded bytes through the same decoding core ([`reader::Ingest`]), so
//! what a replay shows is what the live dashboard showed.

pub mod app;
pub mod chambers_panel;
pub mod connect;
pub mod drift;
pub mod drift_panel;
pub mod event;
pub mod export;
pub mod fleet;
pub mod headless;
pub mod log;
pub mod reader;
pub mod replay;
pub mod ui;

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{mpsc, Arc};

use anyhow::{bail, Context, Result};

pub use connect::connector_for;

/// A way to (re)open the link to a device: a serial port path, `auto`, or
/// `tcp:HOST:PORT` (the emulated board).
pub trait Connector: Send {
    fn connect(&mut self) -> std::io::Result<Box<dyn Port>>;
    fn describe(&self) -> String;
    /// The hammer's supply pressure where the link knows it and the board's
    /// configuration may not (a demo board's simulated hammer): the
    /// commissioning record's point its drift is read at, unless
    /// `--point-bar` says otherwise.
    fn supply_bar(&self) -> Option<f64> {
        None
    }
}

/// A byte stream to a device. Reads must time out (short read timeout) so the
/// reader thread can resend a handshake and notice a stop request.
pub trait Port: std::io::Read + std::io::Write + Send {}
impl<T: std::io::Read + std::io::Write + Send> Port for T {}

/// Events buffered between the reader and the screen. The reader never waits
/// for the screen (logging goes on); beyond this the screen skips events and
/// says so, and catches up from the next counter snapshot.
pub(crate) const EVENT_QUEUE: usize = 16_384;

#[derive(clap::Args, Debug, Clone)]
pub struct MonitorArgs {
    /// The device: a serial port (/dev/ttyACM0, /dev/serial/by-id/...), `auto`
    /// (the first of /dev/serial/by-id/*, /dev/ttyACM*, /dev/ttyUSB*), or
    /// tcp:HOST:PORT (the emulated board's UART), optionally named
    /// (`rig4=/dev/ttyACM0`). Repeat it to watch several devices at once.
    #[arg(long = "port", value_name = "[NAME=]PORT", default_value = "auto")]
    pub ports: Vec<String>,
    /// Directory for cycles.csv (decoded reports), link.log (connects,
    /// disconnects, gaps, errors) and frames.bin (every received byte, for
    /// `hammer replay`). Created if missing; existing files are appended to.
    #[arg(long, value_name = "DIR")]
    pub log: Option<PathBuf>,
    /// Size cap of the three log files together, in MB (10^6 bytes), what
    /// they held before included. At the cap logging stops, says so in
    /// link.log and on screen, and counts what it no longer logs.
    #[arg(long, value_name = "MB", default_value_t = log::DEFAULT_MAX_MB)]
    pub log_max_mb: f64,
    /// Seconds of history in the charts.
    #[arg(long, default_value_t = 300.0)]
    pub history_s: f64,
    /// One line per report and per link event instead of the dashboard
    /// (also used when stdout is not a terminal).
    #[arg(long)]
    pub headless: bool,
    /// Stop after this many reports (for scripts and tests).
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub exit_after_reports: Option<u64>,
    /// The device's name in exports and logs (one device; several are
    /// named with NAME=PORT; default: from the port, e.g. ttyACM0).
    #[arg(long)]
    pub device: Option<String>,
    #[command(flatten)]
    pub export: export::ExportArgs,
    #[command(flatten)]
    pub drift: crate::drift::DriftArgs,
}

impl Default for MonitorArgs {
    fn default() -> Self {
        Self {
            ports: vec!["auto".into()],
            log: None,
            log_max_mb: log::DEFAULT_MAX_MB,
            history_s: 300.0,
            headless: false,
            exit_after_reports: None,
            device: None,
            export: export::ExportArgs::default(),
            drift: crate::drift::DriftArgs::default(),
        }
    }
}

/// A device's name from its port: the last path component or the
/// address, reduced to [A-Za-z0-9_.-] (`/dev/ttyACM0` → `ttyACM0`,
/// `tcp:127.0.0.1:4000` → `tcp_127.0.0.1_4000`).
pub fn device_name(port: &str) -> String {
    let last = port.rsplit('/').next().unwrap_or(port);
    let s: String = last
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "-_.".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() {
        "device".into()
    } else {
        s
    }
}

#[derive(clap::Args, Debug, Clone)]
pub struct ReplayArgs {
    /// A frames.bin written by `hammer monitor --log DIR` (or the DIR itself).
    /// Format: 8 bytes "HMFRAMES", then records [u64 host_time_us LE][u32 len
    /// LE][len bytes]; len 0xFFFF_FFFF marks a (re)connect, 0xFFFF_FFFE a
    /// disconnect (no bytes follow a marker).
    pub log: PathBuf,
    /// One line per report and per link event instead of the dashboard
    /// (also used when stdout is not a terminal).
    #[arg(long)]
    pub headless: bool,
    /// Playback speed relative to the recording (2 = twice as fast; 0 = as fast as possible).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
}

/// How the screen side runs and when it stops on its own.
#[derive(Debug, Clone, Copy)]
pub struct UiOptions {
    pub headless: bool,
    pub exit_after_reports: Option<u64>,
    /// Live: stop on a protocol mismatch in headless mode (nothing to show).
    pub live: bool,
}

/// `NAME=PORT` or `PORT` → (name, port).
pub fn named_port(s: &str) -> (String, String) {
    match s.split_once('=') {
        Some((name, port)) if !name.is_empty() && !name.contains(['/', ':']) => (device_name(name), port.to_string()),
        _ => (device_name(s), s.to_string()),
    }
}

/// Runs the monitor on the port(s) named by `--port`.
pub fn run(args: &MonitorArgs) -> Result<()> {
    match args.ports.as_slice() {
        [one] => {
            let (name, port) = named_port(one);
            let connector = connector_for(&port)?;
            let args = MonitorArgs {
                device: args.device.clone().or(Some(name)),
                ..args.clone()
            };
            run_with(connector, &args)
        }
        many => {
            if args.device.is_some() {
                bail!("--device names one device; name several with --port NAME=PORT");
            }
            let mut devices = vec![];
            for s in many {
                let (name, port) = named_port(s);
                devices.push((name, connector_for(&port)?));
            }
            run_fleet(devices, args)
        }
    }
}

/// Several devices at once ([`fleet`]).
pub fn run_fleet(devices: Vec<(String, Box<dyn Connector>)>, args: &MonitorArgs) -> Result<()> {
    check_args(args)?;
    let headless = args.headless || !std::io::stdout().is_terminal();
    fleet::run(devices, args, headless)
}

fn check_args(args: &MonitorArgs) -> Result<()> {
    if !(args.history_s.is_finite() && args.history_s > 0.0) {
        bail!(
            "--history-s must be a positive number of seconds, not {}",
            args.history_s
        );
    }
    if !(args.log_max_mb.is_finite() && args.log_max_mb > 0.0) {
        bail!("--log-max-mb must be a positive number of MB, not {}", args.log_max_mb);
    }
    Ok(())
}

/// Runs the monitor on any connector (the demo passes its own).
pub fn run_with(connector: Box<dyn Connector>, args: &MonitorArgs) -> Result<()> {
    check_args(args)?;
    let max_bytes = (args.log_max_mb * 1e6) as u64;
    let logger = match &args.log {
        Some(dir) => {
            Some(log::Logger::open(dir, max_bytes).with_context(|| format!("cannot log to {}", dir.display()))?)
        }
        None => None,
    };
    let headless = args.headless || !std::io::stdout().is_terminal();
    let title = connector.describe();
    let exports = export::Exports::open(&args.export)?;
    let device = args
        .device
        .clone()
        .unwrap_or_else(|| device_name(&connector.describe()));
    let device_export = exports.clone().map(|x| export::DeviceExport::new(&device, x));
    let watch = commissioned(&args.drift)?.map(|c| drift::Watch::new(c, &args.drift, connector.supply_bar()));
    let (tx, rx) = mpsc::sync_channel(EVENT_QUEUE);
    let stop = Arc::new(AtomicBool::new(false));
    let reader = reader::spawn(connector, logger, device_export, watch, tx, stop.clone())?;
    let mut app = app::App::new(title, true, args.history_s);
    let opts = UiOptions {
        headless,
        exit_after_reports: args.exit_after_reports,
        live: true,
    };
    let result = show(&mut app, &rx, opts);
    stop.store(true, Ordering::Relaxed);
    drop(rx);
    // The reader notices within one read timeout or retry pause, then flushes the logs.
    if reader.join().is_err() {
        eprintln!("the reader thread panicked; the logs may be incomplete");
    }
    let closed = close_exports(exports);
    result.and(closed)
}

/// The commissioning record `--reference` names, read once for every
/// device watched (each matches its own supply pressure to its points).
pub(crate) fn commissioned(args: &crate::drift::DriftArgs) -> Result<Option<Arc<crate::drift::Commissioned>>> {
    let Some(dir) = &args.reference else {
        return Ok(None);
    };
    let config: hammer_sim::SimConfig = match &args.hammer_config {
        Some(p) => hammer_trace::config::load_toml(p)?,
        None => hammer_sim::SimConfig::default(),
    };
    config.validate()?;
    let c = crate::drift::Commissioned::load(dir, &config).with_context(|| format!("--reference {}", dir.display()))?;
    Ok(Some(Arc::new(c)))
}

/// Writes what the exports still hold and says what they did; an error
/// (so a non-zero exit) when a sink lost data or its server refused it.
pub(crate) fn close_exports(exports: Option<Arc<std::sync::Mutex<export::Exports>>>) -> Result<()> {
    if let Some(x) = exports {
        let mut x = x.lock().unwrap_or_else(|e| e.into_inner());
        if let Err(e) = x.flush() {
            eprintln!("export: {e:#}");
        }
        eprintln!("{}", x.summary());
        if let Some(loss) = x.loss() {
            bail!("not every report reached its destination: {loss}");
        }
    }
    Ok(())
}

/// Replays a recorded `frames.bin` through the decoder and the dashboard.
pub fn replay(args: &ReplayArgs) -> Result<()> {
    replay::run(args)
}

pub(crate) fn show(app: &mut app::App, rx: &mpsc::Receiver<event::Stamped>, opts: UiOptions) -> Result<()> {
    if opts.headless {
        headless::run(app, rx, opts)
    } else {
        ui::run(app, rx, opts)
    }
}
