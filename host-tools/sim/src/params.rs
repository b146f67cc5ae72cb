//! Every parameter of the simulated hammer, with its default and its source.
//!
//! `docs/model.md` lists the same values with the reasoning behind each choice;
//! where the paper is silent the default is an engineering estimate, marked so.

use serde::{Deserialize, Serialize};

use super::effects::Effects;
use super::sensor_model::SensorModel;
use crate::config::{check_range, ConfigError};

/// Geometry and masses of the hammer (the paper, section 3.1.3, unless noted).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HammerParams {
    pub piston_mass_kg: f64,
    pub bore_diameter_m: f64,
    pub rod_diameter_m: f64,
    pub piston_length_m: f64,
    /// Piston position at rest when the simulation starts (paper: 10 mm).
    pub initial_position_m: f64,
    /// Position at which the piston's striking face meets the shank:
    /// initial position + the paper's 42 mm stroke.
    pub impact_position_m: f64,
    /// Position of the rear face at which the rear outlet starts to open (paper: l1 = 30 mm).
    pub rear_outlet_opens_m: f64,
    /// Position below which the front outlet is uncovered (paper: l3 − lp = 55 − 35 = 20 mm).
    pub front_outlet_opens_m: f64,
    pub outlet_diameter_m: f64,
    /// Number of outlet holes per chamber (estimate: one, as drawn in the paper's figure 1).
    pub outlet_count: u32,
    pub outlet_cd: f64,
    /// Dead volume of the rear chamber at x = 0 (estimate: cover recess and port 3 passage).
    pub rear_dead_volume_m3: f64,
    /// Dead volume of the front chamber at impact (estimate: port 4 passage and shank bore).
    pub front_dead_volume_m3: f64,
    /// Inclination of the hammer axis below the horizontal; positive means the
    /// stroke runs downhill. The paper's bench is horizontal.
    pub inclination_deg: f64,
}

impl Default for HammerParams {
    fn default() -> Self {
        let g = hammer_estimator::Geometry::PAPER;
        let c = hammer_estimator::chambers::ChamberGeometry::paper();
        Self {
            piston_mass_kg: g.piston_mass_kg,
            bore_diameter_m: g.bore_diameter_m,
            rod_diameter_m: g.rod_diameter_m,
            piston_length_m: 0.035,
            initial_position_m: 0.010,
            impact_position_m: c.impact_position_m,
            rear_outlet_opens_m: c.rear_outlet_m,
            front_outlet_opens_m: c.front_outlet_m,
            outlet_diameter_m: 0.005,
            outlet_count: 1,
            outlet_cd: 0.62,
            rear_dead_volume_m3: c.rear_dead_m3,
            front_dead_volume_m3: c.front_dead_m3,
            inclination_deg: 0.0,
        }
    }
}

impl HammerParams {
    /// Where `other` is another hammer: each field whose value differs, as
    /// `name = mine vs other`. Read off the serialised form, so a field added
    /// to the hammer is compared without a list to keep.
    pub fn differences(&self, other: &HammerParams) -> Vec<String> {
        let (Ok(serde_json::Value::Object(a)), Ok(serde_json::Value::Object(b))) =
            (serde_json::to_value(self), serde_json::to_value(other))
        else {
            return vec!["the hammer's parameters cannot be compared".into()];
        };
        a.iter()
            .filter_map(|(k, v)| {
                let w = b.get(k)?;
                (v != w).then(|| format!("{k} = {v} vs {w}"))
            })
            .collect()
    }

    pub fn geometry(&self) -> hammer_estimator::Geometry {
        hammer_estimator::Geometry {
            piston_mass_kg: self.piston_mass_kg,
            bore_diameter_m: self.bore_diameter_m,
            rod_diameter_m: self.rod_diameter_m,
            travel_m: self.impact_position_m as f32,
        }
    }

    /// What the chamber characteristics need of this hammer
    /// (`hammer_estimator::chambers`).
    pub fn chambers(&self) -> hammer_estimator::chambers::ChamberGeometry {
        let g = self.geometry();
        hammer_estimator::chambers::ChamberGeometry {
            rear_area_m2: g.rear_area_m2(),
            front_area_m2: g.front_area_m2(),
            rear_dead_m3: self.rear_dead_volume_m3,
            front_dead_m3: self.front_dead_volume_m3,
            impact_position_m: self.impact_position_m,
            rear_outlet_m: self.rear_outlet_opens_m,
            front_outlet_m: self.front_outlet_opens_m,
        }
    }

