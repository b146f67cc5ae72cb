//! The stages of a cycle, after the paper's (a)–(f), bounded by events the
//! simulator knows: direction of motion, the outlet edges and the impact.

use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// (a–b) stroke, rear chamber fed, front outlet still open.
    StrokeIntake,
    /// (b–c) stroke, both outlets closed: rear expands, front compresses.
    StrokeClosed,
    /// (c) stroke, rear outlet open: rear vents, front cushion builds.
    StrokeVenting,
    /// (d) the impact, its ring-down and the valve switching to the front.
    Impact,
    /// (e) backhaul, front fed, rear outlet open.
    BackhaulFed,
    /// (e–f) backhaul, rear outlet closed: the rear cushion builds.
    BackhaulCushion,
    /// (f) backhaul, front outlet open: the return ends, the valve switches back.
    BackhaulVented,
}

pub const STAGES: [Stage; 7] = [
    Stage::StrokeIntake,
    Stage::StrokeClosed,
    Stage::StrokeVenting,
    Stage::Impact,
    Stage::BackhaulFed,
    Stage::BackhaulCushion,
    Stage::BackhaulVented,
];

impl Stage {
    pub fn name(self) -> &'static str {
        match self {
            Stage::StrokeIntake => "stroke_intake",
            Stage::StrokeClosed => "stroke_closed",
            Stage::StrokeVenting => "stroke_venting",
            Stage::Impact => "impact",
            Stage::BackhaulFed => "backhaul_fed",
            Stage::BackhaulCushion => "backhaul_cushion",
            Stage::BackhaulVented => "backhaul_vented",
        }
    }
}

/// Port edges of the hammer, m.
#[derive(Debug, Clone, Copy)]
pub struct Edges {
    pub front_outlet_m: f64,
    pub rear_outlet_m: f64,
}

/// The stage of one instant, from position, velocity and the time since the
/// impact (`impact_window_s` after it counts as the impact stage).
pub fn stage_of(edges: &Edges, x_m: f64, v_mps: f64, since_impact_s: f64, impact_window_s: f64) -> Stage {
    if since_impact_s < impact_window_s {
        return Stage::Impact;
    }
    if v_mps >= 0.0 {
        if x_m < edges.front_outlet_m {
            Stage::StrokeIntake
        } else if x_m < edges.rear_outlet_m {
            Stage::StrokeClosed
        } else {
            Stage::StrokeVenting
        }
    } else if x_m >= edges.rear_outlet_m {
        Stage::BackhaulFed
    } else if x_m >= edges.front_outlet_m {
        Stage::BackhaulCushion
    } else {
        Stage::BackhaulVented
    }
}
