//! The rows of the shape-error table: what each simulates (a complete scene as JSON), how it is
//! reconstructed, its id and the SHA-256 of its configuration.
//!
//! Setup shared by all rows (stated in `shape_error.md`): two datasets per object, a point lamp
//! of 250 W (radiant fraction 0.85) at (-0.2, 0, 0.2) m (`left`) and at (+0.2, 0, 0.2) m
//! (`right`), as the stage-1 validation scenes in `scenes/recon/`; the camera 0.3683 m above
//! the origin looking down -z with the FLIR Boson's 24.3 degree field of view (default table:
//! 320 x 256 pixels; `--quick`: 160 x 128); 45 s of heating at 2 frames/s after 10 frames at
//! ambient (`--quick`: 20 s after 6). NETD 0 rows have no temporal noise, no fixed pattern and
//! no quantisation; NETD 50 mK rows have the camera defaults (fixed pattern 25 mK, 10 mK
//! quantisation). Surface-solver rows run the paper's surface model (Eq. 6) on the camera's
//! pixel grid; volumetric rows (the bunny at 1, 10 and 20 cm, Fig. 4) run the tetrahedral
//! solver and the camera films the solid. Both solvers step with BDF2 (second order in time).
//! All lengths in m, times in s, powers in W.

use anyhow::bail;
use serde::Serialize;
use serde_json::{json, Value};

use super::objects::Revolved;
use crate::sweep::cells::{canonical_json, sha256_hex};

/// Version of the row format, of the setup and of the reconstruction defaults; part of every row
/// hash (2: stage 2 profiles the flux and the globals, material diffusivity passed; 3: noise
/// correction, profiled size, bulge start; 4: the finest level keeps the size, ordered sums).
pub const TABLE_FORMAT: u32 = 4;

/// An object of the table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Object {
    Ball,
    SodaCan,
    Bottle1,
    Bottle2,
    Hemisphere,
    Bunny,
    Vase,
    TwistedSpindle,
}

impl Object {
    /// The table's objects (its default rows).
    pub const ALL: [Object; 6] =
        [Object::Ball, Object::SodaCan, Object::Bottle1, Object::Bottle2, Object::Hemisphere, Object::Bunny];
    /// Shapes nobody tuned the reconstruction on (see [`Revolved::Vase`] and
    /// [`Revolved::TwistedSpindle`]): in the plan only when `--objects` names them.
    pub const UNTUNED: [Object; 2] = [Object::Vase, Object::TwistedSpindle];
    /// [`Object::ALL`] then [`Object::UNTUNED`].
    pub const EVERY: [Object; 8] = [
        Object::Ball,
        Object::SodaCan,
        Object::Bottle1,
        Object::Bottle2,
        Object::Hemisphere,
        Object::Bunny,
        Object::Vase,
        Object::TwistedSpindle,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Object::Ball => "ball",
            Object::SodaCan => "soda_can",
            Object::Bottle1 => "bottle_1",
            Object::Bottle2 => "bottle_2",
            Object::Hemisphere => "hemisphere",
            Object::Bunny => "bunny",
            Object::Vase => "vase",
            Object::TwistedSpindle => "twisted_spindle",
        }
    }

    /// Parses a name of [`Object::name`].
    ///
    /// # Errors
    /// An unknown name, listing the known ones.
    pub fn parse(s: &str) -> anyhow::Result<Object> {
        Object::EVERY.into_iter().find(|o| o.name() == s.trim()).ok_or_else(|| {
            anyhow::anyhow!(
                "--objects: unknown object `{s}`; known: {}",
                Object::EVERY.iter().map(|o| o.name()).collect::<Vec<_>>().join(", ")
            )
        })
    }

    /// The generated surface of revolution, if this object is one.
    pub fn revolved(self) -> Option<Revolved> {
        match self {
            Object::Ball => Some(Revolved::Ball),
            Object::SodaCan => Some(Revolved::SodaCan),
            Object::Bottle1 => Some(Revolved::Bottle1),
            Object::Bottle2 => Some(Revolved::Bottle2),
            Object::Vase => Some(Revolved::Vase),
            Object::TwistedSpindle => Some(Revolved::TwistedSpindle),
            Object::Hemisphere | Object::Bunny => None,
        }
    }

    /// Material of the paper's object (Sec. 7: acrylic ball, aluminium can, PET bottles,
    /// printed bunny) and the wall thickness of the surface-solver rows (m); for the untuned
    /// objects, a glass vase (1.5 mm) and an ABS moulding (1 mm).
    pub fn material_and_wall(self) -> (&'static str, f64) {
        match self {
            Object::Ball => ("pmma", 2e-3),
            // A real can wall is about 0.1 mm, but TetGen did not mesh the can's 0.1 mm relief
            // (2 mm elements) within its 600 s limit; 0.5 mm meshes in seconds (the surface
            // solver only uses C = rho c_p d and k d from it).
            Object::SodaCan => ("aluminium", 0.5e-3),
            Object::Bottle1 | Object::Bottle2 => ("pet", 0.5e-3),
            Object::Hemisphere => ("pla", 1e-3),
            // The paper's printed bunny has a 2 mm shell.
            Object::Bunny => ("pla", 2e-3),
            Object::Vase => ("glass", 1.5e-3),
            Object::TwistedSpindle => ("abs", 1e-3),
        }
    }
}

