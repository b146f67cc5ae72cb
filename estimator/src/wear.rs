//! Wear indicator: cumulative friction work (an Archard-style wear index),
//! a friction drift alarm against a baseline learned at the same operating
//! point, and a remaining-life estimate. The state survives a reset through
//! [`WearState::to_bytes`] / [`WearState::from_bytes`].

use crate::config::WearConfig;
use crate::math;

/// The state's size and its CRC, defined with the wire's `WearBlob` in `hammer-types`.
pub use hammer_types::{crc32, MAX_BASELINES, WEAR_STATE_BYTES};
const MAGIC: [u8; 4] = *b"HMWS";
const VERSION: u32 = 1;

/// Friction statistics at one operating point (Welford).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Baseline {
    pub bin: i32,
    pub n: u32,
    pub mean_n: f32,
    pub m2: f32,
}

impl Baseline {
    pub fn std_n(&self) -> f32 {
        if self.n > 1 {
            math::sqrt(self.m2 / (self.n - 1) as f32)
        } else {
            0.0
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WearState {
    /// Cumulative friction work, J. f64: 10⁹ cycles of a few joules must not round away.
    pub friction_work_j: f64,
    pub cycles: u32,
    pub cusum: f32,
    pub alarm: bool,
    pub baselines: [Baseline; MAX_BASELINES],
    pub n_baselines: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WearStateError {
    TooShort,
    BadMagic,
    UnsupportedVersion(u32),
    BadChecksum,
}

impl core::fmt::Display for WearStateError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::TooShort => write!(f, "wear state: too short"),
            Self::BadMagic => write!(f, "wear state: not a wear state"),
            Self::UnsupportedVersion(v) => write!(f, "wear state: version {v} unsupported"),
            Self::BadChecksum => write!(f, "wear state: checksum mismatch"),
        }
    }
}

/// What one cycle did to the wear state.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct WearUpdate {
    pub wear_index_j: f32,
    pub remaining_fraction: f32,
    pub remaining_cycles: f32,
    pub drift_score: f32,
    pub alarm: bool,
}

impl WearState {
    /// Books one valid cycle: its friction, its friction work and its operating point.
    pub fn update(
        &mut self,
        cfg: &WearConfig,
        friction_n: f32,
        friction_work_j: f32,
        operating_point_pa: f32,
    ) -> WearUpdate {
        self.cycles = self.cycles.wrapping_add(1);
        if friction_work_j.is_finite() && friction_work_j > 0.0 {
            self.friction_work_j += friction_work_j as f64;
        }
        let bin = if operating_point_pa.is_finite() {
            math::round(operating_point_pa / cfg.bin_width_pa) as i32
        } else {
            i32::MIN
        };
        let b = self.baseline_mut(bin);
        let mut score_step = None;
        if let Some(b) = b {
            if b.n < cfg.baseline_cycles as u32 {
                // Learning: Welford's running mean and variance.
                b.n += 1;
                let delta = friction_n - b.mean_n;
                b.mean_n += delta / b.n as f32;
                b.m2 += delta * (friction_n - b.mean_n);
            } else {
                let sigma = b
                    .std_n()
                    .max(cfg.sigma_floor_rel * math::abs(b.mean_n))
                    .max(cfg.sigma_floor_n);
                score_step = Some((friction_n - b.mean_n) / sigma);
            }
        }
        if let Some(z) = score_step {
            self.cusum = (self.cusum + z - cfg.cusum_k).max(0.0);
            self.alarm = self.cusum > cfg.cusum_h;
        }
        let remaining_j = (cfg.budget_j as f64 - self.friction_work_j).max(0.0);
        WearUpdate {
            wear_index_j: self.friction_work_j as f32,
            remaining_fraction: (remaining_j / cfg.budget_j as f64) as f32,
            remaining_cycles: if friction_work_j > 0.0 {
                (remaining_j / friction_work_j as f64) as f32
            } else {
                f32::INFINITY
            },
            drift_score: self.cusum,
            alarm: self.alarm,
        }
    }

    /// The baseline of a bin; a new bin takes a free slot, or none when full.
    fn baseline_mut(&mut self, bin: i32) -> Option<&mut Baseline> {
        let n = self.n_baselines as usize;
        if let Some(i) = self.baselines[..n].iter().position(|b| b.bin == bin) {
            return Some(&mut self.baselines[i]);
        }
        if n < MAX_BASELINES {
            self.baselines[n] = Baseline {
                bin,
                ..Default::default()
            };
            self.n_baselines += 1;
            return Some(&mut self.baselines[n]);
        }
        None
    }

