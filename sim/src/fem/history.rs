//! The last states of an implicit time integration, kept for the next step's starting guess.
//!
//! **Guess.** The polynomial of degree p through the last p + 1 states (K), one step ahead, in
//! Newton's backward-difference form: `T_guess = T^n + ∇T^n + ∇²T^n + … + ∇^p T^n`, with
//! `∇T^n = T^n - T^(n-1)`. For p = 2 that is `3 (T^n - T^(n-1)) + T^(n-2)`. Its error is
//! `O(dt^(p+1))` where the temperatures are smooth in time, but it carries the previous solves'
//! errors, multiplied by up to `2^(p+1) - 1`. While fewer than p + 1 states are known (the
//! first steps) the degree is lower.
//!
//! The degree suits the linear solver (`super::volumetric::Stepper::predictor_degree`): conjugate
//! gradients' iterations grow with the logarithm of the guess's error, a factor's chord iteration
//! needs one substitution however good the guess.

/// The states, most recent first, and the predictor's degree.
#[derive(Clone, Debug)]
pub struct History {
    /// `states[j]` is T^(n-j) (K); unknown ones hold the initial state.
    states: Vec<Vec<f64>>,
    /// How many of `states` are known: 1 + the steps taken, at most `states.len()`.
    known: usize,
    degree: usize,
}

/// The highest degree [`History::new`] accepts.
pub const MAX_DEGREE: usize = 4;

impl History {
    /// The history of an integration starting at `initial` (K), for guesses of degree `degree`
    /// (at most [`MAX_DEGREE`], larger values are taken as it).
    pub fn new(initial: &[f64], degree: usize) -> History {
        // Two states at least: the one before the latest is BDF2's (`previous`).
        let degree = degree.min(MAX_DEGREE);
        History { states: vec![initial.to_vec(); degree.max(1) + 1], known: 1, degree }
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
        self.states.rotate_right(1);
        self.states[0].copy_from_slice(t);
        self.known = (self.known + 1).min(self.states.len());
    }

    /// The starting guess of the next step into `guess` (module doc), over blocks of nodes in
    /// parallel.
    pub fn predict(&self, guess: &mut [f64]) {
        use rayon::prelude::*;
        const BLOCK: usize = 4096;
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
                    _ => {
                        let (d1, d2) = (s[0][i] - s[1][i], s[1][i] - s[2][i]);
                        let (d3, d4) = (s[2][i] - s[3][i], s[3][i] - s[4][i]);
                        s[0][i] + 4.0 * (d1 + d3) - 6.0 * d2 - d4
                    }
                };
            }
        });
    }
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
