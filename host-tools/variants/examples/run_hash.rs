//! Times 0.45 s runs of the second family (the base structure and each
//! single variant, four effect sets each) and hashes every output sample's
//! bits and the cycles: a change meant to leave the numerics as they are
//! (a speed-up) must print the same hash before and after.
//! `cargo run --release -p hammer-variants --example run_hash [REPEATS]`
use hammer_sim::effects::Effects;
use hammer_variants::integrate::Stepper;
use hammer_variants::plant::Plant;
use hammer_variants::sensors::FrontEndState;
use hammer_variants::{Structure, VariantParams};
use std::hash::{Hash, Hasher};

fn main() {
    let reps: usize = std::env::args().nth(1).and_then(|a| a.parse().ok()).unwrap_or(1);
    let mut structures = vec![Structure::BASE];
    structures.extend(Structure::singles());
    let specs: [&[&str]; 4] = [
        &[],
        &["coulomb_friction", "accel_zero_shift"],
        &["leakage", "heat_transfer", "valve_delay"],
        &["supply_restriction", "viscous_friction", "pressure_gain_error"],
    ];
    let mut total = std::time::Duration::ZERO;
    let mut h = std::collections::hash_map::DefaultHasher::new();
    let mut runs = 0;
    for _ in 0..reps {
        for (k, s) in structures.iter().enumerate() {
            for (j, sp) in specs.iter().enumerate() {
                let mut e = Effects::default();
                for x in *sp {
                    e.apply_spec(x).unwrap();
                }
                let bar = [4.0, 5.5, 7.0][(k + j) % 3];
                let plant = Plant::new(VariantParams::default(), *s, e, bar);
                let fe = FrontEndState::new(s.front_end, 7);
                let t0 = std::time::Instant::now();
                let mut st = Stepper::new(plant, fe, 7, 0.45, 1e-6, 10);
                let mut n = 0u64;
                st.advance_to(f64::INFINITY, &mut |x| {
                    for v in [
                        x.t_s,
                        x.p_rear_pa,
                        x.p_front_pa,
                        x.accel_mps2,
                        x.x_m,
                        x.v_mps,
                        x.p_rear_true_pa,
                        x.p_front_true_pa,
                        x.spool,
                        x.accel_true_mps2,
                        x.m_rear_kg,
                        x.m_front_kg,
                        x.t_rear_k,
                        x.t_front_k,
                    ] {
                        v.to_bits().hash(&mut h);
                    }
                    n += 1;
                });
                let (a, b, c) = st.finish();
                total += t0.elapsed();
                runs += 1;
                a.to_bits().hash(&mut h);
                b.to_bits().hash(&mut h);
                format!("{c:?}").hash(&mut h);
                n.hash(&mut h);
            }
        }
    }
    println!(
        "runs {runs}  mean {:.2} ms per 0.45 s run  checksum {:016x}",
        total.as_secs_f64() * 1e3 / runs as f64,
        h.finish()
    );
}
