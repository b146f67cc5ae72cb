//! What a board keeps across resets, as bytes: the configuration record both
//! boards store (the reference board in flash, the emulated one in its PSRAM)
//! and how a stored one becomes the configuration again. The storage itself,
//! with its wear levelling and torn-write handling, is the board's.

use hammer_estimator::Config;
use hammer_wire::DeviceConfig;

/// Bytes of a configuration record: a little-endian length and the
/// configuration's postcard bytes, zero-padded.
pub const CONFIG_RECORD: usize = 200;

/// The record for `cfg`, or `None` if it does not fit (it always does today;
/// the check keeps a grown configuration from being stored truncated).
pub fn config_record(cfg: &DeviceConfig) -> Option<[u8; CONFIG_RECORD]> {
    let mut rec = [0u8; CONFIG_RECORD];
    let used = postcard::to_slice(cfg, &mut rec[2..]).ok()?.len();
    rec[..2].copy_from_slice(&(used as u16).to_le_bytes());
    Some(rec)
}

/// The configuration a record holds, if it decodes and the estimator
/// accepts it. `rate_hz`: the board's own sample rate, which a stored
/// configuration cannot change (the reference board's timer is set at build).
pub fn config_from_record(rec: &[u8], rate_hz: Option<f32>) -> Option<Config> {
    let len = u16::from_le_bytes([*rec.first()?, *rec.get(1)?]) as usize;
    let wire: DeviceConfig = postcard::from_bytes(rec.get(2..2 + len)?).ok()?;
    let mut cfg = Config::default().with_device(&wire);
    if let Some(r) = rate_hz {
        cfg.sample_rate_hz = r;
    }
    cfg.validate().ok()?;
    Some(cfg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_gives_back_its_configuration_and_garbage_gives_none() {
        let mut cfg = Config::default();
        cfg.rear.scale *= 1.01;
        cfg.front.zero_code += 3.0;
        let wire = DeviceConfig::from(&cfg);
        let rec = config_record(&wire).unwrap();
        let back = config_from_record(&rec, None).unwrap();
        // Compared as bytes: the unset supply pressure is a NaN.
        let bytes = |c: &DeviceConfig| postcard::to_slice(c, &mut [0u8; CONFIG_RECORD]).unwrap().to_vec();
        assert_eq!(bytes(&DeviceConfig::from(&back)), bytes(&wire));
        assert!(config_from_record(&[0xff; CONFIG_RECORD], None).is_none());
        assert!(config_from_record(&[], None).is_none());
        let mut bad = wire;
        bad.sample_rate_hz = -1.0;
        assert!(config_from_record(&config_record(&bad).unwrap(), None).is_none());
    }
}
