//! The emulated board at the full 100 kS/s × 3: samples through its ADC model
//! (a ring in the board's PSRAM released by a timer at the reference board's
//! rate and block size), guest time counted in instructions at 125 MIPS, below
//! the STM32G474's 170 MHz. What a bench engineer must be able to trust:
//! nothing lost, every report the host estimator's, and an overrun, when the
//! firmware is late, counted to the sample and handled as the estimator's gap.
//!
//! Needs `qemu-system-arm` and the emulated firmware built (`cargo xtask ci`).

use std::time::{Duration, Instant};

use hammer_app::chambers::{Pipeline, ReaderRoom};
use hammer_estimator::{Config, RawSample};
use hammer_host::client::Client;
use hammer_host::emulator::{firmware_elf, Emulator, Icount};
use hammer_host::soak::{self, SoakArgs};
use hammer_host::stimulus::Stimulus;
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_wire::stimulus::{BLOCK_SETS, RATE_HZ};
use hammer_wire::*;

const T: Duration = Duration::from_secs(30);
/// One DMA half, µs: the most a half may wait for its processing.
const HALF_US: u32 = BLOCK_SETS * 1_000_000 / RATE_HZ;

#[test]
fn half_a_minute_at_full_rate_loses_nothing_and_matches_the_host_bit_for_bit() {
    let soak = soak::run(
        &SoakArgs {
            minutes: 0.5,
            supply_bar: 5.0,
            wear_rate: 0.0,
            seed: 3,
            real_time: false,
            effects: vec![],
        },
        false,
    )
    .expect("soak runs");
    println!("{}", soak.summary());
    assert!(soak.clean(), "{}", soak.summary());
    assert!(soak.hammer_s() >= 30.0, "{}", soak.hammer_s());
    // The paper's hammer at 5 bar beats at about 21 Hz: every cycle reported.
    let rate = soak.reports as f64 / soak.hammer_s();
    assert!((19.0..24.0).contains(&rate), "{rate} reports per second");
    // Real time with room to spare: every half processed well inside the
    // next one, and the core at 125 MIPS busy less than half the time.
    assert!(soak.latency_max_us < HALF_US / 2, "{}", soak.summary());
    assert!(soak.instructions_per_s() < 0.5 * 125e6, "{}", soak.summary());
    assert_eq!(soak.late_stimulus_blocks, 0, "the host kept ahead of the board");
    // The board's own stack measurement, in its status: used, and within its region.
    let s = soak.status.expect("a final status");
    assert!(
        s.stack_used_bytes > 1_000 && s.stack_used_bytes < s.stack_reserved_bytes,
        "stack {} of {}",
        s.stack_used_bytes,
        s.stack_reserved_bytes
    );
}

fn codes(bar: f64, seconds: f64, seed: u64) -> Vec<RawSample> {
    let mut cfg = SimConfig::nominal(bar);
    cfg.solver.duration_s = seconds;
    cfg.seed = seed;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    simulate(&cfg).unwrap().measured.codes
}

fn reports_until(link: &mut Client<std::net::TcpStream>, last_seq: u32) -> Vec<CycleReport> {
    let mut got = vec![];
    let deadline = Instant::now() + T;
    while Instant::now() < deadline {
        if let Some(DeviceMsg::Report(r)) = link.recv(Duration::from_millis(100)).unwrap() {
            got.push(r);
            if r.seq >= last_seq {
                break;
            }
        }
    }
    got
}

fn wire_bytes(r: &CycleReport) -> Vec<u8> {
    postcard::to_allocvec(r).unwrap()
}

