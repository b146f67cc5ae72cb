//! A foreign FMU run by the project (issue 46): the project's own export
//! read back through the import gives the built-in simulator's output; a
//! pythonfmu FMU (another tool's) loads, takes its parameters and runs;
//! `hammer fmu check` passes a good FMU and refuses each kind of bad one
//! with exit 2, naming the FMU and what failed. The bad FMUs are a small C
//! FMU (tests/fmu/mock.c) compiled here, not checked-in binaries.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use hammer_fmu::import::{cycling, FailKind, FmuModel, ModelMap, Options, Signals, WorkerCommand};

mod common;
use common::{hammer, tmp_dir};

fn options(threads: usize, limit_s: f64) -> Options {
    Options {
        threads,
        time_limit: Duration::from_secs_f64(limit_s),
        worker: WorkerCommand {
            program: PathBuf::from(env!("CARGO_BIN_EXE_hammer")),
            args: vec!["fmu".into(), "worker".into()],
            env: Vec::new(),
        },
    }
}

fn open(fmu: &Path, map: &Path, threads: usize) -> FmuModel {
    let map = ModelMap::read(map).unwrap();
    FmuModel::open(fmu, Some(map), options(threads, 60.0)).unwrap_or_else(|e| panic!("{e}"))
}

/// The largest difference between `a` and `b` relative to `b`'s largest magnitude.
fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    let scale = b.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(f64::MIN_POSITIVE);
    a.iter().zip(b).fold(0.0f64, |m, (x, y)| m.max((x - y).abs())) / scale
}

