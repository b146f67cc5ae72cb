//! The one mapping between the estimator's runtime [`Config`] and the
//! device configuration on the wire ([`DeviceConfig`], defined in
//! `hammer-types`): the device answers `GetConfig` with
//! `DeviceConfig::from(&config)` and applies a `SetConfig` with
//! [`Config::with_device`]. Both ways live here and nowhere else.

use crate::config::{ChannelCal, ChannelSpec, Config};
use hammer_types::{ChannelCalibration, DeviceConfig};

fn cal(c: &ChannelCal, s: &ChannelSpec) -> ChannelCalibration {
    ChannelCalibration {
        zero_code: c.zero_code,
        scale: c.scale,
        full_scale_code: c.full_scale_code,
        gain_uncertainty: s.gain_rel,
        offset_uncertainty: s.offset,
    }
}

fn uncal(c: &ChannelCalibration) -> (ChannelCal, ChannelSpec) {
    (
        ChannelCal {
            zero_code: c.zero_code,
            scale: c.scale,
            full_scale_code: c.full_scale_code,
        },
        ChannelSpec {
            gain_rel: c.gain_uncertainty,
            offset: c.offset_uncertainty,
        },
    )
}

impl Config {
    /// The hash every report carries ([`hammer_types::calibration_hash`]),
    /// over the same channel calibrations `GetConfig` answers with.
    pub fn calibration_hash(&self) -> u32 {
        hammer_types::calibration_hash(
            &cal(&self.rear, &self.rear_spec),
            &cal(&self.front, &self.front_spec),
            &cal(&self.accel, &self.accel_spec),
        )
    }
}

impl From<&Config> for DeviceConfig {
    fn from(c: &Config) -> Self {
        DeviceConfig {
            sample_rate_hz: c.sample_rate_hz,
            piston_mass_kg: crate::math::narrow(c.geometry.piston_mass_kg),
            bore_diameter_m: crate::math::narrow(c.geometry.bore_diameter_m),
            rod_diameter_m: crate::math::narrow(c.geometry.rod_diameter_m),
            inclination_deg: c.inclination_deg,
            rear: cal(&c.rear, &c.rear_spec),
            front: cal(&c.front, &c.front_spec),
            accel: cal(&c.accel, &c.accel_spec),
            impact_threshold_mps2: c.impact_threshold_mps2,
            blank_before_s: c.blank_before_s,
            blank_after_s: c.blank_after_s,
            min_period_s: c.min_period_s,
            max_period_s: c.max_period_s,
            accel_zero_shift_tau_s: c.accel_zero_shift_tau_s,
            coverage_factor: c.coverage_factor,
            supply_pressure_pa: c.supply_pressure_pa,
            wear_budget_j: c.wear.budget_j,
            baseline_cycles: c.wear.baseline_cycles,
            cusum_k: c.wear.cusum_k,
            cusum_h: c.wear.cusum_h,
            travel_m: c.geometry.travel_m,
            rear_dead_m3: c.chambers.rear_dead_m3,
            front_dead_m3: c.chambers.front_dead_m3,
            rear_outlet_m: c.chambers.rear_outlet_m,
            front_outlet_m: c.chambers.front_outlet_m,
            pressure_group_delay_s: c.chambers.pressure_group_delay_s,
        }
    }
}

impl Config {
    /// The configuration `d` describes, on top of `self` for anything the
    /// wire does not carry (residual correlation, stuck time, the wear
    /// baseline's floors and bins). Validate before use.
    pub fn with_device(&self, d: &DeviceConfig) -> Config {
        let (rear, rear_spec) = uncal(&d.rear);
        let (front, front_spec) = uncal(&d.front);
        let (accel, accel_spec) = uncal(&d.accel);
        let mut c = *self;
        c.sample_rate_hz = d.sample_rate_hz;
        c.geometry.piston_mass_kg = crate::math::widen(d.piston_mass_kg);
        c.geometry.bore_diameter_m = crate::math::widen(d.bore_diameter_m);
        c.geometry.rod_diameter_m = crate::math::widen(d.rod_diameter_m);
        c.inclination_deg = d.inclination_deg;
        c.rear = rear;
        c.front = front;
        c.accel = accel;
        c.rear_spec = rear_spec;
        c.front_spec = front_spec;
        c.accel_spec = accel_spec;
        c.impact_threshold_mps2 = d.impact_threshold_mps2;
        c.blank_before_s = d.blank_before_s;
        c.blank_after_s = d.blank_after_s;
        c.min_period_s = d.min_period_s;
        c.max_period_s = d.max_period_s;
        c.accel_zero_shift_tau_s = d.accel_zero_shift_tau_s;
        c.coverage_factor = d.coverage_factor;
        c.supply_pressure_pa = d.supply_pressure_pa;
        c.wear.budget_j = d.wear_budget_j;
        c.wear.baseline_cycles = d.baseline_cycles;
        c.wear.cusum_k = d.cusum_k;
        c.wear.cusum_h = d.cusum_h;
        c.geometry.travel_m = d.travel_m;
        c.chambers = crate::ChamberConfig {
            rear_dead_m3: d.rear_dead_m3,
            front_dead_m3: d.front_dead_m3,
            rear_outlet_m: d.rear_outlet_m,
            front_outlet_m: d.front_outlet_m,
            pressure_group_delay_s: d.pressure_group_delay_s,
        };
        c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn configs_convert_without_loss() {
        let mut c = Config {
            supply_pressure_pa: 4e5,
            inclination_deg: 30.0,
            ..Config::default()
        };
        // Every chamber field travels (none left at the default).
        c.geometry.travel_m = 0.061;
        c.chambers.rear_dead_m3 = 21e-6;
        c.chambers.front_dead_m3 = 17e-6;
        c.chambers.rear_outlet_m = 0.041;
        c.chambers.front_outlet_m = 0.017;
        c.chambers.pressure_group_delay_s = 7e-6;
        let wire = DeviceConfig::from(&c);
        let back = Config::default().with_device(&wire);
        // The geometry is f64 in the estimator, f32 on the wire.
        let c32 = Config {
            geometry: back.geometry,
            ..c
        };
        assert_eq!(back, c32);
        assert!((back.geometry.piston_mass_kg - c.geometry.piston_mass_kg).abs() < 1e-6);
        assert!(back.validate().is_ok());
        assert_eq!(DeviceConfig::from(&back), wire);
    }
}
