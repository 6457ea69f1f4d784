//! The model stage 1 inverts, as a small forward solver for tests and benchmarks: the surface
//! heat equation (paper Eq. 6, per unit area) on a triangle mesh,
//! `C m_i (θ'_i - θ_i)/(Δ t) = k d (Lθ')_i +
//!    m_i(q_i - hθ'_i - εσ((T_s+θ'_i)^4 - T_s^4))`
//! (`L` the cotangent Laplacian, `m` the barycentric lumped area, backward Euler), or with Eq. 5's
//! linearised radiation. Solved by Newton's method with Jacobi-preconditioned conjugate
//! gradients (`-L` is positive semidefinite, so the Jacobian is SPD). It is an independent few
//! lines, not the project's surface solver.

use heatsim::surface::operators::{lumped_area, AreaMass, CotanLaplacian};

use super::SIGMA;

/// Parameters of [`simulate`].
#[derive(Clone, Debug)]
pub struct SyntheticModel {
    /// Heat capacity per area C = ρ c_p d, J/(m^2 K).
    pub heat_capacity: f64,
    /// Conductance k d, W/K.
    pub conductance: f64,
    /// Convection coefficient h, W/(m^2 K).
    pub convection: f64,
    /// Emissivity.
    pub emissivity: f64,
    /// Ambient temperature, K.
    pub ambient: f64,
    /// Full T^4 radiation (else Eq. 5).
    pub full_radiation: bool,
}

/// Rise θ (K) per vertex and frame, layout `[vertex * frames + frame]`, of a mesh starting at
/// ambient and heated by `flux` (W/m^2 per vertex) from t = 0; frame k at t = k * frame_dt,
/// each frame interval split into `substeps` backward-Euler steps.
pub fn simulate(
    model: &SyntheticModel,
    verts: &[[f64; 3]],
    tris: &[[usize; 3]],
    flux: &[f64],
    frames: usize,
    frame_dt: f64,
    substeps: usize,
) -> Vec<f64> {
    let n = verts.len();
    let lap = CotanLaplacian::new(verts, tris);
    let m = lumped_area(verts, tris, AreaMass::Barycentric);
    let diag_l = lap.diagonal();
    let dt = frame_dt / substeps as f64;
    let (ts, eps) = (model.ambient, model.emissivity);
    let rad = |th: f64| {
        if model.full_radiation {
            eps * SIGMA * ((ts + th).powi(4) - ts.powi(4))
        } else {
            4.0 * eps * SIGMA * ts.powi(3) * th
        }
    };
    let drad = |th: f64| {
        if model.full_radiation {
            4.0 * eps * SIGMA * (ts + th).powi(3)
        } else {
            4.0 * eps * SIGMA * ts.powi(3)
        }
    };
    let mut out = vec![0.0; n * frames];
    let mut th = vec![0.0; n];
    let mut lx = vec![0.0; n];
    for f in 1..frames {
        for _ in 0..substeps {
            let old = th.clone();
            for _newton in 0..20 {
                // Residual F(θ) = C m (θ - old)/dt - kd Lθ - m (q - hθ - rad(θ)).
                lap.apply(&th, &mut lx);
                let res: Vec<f64> = (0..n)
                    .map(|i| {
                        model.heat_capacity * m[i] * (th[i] - old[i]) / dt
                            - model.conductance * lx[i]
                            - m[i] * (flux[i] - model.convection * th[i] - rad(th[i]))
                    })
                    .collect();
                let jd: Vec<f64> = (0..n)
                    .map(|i| {
                        model.heat_capacity * m[i] / dt - model.conductance * diag_l[i]
                            + m[i] * (model.convection + drad(th[i]))
                    })
                    .collect();
                let jac = |x: &[f64], y: &mut [f64]| {
                    lap.apply(x, y);
                    for i in 0..n {
                        y[i] = (model.heat_capacity * m[i] / dt + m[i] * (model.convection + drad(th[i]))) * x[i]
                            - model.conductance * y[i];
                    }
                };
                let dx = pcg(&jac, &jd, &res, n);
                let mut big = 0.0f64;
                for i in 0..n {
                    th[i] -= dx[i];
                    big = big.max(dx[i].abs());
                }
                if big < 1e-14 {
                    break;
                }
            }
        }
        for i in 0..n {
            out[i * frames + f] = th[i];
        }
    }
    out
}

fn pcg(a: &dyn Fn(&[f64], &mut [f64]), diag: &[f64], b: &[f64], n: usize) -> Vec<f64> {
    let mut x = vec![0.0; n];
    let mut r = b.to_vec();
    let mut z: Vec<f64> = r.iter().zip(diag).map(|(r, d)| r / d).collect();
    let mut p = z.clone();
    let mut rz: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
    let b0: f64 = b.iter().map(|x| x * x).sum::<f64>().sqrt();
    let mut ap = vec![0.0; n];
    for _ in 0..10 * n + 100 {
        let rn: f64 = r.iter().map(|x| x * x).sum::<f64>().sqrt();
        if rn <= 1e-15 * b0 || rn == 0.0 {
            break;
        }
        a(&p, &mut ap);
        let alpha = rz / p.iter().zip(&ap).map(|(a, b)| a * b).sum::<f64>();
        for i in 0..n {
            x[i] += alpha * p[i];
            r[i] -= alpha * ap[i];
            z[i] = r[i] / diag[i];
        }
        let rz2: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
        let beta = rz2 / rz;
        rz = rz2;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
    }
    x
}
