//! Commissioning: the hammer's own reference record, made when it is known
//! sound, that later diagnoses read a change against (`hammer diagnose
//! --reference DIR`; docs/diagnosis.md, "Against the hammer's own record").
//!
//! At each operating point the board's raw captures (one cycle each, with
//! the milliseconds after its closing impact) are written as traces in
//! `DIR/<bar>bar/`, with the board's reports of the steady cycles that
//! arrived meanwhile (`reports.csv`: the chambers as the board reads them,
//! which the monitor's drift is read against), and `DIR/commission.json`
//! records what they were made with: the firmware version, the board, the
//! calibration hash (a later recalibration makes the record stale) and the
//! supply pressure.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use clap::Args;

use crate::client::Client;
use hammer_diagnose::record::{
    is_record, Folder, PointRecord, Record, RECORD_FILE, RECORD_FORMAT, RECORD_VERSION, SUPPLY_AGREE_BAR,
};
use hammer_estimator::CycleReport;
use hammer_trace::trace::{write_csv, write_sidecar, Sidecar};

use crate::drift::{report_reading, steady_reports, write_reports, REPORTS_FILE};

#[derive(Args, Debug)]
pub struct CommissionArgs {
    /// Device: a serial port path, `auto`, or `tcp:HOST:PORT` (the emulated board).
    #[arg(long, default_value = "auto")]
    pub port: String,
    /// Commission a demo board instead of a device: the firmware (QEMU, or
    /// natively without it) fed with the simulated hammer.
    #[arg(long, conflicts_with = "port")]
    pub demo: bool,
    /// Effects of the demo's simulated hammer (`name:key=value,...`), for
    /// trying a diagnosis against a record of the sound one.
    #[arg(long = "effect", value_name = "SPEC", requires = "demo")]
    pub effects: Vec<String>,
    /// Run the demo board's firmware app natively instead of on QEMU. On
    /// QEMU the emulated board samples its running hammer at the full rate
    /// through its ADC model, as a board on a bench does; natively the app
    /// is fed a stretch of hammer per capture over its link.
    #[arg(long, requires = "demo")]
    pub native: bool,
    /// Gauge supply pressure of an operating point, bar (repeatable). On a
    /// device with a terminal you are asked to set each in turn; without
    /// one, give one per run (each run adds its point to the folder). Each
    /// point has its own folder, `<bar>bar/` to a tenth of a bar: two
    /// pressures that name one are refused.
    #[arg(long = "supply-bar", value_name = "BAR", required = true, value_parser = crate::cli::supply_bar)]
    pub supply_bar: Vec<f64>,
    /// Raw cycles to capture at each operating point, for the diagnosis.
    /// The board's reports that arrive meanwhile are kept too: the drift
    /// alarm reads every later window against their median and spread, and
    /// more is better (a record of 30 reported cycles raised 5 false alarms
    /// per 10 000 windows on a sound hammer, 100 raised 0.1, 1 000 none:
    /// docs/fleet.md).
    #[arg(long, default_value_t = 100)]
    pub cycles: usize,
    /// The commissioning folder (created; an existing one of the same board
    /// and calibration gets the points added or replaced).
    #[arg(long)]
    pub out: PathBuf,
}

/// The folder name of an operating point.
fn point_dir(bar: f64) -> String {
    format!("{bar:.1}bar")
}

/// Refuses supply pressures whose captures would land in one point's
/// folder (`--supply-bar 4 --supply-bar 4.04` both name `4.0bar/`: the
/// second would overwrite the first's captures and the record list the
/// same files twice), among `bars` or against the folder's `existing`
/// points (one within [`SUPPLY_AGREE_BAR`] is the same point, replaced).
fn check_point_dirs(bars: &[f64], existing: Option<&Record>, out: &std::path::Path) -> Result<()> {
    for (i, &a) in bars.iter().enumerate() {
        if let Some(&b) = bars[..i].iter().find(|&&b| point_dir(b) == point_dir(a)) {
            bail!(
                "--supply-bar {b} and --supply-bar {a} both name the point folder {}: give each operating point once, in its own tenth of a bar",
                point_dir(a)
            );
        }
        let clash = existing
            .into_iter()
            .flat_map(|r| &r.points)
            .find(|p| point_dir(p.supply_bar) == point_dir(a) && (p.supply_bar - a).abs() > SUPPLY_AGREE_BAR);
        if let Some(p) = clash {
            bail!(
                "--supply-bar {a} names the point folder {}, where {} holds its {} bar point: give {} to replace that point, or use a new folder",
                point_dir(a),
                out.display(),
                p.supply_bar,
                p.supply_bar
            );
        }
    }
    Ok(())
}

