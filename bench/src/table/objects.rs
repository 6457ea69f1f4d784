//! Test objects of the shape-error table (paper Table 2 and Fig. 6): surfaces of revolution
//! generated as closed, outward-oriented triangle meshes.
//!
//! A surface of revolution is given by its *outline* in the (a, r) half-plane, a the position
//! along the axis and r >= 0 the radius, running from a pole (r = 0) at the bottom to a pole at
//! the top. The outline is a chain of segments: straight lines, circular arcs and smooth curves
//! r(a). Revolving it about the axis gives a closed surface whose enclosed volume is
//!
//!   V = pi * integral of r^2 da along the outline
//!
//! (flat end discs have da = 0 and add nothing). [`Profile::analytic_volume`] evaluates this in
//! closed form for lines (frusta, pi h (r0^2 + r0 r1 + r1^2) / 3) and arcs (centre (a_c, r_c),
//! radius rho, a = a_c + rho cos t, r = r_c + rho sin t:
//! integral of r^2 da = -rho [ -r_c^2 cos t + r_c rho (t - sin t cos t) + rho^2 (cos^3 t / 3 - cos t) ]),
//! and by 5-point Gauss-Legendre quadrature on 4000 panels for curves (converged to about
//! 1e-12 relative for the smooth profiles here). The tessellation
//! ([`Profile::mesh`]) samples each segment at about the requested spacing, keeping every
//! segment end (corners stay sharp), and revolves it with a number of sectors giving the same
//! spacing on the largest circle; its volume is that of the inscribed polyhedron, below the
//! analytic value by about (2 pi / sectors)^2 / 6 relative.
//!
//! A [`Section`] makes the cross-section non-circular: the radius at azimuth phi becomes
//! r(a) (1 + e cos(k (phi - theta(a)))), k lobes twisted along the axis (see its documentation
//! for the volume, (1 + e^2 / 2) times that of the surface of revolution).
//!
//! The objects lie on their side: the axis is the world x axis, centred on the origin, so the
//! camera (looking along -z from +z) sees the side of the can or bottle as in the paper's
//! photographs. All lengths in metres.

use std::f64::consts::PI;

use heatsim::mesh::TriMesh;

/// One piece of an outline in the (a, r) half-plane (m).
#[derive(Clone, Debug)]
pub enum Segment {
    /// A straight line from `from` to `to`, each (a, r).
    Line { from: [f64; 2], to: [f64; 2] },
    /// A circular arc: centre (a, r), radius, angles t0 -> t1 (rad); points
    /// (a_c + rho cos t, r_c + rho sin t).
    Arc { centre: [f64; 2], radius: f64, t0: f64, t1: f64 },
    /// A smooth radius function over a in [a0, a1].
    Curve { a0: f64, a1: f64, r: fn(f64) -> f64 },
}

impl Segment {
    /// The point at parameter s in [0, 1], (a, r) in m.
    pub fn at(&self, s: f64) -> [f64; 2] {
        match *self {
            Segment::Line { from, to } => [from[0] + s * (to[0] - from[0]), from[1] + s * (to[1] - from[1])],
            Segment::Arc { centre, radius, t0, t1 } => {
                let t = t0 + s * (t1 - t0);
                [centre[0] + radius * t.cos(), centre[1] + radius * t.sin()]
            }
            Segment::Curve { a0, a1, r } => {
                let a = a0 + s * (a1 - a0);
                [a, r(a)]
            }
        }
    }

    /// Arc length (m), from 2000 chords (exact for lines).
    pub fn length(&self) -> f64 {
        let n = 2000;
        (0..n).map(|i| dist(self.at(i as f64 / n as f64), self.at((i + 1) as f64 / n as f64))).sum()
    }

