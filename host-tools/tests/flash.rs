//! `hammer flash`'s image through probe-rs's own flash loader, with its fake
//! probe (a mocked Cortex-M core; it exists for flash dry runs): probe-rs
//! attaches to the G474 and plans the reference image the way it would on a
//! board, and refuses the emulated board's. Writing needs a real probe.

use hammer_host::flash::{read_image, reference_elf};
use probe_rs::flashing::DownloadOptions;
use probe_rs::integration::FakeProbe;
use probe_rs::Permissions;

fn loader_dry_run(elf: &std::path::Path) -> Result<(), String> {
    let image = read_image(elf).map_err(|e| e.to_string())?;
    let probe = FakeProbe::with_mocked_core().into_probe();
    let mut session = probe
        .attach("STM32G474RETx", Permissions::default())
        .map_err(|e| format!("attach: {e}"))?;
    let mut loader = session.target().flash_loader();
    for s in &image {
        loader
            .add_data(s.address, &s.data)
            .map_err(|e| format!("add_data: {e}"))?;
    }
    let mut options = DownloadOptions::default();
    options.dry_run = true;
    loader.commit(&mut session, options).map_err(|e| format!("commit: {e}"))
}

#[test]
fn probe_rs_plans_the_reference_image_on_the_g474_through_its_fake_probe() {
    let elf = reference_elf();
    assert!(elf.exists(), "cargo xtask firmware builds {} first", elf.display());
    loader_dry_run(&elf).expect("probe-rs accepts the reference image");
    // The emulated board's image is at 0x0000_0000: probe-rs finds no flash there.
    let emu = hammer_host::emulator::firmware_elf();
    let err = loader_dry_run(&emu).expect_err("no flash at the emulated board's addresses");
    assert!(err.contains("add_data") || err.contains("commit"), "{err}");
}
