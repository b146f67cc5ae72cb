//! `hammer soak`: the emulated board at the full 100 kS/s × 3 for minutes of
//! hammer time, every report checked against the host estimator on the very
//! samples the board's ADC delivered, and the board's own real-time figures:
//! overruns, frames lost, CPU duty, the worst latency from a DMA half's
//! completion to the end of its processing.
//!
//! Guest time counts instructions (`-icount`, 125 M instructions per guest
//! second, slower than the STM32G474), so the figures are the firmware's, not
//! the host's: by default the board does not wait for host time while it
//! sleeps, and the run takes as long as the host needs, usually far less
//! than the hammer time it covers.

use std::sync::mpsc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use hammer_app::chambers::{Pipeline, ReaderRoom};
use hammer_estimator::Config;
use hammer_wire::{CycleReport, DeviceConfig, DeviceMsg, HostMsg, Status};

use crate::client::Client;
use crate::demo::{DemoArgs, FullRate};
use crate::emulator::{firmware_elf, Emulator, Icount};
use crate::stimulus::Counters;

#[derive(Args, Debug, Clone)]
pub struct SoakArgs {
    /// Hammer time to run, minutes (guest time: 100 kS/s of samples per second).
    #[arg(long, default_value_t = 1.0)]
    pub minutes: f64,
    /// Gauge supply pressure, bar.
    #[arg(long, default_value_t = 5.0, value_parser = crate::cli::supply_bar)]
    pub supply_bar: f64,
    /// Friction rise per minute, relative (as `hammer demo --wear-rate`).
    #[arg(long, default_value_t = 0.0)]
    pub wear_rate: f64,
    /// Seed of the sensor noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Keep the board to host time while it sleeps (as the dashboard does):
    /// slower, and a host that stalls QEMU for a DMA half shows as an overrun.
    #[arg(long)]
    pub real_time: bool,
    /// Effects of the simulated hammer (`name:key=value,...`, as `hammer
    /// demo --effect`): a faulty hammer's cycles are longer, and the
    /// board's work at their close with them.
    #[arg(long = "effect", value_name = "SPEC")]
    pub effects: Vec<String>,
}

/// What a soak measured.
#[derive(Debug, Clone, Default)]
pub struct Soak {
    pub sample_sets: u64,
    pub overruns: u32,
    pub lost_sets: u32,
    pub late_stimulus_blocks: u32,
    pub reports: u64,
    pub reports_lost: u64,
    pub frames_dropped_on_board: u32,
    pub mismatches: u64,
    pub first_mismatch: Option<String>,
    pub latency_max_us: u32,
    /// The deepest the board's stack has been, and the stack region, bytes.
    pub stack_used_bytes: u32,
    pub stack_reserved_bytes: u32,
    /// The chambers' reader: cycles read, reports sent unread, the most
    /// blocks waiting for it, and those it never got.
    pub chambers_read: u32,
    pub chambers_unread: u32,
    pub reader_blocks_peak: u32,
    pub reader_blocks_dropped: u32,
    /// The blocks the board keeps for its reader.
    pub reader_blocks: u32,
    /// The longest a report waited from its impact to leaving the board's
    /// reader, and the shortest cycle period reported, seconds.
    pub report_latency_max_s: f64,
    pub shortest_period_s: f64,
    /// Guest µs the core was awake / since boot (accumulated across wraps).
    pub busy_us: u64,
    pub uptime_us: u64,
    /// Guest µs the sampling loop spent (estimator, monitor, commands).
    pub dsp_busy_us: u64,
    pub host_s: f64,
    pub status: Option<Status>,
}

/// Guest ns per instruction of the emulated core.
const NS_PER_INSTRUCTION: f64 = (1u32 << Icount::m4_at_125_mips(false).shift) as f64;

impl Soak {
    pub fn hammer_s(&self) -> f64 {
        self.sample_sets as f64 / f64::from(hammer_wire::stimulus::RATE_HZ)
    }

    /// Instructions the core executed per second of hammer time (all of the
    /// firmware: interrupts, estimator, link).
    pub fn instructions_per_s(&self) -> f64 {
        self.busy_us as f64 * 1e3 / NS_PER_INSTRUCTION / self.hammer_s().max(1e-9)
    }

    /// The sampling loop's instructions per sample-set.
    pub fn dsp_instructions_per_set(&self) -> f64 {
        let sets = self.status.map_or(0, |s| s.samples);
        self.dsp_busy_us as f64 * 1e3 / NS_PER_INSTRUCTION / (sets.max(1) as f64)
    }

    /// Everything a soak must show: no sample, frame or report lost, every
    /// report the host's, the stimulus never late.
    pub fn clean(&self) -> bool {
        self.overruns == 0
            && self.lost_sets == 0
            && self.reports_lost == 0
            && self.frames_dropped_on_board == 0
            && self.reader_blocks_dropped == 0
            && self.report_latency_max_s <= 2.0 * self.shortest_period_s
            && self.mismatches == 0
            && self.status.is_some_and(|s| s.dropped_samples == 0)
            && self.reports > 0
    }

