//! Estimator configuration: the hammer, the sensor chain and the thresholds.
//! Defaults describe the paper's hammer on the project's reference bench.

use crate::geometry::{circle_area_f32, Geometry, STANDARD_GRAVITY_MPS2};
use crate::math;

/// Resolutions of the converters the estimator reads. Codes are `u16` (the
/// samples, the wire format, [`ChannelCal::full_scale_code`]), so 16 bits is
/// the most; below 8 bits a cycle's pressure swing spans too few codes to fit.
/// The simulator refuses what falls outside, so it never writes a trace the
/// estimator cannot read.
pub const ADC_BITS_MIN: u8 = 8;
pub const ADC_BITS_MAX: u8 = 16;

/// Linear calibration of one ADC channel: `value = (code − zero_code)·scale`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelCal {
    /// Code that reads zero (set by tare).
    pub zero_code: f32,
    /// Physical units per code (Pa or m/s²).
    pub scale: f32,
    /// Highest code the converter delivers (4095 for 12 bits).
    pub full_scale_code: u16,
}

impl ChannelCal {
    /// A converter whose code 0 reads `min` and whose top code reads `max`.
    pub fn from_range(min: f32, max: f32, bits: u8) -> Self {
        let full = ((1u32 << bits) - 1) as u16;
        let scale = (max - min) / full as f32;
        Self {
            zero_code: -min / scale,
            scale,
            full_scale_code: full,
        }
    }

    #[inline]
    pub fn value(&self, code: u16) -> f32 {
        (code as f32 - self.zero_code) * self.scale
    }

    /// The code this calibration reads as `value` (nearest, clipped to the
    /// converter's range; NaN reads as code 0). The inverse of [`Self::value`]
    /// up to rounding: what an ideal ADC of this calibration converts.
    pub fn code(&self, value: f64) -> u16 {
        let x = libm::roundf(value as f32 / self.scale + self.zero_code);
        if x.is_nan() {
            0
        } else {
            crate::math::clamp(x, 0.0, self.full_scale_code as f32) as u16
        }
    }

    /// Physical value of the range's ends.
    pub fn range(&self) -> (f32, f32) {
        (self.value(0), self.value(self.full_scale_code))
    }
}

/// Standard uncertainties of one channel after calibration and tare.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChannelSpec {
    /// Relative gain uncertainty (0.008 = 0.8 % of reading).
    pub gain_rel: f32,
    /// Offset uncertainty in the channel's units.
    pub offset: f32,
}

/// Everything the estimator needs to know. Build with `Config::default()` and
/// adjust; [`Config::validate`] rejects anything unusable with a typed error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Config {
    pub sample_rate_hz: f32,
    pub geometry: Geometry,
    /// Hammer axis below the horizontal, degrees (the stroke runs downhill when positive).
    pub inclination_deg: f32,
    pub rear: ChannelCal,
    pub front: ChannelCal,
    pub accel: ChannelCal,
    pub rear_spec: ChannelSpec,
    pub front_spec: ChannelSpec,
    pub accel_spec: ChannelSpec,
    /// An impact is an acceleration below −this (or the accelerometer at its bottom rail).
    pub impact_threshold_mps2: f32,
    /// Samples discarded before a detected impact (the shock's leading edge).
    pub blank_before_s: f32,
    /// Samples discarded after a detected impact: contact, ring-down and amplifier recovery.
    pub blank_after_s: f32,
    pub min_period_s: f32,
    pub max_period_s: f32,
    /// Discharge time constant of the piezo accelerometer: the zero shift an
    /// impact leaves decays with it. 0 disables the zero-shift fit.
    pub accel_zero_shift_tau_s: f32,
    /// Expansion factor of the stated uncertainties (2 ≈ 95 % coverage).
    pub coverage_factor: f32,
    /// Within-cycle residuals are correlated; the random part of the
    /// uncertainty is inflated by this factor.
    pub residual_correlation_factor: f32,
    /// A channel that keeps one code this long is stuck (0 disables).
    pub stuck_after_s: f32,
    /// Gauge supply pressure if known: the operating point of the drift baseline.
    /// Unknown (NaN) means the baseline is keyed by the peak rear pressure.
    pub supply_pressure_pa: f32,
    pub wear: WearConfig,
    /// The chambers and the pressure channels' delay, for the chamber
    /// characteristics (`chambers`); with `geometry` (areas, travel = the
    /// impact position) they make a [`crate::chambers::ChamberGeometry`].
    pub chambers: ChamberConfig,
}

