//! What several test binaries share: running the `hammer` binary and a
//! fresh scratch folder per test. Each binary uses what it needs.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::Command;

/// Runs `hammer` with `args`: its exit code, stdout and stderr.
pub fn hammer(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_hammer")).args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// An empty folder of this test binary's own, named `name`.
pub fn tmp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!(
        "hammer-{}-{}-{name}",
        env!("CARGO_CRATE_NAME"),
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}
