//! A relief extruded away from the camera: the cuboid plate and the visible relief of a mesh.
//!
//! Given a simple polygon P in the xy-plane (the silhouette seen from +z) and a height
//! function z = f(x, y) on it (the visible surface), the solid is
//!
//! { (x, y, z) : (x, y) in P, f(x, y) - d <= z <= f(x, y) },
//!
//! i.e. every point of the visible surface has exactly `d` metres of material straight below
//! it along the viewing axis (paper Sec. 4: "uniform thickness directly below the surface").
//!
//! P is triangulated once with Triangle (quality, target edge `h`); the visible surface, the
//! internal interface at the fine-layer depth and the back surface are copies of that
//! triangulation lowered by 0, `s1` and `d`. Side walls are one planar polygon per edge of P
//! and per layer, so tall walls stay cheap. The fine layer (0 to `s1`) gets tetrahedra of about
//! edge `h`; the deep layer a coarser bound, and TetGen grades in between.

use super::plc::{regular_tet_volume, Facet, Plc, Region};
use super::{Grading, SolidError};
use crate::mesh::tetmesh::FaceTag;
use crate::mesh::trimesh::TriMesh;
use std::sync::Mutex;

/// Triangle (like TetGen) keeps global state: one call at a time per process.
static TRIANGLE_LOCK: Mutex<()> = Mutex::new(());

/// A quality triangulation of a simple polygon.
pub struct PolygonMesh {
    /// #N x 2 points (m); the first `outline.len()` are the polygon's corners.
    pub points: Vec<[f64; 2]>,
    /// #F x 3 counter-clockwise triangles.
    pub tris: Vec<[usize; 3]>,
    /// For each polygon edge e (from corner e to corner e+1), the points along it in order,
    /// both corners included.
    pub edge_points: Vec<Vec<usize>>,
}

/// Signed area of a polygon (m^2), positive when counter-clockwise.
pub fn polygon_area(poly: &[[f64; 2]]) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

/// Checks that `poly` is a simple counter-clockwise polygon with at least 3 corners and no
/// zero-length edges. Quadratic in the number of corners (a few hundred here).
pub fn check_simple_polygon(poly: &[[f64; 2]]) -> Result<(), String> {
    let n = poly.len();
    if n < 3 {
        return Err(format!("the outline has {n} corners; at least 3 are needed"));
    }
    if polygon_area(poly) <= 0.0 {
        return Err("the outline is not counter-clockwise or has zero area".into());
    }
    let seg = |i: usize| (poly[i], poly[(i + 1) % n]);
    for i in 0..n {
        let (a, b) = seg(i);
        if a == b {
            return Err(format!("outline edge {i} has zero length"));
        }
        for j in i + 1..n {
            if j == i + 1 || (i == 0 && j == n - 1) {
                continue; // neighbours share a corner
            }
            let (c, d) = seg(j);
            if segments_intersect(a, b, c, d) {
                return Err(format!("outline edges {i} and {j} cross"));
            }
        }
    }
    Ok(())
}

fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn segments_intersect(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (d1, d2) = (orient(c, d, a), orient(c, d, b));
    let (d3, d4) = (orient(a, b, c), orient(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0)) && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0)) {
        return true;
    }
    let on = |p: [f64; 2], q: [f64; 2], r: [f64; 2]| {
        orient(p, q, r) == 0.0
            && r[0] >= p[0].min(q[0])
            && r[0] <= p[0].max(q[0])
            && r[1] >= p[1].min(q[1])
            && r[1] <= p[1].max(q[1])
    };
    on(c, d, a) || on(c, d, b) || on(a, b, c) || on(a, b, d)
}

