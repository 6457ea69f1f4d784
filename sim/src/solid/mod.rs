//! Closed solids of any thickness, described as PLCs for TetGen.
//!
//! Coordinates: the camera looks from +z; every object shows its visible surface towards +z.
//! "Thickness" (paper Sec. 4) is the material directly below the visible surface:
//!
//! | object | construction | thickness d |
//! |---|---|---|
//! | cuboid W x H | visible face z = 0, material z in [-d, 0] | along -z |
//! | hemisphere R | dome shell, outer radius R, inner R - d; solid once d >= R | along the inward normal |
//! | mesh (relief) | visible relief from +z over its silhouette, extruded by d along -z | along -z (the viewing axis) |
//! | mesh (solid) | the closed mesh itself | not used |
//!
//! Every solid is meshed in layers: a fine layer of depth `fine_layer_depth` with
//! tetrahedra of edge about `surface_element_size` right under the visible surface, and a
//! deep layer with edge about `deep_element_size`; TetGen grades between them under its
//! radius-edge bound. Layer interfaces are internal facets tagged [`FaceTag::Interface`].

pub mod extrusion;
pub mod hemisphere;
pub mod plc;
pub mod relief;

pub use plc::{Facet, Plc, Region};

use crate::mesh::error::MeshError;
use crate::mesh::tetmesh::FaceTag;
use crate::mesh::trimesh::TriMesh;

/// Mesh-size controls for the layered construction (m).
#[derive(Clone, Debug, PartialEq)]
pub struct Grading {
    /// Target edge length on and just below the visible surface.
    pub surface_element_size: f64,
    /// Depth of the fine layer below the visible surface.
    pub fine_layer_depth: f64,
    /// Target edge length deep inside.
    pub deep_element_size: f64,
}

impl Grading {
    /// The deep element size used when the scene does not set one: a third of the smaller of
    /// the thickness and the lateral extent, and never finer than the surface size.
    pub fn auto_deep_size(surface_element_size: f64, thickness: f64, lateral_extent: f64) -> f64 {
        (thickness.min(lateral_extent) / 3.0).max(surface_element_size)
    }
}

/// A closed solid ready for TetGen, with what is known about its volume.
#[derive(Clone, Debug)]
pub struct Solid {
    pub plc: Plc,
    /// Exact volume of the polyhedral solid (m^3).
    pub volume: f64,
    /// Volume of the ideal shape the polyhedron approximates (m^3), where one exists.
    pub analytic_volume: Option<f64>,
    /// One line saying what was built, with its sizes.
    pub description: String,
    /// Each change made to the input on the way (dropped slivers, filled holes, ...), in words.
    pub repairs: Vec<String>,
}

impl Solid {
    /// The PLC facets tagged `tag` as a triangle mesh (polygons fan-triangulated).
    pub fn surface(&self, tag: FaceTag) -> TriMesh {
        let mut tris = Vec::new();
        for f in self.plc.facets.iter().filter(|f| f.tag == tag) {
            for w in f.points[1..].windows(2) {
                tris.push([f.points[0], w[0], w[1]]);
            }
        }
        TriMesh { verts: self.plc.points.clone(), tris }
    }
}

/// Errors while building a solid.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SolidError {
    /// A size or option is out of range (the scene validator normally catches these first).
    #[error("{field}: {message}")]
    Invalid { field: String, message: String },
    /// The input surface is unusable (open, self-intersecting, ...).
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// The construction itself failed (for example a degenerate silhouette).
    #[error("could not build the solid: {0}")]
    Construction(String),
}

fn check_positive(field: &str, value: f64) -> Result<(), SolidError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SolidError::Invalid { field: field.into(), message: format!("must be > 0 m, got {value}") })
    }
}

/// A cuboid plate of `width` (x) by `height` (y) and `thickness` (z), visible face at z = 0.
pub fn cuboid(width: f64, height: f64, thickness: f64, grading: &Grading) -> Result<Solid, SolidError> {
    check_positive("object.width", width)?;
    check_positive("object.height", height)?;
    check_positive("object.thickness", thickness)?;
    let (a, b) = (width / 2.0, height / 2.0);
    let part = extrusion::Outline::simple(vec![[-a, -b], [a, -b], [a, b], [-a, b]]);
    let (plc, volume) = extrusion::extrude(&[part], &|_, _| 0.0, thickness, grading)?;
    Ok(Solid {
        plc,
        volume,
        analytic_volume: Some(width * height * thickness),
        description: format!("cuboid {width} m x {height} m, thickness {thickness} m"),
        repairs: Vec::new(),
    })
}

