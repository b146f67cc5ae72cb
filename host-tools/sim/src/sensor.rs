//! What the bench board's ADC sees: sensor gain and offset, bandwidth, noise,
//! clipping and quantisation, plus the sensor-side effects of the catalogue
//! (`accel_zero_shift`, `pressure_gain_error`).

use serde::{Deserialize, Serialize};

use hammer_estimator::{ChannelCal, RawSample};

use super::effects::Effects;
use super::run::{EventRecord, TruthSample, TruthTrace};
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

/// Measured channels on the output grid: the ADC codes, and the physical
/// values they stand for (what a trace file holds).
#[derive(Debug, Clone, Default)]
pub struct Measured {
    pub p_rear_pa: Vec<f64>,
    pub p_front_pa: Vec<f64>,
    pub accel_mps2: Vec<f64>,
    /// What the board's ADC delivers, read by the channels' [`SensorChannel::calibration`].
    pub codes: Vec<RawSample>,
    /// Samples at either end of the ADC range, per channel (rear, front, accel).
    pub clipped: [usize; 3],
}

pub use crate::rng::Rng;

/// Offset left on the accelerometer by an impact: random sign, magnitude
/// between 0.5 and 1.5 times the configured amplitude.
pub fn zero_shift_offset(amplitude: f64, rng: &mut Rng) -> f64 {
    let sign = if rng.next_u64() & 1 == 0 { 1.0 } else { -1.0 };
    sign * amplitude * (0.5 + rng.uniform())
}

/// One channel's state from sample to sample: its own noise stream, so a
/// channel's noise does not depend on how long the others ran (a streamed
/// run draws sample by sample, channel after channel), and its constants,
/// taken out of the per-sample work.
struct ChannelState {
    alpha: f64,
    /// Filter output; `None` until the first sample starts it at rest.
    state: Option<f64>,
    rng: Rng,
    clipped: usize,
    offset: f64,
    noise_std: f64,
    range_min: f64,
    lsb: f64,
    per_lsb: f64,
    full_scale_code: u32,
}

impl ChannelState {
    fn new(ch: &SensorChannel, dt_s: f64, seed: u64) -> Self {
        let alpha = if ch.bandwidth_hz > 0.0 {
            1.0 - (-2.0 * std::f64::consts::PI * ch.bandwidth_hz * dt_s).exp()
        } else {
            1.0
        };
        Self {
            alpha,
            state: None,
            rng: Rng::new(seed),
            clipped: 0,
            offset: ch.offset,
            noise_std: ch.noise_std,
            range_min: ch.range_min,
            lsb: ch.lsb(),
            per_lsb: 1.0 / ch.lsb(),
            full_scale_code: ch.full_scale_code(),
        }
    }

    /// Filter, noise, clipping and quantisation in one pass: the ADC's code
    /// and the value it stands for. The code rounds half up, as
    /// [`SensorChannel::code`] does for the converter's range.
    #[inline]
    fn measure(&mut self, x: f64) -> (f64, u16) {
        let x = x + self.offset;
        let state = self.state.get_or_insert(x);
        *state += self.alpha * (x - *state);
        let c = (*state + self.noise_std * self.rng.normal() - self.range_min) * self.per_lsb;
        // NaN compares false both ways: code 0, as `SensorChannel::code` gives.
        let code = if c >= self.full_scale_code as f64 {
            self.full_scale_code
        } else if c > 0.0 {
            (c + 0.5) as u32
        } else {
            0
        };
        if code == 0 || code == self.full_scale_code {
            self.clipped += 1;
        }
        // adc_bits ≤ 16 (validated), so the code fits.
        (self.range_min + code as f64 * self.lsb, code as u16)
    }
}

/// An accelerometer offset left by an impact, applied on `first..end` samples.
struct ZeroShift {
    t_impact_s: f64,
    offset_mps2: f64,
    first: usize,
    end: usize,
}

/// The sensor chain applied sample by sample, so it can follow a run as it
/// is produced; [`measure`] runs it over a whole trace.
pub struct SensorChain {
    model: SensorModel,
    dt_s: f64,
    gain_rear: f64,
    gain_front: f64,
    zero_shift: Option<(f64, f64)>,
    zero_shift_rng: Rng,
    shifts: Vec<ZeroShift>,
    channels: [ChannelState; 3],
    cals: [ChannelCal; 3],
}

