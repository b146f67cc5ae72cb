//! Empty, and there for its presence: without a build script cargo leaves a
//! package's `[build-dependencies]` out of the build (it compiles none of
//! them), so their features could not be relied on to reach the host's
//! units. The features are the point of this crate (Cargo.toml).
fn main() {}
