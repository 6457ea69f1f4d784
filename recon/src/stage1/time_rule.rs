//! Time rules: how frames become the equations of stage 1. Each equation evaluates the model at
//! one instant through two functionals of the frames of a vertex, the state
//! `bar(x) = Σ_f μ_f x^f` and the rate `dot(x) = Σ_f δ_f x^f` (1/s):
//! - backward Euler, pair (k, k+1): `bar(x) = x^(k+1)`, `dot(x) = (x^(k+1) - x^k)/Δ t` (paper
//!   Eq. 7; exact for the surface solver with step = frame interval);
//! - trapezoid, pair (k, k+1): `bar(x) = (x^k + x^(k+1))/2`, same rate; second order;
//! - central, frame k: `bar(x) = x^k`, `dot(x) = (x^(k-2) - 8x^(k-1) + 8x^(k+1) - x^(k+2))/(12Δ t)`;
//!   fourth order for the continuous-time heating a camera films (uniform frames only).
//!
//! For white noise the rate of the trapezoid and of the central rule is uncorrelated with the
//! state (antisymmetric about the state's instant).

/// Which time rule turns frames into equations (module doc).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize, schemars::JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum TimeRule {
    /// Pairs (k, k+1), `bar(x) = x^(k+1)`: Eq. 7 exactly (the surface solver's backward Euler
    /// with step = frame).
    BackwardEuler,
    /// Pairs (k, k+1), `bar(x) = (x^k + x^(k+1))/2`: second order in the frame interval.
    Trapezoid,
    /// The continuous-time equation at frame k: `bar(x) = x^k` and the five-point derivative
    /// `(x^(k-2) - 8x^(k-1) + 8x^(k+1) - x^(k+2))/(12Δ t)`, fourth order (uniformly spaced
    /// frames only).
    Central,
}

/// One equation's frame functionals: `bar(x) = Σ_f` `mix` `x^f` and
/// `dot(x) = Σ_f` `deriv` `x^f` (1/s).
#[derive(Clone, Debug, PartialEq)]
pub struct FrameRule {
    /// `(frame, weight)` of the mix.
    pub mix: Vec<(usize, f64)>,
    /// `(frame, weight)` of the derivative, 1/s.
    pub deriv: Vec<(usize, f64)>,
}

impl FrameRule {
    pub(crate) fn apply(terms: &[(usize, f64)], x: impl Fn(usize) -> f64) -> f64 {
        terms.iter().map(|&(f, w)| w * x(f)).sum()
    }
}

impl TimeRule {
    /// The equations of frames at `times` (s) whose frames all lie in [`t_start`, `t_end`]:
    /// `(anchor frame, functionals)`, the anchor being the pair's first frame or the centre.
    pub fn equations(self, times: &[f64], t_start: f64, t_end: f64) -> Vec<(usize, FrameRule)> {
        let tol = 1e-9;
        let inside = |a: usize, b: usize| times[a] >= t_start - tol && times[b] <= t_end + tol;
        let pair = |k: usize, w: f64| {
            let dt = times[k + 1] - times[k];
            FrameRule { mix: vec![(k, 1.0 - w), (k + 1, w)], deriv: vec![(k, -1.0 / dt), (k + 1, 1.0 / dt)] }
        };
        let n = times.len();
        match self {
            TimeRule::BackwardEuler | TimeRule::Trapezoid => {
                let w = if self == TimeRule::BackwardEuler { 1.0 } else { 0.5 };
                (0..n.saturating_sub(1)).filter(|&k| inside(k, k + 1)).map(|k| (k, pair(k, w))).collect()
            }
            TimeRule::Central => (2..n.saturating_sub(2))
                .filter(|&k| inside(k - 2, k + 2))
                .filter_map(|k| {
                    let dt = (times[k + 2] - times[k - 2]) / 4.0;
                    let uniform = (0..5).all(|j| (times[k - 2 + j] - times[k - 2] - j as f64 * dt).abs() <= 1e-6 * dt);
                    let c = 1.0 / (12.0 * dt);
                    uniform.then(|| {
                        let deriv = vec![(k - 2, c), (k - 1, -8.0 * c), (k + 1, 8.0 * c), (k + 2, -c)];
                        (k, FrameRule { mix: vec![(k, 1.0)], deriv })
                    })
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The central rule differentiates quartics exactly and needs its five frames inside the
    /// window; pairs cover consecutive frames.
    #[test]
    fn rules_and_windows() {
        let times: Vec<f64> = (0..12).map(|k| -1.0 + 0.5 * k as f64).collect();
        let x = |t: f64| 1.0 + t - 2.0 * t * t + 0.5 * t.powi(3) + 0.1 * t.powi(4);
        let dx = |t: f64| 1.0 - 4.0 * t + 1.5 * t * t + 0.4 * t.powi(3);
        let eqs = TimeRule::Central.equations(&times, 0.0, f64::INFINITY);
        assert_eq!(eqs.first().map(|e| e.0), Some(4), "first centre with t_(k-2) >= 0");
        assert_eq!(eqs.last().map(|e| e.0), Some(9));
        for (k, rule) in &eqs {
            let rate = FrameRule::apply(&rule.deriv, |f| x(times[f]));
            assert!((rate - dx(times[*k])).abs() < 1e-12, "frame {k}: {rate} vs {}", dx(times[*k]));
            assert_eq!(FrameRule::apply(&rule.mix, |f| x(times[f])), x(times[*k]));
        }
        let pairs = TimeRule::Trapezoid.equations(&times, 0.0, 3.0);
        assert_eq!(pairs.iter().map(|e| e.0).collect::<Vec<_>>(), vec![2, 3, 4, 5, 6, 7]);
        let (_, be) = &TimeRule::BackwardEuler.equations(&times, 0.0, 3.0)[0];
        assert_eq!(be.mix, vec![(2, 0.0), (3, 1.0)]);
        // Non-uniform frames: no central equation spans the irregular step.
        let mut jittered = times.clone();
        jittered[6] += 0.1;
        let centres: Vec<usize> =
            TimeRule::Central.equations(&jittered, 0.0, f64::INFINITY).iter().map(|e| e.0).collect();
        assert!(centres.iter().all(|&k| k.abs_diff(6) > 2), "{centres:?}");
    }
}
