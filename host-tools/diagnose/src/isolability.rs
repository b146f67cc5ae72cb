//! The catalogue's isolability, from the model alone, before any data: each
//! effect at its catalogue default is put into the diagnosis' own model
//! (sensor noise and ADC included, nominal parameters exact), every effect
//! is fitted to it alone, and the share of the gap each one explains is a
//! row of the matrix. A large share off the diagonal is a pair the
//! diagnosis can confuse; where the row's effect shows first (signal ×
//! stage) is where it can be told apart.

use serde::{Deserialize, Serialize};

use super::engine::{diagnose, MeasuredInput, Options};
use hammer_sim::effects::{Effects, EFFECT_NAMES};
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Row {
    /// The effect put into the model.
    pub effect: String,
    /// Where its gap is largest: "signal in stage at N bar".
    pub shows_in: String,
    /// Per catalogue effect (in catalogue order): the share of the nominal
    /// gap it explains when fitted alone, and its score (ΔBIC).
    pub explained: Vec<f64>,
    pub score: Vec<f64>,
    /// The diagnosis' verdict on this row.
    pub named: Vec<String>,
}

/// Runs the matrix at `points` (bar; all fitted), `duration_s` of hammer each.
pub fn matrix(points: &[f64], duration_s: f64, diag: &Options) -> anyhow::Result<Vec<Row>> {
    let mut rows = Vec::new();
    for (k, name) in EFFECT_NAMES.iter().enumerate() {
        let mut cfg = SimConfig::default();
        cfg.effects = Effects::default();
        cfg.effects.apply_spec(name)?;
        cfg.solver.duration_s = duration_s;
        let mut inputs = Vec::new();
        for (i, &bar) in points.iter().enumerate() {
            let mut c = cfg.clone();
            c.supply.pressure_bar = bar;
            c.seed = 1000 + 10 * k as u64 + i as u64;
            inputs.push(MeasuredInput {
                label: format!("{name} at {bar} bar"),
                supply_bar: bar,
                trace: simulate(&c)?.trace(),
                fit: true,
            });
        }
        let r = diagnose(&inputs, &SimConfig::default(), diag, &|_, _, _| {})?.report;
        let of = |j: &str| r.effects.iter().find(|e| e.name == j);
        rows.push(Row {
            effect: name.to_string(),
            shows_in: r.where_.first().map_or_else(
                || "-".to_string(),
                |c| format!("{} in {} at {} bar", c.signal, c.stage.name(), c.supply_bar),
            ),
            explained: EFFECT_NAMES
                .iter()
                .map(|j| of(j).map_or(0.0, |e| e.explained_fraction))
                .collect(),
            score: EFFECT_NAMES
                .iter()
                .map(|j| of(j).map_or(f64::NAN, |e| e.score))
                .collect(),
            named: r.verdict.effects.clone(),
        });
    }
    Ok(rows)
}

/// The matrix as a text table: rows present, columns fitted, cells the
/// share of the gap explained (%); `*` marks the verdict.
pub fn render(rows: &[Row]) -> String {
    use std::fmt::Write as _;
    let short = |c: &str| -> String {
        c.split('_')
            .map(|w| w.chars().take(4).collect::<String>())
            .collect::<Vec<_>>()
            .join("_")
    };
    let mut out = String::new();
    let _ = writeln!(
        out,
        "isolability: rows the effect in the model (catalogue default), columns each effect fitted alone,\n\
         cells the share of the nominal gap it explains (%); * the verdict"
    );
    let _ = write!(out, "{:>20}", "");
    for c in EFFECT_NAMES {
        let _ = write!(out, " {:>10}", short(c));
    }
    let _ = writeln!(out, "  shows first in");
    for r in rows {
        let _ = write!(out, "{:>20}", r.effect);
        for (j, c) in EFFECT_NAMES.iter().enumerate() {
            let mark = if r.named.iter().any(|n| n == c) { "*" } else { " " };
            let _ = write!(out, " {:>9.0}{mark}", 100.0 * r.explained[j]);
        }
        let _ = writeln!(out, "  {}", r.shows_in);
    }
    // The confusable pairs: another effect explaining at least half.
    let mut pairs = Vec::new();
    for r in rows {
        for (j, c) in EFFECT_NAMES.iter().enumerate() {
            if *c != r.effect && r.explained[j] >= 0.5 {
                pairs.push(format!("{} ~ {} ({:.0} %)", r.effect, c, 100.0 * r.explained[j]));
            }
        }
    }
    let _ = writeln!(
        out,
        "\nconfusable (another effect alone explains ≥ 50 % of the gap): {}",
        if pairs.is_empty() {
            "none".to_string()
        } else {
            pairs.join("; ")
        }
    );
    out
}
