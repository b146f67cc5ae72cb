//! Between the estimator's types and their wire form.

use hammer_estimator::{ChannelCal, ChannelSpec, Config, CycleReport, Flags, Geometry};

use crate::msg::{ChannelCalibration, DeviceConfig, Report};

impl From<&CycleReport> for Report {
    fn from(r: &CycleReport) -> Self {
        Report {
            seq: r.seq,
            t_impact_s: r.t_impact_s,
            period_s: r.period_s,
            frequency_hz: r.frequency_hz,
            friction_n: r.friction_n,
            friction_stroke_n: r.friction_stroke_n,
            friction_backhaul_n: r.friction_backhaul_n,
            friction_uncertainty_n: r.friction_uncertainty_n,
            friction_stroke_uncertainty_n: r.friction_stroke_uncertainty_n,
            friction_backhaul_uncertainty_n: r.friction_backhaul_uncertainty_n,
            impact_velocity_mps: r.impact_velocity_mps,
            impact_velocity_frictionless_mps: r.impact_velocity_frictionless_mps,
            impact_energy_j: r.impact_energy_j,
            impact_energy_frictionless_j: r.impact_energy_frictionless_j,
            impact_energy_uncertainty_j: r.impact_energy_uncertainty_j,
            impact_energy_frictionless_uncertainty_j: r.impact_energy_frictionless_uncertainty_j,
            friction_work_j: r.friction_work_j,
            friction_work_ratio: r.friction_work_ratio,
            stroke_m: r.stroke_m,
            peak_rear_pa: r.peak_rear_pa,
            peak_front_pa: r.peak_front_pa,
            accel_zero_shift_mps2: r.accel_zero_shift_mps2,
            wear_index_j: r.wear_index_j,
            wear_remaining_fraction: r.wear_remaining_fraction,
            remaining_life_cycles: r.remaining_life_cycles,
            drift_score: r.drift_score,
            flags: r.flags.0,
        }
    }
}

impl Report {
    pub fn flags(&self) -> Flags {
        Flags(self.flags)
    }

    pub fn is_valid(&self) -> bool {
        !self.flags().intersects(Flags::INVALIDATING)
    }
}

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

impl From<&Config> for DeviceConfig {
    fn from(c: &Config) -> Self {
        DeviceConfig {
            sample_rate_hz: c.sample_rate_hz,
            piston_mass_kg: c.geometry.piston_mass_kg as f32,
            bore_diameter_m: c.geometry.bore_diameter_m as f32,
            rod_diameter_m: c.geometry.rod_diameter_m as f32,
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
        }
    }
}

impl DeviceConfig {
    /// The estimator configuration this describes, on top of `base` for
    /// anything the wire does not carry. Validate before use.
    pub fn to_config(&self, base: &Config) -> Config {
        let (rear, rear_spec) = uncal(&self.rear);
        let (front, front_spec) = uncal(&self.front);
        let (accel, accel_spec) = uncal(&self.accel);
        let mut c = *base;
        c.sample_rate_hz = self.sample_rate_hz;
        c.geometry = Geometry {
            piston_mass_kg: self.piston_mass_kg as f64,
            bore_diameter_m: self.bore_diameter_m as f64,
            rod_diameter_m: self.rod_diameter_m as f64,
        };
        c.inclination_deg = self.inclination_deg;
        c.rear = rear;
        c.front = front;
        c.accel = accel;
        c.rear_spec = rear_spec;
        c.front_spec = front_spec;
        c.accel_spec = accel_spec;
        c.impact_threshold_mps2 = self.impact_threshold_mps2;
        c.blank_before_s = self.blank_before_s;
        c.blank_after_s = self.blank_after_s;
        c.min_period_s = self.min_period_s;
        c.max_period_s = self.max_period_s;
        c.accel_zero_shift_tau_s = self.accel_zero_shift_tau_s;
        c.coverage_factor = self.coverage_factor;
        c.supply_pressure_pa = self.supply_pressure_pa;
        c.wear.budget_j = self.wear_budget_j;
        c.wear.baseline_cycles = self.baseline_cycles;
        c.wear.cusum_k = self.cusum_k;
        c.wear.cusum_h = self.cusum_h;
        c
    }

    /// CRC-32 of the configuration's wire bytes: reported in `Hello` and
    /// `Status`, so a host sees which configuration produced a report.
    pub fn hash(&self) -> u32 {
        let mut buf = [0u8; 256];
        match postcard::to_slice(self, &mut buf) {
            Ok(bytes) => hammer_estimator::wear::crc32(bytes),
            Err(_) => 0,
        }
    }
}
