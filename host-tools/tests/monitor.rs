//! `hammer monitor` and `hammer replay` as a bench engineer uses them: the
//! dashboard runs in a real terminal (tmux, 160×50), keys are typed into it
//! and the screen is read back.
//!
//! The device is either the emulated board (QEMU, for its real handshake,
//! identity and status) or the test itself acting as one on a loopback TCP
//! port (the "peer"): it answers the handshake and sends reports that the
//! estimator computed from a simulated hammer, and it can unplug, come back,
//! and send corrupted or truncated frames on purpose.
//!
//! Needs tmux; the QEMU test needs `qemu-system-arm` and the emulated
//! firmware (`cargo xtask firmware`) and fails, not skips, without them.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Mutex, MutexGuard, OnceLock};
use std::time::{Duration, Instant};

use hammer_sim::estimation::run;
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_wire::*;

/// The longest any single wait in these tests may take.
const T: Duration = Duration::from_secs(20);

// ---------------------------------------------------------------- the data

struct Fixture {
    reports: Vec<CycleReport>,
    config: DeviceConfig,
}

/// Reports of a simulated hammer (5 bar, Coulomb friction), computed once.
fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let mut cfg = SimConfig::nominal(5.0);
        cfg.solver.duration_s = 1.2;
        cfg.seed = 11;
        cfg.effects.apply_spec("coulomb_friction").unwrap();
        let sim = simulate(&cfg).unwrap();
        let est = cfg.estimator_config(None).unwrap();
        let reports: Vec<CycleReport> = run(sim.codes(), est).unwrap().to_vec();
        assert!(reports.len() >= 20, "{} reports", reports.len());
        assert!(reports.iter().all(|r| r.is_valid()), "valid cycles to show");
        Fixture {
            reports,
            config: DeviceConfig::from(&est),
        }
    })
}

/// How the dashboard prints friction and energy (and how a user reads them).
fn friction(r: &CycleReport) -> String {
    format!("{:.2} ± {:.2}", r.friction_n, r.friction_uncertainty_n)
}

fn energy(r: &CycleReport) -> String {
    format!("{:.3} ± {:.3}", r.impact_energy_j, r.impact_energy_uncertainty_j)
}

fn frame(m: &DeviceMsg) -> Vec<u8> {
    let mut buf = [0u8; MAX_FRAME];
    let n = encode(m, &mut buf).unwrap();
    buf[..n].to_vec()
}

// ---------------------------------------------------------------- the peer

/// The test as the device: one accepted connection (or one pty) to the dashboard.
struct Peer<S: Read + Write = TcpStream> {
    stream: S,
    dec: Decoder<MAX_FRAME>,
    hellos: u32,
    /// Bytes written to the dashboard.
    sent: u64,
}

fn listen() -> (TcpListener, u16) {
    let l = TcpListener::bind("127.0.0.1:0").unwrap();
    let port = l.local_addr().unwrap().port();
    (l, port)
}

impl Peer {
    fn accept(l: &TcpListener) -> Peer {
        l.set_nonblocking(true).unwrap();
        let deadline = Instant::now() + T;
        loop {
            match l.accept() {
                Ok((s, _)) => {
                    s.set_nonblocking(false).unwrap();
                    s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
                    s.set_nodelay(true).unwrap();
                    return Peer::new(s);
                }
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {
                    assert!(Instant::now() < deadline, "the dashboard never connected");
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(e) => panic!("accept: {e}"),
            }
        }
    }
}

impl<S: Read + Write> Peer<S> {
    fn new(stream: S) -> Peer<S> {
        Peer {
            stream,
            dec: Decoder::new(),
            hellos: 0,
            sent: 0,
        }
    }

    /// Waits for a command from the dashboard that `want` accepts.
    fn expect(&mut self, what: &str, want: impl Fn(&HostMsg) -> bool) -> HostMsg {
        let deadline = Instant::now() + T;
        let mut buf = [0u8; 512];
        loop {
            assert!(Instant::now() < deadline, "the dashboard never sent {what}");
            match self.stream.read(&mut buf) {
                Ok(0) => panic!("the dashboard closed the link while we waited for {what}"),
                Ok(n) => {
                    for &b in &buf[..n] {
                        if let Some(Ok(m)) = self.dec.push::<HostMsg>(b) {
                            if matches!(m, HostMsg::Hello { .. }) {
                                self.hellos += 1;
                            }
                            if want(&m) {
                                return m;
                            }
                        }
                    }
                }
                Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
                // A pty master reads EIO until the dashboard opens the other end.
                Err(_) => std::thread::sleep(Duration::from_millis(20)),
            }
        }
    }

    /// Answers Hello (as a device of `protocol`) and GetConfig, as the firmware does.
    fn handshake(&mut self, protocol: u16) {
        let m = self.expect("Hello", |m| matches!(m, HostMsg::Hello { .. }));
        assert_eq!(
            m,
            HostMsg::Hello {
                protocol_version: PROTOCOL_VERSION
            }
        );
        let f = fixture();
        if protocol != PROTOCOL_VERSION {
            self.send(&DeviceMsg::Rejected {
                command: CommandKind::Hello,
                reason: RejectReason::ProtocolMismatch { device: protocol },
            });
        }
        self.send(&DeviceMsg::Hello(DeviceInfo {
            protocol_version: protocol,
            firmware_version: [0, 7, 3],
            board: b"bench-peer".iter().copied().collect(),
            config_hash: config_hash(&f.config),
        }));
        if protocol == PROTOCOL_VERSION {
            self.expect("GetConfig", |m| *m == HostMsg::GetConfig);
            self.send(&DeviceMsg::Config(f.config));
        }
    }

    fn send(&mut self, m: &DeviceMsg) {
        self.raw(&frame(m));
    }

    fn raw(&mut self, bytes: &[u8]) {
        self.stream.write_all(bytes).unwrap();
        self.sent += bytes.len() as u64;
    }

