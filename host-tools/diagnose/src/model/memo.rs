//! A plant that remembers its runs within one diagnosis.
//!
//! The stages ask the model for some runs more than once (counted: 2.3 %
//! of a structural case's runs at this memory's bound, 7.6 % with no
//! bound), and the model-alone diagnosis that may part a close call asks
//! for runs the record's diagnosis made. Every plant the diagnosis fits is
//! a function of its inputs (the built-in solver has no state between
//! runs; an FMU is reset or instantiated afresh for every run), so a run
//! asked for again is the same bits; with a foreign model at 30 to 65
//! times the built-in one's cost a repeat is worth not running.
//!
//! The key is every input of [`Plant::run`] to the bit; the effects by
//! their serialised table (shortest round-trip floats, so two different
//! values never share a key). Only successful runs are kept: a failure is
//! rare, and a failure that ends the diagnosis must reach
//! [`Plant::fatal`] as it happened. The memory is bounded (the run least
//! recently asked for goes first), and dropped with the diagnosis.

use std::collections::{HashMap, VecDeque};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use super::plant::{Keep, ModelTrace, NuisanceParam, Plant};
use hammer_sim::effects::Effects;

/// At most this many bytes of samples are kept: a 0.45 s built-in run
/// read whole is about 2 MB, its three signals 1 MB. Counted on four
/// cases of the structural benchmark with the record (13 494 runs asked
/// for): 309 repeats at 64 MiB, 333 at 256 MiB, 1025 with no bound (at
/// several GiB a diagnosis): most repeats come soon, and the rest are
/// not worth the memory.
pub const MEMO_BYTES: usize = 64 << 20;

#[derive(Debug, Clone, PartialEq, Eq, Hash)]
struct Key {
    supply_bar: u64,
    nuisance: Vec<u64>,
    effects: String,
    duration_s: u64,
}

#[derive(Debug, Default)]
struct Store {
    /// Each run with what it kept and when it was last asked for.
    runs: HashMap<Key, (Keep, Arc<ModelTrace>, u64)>,
    /// Keys by when they were asked for; an entry whose stamp is not its
    /// run's latest is stale and skipped.
    order: VecDeque<(Key, u64)>,
    bytes: usize,
    clock: u64,
}

impl Store {
    /// Stale entries leave the queue as they reach its front; they are
    /// bounded too, so that a run asked for over and over does not grow it.
    fn compact(&mut self) {
        if self.order.len() > 4 * self.runs.len() + 64 {
            let runs = &self.runs;
            self.order.retain(|(k, s)| runs.get(k).is_some_and(|(_, _, t)| t == s));
        }
    }
}

/// `inner`, each successful run kept and handed out again when asked for
/// with the same inputs.
#[derive(Debug)]
pub struct Memo {
    inner: Arc<dyn Plant>,
    store: Mutex<Store>,
    capacity_bytes: usize,
    asked: AtomicUsize,
    repeats: AtomicUsize,
}

impl Memo {
    pub fn new(inner: Arc<dyn Plant>, capacity_bytes: usize) -> Self {
        Self {
            inner,
            store: Mutex::new(Store::default()),
            capacity_bytes,
            asked: AtomicUsize::new(0),
            repeats: AtomicUsize::new(0),
        }
    }

    /// Runs asked for, and of them the ones handed out again.
    pub fn counts(&self) -> (usize, usize) {
        (self.asked.load(Ordering::Relaxed), self.repeats.load(Ordering::Relaxed))
    }

    fn key(supply_bar: f64, nuisance: &[f64], effects: &Effects, duration_s: f64) -> Option<Key> {
        Some(Key {
            supply_bar: supply_bar.to_bits(),
            nuisance: nuisance.iter().map(|v| v.to_bits()).collect(),
            effects: serde_json::to_string(effects).ok()?,
            duration_s: duration_s.to_bits(),
        })
    }

