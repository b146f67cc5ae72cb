//! [`FmuModel`]: a foreign FMU with its map, opened and checked once, run
//! many times through a pool of worker processes. The diagnosis calls
//! [`FmuModel::run`] with a supply pressure, FMU parameter settings and a
//! duration and gets the three sensor signals (and what else the map
//! reads) in SI, gauge, the project's signs.

use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::{Deserialize, Serialize};

use super::archive::{unpack, Unpacked};
use super::check::{check_map, output, settable};
use super::describe::Description;
use super::fmi2::Typed;
use super::map::is_piston_force;
use super::map::{map_hash, ModelMap, Reference, Signal};
use super::pool::{Pool, Worker, WorkerCommand};
use super::units::{from_gauge_pa, gauge_pa, Quantity};
use super::worker::{Drive, Reply, Request};
use super::{FailKind, FmuError};

/// How the FMU is run.
#[derive(Debug, Clone)]
pub struct Options {
    /// Worker processes (instances) at most.
    pub threads: usize,
    /// The longest one call (open, or one whole run) may take.
    pub time_limit: Duration,
    pub worker: WorkerCommand,
}

/// What `report.json` carries of the model a diagnosis ran.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Identity {
    pub name: String,
    pub guid: String,
    pub fmi_version: String,
    pub generation_tool: Option<String>,
    /// SHA-256 of the map's text (None: opened without a map).
    pub map_hash: Option<String>,
}

/// A run's samples at t = 0, dt, 2 dt, … (SI, gauge, forward +).
#[derive(Debug, Clone, PartialEq)]
pub struct Signals {
    pub dt_s: f64,
    pub p_rear_pa: Vec<f64>,
    pub p_front_pa: Vec<f64>,
    pub accel_mps2: Vec<f64>,
    pub position_m: Option<Vec<f64>>,
    pub velocity_mps: Option<Vec<f64>>,
    /// The impact counter, as read.
    pub impacts: Option<Vec<f64>>,
}

/// How one output becomes a signal: factor to SI, sign, gauge offset.
#[derive(Debug, Clone, Copy)]
struct Conv {
    per_unit: f64,
    sign: f64,
    reference: Option<Reference>,
}

impl Conv {
    fn of(s: &Signal, q: Option<Quantity>) -> Self {
        let per_unit = q.map_or(1.0, |q| {
            q.to_si(s.unit.as_deref().unwrap_or(q.si())).unwrap_or(f64::NAN)
        });
        Conv {
            per_unit,
            sign: s.sign,
            reference: s.pressure,
        }
    }

    fn apply(self, x: f64) -> f64 {
        match self.reference {
            Some(r) => self.sign * gauge_pa(x, self.per_unit, r),
            None => self.sign * x * self.per_unit,
        }
    }
}

/// The map resolved against the description.
struct Plan {
    outputs: Vec<Typed>,
    convs: Vec<Conv>,
    /// Which optional signals are read (position, velocity, impacts).
    optional: [bool; 3],
    supply: (Typed, f64, Reference),
    base: Vec<(Typed, f64)>,
    step_s: f64,
    /// The piston-force input: variable, FMU value per newton, the velocity
    /// column and m/s per its value.
    force: Option<(Typed, f64, usize, f64)>,
}

/// A foreign FMU, ready to run.
pub struct FmuModel {
    fmu: PathBuf,
    desc: Description,
    map: Option<ModelMap>,
    map_hash: Option<String>,
    plan: Option<Plan>,
    open: Request,
    opts: Options,
    pool: Pool,
    // Last: the directory outlives the workers that load from it.
    _unpacked: Unpacked,
}

