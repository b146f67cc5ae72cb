//! `hammer bench-sheet`: the paper's performance sheet from traces at
//! several supply pressures. Per operating point the estimator's valid
//! cycles are averaged (friction per phase and mean, impact energy with and
//! without friction, frequency, blows per minute, impact power, stroke,
//! friction work share); the friction law F0 + k·p is fitted over the
//! points; the simulator gives the model's curves, nominal (no friction) and
//! with the fitted law; the energy friction costs is tabulated (the paper's
//! Table 3). Per point also an estimate of the air drawn per blow, from the
//! chamber states where each feed starts and its port closes (the
//! characteristics of `hammer_estimator::chambers`), and of the impact
//! efficiency it gives. Output: CSV, PNG and an HTML page
//! (`docs/bench-sheet.md`, with the formulas).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use clap::Args;

use hammer_estimator::chambers::P_ATM_PA;
use hammer_estimator::CycleReport;
use hammer_sim::characteristics::{characterise_cycles, Signals};
use hammer_sim::estimation::open_for_estimation;
use hammer_sim::gas::R_AIR;
use hammer_sim::params::{HammerParams, DURATION_S_RANGE, SUPPLY_BAR_RANGE};
use hammer_sim::{simulate_truth, SimConfig};

use crate::chart::render::figure_png;
use crate::chart::{Band, Chart, Series, BLUE, EFFECT, NOMINAL};
use crate::import::MapArgs;

#[derive(Args, Debug)]
pub struct BenchSheetArgs {
    /// Traces, one per operating point (any format `hammer estimate` reads).
    #[arg(required = true)]
    pub traces: Vec<PathBuf>,
    /// Gauge supply pressure of each trace, bar, in the order of the traces
    /// (default: each trace's sidecar, else the mapping's supply_pressure_bar).
    #[arg(long, value_delimiter = ',', value_parser = crate::cli::supply_bar)]
    pub supply_bar: Vec<f64>,
    #[command(flatten)]
    pub mapping: MapArgs,
    /// Directory for index.html, the PNG figures and the CSV tables.
    #[arg(long)]
    pub out: PathBuf,
    /// Simulated time per model point, s.
    #[arg(long, default_value_t = 0.6)]
    pub model_duration_s: f64,
}

/// One operating point: the means over its valid cycles.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    pub trace: String,
    pub supply_bar: f64,
    pub cycles: usize,
    pub cycles_used: usize,
    pub friction_n: f64,
    /// Mean of the cycles' expanded uncertainties: the systematic part does
    /// not average out over cycles, so this is what the mean is good to.
    pub friction_u_n: f64,
    pub friction_stroke_n: f64,
    pub friction_backhaul_n: f64,
    pub impact_energy_j: f64,
    pub impact_energy_u_j: f64,
    pub impact_energy_frictionless_j: f64,
    pub frequency_hz: f64,
    pub stroke_m: f64,
    pub friction_work_ratio: f64,
    /// Free air drawn per blow (at atmosphere and the supply's
    /// temperature), m³, over the cycles whose two feeds were read
    /// (`air_cycles`); an estimate (`docs/bench-sheet.md`).
    pub air_m3: f64,
    pub air_cycles: usize,
    /// The simulator's truth when the trace is simulated.
    pub truth: Option<Truth>,
    /// The hammer the trace's sidecar states (a simulated trace's), which
    /// its estimate was read with.
    pub hammer: Option<HammerParams>,
}

/// The simulator's means over the cycles the estimator reported valid.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Truth {
    pub friction_n: f64,
    pub impact_energy_j: f64,
    /// The air the source gave per cycle, as free air at the supply's temperature, m³.
    pub air_m3: f64,
}

impl Point {
    pub fn blows_per_min(&self) -> f64 {
        60.0 * self.frequency_hz
    }

    pub fn impact_power_w(&self) -> f64 {
        self.impact_energy_j * self.frequency_hz
    }

    /// The energy friction takes from each blow (the paper's Table 3).
    pub fn friction_energy_loss_j(&self) -> f64 {
        self.impact_energy_frictionless_j - self.impact_energy_j
    }

    /// Free air per minute, m³/min.
    pub fn air_per_min_m3(&self) -> f64 {
        self.air_m3 * self.blows_per_min()
    }

