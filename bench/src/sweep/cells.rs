//! The cells of the thickness sweep: what each one simulates (a complete [`Scene`]), its id,
//! and the SHA-256 of its configuration.
//!
//! Meshing is chosen per cell from the heat penetration length L = sqrt(alpha t_end) of the
//! material (alpha = k / (rho c_p) in m^2/s, t_end = 15 s): in 15 s the surface temperature
//! is shaped by the top few L of material, so the fine layer is `FINE_DEPTH_OVER_L` L deep
//! with elements of L / `PART1_L_OVER_H` (part 1) or L / `PART2_L_OVER_H` (part 2: larger
//! objects), clamped to [`MIN_ELEMENT`, `MAX_ELEMENT`] and never thicker than the plate.
//! `--quick` doubles every element size. Mesh convergence of this choice is measured by the
//! `convergence` cells (polystyrene, 1 cm) and reported in summary.md.

use std::collections::BTreeMap;

use anyhow::{bail, Context};
use heatsim::scene::{lookup_material, Scene};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use sha2::{Digest, Sha256};

use super::{FLUX_W_M2, SWEEP_FORMAT};

/// The factor c of the effective-thickness surface model (`surface_effective`).
pub fn effective_factor() -> f64 {
    heatsim::surface::DEFAULT_EFFECTIVE_THICKNESS_FACTOR
}

/// The paper's four materials (Fig. 2).
pub const MATERIALS: &[&str] = &["polystyrene", "steel", "glass", "brick"];

/// Thickness of the reference video of part 1, in m.
pub const REFERENCE_THICKNESS: f64 = 1e-3;

/// Heating duration, in s (paper: 15 s videos).
pub const DURATION: f64 = 15.0;

/// Cuboid visible face of part 1, in m (square): under uniform heating the cuboid's surface
/// temperature is one-dimensional away from the edges, so a small face keeps the finest
/// meshes of the sweep affordable.
pub const PART1_CUBOID_SIDE: f64 = 0.01;
/// Cuboid visible face of part 2, in m (square).
pub const CUBOID_SIDE: f64 = 0.02;
/// Time step, in s: halving it changes the mean rise of the convergence cell by a few 1e-4
/// (see summary.md), so the camera's 1/60 s is not needed.
pub const TIME_STEP: f64 = 1.0 / 30.0;
/// Hemisphere outer radius, in m.
pub const HEMISPHERE_RADIUS: f64 = 0.02;
/// Bunny size (largest extent), in m.
pub const BUNNY_SIZE: f64 = 0.04;

/// Fine-layer depth in units of the penetration length L.
pub const FINE_DEPTH_OVER_L: f64 = 2.0;
/// Part 1: elements per penetration length.
pub const PART1_L_OVER_H: f64 = 2.5;
/// Part 2: elements per penetration length (coarser: the bunny and hemisphere are larger).
pub const PART2_L_OVER_H: f64 = 1.25;
/// Smallest and largest surface element, in m.
pub const MIN_ELEMENT: f64 = 0.25e-3;
pub const MAX_ELEMENT: f64 = 2e-3;

/// Shapes of part 2.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "snake_case")]
pub enum Shape {
    Cuboid,
    Hemisphere,
    Bunny,
}

impl Shape {
    pub const ALL: [Shape; 3] = [Shape::Cuboid, Shape::Hemisphere, Shape::Bunny];

    pub fn name(self) -> &'static str {
        match self {
            Shape::Cuboid => "cuboid",
            Shape::Hemisphere => "hemisphere",
            Shape::Bunny => "bunny",
        }
    }
}

/// What a cell computes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum CellSpec {
    /// Part 1: cuboid of this material and thickness against the 1 mm reference.
    Thickness { material: String, thickness_m: f64 },
    /// Part 2: volumetric against surface and surface_effective on one mesh.
    Surface { shape: Shape, material: String, thickness_m: f64 },
    /// Mesh and time-step convergence of a part-1 cell: element sizes times
    /// `element_factor`, time step times `dt_factor`.
    Convergence { material: String, thickness_m: f64, element_factor: f64, dt_factor: f64 },
}

