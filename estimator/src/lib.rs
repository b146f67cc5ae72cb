//! Per-cycle estimator of an impact hammer's piston friction, impact energy,
//! frequency and wear, from two chamber pressures and the piston acceleration.
//!
//! `no_std` and allocation-free so the very same code runs in host tests, in
//! offline analysis and on the Cortex-M4F.
#![no_std]
#![forbid(unsafe_code)]

pub mod geometry;

pub use geometry::Geometry;
