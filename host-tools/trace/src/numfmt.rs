//! Numbers for people: the formatting rules of the reports in one place
//! (`hammer report`'s page, `hammer diagnose`'s Markdown and terminal
//! summary, `hammer diagnose-bench`'s text, `hammer monitor`'s dashboard).
//!
//! Three dialects are kept as they were, since their outputs are pinned by the
//! documentation's examples: the diagnosis writes significant digits and an
//! en dash for a missing number; the report page writes fixed decimals,
//! chosen per quantity, and an em dash; the dashboard writes `n/a` and units
//! scaled to the value.

/// A missing number in the diagnosis' Markdown and terminal text.
pub const MISSING: &str = "–";
/// A missing number on the report's HTML page.
pub const MISSING_HTML: &str = "—";

/// Three significant digits, plain notation where it reads well (10⁻³ to
/// 10⁵), else scientific; [`MISSING`] when not finite.
pub fn sig3(x: f64) -> String {
    if !x.is_finite() {
        return MISSING.into();
    }
    let a = x.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{x:.2e}")
    } else {
        let decimals = (2.0 - a.log10().floor()).max(0.0) as usize;
        format!("{x:.decimals$}")
    }
}

/// A percentage (`x` already in %): one decimal, two below 1 %; [`MISSING`] when not finite.
pub fn pct(x: f64) -> String {
    if !x.is_finite() {
        MISSING.into()
    } else if x != 0.0 && x.abs() < 1.0 {
        format!("{x:.2}")
    } else {
        format!("{x:.1}")
    }
}

/// A supply pressure without trailing zeros: `4`, `5.5`, `6.25`; `unknown` when not finite.
pub fn bar(bar: f64) -> String {
    if !bar.is_finite() {
        return "unknown".into();
    }
    let r = (bar * 100.0).round() / 100.0;
    // `-0` would print as "-0".
    format!("{}", if r == 0.0 { 0.0 } else { r })
}

/// `x` with `prec` decimals, or [`MISSING_HTML`] where there is no number.
pub fn fixed(x: f64, prec: usize) -> String {
    if x.is_finite() {
        format!("{x:.prec$}")
    } else {
        MISSING_HTML.into()
    }
}

/// Signed, for errors; a value that rounds to zero shows as +0, not −0.
pub fn signed(x: f64, prec: usize) -> String {
    let scale = 10f64.powi(prec as i32);
    let x = (x * scale).round() / scale + 0.0;
    if x.is_finite() {
        format!("{x:+.prec$}")
    } else {
        MISSING_HTML.into()
    }
}

/// A parameter value short enough for a figure's title: four decimals at
/// most, scientific outside 10⁻³ to 10⁵.
pub fn compact(x: f64) -> String {
    if x != 0.0 && !(1e-3..1e5).contains(&x.abs()) {
        format!("{x:.3e}")
    } else {
        format!("{}", (x * 1e4).round() / 1e4)
    }
}

/// A count out of a total with its share to a tenth of a percent, so that
/// a share just short of a target is not printed as the target:
/// `71/79 (89.9 %)`, `7/8 (87.5 %)`, `3/4 (75 %)`; `-` of none.
pub fn fraction((n, of): (usize, usize)) -> String {
    if of == 0 {
        return "-".into();
    }
    let tenths = (1000 * n + of / 2) / of;
    match tenths % 10 {
        0 => format!("{n}/{of} ({} %)", tenths / 10),
        t => format!("{n}/{of} ({}.{t} %)", tenths / 10),
    }
}

// The dashboard's: `n/a` for what is not a number; counts, sizes and times
// in their largest sensible unit. (A report field with its uncertainty and
// unit: [`crate::records::shown`].)

/// `v` with `d` decimals; `n/a` for what the device could not estimate.
pub fn num(v: f64, d: usize) -> String {
    if v.is_finite() {
        format!("{v:.d$}")
    } else {
        "n/a".into()
    }
}

