//! What the estimator reports per impact cycle: the device's `Report`
//! message as it is, field order = wire order.

use serde::{Deserialize, Serialize};

use crate::Flags;

/// One impact cycle: the backhaul after an impact and the stroke that ends
/// in the next. Uncertainties are expanded (coverage factor in the config).
///
/// This is the wire's `DeviceMsg::Report` payload: postcard is not
/// self-describing, so appending, removing or reordering a field changes the
/// protocol (bump `hammer_wire::PROTOCOL_VERSION`). Every field must also be
/// in [`crate::fields::FIELDS`], the one table every rendering is driven by.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
pub struct CycleReport {
    /// Counts every closed cycle, valid or not, from 0: a gap in the sequence is a lost report.
    pub seq: u32,
    /// Time of the impact that closes the cycle, µs from the first sample
    /// by the sample clock. An integer: exact for years, and computed on the
    /// board without double precision, which its FPU lacks (`t_impact_s()`
    /// gives seconds; renderings show that, as column `t_impact_s`).
    pub t_impact_us: u64,
    pub period_s: f32,
    pub frequency_hz: f32,
    /// Mean friction magnitude over the cycle (stroke and backhaul samples).
    pub friction_n: f32,
    pub friction_stroke_n: f32,
    pub friction_backhaul_n: f32,
    pub friction_uncertainty_n: f32,
    pub friction_stroke_uncertainty_n: f32,
    pub friction_backhaul_uncertainty_n: f32,
    pub impact_velocity_mps: f32,
    pub impact_velocity_frictionless_mps: f32,
    pub impact_energy_j: f32,
    pub impact_energy_frictionless_j: f32,
    pub impact_energy_uncertainty_j: f32,
    pub impact_energy_frictionless_uncertainty_j: f32,
    /// Friction work of the cycle (stroke and backhaul).
    pub friction_work_j: f32,
    /// Stroke friction work over impact energy (the paper's "about 10 %").
    pub friction_work_ratio: f32,
    pub stroke_m: f32,
    pub peak_rear_pa: f32,
    pub peak_front_pa: f32,
    /// Zero shift of the accelerometer fitted at the start of the backhaul.
    pub accel_zero_shift_mps2: f32,
    /// Archard-style wear index: cumulative friction work, J.
    pub wear_index_j: f32,
    /// Fraction of the configured wear budget left (1 = new).
    pub wear_remaining_fraction: f32,
    /// Cycles left at the current friction work per cycle.
    pub remaining_life_cycles: f32,
    /// One-sided CUSUM of the friction against its baseline, in baseline σ.
    pub drift_score: f32,
    /// CRC-32 of the channel calibrations the cycle was computed with
    /// ([`crate::calibration_hash`]): a number traced to its calibration.
    pub calibration_hash: u32,
    // The chambers' characteristics of this cycle (protocol 6): how the
    // valve switched each chamber's feed and how the closed chambers held
    // their air, read at the cycle's close from its codes and the 8 ms after
    // it (`hammer_estimator::chambers::at_close`). NaN where not read
    // ([`Flags::CHAMBERS_UNREAD`]) or where a chamber showed no closed phase
    // and feed to read. The state at an onset carries no uncertainty of its
    // own (it is read off the track at the onset).
    /// Onset of the front chamber's feed from the impact that closes the
    /// cycle (negative: before it).
    pub front_feed_s: f32,
    pub front_feed_uncertainty_s: f32,
    /// The piston's position at the front feed's onset (0 at the rear end).
    pub front_feed_x_m: f32,
    pub front_feed_p_rear_pa: f32,
    pub front_feed_p_front_pa: f32,
    /// Polytropic exponent of the front chamber's closed phase before its
    /// feed (1.4 sealed and adiabatic).
    pub front_closed_exponent: f32,
    pub front_closed_exponent_uncertainty: f32,
    /// Effective area of the front feed, from the energy equation against
    /// the supply pressure (NaN without one in the configuration).
    pub front_feed_area_m2: f32,
    pub front_feed_area_uncertainty_m2: f32,
    /// Onset of the rear chamber's feed from the impact that opens the cycle.
    pub rear_feed_s: f32,
    pub rear_feed_uncertainty_s: f32,
    pub rear_feed_x_m: f32,
    pub rear_feed_p_rear_pa: f32,
    pub rear_feed_p_front_pa: f32,
    pub rear_closed_exponent: f32,
    pub rear_closed_exponent_uncertainty: f32,
    pub rear_feed_area_m2: f32,
    pub rear_feed_area_uncertainty_m2: f32,
    pub flags: Flags,
}

