//! The chamber characteristics the diagnosis reads (its features), on a
//! hammer of the second family of a chosen structure and on the model, with
//! no effect and with a valve delay, a restriction, heat exchange and a
//! leak: which characteristic moves with which effect (docs/diagnosis.md,
//! "The chamber characteristics and commissioning").
//!
//! `cargo run --release -p hammer-host --example chambers_case [-- I J]`,
//! I and J indices into `Structure::singles()` (none: the base hammer).

use hammer_host::diagnose::engine::extractor_for;
use hammer_host::diagnose::features::{
    summarize, Signals, FRONT_AREA, FRONT_EXPONENT, FRONT_FEED, REAR_AREA, REAR_EXPONENT, REAR_FEED,
};
use hammer_sim::effects::Effects;
use hammer_sim::SimConfig;
use hammer_variants::{generate, Structure, VariantParams};
fn main() {
    let singles = Structure::singles();
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let mut s = Structure::BASE;
    for i in &args {
        s = s.with(&singles[*i]);
    }
    println!("{:?}", s.variants());
    let ex = extractor_for(&SimConfig::default());
    for bar in [4.0, 7.0] {
        for spec in [
            "none",
            "valve_delay:tau_s=0.0023",
            "supply_restriction:orifice_diameter_m=0.0024",
            "heat_transfer:h_w_per_m2_k=800",
            "leakage:gap_m=2.8e-5",
        ] {
            let mut e = Effects::default();
            if spec != "none" {
                e.apply_spec(spec).unwrap();
            }
            let g = generate(&VariantParams::default(), s, &e, bar, 1.0, 3);
            let t = &g.trace;
            let c = ex.cycles(&Signals::of_trace(t, bar));
            let m = summarize(&c[2..]);
            println!(
                "{bar} {spec:45} n {:2} front {:+.3} ms rear {:+.3} ms n_f {:.3} n_r {:.3} A_f {:.3e} A_r {:.3e}",
                m.cycles,
                m.mean[FRONT_FEED] * 1e3,
                m.mean[REAR_FEED] * 1e3,
                m.mean[FRONT_EXPONENT],
                m.mean[REAR_EXPONENT],
                m.mean[FRONT_AREA],
                m.mean[REAR_AREA]
            );
        }
    }
    // The model.
    let runner = hammer_host::diagnose::model::ModelRunner::new(SimConfig::default(), ex);
    for bar in [4.0, 7.0] {
        for spec in [
            "none",
            "valve_delay:tau_s=0.0023",
            "supply_restriction:orifice_diameter_m=0.0024",
        ] {
            let mut e = Effects::default();
            if spec != "none" {
                e.apply_spec(spec).unwrap();
            }
            let cand = hammer_host::diagnose::model::Candidate { effects: e };
            let f = runner.features(bar, &cand, None).unwrap();
            println!(
                "model {bar} {spec:45} front {:+.3} ms rear {:+.3} ms n_f {:.3} n_r {:.3} A_f {:.3e} A_r {:.3e}",
                f[FRONT_FEED] * 1e3,
                f[REAR_FEED] * 1e3,
                f[FRONT_EXPONENT],
                f[REAR_EXPONENT],
                f[FRONT_AREA],
                f[REAR_AREA]
            );
        }
    }
}
