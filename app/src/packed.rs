//! Sample-sets at 12 bits a code, 4.5 bytes a set instead of 6: the raw
//! capture holds a whole cycle in three quarters of the RAM, which is what
//! lets the firmware fit a 48 KiB part. The ADCs are 12-bit, so nothing is
//! lost; a code above 4095 (only a host could send one) is kept as 4095.

use hammer_estimator::RawSample;

/// Bytes for `sets` sample-sets: two sets (six codes, 72 bits) per 9 bytes.
pub const fn bytes_for(sets: usize) -> usize {
    sets.div_ceil(2) * 9
}

/// `N` sample-sets packed into `B` bytes (`B` = [`bytes_for`]`(N)`).
pub struct Packed<const N: usize, const B: usize> {
    bytes: [u8; B],
}

impl<const N: usize, const B: usize> Packed<N, B> {
    const FITS: () = assert!(B >= bytes_for(N));

    pub const fn new() -> Self {
        let () = Self::FITS;
        Self { bytes: [0; B] }
    }

    /// Bit position of code `ch` (0..3) of set `i`, and its first byte.
    fn at(i: usize, ch: usize) -> (usize, u32) {
        let bit = (i / 2) * 72 + ((i % 2) * 3 + ch) * 12;
        (bit / 8, (bit % 8) as u32)
    }

    /// Stores set `i` (ignored past `N`).
    pub fn set(&mut self, i: usize, s: RawSample) {
        if i >= N {
            return;
        }
        for (ch, code) in [s.rear, s.front, s.accel].into_iter().enumerate() {
            let (byte, shift) = Self::at(i, ch);
            let v = u16::from(code.min(0x0fff)) << shift;
            let mask = 0x0fffu16 << shift;
            let old = u16::from_le_bytes([self.bytes[byte], self.bytes[byte + 1]]);
            let [lo, hi] = ((old & !mask) | v).to_le_bytes();
            self.bytes[byte] = lo;
            self.bytes[byte + 1] = hi;
        }
    }

    /// Code `ch` (0 rear, 1 front, 2 accelerometer) of set `i` alone (0
    /// past `N`): two bytes read, where [`Self::get`] decodes all three.
    #[inline]
    pub fn code(&self, i: usize, ch: usize) -> u16 {
        if i >= N || ch > 2 {
            return 0;
        }
        let (byte, shift) = Self::at(i, ch);
        match self.bytes.get(byte..byte + 2) {
            Some(b) => (u16::from_le_bytes([b[0], b[1]]) >> shift) & 0x0fff,
            None => 0,
        }
    }

    /// Set `i` (zeros past `N`). Its 36 bits read in one piece: the five
    /// bytes from its first (a board's chambers' reading reads each set
    /// many times).
    #[inline]
    pub fn get(&self, i: usize) -> RawSample {
        if i >= N {
            return RawSample::default();
        }
        let (byte, shift) = ((i / 2) * 9 + (i % 2) * 4, (i % 2) * 4);
        let Some(b) = self.bytes.get(byte..byte + 5) else {
            return RawSample::default();
        };
        let w = (u64::from(b[0])
            | u64::from(b[1]) << 8
            | u64::from(b[2]) << 16
            | u64::from(b[3]) << 24
            | u64::from(b[4]) << 32)
            >> shift;
        RawSample {
            rear: (w & 0x0fff) as u16,
            front: ((w >> 12) & 0x0fff) as u16,
            accel: ((w >> 24) & 0x0fff) as u16,
        }
    }
}

impl<const N: usize, const B: usize> Default for Packed<N, B> {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_set_reads_back_and_neighbours_are_untouched() {
        const N: usize = 7;
        let mut p = Packed::<N, { bytes_for(N) }>::new();
        let set = |i: usize| RawSample {
            rear: (i * 577 % 4096) as u16,
            front: (4095 - i * 131 % 4096) as u16,
            accel: (i * 2049 % 4096) as u16,
        };
        for i in 0..N {
            p.set(i, set(i));
        }
        for i in 0..N {
            assert_eq!(p.get(i), set(i), "set {i}");
        }
        // Rewriting one set leaves the others as they were.
        p.set(
            3,
            RawSample {
                rear: 4095,
                front: 0,
                accel: 4095,
            },
        );
        for i in (0..N).filter(|&i| i != 3) {
            assert_eq!(p.get(i), set(i));
        }
        assert_eq!(
            p.get(3),
            RawSample {
                rear: 4095,
                front: 0,
                accel: 4095
            }
        );
        // Out of range: saturated codes, ignored indices.
        p.set(
            0,
            RawSample {
                rear: 65535,
                front: 4096,
                accel: 1,
            },
        );
        assert_eq!(
            p.get(0),
            RawSample {
                rear: 4095,
                front: 4095,
                accel: 1
            }
        );
        p.set(N, set(1));
        assert_eq!(p.get(N), RawSample::default());
        // One code at a time reads what the whole set reads.
        for i in 1..N {
            let s = p.get(i);
            assert_eq!(
                [p.code(i, 0), p.code(i, 1), p.code(i, 2)],
                [s.rear, s.front, s.accel],
                "set {i}"
            );
        }
        assert_eq!(bytes_for(5600), 25_200);
    }
}
