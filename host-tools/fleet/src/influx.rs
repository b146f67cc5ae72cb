//! Cycle reports as InfluxDB line protocol, for a time-series database and
//! Grafana rather than a store of our own.
//!
//! One line per report, measurement `hammer_cycle`:
//! `hammer_cycle,device=<d>[,site=<s>][,supply_bar=<p>] <field>=<value>,... <ns>`.
//! Tags are what a query groups by: the device, the site if given, and the
//! configured gauge supply pressure in bar when the device knows it. Fields
//! are the report's one field table (`hammer_types::FIELDS`) under their
//! unit-suffixed names (integers as `12i`, the rest as floats; a non-finite
//! value is left out, which line protocol cannot carry), then `valid`
//! (boolean) and `flags` (string, names joined by `|`, `-` when none).
//!
//! Time: the device's own (`t_impact_s`, the sample clock's), anchored to
//! the host's clock at the first report of a connection, so the points keep
//! the device's spacing instead of the link's jitter; re-anchored when the
//! two drift more than [`REANCHOR_US`] apart (a device reset restarts its
//! clock). Written in nanoseconds (µs resolution), the default precision of
//! every InfluxDB write API, so no precision parameter is needed.
//!
//! Destinations ([`Destination::parse`]): a file (appended), `udp://HOST:PORT`
//! (one datagram per batch, kept under 1 400 bytes; a longer line goes as
//! lines of its series and time, which InfluxDB merges), or `http(s)://…` (the
//! URL of a write endpoint, e.g. `http://localhost:8086/api/v2/write?org=o&bucket=b`
//! or `…/write?db=hammer`; the body gzip-compressed). The token, from
//! `INFLUX_TOKEN` or `--influx-token-file`, becomes an `Authorization:
//! Token` header. HTTPS checks the server's certificate against the system's
//! roots or `--influx-ca`, with the rules of every TLS link ([`crate::tls`]).

use std::fs::File;
use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpStream, ToSocketAddrs, UdpSocket};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use hammer_estimator::fields::{Value, FIELDS};
use hammer_estimator::CycleReport;

use crate::records::flag_list;

pub const MEASUREMENT: &str = "hammer_cycle";
/// Device time and host time further apart than this: anchor again.
pub const REANCHOR_US: i64 = 1_000_000;
/// A UDP datagram stays under a typical path MTU.
const UDP_MAX: usize = 1_400;
/// Lines per HTTP request at most.
const HTTP_BATCH: usize = 5_000;

/// Escapes a tag value (commas, spaces, equals signs).
fn tag(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if matches!(c, ',' | ' ' | '=' | '\\') {
            out.push('\\');
        }
        if c != '\n' && c != '\r' {
            out.push(c);
        }
    }
    out
}

/// One report as a line, stamped `t_ns`.
pub fn line(device: &str, site: Option<&str>, supply_bar: Option<f64>, r: &CycleReport, t_ns: i64) -> String {
    let mut s = format!("{MEASUREMENT},device={}", tag(device));
    if let Some(site) = site {
        s += &format!(",site={}", tag(site));
    }
    if let Some(p) = supply_bar.filter(|p| p.is_finite()) {
        s += &format!(",supply_bar={p}");
    }
    let mut sep = ' ';
    for f in &FIELDS {
        let v = match f.value(r) {
            Value::U32(v) => format!("{v}i"),
            Value::F32(v) if v.is_finite() => format!("{v}"),
            Value::F64(v) if v.is_finite() => format!("{v}"),
            _ => continue,
        };
        s.push(sep);
        sep = ',';
        s += &format!("{}={v}", f.name);
    }
    s += &format!(",valid={},flags=\"{}\" {t_ns}", r.is_valid(), flag_list(r.flags));
    s
}

/// Measurement of the drift since commissioning (`hammer monitor --reference`).
pub const DRIFT_MEASUREMENT: &str = "hammer_drift";

