//! One fuzz target under AFL++ (cargo-afl): `afl-target NAME` reads inputs
//! as AFL gives them. Built by `cargo xtask fuzz --afl NAME`.

fn main() {
    let name = std::env::args().nth(1).unwrap_or_default();
    let Some(target) = hammer_fuzz::targets::by_name(&name) else {
        eprintln!(
            "usage: afl-target NAME (one of: {})",
            hammer_fuzz::targets::TARGETS
                .iter()
                .map(|t| t.name)
                .collect::<Vec<_>>()
                .join(", ")
        );
        std::process::exit(2);
    };
    afl::fuzz!(|data: &[u8]| {
        (target.run)(data);
    });
}
