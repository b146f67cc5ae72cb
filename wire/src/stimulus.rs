//! The emulated board's ADC, as a ring of sample-sets in memory both sides map.
//!
//! The reference board's ADC + DMA fill a ring at 100 kS/s × 3 whatever the
//! CPU does; the UART of QEMU's mps2-an386 carries about 40 KB/s, a fifteenth
//! of that. So on the emulated board the host writes the ADC's codes into the
//! board's 16 MiB PSRAM, which QEMU backs with a file the host maps too
//! (`-object memory-backend-file,share=on` + `-machine memory-backend=…`),
//! and a timer in the board plays the DMA: every [`Header::block_sets`]
//! sample-sets of guest time it completes one half of a notional two-half DMA
//! ring and interrupts. The firmware then reads that half under the reference
//! board's rule: a half stays intact until the next half completes, so
//! reading it later is an overrun, counted as lost samples.
//!
//! The layout is here, once, for the board (`firmware/emulated/src/adc.rs`)
//! and the host (`host-tools/link/src/stimulus.rs`). Positions are free-running
//! `u32` counts of sample-sets that wrap (11.9 h at 100 kS/s); only their
//! differences are used, and [`CAPACITY_SETS`] divides 2^32, so a position
//! modulo the capacity is its slot in the ring.
//!
//! Who writes what: the host writes the samples, then `written_sets`
//! (release), `end_of_stream`, `stall_us`, `vrefint_code` and `fault`; the board
//! writes every other counter.
//! `magic` is written last by the host, so a board that finds it finds a
//! complete header; a board started without the backing file finds zeros and
//! takes its samples from the UART instead.

use core::sync::atomic::AtomicU32;

/// Where the board's PSRAM (QEMU's machine RAM, `mps.ram`) starts.
pub const PSRAM_BASE: usize = 0x2100_0000;
/// Its size; the backing file must have exactly this size.
pub const PSRAM_BYTES: usize = 16 * 1024 * 1024;
/// The header's place in the PSRAM; the ring follows at [`RING_OFFSET`].
pub const HEADER_OFFSET: usize = 0;
pub const RING_OFFSET: usize = 4096;
/// Sample-sets in the ring: 2^21, 21 s at 100 kS/s, 12 MiB of codes.
pub const CAPACITY_SETS: u32 = 1 << 21;
/// Bytes per sample-set in the ring: rear, front, accel as little-endian u16,
/// the order the reference board's ADC scan writes them.
pub const SET_BYTES: usize = 6;
/// "HSTM", little-endian.
pub const MAGIC: u32 = u32::from_le_bytes(*b"HSTM");
/// Bumped on any change of the header's layout or meaning.
pub const VERSION: u32 = 5;
/// The reference board's DMA half-buffer (firmware/src/sampler.rs), so the
/// emulated board sees the same block size and has the same slack.
pub const BLOCK_SETS: u32 = 256;
/// The reference board's sample rate.
pub const RATE_HZ: u32 = 100_000;
/// The emulated board's core clock (the mps2-an386's SYSCLK), which its
/// SysTick and TIMER0 count: the unit of [`Header::loop_cycles`]. Under
/// QEMU's `-icount shift=0` (1 ns of guest time per instruction) one cycle
/// is 40 instructions.
pub const SYSCLK_HZ: u32 = 25_000_000;

/// The emulated board's non-volatile area, past the ring: QEMU keeps RAM
/// through a board reset, and the host's backing file keeps it beyond QEMU.
pub const NVM_OFFSET: usize = 13 * 1024 * 1024;
pub const NVM_BYTES: usize = 64 * 1024;

/// The chamber bench's exchange (`hammer-chambers-bench`, `cargo xtask
/// bench-chambers`), between the ring and the NVM area: the host writes its
/// input (the configuration record) before QEMU starts, the bench board
/// writes its figures and readings there before it ends QEMU. The sampling
/// firmware never touches it.
pub const BENCH_OFFSET: usize = 12 * 1024 * 1024 + 64 * 1024;
pub const BENCH_BYTES: usize = 64 * 1024;

/// The bench's input: "HBCH" little-endian, then the configuration record
/// (`hammer_app::persisted::config_record`) at [`BENCH_CONFIG`].
pub const BENCH_MAGIC: u32 = u32::from_le_bytes(*b"HBCH");
pub const BENCH_CONFIG: usize = 4;
/// The bench's output, from this offset in its area: the number of cycles
/// read (u32), then per cycle [`BENCH_RECORD_WORDS`] little-endian u32:
/// the report's sequence number, the opening and closing impact's sample
/// index, which readings were found (bit 0 any, 1 front, 2 rear, 3 charge,
/// 8 the reading in the smaller room differed), the core cycles of the
/// reading with the log cache, with a room as long as the window, and so
/// with one track (the accelerometer's, no widening), a spare word; then the reading's 22
/// values as f32 bits: per feed (front, rear) its ten fields in
/// declaration order, then the charge's two.
pub const BENCH_OUTPUT: usize = 4096;
pub const BENCH_RECORD_WORDS: usize = 8 + 22;