/// One drift reading as a line: `hammer_drift,device=<d>[,site=<s>],supply_bar=<p>`
/// then its numeric fields (non-finite ones left out), `alarm` (boolean)
/// and `alarms` (string, the alarming characteristics joined by `|`, `-`
/// when none), stamped `t_ns` (the host's time of the reading).
pub fn drift_line(
    device: &str,
    site: Option<&str>,
    supply_bar: f64,
    fields: &[(String, f64)],
    alarms: &[&str],
    t_ns: i64,
) -> String {
    let mut s = format!("{DRIFT_MEASUREMENT},device={}", tag(device));
    if let Some(site) = site {
        s += &format!(",site={}", tag(site));
    }
    s += &format!(",supply_bar={supply_bar} ");
    for (name, v) in fields.iter().filter(|(_, v)| v.is_finite()) {
        s += &format!("{name}={v},");
    }
    let list = if alarms.is_empty() {
        "-".to_string()
    } else {
        alarms.join("|")
    };
    s += &format!("alarm={},alarms=\"{list}\" {t_ns}", !alarms.is_empty());
    s
}

/// Device time → host time, anchored per connection.
#[derive(Debug, Default, Clone, Copy)]
pub struct Anchor {
    /// Host µs minus device µs.
    offset_us: Option<i64>,
}

impl Anchor {
    /// A new connection: the next report anchors again.
    pub fn reset(&mut self) {
        self.offset_us = None;
    }

    /// The report's time in ns since the epoch, from its device time and the
    /// host time `host_us` it arrived at.
    pub fn stamp_ns(&mut self, r: &CycleReport, host_us: i64) -> i64 {
        let device_us = i64::try_from(r.t_impact_us).unwrap_or(i64::MAX);
        let offset = *self.offset_us.get_or_insert(host_us - device_us);
        let t = device_us + offset;
        let t = if (t - host_us).abs() > REANCHOR_US {
            self.offset_us = Some(host_us - device_us);
            host_us
        } else {
            t
        };
        t.saturating_mul(1_000)
    }
}

/// Where the lines go.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Destination {
    File(PathBuf),
    Udp(String),
    /// host:port, path with query, the URL as given, over TLS or not.
    Http {
        host: String,
        path: String,
        url: String,
        tls: bool,
    },
}

/// The token environment variable of every InfluxDB tool.
pub const TOKEN_ENV: &str = "INFLUX_TOKEN";

/// How to reach an HTTP(S) write endpoint: TLS files and the token's file.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct HttpArgs {
    /// https://: the CA certificate(s), PEM, that signed the server's
    /// certificate (default: the system's roots).
    #[arg(long, value_name = "FILE")]
    pub influx_ca: Option<PathBuf>,
    /// A file holding the InfluxDB token (its first line); default: the
    /// environment variable INFLUX_TOKEN. Never a command-line value.
    #[arg(long, value_name = "FILE")]
    pub influx_token_file: Option<PathBuf>,
    /// https:// WITHOUT checking the server's certificate: anyone on the
    /// path can read the token and change the data. For a test server
    /// only; every connection warns.
    #[arg(long)]
    pub influx_insecure_skip_verify: bool,
}

/// An HTTP(S) endpoint's TLS configuration and token, resolved once.
#[derive(Debug, Clone, Default)]
struct HttpAccess {
    tls: Option<Arc<rustls::ClientConfig>>,
    insecure: bool,
    token: Option<crate::tls::Secret>,
}

impl Destination {
    pub fn parse(s: &str) -> Result<Self> {
        let shown = crate::tls::redacted_url(s);
        if let Some(rest) = s.strip_prefix("udp://") {
            if rest.is_empty() || !rest.contains(':') {
                bail!("--influx {shown}: a UDP destination is udp://HOST:PORT");
            }
            return Ok(Self::Udp(rest.to_string()));
        }
        let (rest, tls) = match (s.strip_prefix("https://"), s.strip_prefix("http://")) {
            (Some(r), _) => (Some(r), true),
            (None, Some(r)) => (Some(r), false),
            _ => (None, false),
        };
        if let Some(rest) = rest {
            let (host, path) = match rest.find('/') {
                Some(i) => (&rest[..i], &rest[i..]),
                None => (rest, "/write"),
            };
            if host.is_empty() {
                bail!("--influx {shown}: no host");
            }
            let secret_param = path.split_once('?').is_some_and(|(_, q)| {
                q.split('&')
                    .any(|kv| matches!(kv.split('=').next(), Some("p" | "token")))
            });
            if secret_param {
                bail!("--influx: no password or token in the URL (they would show in `ps` and in messages); the token comes from {TOKEN_ENV} or --influx-token-file (v1 with a login: `user:password` as the token)");
            }
            if host.contains('@') {
                bail!("--influx {shown}: no credentials in the URL (they would show in `ps`); the token comes from {TOKEN_ENV} or --influx-token-file");
            }
            let host = if host.contains(':') {
                host.to_string()
            } else {
                format!("{host}:{}", if tls { 443 } else { 80 })
            };
            return Ok(Self::Http {
                host,
                path: path.to_string(),
                url: s.to_string(),
                tls,
            });
        }
        if s.contains("://") {
            bail!("--influx {shown}: a FILE, udp://HOST:PORT or http(s)://HOST:PORT/PATH");
        }
        Ok(Self::File(PathBuf::from(s)))
    }
}

