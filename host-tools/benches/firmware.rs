//! The estimator's cost on the Cortex-M4 ISA: the emulated board runs under
//! QEMU with `-icount shift=0`, where one instruction is one nanosecond of
//! guest time and the board's SysTick clock (25 MHz) therefore counts 40
//! instructions a cycle. `cargo xtask bench-firmware` builds the firmware
//! and the profiling plugin first and prints sizes.
//!
//! The run is the same on every host and under any load: a fixed stream
//! (2 s of the paper's hammer at 5 bar with its friction, a whole number of
//! the reference board's 256-set DMA halves, `hammer_wire::stimulus`) is in
//! the board's ADC ring before QEMU starts; the host sends the board
//! nothing (its reports are only read), and the board ends QEMU itself once
//! its sampling loop has processed the last half
//! (`Stimulus::exit_when_drained`). Every interrupt then falls on the same
//! guest instruction in every run, and so does the end.
//!
//! The figure: the core cycles the sampling loop spent on the sample blocks
//! (`Header::loop_cycles`: from a block's hand-over to the loop's next read:
//! the estimator, the monitor's bookkeeping, the copy out of the DMA ring)
//! × 40 / sample-sets = instructions per sample-set. With the profiling
//! plugin (`xtask/qemu-profile`, QEMU's TCG plugin API), every instruction
//! the guest executed is counted by function: the split per sample-set.

mod common;
use common::plugin;
use std::collections::HashMap;
use std::sync::atomic::AtomicBool;
use std::time::Duration;

use hammer_host::client::Client;
use hammer_host::emulator::{firmware_elf, qemu_available, Emulator, Icount};
use hammer_host::stimulus::Stimulus;
use hammer_sim::simulate::simulate;
use hammer_sim::SimConfig;
use hammer_wire::stimulus::{BLOCK_SETS, RATE_HZ, SYSCLK_HZ};
use hammer_wire::DeviceMsg;

/// Guest instructions per board clock cycle at `-icount shift=0` (1 ns each).
const INSTRUCTIONS_PER_CYCLE: f64 = 1e9 / SYSCLK_HZ as f64;
/// The executor's idle spin (firmware/emulated/src/executor.rs): not work.
const IDLE_FUNCTION: &str = "hammer_firmware_emu::executor::spin_until_woken";
/// Functions shown in the split; the rest are summed in one line.
const SHOWN: usize = 24;

fn main() {
    if !qemu_available() {
        eprintln!("qemu-system-arm not installed: apt-get install -y qemu-system-arm");
        std::process::exit(1);
    }
    let mut cfg = SimConfig::nominal(5.0);
    cfg.solver.duration_s = 2.0;
    cfg.effects.apply_spec("coulomb_friction").unwrap();
    let mut samples = simulate(&cfg).unwrap().measured.codes;
    // Whole DMA halves only: a tail short of a half never completes.
    samples.truncate(samples.len() / BLOCK_SETS as usize * BLOCK_SETS as usize);
    let delivered = samples.len() as u32;

    let stimulus = Stimulus::create().expect("stimulus file");
    assert!(stimulus.push(&samples, &AtomicBool::new(false)));
    stimulus.exit_when_drained();
    stimulus.finish();

    let plugin = plugin();
    let profile = std::env::temp_dir().join(format!("hammer-firmware-profile-{}.txt", std::process::id()));
    let extra = match &plugin {
        Some(p) => vec![
            "-plugin".to_string(),
            format!("{},out={}", p.display(), profile.display()),
        ],
        None => vec![],
    };
    let mut emu = Emulator::start_with_args(&firmware_elf(), Some(Icount::COUNT), Some(&stimulus), &extra)
        .expect("emulated firmware (cargo xtask firmware)");
    // The connection starts the board; from then on it is only listened to.
    let mut link = Client::new(emu.connect(Duration::from_secs(20)).expect("connect"));
    let (mut reports, mut valid) = (0u32, 0u32);
    loop {
        match link.recv(Duration::from_secs(300)) {
            Ok(Some(DeviceMsg::Report(r))) => {
                reports += 1;
                valid += u32::from(r.is_valid());
            }
            Ok(Some(_)) => {}
            Ok(None) => panic!("the board sent nothing for 300 s and did not end"),
            Err(_) => break, // QEMU closed the link: the board has ended it
        }
    }
    let status = emu.wait_exit(Duration::from_secs(60)).expect("qemu");
    assert!(
        status.is_some_and(|s| s.success()),
        "QEMU did not end by the board's exit when drained ({status:?})"
    );
    let c = stimulus.counters();
    assert_eq!(c.consumed_sets, delivered, "the board processed every sample-set");
    assert_eq!(
        (c.lost_sets, c.overruns, c.starved_blocks),
        (0, 0, 0),
        "no overrun, no late stimulus"
    );

    let sets = f64::from(c.consumed_sets);
    let per_set = f64::from(c.loop_cycles) * INSTRUCTIONS_PER_CYCLE / sets;
    println!(
        "firmware on the Cortex-M4 ISA (QEMU -icount shift=0): {per_set:.1} instructions per sample-set \
         in the sampling loop over {} sample-sets in 256-set DMA halves, {reports} reports ({valid} valid), \
         {} lost, {} overruns",
        c.consumed_sets, c.lost_sets, c.overruns
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
    match plugin {
        Some(_) => split(&profile, sets),
        None => println!(
            "per-function split: no profiling plugin (cargo build --release -p qemu-profile; \
             cargo xtask bench-firmware does)"
        ),
    }
    let _ = std::fs::remove_file(&profile);
}

/// The plugin's counts by function, per sample-set, boot and all.
fn split(profile: &std::path::Path, sets: f64) {
    let text = match std::fs::read_to_string(profile) {
        Ok(t) => t,
        Err(e) => {
            println!(
                "per-function split: no profile from the plugin ({}: {e})",
                profile.display()
            );
            return;
        }
    };
    let mut by_function: HashMap<String, u64> = HashMap::new();
    for line in text.lines() {
        let Some((n, symbol)) = line.split_once('\t') else {
            continue;
        };
        let Ok(n) = n.parse::<u64>() else { continue };
        // Without the hash: one line per function, generic instances summed.
        let name = format!("{:#}", rustc_demangle::demangle(symbol));
        *by_function.entry(name).or_default() += n;
    }
    let total: u64 = by_function.values().sum();
    let idle = by_function.remove(IDLE_FUNCTION).unwrap_or(0);
    let work = total - idle;
    let mut rows: Vec<(String, u64)> = by_function.into_iter().collect();
    rows.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    println!(
        "per-function split (QEMU plugin, every guest instruction of the run, boot included): \
         {:.1} instructions per sample-set outside the idle spin ({total} executed, {idle} idle)",
        work as f64 / sets
    );
    for (name, n) in rows.iter().take(SHOWN) {
        println!(
            "  {:7.2}  {:5.1} %  {name}",
            *n as f64 / sets,
            *n as f64 * 100.0 / work as f64
        );
    }
    let rest: u64 = rows.iter().skip(SHOWN).map(|r| r.1).sum();
    println!(
        "  {:7.2}  {:5.1} %  ({} other functions)",
        rest as f64 / sets,
        rest as f64 * 100.0 / work.max(1) as f64,
        rows.len().saturating_sub(SHOWN)
    );
}
