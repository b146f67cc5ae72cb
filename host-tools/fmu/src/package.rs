//! The `.fmu` file `hammer fmu` writes (a zip: modelDescription.xml, the
//! shared library under `binaries/linux64/`, `resources/config.json`,
//! `documentation/index.html`) and the model map beside it that
//! `hammer diagnose --model-map` reads (issue 46).

use hammer_sim::params::{NOMINAL_UNCERTAINTY, NUISANCE};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use hammer_sim::effects::REGISTRY;

use crate::description::{guid, model_description, resource};
use crate::instance::Model;
use crate::table::{Binding, Table, Val};

/// The shared library cargo builds from this crate.
pub const LIBRARY_FILE: &str = "libhammer_fmu.so";

/// The second family's nominal values its engineer is unsure of
/// (`hammer_variants::structure::UNCERTAIN`: the ones the structural
/// benchmark draws around nominal), as the FMU's parameters. Declaring
/// fewer left the benchmark's hammers moved where the model could not
/// follow: with only the eight that have a built-in counterpart, two of
/// seed 7's twenty controls were flagged, a polytropic exponent read as
/// heat exchange and a hose as a supply restriction (docs/your-model.md).
pub fn variant_nuisance() -> Vec<String> {
    hammer_variants::structure::UNCERTAIN
        .iter()
        .map(|name| format!("params.{name}"))
        .collect()
}

/// What a model's FMU is called and says of itself.
struct Identity {
    model_identifier: &'static str,
    description: &'static str,
    stop_time_s: f64,
    step_s: f64,
    /// The nominal parameters the map's `[[nuisance]]` lists.
    nuisance: Vec<String>,
}

fn identity(model: &Model) -> Identity {
    match model {
        Model::Hammer(cfg) => Identity {
            model_identifier: "hammer",
            description: "The paper's small pneumatic impact hammer (hammer-monitor's simulator): piston, two chambers, pilot valve, supply; sensor chain with a seed",
            stop_time_s: cfg.solver.duration_s,
            step_s: cfg.solver.output_step_s,
            nuisance: NUISANCE.iter().map(|(name, _)| name.to_string()).collect(),
        },
        Model::Variants(cfg) => Identity {
            model_identifier: "hammer_variants",
            description: "The paper's hammer in hammer-monitor's second model family (hammer-variants): other valve, port, chamber, supply, anvil and sensor laws, fixed-step RK4",
            stop_time_s: cfg.duration_s,
            step_s: hammer_variants::generate::STEP_S * hammer_variants::generate::OUTPUT_EVERY as f64,
            nuisance: variant_nuisance(),
        },
    }
}

/// What `hammer fmu` wrote.
#[derive(Debug)]
pub struct Written {
    pub fmu: PathBuf,
    pub map: PathBuf,
    pub guid: String,
    pub parameters: usize,
    pub outputs: usize,
}

/// The environment variable that names the shared library.
pub const LIBRARY_ENV: &str = "HAMMER_FMU_LIB";

/// Where the FMU's shared library is: `explicit` (`--lib`), else
/// `$HAMMER_FMU_LIB`, else beside the running executable. Cargo puts it
/// there when the workspace or `-p hammer-fmu` is built; building `hammer`
/// alone builds it as a dependency into `deps/` beside the executable. Of
/// those two the newer is taken (the other may be left from an older
/// build). Missing: an error saying how to build it.
pub fn find_library(explicit: Option<&Path>) -> Result<PathBuf, String> {
    let candidates = match explicit {
        Some(p) => vec![p.to_path_buf()],
        None => match std::env::var_os(LIBRARY_ENV) {
            Some(p) => vec![PathBuf::from(p)],
            None => {
                let exe = std::env::current_exe().map_err(|e| format!("where is this program? {e}"))?;
                let dir = exe.parent().unwrap_or(Path::new("."));
                vec![dir.join(LIBRARY_FILE), dir.join("deps").join(LIBRARY_FILE)]
            }
        },
    };
    let modified = |p: &PathBuf| {
        std::fs::metadata(p)
            .ok()
            .filter(|m| m.is_file())
            .map(|m| m.modified().ok())
    };
    match candidates
        .iter()
        .filter_map(|p| Some((modified(p)?, p)))
        .max_by_key(|(t, _)| *t)
    {
        Some((_, p)) => Ok(p.clone()),
        None => Err(format!(
            "the FMU's shared library {} is missing: build it with `cargo build --release -p hammer-fmu` \
             (it lands beside `hammer` in target/release), or give its path with --lib or ${LIBRARY_ENV}",
            candidates[0].display()
        )),
    }
}

