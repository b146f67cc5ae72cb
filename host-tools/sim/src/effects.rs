//! The catalogue of effects the nominal model leaves out.
//!
//! Every effect is off by default. The names are the project's vocabulary:
//! the CLI, config files, sidecars and the diagnosis all use them verbatim.

use serde::{Deserialize, Serialize};

use crate::config::{check_range, ConfigError};

/// Names of every effect, in catalogue order.
pub const EFFECT_NAMES: [&str; 8] = [
    "coulomb_friction",
    "viscous_friction",
    "leakage",
    "valve_delay",
    "heat_transfer",
    "supply_restriction",
    "accel_zero_shift",
    "pressure_gain_error",
];

/// Pressure-dependent Coulomb friction F = F0 + k·p_supply, opposing motion.
/// Defaults reproduce the paper's 10.27 N at 4 bar and 16.7 N at 7 bar.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CoulombFriction {
    pub f0_n: f64,
    pub k_n_per_bar: f64,
    /// Velocity below which the sign function is smoothed, m/s.
    pub smoothing_mps: f64,
    /// Wear: relative growth of the friction per second of running (0 = constant).
    pub growth_per_s: f64,
    /// A sudden change (a scored bore, a lost lubricant film): from `step_at_s`
    /// on, the friction is multiplied by `step_factor`.
    pub step_at_s: f64,
    pub step_factor: f64,
}

impl Default for CoulombFriction {
    fn default() -> Self {
        let k = (16.7 - 10.27) / 3.0;
        Self {
            f0_n: 10.27 - 4.0 * k,
            k_n_per_bar: k,
            smoothing_mps: 1e-3,
            growth_per_s: 0.0,
            step_at_s: 0.0,
            step_factor: 1.0,
        }
    }
}

impl CoulombFriction {
    /// The friction magnitude at the start of the run.
    pub fn force_n(&self, supply_bar: f64) -> f64 {
        self.f0_n + self.k_n_per_bar * supply_bar
    }

    /// Multiplier of [`Self::force_n`] at time `t_s`.
    pub fn factor_at(&self, t_s: f64) -> f64 {
        let step = if self.step_factor != 1.0 && t_s >= self.step_at_s {
            self.step_factor
        } else {
            1.0
        };
        (1.0 + self.growth_per_s * t_s) * step
    }
}

/// Viscous friction F = c·v from the lubricant film.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ViscousFriction {
    pub c_n_s_per_m: f64,
}

impl Default for ViscousFriction {
    fn default() -> Self {
        // ~5 N at the 2 m/s typical of flight: the same order as the Coulomb term.
        Self { c_n_s_per_m: 2.5 }
    }
}

/// Laminar gas leakage through the piston's annular clearance (rear ↔ front)
/// and the rod guide (front → atmosphere).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Leakage {
    /// Radial gap: half the paper's 0.05 mm diametral clearance.
    pub gap_m: f64,
    /// Paper: eccentricity ratio 1 (piston touching the wall).
    pub eccentricity: f64,
    /// Length of the rod guide seen by the front chamber's leak to atmosphere (estimate).
    pub rod_guide_length_m: f64,
}

impl Default for Leakage {
    fn default() -> Self {
        Self {
            gap_m: 25e-6,
            eccentricity: 1.0,
            rod_guide_length_m: 0.020,
        }
    }
}

/// The valve's pilot signal lags the chamber pressures: a first-order lag of
/// time constant `tau_s` on the pilot pressure difference (pilot-line filling).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ValveDelay {
    pub tau_s: f64,
}

impl Default for ValveDelay {
    fn default() -> Self {
        Self { tau_s: 1.0e-3 }
    }
}

/// Convective heat exchange between chamber air and walls held at ambient temperature.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HeatTransfer {
    pub h_w_per_m2_k: f64,
}

impl Default for HeatTransfer {
    fn default() -> Self {
        Self { h_w_per_m2_k: 500.0 }
    }
}

/// A supply hose of finite volume fed through a restriction: the valve-inlet
/// pressure sags while the hammer draws air.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SupplyRestriction {
    pub orifice_diameter_m: f64,
    pub line_volume_m3: f64,
}