/// Which forward model produced the videos.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Solver {
    /// The paper's surface model on the camera's pixel grid.
    Surface,
    /// The tetrahedral solver (the ground truth physics).
    Volumetric,
}

impl Solver {
    pub fn name(self) -> &'static str {
        match self {
            Solver::Surface => "surface",
            Solver::Volumetric => "volumetric",
        }
    }
}

/// One row.
#[derive(Clone, Debug, Serialize)]
pub struct RowSpec {
    pub object: Object,
    pub solver: Solver,
    /// Object (relief or shell) thickness, m.
    pub thickness_m: f64,
    /// Camera temporal noise, mK.
    pub netd_mk: f64,
}

impl RowSpec {
    /// File-name-safe id, e.g. `bottle_1-surface-d0.0005-netd50`.
    pub fn id(&self) -> String {
        format!("{}-{}-d{}-netd{}", self.object.name(), self.solver.name(), self.thickness_m, self.netd_mk)
    }
}

/// Resolution and timing of a run.
#[derive(Clone, Debug, Serialize)]
pub struct Setup {
    pub quick: bool,
    pub width: u32,
    pub height: u32,
    pub duration_s: f64,
    pub time_step_s: f64,
    pub frame_interval_s: f64,
    pub pre_heating_frames: u32,
    /// TetGen surface element (m) and relief raster (m).
    pub surface_element_m: f64,
    pub relief_resolution_m: f64,
    /// Outline spacing of the generated objects (m).
    pub object_spacing_m: f64,
    /// Power of each point lamp, W.
    pub lamp_power_w: f64,
    /// Arguments passed to `simbench reconstruct` after the dataset directories and `--out`.
    pub reconstruct_args: Vec<String>,
}

impl Setup {
    pub fn new(quick: bool, reconstruct_args: Vec<String>) -> Setup {
        if quick {
            Setup {
                quick,
                width: 160,
                height: 128,
                duration_s: 20.0,
                time_step_s: 0.1,
                frame_interval_s: 0.5,
                pre_heating_frames: 6,
                surface_element_m: 4e-3,
                relief_resolution_m: 1e-3,
                object_spacing_m: 1.5e-3,
                lamp_power_w: LAMP_POWER_W,
                reconstruct_args,
            }
        } else {
            Setup {
                quick,
                width: 320,
                height: 256,
                duration_s: 45.0,
                time_step_s: 0.05,
                frame_interval_s: 0.5,
                pre_heating_frames: 10,
                surface_element_m: 2e-3,
                relief_resolution_m: 0.5e-3,
                object_spacing_m: 0.5e-3,
                lamp_power_w: LAMP_POWER_W,
                reconstruct_args,
            }
        }
    }
}