    fn validate(&self) -> Result<(), ConfigError> {
        check_range("hammer.piston_mass_kg", self.piston_mass_kg, 0.01, 100.0)?;
        check_range("hammer.bore_diameter_m", self.bore_diameter_m, 0.005, 0.5)?;
        check_range(
            "hammer.rod_diameter_m",
            self.rod_diameter_m,
            0.0,
            self.bore_diameter_m * 0.95,
        )?;
        check_range("hammer.piston_length_m", self.piston_length_m, 0.005, 1.0)?;
        check_range(
            "hammer.initial_position_m",
            self.initial_position_m,
            0.0,
            self.impact_position_m,
        )?;
        check_range("hammer.impact_position_m", self.impact_position_m, 0.005, 1.0)?;
        check_range(
            "hammer.rear_outlet_opens_m",
            self.rear_outlet_opens_m,
            0.0,
            self.impact_position_m,
        )?;
        check_range(
            "hammer.front_outlet_opens_m",
            self.front_outlet_opens_m,
            0.0,
            self.impact_position_m,
        )?;
        check_range("hammer.outlet_diameter_m", self.outlet_diameter_m, 1e-4, 0.05)?;
        check_range("hammer.outlet_count", self.outlet_count as f64, 1.0, 16.0)?;
        check_range("hammer.outlet_cd", self.outlet_cd, 0.1, 1.0)?;
        check_range("hammer.rear_dead_volume_m3", self.rear_dead_volume_m3, 1e-7, 1e-3)?;
        check_range("hammer.front_dead_volume_m3", self.front_dead_volume_m3, 1e-7, 1e-3)?;
        check_range("hammer.inclination_deg", self.inclination_deg, -90.0, 90.0)?;
        Ok(())
    }
}

/// The pilot-operated 2-position 3-way valve (paper 3.1.2–3.1.3; pilot areas estimated).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ValveParams {
    pub mass_kg: f64,
    pub travel_m: f64,
    /// Stroke over which a control port opens (zero lap: port 3 over the last
    /// `opening_m` of travel, port 4 over the first).
    pub opening_m: f64,
    pub cd: f64,
    /// Effective flow area of the poppet at full opening. The paper models the
    /// valve as AMESim's conical poppet with a sharp-edged seat but gives no seat
    /// geometry; this value is calibrated to its 4 bar anchors (docs/model.md).
    /// The area grows linearly with lift and acts in series with the port bore.
    pub full_open_area_m2: f64,
    pub control_port_diameter_m: f64,
    /// Pilot face fed by the rear chamber; pushes the valve towards "feed rear".
    pub pilot_area_rear_m2: f64,
    /// Pilot face fed by the front chamber; pushes the valve towards "feed front".
    pub pilot_area_front_m2: f64,
    /// Viscous damping of the spool in its bore (estimate).
    pub damping_n_s_per_m: f64,
}

impl Default for ValveParams {
    fn default() -> Self {
        Self {
            mass_kg: 0.005,
            travel_m: 0.002,
            opening_m: 0.001,
            cd: 0.62,
            full_open_area_m2: 2.96e-6,
            control_port_diameter_m: 0.008,
            pilot_area_rear_m2: 50e-6,
            pilot_area_front_m2: 25.8e-6,
            damping_n_s_per_m: 13.1,
        }
    }
}

impl ValveParams {
    fn validate(&self) -> Result<(), ConfigError> {
        check_range("valve.mass_kg", self.mass_kg, 1e-4, 1.0)?;
        check_range("valve.travel_m", self.travel_m, 1e-4, 0.02)?;
        check_range("valve.opening_m", self.opening_m, 1e-5, self.travel_m)?;
        check_range("valve.cd", self.cd, 0.1, 1.0)?;
        check_range("valve.full_open_area_m2", self.full_open_area_m2, 1e-8, 1e-3)?;
        check_range(
            "valve.control_port_diameter_m",
            self.control_port_diameter_m,
            1e-3,
            0.05,
        )?;
        check_range("valve.pilot_area_rear_m2", self.pilot_area_rear_m2, 1e-6, 1e-2)?;
        check_range("valve.pilot_area_front_m2", self.pilot_area_front_m2, 1e-6, 1e-2)?;
        check_range("valve.damping_n_s_per_m", self.damping_n_s_per_m, 0.0, 1e3)?;
        Ok(())
    }
}

