//! The estimator's cost on the Cortex-M4 ISA: the emulated board runs under
//! QEMU with `-icount shift=0`, where one instruction is one nanosecond of
//! guest time and the board's SysTick clock therefore counts instructions.
//! The firmware reports the time it spent processing samples (`dsp_busy_us`);
//! ×1000 / samples = instructions per sample-set (the estimator plus the
//! monitor's bookkeeping; the emulator-only frame decoding is not included).
//! `cargo xtask bench-firmware` builds the firmware first and prints sizes.

use std::time::Duration;

use hammer_host::client::Client;
use hammer_host::emulator::{firmware_elf, qemu_available, Emulator};
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_wire::*;

fn main() {
    if !qemu_available() {
        eprintln!("qemu-system-arm not installed: apt-get install -y qemu-system-arm");
        std::process::exit(1);
    }
    let mut emu = Emulator::start(&firmware_elf(), true).expect("emulated firmware (cargo xtask firmware)");
    let mut link = Client::new(emu.connect(Duration::from_secs(20)).expect("connect"));
    let t = Duration::from_secs(60);
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 1.0;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let sim = simulate(&cfg).unwrap();
    let samples = sim.measured.codes;
    let status = |link: &mut Client<_>| {
        link.send(&HostMsg::GetStatus).unwrap();
        link.recv_until(t, |m| if let DeviceMsg::Status(s) = m { Some(*s) } else { None })
            .unwrap()
            .0
            .expect("status")
    };
    let before = status(&mut link);
    for (i, chunk) in samples.chunks(BLOCK_SAMPLES).enumerate() {
        let block = SampleBlock {
            seq: i as u32,
            samples: chunk.iter().map(|s| [s.rear, s.front, s.accel]).collect(),
        };
        link.send(&HostMsg::Samples(block)).unwrap();
        while link.recv(Duration::ZERO).unwrap().is_some() {}
    }
    let mut after = status(&mut link);
    while after.samples < samples.len() as u64 {
        std::thread::sleep(Duration::from_millis(100));
        after = status(&mut link);
    }
    let n = (after.samples - before.samples) as f64;
    let busy_us = (after.dsp_busy_us - before.dsp_busy_us) as f64;
    println!(
        "firmware on the Cortex-M4 ISA (QEMU -icount shift=0): {:.1} instructions per sample-set over {} sample-sets, {} cycles ({} valid)",
        busy_us * 1000.0 / n,
        n as u64,
        after.cycles - before.cycles,
        (after.cycles - before.cycles) - (after.invalid_cycles - before.invalid_cycles)
    );
    println!(
        "at 100 kS/s that is {:.1} M instructions/s of the STM32G474's 170 MHz (one instruction per cycle assumed: a lower bound on the cost)",
        busy_us * 1000.0 / n * 1e5 / 1e6
    );
}
