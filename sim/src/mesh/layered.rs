//! Walls meshed in prism layers: the material under a surface, down to a wall thickness d
//! measured along the surface normal, cut into `n` layers of prisms and each prism into 14
//! tetrahedra. Thin walls are resolved through their thickness this way without shrinking the
//! elements along the surface (a 1 mm wall with 2 mm TetGen elements has no interior node).
//!
//! Nodes: `q(k, v) = p_v - s_k ν_v`, k = 0 (the surface itself) to n (the inner face), with
//! `ν_v` the unit vertex normal (the sum of the adjacent faces' unit normals weighted by their
//! corner angles, [`vertex_normals`]) and the interface depths
//! `s_k = d (g^k - 1) / (g^n - 1)` (`s_k = d k / n` for g = 1), `g = R^(1 / (n - 1))`: each
//! layer is g times as thick as the one outside it and the innermost R times the outermost,
//! so all layers shrink as n grows (a fixed g would leave the inner layers coarse).
//!
//! Prisms: a surface triangle (a, b, c) and a layer k give the prism with top `(a, b, c)_k` and
//! bottom `(a, b, c)_(k+1)`. Each prism is split symmetrically: a node at its centroid, one at
//! the centre of each side quad (shared with the neighbouring prism, so the mesh conforms), and
//! 14 tetrahedra from the centroid to the top and bottom triangles and to the four triangles of
//! each quad around its centre. (A split into three tetrahedra, quad diagonals by a rule of the
//! edge, needs no extra nodes, but a node lies in 3, 2 or 1 of a prism's tetrahedra by its rank
//! in the triangle: a field varying only through the wall is not reproduced, and with layers much
//! thinner than wide the face carries a node-to-node pattern; docs/notes/forward-model.md.)
//!
//! Validity: with the surface triangle counter-clockwise seen from outside and the layers
//! going inward, every tetrahedron of the split is positive; a negative one or one of
//! (numerically) zero volume means the offset folded (a wall thicker than the surface's radius
//! of curvature allows), and so does an inner face that crosses itself. Both are refused.
//!
//! Tags: faces of layer 0 are the outer surface (visible where the outward normal has
//! n_z > 0, towards the camera, else back), faces of layer n the inner face (`inner_tag`), and
//! the quads over the surface's own boundary edges (the rim of an open surface) `rim_tag`.
//! Region attribute of a tetrahedron: its layer + 1 (1 = the layer under the surface).

use crate::mesh::tetmesh::{FaceTag, TetMesh};
use crate::mesh::trimesh::TriMesh;
use crate::tetgen::{MeshingError, TetgenOutput};
use crate::vec3::{add, cross, dot, norm, scale, sub, unit};
use std::collections::HashMap;

/// A tetrahedron of a layered wall with a volume below `DEGENERATE_REL` times its layer's
/// thickness x (longest edge of its surface triangle)^2 counts as degenerate (dimensionless).
const DEGENERATE_REL: f64 = 1e-9;

/// How the wall under a surface is layered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Layering {
    /// Wall thickness along the normal, in m (> 0).
    pub thickness: f64,
    /// Prism layers through the wall (>= 1).
    pub layers: usize,
    /// Thickness R of the innermost layer over the outermost (>= 1; 1: equal layers).
    pub ratio: f64,
    /// Tag of the inner face (layer n): [`FaceTag::Cavity`] inside a closed shell,
    /// [`FaceTag::Back`] under an open one.
    pub inner_tag: FaceTag,
    /// Tag of the rim quads over the boundary edges of an open surface.
    pub rim_tag: FaceTag,
}

