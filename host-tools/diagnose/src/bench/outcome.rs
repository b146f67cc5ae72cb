//! How a case's verdict stands against what was hidden: named exactly, a
//! close call whose group holds the truth, nothing named, or wrong (issue
//! 44), and the raw naming the confusion matrix keeps.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::super::report::Report;

/// The four outcomes a case is scored by.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum Outcome {
    /// Named outright what was hidden, no group (a control: nothing at all).
    #[default]
    Exact,
    /// One group of at most two effects, which with what is named outright
    /// holds the truth.
    Group,
    /// Nothing named where something was hidden.
    None,
    /// Anything else: an effect named outright that was not hidden, a
    /// group without the truth, a flagged control.
    Wrong,
}

impl Outcome {
    pub fn label(self) -> &'static str {
        match self {
            Outcome::Exact => "exact",
            Outcome::Group => "group",
            Outcome::None => "none",
            Outcome::Wrong => "wrong",
        }
    }
}

/// What a report named: outright, in groups, and raw (the outright ones
/// and each group's first member, the ranking's choice).
pub struct Named {
    pub outright: Vec<String>,
    pub groups: Vec<Vec<String>>,
    pub raw: Vec<String>,
    /// The parameters of each raw-named effect, in the catalogue's terms.
    pub params: BTreeMap<String, serde_json::Value>,
}

impl Named {
    pub fn of(r: &Report) -> Self {
        let outright: Vec<String> = r.verdict.effects.iter().filter(|e| *e != "none").cloned().collect();
        let groups: Vec<Vec<String>> = r
            .verdict
            .alternatives
            .iter()
            .map(|g| g.iter().map(|a| a.effect.clone()).collect())
            .collect();
        let mut params = BTreeMap::new();
        for name in &outright {
            let p = if outright.len() == 1 {
                r.verdict.params.clone()
            } else {
                r.verdict.params.get(name).cloned().unwrap_or_default()
            };
            params.insert(name.clone(), p);
        }
        let mut raw = outright.clone();
        for g in &r.verdict.alternatives {
            if let Some(first) = g.first() {
                raw.push(first.effect.clone());
                params.insert(first.effect.clone(), first.params.clone());
            }
        }
        Self {
            outright,
            groups,
            raw,
            params,
        }
    }

