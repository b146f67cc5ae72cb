//! The sidecar reader, typed as the simulator's record (the deepest shape a
//! sidecar has). Invariants: no panic; an accepted sidecar is of this
//! format and no newer version; its simulated configuration serialises back.

use hammer_sim::simulate::SimulationInfo;
use hammer_trace::trace::{parse_sidecar_as, SIDECAR_FORMAT, SIDECAR_VERSION};

use super::{bit, Target};

pub const TARGET: Target = Target {
    name: "sidecar",
    run,
    dict: &[
        b"{",
        b"}",
        b"[",
        b"]",
        b"\"",
        b":",
        b",",
        b"null",
        b"1e400",
        b"-0",
        b"\"format\"",
        b"\"version\"",
        b"\"simulation\"",
        b"\"supply_pressure_bar\"",
        b"\\u0000",
    ],
    seeds,
};

fn run(data: &[u8]) -> u64 {
    let Ok(text) = std::str::from_utf8(data) else {
        return bit(0);
    };
    match parse_sidecar_as::<SimulationInfo>(text, "fuzz.json") {
        Ok(s) => {
            assert_eq!(s.format, SIDECAR_FORMAT);
            assert!(s.version <= SIDECAR_VERSION);
            let mut code = 1;
            if let Some(sim) = &s.simulation {
                serde_json::to_string(&sim.config).expect("a parsed configuration serialises");
                code = 2 + sim.config.validate().is_ok() as u32;
            }
            bit(code) | bit(8 + s.supply_pressure_bar.is_some() as u32)
        }
        Err(e) => {
            // Which part of the message: serde's category is in the text.
            let m = e.to_string();
            let c = [
                "format is",
                "version",
                "missing field",
                "unknown variant",
                "invalid type",
                "EOF",
                "expected",
            ]
            .iter()
            .position(|k| m.contains(k))
            .unwrap_or(7);
            bit(16 + c as u32)
        }
    }
}

/// The simulator's own sidecar (two cycles of truth kept), and the minimal
/// one an outside user writes.
fn seeds() -> Vec<Vec<u8>> {
    let mut cfg = hammer_sim::SimConfig::nominal(5.0);
    cfg.solver.duration_s = 0.12;
    let sim = hammer_sim::simulate::simulate(&cfg).expect("simulates");
    let mut side = sim.sidecar();
    if let Some(s) = side.simulation.as_mut() {
        s.cycles.truncate(2);
    }
    vec![
        serde_json::to_vec_pretty(&side).expect("serialises"),
        br#"{"supply_pressure_bar": 4}"#.to_vec(),
        br#"{"format":"hammer-trace","version":1,"supply_pressure_bar":null,"source":"device"}"#.to_vec(),
    ]
}
