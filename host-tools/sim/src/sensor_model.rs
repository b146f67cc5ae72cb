//! What a configuration says of the sensor chain: each channel's range,
//! resolution, noise, offset and bandwidth, read from `[sensors.*]` tables
//! over each channel's own defaults. Apart from the chain that applies them
//! ([`crate::sensor`]) because the configuration ([`crate::params`]) holds
//! them and the chain reads the simulation's output: the configuration sits
//! below the run, the chain above it.

use serde::{Deserialize, Serialize};

use hammer_estimator::ChannelCal;

use crate::config::{check_range, ConfigError};

/// One measurement channel from transducer to ADC code. In a config file a
/// `[sensors.NAME]` table gives any subset of the keys; the rest are that
/// channel's defaults (a pressure channel's are not the accelerometer's).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorChannel {
    /// Physical value at ADC code 0.
    pub range_min: f64,
    /// Physical value at the top ADC code.
    pub range_max: f64,
    pub adc_bits: u32,
    /// Standard deviation of white noise before the ADC, in channel units.
    pub noise_std: f64,
    pub offset: f64,
    /// First-order bandwidth of transducer plus anti-alias filter, Hz; 0 = none.
    pub bandwidth_hz: f64,
}

impl SensorChannel {
    /// The channel's delay at low frequencies when sampled every `dt_s`:
    /// the group delay of its one-pole filter as [`crate::sensor`] runs it,
    /// (1 − α)/α samples with α = 1 − exp(−2π·f·dt) (4 µs for 20 kHz at
    /// 10 µs; none without a filter).
    pub fn group_delay_s(&self, dt_s: f64) -> f64 {
        let alpha = self.filter_alpha(dt_s);
        if alpha < 1.0 && alpha > 0.0 {
            (1.0 - alpha) / alpha * dt_s
        } else {
            0.0
        }
    }

    /// The one-pole filter's step weight at a sample every `dt_s`:
    /// y += α·(x − y), α = 1 − exp(−2π·f·dt); 1 (no filter) without a
    /// bandwidth.
    pub fn filter_alpha(&self, dt_s: f64) -> f64 {
        if self.bandwidth_hz > 0.0 {
            1.0 - (-2.0 * std::f64::consts::PI * self.bandwidth_hz * dt_s).exp()
        } else {
            1.0
        }
    }

    pub fn lsb(&self) -> f64 {
        (self.range_max - self.range_min) / self.full_scale_code() as f64
    }

    pub fn full_scale_code(&self) -> u32 {
        (1u32 << self.adc_bits) - 1
    }

    /// ADC code of a physical value, clipped to the converter's range.
    pub fn code(&self, value: f64) -> u32 {
        let c = ((value - self.range_min) / self.lsb()).round();
        if c.is_nan() {
            0
        } else {
            c.clamp(0.0, self.full_scale_code() as f64) as u32
        }
    }

    pub fn value(&self, code: u32) -> f64 {
        self.range_min + code as f64 * self.lsb()
    }

    /// The calibration that reads this channel's codes on the board.
    pub fn calibration(&self) -> ChannelCal {
        // Validated to at most ADC_BITS_MAX, so the cast keeps every value.
        ChannelCal::from_range(self.range_min as f32, self.range_max as f32, self.adc_bits as u8)
    }

    /// `name` is the channel's key under `[sensors]`.
    fn validate(&self, name: &str) -> Result<(), ConfigError> {
        let f = |k: &str| format!("sensors.{name}.{k}");
        check_range(&f("range_min"), self.range_min, -1e9, 1e9)?;
        check_range(&f("range_max"), self.range_max, self.range_min + 1e-9, 1e9)?;
        check_range(
            &f("adc_bits"),
            self.adc_bits as f64,
            hammer_estimator::ADC_BITS_MIN as f64,
            hammer_estimator::ADC_BITS_MAX as f64,
        )?;
        check_range(&f("noise_std"), self.noise_std, 0.0, 1e9)?;
        check_range(&f("offset"), self.offset, -1e9, 1e9)?;
        check_range(&f("bandwidth_hz"), self.bandwidth_hz, 0.0, 1e7)?;
        Ok(())
    }
}