    /// Impact energy over the work the drawn air could do expanding
    /// isothermally from the supply to atmosphere: p_atm·V·ln(p_s,abs/p_atm).
    pub fn impact_efficiency(&self) -> f64 {
        let p_atm = P_ATM_PA as f64;
        let available = p_atm * self.air_m3 * ((self.supply_bar * 1e5 + p_atm) / p_atm).ln();
        self.impact_energy_j / available
    }
}

/// The mean of `f` over `cycles` in f64 (the values are the reports' f32).
fn mean(cycles: &[&CycleReport], f: impl Fn(&CycleReport) -> f32) -> f64 {
    cycles.iter().map(|r| f(r) as f64).sum::<f64>() / cycles.len() as f64
}

/// One trace's operating point.
pub fn point(path: &Path, file: &SimConfig, supply_bar: Option<f64>) -> Result<Point> {
    let input = open_for_estimation(path, file, supply_bar).map_err(|e| anyhow!("{e}"))?;
    let supply_bar = input.supply_bar.ok_or_else(|| {
        anyhow!(
            "{}: no supply pressure: give --supply-bar (one per trace, in order), a sidecar, or [import] supply_pressure_bar",
            path.display()
        )
    })?;
    let reports = input.run()?;
    let cycles: Vec<&CycleReport> = reports.iter().filter(|r| r.is_cycle()).collect();
    let valid: Vec<&CycleReport> = cycles.iter().copied().filter(|r| r.is_valid()).collect();
    if valid.is_empty() {
        bail!(
            "{}: no valid cycle among {} (hammer estimate shows why)",
            path.display(),
            cycles.len()
        );
    }
    // The air per blow, from the chambers' states (every report: a cycle's
    // characteristics need the valid ones either side of it).
    let described = input
        .sidecar
        .as_ref()
        .and_then(|s| s.simulation.as_ref())
        .map_or(file, |s| &s.config);
    let hammer = &described.hammer;
    let signals = Signals {
        dt_s: input.trace.dt_s,
        p_rear_pa: &input.trace.p_rear_pa,
        p_front_pa: &input.trace.p_front_pa,
        accel_mps2: &input.trace.accel_mps2,
        x_m: None,
        pressure_lag_s: described.sensors.front.group_delay_s(input.trace.dt_s),
    };
    let air: Vec<f64> = characterise_cycles(&signals, &reports, &input.config, &hammer.chambers())
        .iter()
        .filter_map(|c| c.feeds.charge)
        .map(|c| c.free_air_m3() as f64)
        .collect();
    let truth = input.sidecar.as_ref().and_then(|s| s.simulation.as_ref()).map(|sim| {
        // The truth of the cycles estimated (matched by impact time).
        let matched: Vec<_> = valid
            .iter()
            .filter_map(|r| {
                let t = r.t_impact_us as f64 * 1e-6;
                sim.cycles
                    .iter()
                    .min_by(|a, b| (a.t_impact_s - t).abs().total_cmp(&(b.t_impact_s - t).abs()))
            })
            .collect();
        let n = matched.len().max(1) as f64;
        let t_supply = sim.config.supply.temperature_k;
        Truth {
            friction_n: matched.iter().map(|c| c.friction_cycle_n).sum::<f64>() / n,
            impact_energy_j: matched.iter().map(|c| c.impact_energy_j).sum::<f64>() / n,
            air_m3: matched.iter().map(|c| c.air_drawn_kg).sum::<f64>() / n * R_AIR * t_supply / P_ATM_PA as f64,
        }
    });
    Ok(Point {
        trace: path.display().to_string(),
        supply_bar,
        cycles: cycles.len(),
        cycles_used: valid.len(),
        friction_n: mean(&valid, |r| r.friction_n),
        friction_u_n: mean(&valid, |r| r.friction_uncertainty_n),
        friction_stroke_n: mean(&valid, |r| r.friction_stroke_n),
        friction_backhaul_n: mean(&valid, |r| r.friction_backhaul_n),
        impact_energy_j: mean(&valid, |r| r.impact_energy_j),
        impact_energy_u_j: mean(&valid, |r| r.impact_energy_uncertainty_j),
        impact_energy_frictionless_j: mean(&valid, |r| r.impact_energy_frictionless_j),
        frequency_hz: mean(&valid, |r| r.frequency_hz),
        stroke_m: mean(&valid, |r| r.stroke_m),
        friction_work_ratio: mean(&valid, |r| r.friction_work_ratio),
        air_m3: air.iter().sum::<f64>() / air.len() as f64,
        air_cycles: air.len(),
        truth,
        hammer: input
            .sidecar
            .as_ref()
            .and_then(|s| s.simulation.as_ref())
            .map(|s| s.config.hammer.clone()),
    })
}

