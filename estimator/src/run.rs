//! Plain loops over runs of raw sample-sets that the hot path needs in a
//! particular shape (see `docs/firmware.md`, Measured).

use crate::RawSample;

/// The first sample whose accelerometer code is at or below `max` (an
/// impact), two samples a turn.
#[inline(always)]
pub(crate) fn first_at_or_below(scan: &[RawSample], max: u16) -> Option<usize> {
    let pairs = scan.chunks_exact(2);
    let odd = pairs.remainder();
    for (k, p) in pairs.enumerate() {
        if p[0].accel <= max {
            return Some(2 * k);
        }
        if p[1].accel <= max {
            return Some(2 * k + 1);
        }
    }
    odd.iter()
        .position(|s| s.accel <= max)
        .map(|i| scan.len() - odd.len() + i)
}

/// Copies a few samples (the delay line's): element by element, as
/// `copy_from_slice` on 6-byte samples calls a byte-wise `memcpy`.
#[inline(always)]
pub(crate) fn copy(dst: &mut [RawSample], src: &[RawSample]) {
    for (d, s) in dst.iter_mut().zip(src) {
        *d = *s;
    }
}
