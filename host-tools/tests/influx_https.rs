//! `--influx https://…` against a local TLS server (rustls, with a CA and
//! certificate made by `openssl`): the gzip batches arrive whole with the
//! token, every printed report once; a server certificate from another CA
//! is refused with a message naming `--influx-ca`, the run exits non-zero,
//! and the token is in no output.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpListener;
use std::path::Path;
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use rustls::pki_types::pem::PemObject;
use rustls::pki_types::{CertificateDer, PrivateKeyDer};

mod pki;

const TOKEN: &str = "influx-tok-93be1d";

/// One request as the server saw it: its Authorization header, whether
/// the body was gzip, the body's lines.
struct Request {
    auth: Option<String>,
    gzip: bool,
    lines: Vec<String>,
}

/// A TLS write endpoint on 127.0.0.1 answering 204 to every POST, until `stop`.
fn server(p: &pki::Pki, stop: Arc<AtomicBool>) -> (u16, std::thread::JoinHandle<Vec<Request>>) {
    let certs: Vec<CertificateDer<'static>> = CertificateDer::pem_file_iter(&p.server_cert)
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    let key = PrivateKeyDer::from_pem_file(&p.server_key).unwrap();
    let config = Arc::new(
        rustls::ServerConfig::builder_with_provider(Arc::new(rustls::crypto::ring::default_provider()))
            .with_safe_default_protocol_versions()
            .unwrap()
            .with_no_client_auth()
            .with_single_cert(certs, key)
            .unwrap(),
    );
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    listener.set_nonblocking(true).unwrap();
    let port = listener.local_addr().unwrap().port();
    let handle = std::thread::spawn(move || {
        let mut got = vec![];
        while !stop.load(Ordering::Relaxed) {
            let Ok((tcp, _)) = listener.accept() else {
                std::thread::sleep(Duration::from_millis(10));
                continue;
            };
            tcp.set_nonblocking(false).unwrap();
            tcp.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
            let conn = rustls::ServerConnection::new(config.clone()).unwrap();
            let mut tls = rustls::StreamOwned::new(conn, tcp);
            // A refused handshake ends here: the client closed it.
            let mut r = BufReader::new(&mut tls);
            let (mut len, mut gzip, mut auth) = (0usize, false, None);
            let mut ok = true;
            loop {
                let mut h = String::new();
                if r.read_line(&mut h).unwrap_or(0) == 0 {
                    ok = false;
                    break;
                }
                if h == "\r\n" {
                    break;
                }
                let lower = h.to_ascii_lowercase();
                if let Some(v) = lower.strip_prefix("content-length:") {
                    len = v.trim().parse().unwrap();
                }
                gzip |= lower.starts_with("content-encoding: gzip");
                if lower.starts_with("authorization:") {
                    auth = Some(h["authorization:".len()..].trim().to_string());
                }
            }
            if !ok {
                continue;
            }
            let mut body = vec![0; len];
            r.read_exact(&mut body).unwrap();
            let mut text = String::new();
            flate2::read::GzDecoder::new(&body[..])
                .read_to_string(&mut text)
                .unwrap();
            tls.write_all(b"HTTP/1.1 204 No Content\r\nContent-Length: 0\r\nConnection: close\r\n\r\n")
                .unwrap();
            tls.conn.send_close_notify();
            let _ = tls.flush();
            got.push(Request {
                auth,
                gzip,
                lines: text.lines().map(String::from).collect(),
            });
        }
        got
    });
    (port, handle)
}

fn demo(port: u16, ca: &Path, token: &str, extra: &[&str]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args(["demo", "--headless", "--native", "--cycles", "30"])
        .args([
            "--influx",
            &format!("https://127.0.0.1:{port}/api/v2/write?org=o&bucket=b"),
        ])
        .arg("--influx-ca")
        .arg(ca)
        .args(extra)
        .env("INFLUX_TOKEN", token)
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn batches_arrive_gzip_with_the_token_and_another_ca_is_refused() {
    if !pki::openssl_present() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("hammer-influx-https-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let p = pki::make(&dir.join("pki"));

    let stop = Arc::new(AtomicBool::new(false));
    let (port, srv) = server(&p, stop.clone());
    let (ok, stdout, stderr) = demo(port, &p.ca, TOKEN, &[]);
    stop.store(true, Ordering::Relaxed);
    let got = srv.join().unwrap();
    assert!(ok, "{stdout}\n{stderr}");
    assert!(!got.is_empty());
    assert!(got
        .iter()
        .all(|r| r.gzip && r.auth.as_deref() == Some(&format!("Token {TOKEN}"))));
    let seqs: Vec<String> = got
        .iter()
        .flat_map(|r| r.lines.iter())
        .map(|l| hammer_host::influx::parse(l).unwrap().fields[0].1.clone())
        .collect();
    let printed: Vec<String> = stdout
        .lines()
        .filter_map(|l| l.strip_prefix("cycle "))
        .map(|l| format!("{}i", l.split_whitespace().next().unwrap()))
        .collect();
    assert!(printed.len() >= 30, "{stdout}");
    assert_eq!(seqs, printed, "every printed report once, in order");
    assert!(
        stderr.contains(&format!("{} lines written, 0 not delivered", printed.len())),
        "{stderr}"
    );
    assert!(!stdout.contains(TOKEN) && !stderr.contains(TOKEN), "the token leaked");

    // The token from a file; a server certificate the given CA did not sign.
    let token_file = dir.join("token");
    std::fs::write(&token_file, format!("{TOKEN}\n")).unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let (port, srv) = server(&p, stop.clone());
    let (ok, stdout, stderr) = demo(
        port,
        &p.other_ca,
        "",
        &["--influx-token-file", &token_file.display().to_string()],
    );
    stop.store(true, Ordering::Relaxed);
    let got = srv.join().unwrap();
    assert!(!ok, "a lost export ends non-zero:\n{stderr}");
    assert!(got.is_empty(), "nothing reached the server");
    assert!(
        stderr.contains("not signed by a CA")
            && stderr.contains("--influx-ca")
            && stderr.contains(&format!("127.0.0.1:{port}")),
        "{stderr}"
    );
    assert!(stderr.contains("0 lines written"), "{stderr}");
    assert!(!stdout.contains(TOKEN) && !stderr.contains(TOKEN), "the token leaked");
    let _ = std::fs::remove_dir_all(&dir);
}
