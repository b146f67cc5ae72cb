//! Plain loops over runs of raw sample-sets that the hot path needs in a
//! particular shape (see `docs/firmware.md`, Measured), and the code an
//! impact is detected at.

use crate::{Config, RawSample};

/// The first sample whose accelerometer code is at or below `max` (an
/// impact), two samples a turn. Out of line, so that the loop has the
/// registers to itself wherever it is called from (inlined into the
/// sampling task it reloaded one from the stack every turn), and written
/// so that a build for size (`opt-level = "s"`) keeps it at ~4.5
/// instructions a sample.
#[inline(never)]
pub(crate) fn first_at_or_below(scan: &[RawSample], max: u16) -> Option<usize> {
    let pairs = scan.chunks_exact(2);
    let odd = pairs.remainder();
    // Pairs not yet looked at: the index of a hit follows from it.
    let mut left = pairs.len();
    for p in pairs {
        if p[0].accel <= max || p[1].accel <= max {
            let k = scan.len() - odd.len() - 2 * left;
            return Some(if p[0].accel <= max { k } else { k + 1 });
        }
        left -= 1;
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

/// The highest accelerometer code that reads below −threshold, when the
/// calibration has a positive scale (the usual case); then detecting an
/// impact is one integer compare per sample.
pub(crate) fn impact_code(cfg: &Config) -> Option<u16> {
    let a = &cfg.accel;
    if a.scale <= 0.0 {
        return None;
    }
    let mut code: Option<u16> = None;
    // value(c) < −thr ⇔ c < zero − thr/scale; scan down from the estimate to be exact in f32.
    let est = a.zero_code - cfg.impact_threshold_mps2 / a.scale;
    let start = if est < 0.0 {
        0
    } else if est > a.full_scale_code as f32 {
        a.full_scale_code
    } else {
        est as u16
    };
    let mut c = start.saturating_add(2).min(a.full_scale_code);
    loop {
        if a.value(c) < -cfg.impact_threshold_mps2 {
            code = Some(c);
            break;
        }
        if c == 0 {
            break;
        }
        c -= 1;
    }
    // Code 0 (the bottom rail) is always an impact.
    Some(code.unwrap_or(0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scan_finds_the_first_hit_at_any_length_and_place() {
        for len in 0..12usize {
            for hit in 0..=len {
                for second in [None, Some(hit + 1), Some(hit + 3)] {
                    let scan: heapless::Vec<RawSample, 16> = (0..len)
                        .map(|i| RawSample {
                            rear: 1,
                            front: 2,
                            accel: if i == hit || Some(i) == second { 100 } else { 2000 },
                        })
                        .collect();
                    let want = scan.iter().position(|s| s.accel <= 100);
                    assert_eq!(first_at_or_below(&scan, 100), want, "len {len}, hit {hit}");
                }
            }
        }
    }

    #[test]
    fn impact_code_matches_the_float_threshold() {
        for thr in [100.0f32, 1500.0, 1999.0, 5000.0] {
            let mut cfg = Config::default();
            cfg.impact_threshold_mps2 = thr;
            let max = impact_code(&cfg).unwrap();
            for c in 0..=4095u16 {
                let float = c == 0 || cfg.accel.value(c) < -thr;
                assert_eq!(c <= max, float, "thr {thr}, code {c}, max {max}");
            }
        }
    }
}
