//! The emulated board's non-volatile storage: a region of its PSRAM past the
//! ADC ring (`hammer_wire::stimulus::NVM_OFFSET`). QEMU keeps RAM through a
//! board reset (a watchdog's, a fault's) and reloads only the program, so
//! what is stored here survives a reset as it would in flash; with the
//! host's backing file it also outlives QEMU. Without that file the PSRAM
//! starts zeroed and holds nothing valid.
//!
//! Two slots per record kind, written in turn; each is a header (magic,
//! sequence number, length, CRC-32 over them and the payload) and the
//! payload. The newest valid slot wins, so a write cut short by a reset
//! leaves the previous record.

use core::ptr::{read_volatile, write_volatile};

use hammer_app::{persisted, Record, Store};
use hammer_estimator::wear::crc32;
use hammer_wire::stimulus::{NVM_BYTES, NVM_OFFSET, PSRAM_BASE};
use hammer_wire::WearBlob;

const SLOT: usize = 256;
const HEADER: usize = 16;
pub const MAX_PAYLOAD: usize = SLOT - HEADER;
const MAGIC: u32 = u32::from_le_bytes(*b"HNV1");
const _: () = assert!(4 * SLOT <= NVM_BYTES && persisted::CONFIG_RECORD <= MAX_PAYLOAD);

fn slot_addr(kind: Record, slot: usize) -> usize {
    let first = match kind {
        Record::Config => 0,
        Record::Wear => 2,
    };
    PSRAM_BASE + NVM_OFFSET + (first + slot) * SLOT
}

fn read_u8(addr: usize) -> u8 {
    // SAFETY: callers stay inside the NVM area, which lies in the PSRAM
    // (asserted in hammer_wire::stimulus); any byte is valid.
    unsafe { read_volatile(addr as *const u8) }
}

fn write_u8(addr: usize, b: u8) {
    // SAFETY: as in `read_u8`; nothing else uses the NVM area.
    unsafe { write_volatile(addr as *mut u8, b) }
}

fn read_u32(addr: usize) -> u32 {
    u32::from_le_bytes([read_u8(addr), read_u8(addr + 1), read_u8(addr + 2), read_u8(addr + 3)])
}

fn write_u32(addr: usize, v: u32) {
    for (i, b) in v.to_le_bytes().into_iter().enumerate() {
        write_u8(addr + i, b);
    }
}

/// A slot's payload when its header and CRC hold: (sequence, payload, length).
fn read_slot(kind: Record, slot: usize) -> Option<(u32, [u8; MAX_PAYLOAD], usize)> {
    let at = slot_addr(kind, slot);
    if read_u32(at) != MAGIC {
        return None;
    }
    let (seq, len, crc) = (read_u32(at + 4), read_u32(at + 8) as usize, read_u32(at + 12));
    if len > MAX_PAYLOAD {
        return None;
    }
    let mut payload = [0u8; MAX_PAYLOAD];
    for (i, b) in payload[..len].iter_mut().enumerate() {
        *b = read_u8(at + HEADER + i);
    }
    (check(seq, &payload[..len]) == crc).then_some((seq, payload, len))
}

fn check(seq: u32, payload: &[u8]) -> u32 {
    let mut buf = [0u8; 4 + MAX_PAYLOAD];
    buf[..4].copy_from_slice(&seq.to_le_bytes());
    buf[4..4 + payload.len()].copy_from_slice(payload);
    crc32(&buf[..4 + payload.len()])
}

/// The newest valid record of `kind`: (sequence, payload, length).
fn newest(kind: Record) -> Option<(u32, [u8; MAX_PAYLOAD], usize)> {
    match (read_slot(kind, 0), read_slot(kind, 1)) {
        (Some(a), Some(b)) => Some(if b.0.wrapping_sub(a.0) as i32 > 0 { b } else { a }),
        (a, b) => a.or(b),
    }
}

/// The payload of the newest valid record of `kind`, if any.
pub fn load(kind: Record) -> Option<([u8; MAX_PAYLOAD], usize)> {
    newest(kind).map(|(_, p, len)| (p, len))
}

fn store(kind: Record, payload: &[u8]) {
    if payload.len() > MAX_PAYLOAD {
        return;
    }
    // Into the slot that does not hold the newest record, with the next sequence.
    let (slot, seq) = match (read_slot(kind, 0), read_slot(kind, 1)) {
        (Some(a), Some(b)) if b.0.wrapping_sub(a.0) as i32 > 0 => (0, b.0.wrapping_add(1)),
        (Some(a), _) => (1, a.0.wrapping_add(1)),
        (None, Some(b)) => (0, b.0.wrapping_add(1)),
        (None, None) => (0, 1),
    };
    let at = slot_addr(kind, slot);
    // The magic last: a slot is valid only once everything else is in place.
    write_u32(at, 0);
    write_u32(at + 4, seq);
    write_u32(at + 8, payload.len() as u32);
    write_u32(at + 12, check(seq, payload));
    for (i, &b) in payload.iter().enumerate() {
        write_u8(at + HEADER + i, b);
    }
    write_u32(at, MAGIC);
}

/// The app's `Store` over the PSRAM area.
pub struct Nvm;

impl Store for Nvm {
    fn store_wear(&mut self, blob: &WearBlob) {
        store(Record::Wear, &blob.bytes);
    }

    fn store_config(&mut self, record: &[u8; persisted::CONFIG_RECORD]) {
        store(Record::Config, record);
    }

    fn failed(&mut self, _: Record) {}
}
