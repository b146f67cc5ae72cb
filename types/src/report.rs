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
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
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
    pub flags: Flags,
}

impl CycleReport {
    /// The impact's time in seconds: the nearest `f64` to the µs count's
    /// decimal value (a division by 10⁶ rounds once; a product by 1e-6 can
    /// print as 1.2345670000000001).
    pub fn t_impact_s(&self) -> f64 {
        self.t_impact_us as f64 / 1e6
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
