//! The Metropolis sampler the paper uses to turn an information matrix into
//! marginals (Shin et al., IPSN 2005, Section 3.4, citing its ref. 4 for
//! Metropolis; evaluated in Section 5.1): a Markov chain over assignments
//! whose stationary distribution is p(π) ∝ exp(Σ_t L\[t\]\[π(t)\]).
//!
//! Each step proposes exchanging the identities of two distinct tracks
//! chosen uniformly (a symmetric proposal) and accepts with probability
//! min(1, e^Δ), Δ = L\[a\]\[π(b)\] + L\[b\]\[π(a)\] − L\[a\]\[π(a)\] − L\[b\]\[π(b)\],
//! O(1) per step. Transpositions generate S_N, so the chain is irreducible
//! for finite L and its time averages converge to the marginals.
//!
//! Choices (not in the paper): the chain starts at the most likely
//! assignment (Hungarian algorithm on L), which makes burn-in short when the
//! belief is peaked; every step after burn-in is counted (rejected steps
//! repeat the state, as Metropolis requires); counts are kept per track as
//! "time spent on the current identity", added when the identity changes,
//! so a step costs O(1) and not O(N). The generator is a seeded ChaCha8, so
//! answers are reproducible.

use super::assignment::min_cost_assignment;
use crate::error::BeliefError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Metropolis estimate of the marginals (row-major) of
/// p(π) ∝ exp(Σ_t l\[t·n + π(t)\]); entries finite or −∞ (ruled out).
pub fn metropolis_marginals(
    n: usize,
    l: &[f64],
    samples: usize,
    burn_in: usize,
    seed: u64,
) -> Result<Vec<f64>, BeliefError> {
    metropolis_diagnosed(n, l, samples, burn_in, seed).map(|run| run.marginals)
}

/// A Metropolis run: the marginals and how far the chain is from having
/// converged.
#[derive(Debug, Clone, PartialEq)]
pub struct MetropolisRun {
    /// Row-major n × n.
    pub marginals: Vec<f64>,
    /// The largest |p₁ − p₂| between the marginals of the first and the
    /// second half of the counted steps: a split-chain convergence
    /// diagnostic (in the spirit of Gelman–Rubin's split R̂). A chain that
    /// has mixed gives halves that agree up to sampling noise; one stuck
    /// in a mode, or still drifting away from its start, does not.
    pub half_difference: f64,
    /// The share of proposals accepted.
    pub acceptance: f64,
}

/// [`metropolis_marginals`] with its convergence diagnostic.
pub fn metropolis_diagnosed(
    n: usize,
    l: &[f64],
    samples: usize,
    burn_in: usize,
    seed: u64,
) -> Result<MetropolisRun, BeliefError> {
    if n == 0 {
        return Err(BeliefError::NoTracks);
    }
    if l.len() != n * n || l.iter().any(|x| x.is_nan() || *x == f64::INFINITY) {
        return Err(BeliefError::Numerical {
            step: "metropolis",
            detail: format!("need {n} × {n} log-likelihoods, finite or −∞"),
        });
    }
    if samples == 0 {
        return Err(BeliefError::Unsupported {
            method: "metropolis",
            what: "zero samples",
        });
    }
    // Start at the best assignment; a ruled-out pairing costs more than any
    // assignment of possible ones, so it is used only if nothing else is
    // possible — and then the belief is empty.
    let spread = l
        .iter()
        .filter(|x| x.is_finite())
        .fold(0.0f64, |m, x| m.max(x.abs()));
    let ruled_out_cost = (2.0 * spread + 1.0) * (n as f64 + 1.0);
    let cost: Vec<f64> = l
        .iter()
        .map(|&x| if x.is_finite() { -x } else { ruled_out_cost })
        .collect();
    let mut state: Vec<u32> = min_cost_assignment(n, &cost);
    if state
        .iter()
        .enumerate()
        .any(|(t, &i)| !l[t * n + i as usize].is_finite())
    {
        return Err(BeliefError::Degenerate { normalizer: 0.0 });
    }
    if n == 1 {
        return Ok(MetropolisRun {
            marginals: vec![1.0],
            half_difference: 0.0,
            acceptance: 1.0,
        });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let at = |t: usize, i: u32| l[t * n + i as usize];
    // One Metropolis step; on acceptance returns the two tracks and the
    // identities they held before. A swap onto a ruled-out pairing has
    // Δ = −∞ and is never accepted.
    let step = |state: &mut Vec<u32>, rng: &mut ChaCha8Rng| -> Option<[(usize, u32); 2]> {
        let a = rng.gen_range(0..n);
        let b = (a + rng.gen_range(1..n)) % n;
        let (ia, ib) = (state[a], state[b]);
        let delta = at(a, ib) + at(b, ia) - at(a, ia) - at(b, ib);
        if delta >= 0.0 || rng.gen::<f64>() < delta.exp() {
            state.swap(a, b);
            Some([(a, ia), (b, ib)])
        } else {
            None
        }
    };
    for _ in 0..burn_in {
        step(&mut state, &mut rng);
    }
    // Sample k is the state after counted step k. time[t·n + i] = samples
    // track t spent on identity i, settled up to sample `since[t]`.
    let mut time = vec![0u64; n * n];
    let mut since = vec![0u64; n];
    let total = samples as u64;
    let half = total / 2;
    let mut first_half: Option<Vec<u64>> = None;
    let mut accepted = 0u64;
    for k in 0..total {
        if k == half && half > 0 {
            let mut settled = time.clone();
            for t in 0..n {
                settled[t * n + state[t] as usize] += k - since[t];
            }
            first_half = Some(settled);
        }
        if let Some(changed) = step(&mut state, &mut rng) {
            accepted += 1;
            for (t, old) in changed {
                time[t * n + old as usize] += k - since[t];
                since[t] = k;
            }
        }
    }
    for t in 0..n {
        time[t * n + state[t] as usize] += total - since[t];
    }
    let half_difference = match first_half {
        Some(first) => first
            .iter()
            .zip(&time)
            .map(|(&a, &all)| {
                let p1 = a as f64 / half as f64;
                let p2 = (all - a) as f64 / (total - half) as f64;
                (p1 - p2).abs()
            })
            .fold(0.0, f64::max),
        None => f64::INFINITY,
    };
    Ok(MetropolisRun {
        marginals: time.iter().map(|&c| c as f64 / total as f64).collect(),
        half_difference,
        acceptance: accepted as f64 / total as f64,
    })
}
