//! Coarse to fine (paper Sec. 6.3): stage 1 and stage 2 at each pyramid level from the
//! coarsest to the finest, the depth of one level upsampled as the next level's start.
//!
//! **Upsampling.** Fine pixel (u, v) sits at coarse coordinates ((u - 1/2)/2, (v - 1/2)/2)
//! (`crate::pyramid`); its start depth is the bilinear interpolation of the coarse depth image
//! over the coarse pixels that are vertices (weights renormalised), and where none of the four
//! is, the depth of the nearest filled pixel (repeated 8-neighbour dilation). It is then blurred
//! once (3 x 3 box over vertices), as the authors' "slightly blurred" upsampling.
//!
//! **Start.** A plane is a stationary point of any intrinsic energy: bending it along its
//! normal changes edge lengths only to second order, so the data term's gradient vanishes
//! there, and so does the half-space hinge's (all n_x = 0). L-BFGS started on the plane
//! stays on it. The coarsest level therefore starts from the plane z = `distance` with a low
//! bulge ([`start_depths`]), towards the camera or away from it as the half-space image
//! prefers: the two-light ambiguity resolution of Sec. 6.2 applied to the start.
//!
//! **Size** (`Stage2Options::profile_scale`, with a known diffusivity). Scaling every depth by s
//! scales the mesh about the camera centre: cotangent weights are unchanged and areas scale as
//! s^2, so the size only enters the data term through alpha / s^2. Optimised with a fixed alpha,
//! the size is a slow mode (measured: docs/notes/code-comments.md). Instead each level optimises with
//! alpha profiled (the size a flat direction, the mean depth held at its start), then scales
//! the depths by s = sqrt(alpha / alpha*), which makes the profiled optimum the known alpha;
//! where s leaves [1/2, 2] the data are taken not to determine the size and it is kept. The
//! finest level of several keeps the size of the coarser ones: its profiled diffusivity is the
//! least reliable (noise and the regularised pixel-scale form weigh most there; measured on
//! the shape-error table's noise-free rows: docs/notes/code-comments.md).
//!
//! **Joint globals** (`Stage2Options::joint_globals`). Profiled at every evaluation, lambda and
//! 1/C are the minimiser of a non-convex function at 50 mK, which jumps with the depths, so the
//! energy L-BFGS sees is discontinuous and its line search gives up early (energy module doc).
//! Jointly, L-BFGS minimises the smooth [`energy_at_globals`] over the depths and the two
//! corrections from stage 1's values at once, starting from the profile at the level's start
//! (`minimise_joint`). Neither way keeps 1/C physical: at 50 mK it went to -5e-2 (profiled)
//! and -2.7e-2 m^2 K/J (joint) on the shading table's bunny at level 0, against the true
//! 2.6e-4; it acts as one more nuisance term of the fit, and bounding it made that bunny
//! worse (`minimise_joint`'s doc).

use heatsim::camera::PixelGrid;
use heatsim::vec3::{dot, norm, sub};

use super::energy::{
    energy, energy_at_globals, vertex_rms_residual, DataTerm, HeatData, RayMesh, Regularisers, Scale, Terms,
};
use super::lamp_shading::LampShading;
use super::optimize::{minimise, LargeSteps, OptimOptions, Optimizer};
use super::symmetry::MirrorSymmetry;
use crate::dataset::CameraInfo;
use crate::error::ReconError;
use crate::pyramid::Level;
use crate::stage1::{Stage1Input, TimeRule};

/// What stage 2 needs from stage 1 at one level (per vertex of the level's pixel mesh).
#[derive(Clone, Debug)]
pub struct Stage1Params {
    /// lambda = (h + R)/C, 1/s.
    pub lambda: f64,
    /// 1/C (m^2 K/J) or 0.
    pub c_inv: f64,
    /// Per video and vertex, q/C (K/s).
    pub flux_over_c: Vec<Vec<f64>>,
    /// Half-space image per vertex (Eq. 9), when there are two videos.
    pub halfspace: Option<Vec<i8>>,
    /// Per video, the temporal covariance of the noise left in the (denoised) series the shape's
    /// data term uses (K^2, frames x frames; `super::noise`); empty: no noise correction.
    pub noise_cov: Vec<Vec<f64>>,
    /// Where these came from (e.g. "stage 1" or "oracle (ground truth)").
    pub source: String,
}

