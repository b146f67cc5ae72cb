//! The monitor's synchronous core: samples in, messages out, commands applied.
//! No I/O and no time source of its own, so it is tested on the host as is.

use crate::packed::{self, Packed};
use hammer_estimator::tare::Tare;
use hammer_estimator::{Config, Estimator, Flags, RawSample, WearState, MAX_CONFIRM};
use hammer_wire::{
    config_hash, Alarm, AlarmKind, CaptureChunk, CommandKind, DeviceConfig, DeviceInfo, DeviceMsg, HostMsg,
    RejectReason, ResetCause, Status, WearBlob, BLOCK_SAMPLES, PROTOCOL_VERSION, WEAR_STATE_BYTES,
};

/// Sample-sets a raw capture holds: one full cycle of the paper's hammer
/// (≤ 50 ms at 4 bar) at 100 kS/s, with margin. 4.5 bytes each (12-bit
/// codes, `packed`): 25.2 KB.
pub const CAPTURE_SAMPLES: usize = 5_600;
const CAPTURE_BYTES: usize = packed::bytes_for(CAPTURE_SAMPLES);

/// Samples kept after the impact that closes a capture: its shock and the
/// few samples before it make the capture a complete cycle for the
/// estimator, and the 8 ms after it hold the front chamber's feed when the
/// valve switches after the impact (the chamber characteristics,
/// `hammer_estimator::chambers`). A 4 bar cycle (≈ 47 ms) and its tail fit
/// in [`CAPTURE_SAMPLES`]; a longer one streams what the buffer holds.
pub const CAPTURE_TAIL: u16 = 800;

/// The firmware's own version, reported in `Hello` and `Status`.
pub const FIRMWARE_VERSION: [u8; 3] = [0, 1, 0];

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum CaptureState {
    Idle,
    /// Waiting for the next impact to start recording `cycles` cycles.
    Armed {
        cycles: u8,
    },
    Recording {
        cycles_left: u8,
    },
    /// The last cycle closed; `left` more samples so the closing impact is in the capture.
    Tail {
        left: u16,
    },
    /// Recorded; `sent` sample-sets streamed so far.
    Streaming {
        sent: usize,
    },
}

/// Counters the monitor keeps beyond the estimator's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct MonitorCounters {
    pub adc_overruns: u32,
    pub rejected_commands: u32,
    pub messages_dropped: u32,
}

pub struct Monitor {
    est: Estimator,
    board: &'static str,
    tare: Option<(Tare, u32)>,
    /// A `MeasureCodes` under way: the same sums as a tare, and samples left.
    measure: Option<(Tare, u32)>,
    capture: CaptureState,
    capture_buf: Packed<CAPTURE_SAMPLES, CAPTURE_BYTES>,
    capture_len: usize,
    capture_id: u16,
    /// The latest samples, so a capture starts at the impact's first shock
    /// sample although the impact is confirmed a few samples later.
    preroll: [RawSample; MAX_CONFIRM],
    /// Where the next sample goes in `preroll` (a ring: no copy per sample).
    preroll_next: usize,
    alarm_on: bool,
    pub counters: MonitorCounters,
    /// Counters of estimators replaced by a new configuration: the status counts since boot.
    carried: hammer_estimator::Counters,
    config_hash: u32,
    reset_cause: ResetCause,
}

impl Monitor {
    pub fn new(cfg: Config, board: &'static str) -> Result<Self, hammer_estimator::ConfigError> {
        let est = Estimator::new(cfg)?;
        Ok(Self {
            reset_cause: ResetCause::PowerOn,
            config_hash: config_hash(&DeviceConfig::from(&cfg)),
            est,
            board,
            tare: None,
            measure: None,
            capture: CaptureState::Idle,
            capture_buf: Packed::new(),
            capture_len: 0,
            capture_id: 0,
            preroll: [RawSample::default(); MAX_CONFIRM],
            preroll_next: 0,
            alarm_on: false,
            counters: MonitorCounters::default(),
            carried: Default::default(),
        })
    }

    pub fn config(&self) -> &Config {
        self.est.config()
    }

    /// CRC of the configuration's wire bytes: changes whenever the configuration does.
    pub fn config_hash(&self) -> u32 {
        self.config_hash
    }

    pub fn estimator(&self) -> &Estimator {
        &self.est
    }

    pub fn info(&self) -> DeviceInfo {
        let mut board = heapless::Vec::new();
        for &b in self.board.as_bytes().iter().take(24) {
            let _ = board.push(b);
        }
        DeviceInfo {
            protocol_version: PROTOCOL_VERSION,
            firmware_version: FIRMWARE_VERSION,
            board,
            config_hash: self.config_hash,
        }
    }

