//! The one path for transcendental functions, and for changing float width
//! (`width`: in integers, as the board has no double-precision unit).
//!
//! Under `cargo test` an inherent `f32::sqrt` would resolve to std's exact
//! method while the target has no std: host and target would then compute
//! different numbers. Everything goes through `libm` explicitly, so a report
//! computed on the host is bit-identical to the one the firmware sends.

mod width;
pub use width::{narrow, widen};

/// `x` limited to `lo ..= hi`, NaN passed through. Unlike `f32::clamp` it
/// cannot panic (on `lo > hi` or a NaN bound), so no panic message with
/// formatted floats (core's float formatting, ~8 KB of flash) reaches the
/// firmware image.
#[inline]
pub fn clamp(x: f32, lo: f32, hi: f32) -> f32 {
    if x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

#[inline]
pub fn sqrt(x: f32) -> f32 {
    libm::sqrtf(x)
}

#[inline]
pub fn exp(x: f32) -> f32 {
    libm::expf(x)
}

/// `sin(x)` for |x| ≤ π/2, the only angles the estimator has (an
/// inclination of ±90° at most; beyond, `x` is clamped): the Taylor series
/// to x¹¹, whose error there is below 6·10⁻⁸, f32's own. libm's `sinf`,
/// which reduces any argument, took 2.9 KB of the firmware's flash.
#[inline]
pub fn sin_small(x: f32) -> f32 {
    let x = clamp(x, -core::f32::consts::FRAC_PI_2, core::f32::consts::FRAC_PI_2);
    let x2 = x * x;
    // x − x³/3! + x⁵/5! − x⁷/7! + x⁹/9! − x¹¹/11!, in Horner's form.
    let p = 1.0 / 39_916_800.0f32;
    let p = 1.0 / 362_880.0 - x2 * p;
    let p = 1.0 / 5_040.0 - x2 * p;
    let p = 1.0 / 120.0 - x2 * p;
    let p = 1.0 / 6.0 - x2 * p;
    x * (1.0 - x2 * p)
}

/// Natural logarithm (the chambers' p·Vⁿ; not on the board's per-sample path).
#[inline]
pub fn ln(x: f32) -> f32 {
    libm::logf(x)
}

/// `xʸ` for real exponents (the orifice flow function; not on the board's
/// per-sample path, where `powi` serves).
#[inline]
pub fn powf(x: f32, y: f32) -> f32 {
    libm::powf(x, y)
}

#[inline]
pub fn abs(x: f32) -> f32 {
    libm::fabsf(x)
}

#[inline]
pub fn round(x: f32) -> f32 {
    libm::roundf(x)
}

#[inline]
pub fn is_finite(x: f32) -> bool {
    x.is_finite()
}

/// `xⁿ` by repeated squaring: the estimator's powers are sample counts.
/// (libm's `powf` took 1.4 KB of the firmware's flash.)
#[inline]
pub fn powi(mut x: f32, mut n: u32) -> f32 {
    let mut r = 1.0;
    while n > 0 {
        if n & 1 == 1 {
            r *= x;
        }
        x *= x;
        n >>= 1;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_small_sine_and_the_integer_power_agree_with_libm() {
        for k in -90..=90 {
            let x = k as f32 * (core::f32::consts::PI / 180.0);
            assert!((sin_small(x) - libm::sinf(x)).abs() < 2e-7, "{k}°");
        }
        assert_eq!(sin_small(0.0), 0.0);
        assert_eq!(sin_small(10.0), sin_small(core::f32::consts::FRAC_PI_2));
        // Squaring doubles a relative error, so xⁿ carries up to about n
        // roundings of f32 (6·10⁻⁸ each): 1.2·10⁻⁵ at n = 200, far below
        // what a decay weight needs.
        for n in 0..200u32 {
            let q = 0.995f32;
            let rel = powi(q, n) / libm::powf(q, n as f32) - 1.0;
            assert!(rel.abs() < (n.max(1) as f32) * 6e-8, "q^{n}: {rel}");
        }
        assert_eq!(powi(3.0, 0), 1.0);
        assert_eq!(powi(3.0, 5), 243.0);
    }
}
