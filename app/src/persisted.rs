//! What a board keeps across resets, as bytes: the configuration record both
//! boards store (the reference board in flash, the emulated one in its PSRAM)
//! and how a stored one becomes the configuration again. The storage itself,
//! with its wear levelling and torn-write handling, is the board's.
//!
//! A record stored before protocol 5 holds the configuration without the
//! chambers (`hammer_wire::DeviceConfigV4`): it still reads, with the default
//! chambers (the paper's hammer) added, so a board keeps its calibration
//! and thresholds across the update (its wear state is another record,
//! whose layout did not change). `hammer calibrate` or a `SetConfig` then
//! stores the hammer's own chambers.

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
    let bytes = rec.get(2..2 + len)?;
    // Only where it takes the record's bytes exactly: the current layout is
    // protocol 4's and six f32 after it, so an old record never reads as a
    // new one, and it reads as one with the default chambers' bytes
    // appended (one deserialiser in the image, not one per layout).
    let wire = match whole::<DeviceConfig>(bytes) {
        Some(w) => w,
        None => {
            let mut grown = [0u8; CONFIG_RECORD + CHAMBER_BYTES];
            let default = config_record(&DeviceConfig::from(&Config::default()))?;
            let used = u16::from_le_bytes([default[0], default[1]]) as usize;
            let tail = default.get(2 + used - CHAMBER_BYTES..2 + used)?;
            grown.get_mut(..len)?.copy_from_slice(bytes);
            grown.get_mut(len..len + CHAMBER_BYTES)?.copy_from_slice(tail);
            whole::<DeviceConfig>(&grown[..len + CHAMBER_BYTES])?
        }
    };
    let mut cfg = Config::default().with_device(&wire);
    if let Some(r) = rate_hz {
        cfg.sample_rate_hz = r;
    }
    cfg.validate().ok()?;
    Some(cfg)
}

/// What protocol 5 appended to the configuration: six f32 (postcard writes
/// an f32 as its four bytes).
const CHAMBER_BYTES: usize = 6 * 4;

/// `T` from all of `bytes`, none left over.
fn whole<'a, T: serde::Deserialize<'a>>(bytes: &'a [u8]) -> Option<T> {
    match postcard::take_from_bytes::<T>(bytes) {
        Ok((v, [])) => Some(v),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hammer_wire::DeviceConfigV4;

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

    /// A record an earlier firmware stored (protocol 4's configuration,
    /// written by that firmware's `config_record` into the fixture: a
    /// calibrated board at 5.5 bar with its CUSUM threshold changed) reads
    /// with its calibration and settings, the default chambers added; its
    /// calibration hash, which every report carries, is the one it had.
    #[test]
    fn a_record_from_before_the_chambers_keeps_its_calibration() {
        let old: &[u8; CONFIG_RECORD] = include_bytes!("../tests/data/config-record-protocol4.bin");
        let cfg = config_from_record(old, None).expect("the old record reads");
        let mut expect = Config::default();
        expect.rear.scale *= 1.01;
        expect.front.zero_code += 3.0;
        expect.accel.zero_code -= 1.5;
        expect.supply_pressure_pa = 5.5e5;
        expect.wear.cusum_h = 6.0;
        // The piston's geometry went through the wire's f32.
        expect.geometry = cfg.geometry;
        assert_eq!(cfg, expect);
        assert_eq!(cfg.calibration_hash(), expect.calibration_hash());
        // The old layout's bytes are the fixture's: the frozen struct is
        // what protocol 4 wrote.
        let len = u16::from_le_bytes([old[0], old[1]]) as usize;
        let v4: DeviceConfigV4 = postcard::from_bytes(&old[2..2 + len]).unwrap();
        let mut again = [0u8; CONFIG_RECORD];
        assert_eq!(postcard::to_slice(&v4, &mut again).unwrap().len(), len);
        assert_eq!(&again[..len], &old[2..2 + len]);
        // Stored again, it is a current record, chambers included, and a
        // current record is never read as an old one.
        let rec = config_record(&DeviceConfig::from(&cfg)).unwrap();
        assert!(u16::from_le_bytes([rec[0], rec[1]]) as usize > len);
        assert_eq!(config_from_record(&rec, None).unwrap(), cfg);
        // A torn old record (its length cut short) reads as nothing.
        let mut torn = *old;
        torn[..2].copy_from_slice(&((len - 3) as u16).to_le_bytes());
        assert!(config_from_record(&torn, None).is_none());
    }

    /// A board's own chambers survive its record (none left at the default).
    #[test]
    fn the_chambers_are_stored() {
        let mut cfg = Config::default();
        cfg.chambers.front_dead_m3 = 23e-6;
        cfg.chambers.pressure_group_delay_s = 9e-6;
        cfg.geometry.travel_m = 0.058;
        let back = config_from_record(&config_record(&DeviceConfig::from(&cfg)).unwrap(), None).unwrap();
        assert_eq!(back.chambers, cfg.chambers);
        assert_eq!(back.geometry.travel_m, 0.058);
    }
}
