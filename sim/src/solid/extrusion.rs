//! A relief extruded away from the camera: the cuboid plate and the visible relief of a mesh.
//!
//! Given a region P of the xy-plane (the silhouette seen from +z: one or more parts, each a
//! simple polygon with simple polygonal holes) and a height function z = f(x, y) on it (the
//! visible surface), the solid is
//!
//! { (x, y, z) : (x, y) in P, f(x, y) - d <= z <= f(x, y) },
//!
//! i.e. every point of the visible surface has exactly `d` metres of material straight below
//! it along the viewing axis (paper Sec. 4: "uniform thickness directly below the surface").
//!
//! Each part is triangulated once with Triangle (quality, target edge `h`); the visible
//! surface, the internal interface at the fine-layer depth and the back surface are copies of
//! that triangulation lowered by 0, `s1` and `d`. The side walls are triangles: two per boundary
//! segment and layer. A triangle is planar whatever the rounding of its corners, whereas one
//! polygon per outline edge holds points that are collinear only to rounding, which TetGen's
//! facet triangulation turns into slivers and then fails on (`sscoutsegment` assertions). The
//! fine layer (0 to `s1`) gets tetrahedra of about edge `h`; the deep layer a coarser bound, and
//! TetGen grades in between. Parts are separate solids in one complex.

use super::plc::{regular_tet_volume, Facet, Plc, Region};
use super::{Grading, SolidError};
use crate::mesh::tetmesh::FaceTag;
use std::sync::Mutex;

/// Triangle (like TetGen) keeps global state: one call at a time per process.
static TRIANGLE_LOCK: Mutex<()> = Mutex::new(());

/// One connected part of a silhouette: a counter-clockwise outer polygon and clockwise holes.
#[derive(Clone, Debug, PartialEq)]
pub struct Outline {
    pub outer: Vec<[f64; 2]>,
    pub holes: Vec<Vec<[f64; 2]>>,
}

impl Outline {
    /// A polygon without holes.
    pub fn simple(outer: Vec<[f64; 2]>) -> Outline {
        Outline { outer, holes: Vec::new() }
    }

    /// Area of the part: the outer polygon's minus its holes' (m^2).
    pub fn area(&self) -> f64 {
        polygon_area(&self.outer) + self.holes.iter().map(|h| polygon_area(h)).sum::<f64>()
    }

    /// The outer polygon, then the holes.
    fn loops(&self) -> impl Iterator<Item = &Vec<[f64; 2]>> {
        std::iter::once(&self.outer).chain(&self.holes)
    }
}

