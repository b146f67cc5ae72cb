//! The structural choices of a variant hammer. Each is a law the
//! diagnosis' model does not have (or has in another form), with the
//! parameters of that law.

use serde::{Deserialize, Serialize};

/// How the valve decides to switch.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ValveLaw {
    /// A pilot force from both chambers with a switching hysteresis (no spool mass).
    PilotThreshold,
    /// Pilot lines uncovered by the piston: the valve switches at port edges.
    PositionLatched,
}

/// How an outlet port opens as the piston edge passes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum PortLaw {
    /// A round hole uncovered by a straight edge (circular segment).
    CircularSegment,
    /// A chamfered, slotted port: a smooth raised-cosine ramp to full area.
    SmoothRamp,
}

/// The chambers' thermodynamics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ChamberLaw {
    /// Energy balance of an open adiabatic volume (enthalpy flows).
    Adiabatic,
    /// p·v^n along the mass change, exponent `polytropic_n`.
    Polytropic,
}

/// What feeds the valve inlet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SupplyLaw {
    /// The supply pressure stands at the valve inlet.
    Stiff,
    /// A hose with inertance and friction into an inlet volume.
    Hose,
}

/// What the piston strikes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AnvilLaw {
    /// A fixed shank face.
    Fixed,
    /// A tool of its own mass pressed against a collar by the feed force,
    /// driven into a compliant workpiece by the blow.
    MovingTool,
}

/// The sensors' front ends.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FrontEnd {
    /// First-order anti-alias filters, noise, 12-bit quantisation.
    FirstOrder,
    /// An accelerometer mount resonance, and pressure ranges that clip.
    ResonantClipping,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Structure {
    pub valve: ValveLaw,
    pub ports: PortLaw,
    pub chambers: ChamberLaw,
    pub supply: SupplyLaw,
    pub anvil: AnvilLaw,
    pub front_end: FrontEnd,
}

impl Structure {
    /// The closest this family comes to the diagnosis' model: it still
    /// differs in its flow law, spool and numerics.
    pub const BASE: Structure = Structure {
        valve: ValveLaw::PilotThreshold,
        ports: PortLaw::CircularSegment,
        chambers: ChamberLaw::Adiabatic,
        supply: SupplyLaw::Stiff,
        anvil: AnvilLaw::Fixed,
        front_end: FrontEnd::FirstOrder,
    };

    /// Names of the variants that differ from [`Structure::BASE`].
    pub fn variants(&self) -> Vec<&'static str> {
        let b = Self::BASE;
        let mut v = Vec::new();
        if self.valve != b.valve {
            v.push("position_latched_valve");
        }
        if self.ports != b.ports {
            v.push("smooth_ramp_ports");
        }
        if self.chambers != b.chambers {
            v.push("polytropic_chambers");
        }
        if self.supply != b.supply {
            v.push("supply_hose");
        }
        if self.anvil != b.anvil {
            v.push("moving_tool");
        }
        if self.front_end != b.front_end {
            v.push("resonant_clipping_sensors");
        }
        v
    }

    /// Every single-variant structure, in [`Structure::variants`] order.
    pub fn singles() -> [Structure; 6] {
        let b = Self::BASE;
        [
            Structure {
                valve: ValveLaw::PositionLatched,
                ..b
            },
            Structure {
                ports: PortLaw::SmoothRamp,
                ..b
            },
            Structure {
                chambers: ChamberLaw::Polytropic,
                ..b
            },
            Structure {
                supply: SupplyLaw::Hose,
                ..b
            },
            Structure {
                anvil: AnvilLaw::MovingTool,
                ..b
            },
            Structure {
                front_end: FrontEnd::ResonantClipping,
                ..b
            },
        ]
    }

    /// Applies the variants of `other` on top of `self`.
    pub fn with(mut self, other: &Structure) -> Structure {
        let b = Self::BASE;
        if other.valve != b.valve {
            self.valve = other.valve;
        }
        if other.ports != b.ports {
            self.ports = other.ports;
        }
        if other.chambers != b.chambers {
            self.chambers = other.chambers;
        }
        if other.supply != b.supply {
            self.supply = other.supply;
        }
        if other.anvil != b.anvil {
            self.anvil = other.anvil;
        }
        if other.front_end != b.front_end {
            self.front_end = other.front_end;
        }
        self
    }
}

/// Every number of a variant hammer. Geometry from the paper; the rest are
/// this family's own estimates, deliberately not the simulator's values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct VariantParams {
    pub piston_mass_kg: f64,
    pub bore_m: f64,
    pub rod_m: f64,
    pub piston_length_m: f64,
    pub x_start_m: f64,
    pub x_impact_m: f64,
    /// Rear outlet edge (rear face position at which it starts to open).
    pub rear_port_m: f64,
    /// Front outlet edge (rear face position below which it opens).
    pub front_port_m: f64,
    pub port_diameter_m: f64,
    /// Ramp length of the smooth ports.
    pub port_ramp_m: f64,
    /// ISO 6358 sonic conductance of one outlet at full opening, m³/(s·Pa).
    pub port_conductance: f64,
    pub port_critical_ratio: f64,
    pub rear_dead_m3: f64,
    pub front_dead_m3: f64,
    /// Valve: ISO 6358 conductance of each supply path at full opening.
    pub valve_conductance: f64,
    pub valve_critical_ratio: f64,
    /// Time constant of the spool's travel.
    pub spool_tau_s: f64,
    pub pilot_rear_m2: f64,
    pub pilot_front_m2: f64,
    pub pilot_hysteresis_n: f64,
    /// Position-latched valve: switch to the return stroke beyond this
    /// position, to the working stroke below the other.
    pub latch_forward_m: f64,
    pub latch_back_m: f64,
    pub polytropic_n: f64,
    pub hose_length_m: f64,
    pub hose_diameter_m: f64,
    pub inlet_volume_m3: f64,
    pub contact_stiffness_n_per_m: f64,
    pub contact_damping_ratio: f64,
    pub tool_mass_kg: f64,
    pub feed_force_n: f64,
    pub workpiece_stiffness_n_per_m: f64,
    pub supply_temperature_k: f64,
    pub ambient_temperature_k: f64,
}