/// The interpreter a pythonfmu FMU's binary embeds: libpython (opened
/// RTLD_GLOBAL so the extension modules it imports find its symbols) and
/// the module path (PYTHONPATH), both from the `python3` on PATH.
fn python_env() -> Result<(PathBuf, String), String> {
    let script = "import sysconfig, sys, os; print(os.path.join(sysconfig.get_config_var('LIBDIR'), sysconfig.get_config_var('LDLIBRARY'))); print(os.pathsep.join(p for p in sys.path if p))";
    let out = std::process::Command::new("python3")
        .args(["-c", script])
        .output()
        .map_err(|e| format!("a pythonfmu FMU needs python3: {e}"))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let mut lines = text.lines();
    match (out.status.success(), lines.next(), lines.next()) {
        (true, Some(lib), Some(path)) if Path::new(lib).is_file() => Ok((PathBuf::from(lib), path.to_string())),
        _ => Err("a pythonfmu FMU needs python3 with its shared libpython (none found)".into()),
    }
}

impl FmuModel {
    fn err(&self, kind: FailKind, detail: impl Into<String>) -> FmuError {
        FmuError {
            fmu: self.fmu.clone(),
            kind,
            detail: detail.into(),
        }
    }

    /// [`Self::open`] with the map read from `model_map`, or from beside
    /// the FMU (`X.map.toml`) where one is: how the CLI and the Python
    /// package open a user's model, in at most `threads` workers started
    /// by `worker`, each call within `time_limit_s`. Also returns the
    /// map's path (for a message that it is missing).
    pub fn open_mapped(
        fmu: &Path,
        model_map: Option<&Path>,
        threads: usize,
        time_limit_s: f64,
        worker: WorkerCommand,
    ) -> Result<(Self, PathBuf), String> {
        if !(time_limit_s > 0.0 && time_limit_s.is_finite()) {
            return Err("the time limit must be positive seconds".into());
        }
        let map_path = model_map.map_or_else(|| crate::map_path(fmu), Path::to_path_buf);
        let map = if model_map.is_none() && !map_path.is_file() {
            None
        } else {
            Some(ModelMap::read(&map_path)?)
        };
        let opts = Options {
            threads,
            time_limit: Duration::from_secs_f64(time_limit_s),
            worker,
        };
        let model = Self::open(fmu, map, opts).map_err(|e| e.to_string())?;
        Ok((model, map_path))
    }

    /// Opens `fmu` (unpacks, reads its description, checks `map` against
    /// it, loads the binary in a first worker and instantiates it).
    pub fn open(fmu: &Path, map: Option<(ModelMap, String)>, mut opts: Options) -> Result<Self, FmuError> {
        let fail = |kind, detail: String| FmuError {
            fmu: fmu.to_path_buf(),
            kind,
            detail,
        };
        if let Err(e) = std::fs::metadata(fmu) {
            return Err(fail(FailKind::Open, format!("cannot read it: {e}")));
        }
        let unpacked = unpack(fmu).map_err(|e| fail(FailKind::NotZip, e))?;
        let (desc, id) = Description::read_cosim(&unpacked.dir).map_err(|e| fail(FailKind::Description, e))?;
        let so = unpacked.dir.join("binaries/linux64").join(format!("{id}.so"));
        if !so.is_file() {
            let found: Vec<String> = std::fs::read_dir(unpacked.dir.join("binaries"))
                .map(|d| {
                    d.filter_map(|e| e.ok())
                        .map(|e| e.file_name().to_string_lossy().into_owned())
                        .collect()
                })
                .unwrap_or_default();
            return Err(fail(
                FailKind::NoBinary,
                format!(
                    "no binary for this platform (binaries/linux64/{id}.so); it has binaries for: {}{}",
                    if found.is_empty() {
                        "none".to_string()
                    } else {
                        found.join(", ")
                    },
                    if desc.source_files.is_empty() && !unpacked.dir.join("sources/buildDescription.xml").is_file() {
                        "; export it with a linux64 binary or with its sources (docs/your-model.md)".to_string()
                    } else {
                        format!("; it has sources: `hammer fmu compile {}` builds one", fmu.display())
                    }
                ),
            ));
        }
        let mut preload = Vec::new();
        if desc
            .generation_tool
            .as_deref()
            .is_some_and(|t| t.starts_with("PythonFMU"))
        {
            let (lib, path) = python_env().map_err(|e| fail(FailKind::NoBinary, e))?;
            preload.push(lib);
            opts.worker.env.push(("PYTHONPATH".into(), path));
        }
        let (map, map_hash) = match map {
            Some((m, text)) => {
                let problems = check_map(&m, &desc);
                if !problems.is_empty() {
                    return Err(fail(
                        FailKind::Map,
                        format!("the map does not fit it: {}", problems.join("; ")),
                    ));
                }
                (Some(m), Some(map_hash(&text)))
            }
            None => (None, None),
        };
        let plan = match &map {
            Some(m) => Some(plan(m, &desc).map_err(|e| fail(FailKind::Map, e))?),
            None => None,
        };
        let open = Request::Open {
            so,
            guid: desc.guid.clone(),
            resources: unpacked.dir.join("resources"),
            preload,
        };
        let model = FmuModel {
            fmu: fmu.to_path_buf(),
            desc,
            map,
            map_hash,
            plan,
            open,
            pool: Pool::new(opts.threads),
            opts,
            _unpacked: unpacked,
        };
        // The first worker now: a binary that does not load or instantiate
        // is an error of the open, not of the first run.
        let reserved = model.pool.take();
        debug_assert!(reserved.is_none(), "a new pool has no idle worker");
        match model.start() {
            Ok(w) => model.pool.give(Some(w)),
            Err(e) => {
                model.pool.give(None);
                return Err(e);
            }
        }
        Ok(model)
    }

