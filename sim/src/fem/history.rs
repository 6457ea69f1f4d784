//! The last states of an implicit time integration, kept for the next step's starting guess.
//!
//! **Guess.** The polynomial of degree p through the last p + 1 states (K), one step ahead, in
//! Newton's backward-difference form: `T_guess = T^n + ∇T^n + ∇²T^n + … + ∇^p T^n`, with
//! `∇T^n = T^n - T^(n-1)`. For p = 2 that is `3 (T^n - T^(n-1)) + T^(n-2)`. Its error is
//! `O(dt^(p+1))` where the temperatures are smooth in time, but it carries the previous solves'
//! errors, multiplied by up to `2^(p+1) - 1`. While fewer than p + 1 states are known (the
//! first steps) the degree is lower.
//!
//! The degree suits the linear solver (`super::volumetric::Stepper::history`): conjugate
//! gradients' iterations grow with the logarithm of the guess's error, so with them the degree
//! is chosen per step ([`History::adaptive`]: the one in 2..=6 whose guess for the last step
//! was closest to its solution, as smooth stretches favour high degrees and a lamp switching on
//! low ones); a factor's chord iteration needs one substitution however good the guess, and
//! keeps degree 2.

/// The states, most recent first, and the predictor's degree.
#[derive(Clone, Debug)]
pub struct History {
    /// `states[j]` is T^(n-j) (K); unknown ones hold the initial state.
    states: Vec<Vec<f64>>,
    /// How many of `states` are known: 1 + the steps taken, at most `states.len()`.
    known: usize,
    degree: usize,
    /// With `Some(p)`, each push sets `degree` to the one in 2..=p whose guess for the pushed
    /// state would have been closest to it (max norm over every `SAMPLE`-th node).
    adaptive: Option<usize>,
}

/// The highest degree [`History::new`] accepts.
pub const MAX_DEGREE: usize = 6;

/// Rows per block of the parallel passes.
const BLOCK: usize = 4096;

impl History {
    /// The history of an integration starting at `initial` (K), for guesses of degree `degree`
    /// (at most [`MAX_DEGREE`], larger values are taken as it).
    pub fn new(initial: &[f64], degree: usize) -> History {
        // Two states at least: the one before the latest is BDF2's (`previous`).
        let degree = degree.min(MAX_DEGREE);
        History { states: vec![initial.to_vec(); degree.max(1) + 1], known: 1, degree, adaptive: None }
    }

    /// A history whose degree follows the data: after each step, the degree in 2..=`max_degree`
    /// whose guess would have been closest to the step's solution (largest difference over every
    /// 8th node) is the next step's.
    pub fn adaptive(initial: &[f64], max_degree: usize) -> History {
        let max_degree = max_degree.clamp(2, MAX_DEGREE);
        History { adaptive: Some(max_degree), ..History::new(initial, max_degree) }
    }

    /// The latest state T^n (K).
    pub fn latest(&self) -> &[f64] {
        &self.states[0]
    }

    /// The state before the latest, T^(n-1) (K); the initial state before the first step.
    pub fn previous(&self) -> &[f64] {
        &self.states[1]
    }

    /// Records the state after a step (K); it becomes the latest.
    pub fn push(&mut self, t: &[f64]) {
        if let Some(max_degree) = self.adaptive {
            self.degree = self.best_degree(t, max_degree);
        }
        self.states.rotate_right(1);
        self.states[0].copy_from_slice(t);
        self.known = (self.known + 1).min(self.states.len());
    }

