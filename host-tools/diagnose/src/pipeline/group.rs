//! Stage 1, group: every input's cycles, start-up dropped, split into fit
//! and held-out halves, and gathered by operating point (supply pressure).
//!
//! The split is by time: the fit sees a trace's earlier cycles, the check
//! its later ones, so drift within a run counts against the model and not
//! for it. Inputs at the same pressure (to 0.01 bar) are one point.

use crate::features::{steady_from, CycleFeatures, Extractor, Signals, PERIOD};
use crate::input::{DiagnoseError, MeasuredInput};
use crate::report::InputInfo;

/// One operating point: the cycles of every input at its supply pressure.
#[derive(Clone)]
pub(crate) struct Point {
    pub(crate) supply_bar: f64,
    pub(crate) fit: Vec<CycleFeatures>,
    pub(crate) held: Vec<CycleFeatures>,
    pub(crate) is_fit_point: bool,
    /// Indices of its inputs.
    pub(crate) inputs: Vec<usize>,
    /// Variance of the reference record's mean per feature, added to the
    /// fit's (empty without a reference: [`super::reference`]).
    pub(crate) reference_var: Vec<f64>,
}

pub(crate) struct Grouped {
    pub(crate) infos: Vec<InputInfo>,
    /// By supply pressure, lowest first.
    pub(crate) points: Vec<Point>,
    /// Per input: the impact times of its steady cycles and the end of the last.
    pub(crate) steady_impacts: Vec<Vec<f64>>,
}

/// One input's steady cycles, split.
struct Split {
    info: InputInfo,
    fit: Vec<CycleFeatures>,
    held: Vec<CycleFeatures>,
    is_fit: bool,
    impacts: Vec<f64>,
}

/// Groups `inputs` by operating point. Without any input marked `fit`, the
/// first one is fitted.
pub(crate) fn group(inputs: &[MeasuredInput], extractor: &Extractor) -> Result<Grouped, DiagnoseError> {
    let any_fit = inputs.iter().any(|i| i.fit);
    let mut grouped = Grouped {
        infos: Vec::new(),
        points: Vec::new(),
        steady_impacts: Vec::new(),
    };
    for (k, inp) in inputs.iter().enumerate() {
        let split = split(inp, inp.fit || (!any_fit && k == 0), extractor)?;
        grouped.steady_impacts.push(split.impacts);
        grouped.infos.push(split.info);
        let key = (inp.supply_bar * 100.0).round() / 100.0;
        match grouped.points.iter_mut().find(|p| (p.supply_bar - key).abs() < 1e-9) {
            Some(p) => {
                p.fit.extend(split.fit);
                p.held.extend(split.held);
                p.is_fit_point |= split.is_fit;
                p.inputs.push(k);
            }
            None => grouped.points.push(Point {
                supply_bar: key,
                fit: split.fit,
                held: split.held,
                is_fit_point: split.is_fit,
                inputs: vec![k],
                reference_var: Vec::new(),
            }),
        }
    }
    grouped.points.sort_by(|a, b| a.supply_bar.total_cmp(&b.supply_bar));
    Ok(grouped)
}

/// The steady cycles of one input: all held out, or (fitted) the earlier
/// half for the fit and the later half held out; a single cycle serves both.
fn split(inp: &MeasuredInput, is_fit: bool, extractor: &Extractor) -> Result<Split, DiagnoseError> {
    if !(inp.supply_bar.is_finite() && inp.supply_bar > 0.0) {
        return Err(DiagnoseError::NoPressure(inp.label.clone()));
    }
    let all = extractor.cycles(&Signals::of_trace(&inp.trace, inp.supply_bar));
    let st = steady_from(&all);
    let steady = &all[st..];
    if steady.is_empty() {
        return Err(DiagnoseError::NoCycles(inp.label.clone()));
    }
    let mut impacts: Vec<f64> = steady.iter().map(|c| c.t_impact_s).collect();
    if let Some(last) = steady.last() {
        impacts.push(last.t_impact_s + last.values[PERIOD]);
    }
    let (fit, held) = if !is_fit {
        (Vec::new(), steady.to_vec())
    } else if steady.len() >= 2 {
        let h = steady.len().div_ceil(2);
        (steady[..h].to_vec(), steady[h..].to_vec())
    } else {
        (steady.to_vec(), steady.to_vec())
    };
    let info = InputInfo {
        label: inp.label.clone(),
        supply_bar: inp.supply_bar,
        cycles: all.len(),
        startup_cycles: st,
        fit_cycles: fit.len(),
        held_out_cycles: held.len(),
    };
    Ok(Split {
        info,
        fit,
        held,
        is_fit,
        impacts,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::extractor_for;
    use crate::pipeline::tests::measured;
    use hammer_sim::SimConfig;

    /// Two traces at 4 bar and one at 7: two points, lowest first, the 4 bar
    /// traces merged; the fit's cycles come before the held-out ones in
    /// time; and the hammer runs faster at the higher pressure.
    #[test]
    fn groups_by_pressure_and_splits_by_time() {
        let inputs = [measured(7.0, false), measured(4.0, true), measured(4.0, false)];
        let g = group(&inputs, &extractor_for(&SimConfig::default())).unwrap();
        let bars: Vec<f64> = g.points.iter().map(|p| p.supply_bar).collect();
        assert_eq!(bars, [4.0, 7.0]);
        assert_eq!(g.points[0].inputs, [1, 2]);
        assert!(g.points[0].is_fit_point && !g.points[1].is_fit_point);
        assert!(g.points[1].fit.is_empty(), "a held-out point gives the fit nothing");
        let info = &g.infos[1];
        assert_eq!(info.fit_cycles, (info.cycles - info.startup_cycles).div_ceil(2));
        let last_fit = g.points[0].fit.iter().map(|c| c.t_impact_s).fold(0.0, f64::max);
        let first_held = g.infos[1].held_out_cycles;
        assert!(first_held > 0);
        assert!(g.points[0]
            .held
            .iter()
            .take(first_held)
            .all(|c| c.t_impact_s > last_fit));
        assert_eq!(g.steady_impacts[0].len(), g.infos[0].held_out_cycles + 1);
        let period = |p: &Point| p.held.iter().map(|c| c.values[PERIOD]).sum::<f64>() / p.held.len() as f64;
        assert!(
            period(&g.points[1]) < period(&g.points[0]),
            "7 bar must beat faster than 4 bar"
        );
    }

    #[test]
    fn refuses_an_input_without_pressure() {
        let mut m = measured(4.0, true);
        m.supply_bar = f64::NAN;
        let e = group(&[m], &extractor_for(&SimConfig::default())).err();
        assert!(matches!(e, Some(DiagnoseError::NoPressure(_))), "{e:?}");
    }
}