    /// The outcome against the `hidden` effects.
    pub fn outcome(&self, hidden: &[String]) -> Outcome {
        let same = |a: &[String], b: &[String]| {
            let (mut a, mut b) = (a.to_vec(), b.to_vec());
            a.sort();
            b.sort();
            a == b
        };
        match self.groups.as_slice() {
            [] if same(&self.outright, hidden) => Outcome::Exact,
            [] if self.outright.is_empty() => Outcome::None,
            [g] if g.len() <= 2 && !hidden.is_empty() => {
                let holds = g.iter().any(|m| {
                    let mut with = self.outright.clone();
                    with.push(m.clone());
                    same(&with, hidden)
                });
                if holds {
                    Outcome::Group
                } else {
                    Outcome::Wrong
                }
            }
            _ => Outcome::Wrong,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn named(outright: &[&str], groups: &[&[&str]]) -> Named {
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        Named {
            outright: s(outright),
            groups: groups.iter().map(|g| s(g)).collect(),
            raw: Vec::new(),
            params: BTreeMap::new(),
        }
    }

    #[test]
    fn four_outcomes() {
        let h = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        assert_eq!(named(&["leakage"], &[]).outcome(&h(&["leakage"])), Outcome::Exact);
        assert_eq!(named(&[], &[]).outcome(&h(&[])), Outcome::Exact, "a quiet control");
        assert_eq!(
            named(&[], &[&["heat_transfer", "leakage"]]).outcome(&h(&["leakage"])),
            Outcome::Group
        );
        assert_eq!(
            named(&[], &[&["heat_transfer", "leakage"]]).outcome(&h(&[])),
            Outcome::Wrong,
            "a flagged control"
        );
        assert_eq!(
            named(&["coulomb_friction"], &[&["heat_transfer", "leakage"]])
                .outcome(&h(&["leakage", "coulomb_friction"])),
            Outcome::Group
        );
        assert_eq!(
            named(&[], &[&["heat_transfer", "supply_restriction"]]).outcome(&h(&["leakage"])),
            Outcome::Wrong
        );
        assert_eq!(named(&[], &[]).outcome(&h(&["leakage"])), Outcome::None);
        assert_eq!(named(&["heat_transfer"], &[]).outcome(&h(&["leakage"])), Outcome::Wrong);
    }
}

/// The cases' outcomes counted, and against a record the same cases
/// against the model alone beside them.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct Tally {
    /// Singles and pairs by outcome label (exact, group, none, wrong).
    pub singles: BTreeMap<String, usize>,
    pub pairs: BTreeMap<String, usize>,
    /// Controls with anything named or grouped: (flagged, all).
    pub controls_flagged: (usize, usize),
    /// Friction cases whose fitted law lies within U of the force balance
    /// at every point: (within, all).
    pub friction_within_u: (usize, usize),
    /// Named valve delays whose front port shift in the model lies within
    /// 15 % of the hammer's true shift: (within, all).
    #[serde(default)]
    pub port_shift_within_15pct: (usize, usize),
    /// Named or grouped heat exchanges and leaks whose physical size in the
    /// verdict's model lies within 15 % of the hammer's, by effect:
    /// (within, all).
    #[serde(default)]
    pub physical_within_15pct: BTreeMap<String, (usize, usize)>,
    /// The same counts against the model alone (with references only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alone: Option<Box<Tally>>,
    /// Cases with an effect: the held-out energy error after the fit,
    /// mean with the record and alone, % of the measured energy.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub energy_after_with_and_alone: Option<(f64, f64)>,
    /// Cases whose error with the record is more than 0.5 points worse
    /// than alone: (index, with, alone).
    #[serde(default)]
    pub worse_with_record: Vec<(usize, f64, f64)>,
}

/// How much worse than alone a case's held-out energy error may be with
/// the record, in points of %: the bound.
pub const WORSE_BY_POINTS: f64 = 0.5;

/// How close a physical size must come to the truth's: the bound.
pub const PHYSICAL_WITHIN: f64 = 0.15;

impl Tally {
    pub fn of(cases: &[super::CaseResult]) -> Self {
        let mut t = Self::count(cases.iter().map(|c| (&c.hidden, c.outcome)));
        for c in cases {
            if let Some(e) = c.port_shift_error {
                t.port_shift_within_15pct.0 += usize::from(e <= PHYSICAL_WITHIN);
                t.port_shift_within_15pct.1 += 1;
            }
            for p in &c.physical_sizes {
                let e = t.physical_within_15pct.entry(p.effect.clone()).or_default();
                e.0 += usize::from(p.error <= PHYSICAL_WITHIN);
                e.1 += 1;
            }
            if let Some(w) = c.friction_within_u {
                t.friction_within_u.0 += usize::from(w);
                t.friction_within_u.1 += 1;
            }
        }
        let alone: Vec<(&super::CaseResult, &super::Alone)> =
            cases.iter().filter_map(|c| Some((c, c.alone.as_ref()?))).collect();
        if !alone.is_empty() {
            t.alone = Some(Box::new(Self::count(alone.iter().map(|(c, a)| (&c.hidden, a.outcome)))));
            let with_effect: Vec<_> = alone.iter().filter(|(c, _)| c.hidden != super::Hidden::None).collect();
            let n = with_effect.len().max(1) as f64;
            t.energy_after_with_and_alone = Some((
                with_effect.iter().map(|(c, _)| c.energy_error_after).sum::<f64>() / n,
                with_effect.iter().map(|(_, a)| a.energy_error_after).sum::<f64>() / n,
            ));
            t.worse_with_record = with_effect
                .iter()
                .filter(|(c, a)| c.energy_error_after > a.energy_error_after + WORSE_BY_POINTS)
                .map(|(c, a)| (c.index, c.energy_error_after, a.energy_error_after))
                .collect();
        }
        t
    }

