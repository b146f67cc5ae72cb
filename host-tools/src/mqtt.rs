//! A device's reports, status, alarms and link events on an MQTT broker
//! (rumqttc), so a fleet can be watched, stored and alarmed on with the
//! tools condition-monitoring people already run.
//!
//! Topics, under `hammer/<site>/<device>/` (docs/fleet.md):
//!
//! | topic | what | QoS | retained |
//! |---|---|---|---|
//! | `state` | birth `{"online":true,...}` on connect; the broker's last will `{"online":false}` | 1 | yes |
//! | `cycle` | every cycle report: the report's JSON (its one field table) | 1 | no |
//! | `status` | the device's status, every second | 0 | yes (the latest) |
//! | `alarm` | drift on/off, sensor faults | 1 | yes (the current state) |
//! | `link` | connects, disconnects, gaps, errors, as the monitor words them | 1 | no |
//!
//! Every payload carries `device`, `host_time` (RFC 3339), `publish_seq`
//! (this publisher's count, gap-free per device and run: a subscriber sees
//! loss or a duplicate in it) and `historical` (false when sent as it
//! happened; true when it waited in the outage buffer).
//!
//! While the broker is unreachable, messages go to an outage buffer on disk
//! (`<buffer dir>/<device>.jsonl`, [`DEFAULT_BUFFER_MB`] by default; beyond
//! it the oldest are dropped and counted) and are replayed in order,
//! flagged historical, once it is back, before anything new. A message
//! counts as delivered at the broker's PUBACK; what was in flight when the
//! link dropped goes back to the buffer, so delivery is at least once (a
//! duplicate shows as a repeated `publish_seq`). A buffer left by an earlier
//! run is replayed too.

use std::collections::VecDeque;
use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use rumqttc::{Client, Connection, Event, LastWill, MqttOptions, Outgoing, Packet, QoS, RecvTimeoutError};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

/// The outage buffer's default cap.
pub const DEFAULT_BUFFER_MB: f64 = 256.0;
/// Messages sent and not yet acknowledged, at most.
const MAX_INFLIGHT: usize = 64;
/// New messages held in memory while online, at most (then the disk buffer).
const MAX_LIVE: usize = 1024;
/// Pause before connecting again after a failure.
const RETRY: Duration = Duration::from_secs(1);

/// What a message is, which sets its topic, QoS and retention.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    State,
    Cycle,
    Status,
    Alarm,
    Link,
}

impl Kind {
    pub fn name(self) -> &'static str {
        match self {
            Kind::State => "state",
            Kind::Cycle => "cycle",
            Kind::Status => "status",
            Kind::Alarm => "alarm",
            Kind::Link => "link",
        }
    }

    fn qos(self) -> QoS {
        match self {
            Kind::Status => QoS::AtMostOnce,
            _ => QoS::AtLeastOnce,
        }
    }

    fn retain(self) -> bool {
        matches!(self, Kind::State | Kind::Status | Kind::Alarm)
    }
}

/// `hammer/<site>/<device>/<kind>`.
pub fn topic(site: &str, device: &str, kind: Kind) -> String {
    format!("hammer/{site}/{device}/{}", kind.name())
}

/// `mqtt://HOST[:PORT]` → (host, port).
pub fn parse_url(url: &str) -> Result<(String, u16)> {
    let Some(rest) = url.strip_prefix("mqtt://") else {
        bail!("--mqtt {url}: an MQTT broker is mqtt://HOST[:PORT] (TLS is not built in)");
    };
    let rest = rest.trim_end_matches('/');
    let (host, port) = match rest.rsplit_once(':') {
        Some((h, p)) => (h, p.parse().with_context(|| format!("--mqtt {url}: port {p:?}"))?),
        None => (rest, 1883),
    };
    if host.is_empty() {
        bail!("--mqtt {url}: no host");
    }
    Ok((host.to_string(), port))
}

/// One message, as queued and as buffered on disk.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct Message {
    kind: Kind,
    /// The payload without `historical`, which is decided when it is sent.
    body: Value,
}