/// Quality-triangulates a simple counter-clockwise polygon with target edge length `h` (m)
/// and a 28 degree minimum angle.
///
/// # Errors
/// [`SolidError::Construction`] if the polygon is not simple or Triangle fails.
pub fn triangulate_polygon(outline: &[[f64; 2]], h: f64) -> Result<PolygonMesh, SolidError> {
    check_simple_polygon(outline).map_err(SolidError::Construction)?;
    let n = outline.len();
    let _guard = TRIANGLE_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let err = |e: &str| SolidError::Construction(format!("Triangle failed: {e}"));
    let mut tg = tritet::Trigen::new(n, Some(n), None, None).map_err(err)?;
    for (i, p) in outline.iter().enumerate() {
        tg.set_point(i, 0, p[0], p[1]).map_err(err)?;
    }
    for i in 0..n {
        // Segment markers are 1-based edge ids; Triangle keeps them on subdivided segments.
        tg.set_segment(i, i as i32 + 1, i, (i + 1) % n).map_err(err)?;
    }
    let max_area = 3f64.sqrt() / 4.0 * h * h;
    tg.generate_mesh(false, false, true, Some(max_area), Some(28.0)).map_err(err)?;
    let points: Vec<[f64; 2]> = (0..tg.out_npoint()).map(|i| [tg.out_point(i, 0), tg.out_point(i, 1)]).collect();
    if points.len() < 3 || tg.out_ncell() == 0 {
        return Err(SolidError::Construction("Triangle produced an empty triangulation".into()));
    }
    let mut tris: Vec<[usize; 3]> = (0..tg.out_ncell())
        .map(|c| [tg.out_cell_point(c, 0), tg.out_cell_point(c, 1), tg.out_cell_point(c, 2)])
        .collect();
    for t in &mut tris {
        if orient(points[t[0]], points[t[1]], points[t[2]]) < 0.0 {
            t.swap(1, 2);
        }
    }
    // Collect the subdivided boundary segments per original edge, then order them.
    let mut on_edge: Vec<Vec<usize>> = vec![Vec::new(); n];
    for s in 0..tg.out_nsegment() {
        let m = tg.out_segment_marker(s);
        if m >= 1 && (m as usize) <= n {
            on_edge[m as usize - 1].push(tg.out_segment_point(s, 0));
            on_edge[m as usize - 1].push(tg.out_segment_point(s, 1));
        }
    }
    // Triangle keeps input points first, so corner i is output point i.
    for (i, p) in outline.iter().enumerate() {
        if points[i] != *p {
            return Err(SolidError::Construction(format!("Triangle renumbered outline corner {i}")));
        }
    }
    let mut edge_points = Vec::with_capacity(n);
    for (e, pts) in on_edge.iter_mut().enumerate() {
        let (a, b) = (outline[e], outline[(e + 1) % n]);
        let dir = [b[0] - a[0], b[1] - a[1]];
        let param = |p: [f64; 2]| (p[0] - a[0]) * dir[0] + (p[1] - a[1]) * dir[1];
        pts.push(e);
        pts.push((e + 1) % n);
        pts.sort_unstable();
        pts.dedup();
        pts.sort_by(|&i, &j| param(points[i]).total_cmp(&param(points[j])));
        if pts.first() != Some(&e) || pts.last() != Some(&((e + 1) % n)) {
            return Err(SolidError::Construction(format!("could not recover outline edge {e} from Triangle's output")));
        }
        edge_points.push(pts.clone());
    }
    Ok(PolygonMesh { points, tris, edge_points })
}

