//! A suite specification: the objects, noise levels, seeds and capture settings a suite holds
//! (`suites/*.json`; the tiers `quick` and `full` are two of them, compiled in).
//!
//! Every object is simulated once (both lamp configurations, noise-free); each noise level and
//! seed only re-films that simulation with another sensor. A noise level with no noise at all
//! (NETD, fixed pattern and quantisation 0) has one case (seed 0); every other level has
//! `seeds` cases, seeds 1 to `seeds`. All lengths in m, times in s, powers in W, temperatures
//! in mK where the field name says so.

use std::path::Path;

use anyhow::{ensure, Context};
use serde::{Deserialize, Serialize};

use crate::table::cells::{Build, Object, RowSpec, Setup, Solver};

/// The shipped tiers: (name, spec text).
pub const TIERS: [(&str, &str); 3] = [
    ("quick", include_str!("../../../suites/quick.json")),
    ("full", include_str!("../../../suites/full.json")),
    ("tiny", include_str!("../../../suites/tiny.json")),
];

/// A suite specification (module documentation).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct SuiteSpec {
    /// Short name, part of the suite's version (letters, digits, `-`, `_`).
    pub name: String,
    /// What the suite is for.
    pub description: String,
    /// Image size, pixels (the FLIR Boson's 24.3 degree field of view at any size).
    pub camera: CameraSize,
    /// Heating and filming.
    pub timing: Timing,
    /// Power of each of the two point lamps, W (radiant fraction 0.85), at (-0.2, 0, 0.2) m
    /// (`left`) and (0.2, 0, 0.2) m (`right`).
    pub lamp_power_w: f64,
    /// Mesh sizes.
    pub meshing: Meshing,
    /// The sensor at each noise level.
    pub noise: Vec<NoiseLevel>,
    /// Seeds per noisy level (1 to 100).
    pub seeds: u32,
    /// The objects.
    pub objects: Vec<ObjectSpec>,
    /// The Cramér–Rao bound to compute at build for some objects (`super::bound`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bound: Option<super::bound::BoundSpec>,
}

/// Image size, pixels, and the optics.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraSize {
    pub width: u32,
    pub height: u32,
    /// Sub-samples per pixel side (`camera.supersampling` of the scenes); absent: point
    /// sampling at the pixel centres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supersampling: Option<u32>,
    /// The lens's point spread function (`camera.psf` of the scenes, e.g.
    /// `{"kind": "gaussian"}`); absent: none.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub psf: Option<serde_json::Value>,
}

/// Heating and filming, s.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Timing {
    /// Heating time after the lamps switch on, s.
    pub duration_s: f64,
    /// Solver time step, s.
    pub time_step_s: f64,
    /// Time between frames, s.
    pub frame_interval_s: f64,
    /// Frames at ambient before the lamps switch on.
    pub pre_heating_frames: u32,
}

/// Mesh sizes, m.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Meshing {
    /// TetGen surface element, m.
    pub surface_element_m: f64,
    /// Relief raster step, m.
    pub relief_resolution_m: f64,
    /// Outline spacing of the generated surfaces of revolution, m.
    pub object_spacing_m: f64,
    /// Prism layers through the wall of a shell (`"build": "shell"`); absent: heatsim's
    /// default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_layers: Option<u32>,
    /// Thickness of a shell's innermost wall layer over its outermost; absent: heatsim's
    /// default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_layer_ratio: Option<f64>,
}

/// The sensor at one noise level: y = Q(T_app + o_p + NETD xi), o_p the fixed pattern
/// (`heatsim::camera::sensor`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct NoiseLevel {
    /// Temporal noise, 1 sigma per pixel and frame, mK.
    pub netd_mk: f64,
    /// Fixed per-pixel offsets, 1 sigma, mK.
    pub fixed_pattern_mk: f64,
    /// Quantisation step, mK (0: none).
    pub quantization_mk: f64,
}

impl NoiseLevel {
    /// No noise of any kind: one case, seed 0.
    pub fn is_clean(&self) -> bool {
        self.netd_mk == 0.0 && self.fixed_pattern_mk == 0.0 && self.quantization_mk == 0.0
    }

    /// The camera model in words.
    pub fn describe(&self) -> String {
        if self.is_clean() {
            return "no temporal noise, no fixed pattern, no quantisation".into();
        }
        format!(
            "NETD {} mK (temporal, per pixel and frame), fixed pattern {} mK (per pixel, constant over frames), quantisation {} mK",
            self.netd_mk, self.fixed_pattern_mk, self.quantization_mk
        )
    }