    /// Reports at a hammer's pace (about 25 a second).
    fn reports(&mut self, rs: &[CycleReport]) {
        for r in rs {
            self.send(&DeviceMsg::Report(*r));
            std::thread::sleep(Duration::from_millis(40));
        }
    }
}

fn status(cpu_permille: u16, dropped: u64, overruns: u32) -> DeviceMsg {
    DeviceMsg::Status(Status {
        uptime_us: 3_723_000_000,
        samples: 372_300_000,
        dropped_samples: dropped,
        adc_overruns: overruns,
        cycles: 81_000,
        cpu_load_permille: cpu_permille,
        protocol_version: PROTOCOL_VERSION,
        firmware_version: [0, 7, 3],
        config_hash: config_hash(&fixture().config),
        ..Default::default()
    })
}

// ---------------------------------------------------------------- the binary

/// Every process these tests start is spawned under this lock, and a pty is
/// made under it too: its master is inheritable until it is swapped for a
/// close-on-exec copy, and a child that inherited it would keep the
/// "device" plugged in after the test unplugs it.
fn spawning() -> MutexGuard<'static, ()> {
    static SPAWN: Mutex<()> = Mutex::new(());
    SPAWN.lock().unwrap_or_else(|e| e.into_inner())
}

fn spawn(cmd: &mut Command) -> Kill {
    let _g = spawning();
    Kill(cmd.spawn().expect("hammer runs"))
}

fn tmux(socket: &str, args: &[&str]) -> std::process::Output {
    let _g = spawning();
    Command::new("tmux")
        .args(["-L", socket])
        .args(args)
        .env_remove("TMUX")
        .stdin(Stdio::null())
        .output()
        .expect("tmux is needed for the dashboard tests (apt-get install tmux)")
}

fn tmp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hammer-monitor-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn hammer_bin() -> &'static str {
    env!("CARGO_BIN_EXE_hammer")
}

fn hammer(args: &[&str]) -> Command {
    let mut c = Command::new(hammer_bin());
    c.args(args);
    c
}