/// A quality triangulation of one part (a polygon with holes).
pub struct PolygonMesh {
    /// #N x 2 points (m); the loops' corners come first, in order (outer, then each hole).
    pub points: Vec<[f64; 2]>,
    /// #F x 3 counter-clockwise triangles.
    pub tris: Vec<[usize; 3]>,
    /// For each loop edge (outer then holes, from corner e to corner e+1 of its loop), the
    /// points along it in order, both corners included.
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
/// zero-length edges.
pub fn check_simple_polygon(poly: &[[f64; 2]]) -> Result<(), String> {
    check_outlines(&[Outline::simple(poly.to_vec())])
}

/// Checks what the extrusion needs of its parts: every loop has at least 3 corners and no
/// zero-length edge, outer loops are counter-clockwise and holes clockwise, and no two edges
/// of any loops of any parts cross or touch (except neighbours at their shared corner). A
/// sweep over x keeps it near-linear for outlines of thousands of corners.
///
/// # Errors
/// A message naming the part, loop and edges.
pub fn check_outlines(parts: &[Outline]) -> Result<(), String> {
    // (part, loop, edge, loop length, a, b)
    let mut segs: Vec<(usize, usize, usize, usize, [f64; 2], [f64; 2])> = Vec::new();
    for (p, part) in parts.iter().enumerate() {
        for (l, lp) in part.loops().enumerate() {
            let n = lp.len();
            let what = if l == 0 { format!("part {p}'s outline") } else { format!("part {p}'s hole {l}") };
            if n < 3 {
                return Err(format!("{what} has {n} corners; at least 3 are needed"));
            }
            let area = polygon_area(lp);
            if (l == 0 && area <= 0.0) || (l > 0 && area >= 0.0) {
                let want = if l == 0 { "counter-clockwise" } else { "clockwise" };
                return Err(format!("{what} is not {want} or has zero area"));
            }
            for e in 0..n {
                let (a, b) = (lp[e], lp[(e + 1) % n]);
                if a == b {
                    return Err(format!("{what}: edge {e} has zero length"));
                }
                segs.push((p, l, e, n, a, b));
            }
        }
    }
    segs.sort_by(|s, t| s.4[0].min(s.5[0]).total_cmp(&t.4[0].min(t.5[0])));
    for i in 0..segs.len() {
        let (p, l, e, n, a, b) = segs[i];
        let x_hi = a[0].max(b[0]);
        for &(q, m, f, _, c, d) in &segs[i + 1..] {
            if c[0].min(d[0]) > x_hi {
                break;
            }
            let neighbours = p == q && l == m && ((e + 1) % n == f || (f + 1) % n == e);
            if !neighbours && segments_intersect(a, b, c, d) {
                return Err(format!(
                    "edge {e} of loop {l} of part {p} and edge {f} of loop {m} of part {q} cross or touch \
                     (loop 0 is a part's outline, the others its holes)"
                ));
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

/// Quality-triangulates one part with target edge length `h` (m) and a 28 degree minimum
/// angle; with `h = None`, without added points (no quality bound).
///
/// # Errors
/// [`SolidError::Construction`] if the part is not valid ([`check_outlines`]) or Triangle fails.
pub fn triangulate(part: &Outline, h: Option<f64>) -> Result<PolygonMesh, SolidError> {
    check_outlines(std::slice::from_ref(part)).map_err(SolidError::Construction)?;
    // A point inside each hole, from a plain triangulation of the hole alone.
    let hole_points: Vec<[f64; 2]> = part
        .holes
        .iter()
        .map(|hole| {
            let ccw: Vec<[f64; 2]> = hole.iter().rev().copied().collect();
            let pm = triangulate(&Outline::simple(ccw), None)?;
            let big = (0..pm.tris.len()).max_by(|&a, &b| tri_area2(&pm, a).total_cmp(&tri_area2(&pm, b)));
            let t = pm.tris[big.expect("non-empty triangulation")];
            Ok([0, 1].map(|k| t.iter().map(|&i| pm.points[i][k]).sum::<f64>() / 3.0))
        })
        .collect::<Result<_, SolidError>>()?;
    let corners: Vec<[f64; 2]> = part.loops().flatten().copied().collect();
    // The first corner of each loop, and one past its last.
    let mut starts = vec![0];
    for lp in part.loops() {
        starts.push(starts.last().unwrap() + lp.len());
    }
    let n = corners.len();
    let _guard = TRIANGLE_LOCK.lock().unwrap_or_else(|e| e.into_inner());
    let err = |e: &str| SolidError::Construction(format!("Triangle failed: {e}"));
    let mut tg = tritet::Trigen::new(n, Some(n), None, Some(hole_points.len())).map_err(err)?;
    for (i, p) in corners.iter().enumerate() {
        tg.set_point(i, 0, p[0], p[1]).map_err(err)?;
    }
    // Edge e of the loop starting at corner s runs from corner s + e to the next in its loop.
    let next = |i: usize| {
        let l = starts.iter().rposition(|&s| s <= i).unwrap();
        if i + 1 == starts[l + 1] {
            starts[l]
        } else {
            i + 1
        }
    };
    for i in 0..n {
        // Segment markers are 1-based edge ids; Triangle keeps them on subdivided segments.
        tg.set_segment(i, i as i32 + 1, i, next(i)).map_err(err)?;
    }
    for (k, p) in hole_points.iter().enumerate() {
        tg.set_hole(k, p[0], p[1]).map_err(err)?;
    }
    let max_area = h.map(|h| 3f64.sqrt() / 4.0 * h * h);
    tg.generate_mesh(false, false, h.is_some(), max_area, h.map(|_| 28.0)).map_err(err)?;
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
    for (i, p) in corners.iter().enumerate() {
        if points[i] != *p {
            return Err(SolidError::Construction(format!("Triangle renumbered outline corner {i}")));
        }
    }
    let mut edge_points = Vec::with_capacity(n);
    for (e, pts) in on_edge.iter_mut().enumerate() {
        let (a, b) = (corners[e], corners[next(e)]);
        let dir = [b[0] - a[0], b[1] - a[1]];
        let param = |p: [f64; 2]| (p[0] - a[0]) * dir[0] + (p[1] - a[1]) * dir[1];
        pts.push(e);
        pts.push(next(e));
        pts.sort_unstable();
        pts.dedup();
        pts.sort_by(|&i, &j| param(points[i]).total_cmp(&param(points[j])));
        if pts.first() != Some(&e) || pts.last() != Some(&next(e)) {
            return Err(SolidError::Construction(format!("could not recover outline edge {e} from Triangle's output")));
        }
        edge_points.push(pts.clone());
    }
    Ok(PolygonMesh { points, tris, edge_points })
}

/// Builds the PLC of the relief `top` over the parts `parts` extruded by `thickness` along -z.
///
/// `top(x, y)` is the height of the visible surface (m). Returns the PLC and the exact volume
/// of the piecewise-linear solid (the parts' area times the thickness).
///
/// # Errors
/// [`SolidError::Construction`] if the parts are not valid together ([`check_outlines`]), a
/// triangulation fails or a height is not finite.
pub fn extrude(
    parts: &[Outline],
    top: &dyn Fn(f64, f64) -> f64,
    thickness: f64,
    grading: &Grading,
) -> Result<(Plc, f64), SolidError> {
    check_outlines(parts).map_err(SolidError::Construction)?;
    // Layer depths below the visible surface: 0, (fine layer), thickness.
    let mut depths = vec![0.0];
    if grading.fine_layer_depth < 0.75 * thickness {
        depths.push(grading.fine_layer_depth);
    }
    depths.push(thickness);
    let mut plc = Plc::default();
    for part in parts {
        let pm = triangulate(part, Some(grading.surface_element_size))?;
        extrude_part(&mut plc, &pm, top, &depths, grading)?;
    }
    let volume = parts.iter().map(Outline::area).sum::<f64>() * thickness;
    Ok((plc, volume))
}

/// Appends one triangulated part, lowered to each of `depths`, to `plc`.
fn extrude_part(
    plc: &mut Plc,
    pm: &PolygonMesh,
    top: &dyn Fn(f64, f64) -> f64,
    depths: &[f64],
    grading: &Grading,
) -> Result<(), SolidError> {
    let n = pm.points.len();
    let heights: Vec<f64> = pm.points.iter().map(|p| top(p[0], p[1])).collect();
    if let Some(i) = heights.iter().position(|z| !z.is_finite()) {
        return Err(SolidError::Construction(format!("the surface height at {:?} is not finite", pm.points[i])));
    }
    let base = plc.points.len();
    for &s in depths {
        for (p, z) in pm.points.iter().zip(&heights) {
            plc.push_point([p[0], p[1], z - s]);
        }
    }
    let at = |layer: usize, i: usize| base + layer * n + i;
    let last = depths.len() - 1;
    for layer in 0..depths.len() {
        let tag = match layer {
            0 => FaceTag::Visible,
            l if l == last => FaceTag::Back,
            _ => FaceTag::Interface,
        };
        for t in &pm.tris {
            let mut f = t.map(|i| at(layer, i));
            if tag == FaceTag::Back {
                f.swap(1, 2); // outward = -z
            }
            plc.facets.push(Facet { points: f.to_vec(), tag });
        }
    }
    for band in 0..last {
        for w in pm.edge_points.iter().flat_map(|along| along.windows(2)) {
            let (a, b) = (at(band, w[0]), at(band, w[1]));
            let (a2, b2) = (at(band + 1, w[0]), at(band + 1, w[1]));
            plc.facets.push(Facet { points: vec![a, a2, b2], tag: FaceTag::Side });
            plc.facets.push(Facet { points: vec![a, b2, b], tag: FaceTag::Side });
        }
    }
    // A region point per band below the centroid of the part's largest triangle.
    let big = (0..pm.tris.len())
        .max_by(|&a, &b| tri_area2(pm, a).total_cmp(&tri_area2(pm, b)))
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
    Ok(())
}

fn tri_area2(pm: &PolygonMesh, t: usize) -> f64 {
    let [a, b, c] = pm.tris[t].map(|i| pm.points[i]);
    orient(a, b, c)
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
        let pm = triangulate(&Outline::simple(square.to_vec()), Some(0.01)).unwrap();
        let area: f64 = pm.tris.iter().map(|t| orient(pm.points[t[0]], pm.points[t[1]], pm.points[t[2]]) / 2.0).sum();
        assert!((area - 0.005).abs() < 1e-15);
        assert_eq!(pm.edge_points.len(), 4);
        // The bottom edge (length 0.1) at h = 0.01 is split into several segments, all on y = 0.
        assert!(pm.edge_points[0].len() >= 10);
        assert!(pm.edge_points[0].iter().all(|&i| pm.points[i][1] == 0.0));
    }
}
