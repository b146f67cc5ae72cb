//! What cannot be read right is refused, naming the fix: a sample rate too
//! low to resolve the impact, absolute pressure given as gauge, and a hammer
//! whose force balance is far off with the geometry in use. The two
//! reproductions of issue 29 (the trace decimated to 10 kS/s, the same trace
//! in absolute pressure) give no valid cycle.

use std::path::{Path, PathBuf};
use std::process::Command;

fn hammer(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_hammer")).args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn tmp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hammer-refusals-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The four signal columns of a simulated trace, each row through `row`.
fn rewrite(from: &Path, to: &Path, mut row: impl FnMut(usize, [&str; 4]) -> Option<String>) {
    let text = std::fs::read_to_string(from).unwrap();
    let mut out = String::from("t_s,p_rear_pa,p_front_pa,accel_mps2\n");
    for (i, line) in text.lines().skip(1).enumerate() {
        let f: Vec<&str> = line.split(',').collect();
        if let Some(r) = row(i, [f[0], f[1], f[2], f[3]]) {
            out.push_str(&r);
            out.push('\n');
        }
    }
    std::fs::write(to, out).unwrap();
}

#[test]
fn low_rates_and_absolute_pressure_give_no_valid_cycle() {
    let dir = tmp_dir("issue");
    let base = dir.join("base.csv");
    let (code, _, err) = hammer(&[
        "simulate",
        "--supply-bar",
        "4",
        "--duration",
        "1",
        "--effect",
        "coulomb_friction:f0_n=1.7,k_n_per_bar=2.14",
        "--seed",
        "1",
        "--out",
        base.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    // The recorder at 10 kS/s (every tenth sample), and at 5 kS/s.
    for step in [10, 20] {
        let ks = dir.join(format!("ks{step}.csv"));
        rewrite(&base, &ks, |i, f| (i % step == 0).then(|| f.join(",")));
        std::fs::write(ks.with_extension("json"), "{\"supply_pressure_bar\":4}").unwrap();
        let (code, out, err) = hammer(&["estimate", ks.to_str().unwrap(), "--format", "jsonl"]);
        assert_eq!(code, 2, "{out}");
        assert!(!out.contains("\"valid\":true"), "{out}");
        assert!(
            err.contains("below the 20 kS/s this estimator needs") && err.contains("80 µs"),
            "{err}"
        );
    }
    // The same trace in absolute pressure: refused, the fix named.
    let abs = dir.join("abs.csv");
    rewrite(&base, &abs, |_, f| {
        let p = |s: &str| s.parse::<f64>().unwrap() + 101_325.0;
        Some(format!("{},{},{},{}", f[0], p(f[1]), p(f[2]), f[3]))
    });
    let (code, out, err) = hammer(&[
        "estimate",
        abs.to_str().unwrap(),
        "--supply-bar",
        "4",
        "--format",
        "jsonl",
    ]);
    assert_eq!(code, 2, "{out}");
    assert!(!out.contains("\"valid\":true"), "{out}");
    assert!(
        err.contains("look absolute") && err.contains("absolute = true"),
        "{err}"
    );
    // ... and read right once the mapping says so.
    let map = dir.join("abs.toml");
    std::fs::write(
        &map,
        "p_rear = { column = \"p_rear_pa\", absolute = true }\np_front = { column = \"p_front_pa\", absolute = true }\n",
    )
    .unwrap();
    let (code, out, err) = hammer(&[
        "estimate",
        abs.to_str().unwrap(),
        "--supply-bar",
        "4",
        "--map",
        map.to_str().unwrap(),
        "--format",
        "table",
    ]);
    assert_eq!(code, 0, "{err}");
    let summary = out.lines().last().unwrap();
    let friction: f64 = summary
        .split("friction ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{summary}"));
    // The paper's friction at 4 bar: 1.7 + 2.14·4 = 10.26 N.
    assert!((friction - 10.26).abs() < 0.3, "{summary}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bigger_hammer_read_with_the_default_geometry_is_named() {
    let dir = tmp_dir("geometry");
    let cfg = dir.join("big.toml");
    std::fs::write(
        &cfg,
        "[hammer]\npiston_mass_kg = 2.5\nbore_diameter_m = 0.055\nrod_diameter_m = 0.035\n",
    )
    .unwrap();
    let sim = dir.join("sim.csv");
    let (code, _, err) = hammer(&[
        "simulate",
        "--supply-bar",
        "5",
        "--duration",
        "0.3",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        sim.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    // Outside data: no sidecar to carry the simulated hammer.
    let plain = dir.join("plain.csv");
    rewrite(&sim, &plain, |_, f| Some(f.join(",")));
    let (code, out, err) = hammer(&["estimate", plain.to_str().unwrap(), "--supply-bar", "5"]);
    assert!(!out.contains("cycles valid"), "{out}");
    assert!(
        err.contains("piston 1.12 kg, bore 41 mm, rod 28 mm (the paper's hammer, the default)")
            && err.contains("--config"),
        "exit {code}: {err}"
    );
    let (code, out, err) = hammer(&[
        "estimate",
        plain.to_str().unwrap(),
        "--supply-bar",
        "5",
        "--config",
        cfg.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        out.contains("of 4 cycles valid") || out.contains("cycles valid"),
        "{out}"
    );
    assert!(!err.contains("force balance"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