impl Default for VariantParams {
    fn default() -> Self {
        Self {
            piston_mass_kg: 1.12,
            bore_m: 0.041,
            rod_m: 0.028,
            piston_length_m: 0.035,
            x_start_m: 0.010,
            x_impact_m: 0.052,
            rear_port_m: 0.030,
            front_port_m: 0.020,
            port_diameter_m: 0.005,
            port_ramp_m: 0.006,
            port_conductance: 2.6e-8,
            port_critical_ratio: 0.35,
            rear_dead_m3: 17e-6,
            front_dead_m3: 17e-6,
            valve_conductance: 3.9e-9,
            valve_critical_ratio: 0.30,
            spool_tau_s: 0.25e-3,
            pilot_rear_m2: 50e-6,
            pilot_front_m2: 26e-6,
            pilot_hysteresis_n: 2.0,
            latch_forward_m: 0.036,
            latch_back_m: 0.016,
            polytropic_n: 1.25,
            hose_length_m: 2.0,
            hose_diameter_m: 0.008,
            inlet_volume_m3: 30e-6,
            contact_stiffness_n_per_m: 1.6e9,
            contact_damping_ratio: 0.45,
            tool_mass_kg: 0.6,
            feed_force_n: 150.0,
            workpiece_stiffness_n_per_m: 3e7,
            supply_temperature_k: 293.15,
            ambient_temperature_k: 293.15,
        }
    }
}

/// The nominal values of this family that a hammer's engineer knows only
/// roughly (its laws' coefficients, its volumes, its anvil and tool), by
/// their field names: the structural benchmark draws each hammer's from
/// these around nominal, and the family's FMU map declares them as the
/// nuisance a diagnosis may recalibrate (issue 46). One list, so that the
/// benchmark never moves a value its own model's map holds fixed. The
/// geometry (bore, rod, strokes, port edges) is measured, not listed.
pub const UNCERTAIN: [&str; 19] = [
    "port_conductance",
    "port_critical_ratio",
    "port_ramp_m",
    "rear_dead_m3",
    "front_dead_m3",
    "valve_conductance",
    "valve_critical_ratio",
    "spool_tau_s",
    "pilot_rear_m2",
    "pilot_front_m2",
    "pilot_hysteresis_n",
    "polytropic_n",
    "hose_length_m",
    "inlet_volume_m3",
    "contact_stiffness_n_per_m",
    "contact_damping_ratio",
    "tool_mass_kg",
    "feed_force_n",
    "workpiece_stiffness_n_per_m",
];

impl VariantParams {
    /// The [`UNCERTAIN`] values, in its order.
    pub fn uncertain_mut(&mut self) -> [&mut f64; 19] {
        [
            &mut self.port_conductance,
            &mut self.port_critical_ratio,
            &mut self.port_ramp_m,
            &mut self.rear_dead_m3,
            &mut self.front_dead_m3,
            &mut self.valve_conductance,
            &mut self.valve_critical_ratio,
            &mut self.spool_tau_s,
            &mut self.pilot_rear_m2,
            &mut self.pilot_front_m2,
            &mut self.pilot_hysteresis_n,
            &mut self.polytropic_n,
            &mut self.hose_length_m,
            &mut self.inlet_volume_m3,
            &mut self.contact_stiffness_n_per_m,
            &mut self.contact_damping_ratio,
            &mut self.tool_mass_kg,
            &mut self.feed_force_n,
            &mut self.workpiece_stiffness_n_per_m,
        ]
    }

    /// This hammer's chambers in the characteristics' terms
    /// (`hammer_estimator::chambers`): the same geometry the plant integrates.
    pub fn chambers(&self) -> hammer_estimator::chambers::ChamberGeometry {
        let area = |d: f64| 0.25 * std::f64::consts::PI * d * d;
        hammer_estimator::chambers::ChamberGeometry {
            rear_area_m2: area(self.bore_m),
            front_area_m2: area(self.bore_m) - area(self.rod_m),
            rear_dead_m3: self.rear_dead_m3,
            front_dead_m3: self.front_dead_m3,
            impact_position_m: self.x_impact_m,
            rear_outlet_m: self.rear_port_m,
            front_outlet_m: self.front_port_m,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each name of [`UNCERTAIN`] is the field its accessor moves: moved
    /// one at a time, exactly that field of the serialised parameters
    /// changes (the FMU's parameter `params.<name>` is that field).
    #[test]
    fn uncertain_names_are_their_fields() {
        let nominal = serde_json::to_value(VariantParams::default()).unwrap();
        for (i, name) in UNCERTAIN.iter().enumerate() {
            let mut p = VariantParams::default();
            *p.uncertain_mut()[i] *= 1.5;
            let moved = serde_json::to_value(&p).unwrap();
            let changed: Vec<&String> = moved
                .as_object()
                .unwrap()
                .iter()
                .filter(|(k, v)| nominal[k.as_str()] != **v)
                .map(|(k, _)| k)
                .collect();
            assert_eq!(changed, [name], "UNCERTAIN[{i}]");
        }
    }
}