    fn lookup(&self, key: &Key, keep: Keep) -> Option<Arc<ModelTrace>> {
        let mut store = self.store.lock().unwrap_or_else(|p| p.into_inner());
        store.clock += 1;
        let now = store.clock;
        let (kept, trace, stamp) = store.runs.get_mut(key)?;
        if *kept == Keep::Signals && keep == Keep::All {
            return None;
        }
        *stamp = now;
        let trace = Arc::clone(trace);
        store.order.push_back((key.clone(), now));
        store.compact();
        Some(trace)
    }

    fn keep(&self, key: Key, keep: Keep, trace: Arc<ModelTrace>) {
        let size = bytes_of(&trace);
        if size > self.capacity_bytes {
            return;
        }
        let mut store = self.store.lock().unwrap_or_else(|p| p.into_inner());
        store.clock += 1;
        let now = store.clock;
        if let Some((_, old, _)) = store.runs.insert(key.clone(), (keep, trace, now)) {
            store.bytes -= bytes_of(&old);
        }
        store.order.push_back((key, now));
        store.bytes += size;
        while store.bytes > self.capacity_bytes {
            let Some((oldest, stamp)) = store.order.pop_front() else {
                break;
            };
            if store.runs.get(&oldest).is_some_and(|(_, _, s)| *s == stamp) {
                if let Some((_, t, _)) = store.runs.remove(&oldest) {
                    store.bytes -= bytes_of(&t);
                }
            }
        }
        store.compact();
    }
}

fn bytes_of(t: &ModelTrace) -> usize {
    let motion = t.motion.as_ref().map_or(0, |m| m.x_m.len() + m.v_mps.len());
    8 * (t.p_rear_pa.len() + t.p_front_pa.len() + t.accel_mps2.len() + motion)
}

/// `t` as a run that kept `keep` returns it.
fn as_kept(t: &ModelTrace, keep: Keep) -> ModelTrace {
    match keep {
        Keep::All => t.clone(),
        Keep::Signals => ModelTrace {
            dt_s: t.dt_s,
            p_rear_pa: t.p_rear_pa.clone(),
            p_front_pa: t.p_front_pa.clone(),
            accel_mps2: t.accel_mps2.clone(),
            motion: None,
            impacts: Vec::new(),
        },
    }
}