impl Default for SupplyRestriction {
    fn default() -> Self {
        Self {
            orifice_diameter_m: 0.0016,
            line_volume_m3: 50e-6,
        }
    }
}

/// Piezo accelerometer zero shift: after every impact the output carries an
/// offset of random sign that decays with the sensor's discharge time constant.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AccelZeroShift {
    pub amplitude_mps2: f64,
    pub tau_s: f64,
}

impl Default for AccelZeroShift {
    fn default() -> Self {
        Self {
            amplitude_mps2: 20.0,
            tau_s: 0.02,
        }
    }
}

/// Relative gain errors of the pressure channels (reading = (1 + g)·true).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PressureGainError {
    pub rear: f64,
    pub front: f64,
}

impl Default for PressureGainError {
    fn default() -> Self {
        Self {
            rear: 0.02,
            front: 0.02,
        }
    }
}

/// The active effects: `None` is off.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct Effects {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coulomb_friction: Option<CoulombFriction>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub viscous_friction: Option<ViscousFriction>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub leakage: Option<Leakage>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub valve_delay: Option<ValveDelay>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heat_transfer: Option<HeatTransfer>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub supply_restriction: Option<SupplyRestriction>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub accel_zero_shift: Option<AccelZeroShift>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pressure_gain_error: Option<PressureGainError>,
}

