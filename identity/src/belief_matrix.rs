//! The belief matrix of Shin, Guibas and Zhao (IPSN 2003), as described in
//! Shin et al., *Lazy Inference on Object Identities* (IPSN 2005), Sections
//! 1 and 4 (and its slides, "Identity Belief Matrix"): keep only the N × N
//! marginals B\[t\]\[i\] = P(track t carries identity i), a doubly stochastic
//! matrix.
//!
//! - Mixing of tracks a and b with swap probability s replaces the two rows
//!   (the paper's columns) by b_a' = (1 − s)·b_a + s·b_b and
//!   b_b' = (1 − s)·b_b + s·b_a. This is exact on the marginals — it is what
//!   the joint convolution does to them — and keeps the matrix doubly
//!   stochastic. O(N).
//! - A read multiplies row t entrywise by the read's likelihood
//!   P(read | identity i) and renormalizes the *whole* matrix to doubly
//!   stochastic by Sinkhorn iterations: the read about track t also says
//!   something about every other track (if t is "car", no other track is).
//!   This is the approximation of the method (the joint is not kept) and the
//!   normalization whose network cost the information matrix avoids.
//!   Non-convergence within the iteration cap is an error.

use super::event::{check_assignment, check_identify, check_mix, Identify};
use super::filter::{to_rows, IdentityFilter, Marginals};
use super::sinkhorn::{sinkhorn, SinkhornOptions};
use idmesh_belief::BeliefError;
use idmesh_belief::Mix;

/// A doubly stochastic N × N matrix of marginals.
#[derive(Debug, Clone, PartialEq)]
pub struct BeliefMatrix {
    n: usize,
    /// Row-major; row t = the distribution of track t's identity.
    b: Vec<f64>,
    options: SinkhornOptions,
}

impl BeliefMatrix {
    /// Every track equally likely to carry every identity.
    pub fn uniform(n: usize) -> Result<Self, BeliefError> {
        Self::uniform_with(n, SinkhornOptions::default())
    }

    /// [`BeliefMatrix::uniform`] with explicit Sinkhorn options.
    pub(crate) fn uniform_with(n: usize, options: SinkhornOptions) -> Result<Self, BeliefError> {
        if n == 0 {
            return Err(BeliefError::NoTracks);
        }
        options.validate()?;
        Ok(BeliefMatrix {
            n,
            b: vec![1.0 / n as f64; n * n],
            options,
        })
    }

    /// Track t surely carries identity `assignment[t]`.
    pub fn from_assignment(assignment: &[u32]) -> Result<Self, BeliefError> {
        Self::from_assignment_with(assignment, SinkhornOptions::default())
    }

    /// [`BeliefMatrix::from_assignment`] with explicit Sinkhorn options.
    pub(crate) fn from_assignment_with(
        assignment: &[u32],
        options: SinkhornOptions,
    ) -> Result<Self, BeliefError> {
        let n = assignment.len();
        if n == 0 {
            return Err(BeliefError::NoTracks);
        }
        check_assignment(n, assignment)?;
        options.validate()?;
        let mut b = vec![0.0; n * n];
        for (t, &i) in assignment.iter().enumerate() {
            b[t * n + i as usize] = 1.0;
        }
        Ok(BeliefMatrix { n, b, options })
    }

    /// B\[t\]\[i\].
    pub fn get(&self, track: usize, identity: usize) -> Option<f64> {
        (track < self.n && identity < self.n).then(|| self.b[track * self.n + identity])
    }
}

