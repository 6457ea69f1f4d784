//! Piecewise linear complex (PLC): the closed solid handed to TetGen.

use crate::mesh::tetmesh::FaceTag;
use crate::vec3::dist;

/// A planar polygonal facet of the PLC boundary or of an internal interface.
#[derive(Clone, Debug, PartialEq)]
pub struct Facet {
    /// Indices into [`Plc::points`], in order around the polygon (at least 3).
    pub points: Vec<usize>,
    /// What the facet is: visible surface, side wall, back, or internal interface.
    pub tag: FaceTag,
}

/// A region of the solid: TetGen floods from `point` to the enclosing facets.
#[derive(Clone, Debug, PartialEq)]
pub struct Region {
    /// A point strictly inside the region (m).
    pub point: [f64; 3],
    /// Attribute copied to every tetrahedron of the region (the layer index, from 1).
    pub attribute: i32,
    /// Upper bound on the volume of its tetrahedra (m^3); `None` = unbounded.
    pub max_volume: Option<f64>,
}

/// Points (#P x 3, metres), facets and regions of a closed solid.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Plc {
    pub points: Vec<[f64; 3]>,
    pub facets: Vec<Facet>,
    pub regions: Vec<Region>,
}

/// Relative tolerance for facet planarity, in units of the facet's diameter.
const PLANARITY_TOL: f64 = 1e-9;

/// Points closer than this times the complex's diameter are duplicates, facets narrower than
/// it slivers.
const DUPLICATE_TOL: f64 = 1e-9;

impl Plc {
    /// Checks what TetGen assumes but cannot report gracefully (it aborts on an assertion):
    /// finite points, no two points closer than `DUPLICATE_TOL` times the complex's diameter,
    /// facets of at least three distinct in-range points that are not collinear (a facet's
    /// width, twice its area over its longest edge, at least `DUPLICATE_TOL` times the
    /// diameter), planar facets, finite region points. Crossing segments are the builder's to
    /// rule out (the extrusion checks its outlines, a closed mesh its self-intersections).
    ///
    /// # Errors
    /// A message naming the facet or point.
    pub fn validate(&self) -> Result<(), String> {
        if self.points.len() < 4 || self.facets.len() < 4 {
            return Err(format!(
                "a closed solid needs at least 4 points and 4 facets, got {} and {}",
                self.points.len(),
                self.facets.len()
            ));
        }
        for (i, p) in self.points.iter().enumerate() {
            if p.iter().any(|c| !c.is_finite()) {
                return Err(format!("point {i} has a non-finite coordinate {p:?}"));
            }
        }
        let diameter = self.diameter();
        self.check_duplicates(DUPLICATE_TOL * diameter)?;
        for (f, facet) in self.facets.iter().enumerate() {
            let n = facet.points.len();
            if n < 3 {
                return Err(format!("facet {f} has {n} points; at least 3 are needed"));
            }
            if let Some(&bad) = facet.points.iter().find(|&&p| p >= self.points.len()) {
                return Err(format!("facet {f} references point {bad} but there are {} points", self.points.len()));
            }
            let mut sorted = facet.points.clone();
            sorted.sort_unstable();
            if sorted.windows(2).any(|w| w[0] == w[1]) {
                return Err(format!("facet {f} repeats a point: {:?}", facet.points));
            }
            self.check_width(f, DUPLICATE_TOL * diameter)?;
            if n > 3 {
                self.check_planar(f)?;
            }
        }
        for (r, region) in self.regions.iter().enumerate() {
            if region.point.iter().any(|c| !c.is_finite()) {
                return Err(format!("region {r} has a non-finite point {:?}", region.point));
            }
        }
        Ok(())
    }

