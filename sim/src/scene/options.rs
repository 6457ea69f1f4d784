//! The smaller sections of a scene file: [`Environment`], [`Timing`], [`SolverOptions`] and
//! [`MeshingOptions`]. Every section is optional and every field has a default.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

use super::validate::{fmt_num, int_in, num, Check};
use super::SceneError;

/// Relative tolerance for `frame_interval` being a whole number of time steps.
pub const FRAME_MULTIPLE_TOLERANCE: f64 = 1e-9;

// ---------------------------------------------------------------------------------------------
// Environment

/// Which boundary faces exchange heat with the room.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum BackBoundary {
    /// Convection and radiation on every boundary face (default).
    #[default]
    Exposed,
    /// Only the visible and side faces lose heat; the back (faces away from the camera, e.g.
    /// the bottom of a cuboid or the inside of a dome) is adiabatic.
    Insulated,
}

/// The room around the object (paper Sec. 3: still air at a known, constant temperature).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Environment {
    /// Air and surroundings temperature, also the initial temperature of the object, in K
    /// (default 295.15; > 0, < 2000).
    pub ambient_temperature: f64,
    /// Free-convection coefficient h, in W/(m² K) (default 5: small objects in still room air,
    /// reference section 2; >= 0, <= 1000).
    pub convection_coefficient: f64,
    /// `"exposed"` (default) or `"insulated"`.
    pub back_boundary: BackBoundary,
}

impl Default for Environment {
    fn default() -> Self {
        Environment { ambient_temperature: 295.15, convection_coefficient: 5.0, back_boundary: BackBoundary::Exposed }
    }
}

impl Environment {
    /// Checks every number (JSON paths `environment.*`).
    ///
    /// # Errors
    /// [`SceneError::Invalid`] for the first value out of range.
    pub fn validate(&self) -> Check {
        num("environment.ambient_temperature", self.ambient_temperature, "K")?.gt(0.0)?.lt(2000.0)?;
        num("environment.convection_coefficient", self.convection_coefficient, "W/(m^2 K)")?.ge(0.0)?.le(1000.0)?;
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// Timing

/// Time stepping and frame recording.
///
/// Heating starts at t = 0 (lamp times are relative to it); before it, `pre_heating_frames`
/// frames of the object at ambient temperature are recorded (the paper uses its first ten
/// frames to remove reflections and fixed-pattern noise, Sec. 7). Frames are then recorded
/// every `frame_interval` until `duration`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct Timing {
    /// Length of the heating sequence, in s (default 15; > 0, >= frame_interval).
    pub duration: f64,
    /// Solver time step, in s (default 1/60: the camera's native rate; > 0,
    /// <= frame_interval).
    pub time_step: f64,
    /// Time between recorded frames, in s (default 1/6: the paper's 6 FPS); a whole number
    /// of time steps within 1e-9 relative.
    pub frame_interval: f64,
    /// Frames recorded before the lamps turn on (default 10).
    pub pre_heating_frames: u32,
}

impl Default for Timing {
    fn default() -> Self {
        Timing { duration: 15.0, time_step: 1.0 / 60.0, frame_interval: 1.0 / 6.0, pre_heating_frames: 10 }
    }
}

impl Timing {
    /// Time steps per recorded frame: frame_interval / time_step rounded to the nearest
    /// integer (exact after [`validate`](Self::validate)).
    pub fn steps_per_frame(&self) -> u64 {
        // `as` saturates; validation guarantees a finite ratio >= 1.
        (self.frame_interval / self.time_step).round() as u64
    }

