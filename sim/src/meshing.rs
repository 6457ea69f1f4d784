//! Scene object -> closed solid -> graded tetrahedral mesh.

use crate::assets::{self, AssetError};
use crate::mesh::error::MeshError;
use crate::mesh::layered::{self, LayeredError, Layering};
use crate::mesh::tetmesh::FaceTag;
use crate::mesh::tetmesh::{MeshStats, TetMesh};
use crate::mesh::trimesh::read_surface;
use crate::mesh::trimesh::TriMesh;
use crate::scene::{Construction, ObjectSpec};
use crate::scene::{MeshingOptions, Scene};
use crate::solid::plc::regular_tet_volume;
use crate::solid::{self, Grading, Solid, SolidError};
use crate::tetgen::{self, MeshingError, TetgenOptions};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::{Duration, Instant};

/// Everything that can stop meshing a scene.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum BuildError {
    #[error(transparent)]
    Asset(#[from] AssetError),
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error(transparent)]
    Solid(#[from] SolidError),
    #[error(transparent)]
    Meshing(#[from] MeshingError),
    #[error(transparent)]
    Layered(#[from] LayeredError),
    /// Anything that went wrong with the object of a mesh file, after reading it: the solid
    /// construction or TetGen on what was built from it.
    #[error("mesh file {}: {source}", .file.display())]
    MeshFile {
        file: std::path::PathBuf,
        #[source]
        source: Box<BuildError>,
    },
}

impl BuildError {
    /// `self` with the mesh file it came from, unless it already names it (read errors do).
    fn in_mesh_file(self, file: &Path) -> BuildError {
        match self {
            BuildError::Mesh(MeshError::Io { .. } | MeshError::Parse { .. } | MeshError::InFile { .. }) => self,
            e => BuildError::MeshFile { file: file.to_path_buf(), source: Box::new(e) },
        }
    }
}

/// A meshed object and how it was made.
pub struct MeshedObject {
    /// The closed solid handed to TetGen; `None` for a wall meshed in prism layers.
    pub solid: Option<Solid>,
    pub mesh: TetMesh,
    pub report: MeshReport,
}

/// Statistics and timings of one meshing run (SI units); `meta.json`'s `mesh` (see
/// `crate::dataset_format`). No `deny_unknown_fields`: serde does not support it together
/// with `flatten`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
pub struct MeshReport {
    /// The object meshed, in words with its dimensions (m).
    pub object: String,
    /// Each change made to the object's input before meshing (dropped silhouette slivers,
    /// filled holes, ...), in words; empty when the input was used as given.
    #[serde(default)]
    pub repairs: Vec<String>,
    /// Counts, element quality and volumes (the fields appear at this level, flattened).
    #[serde(flatten)]
    pub stats: MeshStats,
    /// Volume of the ideal shape (m^3), where one exists.
    pub analytic_volume_m3: Option<f64>,
    /// Exact volume of the polyhedral solid handed to TetGen (m^3).
    pub solid_volume_m3: f64,
    /// (mesh volume - analytic volume) / analytic volume.
    pub volume_rel_error_vs_analytic: Option<f64>,
    /// (mesh volume - solid volume) / solid volume: ~1e-15 for a conforming mesh.
    pub volume_rel_error_vs_solid: f64,
    /// Target edge length on the visible surface, in m.
    pub surface_element_size_m: f64,
    /// Depth of the finely meshed layer under the visible surface, in m.
    pub fine_layer_depth_m: f64,
    /// Target edge length deep inside, in m.
    pub deep_element_size_m: f64,
    /// Radius-edge ratio bound handed to TetGen, dimensionless.
    pub radius_edge_ratio_bound: f64,
    /// Time to build the closed solid, in s.
    pub build_seconds: f64,
    /// Time TetGen took, in s (0 for a wall meshed in prism layers).
    pub tetgen_seconds: f64,
    /// Prism layers through the wall, for a wall meshed in layers (`crate::mesh::layered`);
    /// absent for TetGen's meshes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_layers: Option<usize>,
    /// Thickness of the first (outermost) wall layer, in m, for a wall meshed in layers.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub first_wall_layer_m: Option<f64>,
}

/// The grading the scene asks for, with the automatic deep size filled in.
pub fn grading(opts: &MeshingOptions, thickness: f64, lateral_extent: f64) -> Grading {
    Grading {
        surface_element_size: opts.surface_element_size,
        fine_layer_depth: opts.fine_layer_depth,
        deep_element_size: opts
            .deep_element_size
            .unwrap_or_else(|| Grading::auto_deep_size(opts.surface_element_size, thickness, lateral_extent)),
    }
}

/// Builds the closed solid of the scene's object. `bunny` overrides where the bunny is read
/// from (see [`assets::bunny_path`]).
pub fn build_solid(scene: &Scene, bunny: Option<&Path>) -> Result<(Solid, Grading), BuildError> {
    let m = &scene.meshing;
    match &scene.object {
        ObjectSpec::Cuboid(c) => {
            let g = grading(m, c.thickness, c.width.min(c.height));
            Ok((solid::cuboid(c.width, c.height, c.thickness, &g)?, g))
        }
        ObjectSpec::Hemisphere(h) => {
            let g = grading(m, h.thickness.min(h.radius), h.radius);
            Ok((solid::hemisphere(h.radius, h.thickness, &g)?, g))
        }
        ObjectSpec::Mesh(spec) => {
            let surface = read_surface(&spec.file)?;
            placed(m, &surface, spec.rotation_deg, spec.size, spec.thickness, spec.construction)
        }
        ObjectSpec::Bunny(spec) => {
            let path = assets::bunny_path(bunny)?;
            let surface = read_surface(&path)?;
            placed(m, &surface, spec.rotation_deg, spec.size, spec.thickness, spec.construction)
        }
    }
}

fn placed(
    m: &MeshingOptions,
    surface: &crate::mesh::trimesh::TriMesh,
    rotation_deg: [f64; 3],
    size: f64,
    thickness: Option<f64>,
    construction: Construction,
) -> Result<(Solid, Grading), BuildError> {
    let surface = solid::place_mesh(surface, rotation_deg, size)?;
    match (construction, thickness) {
        (Construction::Relief, Some(d)) => {
            let g = grading(m, d, size);
            let resolution = m.relief_resolution_or_default();
            Ok((solid::relief(&surface, d, resolution, m.relief_max_slope_deg, &g)?, g))
        }
        (Construction::Relief, None) => Err(SolidError::Invalid {
            field: "object.thickness".into(),
            message: "required when object.construction is \"relief\"".into(),
        }
        .into()),
        (Construction::Solid, _) => {
            let g = grading(m, size, size);
            Ok((solid::closed_mesh(&surface)?, g))
        }
        (Construction::Shell, _) => Err(SolidError::Construction(
            "a shell is meshed in prism layers, not as a solid for TetGen (see heatsim::meshing::mesh_scene)".into(),
        )
        .into()),
    }
}

/// A wall to mesh in prism layers: the outer surface, its normals, how it is layered.
struct Wall {
    surface: TriMesh,
    normals: Vec<[f64; 3]>,
    layering: Layering,
    description: String,
    analytic_volume: Option<f64>,
}

/// The wall of the scene's object when it is meshed in prism layers: a mesh or bunny with
/// `construction = "shell"`, or a hemisphere shell (thickness below the radius) with
/// `meshing.wall_layers` set. `None` for the objects TetGen meshes.
fn wall_of(scene: &Scene, bunny: Option<&Path>) -> Result<Option<Wall>, BuildError> {
    let m = &scene.meshing;
    let layering = |thickness: f64, inner_tag: FaceTag, rim_tag: FaceTag| Layering {
        thickness,
        layers: m.wall_layers_or_default(),
        ratio: m.wall_layer_ratio_or_default(),
        inner_tag,
        rim_tag,
    };
    let (spec_surface, rotation_deg, size, thickness) = match &scene.object {
        ObjectSpec::Hemisphere(h) if h.thickness < h.radius && m.wall_layers.is_some() => {
            let dome = solid::hemisphere::unit_dome(m.surface_element_size / h.radius);
            let surface =
                TriMesh { verts: dome.points.iter().map(|&p| p.map(|x| x * h.radius)).collect(), tris: dome.tris };
            let inner = h.radius - h.thickness;
            return Ok(Some(Wall {
                surface,
                normals: dome.points,
                // The inside of the dome and its base ring face away from the camera.
                layering: layering(h.thickness, FaceTag::Back, FaceTag::Back),
                description: format!("hemispherical shell, thickness {} m, radius {} m", h.thickness, h.radius),
                analytic_volume: Some(2.0 / 3.0 * std::f64::consts::PI * (h.radius.powi(3) - inner.powi(3))),
            }));
        }
        ObjectSpec::Mesh(spec) if spec.construction == Construction::Shell => {
            (read_surface(&spec.file)?, spec.rotation_deg, spec.size, spec.thickness)
        }
        ObjectSpec::Bunny(spec) if spec.construction == Construction::Shell => {
            (read_surface(&assets::bunny_path(bunny)?)?, spec.rotation_deg, spec.size, spec.thickness)
        }
        _ => return Ok(None),
    };
    let thickness = thickness.ok_or_else(|| SolidError::Invalid {
        field: "object.thickness".into(),
        message: "required when object.construction is \"shell\"".into(),
    })?;
    let placed = solid::place_mesh(&spec_surface, rotation_deg, size)?;
    placed.validate_solid()?;
    // Each face makes 14 tetrahedra a layer: refuse before subdividing past the limit.
    let tets_per_face = 14 * m.wall_layers_or_default() as u64;
    let (surface, levels) = subdivided_to(placed, m.surface_element_size, tets_per_face, m.max_tetrahedra)?;
    let normals = layered::vertex_normals(&surface);
    Ok(Some(Wall {
        description: format!(
            "hollow shell of a closed mesh ({} faces after {levels} midpoint subdivision(s)), wall {thickness} m",
            surface.tris.len()
        ),
        surface,
        normals,
        layering: layering(thickness, FaceTag::Cavity, FaceTag::Side),
        analytic_volume: None,
    }))
}

/// `surface` split at its edge midpoints until its median edge is at most `h` (m), and how
/// many times it was split.
///
/// # Errors
/// [`MeshingError::TooLarge`] when a split would make more than `limit` tetrahedra at
/// `tets_per_face` each.
fn subdivided_to(
    mut surface: TriMesh,
    h: f64,
    tets_per_face: u64,
    limit: u64,
) -> Result<(TriMesh, usize), MeshingError> {
    let mut levels = 0;
    loop {
        let mut edges = surface.edge_lengths();
        let mid = edges.len() / 2;
        let median = *edges.select_nth_unstable_by(mid, f64::total_cmp).1;
        if median <= h {
            return Ok((surface, levels));
        }
        let count = 4 * surface.tris.len() as u64 * tets_per_face;
        if count > limit {
            return Err(MeshingError::TooLarge { count: count as usize, limit });
        }
        surface = surface.midpoint_subdivided();
        levels += 1;
    }
}

/// Meshes a wall in prism layers (no TetGen) and reports it like a TetGen mesh.
fn mesh_wall(scene: &Scene, wall: Wall, build_seconds: f64) -> Result<MeshedObject, BuildError> {
    let m = &scene.meshing;
    let Wall { surface, normals, layering, description, analytic_volume } = wall;
    let count = 14 * layering.layers as u64 * surface.tris.len() as u64;
    if count > m.max_tetrahedra {
        return Err(MeshingError::TooLarge { count: count as usize, limit: m.max_tetrahedra }.into());
    }
    let t1 = Instant::now();
    let mesh = layered::layered_wall(&surface, &normals, &layering)?;
    let layering_seconds = t1.elapsed().as_secs_f64();
    let stats = mesh.stats();
    let depths = layered::interface_depths(layering.thickness, layering.layers, layering.ratio);
    let report = MeshReport {
        object: description,
        repairs: Vec::new(),
        analytic_volume_m3: analytic_volume,
        solid_volume_m3: stats.volume_m3,
        volume_rel_error_vs_analytic: analytic_volume.map(|a| (stats.volume_m3 - a) / a),
        volume_rel_error_vs_solid: (stats.boundary_volume_m3 - stats.volume_m3) / stats.volume_m3,
        surface_element_size_m: m.surface_element_size,
        fine_layer_depth_m: layering.thickness,
        deep_element_size_m: m.surface_element_size,
        radius_edge_ratio_bound: m.radius_edge_ratio,
        build_seconds: build_seconds + layering_seconds,
        tetgen_seconds: 0.0,
        wall_layers: Some(layering.layers),
        first_wall_layer_m: Some(depths[1]),
        stats,
    };
    Ok(MeshedObject { solid: None, mesh, report })
}

/// Rough count of tetrahedra TetGen will make (for refusing absurd requests up front):
/// the solid's volume over the volume of a regular tetrahedron of the deep size, plus the
/// fine layer (visible area x depth) over that of the surface size, times 1.5 for quality
/// refinement.
fn estimate_tets(solid: &Solid, g: &Grading) -> f64 {
    let visible = solid.surface(crate::mesh::tetmesh::FaceTag::Visible).area();
    let fine = visible * g.fine_layer_depth.min(solid.volume / visible.max(1e-300));
    1.5 * (fine / regular_tet_volume(g.surface_element_size)
        + (solid.volume - fine).max(0.0) / regular_tet_volume(g.deep_element_size))
}

/// Meshes the scene's object with TetGen under the scene's meshing options.
///
/// # Errors
/// [`BuildError`] naming the input problem, or TetGen's failure; for a mesh object, wrapped
/// in [`BuildError::MeshFile`] naming the file.
pub fn mesh_scene(scene: &Scene, bunny: Option<&Path>) -> Result<MeshedObject, BuildError> {
    match &scene.object {
        ObjectSpec::Mesh(spec) => mesh_object(scene, bunny).map_err(|e| e.in_mesh_file(&spec.file)),
        _ => mesh_object(scene, bunny),
    }
}

fn mesh_object(scene: &Scene, bunny: Option<&Path>) -> Result<MeshedObject, BuildError> {
    let m = &scene.meshing;
    let t0 = Instant::now();
    if let Some(wall) = wall_of(scene, bunny)? {
        return mesh_wall(scene, wall, t0.elapsed().as_secs_f64());
    }
    let (solid, g) = build_solid(scene, bunny)?;
    let build_seconds = t0.elapsed().as_secs_f64();
    let estimate = estimate_tets(&solid, &g);
    if estimate > 4.0 * m.max_tetrahedra as f64 {
        return Err(MeshingError::TooLarge { count: estimate as usize, limit: m.max_tetrahedra }.into());
    }
    let opts = TetgenOptions {
        radius_edge_ratio: m.radius_edge_ratio,
        // A closed mesh has no regions: bound it globally by the deep size.
        max_volume: solid.plc.regions.is_empty().then(|| regular_tet_volume(g.deep_element_size)),
        timeout: Duration::from_secs_f64(m.timeout_seconds),
    };
    let t1 = Instant::now();
    let out = tetgen::tetrahedralize(&solid.plc, &opts)?;
    let tetgen_seconds = t1.elapsed().as_secs_f64();
    if out.tets.len() as u64 > m.max_tetrahedra {
        return Err(MeshingError::TooLarge { count: out.tets.len(), limit: m.max_tetrahedra }.into());
    }
    let mesh = TetMesh::from_tetgen(out)?;
    let stats = mesh.stats();
    let report = MeshReport {
        object: solid.description.clone(),
        repairs: solid.repairs.clone(),
        analytic_volume_m3: solid.analytic_volume,
        solid_volume_m3: solid.volume,
        volume_rel_error_vs_analytic: solid.analytic_volume.map(|a| (stats.volume_m3 - a) / a),
        volume_rel_error_vs_solid: (stats.volume_m3 - solid.volume) / solid.volume,
        surface_element_size_m: g.surface_element_size,
        fine_layer_depth_m: g.fine_layer_depth,
        deep_element_size_m: g.deep_element_size,
        radius_edge_ratio_bound: m.radius_edge_ratio,
        build_seconds,
        tetgen_seconds,
        wall_layers: None,
        first_wall_layer_m: None,
        stats,
    };
    Ok(MeshedObject { solid: Some(solid), mesh, report })
}