/// What the chamber characteristics need beyond the piston's areas and
/// travel. f32: the board's FPU is single precision. The dead volumes are
/// the hammer's (fitted on the host from its commissioning record, never on
/// the board); positions are of the piston's rear face from the rear cover.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChamberConfig {
    /// Rear chamber volume at x = 0.
    pub rear_dead_m3: f32,
    /// Front chamber volume at the impact position.
    pub front_dead_m3: f32,
    /// The rear outlet is uncovered above this position.
    pub rear_outlet_m: f32,
    /// The front outlet is uncovered below this position.
    pub front_outlet_m: f32,
    /// How late the pressure channels read (their transducers' and
    /// anti-alias filters' group delay): the characteristics read the
    /// pressures this much earlier (`docs/estimator.md`).
    pub pressure_group_delay_s: f32,
}

impl Default for ChamberConfig {
    /// The paper's hammer (its dead volumes are estimates: `docs/model.md`)
    /// with the paper's transducers behind the default one-pole filter of
    /// 20 kHz at 100 kS/s (0.398 samples: `SensorChannel::group_delay_s`,
    /// (1 − α)/α·dt with α = 1 − exp(−2π·20 kHz·10 µs)).
    fn default() -> Self {
        Self {
            rear_dead_m3: 14.5e-6,
            front_dead_m3: 19.9e-6,
            rear_outlet_m: 0.030,
            front_outlet_m: 0.020,
            pressure_group_delay_s: 3.978_380_4e-6,
        }
    }
}

/// The wear indicator and the friction drift alarm.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WearConfig {
    /// Valid cycles that make a baseline at an operating point.
    pub baseline_cycles: u16,
    /// One-sided CUSUM allowance and decision threshold, in baseline standard deviations.
    pub cusum_k: f32,
    pub cusum_h: f32,
    /// Floor of the baseline's standard deviation, relative and absolute (N):
    /// the alarm is for wear, not for a friction change smaller than this.
    pub sigma_floor_rel: f32,
    pub sigma_floor_n: f32,
    /// Friction work the piston and cylinder may dissipate before service (J, Archard-style budget).
    pub budget_j: f32,
    /// Width of an operating-point bin of the baseline table, Pa.
    pub bin_width_pa: f32,
}

impl Default for WearConfig {
    fn default() -> Self {
        Self {
            baseline_cycles: 50,
            cusum_k: 0.5,
            cusum_h: 10.0,
            sigma_floor_rel: 0.01,
            sigma_floor_n: 0.1,
            budget_j: 5.0e7,
            bin_width_pa: 0.5e5,
        }
    }
}

impl Default for Config {
    fn default() -> Self {
        Self {
            sample_rate_hz: 100_000.0,
            geometry: Geometry::PAPER,
            inclination_deg: 0.0,
            // −1…+10 bar gauge: a vented chamber dips below atmosphere, and a
            // transducer that reads vacuum sees the dip instead of clipping it.
            rear: ChannelCal::from_range(-1e5, 10e5, 12),
            front: ChannelCal::from_range(-1e5, 10e5, 12),
            accel: ChannelCal::from_range(-2000.0, 2000.0, 12),
            // The paper's Kistler sensors: 0.8 % of reading; offsets after tare ~1 kPa.
            rear_spec: ChannelSpec {
                gain_rel: 0.008,
                offset: 1000.0,
            },
            front_spec: ChannelSpec {
                gain_rel: 0.008,
                offset: 1000.0,
            },
            // The paper's accelerometer: 0.5 %; offset after tare ~1 m/s².
            accel_spec: ChannelSpec {
                gain_rel: 0.005,
                offset: 1.0,
            },
            impact_threshold_mps2: 1500.0,
            blank_before_s: 50e-6,
            blank_after_s: 1.0e-3,
            min_period_s: 5e-3,
            max_period_s: 0.12,
            accel_zero_shift_tau_s: 0.02,
            coverage_factor: 2.0,
            residual_correlation_factor: 1.0,
            stuck_after_s: 5e-3,
            supply_pressure_pa: f32::NAN,
            wear: WearConfig::default(),
            chambers: ChamberConfig::default(),
        }
    }
}

/// What is wrong with a configuration; `field` names it, `min`/`max` the allowed range.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ConfigError {
    OutOfRange {
        field: &'static str,
        value: f32,
        min: f32,
        max: f32,
    },
    /// The longest cycle does not fit the estimator's bounded checkpoint memory.
    PeriodTooLongForMemory { max_period_s: f32, limit_s: f32 },
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            ConfigError::OutOfRange { field, value, min, max } => {
                write!(f, "{field} = {value} is out of range: allowed {min} ..= {max}")
            }
            ConfigError::PeriodTooLongForMemory { max_period_s, limit_s } => write!(
                f,
                "max_period_s = {max_period_s} exceeds what the checkpoint memory holds ({limit_s} s)"
            ),
        }
    }
}