    /// pi * integral of r^2 da along the segment (m^3), see the module documentation.
    pub fn analytic_volume(&self) -> f64 {
        match *self {
            Segment::Line { from, to } => {
                let (h, r0, r1) = (to[0] - from[0], from[1], to[1]);
                PI * h * (r0 * r0 + r0 * r1 + r1 * r1) / 3.0
            }
            Segment::Arc { centre, radius: rho, t0, t1 } => {
                let c = centre[1];
                // integral of r^2 da = -rho * integral of (c + rho sin t)^2 sin t dt.
                let f = |t: f64| {
                    -c * c * t.cos() + c * rho * (t - t.sin() * t.cos()) + rho * rho * (t.cos().powi(3) / 3.0 - t.cos())
                };
                PI * (-rho) * (f(t1) - f(t0))
            }
            Segment::Curve { a0, a1, r } => {
                // Composite 5-point Gauss-Legendre.
                const X: [f64; 5] = [
                    0.0,
                    -0.538_469_310_105_683_1,
                    0.538_469_310_105_683_1,
                    -0.906_179_845_938_664,
                    0.906_179_845_938_664,
                ];
                const W: [f64; 5] = [
                    0.568_888_888_888_888_9,
                    0.478_628_670_499_366_5,
                    0.478_628_670_499_366_5,
                    0.236_926_885_056_189_1,
                    0.236_926_885_056_189_1,
                ];
                let panels = 4000;
                let h = (a1 - a0) / panels as f64;
                let mut sum = 0.0;
                for p in 0..panels {
                    let mid = a0 + (p as f64 + 0.5) * h;
                    for (x, w) in X.iter().zip(W) {
                        let rr = r(mid + 0.5 * h * x);
                        sum += w * 0.5 * h * rr * rr;
                    }
                }
                PI * sum
            }
        }
    }
}

fn dist(p: [f64; 2], q: [f64; 2]) -> f64 {
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()
}

/// A non-circular, twisted cross-section of a swept surface.
///
/// With the outline r(a) on a in [a_0, a_1] (length L = a_1 - a_0) and the azimuth phi about
/// the axis (phi = 0 along world +y, pi / 2 along +z), the surface is
///
///   R(a, phi) = r(a) (1 + e cos(k (phi - theta(a)))),  theta(a) = tau ((a - a_0) / L - 1/2),
///
/// `lobes` k (an integer >= 1; k = 2 an oval), `eccentricity` e in [0, 1) (R > 0 wherever
/// r > 0, so every slice is star-shaped about the axis and the surface does not intersect
/// itself) and `twist` tau (rad, the rotation of the section from one end to the other, zero at
/// the middle). The area of the slice at a is (1/2) integral of R^2 dphi over [0, 2 pi]
/// = pi r(a)^2 (1 + e^2 / 2) (the cross term integrates to zero over whole periods, cos^2 to
/// pi), whatever theta(a), so the enclosed volume is (1 + e^2 / 2) times that of the surface of
/// revolution of the same outline ([`Section::volume_factor`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Section {
    pub lobes: u32,
    pub eccentricity: f64,
    /// rad
    pub twist: f64,
}

impl Section {
    /// The circle: a surface of revolution (the factor is exactly 1).
    pub const CIRCLE: Section = Section { lobes: 1, eccentricity: 0.0, twist: 0.0 };

    /// R / r at the fraction s = (a - a_0) / L of the length and azimuth `phi` (rad).
    pub fn factor(&self, s: f64, phi: f64) -> f64 {
        1.0 + self.eccentricity * (f64::from(self.lobes) * (phi - self.twist * (s - 0.5))).cos()
    }

    /// Enclosed volume over that of the surface of revolution: 1 + e^2 / 2.
    pub fn volume_factor(&self) -> f64 {
        1.0 + 0.5 * self.eccentricity * self.eccentricity
    }
}

/// A closed outline from the bottom pole to the top pole.
#[derive(Clone, Debug)]
pub struct Profile {
    pub segments: Vec<Segment>,
}

