//! `hammer selftest`: the first-boot checks of a board on the bench, with
//! the hammer at rest, supply off, both chambers vented (docs/firmware.md,
//! "Bring-up"):
//! - each channel sits in its idle range (pressures near 0 gauge, the
//!   accelerometer near the gravity component), off its rails, quiet;
//! - the ADC's reference (VDDA, measured on the chip's internal reference)
//!   is within 2 % of the 3.3 V every channel's scale assumes;
//! - the board samples for 10 s of its own time without an overrun or a
//!   dropped sample, at the configured rate (its sample clock against its
//!   time base).
//!
//! Each failed check says what it most likely means.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use hammer_estimator::Config;
use hammer_wire::{DeviceMsg, HostMsg, Status};

use crate::client::Client;

#[derive(Args, Debug, Clone)]
pub struct SelftestArgs {
    /// The board's serial port (or tcp:HOST:PORT).
    #[arg(long)]
    pub port: String,
    /// Seconds of the board's own time to sample while watching for losses.
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
}

/// One check's outcome.
#[derive(Debug, Clone)]
pub struct Check {
    pub name: String,
    pub pass: bool,
    /// The measured figure, and on failure what it likely means.
    pub detail: String,
}

const T: Duration = Duration::from_secs(30);
/// Idle limits, as shares of a channel's span (full-scale code × scale): at
/// rest a channel reads its idle value within 2 % (a vented chamber within
/// 0.2 bar on a 10 bar sensor; a sensor's zero is specified far tighter, a
/// chamber left under pressure or a wrong pin is far off) and varies by
/// less than 0.5 % (5 kPa; noise is a few codes).
const IDLE_SHARE: f64 = 0.02;
const QUIET_SHARE: f64 = 0.005;
/// VDDA's tolerance: a channel's gain moves with it one for one, and a
/// 3.3 V regulator holds ±1-2 %; beyond 2 % the gains are off by more than
/// the calibration's own uncertainty (a 1 % gain error biases friction by ~1 N).
const VDDA_SHARE: f64 = 0.02;

/// The ADC reference check on a measured VDDA (`Status::vdda_v`, 0 when the board does not measure it).
pub fn reference_check(vdda_v: f32) -> Check {
    let nominal = f64::from(hammer_app::supply::NOMINAL_VDDA_V);
    let v = f64::from(vdda_v);
    let off = v / nominal - 1.0;
    let (pass, detail) = if !v.is_finite() || v <= 0.0 {
        (
            false,
            "not measured: the board reports no VDDA (a firmware before protocol 3, or its reference channel failed)"
                .to_string(),
        )
    } else if off.abs() > VDDA_SHARE {
        (
            false,
            format!(
                "VDDA {v:.3} V, {:+.1} % from {nominal:.1} V: every channel reads {:+.1} % off; check the 3.3 V regulator and the VDDA/VREF+ supply, then recalibrate",
                off * 100.0,
                (nominal / v - 1.0) * 100.0
            ),
        )
    } else {
        (true, format!("VDDA {v:.3} V ({:+.2} % of {nominal:.1} V)", off * 100.0))
    };
    Check {
        name: "ADC reference".into(),
        pass,
        detail,
    }
}

fn status<S: Read + Write>(link: &mut Client<S>) -> Result<Status> {
    link.send(&HostMsg::GetStatus)?;
    let (s, _) = link.recv_until(T, |m| if let DeviceMsg::Status(s) = m { Some(*s) } else { None })?;
    s.context("no status from the board")
}