impl Message {
    fn payload(&self, historical: bool) -> Vec<u8> {
        let mut body = self.body.clone();
        if let Some(m) = body.as_object_mut() {
            m.insert("historical".into(), historical.into());
        }
        serde_json::to_vec(&body).unwrap_or_default()
    }
}

/// Counters a caller can read while the publisher runs.
#[derive(Debug, Default)]
pub struct Counters {
    pub published: AtomicU64,
    pub replayed: AtomicU64,
    pub buffered: AtomicU64,
    pub dropped: AtomicU64,
    pub online: AtomicBool,
}

/// The outage buffer: a queue in memory, mirrored line by line on disk.
struct Buffer {
    path: PathBuf,
    file: File,
    queue: VecDeque<(Message, usize)>,
    bytes: usize,
    cap: usize,
    /// The file still holds messages taken out of the queue.
    stale: bool,
}

impl Buffer {
    fn open(path: &Path, cap: usize) -> Result<Self> {
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        }
        let mut queue = VecDeque::new();
        let mut bytes = 0;
        if let Ok(f) = File::open(path) {
            for line in BufReader::new(f).lines() {
                let line = line.with_context(|| format!("reading {}", path.display()))?;
                // A line cut by a crash is skipped: it never was a message.
                if let Ok(m) = serde_json::from_str::<Message>(&line) {
                    bytes += line.len() + 1;
                    queue.push_back((m, line.len() + 1));
                }
            }
        }
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .with_context(|| format!("opening {}", path.display()))?;
        Ok(Self {
            path: path.to_path_buf(),
            file,
            queue,
            bytes,
            cap,
            stale: false,
        })
    }

    /// Appends; beyond the cap drops the oldest and returns how many.
    fn push_back(&mut self, m: Message) -> Result<u64> {
        let line = serde_json::to_string(&m)?;
        self.file.write_all(line.as_bytes())?;
        self.file.write_all(b"\n")?;
        self.bytes += line.len() + 1;
        self.queue.push_back((m, line.len() + 1));
        let mut dropped = 0;
        while self.bytes > self.cap && self.queue.len() > 1 {
            let (_, n) = self.queue.pop_front().expect("non-empty");
            self.bytes -= n;
            dropped += 1;
        }
        if dropped > 0 {
            self.rewrite()?;
        }
        Ok(dropped)
    }

    /// Puts messages that were in flight back at the front, in order.
    fn push_front_all(&mut self, ms: Vec<Message>) -> Result<()> {
        for m in ms.into_iter().rev() {
            let n = serde_json::to_string(&m)?.len() + 1;
            self.bytes += n;
            self.queue.push_front((m, n));
        }
        self.rewrite()
    }

    fn pop_front(&mut self) -> Option<Message> {
        let (m, n) = self.queue.pop_front()?;
        self.bytes -= n;
        self.stale = true;
        Some(m)
    }

    /// The file holds exactly the queue.
    fn rewrite(&mut self) -> Result<()> {
        let tmp = self.path.with_extension("jsonl.tmp");
        let mut f = File::create(&tmp)?;
        for (m, _) in &self.queue {
            serde_json::to_writer(&mut f, m)?;
            f.write_all(b"\n")?;
        }
        f.sync_all()?;
        std::fs::rename(&tmp, &self.path)?;
        self.file = OpenOptions::new().append(true).open(&self.path)?;
        self.stale = false;
        Ok(())
    }
}

/// Where and how a device publishes.
#[derive(Debug, Clone)]
pub struct Options {
    pub url: String,
    pub site: String,
    pub device: String,
    pub buffer_dir: PathBuf,
    pub buffer_bytes: usize,
}

/// A device's publisher: [`Publisher::send`] never blocks; a thread owns
/// the MQTT connection, the in-flight window and the outage buffer.
pub struct Publisher {
    tx: Option<Sender<Message>>,
    thread: Option<JoinHandle<()>>,
    pub counters: Arc<Counters>,
    device: String,
    seq: u64,
}

