//! The output of `hammer diagnose`: `report.json` (the [`Report`](super::report::Report) as is),
//! `report.md` (the same for people) and one figure per operating point,
//! `gap-<bar>bar.png`: the measured mean cycle against the nominal and the
//! fitted model, the gap between measurement and nominal model shaded.
//!
//! Units in the Markdown: pressures in bar, acceleration in m/s², velocity in
//! m/s, times in ms, energies in J, frequencies in Hz.
//!
//! [`markdown`](mod@markdown) writes the text (report.md and the terminal summary),
//! [`figures`] the PNGs on the shared chart renderer; this module writes the files.

pub mod figures;
pub mod markdown;

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use super::engine::Outcome;
use figures::gap_png;
pub use figures::{figure_name, FIGURE_SIZE};
pub use markdown::{markdown, summary, verdict_name};

/// Writes DIR/report.json, DIR/report.md and DIR/gap-<bar>bar.png per operating point; returns the paths written.
///
/// Order: report.json, the figures, report.md (written last: it links the figures).
pub fn write_all(dir: &Path, outcome: &Outcome) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut written = Vec::new();

    let json_path = dir.join("report.json");
    let json = serde_json::to_string_pretty(&outcome.report).context("serializing the diagnosis report")?;
    std::fs::write(&json_path, json + "\n").with_context(|| format!("writing {}", json_path.display()))?;
    written.push(json_path);

    let fitted_label = verdict_name(&outcome.report);
    let mut figures = Vec::new();
    for pw in &outcome.waves {
        let name = figure_name(pw.supply_bar);
        let path = dir.join(&name);
        gap_png(&path, pw, fitted_label.as_deref()).with_context(|| format!("drawing {}", path.display()))?;
        figures.push(name);
        written.push(path);
    }

    let md_path = dir.join("report.md");
    std::fs::write(&md_path, markdown(&outcome.report, &figures))
        .with_context(|| format!("writing {}", md_path.display()))?;
    written.push(md_path);
    Ok(written)
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::markdown::{params_inline, with_unit};
    use super::{figure_name, markdown, summary, write_all, FIGURE_SIZE};
    use crate::diagnose::engine::{
        EffectResult, FittedParam, InputInfo, Options, Outcome, PointShrink, PointWaves, Report, Shrink, Verdict,
        WhereCell,
    };
    use crate::diagnose::gap::{CycleSignals, SIGNALS};
    use crate::diagnose::model::Candidate;
    use crate::diagnose::report::{DetectionFloor, ModelFreeStat};
    use crate::diagnose::stages::Stage;

    fn effect(name: &str, score: f64, explained: f64, value: f64) -> EffectResult {
        EffectResult {
            name: name.into(),
            params: serde_json::json!({ "force_n": value }),
            fitted: vec![FittedParam {
                key: format!("{name}.force_n"),
                value,
                sd: 0.05,
            }],
            chi2: 12.0,
            score,
            explained_fraction: explained,
            evidence: vec![format!("force balance: evidence for {name}")],
            model_free_z: Some(9.5),
            contradicted_by: None,
            simulations: 10,
            waveform_fit: Vec::new(),
            candidate: Candidate::default(),
        }
    }

    fn report() -> Report {
        let rms = |x: f64| -> BTreeMap<String, f64> { SIGNALS.iter().map(|s| (s.to_string(), x)).collect() };
        Report {
            model: None,
            tool: "hammer diagnose test".into(),
            inputs: vec![InputInfo {
                label: "run-4bar.trace".into(),
                supply_bar: 4.0,
                cycles: 30,
                startup_cycles: 3,
                fit_cycles: 14,
                held_out_cycles: 13,
            }],
            references: Vec::new(),
            dead_volumes: Vec::new(),
            fit_points: vec![4.0],
            where_: vec![
                WhereCell {
                    supply_bar: 4.0,
                    signal: "p_rear_pa".into(),
                    stage: Stage::StrokeClosed,
                    bias: -5_000.0,
                    rms: 12_000.0,
                    relative_rms: 0.083,
                    timing_shift_s: 2.0e-4,
                },
                WhereCell {
                    supply_bar: 4.0,
                    signal: "accel_mps2".into(),
                    stage: Stage::BackhaulFed,
                    bias: 3.0,
                    rms: 20.0,
                    relative_rms: f64::NAN,
                    timing_shift_s: f64::INFINITY,
                },
            ],
            effects: vec![
                effect("coulomb_friction", 1234.5, 0.87, 2.3),
                effect("viscous_friction", 100.0, 0.2, 0.4),
            ],
            pairs: vec![effect("coulomb_friction+leakage", 1200.0, 0.88, 1.0)],
            verdict: Verdict {
                effects: vec!["coulomb_friction".into()],
                params: serde_json::json!({ "force_n": 2.3 }),
                score: 1234.5,
                reason: "explains 87 % of the nominal chi2".into(),
                alternatives: vec![],
                confirmation: None,
                parted: None,
            },
            recalibration: vec![],
            held_nuisance: vec![],
            oracle: None,
            remainder: vec![],
            model_form: vec![],
            model_free: vec![],
            force_balance: vec![],
            chambers: vec![],
            detection_floors: vec![
                DetectionFloor {
                    effect: "leakage".into(),
                    parameter: "gap_m".into(),
                    value: Some(2.4e-5),
                    stronger_above: true,
                    chi2_needed: 41.0,
                    model_free: false,
                    not_modelled: false,
                    statement: "leakage with gap_m ≥ 2.400e-5 would have been named".into(),
                },
                DetectionFloor {
                    effect: "valve_delay".into(),
                    parameter: "tau_s".into(),
                    value: None,
                    stronger_above: true,
                    chi2_needed: 41.0,
                    model_free: false,
                    not_modelled: false,
                    statement: "valve_delay could not be named".into(),
                },
            ],
            shrink: Shrink {
                impact_energy_error_before: 12.34,
                impact_energy_error_after: 1.23,
                frequency_error_before: 5.0,
                frequency_error_after: 0.4,
                impact_energy_error_recalibrated_only: 7.5,
                impact_energy_error_effects_only: 3.4,
                held_out_points: vec![],
                judged_on: "the later half of the cycles".into(),
                refitted: vec![],
                points: vec![PointShrink {
                    supply_bar: 4.0,
                    held_out_point: false,
                    cycles: 13,
                    impact_energy_measured_j: 1.0,
                    impact_energy_nominal_j: 1.12,
                    impact_energy_fitted_j: 1.01,
                    impact_energy_recalibrated_j: 0.95,
                    impact_energy_effects_only_j: 1.03,
                    frequency_measured_hz: 30.0,
                    frequency_nominal_hz: 31.5,
                    frequency_fitted_hz: 30.1,
                    rms_before: rms(1000.0),
                    rms_after: rms(f64::NAN),
                }],
            },
            chi2_nominal: 1500.0,
            features_compared: 200,
            fit_cycles: 14,
            options: Options::default(),
            simulations: 321,
            elapsed_s: 4.25,
        }
    }

    /// A synthetic cycle: pressures rising, an impact spike, velocity NaN in the first ms.
    fn cycle(n: usize, dt: f64, gain: f64) -> CycleSignals {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let w = (1e-3 / dt).round() as usize;
        CycleSignals {
            dt_s: dt,
            p_rear_pa: t.iter().map(|t| gain * 3e5 * (1.0 - (-t * 200.0).exp())).collect(),
            p_front_pa: t.iter().map(|t| gain * 2e5 * (t * 150.0).sin().abs()).collect(),
            accel_mps2: t
                .iter()
                .enumerate()
                .map(|(k, t)| {
                    if k < w {
                        -2.0e4
                    } else {
                        gain * 300.0 * (t * 200.0).cos()
                    }
                })
                .collect(),
            velocity_mps: t
                .iter()
                .enumerate()
                .map(|(k, t)| {
                    if k < w {
                        f64::NAN
                    } else {
                        gain * 3.0 * (t * 200.0).sin()
                    }
                })
                .collect(),
        }
    }

    fn waves(bar: f64, fitted: bool) -> PointWaves {
        let (n, dt) = (3000, 1e-5);
        let t_s: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let stages = t_s
            .iter()
            .map(|&t| match t {
                t if t < 1e-3 => Stage::Impact,
                t if t < 8e-3 => Stage::BackhaulFed,
                t if t < 14e-3 => Stage::BackhaulCushion,
                t if t < 17e-3 => Stage::BackhaulVented,
                t if t < 22e-3 => Stage::StrokeIntake,
                t if t < 27e-3 => Stage::StrokeClosed,
                _ => Stage::StrokeVenting,
            })
            .collect();
        let mut measured = cycle(n, dt, 1.1);
        measured.p_rear_pa[100] = f64::NAN;
        measured.accel_mps2[2000] = f64::INFINITY;
        PointWaves {
            supply_bar: bar,
            t_s,
            stages,
            measured,
            nominal: cycle(n, dt, 1.0),
            // A different length: the fitted cycle has its own period.
            fitted: fitted.then(|| cycle(3100, dt, 1.08)),
        }
    }

    #[test]
    fn numbers_read_well() {
        assert_eq!(figure_name(5.5), "gap-5.5bar.png");
        assert_eq!(figure_name(f64::NAN), "gap-unknownbar.png");
        assert_eq!(with_unit("p_rear_pa", 12_000.0), "0.120 bar");
        assert_eq!(with_unit("accel_mps2", f64::NAN), "–");
    }

    #[test]
    fn markdown_names_verdict_where_and_shrink() {
        let md = markdown(&report(), &["gap-4bar.png".to_string()]);
        assert!(md.contains("**coulomb_friction** (score 1234 ΔBIC)"), "{md}");
        assert!(md.contains("explains 87 % of the nominal chi2"));
        assert!(md.contains("\"force_n\": 2.3"));
        assert!(
            md.contains("- leakage with gap_m ≥ 2.400e-5 would have been named\n"),
            "{md}"
        );
        // The top where cell, in the sentence and the table.
        assert!(
            md.contains("rear pressure in stroke_closed at 4 bar: RMS 0.120 bar (8.3 %"),
            "{md}"
        );
        assert!(md.contains("| 1 | 4 | rear pressure | stroke_closed | -0.0500 bar | 0.120 bar | 8.3 | +0.20 |"));
        // Effects, evidence, pairs.
        assert!(
            md.contains("| 1 | coulomb_friction | 1234 | 87.0 | coulomb_friction.force_n = 2.30 ± 0.0500 |"),
            "{md}"
        );
        assert!(md.contains("- force balance: evidence for coulomb_friction"));
        assert!(!md.contains("evidence for viscous_friction"));
        assert!(md.contains("### Pairs of effects"));
        // Shrink.
        assert!(md.contains("impact energy error: 12.3 % → 1.2 %"));
        assert!(md.contains("frequency error: 5.0 % → 0.40 %"));
        assert!(
            md.contains("- the named effects in the nominal model, nothing recalibrated: impact energy error 3.4 %")
        );
        assert!(
            md.contains("| 4 | no | 13 | 1.00 / 1.12 / 1.01 | 30.0 / 31.5 / 30.1 | 0.0100 → – |"),
            "{md}"
        );
        assert!(md.contains("![gap 4bar](gap-4bar.png)"));
        assert!(md.contains("321 simulations, 4.2 s") || md.contains("321 simulations, 4.3 s"));
        // Non-finite numbers are shown, not panicked on.
        assert!(md.contains("| – | – |"));
    }

    /// A refitted model that predicts the held-out data worse than nominal
    /// (the structural benchmark's case 0 with a three-step recalibration:
    /// friction named right, energy 17 % → 22 %) is said so in both outputs;
    /// one that predicts better is not.
    /// A chamber characteristic no fit point read is said so, not shown as
    /// a measurement equal to the model's with z 0; a read one keeps its
    /// numbers (the layout against the model alone).
    #[test]
    fn an_unread_chamber_characteristic_is_not_shown_as_measured() {
        let stat = |feature: &str, read: bool| ModelFreeStat {
            feature: feature.into(),
            measured: if read { 1.4321 } else { 1.4 },
            nominal: 1.4,
            se: 0.003,
            z: if read { 10.7 } else { 0.0 },
            recalibrated: Some(1.41),
            reference: None,
            read,
        };
        let mut r = report();
        r.chambers = vec![stat("front_closed_exponent", false), stat("rear_closed_exponent", true)];
        let md = markdown(&r, &[]);
        let row = |name: &str| {
            md.lines()
                .find(|l| l.starts_with(&format!("| {name} |")))
                .unwrap()
                .to_string()
        };
        let unread = row("front_closed_exponent");
        assert_eq!(unread.matches("not read").count(), 3, "{unread}");
        let read = row("rear_closed_exponent");
        assert!(
            !read.contains("not read") && read.contains("0.0321") && read.contains("10.7"),
            "{read}"
        );
        // The JSON of an older report, without the flag, reads as read.
        let json = serde_json::to_value(&r.chambers[1]).unwrap();
        let mut old = json.as_object().unwrap().clone();
        old.remove("read");
        let back: ModelFreeStat = serde_json::from_value(serde_json::Value::Object(old)).unwrap();
        assert!(back.read);
    }

    #[test]
    fn a_refit_worse_than_nominal_on_held_out_data_is_said() {
        let good = report();
        assert!(good.shrink.caution().is_none());
        assert!(!markdown(&good, &[]).contains("Caution"));
        assert!(!summary(&good).contains("caution"));
        let mut r = report();
        r.shrink.impact_energy_error_before = 17.1;
        r.shrink.impact_energy_error_after = 21.9;
        let md = markdown(&r, &[]);
        assert!(
            md.contains("**Caution:** the refitted model predicts the held-out data worse than the nominal model (impact energy error 17.1 % → 21.9 %)"),
            "{md}"
        );
        assert!(summary(&r).contains("caution: the refitted model"));
        // Within the energy's own noise it is not a finding.
        r.shrink.impact_energy_error_after = 17.4;
        assert!(r.shrink.caution().is_none());
        r.shrink.frequency_error_after = 6.0;
        assert!(r.shrink.caution().unwrap().contains("frequency error 5.0 % → 6.0 %"));
    }

    #[test]
    fn markdown_and_summary_of_an_empty_report() {
        let mut r = report();
        r.where_.clear();
        r.effects.clear();
        r.pairs.clear();
        r.shrink.points.clear();
        r.verdict = Verdict {
            effects: vec!["none".into()],
            params: serde_json::json!({}),
            score: f64::NAN,
            reason: String::new(),
            alternatives: vec![],
            confirmation: None,
            parted: None,
        };
        let md = markdown(&r, &[]);
        assert!(md.contains("**none**"));
        assert!(md.contains("No gap cells"));
        let s = summary(&r);
        assert!(s.starts_with("verdict: none"));
    }

    #[test]
    fn summary_fits_one_screen() {
        let s = summary(&report());
        assert!(s.starts_with("verdict: coulomb_friction"));
        assert!(s.contains("1. rear pressure in stroke_closed at 4 bar"));
        assert!(
            s.contains("impact energy error 12.3 % nominal, 7.5 % recalibrated, 1.2 % with the effects (3.4 % with them in the nominal model)"),
            "{s}"
        );
        assert!(s.contains("  params: force_n=2.30\n"), "{s}");
        assert!(s.contains("recalibrated: no nominal parameter beyond its prior"), "{s}");
        assert!(s.contains("unexplained: nothing above 10 %"), "{s}");
        assert!(
            s.contains("could hide unnamed: leakage gap_m < 2.40e-5, valve_delay at any tau_s"),
            "{s}"
        );
        // A named effect is not hiding.
        let mut named = report();
        named.verdict.effects = vec!["leakage".into()];
        let s = summary(&named);
        assert!(s.contains("could hide unnamed: valve_delay at any tau_s\n"), "{s}");
        assert_eq!(
            params_inline(&serde_json::json!({"a": {"x": 1.5, "on": true}, "b": {"y": 0.012345}})),
            "a.on=true, a.x=1.50, b.y=0.0123"
        );
        assert!(s.lines().count() <= 24, "{s}");
    }

    #[test]
    fn write_all_writes_json_markdown_and_figures() {
        let dir = std::env::temp_dir().join(format!("hammer-diagnose-output-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let outcome = Outcome {
            report: report(),
            waves: vec![waves(4.0, true), waves(5.5, false)],
        };
        let written = write_all(&dir, &outcome).unwrap();
        assert_eq!(written.len(), 4, "{written:?}");
        for name in ["gap-4bar.png", "gap-5.5bar.png"] {
            let png = dir.join(name);
            assert!(written.contains(&png));
            let bytes = std::fs::read(&png).unwrap();
            assert!(bytes.len() > 1000);
            assert_eq!(&bytes[1..4], b"PNG");
            // Width and height from the IHDR chunk.
            let w = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
            let h = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
            assert_eq!((w, h), FIGURE_SIZE);
        }
        let json: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
        for key in ["where", "effects", "verdict", "shrink"] {
            assert!(json.get(key).is_some(), "{key} missing");
        }
        assert_eq!(json["verdict"]["effects"][0], "coulomb_friction");
        assert!(json["effects"][0].get("candidate").is_none());
        let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
        assert!(md.contains("![gap 5.5bar](gap-5.5bar.png)"));
        if std::env::var_os("KEEP_DIAGNOSE_OUTPUT").is_none() {
            let _ = std::fs::remove_dir_all(&dir);
        }
    }

    #[test]
    fn degenerate_waves_do_not_panic() {
        let dir = std::env::temp_dir().join(format!("hammer-diagnose-degenerate-{}", std::process::id()));
        let empty = CycleSignals {
            dt_s: 1e-5,
            p_rear_pa: vec![],
            p_front_pa: vec![],
            accel_mps2: vec![],
            velocity_mps: vec![],
        };
        let mut nan = cycle(50, 1e-5, 1.0);
        nan.p_rear_pa.iter_mut().for_each(|x| *x = f64::NAN);
        let mut r = report();
        r.where_.clear();
        let outcome = Outcome {
            report: r,
            waves: vec![
                PointWaves {
                    supply_bar: 3.0,
                    t_s: vec![],
                    stages: vec![],
                    measured: empty.clone(),
                    nominal: empty.clone(),
                    fitted: Some(empty),
                },
                PointWaves {
                    supply_bar: f64::NAN,
                    t_s: (0..50).map(|k| k as f64 * 1e-5).collect(),
                    stages: vec![Stage::Impact; 10],
                    measured: nan.clone(),
                    nominal: nan,
                    fitted: None,
                },
            ],
        };
        let written = write_all(&dir, &outcome).unwrap();
        assert!(written.iter().all(|p| p.exists()));
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// End to end on simulated data: `KEEP_DIAGNOSE_OUTPUT=1 cargo test --release -p hammer-host --lib
    /// diagnose::output -- --ignored` and look at the figures in the temporary directory.
    #[test]
    #[ignore = "runs the whole diagnosis (seconds to minutes)"]
    fn end_to_end_on_simulated_friction() {
        use crate::diagnose::engine::{diagnose, MeasuredInput};
        use hammer_sim::simulate::simulate;
        use hammer_sim::SimConfig;
        let mut inputs = Vec::new();
        for bar in [4.0, 5.5, 7.0] {
            let mut c = SimConfig::nominal(bar);
            c.solver.duration_s = 1.0;
            c.seed = 5;
            c.effects.apply_spec("coulomb_friction").unwrap();
            let sim = simulate(&c).unwrap();
            inputs.push(MeasuredInput {
                label: format!("friction at {bar} bar"),
                supply_bar: bar,
                trace: sim.trace(),
                fit: bar != 5.5,
            });
        }
        let out = diagnose(&inputs, &SimConfig::default(), &Options::default(), &|_, _, _| {}).unwrap();
        let dir = std::env::temp_dir().join(format!("hammer-diagnose-e2e-{}", std::process::id()));
        let written = write_all(&dir, &out).unwrap();
        println!("{}", summary(&out.report));
        println!("{written:?}");
        assert_eq!(written.len(), 2 + out.waves.len());
        if std::env::var_os("KEEP_DIAGNOSE_OUTPUT").is_none() {
            let _ = std::fs::remove_dir_all(&dir);
        }
    }
}