    /// Length of the bounding-box diagonal (m).
    fn diameter(&self) -> f64 {
        let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
        for p in &self.points {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        dist(lo, hi)
    }

    /// No two points closer than `tol` (m): a sweep over x.
    fn check_duplicates(&self, tol: f64) -> Result<(), String> {
        let mut order: Vec<usize> = (0..self.points.len()).collect();
        order.sort_by(|&a, &b| self.points[a][0].total_cmp(&self.points[b][0]));
        for (k, &i) in order.iter().enumerate() {
            for &j in &order[k + 1..] {
                if self.points[j][0] - self.points[i][0] > tol {
                    break;
                }
                let d = dist(self.points[i], self.points[j]);
                if d <= tol {
                    let (a, b) = (i.min(j), i.max(j));
                    return Err(format!("points {a} and {b} are {d:e} m apart: duplicates (closer than {tol:e} m)"));
                }
            }
        }
        Ok(())
    }

    /// Facet `f` is not a sliver: twice its area over its longest edge is at least `tol` (m).
    fn check_width(&self, f: usize, tol: f64) -> Result<(), String> {
        let pts: Vec<[f64; 3]> = self.facets[f].points.iter().map(|&i| self.points[i]).collect();
        let n = newell(&pts);
        let twice_area = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let longest = (0..pts.len()).map(|i| dist(pts[i], pts[(i + 1) % pts.len()])).fold(0.0, f64::max);
        if twice_area < tol * longest {
            return Err(format!(
                "facet {f} is degenerate: its points {:?} are collinear within {:e} m",
                self.facets[f].points,
                twice_area / longest.max(f64::MIN_POSITIVE)
            ));
        }
        Ok(())
    }

    fn check_planar(&self, f: usize) -> Result<(), String> {
        let pts: Vec<[f64; 3]> = self.facets[f].points.iter().map(|&i| self.points[i]).collect();
        let n = newell(&pts);
        let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
        let diam = pts.iter().flat_map(|a| pts.iter().map(move |b| dist(*a, *b))).fold(0.0, f64::max);
        if len <= 0.0 || diam <= 0.0 {
            return Err(format!("facet {f} is degenerate (zero area)"));
        }
        let n = [n[0] / len, n[1] / len, n[2] / len];
        for p in &pts {
            let d = (0..3).map(|k| (p[k] - pts[0][k]) * n[k]).sum::<f64>();
            if d.abs() > PLANARITY_TOL * diam.max(1.0) {
                return Err(format!("facet {f} is not planar: a point lies {d:e} m off its plane"));
            }
        }
        Ok(())
    }

    /// Appends a point and returns its index.
    pub fn push_point(&mut self, p: [f64; 3]) -> usize {
        self.points.push(p);
        self.points.len() - 1
    }
}

/// Newell's normal of a polygon: twice its vector area (m^2); robust for non-convex polygons.
fn newell(pts: &[[f64; 3]]) -> [f64; 3] {
    let mut n = [0.0; 3];
    for (i, a) in pts.iter().enumerate() {
        let b = pts[(i + 1) % pts.len()];
        n[0] += (a[1] - b[1]) * (a[2] + b[2]);
        n[1] += (a[2] - b[2]) * (a[0] + b[0]);
        n[2] += (a[0] - b[0]) * (a[1] + b[1]);
    }
    n
}

/// Volume of a regular tetrahedron of edge `h`: h^3 / (6 sqrt 2) (m^3).
pub fn regular_tet_volume(h: f64) -> f64 {
    h * h * h / (6.0 * std::f64::consts::SQRT_2)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube() -> Plc {
        let mut plc = Plc::default();
        for z in [0.0, 1.0] {
            for (x, y) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
                plc.push_point([x, y, z]);
            }
        }
        for f in [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]] {
            plc.facets.push(Facet { points: f.to_vec(), tag: FaceTag::Side });
        }
        plc
    }

    #[test]
    fn cube_is_valid() {
        assert_eq!(cube().validate(), Ok(()));
    }

    #[test]
    fn bad_plcs_are_named() {
        let mut p = cube();
        p.facets[2].points[1] = 99;
        assert!(p.validate().unwrap_err().contains("facet 2 references point 99"));
        let mut p = cube();
        p.points[5][2] = 1.5;
        assert!(p.validate().unwrap_err().contains("not planar"));
        let mut p = cube();
        p.points[0][0] = f64::NAN;
        assert!(p.validate().unwrap_err().contains("point 0"));
        // A ninth point a hair away from point 6, and a triangle of three collinear points.
        let mut p = cube();
        p.push_point([1.0, 1.0, 1.0 + 1e-12]);
        assert!(p.validate().unwrap_err().contains("points 6 and 8 are"), "{:?}", p.validate());
        let mut p = cube();
        p.push_point([0.5, 0.0, 0.0]);
        p.facets.push(Facet { points: vec![0, 8, 1], tag: FaceTag::Side });
        assert!(p.validate().unwrap_err().contains("facet 6 is degenerate"), "{:?}", p.validate());
    }
}