/// Builds the PLC of the relief `top` over `outline` extruded by `thickness` along -z.
///
/// `top(x, y)` is the height of the visible surface (m). Returns the PLC and the exact volume
/// of the piecewise-linear solid (area of the outline times the thickness).
pub fn extrude(
    outline: &[[f64; 2]],
    top: &dyn Fn(f64, f64) -> f64,
    thickness: f64,
    grading: &Grading,
) -> Result<(Plc, f64), SolidError> {
    let pm = triangulate_polygon(outline, grading.surface_element_size)?;
    let n = pm.points.len();
    let heights: Vec<f64> = pm.points.iter().map(|p| top(p[0], p[1])).collect();
    if let Some(i) = heights.iter().position(|z| !z.is_finite()) {
        return Err(SolidError::Construction(format!("the surface height at {:?} is not finite", pm.points[i])));
    }
    // Layer depths below the visible surface: 0, (fine layer), thickness.
    let mut depths = vec![0.0];
    if grading.fine_layer_depth < 0.75 * thickness {
        depths.push(grading.fine_layer_depth);
    }
    depths.push(thickness);
    let mut plc = Plc::default();
    for &s in &depths {
        for (p, z) in pm.points.iter().zip(&heights) {
            plc.push_point([p[0], p[1], z - s]);
        }
    }
    let last = depths.len() - 1;
    for (layer, _) in depths.iter().enumerate() {
        let tag = match layer {
            0 => FaceTag::Visible,
            l if l == last => FaceTag::Back,
            _ => FaceTag::Interface,
        };
        for t in &pm.tris {
            let mut f = t.map(|i| layer * n + i);
            if tag == FaceTag::Back {
                f.swap(1, 2); // outward = -z
            }
            plc.facets.push(Facet { points: f.to_vec(), tag });
        }
    }
    for band in 0..last {
        for along in &pm.edge_points {
            let mut poly: Vec<usize> = along.iter().map(|&i| band * n + i).collect();
            poly.extend(along.iter().rev().map(|&i| (band + 1) * n + i));
            plc.facets.push(Facet { points: poly, tag: FaceTag::Side });
        }
    }
    // A region point per band above the centroid of the largest triangle.
    let big = (0..pm.tris.len())
        .max_by(|&a, &b| tri_area2(&pm, a).total_cmp(&tri_area2(&pm, b)))
        .expect("non-empty triangulation");
    let t = pm.tris[big];
    let cx = t.iter().map(|&i| pm.points[i][0]).sum::<f64>() / 3.0;
    let cy = t.iter().map(|&i| pm.points[i][1]).sum::<f64>() / 3.0;
    let cz = t.iter().map(|&i| heights[i]).sum::<f64>() / 3.0;
    for band in 0..last {
        let mid = 0.5 * (depths[band] + depths[band + 1]);
        let h = if band == 0 { grading.surface_element_size } else { grading.deep_element_size };
        plc.regions.push(Region {
            point: [cx, cy, cz - mid],
            attribute: band as i32 + 1,
            max_volume: Some(regular_tet_volume(h)),
        });
    }
    let volume = polygon_area(outline) * thickness;
    Ok((plc, volume))
}

fn tri_area2(pm: &PolygonMesh, t: usize) -> f64 {
    let [a, b, c] = pm.tris[t].map(|i| pm.points[i]);
    orient(a, b, c)
}

/// The visible surface of an extrusion as a triangle mesh (for previews and the surface
/// solver): the triangulated outline lifted onto `top`.
pub fn relief_surface(outline: &[[f64; 2]], top: &dyn Fn(f64, f64) -> f64, h: f64) -> Result<TriMesh, SolidError> {
    let pm = triangulate_polygon(outline, h)?;
    let verts = pm.points.iter().map(|p| [p[0], p[1], top(p[0], p[1])]).collect();
    Ok(TriMesh { verts, tris: pm.tris })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crossing_outline_is_rejected() {
        let bowtie = [[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]];
        assert!(check_simple_polygon(&bowtie).is_err());
        let square = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        assert!(check_simple_polygon(&square).is_ok());
        let cw: Vec<_> = square.iter().rev().copied().collect();
        assert!(check_simple_polygon(&cw).is_err());
    }

    #[test]
    fn square_triangulation_covers_the_square_and_keeps_edges() {
        let square = [[0.0, 0.0], [0.1, 0.0], [0.1, 0.05], [0.0, 0.05]];
        let pm = triangulate_polygon(&square, 0.01).unwrap();
        let area: f64 = pm.tris.iter().map(|t| orient(pm.points[t[0]], pm.points[t[1]], pm.points[t[2]]) / 2.0).sum();
        assert!((area - 0.005).abs() < 1e-15);
        assert_eq!(pm.edge_points.len(), 4);
        // The bottom edge (length 0.1) at h = 0.01 is split into several segments, all on y = 0.
        assert!(pm.edge_points[0].len() >= 10);
        assert!(pm.edge_points[0].iter().all(|&i| pm.points[i][1] == 0.0));
    }
}
