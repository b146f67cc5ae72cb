//! What the bench board's ADC sees: sensor gain and offset, bandwidth, noise,
//! clipping and quantisation, plus the sensor-side effects of the catalogue
//! (`accel_zero_shift`, `pressure_gain_error`).

use hammer_estimator::{ChannelCal, RawSample};

use super::effects::Effects;
use super::run::{EventRecord, TruthSample, TruthTrace};
pub use crate::sensor_model::*;

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
        Self {
            alpha: ch.filter_alpha(dt_s),
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