/// A board to capture from, kept open across captures.
struct Session {
    link: Client<Box<dyn crate::monitor::Port>>,
    info: hammer_wire::DeviceInfo,
    demo: Option<Demo>,
    /// The emulated board sampling its hammer at the full rate, as a board
    /// on a bench does: it captures the next cycle of a running hammer.
    _full_rate: Option<(crate::demo::Board, crate::demo::FullRate)>,
}

/// A native demo board and the rest of its simulated hammer, fed a
/// capture's stretch at a time once that capture is armed: the request is
/// never queued behind samples (a paced feed ahead of the request held it
/// back until the capture timed out).
struct Demo {
    _board: crate::demo::Board,
    writer: Arc<Mutex<Box<dyn std::io::Write + Send>>>,
    codes: std::vec::IntoIter<hammer_estimator::RawSample>,
    /// The stretch being fed: the next one follows it.
    feeding: Option<std::thread::JoinHandle<()>>,
    /// The next stretch's first block number (the numbering runs on).
    next_block: u32,
    /// Fed at the hammer's pace (the native app, which takes samples
    /// faster than they are made and would drop them), else as fast as the
    /// board takes them (QEMU's emulated UART is slower than the hammer).
    paced: bool,
}

pub fn run(args: &CommissionArgs) -> Result<()> {
    if args.cycles == 0 || args.cycles > 1000 {
        bail!("--cycles {}: between 1 and 1000", args.cycles);
    }
    if let Some(b) = args
        .supply_bar
        .iter()
        .find(|b| !(b.is_finite() && **b > 0.0 && **b <= 20.0))
    {
        bail!("--supply-bar {b}: a gauge supply pressure between 0 and 20 bar");
    }
    let interactive = std::io::stdin().is_terminal();
    if !args.demo && args.supply_bar.len() > 1 && !interactive {
        bail!("without a terminal to confirm each supply pressure, give one --supply-bar per run (each run adds its point to {})", args.out.display());
    }
    let existing = is_record(&args.out)
        .then(|| Folder::open(&args.out).map(|f| f.record))
        .transpose()?;
    check_point_dirs(&args.supply_bar, existing.as_ref(), &args.out)?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let timeout = Duration::from_secs(120);
    let mut record: Option<Record> = existing;
    for (k, &bar) in args.supply_bar.iter().enumerate() {
        let mut session = open(args, bar)?;
        if !args.demo && interactive && (k > 0 || args.supply_bar.len() > 1) {
            eprintln!("commission: set the supply to {bar} bar, let the hammer run steadily, then press Enter");
            let mut line = String::new();
            std::io::stdin().read_line(&mut line)?;
        }
        let dir = args.out.join(point_dir(bar));
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let mut traces = Vec::new();
        let mut hash = None;
        let mut reports = Vec::new();
        for n in 0..args.cycles {
            let (codes, cfg) = capture_one(&mut session, timeout, &mut reports)?;
            let h = cfg.calibration_hash();
            if hash.is_some_and(|x| x != h) {
                bail!(
                    "the board's calibration changed during commissioning ({:08x} → {h:08x}): start again",
                    hash.unwrap_or(0)
                );
            }
            hash = Some(h);
            let (trace, sidecar) = crate::capture::to_trace(&codes, &cfg, Some(bar));
            let name = format!("cycle-{n:03}.csv");
            let path = dir.join(&name);
            write_csv(&path, &trace)?;
            write_sidecar(&path, &sidecar)?;
            traces.push(format!("{}/{name}", point_dir(bar)));
        }
        let hash = hash.unwrap_or_default();
        let reports = steady_reports(&reports);
        if reports.is_empty() {
            bail!("no report of a steady cycle arrived at {bar} bar while capturing: is the hammer running steadily?");
        }
        let read = reports.iter().filter(|r| report_reading(r).is_some()).count();
        if read < MIN_READ_REPORTS {
            eprintln!(
                "commission: only {read} of the {} reports at {bar} bar carry the board's chamber reading (cycles longer than it reads, or samples lost): the monitor's drift at this point will read the captures instead",
                reports.len()
            );
        }
        let reports_path = dir.join(REPORTS_FILE);
        write_reports(&reports_path, &reports)?;
        // Its sidecar states the point and the calibration, as a capture's does.
        let sidecar: Sidecar = Sidecar {
            calibration_hash: Some(hash),
            ..Sidecar::new(Some(bar), "device")
        };
        write_sidecar(&reports_path, &sidecar)?;
        let info = &session.info;
        let firmware = format!(
            "{}.{}.{}",
            info.firmware_version[0], info.firmware_version[1], info.firmware_version[2]
        );
        let board = String::from_utf8_lossy(&info.board).into_owned();
        let r = record.get_or_insert_with(|| Record {
            format: RECORD_FORMAT.into(),
            version: RECORD_VERSION,
            firmware_version: firmware.clone(),
            board: board.clone(),
            calibration_hash: hash,
            points: Vec::new(),
        });
        if r.calibration_hash != hash || r.board != board {
            bail!(
                "{} was commissioned on {} with calibration {:08x}; this board is {board} with {hash:08x}: use a new folder",
                args.out.display(),
                r.board,
                r.calibration_hash
            );
        }
        r.firmware_version = firmware;
        // A point with reports makes the record version 2, also one that
        // began as version 1.
        r.version = RECORD_VERSION;
        r.points.retain(|p| (p.supply_bar - bar).abs() > SUPPLY_AGREE_BAR);
        r.points.push(PointRecord {
            supply_bar: bar,
            traces,
            reports: Some(format!("{}/{REPORTS_FILE}", point_dir(bar))),
        });
        r.points.sort_by(|a, b| a.supply_bar.total_cmp(&b.supply_bar));
        // Written after every point: an interrupted run keeps what it made.
        let text = serde_json::to_string_pretty(r)?;
        let path = args.out.join(RECORD_FILE);
        std::fs::write(&path, text + "\n").with_context(|| format!("writing {}", path.display()))?;
        outln!(
            "commission: {} cycles captured and {} reported at {bar} bar into {} (calibration {hash:08x}, firmware {})",
            args.cycles,
            reports.len(),
            dir.display(),
            r.firmware_version
        );
    }
    Ok(())
}