/// Options of the coarse-to-fine reconstruction.
#[derive(Clone, Debug)]
pub struct Stage2Options {
    /// Number of levels above `finest` to start from (0: only the finest).
    pub extra_levels: usize,
    /// Finest pyramid level reconstructed (0 = full resolution).
    pub finest: usize,
    /// Diffusivity or profiled.
    pub scale: Scale,
    /// Nominal distance, m: the start plane, and the mean depth kept when profiled.
    pub distance: f64,
    /// Optimiser (iterations per level).
    pub optim: OptimOptions,
    /// Iterations at the coarsest level when not `optim.iterations`: its unknowns are few and
    /// cheap, and its slow modes (the distance, thin parts' offsets) are set there.
    pub coarsest_iterations: Option<usize>,
    /// Normal-consistency weight.
    pub normal_consistency: f64,
    /// Half-space weight at the coarsest level; multiplied by `halfspace_decay` per level and
    /// 0 at the finest level when there is more than one.
    pub halfspace_weight: f64,
    /// Decay of the half-space weight per level.
    pub halfspace_decay: f64,
    /// Unit lamp axis (camera frame) from video 2's lamp to video 1's.
    pub lamp_axis: [f64; 3],
    /// Time rule of the frame pairs (as stage 1).
    pub time_rule: TimeRule,
    /// First / last frame time used, s.
    pub t_start: f64,
    /// Last frame time used, s.
    pub t_end: f64,
    /// Robust per-vertex data loss (energy module doc; known diffusivity only).
    pub robust: bool,
    /// Profile out a constant flux per vertex and video (energy module doc).
    pub profile_flux: bool,
    /// Vertices within this many rings of the mask boundary carry no data term.
    pub boundary_rings: usize,
    /// Minimise over lambda and c too (energy module doc).
    pub profile_globals: bool,
    /// With `profile_globals`, the robust loss and L-BFGS: minimise over the depths and the
    /// globals jointly instead of profiling the globals at every evaluation (module doc).
    pub joint_globals: bool,
    /// With a known diffusivity: optimise the shape with the diffusivity profiled out (its
    /// size then a flat direction, the mean depth held), and scale it to the known diffusivity
    /// after each level (module doc).
    pub profile_scale: bool,
    /// Experimental: refine one level by the output-error fit
    /// (`crate::experimental::output_error`).
    #[cfg(feature = "experimental")]
    pub output_error: Option<crate::experimental::output_error::OeOptions>,
    /// Experimental: the first level's start depths from a file
    /// (`crate::experimental::ExperimentalConfig::initial_depth`).
    #[cfg(feature = "experimental")]
    pub initial_depth: Option<String>,
    /// Experimental: the two-light flux ratio term at every level
    /// (`crate::experimental::lamp_ratio`).
    #[cfg(feature = "experimental")]
    pub lamp_ratio: Option<LampTermOptions>,
    /// Experimental: the lamp-shading term at every level ([`super::lamp_shading`]).
    pub lamp_shading: Option<LampTermOptions>,
    /// Weight of the mirror-symmetry term ([`super::symmetry`], normalised by `distance`) at
    /// the coarsest level, as the authors; 0: off.
    pub symmetry_weight: f64,
}

impl Stage2Options {
    /// Whether the levels minimise over the depths and the globals jointly: asked for, with the
    /// globals fitted at all (`profile_globals`, the robust loss) and L-BFGS.
    pub fn minimises_globals_jointly(&self) -> bool {
        self.joint_globals && self.profile_globals && self.robust && self.optim.optimizer == Optimizer::Lbfgs
    }
}

/// A term of calibrated lamps: `Stage2Options::lamp_ratio` (feature `experimental`) or
/// [`Stage2Options::lamp_shading`].
#[derive(Clone, Debug)]
pub struct LampTermOptions {
    /// The point lamps of each video, camera coordinates (the ratio uses the first two).
    pub lamps: Vec<Vec<super::lamps::PointLamp>>,
    /// Weight of the term (dimensionless, as the normal consistency's).
    pub weight: f64,
    /// A vertex is assigned when its stage-1 flux (the ratio: both fluxes) exceeds this
    /// fraction of the image's maximum.
    pub threshold: f64,
}

/// One row of the convergence log (no timings: a run's log is reproducible bit for bit).
#[derive(Clone, Debug, serde::Serialize)]
pub struct LogRow {
    /// Pyramid level.
    pub level: usize,
    /// Iteration at this level.
    pub iteration: usize,
    /// Energy evaluations so far at this level.
    pub evaluations: usize,
    /// Energy terms.
    pub terms: Terms,
}

/// Result of one level.
#[derive(Clone, Debug)]
pub struct LevelResult {
    /// Pyramid level.
    pub level: usize,
    /// The level's camera.
    pub camera: CameraInfo,
    /// Its pixel mesh.
    pub grid: PixelGrid,
    /// Depth per vertex, m.
    pub depth: Vec<f64>,
    /// Unit normals per vertex (towards the camera), camera frame.
    pub normals: Vec<[f64; 3]>,
    /// Final energy terms.
    pub terms: Terms,
    /// Per vertex, the RMS heat residual at the result (K/s).
    pub residual: Vec<f64>,
    /// Stage-1 parameters used.
    pub stage1: Stage1Params,
    /// What the experiments at this level report (`crate::experimental`; `None` without).
    pub experiments: Option<serde_json::Value>,
    /// With `profile_scale`: the factor the depths were scaled by to the known diffusivity,
    /// `None` when the size was kept (the data did not determine it: outside [1/2, 2]; or the
    /// finest of several levels).
    pub size_factor: Option<f64>,
    /// With `profile_scale`: sqrt(known / profiled diffusivity) at the level's result, applied
    /// or not (`None` where not finite): what the size rule saw.
    pub profiled_size_factor: Option<f64>,
}