    /// A new worker with the FMU loaded and instantiated.
    fn start(&self) -> Result<Worker, FmuError> {
        let mut w = Worker::spawn(&self.opts.worker).map_err(|e| self.err(FailKind::Worker, e))?;
        match w.ask(&self.open, self.opts.time_limit) {
            Ok((Reply::Ready, _)) => Ok(w),
            Ok((Reply::Failed(e), _)) => Err(self.err(classify(&e), e)),
            Ok(_) => Err(self.err(FailKind::Worker, "an unexpected reply to open")),
            Err((kind, e)) => Err(self.err(kind, e)),
        }
    }

    pub fn description(&self) -> &Description {
        &self.desc
    }

    pub fn map(&self) -> Option<&ModelMap> {
        self.map.as_ref()
    }

    pub fn identity(&self) -> Identity {
        Identity {
            name: self.desc.model_name.clone(),
            guid: self.desc.guid.clone(),
            fmi_version: self.desc.fmi_version.clone(),
            generation_tool: self.desc.generation_tool.clone(),
            map_hash: self.map_hash.clone(),
        }
    }

    /// The communication step runs use, s.
    pub fn step_s(&self) -> Option<f64> {
        self.plan.as_ref().map(|p| p.step_s)
    }

    /// Worker processes alive now.
    pub fn workers(&self) -> usize {
        self.pool.live()
    }

    /// One run from t = 0 to `duration_s` at gauge supply pressure
    /// `supply_pa`: the map's fixed values, every mapped effect off, then
    /// `settings` (FMU parameter names, values in the FMU's units; a switch
    /// is 0 or 1) set before initialisation.
    pub fn run(&self, supply_pa: f64, settings: &[(String, f64)], duration_s: f64) -> Result<Signals, FmuError> {
        self.run_with_friction(supply_pa, settings, &hammer_sim::Effects::default(), duration_s)
    }

    /// [`Self::run`] with the friction of `outside`'s effects driven
    /// through the map's piston-force input (`[outside] piston_force`),
    /// evaluated before each communication step and held over it.
    pub fn run_with_friction(
        &self,
        supply_pa: f64,
        settings: &[(String, f64)],
        outside: &hammer_sim::Effects,
        duration_s: f64,
    ) -> Result<Signals, FmuError> {
        self.run_keeping(supply_pa, settings, outside, duration_s, true)
    }

