//! Wear indicator: cumulative friction work (an Archard-style wear index),
//! a friction drift alarm against a baseline learned at the same operating
//! point, and a remaining-life estimate. The state survives a reset through
//! [`WearState::to_bytes`] / [`WearState::from_bytes`].

use crate::config::WearConfig;
use crate::math;

/// The state's size and its CRC, defined with the wire's `WearBlob` in `hammer-types`.
pub use hammer_types::{crc32, MAX_BASELINES, WEAR_STATE_BYTES};
const MAGIC: [u8; 4] = *b"HMWS";
/// 2: the friction work in integer µJ (1: `f64` J, still read).
const VERSION: u32 = 2;

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
    /// Cumulative friction work, µJ. An integer: 10⁹ cycles of a few joules
    /// must not round away, and the target's FPU has no double precision.
    pub friction_work_uj: u64,
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
            // Saturating: f32 → u64 clamps, and 10¹³ J is beyond any hammer's life.
            let uj = (friction_work_j * 1e6 + 0.5) as u64;
            self.friction_work_uj = self.friction_work_uj.saturating_add(uj);
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
        let work_j = self.wear_index_j();
        let remaining_j = (cfg.budget_j - work_j).max(0.0);
        WearUpdate {
            wear_index_j: work_j,
            remaining_fraction: remaining_j / cfg.budget_j,
            remaining_cycles: if friction_work_j > 0.0 {
                remaining_j / friction_work_j
            } else {
                f32::INFINITY
            },
            drift_score: self.cusum,
            alarm: self.alarm,
        }
    }

    /// The wear index, J: the cumulative friction work.
    pub fn wear_index_j(&self) -> f32 {
        self.friction_work_uj as f32 * 1e-6
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
        w.put(&self.friction_work_uj.to_le_bytes());
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
        if version != VERSION && version != 1 {
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
            friction_work_uj: match version {
                1 => f64_joules_to_uj(r.u64()),
                _ => r.u64(),
            },
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

/// A version-1 state's friction work (the bits of an `f64` in joules) in
/// µJ. Through `f32` (24 bits: 6·10⁻⁸ relative, once, at the first boot
/// after the update): exact `f64` arithmetic would cost the board ~1 KB of
/// software routines for this one conversion. Negative or NaN reads as 0.
fn f64_joules_to_uj(bits: u64) -> u64 {
    (crate::math::narrow(f64::from_bits(bits)) * 1e6) as u64
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
    fn u64(&mut self) -> u64 {
        u64::from_le_bytes(self.take())
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
    fn a_version_1_state_keeps_its_friction_work() {
        for j in [0.0f64, 1e-6, 0.875, 120.0, 3.25e6, 1.234_567_891e9] {
            let uj = f64_joules_to_uj(j.to_bits()) as f64;
            assert!((uj - j * 1e6).abs() <= 1e-7 * j * 1e6, "{j} J: {uj} µJ");
        }
        assert_eq!(f64_joules_to_uj((-5.0f64).to_bits()), 0);
        assert_eq!(f64_joules_to_uj(f64::NAN.to_bits()), 0);
        assert_eq!(f64_joules_to_uj(f64::INFINITY.to_bits()), u64::MAX);
        // A version-1 blob (f64 J at offset 16) reads back as µJ.
        let mut s = WearState::default();
        s.friction_work_uj = 0;
        s.cycles = 7;
        let mut b = s.to_bytes();
        b[4..8].copy_from_slice(&1u32.to_le_bytes());
        b[16..24].copy_from_slice(&42.5f64.to_bits().to_le_bytes());
        let end = WEAR_STATE_BYTES - 4;
        let crc = crc32(&b[..end]);
        b[end..].copy_from_slice(&crc.to_le_bytes());
        let back = WearState::from_bytes(&b).unwrap();
        assert_eq!(back.friction_work_uj, 42_500_000);
        assert_eq!(back.cycles, 7);
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
        assert_eq!(s.friction_work_uj, 120_000_000);
    }
}