    /// Forgets the baselines and the alarm (after a repair), keeping the wear index.
    pub fn rebaseline(&mut self) {
        self.baselines = [Baseline::default(); MAX_BASELINES];
        self.n_baselines = 0;
        self.cusum = 0.0;
        self.alarm = false;
    }

    pub fn to_bytes(&self) -> [u8; WEAR_STATE_BYTES] {
        let mut b = [0u8; WEAR_STATE_BYTES];
        let mut w = Writer { buf: &mut b, pos: 0 };
        w.put(&MAGIC);
        w.put(&VERSION.to_le_bytes());
        w.put(&(MAX_BASELINES as u32).to_le_bytes());
        w.put(&self.n_baselines.to_le_bytes());
        w.put(&self.friction_work_j.to_le_bytes());
        w.put(&self.cycles.to_le_bytes());
        w.put(&self.cusum.to_le_bytes());
        w.put(&(self.alarm as u32).to_le_bytes());
        for bl in &self.baselines {
            w.put(&bl.bin.to_le_bytes());
            w.put(&bl.n.to_le_bytes());
            w.put(&bl.mean_n.to_le_bytes());
            w.put(&bl.m2.to_le_bytes());
        }
        let end = w.pos;
        let crc = crc32(&b[..end]);
        b[end..end + 4].copy_from_slice(&crc.to_le_bytes());
        b
    }

    pub fn from_bytes(b: &[u8]) -> Result<Self, WearStateError> {
        if b.len() < WEAR_STATE_BYTES {
            return Err(WearStateError::TooShort);
        }
        if b[..4] != MAGIC {
            return Err(WearStateError::BadMagic);
        }
        let mut r = Reader { buf: b, pos: 4 };
        let version = r.u32();
        if version != VERSION {
            return Err(WearStateError::UnsupportedVersion(version));
        }
        let end = WEAR_STATE_BYTES - 4;
        let crc = u32::from_le_bytes([b[end], b[end + 1], b[end + 2], b[end + 3]]);
        if crc != crc32(&b[..end]) {
            return Err(WearStateError::BadChecksum);
        }
        let cap = r.u32();
        let n_baselines = r.u32().min(cap).min(MAX_BASELINES as u32);
        let mut s = WearState {
            friction_work_j: r.f64(),
            cycles: r.u32(),
            cusum: r.f32(),
            alarm: r.u32() != 0,
            n_baselines,
            ..Default::default()
        };
        for bl in s.baselines.iter_mut() {
            *bl = Baseline {
                bin: r.u32() as i32,
                n: r.u32(),
                mean_n: r.f32(),
                m2: r.f32(),
            };
        }
        Ok(s)
    }
}

struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
}

impl Writer<'_> {
    fn put(&mut self, bytes: &[u8]) {
        self.buf[self.pos..self.pos + bytes.len()].copy_from_slice(bytes);
        self.pos += bytes.len();
    }
}

struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> [u8; N] {
        let mut a = [0u8; N];
        a.copy_from_slice(&self.buf[self.pos..self.pos + N]);
        self.pos += N;
        a
    }
    fn u32(&mut self) -> u32 {
        u32::from_le_bytes(self.take())
    }
    fn f32(&mut self) -> f32 {
        f32::from_le_bytes(self.take())
    }
    fn f64(&mut self) -> f64 {
        f64::from_le_bytes(self.take())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc_matches_the_standard_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn state_round_trips_and_rejects_corruption() {
        let cfg = WearConfig::default();
        let mut s = WearState::default();
        for i in 0..80 {
            s.update(&cfg, 10.0 + (i % 3) as f32 * 0.01, 0.9, 4e5);
        }
        let bytes = s.to_bytes();
        assert_eq!(WearState::from_bytes(&bytes).unwrap(), s);
        let mut bad = bytes;
        bad[20] ^= 1;
        assert_eq!(WearState::from_bytes(&bad), Err(WearStateError::BadChecksum));
        assert_eq!(WearState::from_bytes(&bytes[..10]), Err(WearStateError::TooShort));
        let mut other = bytes;
        other[0] = b'X';
        assert_eq!(WearState::from_bytes(&other), Err(WearStateError::BadMagic));
    }

    #[test]
    fn baselines_are_kept_per_operating_point() {
        let cfg = WearConfig::default();
        let mut s = WearState::default();
        for _ in 0..60 {
            s.update(&cfg, 10.0, 1.0, 4e5);
            s.update(&cfg, 16.0, 1.0, 7e5);
        }
        assert_eq!(s.n_baselines, 2);
        assert!(!s.alarm, "two operating points with different friction are not drift");
        assert!((s.friction_work_j - 120.0).abs() < 1e-9);
    }
}