    /// The starting guess of the next step into `guess` (module doc), over blocks of nodes in
    /// parallel.
    pub fn predict(&self, guess: &mut [f64]) {
        use rayon::prelude::*;
        let s = &self.states;
        let degree = (self.known - 1).min(self.degree);
        guess.par_chunks_mut(BLOCK).enumerate().for_each(|(k, g)| {
            for (j, gi) in g.iter_mut().enumerate() {
                let i = k * BLOCK + j;
                *gi = match degree {
                    0 => s[0][i],
                    1 => 2.0 * s[0][i] - s[1][i],
                    2 => 3.0 * (s[0][i] - s[1][i]) + s[2][i],
                    3 => {
                        let (d1, d2, d3) = (s[0][i] - s[1][i], s[1][i] - s[2][i], s[2][i] - s[3][i]);
                        s[0][i] + 3.0 * (d1 - d2) + d3
                    }
                    4 => {
                        let (d1, d2) = (s[0][i] - s[1][i], s[1][i] - s[2][i]);
                        let (d3, d4) = (s[2][i] - s[3][i], s[3][i] - s[4][i]);
                        s[0][i] + 4.0 * (d1 + d3) - 6.0 * d2 - d4
                    }
                    5 => {
                        let (d1, d2, d3) = (s[0][i] - s[1][i], s[1][i] - s[2][i], s[2][i] - s[3][i]);
                        let (d4, d5) = (s[3][i] - s[4][i], s[4][i] - s[5][i]);
                        s[0][i] + 5.0 * (d1 - d4) + 10.0 * (d3 - d2) + d5
                    }
                    _ => {
                        let (d1, d2, d3) = (s[0][i] - s[1][i], s[1][i] - s[2][i], s[2][i] - s[3][i]);
                        let (d4, d5, d6) = (s[3][i] - s[4][i], s[4][i] - s[5][i], s[5][i] - s[6][i]);
                        s[0][i] + 6.0 * (d1 + d5) + 20.0 * d3 - 15.0 * (d2 + d4) - d6
                    }
                };
            }
        });
    }

    /// The degree in 2..=`max_degree` (at most the known states allow) whose guess from the
    /// current states is closest to `t` in the largest difference over every `SAMPLE`-th node
    /// (the lowest on ties; the same for any thread count).
    fn best_degree(&self, t: &[f64], max_degree: usize) -> usize {
        let top = (self.known - 1).min(max_degree);
        if top <= 2 {
            return 2;
        }
        use rayon::prelude::*;
        // Blocks of whole samples (BLOCK is a multiple of SAMPLE); a maximum is exact in any order.
        let errors = t
            .par_chunks(BLOCK)
            .enumerate()
            .map(|(k, block)| {
                let mut errors = [0.0_f64; MAX_DEGREE + 1];
                for j in (0..block.len()).step_by(SAMPLE) {
                    let i = k * BLOCK + j;
                    let g = guesses(&self.states, i, top);
                    for p in 2..=top {
                        errors[p] = errors[p].max((block[j] - g[p]).abs());
                    }
                }
                errors
            })
            .reduce(|| [0.0; MAX_DEGREE + 1], |a, b| std::array::from_fn(|p| a[p].max(b[p])));
        (2..=top).fold(2, |best, p| if errors[p] < errors[best] { p } else { best })
    }
}

/// Every how many nodes [`History::best_degree`] compares the guesses.
const SAMPLE: usize = 8;
const _: () = assert!(BLOCK % SAMPLE == 0);