/// How the piston meets the shank (paper 3.1.1: spring plus damper; no pulling force).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ContactLaw {
    SpringDamper,
    HuntCrossley,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ContactParams {
    pub law: ContactLaw,
    /// Axial stiffness of the steel contact, ~E·A/L of the 28 mm striking end (estimate).
    pub stiffness_n_per_m: f64,
    /// Coefficient of restitution the damper is sized for; the rest of the
    /// energy is what the shank carries away (estimate).
    pub restitution: f64,
    /// Hertzian exponent of the Hunt–Crossley law.
    pub hunt_crossley_exponent: f64,
}

impl Default for ContactParams {
    fn default() -> Self {
        Self {
            law: ContactLaw::SpringDamper,
            stiffness_n_per_m: 2.0e9,
            restitution: 0.19,
            hunt_crossley_exponent: 1.5,
        }
    }
}

impl ContactParams {
    fn validate(&self) -> Result<(), ConfigError> {
        check_range("contact.stiffness_n_per_m", self.stiffness_n_per_m, 1e6, 1e11)?;
        check_range("contact.restitution", self.restitution, 0.01, 0.99)?;
        check_range("contact.hunt_crossley_exponent", self.hunt_crossley_exponent, 1.0, 2.0)?;
        Ok(())
    }
}

/// The gauge supply pressures the model runs at, bar (`supply.pressure_bar`).
pub const SUPPLY_BAR_RANGE: (f64, f64) = (0.5, 20.0);
/// The simulated times a run accepts, s (`solver.duration_s`).
pub const DURATION_S_RANGE: (f64, f64) = (1e-3, 600.0);

/// Supply and ambient conditions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SupplyParams {
    /// Gauge supply pressure at the valve inlet (the paper runs 4–7 bar).
    pub pressure_bar: f64,
    pub temperature_k: f64,
    pub ambient_temperature_k: f64,
}

impl Default for SupplyParams {
    fn default() -> Self {
        Self {
            pressure_bar: 4.0,
            temperature_k: 293.15,
            ambient_temperature_k: 293.15,
        }
    }
}

impl SupplyParams {
    fn validate(&self) -> Result<(), ConfigError> {
        let (lo, hi) = SUPPLY_BAR_RANGE;
        check_range("supply.pressure_bar", self.pressure_bar, lo, hi)?;
        check_range("supply.temperature_k", self.temperature_k, 200.0, 400.0)?;
        check_range("supply.ambient_temperature_k", self.ambient_temperature_k, 200.0, 400.0)?;
        Ok(())
    }
}

/// Integration and output settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolverParams {
    pub duration_s: f64,
    /// Uniform output grid (the bench board samples at 100 kS/s).
    pub output_step_s: f64,
    pub rtol: f64,
    pub max_step_s: f64,
}

impl Default for SolverParams {
    fn default() -> Self {
        Self {
            duration_s: 0.5,
            output_step_s: 10e-6,
            rtol: 1e-6,
            max_step_s: 2e-4,
        }
    }
}

impl SolverParams {
    fn validate(&self) -> Result<(), ConfigError> {
        let (lo, hi) = DURATION_S_RANGE;
        check_range("solver.duration_s", self.duration_s, lo, hi)?;
        check_range("solver.output_step_s", self.output_step_s, 1e-7, 1e-2)?;
        check_range("solver.rtol", self.rtol, 1e-12, 1e-2)?;
        check_range("solver.max_step_s", self.max_step_s, 1e-7, 1e-2)?;
        Ok(())
    }
}

