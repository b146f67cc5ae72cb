//! `hammer figures`: one figure per catalogued effect against the nominal
//! model, over one steady cycle, in the shared chart model.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context, Result};

use crate::chart::render::figure_png;
use crate::chart::{Chart, Series, EFFECT, NOMINAL};
use crate::numfmt::compact;
use hammer_sim::simulate::{simulate, Simulation};
use hammer_sim::{SimConfig, EFFECT_NAMES};

/// The effect figures' title size, points.
const TITLE_FONT: u32 = 22;

/// Sample range of the last complete steady cycle: impact to next impact.
pub fn last_cycle(sim: &Simulation) -> Option<(usize, usize)> {
    let c = sim.run.cycles.len().checked_sub(1)?;
    let cyc = &sim.run.cycles[c];
    let dt = sim.run.truth.dt_s;
    let i1 = (cyc.t_impact_s / dt).round() as usize;
    let i0 = ((cyc.t_impact_s - cyc.period_s) / dt).round() as usize;
    Some((i0.saturating_sub(20), (i1 + 20).min(sim.run.truth.len())))
}

/// One figure per catalogued effect at its default magnitude.
pub fn effect_figures(dir: &Path, supply_bar: f64) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut base = SimConfig::nominal(supply_bar);
    base.solver.duration_s = 0.4;
    base.sensors.enabled = false;
    let nominal = simulate(&base)?;
    let (n0, n1) = last_cycle(&nominal).ok_or_else(|| anyhow!("nominal run has no complete cycle"))?;
    let mut files = Vec::new();
    for name in EFFECT_NAMES {
        let mut cfg = base.clone();
        cfg.effects.apply_spec(name)?;
        let with = simulate(&cfg)?;
        let (w0, w1) = last_cycle(&with).ok_or_else(|| anyhow!("{name}: no complete cycle"))?;
        let tn: Vec<f64> = (n0..n1)
            .map(|i| (i - n0) as f64 * base.solver.output_step_s * 1e3)
            .collect();
        let tw: Vec<f64> = (w0..w1)
            .map(|i| (i - w0) as f64 * base.solver.output_step_s * 1e3)
            .collect();
        let pair = |label: &str, nom: &[f64], eff: &[f64], scale: f64, lim: Option<(f64, f64)>| {
            let mut chart = Chart::new(
                label,
                vec![
                    Series {
                        label: "nominal".into(),
                        color: NOMINAL,
                        x: &tn,
                        y: nom[n0..n1].iter().map(|v| v * scale).collect(),
                    },
                    Series {
                        label: name.into(),
                        color: EFFECT,
                        x: &tw,
                        y: eff[w0..w1].iter().map(|v| v * scale).collect(),
                    },
                ],
            );
            chart.y_limits = lim;
            chart
        };
        let charts = [
            pair(
                "rear p, bar",
                &nominal.measured.p_rear_pa,
                &with.measured.p_rear_pa,
                1e-5,
                None,
            ),
            pair(
                "front p, bar",
                &nominal.measured.p_front_pa,
                &with.measured.p_front_pa,
                1e-5,
                None,
            ),
            pair(
                "accel, m/s²",
                &nominal.measured.accel_mps2,
                &with.measured.accel_mps2,
                1.0,
                Some((-800.0, 800.0)),
            ),
            pair(
                "velocity, m/s",
                &nominal.run.truth.v_mps,
                &with.run.truth.v_mps,
                1.0,
                None,
            ),
        ];
        let params = effect_params_text(&cfg.effects, name)?;
        let path = dir.join(format!("effect-{name}.png"));
        figure_png(
            &path,
            &format!("{name}:{params} vs nominal, {supply_bar} bar"),
            TITLE_FONT,
            "time since impact, ms",
            &charts,
            (1100, 900),
        )?;
        files.push(path);
    }
    Ok(files)
}

/// `key=value` pairs of an effect's parameters, short enough for a title.
pub fn effect_params_text(effects: &hammer_sim::Effects, name: &str) -> Result<String> {
    let value = serde_json::to_value(effects)?;
    let Some(obj) = value.get(name).and_then(|v| v.as_object()) else {
        return Ok(String::new());
    };
    Ok(obj
        .iter()
        .map(|(k, v)| match v.as_f64() {
            Some(x) => format!("{k}={}", compact(x)),
            None => format!("{k}={v}"),
        })
        .collect::<Vec<_>>()
        .join(","))
}
