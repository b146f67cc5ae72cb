//! Puts this board's `memory.x` and `device.x` where cortex-m-rt's `link.x`
//! looks for them, and passes the linker script to this binary only.
//!
//! The files are found through `CARGO_MANIFEST_DIR`, never the current
//! directory, so the build works from firmware/ as well as from here. There
//! is deliberately no `-Tdefmt.x`: this board has no defmt (see Cargo.toml).

use std::env;
use std::fs;
use std::path::PathBuf;

fn main() {
    let manifest_dir = PathBuf::from(env::var_os("CARGO_MANIFEST_DIR").expect("CARGO_MANIFEST_DIR not set"));
    let out_dir = PathBuf::from(env::var_os("OUT_DIR").expect("OUT_DIR not set"));

    for name in ["memory.x", "device.x"] {
        let src = manifest_dir.join(name);
        let contents = fs::read(&src).unwrap_or_else(|e| panic!("cannot read {}: {e}", src.display()));
        fs::write(out_dir.join(name), contents).unwrap_or_else(|e| panic!("cannot write {name} into OUT_DIR: {e}"));
        println!("cargo:rerun-if-changed={}", src.display());
    }

    println!("cargo:rustc-link-search={}", out_dir.display());
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    println!("cargo:rerun-if-changed=build.rs");
}
