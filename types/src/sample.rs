//! One sample-set: the three channels' raw ADC codes.

/// One sample-set as the wire carries it: ADC codes in channel order rear
/// pressure, front pressure, acceleration.
pub type Codes = [u16; 3];

/// One sample-set: raw ADC codes of rear pressure, front pressure, acceleration.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RawSample {
    pub rear: u16,
    pub front: u16,
    pub accel: u16,
}

/// The wire's sample-set: codes in channel order rear, front, accel.
impl From<Codes> for RawSample {
    fn from(c: Codes) -> Self {
        Self {
            rear: c[0],
            front: c[1],
            accel: c[2],
        }
    }
}

impl From<RawSample> for Codes {
    fn from(s: RawSample) -> Self {
        [s.rear, s.front, s.accel]
    }
}