/// Fewer reports with a chamber reading than this at a point are said: the
/// drift's baseline would rest on too few (docs/fleet.md: 30 gave 5 false
/// alarms per 10 000 windows, 100 gave 0.1).
const MIN_READ_REPORTS: usize = 30;

/// Seconds of simulated hammer a demo board is fed per capture, after the
/// capture is armed: an impact to start on, a full cycle (under 50 ms at
/// 4–7 bar) and its tail, with margin.
const DEMO_PER_CAPTURE_S: f64 = 0.2;
const DEMO_SETTLE_S: f64 = 0.5;

/// Opens the board: a device, or a demo board whose simulated hammer runs
/// at `bar`, fed at its own pace for as long as the captures need.
fn open(args: &CommissionArgs, bar: f64) -> Result<Session> {
    let handshake = Duration::from_secs(20);
    if args.demo && crate::demo::emulated_board_available(args.native) {
        let mut demo = crate::demo::DemoArgs::for_capture(bar);
        demo.effects = args.effects.clone();
        let full_rate = crate::demo::FullRate::start(&demo, None)?;
        let (board, read, write) = crate::demo::start_board(false, Some(&full_rate.stimulus), false)?;
        let port: Box<dyn crate::monitor::Port> =
            Box::new(crate::demo::SharedPort::new(read, Arc::new(Mutex::new(write))));
        let mut link = Client::new(port);
        let (info, _) = link.handshake(handshake)?;
        // The hammer settles before the first capture, as the native one
        // does: until a report of a blow after the settling time.
        link.recv_until(handshake, |m| match m {
            hammer_wire::DeviceMsg::Report(r) => (r.t_impact_s() >= DEMO_SETTLE_S).then_some(()),
            _ => None,
        })?;
        return Ok(Session {
            link,
            info,
            demo: None,
            _full_rate: Some((board, full_rate)),
        });
    }
    if args.demo {
        let mut demo = crate::demo::DemoArgs::for_capture(bar);
        demo.effects = args.effects.clone();
        // (A block's rounding per stretch on top.)
        let codes = crate::demo::hammer_codes(
            &demo,
            DEMO_SETTLE_S + (DEMO_PER_CAPTURE_S + 0.01) * (args.cycles + 1) as f64,
        )?;
        let (board, read, write) = crate::demo::start_board(args.native, None, false)?;
        let writer = Arc::new(Mutex::new(write));
        let port: Box<dyn crate::monitor::Port> = Box::new(crate::demo::SharedPort::new(read, writer.clone()));
        let mut link = Client::new(port);
        let (info, _) = link.handshake(handshake)?;
        let mut demo = Demo {
            _board: board,
            writer,
            codes: codes.into_iter(),
            feeding: None,
            next_block: 0,
            paced: !crate::demo::emulated_board_available(args.native),
        };
        // The hammer settles before the first capture (fed while the link
        // is read: a board whose reports nobody reads stops taking samples).
        demo.feed(DEMO_SETTLE_S);
        return Ok(Session {
            link,
            info,
            demo: Some(demo),
            _full_rate: None,
        });
    }
    let mut connector = crate::monitor::connector_for(&args.port)?;
    let port = connector
        .connect()
        .with_context(|| format!("opening {}", connector.describe()))?;
    let mut link = Client::new(port);
    let (info, _) = link.handshake(handshake)?;
    Ok(Session {
        link,
        info,
        demo: None,
        _full_rate: None,
    })
}

