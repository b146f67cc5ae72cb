//! A relay between a host tool and a board that counts what passes: the
//! bytes each way and the commands the host sends, by kind. What a test
//! needs to say "the monitor asked for no capture", and what the link's
//! load is measured with (`examples/drift_link_bytes.rs`).

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
use std::time::Duration;

use hammer_wire::{Decoder, HostMsg, MAX_FRAME};

/// What passed through a [`Relay`], counted as it passed.
#[derive(Debug, Default)]
pub struct Counts {
    pub to_board_bytes: AtomicU64,
    pub to_host_bytes: AtomicU64,
    pub commands: AtomicU64,
    pub start_captures: AtomicU64,
}

/// Relays one host connection, accepted on its own port, to a board's
/// streams, until dropped or either side closes.
pub struct Relay {
    pub port: u16,
    pub counts: Arc<Counts>,
    stop: Arc<AtomicBool>,
}

impl Relay {
    /// Listens on a free local port; the first connection is relayed to
    /// the board's `rx` (which must time out now and then, so the relay
    /// can stop) and `tx`.
    pub fn start(mut rx: Box<dyn Read + Send>, mut tx: Box<dyn Write + Send>) -> std::io::Result<Relay> {
        let listener = TcpListener::bind("127.0.0.1:0")?;
        let port = listener.local_addr()?.port();
        let counts = Arc::new(Counts::default());
        let stop = Arc::new(AtomicBool::new(false));
        let (c, s) = (counts.clone(), stop.clone());
        std::thread::spawn(move || {
            let Ok((host, _)) = listener.accept() else { return };
            let _ = host.set_read_timeout(Some(Duration::from_millis(20)));
            let Ok(mut to_host) = host.try_clone() else { return };
            let (c2, s2) = (c.clone(), s.clone());
            std::thread::spawn(move || {
                let mut buf = [0u8; 4096];
                while !s2.load(Ordering::Relaxed) {
                    match rx.read(&mut buf) {
                        Ok(0) => break,
                        Ok(n) => {
                            c2.to_host_bytes.fetch_add(n as u64, Ordering::Relaxed);
                            if to_host.write_all(&buf[..n]).is_err() {
                                break;
                            }
                        }
                        Err(_) => {}
                    }
                }
            });
            pump_commands(host, &mut tx, &c, &s);
        });
        Ok(Relay { port, counts, stop })
    }

    pub fn start_captures(&self) -> u64 {
        self.counts.start_captures.load(Ordering::Relaxed)
    }

    pub fn commands(&self) -> u64 {
        self.counts.commands.load(Ordering::Relaxed)
    }

    pub fn to_host_bytes(&self) -> u64 {
        self.counts.to_host_bytes.load(Ordering::Relaxed)
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// The host's bytes to the board, each frame decoded and counted.
fn pump_commands(mut host: TcpStream, tx: &mut Box<dyn Write + Send>, c: &Counts, stop: &AtomicBool) {
    let mut dec: Decoder<MAX_FRAME> = Decoder::new();
    let mut buf = [0u8; 512];
    while !stop.load(Ordering::Relaxed) {
        match host.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                c.to_board_bytes.fetch_add(n as u64, Ordering::Relaxed);
                for &b in &buf[..n] {
                    if let Some(Ok(m)) = dec.push::<HostMsg>(b) {
                        c.commands.fetch_add(1, Ordering::Relaxed);
                        if matches!(m, HostMsg::StartCapture { .. }) {
                            c.start_captures.fetch_add(1, Ordering::Relaxed);
                        }
                    }
                }
                if tx.write_all(&buf[..n]).is_err() {
                    break;
                }
            }
            Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut) => {}
            Err(_) => break,
        }
    }
}
