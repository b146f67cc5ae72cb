//! How far a structural benchmark case's hidden effect moves the front
//! feed's onset, read as the diagnosis reads it against the hammer's own
//! record, beside the true shift of the port's opening (the spool passing
//! mid-travel), per operating point (docs/diagnosis.md, "The chamber
//! characteristics and commissioning").
//!
//! Each case's measured and reference traces are generated as
//! `hammer diagnose-bench --structural --reference` makes them, and read
//! twice: with the configuration's dead volumes, and with the dead volumes
//! the reference's closed phases ask for (`Extractor::calibrated`).
//!
//! `cargo run --release -p hammer-host --example feed_shift -- SEED INDEX...`

use hammer_host::diagnose::bench::{draw_case, BenchOptions};
use hammer_host::diagnose::engine::extractor_for;
use hammer_host::diagnose::features::{CycleFeatures, Extractor, Signals, FRONT_FEED};
use hammer_sim::SimConfig;
use hammer_trace::trace::Trace;

fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

fn cycles(ex: &Extractor, t: &Trace, bar: f64) -> Vec<CycleFeatures> {
    ex.cycles(&Signals::of_trace(t, bar))
}

/// The median time from each cycle's opening impact to the nearest spool
/// crossing of mid-travel towards the front feed.
fn true_opening_s(t: &Trace, cycles: &[CycleFeatures]) -> f64 {
    let Some(spool) = t.extra.get("spool") else {
        return f64::NAN;
    };
    let downs: Vec<f64> = (1..spool.len())
        .filter(|&i| spool[i - 1] >= 0.5 && spool[i] < 0.5)
        .map(|i| i as f64 * t.dt_s)
        .collect();
    median(
        cycles
            .iter()
            .filter_map(|c| {
                downs
                    .iter()
                    .map(|d| d - c.t_impact_s)
                    .min_by(|a, b| a.abs().total_cmp(&b.abs()))
            })
            .collect(),
    )
}

fn main() {
    let args: Vec<u64> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let Some((&seed, indices)) = args.split_first() else {
        eprintln!("usage: feed_shift SEED INDEX...");
        std::process::exit(2);
    };
    let nominal = extractor_for(&SimConfig::default());
    println!("front feed shift against the record, ms: configured dead volumes | calibrated on the record | true port opening");
    let bench = BenchOptions::of(seed, true, true);
    for &index in indices {
        let index = index as usize;
        let case = match draw_case(&bench, index) {
            Ok(c) => c,
            Err(e) => {
                println!("case {index}: {e:#}");
                continue;
            }
        };
        let Some((structure, params)) = &case.structural else {
            continue;
        };
        // The record's cycles read with their dead volumes, then calibrated on.
        let reading = Extractor {
            read_dead_volume: true,
            ..nominal
        };
        let record: Vec<CycleFeatures> = case
            .references
            .iter()
            .flat_map(|r| cycles(&reading, &r.trace, r.supply_bar))
            .collect();
        let calibrated = nominal.calibrated(&record);
        let (n, c) = (nominal.chambers.unwrap(), calibrated.chambers.unwrap());
        println!(
            "case {index} {:?} hidden {} — dead volumes front {:.2} → {:.2} cm³, rear {:.2} → {:.2} cm³ (true {:.2}, {:.2})",
            structure.variants(),
            serde_json::to_string(&case.gen.effects).unwrap_or_default(),
            1e6 * n.front_dead_m3,
            1e6 * c.front_dead_m3,
            1e6 * n.rear_dead_m3,
            1e6 * c.rear_dead_m3,
            1e6 * params.front_dead_m3,
            1e6 * params.rear_dead_m3,
        );
        for (m, r) in case.inputs.iter().zip(&case.references) {
            let bar = m.supply_bar;
            let (m, r) = (&m.trace, &r.trace);
            let shift = |ex: &Extractor| {
                let feed = |t: &Trace| median(cycles(ex, t, bar).iter().map(|c| c.values[FRONT_FEED]).collect());
                1e3 * (feed(m) - feed(r))
            };
            let truth =
                1e3 * (true_opening_s(m, &cycles(&nominal, m, bar)) - true_opening_s(r, &cycles(&nominal, r, bar)));
            println!(
                "  {bar:>4} bar  {:+6.2} | {:+6.2} | {:+6.2}",
                shift(&nominal),
                shift(&calibrated),
                truth
            );
        }
    }
}