    pub fn summary(&self) -> String {
        let mut out = String::new();
        let hammer_s = self.hammer_s();
        out += &format!(
            "soak: {:.1} min of hammer time ({} sample-sets × 3 channels) in {:.1} s of host time\n",
            hammer_s / 60.0,
            self.sample_sets,
            self.host_s
        );
        out += &format!(
            "  overruns: {} ({} sample-sets lost); stimulus late: {} DMA halves (host side; delays, never loses)\n",
            self.overruns, self.lost_sets, self.late_stimulus_blocks
        );
        out += &format!(
            "  frames: {} reports received, {} lost in transit, {} dropped on the board\n",
            self.reports, self.reports_lost, self.frames_dropped_on_board
        );
        out += &format!(
            "  parity: {} reports equal to the host estimator's bit for bit, {} differ{}\n",
            self.reports - self.mismatches.min(self.reports),
            self.mismatches,
            self.first_mismatch
                .as_deref()
                .map_or(String::new(), |m| format!(" (first: {m})"))
        );
        let ips = self.instructions_per_s();
        out += &format!(
            "  CPU: {:.1} M instructions per second of hammer time = {:.1} % of the emulated 125 MIPS core, \
             {:.1} % of a 170 MHz STM32G474 at one instruction per cycle; sampling loop {:.1} instructions per sample-set\n",
            ips / 1e6,
            ips / 125e6 * 100.0,
            ips / 170e6 * 100.0,
            self.dsp_instructions_per_set()
        );
        out += &format!(
            "  latency: worst {} us from a DMA half's completion to the end of its processing (deadline {} us)\n",
            self.latency_max_us,
            u64::from(hammer_wire::stimulus::BLOCK_SETS) * 1_000_000 / u64::from(hammer_wire::stimulus::RATE_HZ)
        );
        out += &format!(
            "  stack: {} B at the deepest of {} B reserved (margin {} B), measured from the painted stack\n",
            self.stack_used_bytes,
            self.stack_reserved_bytes,
            self.stack_reserved_bytes.saturating_sub(self.stack_used_bytes)
        );
        out += &format!(
            "  chambers: {} cycles read, {} reports unread; the reader's blocks: at most {} of {} waiting, {} never got\n",
            self.chambers_read,
            self.chambers_unread,
            self.reader_blocks_peak,
            self.reader_blocks,
            self.reader_blocks_dropped
        );
        out += &format!(
            "  report latency: worst {:.1} ms from a cycle's impact to its report leaving the board (two of the shortest periods: {:.1} ms)\n",
            self.report_latency_max_s * 1e3,
            2.0 * self.shortest_period_s * 1e3
        );
        out += if self.clean() {
            "  verdict: clean"
        } else {
            "  verdict: FAILED"
        };
        out
    }
}

/// Accumulates the board's wrapping µs counters.
#[derive(Default)]
struct Unwrap {
    last: Option<Counters>,
    busy_us: u64,
    uptime_us: u64,
}

impl Unwrap {
    fn update(&mut self, c: Counters) {
        if let Some(l) = self.last {
            self.busy_us += u64::from(c.busy_us.wrapping_sub(l.busy_us));
            self.uptime_us += u64::from(c.uptime_us.wrapping_sub(l.uptime_us));
        } else {
            self.busy_us = u64::from(c.busy_us);
            self.uptime_us = u64::from(c.uptime_us);
        }
        self.last = Some(c);
    }
}

/// The message's frame: equal frames, equal messages to the last bit (NaN included).
fn wire_bytes(m: &DeviceMsg) -> Vec<u8> {
    let mut buf = [0u8; hammer_wire::MAX_FRAME];
    let n = hammer_wire::encode(m, &mut buf).unwrap_or(0);
    buf[..n].to_vec()
}