/// Not inlined: validation runs only when a configuration changes, and inlined
/// into each of its ~40 calls it took 3.7 KB of the firmware's flash.
#[inline(never)]
fn check(field: &'static str, value: f32, min: f32, max: f32) -> Result<(), ConfigError> {
    if math::is_finite(value) && value >= min && value <= max {
        Ok(())
    } else {
        Err(ConfigError::OutOfRange { field, value, min, max })
    }
}

/// Every field's allowed range, in the order they are checked; `check_all`
/// walks a segment beside the values. A table rather than a call per field:
/// each call loaded its name and bounds in code, ~40 B of the board's flash
/// apiece. The two bounds that depend on another field are checked between
/// the segments.
type Limits = [(&'static str, f32, f32)];

const GEOMETRY: [(&str, f32, f32); 3] = [
    ("sample_rate_hz", 1_000.0, 1_000_000.0),
    ("geometry.piston_mass_kg", 0.01, 1000.0),
    ("geometry.bore_diameter_m", 0.001, 1.0),
];

const CHANNELS: [(&str, f32, f32); 17] = [
    ("inclination_deg", -90.0, 90.0),
    ("rear.zero_code", -1e6, 1e6),
    ("rear.scale", 1e-9, 1e9),
    ("front.zero_code", -1e6, 1e6),
    ("front.scale", 1e-9, 1e9),
    ("accel.zero_code", -1e6, 1e6),
    ("accel.scale", 1e-9, 1e9),
    ("rear_spec.gain_rel", 0.0, 0.5),
    ("rear_spec.offset", 0.0, 1e7),
    ("front_spec.gain_rel", 0.0, 0.5),
    ("front_spec.offset", 0.0, 1e7),
    ("accel_spec.gain_rel", 0.0, 0.5),
    ("accel_spec.offset", 0.0, 1e7),
    ("impact_threshold_mps2", 10.0, 1e7),
    ("blank_before_s", 0.0, 1e-3),
    ("blank_after_s", 0.0, 0.02),
    ("min_period_s", 1e-3, 1.0),
];

const REST: [(&str, f32, f32); 12] = [
    ("accel_zero_shift_tau_s", 0.0, 10.0),
    ("coverage_factor", 1.0, 5.0),
    ("residual_correlation_factor", 1.0, 100.0),
    ("stuck_after_s", 0.0, 10.0),
    ("supply_pressure_pa", 0.0, 1e8),
    ("wear.baseline_cycles", 5.0, 10_000.0),
    ("wear.cusum_k", 0.0, 10.0),
    ("wear.cusum_h", 0.5, 1000.0),
    ("wear.sigma_floor_rel", 0.0, 1.0),
    ("wear.sigma_floor_n", 1e-4, 1e4),
    ("wear.budget_j", 1.0, 1e15),
    ("wear.bin_width_pa", 1e3, 1e7),
];

const CHAMBERS: [(&str, f32, f32); 4] = [
    ("geometry.travel_m", 1e-3, 1.0),
    ("chambers.rear_dead_m3", 1e-9, 1e-2),
    ("chambers.front_dead_m3", 1e-9, 1e-2),
    ("chambers.pressure_group_delay_s", 0.0, 1e-3),
];

fn check_all(limits: &Limits, values: &[f32]) -> Result<(), ConfigError> {
    debug_assert_eq!(limits.len(), values.len(), "a value per limit");
    for (&(field, min, max), &v) in limits.iter().zip(values) {
        check(field, v, min, max)?;
    }
    Ok(())
}

/// A scale's magnitude, NaN for 0 (no scale at all is out of any range).
fn abs_nonzero(x: f32) -> f32 {
    if x == 0.0 {
        f32::NAN
    } else {
        math::abs(x)
    }
}

impl Config {
    pub fn validate(&self) -> Result<(), ConfigError> {
        let g = &self.geometry;
        let bore = math::narrow(g.bore_diameter_m);
        check_all(&GEOMETRY, &[self.sample_rate_hz, math::narrow(g.piston_mass_kg), bore])?;
        check(
            "geometry.rod_diameter_m",
            math::narrow(g.rod_diameter_m),
            0.0,
            bore * 0.99,
        )?;
        let (r, f, a) = (&self.rear, &self.front, &self.accel);
        let (rs, fs, as_) = (&self.rear_spec, &self.front_spec, &self.accel_spec);
        check_all(
            &CHANNELS,
            &[
                self.inclination_deg,
                r.zero_code,
                abs_nonzero(r.scale),
                f.zero_code,
                abs_nonzero(f.scale),
                a.zero_code,
                abs_nonzero(a.scale),
                rs.gain_rel,
                rs.offset,
                fs.gain_rel,
                fs.offset,
                as_.gain_rel,
                as_.offset,
                self.impact_threshold_mps2,
                self.blank_before_s,
                self.blank_after_s,
                self.min_period_s,
            ],
        )?;
        check("max_period_s", self.max_period_s, self.min_period_s, 10.0)?;
        let w = &self.wear;
        // An unknown supply (NaN) is allowed: 0 stands in for it.
        let supply = if self.supply_pressure_pa.is_nan() {
            0.0
        } else {
            self.supply_pressure_pa
        };
        check_all(
            &REST,
            &[
                self.accel_zero_shift_tau_s,
                self.coverage_factor,
                self.residual_correlation_factor,
                self.stuck_after_s,
                supply,
                w.baseline_cycles as f32,
                w.cusum_k,
                w.cusum_h,
                w.sigma_floor_rel,
                w.sigma_floor_n,
                w.budget_j,
                w.bin_width_pa,
            ],
        )?;
        let ch = &self.chambers;
        let travel = g.travel_m;
        check_all(
            &CHAMBERS,
            &[travel, ch.rear_dead_m3, ch.front_dead_m3, ch.pressure_group_delay_s],
        )?;
        check("chambers.rear_outlet_m", ch.rear_outlet_m, 1e-4, travel)?;
        check("chambers.front_outlet_m", ch.front_outlet_m, 1e-4, travel)?;
        let k = self.checkpoint_samples() as f32;
        let limit_s = crate::cycle::MAX_CHECKPOINTS as f32 * k / self.sample_rate_hz;
        if self.max_period_s > limit_s {
            return Err(ConfigError::PeriodTooLongForMemory {
                max_period_s: self.max_period_s,
                limit_s,
            });
        }
        Ok(())
    }

    /// Samples between two checkpoints: one per millisecond.
    pub fn checkpoint_samples(&self) -> u32 {
        let k = math::round(self.sample_rate_hz * 1e-3);
        if k < 1.0 {
            1
        } else {
            k as u32
        }
    }

    /// The sample rate in whole Hz: the reports' sample clock.
    pub fn sample_hz(&self) -> u64 {
        (math::round(self.sample_rate_hz) as u64).max(1)
    }

    pub fn dt_s(&self) -> f32 {
        1.0 / self.sample_rate_hz
    }

    pub fn mass_kg(&self) -> f32 {
        math::narrow(self.geometry.piston_mass_kg)
    }

    /// A1 in `f32` arithmetic (no software doubles on the target).
    pub fn rear_area_m2(&self) -> f32 {
        circle_area_f32(math::narrow(self.geometry.bore_diameter_m))
    }

    /// A2 = A1 − the rod's area, in `f32` arithmetic.
    pub fn front_area_m2(&self) -> f32 {
        self.rear_area_m2() - circle_area_f32(math::narrow(self.geometry.rod_diameter_m))
    }

    /// Gravity's force along the axis (forward positive).
    pub fn gravity_n(&self) -> f32 {
        self.mass_kg()
            * STANDARD_GRAVITY_MPS2 as f32
            * math::sin_small(self.inclination_deg * (core::f32::consts::PI / 180.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_is_valid_and_calibration_maps_the_range() {
        let c = Config::default();
        c.validate().unwrap();
        // The range starts below atmosphere so a vented chamber reads as a number, not a rail.
        assert!((c.rear.value(0) + 1e5).abs() < 1.0);
        assert!((c.rear.value(4095) - 10e5).abs() < 1.0);
        assert!((c.accel.value(0) + 2000.0).abs() < 1e-3);
        assert!((c.accel.value(4095) - 2000.0).abs() < 1e-2);
    }

    #[test]
    fn bad_fields_are_named() {
        let mut c = Config::default();
        c.sample_rate_hz = 0.0;
        assert!(matches!(
            c.validate(),
            Err(ConfigError::OutOfRange {
                field: "sample_rate_hz",
                ..
            })
        ));
        let mut c = Config::default();
        c.accel.scale = 0.0;
        assert!(matches!(
            c.validate(),
            Err(ConfigError::OutOfRange {
                field: "accel.scale",
                ..
            })
        ));
        let mut c = Config::default();
        c.max_period_s = 5.0;
        assert!(matches!(c.validate(), Err(ConfigError::PeriodTooLongForMemory { .. })));
        let mut c = Config::default();
        c.blank_after_s = f32::NAN;
        assert!(matches!(
            c.validate(),
            Err(ConfigError::OutOfRange {
                field: "blank_after_s",
                ..
            })
        ));
    }
}
