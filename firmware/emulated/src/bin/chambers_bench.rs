//! The chamber characteristics' cost at a cycle's close on the Cortex-M4 ISA
//! (`cargo xtask bench-chambers`; the host's side is
//! `host-tools/benches/chambers_close.rs`).
//!
//! Not a board image: a bench run on the emulated board's machine. The host
//! writes a stream of ADC codes into the ring of its stimulus and the
//! configuration record into the bench's exchange (`hammer_wire::stimulus`,
//! `BENCH_*`), then starts QEMU with `-icount shift=0`, where SysTick's
//! 25 MHz counts 40 instructions a cycle. This binary runs the estimator
//! over the codes as the board's sampling loop would, and at each cycle's
//! close reads the cycle's characteristics from the codes where they lie
//! (`chambers::at_close`), timed on SysTick: with the closed fits' log
//! cache of 12 000 floats, with a room as long as the window, and so with
//! one track, with and without a room. It writes the counts and the
//! reading to the exchange for the host, which checks the reading against
//! its own, and ends QEMU.

#![no_std]
#![no_main]

use core::ptr::{read_volatile, write_volatile};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::SYST;
use cortex_m_rt::entry;
use cortex_m_semihosting::debug;
use hammer_estimator::chambers::at_close::{characterise_cycle, window_samples, Codes, Work};
use hammer_estimator::chambers::{ChamberGeometry, Characteristics, Feed};
use hammer_estimator::{Estimator, RawSample};
use hammer_wire::stimulus::{self, Header, BENCH_RECORD_WORDS, RATE_HZ};

/// The longest cycle read, sample-sets (0.06 s at 100 kS/s), and the log
/// cache's floats (the figure `docs/firmware.md` states).
const LONGEST_CYCLE: usize = 6_000;
const WINDOW: usize = LONGEST_CYCLE + 1 + 800 + 64 + 1;
const LOG_CACHE: usize = 12_000;
/// Cycles read at most: the exchange's room.
const MAX_CYCLES: usize = (stimulus::BENCH_BYTES - stimulus::BENCH_OUTPUT - 4) / (4 * BENCH_RECORD_WORDS);

static mut X_M: [f32; WINDOW] = [0.0; WINDOW];
static mut ROOM: [f32; LOG_CACHE] = [0.0; LOG_CACHE];

// The interrupt half of the vector table: nothing enabled, every line to
// cortex-m-rt's catch-all.
extern "C" {
    fn DefaultHandler();
}
#[link_section = ".vector_table.interrupts"]
#[no_mangle]
static __INTERRUPTS: [unsafe extern "C" fn(); 32] = [DefaultHandler; 32];

fn bench_addr(offset: usize) -> usize {
    stimulus::PSRAM_BASE + stimulus::BENCH_OFFSET + offset
}

fn read_u8(offset: usize) -> u8 {
    // SAFETY: callers stay inside the bench's area of the PSRAM.
    unsafe { read_volatile(bench_addr(offset) as *const u8) }
}

fn write_u32(offset: usize, v: u32) {
    // SAFETY: callers stay inside the bench's area, 4-aligned.
    unsafe { write_volatile(bench_addr(offset) as *mut u32, v) }
}

/// The ring's sample-sets from `start`, `len` of them.
struct Ring {
    start: usize,
    len: usize,
}

impl Codes for Ring {
    fn len(&self) -> usize {
        self.len
    }
    fn get(&self, i: usize) -> RawSample {
        let pos = (self.start + i) as u32;
        let addr = stimulus::PSRAM_BASE + stimulus::RING_OFFSET + stimulus::slot(pos) * stimulus::SET_BYTES;
        // SAFETY: slot() < CAPACITY_SETS: inside the ring, 2-aligned.
        unsafe {
            RawSample {
                rear: read_volatile(addr as *const u16),
                front: read_volatile((addr + 2) as *const u16),
                accel: read_volatile((addr + 4) as *const u16),
            }
        }
    }
}

/// SysTick's 24-bit down-counter, free-running from the core clock.
fn now() -> u32 {
    SYST::get_current()
}

/// Core cycles from `t0` to `t1` (shorter than one wrap, 0.67 s).
fn elapsed(t0: u32, t1: u32) -> u32 {
    t0.wrapping_sub(t1) & 0x00FF_FFFF
}

fn feed_words(f: &Option<Feed>) -> [u32; 10] {
    let v = f.map_or([f32::NAN; 10], |f| {
        [
            f.onset_s,
            f.onset_uncertainty_s,
            f.x_m,
            f.p_rear_pa,
            f.p_front_pa,
            f.closed_exponent,
            f.closed_exponent_uncertainty,
            f.feed_area_m2,
            f.feed_area_uncertainty_m2,
            f.dead_volume_offset_m3,
        ]
    });
    v.map(f32::to_bits)
}

fn same(a: &Option<Characteristics>, b: &Option<Characteristics>) -> bool {
    let words = |c: &Option<Characteristics>| {
        c.map(|c| {
            let ch = c.charge.map_or([f32::NAN; 2], |q| [q.rear_j, q.front_j]);
            (feed_words(&c.front), feed_words(&c.rear), ch.map(f32::to_bits))
        })
    };
    words(a) == words(b)
}