impl Profile {
    /// Enclosed volume of the surface of revolution (m^3), see the module documentation.
    pub fn analytic_volume(&self) -> f64 {
        self.segments.iter().map(Segment::analytic_volume).sum()
    }

    /// Extent along the axis (m).
    pub fn length(&self) -> f64 {
        let a0 = self.segments[0].at(0.0)[0];
        let a1 = self.segments[self.segments.len() - 1].at(1.0)[0];
        a1 - a0
    }

    /// Largest radius (m), from the segments sampled at 1000 points each.
    pub fn max_radius(&self) -> f64 {
        self.segments.iter().flat_map(|s| (0..=1000).map(move |i| s.at(i as f64 / 1000.0)[1])).fold(0.0, f64::max)
    }

    /// Points of the outline at about `spacing` (m) apart, every segment end included, the
    /// poles first and last.
    pub fn sample(&self, spacing: f64) -> Vec<[f64; 2]> {
        let mut pts: Vec<[f64; 2]> = vec![self.segments[0].at(0.0)];
        for s in &self.segments {
            let n = ((s.length() / spacing).ceil() as usize).max(1);
            for i in 1..=n {
                pts.push(s.at(i as f64 / n as f64));
            }
        }
        pts
    }

    /// The closed, outward-oriented surface about the world x axis, centred on the origin,
    /// with the cross-section `section` ([`Section::CIRCLE`]: the surface of revolution), outline
    /// spacing `spacing` (m) and as many sectors as give that spacing on the largest radius
    /// times 1 + e (a multiple of 4, at least 32).
    ///
    /// # Errors
    /// When the outline does not start and end on the axis or touches it in between, or the
    /// section has e outside [0, 1) or k = 0.
    pub fn mesh(&self, spacing: f64, section: &Section) -> anyhow::Result<TriMesh> {
        let e = section.eccentricity;
        anyhow::ensure!((0.0..1.0).contains(&e) && section.lobes >= 1, "invalid section {section:?}");
        let pts = self.sample(spacing);
        let n = pts.len();
        anyhow::ensure!(n >= 3, "outline has fewer than 3 points");
        let tol = 1e-12;
        anyhow::ensure!(pts[0][1].abs() < tol && pts[n - 1][1].abs() < tol, "outline must start and end on the axis");
        anyhow::ensure!(pts[1..n - 1].iter().all(|p| p[1] > tol), "outline touches the axis between its poles");
        let largest = self.max_radius() * (1.0 + e);
        let sectors = (((2.0 * PI * largest / spacing).ceil() as usize).div_ceil(4) * 4).max(32);
        let (a0, len) = (pts[0][0], pts[n - 1][0] - pts[0][0]);
        let centre = 0.5 * (pts[0][0] + pts[n - 1][0]);
        let mut verts = vec![[pts[0][0] - centre, 0.0, 0.0]];
        for p in &pts[1..n - 1] {
            for j in 0..sectors {
                let phi = 2.0 * PI * j as f64 / sectors as f64;
                let r = p[1] * section.factor((p[0] - a0) / len, phi);
                verts.push([p[0] - centre, r * phi.cos(), r * phi.sin()]);
            }
        }
        let top = verts.len();
        verts.push([pts[n - 1][0] - centre, 0.0, 0.0]);
        let ring = |i: usize, j: usize| 1 + (i - 1) * sectors + (j % sectors);
        let mut tris = Vec::new();
        for j in 0..sectors {
            tris.push([0, ring(1, j + 1), ring(1, j)]);
        }
        for i in 1..n - 2 {
            for j in 0..sectors {
                let (a, b, c, d) = (ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1));
                tris.push([a, b, d]);
                tris.push([a, d, c]);
            }
        }
        for j in 0..sectors {
            tris.push([top, ring(n - 2, j), ring(n - 2, j + 1)]);
        }
        let mut mesh = TriMesh::try_new(verts, tris)?;
        if mesh.signed_volume() < 0.0 {
            mesh = mesh.flipped();
        }
        Ok(mesh)
    }
}

