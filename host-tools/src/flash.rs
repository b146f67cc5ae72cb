//! `hammer flash`: the reference firmware onto a board through a debug
//! probe, with probe-rs as a library, never touching the pages where the
//! board keeps its wear history and configuration unless asked to.
//!
//! Before anything reaches a probe the image is checked and planned: an
//! ARM (32-bit, little-endian) ELF; every loadable segment, at its load
//! address, inside the chip's main flash and outside the persisted-state
//! pages (the last 8 KiB: `firmware/src/persist.rs`); and the sectors a
//! write must erase, from the chip's flash algorithm in probe-rs's target
//! database. `--dry-run` stops there and prints the plan. A write erases
//! only the sectors that hold the image, so the state pages keep their
//! contents; `--erase-state` adds them, after a confirmation.

use std::io::BufRead;
use std::ops::Range;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use object::elf;
use object::read::elf::{ElfFile32, ProgramHeader};

/// Bytes at the end of main flash that hold the persisted state: four 2 KiB
/// pages (`firmware/src/persist.rs`, `AREA_OFFSET`).
pub const STATE_BYTES: u64 = 8 * 1024;

#[derive(Args, Debug, Clone)]
pub struct FlashArgs {
    /// The firmware ELF (default: the reference board's release build).
    pub elf: Option<PathBuf>,
    /// The chip, as probe-rs names it.
    #[arg(long, default_value = "STM32G474RETx")]
    pub chip: String,
    /// Which probe, when several are plugged in: VID:PID or VID:PID:SERIAL.
    #[arg(long)]
    pub probe: Option<String>,
    /// Check the image and print the sectors a flash would erase and write; touch no board.
    #[arg(long)]
    pub dry_run: bool,
    /// Also erase the persisted state (wear history, configuration, calibration). Asks first.
    #[arg(long)]
    pub erase_state: bool,
    /// Do not ask before erasing the state (scripts).
    #[arg(long)]
    pub yes: bool,
    /// After flashing, open the dashboard on this serial port.
    #[arg(long)]
    pub monitor: Option<String>,
}

/// The reference board's release ELF.
pub fn reference_elf() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("host-tools sits in the workspace")
        .to_path_buf();
    root.join("firmware/target/thumbv7em-none-eabihf/release/hammer-firmware")
}

/// A loadable piece of the image, at its load (flash) address.
#[derive(Debug, Clone)]
pub struct Segment {
    pub address: u64,
    pub data: Vec<u8>,
}

/// An image file larger than this is not a firmware for a part with at
/// most a few MiB of flash (and /dev/zero is not read without end).
const MAX_IMAGE_BYTES: u64 = 64 << 20;

/// An ELF machine number's name, for messages.
fn machine_name(m: u16) -> &'static str {
    match m {
        elf::EM_386 => "x86",
        elf::EM_X86_64 => "x86-64",
        elf::EM_AARCH64 => "64-bit ARM",
        elf::EM_ARM => "ARM",
        elf::EM_RISCV => "RISC-V",
        elf::EM_XTENSA => "Xtensa",
        elf::EM_AVR => "AVR",
        _ => "another architecture",
    }
}