/// One cell: its spec, whether the sweep is `--quick`, and the scene it simulates.
#[derive(Clone, Debug)]
pub struct Cell {
    pub spec: CellSpec,
    pub quick: bool,
    pub scene: Scene,
}

/// Which cells a sweep runs.
#[derive(Clone, Debug)]
pub struct Plan {
    pub quick: bool,
    pub materials: Vec<String>,
    pub shapes: Vec<Shape>,
}

/// `n` thicknesses log-spaced from `lo` to `hi` (m), rounded to whole micrometres.
pub fn log_thicknesses(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| {
            let t = if n == 1 { 0.0 } else { k as f64 / (n - 1) as f64 };
            let d = lo * (hi / lo).powf(t);
            (d * 1e6).round() / 1e6
        })
        .collect()
}

impl Plan {
    /// Checks the material names against the library.
    pub fn new(quick: bool, materials: Vec<String>, shapes: Vec<Shape>) -> anyhow::Result<Plan> {
        if materials.is_empty() {
            bail!("--materials: at least one material is needed");
        }
        for m in &materials {
            if lookup_material(m).is_none() {
                bail!("--materials: unknown material {m:?}; the sweep knows {}", MATERIALS.join(", "));
            }
        }
        Ok(Plan { quick, materials, shapes })
    }

    /// Part-1 thicknesses (m): 13 log-spaced values from 1 mm to 1 m (4 with `--quick`).
    pub fn part1_thicknesses(&self) -> Vec<f64> {
        if self.quick {
            vec![1e-3, 1e-2, 1e-1, 1.0]
        } else {
            log_thicknesses(1e-3, 1.0, 13)
        }
    }

    /// Part-2 thicknesses (m): 1 mm to 20 cm.
    pub fn part2_thicknesses(&self) -> Vec<f64> {
        if self.quick {
            vec![2e-3, 1e-2]
        } else {
            vec![1e-3, 2e-3, 5e-3, 1e-2, 2e-2, 5e-2, 1e-1, 2e-1]
        }
    }

    /// Part-2 materials: all of them (with `--quick`, the first only).
    fn part2_materials(&self) -> &[String] {
        if self.quick {
            &self.materials[..1]
        } else {
            &self.materials
        }
    }

    /// Every cell, in a fixed order (the order shards partition).
    pub fn cells(&self) -> anyhow::Result<Vec<Cell>> {
        let mut specs = Vec::new();
        for m in &self.materials {
            for &d in &self.part1_thicknesses() {
                specs.push(CellSpec::Thickness { material: m.clone(), thickness_m: d });
            }
        }
        for &shape in &self.shapes {
            for m in self.part2_materials() {
                // A hemisphere is a solid half ball once d >= R: its cells stop at d = R.
                let ds = self.part2_thicknesses();
                let ds = ds.iter().filter(|&&d| shape != Shape::Hemisphere || d <= HEMISPHERE_RADIUS + 1e-12);
                for &d in ds {
                    specs.push(CellSpec::Surface { shape, material: m.clone(), thickness_m: d });
                }
            }
        }
        // Mesh and time-step convergence of one part-1 cell (the finest mesh of the sweep:
        // polystyrene has the shortest penetration length).
        let conv_material = self.materials[0].clone();
        let factors: &[(f64, f64)] =
            if self.quick { &[(2.0, 1.0), (1.0, 0.5)] } else { &[(2.0, 1.0), (1.5, 1.0), (0.75, 1.0), (1.0, 0.5)] };
        for &(element_factor, dt_factor) in factors {
            specs.push(CellSpec::Convergence {
                material: conv_material.clone(),
                thickness_m: 1e-2,
                element_factor,
                dt_factor,
            });
        }
        specs.into_iter().map(|spec| Cell::new(spec, self.quick)).collect()
    }
}

/// Formats a thickness for ids: whole micrometres.
pub fn thickness_tag(d: f64) -> String {
    format!("{}um", (d * 1e6).round() as u64)
}