/// One point of [`truth_scan`].
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ScanPoint {
    /// Relief factor s: depths m + s (z_true - m), m the truth's mean depth.
    pub s: f64,
    /// The energy as the level optimises it (the diffusivity profiled or given).
    pub terms: Terms,
    /// The energy with the known diffusivity held fixed (`None` without one).
    pub fixed_diffusivity: Option<Terms>,
}

/// The terms of the energy's last evaluation and the point they belong to. The optimisers
/// report the point they evaluated last (after an accepted step), so its terms are not
/// computed twice; any other point misses and is evaluated.
#[derive(Default)]
struct LastTerms(std::cell::RefCell<Option<(Vec<f64>, Terms)>>);

impl LastTerms {
    fn store(&self, x: &[f64], terms: Terms) {
        let mut slot = self.0.borrow_mut();
        match slot.as_mut() {
            Some((y, t)) if y.len() == x.len() => {
                y.copy_from_slice(x);
                *t = terms;
            }
            _ => *slot = Some((x.to_vec(), terms)),
        }
    }

    fn get(&self, x: &[f64]) -> Option<Terms> {
        self.0.borrow().as_ref().filter(|(y, _)| y.as_slice() == x).map(|(_, t)| *t)
    }
}

/// Called after every iteration with (iteration, evaluations, depths, terms).
type IterationReport<'a> = dyn FnMut(usize, usize, &[f64], Terms) + 'a;

/// L-BFGS over the depths `z` (m) and the globals' corrections `d` = (dlambda (1/s), dc
/// (m^2 K/J)) from stage 1's values together (module doc), each of the three blocks with its
/// own L-BFGS scale: the depths in the large-steps coordinates of `steps`, dlambda relative to
/// `lambda0`, dc relative to lambda0 / R (R the radiation coefficient, W/(m^2 K); 1/C <=
/// lambda/R when h >= 0). Like the profile, c is not bounded: kept within [0, lambda0/R]
/// (by c = (lambda0/R)(1 + tanh t)/2), the 50 mK bunny of the shading table came out at 1.65
/// mm against 0.80 mm (the hemisphere 0.135 against 0.137 mm). `f(z, d, grad_z, grad_d)` is
/// the energy; `hold(z)` projects the depths after a step; `report(iteration, evaluations, z,
/// terms)` after every iteration.
#[allow(clippy::too_many_arguments)]
fn minimise_joint(
    z: &mut [f64],
    d: &mut [f64; 2],
    steps: &LargeSteps,
    optim: &OptimOptions,
    lambda0: f64,
    r_coef: f64,
    hold: &dyn Fn(&mut [f64]),
    f: impl Fn(&[f64], [f64; 2], Option<&mut [f64]>, Option<&mut [f64; 2]>) -> Terms,
    report: &mut IterationReport,
) -> Result<(), ReconError> {
    let n = z.len();
    let unit = [lambda0.abs().max(1e-12), lambda0.abs().max(1e-12) / r_coef.max(1e-12)];
    let split = |x: &[f64]| -> (Vec<f64>, [f64; 2]) {
        let mut zz = x[..n].to_vec();
        steps.solve(&mut zz);
        (zz, [x[n] * unit[0], x[n + 1] * unit[1]])
    };
    let mut x: Vec<f64> = steps.apply(z).into_iter().chain([d[0] / unit[0], d[1] / unit[1]]).collect();
    let last = LastTerms::default();
    let joint_opts =
        OptimOptions { large_steps_lambda: 0.0, min_depth: f64::NEG_INFINITY, blocks: vec![n, n + 1], ..optim.clone() };
    let ident = LargeSteps::new(n + 2, &[], 0.0)?;
    minimise(
        &mut x,
        &ident,
        &joint_opts,
        |x, g| {
            let (zz, dd) = split(x);
            if zz.iter().any(|&v| v.is_nan() || v <= optim.min_depth) {
                return f64::INFINITY;
            }
            let (mut gz, mut gd) = (vec![0.0; n], [0.0; 2]);
            let t = f(&zz, dd, Some(&mut gz), Some(&mut gd));
            last.store(x, t);
            steps.solve(&mut gz);
            g[..n].copy_from_slice(&gz);
            g[n] = gd[0] * unit[0];
            g[n + 1] = gd[1] * unit[1];
            t.total
        },
        |x| {
            let (mut zz, _) = split(x);
            hold(&mut zz);
            x[..n].copy_from_slice(&steps.apply(&zz));
        },
        |it, evals, x, _| {
            let (zz, dd) = split(x);
            let terms = last.get(x).unwrap_or_else(|| f(&zz, dd, None, None));
            report(it, evals, &zz, terms);
        },
    )?;
    let (zz, dd) = split(&x);
    z.copy_from_slice(&zz);
    *d = dd;
    Ok(())
}

