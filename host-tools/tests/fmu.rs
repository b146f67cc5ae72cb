//! The simulator as an FMU (issue 45), checked from outside by FMPy, the
//! importer `.ci/run` pins: `hammer fmu` writes a package FMPy's validator
//! finds nothing wrong with; FMPy's co-simulation at 4 and 7 bar gives
//! `hammer simulate`'s impacts (velocity and period per cycle); the
//! friction effect switched on through FMPy lowers the impact energy as
//! `hammer simulate --effect` does; a reset and rerun repeats every output
//! bit for bit. Without python3 and FMPy the test says so, and under CI it
//! fails.

use std::path::Path;
use std::process::Command;

use serde_json::Value;

mod common;
use common::{hammer, tmp_dir};

/// FMPy is installed (or the test is skipped outside CI).
fn fmpy() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import fmpy, numpy"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but python3 or FMPy is missing (.ci/run installs fmpy==0.3.32)"
        );
        eprintln!("SKIPPED: `python3 -m pip install fmpy==0.3.32` to run it");
    }
    ok
}

/// The friction the comparison switches on (not the defaults, so the
/// parameters are seen to arrive).
const FRICTION: [(&str, f64); 2] = [("f0_n", 3.0), ("k_n_per_bar", 2.5)];

/// `hammer simulate`'s per-cycle truth (its sidecar's cycles).
fn simulated_cycles(dir: &Path, name: &str, bar: f64, friction: bool) -> Vec<Value> {
    let out = dir.join(format!("{name}.csv"));
    let bar = bar.to_string();
    let spec = format!(
        "coulomb_friction:{}",
        FRICTION.map(|(k, v)| format!("{k}={v}")).join(",")
    );
    let mut args = vec!["simulate", "--supply-bar", &bar, "--duration", "0.5", "--out"];
    let path = out.to_str().unwrap();
    args.push(path);
    if friction {
        args.extend(["--effect", &spec]);
    }
    let (code, _, err) = hammer(&args);
    assert_eq!(code, 0, "{err}");
    let sidecar: Value = serde_json::from_slice(&std::fs::read(out.with_extension("json")).unwrap()).unwrap();
    sidecar["simulation"]["cycles"].as_array().unwrap().clone()
}

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap()
}

/// FMPy's report on `fmu` for `cases` (tests/fmu/check.py), the case
/// "reset" rerun after a reset.
fn fmpy_check(fmu: &Path, cases: &Value) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fmu/check.py");
    let run = Command::new("python3")
        .arg(&script)
        .arg(fmu)
        .arg(cases.to_string())
        .arg("reset")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{stderr}");
    serde_json::from_slice(&run.stdout).unwrap_or_else(|e| panic!("{e}: {stderr}"))
}

/// The cases both families run: 4 and 7 bar, friction on at 4 bar through
/// its switch and parameters, and a run to repeat after a reset.
fn cases() -> Value {
    let mut friction_start = serde_json::json!({"supply.pressure_bar": 4.0, "effects.coulomb_friction.on": true});
    for (k, v) in FRICTION {
        friction_start[format!("effects.coulomb_friction.{k}")] = v.into();
    }
    let mut reset_case = friction_start.clone();
    reset_case["supply.pressure_bar"] = 7.0.into();
    reset_case["seed"] = 5.into();
    serde_json::json!({
        "4": {"stop": 0.5, "start": {"supply.pressure_bar": 4.0}},
        "7": {"stop": 0.5, "start": {"supply.pressure_bar": 7.0}},
        "4_friction": {"stop": 0.5, "start": friction_start},
        "reset": {"stop": 0.2, "start": reset_case},
    })
}

