//! `hammer bench-sheet` on simulated traces at 4, 5, 6 and 7 bar with the
//! paper's friction: friction and impact energy per pressure are the means
//! of `hammer estimate` on the same traces and lie within 1 % of the
//! simulator's truth; the table holds energy with and without friction and
//! their difference (the paper's Table 3); the air per blow estimated from
//! the chamber states lies within 10 % of the simulator's source; the PNGs and the HTML are
//! written, and the HTML opened in headless Chromium (Debian's package,
//! installed by `.ci/run`) loads every figure.

use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::{hammer, tmp_dir};

/// Mean friction and energy of the valid cycles `hammer estimate` prints.
fn estimate_means(trace: &Path) -> (f64, f64) {
    let (code, out, err) = hammer(&["estimate", trace.to_str().unwrap(), "--format", "jsonl"]);
    assert_eq!(code, 0, "{err}");
    let valid: Vec<serde_json::Value> = out
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|v| v["valid"] == true)
        .collect();
    assert!(valid.len() >= 8, "{out}");
    let mean = |k: &str| valid.iter().map(|v| v[k].as_f64().unwrap()).sum::<f64>() / valid.len() as f64;
    (mean("friction_n"), mean("impact_energy_j"))
}

fn chromium() -> Option<&'static str> {
    let found = ["chromium", "chromium-browser"].into_iter().find(|b| {
        Command::new(b)
            .arg("--version")
            .output()
            .is_ok_and(|o| o.status.success())
    });
    if found.is_none() {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but chromium is missing (.ci/run installs Debian's chromium)"
        );
        eprintln!("SKIPPED the browser half: `apt-get install chromium` to run it");
    }
    found
}

