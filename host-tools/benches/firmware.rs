//! The estimator's cost on the Cortex-M4 ISA: the emulated board runs under
//! QEMU with `-icount shift=0`, where one instruction is one nanosecond of
//! guest time and the board's SysTick clock therefore counts instructions.
//! Samples go through the board's ADC model in the reference board's 256-set
//! DMA halves (`hammer_wire::stimulus`), so the per-block costs are the real
//! board's. The firmware reports the time its sampling loop spent
//! (`dsp_busy_us`: the estimator, the monitor's bookkeeping, the copy out of
//! the DMA ring); ×1000 / samples = instructions per sample-set. The board's
//! whole busy time (interrupts and link included) is reported beside it.
//! `cargo xtask bench-firmware` builds the firmware first and prints sizes.

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use hammer_host::client::Client;
use hammer_host::emulator::{firmware_elf, qemu_available, Emulator, Icount};
use hammer_host::stimulus::Stimulus;
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_wire::stimulus::{BLOCK_SETS, RATE_HZ};
use hammer_wire::*;

fn main() {
    if !qemu_available() {
        eprintln!("qemu-system-arm not installed: apt-get install -y qemu-system-arm");
        std::process::exit(1);
    }
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 2.0;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let samples = simulate(&cfg).unwrap().measured.codes;
    let delivered = (samples.len() / BLOCK_SETS as usize * BLOCK_SETS as usize) as u64;

    let stimulus = Stimulus::create().expect("stimulus file");
    assert!(stimulus.push(&samples, &AtomicBool::new(false)));
    stimulus.finish();
    let mut emu = Emulator::start_with(&firmware_elf(), Some(Icount::COUNT), Some(&stimulus))
        .expect("emulated firmware (cargo xtask firmware)");
    let mut link = Client::new(emu.connect(Duration::from_secs(20)).expect("connect"));
    link.handshake(Duration::from_secs(20)).expect("handshake");
    let deadline = Instant::now() + Duration::from_secs(120);
    let status = loop {
        link.send(&HostMsg::GetStatus).unwrap();
        let (s, _) = link
            .recv_until(Duration::from_secs(20), |m| {
                if let DeviceMsg::Status(s) = m {
                    Some(*s)
                } else {
                    None
                }
            })
            .unwrap();
        let s = s.expect("status");
        if s.samples >= delivered || Instant::now() > deadline {
            break s;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let c = stimulus.counters();
    let n = status.samples as f64;
    let per_set = status.dsp_busy_us as f64 * 1000.0 / n;
    println!(
        "firmware on the Cortex-M4 ISA (QEMU -icount shift=0): {per_set:.1} instructions per sample-set \
         over {} sample-sets in 256-set DMA halves, {} cycles ({} valid), {} dropped",
        status.samples,
        status.cycles,
        status.cycles - status.invalid_cycles,
        status.dropped_samples
    );
    let hammer_s = f64::from(c.consumed_sets) / f64::from(RATE_HZ);
    println!(
        "stack: {} B at the deepest of {} B reserved (margin {} B), measured from the painted stack",
        c.stack_used_bytes,
        c.stack_reserved_bytes,
        c.stack_reserved_bytes.saturating_sub(c.stack_used_bytes)
    );
    println!(
        "at 100 kS/s: sampling loop {:.1} M instructions/s, whole board {:.1} M instructions/s \
         ({:.1} % of the STM32G474's 170 MHz at one instruction per cycle, a lower bound on the cost)",
        per_set * f64::from(RATE_HZ) / 1e6,
        f64::from(c.busy_us) * 1e3 / hammer_s.max(1e-9) / 1e6,
        f64::from(c.busy_us) * 1e3 / hammer_s.max(1e-9) / 170e6 * 100.0
    );
}