/// The guesses of degrees 0..=`top` at node `i` (entry p: degree p): the latest state plus
/// sum over j = 1..p of (-1)^(j-1) C(p, j) d_j, with d_j = T^(n-j+1) - T^(n-j) the first
/// differences (Newton's form summed). All degrees at once, for the comparison: one call per
/// degree takes every difference again (4 % slower steps on the tour and the cuboid).
fn guesses(states: &[Vec<f64>], i: usize, top: usize) -> [f64; MAX_DEGREE + 1] {
    let mut d = [0.0; MAX_DEGREE + 1];
    for j in 1..=top {
        d[j] = states[j - 1][i] - states[j][i];
    }
    let s0 = states[0][i];
    let mut g = [s0; MAX_DEGREE + 1];
    g[1] = s0 + d[1];
    g[2] = s0 + 2.0 * d[1] - d[2];
    if top >= 3 {
        g[3] = s0 + 3.0 * (d[1] - d[2]) + d[3];
    }
    if top >= 4 {
        g[4] = s0 + 4.0 * (d[1] + d[3]) - 6.0 * d[2] - d[4];
    }
    if top >= 5 {
        g[5] = s0 + 5.0 * (d[1] - d[4]) + 10.0 * (d[3] - d[2]) + d[5];
    }
    if top >= 6 {
        g[6] = s0 + 6.0 * (d[1] + d[5]) + 20.0 * d[3] - 15.0 * (d[2] + d[4]) - d[6];
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The guess of degree p is exact for states on a polynomial of degree p in time, and
    /// the degree grows with the states known.
    #[test]
    fn guess_is_exact_for_polynomials_of_its_degree() {
        for degree in 0..=MAX_DEGREE {
            // T(t) at two nodes: a polynomial of degree `degree` and one of degree + 1.
            let exact = |t: f64| {
                [(0..=degree).map(|k| (k as f64 + 1.5) * t.powi(k as i32)).sum::<f64>(), t.powi(degree as i32 + 1)]
            };
            let mut h = History::new(&exact(0.0), degree);
            for step in 1..=degree + 3 {
                let mut guess = [0.0; 2];
                h.predict(&mut guess);
                let want = exact(step as f64);
                if step > degree {
                    assert!(
                        (guess[0] - want[0]).abs() <= 1e-9 * want[0].abs(),
                        "degree {degree}, step {step}: {guess:?} against {want:?}"
                    );
                    // One degree more is not exact: the guess's degree is `degree`, not more.
                    assert!(
                        (guess[1] - want[1]).abs() > 0.5,
                        "degree {degree}, step {step}: {guess:?} against {want:?}"
                    );
                }
                h.push(&want);
            }
        }
    }

    /// The adaptive history picks the lowest degree whose guess is exact: on a cubic in time
    /// (integer values, so the differences are exact) degree 3, and on a quintic degree 5.
    #[test]
    fn adaptive_degree_follows_the_data() {
        for (exact_degree, want) in [(3, 3), (5, 5), (1, 2)] {
            let value = |t: f64| (0..=exact_degree).map(|k| (k as f64 + 2.0) * t.powi(k as i32)).sum::<f64>();
            let mut h = History::adaptive(&[value(0.0)], MAX_DEGREE);
            let mut guess = [0.0];
            for step in 1..=MAX_DEGREE + 3 {
                h.predict(&mut guess);
                if step > MAX_DEGREE + 1 {
                    assert_eq!(h.degree, want, "exact degree {exact_degree}, step {step}");
                    assert_eq!(guess[0], value(step as f64), "exact degree {exact_degree}, step {step}");
                }
                h.push(&[value(step as f64)]);
            }
        }
    }

    /// Degree 2 keeps the bits of the quadratic extrapolation the committed results were
    /// computed with: `3 (T^n - T^(n-1)) + T^(n-2)`, linear and constant before.
    #[test]
    fn degree_two_is_the_quadratic_extrapolation() {
        let states = [[0.1, 300.0], [0.7, 300.3], [1.9, 301.7], [2.3, 302.9]];
        let mut h = History::new(&states[0], 2);
        assert_eq!(h.previous(), &states[0]);
        let mut guess = [0.0; 2];
        h.predict(&mut guess);
        assert_eq!(guess, states[0]);
        h.push(&states[1]);
        h.predict(&mut guess);
        assert_eq!(guess, [2.0 * 0.7 - 0.1, 2.0 * 300.3 - 300.0]);
        h.push(&states[2]);
        h.push(&states[3]);
        h.predict(&mut guess);
        assert_eq!(guess, [3.0 * (2.3 - 1.9) + 0.7, 3.0 * (302.9 - 301.7) + 300.3]);
        assert_eq!((h.latest(), h.previous()), (&states[3][..], &states[2][..]));
    }
}