impl Publisher {
    pub fn start(o: Options) -> Result<Self> {
        let (host, port) = parse_url(&o.url)?;
        let buffer = Buffer::open(&o.buffer_dir.join(format!("{}.jsonl", o.device)), o.buffer_bytes)?;
        let counters = Arc::new(Counters::default());
        counters.buffered.store(buffer.queue.len() as u64, Ordering::Relaxed);
        let (tx, rx) = mpsc::channel();
        let state = topic(&o.site, &o.device, Kind::State);
        let mut opts = MqttOptions::new(format!("hammer-{}-{}", o.site, o.device), host, port);
        opts.set_keep_alive(Duration::from_secs(5));
        opts.set_clean_session(true);
        opts.set_last_will(LastWill::new(
            state.clone(),
            serde_json::to_vec(&json!({"device": o.device, "online": false})).unwrap_or_default(),
            QoS::AtLeastOnce,
            true,
        ));
        let mut session = Session {
            opts,
            site: o.site.clone(),
            device: o.device.clone(),
            rx,
            buffer,
            counters: counters.clone(),
            live: VecDeque::new(),
            unassigned: VecDeque::new(),
            inflight: Vec::new(),
            birth: None,
            closing: false,
        };
        let thread = std::thread::Builder::new()
            .name(format!("mqtt-{}", o.device))
            .spawn(move || session.run())?;
        Ok(Self {
            tx: Some(tx),
            thread: Some(thread),
            counters,
            device: o.device,
            seq: 0,
        })
    }

    /// Queues a message; `body` gets `device`, `host_time`, `publish_seq`.
    pub fn send(&mut self, kind: Kind, mut body: Value, host_time: &str) {
        if let Some(m) = body.as_object_mut() {
            m.insert("device".into(), self.device.clone().into());
            m.insert("host_time".into(), host_time.into());
            m.insert("publish_seq".into(), self.seq.into());
        }
        self.seq += 1;
        if let Some(tx) = &self.tx {
            let _ = tx.send(Message { kind, body });
        }
    }

    pub fn device_name(&self) -> &str {
        &self.device
    }

    /// What it did, for the closing summary.
    pub fn summary(&self) -> String {
        Self::describe(&self.device, &self.counters)
    }

    /// [`Publisher::summary`] from the counters (also after the publisher stopped).
    pub fn describe(device: &str, c: &Counters) -> String {
        format!(
            "mqtt {}: {} published ({} replayed from the outage buffer), {} still buffered, {} dropped at the buffer's cap",
            device,
            c.published.load(Ordering::Relaxed),
            c.replayed.load(Ordering::Relaxed),
            c.buffered.load(Ordering::Relaxed),
            c.dropped.load(Ordering::Relaxed)
        )
    }
}

