//! Opening the link: a serial port (named or found), or the emulated board's
//! TCP socket. Each connector can be asked again after the link dropped.

use std::io;
use std::net::{TcpStream, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Result};

use super::{Connector, Port};

/// The reference board's virtual COM port runs at this rate.
pub const BAUD: u32 = 921_600;
/// Short, so the reader thread resends a handshake and sees a stop request promptly.
pub const READ_TIMEOUT: Duration = Duration::from_millis(50);
/// A device that stops reading must not hang the reader for long.
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(1);
const TCP_CONNECT_TIMEOUT: Duration = Duration::from_secs(1);

/// `auto`, `tcp:HOST:PORT`, or a serial port path. Only the spelling is
/// checked here: a device that is not plugged in yet is waited for.
pub fn connector_for(spec: &str) -> Result<Box<dyn Connector>> {
    let spec = spec.trim();
    if spec.is_empty() {
        bail!("empty port: give a serial port (/dev/ttyACM0), `auto` or tcp:HOST:PORT");
    }
    if spec == "auto" {
        return Ok(Box::new(AutoConnector::new("/dev")));
    }
    if let Some(rest) = spec.strip_prefix("tcp:") {
        let Some((host, port)) = rest.rsplit_once(':') else {
            bail!("`{spec}`: expected tcp:HOST:PORT, e.g. tcp:127.0.0.1:4567");
        };
        let host = host.trim_start_matches('[').trim_end_matches(']');
        if host.is_empty() {
            bail!("`{spec}`: no host; expected tcp:HOST:PORT");
        }
        let Ok(port) = port.parse::<u16>() else {
            bail!("`{spec}`: `{port}` is not a TCP port number");
        };
        if port == 0 {
            bail!("`{spec}`: port 0 is not a port to connect to");
        }
        return Ok(Box::new(TcpConnector {
            host: host.to_string(),
            port,
        }));
    }
    Ok(Box::new(SerialConnector { path: spec.into() }))
}

/// The emulated board's UART (QEMU `-serial tcp:...,server=on`) or any TCP peer.
pub struct TcpConnector {
    pub host: String,
    pub port: u16,
}

impl Connector for TcpConnector {
    fn connect(&mut self) -> io::Result<Box<dyn Port>> {
        let mut last = None;
        for addr in (self.host.as_str(), self.port).to_socket_addrs()? {
            match TcpStream::connect_timeout(&addr, TCP_CONNECT_TIMEOUT) {
                Ok(s) => {
                    s.set_nodelay(true)?;
                    s.set_read_timeout(Some(READ_TIMEOUT))?;
                    s.set_write_timeout(Some(WRITE_TIMEOUT))?;
                    return Ok(Box::new(s));
                }
                Err(e) => last = Some(e),
            }
        }
        Err(last.unwrap_or_else(|| io::Error::new(io::ErrorKind::NotFound, "host has no address")))
    }

    fn describe(&self) -> String {
        if self.host.contains(':') {
            format!("tcp:[{}]:{}", self.host, self.port)
        } else {
            format!("tcp:{}:{}", self.host, self.port)
        }
    }
}

/// One named serial port. A `/dev/serial/by-id/...` name survives replugging
/// into another USB socket; `/dev/ttyACM0` may come back as `ttyACM1`.
pub struct SerialConnector {
    pub path: PathBuf,
}

impl Connector for SerialConnector {
    fn connect(&mut self) -> io::Result<Box<dyn Port>> {
        open_serial(&self.path)
    }

    fn describe(&self) -> String {
        self.path.display().to_string()
    }
}

fn open_serial(path: &Path) -> io::Result<Box<dyn Port>> {
    let port = serialport::new(path.to_string_lossy(), BAUD)
        .timeout(READ_TIMEOUT)
        .open()
        .map_err(|e| io::Error::new(io::Error::from(e.clone()).kind(), format!("{}: {e}", path.display())))?;
    Ok(Box::new(port))
}

/// `--port auto`: the device used last, else the first serial port that opens.
pub struct AutoConnector {
    dev: PathBuf,
    current: Option<PathBuf>,
}

impl AutoConnector {
    /// `dev` is `/dev` except in tests.
    pub fn new(dev: impl Into<PathBuf>) -> Self {
        Self {
            dev: dev.into(),
            current: None,
        }
    }
}