/// The energy at depths `m + s (z_true - m)` for s = 0, 0.25, ..., 2 (m the mean true depth):
/// whether the data term's minimum along this line sits at the truth (s = 1) at the data's
/// noise, and how it weighs against the regularisers. Test-only diagnostic (reads the truth).
pub fn truth_scan(
    mesh: &RayMesh,
    data: &DataTerm,
    reg: &Regularisers,
    scale: Scale,
    metric: Option<f64>,
    zt: &[f64],
) -> Vec<ScanPoint> {
    scan_line(zt)
        .map(|(s, z)| ScanPoint {
            s,
            terms: energy(mesh, data, reg, scale, &z, None),
            fixed_diffusivity: metric.map(|a| energy(mesh, data, reg, Scale::Diffusivity(a), &z, None)),
        })
        .collect()
}

/// The depths of [`truth_scan`]'s line: `(s, m + s (z_true - m))` for s = 0, 0.25, ..., 2.
fn scan_line(zt: &[f64]) -> impl Iterator<Item = (f64, Vec<f64>)> + '_ {
    let m = zt.iter().sum::<f64>() / zt.len().max(1) as f64;
    (0..=8).map(move |k| {
        let s = 0.25 * k as f64;
        (s, zt.iter().map(|v| m + s * (v - m)).collect())
    })
}

/// Everything stage 2 returns.
#[derive(Clone, Debug)]
pub struct Stage2Result {
    /// Per level, coarsest first.
    pub levels: Vec<LevelResult>,
    /// Convergence log.
    pub log: Vec<LogRow>,
}

/// Ray directions of the vertices of `grid` for `camera`.
pub fn ray_dirs(camera: &CameraInfo, grid: &PixelGrid) -> Vec<[f64; 3]> {
    grid.pixels
        .iter()
        .map(|&p| crate::validate::back_project(camera, (p % grid.width) as f64, (p / grid.width) as f64, 1.0))
        .collect()
}

/// Depth errors (mm): raw mean |z - z_gt| and after the best global scale of z.
pub fn depth_errors(z: &[f64], grid: &PixelGrid, truth: &[f64]) -> (f64, f64) {
    let pairs: Vec<(f64, f64)> =
        grid.pixels.iter().zip(z).map(|(&p, &z)| (z, truth[p])).filter(|(_, t)| t.is_finite()).collect();
    let n = pairs.len().max(1) as f64;
    let raw = pairs.iter().map(|(z, t)| (z - t).abs()).sum::<f64>() / n;
    let s = pairs.iter().map(|(z, t)| z * t).sum::<f64>() / pairs.iter().map(|(z, _)| z * z).sum::<f64>();
    let scaled = pairs.iter().map(|(z, t)| (s * z - t).abs()).sum::<f64>() / n;
    (raw * 1e3, scaled * 1e3)
}

/// Test-only diagnostic: the surface area of depths `z` over that of the true depths `zt`
/// scaled to z's size (s = the least-squares factor z ~ s zt, area times s^2), less 1: the
/// area that the form's roughness adds (a rough surface conducts more slowly between pixels).
pub fn area_excess(mesh: &RayMesh, z: &[f64], zt: &[f64]) -> f64 {
    let area = |d: &[f64]| -> f64 {
        use heatsim::surface::operators::{lumped_area, AreaMass};
        lumped_area(&mesh.positions(d), &mesh.tris, AreaMass::Barycentric).iter().sum()
    };
    let s = z.iter().zip(zt).map(|(a, b)| a * b).sum::<f64>() / zt.iter().map(|b| b * b).sum::<f64>();
    area(z) / (s * s * area(zt)) - 1.0
}

/// Largest change of size (either way) a level's profiled diffusivity may make; beyond it the
/// data are taken not to determine the size (on the 50 mK hemisphere shell the profiled
/// diffusivity at the true shape was 0 at the coarsest level) and the size is kept.
const MAX_SIZE_FACTOR: f64 = 2.0;

/// Relative height of the start's bulge: its height over the mask's inscribed radius.
const START_BULGE: f64 = 0.1;

