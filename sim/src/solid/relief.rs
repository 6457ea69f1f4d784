//! The visible relief of a surface mesh seen from +z, as a height field over its silhouette.
//!
//! 1. [`DepthMap::rasterize`]: an orthographic z-buffer on a square grid of spacing `h`; each
//!    sample keeps the largest z of the triangles above it (the first surface a ray coming
//!    from +z meets). The mesh may be open or self-intersecting: only first hits matter.
//!    Samples where the relief is steeper than a bound (default 85 degrees) are dropped: near
//!    the silhouette the surface turns parallel to the viewing axis, and where one part
//!    occludes another the relief jumps; a layer lowered along z would be squeezed to
//!    nothing there, and the camera sees those parts only at grazing angles anyway.
//! 2. [`DepthMap::silhouette`]: the outlines of the covered region by marching squares
//!    (diagonal-only contacts count as separate): every connected part with its holes, each a
//!    solid of its own. Parts and holes narrower than a raster step (mean width 2 area /
//!    perimeter below `h`) or under 4 samples are dropped (holes filled) and the repair is
//!    reported. Loops are simplified by Douglas–Peucker to a tolerance of `h` so that the
//!    outline has few corners; where that would make loops cross, the raster's outline is kept.
//! 3. [`DepthMap::height`]: bilinear interpolation of the covered samples, renormalised over
//!    the covered corners of a grid cell, and the nearest covered sample elsewhere.

use super::extrusion::{check_outlines, polygon_area, Outline};

/// The silhouette of a relief: its parts and each change made to the raster's outline.
#[derive(Clone, Debug)]
pub struct Silhouette {
    pub parts: Vec<Outline>,
    /// What was changed, in words (dropped parts, filled holes, simplification kept off).
    pub repairs: Vec<String>,
}

/// A loop encloses fewer than 4 samples, or its mean width 2 |A| / perimeter is under `h`.
fn is_sliver(lp: &[[f64; 2]], h: f64) -> bool {
    let area = polygon_area(lp).abs();
    let n = lp.len();
    let perimeter: f64 = (0..n).map(|i| (lp[(i + 1) % n][0] - lp[i][0]).hypot(lp[(i + 1) % n][1] - lp[i][1])).sum();
    area < 4.0 * h * h || 2.0 * area / perimeter < h
}

/// Even-odd ray casting: is `p` inside the polygon `poly`?
fn point_in_polygon(p: [f64; 2], poly: &[[f64; 2]]) -> bool {
    let n = poly.len();
    let mut inside = false;
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) && p[0] < a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
            inside = !inside;
        }
    }
    inside
}

/// The loop without the corners that lie exactly on the line through their neighbours.
fn drop_collinear(lp: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let n = lp.len();
    let keep = |i: usize| {
        let (a, b, c) = (lp[(i + n - 1) % n], lp[i], lp[(i + 1) % n]);
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]) != 0.0
    };
    (0..n).filter(|&i| keep(i)).map(|i| lp[i]).collect()
}

/// An orthographic depth map: sample (i, j) sits at (x0 + i h, y0 + j h); `z` is NaN where no
/// triangle covers the sample.
#[derive(Clone, Debug)]
pub struct DepthMap {
    pub x0: f64,
    pub y0: f64,
    pub h: f64,
    pub nx: usize,
    pub ny: usize,
    /// #nx*ny heights (m), row-major in j (index j * nx + i).
    pub z: Vec<f64>,
    /// Height of the nearest covered sample, for every sample (filled by a breadth-first sweep).
    nearest: Vec<f64>,
}

