//! The fleet monitor's host side at full tilt: four boards' byte streams
//! (cycle reports at 4–7 bar from the simulator and the estimator, a status
//! a second, as the firmware sends them) through the monitor's decoding core,
//! its logs and the Parquet and line-protocol exports, one thread per board
//! as in `hammer monitor --port … --port …`. Prints frames handled per
//! second and CPU time per hour of hammer, against what four boards send
//! (≈ 22 frames/s each). Not a timed test: it prints figures.
//! `cargo bench -p hammer-host --bench fleet`

use std::sync::{Arc, Mutex};
use std::time::Instant;

use hammer_estimator::{CycleReport, Estimator};
use hammer_host::monitor::event::Stamped;
use hammer_host::monitor::export::{DeviceExport, ExportArgs, Exports};
use hammer_host::monitor::log::Logger;
use hammer_host::monitor::reader::Ingest;
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_wire::{encode, DeviceInfo, DeviceMsg, Status, MAX_FRAME, PROTOCOL_VERSION};

/// Reports of a board for `hours` of hammer, its one simulated second repeated.
fn stream(bar: f64, reports: usize) -> Vec<u8> {
    let mut cfg = SimConfig::nominal(bar);
    cfg.solver.duration_s = 1.0;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let sim = simulate(&cfg).unwrap();
    let mut est = Estimator::new(cfg.estimator_config(Some(bar)).unwrap()).unwrap();
    let mut one: Vec<CycleReport> = vec![];
    est.push_block(&sim.measured.codes, |r| one.push(r));
    let mut out = vec![];
    let mut buf = [0u8; MAX_FRAME];
    let mut put = |m: &DeviceMsg, out: &mut Vec<u8>| {
        let n = encode(m, &mut buf).unwrap();
        out.extend_from_slice(&buf[..n]);
    };
    put(
        &DeviceMsg::Hello(DeviceInfo {
            protocol_version: PROTOCOL_VERSION,
            firmware_version: [0, 1, 0],
            board: b"bench".iter().copied().collect(),
            config_hash: 1,
        }),
        &mut out,
    );
    for k in 0..reports {
        let r = CycleReport {
            seq: k as u32,
            ..one[k % one.len()]
        };
        put(&DeviceMsg::Report(r), &mut out);
        if k % 21 == 20 {
            put(&DeviceMsg::Status(Status::default()), &mut out);
        }
    }
    out
}

fn cpu_s() -> f64 {
    // utime + stime of this process, in clock ticks (USER_HZ = 100 on Linux).
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = after.split_whitespace().collect();
    let tick = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (tick(11) + tick(12)) / 100.0
}

fn main() {
    const BOARDS: usize = 4;
    const REPORTS: usize = 50_000; // 40 min of one hammer at 21 Hz
    let streams: Vec<Vec<u8>> = (0..BOARDS).map(|k| stream(4.0 + k as f64, REPORTS)).collect();
    let dir = std::env::temp_dir().join(format!("hammer-fleet-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let args = ExportArgs {
        parquet: Some(dir.join("pq")),
        influx: Some(dir.join("cycles.lp").display().to_string()),
        ..Default::default()
    };
    let exports = Exports::open(&args).unwrap().unwrap();
    let frames = Arc::new(Mutex::new(0u64));
    let (t0, c0) = (Instant::now(), cpu_s());
    std::thread::scope(|s| {
        for (k, bytes) in streams.iter().enumerate() {
            let (exports, frames, dir) = (exports.clone(), frames.clone(), dir.clone());
            s.spawn(move || {
                let name = format!("bench{k}");
                let mut logger = Logger::open(&dir.join(&name), u64::MAX).unwrap();
                let mut export = DeviceExport::new(&name, exports);
                let mut ingest = Ingest::new();
                let mut t_us = 1_764_000_000_000_000u64;
                for chunk in bytes.chunks(4096) {
                    t_us += 10_000;
                    logger.raw(t_us, chunk).unwrap();
                    ingest.feed(t_us, chunk, &mut |ev: Stamped| {
                        logger.event(&ev).unwrap();
                        assert!(export.event(&ev).is_none(), "an export failed");
                    });
                }
                logger.flush().unwrap();
                *frames.lock().unwrap() += ingest.stats().frames;
            });
        }
    });
    exports.lock().unwrap().flush().unwrap();
    let (wall, cpu) = (t0.elapsed().as_secs_f64(), cpu_s() - c0);
    let frames = *frames.lock().unwrap();
    // The boards run side by side: this many hours of wall time.
    let hammer_hours = REPORTS as f64 / 21.0 / 3600.0;
    println!("fleet: {BOARDS} boards, {frames} frames ({} reports and a status a second each), logs + Parquet + line protocol", REPORTS);
    println!(
        "  handled {:.0} frames/s in {wall:.2} s of wall time ({:.0} frames/s a board); four boards send about 88 frames/s: {:.0}x headroom",
        frames as f64 / wall,
        frames as f64 / wall / BOARDS as f64,
        frames as f64 / wall / 88.0
    );
    println!(
        "  CPU {cpu:.2} s for {hammer_hours:.2} h of {BOARDS} hammers running side by side: {:.3} % of one core",
        100.0 * cpu / (hammer_hours * 3600.0)
    );
    println!("  {}", exports.lock().unwrap().summary());
    let _ = std::fs::remove_dir_all(&dir);
}