/// The coarsest level's start (module doc): the plane z = `distance` with a bulge of height
/// `START_BULGE` times the mask's inscribed radius (m, at that distance) along the profile
/// sqrt(r (2 - r)) of the normalised distance r from the mask boundary, towards the camera or
/// away from it, whichever violates the half-space image less (towards it without one).
pub fn start_depths(mesh: &RayMesh, reg: &Regularisers, distance: f64) -> Vec<f64> {
    let rings = mesh.boundary_distance();
    let max_ring = rings.iter().copied().filter(|&r| r != usize::MAX).max().unwrap_or(0).max(1) as f64;
    // Pixel pitch at the start distance, m: mean edge length of the plane.
    let plane: Vec<f64> = vec![distance; mesh.len()];
    let x = mesh.positions(&plane);
    let pitch = mesh.edges.iter().map(|&[i, j]| norm(sub(x[i], x[j]))).sum::<f64>() / mesh.edges.len().max(1) as f64;
    let height = START_BULGE * max_ring * pitch;
    let bulge = |sign: f64| -> Vec<f64> {
        rings
            .iter()
            .map(|&r| {
                let r = if r == usize::MAX { 0.0 } else { r as f64 / max_ring };
                distance - sign * height * (r * (2.0 - r)).sqrt()
            })
            .collect()
    };
    if reg.halfspace_sign.len() != mesh.len() {
        return bulge(1.0);
    }
    let hinge = |z: &[f64]| halfspace_violation(mesh, reg, z);
    let (convex, concave) = (bulge(1.0), bulge(-1.0));
    if hinge(&concave) < hinge(&convex) {
        concave
    } else {
        convex
    }
}

/// The half-space hinge of Eq. 10 at depths `z` (unweighted, as in the energy).
fn halfspace_violation(mesh: &RayMesh, reg: &Regularisers, z: &[f64]) -> f64 {
    let n = mesh.normals(z);
    n.iter().zip(&reg.halfspace_sign).map(|(n, &s)| (-(s as f64) * dot(*n, reg.lamp_axis)).max(0.0)).sum::<f64>()
        / mesh.len().max(1) as f64
}

/// Upsamples the depth of `coarse` (per vertex of `cgrid`) to the vertices of `fine` (module doc).
pub fn upsample(cgrid: &PixelGrid, coarse: &[f64], fine: &PixelGrid) -> Vec<f64> {
    let (cw, ch) = (cgrid.width, cgrid.height);
    let mut img = vec![f64::NAN; cw * ch];
    for (k, &p) in cgrid.pixels.iter().enumerate() {
        img[p] = coarse[k];
    }
    let fw = fine.width;
    let mut z: Vec<f64> = fine
        .pixels
        .iter()
        .map(|&p| {
            let (u, v) = ((p % fw) as f64, (p / fw) as f64);
            let (x, y) = ((u - 0.5) / 2.0, (v - 0.5) / 2.0);
            let (x0, y0) = (x.floor(), y.floor());
            let (fx, fy) = (x - x0, y - y0);
            let (mut s, mut ws) = (0.0, 0.0);
            for (dx, dy, w) in
                [(0, 0, (1.0 - fx) * (1.0 - fy)), (1, 0, fx * (1.0 - fy)), (0, 1, (1.0 - fx) * fy), (1, 1, fx * fy)]
            {
                let (xi, yi) = (x0 as i64 + dx, y0 as i64 + dy);
                if xi >= 0 && yi >= 0 && (xi as usize) < cw && (yi as usize) < ch {
                    let d = img[yi as usize * cw + xi as usize];
                    if d.is_finite() && w > 0.0 {
                        s += w * d;
                        ws += w;
                    }
                }
            }
            if ws > 1e-9 {
                s / ws
            } else {
                f64::NAN
            }
        })
        .collect();
    // Fill by dilation over the fine image.
    let fh = fine.height;
    let mut fimg = vec![f64::NAN; fw * fh];
    for (k, &p) in fine.pixels.iter().enumerate() {
        fimg[p] = z[k];
    }
    for _ in 0..(fw + fh) {
        let missing: Vec<usize> = fine.pixels.iter().copied().filter(|&p| fimg[p].is_nan()).collect();
        if missing.is_empty() {
            break;
        }
        let mut updates = Vec::new();
        for p in missing {
            let (u, v) = ((p % fw) as i64, (p / fw) as i64);
            let (mut s, mut c) = (0.0, 0);
            for dv in -1..=1 {
                for du in -1..=1 {
                    let (uu, vv) = (u + du, v + dv);
                    if uu >= 0 && vv >= 0 && (uu as usize) < fw && (vv as usize) < fh {
                        let d = fimg[vv as usize * fw + uu as usize];
                        if d.is_finite() {
                            s += d;
                            c += 1;
                        }
                    }
                }
            }
            if c > 0 {
                updates.push((p, s / c as f64));
            }
        }
        if updates.is_empty() {
            break;
        }
        for (p, d) in updates {
            fimg[p] = d;
        }
    }
    // One 3 x 3 box blur over vertices.
    for (k, &p) in fine.pixels.iter().enumerate() {
        let (u, v) = ((p % fw) as i64, (p / fw) as i64);
        let (mut s, mut c) = (0.0, 0);
        for dv in -1..=1 {
            for du in -1..=1 {
                let (uu, vv) = (u + du, v + dv);
                if uu >= 0 && vv >= 0 && (uu as usize) < fw && (vv as usize) < fh {
                    let d = fimg[vv as usize * fw + uu as usize];
                    if d.is_finite() {
                        s += d;
                        c += 1;
                    }
                }
            }
        }
        z[k] = s / c.max(1) as f64;
    }
    z
}

