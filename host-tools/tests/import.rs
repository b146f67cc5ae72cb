//! Recorders' files give the native result: the same samples written by each
//! format's own reference writer (npTDMS, scipy.io.savemat, pyarrow with
//! Snappy, a pandas CSV in bar/g/ms with `;` and a decimal comma, Python's
//! `wave` at 16 bit) give `hammer estimate --format csv` output
//! byte-identical to the project's CSV of the same samples. The writers are
//! Python packages that `.ci/run` installs at pinned versions; without them
//! the test says so, and under CI it fails.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::{hammer, tmp_dir};

/// The reference writers are installed (or the test is skipped outside CI).
fn writers() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import numpy, scipy, pandas, pyarrow, nptdms"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but a reference writer (numpy, scipy, pandas, pyarrow, npTDMS) is missing (.ci/run installs them)"
        );
        eprintln!("SKIPPED: `python3 -m pip install numpy scipy pandas pyarrow npTDMS` to run it");
    }
    ok
}

fn estimate(trace: &Path, extra: &[&str]) -> String {
    let t = trace.to_str().unwrap();
    let mut args = vec!["estimate", t, "--supply-bar", "4", "--format", "csv"];
    args.extend_from_slice(extra);
    let (code, out, err) = hammer(&args);
    assert_eq!(code, 0, "{t}: {err}");
    out
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.to_str().unwrap().to_string()
}

