//! The one path for transcendental functions.
//!
//! Under `cargo test` an inherent `f32::sqrt` would resolve to std's exact
//! method while the target has no std: host and target would then compute
//! different numbers. Everything goes through `libm` explicitly, so a report
//! computed on the host is bit-identical to the one the firmware sends.

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