/// One sample through the chain: the physical values and the ADC codes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChainSample {
    pub values: [f64; 3],
    pub codes: RawSample,
}

impl SensorChain {
    pub fn new(model: &SensorModel, effects: &Effects, dt_s: f64, seed: u64) -> Self {
        let (gain_rear, gain_front) = effects
            .pressure_gain_error
            .as_ref()
            .map_or((0.0, 0.0), |g| (g.rear, g.front));
        let base = seed ^ 0x5EED_5E45_0000_0001;
        Self {
            model: model.clone(),
            dt_s,
            gain_rear,
            gain_front,
            zero_shift: effects.accel_zero_shift.as_ref().map(|z| (z.amplitude_mps2, z.tau_s)),
            zero_shift_rng: Rng::new(base),
            shifts: Vec::new(),
            channels: [
                ChannelState::new(&model.rear, dt_s, base ^ 0x0000_0000_0000_0100),
                ChannelState::new(&model.front, dt_s, base ^ 0x0000_0000_0000_0200),
                ChannelState::new(&model.accel, dt_s, base ^ 0x0000_0000_0000_0300),
            ],
            cals: [&model.rear, &model.front, &model.accel].map(SensorChannel::calibration),
        }
    }

    /// An impact at `t_impact_s`: with `accel_zero_shift` on, the accelerometer
    /// carries a decaying offset from the first sample at or after it for ~10 τ.
    pub fn impact(&mut self, t_impact_s: f64) {
        if let Some((amplitude, tau_s)) = self.zero_shift {
            let first = (t_impact_s / self.dt_s).ceil() as usize;
            self.shifts.push(ZeroShift {
                t_impact_s,
                offset_mps2: zero_shift_offset(amplitude, &mut self.zero_shift_rng),
                first,
                end: first + (10.0 * tau_s / self.dt_s) as usize,
            });
        }
    }

    /// The measured rear, front and accel values of one truth sample, and
    /// their codes. With the chain off (ideal signals) the codes are those
    /// an ideal converter of the same range gives.
    pub fn measure(&mut self, s: &TruthSample) -> ChainSample {
        let mut accel = s.accel_mps2;
        if let Some((_, tau_s)) = self.zero_shift {
            self.shifts.retain(|z| z.end > s.index);
            // Impacts come in time order, so the offsets started so far lead the list.
            for z in self.shifts.iter().take_while(|z| z.first <= s.index) {
                accel += z.offset_mps2 * (-(s.t_s - z.t_impact_s) / tau_s).exp();
            }
        }
        let inputs = [
            s.p_rear_pa * (1.0 + self.gain_rear),
            s.p_front_pa * (1.0 + self.gain_front),
            accel,
        ];
        if !self.model.enabled {
            let [r, f, a] = &self.cals;
            return ChainSample {
                values: inputs,
                codes: RawSample {
                    rear: r.code(inputs[0]),
                    front: f.code(inputs[1]),
                    accel: a.code(inputs[2]),
                },
            };
        }
        // The converter's own codes: the board's calibration reads each
        // back as itself (`calibration_reads_every_code_as_itself`).
        let [rear, front, acc] = &mut self.channels;
        let (r, rear_code) = rear.measure(inputs[0]);
        let (f, front_code) = front.measure(inputs[1]);
        let (a, accel_code) = acc.measure(inputs[2]);
        ChainSample {
            values: [r, f, a],
            codes: RawSample {
                rear: rear_code,
                front: front_code,
                accel: accel_code,
            },
        }
    }

    /// Samples at either end of the ADC range so far: rear, front, accel.
    pub fn clipped(&self) -> [usize; 3] {
        self.channels.each_ref().map(|c| c.clipped)
    }
}

impl Measured {
    /// Empty, with room for `n` samples: a run's vectors then never move.
    pub fn with_capacity(n: usize) -> Self {
        Self {
            p_rear_pa: Vec::with_capacity(n),
            p_front_pa: Vec::with_capacity(n),
            accel_mps2: Vec::with_capacity(n),
            codes: Vec::with_capacity(n),
            clipped: [0; 3],
        }
    }

    pub fn push(&mut self, m: ChainSample) {
        self.p_rear_pa.push(m.values[0]);
        self.p_front_pa.push(m.values[1]);
        self.accel_mps2.push(m.values[2]);
        self.codes.push(m.codes);
    }
}

