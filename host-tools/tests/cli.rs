//! The `hammer` binary as a user runs it.

use std::path::PathBuf;
use std::process::Command;

fn hammer(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args(args)
        .output()
        .expect("runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn tmp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hammer-cli-test-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `hammer simulate` of a short friction run with a fixed seed.
fn simulate_to(out: &std::path::Path) -> (i32, String, String) {
    hammer(&[
        "simulate",
        "--supply-bar",
        "4",
        "--duration",
        "0.3",
        "--effect",
        "coulomb_friction:f0_n=1.7,k_n_per_bar=2.14",
        "--seed",
        "3",
        "--out",
        out.to_str().unwrap(),
    ])
}

#[test]
fn simulate_prints_a_cycle_summary_and_writes_trace_and_sidecar() {
    let dir = tmp_dir("sim");
    let out = dir.join("run.csv");
    let (code, stdout, stderr) = simulate_to(&out);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("effects: coulomb_friction"), "{stdout}");
    assert!(stdout.contains("steady mean over"), "{stdout}");
    let csv = std::fs::read_to_string(&out).unwrap();
    assert!(
        csv.starts_with("t_s,p_rear_pa,p_front_pa,accel_mps2,"),
        "{}",
        &csv[..80]
    );
    assert_eq!(csv.lines().count(), 1 + 30_001);
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run.json")).unwrap()).unwrap();
    assert_eq!(side["supply_pressure_bar"], 4.0);
    assert_eq!(side["simulation"]["config"]["effects"]["coulomb_friction"]["f0_n"], 1.7);
    assert!(side["simulation"]["cycles"].as_array().unwrap().len() >= 4);
    // Same seed, same trace.
    let out2 = dir.join("again.csv");
    simulate_to(&out2);
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&out2).unwrap());
}

