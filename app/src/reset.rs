//! The reset cause as a board keeps it across a reset: four words in RAM
//! that the startup code does not initialise (`.uninit`), written just
//! before the reset (by the watchdog's feeder, a fault handler) and read once
//! at boot. RAM holds its contents through a reset but not through a power
//! cut, when it comes up as noise: a magic word and a check word tell a
//! record from noise, so noise reads as a power-on.

use hammer_wire::{Duty, ResetCause};

/// The record's size in words.
pub const WORDS: usize = 4;

const MAGIC: u32 = 0x5245_5345; // "ESER"
const KIND_WATCHDOG: u32 = 1;
const KIND_FAULT: u32 = 2;

/// The words that record `cause` (a power-on records nothing: all zero).
pub fn encode(cause: ResetCause) -> [u32; WORDS] {
    let (kind, a, b) = match cause {
        ResetCause::PowerOn => return [0; WORDS],
        ResetCause::Watchdog { overdue } => (
            KIND_WATCHDOG,
            match overdue {
                Duty::Sampling => 0,
                Duty::Link => 1,
                Duty::Persistence => 2,
            },
            0,
        ),
        ResetCause::Fault { pc, cfsr } => (KIND_FAULT, pc, cfsr),
    };
    [MAGIC ^ kind, a, b, check(kind, a, b)]
}

/// The cause recorded in `words`, or a power-on for anything else.
pub fn decode(words: [u32; WORDS]) -> ResetCause {
    let kind = words[0] ^ MAGIC;
    let (a, b) = (words[1], words[2]);
    if words[3] != check(kind, a, b) {
        return ResetCause::PowerOn;
    }
    match (kind, a) {
        (KIND_WATCHDOG, 0) => ResetCause::Watchdog {
            overdue: Duty::Sampling,
        },
        (KIND_WATCHDOG, 1) => ResetCause::Watchdog { overdue: Duty::Link },
        (KIND_WATCHDOG, 2) => ResetCause::Watchdog {
            overdue: Duty::Persistence,
        },
        (KIND_FAULT, _) => ResetCause::Fault { pc: a, cfsr: b },
        _ => ResetCause::PowerOn,
    }
}

fn check(kind: u32, a: u32, b: u32) -> u32 {
    (kind ^ 0xA5A5_5A5A).rotate_left(7) ^ a.rotate_left(13) ^ b.rotate_left(21) ^ MAGIC
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn causes_round_trip_and_noise_or_zeros_read_as_power_on() {
        for cause in [
            ResetCause::Watchdog {
                overdue: Duty::Sampling,
            },
            ResetCause::Watchdog { overdue: Duty::Link },
            ResetCause::Watchdog {
                overdue: Duty::Persistence,
            },
            ResetCause::Fault {
                pc: 0x0800_1234,
                cfsr: 0x8200,
            },
        ] {
            assert_eq!(decode(encode(cause)), cause);
        }
        assert_eq!(decode([0; WORDS]), ResetCause::PowerOn);
        assert_eq!(decode(encode(ResetCause::PowerOn)), ResetCause::PowerOn);
        // RAM after a power cut: any single flipped bit of a record is caught.
        let rec = encode(ResetCause::Watchdog { overdue: Duty::Link });
        for w in 0..WORDS {
            for bit in 0..32 {
                let mut noisy = rec;
                noisy[w] ^= 1 << bit;
                assert_ne!(
                    decode(noisy),
                    ResetCause::Watchdog { overdue: Duty::Link },
                    "word {w} bit {bit}"
                );
            }
        }
        let mut x = 0x1234_5678u32;
        let mut noise_causes = 0;
        for _ in 0..10_000 {
            let mut words = [0; WORDS];
            for w in &mut words {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                *w = x;
            }
            noise_causes += usize::from(decode(words) != ResetCause::PowerOn);
        }
        assert_eq!(noise_causes, 0, "random RAM never reads as a recorded cause");
    }
}