/// The rows of a run: every object through the surface solver at NETD 0 and 50 mK, the bunny
/// through the volumetric solver at 1, 10 and 20 cm (NETD 50 mK); `--quick`: the ball at NETD 0
/// and 50 mK, bottle 1 and the hemisphere at 50 mK, the volumetric bunny at 1 cm. `objects`
/// restricts the list; the [`Object::UNTUNED`] objects it names are added after those rows
/// (surface solver, NETD 0 and 50 mK, in quick and full runs alike).
pub fn plan(quick: bool, objects: &[Object]) -> Vec<RowSpec> {
    let surface = |o: Object, netd: f64| RowSpec {
        object: o,
        solver: Solver::Surface,
        thickness_m: o.material_and_wall().1,
        netd_mk: netd,
    };
    let vol = |d: f64| RowSpec { object: Object::Bunny, solver: Solver::Volumetric, thickness_m: d, netd_mk: 50.0 };
    let rows = if quick {
        vec![
            surface(Object::Ball, 0.0),
            surface(Object::Ball, 50.0),
            surface(Object::Bottle1, 50.0),
            surface(Object::Hemisphere, 50.0),
            vol(0.01),
        ]
    } else {
        let mut v: Vec<RowSpec> = Object::ALL.iter().flat_map(|&o| [surface(o, 0.0), surface(o, 50.0)]).collect();
        v.extend([vol(0.01), vol(0.1), vol(0.2)]);
        v
    };
    let mut rows: Vec<RowSpec> =
        rows.into_iter().filter(|r| objects.is_empty() || objects.contains(&r.object)).collect();
    for o in Object::UNTUNED.into_iter().filter(|o| objects.contains(o)) {
        rows.extend([surface(o, 0.0), surface(o, 50.0)]);
    }
    rows
}

/// Bunny size (largest extent), m: "scaled to about 10 cm".
pub const BUNNY_SIZE: f64 = 0.10;
/// Hemisphere outer radius, m.
pub const HEMISPHERE_RADIUS: f64 = 0.05;
/// Lamp power (W) and positions (m) of the two configurations.
pub const LAMP_POWER_W: f64 = 250.0;
pub const LAMP_LEFT: [f64; 3] = [-0.2, 0.0, 0.2];
pub const LAMP_RIGHT: [f64; 3] = [0.2, 0.0, 0.2];

/// The scene file of a row. `object_file` is the generated OBJ (file name relative to the
/// scene file) and `object_size` its largest extent (m), for the surfaces of revolution.
pub fn scene_json(row: &RowSpec, setup: &Setup, object_file: Option<(&str, f64)>) -> anyhow::Result<Value> {
    let (material, _) = row.object.material_and_wall();
    let d = row.thickness_m;
    let object = match (row.object, object_file) {
        (Object::Hemisphere, _) => json!({ "kind": "hemisphere", "radius": HEMISPHERE_RADIUS, "thickness": d }),
        (Object::Bunny, _) => json!({ "kind": "bunny", "size": BUNNY_SIZE, "thickness": d, "construction": "relief" }),
        (_, Some((file, size))) => {
            json!({ "kind": "mesh", "file": file, "size": size, "thickness": d, "construction": "relief" })
        }
        (o, None) => bail!("{}: the generated object file is missing", o.name()),
    };
    let lamp = |p: [f64; 3]| json!([{ "kind": "point", "power": setup.lamp_power_w, "position": p, "on": 0.0 }]);
    let (netd, fixed, quant) = if row.netd_mk > 0.0 { (row.netd_mk * 1e-3, 0.025, 0.01) } else { (0.0, 0.0, 0.0) };
    let solver = match row.solver {
        // BDF2: second order in time, so that the videos are close to continuous-time physics
        // at the 0.05 s step (backward Euler's first-order error biased stage 1's C by 4 % on
        // the bunny validation scene; scenes/recon/README.md).
        Solver::Surface => json!({ "kind": "surface", "surface_mesh": "camera_grid", "time_integration": "bdf2" }),
        Solver::Volumetric => json!({ "kind": "volumetric", "time_integration": "bdf2" }),
    };
    Ok(json!({
        "name": row.id(),
        "object": object,
        "material": { "name": material },
        "lamp_configurations": [
            { "name": "left", "lamps": lamp(LAMP_LEFT) },
            { "name": "right", "lamps": lamp(LAMP_RIGHT) },
        ],
        "camera": {
            "position": [0.0, 0.0, 0.3683], "look_at": [0.0, 0.0, 0.0],
            "width": setup.width, "height": setup.height,
            "pixel_pitch": 12e-6 * 640.0 / f64::from(setup.width),
            "netd": netd, "fixed_pattern_sigma": fixed, "quantization": quant,
        },
        "timing": {
            "duration": setup.duration_s, "time_step": setup.time_step_s,
            "frame_interval": setup.frame_interval_s, "pre_heating_frames": setup.pre_heating_frames,
        },
        "solver": solver,
        "meshing": {
            "surface_element_size": setup.surface_element_m,
            "relief_resolution": setup.relief_resolution_m,
        },
    }))
}