/// One run of `samples` (whole DMA halves) that the board ends itself once
/// drained, at one instruction per ns of guest time: the board's counters
/// and every report, as postcard bytes. `disturbed`: the host reads late
/// and a thread burns a core meanwhile.
fn drained_run(samples: &[RawSample], disturbed: bool) -> (hammer_host::stimulus::Counters, Vec<Vec<u8>>) {
    let stimulus = Stimulus::create().unwrap();
    assert!(stimulus.push(samples, &std::sync::atomic::AtomicBool::new(false)));
    stimulus.exit_when_drained();
    stimulus.finish();
    let mut emu = Emulator::start_with(&firmware_elf(), Some(Icount::COUNT), Some(&stimulus))
        .expect("QEMU and the emulated firmware");
    let mut link = Client::new(emu.connect(T).unwrap());
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let burner = disturbed.then(|| {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let mut x = 0u64;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
            }
        })
    });
    if disturbed {
        std::thread::sleep(Duration::from_millis(300));
    }
    let mut reports = vec![];
    // Until QEMU closes the link: the board ended the run.
    while let Ok(m) = link.recv(T) {
        match m {
            Some(DeviceMsg::Report(r)) => reports.push(wire_bytes(&r)),
            Some(_) => {}
            None => panic!("the board neither reported nor ended for {T:?}"),
        }
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    if let Some(b) = burner {
        b.join().unwrap();
    }
    let status = emu.wait_exit(T).unwrap();
    assert!(status.is_some_and(|s| s.success()), "the board ended QEMU: {status:?}");
    (stimulus.counters(), reports)
}

/// The firmware bench's run (`cargo xtask bench-firmware`): with nothing
/// sent to the board and the board ending QEMU itself, every interrupt and
/// the end fall on the same guest instruction, so the sampling loop's count
/// is the same however the host is loaded.
#[test]
fn a_run_the_board_ends_when_drained_counts_the_same_instructions_every_time() {
    let mut samples = codes(5.0, 0.4, 2);
    samples.truncate(samples.len() / BLOCK_SETS as usize * BLOCK_SETS as usize);
    let (quiet, quiet_reports) = drained_run(&samples, false);
    let (busy, busy_reports) = drained_run(&samples, true);
    assert_eq!(
        quiet.consumed_sets,
        samples.len() as u32,
        "every sample-set processed: {quiet:?}"
    );
    assert_eq!((quiet.lost_sets, quiet.starved_blocks), (0, 0), "{quiet:?}");
    assert!(quiet.loop_cycles > 0, "{quiet:?}");
    assert!(
        quiet_reports.len() >= 5,
        "{} reports in 0.4 s at 5 bar",
        quiet_reports.len()
    );
    // The whole header: loop and board cycles, uptime, latency, stack.
    assert_eq!(quiet, busy, "the same run, instruction for instruction");
    assert_eq!(quiet_reports, busy_reports);
}

