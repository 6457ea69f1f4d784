//! Lamps as boundary heat sources: the irradiance each lamp puts on every boundary face, with
//! shadows cast by the object itself.
//!
//! # Model
//!
//! The paper's heat equation (Eq. 1) heats the surface with the absorbed flux
//! `β φ_q`: the absorptivity `β` (dimensionless) times the incident irradiance
//! `φ_q` (W/m²). This module computes `φ_q` per boundary face, once per run, for the
//! two kinds of lamp of [`LampSpec`]:
//!
//! - **uniform**: `φ_q =` `flux` on every face tagged [`FaceTag::Visible`] and 0 elsewhere
//!   (normal incidence everywhere, no shadows: an idealised, perfectly collimated source);
//! - **point** (an isotropic bare bulb of electrical power `P` (W) and radiant fraction
//!   `η`, reference section 4), on every boundary face `f` with outward unit normal
//!   `n_f` and centroid `c_f` (m):
//!   `φ_f = (η P)/(4 π r^2) max(0, cosθ) V_f,
//!   r = |x_L - c_f|,
//!   cosθ = (n_f · (x_L - c_f))/r,`
//!   with `V_f ∈ {0, 1}` the visibility of the lamp `x_L` from the centroid: 0 when
//!   the segment from the centroid to the lamp crosses the object's boundary (a shadow, cast
//!   by another part of the object or by the face's own solid).
//!
//! The flux is evaluated at the face centroid (one-point quadrature, constant over the face):
//! the face-to-node load is assembled elsewhere (`simulate`), as for uniform lamps. The
//! one-point rule misses the variation of `r^-2cosθ` across a face, which is of
//! relative size (face size / r)², about 1e-5 for 1 mm faces under a lamp 30 cm away.
//!
//! Not modelled: interreflections between faces, light from the lamp reflected by the room,
//! penumbras (the filament is a point), and the lamp's own conduction and convection losses
//! (the 1 - η share of its power).
//!
//! # Shadow rays
//!
//! An [`Occluder`] is a bounding-volume hierarchy (that of parry's `TriMesh`) over the
//! boundary triangles, built once per run; rays are tested against its boxes, slightly
//! enlarged, and then against each candidate triangle in f64 (Möller-Trumbore). The shadow
//! ray of face `f` starts at `c_f + δ_f n_f`, lifted off the face by
//! `δ_f =` [`SHADOW_OFFSET`] `+` [`SHADOW_OFFSET_REL`] `·` (longest edge of `f`), so
//! that rounding cannot make a face shadow itself, and it ends at the lamp. Faces with
//! `cosθ ≤ 0` face away from the lamp and cast no ray.
//!
//! Units: SI throughout (m, W, W/m²).

use parry3d_f64::math::Vector;
use parry3d_f64::partitioning::BvhNode;
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::TriMesh as ParryTriMesh;
use rayon::prelude::*;
use std::f64::consts::PI;

use crate::mesh::tetmesh::FaceTag;
use crate::scene::{LampSpec, PointLamp};
use crate::vec3::{add, cross, dist, dot, norm, scale, sub};

/// Constant part of the lift of a shadow ray's origin off its face, in m. 0.1 µm: far above
/// the rounding error of coordinates of objects up to metres in size (~1e-16 m), far below any
/// geometric feature a thermal simulation resolves.
pub const SHADOW_OFFSET: f64 = 1e-7;

/// Part of the lift of a shadow ray's origin proportional to the face's longest edge
/// (dimensionless): keeps the lift above rounding for large faces far from the origin.
pub const SHADOW_OFFSET_REL: f64 = 1e-6;

/// Enlargement of every box of the hierarchy in the ray-box test, relative to the bounding-box
/// diagonal of the whole surface (dimensionless). The slab test of a flat box (a triangle in
/// the plane z = 0 has zero thickness in z) is exact only up to rounding; a margin of 1e-9
/// makes sure a ray that hits a triangle (or its edge) by the triangle test is never dropped
/// by the box test first.
const BOX_MARGIN_REL: f64 = 1e-9;

