//! The demo board publishing to a real Mosquitto, through a broker outage:
//! every cycle report the demo prints arrives, in order, with the printed
//! numbers, once by its `publish_seq` (QoS 1 may repeat the one in flight
//! when the broker went down); those produced while the broker was down
//! arrive flagged historical once it is back. Needs QEMU, the emulated firmware and
//! Mosquitto (`.ci/run` installs it; without it the test says so and
//! passes only outside CI).

use std::collections::BTreeMap;
use std::net::TcpListener;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use rumqttc::{Client, Event, MqttOptions, Packet, QoS};
use serde_json::Value;

fn mosquitto_present() -> bool {
    let ok = Command::new("mosquitto")
        .arg("-h")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok();
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but mosquitto is missing (.ci/run installs it)"
        );
        eprintln!("SKIPPED: mosquitto is not installed (apt-get install mosquitto)");
    }
    ok
}

fn free_port() -> u16 {
    TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// A broker on 127.0.0.1:`port` that keeps sessions across a restart.
fn broker(dir: &Path, port: u16) -> Child {
    let conf = dir.join("mosquitto.conf");
    std::fs::write(
        &conf,
        format!(
            "listener {port} 127.0.0.1\nallow_anonymous true\npersistence true\npersistence_location {}/\n",
            dir.display()
        ),
    )
    .unwrap();
    let child = Command::new("mosquitto")
        .arg("-c")
        .arg(&conf)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
        assert!(Instant::now() < deadline, "mosquitto did not start");
        std::thread::sleep(Duration::from_millis(20));
    }
    child
}

/// Stops the broker the way a service manager would (it saves its sessions).
fn stop(mut b: Child) {
    let _ = Command::new("kill").arg("-TERM").arg(b.id().to_string()).status();
    let _ = b.wait();
}

/// A subscriber with a persistent session: what the broker holds for it
/// while it is away arrives when it is back.
fn subscribe(port: u16, got: Arc<Mutex<Vec<(String, Value)>>>, stop: Arc<AtomicBool>) -> std::thread::JoinHandle<()> {
    std::thread::spawn(move || {
        let mut opts = MqttOptions::new("hammer-test-sub", "127.0.0.1", port);
        opts.set_clean_session(false);
        opts.set_keep_alive(Duration::from_secs(5));
        let (client, mut conn) = Client::new(opts, 64);
        while !stop.load(Ordering::Relaxed) {
            match conn.recv_timeout(Duration::from_millis(100)) {
                Ok(Ok(Event::Incoming(Packet::ConnAck(_)))) => {
                    client.subscribe("hammer/#", QoS::AtLeastOnce).unwrap();
                }
                Ok(Ok(Event::Incoming(Packet::Publish(p)))) => {
                    let v: Value = serde_json::from_slice(&p.payload).unwrap();
                    got.lock().unwrap().push((p.topic.clone(), v));
                }
                Ok(Ok(_)) => {}
                Ok(Err(_)) => std::thread::sleep(Duration::from_millis(200)),
                Err(rumqttc::RecvTimeoutError::Timeout) => {}
                Err(_) => return,
            }
        }
    })
}

