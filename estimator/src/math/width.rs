//! f64 ⇄ f32 in integer arithmetic, bit-identical to `as` (round to nearest,
//! ties to even; subnormals, infinities and NaN kept).
//!
//! The board has a single-precision FPU: `as` between the two widths calls
//! compiler-builtins' software routines (`__aeabi_d2f`, `__aeabi_f2d`, 448 B
//! of flash), pulled in by the geometry (f64 on the host, where the
//! simulator's numbers come from) and an old wear state's f64 joules. These
//! few integer operations do the same in less.

/// `x as f32`.
pub fn narrow(x: f64) -> f32 {
    let b = x.to_bits();
    let sign = ((b >> 63) as u32) << 31;
    let exp = ((b >> 52) & 0x7ff) as i32;
    let mant = b & ((1u64 << 52) - 1);
    if exp == 0x7ff {
        // Infinity, or a NaN kept quiet.
        let nan = if mant != 0 { 0x40_0000 | (mant >> 29) as u32 } else { 0 };
        return f32::from_bits(sign | 0x7f80_0000 | nan);
    }
    let e = exp - 1023 + 127;
    if e >= 0xff {
        return f32::from_bits(sign | 0x7f80_0000);
    }
    // The significand, and how far it shifts to 23 bits (further, with its
    // hidden bit, for a subnormal result).
    let (sig, shift) = if e > 0 {
        (mant, 29)
    } else if exp == 0 || e < -24 {
        // An f64 subnormal, or below half the smallest f32 subnormal: ±0.
        return f32::from_bits(sign);
    } else {
        (mant | 1u64 << 52, (30 - e) as u32)
    };
    let kept = (sig >> shift) as u32;
    let rest = sig & ((1u64 << shift) - 1);
    let half = 1u64 << (shift - 1);
    // The exponent field and the significand add: a carry out of the
    // significand raises the exponent (up to infinity), as rounding does.
    let mut bits = ((e.max(0) as u32) << 23) | kept;
    if rest > half || (rest == half && kept & 1 == 1) {
        bits += 1;
    }
    f32::from_bits(sign | bits)
}

/// `x as f64` (exact).
pub fn widen(x: f32) -> f64 {
    let b = x.to_bits();
    let sign = ((b >> 31) as u64) << 63;
    let exp = (b >> 23) & 0xff;
    let mant = (b & 0x7f_ffff) as u64;
    let bits = match exp {
        0 if mant == 0 => sign,
        0 => {
            // Subnormal: normalise (the top set bit becomes the hidden one).
            let top = 63 - mant.leading_zeros();
            sign | ((u64::from(top) + 1023 - 149) << 52) | ((mant << (52 - top)) & ((1u64 << 52) - 1))
        }
        0xff => sign | (0x7ffu64 << 52) | (mant << 29),
        _ => sign | ((u64::from(exp) + 1023 - 127) << 52) | (mant << 29),
    };
    f64::from_bits(bits)
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    /// Both ways, against `as`, over the edges and a spread of bit patterns.
    #[test]
    fn the_widths_convert_as_as_does() {
        let same32 = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        let same64 = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        let edges = [
            0.0,
            1.0,
            1.12,
            0.041,
            0.028,
            f64::MAX,
            f64::MIN_POSITIVE,
            f32::MAX as f64,
            f32::MAX as f64 * (1.0 + f64::EPSILON),
            3.402_823_5e38 * 1.000_000_1,
            f32::MIN_POSITIVE as f64,
            1.4e-45,
            0.7e-45,
            0.8e-45,
            1e-46,
            f64::INFINITY,
            f64::NAN,
            1.0 + 2f64.powi(-24),
            1.0 + 2f64.powi(-24) + 2f64.powi(-40),
            1.0 + 3.0 * 2f64.powi(-24),
        ];
        let both: Vec<f64> = edges.iter().flat_map(|x| [*x, -*x]).collect();
        for x in both {
            assert!(same32(narrow(x), x as f32), "narrow({x:e})");
            let y = x as f32;
            assert!(same64(widen(y), y as f64), "widen({y:e})");
        }
        // A pseudo-random walk over the bit patterns.
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..200_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let x = f64::from_bits(s);
            assert!(same32(narrow(x), x as f32), "narrow({x:e}) bits {s:#x}");
            let y = f32::from_bits((s >> 32) as u32);
            assert!(same64(widen(y), y as f64), "widen({y:e})");
            // Near f32's range: exponents that round, overflow and go subnormal.
            let near = f64::from_bits((s & 0x800f_ffff_ffff_ffff) | (((s >> 52) % 330 + 1023 - 160) << 52));
            assert!(same32(narrow(near), near as f32), "narrow({near:e})");
        }
    }
}
