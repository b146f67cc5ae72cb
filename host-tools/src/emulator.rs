//! The emulated board: the firmware's app on QEMU's mps2-an386 (Cortex-M4F),
//! its UART on a TCP socket on loopback.

use std::io;
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

pub const QEMU: &str = "qemu-system-arm";

/// Where `cargo build --release` in `firmware/` puts the emulated board's ELF.
pub fn firmware_elf() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("host-tools sits in the workspace")
        .to_path_buf();
    root.join("firmware/target/thumbv7em-none-eabihf/release/hammer-firmware-emu")
}

pub fn qemu_available() -> bool {
    Command::new(QEMU)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// A running QEMU; killed when dropped.
pub struct Emulator {
    child: Child,
    pub port: u16,
}

impl Emulator {
    /// Boots `elf`. With `count_instructions`, `-icount shift=0` makes one
    /// instruction one nanosecond of guest time, so the guest's SysTick clock
    /// counts instructions.
    pub fn start(elf: &Path, count_instructions: bool) -> io::Result<Self> {
        if !elf.exists() {
            return Err(io::Error::new(
                io::ErrorKind::NotFound,
                format!(
                    "{} not built: run `cargo xtask firmware` (or cargo build --release in firmware/)",
                    elf.display()
                ),
            ));
        }
        let port = TcpListener::bind("127.0.0.1:0")?.local_addr()?.port();
        let mut cmd = Command::new(QEMU);
        cmd.args(["-M", "mps2-an386", "-nographic", "-monitor", "none"])
            .args(["-semihosting-config", "enable=on,target=native"])
            .args(["-serial", &format!("tcp:127.0.0.1:{port},server=on,wait=off")]);
        if count_instructions {
            cmd.args(["-icount", "shift=0"]);
        }
        cmd.arg("-kernel")
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::inherit());
        let child = cmd
            .spawn()
            .map_err(|e| io::Error::new(e.kind(), format!("cannot start {QEMU}: {e}")))?;
        Ok(Self { child, port })
    }

    /// Connects to the board's UART, retrying while QEMU starts.
    pub fn connect(&mut self, timeout: Duration) -> io::Result<TcpStream> {
        let deadline = Instant::now() + timeout;
        loop {
            match TcpStream::connect(("127.0.0.1", self.port)) {
                Ok(s) => {
                    s.set_nodelay(true)?;
                    s.set_read_timeout(Some(Duration::from_millis(50)))?;
                    return Ok(s);
                }
                Err(e) => {
                    if let Some(status) = self.child.try_wait()? {
                        return Err(io::Error::other(format!("qemu exited ({status})")));
                    }
                    if Instant::now() >= deadline {
                        return Err(e);
                    }
                    std::thread::sleep(Duration::from_millis(20));
                }
            }
        }
    }

    pub fn is_running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