/// A hemisphere of `radius`: a shell of `thickness`, solid once `thickness >= radius`.
pub fn hemisphere(radius: f64, thickness: f64, grading: &Grading) -> Result<Solid, SolidError> {
    check_positive("object.radius", radius)?;
    check_positive("object.thickness", thickness)?;
    let (plc, volume) = hemisphere::hemisphere(radius, thickness, grading)?;
    let inner = (radius - thickness).max(0.0);
    let analytic = 2.0 / 3.0 * std::f64::consts::PI * (radius.powi(3) - inner.powi(3));
    let kind = if thickness >= radius {
        "solid hemisphere".to_string()
    } else {
        format!("hemispherical shell, thickness {thickness} m")
    };
    Ok(Solid {
        plc,
        volume,
        analytic_volume: Some(analytic),
        description: format!("{kind}, radius {radius} m"),
        repairs: Vec::new(),
    })
}

/// Rotates `mesh` by `rotation_deg` (about x, then y, then z), scales it uniformly so that
/// the largest extent of its bounding box is `size` (m), and moves it so that the box is
/// centred on the z-axis with its highest point (nearest the camera) at z = 0.
pub fn place_mesh(mesh: &TriMesh, rotation_deg: [f64; 3], size: f64) -> Result<TriMesh, SolidError> {
    check_positive("object.size", size)?;
    let [ax, ay, az] = rotation_deg.map(f64::to_radians);
    let rot = |p: [f64; 3]| {
        let (s, c) = ax.sin_cos();
        let p = [p[0], c * p[1] - s * p[2], s * p[1] + c * p[2]];
        let (s, c) = ay.sin_cos();
        let p = [c * p[0] + s * p[2], p[1], -s * p[0] + c * p[2]];
        let (s, c) = az.sin_cos();
        [c * p[0] - s * p[1], s * p[0] + c * p[1], p[2]]
    };
    let rotated = mesh.transformed(rot);
    let (lo, hi) = rotated.bounding_box();
    let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
    if !extent.is_finite() || extent <= 0.0 {
        return Err(SolidError::Construction("the mesh has zero extent".into()));
    }
    let s = size / extent;
    let (cx, cy) = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]));
    Ok(rotated.transformed(|p| [(p[0] - cx) * s, (p[1] - cy) * s, (p[2] - hi[2]) * s]))
}

/// The visible relief of `mesh` (already placed, seen from +z) extruded by `thickness`.
///
/// `resolution` is the raster spacing of the relief (m); the silhouette is simplified to the
/// same tolerance. Parts steeper than `max_slope_deg` are cut away (see [`relief()`]).
pub fn relief(
    mesh: &TriMesh,
    thickness: f64,
    resolution: f64,
    max_slope_deg: f64,
    grading: &Grading,
) -> Result<Solid, SolidError> {
    check_positive("object.thickness", thickness)?;
    check_positive("meshing.relief_resolution", resolution)?;
    let dm = relief::DepthMap::rasterize(&mesh.verts, &mesh.tris, resolution, max_slope_deg);
    let silhouette = dm.silhouette(resolution).map_err(SolidError::Construction)?;
    let parts = &silhouette.parts;
    let (plc, volume) = extrusion::extrude(parts, &|x, y| dm.height(x, y), thickness, grading)?;
    let corners: usize = parts.iter().map(|p| p.outer.len() + p.holes.iter().map(Vec::len).sum::<usize>()).sum();
    let holes: usize = parts.iter().map(|p| p.holes.len()).sum();
    Ok(Solid {
        plc,
        volume,
        analytic_volume: None,
        description: format!(
            "visible relief ({} part(s), {holes} hole(s), {corners} outline corners, raster {resolution} m) extruded by {thickness} m",
            parts.len()
        ),
        repairs: silhouette.repairs,
    })
}

/// The closed surface `mesh` itself as the solid (one region, no layering).
///
/// Faces whose normal points towards +z are tagged visible, the others back.
///
/// # Errors
/// [`SolidError::Mesh`] if the surface is not a closed, outward, non-self-intersecting solid.
pub fn closed_mesh(mesh: &TriMesh) -> Result<Solid, SolidError> {
    mesh.validate_solid()?;
    let mut plc = Plc { points: mesh.verts.clone(), ..Plc::default() };
    for (f, t) in mesh.tris.iter().enumerate() {
        let tag = if mesh.face_normal(f)[2] > 0.0 { FaceTag::Visible } else { FaceTag::Back };
        plc.facets.push(Facet { points: t.to_vec(), tag });
    }
    // No region point: the caller bounds the volume globally (TetGen -a).
    let volume = mesh.signed_volume();
    Ok(Solid {
        plc,
        volume,
        analytic_volume: None,
        description: format!("closed mesh with {} faces", mesh.tris.len()),
        repairs: Vec::new(),
    })
}