impl Plant for Memo {
    fn nuisance(&self) -> &[NuisanceParam] {
        self.inner.nuisance()
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
        self.asked.fetch_add(1, Ordering::Relaxed);
        let Some(key) = Self::key(supply_bar, nuisance, effects, duration_s) else {
            return self.inner.run(supply_bar, nuisance, effects, duration_s, keep);
        };
        if let Some(t) = self.lookup(&key, keep) {
            self.repeats.fetch_add(1, Ordering::Relaxed);
            return Ok(as_kept(&t, keep));
        }
        let t = self.inner.run(supply_bar, nuisance, effects, duration_s, keep)?;
        // One copy kept, the run itself handed back.
        self.keep(key, keep, Arc::new(t.clone()));
        Ok(t)
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
    use crate::model::Motion;

    /// A plant that counts its runs and answers with its inputs.
    #[derive(Debug, Default)]
    struct Counting {
        runs: AtomicUsize,
    }

    impl Plant for Counting {
        fn nuisance(&self) -> &[NuisanceParam] {
            &[]
        }
        fn carries(&self, _: &str) -> bool {
            true
        }
        fn run(
            &self,
            supply_bar: f64,
            nuisance: &[f64],
            _: &Effects,
            _: f64,
            keep: Keep,
        ) -> Result<ModelTrace, String> {
            if supply_bar < 0.0 {
                return Err("below ambient".into());
            }
            self.runs.fetch_add(1, Ordering::Relaxed);
            let v = vec![supply_bar + nuisance.iter().sum::<f64>(); 1000];
            Ok(ModelTrace {
                dt_s: 1e-5,
                p_rear_pa: v.clone(),
                p_front_pa: v.clone(),
                accel_mps2: v.clone(),
                motion: (keep == Keep::All).then(|| Motion {
                    x_m: v.clone(),
                    v_mps: v,
                }),
                impacts: Vec::new(),
            })
        }
    }

    fn memo(capacity_bytes: usize) -> (Arc<Counting>, Memo) {
        let inner = Arc::new(Counting::default());
        let m = Memo::new(inner.clone(), capacity_bytes);
        (inner, m)
    }

    #[test]
    fn a_run_asked_again_is_handed_out_not_rerun() {
        let (inner, m) = memo(MEMO_BYTES);
        let fx = Effects::default();
        let a = m.run(5.0, &[1.0, 2.0], &fx, 0.45, Keep::All).unwrap();
        let b = m.run(5.0, &[1.0, 2.0], &fx, 0.45, Keep::All).unwrap();
        assert_eq!(a, b);
        // A run kept whole serves one that keeps the signals only.
        let s = m.run(5.0, &[1.0, 2.0], &fx, 0.45, Keep::Signals).unwrap();
        assert_eq!(
            (s.p_rear_pa.as_slice(), s.motion.as_ref()),
            (a.p_rear_pa.as_slice(), None)
        );
        assert_eq!(inner.runs.load(Ordering::Relaxed), 1);
        assert_eq!(m.counts(), (3, 2));
    }

    #[test]
    fn any_input_that_differs_by_a_bit_is_a_run_of_its_own() {
        let (inner, m) = memo(MEMO_BYTES);
        let fx = Effects::default();
        let mut leak = Effects::default();
        leak.apply_spec("leakage").unwrap();
        let mut more = leak.clone();
        more.apply_spec("leakage:gap_m=2.5000000000000005e-5").unwrap();
        m.run(5.0, &[1.0], &fx, 0.45, Keep::Signals).unwrap();
        m.run(5.0, &[f64::from_bits(1.0f64.to_bits() + 1)], &fx, 0.45, Keep::Signals)
            .unwrap();
        m.run(5.0, &[1.0], &fx, 0.46, Keep::Signals).unwrap();
        m.run(5.5, &[1.0], &fx, 0.45, Keep::Signals).unwrap();
        m.run(5.0, &[1.0], &leak, 0.45, Keep::Signals).unwrap();
        m.run(5.0, &[1.0], &more, 0.45, Keep::Signals).unwrap();
        // Kept with the signals only: a run that wants everything is made.
        m.run(5.0, &[1.0], &fx, 0.45, Keep::All).unwrap();
        assert_eq!(inner.runs.load(Ordering::Relaxed), 7);
        // A failure is not kept: asked again, the plant is asked again.
        assert!(m.run(-1.0, &[1.0], &fx, 0.45, Keep::All).is_err());
        assert_eq!(m.counts(), (8, 0));
    }

    #[test]
    fn the_memory_is_bounded_least_recently_asked_out() {
        // Room for two runs of three signals (1000 samples each).
        let (inner, m) = memo(2 * 3 * 8 * 1000);
        let fx = Effects::default();
        let runs = || inner.runs.load(Ordering::Relaxed);
        m.run(4.0, &[], &fx, 0.45, Keep::Signals).unwrap();
        m.run(5.0, &[], &fx, 0.45, Keep::Signals).unwrap();
        // 4 bar asked again: 5 bar is now the one least recently asked.
        m.run(4.0, &[], &fx, 0.45, Keep::Signals).unwrap();
        m.run(6.0, &[], &fx, 0.45, Keep::Signals).unwrap();
        assert_eq!(runs(), 3);
        m.run(4.0, &[], &fx, 0.45, Keep::Signals).unwrap();
        m.run(6.0, &[], &fx, 0.45, Keep::Signals).unwrap();
        assert_eq!(runs(), 3);
        m.run(5.0, &[], &fx, 0.45, Keep::Signals).unwrap();
        assert_eq!(runs(), 4);
        // One run asked for over and over: the queue stays bounded.
        for _ in 0..1000 {
            m.run(5.0, &[], &fx, 0.45, Keep::Signals).unwrap();
        }
        let store = m.store.lock().unwrap();
        assert!(store.bytes <= 2 * 3 * 8 * 1000);
        assert!(store.order.len() <= 4 * store.runs.len() + 64, "{}", store.order.len());
    }
}
