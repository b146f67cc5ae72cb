//! A plant with some of its nuisance parameters held at their nominal
//! values: the ones the model did not respond to at the fit points.
//!
//! Why: a map lists what its engineer is unsure of, and not every listed
//! parameter acts in every configuration of the model (a hose's length
//! where the supply is a stiff line, a polytropic exponent where the
//! chambers follow another law). Such a parameter's sensitivity column is
//! exactly zero, so the prior alone holds it at nominal in every fit, and
//! its Jacobian columns are simulations that cannot change the answer (the
//! second family's map of 19 lists a polytropic exponent, a hose and a
//! tool, each acting only in its own form). Holding them changes no fitted
//! value but by the order of a sum; `report.json` names them
//! (`held_nuisance`).

use std::sync::Arc;

use super::plant::{Keep, ModelTrace, NuisanceParam, Plant};
use hammer_sim::effects::Effects;

/// `inner` with only the nuisance parameters `kept` (indices into its
/// own list, ascending) left free; the others run at their nominal values.
#[derive(Debug)]
pub struct Pinned {
    inner: Arc<dyn Plant>,
    kept: Vec<usize>,
    free: Vec<NuisanceParam>,
    held: Vec<String>,
}

impl Pinned {
    /// `None` when every parameter is kept (nothing to hold) or an index
    /// is not one of `inner`'s.
    pub fn new(inner: Arc<dyn Plant>, kept: Vec<usize>) -> Option<Self> {
        let all = inner.nuisance();
        if kept.len() == all.len() || kept.iter().any(|&k| k >= all.len()) || !kept.windows(2).all(|w| w[0] < w[1]) {
            return None;
        }
        let free = kept.iter().map(|&k| all[k].clone()).collect();
        let held = (0..all.len())
            .filter(|k| !kept.contains(k))
            .map(|k| all[k].name.clone())
            .collect();
        Some(Self {
            inner,
            kept,
            free,
            held,
        })
    }

    /// The names of the parameters held at nominal, in the model's order.
    pub fn held(&self) -> &[String] {
        &self.held
    }
}

impl Plant for Pinned {
    fn nuisance(&self) -> &[NuisanceParam] {
        &self.free
    }

    fn carries(&self, name: &str) -> bool {
        self.inner.carries(name)
    }

    fn run(
        &self,
        supply_bar: f64,
        nuisance: &[f64],
        effects: &Effects,
        duration_s: f64,
        keep: Keep,
    ) -> Result<ModelTrace, String> {
        if nuisance.len() != self.kept.len() {
            return Err(format!(
                "{} nuisance values for {} free parameters",
                nuisance.len(),
                self.kept.len()
            ));
        }
        let mut all: Vec<f64> = self.inner.nuisance().iter().map(|p| p.nominal).collect();
        for (&k, &v) in self.kept.iter().zip(nuisance) {
            all[k] = v;
        }
        self.inner.run(supply_bar, &all, effects, duration_s, keep)
    }

    fn fatal(&self) -> Option<String> {
        self.inner.fatal()
    }

    fn identity(&self) -> Option<serde_json::Value> {
        self.inner.identity()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// Records the nuisance values it was run with.
    #[derive(Debug)]
    struct Spy {
        params: Vec<NuisanceParam>,
        seen: Mutex<Vec<Vec<f64>>>,
    }

    impl Plant for Spy {
        fn nuisance(&self) -> &[NuisanceParam] {
            &self.params
        }
        fn carries(&self, _: &str) -> bool {
            true
        }
        fn run(&self, _: f64, nuisance: &[f64], _: &Effects, _: f64, _: Keep) -> Result<ModelTrace, String> {
            self.seen.lock().unwrap().push(nuisance.to_vec());
            Ok(ModelTrace::default())
        }
    }

    fn spy() -> Arc<Spy> {
        let params = ["a", "b", "c"]
            .iter()
            .enumerate()
            .map(|(i, n)| NuisanceParam {
                name: n.to_string(),
                nominal: 10.0 * (i + 1) as f64,
                relative_uncertainty: Some(0.2),
            })
            .collect();
        Arc::new(Spy {
            params,
            seen: Mutex::new(Vec::new()),
        })
    }

    /// The held parameter runs at its nominal value, the free ones at what
    /// the fit asks; a call with the wrong count is an error, not a run.
    #[test]
    fn held_parameters_run_at_nominal() {
        let inner = spy();
        let p = Pinned::new(inner.clone(), vec![0, 2]).expect("one held");
        assert_eq!(p.held(), ["b"]);
        assert_eq!(
            p.nuisance().iter().map(|n| n.name.as_str()).collect::<Vec<_>>(),
            ["a", "c"]
        );
        p.run(4.0, &[11.0, 33.0], &Effects::default(), 0.1, Keep::Signals)
            .unwrap();
        assert!(p.run(4.0, &[11.0], &Effects::default(), 0.1, Keep::Signals).is_err());
        assert_eq!(*inner.seen.lock().unwrap(), vec![vec![11.0, 20.0, 33.0]]);
    }

    /// Nothing to hold, an unknown index or an unordered list: no wrapper.
    #[test]
    fn refuses_what_holds_nothing_or_is_not_the_models() {
        assert!(Pinned::new(spy(), vec![0, 1, 2]).is_none());
        assert!(Pinned::new(spy(), vec![0, 3]).is_none());
        assert!(Pinned::new(spy(), vec![2, 0]).is_none());
        assert!(Pinned::new(spy(), vec![]).is_some());
    }
}