    /// Checks every number and their order `time_step <= frame_interval <= duration`
    /// (JSON paths `timing.*`).
    ///
    /// # Errors
    /// [`SceneError::Invalid`] for the first value out of range or out of order, or when
    /// `frame_interval` is not a whole number of time steps.
    pub fn validate(&self) -> Check {
        num("timing.duration", self.duration, "s")?.gt(0.0)?;
        num("timing.time_step", self.time_step, "s")?.gt(0.0)?;
        num("timing.frame_interval", self.frame_interval, "s")?
            .gt(0.0)?
            .ge_other("timing.time_step", self.time_step)?
            .le_other("timing.duration", self.duration)?;
        let ratio = self.frame_interval / self.time_step;
        let whole = ratio.round();
        if (self.frame_interval - whole * self.time_step).abs() > FRAME_MULTIPLE_TOLERANCE * self.frame_interval {
            return Err(SceneError::invalid(
                "timing.frame_interval",
                format!(
                    "must be a whole multiple of timing.time_step ({} s) within 1e-9 relative, \
                     got {} ({} steps)",
                    fmt_num(self.time_step),
                    fmt_num(self.frame_interval),
                    fmt_num(ratio)
                ),
            ));
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// Solver

/// Which heat model is solved.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SolverKind {
    /// Heat equation in the tetrahedral volume (default).
    #[default]
    Volumetric,
    /// The paper's surface model: heat equation on the visible surface with an effective
    /// thickness (Sec. 4).
    Surface,
}

/// Mass matrix of the finite-element discretisation.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum MassMatrix {
    /// Consistent P1 mass matrix (default).
    #[default]
    Consistent,
    /// Row-sum lumped (diagonal) mass matrix.
    Lumped,
}

/// Treatment of the radiative boundary flux εσ(T⁴ - T_amb⁴).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum RadiationModel {
    /// The full T⁴ law, solved by Newton iteration (default).
    #[default]
    Full,
    /// Linearised about the ambient temperature: h_rad = 4εσT_amb³ (reference section 3).
    Linearized,
}

/// Time discretisation of both solvers (`heatsim::fem::volumetric` module doc).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum TimeIntegration {
    /// Backward Euler, first order in the time step (default).
    #[default]
    BackwardEuler,
    /// BDF2, second order: the same cost per step, closer to continuous time at a given step.
    Bdf2,
}

impl TimeIntegration {
    fn is_default(&self) -> bool {
        *self == TimeIntegration::default()
    }
}

/// How both solvers solve each step's linear systems (`heatsim::fem::volumetric::LinearSolver`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum LinearSolverKind {
    /// Sparse Cholesky factor, chord-Newton iteration (default).
    #[default]
    Direct,
    /// Jacobi-preconditioned conjugate gradients, Newton iteration.
    ConjugateGradients,
}

impl LinearSolverKind {
    fn is_default(&self) -> bool {
        *self == LinearSolverKind::default()
    }
}

/// The mesh the surface solver runs on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SurfaceMesh {
    /// The visible surface of the tetrahedral mesh (default): the same vertices as the
    /// volumetric solver's, so the two compare vertex by vertex.
    #[default]
    Visible,
    /// One vertex per pixel the object covers, at the pixel centre's point on the true
    /// surface, triangulated on the pixel grid (`camera::grid::PixelGrid`): the mesh the
    /// reconstruction builds, so the true operator is known on it exactly.
    CameraGrid,
}

/// How the surface solver on the camera grid applies the lamps' flux, which it knows at each
/// vertex (the flux of the face the vertex's pixel sees, `gt_flux`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum SurfaceFlux {
    /// Each triangle absorbs the mean of its corners' fluxes, a vertex a third of each of its
    /// triangles' (default: the solver's behaviour before the option existed).
    #[default]
    TriangleMean,
    /// Each vertex absorbs its own flux over its lumped area (load M_a q), as paper Eq. 6
    /// writes it: the applied flux per area is then exactly `gt_flux`.
    Vertex,
}

impl SurfaceFlux {
    fn is_default(&self) -> bool {
        *self == SurfaceFlux::default()
    }
}

/// How the surface model shares area among vertices (its lumped mass, paper M_a).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum AreaMassKind {
    /// A third of each triangle to each corner (default).
    #[default]
    Barycentric,
    /// Mixed Voronoi areas (Meyer et al. 2003).
    MixedVoronoi,
}