fn quote(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

/// A child process killed when the test ends, however it ends.
struct Kill(Child);

impl Drop for Kill {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A child's stdout, line by line as it comes.
struct Lines {
    rx: std::sync::mpsc::Receiver<String>,
    seen: Vec<String>,
}

impl Lines {
    fn of(child: &mut Kill) -> Lines {
        let out = child.0.stdout.take().expect("stdout piped");
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            use std::io::BufRead;
            for line in std::io::BufReader::new(out).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        Lines { rx, seen: vec![] }
    }

    /// Waits until `n` lines so far satisfy `pred`.
    #[track_caller]
    fn wait(&mut self, what: &str, n: usize, pred: impl Fn(&str) -> bool) {
        let deadline = Instant::now() + T;
        while self.seen.iter().filter(|l| pred(l)).count() < n {
            let left = deadline.saturating_duration_since(Instant::now());
            match self.rx.recv_timeout(left) {
                Ok(l) => self.seen.push(l),
                Err(_) => panic!("never printed {what}:\n{}", self.seen.join("\n")),
            }
        }
    }

    /// Everything printed, once the child has exited.
    fn rest(mut self) -> String {
        while let Ok(l) = self.rx.recv_timeout(T) {
            self.seen.push(l);
        }
        self.seen.join("\n")
    }
}

/// Reads a child's pipe to its end on a thread of its own.
fn drain<R: Read + Send + 'static>(pipe: Option<R>) -> std::thread::JoinHandle<String> {
    std::thread::spawn(move || {
        let mut s = String::new();
        if let Some(mut p) = pipe {
            let _ = p.read_to_string(&mut s);
        }
        s
    })
}

impl Kill {
    /// Waits for exit; returns (status, stdout, stderr). The pipes are read
    /// while it runs: a child that printed more than a pipe holds (64 KiB,
    /// 400 report lines) would wait on it and never exit.
    fn finish(mut self, timeout: Duration) -> (std::process::ExitStatus, String, String) {
        let deadline = Instant::now() + timeout;
        let (out, err) = (drain(self.0.stdout.take()), drain(self.0.stderr.take()));
        loop {
            if let Some(st) = self.0.try_wait().unwrap() {
                return (st, out.join().unwrap(), err.join().unwrap());
            }
            assert!(Instant::now() < deadline, "hammer did not exit within {timeout:?}");
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

// ---------------------------------------------------------------- the terminal

/// A tmux server of our own (its own socket) with one 160×50 window; killed on drop.
struct Tmux {
    socket: String,
}

impl Tmux {
    fn start(name: &str, args: &[&str]) -> Tmux {
        let socket = format!("hammer-monitor-test-{}-{name}", std::process::id());
        let cmd: Vec<String> = std::iter::once(hammer_bin())
            .chain(args.iter().copied())
            .map(quote)
            .collect();
        let cmd = cmd.join(" ");
        // Keep the pane after exit, to read the exit status and the restored terminal.
        let shell = format!("{cmd}; echo \"EXITED $?\"; sleep 60");
        let out = tmux(
            &socket,
            &[
                "-f",
                "/dev/null",
                "new-session",
                "-d",
                "-s",
                "main",
                "-x",
                "160",
                "-y",
                "50",
                &shell,
            ],
        );
        assert!(
            out.status.success(),
            "tmux new-session: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        Tmux { socket }
    }

    fn screen(&self) -> String {
        String::from_utf8_lossy(&tmux(&self.socket, &["capture-pane", "-p", "-t", "main"]).stdout).into_owned()
    }

    fn keys(&self, keys: &str) {
        assert!(tmux(&self.socket, &["send-keys", "-t", "main", "-l", keys])
            .status
            .success());
    }

    /// Polls the screen until `pred` holds; panics with the last screen after `T`.
    #[track_caller]
    fn wait_for(&self, what: &str, pred: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + T;
        loop {
            let s = self.screen();
            if pred(&s) {
                return s;
            }
            assert!(Instant::now() < deadline, "screen never showed {what}:\n{s}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    #[track_caller]
    fn wait_text(&self, text: &str) -> String {
        self.wait_for(text, |s| s.contains(text))
    }

    /// `q`, then the process must exit 0 and leave the alternate screen.
    fn quit(&self) -> String {
        self.quit_with(0)
    }

    /// `q`, then the process must exit with `code` and leave the alternate screen.
    fn quit_with(&self, code: i32) -> String {
        self.keys("q");
        let s = self.wait_text("EXITED");
        assert!(
            s.contains(&format!("EXITED {code}")),
            "the dashboard did not exit with {code}:\n{s}"
        );
        assert!(!s.contains("Link health"), "the terminal was not restored:\n{s}");
        s
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        tmux(&self.socket, &["kill-server"]);
    }
}

/// The number right after `label` on the screen line that holds it.
fn value_after(screen: &str, label: &str) -> Option<u64> {
    let line = screen.lines().find(|l| l.contains(label))?;
    let rest = line.split(label).nth(1)?;
    rest.split_whitespace().next()?.parse().ok()
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// cycles.csv rows as (seq, friction_n, impact_energy_j).
fn csv_reports(dir: &Path) -> Vec<(u32, f32, f32)> {
    let text = read(&dir.join("cycles.csv"));
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let col = |name: &str| {
        header
            .iter()
            .position(|h| *h == name)
            .unwrap_or_else(|| panic!("no {name} column"))
    };
    let (seq, fr, en, host) = (col("seq"), col("friction_n"), col("impact_energy_j"), col("host_time"));
    assert!(header.contains(&"t_impact_s"));
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            assert_eq!(f.len(), header.len(), "{l}");
            assert!(f[host].ends_with('Z'), "RFC 3339 host time: {l}");
            (f[seq].parse().unwrap(), f[fr].parse().unwrap(), f[en].parse().unwrap())
        })
        .collect()
}

// ---------------------------------------------------------------- tests

#[test]
fn the_dashboard_shows_the_emulated_boards_identity_and_health() {
    let t0 = Instant::now();
    let elf = hammer_host::emulator::firmware_elf();
    assert!(
        elf.exists(),
        "{} is missing: build it with `cargo xtask firmware`",
        elf.display()
    );
    assert!(
        hammer_host::emulator::qemu_available(),
        "{} is missing: install QEMU (apt-get install qemu-system-arm)",
        hammer_host::emulator::QEMU
    );
    let mut emu = {
        let _g = spawning();
        hammer_host::emulator::Emulator::start(&elf, false).expect("QEMU boots the emulated board")
    };
    // Ask the board who it is first, as a plain host tool would.
    let info = {
        let mut info = None;
        for _ in 0..10 {
            let stream = emu.connect(T).expect("the board's UART");
            let mut link = hammer_host::client::Client::new(stream);
            if let Ok((i, _)) = link.handshake(Duration::from_secs(6)) {
                info = Some(i);
            }
            if info.is_some() {
                break;
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        info.expect("the emulated board answers Hello")
    };
    let board = String::from_utf8_lossy(&info.board).into_owned();
    let port = format!("tcp:127.0.0.1:{}", emu.port);
    let tmux = Tmux::start("qemu", &["monitor", "--port", &port]);
    let s = tmux.wait_for("the board's identity and status", |s| {
        s.contains(&board) && s.contains("Device status") && s.contains("connected")
    });
    assert!(s.contains(&format!("{:08x}", info.config_hash)), "config hash:\n{s}");
    let fw = format!(
        "{}.{}.{}",
        info.firmware_version[0], info.firmware_version[1], info.firmware_version[2]
    );
    assert!(
        s.contains(&fw) && s.contains(&format!("protocol {PROTOCOL_VERSION}")),
        "{s}"
    );
    assert!(s.contains("CPU load"), "{s}");
    assert!(
        s.contains("Last reset") && s.contains("power-on"),
        "the reset cause:\n{s}"
    );
    assert!(
        s.contains("S/s"),
        "the configuration (GetConfig) arrived and matches the hash:\n{s}"
    );
    assert_eq!(value_after(&s, "CRC errors"), Some(0), "{s}");
    tmux.quit();
    println!("qemu dashboard test: {:.1} s", t0.elapsed().as_secs_f64());
}

/// The dashboard's current cycle: (cycle number, hammer time in s).
fn current_cycle(screen: &str) -> Option<(u32, f64)> {
    let line = screen.lines().find(|l| l.contains("Cycle ") && l.contains(" t "))?;
    let rest = line.split("Cycle ").nth(1)?;
    let mut words = rest.split_whitespace();
    let cycle = words.next()?.parse().ok()?;
    let t = words.nth(1)?.parse().ok()?;
    Some((cycle, t))
}

#[test]
fn the_demo_dashboard_shows_cycles_at_the_hammers_own_rate() {
    let t0 = Instant::now();
    assert!(
        hammer_host::emulator::qemu_available() && hammer_host::emulator::firmware_elf().exists(),
        "QEMU and the emulated firmware are needed (cargo xtask firmware)"
    );
    // The demo's dashboard: the emulated board sampling at the full rate,
    // held to the host's clock.
    let tmux = Tmux::start("demo-rate", &["demo", "--supply-bar", "4"]);
    let first = tmux.wait_for("a cycle on the dashboard", |s| {
        s.contains("qemu-mps2-an386") && current_cycle(s).is_some_and(|(n, _)| n >= 5)
    });
    let wall = Instant::now();
    let (n0, t0_s) = current_cycle(&first).unwrap();
    std::thread::sleep(Duration::from_secs(3));
    let later = tmux.screen();
    let elapsed = wall.elapsed().as_secs_f64();
    let (n1, t1_s) = current_cycle(&later).expect("still showing cycles");
    tmux.quit();
    // The paper's hammer beats at 21.1 Hz at 4 bar: as many cycles per
    // second of wall time (the screen refreshes, so allow a refresh's slack),
    // and the hammer's clock advances with the wall's.
    let rate = f64::from(n1 - n0) / elapsed;
    assert!((17.0..25.0).contains(&rate), "{rate:.1} cycles/s on the wall clock");
    let pace = (t1_s - t0_s) / elapsed;
    assert!((0.8..1.2).contains(&pace), "hammer time runs at {pace:.2} of wall time");
    assert_eq!(value_after(&later, "Dropped samp."), Some(0), "{later}");
    assert_eq!(value_after(&later, "ADC overruns"), Some(0), "{later}");
    println!(
        "demo dashboard: {rate:.1} cycles/s, hammer pace {pace:.2}; test {:.1} s",
        t0.elapsed().as_secs_f64()
    );
}

#[test]
fn the_dashboard_shows_the_reports_a_device_sends() {
    let t0 = Instant::now();
    let f = fixture();
    let (listener, port) = listen();
    let tmux = Tmux::start("reports", &["monitor", "--port", &format!("tcp:127.0.0.1:{port}")]);
    let mut peer = Peer::accept(&listener);
    peer.handshake(PROTOCOL_VERSION);
    let s = tmux.wait_text("bench-peer");
    assert!(
        s.contains("0.7.3") && s.contains(&format!("{:08x}", config_hash(&f.config))),
        "{s}"
    );
    assert!(s.contains("waiting for the first report"), "{s}");

    let shown = &f.reports[..12];
    peer.reports(shown);
    peer.send(&status(123, 4, 2));
    let last = shown.last().unwrap();
    let s = tmux.wait_for("the last report and the status", |s| {
        s.contains(&format!("Cycle {}", last.seq)) && s.contains("12.3 %")
    });
    assert!(
        s.contains(&friction(last)),
        "friction {} on screen:\n{s}",
        friction(last)
    );
    assert!(s.contains(&energy(last)), "energy {} on screen:\n{s}", energy(last));
    let nf = format!(
        "{:.3} ± {:.3}",
        last.impact_energy_frictionless_j, last.impact_energy_frictionless_uncertainty_j
    );
    assert!(s.contains(&nf), "energy without friction {nf}:\n{s}");
    assert!(s.contains(&format!("{:.2}", last.frequency_hz)), "{s}");
    assert_eq!(value_after(&s, "Dropped samp."), Some(4), "{s}");
    assert_eq!(value_after(&s, "ADC overruns"), Some(2), "{s}");
    assert_eq!(value_after(&s, "Seq gaps"), Some(0), "{s}");
    assert!(value_after(&s, "Frames").unwrap() >= 14, "{s}");
    for title in ["Friction (N)", "Impact energy (J)", "Frequency (Hz)"] {
        assert!(s.contains(title), "{title} chart:\n{s}");
    }
    // The latest report's chambers, which the estimator alone leaves unread.
    assert!(s.contains(&format!("Chambers, cycle {}", last.seq)), "{s}");
    assert_eq!(s.matches("n/a (unread)").count(), 6, "{s}");

    // Pause: the view holds still while reports go on arriving.
    tmux.keys("p");
    tmux.wait_text("PAUSED");
    let next = &f.reports[12];
    peer.send(&DeviceMsg::Report(*next));
    let s = tmux.wait_text("PAUSED (1 new reports");
    assert!(s.contains(&format!("Cycle {}", last.seq)), "{s}");
    tmux.keys("p");
    let s = tmux.wait_text(&format!("Cycle {}", next.seq));
    assert!(!s.contains("PAUSED"), "{s}");
    assert!(s.contains(&friction(next)), "{s}");

    // An alarm shows as a banner until cleared.
    peer.send(&DeviceMsg::Alarm(Alarm {
        kind: AlarmKind::DriftOn,
        cycle_seq: next.seq,
        flags: Flags(1 << 13),
        drift_score: 6.5,
    }));
    tmux.wait_text("DRIFT ALARM since cycle");
    tmux.keys("c");
    tmux.wait_for("the banner cleared", |s| !s.contains("DRIFT ALARM since"));

    tmux.keys("?");
    tmux.wait_text("Help (? closes)");
    tmux.keys("?");
    tmux.wait_for("help closed", |s| !s.contains("Help (? closes)"));
    tmux.quit();
    println!("reports dashboard test: {:.1} s", t0.elapsed().as_secs_f64());
}

#[test]
fn unplugging_the_device_reconnects_and_logs_the_gap() {
    let t0 = Instant::now();
    let f = fixture();
    let dir = tmp_dir("unplug");
    let (listener, port) = listen();
    let spec = format!("tcp:127.0.0.1:{port}");
    let tmux = Tmux::start("unplug", &["monitor", "--port", &spec, "--log", dir.to_str().unwrap()]);
    let mut peer = Peer::accept(&listener);
    peer.handshake(PROTOCOL_VERSION);
    peer.reports(&f.reports[..5]);
    tmux.wait_text(&format!("Cycle {}", f.reports[4].seq));

    // Unplug: the port is gone for a second.
    drop(peer);
    drop(listener);
    let s = tmux.wait_text("LINK DOWN since");
    assert!(s.contains("disconnected"), "{s}");
    std::thread::sleep(Duration::from_secs(1));
    let listener = TcpListener::bind(("127.0.0.1", port)).expect("the same port again");
    let mut peer = Peer::accept(&listener);
    peer.handshake(PROTOCOL_VERSION);
    assert!(peer.hellos >= 1, "a fresh handshake on the new link");
    // Reports 5..8 were lost while unplugged.
    peer.reports(&f.reports[8..12]);
    let s = tmux.wait_text(&format!("Cycle {}", f.reports[11].seq));
    assert_eq!(value_after(&s, "Reconnects"), Some(1), "{s}");
    assert_eq!(value_after(&s, "Seq gaps"), Some(1), "{s}");
    assert_eq!(value_after(&s, "Lost reports"), Some(3), "{s}");
    assert!(s.contains("reconnected to"), "{s}");
    assert!(!s.contains("LINK DOWN"), "{s}");
    tmux.quit();

    let log = read(&dir.join("link.log"));
    let disc = log
        .lines()
        .find(|l| l.contains("disconnected from"))
        .expect("disconnect logged");
    let rec = log
        .lines()
        .find(|l| l.contains("reconnected to"))
        .expect("reconnect logged");
    assert!(disc.contains(&spec), "{log}");
    // "... link was down 1.234 s, from <RFC 3339> to <RFC 3339>"
    let down: f64 = rec
        .split("link was down ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!((0.9..10.0).contains(&down), "outage {down} s: {rec}");
    assert_eq!(
        rec.matches('Z').count(),
        3,
        "timestamps of the line, the disconnect and the reconnect: {rec}"
    );
    assert!(log.contains("report sequence gap: expected 5, got 8 (3 lost)"), "{log}");
    let rows = csv_reports(&dir);
    let seqs: Vec<u32> = rows.iter().map(|r| r.0).collect();
    assert_eq!(seqs, [0, 1, 2, 3, 4, 8, 9, 10, 11]);
    for (seq, fr, en) in rows {
        let r = &f.reports[seq as usize];
        assert_eq!(
            (fr, en),
            (r.friction_n, r.impact_energy_j),
            "cycles.csv keeps full precision"
        );
    }
    println!("unplug test: {:.1} s", t0.elapsed().as_secs_f64());
}

/// Bytes the reference decoder counts as `kind`.
fn classify(bytes: &[u8]) -> Vec<DecodeError> {
    let mut d = Decoder::<MAX_FRAME>::new();
    bytes
        .iter()
        .filter_map(|&b| d.push::<DeviceMsg>(b))
        .filter_map(|r| r.err())
        .collect()
}

#[test]
fn corrupted_and_truncated_frames_are_counted_never_shown() {
    let t0 = Instant::now();
    let f = fixture();
    let dir = tmp_dir("corrupt");
    let (listener, port) = listen();
    let tmux = Tmux::start(
        "corrupt",
        &[
            "monitor",
            "--port",
            &format!("tcp:127.0.0.1:{port}"),
            "--log",
            dir.to_str().unwrap(),
        ],
    );
    let mut peer = Peer::accept(&listener);
    peer.handshake(PROTOCOL_VERSION);
    peer.reports(&f.reports[..2]);

    // Poisoned reports whose numbers must never appear anywhere.
    let poison = |friction_n: f32| {
        DeviceMsg::Report(CycleReport {
            seq: 2,
            friction_n,
            friction_uncertainty_n: 0.5,
            ..f.reports[2]
        })
    };
    // One flipped bit in the middle: a CRC mismatch.
    let mut corrupted = frame(&poison(987.65));
    let mid = (corrupted.len() / 2..corrupted.len() - 1)
        .find(|&i| corrupted[i] ^ 0x04 != 0 && classify(&flip(&corrupted, i)) == [DecodeError::Crc])
        .expect("a byte whose flip only breaks the CRC");
    corrupted = flip(&corrupted, mid);
    // Cut short: the rest of the frame never came, the delimiter did.
    let whole = frame(&poison(876.54));
    let cut = (4..whole.len() - 1)
        .find(|&n| classify(&[&whole[..n], &[0]].concat()) == [DecodeError::Cobs])
        .expect("a cut that breaks COBS");
    let truncated = [&whole[..cut], &[0]].concat();
    assert_eq!(classify(&corrupted), [DecodeError::Crc]);
    assert_eq!(classify(&truncated), [DecodeError::Cobs]);
    peer.raw(&corrupted);
    peer.raw(&truncated);
    peer.raw(&corrupted);
    // Line noise with no delimiter for longer than any frame.
    peer.raw(&[0x55; 1000]);
    peer.raw(&[0]);
    peer.reports(&f.reports[2..6]);

    let last = &f.reports[5];
    let s = tmux.wait_text(&format!("Cycle {}", last.seq));
    assert_eq!(value_after(&s, "CRC errors"), Some(2), "{s}");
    assert_eq!(value_after(&s, "COBS errors"), Some(1), "{s}");
    assert_eq!(value_after(&s, "Oversize"), Some(1), "{s}");
    assert_eq!(
        value_after(&s, "Seq gaps"),
        Some(0),
        "a bad frame is not a lost report:\n{s}"
    );
    assert!(s.contains("frame error: CRC mismatch"), "{s}");
    assert!(s.contains(&friction(last)), "{s}");
    for bad in ["987.65", "876.54"] {
        assert!(!s.contains(bad), "{bad} shown:\n{s}");
    }
    tmux.quit();

    let log = read(&dir.join("link.log"));
    assert_eq!(log.matches("frame error: CRC mismatch").count(), 2, "{log}");
    assert_eq!(log.matches("frame error: bad COBS").count(), 1, "{log}");
    assert_eq!(log.matches("frame error: oversize").count(), 1, "{log}");
    let csv = read(&dir.join("cycles.csv"));
    for bad in ["987.65", "876.54"] {
        assert!(!csv.contains(bad), "{bad} logged as data:\n{csv}");
    }
    assert_eq!(
        csv_reports(&dir).iter().map(|r| r.0).collect::<Vec<_>>(),
        [0, 1, 2, 3, 4, 5]
    );
    println!("corruption test: {:.1} s", t0.elapsed().as_secs_f64());
}

fn flip(bytes: &[u8], i: usize) -> Vec<u8> {
    let mut b = bytes.to_vec();
    b[i] ^= 0x04;
    b
}

/// The report lines of headless output (`cycle N ...`).
fn report_lines(out: &str) -> Vec<&str> {
    out.lines().filter(|l| l.starts_with("cycle ")).collect()
}

#[test]
fn replay_reproduces_the_logged_reports() {
    let t0 = Instant::now();
    let f = fixture();
    let dir = tmp_dir("replay");
    let (listener, port) = listen();
    let n = 15;
    let live = spawn(
        hammer(&[
            "monitor",
            "--port",
            &format!("tcp:127.0.0.1:{port}"),
            "--log",
            dir.to_str().unwrap(),
            "--headless",
            "--exit-after-reports",
            &n.to_string(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped()),
    );
    let mut peer = Peer::accept(&listener);
    peer.handshake(PROTOCOL_VERSION);
    peer.send(&status(50, 0, 0));
    peer.reports(&f.reports[..7]);
    let mut bad = frame(&DeviceMsg::Report(f.reports[7]));
    let i = bad.len() / 2;
    bad[i] = bad[i].wrapping_add(1).max(1);
    peer.raw(&bad);
    peer.reports(&f.reports[7..n]);
    let (st, out, err) = live.finish(T);
    assert!(st.success(), "{err}\n{out}");
    let live_lines = report_lines(&out);
    assert_eq!(live_lines.len(), n, "{out}");
    for (line, r) in live_lines.iter().zip(&f.reports) {
        assert!(line.starts_with(&format!("cycle {:>6}  ", r.seq)), "{line}");
        assert!(line.contains(&format!("friction {} N", friction(r))), "{line}");
        assert!(line.contains(&format!("energy {} J", energy(r))), "{line}");
    }
    assert!(out.contains("connected to tcp:"), "{out}");
    assert!(out.contains("device: board bench-peer"), "{out}");

    // The documented frames.bin format: magic, then [u64 t_us][u32 len][bytes].
    let bin = std::fs::read(dir.join("frames.bin")).unwrap();
    assert_eq!(&bin[..8], b"HMFRAMES");
    let (mut at, mut payload, mut markers, mut times) = (8, vec![], 0, vec![]);
    while at < bin.len() {
        let t = u64::from_le_bytes(bin[at..at + 8].try_into().unwrap());
        let len = u32::from_le_bytes(bin[at + 8..at + 12].try_into().unwrap());
        at += 12;
        times.push(t);
        if len >= 0xFFFF_FFFE {
            markers += 1;
        } else {
            payload.extend_from_slice(&bin[at..at + len as usize]);
            at += len as usize;
        }
    }
    assert!(markers >= 1, "a connect marker");
    assert!(times.windows(2).all(|w| w[0] <= w[1]), "host times in order");
    let decoded: Vec<CycleReport> = {
        let mut d = Decoder::<MAX_FRAME>::new();
        payload
            .iter()
            .filter_map(|&b| d.push::<DeviceMsg>(b))
            .filter_map(|m| match m {
                Ok(DeviceMsg::Report(r)) => Some(r),
                _ => None,
            })
            .collect()
    };
    assert_eq!(decoded, f.reports[..n], "frames.bin holds the bytes that came");
    let recorded_s = (times.last().unwrap() - times[0]) as f64 * 1e-6;

    let replay = |speed: &str| {
        let started = Instant::now();
        let r = spawn(
            hammer(&[
                "replay",
                dir.join("frames.bin").to_str().unwrap(),
                "--headless",
                "--speed",
                speed,
            ])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped()),
        );
        let (st, out, err) = r.finish(T);
        // The recording holds the corrupted frame: shown, then a failure that names it.
        assert_eq!(st.code(), Some(2), "{err}\n{out}");
        assert!(err.contains("damaged recording: 1 bad frame ("), "{err}");
        (out, started.elapsed().as_secs_f64())
    };
    let (fast, fast_s) = replay("0");
    assert_eq!(
        report_lines(&fast),
        live_lines,
        "replay prints what the live run printed"
    );
    assert!(
        fast.contains("frame error: CRC mismatch") || fast.contains("frame error: bad COBS"),
        "{fast}"
    );
    assert!(fast.contains("end of recording"), "{fast}");
    let (paced, paced_s) = replay("2");
    assert_eq!(report_lines(&paced), live_lines);
    assert!(
        paced_s >= recorded_s / 2.0 * 0.9,
        "--speed 2 of a {recorded_s:.2} s recording took {paced_s:.2} s"
    );

    // The dashboard too (given the log directory), as fast as it goes.
    let tmux = Tmux::start("replay", &["replay", dir.to_str().unwrap(), "--speed", "0"]);
    let s = tmux.wait_text("END OF RECORDING");
    let last = &f.reports[n - 1];
    assert!(s.contains(&format!("Cycle {}", last.seq)), "{s}");
    assert!(s.contains(&friction(last)) && s.contains(&energy(last)), "{s}");
    assert!(s.contains("hammer replay") && s.contains("bench-peer"), "{s}");
    let errors = value_after(&s, "CRC errors").unwrap() + value_after(&s, "COBS errors").unwrap();
    assert_eq!(errors, 1, "{s}");
    assert_eq!(value_after(&s, "Seq gaps"), Some(0), "{s}");
    let s = tmux.quit_with(2);
    assert!(s.contains("damaged recording: 1 bad frame"), "{s}");
    println!(
        "replay test: {:.1} s (recording {recorded_s:.2} s, replay at speed 0 {fast_s:.2} s, at speed 2 {paced_s:.2} s)",
        t0.elapsed().as_secs_f64()
    );
}

/// A flood of reports into logs capped at 30 kB: logging stops at the cap,
/// says so, and every received byte and report is logged or counted.
#[test]
fn the_log_size_cap_stops_logging_visibly_and_counts_what_it_kept_out() {
    let f = fixture();
    let dir = tmp_dir("log-cap");
    let (listener, port) = listen();
    let n = 400;
    let child = spawn(
        hammer(&[
            "monitor",
            "--port",
            &format!("tcp:127.0.0.1:{port}"),
            "--log",
            dir.to_str().unwrap(),
            "--log-max-mb",
            "0.03",
            "--headless",
            "--exit-after-reports",
            &n.to_string(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped()),
    );
    let mut peer = Peer::accept(&listener);
    peer.handshake(PROTOCOL_VERSION);
    for seq in 0..n {
        let r = f.reports[seq as usize % f.reports.len()];
        peer.send(&DeviceMsg::Report(CycleReport { seq, ..r }));
    }
    let (st, out, err) = child.finish(T);
    assert!(st.success(), "{err}\n{out}");
    assert_eq!(report_lines(&out).len(), n as usize, "{out}");
    assert!(
        out.contains("logging stopped: the logs reached their size cap of 0.03 MB"),
        "{out}"
    );
    assert!(out.contains("not logged (log size cap reached): "), "{out}");

    let link = read(&dir.join("link.log"));
    assert!(
        link.contains("logging stopped: the logs reached their size cap"),
        "{link}"
    );
    let last = link.lines().last().unwrap();
    let counts: Vec<u64> = last
        .split_once("not logged after the size cap: ")
        .unwrap_or_else(|| panic!("no final count: {link}"))
        .1
        .split(", ")
        .map(|p| p.split(' ').next().unwrap().parse().unwrap())
        .collect();
    let (unlogged_bytes, unlogged_reports) = (counts[0], counts[1]);
    assert!(unlogged_reports > 0, "{link}");
    assert_eq!(
        csv_reports(&dir).len() as u64 + unlogged_reports,
        u64::from(n),
        "every report is in cycles.csv or counted"
    );
    let bin = std::fs::read(dir.join("frames.bin")).unwrap();
    let (mut at, mut logged) = (8, 0u64);
    while at < bin.len() {
        let len = u32::from_le_bytes(bin[at + 8..at + 12].try_into().unwrap());
        at += 12;
        if len < 0xFFFF_FFFE {
            at += len as usize;
            logged += u64::from(len);
        }
    }
    assert_eq!(
        logged + unlogged_bytes,
        peer.sent,
        "every received byte is in frames.bin or counted"
    );
    let total: u64 = ["frames.bin", "cycles.csv", "link.log"]
        .iter()
        .map(|f| std::fs::metadata(dir.join(f)).unwrap().len())
        .sum();
    assert!(total <= 30_000 + 600, "{total} bytes of logs under a 30 kB cap");
}

/// A headless monitor says when reports stop (link alive, then silent) and
/// when they come back, once each.
#[test]
fn a_headless_monitor_says_when_reports_stall_and_resume() {
    let f = fixture();
    let (listener, port) = listen();
    let mut child = spawn(
        hammer(&[
            "monitor",
            "--port",
            &format!("tcp:127.0.0.1:{port}"),
            "--headless",
            "--exit-after-reports",
            "6",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped()),
    );
    let mut lines = Lines::of(&mut child);
    let mut peer = Peer::accept(&listener);
    peer.handshake(PROTOCOL_VERSION);
    peer.reports(&f.reports[..3]);
    // Status only, for 1.8 s: the link is alive, the hammer is not.
    for _ in 0..6 {
        peer.send(&status(10, 0, 0));
        std::thread::sleep(Duration::from_millis(300));
    }
    lines.wait("the stall", 1, |l| l.contains("stall: no reports"));
    // Then nothing at all.
    std::thread::sleep(Duration::from_millis(1600));
    peer.reports(&f.reports[3..6]);
    let (st, _, err) = child.finish(T);
    let out = lines.rest();
    assert!(st.success(), "{err}\n{out}");
    let at = |pred: &dyn Fn(&str) -> bool| -> Vec<usize> {
        out.lines()
            .enumerate()
            .filter(|(_, l)| pred(l))
            .map(|(i, _)| i)
            .collect()
    };
    let alive = at(&|l| l.contains("stall: no reports") && l.contains("link alive"));
    let silent = at(&|l| l.contains("stall: no reports") && l.contains("no frames at all"));
    let resumed = at(&|l| l.contains("reports resumed after"));
    let cycle = |seq: u32| at(&|l| l.starts_with(&format!("cycle {seq:>6} ")))[0];
    assert_eq!((alive.len(), silent.len(), resumed.len()), (1, 1, 1), "{out}");
    assert!(cycle(f.reports[2].seq) < alive[0], "{out}");
    assert!(alive[0] < silent[0] && silent[0] < resumed[0], "{out}");
    assert!(resumed[0] < cycle(f.reports[4].seq), "{out}");
}

#[test]
fn a_device_of_another_protocol_is_named_and_not_read() {
    let dir = tmp_dir("mismatch");
    let (listener, port) = listen();
    let child = spawn(
        hammer(&[
            "monitor",
            "--port",
            &format!("tcp:127.0.0.1:{port}"),
            "--headless",
            "--log",
            dir.to_str().unwrap(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped()),
    );
    let mut peer = Peer::accept(&listener);
    peer.handshake(PROTOCOL_VERSION + 1);
    // The monitor may be gone already.
    let _ = peer.stream.write_all(&frame(&DeviceMsg::Report(fixture().reports[0])));
    let (st, out, err) = child.finish(T);
    assert!(!st.success(), "{out}");
    assert!(err.contains("protocol mismatch"), "{err}");
    assert!(out.contains("PROTOCOL MISMATCH"), "{out}");
    assert!(report_lines(&out).is_empty(), "{out}");
    assert!(read(&dir.join("link.log")).contains("PROTOCOL MISMATCH"));
    assert_eq!(csv_reports(&dir).len(), 0);
}

/// The library entry point the demo uses, with a connector of its own.
#[test]
fn run_with_takes_any_connector() {
    struct Loopback(u16, u32);
    impl hammer_host::monitor::Connector for Loopback {
        fn connect(&mut self) -> std::io::Result<Box<dyn hammer_host::monitor::Port>> {
            self.1 += 1;
            let s = TcpStream::connect(("127.0.0.1", self.0))?;
            s.set_read_timeout(Some(Duration::from_millis(50)))?;
            Ok(Box::new(s))
        }
        fn describe(&self) -> String {
            format!("loopback {} (try {})", self.0, self.1)
        }
    }
    let dir = tmp_dir("run-with");
    let (listener, port) = listen();
    let args = hammer_host::monitor::MonitorArgs {
        log: Some(dir.clone()),
        headless: true,
        exit_after_reports: Some(3),
        ..Default::default()
    };
    let monitor = std::thread::spawn(move || hammer_host::monitor::run_with(Box::new(Loopback(port, 0)), &args));
    let mut peer = Peer::accept(&listener);
    peer.handshake(PROTOCOL_VERSION);
    peer.reports(&fixture().reports[..3]);
    let deadline = Instant::now() + T;
    while !monitor.is_finished() {
        assert!(Instant::now() < deadline, "run_with did not return after 3 reports");
        std::thread::sleep(Duration::from_millis(20));
    }
    monitor.join().unwrap().unwrap();
    assert_eq!(csv_reports(&dir).len(), 3);
    assert!(read(&dir.join("link.log")).contains("connected to loopback"));
}

/// A serial port as the dashboard meets it: a pty behind a
/// /dev/serial/by-id-style link, unplugged (the pty closes) and plugged in
/// again (a new pty behind the same link).
#[test]
fn a_serial_port_survives_replugging() {
    use serialport::{SerialPort, TTYPort};
    let t0 = Instant::now();
    let f = fixture();
    let dir = tmp_dir("serial");
    let by_id = dir.join("usb-STMicroelectronics_STLINK-V3_0042-if02");
    let plug = || {
        use std::os::fd::{AsRawFd, BorrowedFd, FromRawFd, IntoRawFd};
        let _g = spawning();
        let (master, slave) = TTYPort::pair().expect("a pty pair");
        let name = slave.name().expect("the pty's name");
        drop(slave);
        // SAFETY: the fd is open (owned by `master`) for the duration of the borrow.
        let copy = unsafe { BorrowedFd::borrow_raw(master.as_raw_fd()) }
            .try_clone_to_owned()
            .expect("a close-on-exec copy of the pty master");
        drop(master);
        // SAFETY: `copy` is an open fd that nothing else owns.
        let master = unsafe { TTYPort::from_raw_fd(copy.into_raw_fd()) };
        let _ = std::fs::remove_file(&by_id);
        std::os::unix::fs::symlink(&name, &by_id).unwrap();
        Peer::new(master)
    };
    let mut peer = plug();
    let mut child = spawn(
        hammer(&[
            "monitor",
            "--port",
            by_id.to_str().unwrap(),
            "--headless",
            "--exit-after-reports",
            "6",
            "--log",
            dir.join("log").to_str().unwrap(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped()),
    );
    let mut lines = Lines::of(&mut child);
    peer.handshake(PROTOCOL_VERSION);
    peer.reports(&f.reports[..3]);
    // Unplugged only once the monitor has read them (a hangup discards unread bytes).
    lines.wait("3 reports", 3, |l| l.starts_with("cycle "));
    drop(peer);
    std::thread::sleep(Duration::from_millis(700));
    let mut peer = plug();
    peer.handshake(PROTOCOL_VERSION);
    peer.reports(&f.reports[3..6]);
    let (st, _, err) = child.finish(T);
    let out = lines.rest();
    assert!(st.success(), "{err}\n{out}");
    let lines = report_lines(&out);
    assert_eq!(lines.len(), 6, "{out}");
    for (line, r) in lines.iter().zip(&f.reports) {
        assert!(line.contains(&friction(r)), "{line}");
    }
    let by_id = by_id.display().to_string();
    assert!(out.contains(&format!("disconnected from {by_id}")), "{out}");
    assert!(out.contains(&format!("reconnected to {by_id} (reconnect 1)")), "{out}");
    assert_eq!(csv_reports(&dir.join("log")).len(), 6);
    println!("serial test: {:.1} s", t0.elapsed().as_secs_f64());
}

/// `hammer demo --devices 2`: a summary row per board above the current
/// board's dashboard; Tab shows the other. The 7-bar board's friction is the
/// larger, as the paper's (10.27 N at 4 bar, 16.7 N at 7).
#[test]
fn the_fleet_dashboard_shows_each_board_and_switches_between_them() {
    assert!(
        hammer_host::emulator::qemu_available() && hammer_host::emulator::firmware_elf().exists(),
        "QEMU and the emulated firmware are needed (cargo xtask firmware)"
    );
    let tmux = Tmux::start("fleet", &["demo", "--devices", "2"]);
    let friction = |s: &str, device: &str| -> Option<f64> {
        let row = s.lines().find(|l| l.contains(device) && l.contains(" up "))?;
        let w: Vec<&str> = row.split_whitespace().collect();
        w.iter()
            .position(|x| *x == "friction")
            .and_then(|i| w[i + 1].parse().ok())
    };
    let s = tmux.wait_for("both boards up with a cycle", |s| {
        s.contains("fleet: 2 devices") && friction(s, "demo1-4.0bar").is_some() && friction(s, "demo2-7.0bar").is_some()
    });
    assert!(s.contains("> demo1-4.0bar"), "the first board is shown first:\n{s}");
    assert!(s.contains("Link health"), "its dashboard is below:\n{s}");
    let (f4, f7) = (
        friction(&s, "demo1-4.0bar").unwrap(),
        friction(&s, "demo2-7.0bar").unwrap(),
    );
    assert!(
        (f4 - 10.27).abs() < 2.0 && (f7 - 16.7).abs() < 2.5,
        "{f4} N, {f7} N:\n{s}"
    );
    tmux.keys("\t");
    tmux.wait_text("> demo2-7.0bar");
    tmux.quit();
}

/// A stream whose sequence runs backwards "restarts" at every report: the
/// headless output and link.log say so a few times a second, then how many
/// they did not list, instead of a line per report.
#[test]
fn a_sequence_running_backwards_is_reported_a_few_times_not_per_report() {
    let f = fixture();
    let dir = tmp_dir("seq-backwards");
    let (listener, port) = listen();
    let mut child = spawn(
        hammer(&[
            "monitor",
            "--port",
            &format!("tcp:127.0.0.1:{port}"),
            "--headless",
            "--exit-after-reports",
            "201",
            "--log",
            dir.to_str().unwrap(),
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped()),
    );
    let lines = Lines::of(&mut child);
    let mut peer = Peer::accept(&listener);
    peer.handshake(PROTOCOL_VERSION);
    let backwards = |seq: u32| CycleReport { seq, ..f.reports[0] };
    // 200 reports in one burst, each a step back.
    let burst: Vec<u8> = (0..200)
        .flat_map(|k| frame(&DeviceMsg::Report(backwards(1000 - k))))
        .collect();
    peer.raw(&burst);
    // A second later, one more: its line says how many were not listed.
    std::thread::sleep(Duration::from_millis(1100));
    peer.reports(&[backwards(800)]);
    let (st, _, err) = child.finish(T);
    let out = lines.rest();
    assert!(st.success(), "{err}\n{out}");
    let restarts = out.lines().filter(|l| l.contains("sequence restarted")).count();
    assert!((2..=11).contains(&restarts), "{restarts} lines:\n{out}");
    let held: u64 = out
        .lines()
        .filter_map(|l| {
            l.split(" [")
                .nth(1)?
                .strip_suffix(" more not listed]")?
                .parse::<u64>()
                .ok()
        })
        .sum();
    assert_eq!(held + restarts as u64, 200, "every restart listed or counted:\n{out}");
    let log = read(&dir.join("link.log"));
    let logged = log.lines().filter(|l| l.contains("sequence restarted")).count();
    assert!(logged <= 21, "{logged} in link.log:\n{log}");
    assert!(log.contains("more sequence gaps or restarts not listed"), "{log}");
    let _ = std::fs::remove_dir_all(&dir);
}