#[test]
fn a_late_firmware_loses_whole_halves_counted_to_the_sample_as_the_reference_board_would() {
    let samples = codes(6.0, 2.0, 11);
    let stimulus = Stimulus::create().unwrap();
    let never = std::sync::atomic::AtomicBool::new(false);
    assert!(stimulus.push(&samples, &never));
    stimulus.finish();
    let mut emu = Emulator::start_with(&firmware_elf(), Some(Icount::m4_at_125_mips(false)), Some(&stimulus))
        .expect("QEMU and the emulated firmware");
    let mut link = Client::new(emu.connect(T).unwrap());
    link.handshake(T).unwrap();

    // A second into the run, the sampling task stalls for 10 ms: four DMA
    // halves complete meanwhile, and all but the last are overwritten.
    while stimulus.counters().consumed_sets < RATE_HZ {
        std::thread::sleep(Duration::from_millis(1));
    }
    stimulus.stall(10_000);
    let deadline = Instant::now() + T;
    while stimulus.counters().dma_sets < samples.len() as u32 - BLOCK_SETS && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(5));
    }
    let c = stimulus.counters();
    let losses = stimulus.losses();
    // What is lost is whole halves of the ring, less what the task had
    // already taken of the first: at least the 10 ms less the two halves the
    // ring holds, at most a half more. Once back, the task may find the next
    // half already due and lose it too, as it would on the real board.
    assert!((1..=3).contains(&c.overruns), "{c:?}");
    assert_eq!(losses.len(), c.overruns as usize);
    assert_eq!(losses.iter().map(|l| l.1).sum::<u32>(), c.lost_sets);
    for (from, lost) in &losses {
        assert_eq!((from + lost) % BLOCK_SETS, 0, "the board resumes at a half: {losses:?}");
        assert!((RATE_HZ..2 * RATE_HZ).contains(from), "{losses:?}");
    }
    let lost_us = c.lost_sets * (1_000_000 / RATE_HZ);
    assert!(
        (10_000 - 2 * HALF_US..=10_000 + 2 * HALF_US).contains(&lost_us),
        "{lost_us} us lost for a 10 ms stall: {c:?}"
    );

    // The host estimator, told of the same gaps at the same places, reports
    // every cycle exactly as the board did: the loss is counted to the
    // sample, and the estimator's gap handling is the board's.
    // The chambers' reader behind it leaves the cycles around the hole unread.
    let mut host = Pipeline::new(Config::default(), Box::new(ReaderRoom::new())).unwrap();
    let mut expected = vec![];
    let mut at = 0usize;
    for &(from, lost) in &losses {
        host.push_block(&samples[at..from as usize], &mut |r| expected.push(r));
        host.push_gap(lost);
        at = (from + lost) as usize;
    }
    host.push_block(&samples[at..], &mut |r| expected.push(r));
    assert!(host.counters().read >= 3, "{:?}", host.counters());
    let got = reports_until(&mut link, expected.last().unwrap().seq);
    assert_eq!(got.len(), expected.len(), "no report lost");
    for (d, h) in got.iter().zip(&expected) {
        assert_eq!(
            wire_bytes(d),
            wire_bytes(h),
            "cycle {}: board {d:?} vs host {h:?}",
            d.seq
        );
    }
    // The cycle with the hole is flagged (and at most the one after it,
    // while the estimator settles); the first report has no history yet.
    let flagged: Vec<usize> = (1..got.len()).filter(|&k| !got[k].is_valid()).collect();
    assert!(
        !flagged.is_empty() && flagged.len() <= 2 && flagged[flagged.len() - 1] - flagged[0] <= 1,
        "flagged cycles {flagged:?}"
    );

    link.send(&HostMsg::GetStatus).unwrap();
    let (s, _) = link
        .recv_until(T, |m| if let DeviceMsg::Status(s) = m { Some(*s) } else { None })
        .unwrap();
    let s = s.expect("status");
    assert_eq!(
        s.dropped_samples,
        u64::from(c.lost_sets),
        "the app counted what the ADC lost"
    );
    assert_eq!(s.adc_overruns, c.overruns);
}