/// A ray that meets a triangle within this barycentric distance of an edge or a corner is
/// ambiguous for the parity test of [`Occluder::contains`] (dimensionless). The barycentric
/// coordinates are computed with relative errors ~1e-15 for well-shaped triangles: 1e-9 flags
/// every hit rounding could move across an edge, and a direction is only rejected when a ray
/// passes within a millionth of a face size of an edge.
const PARITY_EDGE_TOL: f64 = 1e-9;

/// A ray making a cosine below this with a triangle's normal (grazing incidence) is ambiguous
/// for the parity test (dimensionless).
const PARITY_GRAZING_TOL: f64 = 1e-9;

/// Distance to the surface below which a point counts as on the surface, relative to the
/// bounding-box diagonal (dimensionless).
const ON_SURFACE_REL: f64 = 1e-12;

/// Fixed, non-axis-aligned directions of the parity rays of [`Occluder::contains`] (not unit
/// length; normalised on use). Arbitrary, unrelated components keep them off the planes and
/// diagonals of axis-aligned and symmetric meshes.
const PARITY_DIRECTIONS: [[f64; 3]; 7] = [
    [0.318_309_123_456_791, 0.271_828_182_845_905, 0.906_307_787_036_650],
    [-0.577_215_664_901_533, 0.414_213_562_373_095, -0.693_417_805_259_945],
    [0.737_106_325_568_441, -0.618_033_988_749_895, 0.141_421_356_237_310],
    [-0.223_606_797_749_979, -0.866_025_403_784_439, 0.302_775_637_731_995],
    [0.169_014_084_507_042, 0.523_895_775_529_829, -0.833_333_333_333_333],
    [-0.911_111_111_111_111, -0.129_099_444_873_581, 0.371_390_676_354_104],
    [0.447_213_595_499_958, 0.788_675_134_594_813, 0.421_637_021_355_784],
];

/// Errors of the lamp model: bad input meshes and lamps placed where they cannot be.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LampError {
    /// The occluding surface has no triangles.
    #[error("the object's surface has no triangles; cannot trace shadows")]
    EmptyMesh,
    /// A triangle refers to a vertex that does not exist.
    #[error("surface triangle {face} refers to vertex {index}, but there are only {vertex_count} vertices")]
    IndexOutOfRange { face: usize, index: usize, vertex_count: usize },
    /// A vertex coordinate is NaN or infinite.
    #[error("surface vertex {vertex} is not finite: {position:?}")]
    NonFiniteVertex { vertex: usize, position: [f64; 3] },
    /// The surface is too large for the 32-bit indices of the hierarchy.
    #[error("the surface has {count} triangles or vertices, more than the 2^32 - 1 the shadow tracer can index")]
    TooLarge { count: usize },
    /// A lamp position is NaN or infinite.
    #[error("lamps[{index}].position: {position:?} is not finite")]
    NonFinitePosition { index: usize, position: [f64; 3] },
    /// The minimum lamp distance is negative or not finite.
    #[error("the minimum lamp distance must be a finite number >= 0 m, got {value}")]
    InvalidMinDistance { value: f64 },
    /// A point lamp is inside the object.
    #[error("lamps[{index}].position: the lamp at {position:?} m is inside the object; move it outside, in front of the visible surface (+z)")]
    LampInside { index: usize, position: [f64; 3] },
    /// A point lamp is too close to the object's surface.
    #[error("lamps[{index}].position: the lamp is {distance} m from the object's surface; it must be at least {min_distance} m away", distance = round_sig(*distance))]
    LampTooClose { index: usize, distance: f64, min_distance: f64 },
}

/// `x` rounded to 4 significant digits, for messages (`0.0004123` rather than
/// `0.00041234567891`).
fn round_sig(x: f64) -> f64 {
    format!("{x:.3e}").parse().unwrap_or(x)
}

