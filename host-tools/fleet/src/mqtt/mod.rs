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
//! | `drift` | the drift since commissioning (`--reference`), per window | 1 | yes (the latest) |
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
//! run is replayed too. The buffer lives in a directory private to the user
//! ([`buffer_dir`], [`crate::private_files`]), one checksummed record a line,
//! so damage costs only the damaged records.
//!
//! `mqtts://` connects over TLS ([`crate::tls`]: system roots or
//! `--mqtt-ca`, optional client certificate); a login's password comes from
//! [`PASSWORD_ENV`] or a file, never the command line. A broker that refuses
//! is said in words ([`Endpoint`]'s failure reading), shown as a note, asked
//! again with a doubling pause, and makes the run end non-zero.

use std::collections::VecDeque;
use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, TryRecvError};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use rumqttc::{Client, Connection, Event, LastWill, MqttOptions, Outgoing, Packet, QoS, RecvTimeoutError};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

mod buffer;
mod endpoint;
pub use buffer::buffer_dir;
use buffer::{Buffer, Message};
use endpoint::Failure;
pub use endpoint::{BrokerArgs, Endpoint, PASSWORD_ENV};

/// The outage buffer's default cap.
pub const DEFAULT_BUFFER_MB: f64 = 256.0;
/// Messages sent and not yet acknowledged, at most.
const MAX_INFLIGHT: usize = 64;
/// New messages held in memory while online, at most (then the disk buffer).
const MAX_LIVE: usize = 1024;
/// Pause before connecting again after a failure.
const RETRY: Duration = Duration::from_secs(1);
/// A broker that refuses (login, certificate) is asked again after a pause
/// that doubles from [`RETRY`] up to this: it will not change its mind soon.
const MAX_BACKOFF: Duration = Duration::from_secs(60);

/// What a message is, which sets its topic, QoS and retention.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    State,
    Cycle,
    Status,
    Alarm,
    Link,
    /// The drift since commissioning (`hammer monitor --reference`).
    Drift,
}

impl Kind {
    pub fn name(self) -> &'static str {
        match self {
            Kind::State => "state",
            Kind::Cycle => "cycle",
            Kind::Status => "status",
            Kind::Alarm => "alarm",
            Kind::Link => "link",
            Kind::Drift => "drift",
        }
    }

    fn qos(self) -> QoS {
        match self {
            Kind::Status => QoS::AtMostOnce,
            _ => QoS::AtLeastOnce,
        }
    }

    fn retain(self) -> bool {
        matches!(self, Kind::State | Kind::Status | Kind::Alarm | Kind::Drift)
    }
}

/// `hammer/<site>/<device>/<kind>`.
pub fn topic(site: &str, device: &str, kind: Kind) -> String {
    format!("hammer/{site}/{device}/{}", kind.name())
}

/// `mqtt://HOST[:PORT]` (1883) or `mqtts://HOST[:PORT]` (TLS, 8883) →
/// (host, port, tls).
pub fn parse_url(url: &str) -> Result<(String, u16, bool)> {
    let shown = crate::tls::redacted_url(url);
    let (rest, tls) = if let Some(r) = url.strip_prefix("mqtts://") {
        (r, true)
    } else if let Some(r) = url.strip_prefix("mqtt://") {
        (r, false)
    } else {
        bail!("--mqtt {shown}: an MQTT broker is mqtt://HOST[:PORT] or, over TLS, mqtts://HOST[:PORT]");
    };
    let rest = rest.trim_end_matches('/');
    if rest.contains('@') {
        bail!("--mqtt {shown}: no user or password in the URL (they would show in `ps`); use --mqtt-user and HAMMER_MQTT_PASSWORD or --mqtt-password-file");
    }
    let (host, port) = match rest.rsplit_once(':') {
        Some((h, p)) => (h, p.parse().with_context(|| format!("--mqtt {shown}: port {p:?}"))?),
        None => (rest, if tls { 8883 } else { 1883 }),
    };
    if host.is_empty() {
        bail!("--mqtt {shown}: no host");
    }
    Ok((host.to_string(), port, tls))
}

