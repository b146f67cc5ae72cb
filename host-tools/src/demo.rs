//! `hammer demo`: the whole chain with no hardware. A simulated hammer is
//! turned into ADC codes and streamed into the firmware — the emulated board
//! under QEMU, or the same app natively when QEMU is missing — and the
//! dashboard (or, headless, a line per cycle) shows what the firmware reports.

use std::io::{self, Read, Write};
use std::net::TcpStream;
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use hammer_estimator::RawSample;
use hammer_wire::{DeviceMsg, HostMsg, SampleBlock, BLOCK_SAMPLES};

use crate::client::{write_frame, Client};
use crate::emulator::{firmware_elf, qemu_available, Emulator, Icount};
use crate::stimulus::Stimulus;
use hammer_sim::effects::CoulombFriction;
use hammer_sim::simulate::{simulate, stream_codes};
use hammer_sim::SimConfig;

#[derive(Args, Debug, Clone)]
pub struct DemoArgs {
    /// Gauge supply pressure, bar.
    #[arg(long, default_value_t = 4.0, value_parser = crate::cli::supply_bar)]
    pub supply_bar: f64,
    /// Extra simulator effect: NAME or NAME:key=value,... (repeatable). The
    /// paper's pressure-dependent friction is always on.
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
    /// Friction rise per minute of running, relative (0.05 = +5 %/min): wear,
    /// so the wear index climbs and the drift alarm fires.
    #[arg(long, default_value_t = 0.0)]
    pub wear_rate: f64,
    /// Simulated hammer time to stream, s (default: 60, or enough for --cycles when headless).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Print the reports instead of opening the dashboard; for tests and scripts.
    #[arg(long)]
    pub headless: bool,
    /// Headless: stop after this many reports.
    #[arg(long, default_value_t = 30)]
    pub cycles: usize,
    /// Run the firmware's app natively even if QEMU is installed.
    #[arg(long)]
    pub native: bool,
    /// Seed of the sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Headless on the emulated board: keep the hammer's own pace, as the
    /// dashboard does. By default a headless run goes as fast as the host
    /// allows; the board's timing is instruction-counted either way.
    #[arg(long)]
    pub real_time: bool,
    /// Emulated boards to run at once (a fleet): the first at --supply-bar,
    /// the others spread up to 7 bar, each wearing 1 %/min faster than the
    /// one before; shown in the fleet monitor (headless: `[device]` lines).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=8))]
    pub devices: u8,
    #[command(flatten)]
    pub export: crate::monitor::export::ExportArgs,
    #[command(flatten)]
    pub drift: crate::drift::DriftArgs,
}

/// Where the firmware runs.
pub enum Board {
    Qemu(Emulator),
    Native,
}

/// A byte link shared by the sample feeder and the dashboard: reads go to
/// the dashboard, writes from both are serialised frame by frame.
pub struct SharedPort {
    read: Box<dyn Read + Send>,
    write: Arc<Mutex<Box<dyn Write + Send>>>,
}

impl SharedPort {
    pub fn new(read: Box<dyn Read + Send>, write: Arc<Mutex<Box<dyn Write + Send>>>) -> Self {
        Self { read, write }
    }
}

impl DemoArgs {
    /// A demo hammer at `supply_bar` with the defaults, for `hammer capture --demo`.
    pub fn for_capture(supply_bar: f64) -> Self {
        Self {
            supply_bar,
            effects: vec![],
            wear_rate: 0.0,
            seconds: None,
            headless: true,
            cycles: 1,
            native: false,
            seed: 1,
            real_time: false,
            devices: 1,
            export: Default::default(),
            drift: Default::default(),
        }
    }

    /// The `k`-th of `--devices` boards: its supply pressure and wear rate.
    pub fn member(&self, k: u8) -> Self {
        let n = f64::from(self.devices.max(1));
        let top = self.supply_bar.max(7.0);
        let supply_bar = if n > 1.0 {
            self.supply_bar + (top - self.supply_bar) * f64::from(k) / (n - 1.0)
        } else {
            self.supply_bar
        };
        Self {
            supply_bar,
            wear_rate: self.wear_rate + 0.01 * f64::from(k),
            seed: self.seed + u64::from(k),
            devices: 1,
            ..self.clone()
        }
    }

    /// The `k`-th board's name in the fleet, its logs and exports.
    pub fn member_name(&self, k: u8) -> String {
        format!("demo{}-{:.1}bar", k + 1, self.member(k).supply_bar)
    }
}

impl Read for SharedPort {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        self.read.read(buf)
    }
}