    /// The seeds of this level's cases.
    pub fn seeds(&self, count: u32) -> Vec<u32> {
        if self.is_clean() {
            vec![0]
        } else {
            (1..=count).collect()
        }
    }
}

/// One object configuration.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    /// A benchmark object (`ball`, `soda_can`, `bottle_1`, `bottle_2`, `hemisphere`, `bunny`, ...).
    pub object: String,
    /// `surface` (the paper's model on the camera grid) or `volumetric` (the tetrahedral solver).
    pub solver: String,
    /// Relief or shell thickness, m; default: the object's wall.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thickness_m: Option<f64>,
    /// How a volumetric object's solid is made: `relief` (default), `shell` (a closed hollow
    /// shell of the wall thickness, meshed in prism layers) or `solid`.
    #[serde(default, skip_serializing_if = "is_relief")]
    pub build: Build,
}

fn is_relief(b: &Build) -> bool {
    *b == Build::Relief
}

/// An object configuration, resolved.
#[derive(Clone, Debug)]
pub struct SuiteObject {
    /// `ball-surface-d0.002`.
    pub id: String,
    pub object: Object,
    pub solver: Solver,
    pub thickness_m: f64,
    pub build: Build,
}

impl SuiteObject {
    /// The table row (clean camera) whose scene this object uses.
    pub fn row(&self) -> RowSpec {
        RowSpec { object: self.object, solver: self.solver, thickness_m: self.thickness_m, build: self.build }
    }
}

impl SuiteSpec {
    /// A shipped tier by name, or a spec file.
    ///
    /// # Errors
    /// An unknown tier, an unreadable or invalid file (naming it).
    pub fn load(tier: Option<&str>, file: Option<&Path>) -> anyhow::Result<SuiteSpec> {
        match (tier, file) {
            (_, Some(path)) => {
                let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
                SuiteSpec::parse(&text).with_context(|| format!("{}", path.display()))
            }
            (name, None) => {
                let name = name.unwrap_or("quick");
                let (_, text) = TIERS.iter().find(|(n, _)| *n == name).ok_or_else(|| {
                    anyhow::anyhow!(
                        "--tier: unknown tier `{name}`; known: {}",
                        TIERS.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
                    )
                })?;
                SuiteSpec::parse(text).with_context(|| format!("the shipped tier `{name}`"))
            }
        }
    }

    /// Parses and checks a spec.
    ///
    /// # Errors
    /// Unknown fields, values out of range (naming the field), unknown objects, duplicates.
    pub fn parse(text: &str) -> anyhow::Result<SuiteSpec> {
        let spec: SuiteSpec = serde_json::from_str(text).context("parsing the suite spec")?;
        spec.check()?;
        Ok(spec)
    }

    fn check(&self) -> anyhow::Result<()> {
        ensure!(
            !self.name.is_empty() && self.name.chars().all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_'),
            "name: `{}` must be letters, digits, `-` or `_`",
            self.name
        );
        let (w, h) = (self.camera.width, self.camera.height);
        ensure!((16..=2048).contains(&w) && (16..=2048).contains(&h), "camera: {w} x {h} must be 16 to 2048 pixels");
        let t = &self.timing;
        for (field, v) in [
            ("timing.duration_s", t.duration_s),
            ("timing.time_step_s", t.time_step_s),
            ("timing.frame_interval_s", t.frame_interval_s),
            ("lamp_power_w", self.lamp_power_w),
            ("meshing.surface_element_m", self.meshing.surface_element_m),
            ("meshing.relief_resolution_m", self.meshing.relief_resolution_m),
            ("meshing.object_spacing_m", self.meshing.object_spacing_m),
        ] {
            ensure!(v.is_finite() && v > 0.0, "{field}: must be a positive number, got {v}");
        }
        ensure!(!self.noise.is_empty(), "noise: at least one level");
        for (i, n) in self.noise.iter().enumerate() {
            for (field, v) in [
                ("netd_mk", n.netd_mk),
                ("fixed_pattern_mk", n.fixed_pattern_mk),
                ("quantization_mk", n.quantization_mk),
            ] {
                ensure!(v.is_finite() && v >= 0.0, "noise[{i}].{field}: must be >= 0, got {v}");
            }
        }
        ensure!((1..=100).contains(&self.seeds), "seeds: must be 1 to 100, got {}", self.seeds);
        ensure!(!self.objects.is_empty(), "objects: at least one");
        let resolved = self.resolved_objects()?;
        let mut ids: Vec<&str> = resolved.iter().map(|o| o.id.as_str()).collect();
        ids.sort_unstable();
        if let Some(w) = ids.windows(2).find(|w| w[0] == w[1]) {
            anyhow::bail!("objects: `{}` is listed twice", w[0]);
        }
        Ok(())
    }