pub fn run(args: &SoakArgs, progress: bool) -> Result<Soak> {
    if !(args.minutes > 0.0 && args.minutes.is_finite()) {
        bail!("--minutes must be positive");
    }
    let target_sets = (args.minutes * 60.0 * f64::from(hammer_wire::stimulus::RATE_HZ)) as u64;
    let demo = DemoArgs {
        wear_rate: args.wear_rate,
        seed: args.seed,
        effects: args.effects.clone(),
        ..DemoArgs::for_capture(args.supply_bar)
    };
    // The host's estimator and chambers' reader see what the board's ADC
    // delivers, in order.
    let (expected_tx, expected) = mpsc::channel::<CycleReport>();
    let mut host = Pipeline::new(Config::default(), Box::<ReaderRoom>::default())
        .map_err(|e| anyhow::anyhow!("default estimator configuration: {e:?}"))?;
    let mut full_rate = FullRate::start_tapped(&demo, None, move |sets| {
        host.push_block(sets, &mut |r| {
            let _ = expected_tx.send(r);
        })
    })?;
    let icount = Icount::m4_at_125_mips(args.real_time);
    let mut emu = Emulator::start_with(&firmware_elf(), Some(icount), Some(&full_rate.stimulus))?;
    let started = Instant::now();
    let mut link = Client::new(emu.connect(Duration::from_secs(20))?);
    let (_, mut early) = link.handshake(Duration::from_secs(20))?;
    link.send(&HostMsg::GetConfig)?;
    let (config, more) = link.recv_until(Duration::from_secs(20), |m| {
        if let DeviceMsg::Config(c) = m {
            Some(*c)
        } else {
            None
        }
    })?;
    early.extend(more);
    let default = DeviceMsg::Config(DeviceConfig::from(&Config::default()));
    if config.map(|c| wire_bytes(&DeviceMsg::Config(c))) != Some(wire_bytes(&default)) {
        bail!("the board's configuration {config:?} is not the default one the host estimator uses");
    }

    let mut soak = Soak::default();
    let mut unwrap = Unwrap::default();
    let mut last_report = Instant::now();
    let mut last_progress = Instant::now();
    let check = |m: &DeviceMsg, soak: &mut Soak| -> Result<()> {
        if let DeviceMsg::Report(r) = m {
            soak.reports += 1;
            if r.is_valid() && (soak.shortest_period_s == 0.0 || f64::from(r.period_s) < soak.shortest_period_s) {
                soak.shortest_period_s = f64::from(r.period_s);
            }
            let h = expected
                .recv_timeout(Duration::from_secs(30))
                .context("the host estimator fell silent")?;
            if wire_bytes(m) != wire_bytes(&DeviceMsg::Report(h)) {
                soak.mismatches += 1;
                soak.first_mismatch
                    .get_or_insert_with(|| format!("cycle {}: board {r:?} vs host {h:?}", r.seq));
            }
        }
        Ok(())
    };
    for m in &early {
        check(m, &mut soak)?;
    }
    loop {
        let c = full_rate.stimulus.counters();
        unwrap.update(c);
        if u64::from(c.consumed_sets) >= target_sets && soak.reports > 0 {
            break;
        }
        if !emu.is_running() {
            bail!("QEMU exited during the soak");
        }
        if last_report.elapsed() > Duration::from_secs(60) {
            bail!("no report from the board for 60 s of host time");
        }
        if progress && last_progress.elapsed() > Duration::from_secs(5) {
            last_progress = Instant::now();
            eprintln!(
                "soak: {:.1} of {:.1} min of hammer time, {} reports, {} overruns",
                f64::from(c.consumed_sets) / 6e6,
                args.minutes,
                soak.reports,
                c.overruns
            );
        }
        if let Some(m) = link.recv(Duration::from_millis(100))? {
            if matches!(m, DeviceMsg::Report(_)) {
                last_report = Instant::now();
            }
            check(&m, &mut soak)?;
        }
    }
    link.send(&HostMsg::GetStatus)?;
    let (status, rest) = link.recv_until(Duration::from_secs(20), |m| {
        if let DeviceMsg::Status(s) = m {
            Some(*s)
        } else {
            None
        }
    })?;
    for m in &rest {
        check(m, &mut soak)?;
    }
    let c = full_rate.stimulus.counters();
    unwrap.update(c);
    drop(emu);
    full_rate.stop()?;
    soak.sample_sets = u64::from(c.consumed_sets);
    soak.overruns = c.overruns;
    soak.lost_sets = c.lost_sets;
    soak.late_stimulus_blocks = c.starved_blocks;
    soak.latency_max_us = c.latency_max_us;
    soak.stack_used_bytes = c.stack_used_bytes;
    soak.stack_reserved_bytes = c.stack_reserved_bytes;
    soak.chambers_read = c.chambers_read;
    soak.chambers_unread = c.chambers_unread;
    soak.reader_blocks_peak = c.reader_blocks_peak;
    soak.reader_blocks_dropped = c.reader_blocks_dropped;
    soak.reader_blocks = c.reader_blocks;
    soak.report_latency_max_s = f64::from(c.report_latency_max_sets) / f64::from(hammer_wire::stimulus::RATE_HZ);
    soak.busy_us = unwrap.busy_us;
    soak.uptime_us = unwrap.uptime_us;
    soak.reports_lost = link.lost_reports;
    soak.host_s = started.elapsed().as_secs_f64();
    if let Some(s) = status {
        soak.frames_dropped_on_board = s.frames_dropped;
        soak.dsp_busy_us = s.dsp_busy_us;
    }
    soak.status = status;
    Ok(soak)
}
