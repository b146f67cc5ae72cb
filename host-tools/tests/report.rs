//! `hammer report`: the figures and the page for a simulated run and for
//! outside data, and clear errors for bad input.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use hammer_estimator::CycleReport;
use hammer_host::report::{self, ReportArgs, CYCLE_SIZE, RUN_SIZE, TRUTH_SIZE};
use hammer_sim::estimation::open_for_estimation;
use hammer_sim::simulate::{simulate, Simulation};
use hammer_sim::SimConfig;
use hammer_trace::trace::{write_csv, write_sidecar};

/// A white canvas compresses to a few kB; titles, axes, curves and bands take
/// a figure past 100 kB.
const MIN_DRAWN_BYTES: u64 = 30_000;

fn tmp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("hammer-report-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn simulated(supply_bar: f64, duration_s: f64) -> Simulation {
    let mut cfg = SimConfig::nominal(supply_bar);
    cfg.solver.duration_s = duration_s;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    simulate(&cfg).unwrap()
}

/// 0.6 s at 5 bar with the default Coulomb friction, simulated once for all tests.
fn simulation() -> &'static Simulation {
    static SIM: OnceLock<Simulation> = OnceLock::new();
    SIM.get_or_init(|| simulated(5.0, 0.6))
}

/// Writes the simulated trace into `dir`; without the sidecar and the truth
/// columns it looks like a device capture (outside data).
fn write_trace(dir: &Path, sim: &Simulation, outside_data: bool) -> PathBuf {
    let path = dir.join("run.csv");
    let mut trace = sim.trace();
    if outside_data {
        trace.extra.clear();
    } else {
        write_sidecar(&path, &sim.sidecar()).unwrap();
    }
    write_csv(&path, &trace).unwrap();
    path
}

fn args(input: &Path, out: &Path) -> ReportArgs {
    ReportArgs {
        input: input.to_path_buf(),
        out: out.to_path_buf(),
        supply_bar: None,
        config: None,
        map: None,
    }
}

fn png_size(path: &Path) -> (u32, u32) {
    let b = std::fs::read(path).unwrap();
    assert_eq!(&b[..8], b"\x89PNG\r\n\x1a\n", "{} is not a PNG", path.display());
    assert_eq!(&b[12..16], b"IHDR", "{}: first chunk is not IHDR", path.display());
    let w = u32::from_be_bytes([b[16], b[17], b[18], b[19]]);
    let h = u32::from_be_bytes([b[20], b[21], b[22], b[23]]);
    (w, h)
}

fn assert_drawn(path: &Path, size: (u32, u32)) {
    assert_eq!(png_size(path), size, "{}", path.display());
    let bytes = std::fs::metadata(path).unwrap().len();
    assert!(
        bytes > MIN_DRAWN_BYTES,
        "{}: {bytes} bytes, looks blank",
        path.display()
    );
}

/// The estimator's reports, configured as `hammer estimate` does with no config file.
fn estimate(trace_path: &Path) -> Vec<CycleReport> {
    open_for_estimation(trace_path, &SimConfig::default(), None)
        .unwrap()
        .run()
        .unwrap()
}

#[test]
fn simulated_run_gets_every_figure_and_a_page_with_the_summary() {
    let dir = tmp_dir("sim");
    let input = write_trace(&dir, simulation(), false);
    let out = dir.join("report");
    let files = report::run(&args(&input, &out)).unwrap();
    let names: Vec<&str> = files.iter().map(|f| f.file_name().unwrap().to_str().unwrap()).collect();
    assert_eq!(names, ["cycle.png", "run.png", "truth.png", "index.html"]);
    for f in &files {
        assert!(f.is_file(), "{} missing", f.display());
    }
    assert_drawn(&out.join("cycle.png"), CYCLE_SIZE);
    assert_drawn(&out.join("run.png"), RUN_SIZE);
    assert_drawn(&out.join("truth.png"), TRUTH_SIZE);

    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    for png in ["cycle.png", "run.png", "truth.png"] {
        assert!(html.contains(&format!("<img src=\"{png}\"")), "page lacks {png}");
    }
    assert!(!html.contains("http"), "the page must not load external assets");
    let reports = estimate(&input);
    let s = report::summarize(&reports);
    assert!(s.valid_cycles >= 8, "{s:?}");
    for needle in [
        format!("<td class=\"n\">{}</td>", s.valid_cycles),
        format!("{:.3} ± {:.3}", s.friction_mean_n, s.friction_sd_n),
        format!("{:.4}", s.energy_mean_j),
        format!("{:.4}", s.energy_frictionless_mean_j),
        format!("{:.3}", s.frequency_mean_hz),
        format!("{:.1}", 100.0 * s.friction_work_ratio),
        "5 bar (sidecar)".to_string(),
        "coulomb_friction".to_string(),
    ] {
        assert!(html.contains(&needle), "page lacks `{needle}`");
    }
    // Truth means and errors, over the same matched cycles.
    let truth = &simulation().run.cycles;
    let t = report::truth_summary(&report::match_truth(&reports, truth, 0.0));
    assert_eq!(t.matched_cycles, s.valid_cycles);
    assert!(t.friction_error_n.abs() < 0.3, "{t:?}");
    assert!((t.energy_error_j / t.energy_j).abs() < 0.01, "{t:?}");
    for needle in [format!("{:.3}", t.friction_n), format!("{:+.3}", t.friction_error_n)] {
        assert!(html.contains(&needle), "page lacks `{needle}`");
    }
}