#[test]
fn the_bench_sheet_of_a_simulated_sweep() {
    let dir = tmp_dir("sweep");
    let mut traces = Vec::new();
    for bar in ["4", "5", "6", "7"] {
        let t = dir.join(format!("s{bar}.csv"));
        let (code, _, err) = hammer(&[
            "simulate",
            "--supply-bar",
            bar,
            "--duration",
            "0.6",
            "--effect",
            "coulomb_friction:f0_n=1.7,k_n_per_bar=2.14",
            "--seed",
            bar,
            "--out",
            t.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{err}");
        traces.push(t);
    }
    let out = dir.join("sheet");
    let mut args = vec!["bench-sheet"];
    args.extend(traces.iter().map(|t| t.to_str().unwrap()));
    args.extend(["--out", out.to_str().unwrap()]);
    let (code, said, err) = hammer(&args);
    assert_eq!(code, 0, "{err}");
    for f in [
        "operating-points.csv",
        "model.csv",
        "energy.png",
        "frequency.png",
        "friction.png",
        "index.html",
    ] {
        assert!(said.contains(f), "{said}");
        assert!(std::fs::metadata(out.join(f)).unwrap().len() > 500, "{f}");
    }
    let csv = std::fs::read_to_string(out.join("operating-points.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col =
        |row: &[&str], name: &str| -> f64 { row[header.iter().position(|h| *h == name).unwrap()].parse().unwrap() };
    let rows: Vec<Vec<&str>> = csv.lines().skip(1).map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 4);
    for (row, trace) in rows.iter().zip(&traces) {
        let (friction, energy) = estimate_means(trace);
        let bar = col(row, "supply_bar");
        assert!(
            (col(row, "friction_n") - friction).abs() <= 1e-9 * friction,
            "{bar} bar: {row:?} vs {friction}"
        );
        assert!(
            (col(row, "impact_energy_j") - energy).abs() <= 1e-9 * energy,
            "{bar} bar: {row:?} vs {energy}"
        );
        let (tf, te) = (col(row, "truth_friction_n"), col(row, "truth_impact_energy_j"));
        assert!(
            (friction / tf - 1.0).abs() < 0.01,
            "{bar} bar: friction {friction} vs truth {tf}"
        );
        assert!(
            (energy / te - 1.0).abs() < 0.01,
            "{bar} bar: energy {energy} vs truth {te}"
        );
        // Table 3: the energy friction costs, from the same numbers.
        let loss = col(row, "friction_energy_loss_j");
        assert!(
            (loss - (col(row, "impact_energy_frictionless_j") - energy)).abs() < 1e-9,
            "{row:?}"
        );
        assert!(
            loss > 0.1 * energy && loss < 0.3 * energy,
            "{bar} bar: loss {loss} J of {energy} J"
        );
        assert!((col(row, "blows_per_min") - 60.0 * col(row, "frequency_hz")).abs() < 1e-9);
        // The air per blow (an estimate from the chamber states) against
        // the air the simulator's source gave over the same cycles: the
        // estimate leaves out nothing the model has but the feed area's
        // change through the feed, so 10 % holds it (it reads 2–4 % high).
        let (air, truth_air) = (col(row, "air_per_blow_l"), col(row, "truth_air_per_blow_l"));
        assert!(col(row, "air_cycles") >= 5.0, "{bar} bar: {row:?}");
        assert!(
            (air / truth_air - 1.0).abs() < 0.10,
            "{bar} bar: air per blow {air} l vs the source's {truth_air} l"
        );
        let p_atm = 101_325.0;
        let available = p_atm * air * 1e-3 * ((bar * 1e5 + p_atm) / p_atm).ln();
        assert!((col(row, "impact_efficiency") - energy / available).abs() < 1e-9);
    }
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(
        html.contains("Table 3") && html.contains("measured without friction, J"),
        "{html}"
    );
    // The fitted law recovers the simulated one (1.7 N + 2.14 N/bar).
    let law = html.split("<b>F = ").nth(1).unwrap();
    let f0: f64 = law.split(" N").next().unwrap().parse().unwrap();
    let k: f64 = law
        .split("+ ")
        .nth(1)
        .unwrap()
        .split(' ')
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!((f0 - 1.7).abs() < 0.3 && (k - 2.14).abs() < 0.06, "F0 {f0}, k {k}");

    if let Some(browser) = chromium() {
        // The page as written, plus a script that records, once loaded,
        // whether each figure decoded (a broken image has no natural width).
        let check = out.join("check.html");
        std::fs::write(
            &check,
            html.replace(
                "</body>",
                "<script>window.addEventListener('load',()=>{document.body.setAttribute('data-figures',Array.from(document.images).map(i=>(i.complete&&i.naturalWidth>0?'ok:':'missing:')+i.getAttribute('src')).join(' '))})</script></body>",
            ),
        )
        .unwrap();
        let profile = dir.join("chromium-profile");
        let o = Command::new(browser)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "--virtual-time-budget=5000",
            ])
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg("--dump-dom")
            .arg(format!("file://{}", check.display()))
            .output()
            .unwrap();
        let dom = String::from_utf8_lossy(&o.stdout);
        let figures = dom
            .split("data-figures=\"")
            .nth(1)
            .and_then(|s| s.split('"').next())
            .unwrap_or_else(|| panic!("no load record: {}", String::from_utf8_lossy(&o.stderr)));
        assert_eq!(figures, "ok:energy.png ok:frequency.png ok:friction.png");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A simulated trace at `bar` (0.3 s, the paper's friction), with `config`.
fn simulated(dir: &Path, name: &str, bar: &str, config: Option<&Path>) -> PathBuf {
    let t = dir.join(name);
    let mut args = vec![
        "simulate",
        "--supply-bar",
        bar,
        "--duration",
        "0.3",
        "--effect",
        "coulomb_friction",
        "--seed",
        "3",
        "--out",
        t.to_str().unwrap(),
    ];
    if let Some(c) = config {
        args.extend(["--config", c.to_str().unwrap()]);
    }
    let (code, _, err) = hammer(&args);
    assert_eq!(code, 0, "{err}");
    t
}

/// Issue 48 item 5: traces of two hammers, or traces of one hammer and a
/// --config of another, are refused, naming the traces, the config and the
/// field that differs; nothing is written.
#[test]
fn a_sheet_of_mixed_hammers_is_refused() {
    let dir = tmp_dir("mixed");
    let heavy = dir.join("heavy.toml");
    std::fs::write(&heavy, "[hammer]\npiston_mass_kg = 2.0\n").unwrap();
    let light4 = simulated(&dir, "light4.csv", "4", None);
    let heavy7 = simulated(&dir, "heavy7.csv", "7", Some(&heavy));
    let out = dir.join("sheet");
    let (code, _, err) = hammer(&[
        "bench-sheet",
        light4.to_str().unwrap(),
        heavy7.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("light4.csv") && err.contains("heavy7.csv"), "{err}");
    assert!(err.contains("piston_mass_kg = 1.12 vs 2.0"), "{err}");
    assert!(!out.exists(), "nothing written");
    let light7 = simulated(&dir, "light7.csv", "7", None);
    let (code, _, err) = hammer(&[
        "bench-sheet",
        light4.to_str().unwrap(),
        light7.to_str().unwrap(),
        "--config",
        heavy.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--config") && err.contains("heavy.toml"), "{err}");
    assert!(err.contains("piston_mass_kg = 1.12 vs 2.0"), "{err}");
}

/// Issue 48 item 15: the sheet's refusals name the user's flags, not the
/// configuration keys behind them; one pressure gives no "NaN" in the paper's
/// Table 3; a point outside the paper's 4–7 bar carries a caveat.
#[test]
fn the_sheet_names_flags_and_says_what_it_cannot_draw() {
    let dir = tmp_dir("flags");
    let t8 = simulated(&dir, "s8.csv", "8", None);
    let out = dir.join("sheet");
    let t8s = t8.to_str().unwrap();
    let outs = out.to_str().unwrap();
    let (code, _, err) = hammer(&["bench-sheet", t8s, "--model-duration-s", "0", "--out", outs]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--model-duration-s") && !err.contains("solver.duration_s"),
        "{err}"
    );
    let (code, _, err) = hammer(&["bench-sheet", t8s, "--supply-bar", "20.25", "--out", outs]);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("--supply-bar") && !err.contains("supply.pressure_bar"),
        "{err}"
    );
    let (code, _, err) = hammer(&["bench-sheet", t8s, "--out", outs]);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("caveat: the model's curves at 8 bar are an extrapolation"),
        "{err}"
    );
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(!html.contains("NaN"), "{html}");
    assert!(
        html.contains("Caveat:") && html.contains("no friction law fitted"),
        "{html}"
    );
}
