//! What the benches that run the emulated board under QEMU share.

use std::path::PathBuf;

/// The profiling plugin: `HAMMER_QEMU_PROFILE_PLUGIN`, else where
/// `cargo build --release -p qemu-profile` puts it beside the bench.
pub fn plugin() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("HAMMER_QEMU_PROFILE_PLUGIN") {
        return Some(PathBuf::from(p));
    }
    let exe = std::env::current_exe().ok()?;
    let release = exe.parent()?.parent()?;
    Some(release.join("libqemu_profile.so")).filter(|p| p.is_file())
}