/// A bounding-volume hierarchy over the object's boundary triangles, for shadow rays, inside
/// tests and distances (built once per run).
///
/// Holds its own copy of the triangles (#F x 3 corner positions, m), compacted to the vertices
/// they use, so it can be built from a tetrahedral mesh's boundary over all of its nodes.
pub struct Occluder {
    /// #F triangles as corner positions (m), in input order: leaf `i` of the hierarchy of
    /// `surface` is `tris[i]`.
    tris: Vec<[[f64; 3]; 3]>,
    /// The same triangles as a parry mesh: its hierarchy, and closest-point queries.
    surface: ParryTriMesh,
    /// Bounding-box diagonal of the surface (m).
    diagonal: f64,
    /// Enlargement of the boxes in ray-box tests (m): [`BOX_MARGIN_REL`] x `diagonal`.
    margin: f64,
}

impl std::fmt::Debug for Occluder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Occluder").field("triangles", &self.tris.len()).field("diagonal_m", &self.diagonal).finish()
    }
}

#[inline]
fn to_vector(p: [f64; 3]) -> Vector {
    Vector::new(p[0], p[1], p[2])
}

/// Outcome of one ray against one triangle in the parity test.
enum ParityHit {
    Miss,
    Cross,
    /// Near an edge or corner, grazing, or starting on the triangle: rounding could decide it.
    Ambiguous,
}