pub fn si_count(v: f64) -> String {
    if !v.is_finite() {
        return "n/a".into();
    }
    let a = v.abs();
    if a >= 1e9 {
        format!("{:.2} G", v / 1e9)
    } else if a >= 1e6 {
        format!("{:.2} M", v / 1e6)
    } else if a >= 1e4 {
        format!("{:.1} k", v / 1e3)
    } else {
        format!("{v:.0} ")
    }
}

pub fn bytes(n: u64) -> String {
    match n {
        n if n >= 1 << 30 => format!("{:.2} GiB", n as f64 / (1u64 << 30) as f64),
        n if n >= 1 << 20 => format!("{:.2} MiB", n as f64 / (1u64 << 20) as f64),
        n if n >= 1 << 10 => format!("{:.1} KiB", n as f64 / 1024.0),
        n => format!("{n} B"),
    }
}

pub fn duration(s: f64) -> String {
    if !s.is_finite() || s < 0.0 {
        return "n/a".into();
    }
    let s = s as u64;
    match s {
        s if s >= 86_400 => format!("{}d{:02}h{:02}m", s / 86_400, s / 3600 % 24, s / 60 % 60),
        s if s >= 3600 => format!("{}h{:02}m{:02}s", s / 3600, s / 60 % 60, s % 60),
        s if s >= 60 => format!("{}m{:02}s", s / 60, s % 60),
        s => format!("{s}s"),
    }
}

/// A long time to one decimal in its largest unit.
pub fn coarse(s: f64) -> String {
    match s {
        s if s >= 86_400.0 => format!("{:.1} d", s / 86_400.0),
        s if s >= 3600.0 => format!("{:.1} h", s / 3600.0),
        s if s >= 60.0 => format!("{:.1} min", s / 60.0),
        s => format!("{s:.0} s"),
    }
}

pub fn ago(now_us: u64, t_us: u64) -> String {
    format!("{:.1} s ago", now_us.saturating_sub(t_us) as f64 * 1e-6)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_read_well() {
        assert_eq!(bar(4.0), "4");
        assert_eq!(bar(5.5), "5.5");
        assert_eq!(bar(6.25), "6.25");
        assert_eq!(bar(-0.001), "0");
        assert_eq!(sig3(0.0), "0");
        assert_eq!(sig3(123.456), "123");
        assert_eq!(sig3(0.012345), "0.0123");
        assert_eq!(sig3(-2.345), "-2.35");
        assert_eq!(sig3(123456.0), "1.23e5");
        assert_eq!(sig3(f64::NAN), MISSING);
        assert_eq!(pct(0.5), "0.50");
        assert_eq!(pct(12.34), "12.3");
        assert_eq!(fixed(1.23456, 2), "1.23");
        assert_eq!(fixed(f64::INFINITY, 2), MISSING_HTML);
        assert_eq!(signed(-0.0004, 3), "+0.000");
        assert_eq!(signed(-0.24, 1), "-0.2");
        assert_eq!(compact(2.14159), "2.1416");
        assert_eq!(compact(1e-5), "1.000e-5");
        assert_eq!(compact(0.0), "0");
        assert_eq!(fraction((7, 8)), "7/8 (87.5 %)");
        assert_eq!(fraction((71, 79)), "71/79 (89.9 %)");
        assert_eq!(fraction((3, 4)), "3/4 (75 %)");
        assert_eq!(fraction((2, 3)), "2/3 (66.7 %)");
        assert_eq!(fraction((0, 0)), "-");
    }
}

/// Why a device last started, for people.
pub fn reset_cause(c: &hammer_wire::ResetCause) -> String {
    use hammer_wire::{Duty, ResetCause};
    match c {
        ResetCause::PowerOn => "power-on".into(),
        ResetCause::Watchdog { overdue } => format!(
            "watchdog: the {} stopped",
            match overdue {
                Duty::Sampling => "sampling loop",
                Duty::Link => "link",
                Duty::Persistence => "persistence task",
            }
        ),
        ResetCause::Fault { pc, cfsr } => format!("fault at pc {pc:#010x} (CFSR {cfsr:#010x})"),
    }
}
