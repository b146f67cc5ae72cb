//! The map against the FMU's description: every parameter the map sets
//! exists and can be set before initialisation (not calculated, not a
//! constant); an input set during the run is not fixed after
//! initialisation; every output the map reads is one of the FMU's.

use super::describe::{Description, VarKind};
use super::fmi2::Typed;
use super::map::ModelMap;

/// The variable `name` as the worker addresses it, if it is settable:
/// `during_run` for an input the run drives.
pub fn settable(desc: &Description, name: &str, during_run: bool) -> Result<Typed, String> {
    let v = desc
        .variable(name)
        .ok_or_else(|| format!("the FMU has no variable {name}"))?;
    if let Some(why) = v.not_settable(during_run) {
        return Err(format!("{why}: it cannot be set"));
    }
    typed(v.kind, v.vr).ok_or_else(|| format!("{name} is an enumeration"))
}

fn typed(kind: VarKind, vr: u32) -> Option<Typed> {
    match kind {
        VarKind::Real => Some(Typed::Real(vr)),
        VarKind::Integer => Some(Typed::Integer(vr)),
        VarKind::Boolean => Some(Typed::Boolean(vr)),
        _ => None,
    }
}

/// The output `name` as the worker reads it.
pub fn output(desc: &Description, name: &str) -> Result<Typed, String> {
    let v = desc
        .variable(name)
        .ok_or_else(|| format!("the FMU has no output {name}"))?;
    if v.causality != "output" && v.causality != "local" {
        return Err(format!("{name} is not an output (causality {})", v.causality));
    }
    typed(v.kind, v.vr).ok_or_else(|| format!("output {name} is not a number"))
}

/// Every disagreement between `map` and `desc`, each naming the map's
/// key and the variable.
pub fn check_map(map: &ModelMap, desc: &Description) -> Vec<String> {
    let mut problems = Vec::new();
    for (name, at) in map.parameters() {
        if let Err(e) = settable(desc, &name, false) {
            problems.push(format!("{at}: {e}"));
        }
    }
    if let Some(input) = &map.supply.input {
        if let Err(e) = settable(desc, input, false) {
            problems.push(format!("supply.input: {e}"));
        }
    }
    if let Some(f) = &map.outside.piston_force {
        if let Err(e) = settable(desc, &f.input, true) {
            problems.push(format!("outside.piston_force: {e}"));
        }
    }
    for (name, at) in map.outputs() {
        if let Err(e) = output(desc, &name) {
            problems.push(format!("{at}: {e}"));
        }
    }
    problems
}