/// The configuration a row's hash covers: the row, the setup, the scene and the generated
/// object's geometry (its SHA-256).
pub fn config(row: &RowSpec, setup: &Setup, scene: &Value, object_sha: Option<&str>) -> Value {
    json!({
        "format": TABLE_FORMAT,
        "row": row,
        "setup": setup,
        "scene": scene,
        "object_sha256": object_sha,
    })
}

/// SHA-256 (hex) of a configuration, independent of key order.
pub fn hash(config: &Value) -> String {
    sha256_hex(canonical_json(config).as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plans_and_hashes() {
        let full = plan(false, &[]);
        assert_eq!(full.len(), 15);
        let ids: std::collections::BTreeSet<String> = full.iter().map(RowSpec::id).collect();
        assert_eq!(ids.len(), 15, "ids are unique");
        assert_eq!(plan(true, &[]).len(), 5);
        assert_eq!(plan(false, &[Object::Bunny]).len(), 5);
        let setup = Setup::new(true, vec!["--stage".into(), "2".into()]);
        let row = &plan(true, &[])[0];
        let scene = scene_json(row, &setup, Some(("object.obj", 0.06))).unwrap();
        let h = hash(&config(row, &setup, &scene, Some("abc")));
        assert_eq!(h, hash(&config(row, &setup, &scene, Some("abc"))));
        assert_ne!(h, hash(&config(row, &setup, &scene, Some("abd"))), "object geometry");
        let other = Setup::new(true, vec!["--stage".into(), "1".into()]);
        assert_ne!(h, hash(&config(row, &other, &scene, Some("abc"))), "reconstruction arguments");
        // The scene parses as a heatsim scene.
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("object.obj"),
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
        )
        .unwrap();
        let path = dir.path().join("scene.json");
        std::fs::write(&path, serde_json::to_string(&scene).unwrap()).unwrap();
        heatsim::scene::Scene::from_file(&path).unwrap();
    }

    /// The untuned objects enter the plan only when named, two surface rows each, after the
    /// table's rows.
    #[test]
    fn untuned_objects_only_when_named() {
        let full = plan(false, &[]);
        assert!(full.iter().chain(&plan(true, &[])).all(|r| !Object::UNTUNED.contains(&r.object)));
        let untuned = plan(true, &[Object::Ball, Object::Vase, Object::TwistedSpindle]);
        let ids: Vec<String> = untuned.iter().map(RowSpec::id).collect();
        assert_eq!(
            ids,
            [
                "ball-surface-d0.002-netd0",
                "ball-surface-d0.002-netd50",
                "vase-surface-d0.0015-netd0",
                "vase-surface-d0.0015-netd50",
                "twisted_spindle-surface-d0.001-netd0",
                "twisted_spindle-surface-d0.001-netd50"
            ]
        );
        assert_eq!(Object::parse("twisted_spindle").unwrap(), Object::TwistedSpindle);
    }
}
