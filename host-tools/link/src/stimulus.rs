//! The host's end of the emulated board's ADC: a file QEMU uses as the
//! board's PSRAM and this process maps too, holding the ring of ADC codes
//! the board's timer releases at 100 kS/s of guest time. The layout and who
//! writes what are `hammer_wire::stimulus`'s.
//!
//! The host stays ahead of the board and never overwrites a half the board
//! may still read: it writes at most `CAPACITY_SETS − BLOCK_SETS` sample-sets
//! past the board's DMA position, and waits for room otherwise.

use std::fs::{File, OpenOptions};
use std::io;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::time::Duration;

use hammer_estimator::RawSample;
use hammer_wire::stimulus::{self, Header, BLOCK_SETS, CAPACITY_SETS, MAGIC, PSRAM_BYTES, RATE_HZ, VERSION};
use memmap2::MmapMut;

/// The board's counters as last published (see [`Header`] for each).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    pub written_sets: u32,
    pub dma_sets: u32,
    pub consumed_sets: u32,
    pub starved_blocks: u32,
    pub lost_sets: u32,
    pub overruns: u32,
    pub latency_max_us: u32,
    pub uptime_us: u32,
    pub busy_us: u32,
    pub stack_used_bytes: u32,
    pub stack_reserved_bytes: u32,
    pub loop_cycles: u32,
    pub chambers_read: u32,
    pub chambers_unread: u32,
    pub reader_blocks_peak: u32,
    pub reader_blocks_dropped: u32,
    pub report_latency_max_sets: u32,
    pub reader_blocks: u32,
}

/// The shared file and its mapping; removed when dropped.
pub struct Stimulus {
    path: PathBuf,
    /// The mapping's start, taken once from `&mut` so writes need no `&mut self`.
    base: *mut u8,
    _map: MmapMut,
    _file: File,
}

// SAFETY: `base` points into the mapping the struct owns; the mapping is only
// accessed through atomics (header) and volatile writes by one producer at a
// time (`push` is the only writer of the ring).
unsafe impl Send for Stimulus {}
unsafe impl Sync for Stimulus {}

static NEXT_ID: AtomicU32 = AtomicU32::new(0);

impl Stimulus {
    /// Creates the backing file (in /dev/shm when there is one, so it never
    /// touches a disk) and writes an empty stream's header.
    pub fn create() -> io::Result<Self> {
        let dir = if Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        let id = NEXT_ID.fetch_add(1, Ordering::Relaxed);
        let path = dir.join(format!("hammer-stimulus-{}-{id}", std::process::id()));
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(|e| io::Error::new(e.kind(), format!("cannot create {}: {e}", path.display())))?;
        file.set_len(PSRAM_BYTES as u64)?;
        // SAFETY: the file is ours (created above, unique name); QEMU, the
        // only other user, shares it through atomics and the ring protocol.
        let mut map = unsafe { MmapMut::map_mut(&file)? };
        let s = Self {
            path,
            base: map.as_mut_ptr(),
            _map: map,
            _file: file,
        };
        let h = s.header();
        h.version.store(VERSION, Ordering::Relaxed);
        h.capacity_sets.store(CAPACITY_SETS, Ordering::Relaxed);
        h.block_sets.store(BLOCK_SETS, Ordering::Relaxed);
        h.rate_hz.store(RATE_HZ, Ordering::Relaxed);
        s.set_vdda_v(f64::from(hammer_app::supply::NOMINAL_VDDA_V));
        h.magic.store(MAGIC, Ordering::Release);
        Ok(s)
    }

    /// Makes the board's sampling task fault (an undefined instruction) the
    /// next time it asks for samples (see `Header::fault`).
    pub fn fault(&self) {
        self.header().fault.store(1, Ordering::Release);
    }

    /// The board's analog supply from now on: what its ADC will read on the
    /// internal reference channel (a sagging supply raises the code).
    pub fn set_vdda_v(&self, vdda_v: f64) {
        let code = f64::from(stimulus::VREFINT_CAL) * f64::from(hammer_app::supply::VREFINT_CAL_VDDA_V) / vdda_v;
        self.header()
            .vrefint_code
            .store(code.round().clamp(0.0, 4095.0) as u32, Ordering::Relaxed);
    }

    /// QEMU's arguments that make this file the board's PSRAM.
    pub fn qemu_args(&self) -> Vec<String> {
        vec![
            "-object".into(),
            format!(
                "memory-backend-file,id=stimulus,size={}M,mem-path={},share=on",
                PSRAM_BYTES >> 20,
                self.path.display()
            ),
            "-machine".into(),
            "memory-backend=stimulus".into(),
        ]
    }

    fn header(&self) -> &Header {
        // SAFETY: the mapping is PSRAM_BYTES long, page-aligned, and Header
        // (atomics only) fits at HEADER_OFFSET; valid for any bits.
        unsafe { &*(self.base.add(stimulus::HEADER_OFFSET) as *const Header) }
    }

    /// Sample-sets the host may still write before it must wait.
    fn room(&self) -> u32 {
        let h = self.header();
        let ahead = h
            .written_sets
            .load(Ordering::Relaxed)
            .wrapping_sub(h.dma_sets.load(Ordering::Acquire));
        (CAPACITY_SETS - BLOCK_SETS).saturating_sub(ahead)
    }

