//! [`ObjectSpec`]: the shape of the heated object (`"object"` in a scene file).
//!
//! Frame: the camera looks down the z axis from +z; the *visible surface* is the part of the
//! object's boundary facing +z. Lengths in metres.

use std::path::PathBuf;

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::parse::tagged_enum;
use super::validate::{num, Check};
use super::SceneError;

/// Largest accepted object size (width, height, radius, mesh size), in m.
pub const MAX_OBJECT_SIZE: f64 = 100.0;

/// Largest accepted thickness, in m.
pub const MAX_THICKNESS: f64 = 10.0;

/// Mesh file extensions accepted for `object.file` (compared case-insensitively).
pub const MESH_EXTENSIONS: &[&str] = &["obj", "ply", "gltf", "glb"];

/// The heated object; tagged by `"kind"`: `cuboid`, `hemisphere`, `mesh` or `bunny`.
#[derive(Debug, Clone, PartialEq, Serialize, JsonSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ObjectSpec {
    /// A rectangular block seen face-on.
    Cuboid(CuboidSpec),
    /// A dome shell (solid once the thickness reaches the radius).
    Hemisphere(HemisphereSpec),
    /// A triangle mesh read from a file.
    Mesh(MeshSpec),
    /// The Stanford bunny (the asset is located by [`crate::assets`], not by the scene).
    Bunny(BunnySpec),
}

tagged_enum!(ObjectSpec {
    "cuboid" => Cuboid,
    "hemisphere" => Hemisphere,
    "mesh" => Mesh,
    "bunny" => Bunny,
});

/// A cuboid: the visible face is the rectangle z = 0 facing +z, with x in [-w/2, w/2] and
/// y in [-h/2, h/2]; the material fills z in [-d, 0] (d = `thickness`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct CuboidSpec {
    /// Extent along x, in m (required; > 0, <= 100).
    pub width: f64,
    /// Extent along y, in m (required; > 0, <= 100).
    pub height: f64,
    /// Extent along z: depth of material directly below the visible face, in m (required;
    /// > 0, <= 10).
    pub thickness: f64,
}

/// A hemispherical dome shell: centre of the sphere at the origin, top of the dome at
/// z = R, base in the plane z = 0, seen by the camera from +z. Outer radius R, inner radius
/// R - d; solid (a half ball) once d >= R.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct HemisphereSpec {
    /// Outer radius R, in m (required; > 0, <= 100).
    pub radius: f64,
    /// Shell thickness d, in m (required; > 0, <= 10); d >= R gives a solid half ball.
    pub thickness: f64,
}

/// How a mesh becomes a solid.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum Construction {
    /// The surface the camera sees from +z (a height field), extruded away from the camera
    /// (towards -z) by `thickness`. The default.
    #[default]
    Relief,
    /// The closed mesh itself is the solid; `thickness` is ignored.
    Solid,
    /// A hollow shell: the closed mesh is the outer face, and the wall under it is `thickness`
    /// thick along the surface normal, meshed in `meshing.wall_layers` prism layers
    /// ([`crate::mesh::layered`]); the enclosed cavity is empty. Refused where the wall does
    /// not fit (the object is thinner than twice the wall somewhere).
    Shell,
}

/// A triangle mesh from a file.
///
/// Placement: the mesh is rotated by `rotation_deg` (about x, then y, then z, in degrees),
/// then uniformly scaled so that the largest extent of its axis-aligned bounding box is
/// `size`, then centred (the consumer decides the exact centring convention, see
/// [`crate::solid`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MeshSpec {
    /// Path of a `.obj`, `.ply`, `.gltf` or `.glb` file. Relative paths are relative to the
    /// directory of the scene file; after loading, the resolved path is stored (required).
    pub file: PathBuf,
    /// Largest bounding-box extent after rotation, in m; the mesh is uniformly scaled to it
    /// (required; > 0, <= 100).
    pub size: f64,
    /// Rotations about x, then y, then z, in degrees, applied before scaling and centring
    /// (default [0, 0, 0]).
    #[serde(default)]
    pub rotation_deg: [f64; 3],
    /// Relief or wall thickness, in m: required for `construction = "relief"` and `"shell"`
    /// (> 0, <= 10), ignored for `"solid"` (no default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thickness: Option<f64>,
    /// `"relief"` (default), `"shell"` or `"solid"`.
    #[serde(default)]
    pub construction: Construction,
}

/// Default `rotation_deg` of the bunny, in degrees (about x, then y, then z).
pub const BUNNY_DEFAULT_ROTATION_DEG: [f64; 3] = [0.0, 0.0, 0.0];

fn bunny_default_rotation() -> [f64; 3] {
    BUNNY_DEFAULT_ROTATION_DEG
}