impl CellSpec {
    /// The file name of the cell's result, without `.json`.
    pub fn id(&self) -> String {
        match self {
            CellSpec::Thickness { material, thickness_m } => {
                format!("thickness_{material}_{}", thickness_tag(*thickness_m))
            }
            CellSpec::Surface { shape, material, thickness_m } => {
                format!("surface_{}_{material}_{}", shape.name(), thickness_tag(*thickness_m))
            }
            CellSpec::Convergence { material, thickness_m, element_factor, dt_factor } => {
                format!("convergence_{material}_{}_h{element_factor}_dt{dt_factor}", thickness_tag(*thickness_m))
            }
        }
    }

    pub fn material(&self) -> &str {
        match self {
            CellSpec::Thickness { material, .. }
            | CellSpec::Surface { material, .. }
            | CellSpec::Convergence { material, .. } => material,
        }
    }

    pub fn thickness(&self) -> f64 {
        match self {
            CellSpec::Thickness { thickness_m, .. }
            | CellSpec::Surface { thickness_m, .. }
            | CellSpec::Convergence { thickness_m, .. } => *thickness_m,
        }
    }

    /// The part-1 reference cell this cell is compared with, if any (itself for the 1 mm
    /// cell).
    pub fn reference(&self) -> Option<CellSpec> {
        match self {
            CellSpec::Thickness { material, .. } => {
                Some(CellSpec::Thickness { material: material.clone(), thickness_m: REFERENCE_THICKNESS })
            }
            _ => None,
        }
    }

    /// Whether this is a part-1 reference cell.
    pub fn is_reference(&self) -> bool {
        self.reference().is_some_and(|r| &r == self)
    }
}

/// Heat penetration length sqrt(alpha t_end) of a library material, in m.
pub fn penetration_length(material: &str) -> anyhow::Result<f64> {
    let m = lookup_material(material).with_context(|| format!("unknown material {material:?}"))?;
    Ok((m.diffusivity() * DURATION).sqrt())
}

/// The surface element size (m) and fine-layer depth (m) of a cell.
pub fn meshing_for(spec: &CellSpec, quick: bool) -> anyhow::Result<(f64, f64)> {
    let l = penetration_length(spec.material())?;
    let (l_over_h, factor) = match spec {
        CellSpec::Thickness { .. } => (PART1_L_OVER_H, 1.0),
        CellSpec::Surface { .. } => (PART2_L_OVER_H, 1.0),
        CellSpec::Convergence { element_factor, .. } => (PART1_L_OVER_H, *element_factor),
    };
    let quick_factor = if quick { 2.0 } else { 1.0 };
    let h = (l / l_over_h).clamp(MIN_ELEMENT, MAX_ELEMENT) * factor * quick_factor;
    let h = h.min(spec.thickness());
    let depth = (FINE_DEPTH_OVER_L * l).max(h);
    // Round to 0.1 um so the scene JSON (and the hash) is stable across platforms.
    let r = |x: f64| (x * 1e7).round() / 1e7;
    Ok((r(h), r(depth)))
}

/// Focal length of the default camera (FLIR Boson 640, HFOV 24.3 deg), in pixels.
fn default_focal_px() -> f64 {
    let c = heatsim::scene::CameraSpec::default();
    (c.width as f64 / 2.0) / (c.hfov_deg.to_radians() / 2.0).tan()
}

/// A square window of the default camera (same focal length and pixel pitch) that sees an
/// object of lateral extent `extent` (m) at the default working distance: the paper's camera,
/// cropped to the object so that videos stay small.
fn camera_window(extent: f64) -> Value {
    let c = heatsim::scene::CameraSpec::default();
    let f = default_focal_px();
    let distance = c.position[2];
    let side = ((extent * f / distance) * 1.15).ceil() as u32 + 8;
    let hfov = 2.0 * ((side as f64 / 2.0) / f).atan().to_degrees();
    json!({ "width": side, "height": side, "hfov_deg": (hfov * 1e9).round() / 1e9 })
}