impl Demo {
    /// Feeds the next `seconds` of the hammer from a thread, once the
    /// stretch before it is fed, as fast as the board takes them.
    fn feed(&mut self, seconds: f64) {
        let rate = hammer_estimator::Config::default().sample_rate_hz as f64;
        // Whole blocks: a short one inside the stream is not a block the
        // board expects.
        let blocks = (seconds * rate / hammer_wire::BLOCK_SAMPLES as f64).ceil() as usize;
        let stretch: Vec<_> = self.codes.by_ref().take(blocks * hammer_wire::BLOCK_SAMPLES).collect();
        let first = self.next_block;
        self.next_block = first.wrapping_add(blocks as u32);
        let writer = self.writer.clone();
        let before = self.feeding.take();
        let paced = self.paced;
        self.feeding = Some(std::thread::spawn(move || {
            if let Some(b) = before {
                let _ = b.join();
            }
            crate::demo::feed_from(first, stretch, writer, paced, rate)
        }));
    }
}

/// One capture of the next whole cycle; the reports beside it are added to `reports`.
fn capture_one(
    s: &mut Session,
    timeout: Duration,
    reports: &mut Vec<CycleReport>,
) -> Result<(Vec<[u16; 3]>, hammer_estimator::Config)> {
    let Some(demo) = s.demo.as_mut() else {
        return crate::capture::record_armed(&mut s.link, 1, timeout, || {}, reports);
    };
    // The hammer's next stretch follows the board's acknowledgement.
    crate::capture::record_armed(&mut s.link, 1, timeout, || demo.feed(DEMO_PER_CAPTURE_S), reports)
}