/// The Stanford bunny: like [`MeshSpec`] without `file`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct BunnySpec {
    /// Largest bounding-box extent after rotation, in m; the mesh is uniformly scaled to it
    /// (required; > 0, <= 100).
    pub size: f64,
    /// Rotations about x, then y, then z, in degrees, applied before scaling and centring
    /// (default [`BUNNY_DEFAULT_ROTATION_DEG`] = [0, 0, 0]).
    #[serde(default = "bunny_default_rotation")]
    pub rotation_deg: [f64; 3],
    /// Relief or wall thickness, in m: required for `construction = "relief"` and `"shell"`
    /// (> 0, <= 10), ignored for `"solid"` (no default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub thickness: Option<f64>,
    /// `"relief"` (default), `"shell"` or `"solid"`.
    #[serde(default)]
    pub construction: Construction,
}

impl ObjectSpec {
    /// The value of `kind`: `"cuboid"`, `"hemisphere"`, `"mesh"` or `"bunny"`.
    pub fn kind(&self) -> &'static str {
        match self {
            ObjectSpec::Cuboid(_) => "cuboid",
            ObjectSpec::Hemisphere(_) => "hemisphere",
            ObjectSpec::Mesh(_) => "mesh",
            ObjectSpec::Bunny(_) => "bunny",
        }
    }

    /// The thickness that shapes the solid, in m: the cuboid's depth, the shell thickness of
    /// the hemisphere, the relief or wall thickness of a mesh or bunny. `None` for
    /// `construction = "solid"` (any value given is ignored) and for a relief whose thickness
    /// is missing (which [`validate`](Self::validate) rejects).
    pub fn thickness(&self) -> Option<f64> {
        match self {
            ObjectSpec::Cuboid(c) => Some(c.thickness),
            ObjectSpec::Hemisphere(h) => Some(h.thickness),
            ObjectSpec::Mesh(MeshSpec { thickness, construction, .. })
            | ObjectSpec::Bunny(BunnySpec { thickness, construction, .. }) => match construction {
                Construction::Relief | Construction::Shell => *thickness,
                Construction::Solid => None,
            },
        }
    }

    /// Sets the thickness (m) of any object kind (for a mesh or bunny, the relief thickness).
    /// Call [`Scene::validate`](super::Scene::validate) afterwards.
    pub fn set_thickness(&mut self, d: f64) {
        match self {
            ObjectSpec::Cuboid(c) => c.thickness = d,
            ObjectSpec::Hemisphere(h) => h.thickness = d,
            ObjectSpec::Mesh(m) => m.thickness = Some(d),
            ObjectSpec::Bunny(b) => b.thickness = Some(d),
        }
    }

    /// Checks every number (paths `object.*`).
    ///
    /// # Errors
    /// [`SceneError::Invalid`] for the first value out of range.
    pub fn validate(&self) -> Check {
        match self {
            ObjectSpec::Cuboid(c) => {
                length("object.width", c.width)?;
                length("object.height", c.height)?;
                thickness("object.thickness", c.thickness)
            }
            ObjectSpec::Hemisphere(h) => {
                length("object.radius", h.radius)?;
                thickness("object.thickness", h.thickness)
            }
            ObjectSpec::Mesh(m) => {
                check_mesh_file(&m.file)?;
                check_placed_mesh(m.size, m.rotation_deg, m.thickness, m.construction)
            }
            ObjectSpec::Bunny(b) => check_placed_mesh(b.size, b.rotation_deg, b.thickness, b.construction),
        }
    }
}

fn length(path: &str, value: f64) -> Check {
    num(path, value, "m")?.gt(0.0)?.le(MAX_OBJECT_SIZE)?;
    Ok(())
}

fn thickness(path: &str, value: f64) -> Check {
    num(path, value, "m")?.gt(0.0)?.le(MAX_THICKNESS)?;
    Ok(())
}

fn check_mesh_file(file: &std::path::Path) -> Check {
    let ext_ok = file
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| MESH_EXTENSIONS.iter().any(|m| e.eq_ignore_ascii_case(m)));
    if ext_ok {
        Ok(())
    } else {
        Err(SceneError::invalid(
            "object.file",
            format!("must be a .obj, .ply, .gltf or .glb file, got {:?}", file.display().to_string()),
        ))
    }
}

fn check_placed_mesh(
    size: f64,
    rotation_deg: [f64; 3],
    relief_thickness: Option<f64>,
    construction: Construction,
) -> Check {
    length("object.size", size)?;
    for (i, &angle) in rotation_deg.iter().enumerate() {
        num(&format!("object.rotation_deg[{i}]"), angle, "deg")?;
    }
    match (relief_thickness, construction) {
        (Some(d), _) => thickness("object.thickness", d),
        (None, Construction::Relief) => Err(SceneError::invalid(
            "object.thickness",
            "required when object.construction is \"relief\" (the default)",
        )),
        (None, Construction::Shell) => {
            Err(SceneError::invalid("object.thickness", "required when object.construction is \"shell\""))
        }
        (None, Construction::Solid) => Ok(()),
    }
}
