//! No code. This crate's manifest names the dependency features that the
//! workspace's tests and the Python package's wheel (python/, built by
//! maturin for that package alone) must both enable, so that cargo resolves
//! every crate they share alike and the wheel's build reuses the workspace's
//! artifacts instead of compiling the graph a second time. See Cargo.toml.
#![no_std]