impl Write for SharedPort {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        let mut w = self.write.lock().map_err(|_| io::Error::other("writer poisoned"))?;
        w.write_all(buf)?;
        Ok(buf.len())
    }
    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// The demo's hammer: the paper's, with its friction growing at the wear rate.
fn demo_config(args: &DemoArgs, seconds: f64) -> Result<SimConfig> {
    let mut cfg = SimConfig::nominal(args.supply_bar);
    cfg.solver.duration_s = seconds;
    cfg.seed = args.seed;
    // The paper's friction, growing at the demo's wear rate (per minute).
    cfg.effects.coulomb_friction = Some(CoulombFriction {
        growth_per_s: args.wear_rate / 60.0,
        ..Default::default()
    });
    for e in &args.effects {
        cfg.effects.apply_spec(e)?;
    }
    cfg.validate()?;
    Ok(cfg)
}

/// The simulated hammer as the ADC codes the board would sample.
pub fn hammer_codes(args: &DemoArgs, seconds: f64) -> Result<Vec<RawSample>> {
    let sim = simulate(&demo_config(args, seconds)?).context("simulation failed")?;
    Ok(sim.measured.codes)
}

/// Runs the demo's hammer into the emulated board's ADC as fast as the ring
/// takes it: `seconds` of it, or without end (`None`) until `stop`. `tap`
/// sees every sample-set the board will see, in order, once written.
pub fn stream_hammer(
    args: &DemoArgs,
    seconds: Option<f64>,
    stimulus: &Stimulus,
    stop: &AtomicBool,
    mut tap: impl FnMut(&[RawSample]),
) -> Result<()> {
    let cfg = demo_config(args, seconds.unwrap_or(1.0))?;
    const CHUNK: usize = 4096;
    let mut chunk = Vec::with_capacity(CHUNK);
    let mut stopped = false;
    stream_codes(&cfg, seconds.is_none(), |s| {
        chunk.push(s);
        if chunk.len() == CHUNK {
            stopped = !stimulus.push(&chunk, stop);
            if !stopped {
                tap(&chunk);
            }
            chunk.clear();
        }
        if stopped {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })
    .context("simulation failed")?;
    if !stopped && stimulus.push(&chunk, stop) {
        tap(&chunk);
        stimulus.finish();
    }
    Ok(())
}

/// Sample-sets written before the board boots, so that its first halves
/// never wait for the simulator: 0.2 s.
const PREFILL_SETS: u32 = 20_000;

/// The emulated board's ADC fed at the full rate: the simulator streams into
/// its ring from a thread, which ends with the stream or when this is dropped.
pub struct FullRate {
    pub stimulus: Arc<Stimulus>,
    stop: Arc<AtomicBool>,
    producer: Option<std::thread::JoinHandle<Result<()>>>,
}

impl FullRate {
    pub fn start(args: &DemoArgs, seconds: Option<f64>) -> Result<Self> {
        Self::start_tapped(args, seconds, |_| {})
    }

    /// As [`FullRate::start`], with `tap` seeing every sample-set written (see [`stream_hammer`]).
    pub fn start_tapped(
        args: &DemoArgs,
        seconds: Option<f64>,
        tap: impl FnMut(&[RawSample]) + Send + 'static,
    ) -> Result<Self> {
        let stimulus = Arc::new(Stimulus::create()?);
        let stop = Arc::new(AtomicBool::new(false));
        let producer = std::thread::spawn({
            let (args, stimulus, stop) = (args.clone(), stimulus.clone(), stop.clone());
            move || stream_hammer(&args, seconds, &stimulus, &stop, tap)
        });
        // The file's name goes once QEMU has it mapped (a killed run leaves
        // no 16 MiB behind in /dev/shm).
        std::thread::spawn({
            let (stimulus, stop) = (stimulus.clone(), stop.clone());
            move || {
                while !stop.load(Ordering::Relaxed) && !stimulus.unlink_once_mapped() {
                    std::thread::sleep(Duration::from_millis(50));
                }
            }
        });
        let deadline = Instant::now() + Duration::from_secs(20);
        while stimulus.counters().written_sets < PREFILL_SETS && !producer.is_finished() {
            if Instant::now() > deadline {
                bail!("the simulator did not produce 0.2 s of samples within 20 s");
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        Ok(Self {
            stimulus,
            stop,
            producer: Some(producer),
        })
    }

    /// Stops the producer and returns its error, if it had one.
    pub fn stop(&mut self) -> Result<()> {
        self.stop.store(true, Ordering::Relaxed);
        match self.producer.take().map(|p| p.join()) {
            Some(Ok(r)) => r,
            Some(Err(_)) => bail!("the sample producer panicked"),
            None => Ok(()),
        }
    }
}

impl Drop for FullRate {
    fn drop(&mut self) {
        let _ = self.stop();
    }
}

/// The board's ADC counters as one line, for people. The core's duty is
/// per second of samples, not of guest uptime: the board idles for as long
/// as the host takes to start it, and that says nothing about the firmware.
pub fn adc_line(c: &crate::stimulus::Counters) -> String {
    let hammer_us = f64::from(c.consumed_sets) * 1e6 / f64::from(hammer_wire::stimulus::RATE_HZ);
    format!(
        "board ADC: {} sample-sets processed, {} overruns ({} sets lost), {} late stimulus blocks, \
         worst block latency {} us, core awake {:.1} % of the hammer's time",
        c.consumed_sets,
        c.overruns,
        c.lost_sets,
        c.starved_blocks,
        c.latency_max_us,
        f64::from(c.busy_us) / hammer_us.max(1.0) * 100.0,
    )
}

/// Whether the demo's board is the emulated one (QEMU and its firmware are
/// there, and `--native` was not asked for).
pub fn emulated_board_available(native: bool) -> bool {
    !native && qemu_available() && firmware_elf().exists()
}

/// Starts the board and returns it with its link's read and write halves.
/// With `stimulus`, the emulated board samples it at the full rate; without,
/// it takes samples over its UART.
/// `real_time` keeps a full-rate board to host time while it sleeps (see [`Icount`]).
pub fn start_board(
    native: bool,
    stimulus: Option<&Stimulus>,
    real_time: bool,
) -> Result<(Board, Box<dyn Read + Send>, Box<dyn Write + Send>)> {
    let elf = firmware_elf();
    if emulated_board_available(native) {
        // Timed by instructions at (below) the M4's pace, whatever the host does.
        let icount = stimulus.is_some().then_some(Icount::m4_at_125_mips(real_time));
        let mut emu = Emulator::start_with(&elf, icount, stimulus)?;
        let s: TcpStream = emu.connect(Duration::from_secs(20))?;
        s.set_read_timeout(Some(Duration::from_millis(50)))?;
        let r = s.try_clone()?;
        eprintln!(
            "demo: firmware on the emulated board (QEMU mps2-an386, {}), samples {}",
            elf.display(),
            if stimulus.is_some() {
                "through its ADC model at 100 kS/s"
            } else {
                "over its UART"
            }
        );
        return Ok((Board::Qemu(emu), Box::new(r), Box::new(s)));
    }
    if !native {
        if !qemu_available() {
            eprintln!("demo: qemu-system-arm not found: running the firmware's app natively on this machine instead");
        } else {
            eprintln!(
                "demo: {} not built (cargo xtask firmware): running the firmware's app natively instead",
                elf.display()
            );
        }
    } else {
        eprintln!("demo: firmware app running natively (--native)");
    }
    let s = crate::board::start_native_board(hammer_estimator::Config::default())?;
    s.set_read_timeout(Some(Duration::from_millis(50)))?;
    let r = s.try_clone()?;
    Ok((Board::Native, Box::new(r), Box::new(s)))
}

/// Streams `codes` as numbered sample blocks; paced to real time when `paced`.
pub fn feed(codes: Vec<RawSample>, writer: Arc<Mutex<Box<dyn Write + Send>>>, paced: bool, sample_rate_hz: f64) {
    feed_from(0, codes, writer, paced, sample_rate_hz)
}

/// [`feed`] for a stream fed in stretches: its blocks numbered on from
/// `first_block` (a number that goes back reads as lost samples on the board).
pub fn feed_from(
    first_block: u32,
    codes: Vec<RawSample>,
    writer: Arc<Mutex<Box<dyn Write + Send>>>,
    paced: bool,
    sample_rate_hz: f64,
) {
    let start = Instant::now();
    for (i, chunk) in codes.chunks(BLOCK_SAMPLES).enumerate() {
        if paced {
            let due = Duration::from_secs_f64((i * BLOCK_SAMPLES) as f64 / sample_rate_hz);
            if let Some(wait) = due.checked_sub(start.elapsed()) {
                std::thread::sleep(wait);
            }
        }
        let block = SampleBlock {
            seq: first_block.wrapping_add(i as u32),
            samples: chunk.iter().map(|s| [s.rear, s.front, s.accel]).collect(),
        };
        let Ok(mut w) = writer.lock() else { return };
        if write_frame(&mut *w, &HostMsg::Samples(block)).is_err() {
            return; // the board went away
        }
    }
}

/// One line per report, for headless runs: the headless monitor's line.
pub use crate::records::report_line;

pub fn run(args: &DemoArgs) -> Result<()> {
    use std::io::IsTerminal;
    let headless = args.headless || !std::io::stdout().is_terminal();
    if args.devices > 1 {
        return run_fleet(args, headless);
    }
    let seconds = args.seconds.unwrap_or(if headless {
        0.15 + 0.05 * args.cycles as f64
    } else {
        60.0
    });
    let emulated = emulated_board_available(args.native);
    eprintln!(
        "demo: simulating {} the paper's hammer at {} bar (friction{}{})",
        if emulated && args.seconds.is_none() {
            "without end".to_string()
        } else {
            format!("{seconds} s of")
        },
        args.supply_bar,
        if args.wear_rate > 0.0 {
            format!(", rising {:.1} %/min", args.wear_rate * 100.0)
        } else {
            String::new()
        },
        if args.effects.is_empty() {
            String::new()
        } else {
            format!(", {}", args.effects.join(", "))
        }
    );
    // The emulated board samples the simulator's stream through its ADC
    // model, without end unless --seconds; the native app takes it over its link.
    let mut full_rate = None;
    let mut feeder = None;
    let (board, read, write) = if emulated {
        let fr = FullRate::start(args, args.seconds)?;
        let board = start_board(false, Some(&fr.stimulus), args.real_time || !headless)?;
        full_rate = Some(fr);
        board
    } else {
        let codes = hammer_codes(args, seconds)?;
        let board = start_board(args.native, None, false)?;
        feeder = Some(codes);
        board
    };
    let writer = Arc::new(Mutex::new(write));
    let port = SharedPort {
        read,
        write: writer.clone(),
    };
    // The drift feeds the native app at the hammer's pace, as a board is
    // fed: fed faster, its reports could outrun the link's queue
    // (`hammer_app::tasks::OUTGOING`) and be dropped.
    let drift = args.drift.reference.is_some();
    let feeder = feeder.map(|codes| {
        let (writer, paced) = (writer.clone(), !headless || drift);
        std::thread::spawn(move || feed(codes, writer, paced, 1e5))
    });
    let result = if headless && !drift {
        headless_loop(port, args, full_rate.as_ref().map(|f| &*f.stimulus))
    } else {
        dashboard(port, &board, args, headless)
    };
    drop(board); // stops QEMU
    let produced = full_rate.as_mut().map_or(Ok(()), FullRate::stop);
    if let Some(f) = feeder {
        let _ = f.join();
    }
    result.and(produced)
}

/// `--devices N`: N emulated boards, each with its own full-rate stream,
/// watched by the fleet monitor.
fn run_fleet(args: &DemoArgs, headless: bool) -> Result<()> {
    if !emulated_board_available(args.native) {
        bail!("--devices needs the emulated board (qemu-system-arm and `cargo xtask firmware`)");
    }
    let mut streams = vec![];
    let mut boards = vec![];
    let mut devices: Vec<(String, Box<dyn crate::monitor::Connector>)> = vec![];
    for k in 0..args.devices {
        let member = args.member(k);
        eprintln!(
            "demo: board {} at {:.1} bar, wear {:.0} %/min",
            args.member_name(k),
            member.supply_bar,
            member.wear_rate * 100.0
        );
        let fr = FullRate::start(&member, args.seconds)?;
        let (board, read, write) = start_board(false, Some(&fr.stimulus), args.real_time || !headless)?;
        let describe = match &board {
            Board::Qemu(e) => format!("demo: emulated board (QEMU) on tcp:127.0.0.1:{}", e.port),
            Board::Native => "demo: firmware app running natively".to_string(),
        };
        let port = SharedPort::new(read, Arc::new(Mutex::new(write)));
        devices.push((
            args.member_name(k),
            Box::new(DemoConnector {
                port: Some(port),
                describe,
                supply_bar: member.supply_bar,
            }),
        ));
        streams.push(fr);
        boards.push(board);
    }
    let margs = crate::monitor::MonitorArgs {
        headless,
        exit_after_reports: headless.then_some(args.cycles as u64),
        export: args.export.clone(),
        drift: args.drift.clone(),
        ..Default::default()
    };
    let result = crate::monitor::run_fleet(devices, &margs);
    drop(boards); // stops QEMU
    let mut produced = Ok(());
    for mut fr in streams {
        produced = produced.and(fr.stop());
    }
    result.and(produced)
}

fn headless_loop(port: SharedPort, args: &DemoArgs, stimulus: Option<&Stimulus>) -> Result<()> {
    let cycles = args.cycles;
    let exports = crate::monitor::export::Exports::open(&args.export)?;
    let mut export = exports
        .clone()
        .map(|x| crate::monitor::export::DeviceExport::new(&args.member_name(0), x));
    let mut link = Client::new(port);
    let deadline = Duration::from_secs(30);
    let (info, _) = link.handshake(deadline)?;
    if let Some(x) = export.as_mut() {
        let ev = crate::monitor::event::Stamped::now(crate::monitor::event::Event::Device(info.clone()));
        if let Some(note) = x.event(&ev) {
            eprintln!("{note}");
        }
        link.send(&HostMsg::GetConfig)?;
    }
    println!(
        "device: {} firmware {}.{}.{} protocol {} config {:08x}",
        String::from_utf8_lossy(&info.board),
        info.firmware_version[0],
        info.firmware_version[1],
        info.firmware_version[2],
        info.protocol_version,
        info.config_hash
    );
    let mut seen = 0;
    let mut last = Instant::now();
    while seen < cycles {
        let m = link.recv(Duration::from_millis(200))?;
        if let (Some(x), Some(m)) = (export.as_mut(), &m) {
            let ev = crate::monitor::event::Stamped::now(crate::monitor::event::Event::Msg(m.clone()));
            if let Some(note) = x.event(&ev) {
                eprintln!("{note}");
            }
        }
        match m {
            Some(DeviceMsg::Report(r)) => {
                println!("{}", report_line(&r));
                seen += 1;
                last = Instant::now();
            }
            Some(DeviceMsg::Alarm(a)) => println!(
                "ALARM {:?} at cycle {} (drift score {:.1})",
                a.kind, a.cycle_seq, a.drift_score
            ),
            Some(DeviceMsg::Rejected { command, reason }) => println!("device rejected {command:?}: {reason:?}"),
            Some(_) => {}
            None if last.elapsed() > Duration::from_secs(60) => bail!("no report from the board for 60 s"),
            None => {}
        }
    }
    let status = link.request(&HostMsg::GetStatus, deadline, |m| {
        if let DeviceMsg::Status(s) = m {
            Some(*s)
        } else {
            None
        }
    })?;
    if let Some(s) = status {
        println!(
            "status: {} samples, {} cycles ({} invalid), {} dropped samples, {} frames sent, {} dropped, rx errors {}, last reset: {}",
            s.samples,
            s.cycles,
            s.invalid_cycles,
            s.dropped_samples,
            s.frames_sent,
            s.frames_dropped,
            s.rx_crc_errors + s.rx_cobs_errors + s.rx_decode_errors + s.rx_oversize,
            crate::numfmt::reset_cause(&s.reset_cause)
        );
    }
    if let Some(stimulus) = stimulus {
        println!("{}", adc_line(&stimulus.counters()));
    }
    drop(export);
    crate::monitor::close_exports(exports)
}

/// Hands the dashboard the demo board's one link; there is nothing to
/// reconnect to once it closes.
struct DemoConnector {
    port: Option<SharedPort>,
    describe: String,
    /// The simulated hammer's supply pressure (its board holds none).
    supply_bar: f64,
}

impl crate::monitor::Connector for DemoConnector {
    fn connect(&mut self) -> io::Result<Box<dyn crate::monitor::Port>> {
        match self.port.take() {
            Some(p) => Ok(Box::new(p)),
            None => Err(io::Error::new(
                io::ErrorKind::NotConnected,
                "the demo board's link has closed",
            )),
        }
    }

    fn describe(&self) -> String {
        self.describe.clone()
    }

    fn supply_bar(&self) -> Option<f64> {
        Some(self.supply_bar)
    }
}

/// The monitor on the demo board: its dashboard, or headless (with
/// `--reference`, whose drift the monitor reads) until `--cycles` reports.
fn dashboard(port: SharedPort, board: &Board, demo: &DemoArgs, headless: bool) -> Result<()> {
    let args = crate::monitor::MonitorArgs {
        device: Some(demo.member_name(0)),
        export: demo.export.clone(),
        headless,
        exit_after_reports: headless.then_some(demo.cycles as u64),
        drift: demo.drift.clone(),
        ..Default::default()
    };
    let describe = match board {
        Board::Qemu(e) => format!("demo: emulated board (QEMU) on tcp:127.0.0.1:{}", e.port),
        Board::Native => "demo: firmware app running natively".to_string(),
    };
    crate::monitor::run_with(
        Box::new(DemoConnector {
            port: Some(port),
            describe,
            // The demo's board holds no supply pressure; its hammer's is known.
            supply_bar: demo.supply_bar,
        }),
        &args,
    )
}