/// The image's loadable segments, from a little-endian 32-bit ARM ELF
/// only; each refusal names what is actually wrong with the file.
pub fn read_image(path: &Path) -> Result<Vec<Segment>> {
    let meta = std::fs::metadata(path).with_context(|| format!("reading {}", path.display()))?;
    if !meta.is_file() {
        bail!(
            "{} is not a regular file (a device or a directory): give the firmware's ELF",
            path.display()
        );
    }
    // The header first: what the file is, whatever its size.
    let mut file = std::fs::File::open(path).with_context(|| format!("reading {}", path.display()))?;
    let mut bytes = Vec::new();
    std::io::Read::read_to_end(&mut std::io::Read::take(&mut file, 64), &mut bytes)
        .with_context(|| format!("reading {}", path.display()))?;
    let what = |text: String| {
        anyhow::anyhow!(
            "{}: {text}; the firmware is the reference board's build (cargo xtask firmware)",
            path.display()
        )
    };
    if bytes.len() < 4 || &bytes[..4] != b"\x7fELF" {
        return Err(what("not an ELF file (no ELF signature at its start)".into()));
    }
    if bytes.len() < 20 {
        return Err(what(format!(
            "a truncated ELF ({} bytes, not even a header)",
            bytes.len()
        )));
    }
    let (class, data) = (bytes[4], bytes[5]);
    let machine = match data {
        2 => u16::from_be_bytes([bytes[18], bytes[19]]),
        _ => u16::from_le_bytes([bytes[18], bytes[19]]),
    };
    if class == elf::ELFCLASS64 {
        return Err(what(format!(
            "a 64-bit ELF for {} (machine {machine}), not the board's 32-bit ARM one",
            machine_name(machine)
        )));
    }
    if machine != elf::EM_ARM {
        return Err(what(format!(
            "an ELF for {} (machine {machine}), not for ARM",
            machine_name(machine)
        )));
    }
    if data == 2 {
        return Err(what("a big-endian ARM ELF; the board runs little-endian".into()));
    }
    if meta.len() > MAX_IMAGE_BYTES {
        bail!(
            "{} is larger than {} MiB: not a firmware image",
            path.display(),
            MAX_IMAGE_BYTES >> 20
        );
    }
    std::io::Read::read_to_end(&mut std::io::Read::take(file, MAX_IMAGE_BYTES), &mut bytes)
        .with_context(|| format!("reading {}", path.display()))?;
    let elf = ElfFile32::<object::Endianness>::parse(&*bytes)
        .map_err(|e| what(format!("a truncated or damaged ARM ELF ({e})")))?;
    let e = elf.endian();
    let mut out = vec![];
    for ph in elf.elf_program_headers() {
        if ph.p_type(e) != elf::PT_LOAD || ph.p_filesz(e) == 0 {
            continue;
        }
        let data = ph
            .data(e, &*bytes)
            .map_err(|_| anyhow::anyhow!("{}: a segment's data lies outside the file", path.display()))?;
        out.push(Segment {
            address: u64::from(ph.p_paddr(e)),
            data: data.to_vec(),
        });
    }
    if out.is_empty() {
        bail!("{} has nothing to load", path.display());
    }
    let mut spans: Vec<(u64, u64)> = out
        .iter()
        .map(|s| (s.address, s.address + s.data.len() as u64))
        .collect();
    spans.sort_unstable();
    if let Some(w) = spans.windows(2).find(|w| w[1].0 < w[0].1) {
        bail!(
            "{}: two loadable segments overlap (0x{:08x}..0x{:08x} and 0x{:08x}..0x{:08x}): a damaged or hand-made ELF",
            path.display(),
            w[0].0,
            w[0].1,
            w[1].0,
            w[1].1
        );
    }
    Ok(out)
}

/// What a flash of an image will do.
#[derive(Debug, Clone)]
pub struct Plan {
    pub chip: String,
    pub flash: Range<u64>,
    pub state: Range<u64>,
    pub sector_bytes: u64,
    /// Runs of sectors to erase, in order.
    pub erase: Vec<Range<u64>>,
    /// Bytes to program.
    pub write_bytes: u64,
    pub erase_state: bool,
}

/// The chip's main flash and its sector size, from probe-rs's target database.
pub fn chip_flash(chip: &str) -> Result<(Range<u64>, u64)> {
    let registry = probe_rs::config::Registry::from_builtin_families();
    let target = registry
        .get_target_by_name(chip)
        .map_err(|e| anyhow::anyhow!("unknown chip {chip:?} ({e}); probe-rs names it as in `probe-rs chip list`"))?;
    let algo = target
        .flash_algorithms
        .iter()
        .find(|a| a.default)
        .with_context(|| format!("{chip} has no default flash algorithm in probe-rs"))?;
    let p = &algo.flash_properties;
    let sector = p
        .sectors
        .first()
        .map(|s| s.size)
        .with_context(|| format!("{chip}'s flash algorithm lists no sectors"))?;
    if p.sectors.len() > 1 {
        bail!("{chip}'s flash has sectors of several sizes; this planner handles one size");
    }
    Ok((p.address_range.clone(), sector))
}

