//! The force balance at every operating point (fit and held out): what it
//! measures of each effect it sees, as the change since the nominal model
//! (against a record: since the record), with its uncertainty.
//!
//! It needs no valve or port law, so it is the size of friction, viscous
//! friction, a gain error and a zero shift in both modes (the verdict
//! reports it: `effect_fit::at_measured_sizes`); at a held-out point it is
//! the check of a fitted law's line between the fit points.

use super::group::Point;
use crate::effects::force_balance_readings;
use crate::features::summarize;
use crate::fitset::change_of;
use crate::report::{ForceBalancePoint, ForceBalanceQuantity};

/// The coverage factor of the expanded uncertainty U = k·u: about 95 % for
/// a mean of many cycles (docs/diagnosis.md).
pub(crate) const COVERAGE_K: f64 = 2.0;

/// The force balance at every point of `points`, read on the cycles the
/// point contributes (a fit point's fit cycles: the ones the verdict's size
/// came from; a held-out point's held-out cycles).
pub(crate) fn table(points: &[Point], nominal_features: &[Vec<f64>]) -> Vec<ForceBalancePoint> {
    points
        .iter()
        .zip(nominal_features)
        .filter_map(|(p, nominal)| {
            let cycles = if p.is_fit_point { &p.fit } else { &p.held };
            let s = summarize(cycles);
            (s.cycles > 0).then(|| ForceBalancePoint {
                supply_bar: p.supply_bar,
                fit_point: p.is_fit_point,
                against_record: !p.reference_var.is_empty(),
                cycles: s.cycles,
                quantities: force_balance_readings(&|j| change_of(&s, nominal, &p.reference_var, j))
                    .into_iter()
                    .map(|(key, value, u)| ForceBalanceQuantity {
                        key,
                        value,
                        u,
                        expanded_u: COVERAGE_K * u,
                    })
                    .collect(),
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::tests::{measured, nominal_runner, options, quiet};
    use crate::pipeline::{group::group, nominal::nominal};
    use hammer_sim::effects::Effects;
    use hammer_sim::simulate::simulate;
    use hammer_sim::SimConfig;

    /// A hammer with the paper's friction: the force balance reads its law
    /// at the fit point and at the held-out one, within U of the truth; the
    /// nominal hammer reads no friction beyond its U.
    #[test]
    fn the_force_balance_reads_the_friction_law_at_every_point() {
        let runner = nominal_runner();
        let with_friction = |bar: f64, fit: bool| {
            let mut c = SimConfig::nominal(bar);
            c.solver.duration_s = 0.6;
            c.seed = 5;
            c.effects = Effects::default();
            c.effects.apply_spec("coulomb_friction").unwrap();
            let truth = c.effects.coulomb_friction.as_ref().unwrap().force_n(bar);
            let sim = simulate(&c).unwrap();
            let input = crate::input::MeasuredInput {
                label: format!("friction at {bar} bar"),
                supply_bar: bar,
                trace: sim.trace(),
                fit,
            };
            (input, truth)
        };
        let (a, fa) = with_friction(4.0, true);
        let (b, fb) = with_friction(7.0, false);
        let g = group(&[a, b], &runner.extractor).unwrap();
        let nom = nominal(&g.points, &runner, &options(), &quiet).unwrap();
        let t = table(&g.points, &nom.features);
        assert_eq!(t.len(), 2);
        for (row, truth) in t.iter().zip([fa, fb]) {
            let q = row.quantities.iter().find(|q| q.key.ends_with(".friction_n")).unwrap();
            assert!(q.u > 0.0 && q.expanded_u == COVERAGE_K * q.u);
            // The estimator reads the friction within 0.8 % of its truth
            // (docs/estimator.md); the mean's own noise is its U.
            assert!(
                (q.value - truth).abs() <= q.expanded_u + 0.008 * truth,
                "{} bar: {} ± {} N against {truth} N",
                row.supply_bar,
                q.value,
                q.expanded_u
            );
        }
        let g = group(&[measured(4.0, true)], &runner.extractor).unwrap();
        let t = table(&g.points, &nom.features[..1]);
        let q = t[0].quantities.iter().find(|q| q.key.ends_with(".friction_n")).unwrap();
        assert!(
            q.value.abs() <= q.expanded_u + 0.05,
            "nominal: {} ± {} N",
            q.value,
            q.expanded_u
        );
    }
}