    /// [`Self::run_with_friction`]; with `all` false only the three
    /// signals come back (position, velocity and the impacts are None):
    /// the worker reads and pipes only those (all of them when it drives
    /// friction, which reads the velocity).
    pub fn run_keeping(
        &self,
        supply_pa: f64,
        settings: &[(String, f64)],
        outside: &hammer_sim::Effects,
        duration_s: f64,
        all: bool,
    ) -> Result<Signals, FmuError> {
        let plan = self
            .plan
            .as_ref()
            .ok_or_else(|| self.err(FailKind::Map, "no model map: give one to run the FMU"))?;
        let steps = (duration_s / plan.step_s).round();
        if !(steps >= 1.0 && steps <= 1e8) || (steps * plan.step_s - duration_s).abs() > 1e-9 * duration_s.max(1.0) {
            return Err(self.err(
                FailKind::Map,
                format!(
                    "a run of {duration_s} s is not a whole number of communication steps of {} s",
                    plan.step_s
                ),
            ));
        }
        let mut starts = plan.base.clone();
        for (name, v) in settings {
            let t = settable(&self.desc, name, false).map_err(|e| self.err(FailKind::Map, e))?;
            if !v.is_finite() {
                return Err(self.err(FailKind::Map, format!("{name} = {v} is not a finite number")));
            }
            starts.push((t, *v));
        }
        let (sv, per_unit, reference) = plan.supply;
        starts.push((sv, from_gauge_pa(supply_pa, per_unit, reference)));
        let drive = self.drive(plan, outside, supply_pa)?;
        // A run for its three signals reads only those (a third of a run of
        // the project's own FMU went to reading outputs); the friction
        // drive needs the velocity, so a driven run reads every output.
        let read = if all || drive.is_some() {
            plan.outputs.len()
        } else {
            SIGNALS
        };
        let send = if all { plan.outputs.len() } else { SIGNALS };
        let request = Request::Run {
            starts,
            outputs: plan.outputs[..read].to_vec(),
            send,
            step_s: plan.step_s,
            steps: steps as usize,
            drive,
        };
        let mut w = match self.pool.take() {
            Some(w) => w,
            None => match self.start() {
                Ok(w) => w,
                Err(e) => {
                    self.pool.give(None);
                    return Err(e);
                }
            },
        };
        let answer = w.ask(&request, self.opts.time_limit);
        let data = match answer {
            Ok((Reply::Samples { .. }, data)) => {
                self.pool.give(Some(w));
                data
            }
            other => {
                drop(w);
                self.pool.give(None);
                return Err(match other {
                    Ok((Reply::Failed(e), _)) => self.err(classify(&e), e),
                    Ok(_) => self.err(FailKind::Worker, "an unexpected reply to a run"),
                    Err((kind, e)) => self.err(kind, e),
                });
            }
        };
        Ok(signals(plan, &data, all))
    }
}

impl FmuModel {
    /// The worker's drive for `outside`'s friction (None without effects).
    fn drive(&self, plan: &Plan, outside: &hammer_sim::Effects, supply_pa: f64) -> Result<Option<Drive>, FmuError> {
        let active = outside.active();
        if active.is_empty() {
            return Ok(None);
        }
        let Some((input, input_per_n, velocity_column, mps_per_velocity)) = plan.force else {
            return Err(self.err(
                FailKind::Map,
                format!(
                    "{} cannot go in from outside: the map names no piston-force input",
                    active.join(", ")
                ),
            ));
        };
        for name in &active {
            if !hammer_sim::effects::entry(name).is_some_and(is_piston_force) {
                return Err(self.err(FailKind::Map, format!("{name} is not a force on the piston")));
            }
        }
        Ok(Some(Drive {
            input,
            input_per_n,
            velocity_column,
            mps_per_velocity,
            effects: outside.clone(),
            supply_bar: supply_pa / 1e5,
        }))
    }
}