#[test]
fn outside_data_gets_cycle_and_run_figures_but_no_truth() {
    let dir = tmp_dir("outside");
    let input = write_trace(&dir, simulation(), true);
    assert!(!dir.join("run.json").exists());
    let out = dir.join("report");
    let files = report::run(&args(&input, &out)).unwrap();
    assert_eq!(
        files,
        [out.join("cycle.png"), out.join("run.png"), out.join("index.html")]
    );
    assert!(!out.join("truth.png").exists());
    assert_drawn(&out.join("cycle.png"), CYCLE_SIZE);
    assert_drawn(&out.join("run.png"), RUN_SIZE);
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(html.contains("<img src=\"cycle.png\"") && html.contains("<img src=\"run.png\""));
    assert!(!html.contains("truth.png") && !html.contains("simulator truth"));
    assert!(
        html.contains("no sidecar") && html.contains("unknown"),
        "operating point"
    );

    // The supply pressure from the command line is the operating point.
    let mut with_supply = args(&input, &out);
    with_supply.supply_bar = Some(5.0);
    report::run(&with_supply).unwrap();
    let html = std::fs::read_to_string(out.join("index.html")).unwrap();
    assert!(html.contains("5 bar (--supply-bar)"));
}

#[test]
fn bad_input_is_a_clear_error_not_a_panic() {
    let dir = tmp_dir("bad");
    let out = dir.join("report");
    let err = |input: &Path| format!("{:#}", report::run(&args(input, &out)).unwrap_err());

    let missing = dir.join("missing.csv");
    assert!(err(&missing).contains("missing.csv"), "{}", err(&missing));

    let bad = dir.join("bad.csv");
    std::fs::write(&bad, "t_s,p_rear_pa,p_front_pa,accel_mps2\n0,1,2,3\n0.00001,1,oops,3\n").unwrap();
    let e = err(&bad);
    assert!(e.contains("bad.csv:3") && e.contains("oops"), "{e}");

    // A hammer at rest: samples (with a little sensor noise) but no impact.
    let idle = dir.join("idle.csv");
    let mut text = String::from("t_s,p_rear_pa,p_front_pa,accel_mps2\n");
    for i in 0..5000 {
        let k = (i % 3) as f64;
        text.push_str(&format!(
            "{:.6},{},{},{}\n",
            i as f64 * 1e-5,
            300.0 * k,
            -300.0 * k,
            k - 1.0
        ));
    }
    std::fs::write(&idle, text).unwrap();
    let e = err(&idle);
    assert!(e.contains("no complete impact cycle"), "{e}");

    let mut with_config = args(&idle, &out);
    with_config.config = Some(dir.join("nope.toml"));
    let e = format!("{:#}", report::run(&with_config).unwrap_err());
    assert!(e.contains("nope.toml"), "{e}");
    assert!(!out.join("index.html").exists(), "no page for a failed report");
}

#[test]
fn help_explains_units_and_defaults() {
    use clap::Args as _;
    let mut cmd = ReportArgs::augment_args(clap::Command::new("report"));
    let help = cmd.render_long_help().to_string();
    for needle in [
        "--out",
        "--supply-bar",
        "--config",
        "bar",
        "sidecar",
        "default",
        "index.html",
    ] {
        assert!(help.contains(needle), "help lacks `{needle}`:\n{help}");
    }
}

/// Regenerates `docs/report-example/`: a simulated 1 s run at 4 bar with the
/// default Coulomb friction (the same trace as `hammer simulate --supply-bar 4
/// --duration 1 --effect coulomb_friction`).
#[test]
#[ignore = "writes docs/report-example; run with --ignored to regenerate it"]
fn regenerate_docs_example() {
    let dir = tmp_dir("docs");
    let input = write_trace(&dir, &simulated(4.0, 1.0), false);
    let out = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/report-example");
    for f in report::run(&args(&input, &out)).unwrap() {
        println!("wrote {}", f.display());
    }
}
