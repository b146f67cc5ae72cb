//! Stage 1b, reference (only with reference records): the measurement read
//! as a change from the same hammer's own earlier record.
//!
//! A model of another form than the hammer misses the hammer's waveforms by
//! a form error no parameter closes, and an effect is named only above it
//! (`docs/diagnosis.md`, the structural benchmark). A monitoring controller
//! has something better than the model: the hammer itself, recorded when it
//! was known to be sound (commissioning, after an overhaul). The form error
//! is the same in both records, so the change between them is the effects
//! that arose since, and the model is needed only for how an effect changes
//! the features, not for what they are. Every measured cycle's features are
//! moved by (nominal model − reference mean) at its operating point: the
//! rest of the pipeline then diagnoses the nominal model plus the measured
//! change, as if the hammer had the model's form. The reference mean's own
//! uncertainty is added to the fit's variances.

use super::group::{group, Point};
use crate::features::{summarize, Extractor, N_FEATURES};
use crate::input::{DiagnoseError, MeasuredInput};
use crate::report::InputInfo;

/// A reference record's steady cycles at one operating point, averaged.
pub(crate) struct Baseline {
    pub(crate) supply_bar: f64,
    pub(crate) mean: Vec<f64>,
    /// Variance of the mean (cycle-to-cycle variance over the cycles).
    pub(crate) var_of_mean: Vec<f64>,
}

/// The reference records by operating point, and what was read of each.
pub(crate) fn baselines(
    references: &[MeasuredInput],
    extractor: &Extractor,
) -> Result<(Vec<Baseline>, Vec<InputInfo>), DiagnoseError> {
    // Every steady cycle counts, the fit and held-out halves alike, so the
    // fit flags the grouping goes by do not matter here.
    let g = group(references, extractor)?;
    let baselines = g
        .points
        .iter()
        .map(|p| {
            let cycles: Vec<_> = p.fit.iter().chain(&p.held).cloned().collect();
            let s = summarize(&cycles);
            let n = s.cycles.max(1) as f64;
            Baseline {
                supply_bar: p.supply_bar,
                var_of_mean: s
                    .sd
                    .iter()
                    .map(|sd| if sd.is_finite() { sd * sd / n } else { 0.0 })
                    .collect(),
                mean: s.mean,
            }
        })
        .collect();
    Ok((baselines, g.infos))
}

/// Moves every cycle of every point by (nominal − reference mean) at its
/// operating point and records the reference's variance on the point.
/// Every point needs a reference at its supply pressure (to 0.01 bar).
pub(crate) fn transplant(
    points: &mut [Point],
    nominal_features: &[Vec<f64>],
    baselines: &[Baseline],
) -> Result<(), DiagnoseError> {
    for (p, nominal) in points.iter_mut().zip(nominal_features) {
        let b = baselines
            .iter()
            .find(|b| (b.supply_bar - p.supply_bar).abs() < 0.005)
            .ok_or(DiagnoseError::NoReference(p.supply_bar))?;
        let shift: Vec<f64> = (0..N_FEATURES).map(|j| nominal[j] - b.mean[j]).collect();
        for c in p.fit.iter_mut().chain(p.held.iter_mut()) {
            for (v, s) in c.values.iter_mut().zip(&shift) {
                *v += s;
            }
        }
        p.reference_var = b.var_of_mean.clone();
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::features::{ENERGY, F_STROKE, PERIOD};
    use crate::pipeline::tests::{measured, nominal_runner, options, quiet};
    use crate::pipeline::{group::group, nominal::nominal};

    /// The reference is the measurement itself: moved onto the model, each
    /// point's mean becomes the nominal model's (the form error and the
    /// hammer's own values cancel), its variance the reference's.
    #[test]
    fn a_measurement_against_itself_is_the_nominal_model() {
        let runner = nominal_runner();
        let inputs = [measured(4.0, true), measured(7.0, false)];
        let mut g = group(&inputs, &runner.extractor).unwrap();
        let nom = nominal(&g.points, &runner, &options(), &quiet).unwrap();
        let (base, infos) = baselines(&inputs, &runner.extractor).unwrap();
        assert_eq!(infos.len(), 2);
        transplant(&mut g.points, &nom.features, &base).unwrap();
        for (p, nf) in g.points.iter().zip(&nom.features) {
            let cycles: Vec<_> = p.fit.iter().chain(&p.held).cloned().collect();
            let s = summarize(&cycles);
            for j in [PERIOD, ENERGY, F_STROKE] {
                assert!((s.mean[j] - nf[j]).abs() <= 1e-9 * (1.0 + nf[j].abs()), "feature {j}");
            }
            assert!(p.reference_var[ENERGY] > 0.0);
        }
    }

    #[test]
    fn a_point_without_a_reference_is_refused() {
        let runner = nominal_runner();
        let inputs = [measured(4.0, true), measured(7.0, false)];
        let mut g = group(&inputs, &runner.extractor).unwrap();
        let nom = nominal(&g.points, &runner, &options(), &quiet).unwrap();
        let (base, _) = baselines(&inputs[..1], &runner.extractor).unwrap();
        let e = transplant(&mut g.points, &nom.features, &base).err();
        assert!(matches!(e, Some(DiagnoseError::NoReference(b)) if b == 7.0), "{e:?}");
    }
}