/// Heat-solver options.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct SolverOptions {
    /// `"volumetric"` (default) or `"surface"`.
    pub kind: SolverKind,
    /// `"consistent"` (default) or `"lumped"`; the volumetric solver's capacity (the surface
    /// model's is always lumped, Eq. 6).
    pub mass: MassMatrix,
    /// `"full"` (default) or `"linearized"`.
    pub radiation: RadiationModel,
    /// Newton stops when the max-norm of the temperature update falls below this, in K
    /// (default 1e-9; > 0).
    pub newton_tolerance: f64,
    /// Newton iterations allowed per time step before giving up (default 25; 1 to 1000).
    pub max_newton_iterations: u32,
    /// Dimensionless c of the surface model's effective thickness min(d, c·sqrt(α t)), with
    /// d the object's thickness and α the diffusivity; absent: off (default; > 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effective_thickness_factor: Option<f64>,
    /// Surface solver: `"visible"` (default) or `"camera_grid"`.
    pub surface_mesh: SurfaceMesh,
    /// Surface solver: `"barycentric"` (default) or `"mixed_voronoi"` lumped area.
    pub surface_area_mass: AreaMassKind,
    /// Surface solver on the camera grid: `"triangle_mean"` (default) or `"vertex"` (Eq. 6)
    /// application of the lamps' flux. Left out of the serialised scene when default.
    #[serde(default, skip_serializing_if = "SurfaceFlux::is_default")]
    pub surface_flux: SurfaceFlux,
    /// `"backward_euler"` (default, first order in `timing.time_step`) or `"bdf2"` (second
    /// order). Left out of the serialised scene when default, so that the configuration
    /// hashes of earlier runs still match.
    #[serde(default, skip_serializing_if = "TimeIntegration::is_default")]
    pub time_integration: TimeIntegration,
    /// `"direct"` (default: a sparse Cholesky factor) or `"conjugate_gradients"` (faster on
    /// meshes of more than about 1e4 nodes; the same temperatures within the tolerance). Left
    /// out of the serialised scene when default.
    #[serde(default, skip_serializing_if = "LinearSolverKind::is_default")]
    pub linear_solver: LinearSolverKind,
}

impl Default for SolverOptions {
    fn default() -> Self {
        SolverOptions {
            kind: SolverKind::Volumetric,
            mass: MassMatrix::Consistent,
            radiation: RadiationModel::Full,
            newton_tolerance: 1e-9,
            max_newton_iterations: 25,
            effective_thickness_factor: None,
            surface_mesh: SurfaceMesh::Visible,
            surface_area_mass: AreaMassKind::Barycentric,
            surface_flux: SurfaceFlux::TriangleMean,
            time_integration: TimeIntegration::BackwardEuler,
            linear_solver: LinearSolverKind::Direct,
        }
    }
}