impl IdentityFilter for BeliefMatrix {
    fn size(&self) -> usize {
        self.n
    }

    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        check_mix(self.n, &mix)?;
        let (a, b, s, n) = (mix.a as usize, mix.b as usize, mix.swap, self.n);
        for i in 0..n {
            let (x, y) = (self.b[a * n + i], self.b[b * n + i]);
            self.b[a * n + i] = (1.0 - s) * x + s * y;
            self.b[b * n + i] = (1.0 - s) * y + s * x;
        }
        Ok(())
    }

    fn identify(&mut self, identify: Identify) -> Result<(), BeliefError> {
        let n = self.n;
        check_identify(n, &identify)?;
        let t = identify.track as usize;
        // Work on a copy: Sinkhorn can fail, and the update is all-or-nothing.
        let mut next = self.b.clone();
        for (i, x) in next[t * n..(t + 1) * n].iter_mut().enumerate() {
            *x *= identify.likelihood(n, i);
        }
        match sinkhorn(n, &mut next, &self.options) {
            Ok(_) => {
                self.b = next;
                Ok(())
            }
            // No positive diagonal left: the read contradicts the belief
            // (a perfect read of an identity the track cannot carry).
            Err(BeliefError::Degenerate { .. }) => {
                Err(BeliefError::ImpossibleObservation { probability: 0.0 })
            }
            Err(e) => Err(e),
        }
    }

    fn marginals(&self) -> Result<Marginals, BeliefError> {
        Ok(to_rows(self.n, &self.b))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::ExactPermutationFilter;
    use crate::filter::{doubly_stochastic_residual, max_abs_difference};
    use crate::workload::{generate, IdentityWorkloadSpec};
    use proptest::prelude::*;

    fn read(track: u32, identity: u32, accuracy: f64) -> Identify {
        Identify {
            track,
            identity,
            accuracy,
        }
    }

    #[test]
    fn mixing_alone_is_exact_on_marginals() {
        // With no reads the belief matrix equals the exact marginals.
        let mut bm = BeliefMatrix::from_assignment(&[0, 1, 2, 3]).unwrap();
        let mut ex = ExactPermutationFilter::from_assignment(&[0, 1, 2, 3]).unwrap();
        for (a, b, swap) in [(0, 1, 0.5), (1, 2, 0.3), (2, 3, 0.9), (0, 3, 0.1)] {
            let m = Mix { a, b, swap };
            bm.mix(m).unwrap();
            ex.mix(m).unwrap();
        }
        let diff = max_abs_difference(&bm.marginals().unwrap(), &ex.marginals().unwrap());
        assert!(diff < 1e-15, "{diff}");
    }

    #[test]
    fn a_read_renormalizes_every_track() {
        // Slides' example: tracks 0 and 1 mixed; a read of identity 0 on
        // track 0 also moves track 1 towards identity 1.
        let mut bm = BeliefMatrix::from_assignment(&[0, 1, 2]).unwrap();
        bm.mix(Mix {
            a: 0,
            b: 1,
            swap: 0.5,
        })
        .unwrap();
        bm.identify(read(0, 0, 0.9)).unwrap();
        let m = bm.marginals().unwrap();
        assert!(doubly_stochastic_residual(&m) < 1e-10);
        // The exact posterior has odds 0.9/0.05 = 18 for "no swap"; Sinkhorn
        // scaling keeps the cross ratio of the 2 × 2 block, which makes the
        // *squared* odds 18: the belief matrix is not exact even here.
        let odds = 18f64.sqrt();
        assert!((m[0][0] - odds / (1.0 + odds)).abs() < 1e-9);
        assert!((m[1][1] - odds / (1.0 + odds)).abs() < 1e-9);
        assert_eq!(m[2][2], 1.0);
    }

    #[test]
    fn perfect_and_impossible_reads() {
        let mut bm = BeliefMatrix::uniform(3).unwrap();
        bm.identify(read(0, 2, 1.0)).unwrap();
        let m = bm.marginals().unwrap();
        assert_eq!(m[0], vec![0.0, 0.0, 1.0]);
        assert!(m[1][2] == 0.0 && m[2][2] == 0.0);
        assert!(doubly_stochastic_residual(&m) < 1e-10);
        let before = bm.clone();
        assert_eq!(
            bm.identify(read(1, 2, 1.0)),
            Err(BeliefError::ImpossibleObservation { probability: 0.0 })
        );
        assert_eq!(bm, before);
        assert!(bm
            .mix(Mix {
                a: 0,
                b: 0,
                swap: 0.5
            })
            .is_err());
        assert_eq!(bm, before);
    }

    #[test]
    fn non_convergence_is_reported_and_changes_nothing() {
        let opts = SinkhornOptions {
            tolerance: 1e-15,
            max_iterations: 1,
        };
        let mut bm = BeliefMatrix::uniform_with(4, opts).unwrap();
        bm.identify(read(0, 0, 0.9)).ok();
        let before = bm.clone();
        let r = bm.identify(read(1, 0, 0.7));
        assert!(matches!(r, Err(BeliefError::Numerical { .. })), "{r:?}");
        assert_eq!(bm, before);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Mixes and reads keep the belief matrix doubly stochastic.
        #[test]
        fn stays_doubly_stochastic(
            n in 1usize..=8,
            seed in any::<u64>(),
            mix_share in 0.0f64..=1.0,
            accuracy in 0.05f64..=0.99,
            swap in 0.0f64..=1.0,
        ) {
            let spec = IdentityWorkloadSpec {
                tracks: n,
                events: 40,
                mix_share,
                swap,
                accuracy,
                neighbourhood: n,
                seed,
            };
            let w = generate(&spec).unwrap();
            let mut bm = BeliefMatrix::from_assignment(&w.initial).unwrap();
            for e in &w.events {
                bm.apply(e).unwrap();
                let m = bm.marginals().unwrap();
                prop_assert!(doubly_stochastic_residual(&m) < 1e-9);
                prop_assert!(m.iter().flatten().all(|&x| x >= 0.0));
            }
        }
    }
}