/// What a worker's failure message says failed (the messages are
/// [`super::fmi2`]'s own).
fn classify(e: &str) -> FailKind {
    if e.contains("has no function") {
        FailKind::MissingFunction
    } else if e.starts_with("cannot load") {
        FailKind::NoBinary
    } else if e.contains("non-finite") {
        FailKind::NonFinite
    } else if e.contains("fmi2Instantiate")
        || e.contains("InitializationMode")
        || e.contains("fmi2SetupExperiment")
        || e.contains("fmi2Reset")
    {
        FailKind::Instantiate
    } else {
        FailKind::Step
    }
}

fn plan(map: &ModelMap, desc: &Description) -> Result<Plan, String> {
    let s = &map.signals;
    let mut outputs = Vec::new();
    let mut convs = Vec::new();
    let mut optional = [false; 3];
    let mut read = |sig: &Signal, q: Option<Quantity>| -> Result<(), String> {
        outputs.push(output(desc, &sig.output)?);
        convs.push(Conv::of(sig, q));
        Ok(())
    };
    read(&s.p_rear, Some(Quantity::Pressure))?;
    read(&s.p_front, Some(Quantity::Pressure))?;
    read(&s.accel, Some(Quantity::Acceleration))?;
    for (k, (sig, q)) in [
        (&s.position, Some(Quantity::Length)),
        (&s.velocity, Some(Quantity::Velocity)),
        (&s.impact_counter, None),
    ]
    .into_iter()
    .enumerate()
    {
        if let Some(sig) = sig {
            read(sig, q)?;
            optional[k] = true;
        }
    }
    let force = match (&map.outside.piston_force, &s.velocity) {
        (Some(f), Some(_)) => {
            let column = 3 + usize::from(s.position.is_some());
            Some((
                settable(desc, &f.input, true)?,
                f.sign,
                column,
                convs[column].sign * convs[column].per_unit,
            ))
        }
        _ => None,
    };
    let supply_var = settable(desc, map.supply.variable(), false)?;
    let per_unit = Quantity::Pressure.to_si(&map.supply.unit).unwrap_or(f64::NAN);
    let mut base = Vec::new();
    for (name, v) in &map.fixed {
        base.push((settable(desc, name, false)?, *v));
    }
    for (name, v) in map.effects_off() {
        base.push((settable(desc, &name, false)?, v));
    }
    let step_s = map
        .step_s
        .or(desc.default_step_s)
        .ok_or("no communication step: give step_s in the map (the FMU has no DefaultExperiment stepSize)")?;
    Ok(Plan {
        outputs,
        convs,
        optional,
        supply: (supply_var, per_unit, map.supply.pressure),
        base,
        step_s,
        force,
    })
}

/// The columns every run reads first: rear and front pressure, acceleration.
const SIGNALS: usize = 3;

/// The samples of a run as [`Signals`]; `all`: every mapped output was
/// sent, else the first [`SIGNALS`].
fn signals(plan: &Plan, data: &[f64], all: bool) -> Signals {
    let cols = if all { plan.outputs.len() } else { SIGNALS };
    let column = |j: usize| -> Vec<f64> { data.chunks_exact(cols).map(|row| plan.convs[j].apply(row[j])).collect() };
    let mut next = SIGNALS;
    let mut optional = |on: bool| {
        (all && on).then(|| {
            next += 1;
            column(next - 1)
        })
    };
    let position_m = optional(plan.optional[0]);
    let velocity_mps = optional(plan.optional[1]);
    let impacts = optional(plan.optional[2]);
    Signals {
        dt_s: plan.step_s,
        p_rear_pa: column(0),
        p_front_pa: column(1),
        accel_mps2: column(2),
        position_m,
        velocity_mps,
        impacts,
    }
}