impl Cell {
    /// Builds the scene of a cell (validated).
    pub fn new(spec: CellSpec, quick: bool) -> anyhow::Result<Cell> {
        let (h, depth) = meshing_for(&spec, quick)?;
        let d = spec.thickness();
        let (object, extent) = match &spec {
            CellSpec::Thickness { .. } | CellSpec::Convergence { .. } => (
                json!({ "kind": "cuboid", "width": PART1_CUBOID_SIDE, "height": PART1_CUBOID_SIDE, "thickness": d }),
                PART1_CUBOID_SIDE,
            ),
            CellSpec::Surface { shape: Shape::Cuboid, .. } => {
                (json!({ "kind": "cuboid", "width": CUBOID_SIDE, "height": CUBOID_SIDE, "thickness": d }), CUBOID_SIDE)
            }
            CellSpec::Surface { shape: Shape::Hemisphere, .. } => {
                (json!({ "kind": "hemisphere", "radius": HEMISPHERE_RADIUS, "thickness": d }), 2.0 * HEMISPHERE_RADIUS)
            }
            CellSpec::Surface { shape: Shape::Bunny, .. } => {
                (json!({ "kind": "bunny", "size": BUNNY_SIZE, "thickness": d }), BUNNY_SIZE)
            }
        };
        let dt = match &spec {
            CellSpec::Convergence { dt_factor, .. } => TIME_STEP * dt_factor,
            _ => TIME_STEP,
        };
        // Part 1's deep layer (far below the heat's reach in 15 s) is meshed at half the
        // cuboid's side instead of TetGen's default third of min(d, side).
        let deep = match &spec {
            CellSpec::Thickness { .. } | CellSpec::Convergence { .. } => {
                Some(((PART1_CUBOID_SIDE / 2.0).max(h) * 1e7).round() / 1e7)
            }
            CellSpec::Surface { .. } => None,
        };
        let mut meshing = json!({ "surface_element_size": h, "fine_layer_depth": depth });
        if let Some(deep) = deep {
            meshing["deep_element_size"] = json!(deep);
        }
        let doc = json!({
            "name": spec.id(),
            "object": object,
            "material": { "name": spec.material() },
            "lamps": [ { "kind": "uniform", "flux": FLUX_W_M2, "on": 0.0 } ],
            "camera": camera_window(extent),
            "timing": { "duration": DURATION, "time_step": dt, "frame_interval": 1.0 / 6.0, "pre_heating_frames": 0 },
            "meshing": meshing,
        });
        let scene = Scene::from_json_str(&doc.to_string(), std::path::Path::new("."))
            .with_context(|| format!("cell {}: building its scene", spec.id()))?;
        Ok(Cell { spec, quick, scene })
    }

    pub fn id(&self) -> String {
        self.spec.id()
    }

    /// The canonical configuration of the cell: everything its result depends on. `reference`
    /// is the hash of the reference cell (part 1).
    pub fn config(&self) -> Value {
        json!({
            "sweep_format": SWEEP_FORMAT,
            "heatsim_version": heatsim_version(),
            "quick": self.quick,
            "cell": self.spec,
            "scene": self.scene,
            "reference": self.spec.reference().filter(|_| !self.spec.is_reference())
                .map(|r| Cell::new(r, self.quick).map(|c| c.hash()).unwrap_or_default()),
            "surface_effective_thickness_factor": effective_factor(),
        })
    }

    /// SHA-256 (hex) of the canonical JSON of [`Cell::config`].
    pub fn hash(&self) -> String {
        sha256_hex(canonical_json(&self.config()).as_bytes())
    }

    /// A rough cost (arbitrary units, for ordering the work): visible area over h^2 times the
    /// fine depth over h.
    pub fn cost_estimate(&self) -> f64 {
        let m = &self.scene.meshing;
        let h = m.surface_element_size;
        let area = match &self.spec {
            CellSpec::Surface { shape: Shape::Hemisphere, .. } => {
                2.0 * std::f64::consts::PI * HEMISPHERE_RADIUS.powi(2)
            }
            CellSpec::Surface { shape: Shape::Bunny, .. } => 0.6 * BUNNY_SIZE * BUNNY_SIZE,
            CellSpec::Surface { shape: Shape::Cuboid, .. } => CUBOID_SIDE * CUBOID_SIDE,
            _ => PART1_CUBOID_SIDE * PART1_CUBOID_SIDE,
        };
        let runs = if matches!(self.spec, CellSpec::Surface { .. }) { 1.3 } else { 1.0 };
        let steps = DURATION / self.scene.timing.time_step;
        runs * steps * area / (h * h) * (m.fine_layer_depth.min(self.spec.thickness()) / h).max(1.0)
    }
}