impl Occluder {
    /// Builds the hierarchy over the triangles `tris` (#F x 3 indices into `verts`, #V x 3, m).
    /// For [`contains`](Self::contains) the surface must be closed; shadow rays and distances
    /// work on any triangle soup. Triangles of zero area are kept and never block a ray.
    ///
    /// # Errors
    /// [`LampError::EmptyMesh`] without triangles, [`LampError::IndexOutOfRange`] for an index
    /// past `verts`, [`LampError::NonFiniteVertex`] for a NaN or infinite coordinate of a vertex
    /// in use, [`LampError::TooLarge`] beyond 32-bit indices.
    pub fn new(verts: &[[f64; 3]], tris: &[[usize; 3]]) -> Result<Occluder, LampError> {
        if tris.is_empty() {
            return Err(LampError::EmptyMesh);
        }
        if tris.len() >= u32::MAX as usize {
            return Err(LampError::TooLarge { count: tris.len() });
        }
        // Compact to the vertices in use (a tetrahedral mesh's boundary uses few of its nodes).
        let mut map = vec![u32::MAX; verts.len()];
        let mut used: Vec<Vector> = Vec::new();
        let mut indices = Vec::with_capacity(tris.len());
        for (face, t) in tris.iter().enumerate() {
            let mut local = [0u32; 3];
            for (k, &index) in t.iter().enumerate() {
                let Some(&p) = verts.get(index) else {
                    return Err(LampError::IndexOutOfRange { face, index, vertex_count: verts.len() });
                };
                if map[index] == u32::MAX {
                    if !p.iter().all(|c| c.is_finite()) {
                        return Err(LampError::NonFiniteVertex { vertex: index, position: p });
                    }
                    if used.len() >= u32::MAX as usize - 1 {
                        return Err(LampError::TooLarge { count: used.len() + 1 });
                    }
                    map[index] = used.len() as u32;
                    used.push(to_vector(p));
                }
                local[k] = map[index];
            }
            indices.push(local);
        }
        let tri_pts: Vec<[[f64; 3]; 3]> = tris.iter().map(|t| t.map(|i| verts[i])).collect();
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for p in tri_pts.iter().flatten() {
            for d in 0..3 {
                lo[d] = lo[d].min(p[d]);
                hi[d] = hi[d].max(p[d]);
            }
        }
        let diagonal = dist(lo, hi);
        // Without flags parry only rejects an empty index list, excluded above.
        let surface = ParryTriMesh::new(used, indices).map_err(|_| LampError::EmptyMesh)?;
        Ok(Occluder { tris: tri_pts, surface, diagonal, margin: BOX_MARGIN_REL * diagonal })
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// Always false: [`Occluder::new`] refuses empty surfaces.
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// Bounding-box diagonal of the surface (m).
    pub fn diagonal(&self) -> f64 {
        self.diagonal
    }

    /// Whether the open segment from `from` to `to` (m) is free of triangles. A triangle's
    /// edges count as part of it (a segment through an edge is blocked); the end points do not
    /// (a segment that only touches a triangle at an end point is clear, up to rounding: lift
    /// an end point that lies on the surface off it, as [`point_irradiance`] does). A segment
    /// lying in a triangle's plane is not blocked by that triangle.
    pub fn segment_is_clear(&self, from: [f64; 3], to: [f64; 3]) -> bool {
        let dir = sub(to, from);
        // Parameters t in (0, 1) along from + t * dir.
        let ray = SlabRay::new(from, dir, 1.0, self.margin);
        !self
            .surface
            .bvh()
            .leaves(|node| ray.hits(node))
            .any(|leaf| segment_hits_triangle(from, dir, &self.tris[leaf as usize]))
    }

    /// Whether `p` (m) is inside the closed surface, by the parity of the number of crossings
    /// of rays from `p` along fixed, non-axis-aligned directions. A ray that passes within
    /// 1e-9 (barycentric) of a triangle's edge or corner, grazes a triangle or starts on it is
    /// discarded and the next direction is tried; the answer is the majority of the first
    /// three usable rays (two agreeing suffice). That also outvotes a single ray slipping
    /// through a small hole of a surface that is not quite closed. A point on the surface
    /// (within 1e-12 of the diagonal) counts as inside (the solid is closed).
    pub fn contains(&self, p: [f64; 3]) -> bool {
        if !p.iter().all(|c| c.is_finite()) {
            return false;
        }
        let (mut inside, mut outside) = (0, 0);
        for d in PARITY_DIRECTIONS {
            let dir = scale(d, 1.0 / norm(d));
            match self.crossings(p, dir) {
                Some(n) if n % 2 == 1 => inside += 1,
                Some(_) => outside += 1,
                None => continue,
            }
            if inside == 2 || outside == 2 {
                break;
            }
        }
        if inside != outside {
            return inside > outside;
        }
        // No usable majority: only on (or within rounding of) the surface, or for a surface
        // with holes. On the surface counts as inside.
        self.distance(p) <= ON_SURFACE_REL * self.diagonal
    }

    /// Number of triangles crossed by the ray from `p` along the unit vector `dir`, or `None`
    /// when a hit is ambiguous.
    fn crossings(&self, p: [f64; 3], dir: [f64; 3]) -> Option<usize> {
        let ray = SlabRay::new(p, dir, f64::INFINITY, self.margin);
        let t_tol = ON_SURFACE_REL * self.diagonal;
        let mut n = 0;
        for leaf in self.surface.bvh().leaves(|node| ray.hits(node)) {
            match parity_hit(p, dir, &self.tris[leaf as usize], t_tol) {
                ParityHit::Miss => {}
                ParityHit::Cross => n += 1,
                ParityHit::Ambiguous => return None,
            }
        }
        Some(n)
    }

    /// Distance from `p` to the surface (m): to the nearest point of any triangle, from inside
    /// or outside alike.
    pub fn distance(&self, p: [f64; 3]) -> f64 {
        let q = to_vector(p);
        let proj = self.surface.project_local_point(q, false);
        (q - proj.point).length()
    }
}

/// A ray `o + t d`, 0 <= t <= `t_max`, for slab tests against boxes enlarged by `margin` (m).
struct SlabRay {
    o: [f64; 3],
    d: [f64; 3],
    inv: [f64; 3],
    t_max: f64,
    margin: f64,
}

impl SlabRay {
    fn new(o: [f64; 3], d: [f64; 3], t_max: f64, margin: f64) -> SlabRay {
        SlabRay { o, d, inv: d.map(|x| 1.0 / x), t_max, margin }
    }

