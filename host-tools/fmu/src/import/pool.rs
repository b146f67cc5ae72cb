//! The worker processes that run a foreign FMU, seen from the host: each
//! holds one instance (reused through `fmi2Reset`), at most `threads` of
//! them live, a reply that does not come within the time limit kills its
//! worker. A worker that failed, timed out or died is not reused: the next
//! run starts a fresh one.
//!
//! Why processes and not threads: a foreign library can crash, abort,
//! hang in a loop no thread can stop, or spoil the memory it shares; a
//! process boundary turns each into an error with an exit status. It also
//! honours `canBeInstantiatedOnlyOncePerProcess` at any pool size (one
//! instance per process), and lets a pythonfmu FMU have its interpreter
//! (libpython opened RTLD_GLOBAL, PYTHONPATH) without touching the host.

use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::sync::{Condvar, Mutex};
use std::time::Duration;

use super::worker::{Reply, Request};
use super::FailKind;

/// How to start a worker: a program and its arguments (the `hammer`
/// binary and `fmu worker`), with extra environment.
#[derive(Debug, Clone)]
pub struct WorkerCommand {
    pub program: PathBuf,
    pub args: Vec<String>,
    pub env: Vec<(String, String)>,
}

impl WorkerCommand {
    /// The running program as the worker: right when it is `hammer`, whose
    /// hidden `hammer fmu worker` serves [`super::worker::serve`].
    pub fn this_program() -> Result<Self, String> {
        Ok(Self {
            program: std::env::current_exe().map_err(|e| format!("where is this program? {e}"))?,
            args: vec!["fmu".into(), "worker".into()],
            env: Vec::new(),
        })
    }
}

type Answer = Result<(Reply, Vec<f64>), String>;

/// One worker process.
pub struct Worker {
    child: Child,
    /// None once closed (the worker then frees its instance and exits).
    stdin: Option<ChildStdin>,
    replies: Receiver<Answer>,
    /// The last lines the worker (the FMU's logger) wrote to its stderr.
    log: std::sync::Arc<Mutex<Vec<String>>>,
}

/// Lines of a worker's log kept for an error message.
const LOG_LINES: usize = 4;

fn read_answer(out: &mut impl BufRead) -> Option<Answer> {
    let mut line = String::new();
    match out.read_line(&mut line) {
        Ok(0) | Err(_) => return None,
        Ok(_) => {}
    }
    let reply: Reply = match serde_json::from_str(&line) {
        Ok(r) => r,
        Err(e) => return Some(Err(format!("the worker's reply is not the protocol's: {e}"))),
    };
    let mut data = Vec::new();
    if let Reply::Samples { values } = reply {
        // Read through one small buffer: the run's bytes are never held
        // whole beside its values.
        data.reserve_exact(values);
        let mut bytes = [0u8; 8192];
        let mut left = values * 8;
        while left > 0 {
            let n = left.min(bytes.len());
            if out.read_exact(&mut bytes[..n]).is_err() {
                return None;
            }
            data.extend(
                bytes[..n]
                    .chunks_exact(8)
                    .map(|c| f64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]])),
            );
            left -= n;
        }
    }
    Some(Ok((reply, data)))
}