/// The paper's bench ran 4 to 7 bar: the model's anchors (docs/model.md).
const PAPER_SUPPLY_BAR: (f64, f64) = (4.0, 7.0);

/// The one hammer a sheet is of. Traces whose sidecars state different
/// hammers are refused (one friction law over two hammers means nothing),
/// and so is a `--config` naming another hammer than the sidecars (the
/// points would be read with one and the model's curves drawn with the
/// other). Returns the sidecars' hammer, for the model's curves.
fn one_hammer(points: &[Point], config: Option<&Path>, configured: &HammerParams) -> Result<Option<HammerParams>> {
    let mut stated = points.iter().filter_map(|p| p.hammer.as_ref().map(|h| (p, h)));
    let Some((first, hammer)) = stated.next() else {
        return Ok(None);
    };
    for (p, h) in stated {
        let d = hammer.differences(h);
        if !d.is_empty() {
            bail!(
                "{} and {}: their sidecars state different hammers ({}): a sheet is of one hammer; make one per hammer",
                first.trace,
                p.trace,
                d.join(", ")
            );
        }
    }
    if let Some(config) = config {
        let d = hammer.differences(configured);
        if !d.is_empty() {
            bail!(
                "{}'s sidecar states another hammer than --config {} ({}, sidecar vs config): the points would be read with one and the model drawn with the other; leave out --config or give the traces' hammer",
                first.trace,
                config.display(),
                d.join(", ")
            );
        }
    }
    Ok(Some(hammer.clone()))
}

/// The friction law F = F0 + k·p (p gauge, bar), least squares over the points.
pub fn fit_friction_law(points: &[Point]) -> Option<(f64, f64)> {
    let n = points.len() as f64;
    let (sx, sy) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.supply_bar, b + p.friction_n));
    let (mx, my) = (sx / n, sy / n);
    let sxx: f64 = points.iter().map(|p| (p.supply_bar - mx).powi(2)).sum();
    if !(sxx > 1e-12) {
        return None;
    }
    let sxy: f64 = points.iter().map(|p| (p.supply_bar - mx) * (p.friction_n - my)).sum();
    let k = sxy / sxx;
    Some((my - k * mx, k))
}

/// The model at one supply pressure: mean impact energy and frequency of its
/// cycles after the first two (the start-up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelPoint {
    pub supply_bar: f64,
    pub energy_nominal_j: f64,
    pub frequency_nominal_hz: f64,
    pub energy_friction_j: f64,
    pub frequency_friction_hz: f64,
}

fn model_run(base: &SimConfig, supply_bar: f64, law: Option<(f64, f64)>, duration_s: f64) -> Result<(f64, f64)> {
    let mut cfg = base.clone();
    cfg.supply.pressure_bar = supply_bar;
    cfg.solver.duration_s = duration_s;
    cfg.effects = hammer_sim::Effects::default();
    cfg.import = None;
    if let Some((f0, k)) = law {
        cfg.effects.coulomb_friction = Some(hammer_sim::effects::CoulombFriction {
            f0_n: f0.max(0.0),
            k_n_per_bar: k.max(0.0),
            ..Default::default()
        });
    }
    cfg.validate()?;
    let run = simulate_truth(&cfg).map_err(|e| anyhow!("the model at {supply_bar} bar: {e}"))?;
    let cycles = &run.cycles[run.cycles.len().min(2)..];
    if cycles.is_empty() {
        bail!("the model at {supply_bar} bar gives no steady cycle in {duration_s} s");
    }
    let n = cycles.len() as f64;
    Ok((
        cycles.iter().map(|c| c.impact_energy_j).sum::<f64>() / n,
        cycles.iter().map(|c| c.frequency_hz).sum::<f64>() / n,
    ))
}

/// The sheet's numbers.
pub struct Sheet {
    pub points: Vec<Point>,
    pub law: Option<(f64, f64)>,
    pub model: Vec<ModelPoint>,
}