/// Runs the checks on the board at `link`.
pub fn selftest<S: Read + Write>(link: &mut Client<S>, seconds: f64) -> Result<Vec<Check>> {
    link.send(&HostMsg::GetConfig)?;
    let (cfg, _) = link.recv_until(T, |m| if let DeviceMsg::Config(c) = m { Some(*c) } else { None })?;
    let cfg = Config::default().with_device(&cfg.context("no configuration from the board")?);
    link.send(&HostMsg::MeasureCodes { samples: 20_000 })?;
    let (stats, _) = link.recv_until(T, |m| match m {
        DeviceMsg::CodeStats { mean, std, .. } => Some(Ok((*mean, *std))),
        DeviceMsg::Rejected { reason, .. } => Some(Err(*reason)),
        _ => None,
    })?;
    let (mean, std) = match stats {
        Some(Ok(s)) => s,
        Some(Err(r)) => bail!("the board refused to measure: {r:?}"),
        None => bail!("no measurement from the board within {T:?}"),
    };
    let mut checks = vec![];
    let g_axis = 9.80665 * f64::from(hammer_estimator::math::sin_small(cfg.inclination_deg.to_radians()));
    let channels = [
        ("rear pressure", &cfg.rear, 0.0, "Pa"),
        ("front pressure", &cfg.front, 0.0, "Pa"),
        ("acceleration", &cfg.accel, g_axis, "m/s²"),
    ];
    for (k, (name, cal, expected, unit)) in channels.into_iter().enumerate() {
        let span = f64::from(cal.full_scale_code) * f64::from(cal.scale).abs();
        let (idle, quiet) = (IDLE_SHARE * span, QUIET_SHARE * span);
        let m = f64::from(mean[k]);
        let value = (m - f64::from(cal.zero_code)) * f64::from(cal.scale);
        let spread = f64::from(std[k]) * f64::from(cal.scale).abs();
        let full = f64::from(cal.full_scale_code);
        let (pass, why) = if m < 1.0 || m > full - 1.0 {
            (
                false,
                "on a rail: sensor unplugged, unpowered or wired to the wrong pin",
            )
        } else if (value - expected).abs() > idle {
            (
                false,
                if k < 2 {
                    "off its idle value: the chamber is not vented, or the zero is off (run hammer calibrate)"
                } else {
                    "off gravity's component: the hammer moves, the inclination is wrong, or the zero is off"
                },
            )
        } else if spread > quiet {
            (
                false,
                "noisy at rest: a loose connector, ground loop or a running compressor",
            )
        } else {
            (true, "")
        };
        checks.push(Check {
            name: format!("{name} at rest"),
            pass,
            detail: format!(
                "{value:.1} {unit} (expected {expected:.1} ± {idle:.0}), spread {spread:.1} {unit}, mean code {m:.1}{}{why}",
                if why.is_empty() { "" } else { ": " }
            ),
        });
    }

    // Sampling for `seconds` of the board's own time.
    let before = status(link)?;
    checks.push(reference_check(before.vdda_v));
    let deadline = Instant::now() + Duration::from_secs_f64(seconds * 3.0 + 30.0);
    let after = loop {
        let s = status(link)?;
        if s.uptime_us.saturating_sub(before.uptime_us) as f64 >= seconds * 1e6 {
            break s;
        }
        if Instant::now() > deadline {
            bail!(
                "the board's clock did not advance {seconds} s within {:?}",
                deadline - Instant::now()
            );
        }
        std::thread::sleep(Duration::from_millis(200));
    };
    let lost = after.dropped_samples - before.dropped_samples;
    let overruns = after.adc_overruns - before.adc_overruns;
    checks.push(Check {
        name: format!("{seconds} s of sampling without loss"),
        pass: lost == 0 && overruns == 0,
        detail: format!(
            "{overruns} overruns, {lost} samples dropped{}",
            if lost == 0 && overruns == 0 {
                ""
            } else {
                ": the DSP falls behind (CPU load?) or the sampling chain stalls"
            }
        ),
    });
    let dt_s = (after.uptime_us - before.uptime_us) as f64 * 1e-6;
    let rate = (after.samples - before.samples + lost) as f64 / dt_s;
    let nominal = f64::from(cfg.sample_rate_hz);
    let off = rate / nominal - 1.0;
    // Blocks arrive whole, so a 10 s window is off by up to a block or two.
    checks.push(Check {
        name: "sample rate against the board's clock".into(),
        pass: off.abs() < 0.01,
        detail: format!(
            "{rate:.0} S/s of {nominal:.0} ({:+.2} %){}",
            off * 100.0,
            if off.abs() < 0.01 {
                ""
            } else {
                ": the sample timer or the clock tree is misconfigured"
            }
        ),
    });
    Ok(checks)
}

pub fn summary(checks: &[Check]) -> String {
    let mut s = String::new();
    for c in checks {
        s += &format!("{} {}: {}\n", if c.pass { "PASS" } else { "FAIL" }, c.name, c.detail);
    }
    let failed = checks.iter().filter(|c| !c.pass).count();
    s += &if failed == 0 {
        "self-test passed".to_string()
    } else {
        format!("self-test FAILED: {failed} of {} checks", checks.len())
    };
    s
}

pub fn run(args: &SelftestArgs) -> Result<Vec<Check>> {
    let mut connector = crate::monitor::connector_for(&args.port)?;
    let port = connector
        .connect()
        .with_context(|| format!("opening {}", connector.describe()))?;
    let mut link = Client::new(port);
    link.handshake(Duration::from_secs(10))?;
    selftest(&mut link, args.seconds)
}
