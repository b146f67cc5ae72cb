//! The project configuration (TOML) through parsing, validation and the
//! estimator configuration built from it. Invariants: no panic; what the
//! host validates, the estimator and the wire accept (the device can be
//! sent any configuration the host passes).

use hammer_sim::estimation::estimator_config;
use hammer_sim::SimConfig;
use hammer_trace::config::parse_toml;
use hammer_wire::{encode, DeviceConfig, HostMsg, MAX_FRAME};

use super::{bit, Target};

pub const TARGET: Target = Target {
    name: "config",
    run,
    dict: &[
        b"[hammer]",
        b"[valve]",
        b"[supply]",
        b"[solver]",
        b"[sensors.rear]",
        b"[estimator]",
        b"[effects.",
        b" = ",
        b"\n",
        b"nan",
        b"inf",
        b"-inf",
        b"1e30",
        b"-1",
        b"0",
        b"\"",
        b"true",
    ],
    seeds,
};

fn run(data: &[u8]) -> u64 {
    let text = String::from_utf8_lossy(data);
    let cfg: SimConfig = match parse_toml(&text) {
        Ok(c) => c,
        Err(_) => return bit(0),
    };
    if cfg.validate().is_err() {
        return bit(1);
    }
    let est = match estimator_config(
        &cfg.hammer,
        &cfg.sensors,
        &cfg.estimator,
        1e5,
        Some(cfg.supply.pressure_bar),
    ) {
        Ok(e) => e,
        Err(_) => return bit(2),
    };
    hammer_estimator::Estimator::new(est).expect("a configuration the host built is one the estimator takes");
    let mut buf = [0u8; MAX_FRAME];
    encode(&HostMsg::SetConfig(DeviceConfig::from(&est)), &mut buf).expect("a configuration fits a frame");
    bit(3) | bit(4 + cfg.effects.active().len() as u32)
}

/// The default configuration as TOML, and one with effects and sensors set.
fn seeds() -> Vec<Vec<u8>> {
    let default = SimConfig::default();
    let mut rich = SimConfig::nominal(6.0);
    for name in hammer_sim::effects::EFFECT_NAMES.iter().step_by(2) {
        rich.effects.apply_spec(name).expect("a catalogue effect");
    }
    [default, rich]
        .iter()
        .map(|c| toml::to_string(c).expect("serialises").into_bytes())
        .collect()
}
