//! The hammer's start-up, left out of what is read as its steady running:
//! leading cycles whose energy or period differs from the later cycles'
//! median by more than 1 %. One rule for a record's captures (the
//! diagnosis' extractor) and a record's reports (`hammer commission`).

/// Index of the first steady cycle of `energy_period` (each cycle's
/// impact energy and period, for any reading of cycles: the extractor's,
/// a board's reports).
pub fn steady_start(energy_period: &[(f64, f64)]) -> usize {
    if energy_period.len() < 3 {
        return 0;
    }
    let median = |pick: fn(&(f64, f64)) -> f64| {
        let mut xs: Vec<f64> = energy_period[energy_period.len() / 2..].iter().map(pick).collect();
        xs.sort_by(f64::total_cmp);
        xs[xs.len() / 2]
    };
    let (e, p) = (median(|c| c.0), median(|c| c.1));
    energy_period
        .iter()
        .position(|&(ce, cp)| ((ce - e) / e).abs() < 0.01 && ((cp - p) / p).abs() < 0.01)
        .unwrap_or(energy_period.len())
}
