//! Hemisphere: a dome shell of outer radius R and thickness d (inner radius R - d), solid
//! once d >= R.
//!
//! Centre at the origin, dome top at (0, 0, R), flat base in the plane z = 0; the camera looks
//! at the dome from +z. "Thickness" is measured along the inward normal, so every point of the
//! visible dome has `d` metres of material beneath it. The dome is triangulated ring by ring
//! (pole, then circles of latitude spaced about `h` apart); the fine-layer interface and the
//! inner dome are the same triangulation scaled towards the centre, and the base consists of
//! planar trapezoids between consecutive rings (or one disk polygon for the solid core).

use super::plc::{regular_tet_volume, Facet, Plc, Region};
use super::{Grading, SolidError};
use crate::mesh::tetmesh::FaceTag;
use crate::vec3::{cross, dot, sub};
use std::f64::consts::PI;

/// A unit dome triangulation: points on the unit hemisphere (z >= 0), outward triangles and
/// the indices of the equator ring in counter-clockwise order seen from +z.
pub struct Dome {
    pub points: Vec<[f64; 3]>,
    pub tris: Vec<[usize; 3]>,
    pub equator: Vec<usize>,
}

/// Triangulates the unit dome with edges of about `h` (relative to the radius).
pub fn unit_dome(h: f64) -> Dome {
    let rings = ((PI / 2.0) / h).ceil().max(2.0) as usize;
    let mut points = vec![[0.0, 0.0, 1.0]];
    let mut ring_start = vec![0];
    let mut ring_len = vec![1];
    for j in 1..=rings {
        let theta = j as f64 * (PI / 2.0) / rings as f64;
        let m = ((2.0 * PI * theta.sin() / h).round() as usize).max(6);
        ring_start.push(points.len());
        ring_len.push(m);
        // Alternate rings are rotated by half a step for better-shaped triangles.
        let offset = if j % 2 == 0 { 0.5 } else { 0.0 };
        for k in 0..m {
            let phi = 2.0 * PI * (k as f64 + offset) / m as f64;
            let (s, c) = (theta.sin(), theta.cos());
            // The equator lies exactly in z = 0.
            let z = if j == rings { 0.0 } else { c };
            points.push([s * phi.cos(), s * phi.sin(), z]);
        }
    }
    let mut tris = Vec::new();
    for j in 0..rings {
        let (a0, na) = (ring_start[j], ring_len[j]);
        let (b0, nb) = (ring_start[j + 1], ring_len[j + 1]);
        if na == 1 {
            for k in 0..nb {
                tris.push([a0, b0 + k, b0 + (k + 1) % nb]);
            }
            continue;
        }
        // Zip the two rings by azimuth: advance whichever next point comes first.
        let angle = |i: usize| {
            let p = points[i];
            let a = p[1].atan2(p[0]);
            if a < 0.0 {
                a + 2.0 * PI
            } else {
                a
            }
        };
        let (mut i, mut k) = (0usize, 0usize);
        while i < na || k < nb {
            let ai = a0 + i % na;
            let bk = b0 + k % nb;
            let next_a = angle(a0 + (i + 1) % na) + if i + 1 >= na { 2.0 * PI } else { 0.0 };
            let next_b = angle(b0 + (k + 1) % nb) + if k + 1 >= nb { 2.0 * PI } else { 0.0 };
            let advance_a = k >= nb || (i < na && next_a <= next_b);
            if advance_a {
                tris.push([ai, bk, a0 + (i + 1) % na]);
                i += 1;
            } else {
                tris.push([ai, bk, b0 + (k + 1) % nb]);
                k += 1;
            }
        }
    }
    // Orient every triangle outward (normal along the position vector).
    for t in &mut tris {
        let [a, b, c] = t.map(|i| points[i]);
        let n = cross(sub(b, a), sub(c, a));
        let centroid = [(a[0] + b[0] + c[0]) / 3.0, (a[1] + b[1] + c[1]) / 3.0, (a[2] + b[2] + c[2]) / 3.0];
        if dot(n, centroid) < 0.0 {
            t.swap(1, 2);
        }
    }
    let e0 = ring_start[rings];
    let equator = (e0..e0 + ring_len[rings]).collect();
    Dome { points, tris, equator }
}