    /// Appends `sets` to the stream, waiting for room while the ring is
    /// full. Returns `false`, with part of `sets` unwritten, once `stop` is set.
    pub fn push(&self, mut sets: &[RawSample], stop: &AtomicBool) -> bool {
        let h = self.header();
        while !sets.is_empty() {
            if stop.load(Ordering::Relaxed) {
                return false;
            }
            let room = self.room() as usize;
            if room == 0 {
                std::thread::sleep(Duration::from_millis(1));
                continue;
            }
            let n = room.min(sets.len());
            let start = h.written_sets.load(Ordering::Relaxed);
            for (i, s) in sets[..n].iter().enumerate() {
                let at = stimulus::RING_OFFSET + stimulus::slot(start.wrapping_add(i as u32)) * stimulus::SET_BYTES;
                for (k, code) in [s.rear, s.front, s.accel].into_iter().enumerate() {
                    // SAFETY: `at + 2k + 2 <= RING_OFFSET + CAPACITY_SETS * SET_BYTES
                    // <= PSRAM_BYTES` (hammer_wire::stimulus asserts it), 2-aligned;
                    // the board does not read this slot (see `room`).
                    unsafe { std::ptr::write_volatile(self.base.add(at + 2 * k) as *mut u16, code.to_le()) };
                }
            }
            h.written_sets.store(start.wrapping_add(n as u32), Ordering::Release);
            sets = &sets[n..];
        }
        true
    }

    /// Tells the board nothing follows, so it stops counting the missing
    /// halves as a late stimulus.
    pub fn finish(&self) {
        self.header().end_of_stream.store(1, Ordering::Release);
    }

    /// Asks the board to end QEMU (exit status 0) once the stream has ended
    /// and its sampling loop has processed every sample-set written (see
    /// `Header::exit_when_drained`). Only whole DMA halves are ever
    /// processed, so the stream must be a whole number of `BLOCK_SETS`.
    pub fn exit_when_drained(&self) {
        self.header().exit_when_drained.store(1, Ordering::Release);
    }

    /// Fault injection: the board's sampling task stalls `us` µs of guest
    /// time the next time it asks for samples (see `Header::stall_us`).
    pub fn stall(&self, us: u32) {
        self.header().stall_us.store(us, Ordering::Release);
    }

    /// Where the latest overruns (at most `LOST_LOG`) lost samples, oldest
    /// first: (position of the first sample-set lost, how many).
    pub fn losses(&self) -> Vec<(u32, u32)> {
        let h = self.header();
        let n = h.overruns.load(Ordering::Acquire);
        let kept = n.min(stimulus::LOST_LOG as u32);
        (n - kept..n)
            .map(|k| {
                let [from, lost] = &h.lost_log[k as usize % stimulus::LOST_LOG];
                (from.load(Ordering::Relaxed), lost.load(Ordering::Relaxed))
            })
            .collect()
    }

    pub fn counters(&self) -> Counters {
        let h = self.header();
        let l = |a: &AtomicU32| a.load(Ordering::Acquire);
        Counters {
            written_sets: l(&h.written_sets),
            dma_sets: l(&h.dma_sets),
            consumed_sets: l(&h.consumed_sets),
            starved_blocks: l(&h.starved_blocks),
            lost_sets: l(&h.lost_sets),
            overruns: l(&h.overruns),
            latency_max_us: l(&h.latency_max_us),
            uptime_us: l(&h.uptime_us),
            busy_us: l(&h.busy_us),
            stack_used_bytes: l(&h.stack_used_bytes),
            stack_reserved_bytes: l(&h.stack_reserved_bytes),
            loop_cycles: l(&h.loop_cycles),
            chambers_read: l(&h.chambers_read),
            chambers_unread: l(&h.chambers_unread),
            reader_blocks_peak: l(&h.reader_blocks_peak),
            reader_blocks_dropped: l(&h.reader_blocks_dropped),
            report_latency_max_sets: l(&h.report_latency_max_sets),
            reader_blocks: l(&h.reader_blocks),
        }
    }
}

impl Stimulus {
    /// Removes the file's name once the board runs on it (its ADC has
    /// written its uptime, so QEMU has the file mapped; the mapping
    /// outlives the name): a run killed with SIGKILL then leaves nothing in
    /// /dev/shm. True once done.
    pub fn unlink_once_mapped(&self) -> bool {
        if self.header().uptime_us.load(Ordering::Relaxed) == 0 {
            return false;
        }
        match std::fs::remove_file(&self.path) {
            Ok(()) => true,
            Err(e) => e.kind() == io::ErrorKind::NotFound,
        }
    }

    /// Writes `bytes` at the start of the chamber bench's exchange
    /// (`hammer_wire::stimulus::BENCH_OFFSET`), before QEMU starts.
    pub fn write_bench(&self, bytes: &[u8]) -> io::Result<()> {
        if bytes.len() > stimulus::BENCH_BYTES {
            return Err(io::Error::other("bench input larger than its area"));
        }
        for (i, b) in bytes.iter().enumerate() {
            // SAFETY: inside the BENCH area, which lies in the mapping
            // (hammer_wire::stimulus asserts it); QEMU has not started yet.
            unsafe { std::ptr::write_volatile(self.base.add(stimulus::BENCH_OFFSET + i), *b) };
        }
        Ok(())
    }

    /// The chamber bench's exchange as the board left it (read after QEMU ended).
    pub fn read_bench(&self) -> Vec<u8> {
        (0..stimulus::BENCH_BYTES)
            // SAFETY: as in `write_bench`; the board has ended.
            .map(|i| unsafe { std::ptr::read_volatile(self.base.add(stimulus::BENCH_OFFSET + i)) })
            .collect()
    }

    /// The backing file's path (gone once [`Stimulus::unlink_once_mapped`] succeeded).
    pub fn path(&self) -> &Path {
        &self.path
    }
}

impl Drop for Stimulus {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}
