//! The device's configuration on the wire. The estimator derives its
//! runtime `Config` from this (and maps it back); field order is wire order.

use serde::{Deserialize, Serialize};

/// One channel's calibration: `value = (code − zero_code)·scale`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ChannelCalibration {
    pub zero_code: f32,
    pub scale: f32,
    pub full_scale_code: u16,
    pub gain_uncertainty: f32,
    pub offset_uncertainty: f32,
}

/// The device's configuration: the hammer, the sensors, the thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DeviceConfig {
    pub sample_rate_hz: f32,
    pub piston_mass_kg: f32,
    pub bore_diameter_m: f32,
    pub rod_diameter_m: f32,
    pub inclination_deg: f32,
    pub rear: ChannelCalibration,
    pub front: ChannelCalibration,
    pub accel: ChannelCalibration,
    pub impact_threshold_mps2: f32,
    pub blank_before_s: f32,
    pub blank_after_s: f32,
    pub min_period_s: f32,
    pub max_period_s: f32,
    pub accel_zero_shift_tau_s: f32,
    pub coverage_factor: f32,
    /// Gauge supply pressure, NaN when unknown.
    pub supply_pressure_pa: f32,
    pub wear_budget_j: f32,
    pub baseline_cycles: u16,
    pub cusum_k: f32,
    pub cusum_h: f32,
    // Protocol 5: the chambers, for the characteristics the board reads
    // at each cycle's close. Positions are of the piston's rear face from
    // the rear cover; the travel ends at the impact position.
    pub travel_m: f32,
    /// Rear chamber volume at x = 0.
    pub rear_dead_m3: f32,
    /// Front chamber volume at the impact position.
    pub front_dead_m3: f32,
    pub rear_outlet_m: f32,
    pub front_outlet_m: f32,
    /// The pressure channels' group delay (transducer and anti-alias filter).
    pub pressure_group_delay_s: f32,
}

/// The configuration as protocol 4 carried it and boards stored it, before
/// the chambers: read only, to migrate a stored record or an old recording.
/// Frozen: never change a field.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DeviceConfigV4 {
    pub sample_rate_hz: f32,
    pub piston_mass_kg: f32,
    pub bore_diameter_m: f32,
    pub rod_diameter_m: f32,
    pub inclination_deg: f32,
    pub rear: ChannelCalibration,
    pub front: ChannelCalibration,
    pub accel: ChannelCalibration,
    pub impact_threshold_mps2: f32,
    pub blank_before_s: f32,
    pub blank_after_s: f32,
    pub min_period_s: f32,
    pub max_period_s: f32,
    pub accel_zero_shift_tau_s: f32,
    pub coverage_factor: f32,
    pub supply_pressure_pa: f32,
    pub wear_budget_j: f32,
    pub baseline_cycles: u16,
    pub cusum_k: f32,
    pub cusum_h: f32,
}

impl DeviceConfigV4 {
    /// The configuration with `chambers`' travel, chambers and group delay
    /// (which protocol 4 did not hold) and everything else of this one.
    pub fn with_chambers_of(&self, chambers: &DeviceConfig) -> DeviceConfig {
        DeviceConfig {
            sample_rate_hz: self.sample_rate_hz,
            piston_mass_kg: self.piston_mass_kg,
            bore_diameter_m: self.bore_diameter_m,
            rod_diameter_m: self.rod_diameter_m,
            inclination_deg: self.inclination_deg,
            rear: self.rear,
            front: self.front,
            accel: self.accel,
            impact_threshold_mps2: self.impact_threshold_mps2,
            blank_before_s: self.blank_before_s,
            blank_after_s: self.blank_after_s,
            min_period_s: self.min_period_s,
            max_period_s: self.max_period_s,
            accel_zero_shift_tau_s: self.accel_zero_shift_tau_s,
            coverage_factor: self.coverage_factor,
            supply_pressure_pa: self.supply_pressure_pa,
            wear_budget_j: self.wear_budget_j,
            baseline_cycles: self.baseline_cycles,
            cusum_k: self.cusum_k,
            cusum_h: self.cusum_h,
            ..*chambers
        }
    }
}

impl ChannelCalibration {
    /// The calibration's bytes in a fixed little-endian layout (not the
    /// wire's varints), so its hash does not depend on a serialiser.
    fn bytes(&self) -> [u8; 18] {
        let mut b = [0u8; 18];
        b[0..4].copy_from_slice(&self.zero_code.to_le_bytes());
        b[4..8].copy_from_slice(&self.scale.to_le_bytes());
        b[8..10].copy_from_slice(&self.full_scale_code.to_le_bytes());
        b[10..14].copy_from_slice(&self.gain_uncertainty.to_le_bytes());
        b[14..18].copy_from_slice(&self.offset_uncertainty.to_le_bytes());
        b
    }
}

/// CRC-32 of the three channels' calibrations (rear, front, accelerometer):
/// every cycle report carries it, so a logged number can be traced to the
/// calibration that produced it, whatever else of the configuration changed.
pub fn calibration_hash(rear: &ChannelCalibration, front: &ChannelCalibration, accel: &ChannelCalibration) -> u32 {
    let mut b = [0u8; 54];
    b[0..18].copy_from_slice(&rear.bytes());
    b[18..36].copy_from_slice(&front.bytes());
    b[36..54].copy_from_slice(&accel.bytes());
    crate::crc32(&b)
}

impl DeviceConfig {
    /// This configuration with `other`'s chambers (travel, dead volumes,
    /// outlets, the pressures' group delay): a calibration keeps the
    /// channels it measured and takes the hammer's chambers from its file.
    pub fn with_chambers_of(&self, other: &DeviceConfig) -> DeviceConfig {
        DeviceConfig {
            travel_m: other.travel_m,
            rear_dead_m3: other.rear_dead_m3,
            front_dead_m3: other.front_dead_m3,
            rear_outlet_m: other.rear_outlet_m,
            front_outlet_m: other.front_outlet_m,
            pressure_group_delay_s: other.pressure_group_delay_s,
            ..*self
        }
    }

    /// [`calibration_hash`] of this configuration's channels.
    pub fn calibration_hash(&self) -> u32 {
        calibration_hash(&self.rear, &self.front, &self.accel)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn channel(scale: f32) -> ChannelCalibration {
        ChannelCalibration {
            zero_code: 372.25,
            scale,
            full_scale_code: 4095,
            gain_uncertainty: 0.008,
            offset_uncertainty: 1000.0,
        }
    }

    /// Any channel's zero, scale or uncertainty changes the hash; the order
    /// of the channels matters (a swapped rear/front is another calibration).
    #[test]
    fn the_hash_follows_every_calibration_field_and_the_channel_order() {
        let (a, b, c) = (channel(268.5), channel(270.0), channel(0.9765));
        let h = calibration_hash(&a, &b, &c);
        assert_ne!(h, calibration_hash(&b, &a, &c));
        assert_ne!(h, calibration_hash(&a, &b, &channel(0.9766)));
        let mut z = a;
        z.zero_code += 0.25;
        assert_ne!(h, calibration_hash(&z, &b, &c));
        let mut u = c;
        u.offset_uncertainty = 2.0;
        assert_ne!(h, calibration_hash(&a, &b, &u));
        let mut f = b;
        f.full_scale_code = 4094;
        assert_ne!(h, calibration_hash(&a, &f, &c));
        assert_eq!(h, calibration_hash(&a, &b, &c));
    }
}
