//! A close call against a record, parted by the hammer's own waveforms.
//!
//! Against a record, the diagnosis fits the change since the record: the
//! model's form error cancels, and so does much of what sets two effects
//! apart in absolute terms. A close call there says that the change alone
//! cannot part them. The same traces fitted by the model alone are other
//! evidence: the absolute levels, where the effects differ but the form
//! error has not cancelled. Neither reading may overrule the other:
//!
//! - where the model alone puts the same member first and names it
//!   outright, with no close call of its own and no other member of the
//!   group beside it, the two readings together part the group, and the
//!   member is named outright (the group and the model alone's scores are
//!   kept in the report);
//! - where the model alone names another member, none, or a close call of
//!   its own, the group stays as the record left it.
//!
//! So a record adds evidence and never subtracts it: on the structural
//! benchmark the record had grouped heat exchange with a leak in cases the
//! model alone named heat exchange outright (seed 7: 15, 48, 67, 89), and
//! in case 112 the model alone named heat exchange where the record's
//! group put the true supply restriction first: that group stays.

use crate::report::{Alternative, EffectResult, Parted, Verdict};

/// The close call `group` (the ranking's choice first) parted by `alone`,
/// the same traces' verdict against the model alone (`singles`: its single
/// effects as ranked); `None` where the model alone does not part it.
pub(crate) fn by_alone(group: &[Alternative], alone: &Verdict, singles: &[EffectResult]) -> Option<Parted> {
    let first = &group.first()?.effect;
    let v = alone;
    let others_named = group[1..].iter().any(|a| v.effects.contains(&a.effect));
    if group.len() < 2 || !v.alternatives.is_empty() || !v.effects.contains(first) || others_named {
        return None;
    }
    let score = |name: &str| singles.iter().find(|e| e.name == name).map(|e| e.score);
    Some(Parted {
        group: group.iter().map(|a| a.effect.clone()).collect(),
        alone_scores: group.iter().map(|a| score(&a.effect)).collect(),
        alone_effects: v.effects.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn member(name: &str) -> Alternative {
        Alternative {
            effect: name.into(),
            params: serde_json::json!({}),
            score: 100.0,
            impact_energy_error_after: 0.01,
            frequency_error_after: 0.01,
            parting_test: None,
        }
    }

    /// The model alone's verdict: `effects` outright, `groups` as close calls.
    fn alone(effects: &[&str], groups: &[&[&str]]) -> Verdict {
        Verdict {
            effects: effects.iter().map(|e| e.to_string()).collect(),
            params: serde_json::json!({}),
            score: 50.0,
            reason: String::new(),
            alternatives: groups.iter().map(|g| g.iter().map(|n| member(n)).collect()).collect(),
            confirmation: None,
            parted: None,
        }
    }

    #[test]
    fn the_model_alone_parts_a_close_call_only_where_it_names_the_same_first_outright() {
        let group = [member("heat_transfer"), member("leakage")];
        let parted = by_alone(&group, &alone(&["heat_transfer"], &[]), &[]).expect("parted");
        assert_eq!(parted.group, ["heat_transfer", "leakage"]);
        assert_eq!(parted.alone_effects, ["heat_transfer"]);
        // Another member first, none, both, or a close call of its own: the group stays.
        assert!(by_alone(&group, &alone(&["leakage"], &[]), &[]).is_none());
        assert!(by_alone(&group, &alone(&["none"], &[]), &[]).is_none());
        assert!(by_alone(&group, &alone(&["heat_transfer", "leakage"], &[]), &[]).is_none());
        assert!(by_alone(&group, &alone(&[], &[&["heat_transfer", "leakage"]]), &[]).is_none());
        // A pair's first member beside it is no objection.
        assert!(by_alone(&group, &alone(&["coulomb_friction", "heat_transfer"], &[]), &[]).is_some());
        assert!(by_alone(&group[..1], &alone(&["heat_transfer"], &[]), &[]).is_none());
    }
}