/// Batches lines and sends them to a [`Destination`].
pub struct Writer {
    dest: Destination,
    http: HttpAccess,
    file: Option<File>,
    udp: Option<UdpSocket>,
    pending: Vec<String>,
    /// Lines written and lines a failed write could not deliver.
    pub lines: u64,
    pub lines_failed: u64,
}

impl Writer {
    /// Opens `dest`; `http` says how to reach an HTTP(S) endpoint.
    pub fn open(dest: Destination, http: &HttpArgs) -> Result<Self> {
        let mut w = Self {
            dest,
            http: HttpAccess::default(),
            file: None,
            udp: None,
            pending: vec![],
            lines: 0,
            lines_failed: 0,
        };
        match &w.dest {
            Destination::File(p) => {
                // A line torn by an earlier run (a full disk, a crash) is cut
                // back, so this run's first point starts on its own line.
                let (f, _, torn) = crate::private_files::open_append_whole_lines(p)
                    .with_context(|| format!("opening {}", p.display()))?;
                if torn > 0 {
                    eprintln!("influx: {}: cut back a torn last line ({torn} bytes)", p.display());
                }
                w.file = Some(f)
            }
            Destination::Udp(addr) => {
                let sock = UdpSocket::bind("0.0.0.0:0").context("binding a UDP socket")?;
                sock.connect(addr).with_context(|| format!("udp://{addr}"))?;
                w.udp = Some(sock);
            }
            Destination::Http { host, tls, .. } => {
                let name = host.rsplit_once(':').map_or(host.as_str(), |(h, _)| h);
                w.http = HttpAccess {
                    tls: tls
                        .then(|| {
                            crate::tls::server_name(name)?;
                            crate::tls::client_config(
                                &crate::tls::TlsFiles {
                                    ca: http.influx_ca.clone(),
                                    insecure: http.influx_insecure_skip_verify,
                                    ..Default::default()
                                },
                                "--influx",
                            )
                        })
                        .transpose()?,
                    insecure: http.influx_insecure_skip_verify,
                    token: match &http.influx_token_file {
                        Some(f) => Some(crate::tls::Secret::from_file(f, "--influx-token-file")?),
                        None => crate::tls::Secret::from_env(TOKEN_ENV),
                    },
                };
                if !tls && (http.influx_ca.is_some() || http.influx_insecure_skip_verify) {
                    bail!("--influx-ca and --influx-insecure-skip-verify are for https://");
                }
            }
        }
        Ok(w)
    }

    pub fn push(&mut self, line: String) -> Result<()> {
        self.pending.push(line);
        if self.pending.len() >= HTTP_BATCH {
            self.flush()?;
        }
        Ok(())
    }