/// One chamber's characteristics as a report carries them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedFields {
    pub feed_s: f32,
    pub feed_uncertainty_s: f32,
    pub feed_x_m: f32,
    pub feed_p_rear_pa: f32,
    pub feed_p_front_pa: f32,
    pub closed_exponent: f32,
    pub closed_exponent_uncertainty: f32,
    pub feed_area_m2: f32,
    pub feed_area_uncertainty_m2: f32,
}

impl FeedFields {
    /// A chamber not read.
    pub const NAN: FeedFields = FeedFields {
        feed_s: f32::NAN,
        feed_uncertainty_s: f32::NAN,
        feed_x_m: f32::NAN,
        feed_p_rear_pa: f32::NAN,
        feed_p_front_pa: f32::NAN,
        closed_exponent: f32::NAN,
        closed_exponent_uncertainty: f32::NAN,
        feed_area_m2: f32::NAN,
        feed_area_uncertainty_m2: f32::NAN,
    };
}

/// Two reports are equal when they are the same bytes: every field bit for
/// bit, so a NaN (an unread chamber) equals itself and the board's report
/// is compared with the host's as the wire carries them.
impl PartialEq for CycleReport {
    fn eq(&self, other: &Self) -> bool {
        self.t_impact_us == other.t_impact_us
            && self.flags == other.flags
            && crate::FIELDS.iter().all(|f| f.value(self).same(f.value(other)))
    }
}

impl CycleReport {
    /// The impact's time in seconds: the nearest `f64` to the µs count's
    /// decimal value (a division by 10⁶ rounds once; a product by 1e-6 can
    /// print as 1.2345670000000001).
    pub fn t_impact_s(&self) -> f64 {
        self.t_impact_us as f64 / 1e6
    }

    /// The chambers not read: every characteristic NaN, flagged
    /// [`Flags::CHAMBERS_UNREAD`]. What a cycle's report says until a
    /// reader reads them.
    pub fn mark_chambers_unread(&mut self) {
        self.set_chambers(FeedFields::NAN, FeedFields::NAN);
        self.flags.insert(Flags::CHAMBERS_UNREAD);
    }

    /// The chambers read: `front` and `rear` (either [`FeedFields::NAN`]
    /// where that chamber showed nothing to read), the flag cleared.
    pub fn set_chambers_read(&mut self, front: FeedFields, rear: FeedFields) {
        self.set_chambers(front, rear);
        self.flags.remove(Flags::CHAMBERS_UNREAD);
    }

    fn set_chambers(&mut self, f: FeedFields, r: FeedFields) {
        self.front_feed_s = f.feed_s;
        self.front_feed_uncertainty_s = f.feed_uncertainty_s;
        self.front_feed_x_m = f.feed_x_m;
        self.front_feed_p_rear_pa = f.feed_p_rear_pa;
        self.front_feed_p_front_pa = f.feed_p_front_pa;
        self.front_closed_exponent = f.closed_exponent;
        self.front_closed_exponent_uncertainty = f.closed_exponent_uncertainty;
        self.front_feed_area_m2 = f.feed_area_m2;
        self.front_feed_area_uncertainty_m2 = f.feed_area_uncertainty_m2;
        self.rear_feed_s = r.feed_s;
        self.rear_feed_uncertainty_s = r.feed_uncertainty_s;
        self.rear_feed_x_m = r.feed_x_m;
        self.rear_feed_p_rear_pa = r.feed_p_rear_pa;
        self.rear_feed_p_front_pa = r.feed_p_front_pa;
        self.rear_closed_exponent = r.closed_exponent;
        self.rear_closed_exponent_uncertainty = r.closed_exponent_uncertainty;
        self.rear_feed_area_m2 = r.feed_area_m2;
        self.rear_feed_area_uncertainty_m2 = r.feed_area_uncertainty_m2;
    }

    /// The front chamber's characteristics as carried.
    pub fn front_feed(&self) -> FeedFields {
        FeedFields {
            feed_s: self.front_feed_s,
            feed_uncertainty_s: self.front_feed_uncertainty_s,
            feed_x_m: self.front_feed_x_m,
            feed_p_rear_pa: self.front_feed_p_rear_pa,
            feed_p_front_pa: self.front_feed_p_front_pa,
            closed_exponent: self.front_closed_exponent,
            closed_exponent_uncertainty: self.front_closed_exponent_uncertainty,
            feed_area_m2: self.front_feed_area_m2,
            feed_area_uncertainty_m2: self.front_feed_area_uncertainty_m2,
        }
    }