    /// Samples lost before they arrived: the cycle under way is flagged.
    pub fn on_overrun(&mut self, lost: u32) {
        self.counters.adc_overruns = self.counters.adc_overruns.wrapping_add(1);
        self.est.push_gap(lost);
        if matches!(self.capture, CaptureState::Recording { .. }) {
            // A capture with a hole is not a trace: start over at the next impact.
            self.capture = CaptureState::Armed { cycles: 1 };
            self.capture_len = 0;
        }
    }

    /// Feeds samples; reports, alarms and tare results go to `out`.
    pub fn on_samples(&mut self, block: &[RawSample], out: &mut impl FnMut(DeviceMsg)) {
        // The common case: neither a tare nor a capture needs each sample, so
        // the estimator takes whole stretches through its hot loop.
        if self.tare.is_none()
            && self.measure.is_none()
            && matches!(self.capture, CaptureState::Idle | CaptureState::Streaming { .. })
        {
            // The common case: neither a tare nor a capture needs each
            // sample, so the whole block goes through the estimator's hot
            // loop in one call, reports leaving as they close.
            let Self { est, alarm_on, .. } = self;
            est.push_block(block, |r| {
                out(DeviceMsg::Report(r));
                alarms(alarm_on, &r, out);
            });
            return;
        }
        for &s in block {
            if let Some((sums, left)) = &mut self.measure {
                sums.push(s);
                *left -= 1;
                if *left == 0 {
                    let (samples, mean, std) = sums.code_stats();
                    self.measure = None;
                    out(DeviceMsg::CodeStats { samples, mean, std });
                }
            }
            if let Some((tare, left)) = &mut self.tare {
                tare.push(s);
                *left -= 1;
                if *left == 0 {
                    let t = *tare;
                    self.tare = None;
                    self.finish_tare(&t, out);
                }
            }
            self.preroll[self.preroll_next] = s;
            self.preroll_next = (self.preroll_next + 1) % MAX_CONFIRM;
            let impacts = self.est.counters().impacts;
            let report = self.est.push(s);
            if let Some(r) = &report {
                out(DeviceMsg::Report(*r));
                alarms(&mut self.alarm_on, r, out);
            }
            if self.est.counters().impacts != impacts && self.capture_on_impact() {
                continue;
            }
            if matches!(self.capture, CaptureState::Recording { .. } | CaptureState::Tail { .. }) {
                if self.capture_len < CAPTURE_SAMPLES {
                    self.capture_buf.set(self.capture_len, s);
                    self.capture_len += 1;
                } else {
                    // Longer than the buffer: stream what there is.
                    self.capture = CaptureState::Streaming { sent: 0 };
                }
                if let CaptureState::Tail { left } = self.capture {
                    self.capture = if left <= 1 {
                        CaptureState::Streaming { sent: 0 }
                    } else {
                        CaptureState::Tail { left: left - 1 }
                    };
                }
            }
        }
    }

    /// An impact was confirmed at the latest sample. True when that sample
    /// is already in the capture (a recording started with its pre-roll).
    fn capture_on_impact(&mut self) -> bool {
        // The shock samples between the impact's start and its confirmation.
        let since = (self.est.samples_since_impact() as usize).clamp(1, MAX_CONFIRM);
        let mut started = false;
        self.capture = match self.capture {
            CaptureState::Armed { cycles } => {
                // The last `since` samples, oldest first, out of the ring.
                for k in 0..since {
                    let s = self.preroll[(self.preroll_next + MAX_CONFIRM - since + k) % MAX_CONFIRM];
                    self.capture_buf.set(k, s);
                }
                self.capture_len = since;
                self.capture_id = self.capture_id.wrapping_add(1);
                started = true;
                CaptureState::Recording { cycles_left: cycles }
            }
            CaptureState::Recording { cycles_left } if cycles_left <= 1 => CaptureState::Tail {
                left: CAPTURE_TAIL.saturating_sub(since as u16 - 1).max(1),
            },
            CaptureState::Recording { cycles_left } => CaptureState::Recording {
                cycles_left: cycles_left - 1,
            },
            other => other,
        };
        started
    }

    /// The next chunk of a finished capture, if any: call until `None`.
    pub fn next_capture_chunk(&mut self) -> Option<DeviceMsg> {
        let CaptureState::Streaming { sent } = self.capture else {
            return None;
        };
        if sent >= self.capture_len {
            self.capture = CaptureState::Idle;
            return None;
        }
        let end = (sent + BLOCK_SAMPLES).min(self.capture_len);
        let mut samples = heapless::Vec::new();
        for i in sent..end {
            let s = self.capture_buf.get(i);
            let _ = samples.push([s.rear, s.front, s.accel]);
        }
        // The last chunk ends the capture at once: the host may ask for the
        // next one as soon as this chunk reaches it, before the link task
        // calls again (it stops when the outgoing queue is nearly full).
        self.capture = if end >= self.capture_len {
            CaptureState::Idle
        } else {
            CaptureState::Streaming { sent: end }
        };
        Some(DeviceMsg::Capture(CaptureChunk {
            capture_id: self.capture_id,
            offset: sent as u32,
            total: self.capture_len as u32,
            samples,
        }))
    }