/// (impact number, velocity, period) at each new impact of an FMPy run.
fn fmu_impacts(report: &Value, case: &str) -> Vec<(u64, f64, f64)> {
    let run = &report["runs"][case];
    assert_eq!(
        run["samples"].as_u64(),
        Some(50_001),
        "{case}: a sample every 10 µs over 0.5 s"
    );
    run["impacts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| (r[0].as_u64().unwrap(), f(&r[1]), f(&r[2])))
        .collect()
}

/// The validator's verdict and the reset's, the same for both families.
fn check_validation_and_reset(report: &Value) {
    assert_eq!(report["problems"], serde_json::json!([]), "FMPy's validator");
    assert!(
        report["reset"]["bytes"].as_u64().unwrap() > 100_000,
        "{}",
        report["reset"]
    );
    assert_eq!(
        report["reset"]["identical"], true,
        "a reset and rerun repeats every output"
    );
}

/// The second family's FMU runs as the family runs itself
/// (`hammer_variants::generate`, its own truth): per-cycle impact velocity
/// and period, the friction effect through FMPy, the reset.
#[test]
fn fmpy_runs_the_variants_fmu_as_the_family_runs_itself() {
    if !fmpy() {
        return;
    }
    let dir = tmp_dir("variants");
    let fmu = dir.join("variants.fmu");
    let (code, out, err) = hammer(&["fmu", "--family", "variants", "--out", fmu.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("variants.map.toml"), "{out}");
    let report = fmpy_check(&fmu, &cases());
    check_validation_and_reset(&report);
    let cfg = hammer_fmu::VariantsConfig::default();
    let mut energies = Vec::new();
    for (case, bar, friction) in [("4", 4.0, false), ("7", 7.0, false), ("4_friction", 4.0, true)] {
        let mut effects = hammer_sim::Effects::default();
        if friction {
            let spec = FRICTION.map(|(k, v)| format!("{k}={v}")).join(",");
            effects.apply_spec(&format!("coulomb_friction:{spec}")).unwrap();
        }
        let own = hammer_variants::generate(&cfg.params, cfg.structure, &effects, bar, 0.5, cfg.seed);
        let cycles = &own.truth.cycles;
        let impacts = fmu_impacts(&report, case);
        // The family's cycles close at every impact after the first.
        assert_eq!(cycles.len() + 1, impacts.len(), "{case}");
        let mut worst = 0.0f64;
        for (c, (_, v, period)) in cycles.iter().zip(&impacts[1..]) {
            for (got, want) in [(*v, c.impact_velocity_mps), (*period, c.period_s)] {
                worst = worst.max((got - want).abs() / want.abs());
            }
        }
        eprintln!(
            "variants {case} bar: {} cycles, worst relative difference {worst:e}",
            cycles.len()
        );
        assert!(worst <= 1e-4, "{case}: {worst:e} beyond 0.01 %");
        let steady = &impacts[3..];
        let m = cfg.params.piston_mass_kg;
        energies.push(steady.iter().map(|(_, v, _)| 0.5 * m * v * v).sum::<f64>() / steady.len() as f64);
    }
    eprintln!(
        "variants: steady impact energy at 4 bar {:.4} J, with friction {:.4} J",
        energies[0], energies[2]
    );
    assert!(energies[2] < 0.97 * energies[0], "{energies:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn fmpy_runs_the_fmu_as_hammer_simulate_runs_the_model() {
    if !fmpy() {
        return;
    }
    let dir = tmp_dir("fmpy");
    let fmu = dir.join("hammer.fmu");
    let (code, out, err) = hammer(&["fmu", "--out", fmu.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("hammer.map.toml"), "{out}");
    let map: toml::Table = toml::from_str(&std::fs::read_to_string(dir.join("hammer.map.toml")).unwrap()).unwrap();
    assert_eq!(map["supply"]["parameter"].as_str(), Some("supply.pressure_bar"));

    let report = fmpy_check(&fmu, &cases());
    check_validation_and_reset(&report);

    let mut energies = Vec::new();
    for (case, bar, friction) in [("4", 4.0, false), ("7", 7.0, false), ("4_friction", 4.0, true)] {
        let run = &report["runs"][case];
        assert_eq!(
            run["samples"].as_u64(),
            Some(50_001),
            "{case}: a sample every 10 µs over 0.5 s"
        );
        let fmu_impacts: Vec<(u64, f64, f64)> = run["impacts"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| (r[0].as_u64().unwrap(), f(&r[1]), f(&r[2])))
            .collect();
        let cycles = simulated_cycles(&dir, case, bar, friction);
        assert!(cycles.len() >= 8, "{case}: {} cycles", cycles.len());
        let mut worst = 0.0f64;
        for c in &cycles {
            // Cycle k ends in impact number k + 1 (counted from one).
            let k = c["index"].as_u64().unwrap();
            let (_, v, period) = fmu_impacts
                .iter()
                .find(|(n, ..)| *n == k + 1)
                .unwrap_or_else(|| panic!("{case}: the FMU misses impact {}", k + 1));
            for (got, want) in [(*v, f(&c["impact_velocity_mps"])), (*period, f(&c["period_s"]))] {
                worst = worst.max((got - want).abs() / want.abs());
            }
        }
        eprintln!(
            "{case} bar: {} cycles, worst relative difference {worst:e}",
            cycles.len()
        );
        assert!(worst <= 1e-4, "{case}: {worst:e} beyond 0.01 %");
        // Mean impact energy after the start-up (from the third impact, past 0.1 s).
        let m = hammer_sim::SimConfig::default().hammer.piston_mass_kg;
        let steady: Vec<&Value> = cycles
            .iter()
            .filter(|c| c["index"].as_u64().unwrap() >= 2 && f(&c["t_impact_s"]) > 0.1)
            .collect();
        let mean = |e: &dyn Fn(&Value) -> f64| steady.iter().map(|c| e(c)).sum::<f64>() / steady.len() as f64;
        let sim_energy = mean(&|c| f(&c["impact_energy_j"]));
        let fmu_energy = mean(&|c| {
            let n = c["index"].as_u64().unwrap() + 1;
            let v = fmu_impacts.iter().find(|i| i.0 == n).unwrap().1;
            0.5 * m * v * v
        });
        eprintln!("{case} bar: steady impact energy {fmu_energy:.5} J (FMU) vs {sim_energy:.5} J (simulate)");
        assert!((fmu_energy / sim_energy - 1.0).abs() <= 1e-4, "{case}");
        energies.push(fmu_energy);
    }
    // Friction on through FMPy lowers the energy, as `--effect` does (the
    // same numbers, checked above per cycle).
    assert!(energies[2] < 0.97 * energies[0], "{energies:?}");

    assert!(
        report["reset"]["bytes"].as_u64().unwrap() > 100_000,
        "{}",
        report["reset"]
    );
    assert_eq!(
        report["reset"]["identical"], true,
        "a reset and rerun repeats every output"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Without its shared library `hammer fmu` refuses, saying how to build it.
#[test]
fn a_missing_library_is_refused_with_how_to_build_it() {
    let dir = tmp_dir("nolib");
    let fmu = dir.join("x.fmu");
    let (code, _, err) = hammer(&[
        "fmu",
        "--out",
        fmu.to_str().unwrap(),
        "--lib",
        "/nonexistent/libhammer_fmu.so",
    ]);
    assert_eq!(code, 2);
    assert!(
        err.contains("/nonexistent/libhammer_fmu.so") && err.contains("cargo build --release -p hammer-fmu"),
        "{err}"
    );
    assert!(!fmu.exists());
    let _ = std::fs::remove_dir_all(&dir);
}