/// What an [`crate::Observer`] sees of a level once its shape is found: the level's whole
/// problem, for diagnostics against a ground truth (which the method itself never reads).
pub struct LevelView<'a> {
    /// Index of the level in the run (0: the coarsest) and number of levels.
    pub index: usize,
    /// Number of levels of the run.
    pub levels: usize,
    /// The level's images.
    pub level: &'a Level,
    /// Stage 1's input at the level, as the data term used it (denoised).
    pub input: &'a Stage1Input,
    /// The series before stage 1's denoising, when the observer asked for them
    /// ([`crate::Observer::wants_raw_series`]).
    pub raw_series: Option<&'a [Vec<f64>]>,
    /// The pixel mesh on camera rays.
    pub mesh: &'a RayMesh,
    /// The heat data term.
    pub data: &'a DataTerm,
    /// The regularisers.
    pub reg: &'a Regularisers,
    /// The diffusivity as the level optimised it (profiled or given).
    pub scale: Scale,
    /// The known diffusivity when the level optimised with it profiled, m^2/s.
    pub metric: Option<f64>,
    /// The options of the run.
    pub opts: &'a Stage2Options,
    /// Ambient temperature, K, and emissivity.
    pub ambient: f64,
    /// Emissivity.
    pub emissivity: f64,
    /// The level's result.
    pub result: &'a LevelResult,
}

/// The data term and regularisers of one level.
struct LevelProblem {
    mesh: RayMesh,
    data: DataTerm,
    reg: Regularisers,
}

/// Builds level `li` of `nlev`'s problem from its stage-1 input and parameters.
fn level_problem(
    li: usize,
    nlev: usize,
    level: &Level,
    input: &Stage1Input,
    params: &Stage1Params,
    opts: &Stage2Options,
) -> Result<LevelProblem, ReconError> {
    let grid = &input.grid;
    let mesh = RayMesh::new(ray_dirs(&level.camera, grid), grid.tris.clone())?;
    let tol = 1e-9;
    let pairs: Vec<usize> = (0..input.times.len().saturating_sub(1))
        .filter(|&k| input.times[k] >= opts.t_start - tol && input.times[k + 1] <= opts.t_end + tol)
        .collect();
    let heat = HeatData {
        series: &input.series,
        times: &input.times,
        pairs: &pairs,
        // The shape's data term is built on frame pairs: the five-point rule of stage 1
        // has no pair form, its pairs use the trapezoid (the same order in time as stage 1's
        // default).
        time_weight: match opts.time_rule {
            TimeRule::BackwardEuler => 1.0,
            TimeRule::Trapezoid | TimeRule::Central => 0.5,
        },
        lambda: params.lambda,
        c_inv: params.c_inv,
        flux_over_c: &params.flux_over_c,
        ambient: input.ambient,
        emissivity: input.emissivity,
        profile_flux: opts.profile_flux,
        boundary_rings: opts.boundary_rings,
        profile_globals: opts.profile_globals,
        noise_cov: &params.noise_cov,
    };
    let mut data = DataTerm::new(&mesh, &heat)?;
    data.robust = opts.robust;
    let last = li + 1 == nlev;
    let hs_w = if last && nlev > 1 { 0.0 } else { opts.halfspace_weight * opts.halfspace_decay.powi(li as i32) };
    let excluded: Vec<bool> = mesh.boundary_distance().iter().map(|&k| k < opts.boundary_rings).collect();
    let reg = Regularisers {
        normal_consistency: opts.normal_consistency,
        halfspace: if params.halfspace.is_some() { hs_w } else { 0.0 },
        halfspace_sign: params.halfspace.clone().unwrap_or_default(),
        lamp_axis: opts.lamp_axis,
        #[cfg(feature = "experimental")]
        lamp_ratio: opts.lamp_ratio.as_ref().filter(|o| params.flux_over_c.len() >= 2 && o.lamps.len() >= 2).map(|o| {
            let b = &params.flux_over_c;
            let lamps = [o.lamps[0].clone(), o.lamps[1].clone()];
            (crate::experimental::lamp_ratio::LampRatio::new(lamps, &b[0], &b[1], o.threshold, &excluded), o.weight)
        }),
        lamp_shading: opts
            .lamp_shading
            .as_ref()
            .filter(|o| o.lamps.len() == params.flux_over_c.len())
            .map(|o| (LampShading::new(o.lamps.clone(), &params.flux_over_c, o.threshold, &excluded), o.weight)),
        symmetry: (li == 0 && opts.symmetry_weight > 0.0)
            .then(|| (MirrorSymmetry::new(grid, opts.distance), opts.symmetry_weight)),
    };
    Ok(LevelProblem { mesh, data, reg })
}