impl Sheet {
    /// What the reader must know before trusting the model's curves: where
    /// they leave the supply pressures the model was checked at.
    pub fn caveats(&self) -> Vec<String> {
        let (lo, hi) = PAPER_SUPPLY_BAR;
        let outside: Vec<String> = self
            .points
            .iter()
            .filter(|p| p.supply_bar < lo - 1e-9 || p.supply_bar > hi + 1e-9)
            .map(|p| format!("{}", p.supply_bar))
            .collect();
        if outside.is_empty() {
            return Vec::new();
        }
        vec![format!(
            "the model's curves at {} bar are an extrapolation: the model is anchored to the paper's bench at {lo}–{hi} bar (docs/model.md)",
            outside.join(", ")
        )]
    }
}

pub fn compute(args: &BenchSheetArgs) -> Result<Sheet> {
    let mut file = args.mapping.load()?;
    if !args.supply_bar.is_empty() && args.supply_bar.len() != args.traces.len() {
        bail!(
            "--supply-bar gives {} pressures for {} traces: give one per trace, in order",
            args.supply_bar.len(),
            args.traces.len()
        );
    }
    let (lo_s, hi_s) = DURATION_S_RANGE;
    if !(args.model_duration_s >= lo_s && args.model_duration_s <= hi_s) {
        bail!(
            "--model-duration-s {}: the model runs {lo_s} to {hi_s} s per point",
            args.model_duration_s
        );
    }
    let (lo, hi) = SUPPLY_BAR_RANGE;
    if let Some(bar) = args.supply_bar.iter().find(|b| !(**b >= lo && **b <= hi)) {
        bail!("--supply-bar {bar}: the model's curves run from {lo} to {hi} bar (gauge)");
    }
    let mut points = Vec::new();
    for (i, t) in args.traces.iter().enumerate() {
        points.push(point(t, &file, args.supply_bar.get(i).copied())?);
    }
    if let Some(p) = points.iter().find(|p| !(p.supply_bar >= lo && p.supply_bar <= hi)) {
        bail!(
            "{}: supply pressure {} bar (from its sidecar or the mapping): the model's curves run from {lo} to {hi} bar (gauge)",
            p.trace,
            p.supply_bar
        );
    }
    if let Some(hammer) = one_hammer(&points, args.mapping.config.as_deref(), &file.hammer)? {
        // The model's curves are of the hammer the traces were read with.
        file.hammer = hammer;
    }
    points.sort_by(|a, b| a.supply_bar.total_cmp(&b.supply_bar));
    let law = fit_friction_law(&points);
    let (lo, hi) = (points[0].supply_bar, points[points.len() - 1].supply_bar);
    let mut grid: Vec<f64> = points.iter().map(|p| p.supply_bar).collect();
    let mut p = lo;
    while p < hi {
        grid.push(p);
        p += 0.25;
    }
    grid.sort_by(f64::total_cmp);
    grid.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    let mut model = Vec::new();
    for &bar in &grid {
        let (en, fnom) = model_run(&file, bar, None, args.model_duration_s)?;
        let (ef, ff) = match law {
            Some(l) => model_run(&file, bar, Some(l), args.model_duration_s)?,
            None => (f64::NAN, f64::NAN),
        };
        model.push(ModelPoint {
            supply_bar: bar,
            energy_nominal_j: en,
            frequency_nominal_hz: fnom,
            energy_friction_j: ef,
            frequency_friction_hz: ff,
        });
    }
    Ok(Sheet { points, law, model })
}