#[test]
fn a_stuck_sampling_task_is_reset_by_the_supervised_watchdog_which_says_why() {
    let samples = codes(5.0, 8.0, 12);
    let stimulus = Stimulus::create().unwrap();
    assert!(stimulus.push(&samples, &std::sync::atomic::AtomicBool::new(false)));
    stimulus.finish();
    let mut emu = Emulator::start_with(&firmware_elf(), Some(Icount::m4_at_125_mips(false)), Some(&stimulus))
        .expect("QEMU and the emulated firmware");
    let mut link = Client::new(emu.connect(T).unwrap());
    let (info, _) = link.handshake(T).unwrap();
    let status = |link: &mut Client<std::net::TcpStream>| {
        link.send(&HostMsg::GetStatus).unwrap();
        link.recv_until(T, |m| if let DeviceMsg::Status(s) = m { Some(*s) } else { None })
            .unwrap()
            .0
            .expect("status")
    };
    assert_eq!(status(&mut link).reset_cause, ResetCause::PowerOn);
    while stimulus.counters().consumed_sets < RATE_HZ / 2 {
        std::thread::sleep(Duration::from_millis(1));
    }
    // The sampling task hangs for 5 s; interrupts still run, the link task
    // does not (one executor). The watchdog is fed only while every duty
    // checks in: sampling is quiet after 0.5 s, the watchdog strikes within
    // 2 s more, and the board restarts, saying why.
    stimulus.stall(5_000_000);
    let deadline = Instant::now() + T;
    let after = loop {
        assert!(Instant::now() < deadline, "no status after a reset");
        let s = status(&mut link);
        if s.reset_cause != ResetCause::PowerOn {
            break s;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(
        after.reset_cause,
        ResetCause::Watchdog {
            overdue: Duty::Sampling
        }
    );
    assert!(after.uptime_us < 3_000_000, "a fresh boot: {after:?}");
    assert_eq!(after.config_hash, info.config_hash);
    assert!(emu.is_running(), "a reset, not an exit");
    // The restarted board samples on where the DMA stands.
    let before = stimulus.counters().consumed_sets;
    std::thread::sleep(Duration::from_millis(300));
    assert!(
        stimulus.counters().consumed_sets > before,
        "sampling again after the reset"
    );
}

/// A real fault (an undefined instruction in the sampling task): the fault
/// handler records where and why in RAM that survives the reset, resets, and
/// the next boot reports it in every `Status`.
#[test]
fn a_fault_is_recorded_and_reported_after_the_reset() {
    let samples = codes(5.0, 8.0, 13);
    let stimulus = Stimulus::create().unwrap();
    assert!(stimulus.push(&samples, &std::sync::atomic::AtomicBool::new(false)));
    stimulus.finish();
    let mut emu = Emulator::start_with(&firmware_elf(), Some(Icount::m4_at_125_mips(false)), Some(&stimulus))
        .expect("QEMU and the emulated firmware");
    let mut link = Client::new(emu.connect(T).unwrap());
    link.handshake(T).unwrap();
    let status = |link: &mut Client<std::net::TcpStream>| {
        link.send(&HostMsg::GetStatus).unwrap();
        link.recv_until(T, |m| if let DeviceMsg::Status(s) = m { Some(*s) } else { None })
            .unwrap()
            .0
            .expect("status")
    };
    assert_eq!(status(&mut link).reset_cause, ResetCause::PowerOn);
    stimulus.fault();
    let deadline = Instant::now() + T;
    let after = loop {
        assert!(Instant::now() < deadline, "no status after the fault");
        let s = status(&mut link);
        if s.reset_cause != ResetCause::PowerOn {
            break s;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let ResetCause::Fault { pc, cfsr } = after.reset_cause else {
        panic!("not a fault record: {:?}", after.reset_cause);
    };
    // UFSR.UNDEFINSTR (CFSR bit 16): the core says what it was.
    assert_ne!(cfsr & (1 << 16), 0, "CFSR {cfsr:#010x}");
    // The faulting instruction is in the image (the emulated board's code
    // memory starts at 0) and is a UDF (0xDExx, Thumb).
    let elf = std::fs::read(firmware_elf()).unwrap();
    let udf = udf_addresses(&elf);
    assert!(
        udf.contains(&pc),
        "pc {pc:#010x} is not one of the image's UDFs {udf:08x?}"
    );
    assert!(after.uptime_us < 3_000_000, "a fresh boot: {after:?}");
    assert!(emu.is_running(), "a reset, not an exit");
    let before = stimulus.counters().consumed_sets;
    std::thread::sleep(Duration::from_millis(300));
    assert!(
        stimulus.counters().consumed_sets > before,
        "sampling again after the reset"
    );
}

/// Addresses of the Thumb `UDF #imm8` instructions (0xDExx) in the ELF's
/// executable sections.
fn udf_addresses(elf: &[u8]) -> Vec<u32> {
    let u16le = |o: usize| u16::from_le_bytes([elf[o], elf[o + 1]]);
    let u32le = |o: usize| u32::from_le_bytes([elf[o], elf[o + 1], elf[o + 2], elf[o + 3]]);
    let (shoff, shentsize, shnum) = (u32le(32) as usize, u16le(46) as usize, u16le(48) as usize);
    let mut found = vec![];
    for i in 0..shnum {
        let o = shoff + i * shentsize;
        const SHF_EXECINSTR: u32 = 4;
        if u32le(o + 8) & SHF_EXECINSTR == 0 {
            continue;
        }
        let (addr, off, size) = (u32le(o + 12), u32le(o + 16) as usize, u32le(o + 20) as usize);
        for k in (0..size).step_by(2) {
            if elf[off + k + 1] == 0xDE {
                found.push(addr + k as u32);
            }
        }
    }
    found
}