/// Minimises level `li`'s energy over the depths `z` (and the globals when minimised jointly:
/// returned as their corrections from stage 1's values), logging every iteration.
#[allow(clippy::too_many_arguments)]
fn optimise_level(
    li: usize,
    level: &Level,
    problem: &LevelProblem,
    params: &Stage1Params,
    scale: Scale,
    target_mean: f64,
    r_coef: f64,
    opts: &Stage2Options,
    z: &mut [f64],
    log: &mut Vec<LogRow>,
    observer: &mut dyn crate::Observer,
) -> Result<Option<[f64; 2]>, ReconError> {
    let LevelProblem { mesh, data, reg } = problem;
    let steps = LargeSteps::new(mesh.len(), &mesh.edges, opts.optim.large_steps_lambda)?;
    let profiled = matches!(scale, Scale::Profiled);
    let optim = OptimOptions {
        iterations: if li == 0 {
            opts.coarsest_iterations.unwrap_or(opts.optim.iterations)
        } else {
            opts.optim.iterations
        },
        ..opts.optim.clone()
    };
    let mut report = |it: usize, evals: usize, z: &[f64], terms: Terms| {
        log.push(LogRow { level: level.level, iteration: it, evaluations: evals, terms });
        observer.iteration(level.level, it, z);
    };
    let hold_mean = |z: &mut [f64]| {
        if profiled {
            let mean = z.iter().sum::<f64>() / z.len() as f64;
            z.iter_mut().for_each(|v| *v *= target_mean / mean);
        }
    };
    if opts.minimises_globals_jointly() {
        let start = energy(mesh, data, reg, scale, z, None);
        let mut d = [start.lambda - params.lambda, start.c_inv - params.c_inv];
        minimise_joint(
            z,
            &mut d,
            &steps,
            &optim,
            params.lambda,
            r_coef,
            &hold_mean,
            |z, d, g, gd| energy_at_globals(mesh, data, reg, scale, z, d, g, gd),
            &mut report,
        )?;
        Ok(Some(d))
    } else {
        let last = LastTerms::default();
        minimise(
            z,
            &steps,
            &optim,
            |z, g| {
                let t = energy(mesh, data, reg, scale, z, Some(g));
                last.store(z, t);
                t.total
            },
            hold_mean,
            |it, evals, z, _e| {
                report(it, evals, z, last.get(z).unwrap_or_else(|| energy(mesh, data, reg, scale, z, None)))
            },
        )?;
        Ok(None)
    }
}