fn write_file(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// Writes the sheet into `args.out`; returns the files written.
pub fn run(args: &BenchSheetArgs) -> Result<Vec<PathBuf>> {
    let sheet = compute(args)?;
    for c in sheet.caveats() {
        eprintln!("caveat: {c}");
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let mut files = Vec::new();
    let out = |name: &str| args.out.join(name);

    let mut csv = String::from(
        "supply_bar,cycles,cycles_used,friction_n,friction_u_n,friction_stroke_n,friction_backhaul_n,impact_energy_j,impact_energy_u_j,impact_energy_frictionless_j,friction_energy_loss_j,frequency_hz,blows_per_min,impact_power_w,stroke_m,friction_work_ratio,air_per_blow_l,air_cycles,air_l_per_min,impact_efficiency,truth_friction_n,truth_impact_energy_j,truth_air_per_blow_l,trace\n",
    );
    for p in &sheet.points {
        let (tf, te, ta) = p.truth.map_or((f64::NAN, f64::NAN, f64::NAN), |t| {
            (t.friction_n, t.impact_energy_j, t.air_m3)
        });
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            p.supply_bar,
            p.cycles,
            p.cycles_used,
            p.friction_n,
            p.friction_u_n,
            p.friction_stroke_n,
            p.friction_backhaul_n,
            p.impact_energy_j,
            p.impact_energy_u_j,
            p.impact_energy_frictionless_j,
            p.friction_energy_loss_j(),
            p.frequency_hz,
            p.blows_per_min(),
            p.impact_power_w(),
            p.stroke_m,
            p.friction_work_ratio,
            p.air_m3 * 1e3,
            p.air_cycles,
            p.air_per_min_m3() * 1e3,
            p.impact_efficiency(),
            tf,
            te,
            ta * 1e3,
            p.trace.replace(',', "_")
        );
    }
    write_file(&out("operating-points.csv"), &csv)?;
    files.push(out("operating-points.csv"));

    let mut mcsv = String::from(
        "supply_bar,energy_nominal_j,frequency_nominal_hz,energy_fitted_friction_j,frequency_fitted_friction_hz,friction_energy_loss_j\n",
    );
    for m in &sheet.model {
        let _ = writeln!(
            mcsv,
            "{},{},{},{},{},{}",
            m.supply_bar,
            m.energy_nominal_j,
            m.frequency_nominal_hz,
            m.energy_friction_j,
            m.frequency_friction_hz,
            m.energy_nominal_j - m.energy_friction_j
        );
    }
    write_file(&out("model.csv"), &mcsv)?;
    files.push(out("model.csv"));

    let px: Vec<f64> = sheet.points.iter().map(|p| p.supply_bar).collect();
    let mx: Vec<f64> = sheet.model.iter().map(|m| m.supply_bar).collect();
    let law_label = match sheet.law {
        Some((f0, k)) => format!("model, fitted friction {f0:.2} N + {k:.3} N/bar·p"),
        None => "model, fitted friction (one pressure: no law)".into(),
    };
    let measured = |label: &str, y: Vec<f64>| Series {
        label: label.into(),
        color: BLUE,
        x: &px,
        y,
    };
    let band = |y: Vec<f64>, u: Vec<f64>| Band {
        color: BLUE,
        x: &px,
        lo: y.iter().zip(&u).map(|(a, b)| a - b).collect(),
        hi: y.iter().zip(&u).map(|(a, b)| a + b).collect(),
    };
    // Energy (the paper's Figure 13).
    let ey: Vec<f64> = sheet.points.iter().map(|p| p.impact_energy_j).collect();
    let eu: Vec<f64> = sheet.points.iter().map(|p| p.impact_energy_u_j).collect();
    let mut energy = Chart::new(
        "impact energy, J",
        vec![
            measured("measured (± U)", ey.clone()),
            Series {
                label: "model, no friction".into(),
                color: NOMINAL,
                x: &mx,
                y: sheet.model.iter().map(|m| m.energy_nominal_j).collect(),
            },
            Series {
                label: law_label.clone(),
                color: EFFECT,
                x: &mx,
                y: sheet.model.iter().map(|m| m.energy_friction_j).collect(),
            },
        ],
    );
    energy.bands.push(band(ey, eu));
    energy.points = true;
    energy.legend = crate::chart::SeriesLabelPosition::UpperLeft;
    figure_png(
        &out("energy.png"),
        "Impact energy over supply pressure",
        18,
        "supply pressure, bar (gauge)",
        &[energy],
        (900, 560),
    )?;
    files.push(out("energy.png"));
    // Frequency (the paper's Figure 14).
    let fy: Vec<f64> = sheet.points.iter().map(|p| p.frequency_hz).collect();
    let mut freq = Chart::new(
        "impact frequency, Hz",
        vec![
            measured("measured", fy),
            Series {
                label: "model, no friction".into(),
                color: NOMINAL,
                x: &mx,
                y: sheet.model.iter().map(|m| m.frequency_nominal_hz).collect(),
            },
            Series {
                label: law_label,
                color: EFFECT,
                x: &mx,
                y: sheet.model.iter().map(|m| m.frequency_friction_hz).collect(),
            },
        ],
    );
    freq.points = true;
    freq.legend = crate::chart::SeriesLabelPosition::UpperLeft;
    figure_png(
        &out("frequency.png"),
        "Impact frequency over supply pressure",
        18,
        "supply pressure, bar (gauge)",
        &[freq],
        (900, 560),
    )?;
    files.push(out("frequency.png"));
    // Friction (the paper's Table 2 as a curve) with the fitted law.
    let fr: Vec<f64> = sheet.points.iter().map(|p| p.friction_n).collect();
    let fu: Vec<f64> = sheet.points.iter().map(|p| p.friction_u_n).collect();
    let mut series = vec![
        measured("measured, cycle mean (± U)", fr.clone()),
        Series {
            label: "stroke".into(),
            color: crate::chart::ORANGE,
            x: &px,
            y: sheet.points.iter().map(|p| p.friction_stroke_n).collect(),
        },
        Series {
            label: "backhaul".into(),
            color: crate::chart::GREEN,
            x: &px,
            y: sheet.points.iter().map(|p| p.friction_backhaul_n).collect(),
        },
    ];
    if let Some((f0, k)) = sheet.law {
        series.push(Series {
            label: format!("fitted law {f0:.2} N + {k:.3} N/bar·p"),
            color: EFFECT,
            x: &mx,
            y: mx.iter().map(|p| f0 + k * p).collect(),
        });
    }
    let mut friction = Chart::new("friction, N", series);
    friction.bands.push(band(fr, fu));
    friction.points = true;
    friction.legend = crate::chart::SeriesLabelPosition::UpperLeft;
    figure_png(
        &out("friction.png"),
        "Friction over supply pressure",
        18,
        "supply pressure, bar (gauge)",
        &[friction],
        (900, 560),
    )?;
    files.push(out("friction.png"));

    write_file(&out("index.html"), &html(&sheet))?;
    files.push(out("index.html"));
    Ok(files)
}

/// A table's energy cell: a value the sheet has none of (the model with a
/// friction law, from one pressure) is a dash, not "NaN".
fn joules(v: f64) -> String {
    if v.is_finite() {
        format!("{v:.3}")
    } else {
        "–".into()
    }
}

fn html(sheet: &Sheet) -> String {
    let mut h = String::from(
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>Bench sheet</title>\n<style>body{font-family:sans-serif;max-width:1000px;margin:auto}table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px;text-align:right}img{max-width:100%}</style>\n</head>\n<body>\n<h1>Bench sheet</h1>\n",
    );
    let _ = writeln!(
        h,
        "<p>Means over each trace's valid cycles; U is the mean of the cycles' expanded uncertainties (k = 2). Tables as CSV: <a href=\"operating-points.csv\">operating-points.csv</a>, <a href=\"model.csv\">model.csv</a>.</p>"
    );
    match sheet.law {
        Some((f0, k)) => {
            let _ = writeln!(
                h,
                "<p>Friction law fitted over the points (least squares): <b>F = {f0:.3} N + {k:.4} N/bar · p</b> (p gauge supply pressure). The model's curve with friction uses it.</p>"
            );
        }
        None => h.push_str(
            "<p>One pressure only: no friction law fitted, so the model with friction is not drawn (–).</p>\n",
        ),
    }
    for c in sheet.caveats() {
        let _ = writeln!(h, "<p><b>Caveat:</b> {c}.</p>");
    }
    h.push_str("<h2>Operating points</h2>\n<table>\n<tr><th>supply, bar</th><th>friction, N (± U)</th><th>stroke, N</th><th>backhaul, N</th><th>energy, J (± U)</th><th>energy w/o friction, J</th><th>frequency, Hz</th><th>blows/min</th><th>impact power, W</th><th>stroke, mm</th><th>friction work share</th><th>cycles used</th></tr>\n");
    for p in &sheet.points {
        let _ = writeln!(
            h,
            "<tr><td>{:.2}</td><td>{:.2} ± {:.2}</td><td>{:.2}</td><td>{:.2}</td><td>{:.3} ± {:.3}</td><td>{:.3}</td><td>{:.2}</td><td>{:.0}</td><td>{:.1}</td><td>{:.1}</td><td>{:.1} %</td><td>{} of {}</td></tr>",
            p.supply_bar,
            p.friction_n,
            p.friction_u_n,
            p.friction_stroke_n,
            p.friction_backhaul_n,
            p.impact_energy_j,
            p.impact_energy_u_j,
            p.impact_energy_frictionless_j,
            p.frequency_hz,
            p.blows_per_min(),
            p.impact_power_w(),
            p.stroke_m * 1e3,
            100.0 * p.friction_work_ratio,
            p.cycles_used,
            p.cycles
        );
    }
    h.push_str("</table>\n<h2>Air per blow and impact efficiency (estimates)</h2>\n<p><b>Estimates</b>, not measurements: the air each chamber draws from its feed's onset to the valve's switch, from the measured pressure and the volume on the piston's track: while the chamber is closed, the energy equation γ·R·T<sub>s</sub>·Δm = Δ(p·V) + (γ − 1)·∫p dV; once its outlet is uncovered with the feed still open, the orifice law with the feed's area read from its fill, R·T<sub>s</sub>·ṁ = A·p<sub>s</sub>·Ψ(p/p<sub>s</sub>)·√(R·T<sub>s</sub>). Given as free air (at atmosphere and 20 °C). The impact efficiency is the impact energy over the work that air could do expanding isothermally from the supply to atmosphere, p<sub>atm</sub>·V<sub>free</sub>·ln(p<sub>s,abs</sub>/p<sub>atm</sub>). Wall heat exchange, leakage and a feed area that changes over the feed are not in it (docs/bench-sheet.md).</p>\n<table>\n<tr><th>supply, bar</th><th>free air per blow, l</th><th>free air, l/min</th><th>impact efficiency</th><th>cycles read</th><th>simulator's air per blow, l</th></tr>\n");
    for p in &sheet.points {
        let _ = writeln!(
            h,
            "<tr><td>{:.2}</td><td>{:.4}</td><td>{:.1}</td><td>{:.1} %</td><td>{} of {}</td><td>{}</td></tr>",
            p.supply_bar,
            p.air_m3 * 1e3,
            p.air_per_min_m3() * 1e3,
            100.0 * p.impact_efficiency(),
            p.air_cycles,
            p.cycles_used,
            p.truth.map_or("–".to_string(), |t| format!("{:.4}", t.air_m3 * 1e3))
        );
    }
    h.push_str("</table>\n<h2>The energy friction costs (the paper's Table 3)</h2>\n<table>\n<tr><th>supply, bar</th><th>measured with friction, J</th><th>measured without friction, J</th><th>difference, J</th><th>difference, %</th><th>model without friction, J</th><th>model with fitted friction, J</th><th>model difference, J</th></tr>\n");
    for p in &sheet.points {
        let m = sheet.model.iter().find(|m| (m.supply_bar - p.supply_bar).abs() < 1e-9);
        let (mn, mf) = m.map_or((f64::NAN, f64::NAN), |m| (m.energy_nominal_j, m.energy_friction_j));
        let _ = writeln!(
            h,
            "<tr><td>{:.2}</td><td>{:.3}</td><td>{:.3}</td><td>{:.3}</td><td>{:.1} %</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            p.supply_bar,
            p.impact_energy_j,
            p.impact_energy_frictionless_j,
            p.friction_energy_loss_j(),
            100.0 * p.friction_energy_loss_j() / p.impact_energy_frictionless_j,
            joules(mn),
            joules(mf),
            joules(mn - mf)
        );
    }
    h.push_str("</table>\n<h2>Curves over supply pressure (the paper's Figures 13–14)</h2>\n");
    for (f, alt) in [
        (
            "energy.png",
            "impact energy over supply pressure: measured with U, model nominal and with the fitted friction",
        ),
        (
            "frequency.png",
            "impact frequency over supply pressure: measured, model nominal and with the fitted friction",
        ),
        (
            "friction.png",
            "friction over supply pressure per phase, with the fitted law",
        ),
    ] {
        let _ = writeln!(
            h,
            "<figure>\n<img src=\"{f}\" alt=\"{alt}\">\n<figcaption>{alt}</figcaption>\n</figure>"
        );
    }
    h.push_str("</body>\n</html>\n");
    h
}
