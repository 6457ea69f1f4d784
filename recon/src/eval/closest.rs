//! Closest points on a triangle surface: the exact point of each triangle nearest to a query
//! (Ericson, *Real-Time Collision Detection*, 5.1.5: Voronoi regions of the vertices, edges and
//! face), with a bounding-volume hierarchy (parry3d-f64's `TriMesh` BVH) to find the nearest
//! triangle. Distances are Euclidean, in metres.

use heatsim::mesh::TriMesh;
use heatsim::vec3::{add, cross, dot, norm, scale, sub};
use parry3d_f64::math::Vector;
use parry3d_f64::query::PointProjection;
use parry3d_f64::shape::TriMesh as ParryTriMesh;

use super::EvalError;

/// The point of a surface nearest to a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Closest {
    /// The nearest point on the surface (m).
    pub point: [f64; 3],
    /// Index of the triangle it lies on (the first found when several are equally near).
    pub face: usize,
    /// Distance from the query point (m).
    pub distance: f64,
}

/// A triangle surface prepared for closest-point queries: its triangles, unit face normals
/// and a BVH over them (built once, queried from many threads).
pub struct SurfaceIndex {
    tris: Vec<[[f64; 3]; 3]>,
    normals: Vec<[f64; 3]>,
    bvh: ParryTriMesh,
}

impl std::fmt::Debug for SurfaceIndex {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SurfaceIndex").field("triangles", &self.tris.len()).finish()
    }
}