    /// The rear chamber's characteristics as carried.
    pub fn rear_feed(&self) -> FeedFields {
        FeedFields {
            feed_s: self.rear_feed_s,
            feed_uncertainty_s: self.rear_feed_uncertainty_s,
            feed_x_m: self.rear_feed_x_m,
            feed_p_rear_pa: self.rear_feed_p_rear_pa,
            feed_p_front_pa: self.rear_feed_p_front_pa,
            closed_exponent: self.rear_closed_exponent,
            closed_exponent_uncertainty: self.rear_closed_exponent_uncertainty,
            feed_area_m2: self.rear_feed_area_m2,
            feed_area_uncertainty_m2: self.rear_feed_area_uncertainty_m2,
        }
    }

    /// True when the numbers are estimates (no invalidating flag).
    pub fn is_valid(&self) -> bool {
        !self.flags.intersects(Flags::INVALIDATING)
    }

    /// True when the record closes a cycle between two impacts, false for a
    /// no-impact record (a stretch that reached no impact, flagged with the
    /// channel suspected).
    pub fn is_cycle(&self) -> bool {
        !self.flags.contains(Flags::NO_IMPACT)
    }
}

/// Protocols 4 and 5's report: [`CycleReport`] without the chambers'
/// characteristics (and its flags then a `u16`, which postcard writes as a
/// `u32` of the same value is written). Read from a recording made before
/// protocol 6; never sent.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
pub struct CycleReportV5 {
    pub seq: u32,
    pub t_impact_us: u64,
    pub period_s: f32,
    pub frequency_hz: f32,
    pub friction_n: f32,
    pub friction_stroke_n: f32,
    pub friction_backhaul_n: f32,
    pub friction_uncertainty_n: f32,
    pub friction_stroke_uncertainty_n: f32,
    pub friction_backhaul_uncertainty_n: f32,
    pub impact_velocity_mps: f32,
    pub impact_velocity_frictionless_mps: f32,
    pub impact_energy_j: f32,
    pub impact_energy_frictionless_j: f32,
    pub impact_energy_uncertainty_j: f32,
    pub impact_energy_frictionless_uncertainty_j: f32,
    pub friction_work_j: f32,
    pub friction_work_ratio: f32,
    pub stroke_m: f32,
    pub peak_rear_pa: f32,
    pub peak_front_pa: f32,
    pub accel_zero_shift_mps2: f32,
    pub wear_index_j: f32,
    pub wear_remaining_fraction: f32,
    pub remaining_life_cycles: f32,
    pub drift_score: f32,
    pub calibration_hash: u32,
    pub flags: u16,
}

impl CycleReportV5 {
    /// The report as protocol 6 carries it: the chambers unread.
    pub fn into_current(self) -> CycleReport {
        let mut r = CycleReport {
            seq: self.seq,
            t_impact_us: self.t_impact_us,
            period_s: self.period_s,
            frequency_hz: self.frequency_hz,
            friction_n: self.friction_n,
            friction_stroke_n: self.friction_stroke_n,
            friction_backhaul_n: self.friction_backhaul_n,
            friction_uncertainty_n: self.friction_uncertainty_n,
            friction_stroke_uncertainty_n: self.friction_stroke_uncertainty_n,
            friction_backhaul_uncertainty_n: self.friction_backhaul_uncertainty_n,
            impact_velocity_mps: self.impact_velocity_mps,
            impact_velocity_frictionless_mps: self.impact_velocity_frictionless_mps,
            impact_energy_j: self.impact_energy_j,
            impact_energy_frictionless_j: self.impact_energy_frictionless_j,
            impact_energy_uncertainty_j: self.impact_energy_uncertainty_j,
            impact_energy_frictionless_uncertainty_j: self.impact_energy_frictionless_uncertainty_j,
            friction_work_j: self.friction_work_j,
            friction_work_ratio: self.friction_work_ratio,
            stroke_m: self.stroke_m,
            peak_rear_pa: self.peak_rear_pa,
            peak_front_pa: self.peak_front_pa,
            accel_zero_shift_mps2: self.accel_zero_shift_mps2,
            wear_index_j: self.wear_index_j,
            wear_remaining_fraction: self.wear_remaining_fraction,
            remaining_life_cycles: self.remaining_life_cycles,
            drift_score: self.drift_score,
            calibration_hash: self.calibration_hash,
            flags: Flags(u32::from(self.flags)),
            ..CycleReport::default()
        };
        r.mark_chambers_unread();
        r
    }
}
