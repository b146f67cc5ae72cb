//! The one path for transcendental functions.
//!
//! Under `cargo test` an inherent `f32::sqrt` would resolve to std's exact
//! method while the target has no std: host and target would then compute
//! different numbers. Everything goes through `libm` explicitly, so a report
//! computed on the host is bit-identical to the one the firmware sends.

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

#[inline]
pub fn sin(x: f32) -> f32 {
    libm::sinf(x)
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

#[inline]
pub fn pow(x: f32, y: f32) -> f32 {
    libm::powf(x, y)
}
