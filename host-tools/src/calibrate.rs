//! `hammer calibrate`: zero and span of the pressure channels against a
//! reference, and the accelerometer's zero at rest, measured by the board on
//! its own raw codes and written back to it as its configuration, which it
//! stores and carries (`config_hash` in `Hello` and every `Status`).
//!
//! The steps, each started by the operator:
//! 1. both chambers vented to atmosphere, the hammer at rest: the board's
//!    tare zeroes all three channels (0 Pa gauge, the accelerometer's gravity
//!    component);
//! 2. a reference pressure applied to both chambers (a tee from one
//!    regulator and a reference gauge): the board averages its codes
//!    (`MeasureCodes`), and each channel's scale becomes
//!    reference / (mean code − zero code);
//! 3. the new configuration is sent (`SetConfig`), acknowledged, read back;
//!    with `--hammer-config FILE` it also carries that hammer's chambers
//!    (travel, dead volumes, outlets) and its pressure transducers' group
//!    delay, which the board's chamber characteristics read with; without
//!    one the board keeps those it has (the paper's hammer by default, and
//!    after an update from a firmware that did not store them).
//!
//! A 1 % gain error biases the friction by about 1 N (docs/firmware.md), so
//! the span is refused when the channel barely moved or the pressure was
//! not steady.

use std::io::{BufRead, Read, Write};
use std::time::Duration;

use anyhow::{bail, Context, Result};
use clap::Args;
use hammer_wire::{config_hash, ChannelCalibration, DeviceConfig, DeviceMsg, HostMsg};

use crate::client::Client;

#[derive(Args, Debug, Clone)]
pub struct CalibrateArgs {
    /// The board's serial port (or tcp:HOST:PORT, as for `hammer monitor`).
    #[arg(long)]
    pub port: String,
    /// Sample-sets averaged per step (0.2 s at 100 kS/s).
    #[arg(long, default_value_t = 20_000)]
    pub samples: u32,
    /// The reference pressure, bar gauge; asked for when not given.
    #[arg(long)]
    pub reference_bar: Option<f64>,
    /// The hammer's configuration (`hammer simulate --config`'s TOML): its
    /// chambers' geometry and its pressure transducers' group delay are
    /// stored with the calibration; without it the board keeps its own.
    #[arg(long, value_name = "FILE")]
    pub hammer_config: Option<std::path::PathBuf>,
}

/// The chambers' part of the board's configuration that `hammer_config`
/// describes (at the board's sample rate, which sets the filter's delay).
pub fn hammer_chambers(hammer_config: &std::path::Path, sample_rate_hz: f32) -> Result<DeviceConfig> {
    let mut cfg: hammer_sim::SimConfig = hammer_trace::config::load_toml(hammer_config)?;
    cfg.solver.output_step_s = 1.0 / f64::from(sample_rate_hz);
    cfg.validate()
        .and_then(|()| cfg.estimator_config(None))
        .map(|c| DeviceConfig::from(&c))
        .with_context(|| hammer_config.display().to_string())
}

/// Who applies the conditions: a person at the bench, or a test.
pub trait Operator {
    /// Returns once both chambers are vented and the hammer is at rest.
    fn vented_at_rest(&mut self) -> Result<()>;
    /// Returns the reference pressure (Pa gauge) once it is applied to both chambers.
    fn reference_applied(&mut self) -> Result<f64>;
}

/// What a calibration did.
#[derive(Debug, Clone, Copy)]
pub struct Calibration {
    pub before: DeviceConfig,
    pub after: DeviceConfig,
    pub reference_pa: f64,
    /// Each pressure channel's mean code at the reference and its spread.
    pub span_codes: [f64; 2],
    pub span_std_codes: [f64; 2],
    pub config_hash: u32,
    /// What every report computed with this calibration carries (`CycleReport::calibration_hash`).
    pub calibration_hash: u32,
}

impl Calibration {
    /// The gain each pressure channel had before, relative to now: 1.007
    /// means it read 0.7 % high.
    pub fn gain_change(&self) -> [f64; 2] {
        [
            f64::from(self.before.rear.scale) / f64::from(self.after.rear.scale),
            f64::from(self.before.front.scale) / f64::from(self.after.front.scale),
        ]
    }

    pub fn summary(&self) -> String {
        let g = self.gain_change();
        let ch = |name: &str, b: &ChannelCalibration, a: &ChannelCalibration| {
            format!(
                "  {name:<6} zero code {:8.2} -> {:8.2}, scale {:10.4} -> {:10.4} per code\n",
                b.zero_code, a.zero_code, b.scale, a.scale
            )
        };
        let mut s = format!(
            "calibration against {:.3} bar (config hash {:08x}, reports carry calibration {:08x}):\n",
            self.reference_pa / 1e5,
            self.config_hash,
            self.calibration_hash
        );
        s += &ch("rear", &self.before.rear, &self.after.rear);
        s += &ch("front", &self.before.front, &self.after.front);
        s += &ch("accel", &self.before.accel, &self.after.accel);
        s += &format!(
            "  the rear channel read {:+.2} %, the front {:+.2} % before\n",
            (g[0] - 1.0) * 100.0,
            (g[1] - 1.0) * 100.0
        );
        let a = &self.after;
        s += &format!(
            "  chambers: travel {:.1} mm, dead volumes rear {:.2} front {:.2} cm³, outlets rear {:.1} front {:.1} mm, pressure delay {:.2} µs{}",
            a.travel_m * 1e3,
            a.rear_dead_m3 * 1e6,
            a.front_dead_m3 * 1e6,
            a.rear_outlet_m * 1e3,
            a.front_outlet_m * 1e3,
            a.pressure_group_delay_s * 1e6,
            if same_chambers(&self.before, a) { " (unchanged)" } else { " (new)" }
        );
        s
    }
}

