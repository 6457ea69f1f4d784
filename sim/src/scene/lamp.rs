//! [`LampSpec`]: heat sources (`"lamps"` in a scene file).
//!
//! Times are measured from the start of heating: t = 0 follows the pre-heating frames (see
//! [`Timing::pre_heating_frames`](super::Timing::pre_heating_frames)). A lamp is on for
//! `on <= t < off`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::parse::tagged_enum;
use super::validate::{finite3, num, Check};

/// Default radiant fraction of an incandescent lamp's electrical power (reference section 4:
/// 0.8–0.9).
pub const DEFAULT_RADIANT_FRACTION: f64 = 0.85;

/// A lamp; tagged by `"kind"`: `uniform` or `point`.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum LampSpec {
    /// Uniform irradiance on the visible surface (normal incidence everywhere).
    Uniform(UniformLamp),
    /// An isotropic point source: irradiance radiant_fraction · power / (4 π r²) · cos θ.
    Point(PointLamp),
}

tagged_enum!(LampSpec {
    "uniform" => Uniform,
    "point" => Point,
});

/// Uniform irradiance on the visible surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct UniformLamp {
    /// Irradiance on the visible surface, in W/m², before absorptivity: the absorbed flux is
    /// `material.absorptivity * flux` (required; >= 0).
    pub flux: f64,
    /// Switch-on time, in s (default 0; >= 0).
    #[serde(default)]
    pub on: f64,
    /// Switch-off time, in s (> on); absent: stays on (default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub off: Option<f64>,
}

fn default_radiant_fraction() -> f64 {
    DEFAULT_RADIANT_FRACTION
}

/// An isotropic point source such as a bare incandescent bulb.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct PointLamp {
    /// Electrical power, in W (required; >= 0).
    pub power: f64,
    /// Position of the filament, in m (required).
    pub position: [f64; 3],
    /// Fraction of the electrical power radiated, dimensionless (default 0.85; in (0, 1]).
    #[serde(default = "default_radiant_fraction")]
    pub radiant_fraction: f64,
    /// Switch-on time, in s (default 0; >= 0).
    #[serde(default)]
    pub on: f64,
    /// Switch-off time, in s (> on); absent: stays on (default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub off: Option<f64>,
}

impl LampSpec {
    /// Switch-on time, in s.
    pub fn on(&self) -> f64 {
        match self {
            LampSpec::Uniform(l) => l.on,
            LampSpec::Point(l) => l.on,
        }
    }

    /// Switch-off time, in s (`None`: stays on).
    pub fn off(&self) -> Option<f64> {
        match self {
            LampSpec::Uniform(l) => l.off,
            LampSpec::Point(l) => l.off,
        }
    }

    /// Whether the lamp is on at time `t` (s): `on <= t < off`.
    pub fn is_on(&self, t: f64) -> bool {
        t >= self.on() && self.off().is_none_or(|off| t < off)
    }

    /// Checks every number; JSON paths `lamps[{index}].*`.
    ///
    /// # Errors
    /// [`SceneError::Invalid`](super::SceneError::Invalid) for the first value out of range.
    pub fn validate(&self, index: usize) -> Check {
        self.validate_at(&format!("lamps[{index}]"))
    }

    /// [`validate`](Self::validate) with the lamp's JSON path given, e.g.
    /// `lamp_configurations[1].lamps[0]`.
    pub fn validate_at(&self, path: &str) -> Check {
        let p = |field: &str| format!("{path}.{field}");
        match self {
            LampSpec::Uniform(l) => {
                num(&p("flux"), l.flux, "W/m^2")?.ge(0.0)?;
            }
            LampSpec::Point(l) => {
                num(&p("power"), l.power, "W")?.ge(0.0)?;
                finite3(&p("position"), l.position)?;
                num(&p("radiant_fraction"), l.radiant_fraction, "")?.within(0.0, false, 1.0, true)?;
            }
        }
        let on = self.on();
        num(&p("on"), on, "s")?.ge(0.0)?;
        if let Some(off) = self.off() {
            num(&p("off"), off, "s")?.gt_other(&p("on"), on)?;
        }
        Ok(())
    }
}

/// A named set of lamps: a scene may film the same object under several lamp configurations
/// (the paper's left-lamp and right-lamp videos); `simbench simulate` writes one dataset each,
/// into a subdirectory named after the configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct LampConfiguration {
    /// Name of the configuration and of its dataset directory (letters, digits, `-`, `_`).
    pub name: String,
    /// The lamps switched on in this configuration.
    pub lamps: Vec<LampSpec>,
}