/// Builds the PLC of a hemisphere of radius `radius` and thickness `thickness` (m). Returns
/// the PLC and the exact volume of the polyhedral solid (sum of signed tetrahedra from the
/// origin over its boundary).
pub fn hemisphere(radius: f64, thickness: f64, grading: &Grading) -> Result<(Plc, f64), SolidError> {
    let solid = thickness >= radius;
    let dome = unit_dome(grading.surface_element_size / radius);
    // Radii of the dome layers, outermost first. A solid hemisphere ends in a core region.
    let mut radii = vec![radius];
    let s1 = grading.fine_layer_depth;
    let has_fine_layer = s1 < 0.75 * thickness.min(radius);
    if has_fine_layer {
        radii.push(radius - s1);
    }
    if !solid {
        radii.push(radius - thickness);
    }
    let n = dome.points.len();
    let mut plc = Plc::default();
    for &r in &radii {
        for p in &dome.points {
            plc.push_point([p[0] * r, p[1] * r, p[2] * r]);
        }
    }
    let last = radii.len() - 1;
    for (layer, _) in radii.iter().enumerate() {
        let tag = if layer == 0 {
            FaceTag::Visible
        } else if layer == last && !solid {
            FaceTag::Back
        } else {
            FaceTag::Interface
        };
        for t in &dome.tris {
            let mut f = t.map(|i| layer * n + i);
            if tag == FaceTag::Back {
                f.swap(1, 2); // the inner dome faces the centre
            }
            plc.facets.push(Facet { points: f.to_vec(), tag });
        }
    }
    // Base: trapezoids between consecutive rings, and a disk under a solid core.
    let m = dome.equator.len();
    for band in 0..last {
        for k in 0..m {
            let (a, b) = (dome.equator[k], dome.equator[(k + 1) % m]);
            let quad = vec![band * n + a, (band + 1) * n + a, (band + 1) * n + b, band * n + b];
            plc.facets.push(Facet { points: quad, tag: FaceTag::Back });
        }
    }
    if solid {
        let disk: Vec<usize> = dome.equator.iter().rev().map(|&i| last * n + i).collect();
        plc.facets.push(Facet { points: disk, tag: FaceTag::Back });
    }
    // Regions: the middle of each shell band on the axis, and the core.
    let bands = if solid { last + 1 } else { last };
    for band in 0..bands {
        let r_out = radii[band];
        let r_in = radii.get(band + 1).copied().unwrap_or(0.0);
        let h = if band == 0 { grading.surface_element_size } else { grading.deep_element_size };
        // On the axis just below the pole, between the two domes (the pole is a dome vertex).
        let z = if r_in > 0.0 { 0.5 * (r_out + r_in) * pole_height(&dome) } else { 0.5 * r_out };
        plc.regions.push(Region {
            point: [0.0, 0.0, z],
            attribute: band as i32 + 1,
            max_volume: Some(regular_tet_volume(h)),
        });
    }
    let volume = polyhedron_volume(&plc);
    Ok((plc, volume))
}

/// The dome's pole is exactly at height 1; the region point sits between two domes on the axis.
fn pole_height(dome: &Dome) -> f64 {
    dome.points[0][2]
}

/// Volume of the closed boundary (visible, side and back facets; interfaces excluded),
/// by fan-triangulating each facet and summing signed tetrahedra from the origin.
fn polyhedron_volume(plc: &Plc) -> f64 {
    let mut v = 0.0;
    for f in plc.facets.iter().filter(|f| f.tag != FaceTag::Interface) {
        let p0 = plc.points[f.points[0]];
        for w in f.points[1..].windows(2) {
            let (a, b) = (plc.points[w[0]], plc.points[w[1]]);
            v += dot(p0, cross(a, b)) / 6.0;
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_dome_is_a_closed_cap_with_outward_normals() {
        let dome = unit_dome(0.1);
        // Every edge used twice except the equator's, which are used once.
        let mut edges = std::collections::BTreeMap::new();
        for t in &dome.tris {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        let once = edges.values().filter(|&&c| c == 1).count();
        assert_eq!(once, dome.equator.len());
        assert!(edges.values().all(|&c| c == 1 || c == 2));
        // Area close to 2 pi.
        let area: f64 = dome
            .tris
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| dome.points[i]);
                let n = cross(sub(b, a), sub(c, a));
                dot(n, n).sqrt() / 2.0
            })
            .sum();
        assert!((area - 2.0 * PI).abs() / (2.0 * PI) < 0.01, "area {area}");
    }
}
