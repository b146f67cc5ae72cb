//! Empty: cargo resolves `[build-dependencies]` only for a package with a
//! build script, and their features are the point of this crate (Cargo.toml).
fn main() {}