#[entry]
fn main() -> ! {
    let Some(mut core) = cortex_m::Peripherals::take() else {
        fail("core peripherals taken twice")
    };
    core.SYST.set_clock_source(SystClkSource::Core);
    core.SYST.set_reload(0x00FF_FFFF);
    core.SYST.clear_current();
    core.SYST.enable_counter();

    // SAFETY: the PSRAM is always mapped; Header is atomics only.
    let h = unsafe { &*((stimulus::PSRAM_BASE + stimulus::HEADER_OFFSET) as *const Header) };
    let magic = |at: usize| u32::from_le_bytes([0, 1, 2, 3].map(|k| read_u8(at + k)));
    if h.magic.load(core::sync::atomic::Ordering::Acquire) != stimulus::MAGIC || magic(0) != stimulus::BENCH_MAGIC {
        fail("no stimulus or no bench input");
    }
    let mut record = [0u8; hammer_app::persisted::CONFIG_RECORD];
    for (k, b) in record.iter_mut().enumerate() {
        *b = read_u8(stimulus::BENCH_CONFIG + k);
    }
    let Some(cfg) = hammer_app::persisted::config_from_record(&record, Some(RATE_HZ as f32)) else {
        fail("the bench's configuration record does not read")
    };
    let written = h.written_sets.load(core::sync::atomic::Ordering::Acquire) as usize;
    let Ok(mut est) = Estimator::new(cfg) else {
        fail("configuration rejected")
    };
    let geo = ChamberGeometry::of(&cfg);
    if window_samples(LONGEST_CYCLE, cfg.dt_s()) > WINDOW {
        fail("the window outgrows the bench's room");
    }
    // SAFETY: the only references to the two statics, taken once.
    let (x_m, room) = unsafe { (&mut *core::ptr::addr_of_mut!(X_M), &mut *core::ptr::addr_of_mut!(ROOM)) };
    let (mut prev, mut read) = (None, 0usize);
    let ring = Ring { start: 0, len: written };
    for i in 0..written {
        let Some(report) = est.push(ring.get(i)) else {
            continue;
        };
        // The impact's sample: its time is the sample's edge in whole µs.
        let index = ((report.t_impact_us * u64::from(RATE_HZ) + 500_000) / 1_000_000) as usize;
        let open = match prev.replace((report, index)) {
            Some((p, open)) if p.is_valid() && report.is_valid() && report.seq == p.seq.wrapping_add(1) => open,
            _ => continue,
        };
        if read == MAX_CYCLES || index - open > LONGEST_CYCLE {
            continue;
        }
        let codes = Ring {
            start: open,
            len: written - open,
        };
        let close = index - open;
        let mut time = |room: &mut [f32], track_term: bool| {
            let mut work = Work {
                x_m: &mut x_m[..],
                room,
            };
            let t0 = now();
            let c = characterise_cycle(&cfg, &geo, &codes, close, &report, track_term, &mut work);
            (c, elapsed(t0, now()))
        };
        let (cached, t_cached) = time(&mut room[..], true);
        // The room a board would lend: as long as the window (the track's
        // source over the cycle, then the logarithms of a closed phase up
        // to half the window long).
        let window = window_samples(close, cfg.dt_s()).min(LOG_CACHE);
        let (direct, t_direct) = time(&mut room[..window], true);
        let (one, t_one) = time(&mut room[..window], false);
        // No room at all: the track's passes read their source from the
        // codes, the closed fits their logarithms as they go.
        let (bare, t_bare) = time(&mut room[..0], false);
        let c = cached.unwrap_or_default();
        let present = u32::from(cached.is_some())
            | u32::from(c.front.is_some()) << 1
            | u32::from(c.rear.is_some()) << 2
            | u32::from(c.charge.is_some()) << 3
            | u32::from(!same(&cached, &direct)) << 8
            | u32::from(!same(&one, &bare)) << 9;
        let charge = c.charge.map_or([f32::NAN; 2], |q| [q.rear_j, q.front_j]);
        let mut words = [0u32; BENCH_RECORD_WORDS];
        words[..8].copy_from_slice(&[
            report.seq,
            open as u32,
            index as u32,
            present,
            t_cached,
            t_direct,
            t_one,
            t_bare,
        ]);
        words[8..18].copy_from_slice(&feed_words(&c.front));
        words[18..28].copy_from_slice(&feed_words(&c.rear));
        words[28..30].copy_from_slice(&charge.map(f32::to_bits));
        let at = stimulus::BENCH_OUTPUT + 4 + read * 4 * BENCH_RECORD_WORDS;
        for (k, w) in words.iter().enumerate() {
            write_u32(at + 4 * k, *w);
        }
        read += 1;
    }
    write_u32(stimulus::BENCH_OUTPUT, read as u32);
    debug::exit(debug::EXIT_SUCCESS);
    loop {
        cortex_m::asm::wfi();
    }
}

fn fail(why: &str) -> ! {
    cortex_m_semihosting::heprintln!("chambers bench: {}", why);
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    cortex_m_semihosting::heprintln!("panic: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}