/// The version of heatsim the results come from.
pub fn heatsim_version() -> String {
    format!("simbench {}", env!("CARGO_PKG_VERSION"))
}

/// JSON with object keys sorted at every level and no whitespace: equal values give equal
/// bytes whatever the field order of the structs.
pub fn canonical_json(v: &Value) -> String {
    fn sort(v: &Value) -> Value {
        match v {
            Value::Object(map) => {
                let sorted: BTreeMap<&String, Value> = map.iter().map(|(k, v)| (k, sort(v))).collect();
                Value::Object(sorted.into_iter().map(|(k, v)| (k.clone(), v)).collect())
            }
            Value::Array(a) => Value::Array(a.iter().map(sort).collect()),
            other => other.clone(),
        }
    }
    // serde_json's map keeps insertion order or sorts, depending on features; inserting in
    // sorted order gives sorted output either way.
    sort(v).to_string()
}

/// Lower-case hex SHA-256.
pub fn sha256_hex(bytes: &[u8]) -> String {
    let digest = Sha256::digest(bytes);
    digest.iter().map(|b| format!("{b:02x}")).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plan(quick: bool) -> Plan {
        Plan::new(quick, MATERIALS.iter().map(|s| s.to_string()).collect(), Shape::ALL.to_vec()).unwrap()
    }

    #[test]
    fn default_plan_has_the_papers_ranges() {
        let p = plan(false);
        let t1 = p.part1_thicknesses();
        assert!(t1.len() >= 12);
        assert_eq!(t1[0], 1e-3);
        assert_eq!(*t1.last().unwrap(), 1.0);
        assert!(t1.windows(2).all(|w| w[1] > w[0]));
        assert_eq!(*p.part2_thicknesses().last().unwrap(), 0.2);
        let cells = p.cells().unwrap();
        let mut ids: Vec<String> = cells.iter().map(|c| c.id()).collect();
        ids.sort();
        ids.dedup();
        assert_eq!(ids.len(), cells.len(), "ids are unique");
    }

    #[test]
    fn hash_is_stable_and_sensitive() {
        let a = Cell::new(CellSpec::Thickness { material: "steel".into(), thickness_m: 0.01 }, false).unwrap();
        let b = Cell::new(CellSpec::Thickness { material: "steel".into(), thickness_m: 0.01 }, false).unwrap();
        assert_eq!(a.hash(), b.hash());
        assert_eq!(a.hash().len(), 64);
        let c = Cell::new(CellSpec::Thickness { material: "steel".into(), thickness_m: 0.02 }, false).unwrap();
        assert_ne!(a.hash(), c.hash());
        let q = Cell::new(CellSpec::Thickness { material: "steel".into(), thickness_m: 0.01 }, true).unwrap();
        assert_ne!(a.hash(), q.hash());
        let mut e = a.clone();
        e.scene.environment.convection_coefficient = 6.0;
        assert_ne!(a.hash(), e.hash());
    }

    #[test]
    fn canonical_json_ignores_key_order() {
        let x: Value = serde_json::from_str(r#"{"b": 1, "a": {"d": [1, {"f": 2, "e": 3}], "c": null}}"#).unwrap();
        let y: Value = serde_json::from_str(r#"{"a": {"c": null, "d": [1, {"e": 3, "f": 2}]}, "b": 1}"#).unwrap();
        assert_eq!(canonical_json(&x), canonical_json(&y));
        assert_eq!(canonical_json(&x), r#"{"a":{"c":null,"d":[1,{"e":3,"f":2}]},"b":1}"#);
    }

    #[test]
    fn unknown_material_is_named() {
        let e = Plan::new(false, vec!["unobtainium".into()], vec![]).unwrap_err();
        assert!(e.to_string().contains("unobtainium"), "{e}");
    }

    #[test]
    fn elements_never_exceed_the_plate() {
        for m in MATERIALS {
            let (h, depth) =
                meshing_for(&CellSpec::Thickness { material: m.to_string(), thickness_m: 1e-3 }, false).unwrap();
            assert!(h <= 1e-3 && depth >= h, "{m}: {h} {depth}");
        }
    }
}