    /// Whether the ray meets the node's box enlarged by the margin (conservative: a NaN from
    /// 0 x inf never rejects).
    #[inline]
    fn hits(&self, node: &BvhNode) -> bool {
        let (lo, hi) = (node.mins(), node.maxs());
        let (mut t0, mut t1) = (0.0_f64, self.t_max);
        for k in 0..3 {
            let (lo, hi) = (lo[k] - self.margin, hi[k] + self.margin);
            if self.d[k] == 0.0 {
                if self.o[k] < lo || self.o[k] > hi {
                    return false;
                }
                continue;
            }
            let a = (lo - self.o[k]) * self.inv[k];
            let b = (hi - self.o[k]) * self.inv[k];
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
            if t0 > t1 {
                return false;
            }
        }
        true
    }
}

/// Whether the segment `o + t d`, 0 < t < 1, meets the closed triangle `tri` (Möller-Trumbore
/// in f64; edges inclusive, a segment in the triangle's plane never hits).
#[inline]
fn segment_hits_triangle(o: [f64; 3], d: [f64; 3], tri: &[[f64; 3]; 3]) -> bool {
    let e1 = sub(tri[1], tri[0]);
    let e2 = sub(tri[2], tri[0]);
    let pvec = cross(d, e2);
    let det = dot(e1, pvec);
    if det == 0.0 {
        return false;
    }
    let inv = 1.0 / det;
    let tvec = sub(o, tri[0]);
    let u = dot(tvec, pvec) * inv;
    if !(0.0..=1.0).contains(&u) {
        return false;
    }
    let qvec = cross(tvec, e1);
    let v = dot(d, qvec) * inv;
    if v < 0.0 || u + v > 1.0 {
        return false;
    }
    let t = dot(e2, qvec) * inv;
    t > 0.0 && t < 1.0
}

/// Classifies the ray `p + t dir` (t > 0, `dir` a unit vector) against `tri` for the parity
/// test; `t_tol` (m) is the distance below which `p` lies on the triangle.
#[inline]
fn parity_hit(p: [f64; 3], dir: [f64; 3], tri: &[[f64; 3]; 3], t_tol: f64) -> ParityHit {
    let e1 = sub(tri[1], tri[0]);
    let e2 = sub(tri[2], tri[0]);
    let n = norm(cross(e1, e2));
    if n == 0.0 {
        // Zero area: no interior to cross; its edges belong to its neighbours.
        return ParityHit::Miss;
    }
    let pvec = cross(dir, e2);
    let det = dot(e1, pvec);
    if det.abs() <= PARITY_GRAZING_TOL * n {
        // det / n is the cosine between the ray and the normal: grazing. Whether it
        // crosses is decided by rounding; let another direction decide.
        return ParityHit::Ambiguous;
    }
    let inv = 1.0 / det;
    let tvec = sub(p, tri[0]);
    let u = dot(tvec, pvec) * inv;
    let qvec = cross(tvec, e1);
    let v = dot(dir, qvec) * inv;
    let w = 1.0 - u - v;
    let closest = u.min(v).min(w);
    if closest < -PARITY_EDGE_TOL {
        return ParityHit::Miss;
    }
    let t = dot(e2, qvec) * inv;
    if t < -t_tol {
        return ParityHit::Miss;
    }
    if t <= t_tol || closest <= PARITY_EDGE_TOL {
        return ParityHit::Ambiguous;
    }
    ParityHit::Cross
}

/// Incident irradiance (W/m², #F) of the point lamp `lamp` on each face of `faces` (#F x 3
/// indices into `verts`, #V x 3, m; counter-clockwise seen from outside):
/// `η P / (4 π r^2) max(0, cosθ)` at the face centroid, θ between the outward
/// face normal and the direction to the lamp, and 0 when the shadow ray from the centroid
/// (lifted by [`SHADOW_OFFSET`] + [`SHADOW_OFFSET_REL`] x longest edge along the normal) to
/// the lamp is blocked by `occluder`. Faces of zero area get 0.
///
/// Faces are independent and computed in parallel; the result does not depend on the number
/// of threads.
///
/// # Panics
/// If an index of `faces` is out of range of `verts` (validate the mesh first).
pub fn point_irradiance(lamp: &PointLamp, verts: &[[f64; 3]], faces: &[[usize; 3]], occluder: &Occluder) -> Vec<f64> {
    let x_lamp = lamp.position;
    let intensity = lamp.radiant_fraction * lamp.power / (4.0 * PI); // W/sr
    faces
        .par_iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| verts[i]);
            let n = cross(sub(b, a), sub(c, a));
            let n_len = norm(n);
            if n_len == 0.0 {
                return 0.0;
            }
            let centroid = scale(add(add(a, b), c), 1.0 / 3.0);
            let to_lamp = sub(x_lamp, centroid);
            let r2 = dot(to_lamp, to_lamp);
            // cos(theta) * r, without the square root until it is needed.
            let cos_r = dot(n, to_lamp) / n_len;
            if cos_r <= 0.0 || r2 == 0.0 {
                return 0.0;
            }
            let r = r2.sqrt();
            let size = dist(a, b).max(dist(b, c)).max(dist(c, a));
            let origin = add(centroid, scale(n, (SHADOW_OFFSET + SHADOW_OFFSET_REL * size) / n_len));
            if !occluder.segment_is_clear(origin, x_lamp) {
                return 0.0;
            }
            intensity * cos_r / (r2 * r)
        })
        .collect()
}