/// The generated objects: the paper's Table 2 objects (the hemisphere and the bunny are built
/// by `heatsim` from the scene's `object.kind`), and two shapes the reconstruction was not
/// tuned on (not in the table's default rows): a vase and a twisted spindle, the latter not
/// rotationally symmetric about its axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Revolved {
    /// A 6 cm ball (radius 30 mm).
    Ball,
    /// A 330 ml soda can: 66 mm diameter, 122 mm long, a 5 mm fillet at the bottom and a 9 mm
    /// rounded shoulder at the top.
    SodaCan,
    /// A 105 mm bottle: 48 mm body with four ring grooves (1.5 mm deep), an S-shaped shoulder to
    /// a 22 mm neck with a lip.
    Bottle1,
    /// A 105 mm bottle: 56 mm waisted body with eight shallow ribs (1 mm deep), a shoulder to a
    /// 26 mm neck.
    Bottle2,
    /// A 110 mm vase: 52 mm flat foot (5 mm fillet), a 68 mm belly at 40 mm, a concave waist of
    /// 28 mm at 88 mm and a lip flaring to 42 mm, closed by a flat disc (see `vase_r`).
    Vase,
    /// A 100 mm spindle (a lemon: one circular arc from pole to pole, 52 mm at the middle)
    /// with an oval cross-section, k = 2, e = 0.2 (62.4 mm x 41.6 mm at the middle, the long
    /// axis along world y there; e = 0.2 is the largest e for which the k = 2 section stays
    /// convex, R^2 + 2 R'^2 - R R'' >= 0 at phi - theta = pi / 2 needing 1 - e >= 4 e), twisted
    /// by 90 degrees from end to end ([`Section`]): no symmetry about the axis.
    TwistedSpindle,
}

fn gauss(a: f64, centre: f64, sigma: f64) -> f64 {
    (-0.5 * ((a - centre) / sigma).powi(2)).exp()
}

