//! The worker process: one FMU instance, driven over its standard input
//! and output by the host ([`super::pool`]). A foreign library runs here
//! and only here, so a crash, a hang or an abort ends this process and the
//! host reports it; the host's own memory is never the FMU's to spoil.
//!
//! Protocol: the host writes one JSON [`Request`] per line; the worker
//! answers each with one JSON [`Reply`] line, a [`Reply::Samples`] followed
//! by its values as little-endian f64 (row by row: t = 0, then each step;
//! the columns the request asks back), so a run's samples cross the pipe
//! exactly and without formatting.

use std::io::{BufRead, Write};
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::fmi2::{self, Instance, Typed};

#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum Request {
    /// Load the binary `so` (after `preload`, opened RTLD_GLOBAL) and
    /// instantiate it.
    Open {
        so: PathBuf,
        guid: String,
        resources: PathBuf,
        preload: Vec<PathBuf>,
    },
    /// One run from t = 0: values set before initialisation, `steps`
    /// communication steps of `step_s`, `outputs` read (and checked
    /// finite) at each point; the first `send` of them are sent back (a
    /// driven run reads its velocity without needing it back).
    Run {
        starts: Vec<(Typed, f64)>,
        outputs: Vec<Typed>,
        send: usize,
        step_s: f64,
        steps: usize,
        drive: Option<Drive>,
    },
}

/// Friction from outside: before each step the built-in plant's friction
/// law ([`hammer_sim::model::HammerModel::friction_n`], the one place it is
/// written) at the step's start time and the last velocity read, set on
/// the FMU's piston-force input and held over the step.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Drive {
    pub input: Typed,
    /// The FMU's input value per newton along the project's axis (its unit
    /// and sign).
    pub input_per_n: f64,
    /// Which output column is the velocity, and m/s per its value.
    pub velocity_column: usize,
    pub mps_per_velocity: f64,
    /// The effects whose friction goes in, and the run's supply pressure.
    pub effects: hammer_sim::Effects,
    pub supply_bar: f64,
}

impl Drive {
    /// The closure the instance asks before each step.
    fn law(&self) -> impl FnMut(f64, &[f64]) -> (Typed, f64) + '_ {
        let mut cfg = hammer_sim::SimConfig::default();
        cfg.supply.pressure_bar = self.supply_bar;
        cfg.effects = self.effects.clone();
        let plant = hammer_sim::model::HammerModel::new(&cfg);
        move |t, row| {
            let v = row[self.velocity_column] * self.mps_per_velocity;
            (self.input, plant.friction_n(t, v) * self.input_per_n)
        }
    }
}

#[derive(Debug, Clone, Serialize, Deserialize)]
pub enum Reply {
    Ready,
    /// `values` f64 follow the line.
    Samples {
        values: usize,
    },
    Failed(String),
}

/// The samples a reply carries: the first `send` of every `row` values.
struct Columns<'a> {
    data: &'a [f64],
    row: usize,
    send: usize,
}

impl Columns<'_> {
    const NONE: Columns<'static> = Columns {
        data: &[],
        row: 1,
        send: 0,
    };

    fn values(&self) -> usize {
        self.data.len() / self.row * self.send
    }
}

/// Bytes of samples converted at a time: a run's samples (megabytes) are
/// never copied whole, so the worker allocates nothing per run.
const CHUNK: usize = 8192;

fn send(out: &mut impl Write, reply: &Reply, samples: Columns) -> std::io::Result<()> {
    let line = serde_json::to_string(reply).map_err(std::io::Error::other)?;
    out.write_all(line.as_bytes())?;
    out.write_all(b"\n")?;
    let mut bytes = [0u8; CHUNK];
    let mut n = 0;
    for row in samples.data.chunks_exact(samples.row) {
        for x in &row[..samples.send] {
            bytes[n..n + 8].copy_from_slice(&x.to_le_bytes());
            n += 8;
            if n == CHUNK {
                out.write_all(&bytes)?;
                n = 0;
            }
        }
    }
    out.write_all(&bytes[..n])?;
    out.flush()
}

/// The protocol's own copy of standard output; file descriptor 1 then
/// points at standard error, so an FMU that prints (many do, with printf)
/// lands in the log, not in the middle of a reply.
fn protocol_out() -> std::io::Result<std::fs::File> {
    use std::os::fd::FromRawFd;
    // SAFETY: dup and dup2 on the process's own standard descriptors.
    let fd = unsafe { libc::dup(1) };
    if fd < 0 || unsafe { libc::dup2(2, 1) } < 0 {
        return Err(std::io::Error::last_os_error());
    }
    // SAFETY: fd is a new descriptor this process owns from here on.
    Ok(unsafe { std::fs::File::from_raw_fd(fd) })
}

/// Serves requests from standard input until it closes; the process's
/// exit code (0: the host closed the pipe; 2: a broken protocol).
pub fn serve() -> i32 {
    let stdin = std::io::stdin();
    let Ok(out) = protocol_out() else { return 2 };
    let mut stdout = std::io::BufWriter::new(out);
    let mut instance: Option<Instance> = None;
    let mut ran = false;
    // Every run's samples, in the one buffer.
    let mut samples: Vec<f64> = Vec::new();
    for line in stdin.lock().lines() {
        let Ok(line) = line else { return 2 };
        let request: Request = match serde_json::from_str(&line) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("fmu worker: a request it cannot read: {e}");
                return 2;
            }
        };
        fmi2::take_log();
        let (reply, columns) = match request {
            Request::Open {
                so,
                guid,
                resources,
                preload,
            } => {
                let opened = preload
                    .iter()
                    .try_for_each(|p| fmi2::open(p, true).map(|_| ()))
                    .and_then(|()| Instance::new(&so, &guid, &resources));
                match opened {
                    Ok(i) => {
                        instance = Some(i);
                        (Reply::Ready, Columns::NONE)
                    }
                    Err(e) => (Reply::Failed(e), Columns::NONE),
                }
            }
            Request::Run {
                starts,
                outputs,
                send,
                step_s,
                steps,
                drive,
            } => match instance.as_mut() {
                None => (Reply::Failed("no instance".into()), Columns::NONE),
                Some(_) if outputs.is_empty() || send > outputs.len() => {
                    (Reply::Failed("a run must read its outputs".into()), Columns::NONE)
                }
                Some(i) => {
                    let mut law = drive.as_ref().map(Drive::law);
                    let hook = law.as_mut().map(|l| l as &mut dyn FnMut(f64, &[f64]) -> (Typed, f64));
                    let r = i.run(ran, &starts, &outputs, step_s, steps, hook, &mut samples);
                    ran = true;
                    match r {
                        Ok(()) => {
                            let c = Columns {
                                data: &samples,
                                row: outputs.len(),
                                send,
                            };
                            (Reply::Samples { values: c.values() }, c)
                        }
                        Err(e) => (Reply::Failed(e), Columns::NONE),
                    }
                }
            },
        };
        let reply = match reply {
            Reply::Failed(e) => Reply::Failed(with_log(e)),
            r => r,
        };
        if send(&mut stdout, &reply, columns).is_err() {
            return 2;
        }
    }
    0
}

/// A failure with what the FMU logged while the request ran.
fn with_log(e: String) -> String {
    let log = fmi2::take_log();
    if log.is_empty() {
        e
    } else {
        format!("{e}; the FMU logged: {}", log.join(" | "))
    }
}