/// Per-face absorbed flux (W/m², #F) of one lamp while it is on: `absorptivity` (β of the
/// paper's Eq. 1, dimensionless) times the incident irradiance. A uniform lamp irradiates the
/// faces tagged [`FaceTag::Visible`] with its `flux` and nothing else; a point lamp every face
/// of `faces`, as computed by [`point_irradiance`]. `faces` (#F x 3) and `tags` (#F) are a
/// mesh's boundary, e.g. [`TetMesh::boundary`](crate::mesh::tetmesh::TetMesh::boundary) and
/// `boundary_tag`; `occluder` is built from the same boundary.
///
/// # Panics
/// If `tags` and `faces` differ in length, or an index of `faces` is out of range.
pub fn absorbed_face_flux(
    lamp: &LampSpec,
    absorptivity: f64,
    verts: &[[f64; 3]],
    faces: &[[usize; 3]],
    tags: &[FaceTag],
    occluder: &Occluder,
) -> Vec<f64> {
    assert_eq!(faces.len(), tags.len(), "absorbed_face_flux: one tag per face");
    match lamp {
        LampSpec::Uniform(u) => {
            let q = absorptivity * u.flux;
            tags.iter().map(|&t| if t == FaceTag::Visible { q } else { 0.0 }).collect()
        }
        LampSpec::Point(p) => {
            let mut e = point_irradiance(p, verts, faces, occluder);
            e.iter_mut().for_each(|x| *x *= absorptivity);
            e
        }
    }
}

