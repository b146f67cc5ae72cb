//! Which duties of the firmware are alive, for a watchdog that is fed only
//! while all of them are.
//!
//! Feeding a watchdog from one task proves only that this task runs. Here
//! each supervised duty (the sampling loop, the link, persistence) checks in
//! ([`Supervisor::beat`]) as it works, and whatever feeds the hardware
//! watchdog asks [`Watch::tick`] first: a duty that has not checked in within
//! its period stops the feeding and is named, so the board can record why it
//! is about to be reset. Beats are counters, not timestamps, so the tasks
//! need no clock; the watch's ticks give the time.

use core::sync::atomic::{AtomicU32, Ordering};

pub use hammer_wire::Duty;

/// The duties, in the order of [`Supervisor`]'s counters.
pub const DUTIES: [Duty; 3] = [Duty::Sampling, Duty::Link, Duty::Persistence];

const fn index(d: Duty) -> usize {
    match d {
        Duty::Sampling => 0,
        Duty::Link => 1,
        Duty::Persistence => 2,
    }
}

/// Check-in counters, one per duty; `const`-constructible for a `static`.
pub struct Supervisor {
    beats: [AtomicU32; DUTIES.len()],
}

impl Supervisor {
    pub const fn new() -> Self {
        Self {
            beats: [const { AtomicU32::new(0) }; DUTIES.len()],
        }
    }

    /// `duty` is alive.
    pub fn beat(&self, duty: Duty) {
        self.beats[index(duty)].fetch_add(1, Ordering::Relaxed);
    }

    fn count(&self, duty: Duty) -> u32 {
        self.beats[index(duty)].load(Ordering::Relaxed)
    }
}

impl Default for Supervisor {
    fn default() -> Self {
        Self::new()
    }
}

/// The feeder's view: how many of its ticks each duty has been quiet.
pub struct Watch {
    /// Ticks a duty may stay quiet; `None`: not supervised on this board.
    limits: [Option<u32>; DUTIES.len()],
    seen: [u32; DUTIES.len()],
    quiet: [u32; DUTIES.len()],
}

impl Watch {
    /// `limits[duty]`: ticks of the feeder's period a duty may go without a
    /// beat, in [`DUTIES`] order; `None` for a duty this board does not have.
    pub const fn new(limits: [Option<u32>; DUTIES.len()]) -> Self {
        Self {
            limits,
            seen: [0; DUTIES.len()],
            quiet: [0; DUTIES.len()],
        }
    }

    /// Called once per feeder period: `Ok` to feed the watchdog, or the
    /// first duty that has been quiet for longer than its limit.
    pub fn tick(&mut self, sup: &Supervisor) -> Result<(), Duty> {
        let mut overdue = None;
        for (i, duty) in DUTIES.into_iter().enumerate() {
            let count = sup.count(duty);
            if count != self.seen[i] {
                self.seen[i] = count;
                self.quiet[i] = 0;
            } else {
                self.quiet[i] = self.quiet[i].saturating_add(1);
            }
            if let Some(limit) = self.limits[i] {
                if self.quiet[i] > limit && overdue.is_none() {
                    overdue = Some(duty);
                }
            }
        }
        overdue.map_or(Ok(()), Err)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quiet_duty_stops_the_feeding_and_is_named_and_unsupervised_ones_never_do() {
        let sup = Supervisor::new();
        let mut watch = Watch::new([Some(2), Some(5), None]);
        for _ in 0..10 {
            sup.beat(Duty::Sampling);
            sup.beat(Duty::Link);
            assert_eq!(watch.tick(&sup), Ok(()));
        }
        // Sampling stops: two quiet ticks are allowed, the third is not.
        sup.beat(Duty::Link);
        assert_eq!(watch.tick(&sup), Ok(()));
        sup.beat(Duty::Link);
        assert_eq!(watch.tick(&sup), Ok(()));
        sup.beat(Duty::Link);
        assert_eq!(watch.tick(&sup), Err(Duty::Sampling));
        // It comes back: fed again at once.
        sup.beat(Duty::Sampling);
        sup.beat(Duty::Link);
        assert_eq!(watch.tick(&sup), Ok(()));
        // The link goes quiet for longer than its own limit.
        for k in 0..7 {
            sup.beat(Duty::Sampling);
            let r = watch.tick(&sup);
            assert_eq!(r.is_err(), k >= 5, "tick {k}: {r:?}");
        }
    }
}