    fn count<'a>(cases: impl Iterator<Item = (&'a super::Hidden, Outcome)>) -> Self {
        let mut t = Self::default();
        for (hidden, outcome) in cases {
            match hidden {
                super::Hidden::None => {
                    t.controls_flagged.0 += usize::from(outcome != Outcome::Exact);
                    t.controls_flagged.1 += 1;
                }
                super::Hidden::One(_) => *t.singles.entry(outcome.label().into()).or_default() += 1,
                super::Hidden::Two(..) => *t.pairs.entry(outcome.label().into()).or_default() += 1,
            }
        }
        t
    }

    /// One line per kind of case: the four outcomes in % of its cases.
    fn lines(&self, out: &mut String, indent: &str) {
        use std::fmt::Write as _;
        for (what, counts) in [("singles", &self.singles), ("pairs", &self.pairs)] {
            let n: usize = counts.values().sum();
            let part = |k: &str| {
                let c = counts.get(k).copied().unwrap_or(0);
                format!("{k} {c}/{n} ({:.1} %)", 100.0 * c as f64 / n.max(1) as f64)
            };
            let _ = writeln!(
                out,
                "{indent}{what:<8} {}, {}, {}, {}",
                part("exact"),
                part("group"),
                part("none"),
                part("wrong")
            );
        }
        let (f, n) = self.controls_flagged;
        let _ = writeln!(
            out,
            "{indent}controls flagged (named or grouped) {f}/{n} ({:.1} %)",
            100.0 * f as f64 / n.max(1) as f64
        );
    }

    pub fn render(&self, out: &mut String) {
        use std::fmt::Write as _;
        let _ = writeln!(
            out,
            "\noutcomes (exact; a group of at most two holding the truth; none; wrong):"
        );
        self.lines(out, "  ");
        let (w, n) = self.friction_within_u;
        if n > 0 {
            let _ = writeln!(
                out,
                "  friction cases with the fitted law within U of the force balance at every point: {w}/{n}"
            );
        }
        let (w, n) = self.port_shift_within_15pct;
        if n > 0 {
            let _ = writeln!(
                out,
                "  valve delays named or grouped, sized in physical terms (the verdict's model's front port shift at the named τ against the hammer's true shift): within 15 % in {w}/{n}"
            );
        }
        for (effect, (w, n)) in &self.physical_within_15pct {
            let what = match effect.as_str() {
                "heat_transfer" => "heat exchanges named or grouped, sized as the heat across the walls a cycle",
                _ => "leaks named or grouped, sized as the air leaked a cycle",
            };
            let _ = writeln!(
                out,
                "  {what} (the verdict's model at the named size against the hammer's): within 15 % in {w}/{n}"
            );
        }
        let (mut w, mut n) = self.port_shift_within_15pct;
        for (a, b) in self.physical_within_15pct.values() {
            (w, n) = (w + a, n + b);
        }
        if n > 0 {
            let _ = writeln!(
                out,
                "  physical sizes within 15 % over the three: {w}/{n} ({:.1} %)",
                100.0 * w as f64 / n as f64
            );
        }
        if let Some(a) = &self.alone {
            let _ = writeln!(out, "the same cases against the model alone:");
            a.lines(out, "  ");
        }
        if let Some((with, alone)) = self.energy_after_with_and_alone {
            let _ = writeln!(
                out,
                "held-out energy error after the fit, mean over cases with an effect, % of the measured energy: {with:.2} with the record, {alone:.2} alone; {} cases more than {WORSE_BY_POINTS} points worse with it{}",
                self.worse_with_record.len(),
                self.worse_with_record
                    .iter()
                    .map(|(i, w, a)| format!(" (case {i}: {w:.2} against {a:.2})"))
                    .collect::<String>()
            );
        }
    }
}

/// Every case with and without its record, side by side.
pub fn side_by_side(out: &mut String, cases: &[super::CaseResult]) {
    use std::fmt::Write as _;
    if cases.iter().all(|c| c.alone.is_none()) {
        return;
    }
    let names = |raw: &[String], groups: &[Vec<String>]| {
        let mut s = if raw.is_empty() {
            "none".to_string()
        } else {
            raw.join("+")
        };
        for g in groups {
            s += &format!(" [{}]", g.join("|"));
        }
        s
    };
    let errs = |e: &BTreeMap<String, f64>| {
        e.iter()
            .map(|(k, v)| {
                format!(
                    "{}={:.1}%",
                    k.split('_').map(|w| &w[..w.len().min(4)]).collect::<Vec<_>>().join("_"),
                    100.0 * v
                )
            })
            .collect::<Vec<_>>()
            .join(" ")
    };
    let _ = writeln!(out, "\nevery case, with the record | against the model alone (named [group], outcome, size errors, held-out energy error %):");
    for c in cases {
        let Some(a) = &c.alone else { continue };
        let _ = writeln!(
            out,
            "  case {:>3} hidden {:<40} | {} {} {} {:.2} | {} {} {} {:.2}",
            c.index,
            c.hidden.names().join("+"),
            names(&c.named, &c.alternatives),
            c.outcome.label(),
            errs(&c.param_errors),
            c.energy_error_after,
            names(&a.named, &a.alternatives),
            a.outcome.label(),
            errs(&a.param_errors),
            a.energy_error_after
        );
    }
}