impl Drop for Publisher {
    /// Sends what it can within a few seconds; the rest stays in the buffer
    /// for the next run.
    fn drop(&mut self) {
        self.tx = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

struct Session {
    opts: MqttOptions,
    site: String,
    device: String,
    rx: Receiver<Message>,
    buffer: Buffer,
    counters: Arc<Counters>,
    /// New messages while online, not yet handed to the client.
    live: VecDeque<Message>,
    /// Handed to the client, waiting for their packet id: (message, historical).
    unassigned: VecDeque<(Message, bool)>,
    /// Sent, waiting for PUBACK: (packet id, message, historical).
    inflight: Vec<(u16, Message, bool)>,
    /// The latest `state` body, re-sent on every connect.
    birth: Option<Message>,
    closing: bool,
}

impl Session {
    fn online(&self) -> bool {
        self.counters.online.load(Ordering::Relaxed)
    }

    fn to_buffer(&mut self, m: Message) {
        match self.buffer.push_back(m) {
            Ok(dropped) => {
                self.counters.dropped.fetch_add(dropped, Ordering::Relaxed);
            }
            Err(e) => {
                eprintln!(
                    "mqtt {}: the outage buffer failed ({e:#}); a message is lost",
                    self.device
                );
                self.counters.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
        self.counters
            .buffered
            .store(self.buffer.queue.len() as u64, Ordering::Relaxed);
    }

    /// Takes new messages from the monitor; false once it has hung up.
    fn take_new(&mut self) -> bool {
        loop {
            match self.rx.try_recv() {
                Ok(m) => {
                    if m.kind == Kind::State {
                        self.birth = Some(m.clone());
                    }
                    // A broker that is up but slower than the fleet: beyond
                    // MAX_LIVE the queue spills to the bounded disk buffer
                    // rather than growing in memory.
                    if self.online() && self.buffer.queue.is_empty() && self.live.len() < MAX_LIVE {
                        self.live.push_back(m);
                    } else {
                        self.to_buffer(m);
                    }
                }
                Err(TryRecvError::Empty) => return true,
                Err(TryRecvError::Disconnected) => return false,
            }
        }
    }

    /// Hands messages to the client while the window has room: the buffer first.
    fn feed(&mut self, client: &Client) {
        while self.unassigned.len() + self.inflight.len() < MAX_INFLIGHT {
            let (m, historical) = match self.buffer.pop_front() {
                Some(m) => (m, true),
                None => match self.live.pop_front() {
                    Some(m) => (m, false),
                    None => break,
                },
            };
            let t = topic(&self.site, &self.device, m.kind);
            match client.try_publish(t, m.kind.qos(), m.kind.retain(), m.payload(historical)) {
                Ok(()) => self.unassigned.push_back((m, historical)),
                Err(_) => {
                    // The request queue is full: try again next round.
                    if historical {
                        let _ = self.buffer.push_front_all(vec![m]);
                    } else {
                        self.live.push_front(m);
                    }
                    break;
                }
            }
        }
        self.counters
            .buffered
            .store(self.buffer.queue.len() as u64, Ordering::Relaxed);
    }

    fn delivered(&self, historical: bool) {
        self.counters.published.fetch_add(1, Ordering::Relaxed);
        if historical {
            self.counters.replayed.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// The link dropped: whatever was not acknowledged waits in the buffer.
    fn lost(&mut self) {
        self.counters.online.store(false, Ordering::Relaxed);
        let mut back: Vec<Message> = self.inflight.drain(..).map(|(_, m, _)| m).collect();
        back.extend(self.unassigned.drain(..).map(|(m, _)| m));
        back.extend(self.live.drain(..));
        back.retain(|m| m.kind != Kind::State);
        if let Err(e) = self.buffer.push_front_all(back) {
            eprintln!("mqtt {}: the outage buffer failed ({e:#})", self.device);
        }
        self.counters
            .buffered
            .store(self.buffer.queue.len() as u64, Ordering::Relaxed);
    }

    /// One connection, until it fails or the monitor stops and all is sent.
    fn connection(&mut self) {
        let (client, mut conn): (Client, Connection) = Client::new(self.opts.clone(), MAX_INFLIGHT * 2);
        let mut drain_deadline = None;
        loop {
            if !self.closing && !self.take_new() {
                self.closing = true;
            }
            if self.closing {
                let deadline =
                    *drain_deadline.get_or_insert_with(|| std::time::Instant::now() + Duration::from_secs(3));
                let idle = self.buffer.queue.is_empty()
                    && self.live.is_empty()
                    && self.unassigned.is_empty()
                    && self.inflight.is_empty();
                if idle || std::time::Instant::now() > deadline || !self.online() {
                    if self.online() {
                        // A clean disconnect does not fire the will: say it ourselves.
                        let t = topic(&self.site, &self.device, Kind::State);
                        let gone = json!({"device": self.device, "online": false});
                        let _ = client.try_publish(
                            t,
                            QoS::AtLeastOnce,
                            true,
                            serde_json::to_vec(&gone).unwrap_or_default(),
                        );
                        let _ = client.disconnect();
                        for _ in 0..50 {
                            match conn.recv_timeout(Duration::from_millis(20)) {
                                Ok(Ok(Event::Outgoing(Outgoing::Disconnect)))
                                | Ok(Err(_))
                                | Err(RecvTimeoutError::Disconnected) => break,
                                _ => {}
                            }
                        }
                    }
                    self.lost();
                    return;
                }
            }
            if self.online() {
                self.feed(&client);
            }
            match conn.recv_timeout(Duration::from_millis(20)) {
                Ok(Ok(Event::Incoming(Packet::ConnAck(_)))) => {
                    self.counters.online.store(true, Ordering::Relaxed);
                    // Birth first, ahead of the replay.
                    if let Some(b) = self.birth.clone() {
                        let t = topic(&self.site, &self.device, Kind::State);
                        if client.try_publish(t, QoS::AtLeastOnce, true, b.payload(false)).is_ok() {
                            self.unassigned.push_front((b, false));
                        }
                    }
                }
                Ok(Ok(Event::Outgoing(Outgoing::Publish(pkid)))) => {
                    if let Some((m, h)) = self.unassigned.pop_front() {
                        if pkid == 0 {
                            self.delivered(h); // QoS 0: handed to the network
                        } else {
                            self.inflight.push((pkid, m, h));
                        }
                    }
                }
                Ok(Ok(Event::Incoming(Packet::PubAck(ack)))) => {
                    if let Some(i) = self.inflight.iter().position(|(p, _, _)| *p == ack.pkid) {
                        let (_, _, h) = self.inflight.remove(i);
                        self.delivered(h);
                    }
                    // The replay is acknowledged to its end: the file may go.
                    if self.buffer.stale
                        && self.buffer.queue.is_empty()
                        && self.inflight.iter().all(|(_, _, h)| !h)
                        && self.unassigned.iter().all(|(_, h)| !h)
                    {
                        let _ = self.buffer.rewrite();
                    }
                }
                Ok(Ok(_)) => {}
                Ok(Err(_)) | Err(RecvTimeoutError::Disconnected) => {
                    self.lost();
                    return;
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
        }
    }

    fn run(&mut self) {
        loop {
            self.connection();
            if self.closing {
                return;
            }
            // Offline: keep buffering while waiting to retry.
            let until = std::time::Instant::now() + RETRY;
            while std::time::Instant::now() < until {
                if !self.take_new() {
                    self.closing = true;
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            if self.closing {
                // One last try to deliver, then keep the rest on disk.
                self.connection();
                return;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn urls_parse_or_say_what_is_wrong() {
        assert_eq!(parse_url("mqtt://127.0.0.1:1884").unwrap(), ("127.0.0.1".into(), 1884));
        assert_eq!(parse_url("mqtt://broker").unwrap(), ("broker".into(), 1883));
        assert!(parse_url("mqtts://b").is_err());
        assert!(parse_url("mqtt://:1883").is_err());
        assert!(parse_url("mqtt://b:x").is_err());
    }

    #[test]
    fn the_buffer_keeps_order_survives_a_restart_and_drops_the_oldest_at_its_cap() {
        let dir = std::env::temp_dir().join(format!("hammer-mqtt-buf-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let path = dir.join("d.jsonl");
        let msg = |k: u64| Message {
            kind: Kind::Cycle,
            body: json!({"publish_seq": k, "friction_n": 10.27}),
        };
        let mut b = Buffer::open(&path, 10_000).unwrap();
        for k in 0..10 {
            assert_eq!(b.push_back(msg(k)).unwrap(), 0);
        }
        assert_eq!(b.pop_front().unwrap().body["publish_seq"], 0);
        b.push_front_all(vec![msg(0)]).unwrap();
        drop(b);
        let mut b = Buffer::open(&path, 10_000).unwrap();
        let seqs: Vec<u64> = b
            .queue
            .iter()
            .map(|(m, _)| m.body["publish_seq"].as_u64().unwrap())
            .collect();
        assert_eq!(seqs, (0..10).collect::<Vec<_>>());
        // A cap of about 5 messages: the oldest go, counted, the newest stay.
        let one = b.queue[0].1;
        b.cap = 5 * one + 2;
        let dropped = b.push_back(msg(10)).unwrap();
        assert!(b.bytes <= b.cap, "{} bytes over a cap of {}", b.bytes, b.cap);
        assert_eq!(b.queue.len() as u64, 11 - dropped);
        assert!((6..=7).contains(&dropped), "{dropped}");
        assert_eq!(b.queue.front().unwrap().0.body["publish_seq"], dropped);
        assert_eq!(b.queue.back().unwrap().0.body["publish_seq"], 10);
        drop(b);
        let b = Buffer::open(&path, usize::MAX).unwrap();
        assert_eq!(
            b.queue.len() as u64,
            11 - dropped,
            "the file holds what the queue holds"
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn topics_and_flags() {
        assert_eq!(topic("lab", "rig4", Kind::Cycle), "hammer/lab/rig4/cycle");
        let m = Message {
            kind: Kind::Cycle,
            body: json!({"seq": 3}),
        };
        let v: Value = serde_json::from_slice(&m.payload(true)).unwrap();
        assert_eq!(v["historical"], true);
        assert!(Kind::State.retain() && !Kind::Cycle.retain() && Kind::Status.qos() == QoS::AtMostOnce);
    }
}

/// `hammer mqtt-tail`.
#[derive(clap::Args, Debug, Clone)]
pub struct TailArgs {
    /// The broker, mqtt://HOST[:PORT].
    #[arg(long, value_name = "URL")]
    pub mqtt: String,
    /// The site whose devices to show.
    #[arg(long, default_value = "lab")]
    pub site: String,
    /// Stop after this many cycle reports (for scripts and tests).
    #[arg(long, value_name = "N")]
    pub count: Option<u64>,
}

/// One line for a message on a fleet topic, or none for kinds not shown.
pub fn tail_line(topic: &str, payload: &[u8]) -> Option<String> {
    let mut parts = topic.split('/');
    let (_, _, device, kind) = (parts.next()?, parts.next()?, parts.next()?, parts.next()?);
    let v: Value = serde_json::from_slice(payload).ok()?;
    let f = |k: &str| v.get(k).and_then(Value::as_f64).unwrap_or(f64::NAN);
    let historical = if v["historical"] == true { "  (historical)" } else { "" };
    match kind {
        "cycle" => Some(format!(
            "[{device}] cycle {:>6}  friction {:.2} N  energy {:.3} J  {:.2} Hz  wear {:.1} J  {}{historical}",
            v["seq"].as_u64()?,
            f("friction_n"),
            f("impact_energy_j"),
            f("frequency_hz"),
            f("wear_index_j"),
            if v["valid"] == true { "valid" } else { "NOT VALID" }
        )),
        "state" if v["online"] == true => Some(format!(
            "[{device}] online: {} firmware {} protocol {} config {}",
            v["board"].as_str().unwrap_or("?"),
            v["firmware"].as_str().unwrap_or("?"),
            v["protocol"],
            v["config_hash"].as_str().unwrap_or("?")
        )),
        "state" => Some(format!("[{device}] offline")),
        "alarm" => Some(format!("[{device}] ALARM {}{historical}", v["kind"])),
        "link" => Some(format!("[{device}] {}{historical}", v["event"].as_str().unwrap_or("?"))),
        _ => None,
    }
}

pub fn tail(args: &TailArgs) -> Result<()> {
    let (host, port) = parse_url(&args.mqtt)?;
    let mut opts = MqttOptions::new(format!("hammer-tail-{}", std::process::id()), host, port);
    opts.set_keep_alive(Duration::from_secs(5));
    let (client, mut conn) = Client::new(opts, 16);
    let filter = format!("hammer/{}/#", args.site);
    let mut cycles = 0u64;
    let mut out = std::io::stdout().lock();
    let mut errors = 0u32;
    loop {
        match conn.recv() {
            Ok(Ok(Event::Incoming(Packet::ConnAck(_)))) => {
                errors = 0;
                client.subscribe(filter.clone(), QoS::AtLeastOnce)?;
            }
            Ok(Ok(Event::Incoming(Packet::Publish(p)))) => {
                if let Some(line) = tail_line(&p.topic, &p.payload) {
                    if writeln!(out, "{line}").is_err() {
                        return Ok(());
                    }
                }
                if p.topic.ends_with("/cycle") {
                    cycles += 1;
                    if args.count.is_some_and(|n| cycles >= n) {
                        return Ok(());
                    }
                }
            }
            Ok(Ok(_)) => {}
            Ok(Err(e)) => {
                errors += 1;
                if errors == 1 {
                    eprintln!("mqtt-tail: {e}; retrying every second");
                }
                std::thread::sleep(RETRY);
            }
            Err(_) => bail!("the MQTT connection ended"),
        }
    }
}