impl DepthMap {
    /// Rasterises the triangles `tris` of `verts` with spacing `h` (m), then drops the samples
    /// where the relief is steeper than `max_slope_deg` (see `drop_steep`).
    pub fn rasterize(verts: &[[f64; 3]], tris: &[[usize; 3]], h: f64, max_slope_deg: f64) -> DepthMap {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for v in verts {
            for k in 0..2 {
                lo[k] = lo[k].min(v[k]);
                hi[k] = hi[k].max(v[k]);
            }
        }
        // One empty sample of margin on each side so the silhouette closes.
        let x0 = lo[0] - h;
        let y0 = lo[1] - h;
        let nx = ((hi[0] - lo[0]) / h).ceil() as usize + 3;
        let ny = ((hi[1] - lo[1]) / h).ceil() as usize + 3;
        let mut z = vec![f64::NAN; nx * ny];
        for t in tris {
            let [a, b, c] = t.map(|i| verts[i]);
            let det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
            if det.abs() < 1e-300 {
                continue; // seen edge-on: covers no area
            }
            // Sample index ranges [lo, hi) of the triangle's bounding box; the 1e-9 slack keeps
            // samples lying exactly on a box edge despite rounding in (x - x0) / h.
            let first = |v: f64, o: f64| ((v - o) / h - 1e-9).ceil().max(0.0) as usize;
            let past = |v: f64, o: f64| ((v - o) / h + 1e-9).floor().max(-1.0) as usize + 1;
            let (i_lo, i_hi) = (first(a[0].min(b[0]).min(c[0]), x0), past(a[0].max(b[0]).max(c[0]), x0).min(nx));
            let (j_lo, j_hi) = (first(a[1].min(b[1]).min(c[1]), y0), past(a[1].max(b[1]).max(c[1]), y0).min(ny));
            // A small tolerance keeps samples on shared edges covered by at least one side.
            let eps = -1e-12;
            for j in j_lo..j_hi {
                let y = y0 + j as f64 * h;
                for i in i_lo..i_hi {
                    let x = x0 + i as f64 * h;
                    let l1 = ((x - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (y - a[1])) / det;
                    let l2 = ((b[0] - a[0]) * (y - a[1]) - (x - a[0]) * (b[1] - a[1])) / det;
                    let l0 = 1.0 - l1 - l2;
                    if l0 < eps || l1 < eps || l2 < eps {
                        continue;
                    }
                    let zz = l0 * a[2] + l1 * b[2] + l2 * c[2];
                    let cell = &mut z[j * nx + i];
                    if cell.is_nan() || zz > *cell {
                        *cell = zz;
                    }
                }
            }
        }
        drop_steep(&mut z, nx, ny, h, max_slope_deg);
        let nearest = nearest_fill(&z, nx, ny);
        DepthMap { x0, y0, h, nx, ny, z, nearest }
    }

    fn covered(&self, i: usize, j: usize) -> bool {
        i < self.nx && j < self.ny && self.z[j * self.nx + i].is_finite()
    }

    /// Number of covered samples.
    pub fn covered_count(&self) -> usize {
        self.z.iter().filter(|z| z.is_finite()).count()
    }

    /// Height of the visible surface at (x, y) (m).
    pub fn height(&self, x: f64, y: f64) -> f64 {
        let fx = ((x - self.x0) / self.h).clamp(0.0, (self.nx - 1) as f64);
        let fy = ((y - self.y0) / self.h).clamp(0.0, (self.ny - 1) as f64);
        let i = (fx.floor() as usize).min(self.nx - 2);
        let j = (fy.floor() as usize).min(self.ny - 2);
        let (u, v) = (fx - i as f64, fy - j as f64);
        let mut sum = 0.0;
        let mut wsum = 0.0;
        for (di, dj, w) in [(0, 0, (1.0 - u) * (1.0 - v)), (1, 0, u * (1.0 - v)), (0, 1, (1.0 - u) * v), (1, 1, u * v)]
        {
            let zz = self.z[(j + dj) * self.nx + i + di];
            if zz.is_finite() && w > 0.0 {
                sum += w * zz;
                wsum += w;
            }
        }
        if wsum > 1e-9 {
            sum / wsum
        } else {
            let (ri, rj) = (fx.round() as usize, fy.round() as usize);
            self.nearest[rj * self.nx + ri]
        }
    }

    /// The parts of the covered region as outlines with holes, simplified to within
    /// `tolerance` (m), and what was changed on the way (see [`Silhouette`]).
    ///
    /// # Errors
    /// A message if no part is larger than a sliver.
    pub fn silhouette(&self, tolerance: f64) -> Result<Silhouette, String> {
        let (mut outers, mut holes) = (Vec::new(), Vec::new());
        for lp in self.contours() {
            if polygon_area(&lp) > 0.0 {
                outers.push(lp);
            } else {
                holes.push(lp);
            }
        }
        let mut repairs = Vec::new();
        let total = outers.len();
        outers.retain(|lp| !is_sliver(lp, self.h));
        if outers.len() < total {
            repairs.push(format!(
                "dropped {} of {total} silhouette parts narrower than the raster step {} m or smaller than 4 samples",
                total - outers.len(),
                self.h
            ));
        }
        if outers.is_empty() {
            return Err(format!(
                "the surface covers {} samples of the relief raster (spacing {} m) and no part of them is wider than \
                 a sample (is it seen edge-on from +z, or smaller than the raster spacing?)",
                self.covered_count(),
                self.h
            ));
        }
        // Each hole belongs to the smallest outer loop containing it; islands in a hole are parts.
        let mut parts: Vec<Outline> = outers.into_iter().map(Outline::simple).collect();
        let (n_holes, mut filled) = (holes.len(), 0);
        for hole in holes {
            let owner = (0..parts.len())
                .filter(|&p| point_in_polygon(hole[0], &parts[p].outer))
                .min_by(|&a, &b| polygon_area(&parts[a].outer).total_cmp(&polygon_area(&parts[b].outer)));
            match owner {
                Some(p) if !is_sliver(&hole, self.h) => parts[p].holes.push(hole),
                _ => filled += 1,
            }
        }
        if filled > 0 {
            repairs.push(format!(
                "filled {filled} of {n_holes} holes of the silhouette narrower than the raster step or smaller than 4 samples"
            ));
        }
        let simplified: Vec<Outline> = parts
            .iter()
            .map(|p| Outline {
                outer: simplify_closed(&p.outer, tolerance),
                holes: p.holes.iter().map(|h| simplify_closed(h, tolerance)).collect(),
            })
            .collect();
        if check_outlines(&simplified).is_ok() {
            return Ok(Silhouette { parts: simplified, repairs });
        }
        // Simplifying made loops cross (walls thinner than the tolerance): keep the raster's
        // own outline, only without its collinear corners (exact: they lie on grid lines).
        let raw: Vec<Outline> = parts
            .iter()
            .map(|p| Outline {
                outer: drop_collinear(&p.outer),
                holes: p.holes.iter().map(|h| drop_collinear(h)).collect(),
            })
            .collect();
        check_outlines(&raw)?;
        repairs.push(format!(
            "kept the raster outline unsimplified: simplifying it to {tolerance} m would make its edges cross"
        ));
        Ok(Silhouette { parts: raw, repairs })
    }

    /// Marching-squares contours of the covered region; outer boundaries counter-clockwise,
    /// holes clockwise. Contour points are midpoints of grid edges.
    fn contours(&self) -> Vec<Vec<[f64; 2]>> {
        // Edge keys: horizontal edge (i,j)-(i+1,j) -> 2*(j*nx+i); vertical (i,j)-(i,j+1) -> 2*(j*nx+i)+1.
        let nx = self.nx;
        let hkey = |i: usize, j: usize| 2 * (j * nx + i);
        let vkey = |i: usize, j: usize| 2 * (j * nx + i) + 1;
        let mut next: std::collections::BTreeMap<usize, usize> = std::collections::BTreeMap::new();
        for j in 0..self.ny - 1 {
            for i in 0..self.nx - 1 {
                // Corners counter-clockwise and the edge from corner k to corner k+1.
                let inside =
                    [self.covered(i, j), self.covered(i + 1, j), self.covered(i + 1, j + 1), self.covered(i, j + 1)];
                let edges = [hkey(i, j), vkey(i + 1, j), hkey(i, j + 1), vkey(i, j)];
                let exits: Vec<usize> = (0..4).filter(|&k| inside[k] && !inside[(k + 1) % 4]).collect();
                for &k in &exits {
                    // Pair the exit with the nearest entry before it (counter-clockwise order):
                    // diagonal-only contacts stay separate.
                    let entry = (1..4)
                        .map(|s| (k + 4 - s) % 4)
                        .find(|&e| !inside[e] && inside[(e + 1) % 4])
                        .expect("an exit has an entry");
                    next.insert(edges[k], edges[entry]);
                }
            }
        }
        let point = |key: usize| {
            let cell = key / 2;
            let (i, j) = ((cell % nx) as f64, (cell / nx) as f64);
            if key.is_multiple_of(2) {
                [self.x0 + (i + 0.5) * self.h, self.y0 + j * self.h]
            } else {
                [self.x0 + i * self.h, self.y0 + (j + 0.5) * self.h]
            }
        };
        let mut loops = Vec::new();
        while let Some((&start, _)) = next.iter().next() {
            let mut lp = Vec::new();
            let mut key = start;
            while let Some(n) = next.remove(&key) {
                lp.push(point(key));
                key = n;
            }
            if lp.len() >= 3 {
                loops.push(lp);
            }
        }
        loops
    }
}

/// Uncovers every sample whose height differs from a covered 4-neighbour by more than
/// h tan(max_slope): grazing parts near the silhouette and both sides of occlusion cliffs.
/// The test reads the raster as it was before any sample is dropped.
fn drop_steep(z: &mut [f64], nx: usize, ny: usize, h: f64, max_slope_deg: f64) {
    let limit = h * max_slope_deg.to_radians().tan();
    let original = z.to_vec();
    for j in 0..ny {
        for i in 0..nx {
            let k = j * nx + i;
            if original[k].is_nan() {
                continue;
            }
            let steep = [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|&(di, dj): &(isize, isize)| {
                let (a, b) = (i as isize + di, j as isize + dj);
                if a < 0 || b < 0 || a >= nx as isize || b >= ny as isize {
                    return false;
                }
                let q = original[b as usize * nx + a as usize];
                q.is_finite() && (q - original[k]).abs() > limit
            });
            if steep {
                z[k] = f64::NAN;
            }
        }
    }
}

/// For every sample, the height of the nearest covered sample (8-neighbour breadth-first
/// sweep from all covered samples at once; deterministic).
fn nearest_fill(z: &[f64], nx: usize, ny: usize) -> Vec<f64> {
    let mut out = z.to_vec();
    let mut queue: std::collections::VecDeque<usize> = (0..z.len()).filter(|&k| z[k].is_finite()).collect();
    while let Some(k) = queue.pop_front() {
        let (i, j) = ((k % nx) as isize, (k / nx) as isize);
        for (di, dj) in [(-1, 0), (1, 0), (0, -1), (0, 1), (-1, -1), (1, -1), (-1, 1), (1, 1)] {
            let (a, b) = (i + di, j + dj);
            if a < 0 || b < 0 || a >= nx as isize || b >= ny as isize {
                continue;
            }
            let q = b as usize * nx + a as usize;
            if out[q].is_nan() {
                out[q] = out[k];
                queue.push_back(q);
            }
        }
    }
    out
}

/// Douglas–Peucker simplification of a closed polyline, split at its first point and the
/// point farthest from it.
pub fn simplify_closed(poly: &[[f64; 2]], tol: f64) -> Vec<[f64; 2]> {
    let n = poly.len();
    if n < 4 {
        return poly.to_vec();
    }
    let d2 = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
    let far = (1..n).max_by(|&a, &b| d2(poly[0], poly[a]).total_cmp(&d2(poly[0], poly[b]))).unwrap();
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[far] = true;
    let chain_a: Vec<usize> = (0..=far).collect();
    let chain_b: Vec<usize> = (far..n).chain(std::iter::once(0)).collect();
    dp(poly, &chain_a, tol, &mut keep);
    dp(poly, &chain_b, tol, &mut keep);
    (0..n).filter(|&i| keep[i]).map(|i| poly[i]).collect()
}

fn dp(poly: &[[f64; 2]], chain: &[usize], tol: f64, keep: &mut [bool]) {
    if chain.len() < 3 {
        return;
    }
    let (a, b) = (poly[chain[0]], poly[*chain.last().unwrap()]);
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = (dx * dx + dy * dy).sqrt();
    let dist = |p: [f64; 2]| {
        if len == 0.0 {
            ((p[0] - a[0]).powi(2) + (p[1] - a[1]).powi(2)).sqrt()
        } else {
            ((p[0] - a[0]) * dy - (p[1] - a[1]) * dx).abs() / len
        }
    };
    let (k, dmax) = chain[1..chain.len() - 1]
        .iter()
        .enumerate()
        .map(|(k, &i)| (k + 1, dist(poly[i])))
        .max_by(|x, y| x.1.total_cmp(&y.1))
        .unwrap();
    if dmax > tol {
        keep[chain[k]] = true;
        dp(poly, &chain[..=k], tol, keep);
        dp(poly, &chain[k..], tol, keep);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A square pyramid of base 2 x 2 and apex height 1, as an open surface (no base).
    fn pyramid() -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
        let v = vec![[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let t = vec![[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]];
        (v, t)
    }

    #[test]
    fn pyramid_heights_are_exact_inside() {
        let (v, t) = pyramid();
        let dm = DepthMap::rasterize(&v, &t, 0.05, 89.0);
        for (x, y) in [(0.0, 0.0), (0.3, -0.2), (-0.5, 0.5), (0.9, 0.1)] {
            let expected = 1.0 - f64::max(f64::abs(x), f64::abs(y));
            assert!((dm.height(x, y) - expected).abs() < 1e-9, "({x},{y}): {} vs {expected}", dm.height(x, y));
        }
    }

    #[test]
    fn pyramid_silhouette_is_the_square() {
        let (v, t) = pyramid();
        let dm = DepthMap::rasterize(&v, &t, 0.05, 89.0);
        let s = dm.silhouette(0.05).unwrap();
        assert_eq!(s.parts.len(), 1);
        assert!(s.parts[0].holes.is_empty() && s.repairs.is_empty(), "{s:?}");
        let area = s.parts[0].area();
        // Marching squares puts the outline half a sample outside the covered samples.
        assert!((area - 4.0).abs() < 4.0 * 0.06, "area {area}");
        assert!(
            s.parts[0].outer.len() <= 8,
            "a square should simplify to a few corners, got {}",
            s.parts[0].outer.len()
        );
    }

    #[test]
    fn only_the_first_hit_counts() {
        // Two parallel squares; the upper one (z = 2) hides the lower one.
        let v = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 2.0],
            [1.0, 0.0, 2.0],
            [1.0, 1.0, 2.0],
            [0.0, 1.0, 2.0],
        ];
        let t = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let dm = DepthMap::rasterize(&v, &t, 0.1, 89.0);
        assert_eq!(dm.height(0.5, 0.5), 2.0);
    }

    #[test]
    fn cliffs_are_cut_away() {
        // A step of height 1 between two flat squares side by side: with a 75 degree bound
        // the samples on both sides of the step are dropped, the flats are kept.
        let v = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 1.0],
            [2.0, 0.0, 1.0],
            [2.0, 1.0, 1.0],
            [1.0, 1.0, 1.0],
        ];
        let t = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let dm = DepthMap::rasterize(&v, &t, 0.1, 75.0);
        let at = |x: f64, y: f64| {
            dm.z[((y - dm.y0) / dm.h).round() as usize * dm.nx + ((x - dm.x0) / dm.h).round() as usize]
        };
        assert!(at(1.0, 0.5).is_nan() && at(0.9, 0.5).is_nan());
        assert_eq!(at(0.5, 0.5), 0.0);
        assert_eq!(at(1.5, 0.5), 1.0);
    }

    #[test]
    fn diagonal_blobs_are_separate_parts() {
        // Two squares whose samples touch only diagonally: two parts.
        let v = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.05, 1.05, 0.0],
            [1.55, 1.05, 0.0],
            [1.55, 1.55, 0.0],
            [1.05, 1.55, 0.0],
        ];
        let t = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let dm = DepthMap::rasterize(&v, &t, 0.1, 89.0);
        let s = dm.silhouette(0.01).unwrap();
        assert!(check_outlines(&s.parts).is_ok());
        let mut areas: Vec<f64> = s.parts.iter().map(Outline::area).collect();
        areas.sort_by(f64::total_cmp);
        assert_eq!(areas.len(), 2, "{s:?}");
        assert!(areas[0] > 0.2 && areas[0] < 0.4 && areas[1] > 0.9 && areas[1] < 1.3, "areas {areas:?}");
    }

    /// A square frame (outer side 2, hole side 1) plus a small square island in the hole and
    /// a speck under 4 samples: one part with a hole, the island as a second part, the speck
    /// dropped and reported.
    #[test]
    fn holes_islands_and_specks() {
        let square = |c: [f64; 2], r: f64, z: f64| {
            [[c[0] - r, c[1] - r, z], [c[0] + r, c[1] - r, z], [c[0] + r, c[1] + r, z], [c[0] - r, c[1] + r, z]]
        };
        let mut v = Vec::new();
        let mut t = Vec::new();
        // The frame as four strips.
        for (c, rx, ry) in
            [([0.0, 0.75], 1.0, 0.25), ([0.0, -0.75], 1.0, 0.25), ([0.75, 0.0], 0.25, 0.5), ([-0.75, 0.0], 0.25, 0.5)]
        {
            let b = v.len();
            v.extend([
                [c[0] - rx, c[1] - ry, 0.0],
                [c[0] + rx, c[1] - ry, 0.0],
                [c[0] + rx, c[1] + ry, 0.0],
                [c[0] - rx, c[1] + ry, 0.0],
            ]);
            t.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        }
        for (c, r) in [([0.0, 0.0], 0.2), ([1.6, 1.6], 0.04)] {
            let b = v.len();
            v.extend(square(c, r, 0.0));
            t.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
        }
        let dm = DepthMap::rasterize(&v, &t, 0.05, 89.0);
        let s = dm.silhouette(0.05).unwrap();
        assert!(check_outlines(&s.parts).is_ok());
        assert_eq!(s.parts.len(), 2, "{s:?}");
        let frame = s.parts.iter().find(|p| !p.holes.is_empty()).expect("the frame keeps its hole");
        assert!((frame.area() - 3.0).abs() < 0.3, "frame area {}", frame.area());
        assert_eq!(s.repairs.len(), 1, "{:?}", s.repairs);
        assert!(s.repairs[0].contains("dropped 1 of 3"), "{:?}", s.repairs);
    }
}