impl SolverOptions {
    /// Checks every number (JSON paths `solver.*`).
    ///
    /// # Errors
    /// [`SceneError::Invalid`] for the first value out of range.
    pub fn validate(&self) -> Check {
        num("solver.newton_tolerance", self.newton_tolerance, "K")?.gt(0.0)?;
        int_in("solver.max_newton_iterations", self.max_newton_iterations.into(), 1, 1000, "")?;
        if let Some(c) = self.effective_thickness_factor {
            num("solver.effective_thickness_factor", c, "")?.gt(0.0)?;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------------------------
// Meshing

/// Prism layers through a shell's wall when `meshing.wall_layers` is absent.
pub const DEFAULT_WALL_LAYERS: u32 = 8;
/// Most prism layers accepted through a wall.
pub const MAX_WALL_LAYERS: u32 = 64;
/// Thickness of the innermost wall layer over the outermost when `meshing.wall_layer_ratio` is
/// absent (dimensionless).
pub const DEFAULT_WALL_LAYER_RATIO: f64 = 4.0;
/// Largest accepted innermost-to-outermost wall layer ratio (dimensionless).
pub const MAX_WALL_LAYER_RATIO: f64 = 100.0;

/// Tetrahedral meshing controls.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct MeshingOptions {
    /// Target edge length on the visible surface, in m (default 2e-3; > 0, <= 100).
    pub surface_element_size: f64,
    /// Depth below the visible surface meshed at `surface_element_size`, in m (default 4e-3;
    /// > 0, <= 10).
    pub fine_layer_depth: f64,
    /// Target edge length deeper down, in m (>= surface_element_size); absent: chosen
    /// automatically (default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deep_element_size: Option<f64>,
    /// TetGen's radius-edge quality bound (`-q`), dimensionless (default 1.5; in [1.1, 10]).
    pub radius_edge_ratio: f64,
    /// Raster spacing for the relief of a mesh object, in m (> 0); absent:
    /// surface_element_size / 2 (default).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub relief_resolution: Option<f64>,
    /// Steepest relief slope kept, in degrees from horizontal (default 85; in (0, 89]).
    /// Parts of a mesh object's visible relief steeper than this (seen at grazing angles,
    /// and the cliffs where one part occludes another) are cut away and become side walls:
    /// a layer lowered along the viewing axis would otherwise be squeezed to nothing there.
    pub relief_max_slope_deg: f64,
    /// Prism layers through the wall of a shell ([`crate::mesh::layered`]): of a mesh object
    /// with `construction = "shell"` (default 8 when absent), and of a hemisphere shell
    /// (thickness below the radius), which is meshed in layers when this is set and by TetGen
    /// when it is absent (default); in [1, 64].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_layers: Option<u32>,
    /// Thickness of the innermost wall layer over the outermost (dimensionless; default 4; in
    /// [1, 100]; 1: equal layers); the layers grow geometrically in between, so they are
    /// thinnest under the surface, where heat entering the face makes the steepest gradients
    /// early in a video, and still all shrink as `wall_layers` grows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wall_layer_ratio: Option<f64>,
    /// Meshes with more tetrahedra than this are refused (default 2000000; >= 1).
    pub max_tetrahedra: u64,
    /// Wall-clock limit for meshing, in s (default 600; > 0).
    pub timeout_seconds: f64,
}

impl Default for MeshingOptions {
    fn default() -> Self {
        MeshingOptions {
            surface_element_size: 2e-3,
            fine_layer_depth: 4e-3,
            deep_element_size: None,
            radius_edge_ratio: 1.5,
            relief_resolution: None,
            relief_max_slope_deg: 85.0,
            wall_layers: None,
            wall_layer_ratio: None,
            max_tetrahedra: 2_000_000,
            timeout_seconds: 600.0,
        }
    }
}

impl MeshingOptions {
    /// The relief raster spacing in m: `relief_resolution`, or surface_element_size / 2.
    pub fn relief_resolution_or_default(&self) -> f64 {
        self.relief_resolution.unwrap_or(self.surface_element_size / 2.0)
    }

    /// The innermost-to-outermost wall layer ratio: `wall_layer_ratio`, or
    /// [`DEFAULT_WALL_LAYER_RATIO`].
    pub fn wall_layer_ratio_or_default(&self) -> f64 {
        self.wall_layer_ratio.unwrap_or(DEFAULT_WALL_LAYER_RATIO)
    }

    /// The prism layers through a shell's wall: `wall_layers`, or [`DEFAULT_WALL_LAYERS`].
    pub fn wall_layers_or_default(&self) -> usize {
        self.wall_layers.unwrap_or(DEFAULT_WALL_LAYERS) as usize
    }

    /// Checks every number (JSON paths `meshing.*`).
    ///
    /// # Errors
    /// [`SceneError::Invalid`] for the first value out of range.
    pub fn validate(&self) -> Check {
        num("meshing.surface_element_size", self.surface_element_size, "m")?.gt(0.0)?.le(100.0)?;
        num("meshing.fine_layer_depth", self.fine_layer_depth, "m")?.gt(0.0)?.le(10.0)?;
        if let Some(h) = self.deep_element_size {
            num("meshing.deep_element_size", h, "m")?
                .gt(0.0)?
                .le(100.0)?
                .ge_other("meshing.surface_element_size", self.surface_element_size)?;
        }
        num("meshing.radius_edge_ratio", self.radius_edge_ratio, "")?.within(1.1, true, 10.0, true)?;
        if let Some(h) = self.relief_resolution {
            num("meshing.relief_resolution", h, "m")?.gt(0.0)?.le(100.0)?;
        }
        num("meshing.relief_max_slope_deg", self.relief_max_slope_deg, "deg")?.gt(0.0)?.le(89.0)?;
        if let Some(n) = self.wall_layers {
            int_in("meshing.wall_layers", n.into(), 1, MAX_WALL_LAYERS.into(), "")?;
        }
        if let Some(r) = self.wall_layer_ratio {
            num("meshing.wall_layer_ratio", r, "")?.ge(1.0)?.le(MAX_WALL_LAYER_RATIO)?;
        }
        int_in("meshing.max_tetrahedra", self.max_tetrahedra, 1, u64::MAX, "")?;
        num("meshing.timeout_seconds", self.timeout_seconds, "s")?.gt(0.0)?;
        Ok(())
    }
}