#[test]
fn foreign_files_give_the_native_result() {
    if !writers() {
        return;
    }
    let dir = tmp_dir("formats");
    let native = dir.join("native.csv");
    let (code, _, err) = hammer(&[
        "simulate",
        "--supply-bar",
        "4",
        "--duration",
        "0.4",
        "--seed",
        "3",
        "--out",
        native.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    // No sidecar: every file is read with the same config and --supply-bar.
    std::fs::remove_file(dir.join("native.json")).unwrap();
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/import/writers.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(&native)
        .arg(&dir)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));

    let want = estimate(&native, &[]);
    let cycles = want.lines().count() - 1;
    assert!(cycles >= 5, "the native trace gives cycles to compare: {want}");
    // The project's names need no mapping.
    for f in [
        "tdms_rate.tdms",
        "tdms_time.tdms",
        "mat_vectors.mat",
        "mat_rate.mat",
        "arrow.parquet",
    ] {
        assert_eq!(estimate(&dir.join(f), &[]), want, "{f}");
    }
    let recorder_map = write(
        &dir,
        "recorder.toml",
        "[import]\ndecimal = \",\"\n\
         t = { column = \"Zeit [ms]\", unit = \"ms\" }\n\
         p_rear = { column = \"P hinten [bar]\", unit = \"bar\" }\n\
         p_front = { column = \"P vorne [bar]\", unit = \"bar\" }\n\
         accel = { column = \"Beschl. [g]\", unit = \"g\" }\n",
    );
    assert_eq!(
        estimate(&dir.join("recorder.csv"), &["--map", &recorder_map]),
        want,
        "pandas CSV"
    );

    // WAV rounds to 16 bit: compared with the project's CSV of the same rounded values.
    let wav_map = write(
        &dir,
        "wav.toml",
        "p_rear = { column = 1, unit = \"bar\", scale = 10 }\n\
         p_front = { column = 2, unit = \"bar\", scale = 10 }\n\
         accel = { column = 3, unit = \"m/s2\", scale = 2000 }\n",
    );
    let wav_want = estimate(&dir.join("sound_native.csv"), &[]);
    assert!(wav_want.lines().count() > 5, "{wav_want}");
    assert_eq!(estimate(&dir.join("sound.wav"), &["--map", &wav_map]), wav_want, "WAV");

    // `hammer import` converts, says what it understood, and the converted trace reads the same.
    let conv = dir.join("converted.csv");
    let (code, said, err) = hammer(&[
        "import",
        dir.join("recorder.csv").to_str().unwrap(),
        "--map",
        &recorder_map,
        "--supply-bar",
        "4",
        "--out",
        conv.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    for part in [
        "delimited text",
        "delimiter `;`, decimal `,`, header on line 4",
        "p_rear   <- P hinten [bar] [bar] gauge",
        "accel    <- Beschl. [g] [g]",
        "40001 samples at 100.000000 kS/s",
    ] {
        assert!(said.contains(part), "`{part}` in:\n{said}");
    }
    let sidecar: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("converted.json")).unwrap()).unwrap();
    assert_eq!(sidecar["supply_pressure_bar"], 4.0);
    assert_eq!(sidecar["import"]["understood"]["signals"][1]["unit"], "bar");
    assert_eq!(sidecar["import"]["understood"]["mapping"]["decimal"], ",");
    assert_eq!(estimate(&conv, &[]), want, "the converted trace");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Malformed files of each format: a clear error naming the file, exit 2, no panic.
#[test]
fn malformed_files_get_a_clear_error() {
    let dir = tmp_dir("malformed");
    let mut tdms = b"TDSm".to_vec();
    tdms.extend_from_slice(&[0x0e, 0, 0, 0, 0x68, 0x12, 0, 0]);
    tdms.extend_from_slice(&u64::MAX.to_le_bytes());
    tdms.extend_from_slice(&20u64.to_le_bytes());
    tdms.extend_from_slice(&[1, 0, 0, 0, 0xff, 0xff, 0xff, 0x7f]);
    let mut mat = vec![b' '; 128];
    mat[..19].copy_from_slice(b"MATLAB 5.0 MAT-file");
    mat[124..128].copy_from_slice(&[0, 1, b'I', b'M']);
    mat.extend_from_slice(&[14, 0, 0, 0, 0xff, 0xff, 0xff, 0x0f]);
    let mut mat73 = vec![b' '; 600];
    mat73[..19].copy_from_slice(b"MATLAB 7.3 MAT-file");
    mat73[124..128].copy_from_slice(&[0, 2, b'I', b'M']);
    mat73[512..516].copy_from_slice(b"\x89HDF");
    let mut wav = b"RIFF\x24\x00\x00\x00WAVEfmt ".to_vec();
    wav.extend_from_slice(&[16, 0, 0, 0, 1, 0, 0, 0, 0x44, 0xac, 0, 0]);
    let parquet = b"PAR1\x00\x00\x00garbagePAR1".to_vec();
    let cases: [(&str, Vec<u8>, &str); 6] = [
        ("bad.tdms", tdms, "NI TDMS"),
        ("bad.mat", mat, "a data element claims"),
        ("v73.mat", mat73, "v7.3"),
        ("bad.wav", wav, "WAV"),
        ("bad.parquet", parquet, "Parquet"),
        (
            "bad.txt",
            b"Zeit;Druck\n0;1\n".to_vec(),
            "no header row with the columns",
        ),
    ];
    for (name, bytes, says) in cases {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        let (code, _, err) = hammer(&["estimate", p.to_str().unwrap(), "--supply-bar", "4"]);
        assert_eq!(code, 2, "{name}: {err}");
        assert!(err.contains(name) && err.contains(says), "{name}: {err}");
        assert!(!err.contains("panicked"), "{name}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A recorder that clipped the rear chamber's dip at 0 gauge: `hammer
/// import` names the rail; the same trace unclipped (the dip below 0 kept,
/// noise-free) has none.
#[test]
fn import_names_the_values_a_recorder_clipped() {
    let dir = tmp_dir("rails");
    let ideal = dir.join("ideal.csv");
    let (code, _, err) = hammer(&[
        "simulate",
        "--supply-bar",
        "4",
        "--duration",
        "0.4",
        "--ideal-sensors",
        "--out",
        ideal.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let text = std::fs::read_to_string(&ideal).unwrap();
    let mut clipped = String::from("t_s,p_rear_pa,p_front_pa,accel_mps2\n");
    let mut plain = clipped.clone();
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let rear: f64 = f[1].parse().unwrap();
        clipped.push_str(&format!("{},{},{},{}\n", f[0], rear.max(0.0), f[2], f[3]));
        plain.push_str(&format!("{},{},{},{}\n", f[0], f[1], f[2], f[3]));
    }
    let said = |name: &str, body: &str| {
        let p = write(&dir, name, body);
        let out = dir.join(format!("conv-{name}"));
        let (code, said, err) = hammer(&["import", &p, "--out", out.to_str().unwrap()]);
        assert_eq!(code, 0, "{err}");
        said
    };
    let c = said("clipped.csv", &clipped);
    let rear = c.lines().find(|l| l.trim_start().starts_with("p_rear_pa")).unwrap();
    assert!(rear.contains("rail at 0.0000 bar"), "{c}");
    let p = said("plain.csv", &plain);
    assert!(!p.contains("rail at"), "{p}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// The project's own Parquet capture (`hammer capture --out X.parquet`,
/// zstd, the ADC codes beside the values, the sidecar in the metadata) reads
/// back as the trace it holds, with the sidecar's operating point.
#[test]
fn the_projects_parquet_capture_reads_back_with_its_sidecar() {
    use hammer_sim::estimation::open_for_estimation;
    use hammer_sim::SimConfig;
    let dir = tmp_dir("capture");
    let native = dir.join("run.csv");
    let (code, _, err) = hammer(&[
        "simulate",
        "--supply-bar",
        "5",
        "--duration",
        "0.3",
        "--out",
        native.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    std::fs::remove_file(dir.join("run.json")).unwrap();
    let trace = hammer_trace::trace::read_csv(&native).unwrap();
    let codes: Vec<[u16; 3]> = (0..trace.len()).map(|i| [i as u16, 0, 1]).collect();
    let pq = dir.join("capture.parquet");
    let mut f = std::fs::File::create(&pq).unwrap();
    hammer_host::parquet_files::write_trace(
        &mut f,
        &trace,
        &codes,
        "{\"supply_pressure_bar\":5,\"source\":\"device\"}",
    )
    .unwrap();
    drop(f);
    let from_pq = open_for_estimation(&pq, &SimConfig::default(), None).unwrap();
    assert_eq!(from_pq.supply_bar, Some(5.0), "the embedded sidecar's operating point");
    assert_eq!(from_pq.sidecar.as_ref().map(|s| s.source.as_str()), Some("device"));
    assert_eq!(from_pq.trace.p_rear_pa, trace.p_rear_pa);
    assert_eq!(from_pq.trace.accel_mps2, trace.accel_mps2);
    assert_eq!(
        estimate_at(&pq, "5"),
        estimate_at(&native, "5"),
        "the same cycles from the capture and the CSV"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

fn estimate_at(trace: &Path, bar: &str) -> String {
    let (code, out, err) = hammer(&[
        "estimate",
        trace.to_str().unwrap(),
        "--supply-bar",
        bar,
        "--format",
        "csv",
    ]);
    assert_eq!(code, 0, "{err}");
    out
}

/// A recorder set to 0–10 bar clipped the rear chamber's dip at 0 gauge
/// (on a hammer whose rear outlet opens early, ~15 % of the samples): the
/// clipped value is a rail, so those samples leave the friction fit as the
/// board's own rail samples do, and friction reads its truth. Left in the
/// fit (as before issue 29), they read it 1 N high and flagged a zero
/// shift that was not there.
#[test]
fn a_dip_a_recorder_clipped_leaves_the_friction_fit() {
    let dir = tmp_dir("clipped-fit");
    let config = write(
        &dir,
        "sim.toml",
        "[hammer]\nrear_outlet_opens_m = 0.022\n[sensors.rear]\nadc_bits = 16\n[sensors.front]\nadc_bits = 16\n",
    );
    let sim = dir.join("sim.csv");
    let (code, _, err) = hammer(&[
        "simulate",
        "--config",
        &config,
        "--supply-bar",
        "4",
        "--duration",
        "1",
        "--effect",
        "coulomb_friction:f0_n=1.7,k_n_per_bar=2.14",
        "--seed",
        "1",
        "--out",
        sim.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let text = std::fs::read_to_string(&sim).unwrap();
    let mut clipped = String::from("t_s,p_rear_pa,p_front_pa,accel_mps2\n");
    let (mut at_zero, mut n) = (0usize, 0usize);
    for line in text.lines().skip(1) {
        let f: Vec<&str> = line.split(',').collect();
        let rear = f[1].parse::<f64>().unwrap().max(0.0);
        at_zero += usize::from(rear == 0.0);
        n += 1;
        clipped.push_str(&format!("{},{rear},{},{}\n", f[0], f[2], f[3]));
    }
    assert!(at_zero * 10 >= n, "{at_zero} of {n} rear samples clipped");
    let trace = write(&dir, "recorder.csv", &clipped);
    let out = estimate(Path::new(&trace), &[]);
    let mut rows = out.lines();
    let head: Vec<&str> = rows.next().unwrap().split(',').collect();
    let col = |name: &str| head.iter().position(|h| *h == name).unwrap();
    let (friction, valid, flags) = (col("friction_n"), col("valid"), col("flags"));
    let cycles: Vec<Vec<String>> = rows
        .map(|l| l.split(',').map(str::to_string).collect())
        .filter(|r: &Vec<String>| r[valid] == "true")
        .collect();
    assert!(cycles.len() >= 15, "{out}");
    let mean = cycles.iter().map(|r| r[friction].parse::<f64>().unwrap()).sum::<f64>() / cycles.len() as f64;
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("sim.json")).unwrap()).unwrap();
    let truth: Vec<f64> = side["simulation"]["cycles"]
        .as_array()
        .unwrap()
        .iter()
        .skip(2)
        .map(|c| c["friction_cycle_n"].as_f64().unwrap())
        .collect();
    let truth = truth.iter().sum::<f64>() / truth.len() as f64;
    assert!(
        (mean - truth).abs() <= 0.15,
        "friction {mean:.3} N against the truth {truth:.3} N"
    );
    assert!(
        cycles.iter().all(|r| !r[flags].contains("accel_zero_shift")),
        "a clipped stretch read as a zero shift:\n{out}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The same clipped dip recorded quantised, as a 0–10 bar recorder of 10,
/// 12, 14 and 16 bits writes it (244 Pa steps at 12 bits, under the 500 Pa
/// noise): 0 gauge is still found a rail (it piles up samples no level
/// beside it holds), so friction at 4 bar reads its truth within 0.15 N and
/// no zero shift is flagged, with no range configured (issue 48, item 1).
/// Before, the equal neighbours a quantised channel has everywhere hid the
/// rail: at 10 to 14 bits friction read 1.2 N high with a false zero shift.
#[test]
fn a_quantised_clipped_floor_is_a_rail_at_every_depth() {
    use hammer_trace::import::inspect;
    for bits in [10u32, 12, 14, 16] {
        let mut cfg = hammer_sim::SimConfig::nominal(4.0);
        cfg.solver.duration_s = 0.6;
        cfg.seed = 1;
        // The rear outlet opens early: a deep dip below atmosphere.
        cfg.hammer.rear_outlet_opens_m = 0.022;
        for ch in [&mut cfg.sensors.rear, &mut cfg.sensors.front] {
            ch.range_min = 0.0;
            ch.range_max = 10e5;
            ch.adc_bits = bits;
        }
        let sim = hammer_sim::simulate(&cfg).unwrap();
        let m = &sim.measured;
        let n = m.p_rear_pa.len();
        let trace = hammer_trace::trace::Trace {
            dt_s: cfg.solver.output_step_s,
            t_s: (0..n).map(|i| i as f64 * cfg.solver.output_step_s).collect(),
            p_rear_pa: m.p_rear_pa.clone(),
            p_front_pa: m.p_front_pa.clone(),
            accel_mps2: m.accel_mps2.clone(),
            extra: Default::default(),
            gaps: vec![],
        };
        let at_zero = trace.p_rear_pa.iter().filter(|&&p| p == 0.0).count();
        assert!(at_zero * 10 >= n, "{bits} bits: {at_zero} of {n} rear samples at 0");
        // `hammer import` reports the rail.
        let rear = &inspect::stats(&trace).channels[0];
        assert!(
            rear.rails.iter().any(|r| r.value == 0.0 && r.samples == at_zero),
            "{bits} bits: {rear:?}"
        );
        // No range configured: the default config, the recorder's unknown.
        let (reports, _) =
            hammer_sim::estimation::estimate_trace(&trace, &hammer_sim::SimConfig::default(), Some(4.0), "quantised")
                .unwrap();
        // After the start-up (the truth's first two cycles).
        let t0 = sim.run.cycles[1].t_impact_s;
        let cycles: Vec<_> = reports
            .iter()
            .filter(|r| r.is_cycle() && r.t_impact_s() > t0 + 1e-3)
            .collect();
        assert!(cycles.len() >= 5 && cycles.iter().all(|r| r.is_valid()), "{bits} bits");
        assert!(
            cycles
                .iter()
                .all(|r| !r.flags.contains(hammer_estimator::Flags::ACCEL_ZERO_SHIFT)),
            "{bits} bits: a clipped stretch read as a zero shift"
        );
        let truth: Vec<f64> = sim.run.cycles.iter().skip(2).map(|c| c.friction_cycle_n).collect();
        let truth = truth.iter().sum::<f64>() / truth.len() as f64;
        let mean = cycles.iter().map(|r| r.friction_n as f64).sum::<f64>() / cycles.len() as f64;
        eprintln!(
            "{bits} bits: {at_zero} of {n} rear samples at 0 gauge; friction {mean:.3} N, truth {truth:.3} N, {} cycles valid",
            cycles.len()
        );
        assert!(
            (mean - truth).abs() <= 0.15,
            "{bits} bits: friction {mean:.3} N against the truth {truth:.3} N"
        );
    }
}

/// Runs a Python snippet (the reference writers) with `args` as `sys.argv[1:]`.
fn py(script: &str, args: &[&str]) {
    let out = Command::new("python3")
        .arg("-c")
        .arg(script)
        .args(args)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

/// The trace (8 of 8 cycles valid at 4 bar) as the project's four
/// columns, no sidecar: every layout of it must give this file's numbers.
fn plain_trace(dir: &Path) -> PathBuf {
    let sim = dir.join("s4.csv");
    let (code, _, err) = hammer(&[
        "simulate",
        "--supply-bar",
        "4",
        "--duration",
        "0.5",
        "--seed",
        "1",
        "--effect",
        "coulomb_friction",
        "--out",
        sim.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let text = std::fs::read_to_string(&sim).unwrap();
    let plain: String = text
        .lines()
        .map(|l| l.split(',').take(4).collect::<Vec<_>>().join(",") + "\n")
        .collect();
    write(dir, "plain4.csv", &plain).into()
}

/// Refused with exit 2, the file named, each of `says` in the message, no panic.
fn refused(args: &[&str], file: &str, says: &[&str]) -> String {
    let (code, out, err) = hammer(args);
    assert_eq!(code, 2, "{args:?} gave {code}: {out}{err}");
    assert!(err.contains(file), "{file} named in: {err}");
    for s in says {
        assert!(err.contains(s), "`{s}` in: {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
    err
}

/// Issue 48, item 2: a struct column among a Parquet file's columns moved
/// every later column's data under the next name (the accelerometer read
/// from `accel_b_mps2`). Columns are read by their full leaf name: the
/// struct's fields are `meta.a`, `meta.b`, the rest keep their data, and a
/// signal inside a struct is mapped by that name.
#[test]
fn a_struct_column_in_parquet_moves_no_data() {
    if !writers() {
        return;
    }
    let dir = tmp_dir("parquet-struct");
    let plain = plain_trace(&dir);
    py(
        "import sys, numpy as np, pandas as pd, pyarrow as pa, pyarrow.parquet as pq\n\
         df = pd.read_csv(sys.argv[1]); n = len(df); d = sys.argv[2]\n\
         meta = pa.StructArray.from_arrays([pa.array(np.arange(n, dtype=float)), pa.array(np.ones(n))], names=['a', 'b'])\n\
         pq.write_table(pa.table({'t_s': df.t_s, 'p_rear_pa': df.p_rear_pa, 'p_front_pa': df.p_front_pa, 'meta': meta,\n\
             'accel_mps2': df.accel_mps2, 'accel_b_mps2': -3 * df.accel_mps2}), d + '/nested.parquet')\n\
         inner = pa.StructArray.from_arrays([pa.array(df.accel_mps2), pa.array(np.zeros(n))], names=['accel', 'x'])\n\
         pq.write_table(pa.table({'t_s': df.t_s, 'sensors': inner, 'p_rear_pa': df.p_rear_pa, 'p_front_pa': df.p_front_pa}), d + '/inner.parquet')\n",
        &[plain.to_str().unwrap(), dir.to_str().unwrap()],
    );
    let want = estimate(&plain, &[]);
    assert_eq!(want.lines().filter(|l| l.contains(",true,")).count(), 8, "{want}");
    assert_eq!(
        estimate(&dir.join("nested.parquet"), &[]),
        want,
        "the struct moved columns"
    );
    let map = write(&dir, "inner.toml", "accel = { column = \"sensors.accel\" }\n");
    assert_eq!(
        estimate(&dir.join("inner.parquet"), &["--map", &map]),
        want,
        "a signal inside a struct"
    );
    // Unmapped, the signal inside the struct is not found: the error lists the leaves by their names.
    let f = dir.join("inner.parquet");
    refused(
        &["estimate", f.to_str().unwrap(), "--supply-bar", "4"],
        "inner.parquet",
        &["no channel `accel_mps2`", "sensors.accel"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 48, item 3: a map's `sample_rate_hz` overrode the file's own
/// `t_s` (8 valid cycles at 15 J from a 4 bar trace read at half its
/// rate). A rate that contradicts the time column is refused, naming the
/// file and both rates; one that agrees reads the native numbers.
#[test]
fn a_rate_that_contradicts_the_time_column_is_refused() {
    let dir = tmp_dir("rate");
    let plain = plain_trace(&dir);
    let p = plain.to_str().unwrap();
    let half = write(&dir, "half.toml", "sample_rate_hz = 50000\n");
    refused(
        &["estimate", p, "--supply-bar", "4", "--map", &half],
        "plain4.csv",
        &["`t_s`", "100000 Hz", "50000 Hz"],
    );
    let with_t = write(
        &dir,
        "with_t.toml",
        "sample_rate_hz = 50000\nt = { column = \"t_s\" }\n",
    );
    refused(
        &["estimate", p, "--supply-bar", "4", "--map", &with_t],
        "plain4.csv",
        &["100000 Hz", "50000 Hz"],
    );
    let agrees = write(&dir, "agrees.toml", "sample_rate_hz = 100000\n");
    assert_eq!(estimate(&plain, &["--map", &agrees]), estimate(&plain, &[]));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 48, item 4: delimited text. pandas' `to_csv(decimal=",")` quotes
/// each number under `,` (`"1,5"`): read by RFC 4180 it gives the native
/// numbers, with the project's names and with a recorder's names mapped
/// (it imported as garbage, up to 999 756 bar). A `;` file with decimal
/// commas in the project's names needs no map. A row with more fields than
/// the header is refused with its file and line.
#[test]
fn quoted_fields_and_decimal_commas_read_as_native() {
    if !writers() {
        return;
    }
    let dir = tmp_dir("text");
    let plain = plain_trace(&dir);
    py(
        "import sys, pandas as pd\n\
         df = pd.read_csv(sys.argv[1]); d = sys.argv[2]\n\
         df.to_csv(d + '/quoted.csv', decimal=',', index=False)\n\
         df.to_csv(d + '/semicolon.csv', sep=';', decimal=',', index=False)\n\
         df.columns = ['Zeit', 'P1', 'P2', 'A']\n\
         df.to_csv(d + '/named.csv', decimal=',', index=False)\n",
        &[plain.to_str().unwrap(), dir.to_str().unwrap()],
    );
    assert!(std::fs::read_to_string(dir.join("quoted.csv"))
        .unwrap()
        .contains("\",\""));
    let want = estimate(&plain, &[]);
    assert_eq!(estimate(&dir.join("quoted.csv"), &[]), want, "quoted decimal commas");
    assert_eq!(
        estimate(&dir.join("semicolon.csv"), &[]),
        want,
        "`;` and decimal commas, no map"
    );
    let map = write(
        &dir,
        "named.toml",
        "decimal = \",\"\nt = { column = \"Zeit\" }\np_rear = { column = \"P1\" }\n\
         p_front = { column = \"P2\" }\naccel = { column = \"A\" }\n",
    );
    assert_eq!(
        estimate(&dir.join("named.csv"), &["--map", &map]),
        want,
        "mapped, `,` guessed"
    );

    // A row with a field too many (a decimal comma unquoted under `,`), in
    // the project's CSV and in a recorder's text.
    let text = std::fs::read_to_string(&plain).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    lines[40] = lines[40].replacen('.', ",", 1);
    let extra = write(&dir, "extra.csv", &(lines.join("\n") + "\n"));
    refused(
        &["estimate", &extra, "--supply-bar", "4"],
        "extra.csv:41",
        &["expected 4 fields, found 5"],
    );
    let semi: Vec<String> = lines.iter().map(|l| l.replace(',', ";")).collect();
    let mut semi = semi.join("\n") + "\n";
    semi = semi.replacen("\n0.000100000;", "\n0.000100000;1;", 1);
    let extra = write(&dir, "extra_semi.csv", &semi);
    refused(
        &["estimate", &extra, "--supply-bar", "4"],
        "extra_semi.csv:12",
        &["expected 4 fields, found 5"],
    );

    // A decimal comma the first rows did not show is named with its fix.
    let mut late = String::from("t_s;p_rear_pa;p_front_pa;accel_mps2\n");
    for (i, l) in text.lines().skip(1).take(200).enumerate() {
        let l = l.replace(',', ";");
        late.push_str(&if i == 150 { l.replacen('.', ",", 2) } else { l });
        late.push('\n');
    }
    let late = write(&dir, "late.csv", &late);
    refused(
        &["estimate", &late, "--supply-bar", "4"],
        "late.csv",
        &["line 152", "decimal = \",\""],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 48, item 6: the same channel names in two TDMS groups took the
/// alphabetically first group. Refused, naming both groups and the map key
/// that chooses; with `group` given, the native numbers.
#[test]
fn tdms_channels_in_two_groups_need_a_group() {
    if !writers() {
        return;
    }
    let dir = tmp_dir("tdms-groups");
    let plain = plain_trace(&dir);
    py(
        "import sys, pandas as pd\n\
         from nptdms import ChannelObject, TdmsWriter\n\
         df = pd.read_csv(sys.argv[1])\n\
         with TdmsWriter(sys.argv[2]) as w:\n\
         \x20   w.write_segment([ChannelObject(g, s, df[s].to_numpy() * k, properties={'wf_increment': 1e-5})\n\
         \x20       for g, k in [('bench', 1.0), ('a_spare', 0.5)] for s in ['p_rear_pa', 'p_front_pa', 'accel_mps2']])\n",
        &[plain.to_str().unwrap(), dir.join("two.tdms").to_str().unwrap()],
    );
    let f = dir.join("two.tdms");
    refused(
        &["estimate", f.to_str().unwrap(), "--supply-bar", "4"],
        "two.tdms",
        &["`a_spare`", "`bench`", "group = "],
    );
    let map = write(&dir, "group.toml", "group = \"bench\"\n");
    assert_eq!(estimate(&f, &["--map", &map]), estimate(&plain, &[]));
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 48, item 15: a float32 time column (pyarrow, scipy) was "not
/// uniform": its stamps are good to f32's step, and read so they give the
/// native numbers; a recording long enough that f32 cannot tell its
/// samples apart is refused, naming float32 as the cause.
#[test]
fn a_float32_time_column_reads_or_names_float32() {
    if !writers() {
        return;
    }
    let dir = tmp_dir("float32");
    let plain = plain_trace(&dir);
    py(
        "import sys, numpy as np, pandas as pd, pyarrow as pa, pyarrow.parquet as pq, scipy.io\n\
         df = pd.read_csv(sys.argv[1]); d = sys.argv[2]\n\
         sig = {s: df[s].to_numpy() for s in ['p_rear_pa', 'p_front_pa', 'accel_mps2']}\n\
         t32 = df.t_s.to_numpy().astype(np.float32)\n\
         pq.write_table(pa.table({'t_s': pa.array(t32), **sig}), d + '/f32.parquet')\n\
         scipy.io.savemat(d + '/f32.mat', {'t_s': t32, **sig})\n\
         late = (3600 + df.t_s.to_numpy()).astype(np.float32)\n\
         pq.write_table(pa.table({'t_s': pa.array(late), **sig}), d + '/late.parquet')\n",
        &[plain.to_str().unwrap(), dir.to_str().unwrap()],
    );
    let want = estimate(&plain, &[]);
    assert_eq!(estimate(&dir.join("f32.parquet"), &[]), want, "float32 stamps, Parquet");
    assert_eq!(estimate(&dir.join("f32.mat"), &[]), want, "float32 stamps, MAT");
    let f = dir.join("late.parquet");
    refused(
        &["estimate", f.to_str().unwrap(), "--supply-bar", "4"],
        "late.parquet",
        &["float32", "float64"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 48, item 15: messages that named the wrong thing now name the cause.
#[test]
fn import_messages_name_the_cause() {
    let dir = tmp_dir("messages");
    let plain = plain_trace(&dir);
    let p = plain.to_str().unwrap();
    fn est<'a>(p: &'a str, map: &'a str) -> [&'a str; 6] {
        ["estimate", p, "--supply-bar", "4", "--map", map]
    }
    // An error inside `[import]` is itself, not "unknown field `import`".
    let m = write(&dir, "wrapped.toml", "[import]\nsample_rate_hz = \"fast\"\n");
    let e = refused(&est(p, &m), "wrapped.toml", &["sample_rate_hz", "expected f64"]);
    assert!(!e.contains("unknown field `import`"), "{e}");
    let m = write(&dir, "typo.toml", "[import]\ndelimeter = \";\"\n");
    refused(&est(p, &m), "typo.toml", &["unknown field `delimeter`"]);
    // skip_lines past the end says so, with or without a header.
    for (name, body) in [
        ("skip.toml", "[import]\nskip_lines = 100000\n"),
        ("skip_nohead.toml", "[import]\nskip_lines = 100000\nheader = false\n"),
    ] {
        let m = write(&dir, name, body);
        let e = refused(&est(p, &m), "plain4.csv", &["skip_lines = 100000", "past the end"]);
        assert!(!e.contains("empty file"), "{e}");
    }
    // Duplicate column names a signal is read from.
    let text = std::fs::read_to_string(&plain).unwrap();
    let dup: String = text
        .lines()
        .enumerate()
        .map(|(i, l)| {
            let extra = if i == 0 { "p_front_pa" } else { "0" };
            format!("{};{extra}\n", l.replace(',', ";"))
        })
        .collect();
    let d = write(&dir, "dup.csv", &dup);
    refused(
        &["estimate", &d, "--supply-bar", "4"],
        "dup.csv",
        &["`p_front_pa` 2 times", "columns 3, 5"],
    );
    // Gauge data mapped as absolute reads below vacuum: refused.
    let m = write(
        &dir,
        "abs.toml",
        "p_rear = { absolute = true }\np_front = { absolute = true }\n",
    );
    refused(&est(p, &m), "plain4.csv", &["below vacuum", "absolute = true"]);
    // Time that goes backwards says so at its row, also as the first interval.
    let mut rows: Vec<&str> = text.lines().collect();
    rows.swap(1, 2);
    let b = write(&dir, "back.csv", &(rows.join("\n") + "\n"));
    let e = refused(
        &["estimate", &b, "--supply-bar", "4"],
        "back.csv:3",
        &["time goes backwards"],
    );
    assert!(!e.contains("NaN"), "{e}");
    let b = write(&dir, "back2.csv", &format!("{}\n{}\n{}\n", rows[0], rows[1], rows[2]));
    refused(
        &["estimate", &b, "--supply-bar", "4"],
        "back2.csv:3",
        &["time goes backwards"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 48, item 15: a MAT struct was skipped without a word; the signals
/// not found name it.
#[test]
fn a_mat_struct_is_named_not_skipped_silently() {
    if !writers() {
        return;
    }
    let dir = tmp_dir("mat-struct");
    let plain = plain_trace(&dir);
    py(
        "import sys, pandas as pd, scipy.io\n\
         df = pd.read_csv(sys.argv[1])\n\
         scipy.io.savemat(sys.argv[2], {'rec': {s: df[s].to_numpy() for s in df.columns}})\n",
        &[plain.to_str().unwrap(), dir.join("struct.mat").to_str().unwrap()],
    );
    let f = dir.join("struct.mat");
    refused(
        &["estimate", f.to_str().unwrap(), "--supply-bar", "4"],
        "struct.mat",
        &["`rec`", "struct"],
    );
    let _ = std::fs::remove_dir_all(&dir);
}