impl Connector for AutoConnector {
    fn connect(&mut self) -> io::Result<Box<dyn Port>> {
        let mut candidates = scan_serial_ports(&self.dev);
        if let Some(cur) = &self.current {
            if let Some(i) = candidates.iter().position(|c| c == cur) {
                let c = candidates.remove(i);
                candidates.insert(0, c);
            }
        }
        if candidates.is_empty() {
            return Err(io::Error::new(
                io::ErrorKind::NotFound,
                format!(
                    "no serial port found (looked for {0}/serial/by-id/*, {0}/ttyACM*, {0}/ttyUSB*)",
                    self.dev.display()
                ),
            ));
        }
        let mut last = None;
        for c in candidates {
            match open_serial(&c) {
                Ok(p) => {
                    self.current = Some(c);
                    return Ok(p);
                }
                Err(e) => last = Some(e),
            }
        }
        Err(last.unwrap_or_else(|| io::Error::other("no serial port opened")))
    }

    fn describe(&self) -> String {
        match &self.current {
            Some(p) => format!("auto ({})", p.display()),
            None => "auto".into(),
        }
    }
}

/// Serial ports under `dev`, most specific first: `serial/by-id/*` (stable
/// names with the vendor and serial number), then `ttyACM*` (CDC-ACM: the
/// ST-LINK virtual COM port) and `ttyUSB*` (USB-serial adapters) not already
/// named by an id link. Without libudev: only what the directory shows.
pub fn scan_serial_ports(dev: &Path) -> Vec<PathBuf> {
    let mut out: Vec<PathBuf> = vec![];
    let mut targets: Vec<PathBuf> = vec![];
    if let Ok(rd) = std::fs::read_dir(dev.join("serial/by-id")) {
        let mut ids: Vec<PathBuf> = rd.filter_map(|e| e.ok()).map(|e| e.path()).collect();
        ids.sort();
        for p in ids {
            if let Ok(t) = std::fs::canonicalize(&p) {
                targets.push(t);
            }
            out.push(p);
        }
    }
    let mut ttys: Vec<(u8, u32, PathBuf)> = vec![];
    if let Ok(rd) = std::fs::read_dir(dev) {
        for e in rd.filter_map(|e| e.ok()) {
            let name = e.file_name();
            let name = name.to_string_lossy();
            for (rank, prefix) in [(0u8, "ttyACM"), (1, "ttyUSB")] {
                if let Some(n) = name.strip_prefix(prefix).and_then(|n| n.parse::<u32>().ok()) {
                    ttys.push((rank, n, e.path()));
                }
            }
        }
    }
    ttys.sort();
    for (_, _, p) in ttys {
        let canon = std::fs::canonicalize(&p).unwrap_or_else(|_| p.clone());
        if !targets.contains(&canon) {
            out.push(p);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_or_explain() {
        assert_eq!(
            connector_for("tcp:127.0.0.1:4567").unwrap().describe(),
            "tcp:127.0.0.1:4567"
        );
        assert_eq!(connector_for("tcp:[::1]:80").unwrap().describe(), "tcp:[::1]:80");
        assert_eq!(connector_for("/dev/ttyACM3").unwrap().describe(), "/dev/ttyACM3");
        assert_eq!(connector_for("auto").unwrap().describe(), "auto");
        for bad in [
            "",
            "tcp:",
            "tcp:host",
            "tcp::80",
            "tcp:h:port",
            "tcp:h:0",
            "tcp:h:70000",
        ] {
            assert!(connector_for(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn auto_scan_prefers_ids_and_orders_numerically() {
        let dev = std::env::temp_dir().join(format!("hammer-monitor-dev-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dev);
        std::fs::create_dir_all(dev.join("serial/by-id")).unwrap();
        for n in ["ttyACM10", "ttyACM2", "ttyUSB0", "ttyS0", "ttyACMx"] {
            std::fs::write(dev.join(n), b"").unwrap();
        }
        std::os::unix::fs::symlink(dev.join("ttyACM10"), dev.join("serial/by-id/usb-STM_STLINK-if02")).unwrap();
        let got: Vec<String> = scan_serial_ports(&dev)
            .iter()
            .map(|p| p.strip_prefix(&dev).unwrap().display().to_string())
            .collect();
        assert_eq!(got, ["serial/by-id/usb-STM_STLINK-if02", "ttyACM2", "ttyUSB0"]);
        let mut auto = AutoConnector::new(dev.join("nothing-here"));
        let err = auto.connect().err().unwrap();
        assert!(err.to_string().contains("no serial port found"), "{err}");
        let _ = std::fs::remove_dir_all(&dev);
    }
}
