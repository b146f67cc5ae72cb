//! The quality flags of a cycle: one varint on the wire (a `u32` since
//! protocol 6; postcard writes a `u16` and a `u32` of one value alike, so a
//! protocol-5 report's flags read as they are).

use serde::{Deserialize, Serialize};

/// Quality flags of a cycle. Bits in [`Flags::INVALIDATING`] mean the numbers
/// of that cycle are not estimates and must not be used as such; the others
/// are warnings whose effect is already in the stated uncertainty.
///
/// On the wire (and in JSON) a `Flags` is its bare integer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Flags(pub u32);

impl Flags {
    pub const REAR_SATURATED: Flags = Flags(1 << 0);
    pub const FRONT_SATURATED: Flags = Flags(1 << 1);
    pub const ACCEL_SATURATED: Flags = Flags(1 << 2);
    pub const REAR_STUCK: Flags = Flags(1 << 3);
    pub const FRONT_STUCK: Flags = Flags(1 << 4);
    pub const ACCEL_STUCK: Flags = Flags(1 << 5);
    /// A channel sat at a rail for most of the cycle: open or shorted sensor.
    pub const DISCONNECTED: Flags = Flags(1 << 6);
    /// Samples were lost inside the cycle (ADC overrun, link gap).
    pub const DROPPED_SAMPLES: Flags = Flags(1 << 7);
    /// No turning point from backhaul to stroke was found.
    pub const NO_REVERSAL: Flags = Flags(1 << 8);
    /// Period, stroke or friction outside what a working hammer produces.
    pub const IMPLAUSIBLE: Flags = Flags(1 << 9);
    /// The cycle was longer than the checkpoint memory.
    pub const OVERFLOW: Flags = Flags(1 << 10);
    /// Warning: the accelerometer carried a zero shift after the impact; fitted and removed.
    pub const ACCEL_ZERO_SHIFT: Flags = Flags(1 << 11);
    /// Warning: stroke and backhaul friction disagree beyond their uncertainty
    /// (a pressure or acceleration gain error looks like this).
    pub const PHASE_MISMATCH: Flags = Flags(1 << 12);
    /// Warning: the friction drift alarm is active.
    pub const DRIFT_ALARM: Flags = Flags(1 << 13);
    /// The accelerometer disagrees with the force the pressures exert (its
    /// gain, its sign, or a dead sensor): the force balance cannot hold.
    pub const ACCEL_FAULT: Flags = Flags(1 << 14);
    /// No impact came when one was due while the pressures kept cycling (a
    /// record instead of silence; the other flags name the suspect), or the
    /// cycle did not open at a confirmed impact.
    pub const NO_IMPACT: Flags = Flags(1 << 15);
    /// The chambers' characteristics (`front_*`, `rear_*` fields) were not
    /// read for this cycle; they are NaN. Not an invalidating flag: the
    /// cycle's own numbers stand. Set where the cycle is not a valid one,
    /// its window (the cycle and the 8 ms after it) is longer than the
    /// board holds, samples were lost in it, the reading was overtaken by
    /// the samples (never in a board within its budget), a raw capture held
    /// the window, or by a reader that does not read them (a host's plain
    /// estimate, a recording from before protocol 6).
    pub const CHAMBERS_UNREAD: Flags = Flags(1 << 16);

    pub const INVALIDATING: Flags = Flags(
        Self::SENSOR_FAULTS.0
            | Self::DROPPED_SAMPLES.0
            | Self::NO_REVERSAL.0
            | Self::IMPLAUSIBLE.0
            | Self::OVERFLOW.0
            | Self::NO_IMPACT.0,
    );

    /// Flags that blame a sensor rather than the hammer: the device's
    /// `SensorFault` alarm. The one definition of that set: the device raises
    /// the alarm from it, the host only displays the alarm.
    pub const SENSOR_FAULTS: Flags = Flags(
        Self::REAR_SATURATED.0
            | Self::FRONT_SATURATED.0
            | Self::ACCEL_SATURATED.0
            | Self::REAR_STUCK.0
            | Self::FRONT_STUCK.0
            | Self::ACCEL_STUCK.0
            | Self::DISCONNECTED.0
            | Self::ACCEL_FAULT.0,
    );

    pub const NAMES: [(Flags, &'static str); 17] = [
        (Self::REAR_SATURATED, "rear_saturated"),
        (Self::FRONT_SATURATED, "front_saturated"),
        (Self::ACCEL_SATURATED, "accel_saturated"),
        (Self::REAR_STUCK, "rear_stuck"),
        (Self::FRONT_STUCK, "front_stuck"),
        (Self::ACCEL_STUCK, "accel_stuck"),
        (Self::DISCONNECTED, "disconnected"),
        (Self::DROPPED_SAMPLES, "dropped_samples"),
        (Self::NO_REVERSAL, "no_reversal"),
        (Self::IMPLAUSIBLE, "implausible"),
        (Self::OVERFLOW, "overflow"),
        (Self::ACCEL_ZERO_SHIFT, "accel_zero_shift"),
        (Self::PHASE_MISMATCH, "phase_mismatch"),
        (Self::DRIFT_ALARM, "drift_alarm"),
        (Self::ACCEL_FAULT, "accel_fault"),
        (Self::NO_IMPACT, "no_impact"),
        (Self::CHAMBERS_UNREAD, "chambers_unread"),
    ];

    pub fn contains(self, other: Flags) -> bool {
        self.0 & other.0 == other.0
    }

    pub fn intersects(self, other: Flags) -> bool {
        self.0 & other.0 != 0
    }

    pub fn insert(&mut self, other: Flags) {
        self.0 |= other.0;
    }

    pub fn remove(&mut self, other: Flags) {
        self.0 &= !other.0;
    }

    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// Names of the set flags.
    pub fn names(self) -> impl Iterator<Item = &'static str> {
        Self::NAMES
            .into_iter()
            .filter(move |(f, _)| self.contains(*f))
            .map(|(_, n)| n)
    }
}

impl core::ops::BitOr for Flags {
    type Output = Flags;
    fn bitor(self, rhs: Flags) -> Flags {
        Flags(self.0 | rhs.0)
    }
}