/// The nominal parameters a modeller knows only to a few percent (calibrated
/// or estimated in docs/model.md), each with the config field it is: the
/// diagnosis lets each of them move within a prior rather than blame an
/// effect for what they explain, and the FMU's model map lists the same.
/// Mass and piston areas are not among them: they are measured.
pub const NUISANCE: [(&str, fn(&mut SimConfig) -> &mut f64); 9] = [
    ("valve.full_open_area_m2", |c| &mut c.valve.full_open_area_m2),
    ("valve.cd", |c| &mut c.valve.cd),
    ("valve.damping_n_s_per_m", |c| &mut c.valve.damping_n_s_per_m),
    ("valve.pilot_area_rear_m2", |c| &mut c.valve.pilot_area_rear_m2),
    ("valve.pilot_area_front_m2", |c| &mut c.valve.pilot_area_front_m2),
    ("hammer.outlet_cd", |c| &mut c.hammer.outlet_cd),
    ("hammer.rear_dead_volume_m3", |c| &mut c.hammer.rear_dead_volume_m3),
    ("hammer.front_dead_volume_m3", |c| &mut c.hammer.front_dead_volume_m3),
    ("contact.restitution", |c| &mut c.contact.restitution),
];

/// The relative uncertainty the nominal parameters are known to by default
/// (a real hammer's, ±20 %): the diagnosis' `nominal_uncertainty` and the
/// FMU map's `relative_uncertainty`.
pub const NOMINAL_UNCERTAINTY: f64 = 0.2;

/// Everything a simulation run needs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    pub hammer: HammerParams,
    pub valve: ValveParams,
    pub contact: ContactParams,
    pub supply: SupplyParams,
    pub solver: SolverParams,
    pub effects: Effects,
    pub sensors: SensorModel,
    /// Seed of the sensor noise and of the zero-shift signs.
    pub seed: u64,
    /// How the estimator reads this hammer (thresholds, calibration accuracy).
    pub estimator: hammer_trace::EstimatorParams,
    /// What a recorder's file means (`[import]`: columns, units, gauge or
    /// absolute, sign, text layout); none for the project's own traces.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub import: Option<hammer_trace::import::ImportMap>,
}

impl SimConfig {
    /// The nominal model at a supply pressure: every effect off, default sensors.
    pub fn nominal(supply_bar: f64) -> Self {
        let mut c = Self::default();
        c.supply.pressure_bar = supply_bar;
        c
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        self.hammer.validate()?;
        self.valve.validate()?;
        self.contact.validate()?;
        self.supply.validate()?;
        self.solver.validate()?;
        self.effects.validate()?;
        self.sensors.validate()?;
        if let Some(m) = &self.import {
            m.validate()?;
        }
        Ok(())
    }
}

/// What a run changes on top of its configuration file: `hammer
/// simulate`'s flags and the Python package's `simulate` arguments, applied
/// the same way by both.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RunOverrides {
    /// Gauge supply pressure, bar (`supply.pressure_bar`).
    pub supply_bar: Option<f64>,
    /// Simulated time, s (`solver.duration_s`).
    pub duration_s: Option<f64>,
    /// Seed of the sensor noise.
    pub seed: Option<u64>,
    /// Output grid step, s (`solver.output_step_s`).
    pub output_step_s: Option<f64>,
    /// Relative tolerance of the integrator (`solver.rtol`).
    pub rtol: Option<f64>,
    /// No noise, bandwidth, clipping or quantisation.
    pub ideal_sensors: bool,
    /// Effects switched on: `NAME` or `NAME:key=value,...`.
    pub effects: Vec<String>,
}

impl RunOverrides {
    /// Writes the overrides into `cfg`; an unknown effect or key is refused.
    /// The caller validates the result (naming a refused value its own way).
    pub fn apply(&self, cfg: &mut SimConfig) -> Result<(), ConfigError> {
        if let Some(v) = self.supply_bar {
            cfg.supply.pressure_bar = v;
        }
        if let Some(v) = self.duration_s {
            cfg.solver.duration_s = v;
        }
        if let Some(v) = self.seed {
            cfg.seed = v;
        }
        if let Some(v) = self.output_step_s {
            cfg.solver.output_step_s = v;
        }
        if let Some(v) = self.rtol {
            cfg.solver.rtol = v;
        }
        if self.ideal_sensors {
            cfg.sensors.enabled = false;
        }
        for spec in &self.effects {
            cfg.effects.apply_spec(spec)?;
        }
        Ok(())
    }
}