fn smoothstep(a: f64, a0: f64, a1: f64) -> f64 {
    let s = ((a - a0) / (a1 - a0)).clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

/// Bottle 1 (m): body radius 24 mm, bottom fillet 4 mm, grooves at 15, 27, 39, 51 mm
/// (depth 1.5 mm, sigma 1.2 mm), shoulder 62 -> 85 mm to the 11 mm neck, lip at 95 mm.
const B1: (f64, f64, f64) = (0.024, 0.004, 0.105);
fn bottle1_r(a: f64) -> f64 {
    let (rb, _, _) = B1;
    let grooves: f64 = [0.015, 0.027, 0.039, 0.051].iter().map(|&c| 0.0015 * gauss(a, c, 0.0012)).sum();
    let neck = 0.011;
    rb - grooves + (neck - rb) * smoothstep(a, 0.062, 0.085) + 0.001 * gauss(a, 0.095, 0.0012)
}

/// Bottle 2 (m): bottom radius 28 mm with a 5 mm fillet, waisted body (4 mm at 40 mm), ribs
/// every 8 mm from 12 to 68 mm (depth 1 mm, sigma 1.5 mm), shoulder 75 -> 92 mm to the 13 mm
/// neck.
const B2: (f64, f64, f64) = (0.028, 0.005, 0.105);
fn bottle2_r(a: f64) -> f64 {
    let (rb, fillet, _) = B2;
    let waist = 0.004 * (PI * ((a - fillet) / 0.070).clamp(0.0, 1.0)).sin().powi(2);
    let ribs: f64 = (0..8).map(|k| 0.001 * gauss(a, 0.012 + 0.008 * k as f64, 0.0015)).sum();
    let neck = 0.013;
    let body = rb - waist - ribs;
    body + (neck - body) * smoothstep(a, 0.075, 0.092)
}

/// Vase (m): foot radius 26 mm with a 5 mm fillet, then r(a) through the knots (a, r) =
/// (5, 26), (40, 34), (88, 14), (110, 21) mm with the quintic smootherstep
/// 6 s^5 - 15 s^4 + 10 s^3 between them (zero slope and curvature at every knot: C2 along the
/// curve, C1 where it meets the fillet; convex at the belly and the lip, concave at the waist,
/// inflections in between).
const VASE: (f64, f64, f64) = (0.026, 0.005, 0.110);
const VASE_KNOTS: [[f64; 2]; 4] = [[0.005, 0.026], [0.040, 0.034], [0.088, 0.014], [0.110, 0.021]];
fn vase_r(a: f64) -> f64 {
    let k = VASE_KNOTS;
    let i = (1..k.len() - 1).find(|&i| a < k[i][0]).unwrap_or(k.len() - 1);
    let (p, q) = (k[i - 1], k[i]);
    let s = ((a - p[0]) / (q[0] - p[0])).clamp(0.0, 1.0);
    p[1] + (q[1] - p[1]) * s * s * s * (s * (6.0 * s - 15.0) + 10.0)
}

/// Twisted spindle (m): half-length h = 50 mm, middle radius r_0 = 26 mm; the arc's centre
/// lies c = (h^2 - r_0^2) / (2 r_0) below the axis, its radius is c + r_0.
const SPINDLE: (f64, f64) = (0.050, 0.026);

impl Revolved {
    /// All generated objects.
    pub const ALL: [Revolved; 6] = [
        Revolved::Ball,
        Revolved::SodaCan,
        Revolved::Bottle1,
        Revolved::Bottle2,
        Revolved::Vase,
        Revolved::TwistedSpindle,
    ];

    /// The cross-section ([`Section::CIRCLE`] for the surfaces of revolution).
    pub fn section(self) -> Section {
        match self {
            Revolved::TwistedSpindle => Section { lobes: 2, eccentricity: 0.2, twist: 0.5 * PI },
            _ => Section::CIRCLE,
        }
    }

    /// Enclosed volume (m^3): the outline's ([`Profile::analytic_volume`]) times the
    /// section's [`Section::volume_factor`].
    pub fn analytic_volume(self) -> f64 {
        self.profile().analytic_volume() * self.section().volume_factor()
    }

    /// The outline (m).
    pub fn profile(self) -> Profile {
        use Segment::*;
        let segments = match self {
            Revolved::Ball => {
                let r = 0.030;
                vec![Arc { centre: [r, 0.0], radius: r, t0: PI, t1: 0.0 }]
            }
            Revolved::SodaCan => {
                let (r, h, fb, ft) = (0.033, 0.122, 0.005, 0.009);
                vec![
                    Line { from: [0.0, 0.0], to: [0.0, r - fb] },
                    Arc { centre: [fb, r - fb], radius: fb, t0: PI, t1: 0.5 * PI },
                    Line { from: [fb, r], to: [h - ft, r] },
                    Arc { centre: [h - ft, r - ft], radius: ft, t0: 0.5 * PI, t1: 0.0 },
                    Line { from: [h, r - ft], to: [h, 0.0] },
                ]
            }
            Revolved::Bottle1 | Revolved::Bottle2 => {
                let ((rb, fillet, h), r) = match self {
                    Revolved::Bottle1 => (B1, bottle1_r as fn(f64) -> f64),
                    _ => (B2, bottle2_r as fn(f64) -> f64),
                };
                let top = r(h);
                vec![
                    Line { from: [0.0, 0.0], to: [0.0, rb - fillet] },
                    Arc { centre: [fillet, rb - fillet], radius: fillet, t0: PI, t1: 0.5 * PI },
                    Curve { a0: fillet, a1: h, r },
                    Line { from: [h, top], to: [h, 0.0] },
                ]
            }
            Revolved::Vase => {
                let (rb, fillet, h) = VASE;
                vec![
                    Line { from: [0.0, 0.0], to: [0.0, rb - fillet] },
                    Arc { centre: [fillet, rb - fillet], radius: fillet, t0: PI, t1: 0.5 * PI },
                    Curve { a0: fillet, a1: h, r: vase_r },
                    Line { from: [h, vase_r(h)], to: [h, 0.0] },
                ]
            }
            Revolved::TwistedSpindle => {
                let (h, r0) = SPINDLE;
                let c = (h * h - r0 * r0) / (2.0 * r0);
                // From the pole at a = 0 (angle atan2(c, -h)) over the top to the pole at a = 2 h.
                vec![Arc { centre: [h, -c], radius: c + r0, t0: c.atan2(-h), t1: c.atan2(h) }]
            }
        };
        Profile { segments }
    }

    /// Name used in ids, CSV rows and file names.
    pub fn name(self) -> &'static str {
        match self {
            Revolved::Ball => "ball",
            Revolved::SodaCan => "soda_can",
            Revolved::Bottle1 => "bottle_1",
            Revolved::Bottle2 => "bottle_2",
            Revolved::Vase => "vase",
            Revolved::TwistedSpindle => "twisted_spindle",
        }
    }

    /// The closed surface lying on its side (axis along world x, centred on the origin) at
    /// outline spacing `spacing` (m), with its [`Revolved::section`], checked with
    /// [`TriMesh::validate_solid`].
    ///
    /// # Errors
    /// If the generated mesh is not a valid solid (a bug; the tests check every object).
    pub fn mesh(self, spacing: f64) -> anyhow::Result<TriMesh> {
        let m = self.profile().mesh(spacing, &self.section())?;
        m.validate_solid().map_err(|e| anyhow::anyhow!("generated {} mesh is not a valid solid: {e}", self.name()))?;
        Ok(m)
    }

    /// The OBJ file of [`Revolved::mesh`] at `spacing` (m) and its largest extent (m).
    ///
    /// # Errors
    /// As [`Revolved::mesh`].
    pub fn obj_file(self, spacing: f64) -> anyhow::Result<(Vec<u8>, f64)> {
        let mesh = self.mesh(spacing)?;
        let (lo, hi) = mesh.bounding_box();
        let size = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max);
        let mut bytes = Vec::new();
        let kind = if self.section() == Section::CIRCLE {
            "surface of revolution"
        } else {
            "swept surface with a twisted non-circular section"
        };
        let comment = format!("{}: {kind} lying on its side (axis x), metres; generated by simbench", self.name());
        heatsim::mesh::write_obj_to(&mut bytes, &mesh, &comment)?;
        Ok((bytes, size))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn const_r(_: f64) -> f64 {
        0.02
    }

    #[test]
    fn segment_volumes_agree_with_closed_forms() {
        // Cylinder side by a line and by a curve: pi r^2 L.
        let line = Segment::Line { from: [0.0, 0.02], to: [0.1, 0.02] };
        let curve = Segment::Curve { a0: 0.0, a1: 0.1, r: const_r };
        let cyl = PI * 0.02f64.powi(2) * 0.1;
        assert!((line.analytic_volume() / cyl - 1.0).abs() < 1e-14);
        assert!((curve.analytic_volume() / cyl - 1.0).abs() < 1e-12);
        // A cone: pi r^2 h / 3.
        let cone = Segment::Line { from: [0.0, 0.0], to: [0.05, 0.03] };
        assert!((cone.analytic_volume() / (PI * 0.03f64.powi(2) * 0.05 / 3.0) - 1.0).abs() < 1e-14);
        // A quarter arc from the pole: a hemisphere, (2/3) pi R^3.
        let r = 0.04;
        let quarter = Segment::Arc { centre: [r, 0.0], radius: r, t0: PI, t1: 0.5 * PI };
        assert!((quarter.analytic_volume() / (2.0 / 3.0 * PI * r.powi(3)) - 1.0).abs() < 1e-12);
        // Arc lengths.
        assert!((quarter.length() / (0.5 * PI * r) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn every_object_meshes_into_a_valid_solid_near_its_analytic_volume() {
        for o in Revolved::ALL {
            let m = o.mesh(2e-3).unwrap();
            let rel = m.signed_volume() / o.analytic_volume() - 1.0;
            // Inscribed polyhedron: below by about (2 pi / sectors)^2 / 6 plus the outline chords.
            assert!(rel < 0.0 && rel > -0.01, "{}: {rel}", o.name());
            // Finer spacing: closer (the error falls as spacing^2).
            let fine = o.mesh(0.5e-3).unwrap().signed_volume() / o.analytic_volume() - 1.0;
            assert!(fine < 0.0 && fine.abs() < 0.1 * rel.abs(), "{}: {fine} at 0.5 mm, {rel} at 2 mm", o.name());
        }
    }

    #[test]
    fn section_volume_factor_and_shape() {
        // An oval section of a sphere (an ellipsoid-like solid): 4/3 pi R^3 (1 + e^2 / 2), with or
        // without twist.
        let r = 0.03;
        let ball = Profile { segments: vec![Segment::Arc { centre: [r, 0.0], radius: r, t0: PI, t1: 0.0 }] };
        for twist in [0.0, PI] {
            let s = Section { lobes: 2, eccentricity: 0.3, twist };
            let m = ball.mesh(0.5e-3, &s).unwrap();
            m.validate_solid().unwrap();
            let exact = 4.0 / 3.0 * PI * r.powi(3) * 1.045;
            let rel = m.signed_volume() / exact - 1.0;
            assert!(rel.abs() < 2e-3, "twist {twist}: {rel}");
            // Untwisted: r (1 + e) along y; along z, with sin(phi) = u, the height
            // r (1 + e - 2 e u^2) u peaks at u^2 = (1 + e) / (6 e) (for e > 0.2 the section is
            // concave about phi = pi / 2).
            if twist == 0.0 {
                let (lo, hi) = m.bounding_box();
                let tol = 1e-3 * r;
                assert!((hi[1] - 1.3 * r).abs() < tol && (lo[1] + 1.3 * r).abs() < tol, "{hi:?} {lo:?}");
                let u = (1.3f64 / 1.8).sqrt();
                assert!((hi[2] - r * (1.3 - 0.6 * u * u) * u).abs() < tol, "{hi:?}");
            }
        }
        // The circle's factor is exactly 1: the surfaces of revolution are unchanged, bit for bit.
        for (s, phi) in [(0.0, 0.0), (0.3, 1.7), (1.0, 6.2)] {
            assert_eq!(Section::CIRCLE.factor(s, phi), 1.0);
        }
    }

    #[test]
    fn untuned_objects_have_their_stated_size() {
        let m = Revolved::Vase.mesh(0.5e-3).unwrap();
        let (lo, hi) = m.bounding_box();
        assert!((hi[0] - lo[0] - 0.110).abs() < 1e-9 && (hi[1] - 0.034).abs() < 1e-5, "{lo:?} {hi:?}");
        // The waist is the narrowest point between belly and lip.
        assert!((vase_r(0.088) - 0.014).abs() < 1e-12 && vase_r(0.080) > 0.014 && vase_r(0.095) > 0.014);
        let m = Revolved::TwistedSpindle.mesh(0.5e-3).unwrap();
        let (lo, hi) = m.bounding_box();
        assert!((hi[0] - lo[0] - 0.100).abs() < 1e-9, "{lo:?} {hi:?}");
        // Wide along y at the middle (1.2 r_0), not symmetric under phi -> -phi about x (the twist).
        assert!((hi[1] - 0.0312).abs() < 2e-4, "{hi:?}");
        let s = Revolved::TwistedSpindle.section();
        assert!((s.factor(0.2, 0.3) - s.factor(0.2, -0.3)).abs() > 0.05);
    }
}