    /// Sends what is pending. On failure the batch is counted in
    /// `lines_failed` and dropped (the logs keep every report).
    pub fn flush(&mut self) -> Result<()> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let batch = std::mem::take(&mut self.pending);
        let n = batch.len() as u64;
        let result = self.send(&batch);
        match &result {
            Ok(()) => self.lines += n,
            Err(_) => self.lines_failed += n,
        }
        result
    }

    fn send(&mut self, batch: &[String]) -> Result<()> {
        match &self.dest {
            Destination::File(p) => {
                let mut body = batch.join("\n");
                body.push('\n');
                let f = self.file.as_mut().expect("opened");
                // The batch whole or not at all: a short write (a full disk)
                // is cut back, so the count of lines written stays exact.
                let len = f.metadata().with_context(|| format!("{}", p.display()))?.len();
                f.write_all(body.as_bytes()).map_err(|e| {
                    let cut = f.set_len(len);
                    anyhow::Error::new(e).context(match cut {
                        Ok(()) => format!("writing {} (the batch is not in it)", p.display()),
                        Err(c) => format!(
                            "writing {} (and cutting back the partial batch failed: {c})",
                            p.display()
                        ),
                    })
                })
            }
            Destination::Udp(addr) => {
                let sock = self.udp.as_ref().expect("opened");
                let mut datagram = String::new();
                for l in batch.iter().flat_map(|l| shared_out(l, UDP_MAX - 1)) {
                    if !datagram.is_empty() && datagram.len() + l.len() + 1 > UDP_MAX {
                        sock.send(datagram.as_bytes())
                            .with_context(|| format!("udp://{addr}"))?;
                        datagram.clear();
                    }
                    datagram += &l;
                    datagram.push('\n');
                }
                sock.send(datagram.as_bytes())
                    .with_context(|| format!("udp://{addr}"))?;
                Ok(())
            }
            Destination::Http { host, path, url, .. } => {
                post(host, path, batch, &self.http).with_context(|| format!("POST {url}"))
            }
        }
    }
}

impl Drop for Writer {
    fn drop(&mut self) {
        if let Err(e) = self.flush() {
            eprintln!("influx: {e:#}");
        }
    }
}

/// One HTTP/1.1 POST of the batch, gzip-compressed, over TLS when asked;
/// any 2xx is success. A TLS failure says what to check.
fn post(host: &str, path: &str, batch: &[String], access: &HttpAccess) -> Result<()> {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    for l in batch {
        gz.write_all(l.as_bytes())?;
        gz.write_all(b"\n")?;
    }
    let body = gz.finish()?;
    let addr = host
        .to_socket_addrs()
        .with_context(|| format!("resolving {host}"))?
        .next()
        .with_context(|| format!("{host} has no address"))?;
    let s = TcpStream::connect_timeout(&addr, Duration::from_secs(5))?;
    s.set_read_timeout(Some(Duration::from_secs(10)))?;
    s.set_write_timeout(Some(Duration::from_secs(10)))?;
    let mut head = format!(
        "POST {path} HTTP/1.1\r\nHost: {host}\r\nContent-Type: text/plain; charset=utf-8\r\nContent-Encoding: gzip\r\nContent-Length: {}\r\nConnection: close\r\n",
        body.len()
    );
    if let Some(t) = &access.token {
        head += &format!("Authorization: Token {}\r\n", t.expose());
    }
    head += "\r\n";
    match &access.tls {
        None => exchange(s, head.as_bytes(), &body),
        Some(cfg) => {
            let name = host.rsplit_once(':').map_or(host, |(h, _)| h);
            if access.insecure {
                eprintln!(
                    "{}",
                    crate::tls::insecure_warning(&format!("https://{host}"), "--influx")
                );
            }
            let conn = rustls::ClientConnection::new(cfg.clone(), crate::tls::server_name(name)?)?;
            exchange(rustls::StreamOwned::new(conn, s), head.as_bytes(), &body).map_err(|e| {
                match crate::tls::rustls_error(e.as_ref()) {
                    Some(r) => anyhow::anyhow!(crate::tls::explain(r, host, name, "--influx", "http://")),
                    None => e,
                }
            })
        }
    }
}

/// Sends the request, reads the status: an error unless 2xx.
fn exchange(mut s: impl Read + Write, head: &[u8], body: &[u8]) -> Result<()> {
    s.write_all(head)?;
    s.write_all(body)?;
    s.flush()?;
    let mut reader = BufReader::new(s);
    let mut status = String::new();
    reader.read_line(&mut status)?;
    if status.is_empty() {
        bail!("the server closed the connection without an answer");
    }
    let code: u16 = status
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .with_context(|| format!("not an HTTP answer: {:?}", status.trim()))?;
    if !(200..300).contains(&code) {
        let mut rest = String::new();
        let _ = reader.take(4096).read_to_string(&mut rest);
        let body = rest.split("\r\n\r\n").nth(1).unwrap_or("").trim();
        bail!("{} {body}", status.trim());
    }
    Ok(())
}

