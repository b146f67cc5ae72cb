//! State kept across resets in the last four 2 KiB pages of flash (bank 2 in
//! the factory dual-bank mode), two pages per record kind:
//!
//! | flash offset | address     | use                                |
//! |--------------|-------------|------------------------------------|
//! | 0x7_E000     | 0x0807_E000 | configuration, page A              |
//! | 0x7_E800     | 0x0807_E800 | configuration, page B              |
//! | 0x7_F000     | 0x0807_F000 | wear state, page A                 |
//! | 0x7_F800     | 0x0807_F800 | wear state, page B                 |
//!
//! Each page holds eight 256-byte record slots, written in turn; a page is
//! erased only when the other one is full, so one erase serves eight stores
//! (flash pages endure 10 000 erase cycles). The newest valid record, by
//! sequence number, wins. A reset in the middle of a write leaves at worst a
//! record that fails its CRC (or an ECC error, see the NMI handler) next to
//! the intact previous one; a reset during an erase only ever hits the page
//! that does not hold the newest record.
//!
//! A record is a 16-byte header (magic, sequence number, length, CRC-32 over
//! sequence, length and payload) and the payload, padded to the 8-byte
//! programming unit. Bank 2 is written while the code runs from bank 1
//! (read-while-write), so the DSP keeps running; only the calling task waits.

use core::sync::atomic::{AtomicBool, Ordering};

use defmt::{info, warn};
use embassy_stm32::flash::{self, Blocking, Flash, FLASH_SIZE};
use embassy_stm32::pac;
use embassy_stm32::peripherals::FLASH;
use embassy_stm32::Peri;
use hammer_estimator::wear::crc32;

const PAGE: u32 = 2048;
/// Start of the persisted pages, as an offset from the start of flash.
pub const AREA_OFFSET: u32 = FLASH_SIZE as u32 - 4 * PAGE;
const FLASH_ADDRESS: u32 = 0x0800_0000;

/// A record kind: two pages, alternately written.
pub struct Area {
    first_page: u32,
}

pub const CONFIG: Area = Area {
    first_page: AREA_OFFSET,
};
pub const WEAR: Area = Area {
    first_page: AREA_OFFSET + 2 * PAGE,
};

const MAGIC: [u8; 4] = *b"HMP1";
const HEADER: usize = 16;
const SLOT: usize = 256;
const SLOTS_PER_PAGE: u32 = PAGE / SLOT as u32;
pub const MAX_PAYLOAD: usize = SLOT - HEADER;

#[derive(Debug, defmt::Format)]
pub enum Error {
    Flash(flash::Error),
    TooLarge,
    /// Read back differently from what was written.
    Verify,
}

impl From<flash::Error> for Error {
    fn from(e: flash::Error) -> Self {
        Self::Flash(e)
    }
}

/// Set by the NMI handler when a read hit a double ECC error: a page whose
/// programming was cut short by a reset reads back as that, not as garbage.
static ECC_FAULT: AtomicBool = AtomicBool::new(false);
/// True while `Persist::read` copies a slot: only then is an ECC error
/// expected and survivable.
static READING: AtomicBool = AtomicBool::new(false);

pub struct Persist {
    flash: Flash<'static, Blocking>,
}

/// Where a record lives: page 0 or 1 of its area, slot 0..8 in the page.
#[derive(Clone, Copy, PartialEq, Eq)]
struct Slot {
    page: u32,
    index: u32,
}

impl Slot {
    fn offset(self, area: &Area) -> u32 {
        area.first_page + self.page * PAGE + self.index * SLOT as u32
    }

    fn all() -> impl Iterator<Item = Slot> {
        (0..2).flat_map(|page| (0..SLOTS_PER_PAGE).map(move |index| Slot { page, index }))
    }
}

enum Contents {
    /// Erased: may be programmed.
    Blank,
    Record {
        seq: u32,
        len: usize,
    },
    /// Anything else (cut-short write, ECC error): skipped, never programmed.
    Invalid,
}

impl Persist {
    /// `None` when the pages cannot be used safely: the option bytes select
    /// single-bank mode (4 KiB pages, and embassy's `dual-bank` driver would
    /// panic), or the program image has grown into the persisted pages,
    /// which `memory.x` does not yet keep it out of.
    pub fn new(flash: Peri<'static, FLASH>) -> Option<Self> {
        if !pac::FLASH.optr().read().dbank() {
            warn!("persist: flash is in single-bank mode (DBANK=0); state will not be kept");
            return None;
        }
        extern "C" {
            // End of everything cortex-m-rt places in FLASH (link.x).
            static __veneer_limit: u8;
        }
        // Only the symbol's address is taken; it is never read.
        let image_end = core::ptr::addr_of!(__veneer_limit) as u32;
        if image_end > FLASH_ADDRESS + AREA_OFFSET {
            warn!(
                "persist: program image (ends {=u32:#x}) overlaps the persisted pages",
                image_end
            );
            return None;
        }
        Some(Self {
            flash: Flash::new_blocking(flash),
        })
    }