/// True when `a` and `b` hold the same chambers.
fn same_chambers(a: &DeviceConfig, b: &DeviceConfig) -> bool {
    config_hash(&a.with_chambers_of(b)) == config_hash(a)
}

const T: Duration = Duration::from_secs(30);

fn config<S: Read + Write>(link: &mut Client<S>, after: &HostMsg) -> Result<DeviceConfig> {
    link.send(after)?;
    let (cfg, _) = link.recv_until(T, |m| match m {
        DeviceMsg::Config(c) => Some(Ok(*c)),
        DeviceMsg::Rejected { command, reason } => Some(Err(format!("{command:?} rejected: {reason:?}"))),
        _ => None,
    })?;
    match cfg {
        Some(Ok(c)) => Ok(c),
        Some(Err(e)) => bail!("the board refused: {e}"),
        None => bail!("no configuration from the board within {T:?}"),
    }
}

/// Runs the steps on the board at `link`; `chambers`: a configuration whose
/// chambers the board is to take ([`hammer_chambers`]), else it keeps its own.
pub fn calibrate<S: Read + Write>(
    link: &mut Client<S>,
    op: &mut dyn Operator,
    samples: u32,
    chambers: Option<&DeviceConfig>,
) -> Result<Calibration> {
    let before = config(link, &HostMsg::GetConfig)?;
    op.vented_at_rest()?;
    // The tare answers with its Ack and the new configuration (or a rejection: not at rest).
    let zeroed = config(link, &HostMsg::Tare { samples }).context("zero at atmosphere and rest")?;
    let reference_pa = op.reference_applied()?;
    if !(reference_pa.is_finite() && reference_pa > 0.5e5) {
        bail!("a reference of {reference_pa} Pa is too small to calibrate a span: use at least 0.5 bar");
    }
    link.send(&HostMsg::MeasureCodes { samples })?;
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
    let mut after = zeroed;
    let mut span_codes = [0.0; 2];
    let mut span_std = [0.0; 2];
    for (k, (name, cal)) in [("rear", &mut after.rear), ("front", &mut after.front)]
        .into_iter()
        .enumerate()
    {
        let span = f64::from(mean[k]) - f64::from(cal.zero_code);
        span_codes[k] = f64::from(mean[k]);
        span_std[k] = f64::from(std[k]);
        if span < 100.0 {
            bail!("the {name} channel moved {span:.1} codes under the reference: is the pressure applied to it?");
        }
        if f64::from(mean[k]) >= f64::from(cal.full_scale_code) - 1.0 {
            bail!("the {name} channel is at its top rail: the reference is beyond its range");
        }
        if f64::from(std[k]) > 0.01 * span {
            bail!(
                "the {name} channel varies by {:.1} codes under a {span:.0}-code span: the pressure is not steady",
                std[k]
            );
        }
        cal.scale = (reference_pa / span) as f32;
    }
    if let Some(c) = chambers {
        after = after.with_chambers_of(c);
    }
    let set = config(link, &HostMsg::SetConfig(after)).context("writing the calibration")?;
    Ok(Calibration {
        before,
        after: set,
        reference_pa,
        span_codes,
        span_std_codes: span_std,
        config_hash: config_hash(&set),
        calibration_hash: set.calibration_hash(),
    })
}

/// The person at the bench, prompted on stderr, answering on stdin.
struct Bench<'a> {
    input: &'a mut dyn BufRead,
    reference_bar: Option<f64>,
}

impl Bench<'_> {
    fn line(&mut self) -> Result<String> {
        let mut s = String::new();
        if self.input.read_line(&mut s)? == 0 {
            bail!("input ended before the calibration did");
        }
        Ok(s.trim().to_string())
    }
}

impl Operator for Bench<'_> {
    fn vented_at_rest(&mut self) -> Result<()> {
        eprint!("1/2 vent both chambers to atmosphere, hammer at rest, supply off; then press Enter: ");
        self.line().map(|_| ())
    }

    fn reference_applied(&mut self) -> Result<f64> {
        match self.reference_bar {
            Some(bar) => {
                eprint!("2/2 apply {bar} bar (gauge) to both chambers; then press Enter: ");
                self.line()?;
                Ok(bar * 1e5)
            }
            None => {
                eprint!("2/2 apply a steady reference pressure to both chambers and type its gauge value in bar: ");
                let s = self.line()?;
                let bar: f64 = s.parse().with_context(|| format!("{s:?} is not a pressure in bar"))?;
                Ok(bar * 1e5)
            }
        }
    }
}

pub fn run(args: &CalibrateArgs) -> Result<Calibration> {
    let mut connector = crate::monitor::connector_for(&args.port)?;
    let port = connector
        .connect()
        .with_context(|| format!("opening {}", connector.describe()))?;
    let mut link = Client::new(port);
    link.handshake(Duration::from_secs(10))?;
    // The file is read before the operator is asked for anything.
    let chambers = match &args.hammer_config {
        Some(p) => Some(hammer_chambers(
            p,
            config(&mut link, &HostMsg::GetConfig)?.sample_rate_hz,
        )?),
        None => None,
    };
    let stdin = std::io::stdin();
    let mut input = stdin.lock();
    let mut bench = Bench {
        input: &mut input,
        reference_bar: args.reference_bar,
    };
    calibrate(&mut link, &mut bench, args.samples, chambers.as_ref())
}