/// `line` as lines of at most `max` bytes, one datagram each (a report
/// with its chambers read is about 1.5 KB): the same series and time, its
/// fields shared out in order. InfluxDB merges the fields of one series at
/// one time into one point, so the point is whole once all have arrived. A
/// line that fits is left as it is. This module's lines only: no space in
/// a field, no comma in a string field (numbers, booleans, flag names).
fn shared_out(line: &str, max: usize) -> Vec<String> {
    let mut esc = false;
    let series_end = line.char_indices().find_map(|(i, c)| {
        let end = c == ' ' && !esc;
        esc = c == '\\' && !esc;
        end.then_some(i)
    });
    let (Some(s), Some(t)) = (series_end, line.rfind(' ')) else {
        return vec![line.to_string()];
    };
    if line.len() <= max || t <= s {
        return vec![line.to_string()];
    }
    let (series, time) = (&line[..s], &line[t..]);
    let mut out = vec![];
    let mut fields = String::new();
    for f in line[s + 1..t].split(',') {
        if !fields.is_empty() && series.len() + 1 + fields.len() + 1 + f.len() + time.len() > max {
            out.push(format!("{series} {fields}{time}"));
            fields.clear();
        }
        if !fields.is_empty() {
            fields.push(',');
        }
        fields.push_str(f);
    }
    out.push(format!("{series} {fields}{time}"));
    out
}

/// A parsed line (for tests and tools): measurement, tags, fields as text, timestamp.
#[derive(Debug, Clone, PartialEq)]
pub struct Parsed {
    pub measurement: String,
    pub tags: Vec<(String, String)>,
    pub fields: Vec<(String, String)>,
    pub t_ns: i64,
}