/// Checks every lamp of a scene against the object: a point lamp must be outside the object
/// and at least `min_distance` (m) from its surface (the point-source model and the one-point
/// quadrature per face both fail close to the surface, and a real bulb has a size). Uniform
/// lamps have no position and always pass.
///
/// # Errors
/// For the first offending lamp `i`: [`LampError::NonFinitePosition`],
/// [`LampError::LampInside`] or [`LampError::LampTooClose`], each naming `lamps[i].position`;
/// [`LampError::InvalidMinDistance`] for a negative or non-finite `min_distance`.
pub fn check_lamps(lamps: &[LampSpec], occluder: &Occluder, min_distance: f64) -> Result<(), LampError> {
    if !(min_distance.is_finite() && min_distance >= 0.0) {
        return Err(LampError::InvalidMinDistance { value: min_distance });
    }
    for (index, lamp) in lamps.iter().enumerate() {
        let LampSpec::Point(p) = lamp else { continue };
        let position = p.position;
        if !position.iter().all(|c| c.is_finite()) {
            return Err(LampError::NonFinitePosition { index, position });
        }
        if occluder.contains(position) {
            return Err(LampError::LampInside { index, position });
        }
        let distance = occluder.distance(position);
        if distance < min_distance {
            return Err(LampError::LampTooClose { index, distance, min_distance });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_tri() -> [[f64; 3]; 3] {
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    }

    #[test]
    fn segment_triangle_open_ends_and_closed_edges() {
        let t = unit_tri();
        // Through the interior.
        assert!(segment_hits_triangle([0.2, 0.2, 1.0], [0.0, 0.0, -2.0], &t));
        // Stops short of the plane.
        assert!(!segment_hits_triangle([0.2, 0.2, 1.0], [0.0, 0.0, -0.5], &t));
        // Ends exactly on the triangle: open segment, no hit.
        assert!(!segment_hits_triangle([0.25, 0.25, 1.0], [0.0, 0.0, -1.0], &t));
        // Through an edge (u + v = 1): edges are part of the triangle.
        assert!(segment_hits_triangle([0.5, 0.5, 1.0], [0.0, 0.0, -2.0], &t));
        // Outside.
        assert!(!segment_hits_triangle([0.8, 0.8, 1.0], [0.0, 0.0, -2.0], &t));
        // In the plane.
        assert!(!segment_hits_triangle([-1.0, 0.2, 0.0], [3.0, 0.0, 0.0], &t));
    }

    #[test]
    fn parity_flags_edges_and_grazing() {
        let t = unit_tri();
        let down = [0.0, 0.0, -1.0];
        assert!(matches!(parity_hit([0.2, 0.2, 1.0], down, &t, 1e-12), ParityHit::Cross));
        assert!(matches!(parity_hit([0.5, 0.5, 1.0], down, &t, 1e-12), ParityHit::Ambiguous));
        assert!(matches!(parity_hit([0.0, 0.0, 1.0], down, &t, 1e-12), ParityHit::Ambiguous));
        assert!(matches!(parity_hit([0.2, 0.2, 0.0], down, &t, 1e-12), ParityHit::Ambiguous));
        assert!(matches!(parity_hit([0.2, 0.2, -1.0], down, &t, 1e-12), ParityHit::Miss));
        assert!(matches!(parity_hit([2.0, 2.0, 1.0], down, &t, 1e-12), ParityHit::Miss));
        assert!(matches!(parity_hit([-1.0, 0.2, 0.0], [1.0, 0.0, 0.0], &t, 1e-12), ParityHit::Ambiguous));
    }

    /// The unit cube [0, 1]^3, 12 outward triangles.
    fn unit_cube() -> Occluder {
        let verts: Vec<[f64; 3]> =
            (0..8).map(|i| [(i & 1) as f64, ((i >> 1) & 1) as f64, ((i >> 2) & 1) as f64]).collect();
        let quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]];
        let tris: Vec<[usize; 3]> = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        for t in &tris {
            let n = cross(sub(verts[t[1]], verts[t[0]]), sub(verts[t[2]], verts[t[0]]));
            let c = scale(add(add(verts[t[0]], verts[t[1]]), verts[t[2]]), 1.0 / 3.0);
            assert!(dot(n, sub(c, [0.5; 3])) > 0.0, "outward");
        }
        Occluder::new(&verts, &tris).unwrap()
    }

    /// Points whose first parity ray runs exactly through a corner or along a face diagonal:
    /// that ray is discarded as ambiguous and the other directions decide.
    #[test]
    fn contains_survives_rays_through_corners_and_edges() {
        let occ = unit_cube();
        let d0 = PARITY_DIRECTIONS[0];
        let d0 = scale(d0, 1.0 / norm(d0));
        // Through the corner (1, 1, 1) from inside, through (0, 0, 0) from outside.
        let inside = sub([1.0; 3], scale(d0, 0.3));
        let outside = sub([0.0; 3], scale(d0, 0.3));
        assert!(occ.crossings(inside, d0).is_none() && occ.crossings(outside, d0).is_none());
        assert!(occ.contains(inside));
        assert!(!occ.contains(outside));
        // Through the middle of the edge from (1, 0, 1) to (1, 1, 1), from inside.
        let edge_inside = sub([1.0, 0.5, 1.0], scale(d0, 0.2));
        assert!(occ.crossings(edge_inside, d0).is_none());
        assert!(occ.contains(edge_inside));
        // Generic points.
        assert!(occ.contains([0.3, 0.6, 0.2]));
        assert!(!occ.contains([1.3, 0.6, 0.2]));
        assert_eq!(occ.crossings([0.3, 0.6, 0.2], d0), Some(1));
        assert_eq!(occ.crossings([-0.1, 0.3, -0.3], d0), Some(2));
    }

    #[test]
    fn rounded_distance_in_messages() {
        assert_eq!(round_sig(0.000412345678), 0.0004123);
        let e = LampError::LampTooClose { index: 1, distance: 0.0004, min_distance: 0.001 };
        assert_eq!(
            e.to_string(),
            "lamps[1].position: the lamp is 0.0004 m from the object's surface; it must be at least 0.001 m away"
        );
    }
}
