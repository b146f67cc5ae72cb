//! Per-cycle records of `hammer estimate`: the output formats. Traces are
//! opened for the estimator by `hammer_sim::estimation`, the same crate and
//! code path as the firmware; only the sample source differs.

use std::fmt::Write as _;

use hammer_estimator::CycleReport;

pub fn flag_names(r: &CycleReport) -> Vec<&'static str> {
    r.flags.names().collect()
}

/// One JSON object per cycle.
pub fn jsonl_record(r: &CycleReport) -> serde_json::Value {
    serde_json::json!({
        "seq": r.seq,
        "t_impact_s": r.t_impact_s,
        "period_s": r.period_s,
        "frequency_hz": r.frequency_hz,
        "friction_n": r.friction_n,
        "friction_stroke_n": r.friction_stroke_n,
        "friction_backhaul_n": r.friction_backhaul_n,
        "friction_uncertainty_n": r.friction_uncertainty_n,
        "friction_stroke_uncertainty_n": r.friction_stroke_uncertainty_n,
        "friction_backhaul_uncertainty_n": r.friction_backhaul_uncertainty_n,
        "impact_velocity_mps": r.impact_velocity_mps,
        "impact_velocity_frictionless_mps": r.impact_velocity_frictionless_mps,
        "impact_energy_j": r.impact_energy_j,
        "impact_energy_frictionless_j": r.impact_energy_frictionless_j,
        "impact_energy_uncertainty_j": r.impact_energy_uncertainty_j,
        "impact_energy_frictionless_uncertainty_j": r.impact_energy_frictionless_uncertainty_j,
        "friction_work_j": r.friction_work_j,
        "friction_work_ratio": r.friction_work_ratio,
        "stroke_m": r.stroke_m,
        "peak_rear_pa": r.peak_rear_pa,
        "peak_front_pa": r.peak_front_pa,
        "accel_zero_shift_mps2": r.accel_zero_shift_mps2,
        "wear_index": r.wear_index_j,
        "wear_remaining_fraction": r.wear_remaining_fraction,
        "remaining_life_cycles": r.remaining_life_cycles,
        "drift_score": r.drift_score,
        "valid": r.is_valid(),
        "flags": flag_names(r),
    })
}

pub const CSV_HEADER: &str = "seq,t_impact_s,frequency_hz,friction_n,friction_stroke_n,friction_backhaul_n,friction_uncertainty_n,impact_velocity_mps,impact_energy_j,impact_energy_frictionless_j,impact_energy_uncertainty_j,friction_work_j,stroke_m,wear_index,drift_score,valid,flags";

pub fn csv_record(r: &CycleReport) -> String {
    format!(
        "{},{:.6},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
        r.seq,
        r.t_impact_s,
        r.frequency_hz,
        r.friction_n,
        r.friction_stroke_n,
        r.friction_backhaul_n,
        r.friction_uncertainty_n,
        r.impact_velocity_mps,
        r.impact_energy_j,
        r.impact_energy_frictionless_j,
        r.impact_energy_uncertainty_j,
        r.friction_work_j,
        r.stroke_m,
        r.wear_index_j,
        r.drift_score,
        r.is_valid(),
        flag_names(r).join("|")
    )
}

/// A human-readable table with a summary line over the valid cycles.
pub fn table(reports: &[CycleReport]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:>4} {:>9} {:>7} {:>15} {:>7} {:>7} {:>15} {:>8} {:>7} {:>7}  flags",
        "seq", "t_imp_s", "f_hz", "friction_n", "F_str", "F_back", "energy_j", "E_nofr", "stroke", "wear_j"
    );
    for r in reports {
        let _ = writeln!(
            s,
            "{:>4} {:>9.4} {:>7.3} {:>7.2} ± {:<5.2} {:>7.2} {:>7.2} {:>7.3} ± {:<5.3} {:>8.3} {:>5.1}mm {:>7.1}  {}",
            r.seq,
            r.t_impact_s,
            r.frequency_hz,
            r.friction_n,
            r.friction_uncertainty_n,
            r.friction_stroke_n,
            r.friction_backhaul_n,
            r.impact_energy_j,
            r.impact_energy_uncertainty_j,
            r.impact_energy_frictionless_j,
            r.stroke_m * 1e3,
            r.wear_index_j,
            flag_names(r).join(",")
        );
    }
    let valid: Vec<&CycleReport> = reports.iter().filter(|r| r.is_valid()).collect();
    if !valid.is_empty() {
        let n = valid.len() as f32;
        let mean = |f: fn(&CycleReport) -> f32| valid.iter().map(|r| f(r)).sum::<f32>() / n;
        let sd = |f: fn(&CycleReport) -> f32| {
            let m = mean(f);
            (valid.iter().map(|r| (f(r) - m).powi(2)).sum::<f32>() / (n - 1.0).max(1.0)).sqrt()
        };
        let _ = writeln!(
            s,
            "summary: {} of {} cycles valid; friction {:.3} N (cycle-to-cycle sd {:.3}), energy {:.4} J (sd {:.4}), friction-blind energy {:.4} J, frequency {:.3} Hz, friction work {:.1} % of impact energy",
            valid.len(),
            reports.len(),
            mean(|r| r.friction_n),
            sd(|r| r.friction_n),
            mean(|r| r.impact_energy_j),
            sd(|r| r.impact_energy_j),
            mean(|r| r.impact_energy_frictionless_j),
            mean(|r| r.frequency_hz),
            100.0 * mean(|r| r.friction_work_ratio)
        );
    } else {
        let _ = writeln!(s, "summary: no valid cycle among {}", reports.len());
    }
    s
}