/// Parses a line this module wrote (escaped tag values, quoted string fields).
pub fn parse(l: &str) -> Result<Parsed> {
    // Split at unescaped spaces outside quotes: series, fields, time
    // (escapes kept for the splits below).
    let mut parts = vec![String::new()];
    let (mut esc, mut quoted) = (false, false);
    for c in l.chars() {
        let cur = parts.last_mut().expect("one part at least");
        if esc {
            cur.push(c);
            esc = false;
            continue;
        }
        match c {
            '\\' => {
                cur.push(c);
                esc = true;
            }
            '"' => {
                quoted = !quoted;
                cur.push(c);
            }
            ' ' if !quoted => parts.push(String::new()),
            _ => cur.push(c),
        }
    }
    let [series, fields, time] =
        <[String; 3]>::try_from(parts).map_err(|p| anyhow::anyhow!("{} parts in {l:?}", p.len()))?;
    let split_unescaped = |s: &str, sep: char| -> Vec<String> {
        let mut out = vec![String::new()];
        let (mut esc, mut quoted) = (false, false);
        for c in s.chars() {
            if esc {
                out.last_mut().unwrap().push(c);
                esc = false;
            } else if c == '\\' {
                esc = true;
            } else if c == '"' {
                quoted = !quoted;
                out.last_mut().unwrap().push(c);
            } else if c == sep && !quoted {
                out.push(String::new());
            } else {
                out.last_mut().unwrap().push(c);
            }
        }
        out
    };
    let kv = |s: &str| -> Result<(String, String)> {
        let (k, v) = s.split_once('=').with_context(|| format!("no '=' in {s:?}"))?;
        Ok((k.to_string(), v.to_string()))
    };
    let mut series = split_unescaped(&series, ',').into_iter();
    let measurement = series.next().unwrap_or_default();
    let tags = series.map(|t| kv(&t)).collect::<Result<_>>()?;
    let fields = split_unescaped(&fields, ',')
        .iter()
        .map(|f| kv(f))
        .collect::<Result<_>>()?;
    Ok(Parsed {
        measurement,
        tags,
        fields,
        t_ns: time.parse().with_context(|| format!("timestamp {time:?}"))?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use hammer_estimator::Flags;

    fn report(seq: u32) -> CycleReport {
        CycleReport {
            seq,
            t_impact_us: 47_000 * u64::from(seq),
            friction_n: 10.27,
            impact_energy_j: 4.5,
            drift_score: f32::NAN,
            calibration_hash: 7,
            flags: Flags::IMPLAUSIBLE,
            ..Default::default()
        }
    }

    #[test]
    fn a_line_parses_back_to_the_report_and_skips_what_it_cannot_carry() {
        let r = report(3);
        let l = line("rig 4,a", Some("lab"), Some(4.0), &r, 1_764_000_000_000_000_000);
        let p = parse(&l).unwrap();
        assert_eq!(p.measurement, MEASUREMENT);
        assert_eq!(
            p.tags,
            [("device", "rig 4,a"), ("site", "lab"), ("supply_bar", "4")].map(|(a, b)| (a.to_string(), b.to_string()))
        );
        let field = |k: &str| p.fields.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
        assert_eq!(field("seq").as_deref(), Some("3i"));
        assert_eq!(field("friction_n").unwrap().parse::<f32>().unwrap(), 10.27);
        assert_eq!(field("t_impact_s").unwrap().parse::<f64>().unwrap(), r.t_impact_s());
        assert_eq!(field("drift_score"), None, "NaN is left out");
        assert_eq!(field("valid").as_deref(), Some("false"));
        assert_eq!(field("flags").as_deref(), Some("\"implausible\""));
        assert_eq!(p.t_ns, 1_764_000_000_000_000_000);
        assert_eq!(p.fields.len(), FIELDS.len() - 1 + 2);
    }

    /// Unread chambers (NaN) are left out, not written as a NaN that would
    /// make InfluxDB refuse the whole line; read ones are there to the bit.
    #[test]
    fn the_chambers_are_fields_when_read_and_left_out_when_not() {
        use crate::records::tests::{read_front, CHAMBERS};
        let mut unread = report(4);
        unread.mark_chambers_unread();
        let read = read_front(report(5));
        for r in [unread, read] {
            let l = line("rig", None, None, &r, 1);
            assert!(!l.contains("NaN") && !l.contains("inf"), "{l}");
            let p = parse(&l).unwrap();
            let field = |k: &str| p.fields.iter().find(|(n, _)| n == k).map(|(_, v)| v.clone());
            for (name, _) in CHAMBERS {
                let want = FIELDS.iter().find(|f| f.name == name).unwrap().value(&r);
                let Value::F32(want) = want else { panic!("{name}") };
                match field(name) {
                    Some(v) => assert_eq!(v.parse::<f32>().unwrap().to_bits(), want.to_bits(), "{name}"),
                    None => assert!(want.is_nan(), "{name} ({want}) is missing"),
                }
            }
            let (chambers, finite) = CHAMBERS.iter().fold((0, 0), |(n, k), (name, _)| {
                let v = FIELDS.iter().find(|f| f.name == *name).unwrap().f64(&r);
                (n + usize::from(field(name).is_some()), k + usize::from(v.is_finite()))
            });
            assert_eq!(chambers, finite);
            assert_eq!(p.fields.len(), FIELDS.len() - 1 - 18 + finite + 2, "{l}");
        }
        assert!(line("rig", None, None, &unread, 1).contains(r#"flags="implausible|chambers_unread""#));
    }

    #[test]
    fn device_time_keeps_its_spacing_and_a_reset_device_is_anchored_again() {
        let mut a = Anchor::default();
        let host0 = 1_764_000_000_000_000i64;
        // Arrivals jitter by up to 20 ms; the stamps keep 47 ms steps.
        let jitter = [0, 20_000, 3_000, 15_000];
        let stamps: Vec<i64> = (0..4u32)
            .map(|k| a.stamp_ns(&report(k), host0 + i64::from(k) * 47_000 + jitter[k as usize]))
            .collect();
        for w in stamps.windows(2) {
            assert_eq!(w[1] - w[0], 47_000_000);
        }
        // The device restarted its clock (a reset, 2 s later): host time again.
        let t = a.stamp_ns(&report(0), host0 + 2_000_000);
        assert_eq!(t, (host0 + 2_000_000) * 1000);
        let t = a.stamp_ns(&report(1), host0 + 2_060_000);
        assert_eq!(t, (host0 + 2_047_000) * 1000, "then its own spacing");
    }

    #[test]
    fn destinations_parse_or_say_what_is_wrong() {
        assert_eq!(
            Destination::parse("udp://127.0.0.1:8089").unwrap(),
            Destination::Udp("127.0.0.1:8089".into())
        );
        assert_eq!(
            Destination::parse("http://db:8086/api/v2/write?bucket=b").unwrap(),
            Destination::Http {
                host: "db:8086".into(),
                path: "/api/v2/write?bucket=b".into(),
                url: "http://db:8086/api/v2/write?bucket=b".into(),
                tls: false,
            }
        );
        assert_eq!(
            Destination::parse("https://cloud.example/api/v2/write?bucket=b").unwrap(),
            Destination::Http {
                host: "cloud.example:443".into(),
                path: "/api/v2/write?bucket=b".into(),
                url: "https://cloud.example/api/v2/write?bucket=b".into(),
                tls: true,
            }
        );
        let e = Destination::parse("https://user:t0ken@x/write").unwrap_err();
        assert!(
            !format!("{e:#}").contains("t0ken"),
            "the refusal names no credential: {e:#}"
        );
        let e = Destination::parse("https://:t0ken@/write").unwrap_err();
        assert!(!format!("{e:#}").contains("t0ken"), "{e:#}");
        let e = Destination::parse("http://x:8086/write?db=h&u=me&p=s3cret").unwrap_err();
        assert!(!format!("{e:#}").contains("s3cret"), "{e:#}");
        assert_eq!(
            Destination::parse("cycles.lp").unwrap(),
            Destination::File("cycles.lp".into())
        );
        assert!(Destination::parse("udp://nohost").is_err());
        assert!(Destination::parse("mqtt://x").is_err());
    }

    #[test]
    fn udp_batches_arrive_as_whole_lines() {
        let server = UdpSocket::bind("127.0.0.1:0").unwrap();
        server.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let addr = server.local_addr().unwrap();
        let mut w = Writer::open(
            Destination::parse(&format!("udp://{addr}")).unwrap(),
            &HttpArgs::default(),
        )
        .unwrap();
        for k in 0..20 {
            w.push(line("rig", None, None, &report(k), 1_000 + i64::from(k)))
                .unwrap();
        }
        w.flush().unwrap();
        let mut got = vec![];
        let mut buf = [0u8; 2048];
        while got.len() < 20 {
            let n = server.recv(&mut buf).unwrap();
            assert!(n <= UDP_MAX, "{n} bytes");
            got.extend(
                std::str::from_utf8(&buf[..n])
                    .unwrap()
                    .lines()
                    .map(|l| parse(l).unwrap()),
            );
        }
        let seqs: Vec<String> = got.iter().map(|p| p.fields[0].1.clone()).collect();
        assert_eq!(seqs, (0..20).map(|k| format!("{k}i")).collect::<Vec<_>>());
        assert_eq!(w.lines, 20);
    }

    /// A report with its chambers read makes a line over a datagram: it
    /// goes as lines of its series and time, each field once.
    #[test]
    fn a_line_over_a_datagram_is_shared_out_whole() {
        // Every number as long as an f32 prints, as a running hammer's are.
        let r = CycleReport {
            seq: 123_456,
            t_impact_us: 12_345_678_901,
            period_s: 0.046_812_345,
            frequency_hz: 21.362_345,
            friction_stroke_n: 10.236_917,
            friction_backhaul_n: 11.234_567,
            friction_uncertainty_n: 1.123_456_7,
            friction_stroke_uncertainty_n: 1.234_567_8,
            friction_backhaul_uncertainty_n: 1.345_678_9,
            impact_velocity_mps: 8.123_456_7,
            impact_velocity_frictionless_mps: 8.234_567_8,
            impact_energy_frictionless_j: 4.912_345_6,
            impact_energy_uncertainty_j: 0.166_123_45,
            impact_energy_frictionless_uncertainty_j: 0.180_123_45,
            friction_work_j: 0.452_345_67,
            friction_work_ratio: 0.100_523_45,
            stroke_m: 0.061_234_567,
            peak_rear_pa: 412_345.66,
            peak_front_pa: 398_765.44,
            accel_zero_shift_mps2: 1.234_567_8,
            wear_index_j: 123_456.79,
            wear_remaining_fraction: 0.997_654_3,
            remaining_life_cycles: 1.234_567_9e8,
            drift_score: 0.123_456_79,
            rear_feed_s: 2.345_678_9e-3,
            rear_feed_uncertainty_s: 3.456_789e-5,
            rear_feed_x_m: 0.012_345_67,
            rear_feed_p_rear_pa: 123_456.79,
            rear_feed_p_front_pa: 234_567.89,
            rear_closed_exponent: 1.234_567_8,
            rear_closed_exponent_uncertainty: 0.012_345_67,
            rear_feed_area_m2: 1.234_567_8e-5,
            rear_feed_area_uncertainty_m2: 1.234_567_8e-7,
            ..crate::records::tests::read_front(report(9))
        };
        let whole = line("rig 4,a", Some("lab"), Some(4.0), &r, 1_764_000_000_000_000_123);
        assert!(whole.len() > UDP_MAX, "{} bytes: make the report longer", whole.len());
        let server = UdpSocket::bind("127.0.0.1:0").unwrap();
        server.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
        let addr = server.local_addr().unwrap();
        let mut w = Writer::open(Destination::Udp(addr.to_string()), &HttpArgs::default()).unwrap();
        w.push(whole.clone()).unwrap();
        w.push(line("rig", None, None, &report(10), 7)).unwrap();
        w.flush().unwrap();
        let want = parse(&whole).unwrap();
        let (mut fields, mut buf, mut short) = (vec![], [0u8; 4096], None);
        while short.is_none() {
            let n = server.recv(&mut buf).unwrap();
            assert!(n <= UDP_MAX, "{n} bytes");
            for l in std::str::from_utf8(&buf[..n]).unwrap().lines() {
                let p = parse(l).unwrap();
                if p.t_ns == 7 {
                    short = Some(p);
                    continue;
                }
                assert_eq!(
                    (&p.measurement, &p.tags, p.t_ns),
                    (&want.measurement, &want.tags, want.t_ns)
                );
                fields.extend(p.fields);
            }
        }
        assert_eq!(fields, want.fields, "every field once, in order");
        assert_eq!(
            short.unwrap().fields.len(),
            FIELDS.len() - 1 + 2,
            "a short line as it is"
        );
        assert_eq!(shared_out("no fields", 4), ["no fields"]);
    }

    #[test]
    fn http_posts_gzip_and_reports_the_servers_refusal() {
        use std::net::TcpListener;
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let addr = listener.local_addr().unwrap();
        let server = std::thread::spawn(move || {
            let mut bodies = vec![];
            for status in ["204 No Content", "400 Bad Request"] {
                let (mut s, _) = listener.accept().unwrap();
                let mut r = BufReader::new(s.try_clone().unwrap());
                let mut len = 0;
                let mut gzip = false;
                loop {
                    let mut h = String::new();
                    r.read_line(&mut h).unwrap();
                    if h == "\r\n" {
                        break;
                    }
                    if let Some(v) = h.to_ascii_lowercase().strip_prefix("content-length:") {
                        len = v.trim().parse().unwrap();
                    }
                    gzip |= h.to_ascii_lowercase().starts_with("content-encoding: gzip");
                }
                let mut body = vec![0; len];
                r.read_exact(&mut body).unwrap();
                let mut text = String::new();
                flate2::read::GzDecoder::new(&body[..])
                    .read_to_string(&mut text)
                    .unwrap();
                bodies.push((gzip, text));
                write!(s, "HTTP/1.1 {status}\r\nContent-Length: 12\r\n\r\nbad request!").unwrap();
            }
            bodies
        });
        let mut w = Writer::open(
            Destination::parse(&format!("http://{addr}/api/v2/write?bucket=b")).unwrap(),
            &HttpArgs::default(),
        )
        .unwrap();
        w.push(line("rig", None, None, &report(1), 5)).unwrap();
        w.flush().unwrap();
        w.push(line("rig", None, None, &report(2), 6)).unwrap();
        let e = w.flush().unwrap_err();
        assert!(format!("{e:#}").contains("400 Bad Request"), "{e:#}");
        assert_eq!((w.lines, w.lines_failed), (1, 1));
        let bodies = server.join().unwrap();
        assert!(bodies[0].0, "gzip");
        assert_eq!(parse(bodies[0].1.trim()).unwrap().fields[0].1, "1i");
    }
}