#[test]
fn every_report_arrives_once_in_order_through_a_broker_outage() {
    if !mosquitto_present() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("hammer-mqtt-test-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let port = free_port();
    let b = broker(&dir, port);
    let got = Arc::new(Mutex::new(vec![]));
    let done = Arc::new(AtomicBool::new(false));
    let sub = subscribe(port, got.clone(), done.clone());
    let cycles = |got: &Mutex<Vec<(String, Value)>>| {
        got.lock()
            .unwrap()
            .iter()
            .filter(|(t, _)| t.ends_with("/cycle"))
            .count()
    };
    // The subscriber connects and subscribes within a moment.
    std::thread::sleep(Duration::from_secs(1));
    // 400 cycles at the hammer's own pace: about 19 s.
    let demo = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args(["demo", "--headless", "--real-time", "--cycles", "400"])
        .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}"), "--site", "ci"])
        .arg("--mqtt-buffer")
        .arg(dir.join("buffer"))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Once reports flow, the broker goes away for 10 s, then comes back.
    let deadline = Instant::now() + Duration::from_secs(60);
    while cycles(&got) < 20 {
        assert!(Instant::now() < deadline, "no reports reached the broker");
        std::thread::sleep(Duration::from_millis(20));
    }
    stop(b);
    std::thread::sleep(Duration::from_secs(10));
    let b = broker(&dir, port);
    let out = demo.wait_with_output().unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{stdout}\n{stderr}");
    let printed: BTreeMap<u64, f64> = stdout
        .lines()
        .filter_map(|l| {
            let w: Vec<&str> = l.split_whitespace().collect();
            (w.first() == Some(&"cycle")).then(|| (w[1].parse().unwrap(), w[6].parse().unwrap()))
        })
        .collect();
    assert!(printed.len() >= 400, "{stdout}");
    let deadline = Instant::now() + Duration::from_secs(30);
    while cycles(&got) < printed.len() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    done.store(true, Ordering::Relaxed);
    sub.join().unwrap();
    stop(b);

    let got = got.lock().unwrap();
    let device = "demo1-4.0bar";
    let of = |kind: &str| -> Vec<&Value> {
        got.iter()
            .filter(|(t, _)| *t == format!("hammer/ci/{device}/{kind}"))
            .map(|(_, v)| v)
            .collect()
    };
    // QoS 1 is at least once: what was in flight when the broker went down
    // (sent, never acknowledged) is sent again, flagged historical, under its
    // own publish_seq, by which a subscriber drops the repeat.
    let mut received: Vec<&Value> = vec![];
    let mut repeats = 0;
    for v in of("cycle") {
        if received.iter().any(|r| r["publish_seq"] == v["publish_seq"]) {
            assert_eq!(v["historical"], true, "a repeat is a replay: {v}");
            repeats += 1;
        } else {
            received.push(v);
        }
    }
    assert!(
        repeats <= 4,
        "{repeats} repeats: more than the reports in flight at the outage"
    );
    let seqs: Vec<u64> = received.iter().map(|v| v["seq"].as_u64().unwrap()).collect();
    let expected: Vec<u64> = printed.keys().copied().collect();
    assert_eq!(seqs, expected, "every printed report once, in order:\n{stderr}");
    for v in &received {
        let seq = v["seq"].as_u64().unwrap();
        assert!((v["friction_n"].as_f64().unwrap() - printed[&seq]).abs() < 0.006, "{v}");
        assert_eq!(v["device"], device);
    }
    let publish_seqs: Vec<u64> = received.iter().map(|v| v["publish_seq"].as_u64().unwrap()).collect();
    assert!(publish_seqs.windows(2).all(|w| w[0] < w[1]));
    let historical: Vec<u64> = received
        .iter()
        .filter(|v| v["historical"] == true)
        .map(|v| v["seq"].as_u64().unwrap())
        .collect();
    println!(
        "{} reports, {} of them replayed after the outage, {repeats} repeated",
        received.len(),
        historical.len()
    );
    assert!(
        historical.len() >= 150,
        "10 s of outage is ~210 reports, replayed: {historical:?}\n{stderr}"
    );
    // The first reports went out live.
    assert!(received[..10].iter().all(|v| v["historical"] == false));
    // Birth on connect, and the clean end says offline.
    let states = of("state");
    assert!(
        states
            .iter()
            .any(|v| v["online"] == true && v["protocol"] == hammer_wire::PROTOCOL_VERSION),
        "{states:?}"
    );
    assert_eq!(states.last().unwrap()["online"], false);
    assert!(stderr.contains("0 still buffered, 0 dropped"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn mqtt_tail_lines_name_the_device_and_the_flag() {
    let line = hammer_host::mqtt::tail_line(
        "hammer/lab/rig4/cycle",
        br#"{"seq":7,"friction_n":10.27,"impact_energy_j":3.9,"frequency_hz":21.4,"wear_index_j":6.5,"valid":true,"historical":true}"#,
    )
    .unwrap();
    assert!(
        line.starts_with("[rig4] cycle      7  friction 10.27 N") && line.ends_with("(historical)"),
        "{line}"
    );
    assert_eq!(
        hammer_host::mqtt::tail_line("hammer/lab/rig4/state", br#"{"online":false}"#).as_deref(),
        Some("[rig4] offline")
    );
    assert_eq!(hammer_host::mqtt::tail_line("hammer/lab/rig4/cycle", b"not json"), None);
}

/// `hammer demo --headless --devices 2 --mqtt …`, watched with
/// `mosquitto_sub -v -t 'hammer/#'`: both boards' births and cycle reports
/// on the broker, with the numbers the demo prints.
#[test]
fn two_boards_publish_their_births_and_reports() {
    if !mosquitto_present() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("hammer-mqtt-two-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let port = free_port();
    let b = broker(&dir, port);
    let sub = Command::new("mosquitto_sub")
        .args([
            "-h",
            "127.0.0.1",
            "-p",
            &port.to_string(),
            "-v",
            "-q",
            "1",
            "-t",
            "hammer/#",
        ])
        .stdout(Stdio::piped())
        .spawn()
        .expect("mosquitto_sub (Debian: mosquitto-clients)");
    std::thread::sleep(Duration::from_secs(1));
    let out = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args(["demo", "--headless", "--devices", "2", "--cycles", "15"])
        .args(["--mqtt", &format!("mqtt://127.0.0.1:{port}")])
        .arg("--mqtt-buffer")
        .arg(dir.join("buffer"))
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::thread::sleep(Duration::from_secs(1));
    let _ = Command::new("kill").arg(sub.id().to_string()).status();
    let seen_text = String::from_utf8_lossy(&sub.wait_with_output().unwrap().stdout).into_owned();
    stop(b);
    // "topic payload" lines.
    let got: Vec<(String, Value)> = seen_text
        .lines()
        .filter_map(|l| l.split_once(' '))
        .map(|(t, p)| (t.to_string(), serde_json::from_str(p).unwrap()))
        .collect();
    for device in ["demo1-4.0bar", "demo2-7.0bar"] {
        let prefix = format!("[{device}] cycle ");
        let printed: BTreeMap<u64, f64> = stdout
            .lines()
            .filter_map(|l| l.strip_prefix(&prefix))
            .map(|l| {
                let w: Vec<&str> = l.split_whitespace().collect();
                (w[0].parse().unwrap(), w[5].parse().unwrap())
            })
            .collect();
        assert!(printed.len() >= 15, "{device}: {stdout}");
        let topic = format!("hammer/lab/{device}/cycle");
        let seqs: Vec<u64> = got
            .iter()
            .filter(|(t, _)| *t == topic)
            .map(|(_, v)| v["seq"].as_u64().unwrap())
            .collect();
        assert_eq!(
            seqs,
            printed.keys().copied().collect::<Vec<_>>(),
            "{device}: once each, in order"
        );
        for (_, v) in got.iter().filter(|(t, _)| *t == topic) {
            let seq = v["seq"].as_u64().unwrap();
            assert!(
                (v["friction_n"].as_f64().unwrap() - printed[&seq]).abs() < 0.006,
                "{device} #{seq}"
            );
            assert_eq!(v["historical"], false);
        }
        let birth = format!("hammer/lab/{device}/state");
        assert!(
            got.iter().any(|(t, v)| *t == birth && v["online"] == true),
            "no birth from {device}:\n{seen_text}"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}
