//! Sensor front ends of this family: what lies between the physical signal
//! and the number in the trace. Processed at the integration step, sampled
//! at the output rate, as an analog chain in front of an ADC is.

use serde::{Deserialize, Serialize};

use crate::structure::FrontEnd;

/// Ranges and noise of the three channels for one front end.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Channels {
    /// Gauge pressure range of both pressure channels, Pa.
    pub pressure_range_pa: (f64, f64),
    pub accel_range_mps2: (f64, f64),
    pub pressure_noise_pa: f64,
    pub accel_noise_mps2: f64,
    pub bandwidth_hz: f64,
    /// Accelerometer mount resonance (`None`: a rigid mount).
    pub resonance_hz: Option<f64>,
    pub resonance_damping: f64,
    pub adc_bits: u32,
}

impl Channels {
    pub fn of(front_end: FrontEnd) -> Self {
        let first = Self {
            pressure_range_pa: (0.0, 10e5),
            accel_range_mps2: (-2000.0, 2000.0),
            pressure_noise_pa: 400.0,
            accel_noise_mps2: 1.2,
            bandwidth_hz: 25e3,
            resonance_hz: None,
            resonance_damping: 0.0,
            adc_bits: 12,
        };
        match front_end {
            FrontEnd::FirstOrder => first,
            FrontEnd::ResonantClipping => Self {
                // A 0–7.5 bar transducer: clips a vented chamber below
                // atmosphere and the peaks at high supply.
                pressure_range_pa: (0.0, 7.5e5),
                resonance_hz: Some(18e3),
                resonance_damping: 0.06,
                ..first
            },
        }
    }
}

/// splitmix64 and Box–Muller: this family's own noise.
#[derive(Debug, Clone)]
pub struct Noise(u64);

impl Noise {
    pub fn new(seed: u64) -> Self {
        Self(seed ^ 0x005E_ED0F_7A21_A7B5)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    pub fn gauss(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// One channel's analog state.
#[derive(Debug, Clone, Copy, Default)]
struct Analog {
    lowpass: f64,
    res_y: f64,
    res_v: f64,
}

pub struct FrontEndState {
    pub ch: Channels,
    rear: Analog,
    front: Analog,
    accel: Analog,
    noise: Noise,
    started: bool,
    /// The low-pass filters' gain with the step and bandwidth it was worked
    /// out for (an exponential per 1 µs step otherwise; the same
    /// expression, so the same bits).
    alpha: Option<(f64, f64, f64)>,
}

impl FrontEndState {
    pub fn new(front_end: FrontEnd, seed: u64) -> Self {
        Self {
            ch: Channels::of(front_end),
            rear: Analog::default(),
            front: Analog::default(),
            accel: Analog::default(),
            noise: Noise::new(seed),
            started: false,
            alpha: None,
        }
    }

    /// Advances the analog chain by `h` with the physical inputs (gauge Pa, m/s²).
    pub fn step(&mut self, h: f64, rear_pa: f64, front_pa: f64, accel_mps2: f64) {
        if !self.started {
            self.rear.lowpass = rear_pa;
            self.front.lowpass = front_pa;
            self.accel.lowpass = accel_mps2;
            self.accel.res_y = accel_mps2;
            self.started = true;
        }
        let bw = self.ch.bandwidth_hz;
        let alpha = match self.alpha {
            Some((step, band, alpha)) if step.to_bits() == h.to_bits() && band.to_bits() == bw.to_bits() => alpha,
            _ => {
                let alpha = 1.0 - (-2.0 * std::f64::consts::PI * bw * h).exp();
                self.alpha = Some((h, bw, alpha));
                alpha
            }
        };
        let mut a = accel_mps2;
        if let Some(f) = self.ch.resonance_hz {
            // A base-excited mount: second order, semi-implicit Euler (ω·h ≈ 0.1).
            let w = 2.0 * std::f64::consts::PI * f;
            let s = &mut self.accel;
            s.res_v += h * (w * w * (accel_mps2 - s.res_y) - 2.0 * self.ch.resonance_damping * w * s.res_v);
            s.res_y += h * s.res_v;
            a = s.res_y;
        }
        self.rear.lowpass += alpha * (rear_pa - self.rear.lowpass);
        self.front.lowpass += alpha * (front_pa - self.front.lowpass);
        self.accel.lowpass += alpha * (a - self.accel.lowpass);
    }

    /// What the ADC reads now: noise, range and quantisation; `gains` are the
    /// pressure channels' relative gain errors, `accel_offset` a zero shift.
    pub fn sample(&mut self, gains: (f64, f64), accel_offset_mps2: f64) -> (f64, f64, f64) {
        let ch = self.ch;
        let adc = |v: f64, (lo, hi): (f64, f64)| {
            let lsb = (hi - lo) / ((1u64 << ch.adc_bits) - 1) as f64;
            let code = ((v - lo) / lsb).round().clamp(0.0, ((1u64 << ch.adc_bits) - 1) as f64);
            lo + code * lsb
        };
        let r = (1.0 + gains.0) * self.rear.lowpass + ch.pressure_noise_pa * self.noise.gauss();
        let f = (1.0 + gains.1) * self.front.lowpass + ch.pressure_noise_pa * self.noise.gauss();
        let a = self.accel.lowpass + accel_offset_mps2 + ch.accel_noise_mps2 * self.noise.gauss();
        (
            adc(r, ch.pressure_range_pa),
            adc(f, ch.pressure_range_pa),
            adc(a, ch.accel_range_mps2),
        )
    }
}