    fn reject(&mut self, command: CommandKind, reason: RejectReason, out: &mut impl FnMut(DeviceMsg)) {
        self.counters.rejected_commands = self.counters.rejected_commands.wrapping_add(1);
        out(DeviceMsg::Rejected { command, reason });
    }

    /// Counts a frame that did not decode and says so to the host.
    pub fn on_bad_frame(&mut self, reason: RejectReason, out: &mut impl FnMut(DeviceMsg)) {
        self.reject(CommandKind::Unknown, reason, out);
    }

    fn finish_tare(&mut self, t: &Tare, out: &mut impl FnMut(DeviceMsg)) {
        match t.finish(self.est.config()) {
            Ok(r) => {
                if self.replace_config(r.config).is_ok() {
                    out(DeviceMsg::Ack(CommandKind::Tare));
                    out(DeviceMsg::Config(DeviceConfig::from(self.est.config())));
                } else {
                    self.reject(CommandKind::Tare, RejectReason::InvalidConfig, out);
                }
            }
            Err(_) => self.reject(CommandKind::Tare, RejectReason::TareNotAtRest, out),
        }
    }

    /// A new configuration restarts the estimator but keeps the wear state.
    fn replace_config(&mut self, cfg: Config) -> Result<(), hammer_estimator::ConfigError> {
        // Built straight into its place (`renew`, which checks `cfg` first
        // and leaves the estimator as it was on a rejection): the estimator
        // is ~7 KB, and copies of it on the stack made this the deepest
        // frame of the sampling task.
        let wear = *self.est.wear_state();
        let old = self.est.counters();
        self.est.renew(cfg)?;
        self.est.restore_wear(wear);
        let c = &mut self.carried;
        c.samples = c.samples.wrapping_add(old.samples);
        c.dropped_samples = c.dropped_samples.wrapping_add(old.dropped_samples);
        c.impacts = c.impacts.wrapping_add(old.impacts);
        c.cycles = c.cycles.wrapping_add(old.cycles);
        c.invalid_cycles = c.invalid_cycles.wrapping_add(old.invalid_cycles);
        c.stalls = c.stalls.wrapping_add(old.stalls);
        self.config_hash = config_hash(&DeviceConfig::from(&cfg));
        Ok(())
    }

    /// Applies a host command. `Samples` is not a command: the link task
    /// routes it to the sample source.
    pub fn on_command(&mut self, cmd: HostMsg, now_us: u64, out: &mut impl FnMut(DeviceMsg)) {
        match cmd {
            HostMsg::Hello { protocol_version } => {
                if protocol_version == PROTOCOL_VERSION {
                    out(DeviceMsg::Hello(self.info()));
                } else {
                    self.reject(
                        CommandKind::Hello,
                        RejectReason::ProtocolMismatch {
                            device: PROTOCOL_VERSION,
                        },
                        out,
                    );
                    out(DeviceMsg::Hello(self.info()));
                }
            }
            HostMsg::GetConfig => out(DeviceMsg::Config(DeviceConfig::from(self.est.config()))),
            HostMsg::SetConfig(c) => {
                let cfg = self.est.config().with_device(&c);
                match self.replace_config(cfg) {
                    Ok(()) => {
                        out(DeviceMsg::Ack(CommandKind::SetConfig));
                        out(DeviceMsg::Config(DeviceConfig::from(self.est.config())));
                    }
                    Err(_) => self.reject(CommandKind::SetConfig, RejectReason::InvalidConfig, out),
                }
            }
            HostMsg::Tare { samples } => {
                if self.tare.is_some() || samples < hammer_estimator::tare::MIN_TARE_SAMPLES || samples > 1_000_000 {
                    self.reject(CommandKind::Tare, RejectReason::Busy, out);
                } else {
                    self.tare = Some((Tare::default(), samples));
                }
            }
            HostMsg::StartCapture { cycles } => {
                if self.capture != CaptureState::Idle || cycles == 0 {
                    self.reject(CommandKind::StartCapture, RejectReason::Busy, out);
                } else {
                    self.capture = CaptureState::Armed { cycles };
                    out(DeviceMsg::Ack(CommandKind::StartCapture));
                }
            }
            HostMsg::GetStatus => out(DeviceMsg::Status(self.status(now_us, 0, 0, Default::default()))),
            HostMsg::ResetWear => {
                self.est.restore_wear(WearState::default());
                self.alarm_on = false;
                out(DeviceMsg::Ack(CommandKind::ResetWear));
            }
            HostMsg::GetWear => out(DeviceMsg::Wear(self.wear_blob())),
            HostMsg::RestoreWear(blob) => match WearState::from_bytes(&blob.bytes) {
                Ok(w) => {
                    self.est.restore_wear(w);
                    out(DeviceMsg::Ack(CommandKind::RestoreWear));
                }
                Err(_) => self.reject(CommandKind::RestoreWear, RejectReason::BadWearState, out),
            },
            HostMsg::Samples(_) => self.reject(CommandKind::Samples, RejectReason::Busy, out),
            HostMsg::MeasureCodes { samples } => {
                // The sums stop growing at 10⁶ samples (see `Tare::push`).
                if self.measure.is_some() || samples == 0 || samples > 1_000_000 {
                    self.reject(CommandKind::MeasureCodes, RejectReason::Busy, out);
                } else {
                    self.measure = Some((Tare::default(), samples));
                    out(DeviceMsg::Ack(CommandKind::MeasureCodes));
                }
            }
        }
    }