/// Why a layered wall could not be built.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LayeredError {
    /// The thickness or layer count is out of range.
    #[error("{field}: {message}")]
    Invalid { field: &'static str, message: String },
    /// The offset folded: the wall is too thick for the surface's curvature there.
    #[error("object.thickness: a wall of {thickness} m does not fit under the surface: {what} (the surface curves more tightly than the wall is thick there, or two parts are closer than twice the wall); use a thinner wall or construction \"relief\"")]
    Folded { thickness: f64, what: String },
    /// The tetrahedra did not make a valid mesh.
    #[error(transparent)]
    Mesh(#[from] MeshingError),
}

/// Unit vertex normals of `surface`: the adjacent faces' unit normals weighted by their corner
/// angles at the vertex (dimensionless). A vertex no face uses gets [0, 0, 0].
pub fn vertex_normals(surface: &TriMesh) -> Vec<[f64; 3]> {
    let mut acc = vec![[0.0; 3]; surface.verts.len()];
    for t in &surface.tris {
        let p = t.map(|i| surface.verts[i]);
        let Some(n) = unit(cross(sub(p[1], p[0]), sub(p[2], p[0]))) else { continue };
        for c in 0..3 {
            let e1 = sub(p[(c + 1) % 3], p[c]);
            let e2 = sub(p[(c + 2) % 3], p[c]);
            let angle = norm(cross(e1, e2)).atan2(dot(e1, e2));
            acc[t[c]] = add(acc[t[c]], scale(n, angle));
        }
    }
    acc.into_iter().map(|a| unit(a).unwrap_or([0.0; 3])).collect()
}

/// The wall under `surface` (outward, counter-clockwise seen from outside; closed or with a
/// rim) offset along `normals` (one unit vector per vertex, outward), layered as `layering`
/// says (module documentation).
///
/// # Errors
/// [`LayeredError::Invalid`] for a thickness or layer count out of range or normals of the
/// wrong length; [`LayeredError::Folded`] when a prism inverts or the inner face crosses
/// itself.
pub fn layered_wall(surface: &TriMesh, normals: &[[f64; 3]], layering: &Layering) -> Result<TetMesh, LayeredError> {
    let Layering { thickness: d, layers: n, ratio, inner_tag, rim_tag } = *layering;
    if !(d.is_finite() && d > 0.0) {
        return Err(LayeredError::Invalid { field: "object.thickness", message: format!("must be > 0 m, got {d}") });
    }
    if n == 0 {
        return Err(LayeredError::Invalid { field: "meshing.wall_layers", message: "must be >= 1, got 0".into() });
    }
    if !(ratio.is_finite() && ratio >= 1.0) {
        return Err(LayeredError::Invalid {
            field: "meshing.wall_layer_ratio",
            message: format!("must be >= 1, got {ratio}"),
        });
    }
    if normals.len() != surface.verts.len() {
        return Err(LayeredError::Invalid {
            field: "normals",
            message: format!("{} normals for {} vertices", normals.len(), surface.verts.len()),
        });
    }
    let nv = surface.verts.len();
    let node = |k: usize, v: usize| k * nv + v;
    let mut points = Vec::with_capacity(nv * (n + 1));
    let depths = interface_depths(d, n, ratio);
    for &depth in &depths {
        points.extend(surface.verts.iter().zip(normals).map(|(&p, &nu)| sub(p, scale(nu, depth))));
    }
    // The centre node of the side quad over edge (u, v) in layer k, made on first use.
    let mut quad_centres: HashMap<(usize, usize, usize), usize> = HashMap::new();
    let mut quad_centre = |points: &mut Vec<[f64; 3]>, k: usize, u: usize, v: usize| {
        *quad_centres.entry((k, u.min(v), u.max(v))).or_insert_with(|| {
            let c = [node(k, u), node(k, v), node(k + 1, u), node(k + 1, v)]
                .iter()
                .fold([0.0; 3], |a, &i| add(a, points[i]));
            points.push(scale(c, 0.25));
            points.len() - 1
        })
    };
    let templates = symmetric_templates();
    let mut tets = Vec::with_capacity(14 * n * surface.tris.len());
    let mut tet_region = Vec::with_capacity(tets.capacity());
    for (f, t) in surface.tris.iter().enumerate() {
        let edge = [0, 1, 2]
            .map(|i| norm(sub(surface.verts[t[i]], surface.verts[t[(i + 1) % 3]])))
            .into_iter()
            .fold(0.0, f64::max);
        for k in 0..n {
            let min_volume = DEGENERATE_REL * (depths[k + 1] - depths[k]) * edge * edge;
            let folded = || LayeredError::Folded {
                thickness: d,
                what: format!("the prism under surface face {f} in layer {} inverts", k + 1),
            };
            let mut local = [0usize; 10];
            for i in 0..3 {
                local[i] = node(k, t[i]);
                local[i + 3] = node(k + 1, t[i]);
                local[i + 7] = quad_centre(&mut points, k, t[i], t[(i + 1) % 3]);
            }
            let c = local[..6].iter().fold([0.0; 3], |a, &i| add(a, points[i]));
            points.push(scale(c, 1.0 / 6.0));
            local[6] = points.len() - 1;
            for tpl in &templates {
                let tet = tpl.map(|i| local[i]);
                if crate::mesh::tetmesh::tet_signed_volume(tet.map(|i| points[i])) <= min_volume {
                    return Err(folded());
                }
                tets.push(tet);
                tet_region.push(k as i32 + 1);
            }
        }
    }
    let inner = TriMesh { verts: points[node(n, 0)..node(n, 0) + nv].to_vec(), tris: surface.tris.clone() };
    if let Some(&[i, j]) = inner.self_intersections(1).first() {
        return Err(LayeredError::Folded {
            thickness: d,
            what: format!("the inner face crosses itself (faces {i} and {j})"),
        });
    }
    let mut marked_faces = Vec::with_capacity(2 * surface.tris.len());
    for (f, t) in surface.tris.iter().enumerate() {
        let outer = if surface.face_normal(f)[2] > 0.0 { FaceTag::Visible } else { FaceTag::Back };
        marked_faces.push((*t, outer.marker()));
        marked_faces.push((t.map(|v| node(n, v)), inner_tag.marker()));
    }
    for [u, v] in surface.boundary_edges() {
        let (u, v) = (u.min(v), u.max(v));
        for k in 0..n {
            let (u0, v0, u1, v1) = (node(k, u), node(k, v), node(k + 1, u), node(k + 1, v));
            let q = quad_centres[&(k, u, v)];
            for tri in [[u0, v0, q], [v0, v1, q], [v1, u1, q], [u1, u0, q]] {
                marked_faces.push((tri, rim_tag.marker()));
            }
        }
    }
    Ok(TetMesh::from_tetgen(TetgenOutput { points, tets, tet_region, marked_faces })?)
}

/// The depths s_0 = 0 < s_1 < ... < s_n = d of the layer interfaces (m) of `n` layers whose
/// innermost is `ratio` times as thick as the outermost (module documentation).
pub fn interface_depths(d: f64, n: usize, ratio: f64) -> Vec<f64> {
    let growth = if n > 1 { ratio.powf(1.0 / (n - 1) as f64) } else { 1.0 };
    (0..=n)
        .map(|k| {
            if k == n {
                d
            } else if growth == 1.0 {
                d * k as f64 / n as f64
            } else {
                d * (growth.powi(k as i32) - 1.0) / (growth.powi(n as i32) - 1.0)
            }
        })
        .collect()
}

/// The 14 tetrahedra of a prism split symmetrically, as indices into its local nodes: 0, 1, 2
/// the top (the surface triangle's corners in order), 3, 4, 5 the bottom, 6 the centroid, 7, 8,
/// 9 the centres of the side quads over edges (0, 1), (1, 2), (2, 0). Each is oriented to be
/// positive on an unfolded prism (checked on the right prism over the unit triangle).
fn symmetric_templates() -> Vec<[usize; 4]> {
    let mut canonical = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0; 3],
        [0.0; 3],
        [0.0; 3],
        [0.0; 3],
        [0.0; 3],
        [0.0; 3],
        [0.0; 3],
    ];
    for i in 0..3 {
        canonical[i + 3] = sub(canonical[i], [0.0, 0.0, 1.0]);
    }
    canonical[6] = scale(canonical[..6].iter().fold([0.0; 3], |a, &p| add(a, p)), 1.0 / 6.0);
    for i in 0..3 {
        let j = (i + 1) % 3;
        canonical[i + 7] = scale(add(add(canonical[i], canonical[j]), add(canonical[i + 3], canonical[j + 3])), 0.25);
    }
    let mut out = vec![[0, 1, 2, 6], [3, 4, 5, 6]];
    for i in 0..3 {
        let (j, q) = ((i + 1) % 3, i + 7);
        out.extend([[i, j, q, 6], [j, j + 3, q, 6], [j + 3, i + 3, q, 6], [i + 3, i, q, 6]]);
    }
    for t in &mut out {
        if crate::mesh::tetmesh::tet_signed_volume(t.map(|i| canonical[i])) < 0.0 {
            t.swap(0, 1);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn octahedron() -> TriMesh {
        let verts = vec![
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ];
        let tris = vec![[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]];
        TriMesh { verts, tris }
    }

    #[test]
    fn interface_depths_grow_geometrically() {
        let s = interface_depths(7e-3, 3, 4.0);
        for (got, want) in s.iter().zip([0.0, 1e-3, 3e-3, 7e-3]) {
            assert!((got - want).abs() < 1e-15, "{s:?}");
        }
        assert_eq!(interface_depths(1.0, 4, 1.0), vec![0.0, 0.25, 0.5, 0.75, 1.0]);
    }

    #[test]
    fn a_closed_wall_conforms_and_has_the_frustum_volume() {
        let s = octahedron();
        // Radial normals: every layer is the octahedron scaled by (1 - depth).
        let normals: Vec<[f64; 3]> = s.verts.clone();
        let layering =
            Layering { thickness: 0.3, layers: 3, ratio: 1.0, inner_tag: FaceTag::Cavity, rim_tag: FaceTag::Side };
        let m = layered_wall(&s, &normals, &layering).unwrap();
        assert_eq!(m.tets.len(), 14 * 3 * 8);
        // A conforming mesh of a closed wall has exactly the outer and inner faces as boundary.
        assert_eq!(m.boundary.len(), 16);
        let outer = 4.0 / 3.0;
        let expected = outer * (1.0 - 0.7_f64.powi(3));
        assert!((m.volume() - expected).abs() < 1e-12, "{} vs {expected}", m.volume());
        assert!((m.stats().boundary_volume_m3 - expected).abs() < 1e-12);
        assert_eq!(m.boundary_tag.iter().filter(|&&t| t == FaceTag::Cavity).count(), 8);
        assert_eq!(m.boundary_tag.iter().filter(|&&t| t == FaceTag::Visible).count(), 4);
    }

    #[test]
    fn an_open_wall_has_its_rim() {
        // The upper half of the octahedron: 4 faces, a square rim.
        let mut s = octahedron();
        s.tris.truncate(4);
        let normals: Vec<[f64; 3]> = s.verts.clone();
        let layering =
            Layering { thickness: 0.2, layers: 2, ratio: 2.0, inner_tag: FaceTag::Back, rim_tag: FaceTag::Side };
        let m = layered_wall(&s, &normals, &layering).unwrap();
        let rim = m.boundary_tag.iter().filter(|&&t| t == FaceTag::Side).count();
        // Four triangles a rim quad.
        assert_eq!(rim, 4 * 2 * 4);
        assert_eq!(m.boundary.len(), 4 + 4 + rim);
        assert!((m.stats().boundary_volume_m3 - m.volume()).abs() < 1e-12);
    }

    #[test]
    fn a_wall_thicker_than_the_body_is_refused() {
        let s = octahedron();
        let normals: Vec<[f64; 3]> = s.verts.clone();
        let layering =
            Layering { thickness: 1.5, layers: 2, ratio: 1.0, inner_tag: FaceTag::Cavity, rim_tag: FaceTag::Side };
        let e = layered_wall(&s, &normals, &layering).unwrap_err();
        assert!(matches!(e, LayeredError::Folded { .. }), "{e}");
        assert!(e.to_string().starts_with("object.thickness:"), "{e}");
    }
}