/// Checks `image` against the chip and lists the sectors a write erases.
pub fn plan(image: &[Segment], chip: &str, erase_state: bool) -> Result<Plan> {
    let (flash, sector) = chip_flash(chip)?;
    let state = flash.end - STATE_BYTES..flash.end;
    let mut erase: Vec<Range<u64>> = vec![];
    let mut write_bytes = 0;
    for s in image {
        let r = s.address..s.address + s.data.len() as u64;
        if r.start < flash.start || r.end > flash.end {
            bail!(
                "a segment at {:#010x} ({} bytes) lies outside {chip}'s flash {:#010x}..{:#010x}: \
                 an image for another board (the emulated board's?)",
                r.start,
                s.data.len(),
                flash.start,
                flash.end
            );
        }
        if r.end > state.start {
            bail!(
                "a segment at {:#010x}..{:#010x} reaches into the persisted-state pages {:#010x}..{:#010x}: \
                 the image is too large, or its memory.x does not keep them free",
                r.start,
                r.end,
                state.start,
                state.end
            );
        }
        write_bytes += s.data.len() as u64;
        let first = flash.start + (r.start - flash.start) / sector * sector;
        let end = flash.start + (r.end - flash.start).div_ceil(sector) * sector;
        erase.push(first..end);
    }
    if erase_state {
        erase.push(state.clone());
    }
    erase.sort_by_key(|r| r.start);
    let mut merged: Vec<Range<u64>> = vec![];
    for r in erase {
        match merged.last_mut() {
            Some(last) if r.start <= last.end => last.end = last.end.max(r.end),
            _ => merged.push(r),
        }
    }
    Ok(Plan {
        chip: chip.to_string(),
        flash,
        state,
        sector_bytes: sector,
        erase: merged,
        write_bytes,
        erase_state,
    })
}

impl Plan {
    pub fn erases_state(&self) -> bool {
        self.erase
            .iter()
            .any(|r| r.start < self.state.end && self.state.start < r.end)
    }

    pub fn describe(&self) -> String {
        let sectors: u64 = self.erase.iter().map(|r| (r.end - r.start) / self.sector_bytes).sum();
        let mut s = format!(
            "{}: flash {:#010x}..{:#010x}, {} B sectors\n",
            self.chip, self.flash.start, self.flash.end, self.sector_bytes
        );
        s += &format!("erase {sectors} sectors:");
        for r in &self.erase {
            s += &format!(
                " {:#010x}..{:#010x} ({} sectors)",
                r.start,
                r.end,
                (r.end - r.start) / self.sector_bytes
            );
        }
        s += &format!("\nwrite {} bytes\n", self.write_bytes);
        s += &if self.erases_state() {
            format!(
                "the persisted state {:#010x}..{:#010x} (wear history, configuration) WILL BE ERASED",
                self.state.start, self.state.end
            )
        } else {
            format!(
                "the persisted state {:#010x}..{:#010x} (wear history, configuration) is untouched",
                self.state.start, self.state.end
            )
        };
        s
    }
}

/// Applies a plan to a flash image in memory, as the chip would: the erased
/// sectors read 0xFF, then the segments are written. What the planner
/// promises about the state pages is checked against this.
pub fn apply(plan: &Plan, image: &[Segment], flash: &mut [u8]) {
    let base = plan.flash.start;
    for r in &plan.erase {
        flash[(r.start - base) as usize..(r.end - base) as usize].fill(0xFF);
    }
    for s in image {
        let at = (s.address - base) as usize;
        flash[at..at + s.data.len()].copy_from_slice(&s.data);
    }
}

fn confirm_state_erase(yes: bool) -> Result<()> {
    if yes {
        return Ok(());
    }
    eprint!("--erase-state erases the board's wear history, configuration and calibration; type 'erase' to go on: ");
    let mut line = String::new();
    std::io::stdin().lock().read_line(&mut line)?;
    if line.trim() != "erase" {
        bail!("not confirmed: nothing was written");
    }
    Ok(())
}

