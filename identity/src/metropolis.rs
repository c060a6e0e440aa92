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
//!
//! Large blocks (more than [`SUPPORT_PROPOSALS_FROM`] tracks) are sparse: a
//! track of a crowd's block of 9,590 can carry tens of identities, so a
//! uniformly chosen pair is almost never a possible swap and the chain
//! hardly moves. There a step picks a track a and one of the identities a
//! can carry, and proposes swapping with the track b that holds it — still
//! symmetric (see [`Chain::step`]), so the stationary distribution is the
//! same — and the start is found by the sparse assignment solver
//! ([`super::sparse_assignment`]) instead of the O(N³) dense one. L is kept
//! as compressed rows of its finite entries, and so are the counts.

use super::assignment::{min_cost_assignment, DENSE_ASSIGNMENT_LIMIT};
use super::sparse_assignment::{sparse_min_cost_assignment, SparseRow};
use idmesh_belief::BeliefError;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::sync::atomic::{AtomicBool, Ordering};

/// A Metropolis run: the marginals and how far the chain is from having
/// converged.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct MetropolisRun {
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
#[cfg(test)]
pub(crate) fn metropolis_diagnosed(
    n: usize,
    l: &[f64],
    samples: usize,
    burn_in: usize,
    seed: u64,
) -> Result<MetropolisRun, BeliefError> {
    metropolis_stoppable(n, l, samples, burn_in, seed, &AtomicBool::new(false))
}

/// Steps between two looks at the stop flag.
const STOP_EVERY: usize = 1 << 16;

