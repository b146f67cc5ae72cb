//! Every message on the link. Field order is wire order: append nothing,
//! reorder nothing without bumping `PROTOCOL_VERSION`.

use heapless::Vec;
use serde::{Deserialize, Serialize};

use crate::BLOCK_SAMPLES;

/// The payloads defined once in `hammer-types` (estimator, firmware and host use the same).
pub use hammer_types::{
    ChannelCalibration, Codes, CycleReport, CycleReportV5, DeviceConfig, DeviceConfigV4, Flags, WEAR_STATE_BYTES,
};

/// A block of consecutive sample-sets; `seq` counts blocks so a lost one shows.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SampleBlock {
    pub seq: u32,
    pub samples: Vec<Codes, BLOCK_SAMPLES>,
}

/// Host → device.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum HostMsg {
    /// Handshake; the device answers with [`DeviceMsg::Hello`].
    Hello {
        protocol_version: u16,
    },
    GetConfig,
    SetConfig(DeviceConfig),
    /// Zero the offsets from the next `samples` sample-sets (hammer at rest, unpressurised).
    Tare {
        samples: u32,
    },
    /// Record the raw samples of the next `cycles` impact cycles and stream them.
    StartCapture {
        cycles: u8,
    },
    GetStatus,
    /// Start the wear index, baselines and alarm from scratch.
    ResetWear,
    /// Send the wear state ([`DeviceMsg::Wear`]).
    GetWear,
    /// Continue from a saved wear state.
    RestoreWear(WearBlob),
    /// The sample stream, where the board has no ADC of its own (the emulated board).
    Samples(SampleBlock),
    /// Average the next `samples` sample-sets and answer with
    /// [`DeviceMsg::CodeStats`]: a calibration's span point.
    MeasureCodes {
        samples: u32,
    },
}

/// Which command an acknowledgement or a rejection is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum CommandKind {
    Hello,
    GetConfig,
    SetConfig,
    Tare,
    StartCapture,
    GetStatus,
    ResetWear,
    GetWear,
    RestoreWear,
    Samples,
    /// A frame that did not decode (CRC, COBS, unknown message).
    Unknown,
    MeasureCodes,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum RejectReason {
    ProtocolMismatch {
        device: u16,
    },
    InvalidConfig,
    Busy,
    BadWearState,
    CorruptFrame,
    Oversize,
    TareNotAtRest,
    /// A sample block arrived out of order: `expected` block seq, the gap was counted as lost samples.
    SampleGap {
        expected: u32,
        got: u32,
    },
}

/// Device → host.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum DeviceMsg {
    Hello(DeviceInfo),
    /// Everything the estimator reports for one cycle, as it reports it.
    Report(CycleReport),
    Status(Status),
    Capture(CaptureChunk),
    Alarm(Alarm),
    Config(DeviceConfig),
    Wear(WearBlob),
    Ack(CommandKind),
    Rejected {
        command: CommandKind,
        reason: RejectReason,
    },
    /// The answer to [`HostMsg::MeasureCodes`]: per channel (rear, front,
    /// accel), the mean and standard deviation of the raw codes.
    CodeStats {
        samples: u32,
        mean: [f32; 3],
        std: [f32; 3],
    },
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceInfo {
    pub protocol_version: u16,
    pub firmware_version: [u8; 3],
    pub board: Vec<u8, 24>,
    pub config_hash: u32,
}

/// Device health. Every counter only grows; a host compares two to see losses.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Status {
    pub uptime_us: u64,
    pub samples: u64,
    pub dropped_samples: u64,
    pub adc_overruns: u32,
    pub cycles: u32,
    pub invalid_cycles: u32,
    pub stalls: u32,
    pub frames_sent: u32,
    /// Outgoing frames dropped because the transmit queue was full.
    pub frames_dropped: u32,
    pub rx_frames: u32,
    pub rx_crc_errors: u32,
    pub rx_cobs_errors: u32,
    pub rx_decode_errors: u32,
    pub rx_oversize: u32,
    pub rejected_commands: u32,
    /// Share of time spent processing samples, per mille.
    pub cpu_load_permille: u16,
    /// Total time spent processing samples since boot (under QEMU with
    /// `-icount shift=0`: thousands of instructions).
    pub dsp_busy_us: u64,
    pub protocol_version: u16,
    pub firmware_version: [u8; 3],
    pub config_hash: u32,
    /// Why the device last started (kept until the next reset).
    pub reset_cause: ResetCause,
    /// The deepest the stack has been since boot, and the stack region's
    /// size, bytes (from the stack painted at boot; 0 where not measured).
    pub stack_used_bytes: u32,
    pub stack_reserved_bytes: u32,
    /// The ADC's reference (VDDA) as the board measured it from the chip's
    /// internal reference, V; 0 where not measured. Every channel's gain
    /// follows it (`hammer_app::supply`).
    pub vdda_v: f32,
}

/// A duty of the firmware that the watchdog supervises: each must check in
/// within its period, or the watchdog is no longer fed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum Duty {
    Sampling,
    Link,
    Persistence,
}

/// Why the device last started, as it recorded it in RAM that survives a reset.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum ResetCause {
    /// Power-on or a reset with nothing recorded.
    #[default]
    PowerOn,
    /// The watchdog: `overdue` had not checked in within its period.
    Watchdog { overdue: Duty },
    /// A fault exception: the faulting instruction and the fault status (CFSR).
    Fault { pc: u32, cfsr: u32 },
}

/// A piece of a raw capture: ADC codes plus what is needed to turn them into a trace.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CaptureChunk {
    pub capture_id: u16,
    /// Index of the first sample-set of this chunk within the capture.
    pub offset: u32,
    /// Sample-sets in the whole capture.
    pub total: u32,
    pub samples: Vec<Codes, BLOCK_SAMPLES>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum AlarmKind {
    /// The friction drift alarm came on (sustained rise against the baseline).
    DriftOn,
    DriftOff,
    /// A cycle carried sensor fault flags (saturated, stuck, disconnected).
    SensorFault,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Alarm {
    pub kind: AlarmKind,
    pub cycle_seq: u32,
    pub flags: Flags,
    pub drift_score: f32,
}

/// The saved wear state (`hammer_estimator::WearState::to_bytes`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WearBlob {
    pub bytes: Vec<u8, WEAR_STATE_BYTES>,
}

/// CRC-32 of a configuration's wire bytes: reported in `Hello` and
/// `Status`, so a host sees which configuration produced a report.
pub fn config_hash(c: &DeviceConfig) -> u32 {
    let mut buf = [0u8; 256];
    match postcard::to_slice(c, &mut buf) {
        Ok(bytes) => hammer_types::crc32(bytes),
        Err(_) => 0,
    }
}