/// The model map's path beside `fmu`: `hammer.fmu` → `hammer.map.toml`.
pub fn map_path(fmu: &Path) -> PathBuf {
    fmu.with_extension("map.toml")
}

/// Writes the FMU of `model` to `out` with the shared library at
/// `library`, and its model map beside it.
pub fn write_fmu(model: &Model, library: &Path, out: &Path) -> Result<Written, String> {
    let table = match model {
        Model::Hammer(cfg) => {
            cfg.validate().map_err(|e| e.to_string())?;
            Table::new(cfg)?
        }
        Model::Variants(cfg) => {
            cfg.validate()?;
            crate::variants::table(cfg)?
        }
    };
    let so = std::fs::read(library).map_err(|e| format!("{}: {e}", library.display()))?;
    let (resource_file, json) = resource(model)?;
    let id = guid(&json);
    let who = identity(model);
    let xml = model_description(
        &table,
        who.model_identifier,
        who.description,
        &id,
        who.stop_time_s,
        who.step_s,
    );
    let files: Vec<(String, Vec<u8>)> = vec![
        ("modelDescription.xml".into(), xml.into_bytes()),
        (format!("binaries/linux64/{}.so", who.model_identifier), so),
        (format!("resources/{resource_file}"), json.into_bytes()),
        ("documentation/index.html".into(), documentation(&table).into_bytes()),
    ];
    let zip = zip_stored(&files);
    std::fs::write(out, zip).map_err(|e| format!("{}: {e}", out.display()))?;
    let map = map_path(out);
    std::fs::write(&map, model_map(&table, out, &who.nuisance)?).map_err(|e| format!("{}: {e}", map.display()))?;
    let outputs = table.vars.iter().filter(|v| v.is_output()).count();
    Ok(Written {
        fmu: out.to_path_buf(),
        map,
        guid: id,
        parameters: table.vars.len() - outputs,
        outputs,
    })
}

/// The model map of the project's own FMU, in the one format
/// [`crate::import::map`] reads: the noiseless outputs (the diagnosis
/// applies the sensor effects itself, so the sensor effects are left to
/// `[outside]`), the supply parameter, the nuisance list, and every
/// physical catalogue effect with its switch and parameters.
fn model_map(table: &Table, fmu: &Path, nuisance: &[String]) -> Result<String, String> {
    use crate::import::map::{
        EffectCarrier, EffectParam, ModelMap, Nuisance, Outside, Reference, Signal, Signals, Supply,
    };
    let name = fmu
        .file_name()
        .map_or(String::new(), |n| n.to_string_lossy().into_owned());
    let start = |n: &str| {
        table.vars.iter().find(|v| v.name == n).and_then(|v| match v.start {
            Val::Real(x) => Some(x),
            _ => None,
        })
    };
    let signal = |output: &str, unit: Option<&str>, pressure: Option<Reference>| Signal {
        output: output.to_string(),
        unit: unit.map(str::to_string),
        pressure,
        sign: 1.0,
    };
    let out = |k: usize| table.outputs[k];
    let named = |n: &str| table.outputs.iter().find(|o| o.name == n).copied();
    let (x, v, count) = (named("x_m"), named("v_mps"), named("impact_count"));
    let mut effects = std::collections::BTreeMap::new();
    for (k, e) in REGISTRY.iter().enumerate().filter(|(_, e)| !e.sensor()) {
        let mut params = std::collections::BTreeMap::new();
        for var in &table.vars {
            let Binding::EffectParam(j, key) = &var.binding else {
                continue;
            };
            let Some(p) = e.params().iter().find(|p| p.key == key).filter(|_| *j == k) else {
                continue;
            };
            let nominal = match var.start {
                Val::Real(x) => x,
                _ => f64::NAN,
            };
            params.insert(
                key.clone(),
                EffectParam {
                    parameter: var.name.clone(),
                    unit: p.unit.to_string(),
                    lo: p.lo,
                    hi: p.hi,
                    nominal,
                    off: None,
                    scale: None,
                },
            );
        }
        effects.insert(
            e.name().to_string(),
            EffectCarrier {
                switch: Some(format!("effects.{}.on", e.name())),
                params,
                law: None,
            },
        );
    }
    let map = ModelMap {
        fmu: Some(name),
        step_s: None,
        signals: Signals {
            p_rear: signal(out(0).name, out(0).unit, Some(Reference::Gauge)),
            p_front: signal(out(1).name, out(1).unit, Some(Reference::Gauge)),
            accel: signal(out(2).name, out(2).unit, None),
            position: x.map(|o| signal(o.name, o.unit, None)),
            velocity: v.map(|o| signal(o.name, o.unit, None)),
            impact_counter: count.map(|o| signal(o.name, None, None)),
        },
        supply: Supply {
            parameter: Some("supply.pressure_bar".into()),
            input: None,
            unit: "bar".into(),
            pressure: Reference::Gauge,
        },
        nuisance: nuisance
            .iter()
            .map(|p| Nuisance {
                parameter: p.clone(),
                nominal: start(p).unwrap_or(f64::NAN),
                relative_uncertainty: NOMINAL_UNCERTAINTY,
            })
            .collect(),
        fixed: Default::default(),
        effects,
        outside: Outside::default(),
    };
    map.validate()
        .map_err(|e| format!("the model map written would not read back: {e}"))?;
    Ok(format!(
        "# The model map of {} for `hammer fmu check` and `hammer diagnose --model-map` (written by `hammer fmu`;\n\
         # format: docs/your-model.md). Signals are the noiseless outputs: the project applies the sensor effects.\n{}",
        map.fmu.as_deref().unwrap_or(""),
        map.to_toml()?
    ))
}

