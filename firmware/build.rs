//! Puts the repository's `memory.x` where cortex-m-rt's `link.x` looks for it.
//!
//! The file lives at the repository root, outside this crate, so it is found
//! through `CARGO_MANIFEST_DIR` rather than the current directory: the build
//! then works no matter which directory under firmware/ cargo was started from.

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR not set"));
    let memory_x = manifest_dir
        .parent()
        .expect("firmware/ has a parent directory")
        .join("memory.x");
    let out_dir = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR not set"));

    let contents =
        fs::read(&memory_x).unwrap_or_else(|e| panic!("cannot read linker memory layout {}: {e}", memory_x.display()));
    fs::write(out_dir.join("memory.x"), contents).expect("cannot write memory.x into OUT_DIR");

    println!("cargo:rustc-link-search={}", out_dir.display());
    // Linker scripts belong to this binary alone (see .cargo/config.toml):
    // cortex-m-rt's layout, and the defmt section table this board logs with.
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    println!("cargo:rerun-if-changed={}", memory_x.display());
    println!("cargo:rerun-if-changed=build.rs");
}