    /// The objects with their ids, solvers and thicknesses.
    ///
    /// # Errors
    /// An unknown object or solver, a thickness that is not positive.
    pub fn resolved_objects(&self) -> anyhow::Result<Vec<SuiteObject>> {
        self.objects
            .iter()
            .enumerate()
            .map(|(i, o)| {
                let object = Object::parse(&o.object).with_context(|| format!("objects[{i}].object"))?;
                let solver = match o.solver.as_str() {
                    "surface" => Solver::Surface,
                    "volumetric" => Solver::Volumetric,
                    s => anyhow::bail!("objects[{i}].solver: `{s}` is neither `surface` nor `volumetric`"),
                };
                let thickness_m = o.thickness_m.unwrap_or(object.material_and_wall().1);
                ensure!(thickness_m.is_finite() && thickness_m > 0.0, "objects[{i}].thickness_m: must be > 0");
                ensure!(
                    o.build == Build::Relief || solver == Solver::Volumetric,
                    "objects[{i}].build: `{}` needs the volumetric solver",
                    o.build.name()
                );
                // Relief ids stay as they were, so that existing suites keep their versions.
                let id = match o.build {
                    Build::Relief => format!("{}-{}-d{}", object.name(), solver.name(), thickness_m),
                    b => format!("{}-{}-{}-d{}", object.name(), solver.name(), b.name(), thickness_m),
                };
                Ok(SuiteObject { id, object, solver, thickness_m, build: o.build })
            })
            .collect()
    }

    /// The table setup these settings give (clean camera; the scene's noise is 0).
    pub fn setup(&self) -> Setup {
        Setup {
            width: self.camera.width,
            height: self.camera.height,
            supersampling: self.camera.supersampling,
            psf: self.camera.psf.clone(),
            duration_s: self.timing.duration_s,
            time_step_s: self.timing.time_step_s,
            frame_interval_s: self.timing.frame_interval_s,
            pre_heating_frames: self.timing.pre_heating_frames,
            surface_element_m: self.meshing.surface_element_m,
            relief_resolution_m: self.meshing.relief_resolution_m,
            object_spacing_m: self.meshing.object_spacing_m,
            wall_layers: self.meshing.wall_layers,
            wall_layer_ratio: self.meshing.wall_layer_ratio,
            lamp_power_w: self.lamp_power_w,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_tiers_parse() {
        for (name, _) in TIERS {
            let spec = SuiteSpec::load(Some(name), None).unwrap();
            assert_eq!(spec.name, name);
        }
        assert!(SuiteSpec::load(Some("huge"), None).unwrap_err().to_string().contains("unknown tier"));
    }

    #[test]
    fn bad_specs_name_the_field() {
        let good = SuiteSpec::load(Some("tiny"), None).unwrap();
        let text = serde_json::to_string(&good).unwrap();
        let bad = |from: &str, to: &str| {
            assert!(text.contains(from), "{from}");
            format!("{:#}", SuiteSpec::parse(&text.replacen(from, to, 1)).unwrap_err())
        };
        assert!(bad("\"seeds\":", "\"seedz\":").contains("seedz"));
        assert!(bad("\"solver\":\"surface\"", "\"solver\":\"fluid\"").contains("objects[0].solver"));
        let v = serde_json::to_value(&good).unwrap();
        let mut w = v.clone();
        w["lamp_power_w"] = serde_json::json!(-1.0);
        assert!(format!("{:#}", SuiteSpec::parse(&w.to_string()).unwrap_err()).contains("lamp_power_w"));
        let mut w = v.clone();
        let first = w["objects"][0].clone();
        w["objects"].as_array_mut().unwrap().push(first);
        assert!(format!("{:#}", SuiteSpec::parse(&w.to_string()).unwrap_err()).contains("listed twice"));
    }
}
