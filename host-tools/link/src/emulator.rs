//! The emulated board: the firmware's app on QEMU's mps2-an386 (Cortex-M4F),
//! its UART on a TCP socket on loopback, its ADC fed from a [`Stimulus`].

use std::io;
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::stimulus::Stimulus;

pub const QEMU: &str = "qemu-system-arm";

/// How guest time advances (QEMU's `-icount`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Icount {
    /// 2^shift ns of guest time per instruction.
    pub shift: u8,
    /// Hold the guest back to the host's clock (`align=on`), so the board
    /// keeps the hammer's own pace; otherwise it runs as fast as the host
    /// allows. The board's timing is the instruction count's either way: the
    /// full-rate board never halts its core (firmware/emulated/src/executor.rs),
    /// so no host hiccup can look like a slow firmware.
    pub real_time: bool,
}

impl Icount {
    /// One instruction per nanosecond: the guest's clock counts instructions.
    pub const COUNT: Self = Self {
        shift: 0,
        real_time: false,
    };

    /// 8 ns per instruction, 125 M instructions per second of guest time. The
    /// STM32G474 runs 170 MHz at about one instruction per cycle (more with
    /// flash wait states and divisions), so a board emulated at this rate is
    /// slower than the real one: deadlines it meets, the chip meets.
    pub const fn m4_at_125_mips(real_time: bool) -> Self {
        Self { shift: 3, real_time }
    }

    fn arg(&self) -> String {
        if self.real_time {
            format!("shift={},align=on", self.shift)
        } else {
            // sleep=on is the default and what COUNT always had: a halted
            // (WFI) core's guest time follows the host's clock.
            format!("shift={}", self.shift)
        }
    }
}

/// Where `cargo build --release` in `firmware/` puts the emulated board's ELF.
pub fn firmware_elf() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .and_then(Path::parent)
        .expect("host-tools/link sits in the workspace")
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
        Self::start_with(elf, count_instructions.then_some(Icount::COUNT), None)
    }

    /// Boots `elf` with its samples from `stimulus` at the full rate (the
    /// board's ADC model) instead of over the UART. QEMU then waits for the
    /// UART's client before the board starts, so no report is sent to nobody.
    ///
    /// With `icount`, guest time counts instructions while the core runs, so
    /// guest timing no longer depends on the host's speed or on QEMU
    /// translating code; without, it is the host's clock.
    pub fn start_with(elf: &Path, icount: Option<Icount>, stimulus: Option<&Stimulus>) -> io::Result<Self> {
        Self::start_with_args(elf, icount, stimulus, &[])
    }

    /// [`Emulator::start_with`] with more QEMU arguments (a profiling
    /// plugin, say), each one argument whatever its spaces.
    pub fn start_with_args(
        elf: &Path,
        icount: Option<Icount>,
        stimulus: Option<&Stimulus>,
        extra: &[String],
    ) -> io::Result<Self> {
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
            .args([
                "-serial",
                &format!(
                    "tcp:127.0.0.1:{port},server=on,wait={}",
                    if stimulus.is_some() { "on" } else { "off" }
                ),
            ]);
        if let Some(s) = stimulus {
            cmd.args(s.qemu_args());
        }
        if let Some(i) = icount {
            cmd.args(["-icount", &i.arg()]);
        }
        // Extra QEMU arguments for a developer (`-d nochain,exec -D exec.log`
        // to profile the firmware by translation block).
        if let Ok(extra) = std::env::var("HAMMER_QEMU_ARGS") {
            cmd.args(extra.split_whitespace());
        }
        cmd.args(extra);
        cmd.arg("-kernel")
            .arg(elf)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        let mut child = cmd
            .spawn()
            .map_err(|e| io::Error::new(e.kind(), format!("cannot start {QEMU}: {e}")))?;
        // QEMU's and the board's own words (a panic over semihosting) pass
        // through, less QEMU's note that it waits for the UART's client.
        if let Some(err) = child.stderr.take() {
            std::thread::spawn(move || {
                use std::io::BufRead;
                for line in io::BufReader::new(err).lines().map_while(Result::ok) {
                    if !line.contains("QEMU waiting for connection") {
                        eprintln!("{line}");
                    }
                }
            });
        }
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

    /// Waits for QEMU to end by itself (the board's semihosting exit), at
    /// most `timeout`; `Ok(None)` if it still runs then.
    pub fn wait_exit(&mut self, timeout: Duration) -> io::Result<Option<std::process::ExitStatus>> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(status) = self.child.try_wait()? {
                return Ok(Some(status));
            }
            if Instant::now() >= deadline {
                return Ok(None);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