impl SurfaceIndex {
    /// Builds the index over `mesh` (which [`TriMesh::try_new`] already checked: non-empty,
    /// finite, indices in range).
    ///
    /// # Errors
    /// [`EvalError::Invalid`] if the mesh has more than 2^32 - 2 vertices or triangles.
    pub fn new(mesh: &TriMesh) -> Result<SurfaceIndex, EvalError> {
        if mesh.verts.len() >= u32::MAX as usize || mesh.tris.len() >= u32::MAX as usize {
            return Err(EvalError::Invalid("the mesh is too large for 32-bit indices".into()));
        }
        let tris: Vec<[[f64; 3]; 3]> = mesh.tris.iter().map(|t| t.map(|i| mesh.verts[i])).collect();
        let normals = (0..mesh.tris.len()).map(|f| mesh.face_normal(f)).collect();
        let verts: Vec<Vector> = mesh.verts.iter().map(|p| Vector::new(p[0], p[1], p[2])).collect();
        let indices: Vec<[u32; 3]> = mesh.tris.iter().map(|t| t.map(|i| i as u32)).collect();
        let bvh = ParryTriMesh::new(verts, indices)
            .map_err(|e| EvalError::Invalid(format!("cannot build the triangle hierarchy: {e:?}")))?;
        Ok(SurfaceIndex { tris, normals, bvh })
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// Always false: meshes have at least one triangle.
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// Unit normal of triangle `f` (right-hand rule; zero for a zero-area triangle).
    pub fn face_normal(&self, f: usize) -> [f64; 3] {
        self.normals[f]
    }

    /// The nearest point of the surface to `p` (m).
    pub fn closest(&self, p: [f64; 3]) -> Closest {
        let q = Vector::new(p[0], p[1], p[2]);
        let found = self.bvh.bvh().project_point(q, f64::MAX, |leaf, _| {
            let c = closest_point_on_triangle(p, &self.tris[leaf as usize]);
            Some(PointProjection::new(false, Vector::new(c[0], c[1], c[2])))
        });
        match found {
            Some((face, (distance, proj))) => {
                Closest { point: [proj.point.x, proj.point.y, proj.point.z], face: face as usize, distance }
            }
            // Only for a non-finite query point: no triangle is nearer than infinity.
            None => Closest { point: [f64::NAN; 3], face: 0, distance: f64::NAN },
        }
    }

    /// Signed distance of `p` to the surface (m): the distance, negative when `p` lies behind
    /// the nearest triangle (on the side its normal points away from).
    pub fn signed_distance(&self, p: [f64; 3]) -> f64 {
        let c = self.closest(p);
        if dot(sub(p, c.point), self.normals[c.face]) < 0.0 {
            -c.distance
        } else {
            c.distance
        }
    }
}

/// The point of triangle `t` (corners in m) nearest to `p` (Ericson 5.1.5).
pub fn closest_point_on_triangle(p: [f64; 3], t: &[[f64; 3]; 3]) -> [f64; 3] {
    let [a, b, c] = *t;
    let ab = sub(b, a);
    let ac = sub(c, a);
    let ap = sub(p, a);
    let d1 = dot(ab, ap);
    let d2 = dot(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = sub(p, b);
    let d3 = dot(ab, bp);
    let d4 = dot(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return add(a, scale(ab, v));
    }
    let cp = sub(p, c);
    let d5 = dot(ab, cp);
    let d6 = dot(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return add(a, scale(ac, w));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return add(b, scale(sub(c, b), w));
    }
    let denom = va + vb + vc;
    if denom == 0.0 || !denom.is_finite() {
        // Degenerate (zero-area) triangle: the nearest of its three edges.
        let seg = |u: [f64; 3], v: [f64; 3]| {
            let d = sub(v, u);
            let l2 = dot(d, d);
            let s = if l2 > 0.0 { (dot(sub(p, u), d) / l2).clamp(0.0, 1.0) } else { 0.0 };
            add(u, scale(d, s))
        };
        let cands = [seg(a, b), seg(b, c), seg(c, a)];
        return *cands.iter().min_by(|x, y| norm(sub(p, **x)).total_cmp(&norm(sub(p, **y)))).unwrap();
    }
    let v = vb / denom;
    let w = vc / denom;
    add(a, add(scale(ab, v), scale(ac, w)))
}

/// Unit normal of a triangle given by its corners (zero for zero area).
pub fn triangle_normal(t: &[[f64; 3]; 3]) -> [f64; 3] {
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    let l = norm(n);
    if l > 0.0 {
        scale(n, 1.0 / l)
    } else {
        [0.0; 3]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force over a dense barycentric grid: the exact closest point is never farther.
    #[test]
    fn triangle_projection_matches_a_dense_search() {
        let t = [[0.0, 0.0, 0.0], [1.0, 0.2, 0.1], [0.3, 0.9, -0.2]];
        let queries = [[0.2, 0.2, 0.5], [2.0, 0.0, 0.0], [-1.0, -1.0, 0.3], [0.5, 1.5, 0.0], [0.7, 0.6, -0.4]];
        for p in queries {
            let c = closest_point_on_triangle(p, &t);
            let dc = norm(sub(p, c));
            let n = 200;
            let mut best = f64::INFINITY;
            for i in 0..=n {
                for j in 0..=(n - i) {
                    let (u, v) = (i as f64 / n as f64, j as f64 / n as f64);
                    let q = add(t[0], add(scale(sub(t[1], t[0]), u), scale(sub(t[2], t[0]), v)));
                    best = best.min(norm(sub(p, q)));
                }
            }
            assert!(dc <= best + 1e-12, "{p:?}: {dc} > {best}");
            assert!(best - dc < 1e-2, "{p:?}: grid {best} vs exact {dc}");
        }
    }

    #[test]
    fn index_finds_the_nearest_triangle() {
        // Two unit squares, one at z = 0 and one at z = 1.
        let verts = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ];
        let tris = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let mesh = TriMesh::try_new(verts, tris).unwrap();
        let idx = SurfaceIndex::new(&mesh).unwrap();
        let c = idx.closest([0.25, 0.75, 0.3]);
        assert!((c.distance - 0.3).abs() < 1e-15);
        assert_eq!(c.face, 1);
        let c = idx.closest([0.9, 0.1, 0.8]);
        assert!((c.distance - 0.2).abs() < 1e-15);
        assert_eq!(c.face, 2);
        assert!((idx.signed_distance([0.5, 0.5, -0.1]) + 0.1).abs() < 1e-15);
    }
}