/// Runs stage 2 from the coarsest level to `opts.finest`. `stage1(level, input, observer)` gives the
/// stage-1 parameters at a level (the estimator, or an oracle for tests) and may denoise
/// `input`, whose series the shape's data term then uses; `observer` is told of every
/// iteration and shown every level's problem ([`LevelView`]).
///
/// # Errors
/// Empty meshes, stage-1 failures, a non-finite energy.
pub fn reconstruct(
    finest: &Level,
    ambient: f64,
    emissivity: f64,
    opts: &Stage2Options,
    mut stage1: impl FnMut(&Level, &mut Stage1Input, &mut dyn crate::Observer) -> Result<Stage1Params, ReconError>,
    observer: &mut dyn crate::Observer,
) -> Result<Stage2Result, ReconError> {
    let mut pyramid = vec![finest.clone()];
    for _ in 0..opts.extra_levels {
        let next = pyramid.last().expect("non-empty").downsample();
        pyramid.push(next);
    }
    pyramid.reverse();
    let nlev = pyramid.len();
    let mut log = Vec::new();
    let mut levels: Vec<LevelResult> = Vec::new();
    for (li, level) in pyramid.iter().enumerate() {
        let mut input = Stage1Input::from_level(level, ambient, emissivity)?;
        let wants_raw = observer.wants_raw_series() || experiments_want_raw_series(opts, level.level);
        let raw_series = wants_raw.then(|| input.series.clone());
        observer.level_start(li, nlev, level);
        let params = stage1(level, &mut input, observer)?;
        let problem = level_problem(li, nlev, level, &input, &params, opts)?;
        let LevelProblem { mesh, data, reg } = &problem;
        let mut z = match levels.last() {
            None => start_depths(mesh, reg, opts.distance),
            Some(prev) => upsample(&prev.grid, &prev.depth, &input.grid),
        };
        #[cfg(feature = "experimental")]
        if let (None, Some(path)) = (levels.last(), &opts.initial_depth) {
            crate::experimental::apply_start_depth(path, &input.grid, &mut z)?;
        }
        let r_coef = 4.0 * emissivity * crate::stage1::SIGMA * ambient.powi(3);
        let (scale, metric) = match opts.scale {
            Scale::Diffusivity(a) if opts.profile_scale => (Scale::Profiled, Some(a)),
            Scale::Diffusivity(a) => (Scale::Diffusivity(a), None),
            Scale::Profiled => (Scale::Profiled, None),
        };
        let target_mean = if metric.is_some() { z.iter().sum::<f64>() / z.len() as f64 } else { opts.distance };
        let globals =
            optimise_level(li, level, &problem, &params, scale, target_mean, r_coef, opts, &mut z, &mut log, observer)?;
        // The energy at given depths, with the jointly minimised globals when there are any.
        let terms_at = |scale: Scale, z: &[f64]| match globals {
            Some(d) => energy_at_globals(mesh, data, reg, scale, z, d, None, None),
            None => energy(mesh, data, reg, scale, z, None),
        };
        let mut terms = terms_at(scale, &z);
        let (mut size_factor, mut profiled_size_factor) = (None, None);
        if let Some(a) = metric {
            // Cotangent weights are scale invariant and areas scale as s^2: the size whose
            // profiled diffusivity is the known one, unless the data do not determine it.
            let s = (a / terms.alpha).sqrt();
            profiled_size_factor = s.is_finite().then_some(s);
            // The finest level of several refines the form only (module doc).
            let finest_of_several = li + 1 == nlev && nlev > 1;
            if !finest_of_several && s.is_finite() && (1.0 / MAX_SIZE_FACTOR..=MAX_SIZE_FACTOR).contains(&s) {
                z.iter_mut().for_each(|v| *v *= s);
                size_factor = Some(s);
            }
            terms = terms_at(Scale::Diffusivity(a), &z);
        }
        #[cfg(not(feature = "experimental"))]
        let experiments = None;
        #[cfg(feature = "experimental")]
        let experiments = {
            let report = crate::experimental::after_level(
                opts,
                level.level,
                mesh,
                raw_series.as_deref(),
                &input,
                &params,
                metric,
                &mut z,
                observer,
            )?;
            if report.is_some() {
                terms = terms_at(metric.map_or(scale, Scale::Diffusivity), &z);
            }
            report
        };
        let normals = mesh.normals(&z);
        let residual = vertex_rms_residual(mesh, data, &terms, &z);
        levels.push(LevelResult {
            level: level.level,
            camera: level.camera.clone(),
            grid: input.grid.clone(),
            depth: z,
            normals,
            terms,
            residual,
            stage1: params,
            experiments,
            size_factor,
            profiled_size_factor,
        });
        observer.level(&LevelView {
            index: li,
            levels: nlev,
            level,
            input: &input,
            raw_series: raw_series.as_deref(),
            mesh,
            data,
            reg,
            scale,
            metric,
            opts,
            ambient,
            emissivity,
            result: levels.last().expect("just pushed"),
        });
    }
    Ok(Stage2Result { levels, log })
}

/// Whether an experiment at pyramid `level` fits the series as filmed (before denoising).
fn experiments_want_raw_series(_opts: &Stage2Options, _level: usize) -> bool {
    #[cfg(feature = "experimental")]
    return crate::experimental::wants_raw_series(_opts, _level);
    #[cfg(not(feature = "experimental"))]
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn area_excess_sees_roughness_not_size() {
        let (w, h) = (9, 8);
        let grid = PixelGrid::new(&vec![true; w * h], w, h);
        let dirs: Vec<[f64; 3]> = (0..grid.vertex_count())
            .map(|k| {
                let (u, v) = grid.pixel_uv(k);
                [(u as f64 - 4.0) * 0.01, (v as f64 - 3.5) * 0.01, 1.0]
            })
            .collect();
        let zt: Vec<f64> = dirs.iter().map(|d| 0.4 - 0.8 * (d[0] * d[0] + d[1] * d[1])).collect();
        let mesh = RayMesh::new(dirs, grid.tris.clone()).expect("mesh");
        assert!(area_excess(&mesh, &zt, &zt).abs() < 1e-12);
        let scaled: Vec<f64> = zt.iter().map(|z| 0.9 * z).collect();
        assert!(area_excess(&mesh, &scaled, &zt).abs() < 1e-12, "a similar copy adds no area");
        let rough: Vec<f64> = zt.iter().enumerate().map(|(i, z)| z + if i % 2 == 0 { 1e-3 } else { -1e-3 }).collect();
        let e = area_excess(&mesh, &rough, &zt);
        assert!(e > 1e-3, "roughness of a quarter of the pixel pitch adds area: {e:e}");
    }
}