/// Applies the sensor chain to a whole truth trace.
pub fn measure(
    model: &SensorModel,
    effects: &Effects,
    truth: &TruthTrace,
    impacts: &[EventRecord],
    seed: u64,
) -> Measured {
    let mut chain = SensorChain::new(model, effects, truth.dt_s, seed);
    // Offsets only reach samples at or after their impact, so telling the
    // chain of every impact first is what a streamed run does too.
    for e in impacts {
        chain.impact(e.t_s);
    }
    let mut m = Measured::with_capacity(truth.len());
    for i in 0..truth.len() {
        m.push(chain.measure(&truth.sample(i)));
    }
    m.clipped = chain.clipped();
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_clip() {
        let ch = SensorModel::default().rear;
        // The default range starts at −1 bar gauge.
        assert_eq!(ch.code(-2e5), 0);
        assert_eq!(ch.code(0.0), 372);
        assert_eq!(ch.code(2e6), 4095);
        assert_eq!(ch.code(f64::NAN), 0);
        let v = ch.value(ch.code(3.21e5));
        assert!((v - 3.21e5).abs() <= ch.lsb() / 2.0 + 1e-9);
    }

    /// The simulator writes no trace the estimator would refuse: the same
    /// resolutions pass both, and a refusal names the key of the config file.
    #[test]
    fn adc_resolution_is_refused_where_the_estimator_refuses_it() {
        for bits in [4, 7, 8, 12, 16, 17, 24, 32] {
            for ch in ["rear", "front", "accel"] {
                let mut m = SensorModel::default();
                match ch {
                    "rear" => m.rear.adc_bits = bits,
                    "front" => m.front.adc_bits = bits,
                    _ => m.accel.adc_bits = bits,
                }
                let sim = m.validate();
                let est = crate::estimation::estimator_config(
                    &crate::params::HammerParams::default(),
                    &m,
                    &Default::default(),
                    1e5,
                    None,
                );
                assert_eq!(sim.is_ok(), est.is_ok(), "{ch} {bits} bits: {sim:?} vs {est:?}");
                assert_eq!(sim.is_ok(), (8..=16).contains(&bits), "{ch} {bits}");
                if let Err(e) = sim {
                    let msg = e.to_string();
                    assert!(
                        msg.contains(&format!("sensors.{ch}.adc_bits = {bits}")) && msg.contains("8 ..= 16"),
                        "{msg}"
                    );
                }
            }
        }
    }

    /// The chain hands the estimator the converter's codes directly; the
    /// board reads them through the channel's calibration (`f32`), which
    /// must give every code back, at every resolution and for ranges that
    /// do not start at zero.
    #[test]
    fn calibration_reads_every_code_as_itself() {
        for bits in 8..=16 {
            for (min, max) in [(-1e5, 10e5), (-2000.0, 2000.0), (0.0, 1e6), (-12_345.678, 987_654.321)] {
                let ch = SensorChannel {
                    range_min: min,
                    range_max: max,
                    adc_bits: bits,
                    ..SensorModel::default().rear
                };
                let cal = ch.calibration();
                for code in 0..=ch.full_scale_code() {
                    assert_eq!(u32::from(cal.code(ch.value(code))), code, "{bits} bits, {min}..{max}");
                }
            }
        }
    }

    /// One pass of the chain quantises as the converter's `code` does (half
    /// up, clipped at both ends, NaN to 0).
    #[test]
    fn the_chain_quantises_as_the_converter_does() {
        let ch = SensorChannel {
            noise_std: 0.0,
            bandwidth_hz: 0.0,
            ..SensorModel::default().rear
        };
        let lsb = ch.lsb();
        for x in [
            -2e5,
            -1e5,
            -1e5 + 0.49 * lsb,
            0.0,
            3.21e5,
            3.21e5 + 0.51 * lsb,
            1e6 - 0.2 * lsb,
            2e6,
            f64::NAN,
        ] {
            let mut st = ChannelState::new(&ch, 1e-5, 1);
            let (value, code) = st.measure(x);
            assert_eq!(u32::from(code), ch.code(x), "{x}");
            assert_eq!(value, ch.value(ch.code(x)), "{x}");
        }
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
