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
#[cfg(test)]
mod tests;

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