/// The project's FMU through the import is the built-in simulator: every
/// signal of a run with friction on (set through the map's effect
/// settings) equals `simulate_truth`'s within 1e-9 relative; the worker is
/// reused through fmi2Reset and repeats itself; three callers share a pool
/// of two workers.
#[test]
fn the_projects_fmu_through_the_import_is_the_built_in_simulator() {
    let dir = tmp_dir("own");
    let fmu = dir.join("hammer.fmu");
    let (code, _, err) = hammer(&["fmu", "--out", fmu.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let model = open(&fmu, &hammer_fmu::map_path(&fmu), 2);
    let map = model.map().unwrap().clone();
    let friction = hammer_sim::effects::REGISTRY
        .iter()
        .find(|e| hammer_fmu::import::map::law_force_n(**e, e.default_params(), 1.0).is_some())
        .unwrap();
    let keys: Vec<&str> = friction.params().iter().map(|p| p.key).collect();
    let values = [(keys[0], 3.0), (keys[1], 2.5)];
    let settings = map.effect_settings(friction.name(), &values, 4.0).unwrap();
    let duration_s = 0.2;
    let run = model.run(4e5, &settings, duration_s).unwrap();

    let mut cfg = hammer_sim::SimConfig::default();
    cfg.supply.pressure_bar = 4.0;
    cfg.solver.duration_s = duration_s;
    let spec = format!("{}:{}={},{}={}", friction.name(), keys[0], 3.0, keys[1], 2.5);
    cfg.effects.apply_spec(&spec).unwrap();
    let truth = hammer_sim::simulate_truth(&cfg).unwrap().truth;
    assert_eq!(run.dt_s, truth.dt_s);
    let pairs = [
        ("p_rear", &run.p_rear_pa, &truth.p_rear_pa),
        ("p_front", &run.p_front_pa, &truth.p_front_pa),
        ("accel", &run.accel_mps2, &truth.accel_mps2),
        ("position", run.position_m.as_ref().unwrap(), &truth.x_m),
        ("velocity", run.velocity_mps.as_ref().unwrap(), &truth.v_mps),
    ];
    for (name, a, b) in pairs {
        let d = rel_diff(a, b);
        eprintln!("{name}: largest difference relative to the largest value {d:e}");
        assert!(d <= 1e-9, "{name}: relative difference {d:e}");
    }
    let impacts = run.impacts.as_ref().unwrap();
    assert!(impacts.last().copied().unwrap_or(0.0) >= 3.0, "impacts counted");
    // Friction off (the map's off settings) is another run; the same
    // settings again, on a reused instance, repeat the first bit for bit.
    let off = model.run(4e5, &[], duration_s).unwrap();
    assert!(rel_diff(&off.velocity_mps.unwrap(), run.velocity_mps.as_ref().unwrap()) > 1e-3);
    std::thread::scope(|s| {
        let runs: Vec<_> = (0..3)
            .map(|_| s.spawn(|| model.run(4e5, &settings, duration_s).unwrap()))
            .collect();
        for r in runs {
            assert_eq!(r.join().unwrap(), run, "a rerun repeats the run");
        }
    });
    assert!(model.workers() <= 2, "{} workers for a pool of 2", model.workers());
    let id = model.identity();
    assert_eq!(id.name, "hammer");
    assert_eq!(id.fmi_version, "2.0");
    assert_eq!(id.map_hash.as_ref().map(String::len), Some(64));
    let json = serde_json::to_string(&id).unwrap();
    assert_eq!(serde_json::from_str::<hammer_fmu::import::Identity>(&json).unwrap(), id);
}

/// `hammer fmu check` on the project's FMU: loads, fits the map, runs,
/// and names each catalogue effect's coverage.
#[test]
fn hammer_fmu_check_passes_the_projects_fmu() {
    let dir = tmp_dir("check");
    let fmu = dir.join("variants.fmu");
    let (code, _, err) = hammer(&["fmu", "--family", "variants", "--out", fmu.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = hammer(&[
        "fmu",
        "check",
        fmu.to_str().unwrap(),
        "--duration",
        "0.4",
        "--supply-bar",
        "5",
    ]);
    assert_eq!(code, 0, "{err}");
    for name in hammer_sim::EFFECT_NAMES {
        assert!(out.lines().any(|l| l.trim_start().starts_with(name)), "{name}: {out}");
    }
    assert!(out.contains("steady cycling"), "{out}");
}

/// Whether there is a compiler `cc` (or `c++`) for the mock FMU (CI
/// installs gcc and g++: there a missing one fails the test).
fn have(compiler: &str) -> bool {
    if Command::new(compiler).arg("--version").output().is_ok() {
        return true;
    }
    assert!(std::env::var_os("CI").is_none(), "CI is set but there is no {compiler}");
    eprintln!("SKIPPED: no compiler ({compiler}) for the mock FMU");
    false
}

/// The C mock FMU, built with `flags`, packed with its description.
fn mock_fmu(dir: &Path, name: &str, flags: &[&str], platform: &str) -> PathBuf {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fmu/mock.c");
    let so = dir.join(format!("{name}.so"));
    let ok = Command::new("cc")
        .args(["-shared", "-fPIC", "-O1"])
        .args(flags)
        .arg(&src)
        .arg("-o")
        .arg(&so)
        .arg("-lm")
        .status()
        .unwrap();
    assert!(ok.success(), "cc {}", src.display());
    let ext = if platform == "linux64" { "so" } else { "dylib" };
    let files = vec![
        ("modelDescription.xml".to_string(), mock_description("").into_bytes()),
        (format!("binaries/{platform}/mock.{ext}"), std::fs::read(&so).unwrap()),
    ];
    let fmu = dir.join(format!("{name}.fmu"));
    std::fs::write(&fmu, hammer_fmu::package::zip_stored(&files)).unwrap();
    fmu
}

/// The mock's modelDescription.xml; `sources`, if not empty, go into the
/// co-simulation interface (`<SourceFiles>…`).
fn mock_description(sources: &str) -> String {
    let var = |name: &str, vr: u32, attrs: &str, ty: &str| {
        format!(r#"<ScalarVariable name="{name}" valueReference="{vr}" {attrs}><{ty}/></ScalarVariable>"#)
    };
    let par = r#"causality="parameter" variability="fixed" initial="exact""#;
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="mock" guid="{{mock}}" generationTool="hammer-monitor tests (C)">
<CoSimulation modelIdentifier="mock" canBeInstantiatedOnlyOncePerProcess="true">{sources}</CoSimulation>
<DefaultExperiment stepSize="1e-4"/>
<ModelVariables>{}{}{}{}{}{}{}</ModelVariables></fmiModelDescription>"#,
        var("supply_bar", 0, par, "Real start=\"5\""),
        var("freq_hz", 1, par, "Real start=\"40\""),
        var("mode", 2, par, "Integer start=\"0\""),
        var(
            "derived",
            3,
            r#"causality="calculatedParameter" variability="fixed""#,
            "Real"
        ),
        var("p_rear", 10, r#"causality="output""#, "Real"),
        var("p_front", 11, r#"causality="output""#, "Real"),
        var("accel", 12, r#"causality="output""#, "Real"),
    )
}

const MOCK_MAP: &str = r#"
[signals]
p_rear = { output = "p_rear", unit = "Pa", pressure = "gauge" }
p_front = { output = "p_front", unit = "Pa", pressure = "gauge" }
accel = { output = "accel", unit = "m/s2" }
[supply]
parameter = "supply_bar"
unit = "bar"
pressure = "gauge"
[fixed]
mode = 0
"#;

/// A source-code FMU, as tools export one for another platform: sources
/// and no binary, its functions named with the model identifier as FMI 2.0
/// asks of sources, one file C++. Refused with the way out; `hammer fmu
/// compile` builds it into an FMU whose binary has the standard names (the
/// import resolves no other), which then checks; sources that do not
/// compile are exit 2 with the compiler's words.
#[test]
fn a_source_fmu_is_compiled_and_then_checks() {
    if !have("cc") || !have("c++") {
        return;
    }
    let dir = tmp_dir("source");
    let mock = std::fs::read(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fmu/mock.c")).unwrap();
    let source_fmu = |name: &str, all_c: &str| {
        let files = vec![
            (
                "modelDescription.xml".to_string(),
                mock_description(r#"<SourceFiles><File name="all.c"/><File name="extra.cpp"/></SourceFiles>"#)
                    .into_bytes(),
            ),
            ("sources/all.c".to_string(), all_c.as_bytes().to_vec()),
            ("sources/mock.c".to_string(), mock.clone()),
            (
                "sources/extra.cpp".to_string(),
                b"extern \"C\" int mock_extra(void) { return 1; }\n".to_vec(),
            ),
        ];
        let fmu = dir.join(format!("{name}.fmu"));
        std::fs::write(&fmu, hammer_fmu::package::zip_stored(&files)).unwrap();
        fmu
    };
    let fmu = source_fmu("src", "#define FMI2_FUNCTION_PREFIX mock_\n#include \"mock.c\"\n");
    let map = dir.join("src.map.toml");
    std::fs::write(&map, MOCK_MAP).unwrap();
    let check = |fmu: &Path| {
        hammer(&[
            "fmu",
            "check",
            fmu.to_str().unwrap(),
            "--model-map",
            map.to_str().unwrap(),
            "--duration",
            "0.3",
        ])
    };
    let (code, out, err) = check(&fmu);
    assert_eq!(code, 2, "{out}{err}");
    assert!(err.contains("it has sources: `hammer fmu compile"), "{err}");
    let (code, out, err) = hammer(&["fmu", "compile", fmu.to_str().unwrap()]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("compiled 2 source file(s)"), "{out}");
    assert!(out.contains("with c++ into binaries/linux64/mock.so"), "{out}");
    let compiled = dir.join("src.linux64.fmu");
    let (code, out, err) = check(&compiled);
    assert_eq!(code, 0, "the compiled FMU checks: {out}{err}");
    assert!(out.contains("steady cycling"), "{out}");
    // Sources that do not compile: the FMU, the file and the compiler's error.
    let broken = source_fmu("broken", "this is not C;\n");
    let (code, out, err) = hammer(&["fmu", "compile", broken.to_str().unwrap()]);
    assert_eq!(code, 2, "{out}{err}");
    assert!(err.contains("broken.fmu: compiling all.c: cc failed"), "{err}");
    assert!(err.contains("sources/all.c:1:"), "the FMU's own path: {err}");
    assert!(!err.contains("hammer-fmu-"), "not where it was unpacked: {err}");
    assert!(!dir.join("broken.linux64.fmu").exists());
}

/// Each bad FMU or map: exit 2, the FMU (or map) named, what failed said.
#[test]
fn bad_fmus_exit_2_naming_the_fmu_and_what_failed() {
    if !have("cc") {
        return;
    }
    let dir = tmp_dir("bad");
    let good = mock_fmu(&dir, "mock", &[], "linux64");
    let no_reset = mock_fmu(&dir, "noreset", &["-DNO_RESET"], "linux64");
    let darwin = mock_fmu(&dir, "darwin", &[], "darwin64");
    let other_guid = mock_fmu(&dir, "otherguid", &["-DGUID=\"{other}\""], "linux64");
    // A binary that needs a library this machine lacks, as one linked on a
    // newer distribution needs its glibc: linked against a stub, the stub
    // then removed.
    let stub = dir.join("libhammerabsent.so");
    let linked = Command::new("cc")
        .args(["-shared", "-fPIC", "-x", "c", "-", "-o"])
        .arg(&stub)
        .stdin(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(linked.success(), "cc the stub");
    let search = format!("-L{}", dir.display());
    let unloadable = mock_fmu(
        &dir,
        "unloadable",
        &["-Wl,--no-as-needed", &search, "-lhammerabsent"],
        "linux64",
    );
    std::fs::remove_file(&stub).unwrap();
    // An FMI 3.0 FMU as the Reference FMUs lay it out (an
    // instantiationToken, not a guid): refused by its version.
    let fmi3 = dir.join("fmi3.fmu");
    let xml3 = r#"<fmiModelDescription fmiVersion="3.0" modelName="mock" instantiationToken="{mock}">
<CoSimulation modelIdentifier="mock"/></fmiModelDescription>"#;
    let files3 = vec![
        ("modelDescription.xml".to_string(), xml3.as_bytes().to_vec()),
        (
            "binaries/x86_64-linux/mock.so".to_string(),
            std::fs::read(dir.join("mock.so")).unwrap(),
        ),
    ];
    std::fs::write(&fmi3, hammer_fmu::package::zip_stored(&files3)).unwrap();
    let not_zip = dir.join("text.fmu");
    std::fs::write(&not_zip, "this is not a zip file\n").unwrap();
    let map_with = |name: &str, from: &str, to: &str| {
        let p = dir.join(format!("{name}.map.toml"));
        std::fs::write(&p, MOCK_MAP.replacen(from, to, 1)).unwrap();
        p
    };
    let good_map = map_with("good", "", "");
    let check = |fmu: &Path, map: &Path, extra: &[&str]| {
        let mut args = vec![
            "fmu",
            "check",
            fmu.to_str().unwrap(),
            "--model-map",
            map.to_str().unwrap(),
        ];
        args.extend(["--duration", "0.3"]);
        args.extend(extra);
        hammer(&args)
    };
    let (code, out, err) = check(&good, &good_map, &[]);
    assert_eq!(code, 0, "the good mock passes: {err}");
    // Without a map (none beside it): loaded and instantiated, then refused.
    let (code, out2, err2) = hammer(&["fmu", "check", good.to_str().unwrap()]);
    assert_eq!(code, 2, "{out2}{err2}");
    assert!(out2.contains("loaded and instantiated"), "{out2}");
    assert!(err2.contains("mock.fmu: no model map"), "{err2}");
    assert!(out.contains("coulomb_friction       not modelled"), "{out}");
    let cases: Vec<(&str, PathBuf, PathBuf, Vec<&str>, &str)> = vec![
        (
            "missing file",
            dir.join("absent.fmu"),
            good_map.clone(),
            vec![],
            "cannot read it",
        ),
        ("not a zip", not_zip, good_map.clone(), vec![], "not a zip"),
        (
            "no binary",
            darwin,
            good_map.clone(),
            vec![],
            "no binary for this platform",
        ),
        (
            "binary does not load",
            unloadable,
            good_map.clone(),
            vec![],
            "libhammerabsent.so: cannot open shared object file: No such file or directory (built on a newer Linux",
        ),
        (
            "missing function",
            no_reset,
            good_map.clone(),
            vec![],
            "no function fmi2Reset",
        ),
        (
            "unknown parameter",
            good.clone(),
            map_with("unknown", "mode = 0", "nope = 1"),
            vec![],
            "fixed: the FMU has no variable nope",
        ),
        (
            "fixed after initialisation",
            good.clone(),
            {
                // Friction through a piston-force input set during the run:
                // the map names a parameter fixed once initialised.
                let p = dir.join("fixed_input.map.toml");
                let accel = "accel = { output = \"accel\", unit = \"m/s2\" }";
                let text = MOCK_MAP.replacen(
                    accel,
                    &format!("{accel}\nvelocity = {{ output = \"accel\", unit = \"m/s\" }}"),
                    1,
                ) + "[outside]\npiston_force = { input = \"freq_hz\", unit = \"N\" }\n";
                std::fs::write(&p, text).unwrap();
                p
            },
            vec![],
            "outside.piston_force: freq_hz is fixed after initialisation",
        ),
        (
            "calculated parameter",
            good.clone(),
            map_with("calculated", "mode = 0", "derived = 1"),
            vec![],
            "derived is calculated",
        ),
        (
            "missing output",
            good.clone(),
            map_with("output", "\"p_front\"", "\"p_front_x\""),
            vec![],
            "signals.p_front: the FMU has no output p_front_x",
        ),
        (
            "doStep fails",
            good.clone(),
            map_with("m1", "mode = 0", "mode = 1"),
            vec![],
            "fmi2DoStep at t = ",
        ),
        (
            "the FMU's own reason",
            good.clone(),
            map_with("m1log", "mode = 0", "mode = 1"),
            vec![],
            "the FMU logged: [fmi2Error] logStatusError: the valve's solver did not converge",
        ),
        (
            "GUID refused",
            other_guid,
            good_map.clone(),
            vec![],
            "fmi2Instantiate returned no instance; the FMU logged: [fmi2Error] logStatusError: Wrong GUID.",
        ),
        ("FMI 3.0", fmi3.clone(), good_map.clone(), vec![], "FMI version 3.0"),
        (
            "non-finite",
            good.clone(),
            map_with("m2", "mode = 0", "mode = 2"),
            vec![],
            "non-finite output",
        ),
        (
            "time-out",
            good.clone(),
            map_with("m3", "mode = 0", "mode = 3"),
            vec!["--time-limit", "1"],
            "time limit of 1.000 s",
        ),
        (
            "crash",
            good.clone(),
            map_with("m4", "mode = 0", "mode = 4"),
            vec![],
            "SIGSEGV",
        ),
        (
            "no steady cycling",
            good.clone(),
            map_with("m5", "mode = 0", "mode = 5"),
            vec![],
            "never reaches steady cycling",
        ),
    ];
    for (what, fmu, map, extra, says) in cases {
        let (code, out, err) = check(&fmu, &map, &extra);
        assert_eq!(code, 2, "{what}: {out}{err}");
        let name = fmu.file_name().unwrap().to_string_lossy().into_owned();
        assert!(err.contains(&name), "{what}: the FMU is named: {err}");
        assert!(err.contains(says), "{what}: says {says:?}: {err}");
        assert!(!err.contains("panicked"), "{what}: {err}");
        assert!(
            !err.contains("this is not a zip file"),
            "{what}: never quotes the file: {err}"
        );
    }
    // The diagnosis with a crashing or hanging FMU, or one whose every run
    // fails (so the nominal model's too): exit 2, the FMU named, what
    // failed said; never a panic of the host.
    let traces = friction_traces(&dir);
    let mode = |n: u8| map_with(&format!("d{n}"), "mode = 0", &format!("mode = {n}"));
    let no_cycle = "the nominal model does not run at 4 bar: no steady impact cycle";
    for (what, map, extra, says) in [
        ("crash", mode(4), vec![], "SIGSEGV"),
        ("doStep fails", mode(1), vec![], "fmi2DoStep at t = "),
        ("non-finite", mode(2), vec![], "non-finite output"),
        ("no steady cycling", mode(5), vec![], no_cycle),
        (
            "time-out",
            mode(3),
            vec!["--model-time-limit", "1"],
            "time limit of 1.000 s",
        ),
    ] {
        let out = dir.join(format!("diagnose-{what}"));
        let mut args = vec![
            "diagnose",
            "--measured",
            &traces[0],
            "--measured",
            &traces[1],
            "--model",
            good.to_str().unwrap(),
            "--model-map",
            map.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend(extra.iter().copied());
        let (code, stdout, err) = hammer(&args);
        assert_eq!(code, 2, "diagnose, {what}: {stdout}{err}");
        assert!(
            err.contains("mock.fmu") && err.contains(says),
            "diagnose, {what}: {err}"
        );
        assert!(!err.contains("panicked"), "diagnose, {what}: {err}");
        assert!(
            !out.join("report.json").exists(),
            "diagnose, {what}: no report of a failed model"
        );
    }
    // Through the API: the kinds are typed, and the pool recovers from a
    // crash (the next run starts a fresh worker).
    let m = ModelMap::read(&good_map).unwrap();
    let model = FmuModel::open(&good, Some(m), options(1, 2.0)).unwrap();
    let crash = model.run(5e5, &[("mode".into(), 4.0)], 0.1).unwrap_err();
    assert_eq!(crash.kind, FailKind::Crashed, "{crash}");
    let hang = model.run(5e5, &[("mode".into(), 3.0)], 0.1);
    assert!(hang.is_err());
    let ok = model.run(5e5, &[], 0.1).unwrap();
    assert_eq!(ok.p_rear_pa.len(), 1001);
    assert!(
        (ok.p_rear_pa[0] - 2.5e5).abs() < 1e-6,
        "supply 5 bar: {}",
        ok.p_rear_pa[0]
    );
    let unknown = model.run(5e5, &[("nope".into(), 1.0)], 0.1).unwrap_err();
    assert_eq!(unknown.kind, FailKind::Map);
    // The same outputs read as absolute kPa, and the acceleration with the
    // other sign: SI gauge and the project's sign out.
    let text = MOCK_MAP
        .replacen(
            r#"p_rear = { output = "p_rear", unit = "Pa", pressure = "gauge" }"#,
            r#"p_rear = { output = "p_rear", unit = "kPa", pressure = "absolute" }"#,
            1,
        )
        .replacen(r#"unit = "m/s2" }"#, r#"unit = "m/s2", sign = -1 }"#, 1);
    let read_as = FmuModel::open(&good, Some((ModelMap::parse(&text).unwrap(), text)), options(1, 5.0)).unwrap();
    let other = read_as.run(5e5, &[], 0.1).unwrap();
    let p_atm_pa = 101_325.0;
    for i in [0, 10, 500, 1000] {
        let expect = ok.p_rear_pa[i] * 1e3 - p_atm_pa;
        assert!(
            (other.p_rear_pa[i] - expect).abs() <= 1e-9 * expect.abs().max(p_atm_pa),
            "{i}"
        );
        assert_eq!(other.accel_mps2[i], -ok.accel_mps2[i]);
        assert_eq!(other.p_front_pa[i], ok.p_front_pa[i]);
    }
}

/// pythonfmu is installed (or the test is skipped outside CI).
fn pythonfmu() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import pythonfmu; assert pythonfmu.__version__ == '0.7.0'"])
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI is set but pythonfmu 0.7.0 is missing (.ci/run installs pythonfmu==0.7.0)"
        );
        eprintln!("SKIPPED: `python3 -m pip install pythonfmu==0.7.0` to run it");
    }
    ok
}

/// tests/fmu/pyhammer.py built into `dir/PyHammer.fmu`, and the catalogue's
/// friction effect with a supply-pressure law (what its map carries).
fn pyhammer(dir: &Path) -> (PathBuf, &'static dyn hammer_sim::effects::EffectEntry) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fmu/pyhammer.py");
    let built = Command::new("python3")
        .args(["-m", "pythonfmu", "build", "-f"])
        .arg(&script)
        .arg("-d")
        .arg(dir)
        .output()
        .unwrap();
    assert!(built.status.success(), "{}", String::from_utf8_lossy(&built.stderr));
    let friction = hammer_sim::effects::REGISTRY
        .iter()
        .find(|e| hammer_fmu::import::map::law_force_n(**e, e.default_params(), 1.0).is_some())
        .copied()
        .unwrap();
    (dir.join("PyHammer.fmu"), friction)
}

fn peak(v: &[f64]) -> f64 {
    v[v.len() / 2..].iter().fold(f64::NEG_INFINITY, |m, x| m.max(*x))
}

/// An FMU by another tool: a hammer-like model written with pythonfmu,
/// built here, loaded by the host (libpython opened RTLD_GLOBAL,
/// PYTHONPATH set, in the worker), its supply pressure and the friction
/// law set through the map, a short run read and cycling.
#[test]
fn a_pythonfmu_fmu_loads_takes_its_parameters_and_runs() {
    if !pythonfmu() {
        return;
    }
    let dir = tmp_dir("pythonfmu");
    let (fmu, friction) = pyhammer(&dir);
    let map_text = format!(
        r#"step_s = 1e-4
[signals]
p_rear = {{ output = "p_rear", unit = "bar", pressure = "gauge" }}
p_front = {{ output = "p_front", unit = "Pa", pressure = "gauge" }}
accel = {{ output = "accel", unit = "m/s2" }}
position = {{ output = "x", unit = "m" }}
velocity = {{ output = "v", unit = "m/s" }}
impact_counter = {{ output = "impacts" }}
[supply]
parameter = "supply_bar"
unit = "bar"
pressure = "gauge"
[fixed]
mass_kg = 0.2
[effects.{}]
law = {{ parameter = "friction_n", unit = "N", off = 0.0 }}
[outside]
piston_force = {{ input = "f_ext_n", unit = "N" }}
"#,
        friction.name()
    );
    // p_rear is read as if in bar: the unit conversion is seen (×1e5).
    let map = ModelMap::parse(&map_text).unwrap();
    let model =
        FmuModel::open(&fmu, Some((map.clone(), map_text.clone())), options(1, 60.0)).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(model.identity().generation_tool.as_deref(), Some("PythonFMU 0.7.0"));
    let run = |bar: f64, settings: &[(String, f64)]| -> Signals { model.run(bar * 1e5, settings, 0.3).unwrap() };
    let at5 = run(5.0, &[]);
    let at7 = run(7.0, &[]);
    // The rear chamber fills to the supply pressure (read in "bar": ×1e5).
    let p5 = peak(&at5.p_rear_pa) / 1e5;
    let p7 = peak(&at7.p_rear_pa) / 1e5;
    assert!(
        (p5 / 5e5 - 1.0).abs() < 0.02 && (p7 / 7e5 - 1.0).abs() < 0.02,
        "{p5} {p7}"
    );
    // The front chamber is fed for the backhaul only, read in Pa (×1).
    let front = peak(&at5.p_front_pa) / 5e5;
    assert!(front > 0.5 && front <= 1.0, "{front}");
    let c = cycling::steady(&at5).unwrap();
    assert!(c.cycles >= 3, "{c:?}");
    // The friction law at 5 bar: the catalogue's force, and a slower piston.
    let settings = map.effect_settings(friction.name(), &[], 5.0).unwrap();
    let f = hammer_fmu::import::map::law_force_n(friction, friction.default_params(), 5.0).unwrap();
    assert_eq!(settings, vec![("friction_n".to_string(), f)]);
    let rubbed = run(5.0, &settings);
    let (v0, v1) = (
        peak(at5.velocity_mps.as_ref().unwrap()),
        peak(rubbed.velocity_mps.as_ref().unwrap()),
    );
    assert!(v1 < v0, "friction {f} N slows the piston: {v1} vs {v0} m/s");

    // The same friction from outside: the catalogue's law (smoothed at
    // its smoothing speed) on the piston-force input, held over each
    // 100 µs step. Its impact energy against the FMU's own friction: the
    // energy error of driving friction from outside, within the 1 % the
    // diagnosis asks of its held-out energy, and far below what the
    // friction itself takes off.
    let mut outside = hammer_sim::Effects::default();
    friction.set(&mut outside, friction.default_params()).unwrap();
    let driven = model.run_with_friction(5e5, &[], &outside, 0.3).unwrap();
    let energy = |s: &Signals| {
        let v = s.velocity_mps.as_ref().unwrap();
        let hits = s.impacts.as_ref().unwrap();
        let at: Vec<usize> = (1..hits.len()).filter(|&i| hits[i] > hits[i - 1]).collect();
        let peaks: Vec<f64> = at[at.len() / 2..]
            .windows(2)
            .map(|w| v[w[0]..w[1]].iter().fold(0.0f64, |m, x| m.max(*x)))
            .collect();
        peaks.iter().map(|p| 0.5 * 0.2 * p * p).sum::<f64>() / peaks.len() as f64
    };
    let (e_free, e_inside, e_outside) = (energy(&at5), energy(&rubbed), energy(&driven));
    let taken = 1.0 - e_inside / e_free;
    let error = (e_outside / e_inside - 1.0).abs();
    eprintln!(
        "impact energy at 5 bar: no friction {e_free:.4} J, FMU's friction {e_inside:.4} J, from outside {e_outside:.4} J: \
         friction takes {:.1} %, driving it from outside errs by {:.3} %",
        100.0 * taken,
        100.0 * error
    );
    assert!(taken > 0.05, "the friction is seen: {taken}");
    assert!(error < 0.01, "energy error from outside {error}");
    // Without an input in the map, friction from outside is refused.
    let text = map_text.replace("[outside]\npiston_force = { input = \"f_ext_n\", unit = \"N\" }\n", "");
    assert_ne!(text, map_text);
    let no_input = FmuModel::open(&fmu, Some((ModelMap::parse(&text).unwrap(), text)), options(1, 60.0)).unwrap();
    let refused = no_input.run_with_friction(5e5, &[], &outside, 0.3).unwrap_err();
    assert_eq!(refused.kind, FailKind::Map, "{refused}");
}

/// Two measured traces of the built-in hammer with friction, at 4 and 7 bar.
fn friction_traces(dir: &Path) -> Vec<String> {
    [4, 7]
        .iter()
        .map(|bar| {
            let out = dir.join(format!("m{bar}.csv"));
            let (code, _, err) = hammer(&[
                "simulate",
                "--supply-bar",
                &bar.to_string(),
                "--duration",
                "0.6",
                "--effect",
                "coulomb_friction",
                "--seed",
                &bar.to_string(),
                "--out",
                out.to_str().unwrap(),
            ]);
            assert_eq!(code, 0, "{err}");
            out.to_string_lossy().into_owned()
        })
        .collect()
}

/// Every number of `a` against `b`'s, relative to the larger; the keys
/// that count work or time (`simulations`, `elapsed_s`) and the model's
/// own identity are left out. Non-numbers must be equal.
fn largest_difference(a: &serde_json::Value, b: &serde_json::Value, path: &str, worst: &mut (f64, String)) {
    use serde_json::Value;
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            for (k, v) in x {
                if ["simulations", "elapsed_s", "model", "tool"].contains(&k.as_str()) {
                    continue;
                }
                let w = y.get(k).unwrap_or_else(|| panic!("{path}/{k} missing"));
                largest_difference(v, w, &format!("{path}/{k}"), worst);
            }
        }
        (Value::Array(x), Value::Array(y)) => {
            assert_eq!(x.len(), y.len(), "{path}");
            for (i, (v, w)) in x.iter().zip(y).enumerate() {
                largest_difference(v, w, &format!("{path}[{i}]"), worst);
            }
        }
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
            let d = (x - y).abs() / x.abs().max(y.abs()).max(f64::MIN_POSITIVE);
            if d > worst.0 {
                *worst = (d, path.to_string());
            }
        }
        _ => assert_eq!(a, b, "{path}"),
    }
}

/// The built-in model through its own FMU is the built-in path:
/// `hammer diagnose --model hammer.fmu` names what the built-in model
/// names, with every number of report.json within 1e-6 relative (the
/// import runs the same solver, so in fact bit for bit), and the report
/// carries the FMU's identity: name, GUID, FMI version, tool, map hash.
/// The FMU's diagnosis runs on one thread (`--threads 1`: one instance,
/// as a single runtime-licence seat allows), the built-in one on the
/// machine's cores: the verdict does not depend on it.
#[test]
fn diagnose_through_the_projects_fmu_is_the_built_in_path() {
    let dir = tmp_dir("diagnose-own");
    let fmu = dir.join("hammer.fmu");
    let (code, _, err) = hammer(&["fmu", "--out", fmu.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let traces = friction_traces(&dir);
    let diagnose = |out: &str, model: Option<&Path>| -> serde_json::Value {
        let out = dir.join(out);
        let mut args = vec!["diagnose", "--measured", &traces[0], "--measured", &traces[1]];
        let fmu_arg;
        if let Some(m) = model {
            fmu_arg = m.to_string_lossy().into_owned();
            args.extend(["--model", &fmu_arg, "--threads", "1"]);
        }
        let out_arg = out.to_string_lossy().into_owned();
        args.extend(["--out", &out_arg]);
        let (code, stdout, err) = hammer(&args);
        assert_eq!(code, 0, "{stdout}{err}");
        if model.is_some() {
            assert!(stdout.contains("simulations on 1 thread,"), "{stdout}");
        }
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
    };
    let builtin = diagnose("builtin", None);
    let mut through = diagnose("fmu", Some(&fmu));
    assert_eq!(through["options"]["threads"], 1, "the report says what ran");
    through["options"]["threads"] = builtin["options"]["threads"].clone();
    assert_eq!(through["verdict"]["effects"], builtin["verdict"]["effects"]);
    assert!(
        builtin["verdict"]["effects"].to_string().contains("coulomb_friction"),
        "{}",
        builtin["verdict"]
    );
    let mut worst = (0.0, String::new());
    largest_difference(&builtin, &through, "", &mut worst);
    eprintln!("largest relative difference: {:e} at {}", worst.0, worst.1);
    assert!(worst.0 <= 1e-6, "{worst:?}");
    assert!(builtin.get("model").is_none(), "the built-in path names no model");
    let id = &through["model"];
    assert_eq!(id["name"], "hammer");
    assert_eq!(id["fmi_version"], "2.0");
    assert!(id["guid"].as_str().is_some_and(|g| g.starts_with('{')), "{id}");
    let map_text = std::fs::read_to_string(hammer_fmu::map_path(&fmu)).unwrap();
    assert_eq!(
        id["map_hash"].as_str(),
        Some(hammer_fmu::import::map::map_hash(&map_text).as_str())
    );
}

/// A restricted diagnosis with an FMU by another tool, end to end: the
/// pythonfmu model (tests/fmu/pyhammer.py) is given the paper's piston
/// (mass, areas) through the map's fixed values; its friction law is
/// the catalogue's Coulomb friction, its time constant the one nuisance
/// parameter. "Measured": the same FMU with friction on, at 5 bar (fitted)
/// and 6 bar (held out). The diagnosis names the friction, the force
/// balance sizes it within 2 % of the FMU's own force at each point (its
/// outputs are step means, so the balance holds to the integration's
/// error), the held-out energy error shrinks, the effects the map cannot
/// carry read "not modelled", and the report names the FMU and its tool.
#[test]
fn a_pythonfmu_model_is_diagnosed_end_to_end() {
    use hammer_host::diagnose::engine::{diagnose_with, MeasuredInput, Options};
    use hammer_host::diagnose::model::{FmuPlant, Plant};
    if !pythonfmu() {
        return;
    }
    let dir = tmp_dir("pythonfmu-diagnose");
    let (fmu, friction) = pyhammer(&dir);
    let cfg = hammer_sim::SimConfig::default();
    let g = cfg.hammer.geometry();
    let map_text = format!(
        r#"step_s = 1e-4
[signals]
p_rear = {{ output = "p_rear", unit = "Pa", pressure = "gauge" }}
p_front = {{ output = "p_front", unit = "Pa", pressure = "gauge" }}
accel = {{ output = "accel", unit = "m/s2" }}
position = {{ output = "x", unit = "m" }}
velocity = {{ output = "v", unit = "m/s" }}
impact_counter = {{ output = "impacts" }}
[supply]
parameter = "supply_bar"
unit = "bar"
pressure = "gauge"
[[nuisance]]
parameter = "tau_s"
nominal = 2e-3
relative_uncertainty = 0.2
[fixed]
mass_kg = {}
area_m2 = {}
area_front_m2 = {}
stroke_m = {}
[effects.{}]
law = {{ parameter = "friction_n", unit = "N", off = 0.0 }}
"#,
        g.piston_mass_kg,
        g.rear_area_m2(),
        g.front_area_m2(),
        0.8 * cfg.hammer.impact_position_m,
        friction.name()
    );
    let map = ModelMap::parse(&map_text).unwrap();
    let model = FmuModel::open(&fmu, Some((map.clone(), map_text)), options(2, 60.0)).unwrap_or_else(|e| panic!("{e}"));
    // The measured hammer: the FMU itself with the catalogue's friction on.
    let law = |bar: f64| hammer_fmu::import::map::law_force_n(friction, friction.default_params(), bar).unwrap();
    let inputs: Vec<MeasuredInput> = [(5.0, true), (6.0, false)]
        .iter()
        .map(|&(bar, fit)| {
            let settings = map.effect_settings(friction.name(), &[], bar).unwrap();
            let s = model.run(bar * 1e5, &settings, 0.8).unwrap_or_else(|e| panic!("{e}"));
            let n = s.p_rear_pa.len();
            let mut trace = hammer_trace::trace::Trace::default();
            trace.dt_s = s.dt_s;
            trace.t_s = (0..n).map(|i| i as f64 * s.dt_s).collect();
            trace.p_rear_pa = s.p_rear_pa;
            trace.p_front_pa = s.p_front_pa;
            trace.accel_mps2 = s.accel_mps2;
            MeasuredInput {
                label: format!("pyhammer with friction at {bar} bar"),
                supply_bar: bar,
                trace,
                fit,
            }
        })
        .collect();
    let plant = FmuPlant::new(model).unwrap();
    assert_eq!(plant.nuisance()[0].name, "tau_s");
    let opts = Options {
        figures: false,
        threads: 2,
        ..Options::default()
    };
    let out = diagnose_with(&inputs, &[], &cfg, std::sync::Arc::new(plant), &opts, &|_, _, _| {})
        .unwrap_or_else(|e| panic!("{e}"));
    let r = &out.report;
    let json = serde_json::to_value(r).unwrap();
    eprintln!(
        "verdict {}\nforce balance {}\nshrink {}",
        json["verdict"], json["force_balance"], json["shrink"]
    );
    assert_eq!(
        r.verdict.effects,
        vec![friction.name().to_string()],
        "{}",
        json["verdict"]
    );
    for p in &r.force_balance {
        let q = p.quantities.iter().find(|q| q.key.ends_with(".friction_n")).unwrap();
        let truth = law(p.supply_bar);
        assert!(
            (q.value / truth - 1.0).abs() < 0.02,
            "{} bar: the force balance reads {} N, the FMU's friction is {truth} N",
            p.supply_bar,
            q.value
        );
    }
    let s = &r.shrink;
    assert!(
        s.impact_energy_error_after < 0.5 * s.impact_energy_error_before,
        "held out: {} % → {} %",
        s.impact_energy_error_before,
        s.impact_energy_error_after
    );
    let carried: Vec<&str> = map
        .coverage()
        .iter()
        .filter(|(_, c)| c.label() != "not modelled")
        .map(|(n, _)| *n)
        .collect();
    for f in &r.detection_floors {
        assert_eq!(f.not_modelled, !carried.contains(&f.effect.as_str()), "{f:?}");
    }
    assert!(
        r.effects.iter().all(|e| carried.iter().any(|c| e.name.contains(c))),
        "only what the map carries is ranked"
    );
    assert_eq!(json["model"]["generation_tool"], "PythonFMU 0.7.0");
}

/// The second family's structure is a parameter of its FMU: each law's
/// other form is a Boolean `structure.<variant>`, named as
/// `hammer_variants` names it. Through the import, each single variant
/// set so impacts when the family run with that structure does (within the
/// communication step), and differently from the base structure, which is
/// what lets a benchmark give each case's drawn structure to one FMU.
#[test]
fn the_variants_fmus_structure_is_set_per_run() {
    let dir = tmp_dir("variants-structure");
    let fmu = dir.join("variants.fmu");
    let (code, _, err) = hammer(&["fmu", "--family", "variants", "--out", fmu.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let model = open(&fmu, &hammer_fmu::map_path(&fmu), 2);
    let cfg = hammer_fmu::VariantsConfig::default();
    let duration_s = 0.5;
    let impacts_of = |s: &Signals| -> Vec<f64> {
        let count = s.impacts.as_ref().unwrap();
        (1..count.len())
            .filter(|&i| count[i] > count[i - 1])
            .map(|i| i as f64 * s.dt_s)
            .collect()
    };
    let base = impacts_of(&model.run(5e5, &[], duration_s).unwrap());
    let family_base: Vec<f64> = hammer_variants::generate(
        &cfg.params,
        hammer_variants::Structure::BASE,
        &hammer_sim::Effects::default(),
        5.0,
        duration_s,
        cfg.seed,
    )
    .truth
    .cycles
    .iter()
    .map(|c| c.t_impact_s)
    .collect();
    // The base run's first impact opens no cycle of the family's truth.
    let base = base[1..].to_vec();
    let singles = hammer_variants::Structure::singles();
    for single in singles {
        let name = single.variants()[0];
        let settings: Vec<(String, f64)> = singles
            .iter()
            .map(|s| {
                (
                    format!("structure.{}", s.variants()[0]),
                    f64::from(u8::from(s == &single)),
                )
            })
            .collect();
        let run = model
            .run(5e5, &settings, duration_s)
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let got = impacts_of(&run)[1..].to_vec();
        let own = hammer_variants::generate(
            &cfg.params,
            single,
            &hammer_sim::Effects::default(),
            5.0,
            duration_s,
            cfg.seed,
        );
        let want: Vec<f64> = own.truth.cycles.iter().map(|c| c.t_impact_s).collect();
        assert!(want.len() >= 5, "{name}: {} impacts", want.len());
        // The counter rises at a communication point beside the impact.
        let matched = want
            .iter()
            .filter(|t| got.iter().any(|g| (*g - **t).abs() <= run.dt_s))
            .count();
        assert_eq!(
            matched,
            want.len(),
            "{name}: the FMU's impacts {got:?}, the family's {want:?}"
        );
        // Moved from the base structure's impacts as far as the family's
        // own run moved (a sensor front end does not move the piston).
        let largest = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        let (moved, family_moved) = (largest(&got, &base), largest(&want, &family_base));
        eprintln!(
            "{name}: {} impacts as the family's own run; {moved:.2e} s from the base structure's ({family_moved:.2e} s in the family)",
            want.len()
        );
        assert_eq!(moved > 2.0 * run.dt_s, family_moved > 2.0 * run.dt_s, "{name}");
    }
    let bad = model
        .run(5e5, &[("structure.no_such_law".into(), 1.0)], duration_s)
        .unwrap_err();
    assert_eq!(bad.kind, FailKind::Map, "{bad}");
}