impl Worker {
    pub fn spawn(cmd: &WorkerCommand) -> Result<Self, String> {
        let mut child = Command::new(&cmd.program)
            .args(&cmd.args)
            .envs(cmd.env.iter().map(|(k, v)| (k, v)))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start the worker {}: {e}", cmd.program.display()))?;
        let (Some(stdin), Some(stdout), Some(stderr)) = (child.stdin.take(), child.stdout.take(), child.stderr.take())
        else {
            let _ = child.kill();
            return Err("the worker's pipes".into());
        };
        let (tx, replies) = mpsc::channel();
        std::thread::spawn(move || {
            let mut out = BufReader::new(stdout);
            while let Some(a) = read_answer(&mut out) {
                if tx.send(a).is_err() {
                    break;
                }
            }
        });
        let log = std::sync::Arc::new(Mutex::new(Vec::new()));
        std::thread::spawn({
            let log = log.clone();
            move || {
                for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                    let mut l = log.lock().unwrap_or_else(|p| p.into_inner());
                    l.push(line.chars().take(300).collect());
                    let n = l.len();
                    if n > LOG_LINES {
                        l.drain(..n - LOG_LINES);
                    }
                }
            }
        });
        Ok(Self {
            child,
            stdin: Some(stdin),
            replies,
            log,
        })
    }

    /// Sends `request` and waits at most `limit` for its reply.
    pub fn ask(&mut self, request: &Request, limit: Duration) -> Result<(Reply, Vec<f64>), (FailKind, String)> {
        let line = serde_json::to_string(request).map_err(|e| (FailKind::Worker, e.to_string()))?;
        let sent = self.stdin.as_mut().map(|stdin| {
            stdin
                .write_all(line.as_bytes())
                .and_then(|()| stdin.write_all(b"\n"))
                .and_then(|()| stdin.flush())
        });
        if !matches!(sent, Some(Ok(()))) {
            return Err(self.died());
        }
        match self.replies.recv_timeout(limit) {
            Ok(Ok(a)) => Ok(a),
            Ok(Err(e)) => Err((FailKind::Worker, e)),
            Err(RecvTimeoutError::Timeout) => {
                let _ = self.child.kill();
                let _ = self.child.wait();
                Err((
                    FailKind::Timeout,
                    format!(
                        "no answer within the time limit of {:.3} s; its worker was stopped",
                        limit.as_secs_f64()
                    ),
                ))
            }
            Err(RecvTimeoutError::Disconnected) => Err(self.died()),
        }
    }

    /// Why the worker is gone: its exit status and last log lines.
    fn died(&mut self) -> (FailKind, String) {
        let status = self.child.wait().map_or("an unknown status".into(), |s| {
            use std::os::unix::process::ExitStatusExt;
            match s.signal() {
                Some(sig) => format!("signal {sig}{}", signal_name(sig)),
                None => format!("exit code {}", s.code().unwrap_or(-1)),
            }
        });
        // The stderr reader may still be draining: give it a moment.
        std::thread::sleep(Duration::from_millis(20));
        let log = self.log.lock().map(|l| l.join(" | ")).unwrap_or_default();
        let log = if log.is_empty() {
            String::new()
        } else {
            format!("; its log: {log}")
        };
        (FailKind::Crashed, format!("the FMU's process ended ({status}){log}"))
    }
}

fn signal_name(sig: i32) -> &'static str {
    match sig {
        libc::SIGSEGV => " SIGSEGV",
        libc::SIGABRT => " SIGABRT",
        libc::SIGBUS => " SIGBUS",
        libc::SIGFPE => " SIGFPE",
        libc::SIGILL => " SIGILL",
        libc::SIGKILL => " SIGKILL",
        _ => "",
    }
}

/// How long a worker whose input was closed may take to free its instance
/// (`fmi2FreeInstance`: a tool's runtime licence is returned there) and exit.
const EXIT_GRACE: Duration = Duration::from_secs(2);

impl Drop for Worker {
    fn drop(&mut self) {
        // Closing stdin ends a healthy worker (its instance freed); one
        // that has not exited within the grace period is killed.
        drop(self.stdin.take());
        let start = std::time::Instant::now();
        while start.elapsed() < EXIT_GRACE {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// At most `size` workers, idle ones kept for the next run.
pub struct Pool {
    size: usize,
    state: Mutex<(Vec<Worker>, usize)>,
    freed: Condvar,
}

impl Pool {
    pub fn new(size: usize) -> Self {
        Self {
            size: size.max(1),
            state: Mutex::new((Vec::new(), 0)),
            freed: Condvar::new(),
        }
    }

    /// An idle worker, or None when a new one may be started (counted
    /// live now); waits while `size` are busy.
    pub fn take(&self) -> Option<Worker> {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        loop {
            if let Some(w) = s.0.pop() {
                return Some(w);
            }
            if s.1 < self.size {
                s.1 += 1;
                return None;
            }
            s = self.freed.wait(s).unwrap_or_else(|p| p.into_inner());
        }
    }

    /// Returns a worker to the pool (`Some`) or gives its place up (`None`).
    pub fn give(&self, w: Option<Worker>) {
        let mut s = self.state.lock().unwrap_or_else(|p| p.into_inner());
        match w {
            Some(w) => s.0.push(w),
            None => s.1 -= 1,
        }
        self.freed.notify_one();
    }

    /// Workers alive now (busy or idle).
    pub fn live(&self) -> usize {
        self.state.lock().map(|s| s.1).unwrap_or(0)
    }
}