/// documentation/index.html: the variables, as the description lists them.
fn documentation(table: &Table) -> String {
    let mut h = String::from(
        "<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>hammer FMU</title></head><body>\n\
         <h1>The paper's pneumatic impact hammer (hammer-monitor)</h1>\n\
         <p>FMI 2.0 co-simulation, linux64. Parameters are fixed: set them before \
         initialisation. Outputs are the output-grid sample at or just before each \
         communication point (<code>solver.output_step_s</code>). See docs/your-model.md \
         in hammer-monitor.</p>\n<table><tr><th>vr</th><th>name</th><th>unit</th><th>start</th><th>description</th></tr>\n",
    );
    for (vr, v) in table.vars.iter().enumerate() {
        let start = if v.is_output() {
            "output".to_string()
        } else {
            format!("{:?}", v.start)
        };
        let _ = writeln!(
            h,
            "<tr><td>{vr}</td><td>{}</td><td>{}</td><td>{start}</td><td>{}</td></tr>",
            v.name,
            v.unit.as_deref().unwrap_or(""),
            v.description.replace('<', "&lt;")
        );
    }
    h.push_str("</table></body></html>\n");
    h
}

/// A zip archive of `files`, stored (no compression): the few lines a
/// reader needs, without a dependency for it.
pub fn zip_stored(files: &[(String, Vec<u8>)]) -> Vec<u8> {
    let mut out = Vec::new();
    let mut central = Vec::new();
    // 1980-01-01 00:00 in DOS time: a fixed date keeps the file reproducible.
    let (time, date) = (0u16, (0u16 << 9) | (1 << 5) | 1);
    for (name, data) in files {
        let crc = crc32fast::hash(data);
        let offset = out.len() as u32;
        let head = |sig: u32, central_entry: bool| {
            let mut b = Vec::new();
            b.extend(sig.to_le_bytes());
            if central_entry {
                b.extend(20u16.to_le_bytes()); // made by
            }
            b.extend(20u16.to_le_bytes()); // version needed
            b.extend(0u16.to_le_bytes()); // flags
            b.extend(0u16.to_le_bytes()); // stored
            b.extend(time.to_le_bytes());
            b.extend(date.to_le_bytes());
            b.extend(crc.to_le_bytes());
            b.extend((data.len() as u32).to_le_bytes());
            b.extend((data.len() as u32).to_le_bytes());
            b.extend((name.len() as u16).to_le_bytes());
            b.extend(0u16.to_le_bytes()); // extra
            if central_entry {
                b.extend([0u8; 6]); // comment length, disk, internal attributes
                b.extend(0u32.to_le_bytes()); // external attributes
                b.extend(offset.to_le_bytes());
            }
            b.extend(name.as_bytes());
            b
        };
        out.extend(head(0x0403_4b50, false));
        out.extend(data);
        central.extend(head(0x0201_4b50, true));
    }
    let (cd_offset, cd_len) = (out.len() as u32, central.len() as u32);
    out.extend(central);
    out.extend(0x0605_4b50u32.to_le_bytes());
    out.extend([0u8; 4]); // disk numbers
    out.extend((files.len() as u16).to_le_bytes());
    out.extend((files.len() as u16).to_le_bytes());
    out.extend(cd_len.to_le_bytes());
    out.extend(cd_offset.to_le_bytes());
    out.extend(0u16.to_le_bytes());
    out
}