/// The three channels of the bench board (defaults: 12-bit ADC; pressure
/// −1…10 bar gauge; ±2000 m/s² so flight accelerations, under 1000 m/s² at
/// 7 bar, are resolved and impacts clip). Read from a config through
/// [`SensorTables`]: each table over its own channel's defaults.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "SensorTables")]
pub struct SensorModel {
    pub rear: SensorChannel,
    pub front: SensorChannel,
    pub accel: SensorChannel,
    /// False gives the ideal (noiseless, unquantised) signals.
    pub enabled: bool,
}

impl Default for SensorModel {
    fn default() -> Self {
        // −1…+10 bar gauge: the vented chambers dip below atmosphere (to
        // about −9 kPa at 4 bar), which a 0-based range would clip.
        let pressure = SensorChannel {
            range_min: -1e5,
            range_max: 10e5,
            adc_bits: 12,
            noise_std: 500.0,
            offset: 0.0,
            bandwidth_hz: 20e3,
        };
        Self {
            rear: pressure.clone(),
            front: pressure,
            accel: SensorChannel {
                range_min: -2000.0,
                range_max: 2000.0,
                adc_bits: 12,
                noise_std: 1.0,
                offset: 0.0,
                bandwidth_hz: 20e3,
            },
            enabled: true,
        }
    }
}

/// `[sensors]` as a user writes it: any channel, any subset of its keys.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorTables {
    #[serde(default)]
    rear: ChannelKeys,
    #[serde(default)]
    front: ChannelKeys,
    #[serde(default)]
    accel: ChannelKeys,
    enabled: Option<bool>,
}

/// The keys of one `[sensors.NAME]` table, each optional.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct ChannelKeys {
    range_min: Option<f64>,
    range_max: Option<f64>,
    adc_bits: Option<u32>,
    noise_std: Option<f64>,
    offset: Option<f64>,
    bandwidth_hz: Option<f64>,
}

impl ChannelKeys {
    fn over(self, mut c: SensorChannel) -> SensorChannel {
        c.range_min = self.range_min.unwrap_or(c.range_min);
        c.range_max = self.range_max.unwrap_or(c.range_max);
        c.adc_bits = self.adc_bits.unwrap_or(c.adc_bits);
        c.noise_std = self.noise_std.unwrap_or(c.noise_std);
        c.offset = self.offset.unwrap_or(c.offset);
        c.bandwidth_hz = self.bandwidth_hz.unwrap_or(c.bandwidth_hz);
        c
    }
}

impl From<SensorTables> for SensorModel {
    fn from(t: SensorTables) -> Self {
        let d = SensorModel::default();
        Self {
            rear: t.rear.over(d.rear),
            front: t.front.over(d.front),
            accel: t.accel.over(d.accel),
            enabled: t.enabled.unwrap_or(d.enabled),
        }
    }
}

impl SensorModel {
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.rear.validate("rear")?;
        self.front.validate("front")?;
        self.accel.validate("accel")
    }
}

#[cfg(test)]
mod table_tests {
    use super::*;
    use crate::SimConfig;

    /// The paper's transducers start at 0 gauge: saying so is one key per
    /// channel, the rest from that channel's defaults; an unknown key is
    /// still refused, naming it.
    #[test]
    fn a_sensor_table_takes_any_subset_of_its_keys() {
        let c: SimConfig = toml::from_str("[sensors.rear]\nrange_min = 0\n[sensors.front]\nrange_min = 0\n").unwrap();
        let d = SensorModel::default();
        assert_eq!(c.sensors.rear.range_min, 0.0);
        assert_eq!(c.sensors.front.range_min, 0.0);
        assert_eq!(c.sensors.rear.range_max, d.rear.range_max);
        assert_eq!(c.sensors.rear.adc_bits, d.rear.adc_bits);
        assert_eq!(c.sensors.accel, d.accel, "the accelerometer keeps its own defaults");
        c.validate().unwrap();
        c.estimator_config(Some(4.0)).unwrap();
        let c: SimConfig = toml::from_str("[sensors.accel]\nrange_max = 5000\n").unwrap();
        assert_eq!(
            (c.sensors.accel.range_min, c.sensors.accel.range_max),
            (-2000.0, 5000.0)
        );
        assert_eq!(c.sensors.rear, d.rear);
        let e = toml::from_str::<SimConfig>("[sensors.rear]\nrange_mni = 0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("range_mni"), "{e}");
        // A whole table (as a simulator's sidecar holds it) reads back the same.
        let whole = toml::to_string(&SimConfig::default()).unwrap();
        assert_eq!(toml::from_str::<SimConfig>(&whole).unwrap().sensors, d);
    }
}
