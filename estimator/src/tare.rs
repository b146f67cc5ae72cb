//! Tare: zero offsets from samples taken with the hammer at rest and unpressurised.

use crate::config::Config;
use crate::geometry::STANDARD_GRAVITY_MPS2;
use crate::{math, RawSample};

/// Samples needed for a tare (10 ms at 100 kS/s).
pub const MIN_TARE_SAMPLES: u32 = 1000;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Tare {
    n: u32,
    /// The first sample's codes: the sums are of deviations from them. At
    /// rest those are a few codes, so `f32` turns the sums into a mean and
    /// a variance without loss, where the sums of raw codes squared (10¹²
    /// after 10⁵ samples) would need `f64`, which the target's FPU lacks.
    origin: [u16; 3],
    sum: [i64; 3],
    sum_sq: [u64; 3],
    rail: [u32; 3],
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TareError {
    TooFewSamples {
        have: u32,
        need: u32,
    },
    /// The channel moves: the hammer is not at rest (or the sensor is noisy), std in channel units.
    NotAtRest {
        channel: &'static str,
        std: f32,
        limit: f32,
    },
}

impl core::fmt::Display for TareError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::TooFewSamples { have, need } => write!(f, "tare: {have} samples, need {need}"),
            Self::NotAtRest { channel, std, limit } => {
                write!(f, "tare: {channel} varies by {std} (limit {limit}): hammer not at rest")
            }
        }
    }
}

/// Which channels were zeroed; a channel resting on its bottom rail (a
/// pressure range that starts at 0 gauge) cannot be and keeps its zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TareResult {
    pub config: Config,
    pub zeroed: [bool; 3],
}

const NAMES: [&str; 3] = ["rear", "front", "accel"];

impl Tare {
    /// Adds a sample; beyond 10⁶ samples the tare has enough and ignores more
    /// (which also keeps the integer sums far from overflow).
    pub fn push(&mut self, s: RawSample) {
        if self.n >= 1_000_000 {
            return;
        }
        let codes = [s.rear, s.front, s.accel];
        if self.n == 0 {
            self.origin = codes;
        }
        self.n += 1;
        for ch in 0..3 {
            let d = i64::from(codes[ch]) - i64::from(self.origin[ch]);
            self.sum[ch] += d;
            self.sum_sq[ch] += d.unsigned_abs() * d.unsigned_abs();
            if codes[ch] == 0 {
                self.rail[ch] += 1;
            }
        }
    }

    /// Samples taken, and each channel's mean and standard deviation in
    /// codes: what a calibration's span point needs from the board.
    pub fn code_stats(&self) -> (u32, [f32; 3], [f32; 3]) {
        let mut mean = [0.0f32; 3];
        let mut std = [0.0f32; 3];
        if self.n > 0 {
            for ch in 0..3 {
                let (m, var) = self.moments(ch);
                mean[ch] = m;
                std[ch] = math::sqrt(var);
            }
        }
        (self.n, mean, std)
    }

    /// A channel's mean and variance in codes (`n` > 0).
    fn moments(&self, ch: usize) -> (f32, f32) {
        let n = self.n as f32;
        let d = self.sum[ch] as f32 / n;
        let var = (self.sum_sq[ch] as f32 / n - d * d).max(0.0);
        (f32::from(self.origin[ch]) + d, var)
    }

    /// New zero codes for `cfg`: pressures read 0 gauge, the accelerometer reads
    /// the gravity component along the axis.
    pub fn finish(&self, cfg: &Config) -> Result<TareResult, TareError> {
        if self.n < MIN_TARE_SAMPLES {
            return Err(TareError::TooFewSamples {
                have: self.n,
                need: MIN_TARE_SAMPLES,
            });
        }
        let cals = [cfg.rear, cfg.front, cfg.accel];
        // At rest a channel varies by its noise only: a few kPa, a few m/s².
        let limits = [5_000.0f32, 5_000.0, 10.0];
        let mut out = *cfg;
        let mut zeroed = [false; 3];
        let g_axis =
            (STANDARD_GRAVITY_MPS2 as f32) * math::sin_small(cfg.inclination_deg * (core::f32::consts::PI / 180.0));
        for ch in 0..3 {
            let (mean, var) = self.moments(ch);
            let std = math::sqrt(var) * math::abs(cals[ch].scale);
            if std > limits[ch] {
                return Err(TareError::NotAtRest {
                    channel: NAMES[ch],
                    std,
                    limit: limits[ch],
                });
            }
            // More than 5 % of the samples on the bottom rail.
            if u64::from(self.rail[ch]) * 20 > u64::from(self.n) {
                continue;
            }
            let expected = if ch == 2 { g_axis } else { 0.0 };
            let zero = mean - expected / cals[ch].scale;
            match ch {
                0 => out.rear.zero_code = zero,
                1 => out.front.zero_code = zero,
                _ => out.accel.zero_code = zero,
            }
            zeroed[ch] = true;
        }
        Ok(TareResult { config: out, zeroed })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tare_zeroes_offsets_and_refuses_a_moving_hammer() {
        let cfg = Config::default();
        let mut t = Tare::default();
        for i in 0..2000u32 {
            // Accelerometer reads +3 m/s² of offset (~3 codes), pressures 10 codes above zero.
            t.push(RawSample {
                rear: 10 + (i % 2) as u16,
                front: 10,
                accel: 2051 + (i % 3) as u16,
            });
        }
        let r = t.finish(&cfg).unwrap();
        assert_eq!(r.zeroed, [true, true, true]);
        assert!(r.config.rear.value(10).abs() < 200.0);
        assert!(r.config.accel.value(2052).abs() < 1.0);
        let mut moving = Tare::default();
        for i in 0..2000u32 {
            moving.push(RawSample {
                rear: 500 + (i % 400) as u16,
                front: 10,
                accel: 2048,
            });
        }
        assert!(matches!(
            moving.finish(&cfg),
            Err(TareError::NotAtRest { channel: "rear", .. })
        ));
        let mut railed = Tare::default();
        for _ in 0..2000 {
            railed.push(RawSample {
                rear: 0,
                front: 0,
                accel: 2048,
            });
        }
        assert_eq!(railed.finish(&cfg).unwrap().zeroed, [false, false, true]);
        assert!(matches!(
            Tare::default().finish(&cfg),
            Err(TareError::TooFewSamples { .. })
        ));
    }
}