impl Effects {
    /// Names of the effects that are on.
    pub fn active(&self) -> Vec<&'static str> {
        let on = [
            self.coulomb_friction.is_some(),
            self.viscous_friction.is_some(),
            self.leakage.is_some(),
            self.valve_delay.is_some(),
            self.heat_transfer.is_some(),
            self.supply_restriction.is_some(),
            self.accel_zero_shift.is_some(),
            self.pressure_gain_error.is_some(),
        ];
        EFFECT_NAMES
            .iter()
            .zip(on)
            .filter(|(_, o)| *o)
            .map(|(n, _)| *n)
            .collect()
    }

    /// Switches an effect on from a CLI spec `name` or `name:key=value,key=value`.
    /// Unspecified keys keep their defaults.
    pub fn apply_spec(&mut self, spec: &str) -> Result<(), ConfigError> {
        let (name, args) = match spec.split_once(':') {
            Some((n, a)) => (n.trim(), a.trim()),
            None => (spec.trim(), ""),
        };
        let mut table = toml::Table::new();
        for pair in args.split(',').filter(|p| !p.trim().is_empty()) {
            let (k, v) = pair.split_once('=').ok_or_else(|| ConfigError::Invalid {
                field: format!("effects.{name}"),
                message: format!("expected key=value, got `{pair}`"),
            })?;
            let value: f64 = v.trim().parse().map_err(|_| ConfigError::Invalid {
                field: format!("effects.{name}.{}", k.trim()),
                message: format!("`{}` is not a number", v.trim()),
            })?;
            table.insert(k.trim().to_string(), toml::Value::Float(value));
        }
        let field = format!("effects.{name}");
        let bad = |e: toml::de::Error| ConfigError::Invalid {
            field: field.clone(),
            message: e.message().to_string(),
        };
        let value = toml::Value::Table(table);
        match name {
            "coulomb_friction" => self.coulomb_friction = Some(value.try_into().map_err(bad)?),
            "viscous_friction" => self.viscous_friction = Some(value.try_into().map_err(bad)?),
            "leakage" => self.leakage = Some(value.try_into().map_err(bad)?),
            "valve_delay" => self.valve_delay = Some(value.try_into().map_err(bad)?),
            "heat_transfer" => self.heat_transfer = Some(value.try_into().map_err(bad)?),
            "supply_restriction" => self.supply_restriction = Some(value.try_into().map_err(bad)?),
            "accel_zero_shift" => self.accel_zero_shift = Some(value.try_into().map_err(bad)?),
            "pressure_gain_error" => self.pressure_gain_error = Some(value.try_into().map_err(bad)?),
            other => {
                return Err(ConfigError::Invalid {
                    field: "effect".into(),
                    message: format!("unknown effect `{other}`; known: {}", EFFECT_NAMES.join(", ")),
                })
            }
        }
        self.validate()
    }

    pub fn validate(&self) -> Result<(), ConfigError> {
        if let Some(e) = &self.coulomb_friction {
            check_range("effects.coulomb_friction.f0_n", e.f0_n, 0.0, 1e3)?;
            check_range("effects.coulomb_friction.k_n_per_bar", e.k_n_per_bar, 0.0, 1e3)?;
            check_range("effects.coulomb_friction.smoothing_mps", e.smoothing_mps, 1e-6, 0.1)?;
            check_range("effects.coulomb_friction.growth_per_s", e.growth_per_s, 0.0, 10.0)?;
            check_range("effects.coulomb_friction.step_at_s", e.step_at_s, 0.0, 1e6)?;
            check_range("effects.coulomb_friction.step_factor", e.step_factor, 0.0, 100.0)?;
        }
        if let Some(e) = &self.viscous_friction {
            check_range("effects.viscous_friction.c_n_s_per_m", e.c_n_s_per_m, 0.0, 1e3)?;
        }
        if let Some(e) = &self.leakage {
            check_range("effects.leakage.gap_m", e.gap_m, 0.0, 2e-4)?;
            check_range("effects.leakage.eccentricity", e.eccentricity, 0.0, 1.0)?;
            check_range("effects.leakage.rod_guide_length_m", e.rod_guide_length_m, 1e-3, 0.2)?;
        }
        if let Some(e) = &self.valve_delay {
            check_range("effects.valve_delay.tau_s", e.tau_s, 1e-6, 0.05)?;
        }
        if let Some(e) = &self.heat_transfer {
            check_range("effects.heat_transfer.h_w_per_m2_k", e.h_w_per_m2_k, 0.0, 1e5)?;
        }
        if let Some(e) = &self.supply_restriction {
            check_range(
                "effects.supply_restriction.orifice_diameter_m",
                e.orifice_diameter_m,
                5e-4,
                0.05,
            )?;
            check_range("effects.supply_restriction.line_volume_m3", e.line_volume_m3, 1e-6, 0.1)?;
        }
        if let Some(e) = &self.accel_zero_shift {
            check_range("effects.accel_zero_shift.amplitude_mps2", e.amplitude_mps2, 0.0, 1e4)?;
            check_range("effects.accel_zero_shift.tau_s", e.tau_s, 1e-4, 10.0)?;
        }
        if let Some(e) = &self.pressure_gain_error {
            check_range("effects.pressure_gain_error.rear", e.rear, -0.5, 0.5)?;
            check_range("effects.pressure_gain_error.front", e.front, -0.5, 0.5)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_friction_reproduces_the_paper() {
        let f = CoulombFriction::default();
        assert!((f.force_n(4.0) - 10.27).abs() < 1e-9);
        assert!((f.force_n(7.0) - 16.7).abs() < 1e-9);
    }

    #[test]
    fn specs_switch_effects_on_and_name_bad_fields() {
        let mut e = Effects::default();
        e.apply_spec("coulomb_friction:f0_n=1.7,k_n_per_bar=2.14").unwrap();
        assert_eq!(e.coulomb_friction.as_ref().unwrap().f0_n, 1.7);
        e.apply_spec("leakage").unwrap();
        assert_eq!(e.active(), vec!["coulomb_friction", "leakage"]);
        let err = e.apply_spec("leakage:gapp_m=1e-5").unwrap_err().to_string();
        assert!(err.contains("gapp_m"), "{err}");
        let err = e.apply_spec("valve_delay:tau_s=-1").unwrap_err().to_string();
        assert!(err.contains("effects.valve_delay.tau_s"), "{err}");
        let err = e.apply_spec("magic").unwrap_err().to_string();
        assert!(err.contains("unknown effect") && err.contains("heat_transfer"), "{err}");
        let err = e.apply_spec("leakage:gap_m=abc").unwrap_err().to_string();
        assert!(err.contains("effects.leakage.gap_m"), "{err}");
    }
}
