//! Writes variant traces for a quick look: `write_case DIR STRUCTURE_INDEX|base FRICTION(0|1) BAR...`
use hammer_sim::effects::{CoulombFriction, Effects};
use hammer_variants::{generate, Structure, VariantParams};

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let dir = std::path::PathBuf::from(&a[0]);
    std::fs::create_dir_all(&dir).unwrap();
    let s = if a[1] == "base" {
        Structure::BASE
    } else {
        Structure::singles()[a[1].parse::<usize>().unwrap()]
    };
    let mut e = Effects::default();
    if a[2] == "1" {
        e.coulomb_friction = Some(CoulombFriction::default());
    }
    for bar in &a[3..] {
        let b: f64 = bar.parse().unwrap();
        let g = generate(&VariantParams::default(), s, &e, b, 0.5, 4);
        g.write(&dir.join(format!("p{bar}.csv"))).unwrap();
    }
}