fn open_probe(selector: Option<&str>) -> Result<probe_rs::probe::Probe> {
    let lister = probe_rs::probe::list::Lister::new();
    let probes = lister.list_all();
    match (selector, probes.len()) {
        (Some(sel), _) => {
            let sel: probe_rs::probe::DebugProbeSelector =
                sel.parse().map_err(|e| anyhow::anyhow!("--probe {sel:?}: {e}"))?;
            lister
                .open(sel.clone())
                .map_err(|e| anyhow::anyhow!("cannot open the probe {sel}: {e}"))
        }
        (None, 0) => {
            bail!("no debug probe found: is the board's ST-LINK plugged in, and may this user open it (udev rules)?")
        }
        (None, 1) => probes[0]
            .open()
            .map_err(|e| anyhow::anyhow!("cannot open the probe {}: {e}", probes[0])),
        (None, _) => {
            let list: Vec<String> = probes.iter().map(|p| format!("  {p}")).collect();
            bail!(
                "several debug probes; choose one with --probe VID:PID[:SERIAL]:\n{}",
                list.join("\n")
            )
        }
    }
}

pub fn run(args: &FlashArgs) -> Result<()> {
    let path = args.elf.clone().unwrap_or_else(reference_elf);
    let image = read_image(&path)?;
    let plan = plan(&image, &args.chip, args.erase_state)?;
    println!("{}: {}", path.display(), plan.describe());
    if args.dry_run {
        println!("dry run: no probe opened, nothing written");
        return Ok(());
    }
    if args.erase_state {
        confirm_state_erase(args.yes)?;
    }
    let probe = open_probe(args.probe.as_deref())?;
    let mut session = probe
        .attach(args.chip.as_str(), probe_rs::Permissions::default())
        .map_err(|e| {
            anyhow::anyhow!(
                "cannot attach to {} through the probe: {e} (is it that chip?)",
                args.chip
            )
        })?;
    let mut loader = session.target().flash_loader();
    for s in &image {
        loader.add_data(s.address, &s.data)?;
    }
    if args.erase_state {
        loader.add_data(plan.state.start, &vec![0xFF; STATE_BYTES as usize])?;
    }
    let mut options = probe_rs::flashing::DownloadOptions::default();
    options.verify = true;
    loader
        .commit(&mut session, options)
        .map_err(|e| anyhow::anyhow!("flashing failed: {e}"))?;
    session.core(0)?.reset()?;
    println!("flashed, verified and reset");
    drop(session);
    if let Some(port) = &args.monitor {
        #[derive(clap::Parser)]
        struct Defaults {
            #[command(flatten)]
            monitor: crate::monitor::MonitorArgs,
        }
        let margs = <Defaults as clap::Parser>::parse_from(["hammer-monitor", "--port", port]).monitor;
        return crate::monitor::run(&margs);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(address: u64, len: usize) -> Segment {
        Segment {
            address,
            data: vec![0x5A; len],
        }
    }

    /// A minimal ELF32 header and program headers, little-endian, for ARM
    /// unless changed: one PT_LOAD of 16 bytes at each of `at`.
    fn elf(at: &[u32]) -> Vec<u8> {
        let mut b = vec![0x7f, b'E', b'L', b'F', 1, 1, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0];
        let phoff = 52u32;
        let data = phoff + 32 * at.len() as u32;
        b.extend(2u16.to_le_bytes()); // executable
        b.extend(40u16.to_le_bytes()); // ARM
        b.extend(1u32.to_le_bytes());
        b.extend(0u32.to_le_bytes());
        b.extend(phoff.to_le_bytes());
        b.extend(0u32.to_le_bytes());
        b.extend(0u32.to_le_bytes());
        b.extend(52u16.to_le_bytes());
        b.extend(32u16.to_le_bytes());
        b.extend((at.len() as u16).to_le_bytes());
        b.extend([40, 0, 0, 0, 0, 0]);
        for &a in at {
            for v in [1, data, a, a, 16, 16, 5, 4] {
                b.extend(v.to_le_bytes());
            }
        }
        b.extend([0xAB; 16]);
        b
    }

    #[test]
    fn each_refused_image_is_named_for_what_is_wrong_with_it() {
        let dir = std::env::temp_dir().join(format!("hammer-flash-elf-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let says = |name: &str, bytes: &[u8], expected: &str| {
            let p = dir.join(name);
            std::fs::write(&p, bytes).unwrap();
            let e = format!("{:#}", read_image(&p).unwrap_err());
            assert!(e.contains(expected), "{name}: {e}");
        };
        let good = elf(&[0x0800_0000, 0x0800_0010]);
        assert_eq!(
            read_image(&{
                let p = dir.join("good.elf");
                std::fs::write(&p, &good).unwrap();
                p
            })
            .unwrap()
            .len(),
            2
        );
        says("text.elf", b"#!/bin/sh\necho hi\n", "not an ELF file");
        says("short.elf", &good[..12], "a truncated ELF");
        says("cut.elf", &good[..60], "a truncated or damaged ARM ELF");
        let mut be = good.clone();
        be[5] = 2;
        be[18..20].copy_from_slice(&40u16.to_be_bytes());
        says("be.elf", &be, "a big-endian ARM ELF");
        let mut x64 = good.clone();
        x64[4] = 2;
        x64[18..20].copy_from_slice(&62u16.to_le_bytes());
        says("x64.elf", &x64, "a 64-bit ELF for x86-64");
        let mut riscv = good.clone();
        riscv[18..20].copy_from_slice(&243u16.to_le_bytes());
        says("rv.elf", &riscv, "an ELF for RISC-V (machine 243)");
        says(
            "overlap.elf",
            &elf(&[0x0800_0000, 0x0800_0008]),
            "two loadable segments overlap",
        );
        // A device is refused at once, never read without end.
        let t = std::time::Instant::now();
        let e = format!("{:#}", read_image(Path::new("/dev/zero")).unwrap_err());
        assert!(e.contains("not a regular file"), "{e}");
        println!("/dev/zero refused in {:?}", t.elapsed());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn the_plan_erases_whole_sectors_and_refuses_the_state_pages_and_foreign_addresses() {
        let image = [seg(0x0800_0000, 472), seg(0x0800_01D8, 5000)];
        let p = plan(&image, "STM32G474RETx", false).unwrap();
        assert_eq!(p.sector_bytes, 2048);
        assert_eq!(p.erase, vec![0x0800_0000..0x0800_1800]);
        assert!(!p.erases_state());
        assert!(p.describe().contains("untouched"), "{}", p.describe());
        // Into the last 8 KiB: refused.
        let e = plan(&[seg(0x0807_D000, 8192)], "STM32G474RETx", false).unwrap_err();
        assert!(e.to_string().contains("persisted-state"), "{e}");
        // The emulated board's image starts at 0.
        let e = plan(&[seg(0, 100)], "STM32G474RETx", false).unwrap_err();
        assert!(e.to_string().contains("outside"), "{e}");
        let e = plan(&image, "NoSuchChip", false).unwrap_err();
        assert!(e.to_string().contains("unknown chip"), "{e}");
        let p = plan(&image, "STM32G474RETx", true).unwrap();
        assert!(p.erases_state() && p.describe().contains("WILL BE ERASED"));
    }

    #[test]
    fn a_flash_by_the_plan_keeps_a_stored_wear_state() {
        let image = [seg(0x0800_0000, 70_000), seg(0x0801_2000, 3000)];
        let p = plan(&image, "STM32G474RETx", false).unwrap();
        let mut flash = vec![0xFFu8; (p.flash.end - p.flash.start) as usize];
        // An old firmware and a wear record in the state pages.
        flash[..100_000].fill(0x11);
        let state_at = (p.state.start - p.flash.start) as usize;
        for (i, b) in flash[state_at..].iter_mut().enumerate() {
            *b = (i * 7 % 251) as u8;
        }
        let before = flash[state_at..].to_vec();
        apply(&p, &image, &mut flash);
        assert_eq!(&flash[state_at..], &before[..], "the state pages kept their bytes");
        assert!(flash[..70_000].iter().all(|&b| b == 0x5A), "the new image is there");
        // Old firmware bytes beyond the image's sectors are left; inside them, erased.
        assert_eq!(flash[70_000], 0xFF);
        let p = plan(&image, "STM32G474RETx", true).unwrap();
        apply(&p, &image, &mut flash);
        assert!(
            flash[state_at..].iter().all(|&b| b == 0xFF),
            "--erase-state erases them"
        );
    }
}