#[test]
fn bad_arguments_and_configs_name_the_field() {
    let (code, _, err) = hammer(&["simulate", "--effect", "leakage:gap=1e-5"]);
    assert_eq!(code, 2);
    assert!(err.contains("effects.leakage") && err.contains("gap"), "{err}");
    // A flag's value is refused under the flag's name, not the config key it sets.
    let (code, _, err) = hammer(&["simulate", "--supply-bar", "22"]);
    assert_eq!(code, 2);
    assert!(
        err.contains("--supply-bar 22 is out of range: allowed 0.5 ..= 20") && !err.contains("pressure_bar"),
        "{err}"
    );
    let (code, _, err) = hammer(&["simulate", "--dt", "1"]);
    assert_eq!(code, 2);
    assert!(
        err.contains("--dt 1 is out of range") && !err.contains("output_step_s"),
        "{err}"
    );
    let (code, _, err) = hammer(&["simulate", "--effect", "gremlins"]);
    assert_eq!(code, 2);
    assert!(err.contains("unknown effect `gremlins`"), "{err}");

    let dir = tmp_dir("cfg");
    let cfg = dir.join("hammer.toml");
    std::fs::write(&cfg, "[valve]\nmass_kg = 0.005\npilot_aera_rear_m2 = 1e-5\n").unwrap();
    let (code, _, err) = hammer(&["simulate", "--config", cfg.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(err.contains("pilot_aera_rear_m2") && err.contains("line 3"), "{err}");
    std::fs::write(&cfg, "[hammer]\npiston_mass_kg = 0.0\n").unwrap();
    let (code, _, err) = hammer(&["simulate", "--config", cfg.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(
        err.contains(&format!("{}: hammer.piston_mass_kg = 0", cfg.display())),
        "{err}"
    );
    // The estimator reads codes of at most 16 bits: the simulator refuses more.
    std::fs::write(
        &cfg,
        "[sensors.accel]\nrange_min = -2000.0\nrange_max = 2000.0\nadc_bits = 24\nnoise_std = 1.0\noffset = 0.0\nbandwidth_hz = 2e4\n",
    )
    .unwrap();
    let (code, _, err) = hammer(&["simulate", "--config", cfg.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(
        err.contains("sensors.accel.adc_bits = 24 is out of range: allowed 8 ..= 16"),
        "{err}"
    );
    std::fs::write(
        &cfg,
        "[effects.valve_delay]\ntau_s = 0.002\n[supply]\npressure_bar = 6\n",
    )
    .unwrap();
    let (code, out, err) = hammer(&["simulate", "--config", cfg.to_str().unwrap(), "--duration", "0.2"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("supply 6.00 bar") && out.contains("valve_delay"), "{out}");
}

#[test]
fn help_explains_units_and_defaults() {
    let (code, out, _) = hammer(&["simulate", "--help"]);
    assert_eq!(code, 0);
    for needle in ["bar", "default 0.5", "coulomb_friction", "pressure_gain_error", "10e-6"] {
        assert!(out.contains(needle), "help lacks `{needle}`:\n{out}");
    }
}

fn png_size(path: &std::path::Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap();
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "{} is not a PNG", path.display());
    let w = u32::from_be_bytes([b[16], b[17], b[18], b[19]]);
    let h = u32::from_be_bytes([b[20], b[21], b[22], b[23]]);
    (w, h)
}

#[test]
fn one_figure_per_effect() {
    let dir = tmp_dir("figs");
    let (code, out, err) = hammer(&["figures", "--out", dir.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    for name in hammer_sim::EFFECT_NAMES {
        let f = dir.join(format!("effect-{name}.png"));
        assert!(out.contains(f.to_str().unwrap()));
        assert_eq!(png_size(&f), (1100, 900));
        // Four panels of two curves each: a blank canvas compresses to a few kB.
        assert!(
            std::fs::metadata(&f).unwrap().len() > 40_000,
            "{} too small",
            f.display()
        );
    }
}

#[test]
fn estimate_prints_one_record_per_cycle_in_each_format() {
    let dir = tmp_dir("est");
    let trace = dir.join("run.csv");
    let (code, _, err) = hammer(&[
        "simulate",
        "--supply-bar",
        "6",
        "--duration",
        "0.6",
        "--effect",
        "coulomb_friction",
        "--out",
        trace.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let side: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("run.json")).unwrap()).unwrap();
    let truth_cycles = side["simulation"]["cycles"].as_array().unwrap().len();

    let (code, out, err) = hammer(&["estimate", trace.to_str().unwrap(), "--format", "jsonl"]);
    assert_eq!(code, 0, "{err}");
    let records: Vec<serde_json::Value> = out.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    // The estimator's first cycle closes at the second impact, like the truth's.
    assert_eq!(records.len(), truth_cycles);
    for key in [
        "t_impact_s",
        "frequency_hz",
        "friction_n",
        "friction_stroke_n",
        "friction_backhaul_n",
        "friction_uncertainty_n",
        "impact_velocity_mps",
        "impact_energy_j",
        "impact_energy_frictionless_j",
        "impact_energy_uncertainty_j",
        "wear_index_j",
        "flags",
    ] {
        assert!(records.iter().all(|r| r.get(key).is_some()), "missing {key}");
    }
    let last = records.last().unwrap();
    assert!((last["friction_n"].as_f64().unwrap() - 14.55).abs() < 0.3, "{last}");
    // The chambers as a board reads them: every cycle after a valid one
    // whose 8 ms after it the trace holds (the first has no start: NaN,
    // null, flagged so).
    let first = &records[0];
    assert_eq!(first["flags"], serde_json::json!(["chambers_unread"]), "{first}");
    assert!(
        first["front_feed_s"].is_null() && first["rear_feed_area_uncertainty_m2"].is_null(),
        "{first}"
    );
    let read: Vec<&serde_json::Value> = records
        .iter()
        .filter(|r| r["front_feed_s"].as_f64().is_some_and(f64::is_finite))
        .collect();
    assert!(
        read.len() + 2 >= records.len(),
        "{} of {} read",
        read.len(),
        records.len()
    );
    for r in &read {
        assert_eq!(r["flags"], serde_json::json!([]), "{r}");
        let n = r["front_closed_exponent"].as_f64().unwrap();
        assert!((1.0..1.5).contains(&n), "{r}");
    }

    // The CSV: the same columns as the JSON (every field, unit-suffixed names), the same numbers.
    let (code, out, _) = hammer(&["estimate", trace.to_str().unwrap(), "--format", "csv"]);
    assert_eq!(code, 0);
    assert!(
        out.starts_with("seq,t_impact_s,period_s,frequency_hz,friction_n,"),
        "{out}"
    );
    assert_eq!(out.lines().count(), truth_cycles + 1);
    let header: Vec<&str> = out.lines().next().unwrap().split(',').collect();
    let hash = header.iter().position(|c| *c == "calibration_hash").unwrap();
    assert_eq!(
        &header[hash - 1..hash + 3],
        [
            "drift_score",
            "calibration_hash",
            "front_feed_s",
            "front_feed_uncertainty_s"
        ]
    );
    assert_eq!(
        &header[header.len() - 3..],
        ["rear_feed_area_uncertainty_m2", "valid", "flags"]
    );
    // One trace, one calibration: every record names the same one.
    let cal = &records[0]["calibration_hash"];
    assert!(cal.as_u64().is_some_and(|h| h > 0), "{cal}");
    assert!(records.iter().all(|r| &r["calibration_hash"] == cal));
    assert!(!header.contains(&"wear_index"), "renamed wear_index_j");
    let mut keys: Vec<&str> = records[0].as_object().unwrap().keys().map(|k| k.as_str()).collect();
    let mut columns = header.clone();
    keys.sort_unstable();
    columns.sort_unstable();
    assert_eq!(columns, keys, "the CSV's columns are the JSON's keys");
    for (line, json) in out.lines().skip(1).zip(&records) {
        let cells: Vec<&str> = line.split(',').collect();
        assert_eq!(cells.len(), header.len(), "{line}");
        for (name, cell) in header.iter().zip(&cells) {
            match *name {
                "flags" => assert_eq!(
                    *cell,
                    match json["flags"].as_array().unwrap().len() {
                        0 => "-".to_string(),
                        _ => json["flags"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .map(|f| f.as_str().unwrap())
                            .collect::<Vec<_>>()
                            .join("|"),
                    }
                ),
                "valid" => assert_eq!(*cell, json["valid"].to_string()),
                _ => {
                    let v: f64 = cell.parse().unwrap_or(f64::NAN);
                    let j = json[*name].as_f64().unwrap_or(f64::NAN);
                    // Both carry the report's own number: an f32 field reads back to the same f32.
                    let same = v == j || (v as f32 == j as f32) || (v.is_nan() && j.is_nan());
                    assert!(same, "{name}: csv {cell}, json {j}");
                }
            }
        }
    }

    // Parquet: the same numbers, read back (NaN = a JSON null).
    let pq = dir.join("cycles.parquet");
    let (code, _, err) = hammer(&[
        "estimate",
        trace.to_str().unwrap(),
        "--format",
        "parquet",
        "--out",
        pq.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let rows = hammer_host::parquet_files::read(&pq).unwrap();
    assert_eq!(rows.len(), records.len());
    for (row, json) in rows.iter().zip(&records) {
        assert_eq!(row.device, "run");
        assert_eq!(row.host_time_us, None);
        assert_eq!(row.valid, json["valid"].as_bool().unwrap());
        for (f, v) in hammer_estimator::fields::FIELDS.iter().zip(&row.values) {
            let (v, j) = (v.as_f64(), json[f.name].as_f64().unwrap_or(f64::NAN));
            assert!(
                v == j || v as f32 == j as f32 || (v.is_nan() && j.is_nan()),
                "{}: {v} vs {j}",
                f.name
            );
        }
    }

    let (code, out, _) = hammer(&["estimate", trace.to_str().unwrap(), "--supply-bar", "6"]);
    assert_eq!(code, 0);
    assert!(out.lines().last().unwrap().starts_with("summary:"), "{out}");

    // Bad input: a clear error, exit code 2, no panic.
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n0.00001,1,oops,3\n").unwrap();
    let (code, _, err) = hammer(&["estimate", bad.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(err.contains(":3:") && err.contains("oops"), "{err}");
}

/// The report lines of headless output (`cycle N ...`, the headless monitor's line).
fn report_lines(out: &str) -> Vec<&str> {
    out.lines().filter(|l| l.starts_with("cycle ")).collect()
}

/// The friction figure of a `hammer demo --headless` line.
fn friction_of(line: &str) -> f64 {
    let rest = line.split("friction").nth(1).unwrap();
    rest.split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn demo_headless_runs_the_firmware_app_natively() {
    let (code, out, err) = hammer(&["demo", "--headless", "--native", "--cycles", "6"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("natively"), "{err}");
    let lines = report_lines(&out);
    assert_eq!(lines.len(), 6, "{out}");
    // The paper's friction at 4 bar.
    for l in &lines[1..] {
        assert!((friction_of(l) - 10.27).abs() < 0.3, "{l}");
    }
    assert!(out.contains("0 dropped samples"), "{out}");
}

fn emulated_board_is_there() {
    let emulated = hammer_host::emulator::qemu_available() && hammer_host::emulator::firmware_elf().exists();
    assert!(
        emulated,
        "CI installs qemu-system-arm and builds the firmware before the tests (cargo xtask ci)"
    );
}

/// The demo's figures a run must show: every report, nothing dropped.
fn assert_demo_lossless(out: &str, err: &str, cycles: usize) {
    assert!(
        err.contains("emulated board") && err.contains("ADC model at 100 kS/s"),
        "{err}"
    );
    assert!(out.contains("device: qemu-mps2-an386"), "{out}");
    assert_eq!(report_lines(out).len(), cycles, "{out}");
    assert!(out.contains(" 0 dropped samples"), "{out}");
    assert!(out.contains(" 0 overruns (0 sets lost)"), "{out}");
}

#[test]
fn demo_headless_on_the_emulated_board_keeps_up_with_the_full_rate() {
    emulated_board_is_there();
    // The issue's acceptance command: 40 cycles at 4 bar, about 1.9 s of
    // hammer, within 1.5x that plus a few seconds of start-up.
    let started = std::time::Instant::now();
    let (code, out, err) = hammer(&["demo", "--headless", "--cycles", "40", "--supply-bar", "4"]);
    let wall_s = started.elapsed().as_secs_f64();
    assert_eq!(code, 0, "{err}");
    assert_demo_lossless(&out, &err, 40);
    let lines = report_lines(&out);
    for l in &lines[1..] {
        assert!((friction_of(l) - 10.27).abs() < 0.4, "the paper's 4 bar friction: {l}");
    }
    let hammer_s = 40.0 / 21.1 + 0.15;
    assert!(
        wall_s < 1.5 * hammer_s + 4.0,
        "{wall_s:.1} s of wall time for {hammer_s:.1} s of hammer"
    );
}

#[test]
fn demo_real_time_keeps_the_hammers_own_pace() {
    emulated_board_is_there();
    let started = std::time::Instant::now();
    let (code, out, err) = hammer(&[
        "demo",
        "--headless",
        "--real-time",
        "--cycles",
        "20",
        "--supply-bar",
        "6",
    ]);
    let wall_s = started.elapsed().as_secs_f64();
    assert_eq!(code, 0, "{err}");
    assert_demo_lossless(&out, &err, 20);
    let lines = report_lines(&out);
    assert!((friction_of(lines[2]) - 14.55).abs() < 0.4, "{}", lines[2]);
    // 20 cycles of a ~23 Hz hammer take ~0.9 s of its time: not less on the
    // wall clock (the board waits for host time), and not much more.
    assert!((0.8..0.9 * 1.5 + 4.0).contains(&wall_s), "{wall_s:.2} s");
}

#[test]
fn capture_from_a_demo_board_writes_a_trace_the_estimator_reads() {
    let dir = tmp_dir("capture");
    let out = dir.join("cap.csv");
    let (code, stdout, err) = hammer(&[
        "capture",
        "--demo",
        "5",
        "--cycles",
        "2",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("captured"), "{stdout}");
    let trace = hammer_trace::trace::read_csv(&out).unwrap();
    assert!(trace.len() > 4000, "one full cycle at 100 kS/s: {}", trace.len());
    let side = hammer_trace::trace::read_sidecar(&out).unwrap().unwrap();
    assert_eq!(side.source, "device");
    assert_eq!(side.supply_pressure_bar, Some(5.0));
    // The capture runs from one impact past the next: one complete cycle.
    let (code, jsonl, _) = hammer(&["estimate", out.to_str().unwrap(), "--format", "jsonl"]);
    assert_eq!(code, 0);
    let recs: Vec<serde_json::Value> = jsonl.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    assert_eq!(recs.len(), 1, "{jsonl}");
    assert!(
        (recs[0]["friction_n"].as_f64().unwrap() - 12.41).abs() < 0.3,
        "{}",
        recs[0]
    );

    // The same as one Parquet file: samples, the codes they came from, the sidecar.
    let pq = dir.join("cap.parquet");
    let (code, stdout, err) = hammer(&["capture", "--demo", "5", "--out", pq.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("cap.parquet"), "{stdout}");
    let (samples, codes, side) = hammer_host::parquet_files::read_trace(&pq).unwrap();
    assert!(samples.len() > 4000, "one full cycle at 100 kS/s: {}", samples.len());
    let side: serde_json::Value = serde_json::from_str(&side.expect("the sidecar in the metadata")).unwrap();
    assert_eq!(side["supply_pressure_bar"], 5.0, "{side}");
    assert!(samples.windows(2).all(|w| (w[1][0] - w[0][0] - 1e-5).abs() < 1e-12));
    // Each pressure is its code through one affine calibration.
    let (i, j) = (0, (1..codes.len()).find(|&k| codes[k][0] != codes[0][0]).unwrap());
    let scale = (samples[j][1] - samples[i][1]) / (f64::from(codes[j][0]) - f64::from(codes[i][0]));
    for (s, c) in samples.iter().zip(&codes) {
        let p = samples[i][1] + scale * (f64::from(c[0]) - f64::from(codes[i][0]));
        assert!(
            (s[1] - p).abs() < 1e-6 * scale.abs().max(1.0) * 4096.0,
            "{} vs {p}",
            s[1]
        );
    }
}

#[test]
fn config_check_names_the_field_and_range_or_prints_the_resolved_config() {
    let dir = tmp_dir("check");
    let good = dir.join("good.toml");
    std::fs::write(
        &good,
        "[supply]\npressure_bar = 6.0\n[estimator]\ncoverage_factor = 3.0\n",
    )
    .unwrap();
    let (code, out, err) = hammer(&["config", "check", good.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains(": ok") && out.contains("supply 6 bar"), "{out}");
    // The chambers the board is given with `hammer calibrate --hammer-config`:
    // the paper's hammer, its transducers' delay at 100 kS/s.
    assert!(
        out.contains("travel 52.0 mm, dead volumes rear 14.50 front 19.90 cm³, outlets rear 30.0 front 20.0 mm, pressure delay 3.98 µs"),
        "{out}"
    );
    let own = dir.join("own.toml");
    std::fs::write(&own, "[hammer]\nfront_dead_volume_m3 = 30e-6\n").unwrap();
    let (code, out, err) = hammer(&["config", "check", own.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("front 30.00 cm³"), "{out}");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[estimator]\ncoverage_factor = 9.0\n").unwrap();
    let (code, _, err) = hammer(&["config", "check", bad.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(
        err.contains("estimator.coverage_factor") && err.contains("1 ..= 5"),
        "{err}"
    );
    // A range whose calibration the estimator cannot use is named by its keys.
    std::fs::write(
        &bad,
        "[sensors.rear]\nrange_min = 1e5\nrange_max = 100001.0\nadc_bits = 12\nnoise_std = 1.0\noffset = 0.0\nbandwidth_hz = 0.0\n",
    )
    .unwrap();
    let (code, _, err) = hammer(&["config", "check", bad.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(
        err.contains("sensors.rear.range_min, sensors.rear.range_max") && !err.contains("zero_code"),
        "{err}"
    );
    // A transducer as a user states it: one key, the rest the channel's defaults.
    std::fs::write(
        &bad,
        "[sensors.rear]\nrange_min = 0.0\n[sensors.front]\nrange_min = 0\n",
    )
    .unwrap();
    let (code, out, err) = hammer(&["config", "check", bad.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("pressure 0.00 … 10.00 bar"), "{out}");
    std::fs::write(&bad, "[sensors.rear]\nrange_mni = 0.0\n").unwrap();
    let (code, _, err) = hammer(&["config", "check", bad.to_str().unwrap()]);
    assert_eq!(code, 2);
    assert!(err.contains("unknown field `range_mni`"), "{err}");
}

#[test]
fn diagnose_writes_its_report_and_names_the_hidden_effect() {
    let dir = tmp_dir("diagnose");
    let mut paths = Vec::new();
    for bar in ["4", "7"] {
        let p = dir.join(format!("m{bar}.csv"));
        let (code, _, err) = hammer(&[
            "simulate",
            "--supply-bar",
            bar,
            "--duration",
            "0.8",
            "--effect",
            "viscous_friction:c_n_s_per_m=3",
            "--seed",
            "5",
            "--out",
            p.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{err}");
        paths.push(p);
    }
    // The 7 bar trace loses its sidecar: its pressure is given after it.
    std::fs::remove_file(paths[1].with_extension("json")).unwrap();
    let out = dir.join("report");
    let (code, stdout, err) = hammer(&[
        "diagnose",
        "--measured",
        paths[0].to_str().unwrap(),
        "--measured",
        paths[1].to_str().unwrap(),
        "--supply-bar",
        "7",
        "--fit-on",
        paths[0].to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    println!("{stdout}");
    assert!(stdout.contains("verdict: viscous_friction"), "{stdout}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    for key in ["where", "effects", "verdict", "shrink"] {
        assert!(json.get(key).is_some(), "report.json lacks {key}");
    }
    assert_eq!(json["verdict"]["effects"][0], "viscous_friction");
    let c = json["verdict"]["params"]["c_n_s_per_m"].as_f64().unwrap();
    assert!((c - 3.0).abs() < 0.3, "{c}");
    assert_eq!(json["shrink"]["held_out_points"][0], 7.0);
    assert_eq!(json["effects"].as_array().unwrap().len(), 8);
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("viscous_friction") && md.contains("gap-7bar.png"));
    assert!(png_size(&out.join("gap-4bar.png")).0 > 0);
    // No terminal, no progress bar on stderr.
    assert!(!err.contains("diagnose ["), "{err}");
}

/// Against a record of the same hammer without the effect (`--reference`):
/// the change is diagnosed, the report says so, and a measured operating
/// point without a reference is refused with a reason.
#[test]
fn diagnose_reads_a_change_from_a_reference_record() {
    let dir = tmp_dir("diagnose-ref");
    let record = |name: &str, bar: &str, effect: Option<&str>, seed: &str| {
        let p = dir.join(format!("{name}{bar}.csv"));
        let mut args = vec![
            "simulate",
            "--supply-bar",
            bar,
            "--duration",
            "0.8",
            "--seed",
            seed,
            "--out",
            p.to_str().unwrap(),
        ];
        if let Some(e) = effect {
            args.extend_from_slice(&["--effect", e]);
        }
        let (code, _, err) = hammer(&args);
        assert_eq!(code, 0, "{err}");
        p.to_str().unwrap().to_string()
    };
    let m4 = record("m", "4", Some("viscous_friction:c_n_s_per_m=3"), "5");
    let m7 = record("m", "7", Some("viscous_friction:c_n_s_per_m=3"), "5");
    let r4 = record("r", "4", None, "6");
    let r7 = record("r", "7", None, "6");
    let out = dir.join("report");
    let out_s = out.to_str().unwrap();
    let (code, stdout, err) = hammer(&[
        "diagnose",
        "--measured",
        &m4,
        "--measured",
        &m7,
        "--reference",
        &r4,
        "--reference",
        &r7,
        "--fit-on",
        &m4,
        "--out",
        out_s,
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        stdout.contains("read as a change from 2 reference record(s)"),
        "{stdout}"
    );
    assert!(stdout.contains("verdict: viscous_friction"), "{stdout}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(json["references"].as_array().map(Vec::len), Some(2));
    let c = json["verdict"]["params"]["c_n_s_per_m"].as_f64().unwrap();
    assert!((c - 3.0).abs() < 0.3, "{c}");
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.contains("reference record"), "{md}");
    // Both records are read through the dead volumes the reference's
    // closed phases ask for; the simulator is the diagnosis' own model, so
    // its record gives the configured front dead volume back.
    let dead = json["dead_volumes"].as_array().expect("dead_volumes");
    let front = dead.iter().find(|d| d["chamber"] == "front").expect("front");
    let (used, nominal) = (
        front["used_m3"].as_f64().unwrap(),
        front["nominal_m3"].as_f64().unwrap(),
    );
    println!("front dead volume {used:e} m³ against the configured {nominal:e}");
    assert!((used / nominal - 1.0).abs() < 0.03, "{used} against {nominal}");
    assert!(
        md.contains("dead volumes the reference's closed phases ask for"),
        "{md}"
    );
    let (code, _, err) = hammer(&[
        "diagnose",
        "--measured",
        &m4,
        "--measured",
        &m7,
        "--reference",
        &r4,
        "--out",
        out_s,
    ]);
    assert_ne!(code, 0);
    assert!(err.contains("no reference record at 7 bar"), "{err}");
}

#[test]
fn diagnose_refuses_bad_inputs_with_a_reason() {
    let dir = tmp_dir("diagnose-bad");
    let csv = dir.join("nosidecar.csv");
    std::fs::write(&csv, "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,0,0,0\n0.00001,0,0,0\n").unwrap();
    let out = dir.join("out");
    let refused = |args: &[&str], reason: &str| {
        let mut all = vec!["diagnose"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["--out", out.to_str().unwrap()]);
        let (code, _, err) = hammer(&all);
        assert_ne!(code, 0, "{args:?}");
        assert!(err.contains(reason), "{args:?}: {err}");
    };
    let csv = csv.to_str().unwrap();
    refused(&["--measured", csv], "supply pressure unknown");
    refused(&["--measured", csv, "--supply-bar", "5"], "no complete impact cycle");
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, "t_s,p_rear_pa\n0,abc\n").unwrap();
    refused(&["--measured", bad.to_str().unwrap()], "bad.csv");
    refused(
        &["--measured", csv, "--supply-bar", "5", "--fit-on", "other.csv"],
        "--fit-on",
    );
}

/// The CI's small run of the blind benchmark: twelve cases (the eight
/// effects, two controls, two pairs) from a perturbed generator.
#[test]
fn diagnose_bench_small_run() {
    let dir = tmp_dir("bench");
    let (code, stdout, err) = hammer(&[
        "diagnose-bench",
        "--cases",
        "12",
        "--seed",
        "1",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    println!("{stdout}");
    let count = |prefix: &str| -> (usize, usize) {
        let line = stdout.lines().find(|l| l.starts_with(prefix)).unwrap();
        let frac = line[prefix.len()..].split_whitespace().next().unwrap();
        let (a, b) = frac.split_once('/').unwrap();
        (a.parse().unwrap(), b.parse().unwrap())
    };
    let singles = count("single effect named right:");
    let controls = count("no-effect controls flagged:");
    let pairs = count("pairs named right:");
    assert_eq!((singles.1, controls.1, pairs.1), (8, 2, 2));
    assert!(singles.0 >= 7, "{singles:?}");
    assert_eq!(controls.0, 0, "a control was flagged");
    assert!(pairs.0 >= 1, "{pairs:?}");
    assert!(stdout.contains("confusion (rows hidden, columns named)"));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("bench.json")).unwrap()).unwrap();
    assert_eq!(json["cases"].as_array().unwrap().len(), 12);
}

/// A benchmark stopped and resumed is the benchmark run straight: the log
/// of finished cases (`cases.jsonl`) gives back the cases it holds to the
/// bit, and only the missing ones run. A log of other options is refused.
#[test]
fn a_resumed_benchmark_is_the_straight_run() {
    let (straight, resumed) = (tmp_dir("resume-straight"), tmp_dir("resume-resumed"));
    let run = |dir: &std::path::Path, cases: &str, more: &[&str]| {
        let mut args = vec![
            "diagnose-bench",
            "--cases",
            cases,
            "--seed",
            "3",
            "--points",
            "4,7",
            "--out",
        ];
        args.push(dir.to_str().unwrap());
        args.extend_from_slice(more);
        let (code, _, err) = hammer(&args);
        assert_eq!(code, 0, "{err}");
        err
    };
    run(&straight, "2", &[]);
    run(&resumed, "1", &[]);
    let err = run(&resumed, "2", &["--resume"]);
    assert!(err.contains("1 of 2 cases done, 1 to run"), "{err}");
    let cases = |dir: &std::path::Path| {
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("bench.json")).unwrap()).unwrap();
        let mut cases = json["cases"].as_array().unwrap().clone();
        for c in &mut cases {
            c.as_object_mut().unwrap().remove("diagnose_s");
        }
        cases
    };
    let (a, b) = (cases(&straight), cases(&resumed));
    assert_eq!(a.len(), 2);
    assert_eq!(a, b, "the resumed run's cases differ from the straight run's");
    // Another seed is another run: refused, the log named, nothing run.
    let (code, _, err) = hammer(&[
        "diagnose-bench",
        "--cases",
        "3",
        "--seed",
        "4",
        "--points",
        "4,7",
        "--resume",
        "--out",
        resumed.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("cases.jsonl") && err.contains("seed"), "{err}");
}

/// The structural benchmark's first 24 cases, two rounds of its plan (hammers of the second
/// model family, one or two structural variants each, parameters ±10 %,
/// transducers that clip below atmosphere): every effect the model-free
/// force balance sees (friction, viscous friction, zero shift, gain error)
/// is named right with its magnitude within 15 %, the controls stay `none`,
/// and an effect named that was not hidden is grouped in a close call with
/// the one that was (the diagnosis says `none` rather than guess where the
/// model's form hides an effect). Full run: docs/diagnose-bench/structural.
#[test]
fn diagnose_bench_structural_small_run() {
    let dir = tmp_dir("sbench");
    let (code, stdout, err) = hammer(&[
        "diagnose-bench",
        "--structural",
        "--cases",
        "24",
        "--seed",
        "7",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    println!("{stdout}");
    assert!(stdout.contains("--structural (generator: hammer-variants"));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("bench.json")).unwrap()).unwrap();
    let cases = json["cases"].as_array().unwrap();
    assert_eq!(cases.len(), 24);
    let mut force_balance_named = 0;
    let mut wrong_names = 0;
    for c in cases {
        assert!(!c["variants"].as_array().unwrap().is_empty(), "{c}");
        let hidden: Vec<String> = match &c["hidden"] {
            serde_json::Value::String(s) if s == "None" => vec![],
            h => h
                .as_object()
                .unwrap()
                .values()
                .flat_map(|v| match v {
                    serde_json::Value::String(s) => vec![s.clone()],
                    v => v
                        .as_array()
                        .unwrap()
                        .iter()
                        .map(|x| x.as_str().unwrap().to_string())
                        .collect(),
                })
                .collect(),
        };
        let named: Vec<String> = c["named"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_str().unwrap().to_string())
            .collect();
        // A name that was not hidden comes in a close call with what was
        // (the group holds the truth), or is the hidden effect's cluster-mate
        // with the hidden one next in line among the unseen effects (a
        // pair may be named in part).
        let unseen: Vec<&str> = c["ranking"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|e| e["model_free_z"].is_null())
            .map(|e| e["name"].as_str().unwrap())
            .collect();
        let wrong = !named.iter().all(|n| hidden.contains(n)) && c["outcome"] != "Group";
        if wrong {
            wrong_names += 1;
            assert!(
                hidden.len() == 1
                    && named.len() == 1
                    && unseen.first() == Some(&named[0].as_str())
                    && unseen.get(1) == Some(&hidden[0].as_str()),
                "named {named:?}, hidden {hidden:?}, groups {}, unseen ranked {unseen:?}",
                c["alternatives"]
            );
        }
        if hidden.is_empty() {
            assert!(named.is_empty(), "a control was flagged: {named:?}");
        }
        if hidden.len() == 1
            && [
                "coulomb_friction",
                "viscous_friction",
                "pressure_gain_error",
                "accel_zero_shift",
            ]
            .contains(&hidden[0].as_str())
        {
            assert_eq!(named, hidden, "a force-balance effect missed");
            let e = c["param_errors"][&hidden[0]].as_f64().unwrap();
            assert!(e <= 0.15, "{}: {e}", hidden[0]);
            force_balance_named += 1;
        }
    }
    assert_eq!(force_balance_named, 8, "the plan's force-balance singles");
    // One of the 16 singles is a cluster-mate named for the hidden effect
    // (case 13, a leak named heat exchange, 8.5 % apart): no more.
    assert!(wrong_names <= 1, "{wrong_names} wrong names");
    // The effects the force balance cannot see: each case's report says how
    // large one would have had to be to be named. Hidden below that floor
    // it must not be named (the floor would be wrong); at or beyond it, half
    // are (measured on these 24: 3 of 4 above, 0 of 4 below; on the first
    // 40: 3 of 6, 0 of 9; the whole 120: 10 of 15, 1 of 25; at seed 8, 7 of
    // 11 and 2 of 29).
    let tally = |k: &str| {
        let t = json[k].as_array().unwrap();
        (t[0].as_u64().unwrap(), t[1].as_u64().unwrap())
    };
    let (above, below) = (tally("floor_above"), tally("floor_below"));
    assert!(above.1 >= 4 && below.1 >= 4, "above {above:?}, below {below:?}");
    assert!(2 * above.0 >= above.1, "effects beyond their floor missed: {above:?}");
    assert_eq!(below.0, 0, "an effect below its floor was named");
    // What the model alone's evidence can reach: a ranking of the fits names
    // no case whose hidden effect another law fitted better, so the
    // diagnosis' right names beyond the floor are among the best fits.
    let ceiling = &json["model_alone_ceiling"];
    let pair = |v: &serde_json::Value| (v[0].as_u64().unwrap(), v[1].as_u64().unwrap());
    let best = pair(&ceiling["best_fit"]);
    assert_eq!(best.1, above.1, "{ceiling}");
    assert!(
        above.0 <= best.0,
        "named right beyond the best fits: {above:?} {best:?}"
    );
    // The form alone moves the chamber characteristics: the second family's
    // front port opens before the impact, the model's after it, so every
    // control's front feed is earlier than the nominal model's by over 1 ms.
    let spans = ceiling["form_spans"].as_array().unwrap();
    assert!(spans.len() >= 6, "{ceiling}");
    let front = spans.iter().find(|s| s["feature"] == "front_feed_s").unwrap();
    let (lo, hi) = (
        front["controls"][0].as_f64().unwrap(),
        front["controls"][1].as_f64().unwrap(),
    );
    assert!(lo <= hi && hi < -1e-3, "front feed change in the controls {lo}…{hi} s");
}

/// The catalogue's isolability from the model alone: every effect put into
/// the model at its default is named by the diagnosis and explains nearly
/// all of its own gap; the effects the force balance pins leave no other
/// effect more than a fifth of theirs.
#[test]
fn isolability_matrix_has_its_diagonal() {
    let dir = tmp_dir("iso");
    let (code, stdout, err) = hammer(&[
        "diagnose-bench",
        "--isolability",
        "--points",
        "4,7",
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    println!("{stdout}");
    let rows: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("isolability.json")).unwrap()).unwrap();
    let rows = rows.as_array().unwrap();
    assert_eq!(rows.len(), hammer_sim::effects::EFFECT_NAMES.len());
    for (i, r) in rows.iter().enumerate() {
        let name = r["effect"].as_str().unwrap();
        let explained: Vec<f64> = r["explained"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert!(r["named"].as_array().unwrap().iter().any(|n| n == name), "{r}");
        assert!(explained[i] >= 0.9, "{name}: {}", explained[i]);
        if [
            "coulomb_friction",
            "viscous_friction",
            "accel_zero_shift",
            "pressure_gain_error",
        ]
        .contains(&name)
        {
            let other = explained
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(_, x)| *x)
                .fold(0.0, f64::max);
            assert!(other <= 0.2, "{name}: another effect explains {other}");
        }
    }
}

/// Standard output that cannot be written is an error, never a panic or a
/// silent success; a trace with no impact is an error as in `report`.
#[test]
fn output_failures_and_empty_traces_are_errors_not_panics_or_silence() {
    let dir = tmp_dir("outerr");
    let run = dir.join("run.csv");
    assert_eq!(simulate_to(&run).0, 0);
    let full = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_hammer"))
            .args(args)
            .stdout(std::fs::OpenOptions::new().write(true).open("/dev/full").unwrap())
            .output()
            .unwrap();
        (out.status.code(), String::from_utf8_lossy(&out.stderr).into_owned())
    };
    for args in [
        &["estimate", run.to_str().unwrap()][..],
        &["estimate", run.to_str().unwrap(), "--format", "jsonl"],
        &["simulate", "--duration", "0.05"],
    ] {
        let (code, stderr) = full(args);
        assert_eq!(code, Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains("writing to standard output") && !stderr.contains("panicked"),
            "{stderr}"
        );
    }
    // --out naming the sidecar's own path would overwrite the trace with it.
    let (code, _, stderr) = hammer(&[
        "simulate",
        "--duration",
        "0.05",
        "--out",
        dir.join("x.json").to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("sidecar would overwrite the trace"), "{stderr}");
    assert!(!dir.join("x.json").exists());
    // An operating point no hammer runs at is refused at the flag, in bar.
    let (code, _, stderr) = hammer(&["estimate", run.to_str().unwrap(), "--supply-bar", "2000"]);
    assert_eq!(code, 2);
    assert!(
        stderr.contains("--supply-bar") && stderr.contains("allowed 0 ..= 25 bar"),
        "{stderr}"
    );
    assert!(!stderr.contains("supply_pressure_pa"), "{stderr}");
    // A quiet trace (a hammer at rest, sensors with a little noise): no
    // cycle is an error that says so, and nothing is printed.
    let quiet = dir.join("quiet.csv");
    let mut text = String::from("t_s,p_rear_pa,p_front_pa,accel_mps2\n");
    for i in 0..5000 {
        let k = (i % 3) as f64;
        text += &format!(
            "{:.9},{},{},{}\n",
            i as f64 * 1e-5,
            1e5 + 300.0 * k,
            5e4 - 300.0 * k,
            k - 1.0
        );
    }
    std::fs::write(&quiet, text).unwrap();
    let (code, stdout, stderr) = hammer(&["estimate", quiet.to_str().unwrap(), "--supply-bar", "4"]);
    assert_eq!(code, 2, "{stdout}");
    assert!(stdout.is_empty(), "{stdout}");
    assert!(stderr.contains("no impact cycle in 5000 samples"), "{stderr}");
    // Every channel frozen at one value: the stretch is a flagged record that
    // names the stuck channels, printed, and still no cycle (exit 2).
    let mut text = String::from("t_s,p_rear_pa,p_front_pa,accel_mps2\n");
    for i in 0..5000 {
        text += &format!("{:.9},100000,50000,0\n", i as f64 * 1e-5);
    }
    std::fs::write(&quiet, text).unwrap();
    let (code, stdout, stderr) = hammer(&["estimate", quiet.to_str().unwrap(), "--supply-bar", "4"]);
    assert_eq!(code, 2, "{stdout}");
    assert!(
        stdout.contains("accel_stuck") && stdout.contains("no_impact"),
        "{stdout}"
    );
    assert!(
        stderr.contains("no impact cycle") && stderr.contains("accel_stuck"),
        "{stderr}"
    );
}

/// One frames.bin record of received bytes (the format `hammer monitor --log` writes).
fn bytes_record(t_us: u64, bytes: &[u8]) -> Vec<u8> {
    [&t_us.to_le_bytes()[..], &(bytes.len() as u32).to_le_bytes(), bytes].concat()
}

fn wire_frame(m: &hammer_wire::DeviceMsg) -> Vec<u8> {
    let mut buf = [0u8; hammer_wire::MAX_FRAME];
    let n = hammer_wire::encode(m, &mut buf).unwrap();
    buf[..n].to_vec()
}

fn replay_cycles(out: &str) -> Vec<u32> {
    out.lines()
        .filter_map(|l| l.strip_prefix("cycle "))
        .map(|l| l.split_whitespace().next().unwrap().parse().unwrap())
        .collect()
}

#[test]
fn replay_of_a_damaged_recording_shows_the_good_frames_then_fails_naming_the_bad_ones() {
    use hammer_wire::{CycleReport, DeviceInfo, DeviceMsg, PROTOCOL_VERSION};
    let dir = tmp_dir("replay-damage");
    let hello = wire_frame(&DeviceMsg::Hello(DeviceInfo {
        protocol_version: PROTOCOL_VERSION,
        firmware_version: [1, 2, 3],
        board: b"bench".iter().copied().collect(),
        config_hash: 7,
    }));
    let report = |seq| {
        wire_frame(&DeviceMsg::Report(CycleReport {
            seq,
            ..Default::default()
        }))
    };
    let opened = [&5u64.to_le_bytes()[..], &u32::MAX.to_le_bytes()].concat();
    let clean_part = [hello, report(0), report(1)].concat();
    let mut clean = [&b"HMFRAMES"[..], &opened, &bytes_record(6, &clean_part)].concat();
    let clean_path = dir.join("clean.bin");
    std::fs::write(&clean_path, &clean).unwrap();
    let (code, out, err) = hammer(&["replay", clean_path.to_str().unwrap(), "--headless", "--speed", "0"]);
    assert_eq!(code, 0, "{err}\n{out}");
    assert_eq!(replay_cycles(&out), [0, 1]);
    assert!(!out.contains("damaged") && !err.contains("damaged"), "{err}\n{out}");

    // A second chunk: a report with a flipped byte, a good one, line noise, a
    // good one, and a report cut off by the end of the recording.
    let mut corrupt = report(2);
    let mid = corrupt.len() / 2;
    corrupt[mid] = corrupt[mid].wrapping_add(1).max(1);
    let noise = [0x55u8; 7];
    let cut = report(5);
    let chunk = [&corrupt[..], &report(3), &noise, &report(4), &cut[..cut.len() / 2]].concat();
    let chunk_at = clean.len() as u64 + 12;
    clean.extend_from_slice(&bytes_record(7, &chunk));
    let damaged_path = dir.join("damaged.bin");
    std::fs::write(&damaged_path, &clean).unwrap();
    let (code, out, err) = hammer(&["replay", damaged_path.to_str().unwrap(), "--headless", "--speed", "0"]);
    assert_eq!(code, 2, "{err}\n{out}");
    assert_eq!(replay_cycles(&out), [0, 1, 3, 4], "the good frames are shown:\n{out}");
    // A bad frame begins after its leading delimiter.
    let corrupt_at = chunk_at + 1;
    let noise_at = chunk_at + (corrupt.len() + report(3).len()) as u64;
    let cut_at = noise_at + (noise.len() + report(4).len()) as u64 + 1;
    assert!(err.contains("damaged recording: 2 bad frames"), "{err}");
    assert!(err.contains(&format!(" at byte {corrupt_at}")), "{err}");
    assert!(err.contains(&format!(" at byte {noise_at}")), "{err}");
    assert!(
        err.contains(&format!(
            "ends inside a frame ({} bytes from byte {cut_at})",
            cut.len() / 2 - 1
        )),
        "{err}"
    );
    assert!(
        out.contains("damaged recording: 2 bad frames"),
        "said on screen too:\n{out}"
    );

    // A garbled end of file: half a record header.
    let garbled_path = dir.join("garbled.bin");
    let end = clean.len();
    std::fs::write(
        &garbled_path,
        [&clean[..end - chunk.len() - 12], &[1, 2, 3, 4, 5]].concat(),
    )
    .unwrap();
    let (code, out, err) = hammer(&["replay", garbled_path.to_str().unwrap(), "--headless", "--speed", "0"]);
    assert_eq!(code, 2, "{err}\n{out}");
    assert_eq!(replay_cycles(&out), [0, 1]);
    assert!(
        err.contains(&format!("cut short at byte {}", end - chunk.len() - 12)),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn flash_dry_run_plans_the_reference_image_and_refuses_other_images() {
    let elf = hammer_host::flash::reference_elf();
    assert!(
        elf.exists(),
        "cargo xtask firmware builds {} before the tests",
        elf.display()
    );
    let (code, out, err) = hammer(&["flash", "--dry-run"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("erase ") && out.contains("sectors"), "{out}");
    assert!(
        out.contains("0x0807e000..0x08080000") && out.contains("is untouched"),
        "{out}"
    );
    assert!(out.contains("nothing written"), "{out}");
    // --erase-state says so in the plan.
    let (code, out, _) = hammer(&["flash", "--dry-run", "--erase-state"]);
    assert_eq!(code, 0);
    assert!(out.contains("WILL BE ERASED"), "{out}");
    // The emulated board's image and a host binary: refused with the reason, no panic.
    let emu = hammer_host::emulator::firmware_elf();
    let (code, _, err) = hammer(&["flash", "--dry-run", emu.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("outside STM32G474RETx's flash"), "{err}");
    let (code, _, err) = hammer(&["flash", "--dry-run", env!("CARGO_BIN_EXE_hammer")]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("a 64-bit ELF for x86-64"), "{err}");
    // A device is refused at once, not read without end.
    let t = std::time::Instant::now();
    let (code, _, err) = hammer(&["flash", "--dry-run", "/dev/zero"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not a regular file"), "{err}");
    println!(
        "flash --dry-run /dev/zero: refused in {:.2} s",
        t.elapsed().as_secs_f64()
    );
    let (code, _, err) = hammer(&["flash", "--dry-run", "--chip", "NoSuchChip"]);
    assert_eq!(code, 2);
    assert!(err.contains("unknown chip"), "{err}");
}

/// A demo killed with SIGKILL leaves no 16 MiB stimulus file in /dev/shm:
/// its name goes as soon as the emulated board runs on it.
#[test]
fn a_killed_demo_leaves_no_stimulus_file_behind() {
    emulated_board_is_there();
    use std::io::BufRead;
    let mut demo = Command::new(env!("CARGO_BIN_EXE_hammer"))
        .args(["demo", "--headless", "--real-time", "--cycles", "1000"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let prefix = format!("hammer-stimulus-{}-", demo.id());
    let leftovers = || -> Vec<String> {
        std::fs::read_dir("/dev/shm")
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(&prefix))
            .collect()
    };
    let lines = std::io::BufReader::new(demo.stdout.take().unwrap()).lines();
    let mut reports = 0;
    for l in lines.map_while(Result::ok) {
        if l.starts_with("cycle ") {
            reports += 1;
            if reports == 5 {
                break;
            }
        }
    }
    assert_eq!(reports, 5, "the board ran");
    assert_eq!(leftovers(), Vec::<String>::new(), "unlinked while running");
    demo.kill().unwrap();
    demo.wait().unwrap();
    assert_eq!(leftovers(), Vec::<String>::new(), "nothing left after SIGKILL");
    // A SIGKILL leaves the demo no time to stop its QEMU, which then runs
    // on by itself (a known limit: docs/firmware.md). Ended here, so that
    // the tests after this one do not share the cores with it.
    for entry in std::fs::read_dir("/proc").into_iter().flatten().flatten() {
        let cmdline = std::fs::read(entry.path().join("cmdline")).unwrap_or_default();
        if String::from_utf8_lossy(&cmdline).contains(&prefix) {
            if let Ok(pid) = entry.file_name().to_string_lossy().parse::<u32>() {
                let _ = Command::new("kill").arg(pid.to_string()).status();
            }
        }
    }
}
