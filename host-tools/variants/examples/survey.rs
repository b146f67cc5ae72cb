//! Prints each structure's steady cycle at a few supply pressures: what the
//! variant hammers do, before any benchmark uses them.

use hammer_sim::effects::Effects;
use hammer_variants::{generate, Structure, VariantParams};

fn main() {
    let params = VariantParams::default();
    let mut friction = Effects::default();
    friction
        .apply_spec(hammer_sim::effects::EFFECT_NAMES[0])
        .expect("catalogue effect");
    let structures: Vec<Structure> = std::iter::once(Structure::BASE).chain(Structure::singles()).collect();
    println!(
        "{:<28} {:>5} {:>7} {:>8} {:>7} {:>8} {:>8} {:>7} {:>7}",
        "structure", "bar", "cycles", "E_J", "f_Hz", "stroke", "F_str", "F_back", "resid%"
    );
    for s in structures {
        for bar in [4.0, 7.0] {
            let t0 = std::time::Instant::now();
            let g = generate(&params, s, &friction, bar, 0.5, 1);
            let tr = &g.truth;
            let name = if tr.variants.is_empty() {
                "base".to_string()
            } else {
                tr.variants.join("+")
            };
            println!(
                "{:<28} {:>5.1} {:>7} {:>8.3} {:>7.2} {:>8.4} {:>8.2} {:>7.2} {:>7.3}  ({:.2} s)",
                name,
                bar,
                tr.cycles.len(),
                tr.steady(1, |c| c.impact_energy_j).unwrap_or(f64::NAN),
                tr.steady(1, |c| c.frequency_hz).unwrap_or(f64::NAN),
                tr.steady(1, |c| c.stroke_m).unwrap_or(f64::NAN),
                tr.steady(1, |c| c.friction_stroke_n).unwrap_or(f64::NAN),
                tr.steady(1, |c| c.friction_backhaul_n).unwrap_or(f64::NAN),
                100.0 * tr.energy_residual_j / tr.pressure_work_j.abs().max(1e-9),
                t0.elapsed().as_secs_f64()
            );
        }
    }
}