    pub fn wear_blob(&self) -> WearBlob {
        let bytes = self.est.wear_state().to_bytes();
        let mut v = heapless::Vec::<u8, WEAR_STATE_BYTES>::new();
        let _ = v.extend_from_slice(&bytes);
        WearBlob { bytes: v }
    }

    /// The device's health. `cpu_load_permille` and the link counters come from the board's tasks.
    pub fn status(&self, now_us: u64, cpu_load_permille: u16, dsp_busy_us: u64, link: LinkCounters) -> Status {
        let (c, k) = (self.est.counters(), &self.carried);
        Status {
            uptime_us: now_us,
            samples: c.samples.wrapping_add(k.samples),
            dropped_samples: c.dropped_samples.wrapping_add(k.dropped_samples),
            adc_overruns: self.counters.adc_overruns,
            cycles: c.cycles.wrapping_add(k.cycles),
            invalid_cycles: c.invalid_cycles.wrapping_add(k.invalid_cycles),
            stalls: c.stalls.wrapping_add(k.stalls),
            frames_sent: link.frames_sent,
            frames_dropped: link.frames_dropped.wrapping_add(self.counters.messages_dropped),
            rx_frames: link.rx_frames,
            rx_crc_errors: link.rx_crc_errors,
            rx_cobs_errors: link.rx_cobs_errors,
            rx_decode_errors: link.rx_decode_errors,
            rx_oversize: link.rx_oversize,
            rejected_commands: self.counters.rejected_commands,
            cpu_load_permille,
            dsp_busy_us,
            protocol_version: PROTOCOL_VERSION,
            firmware_version: FIRMWARE_VERSION,
            config_hash: self.config_hash,
            reset_cause: self.reset_cause,
            // The board's, filled in by the sampling task (`Shared::with_board_figures`).
            stack_used_bytes: 0,
            stack_reserved_bytes: 0,
            vdda_v: 0.0,
        }
    }

    /// Why the board last started, as it recorded it before the reset: every
    /// status carries it until the next reset.
    pub fn set_reset_cause(&mut self, cause: ResetCause) {
        self.reset_cause = cause;
    }
}

/// Link-side counters, kept by the link tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LinkCounters {
    pub frames_sent: u32,
    pub frames_dropped: u32,
    pub rx_frames: u32,
    pub rx_crc_errors: u32,
    pub rx_cobs_errors: u32,
    pub rx_decode_errors: u32,
    pub rx_oversize: u32,
}

/// Alarms for a report: the drift alarm's changes (`alarm_on` is its state)
/// and every sensor fault.
fn alarms(alarm_on: &mut bool, r: &hammer_estimator::CycleReport, out: &mut impl FnMut(DeviceMsg)) {
    let drift = r.flags.contains(Flags::DRIFT_ALARM);
    if r.is_valid() && drift != *alarm_on {
        *alarm_on = drift;
        let kind = if drift { AlarmKind::DriftOn } else { AlarmKind::DriftOff };
        out(DeviceMsg::Alarm(Alarm {
            kind,
            cycle_seq: r.seq,
            flags: r.flags,
            drift_score: r.drift_score,
        }));
    }
    if r.flags.intersects(Flags::SENSOR_FAULTS) {
        out(DeviceMsg::Alarm(Alarm {
            kind: AlarmKind::SensorFault,
            cycle_seq: r.seq,
            flags: r.flags,
            drift_score: r.drift_score,
        }));
    }
}