/// [`metropolis_diagnosed`] that gives up with [`BeliefError::Stopped`]
/// within [`STOP_EVERY`] steps of `stop` being set.
pub(crate) fn metropolis_stoppable(
    n: usize,
    l: &[f64],
    samples: usize,
    burn_in: usize,
    seed: u64,
    stop: &AtomicBool,
) -> Result<MetropolisRun, BeliefError> {
    let stopped = |step: usize| {
        if step.is_multiple_of(STOP_EVERY) && stop.load(Ordering::Relaxed) {
            Err(BeliefError::Stopped {
                method: "metropolis",
            })
        } else {
            Ok(())
        }
    };
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
    let support = Support::of(n, l);
    let state = start(n, l, &support)?;
    if n == 1 {
        return Ok(MetropolisRun {
            marginals: vec![1.0],
            half_difference: 0.0,
            acceptance: 1.0,
        });
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut chain = Chain::at(state, &support, n > SUPPORT_PROPOSALS_FROM);
    for step in 0..burn_in {
        stopped(step)?;
        chain.step(&support, &mut rng);
    }
    // Sample k is the state after counted step k. time[q] = samples the
    // track of support entry q spent on its identity, settled up to sample
    // `since[t]`.
    let mut time = vec![0u64; support.ids.len()];
    let mut since = vec![0u64; n];
    let total = samples as u64;
    let half = total / 2;
    let mut first_half: Option<Vec<u64>> = None;
    let mut accepted = 0u64;
    for k in 0..total {
        stopped(k as usize)?;
        if k == half && half > 0 {
            let mut settled = time.clone();
            for t in 0..n {
                settled[chain.at[t]] += k - since[t];
            }
            first_half = Some(settled);
        }
        if let Some(changed) = chain.step(&support, &mut rng) {
            accepted += 1;
            for (t, old) in changed {
                time[old] += k - since[t];
                since[t] = k;
            }
        }
    }
    for t in 0..n {
        time[chain.at[t]] += total - since[t];
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
    let mut marginals = vec![0.0; n * n];
    for t in 0..n {
        for q in support.range(t) {
            marginals[t * n + support.ids[q] as usize] = time[q] as f64 / total as f64;
        }
    }
    Ok(MetropolisRun {
        marginals,
        half_difference,
        acceptance: accepted as f64 / total as f64,
    })
}

/// The chain's state: who carries what, where that sits in each track's
/// support, and who holds each identity.
struct Chain {
    state: Vec<u32>,
    at: Vec<usize>,
    holder: Vec<usize>,
    /// Proposals within a track's support (large blocks), else any pair.
    local: bool,
}

impl Chain {
    fn at(state: Vec<u32>, support: &Support, local: bool) -> Self {
        let at = state
            .iter()
            .enumerate()
            .map(|(t, &i)| support.find(t, i).unwrap_or(usize::MAX))
            .collect();
        let mut holder = vec![0usize; state.len()];
        for (t, &i) in state.iter().enumerate() {
            holder[i as usize] = t;
        }
        Chain {
            state,
            at,
            holder,
            local,
        }
    }

    /// One Metropolis step; on acceptance returns the two tracks and the
    /// support entries they held before. A swap onto a ruled-out pairing
    /// has Δ = −∞ and is never accepted.
    fn step(&mut self, support: &Support, rng: &mut ChaCha8Rng) -> Option<[(usize, usize); 2]> {
        let n = self.state.len();
        let a = rng.gen_range(0..n);
        let (b, a_to_b) = if self.local {
            // An identity a can carry, and whoever holds it: a symmetric
            // proposal (a pair {a, b} with both swaps possible is proposed
            // with probability (1/|S_a| + 1/|S_b|)/n either way).
            let range = support.range(a);
            let q = range.start + rng.gen_range(0..range.len());
            let b = self.holder[support.ids[q] as usize];
            if b == a {
                return None;
            }
            (b, Some(q))
        } else {
            let b = (a + rng.gen_range(1..n)) % n;
            (b, support.find(a, self.state[b]))
        };
        let (ia, ib) = (self.state[a], self.state[b]);
        let b_to_a = support.find(b, ia);
        let value = |q: Option<usize>| q.map_or(f64::NEG_INFINITY, |q| support.l[q]);
        let delta = value(a_to_b) + value(b_to_a) - support.l[self.at[a]] - support.l[self.at[b]];
        if delta >= 0.0 || rng.gen::<f64>() < delta.exp() {
            let before = [(a, self.at[a]), (b, self.at[b])];
            self.state.swap(a, b);
            self.at[a] = a_to_b.unwrap_or(usize::MAX);
            self.at[b] = b_to_a.unwrap_or(usize::MAX);
            self.holder[ib as usize] = a;
            self.holder[ia as usize] = b;
            Some(before)
        } else {
            None
        }
    }
}

/// Blocks larger than this propose swaps within a track's support (see
/// the module docs); smaller ones propose any pair, as the paper does.
pub(crate) const SUPPORT_PROPOSALS_FROM: usize = 100;

/// The chain's start: the most likely assignment. A ruled-out pairing
/// costs more than any assignment of possible ones, so it is used only if
/// nothing else is possible — and then the belief is empty.
fn start(n: usize, l: &[f64], support: &Support) -> Result<Vec<u32>, BeliefError> {
    let state = if n > DENSE_ASSIGNMENT_LIMIT {
        let rows: Vec<SparseRow> = (0..n)
            .map(|t| {
                support
                    .range(t)
                    .map(|q| (support.ids[q], -support.l[q]))
                    .collect()
            })
            .collect();
        sparse_min_cost_assignment(&rows).ok_or(BeliefError::Degenerate { normalizer: 0.0 })?
    } else {
        let spread = l
            .iter()
            .filter(|x| x.is_finite())
            .fold(0.0f64, |m, x| m.max(x.abs()));
        let ruled_out_cost = (2.0 * spread + 1.0) * (n as f64 + 1.0);
        let cost: Vec<f64> = l
            .iter()
            .map(|&x| if x.is_finite() { -x } else { ruled_out_cost })
            .collect();
        min_cost_assignment(n, &cost)
    };
    if state
        .iter()
        .enumerate()
        .any(|(t, &i)| !l[t * n + i as usize].is_finite())
    {
        return Err(BeliefError::Degenerate { normalizer: 0.0 });
    }
    Ok(state)
}

/// The finite entries of L row by row (compressed rows): the identities
/// each track can carry, ascending, and their log-likelihoods.
struct Support {
    /// Row t's entries are `offsets[t]..offsets[t + 1]`.
    offsets: Vec<usize>,
    ids: Vec<u32>,
    l: Vec<f64>,
}

impl Support {
    fn of(n: usize, l: &[f64]) -> Self {
        let mut support = Support {
            offsets: vec![0],
            ids: Vec::new(),
            l: Vec::new(),
        };
        for t in 0..n {
            for (i, &x) in l[t * n..(t + 1) * n].iter().enumerate() {
                if x.is_finite() {
                    support.ids.push(i as u32);
                    support.l.push(x);
                }
            }
            support.offsets.push(support.ids.len());
        }
        support
    }

    fn range(&self, t: usize) -> std::ops::Range<usize> {
        self.offsets[t]..self.offsets[t + 1]
    }

    /// The entry of track t for identity i, if t can carry i.
    fn find(&self, t: usize, i: u32) -> Option<usize> {
        let range = self.range(t);
        self.ids[range.clone()]
            .binary_search(&i)
            .ok()
            .map(|q| range.start + q)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::permanent::marginals_from_log_likelihoods;
    use rand::Rng;

    /// `groups` triples of tracks, each free within its own three
    /// identities, chained into one block by links of log-likelihood −40
    /// from each triple's last track to the next triple's first identity.
    /// Any assignment using a link needs two of them (e^−80 against the
    /// rest), so the exact marginals are the triples' own, to 1e-30.
    fn chained_triples(groups: usize, seed: u64) -> (usize, Vec<f64>, Vec<f64>) {
        let n = 3 * groups;
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut l = vec![f64::NEG_INFINITY; n * n];
        let mut exact = vec![0.0; n * n];
        for g in 0..groups {
            let local: Vec<f64> = (0..9).map(|_| rng.gen_range(-3.0..0.0)).collect();
            let p = marginals_from_log_likelihoods(3, &local).unwrap();
            for r in 0..3 {
                for c in 0..3 {
                    l[(3 * g + r) * n + 3 * g + c] = local[r * 3 + c];
                    exact[(3 * g + r) * n + 3 * g + c] = p[r * 3 + c];
                }
            }
            let next = (3 * (g + 1)) % n;
            l[(3 * g + 2) * n + next] = -40.0;
        }
        (n, l, exact)
    }

    #[test]
    fn a_large_sparse_block_converges_to_its_exact_marginals() {
        // 210 tracks: support proposals and the sparse start both run.
        let (n, l, exact) = chained_triples(70, 4);
        assert!(n > DENSE_ASSIGNMENT_LIMIT && DENSE_ASSIGNMENT_LIMIT > SUPPORT_PROPOSALS_FROM);
        assert_eq!(
            crate::blocks::blocks_of_log_likelihoods(n, &l).len(),
            1,
            "one block"
        );
        let run = metropolis_diagnosed(n, &l, 20_000 * n, 2_000 * n, 9).unwrap();
        let worst = run
            .marginals
            .iter()
            .zip(&exact)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 0.03, "largest error {worst}");
        assert!(run.half_difference < 0.05, "{}", run.half_difference);
        // Uniform pairs on the same block: most proposals are impossible
        // swaps, so far fewer are accepted.
        let support = Support::of(n, &l);
        let state = start(n, &l, &support).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let mut uniform = Chain::at(state.clone(), &support, false);
        let mut local = Chain::at(state, &support, true);
        let steps = 100_000;
        let moved = |chain: &mut Chain, rng: &mut ChaCha8Rng| {
            (0..steps)
                .filter(|_| chain.step(&support, rng).is_some())
                .count()
        };
        let (u, s) = (moved(&mut uniform, &mut rng), moved(&mut local, &mut rng));
        assert!(s > 20 * u.max(1), "accepted: uniform {u}, support {s}");
    }

    #[test]
    fn a_chain_stops_when_told() {
        let (n, l, _) = chained_triples(70, 4);
        let stop = AtomicBool::new(true);
        // A chain of 10^12 steps would run for hours.
        let e = metropolis_stoppable(n, &l, 1 << 40, 0, 1, &stop).unwrap_err();
        assert!(matches!(e, BeliefError::Stopped { .. }), "{e}");
        assert!(metropolis_stoppable(n, &l, 1_000, 0, 1, &AtomicBool::new(false)).is_ok());
    }
}