/// Counters a caller can read while the publisher runs.
#[derive(Debug, Default)]
pub struct Counters {
    pub published: AtomicU64,
    pub replayed: AtomicU64,
    pub buffered: AtomicU64,
    pub dropped: AtomicU64,
    /// Damaged records found in the outage buffer and skipped.
    pub damaged: AtomicU64,
    pub online: AtomicBool,
    /// The broker's latest refusal, until a connection succeeds.
    pub refusal: Mutex<Option<String>>,
    /// Things to show the user (refusals, TLS warnings), taken by the monitor.
    pub notes: Mutex<Vec<String>>,
}

impl Counters {
    fn note(&self, text: String) {
        self.notes.lock().unwrap_or_else(|e| e.into_inner()).push(text);
    }

    /// The notes since the last call.
    pub fn take_notes(&self) -> Vec<String> {
        std::mem::take(&mut *self.notes.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// The broker's refusal, if the latest connection was refused.
    pub fn refused(&self) -> Option<String> {
        self.refusal.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Data this publisher lost, or did not deliver (the broker refused or
    /// stayed away; what waits in the buffer goes out with the next run):
    /// what makes a run end non-zero.
    pub fn undelivered(&self) -> bool {
        self.dropped.load(Ordering::Relaxed) > 0
            || self.damaged.load(Ordering::Relaxed) > 0
            || self.buffered.load(Ordering::Relaxed) > 0
            || self.refused().is_some()
    }
}

/// Where and how a device publishes.
#[derive(Debug, Clone)]
pub struct Options {
    pub endpoint: Endpoint,
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
        let (buffer, damage) = Buffer::open(&o.buffer_dir.join(format!("{}.jsonl", o.device)), o.buffer_bytes);
        let counters = Arc::new(Counters::default());
        counters.damaged.store(damage.records, Ordering::Relaxed);
        for n in damage.notes {
            counters.note(format!("mqtt {}: {n}", o.device));
        }
        counters.buffered.store(buffer.queue.len() as u64, Ordering::Relaxed);
        let (tx, rx) = mpsc::channel();
        let state = topic(&o.site, &o.device, Kind::State);
        let mut opts = o.endpoint.options(format!("hammer-{}-{}", o.site, o.device));
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
            endpoint: o.endpoint.clone(),
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
        let mut s = format!(
            "mqtt {}: {} published ({} replayed from the outage buffer), {} still buffered, {} dropped at the buffer's cap",
            device,
            c.published.load(Ordering::Relaxed),
            c.replayed.load(Ordering::Relaxed),
            c.buffered.load(Ordering::Relaxed),
            c.dropped.load(Ordering::Relaxed)
        );
        let damaged = c.damaged.load(Ordering::Relaxed);
        if damaged > 0 {
            s += &format!(", {damaged} damaged records in the buffer skipped");
        }
        if let Some(r) = c.refused() {
            s += &format!("; NOT DELIVERED, refused: {r}");
        }
        s
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
    endpoint: Endpoint,
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
        let had_file = self.buffer.file.is_some();
        let (dropped, failed) = self.buffer.push_back(m);
        self.counters.dropped.fetch_add(dropped, Ordering::Relaxed);
        if let Some(e) = failed {
            if had_file {
                self.counters.note(format!(
                    "mqtt {}: the outage buffer failed ({e:#}); buffering in memory until it can be written",
                    self.device
                ));
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
        let had_file = self.buffer.file.is_some();
        if let Err(e) = self.buffer.push_front_all(back) {
            if had_file {
                self.counters.note(format!(
                    "mqtt {}: the outage buffer failed ({e:#}); buffering in memory until it can be written",
                    self.device
                ));
            }
        }
        self.counters
            .buffered
            .store(self.buffer.queue.len() as u64, Ordering::Relaxed);
    }

    /// One connection, until it fails (said how) or the monitor stops and
    /// all is sent.
    fn connection(&mut self) -> Option<Failure> {
        if let Some(w) = self.endpoint.connection_warning() {
            self.counters.note(w);
        }
        let (client, mut conn): (Client, Connection) = Client::new(self.opts.clone(), MAX_INFLIGHT * 2);
        let mut drain_deadline = None;
        let mut acked = false;
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
                    return None;
                }
            }
            if self.online() {
                self.feed(&client);
            }
            // Until the broker has answered, the client is connecting (TCP,
            // TLS, CONNECT): a timeout here would drop that half-made
            // connection and start over, so a handshake slower than the
            // poll (a remote broker) would never finish. It has its own
            // timeout (5 s); new messages wait in the channel meanwhile.
            let wait = if acked {
                Duration::from_millis(20)
            } else {
                Duration::from_secs(30)
            };
            match conn.recv_timeout(wait) {
                Ok(Ok(Event::Incoming(Packet::ConnAck(_)))) => {
                    acked = true;
                    self.counters.online.store(true, Ordering::Relaxed);
                    if self
                        .counters
                        .refusal
                        .lock()
                        .unwrap_or_else(|e| e.into_inner())
                        .take()
                        .is_some()
                    {
                        self.counters.note(format!(
                            "mqtt {}: connected to {}",
                            self.device,
                            self.endpoint.describe()
                        ));
                    }
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
                Ok(Err(e)) => {
                    self.lost();
                    return Some(self.endpoint.failure(&e, acked));
                }
                Err(RecvTimeoutError::Disconnected) => {
                    self.lost();
                    return Some(Failure {
                        text: format!("{}: the MQTT client stopped", self.endpoint.describe()),
                        refused: false,
                    });
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
        }
    }

    /// Says a failure once (not at every retry) and keeps a refusal for the
    /// dashboard and the closing line.
    fn report(&mut self, f: &Failure, last: &mut Option<String>) {
        if last.as_deref() != Some(f.text.as_str()) {
            self.counters.note(format!("mqtt {}: {}", self.device, f.text));
            *last = Some(f.text.clone());
        }
        *self.counters.refusal.lock().unwrap_or_else(|e| e.into_inner()) = f.refused.then(|| f.text.clone());
    }

    fn run(&mut self) {
        self.run_connections();
        if self.buffer.file.is_none() && !self.buffer.queue.is_empty() {
            // One more try to keep them for the next run.
            if self.buffer.rewrite().is_err() {
                let n = self.buffer.queue.len() as u64;
                self.counters.dropped.fetch_add(n, Ordering::Relaxed);
                self.counters.note(format!(
                    "mqtt {}: {n} undelivered messages could not be written to the outage buffer {} and are lost",
                    self.device,
                    self.buffer.path.display()
                ));
                self.counters.buffered.store(0, Ordering::Relaxed);
            }
        }
    }

    fn run_connections(&mut self) {
        let mut backoff = RETRY;
        let mut last = None;
        loop {
            let failure = self.connection();
            if let Some(f) = &failure {
                self.report(f, &mut last);
            }
            if self.closing {
                return;
            }
            // A refusal waits longer each time; anything else (the broker
            // away) is asked again every RETRY.
            let pause = match &failure {
                Some(f) if f.refused => {
                    let p = backoff;
                    backoff = (backoff * 2).min(MAX_BACKOFF);
                    p
                }
                _ => {
                    backoff = RETRY;
                    RETRY
                }
            };
            // Offline: keep buffering while waiting to retry.
            let until = std::time::Instant::now() + pause;
            while std::time::Instant::now() < until {
                if !self.take_new() {
                    self.closing = true;
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            if self.closing {
                // One last try to deliver, then keep the rest on disk.
                if let Some(f) = self.connection() {
                    self.report(&f, &mut last);
                }
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
        assert_eq!(
            parse_url("mqtt://127.0.0.1:1884").unwrap(),
            ("127.0.0.1".into(), 1884, false)
        );
        assert_eq!(parse_url("mqtt://broker").unwrap(), ("broker".into(), 1883, false));
        assert_eq!(parse_url("mqtts://b").unwrap(), ("b".into(), 8883, true));
        let e = parse_url("mqtts://u:secret@b").unwrap_err().to_string();
        assert!(
            !e.contains("secret") && e.contains("<redacted>@b"),
            "no credentials in a URL, nor in its refusal: {e}"
        );
        let e = parse_url("tcp://u:secret@b").unwrap_err().to_string();
        assert!(!e.contains("secret"), "{e}");
        assert!(parse_url("ssl://b").is_err());
        assert!(parse_url("mqtt://:1883").is_err());
        assert!(parse_url("mqtt://b:x").is_err());
    }

    fn msg(k: u64) -> Message {
        Message {
            kind: Kind::Cycle,
            body: json!({"publish_seq": k, "friction_n": 10.27}),
        }
    }

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("hammer-mqtt-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        crate::private_files::ensure_private_dir(&dir).unwrap();
        dir
    }

    fn seqs(b: &Buffer) -> Vec<u64> {
        b.queue
            .iter()
            .map(|(m, _)| m.body["publish_seq"].as_u64().unwrap())
            .collect()
    }

    #[test]
    fn the_buffer_keeps_order_survives_a_restart_and_drops_the_oldest_at_its_cap() {
        let dir = scratch("buf");
        let path = dir.join("d.jsonl");
        let (mut b, damage) = Buffer::open(&path, 10_000);
        assert_eq!(damage.records, 0);
        for k in 0..10 {
            assert_eq!(b.push_back(msg(k)).0, 0);
        }
        assert_eq!(b.pop_front().unwrap().body["publish_seq"], 0);
        b.push_front_all(vec![msg(0)]).unwrap();
        drop(b);
        use std::os::unix::fs::PermissionsExt;
        assert_eq!(std::fs::metadata(&path).unwrap().permissions().mode() & 0o777, 0o600);
        let (mut b, _) = Buffer::open(&path, 10_000);
        assert_eq!(seqs(&b), (0..10).collect::<Vec<_>>());
        // A cap of about 5 messages: the oldest go, counted, the newest stay.
        let one = b.queue[0].1;
        b.cap = 5 * one + 2;
        let (dropped, failed) = b.push_back(msg(10));
        assert!(failed.is_none());
        assert!(b.bytes <= b.cap, "{} bytes over a cap of {}", b.bytes, b.cap);
        assert_eq!(b.queue.len() as u64, 11 - dropped);
        assert!((6..=7).contains(&dropped), "{dropped}");
        assert_eq!(b.queue.front().unwrap().0.body["publish_seq"], dropped);
        assert_eq!(b.queue.back().unwrap().0.body["publish_seq"], 10);
        drop(b);
        let (b, _) = Buffer::open(&path, usize::MAX);
        assert_eq!(
            b.queue.len() as u64,
            11 - dropped,
            "the file holds what the queue holds"
        );
        let leftovers: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(leftovers, ["d.jsonl"], "no temporary file left");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Ten good records, one of them damaged the way `damage` does it (which
    /// may add damaged lines): the other nine come back in order, the
    /// `damaged` lines are counted, and the file is clean after.
    fn damaged_buffer_keeps_the_intact(name: &str, damaged: u64, damage: impl Fn(&mut Vec<u8>)) {
        let dir = scratch(name);
        let path = dir.join("d.jsonl");
        let (mut b, _) = Buffer::open(&path, usize::MAX);
        for k in 0..10 {
            b.push_back(msg(k));
        }
        drop(b);
        let mut bytes = std::fs::read(&path).unwrap();
        damage(&mut bytes);
        std::fs::write(&path, &bytes).unwrap();
        let (b, d) = Buffer::open(&path, usize::MAX);
        assert_eq!(d.records, damaged, "{name}: the damaged records counted");
        assert!(
            d.notes[0].contains(&format!("{damaged} damaged records")),
            "{:?}",
            d.notes
        );
        let kept = seqs(&b);
        assert_eq!(kept.len(), 9, "{name}: {kept:?}");
        assert!(kept.windows(2).all(|w| w[0] < w[1]), "{name}: in order");
        assert!(
            b.queue.iter().all(|(m, _)| m.body["friction_n"] == 10.27),
            "{name}: no damaged value passes"
        );
        drop(b);
        let (b, d) = Buffer::open(&path, usize::MAX);
        assert_eq!((d.records, b.queue.len()), (0, 9), "{name}: counted once");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_flipped_digit_fails_its_checksum() {
        damaged_buffer_keeps_the_intact("flip", 1, |b| {
            let text = String::from_utf8(b.clone()).unwrap();
            let third = text.match_indices("10.27").nth(3).unwrap().0;
            b[third + 1] = b'1'; // 10.27 -> 11.27, still JSON
        });
    }

    #[test]
    fn an_invalid_utf8_byte_costs_its_record_only() {
        damaged_buffer_keeps_the_intact("utf8", 1, |b| {
            let second_line = b.iter().position(|&c| c == b'\n').unwrap() + 20;
            b[second_line] = 0xff;
        });
    }

    #[test]
    fn appended_garbage_or_a_torn_record_is_skipped() {
        damaged_buffer_keeps_the_intact("garbage", 3, |b| {
            // The first record replaced by binary garbage of the same length.
            let end = b.iter().position(|&c| c == b'\n').unwrap();
            for (i, c) in b[..end].iter_mut().enumerate() {
                *c = (i as u8).wrapping_mul(37) | 0x80;
            }
            // and a byte of garbage appended after the last record, then a
            // record cut short by a crash.
            b.extend_from_slice(b"\xff\n");
            b.extend_from_slice(b"0badc0de {\"kind\":\"cy");
        });
    }

    #[test]
    fn an_unreadable_buffer_is_set_aside_and_a_new_one_started() {
        let dir = scratch("unreadable");
        let path = dir.join("d.jsonl");
        // A directory where the file should be: opens, cannot be read.
        std::fs::create_dir(&path).unwrap();
        let (mut b, d) = Buffer::open(&path, usize::MAX);
        assert!(d.notes.iter().any(|n| n.contains("set aside")), "{:?}", d.notes);
        assert!(b.file.is_some());
        assert!(b.push_back(msg(1)).1.is_none(), "publishing goes on with a new file");
        drop(b);
        let (b, _) = Buffer::open(&path, usize::MAX);
        assert_eq!(seqs(&b), [1]);
        let names: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(names.iter().any(|n| n.starts_with("d.jsonl.unreadable-")), "{names:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_planted_symlink_is_never_followed() {
        let dir = scratch("plant");
        let victim = dir.join("victim.txt");
        std::fs::write(&victim, "the victim's data\n").unwrap();
        let path = dir.join("d.jsonl");
        std::os::unix::fs::symlink(&victim, &path).unwrap();
        let (mut b, d) = Buffer::open(&path, usize::MAX);
        assert!(d.notes.iter().any(|n| n.contains("set aside")), "{:?}", d.notes);
        b.push_back(msg(1));
        b.push_front_all(vec![msg(0)]).unwrap();
        drop(b);
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "the victim's data\n");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_shared_buffer_directory_is_refused_for_a_private_one() {
        use std::os::unix::fs::PermissionsExt;
        let dir = scratch("shared");
        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o1777)).unwrap();
        let (used, note) = buffer_dir(Some(&dir)).unwrap();
        assert_ne!(used, dir);
        let note = note.expect("says so");
        assert!(
            note.contains("writable by other users") && note.contains(&used.display().to_string()),
            "{note}"
        );
        assert_eq!(std::fs::metadata(&used).unwrap().permissions().mode() & 0o777, 0o700);
        let _ = std::fs::remove_dir_all(&dir);
        let _ = std::fs::remove_dir_all(&used);
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
    /// The broker, mqtt://HOST[:PORT] or mqtts://HOST[:PORT].
    #[arg(long, value_name = "URL")]
    pub mqtt: String,
    #[command(flatten)]
    pub broker: BrokerArgs,
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
    let endpoint = Endpoint::resolve(&args.mqtt, &args.broker)?;
    let mut opts = endpoint.options(format!("hammer-tail-{}", std::process::id()));
    opts.set_keep_alive(Duration::from_secs(5));
    let (client, mut conn) = Client::new(opts, 16);
    let filter = format!("hammer/{}/#", args.site);
    let mut cycles = 0u64;
    let mut out = std::io::stdout().lock();
    let mut last: Option<String> = None;
    let mut backoff = RETRY;
    let mut acked = false;
    if let Some(w) = endpoint.connection_warning() {
        eprintln!("{w}");
    }
    loop {
        match conn.recv() {
            Ok(Ok(Event::Incoming(Packet::ConnAck(_)))) => {
                acked = true;
                last = None;
                backoff = RETRY;
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
                let f = endpoint.failure(&e, acked);
                acked = false;
                let pause = if f.refused {
                    let p = backoff;
                    backoff = (backoff * 2).min(MAX_BACKOFF);
                    p
                } else {
                    RETRY
                };
                if last.as_deref() != Some(f.text.as_str()) {
                    eprintln!("mqtt-tail: {}; trying again in {} s", f.text, pause.as_secs());
                    last = Some(f.text);
                }
                std::thread::sleep(pause);
                if let Some(w) = endpoint.connection_warning() {
                    eprintln!("{w}");
                }
            }
            Err(_) => bail!("the MQTT connection ended"),
        }
    }
}