    /// Reads a slot into `bytes` and classifies it.
    fn read(&mut self, area: &Area, slot: Slot, bytes: &mut [u8; SLOT]) -> Contents {
        ECC_FAULT.store(false, Ordering::SeqCst);
        READING.store(true, Ordering::SeqCst);
        let read = self.flash.blocking_read(slot.offset(area), bytes);
        READING.store(false, Ordering::SeqCst);
        if read.is_err() {
            return Contents::Invalid;
        }
        if ECC_FAULT.swap(false, Ordering::SeqCst) {
            warn!("persist: ECC error in page {} slot {}, skipped", slot.page, slot.index);
            return Contents::Invalid;
        }
        if bytes.iter().all(|&b| b == 0xFF) {
            return Contents::Blank;
        }
        if bytes[..4] != MAGIC {
            return Contents::Invalid;
        }
        let word = |i: usize| u32::from_le_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
        let (seq, len, crc) = (word(4), word(8) as usize, word(12));
        if len > MAX_PAYLOAD || crc32_record(&bytes[4..12], &bytes[HEADER..HEADER + len]) != crc {
            return Contents::Invalid;
        }
        Contents::Record { seq, len }
    }

    /// The valid record with the highest sequence number (compared with
    /// wrap-around, as all live records are within 16 of each other).
    fn newest(&mut self, area: &Area) -> Option<(Slot, u32)> {
        let mut bytes = [0u8; SLOT];
        let mut best: Option<(Slot, u32)> = None;
        for slot in Slot::all() {
            if let Contents::Record { seq, .. } = self.read(area, slot, &mut bytes) {
                if best.is_none_or(|(_, s)| seq.wrapping_sub(s) as i32 > 0) {
                    best = Some((slot, seq));
                }
            }
        }
        best
    }

    /// The newest stored payload, if it has exactly `N` bytes.
    pub fn load<const N: usize>(&mut self, area: &Area) -> Option<[u8; N]> {
        let (slot, _) = self.newest(area)?;
        let mut bytes = [0u8; SLOT];
        let Contents::Record { seq, len } = self.read(area, slot, &mut bytes) else {
            return None;
        };
        if len != N {
            warn!("persist: stored record has {} bytes, expected {}", len, N);
            return None;
        }
        let mut out = [0u8; N];
        out.copy_from_slice(&bytes[HEADER..HEADER + N]);
        info!(
            "persist: loaded record #{} (page {} slot {})",
            seq, slot.page, slot.index
        );
        Some(out)
    }

    /// Stores a new payload in the next blank slot after the newest record;
    /// when its page is full, erases the other page (~22 ms, blocking the
    /// calling task) and starts there. Reads the record back to verify it.
    pub fn store(&mut self, area: &Area, payload: &[u8]) -> Result<(), Error> {
        if payload.len() > MAX_PAYLOAD {
            return Err(Error::TooLarge);
        }
        let newest = self.newest(area);
        let seq = newest.map_or(1, |(_, s)| s.wrapping_add(1));
        let mut scratch = [0u8; SLOT];
        let mut target = None;
        if let Some((at, _)) = newest {
            for index in at.index + 1..SLOTS_PER_PAGE {
                let slot = Slot { page: at.page, index };
                if matches!(self.read(area, slot, &mut scratch), Contents::Blank) {
                    target = Some(slot);
                    break;
                }
            }
        }
        let slot = match target {
            Some(slot) => slot,
            None => {
                // The page not holding the newest record (page 0 if none).
                let page = newest.map_or(0, |(at, _)| 1 - at.page);
                let first = Slot { page, index: 0 };
                self.flash
                    .blocking_erase(first.offset(area), first.offset(area) + PAGE)?;
                first
            }
        };

        let mut record = [0xFFu8; SLOT];
        record[..4].copy_from_slice(&MAGIC);
        record[4..8].copy_from_slice(&seq.to_le_bytes());
        record[8..12].copy_from_slice(&(payload.len() as u32).to_le_bytes());
        record[HEADER..HEADER + payload.len()].copy_from_slice(payload);
        let crc = crc32_record(&record[4..12], payload);
        record[12..16].copy_from_slice(&crc.to_le_bytes());
        let len = (HEADER + payload.len()).next_multiple_of(flash::WRITE_SIZE);
        self.flash.blocking_write(slot.offset(area), &record[..len])?;

        match self.read(area, slot, &mut scratch) {
            Contents::Record { seq: s, .. } if s == seq && scratch[..len] == record[..len] => Ok(()),
            _ => Err(Error::Verify),
        }
    }
}

/// CRC over sequence number, length and payload (not the magic, which only
/// tells an erased or foreign page from a record).
fn crc32_record(seq_len: &[u8], payload: &[u8]) -> u32 {
    let mut buf = [0u8; SLOT];
    buf[..8].copy_from_slice(seq_len);
    buf[8..8 + payload.len()].copy_from_slice(payload);
    crc32(&buf[..8 + payload.len()])
}

/// Flash double-ECC errors raise an NMI (RM0440, "Error code correction").
/// During `Persist::read`, taking note and returning lets it skip the
/// half-written slot instead of the board reset-looping on it. Anything
/// else — an ECC error in the program, clock security, SRAM parity — resets.
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    let eccr = pac::FLASH.eccr().read();
    if eccr.eccd() && READING.load(Ordering::SeqCst) {
        ECC_FAULT.store(true, Ordering::SeqCst);
        // Write-1-to-clear; keep ECCIE and the other flag as they are.
        pac::FLASH.eccr().modify(|w| {
            w.set_eccd(true);
            w.set_eccc(false);
        });
    } else {
        cortex_m::peripheral::SCB::sys_reset();
    }
}