const _: () = assert!(RING_OFFSET + CAPACITY_SETS as usize * SET_BYTES <= BENCH_OFFSET);
const _: () = assert!(BENCH_OFFSET + BENCH_BYTES <= NVM_OFFSET);
const _: () = assert!(NVM_OFFSET + NVM_BYTES <= PSRAM_BYTES);
const _: () = assert!(CAPACITY_SETS.is_power_of_two() && CAPACITY_SETS % BLOCK_SETS == 0);
const _: () = assert!(core::mem::size_of::<Header>() <= RING_OFFSET);

/// Overruns the header remembers where they happened.
pub const LOST_LOG: usize = 8;

/// The shared header. `repr(C)` and only 32-bit atomics, which both the
/// Cortex-M4 and the host have, so each side reads whole values.
#[repr(C)]
pub struct Header {
    /// [`MAGIC`] once the host has filled the header.
    pub magic: AtomicU32,
    pub version: AtomicU32,
    /// Ring length in sample-sets ([`CAPACITY_SETS`]).
    pub capacity_sets: AtomicU32,
    /// Sample-sets per DMA half ([`BLOCK_SETS`]).
    pub block_sets: AtomicU32,
    /// Sample rate the board's timer reproduces.
    pub rate_hz: AtomicU32,
    /// Host: sample-sets written so far.
    pub written_sets: AtomicU32,
    /// Host: non-zero once nothing follows `written_sets`.
    pub end_of_stream: AtomicU32,
    /// Board: sample-sets the "DMA" has completed (whole halves).
    pub dma_sets: AtomicU32,
    /// Board: halves the timer had to skip because the host had not written
    /// them yet. Not the firmware's fault: the stimulus was late, and the
    /// samples are only delayed, never lost. Non-zero invalidates timing figures.
    pub starved_blocks: AtomicU32,
    /// Board: sample-sets handed to the app.
    pub consumed_sets: AtomicU32,
    /// Board: sample-sets lost to overruns (the app was too late for a half).
    pub lost_sets: AtomicU32,
    /// Board: overrun events.
    pub overruns: AtomicU32,
    /// Board: the longest time from a half's completion to the end of its
    /// processing, in microseconds of guest time.
    pub latency_max_us: AtomicU32,
    /// Board: guest time since boot, µs (wraps after 71 min; use differences).
    pub uptime_us: AtomicU32,
    /// Board: of that, time the core was not idle, µs (wraps likewise).
    pub busy_us: AtomicU32,
    /// Board: the latest [`LOST_LOG`] overruns, overrun number `n` at
    /// `n % LOST_LOG`: the position of the first sample-set lost, and how many.
    pub lost_log: [[AtomicU32; 2]; LOST_LOG],
    /// Board: the deepest its stack has been, and the stack region's size,
    /// bytes (measured about once a second from the painted stack).
    pub stack_used_bytes: AtomicU32,
    pub stack_reserved_bytes: AtomicU32,
    /// Host: fault injection. The board's sampling task, the next time it
    /// asks for samples, stays busy this long (µs of guest time) and clears
    /// it: a firmware that is late, to show the overrun it causes.
    pub stall_us: AtomicU32,
    /// Host: what the ADC reads on the internal reference channel, 12-bit
    /// code: the host's model of the board's analog supply (VDDA =
    /// 3.0 V · [`VREFINT_CAL`] / code). 0: no reference, not measured.
    pub vrefint_code: AtomicU32,
    /// Board: core cycles ([`SYSCLK_HZ`]) the sampling loop spent on the
    /// sample blocks it was handed, each from its hand-over to the loop's
    /// next read (the app's processing, the plumbing around it and whatever
    /// interrupt fell in between); wraps. Over the blocks only, so the
    /// loop's idle turns (no samples, a command) are not in it.
    pub loop_cycles: AtomicU32,
    /// Host: non-zero asks the board to end QEMU (semihosting exit, status
    /// 0) as soon as the stream has ended (`end_of_stream`) and the sampling
    /// loop has processed every sample-set written: under `-icount` such a
    /// run ends at the same guest instruction every time, whatever the host
    /// does meanwhile (the firmware bench).
    pub exit_when_drained: AtomicU32,
    /// Host: fault injection. Non-zero: the board's sampling task, the next
    /// time it asks for samples, clears it and executes an undefined
    /// instruction, to show the fault record a real fault leaves.
    pub fault: AtomicU32,
    /// Board: the chambers' reader (`hammer_app::chambers`): cycles read,
    /// reports sent unread, the most sample blocks ever waiting for it and
    /// the blocks it never got (none free when the sampling task read).
    pub chambers_read: AtomicU32,
    pub chambers_unread: AtomicU32,
    pub reader_blocks_peak: AtomicU32,
    pub reader_blocks_dropped: AtomicU32,
    /// Board: the longest a report waited from its impact to leaving the
    /// chambers' reader, sample-sets.
    pub report_latency_max_sets: AtomicU32,
    /// Board: how many sample blocks it keeps for the chambers' reader
    /// (version 5: the emulated board keeps more than the reference one).
    pub reader_blocks: AtomicU32,
}

/// The emulated chip's factory calibration of its internal reference, the
/// code it read at VDDA = 3.0 V (a typical STM32G474's; the reference board
/// reads its own from system memory).
pub const VREFINT_CAL: u16 = 1655;

/// The ring slot of sample-set position `pos`.
pub const fn slot(pos: u32) -> usize {
    (pos % CAPACITY_SETS) as usize
}
