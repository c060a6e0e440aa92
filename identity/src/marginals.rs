//! Marginals on demand from an information matrix (Shin et al., IPSN 2005,
//! Section 3.4): the query that pays for the lazy evidence updates. Three
//! ways, chosen by [`MarginalMethod`]:
//!
//! - [`MarginalMethod::Exact`] — the permanent of exp(L) by Ryser's formula
//!   ([`crate::permanent`]), O(2^N·N), N ≤ 22. The paper computed
//!   the N! joint probabilities instead.
//! - [`MarginalMethod::Metropolis`] — the paper's sampler
//!   ([`crate::metropolis`]); converges like 1/√samples.
//! - [`MarginalMethod::Sinkhorn`] — scale exp(L) to a doubly stochastic
//!   matrix ([`crate::sinkhorn`]), O(N²) per sweep. Not in the
//!   paper. It is deterministic and cheap but *biased*, even for N = 2:
//!   scaling keeps the cross ratio A₀₀A₁₁/(A₀₁A₁₀) of exp(L), which is the
//!   exact odds p/(1 − p), whereas the scaled matrix has odds
//!   [p/(1 − p)]² — Sinkhorn returns odds √(exact odds), less confident
//!   than the truth. (In variational terms Sinkhorn minimizes
//!   Σ γ ln(γ/A) over doubly stochastic γ, whose entropy term counts the
//!   uncertainty of a 2-assignment belief twice.) The tests measure its
//!   error; it is an estimate of the right shape, not of the right
//!   sharpness.
//! - [`MarginalMethod::FractionalBethe`] — the stationary point of the
//!   fractional Bethe free energy of the matching problem (Chertkov and
//!   Yedidia, "Approximating the permanent with fractional belief
//!   propagation", JMLR 2013):
//!
//!     F_γ(P) = Σ_ij P_ij ln(P_ij/A_ij) − γ·Σ_ij (1 − P_ij) ln(1 − P_ij)
//!
//!   over doubly stochastic P. γ = 0 is plain Sinkhorn, γ = 1 the Bethe
//!   (belief propagation) approximation. Setting the gradient to the row and
//!   column multipliers gives P_ij·(1 − P_ij)^γ = A_ij·x_i·y_j, i.e. the
//!   fixed point P = Sinkhorn(A ⊙ (1 − P)^{−γ}), which we iterate. For
//!   N = 2 (P = [[p, q], [q, p]]) the entropy terms give odds
//!   p/q = (exact odds)^{1/(2(1−γ))}: γ = ½ is *exact* for two tracks,
//!   while pure Bethe (γ = 1) collapses to 0/1 there. γ = ½ is our default
//!   ([`MarginalMethod::half_bethe`]); the tests measure it against the
//!   permanent for N = 3..6. 1 − P_ij is computed as the sum of the other
//!   entries of its row, so it does not round to 0 for confident entries.

//!
//! ## Block by block
//! Every method works on the independent blocks of the belief
//! ([`crate::blocks`]: the components of the pattern of finite
//! entries of L — with a known start, the groups of tracks that mixing has
//! connected) one at a time, and the marginals between blocks are 0. So
//! the cost is that of the largest block, not of n: at n = 10,000 a known
//! start plus a crowd's mixes leaves blocks of a few tracks, each answered
//! exactly. [`MarginalMethod::Auto`], the default, is exact on blocks of
//! at most [`AUTO_EXACT_BLOCK`] tracks, half-Bethe on blocks of at most
//! [`AUTO_BETHE_BLOCK`], and Metropolis ([`AUTO_STEPS_PER_TRACK`] steps per
//! track) beyond; a method that cannot take a block (exact beyond
//! [`super::permanent::MAX_PERMANENT_TRACKS`], `sinkhorn` and `bethe`
//! beyond [`MAX_SCALED_BLOCK`]) says so with the block's size
//! ([`BeliefError::TooLargeBlock`]).
//!
//! Why Metropolis on the largest blocks: a crowd's mixing graph percolates.
//! The simulated crowd of 1,000 people of the process test is one block of
//! 197 tracks after 10 s and of 901 after 20 s. Scaling such a block
//! (Sinkhorn, and half-Bethe, which scales once per fixed-point step)
//! converges slowly on its peaked entries even by Newton–CG over the
//! positive entries alone: a Sinkhorn query on that stream took about 2
//! minutes at the 550-track block and did not finish the 900-track one
//! in 3 minutes, whereas Metropolis answers the 956-track block of the
//! bench's `crowd` stream in 0.16 s. Metropolis always answers in time
//! linear in its steps; it is the least accurate method of the block
//! (split-half diagnostic in [`super::metropolis::metropolis_diagnosed`]).

use super::assignment::most_likely_assignment;
use super::blocks::{blocks_of_log_likelihoods, sub_matrix, Block};
use super::filter::to_rows;
use super::metropolis::{metropolis_stoppable, MetropolisRun};
use super::permanent::{exp_rows, marginals_from_log_likelihoods, MAX_PERMANENT_TRACKS};
use super::sinkhorn::{sinkhorn, SinkhornOptions};
use super::sparse_marginals::{IdentityRow, SparseMarginals};
use idmesh_belief::BeliefError;
use std::sync::atomic::{AtomicBool, Ordering};

/// How marginals are computed from an information matrix.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum MarginalMethod {
    /// Exact, by the permanent, on blocks of at most
    /// [`super::permanent::MAX_PERMANENT_TRACKS`] tracks.
    Exact,
    /// Exact on blocks of at most [`AUTO_EXACT_BLOCK`] tracks, the
    /// half-Bethe estimate on larger blocks: answers at any size.
    #[default]
    Auto,
    /// The paper's Metropolis sampler, run on each block: `samples` counted
    /// steps after `burn_in` uncounted ones per block, from a ChaCha8
    /// generator seeded by `seed`.
    Metropolis {
        samples: usize,
        burn_in: usize,
        seed: u64,
    },
    /// Sinkhorn scaling of exp(L) (approximate, see the module docs).
    Sinkhorn,
    /// The fractional Bethe fixed point with parameter `gamma` in [0, 1]
    /// (see the module docs; ½ is exact for N = 2), iterated at most
    /// `max_iterations` times until no marginal moves more than
    /// `tolerance`.
    FractionalBethe {
        gamma: f64,
        max_iterations: usize,
        tolerance: f64,
    },
}

/// Counted Metropolis steps when none are asked for.
pub const DEFAULT_SAMPLES: usize = 10_000;

/// The largest block [`MarginalMethod::Auto`] answers exactly (2^16
/// Gray-code steps of 16² each: about a millisecond).
pub(crate) const AUTO_EXACT_BLOCK: usize = 16;

/// The largest block [`MarginalMethod::Auto`] answers by half-Bethe (a
/// block of 96 tracks of the bench's `crowd` stream: 0.17 s); larger ones
/// by Metropolis (see the module docs).
pub(crate) const AUTO_BETHE_BLOCK: usize = 100;

/// The largest block the scaling methods (`sinkhorn`, `bethe`) take: the
/// size up to which a Newton step is a Cholesky solve (of the N × N Schur
/// complement above 400 tracks: [`super::sinkhorn::MAX_SCHUR_TRACKS`]).
/// Beyond it the conjugate-gradient steps crawl on a crowd's peaked block (a Sinkhorn query took
/// about 2 minutes on a block of 550 tracks, and more than 3 on one of
/// 900), so they refuse, naming the block, instead of holding the query.
pub(crate) const MAX_SCALED_BLOCK: usize = super::sinkhorn::MAX_SCHUR_TRACKS;

/// Counted Metropolis steps per track of a block [`MarginalMethod::Auto`]
/// samples (a tenth as many burn-in steps, seed 0): a chain of 10^4 steps
/// would barely move a 900-track block from its start.
pub(crate) const AUTO_STEPS_PER_TRACK: usize = 1_000;

impl MarginalMethod {
    /// The method a command line or a query names: `auto`, `exact`,
    /// `metropolis` (`samples` counted steps after a tenth as many burn-in
    /// steps, from `seed`), `sinkhorn` or `bethe` (γ = ½).
    pub fn named(name: &str, samples: usize, seed: u64) -> Option<Self> {
        Some(match name {
            "auto" => MarginalMethod::Auto,
            "exact" => MarginalMethod::Exact,
            "metropolis" => MarginalMethod::Metropolis {
                samples,
                burn_in: samples / 10,
                seed,
            },
            "sinkhorn" => MarginalMethod::Sinkhorn,
            "bethe" => MarginalMethod::half_bethe(),
            _ => return None,
        })
    }

    /// The name [`MarginalMethod::named`] reads.
    pub fn name(&self) -> &'static str {
        match self {
            MarginalMethod::Auto => "auto",
            MarginalMethod::Exact => "exact",
            MarginalMethod::Metropolis { .. } => "metropolis",
            MarginalMethod::Sinkhorn => "sinkhorn",
            MarginalMethod::FractionalBethe { .. } => "bethe",
        }
    }

    /// [`MarginalMethod::FractionalBethe`] with γ = ½, 1,000 iterations,
    /// tolerance 1e-10.
    pub fn half_bethe() -> Self {
        MarginalMethod::FractionalBethe {
            gamma: 0.5,
            max_iterations: 1_000,
            tolerance: 1e-10,
        }
    }
}

/// Marginals block by block: for each independent block, its tracks, its
/// identities and the block's k × k marginals (row-major). Entries between
/// blocks are 0.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockMarginals {
    pub n: usize,
    pub blocks: Vec<(Block, Vec<f64>)>,
    /// How far the blocks answered by Metropolis are from converged; None
    /// when no block was sampled.
    pub sampling: Option<Sampling>,
}

/// The convergence diagnostic of the blocks answered by Metropolis
/// ([`super::metropolis::MetropolisRun`]): what a user needs to know
/// whether sampled marginals can be trusted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sampling {
    /// How many blocks were sampled.
    pub blocks: usize,
    /// The largest split-half difference |p₁ − p₂| over them: about the
    /// sampling error of the worst marginal (0.01 and below: mixed).
    pub half_difference: f64,
    /// The smallest share of proposals accepted.
    pub acceptance: f64,
}

impl Sampling {
    fn of(run: &MetropolisRun) -> Self {
        Sampling {
            blocks: 1,
            half_difference: run.half_difference,
            acceptance: run.acceptance,
        }
    }

    fn and(self, other: Sampling) -> Self {
        Sampling {
            blocks: self.blocks + other.blocks,
            half_difference: self.half_difference.max(other.half_difference),
            acceptance: self.acceptance.min(other.acceptance),
        }
    }
}

impl BlockMarginals {
    /// The n × n marginals, row-major.
    pub fn dense(&self) -> Vec<f64> {
        let n = self.n;
        let mut out = vec![0.0; n * n];
        for (block, p) in &self.blocks {
            let k = block.size();
            for (r, &t) in block.tracks.iter().enumerate() {
                for (c, &i) in block.identities.iter().enumerate() {
                    out[t * n + i] = p[r * k + c];
                }
            }
        }
        out
    }

    /// The marginals by row: each track lists the identities of its
    /// block that it may carry; nothing else (rest 0).
    pub fn sparse(&self) -> Result<SparseMarginals, BeliefError> {
        let mut rows = vec![IdentityRow::default(); self.n];
        for (block, p) in &self.blocks {
            let k = block.size();
            for (r, &t) in block.tracks.iter().enumerate() {
                let entries = block
                    .identities
                    .iter()
                    .enumerate()
                    .map(|(c, &i)| (i as u32, p[r * k + c]))
                    .filter(|&(_, q)| q != 0.0)
                    .collect();
                if let Some(row) = rows.get_mut(t) {
                    *row = IdentityRow::collect(0.0, entries);
                }
            }
        }
        SparseMarginals::new(rows)
    }

    /// The most likely one-to-one assignment under these marginals,
    /// solved block by block (`result[t]` = identity of track t).
    pub fn most_likely(&self) -> Result<Vec<u32>, BeliefError> {
        let mut out = vec![0u32; self.n];
        for (block, p) in &self.blocks {
            let local = most_likely_assignment(&to_rows(block.size(), p))?;
            for (r, &c) in local.iter().enumerate() {
                out[block.tracks[r]] = block.identities[c as usize] as u32;
            }
        }
        Ok(out)
    }

    /// The number of tracks of the largest block.
    pub fn largest_block(&self) -> usize {
        self.blocks.iter().map(|(b, _)| b.size()).max().unwrap_or(0)
    }
}

/// Marginals (row-major) of p(π) ∝ exp(Σ_t l\[t·n + π(t)\]); entries finite
/// or −∞ (an identity the track cannot carry).
pub(crate) fn information_marginals(
    n: usize,
    l: &[f64],
    method: &MarginalMethod,
    sinkhorn_options: &SinkhornOptions,
) -> Result<Vec<f64>, BeliefError> {
    block_marginals(n, l, method, sinkhorn_options).map(|m| m.dense())
}

/// [`information_marginals`] block by block (see the module docs).
pub(crate) fn block_marginals(
    n: usize,
    l: &[f64],
    method: &MarginalMethod,
    sinkhorn_options: &SinkhornOptions,
) -> Result<BlockMarginals, BeliefError> {
    block_marginals_stoppable(n, l, method, sinkhorn_options, &AtomicBool::new(false))
}

/// [`block_marginals`] that gives up with [`BeliefError::Stopped`] soon
/// after `stop` is set: between blocks, and within a Metropolis chain
/// (the one method whose time the asker sets, by its samples). The other
/// methods refuse blocks too large to finish in seconds.
pub(crate) fn block_marginals_stoppable(
    n: usize,
    l: &[f64],
    method: &MarginalMethod,
    sinkhorn_options: &SinkhornOptions,
    stop: &AtomicBool,
) -> Result<BlockMarginals, BeliefError> {
    if n == 0 {
        return Err(BeliefError::NoTracks);
    }
    if l.len() != n * n {
        return Err(BeliefError::Numerical {
            step: "information matrix",
            detail: format!("expected {n} × {n} entries, got {}", l.len()),
        });
    }
    if let Some(&bad) = l.iter().find(|x| x.is_nan() || **x == f64::INFINITY) {
        return Err(BeliefError::Numerical {
            step: "information matrix",
            detail: format!("entry {bad} is neither finite nor −∞"),
        });
    }
    let blocks = blocks_of_log_likelihoods(n, l);
    if blocks.iter().any(|b| !b.is_balanced()) {
        // Some tracks can carry fewer identities than they are: no
        // assignment is possible at all.
        return Err(BeliefError::Degenerate { normalizer: 0.0 });
    }
    let largest = blocks.iter().map(Block::size).max().unwrap_or(0);
    let limit = match method {
        MarginalMethod::Exact => Some(("exact marginals (permanent)", MAX_PERMANENT_TRACKS)),
        MarginalMethod::Sinkhorn => Some(("sinkhorn marginals (scaling)", MAX_SCALED_BLOCK)),
        MarginalMethod::FractionalBethe { .. } => {
            Some(("bethe marginals (scaling)", MAX_SCALED_BLOCK))
        }
        MarginalMethod::Auto | MarginalMethod::Metropolis { .. } => None,
    };
    if let Some((name, limit)) = limit.filter(|&(_, limit)| largest > limit) {
        return Err(BeliefError::TooLargeBlock {
            method: name,
            block: largest,
            tracks: n,
            limit,
        });
    }
    let mut out = Vec::with_capacity(blocks.len());
    let mut sampling: Option<Sampling> = None;
    for block in blocks {
        if stop.load(Ordering::Relaxed) {
            return Err(BeliefError::Stopped {
                method: method.name(),
            });
        }
        let k = block.size();
        let p = if k == 1 {
            vec![1.0]
        } else {
            let sub = sub_matrix(n, l, &block);
            let (p, sampled) = one_block(k, &sub, method, sinkhorn_options, stop)?;
            if let Some(run) = sampled {
                sampling = Some(match sampling {
                    Some(before) => before.and(run),
                    None => run,
                });
            }
            p
        };
        out.push((block, p));
    }
    Ok(BlockMarginals {
        n,
        blocks: out,
        sampling,
    })
}

/// The marginals of one block (k ≥ 2) by `method`, and the diagnostic of
/// a block answered by Metropolis.
fn one_block(
    k: usize,
    l: &[f64],
    method: &MarginalMethod,
    sinkhorn_options: &SinkhornOptions,
    stop: &AtomicBool,
) -> Result<(Vec<f64>, Option<Sampling>), BeliefError> {
    let sampled = |run: MetropolisRun| {
        let sampling = Sampling::of(&run);
        (run.marginals, Some(sampling))
    };
    Ok(match *method {
        MarginalMethod::Exact => (marginals_from_log_likelihoods(k, l)?, None),
        MarginalMethod::Auto if k <= AUTO_EXACT_BLOCK => {
            (marginals_from_log_likelihoods(k, l)?, None)
        }
        MarginalMethod::Auto if k <= AUTO_BETHE_BLOCK => {
            one_block(k, l, &MarginalMethod::half_bethe(), sinkhorn_options, stop)?
        }
        MarginalMethod::Auto => {
            let samples = AUTO_STEPS_PER_TRACK * k;
            sampled(metropolis_stoppable(k, l, samples, samples / 10, 0, stop)?)
        }
        MarginalMethod::Metropolis {
            samples,
            burn_in,
            seed,
        } => sampled(metropolis_stoppable(k, l, samples, burn_in, seed, stop)?),
        MarginalMethod::Sinkhorn => {
            let mut a = exp_rows(k, l)?;
            sinkhorn(k, &mut a, sinkhorn_options)?;
            (a, None)
        }
        MarginalMethod::FractionalBethe {
            gamma,
            max_iterations,
            tolerance,
        } => (
            fractional_bethe(k, l, gamma, max_iterations, tolerance, sinkhorn_options)?,
            None,
        ),
    })
}

/// Iterates P ← Sinkhorn(A ⊙ (1 − P)^{−γ}) from P = Sinkhorn(A).
///
/// Each step scales P ⊙ R′ ⊘ R instead of A ⊙ R′ (R the weights
/// (1 − P)^{−γ} of the step that made P, R′ the new ones): P is A ⊙ R
/// with its rows and columns scaled (and entries on no positive diagonal
/// zeroed), and Sinkhorn's limit does not depend on such scalings of its
/// input, so the result is the same — but the last step's scalings nearly
/// balance the new matrix, so Sinkhorn starts close to its answer instead
/// of from scratch. Only the positive entries are touched (a block of a
/// crowd's information matrix is sparse: see [`super::sinkhorn`]).
fn fractional_bethe(
    n: usize,
    l: &[f64],
    gamma: f64,
    max_iterations: usize,
    tolerance: f64,
    sinkhorn_options: &SinkhornOptions,
) -> Result<Vec<f64>, BeliefError> {
    if !((0.0..=1.0).contains(&gamma) && tolerance > 0.0 && tolerance.is_finite()) {
        return Err(BeliefError::Unsupported {
            method: "fractional Bethe marginals",
            what: "gamma outside [0, 1] or a tolerance that is not positive and finite",
        });
    }
    let mut p = exp_rows(n, l)?;
    sinkhorn(n, &mut p, sinkhorn_options)?;
    // The positive entries of Sinkhorn(A): no step makes another positive.
    let columns: Vec<Vec<usize>> = p
        .chunks(n)
        .map(|row| (0..n).filter(|&j| row[j] > 0.0).collect())
        .collect();
    let mut w = vec![0.0; n * n];
    // The weights of the step that made P (none for Sinkhorn(A)).
    let mut weights = vec![1.0; n * n];
    let mut others = vec![0.0; n];
    for _ in 0..max_iterations {
        for (i, cols) in columns.iter().enumerate() {
            let (p_row, w_row) = (&p[i * n..(i + 1) * n], &mut w[i * n..(i + 1) * n]);
            // others[j] = Σ_{k≠j} P_ik = 1 − P_ij without cancellation.
            let mut before = 0.0;
            for &j in cols {
                others[j] = before;
                before += p_row[j];
            }
            let mut after = 0.0;
            for &j in cols.iter().rev() {
                others[j] += after;
                after += p_row[j];
            }
            let weights_row = &mut weights[i * n..(i + 1) * n];
            for &j in cols {
                // A row with one positive entry is fixed by scaling anyway.
                let weight = if others[j] > 0.0 {
                    others[j].powf(-gamma)
                } else {
                    1.0
                };
                w_row[j] = p_row[j] * (weight / weights_row[j]);
                weights_row[j] = weight;
            }
        }
        sinkhorn(n, &mut w, sinkhorn_options)?;
        let change = columns
            .iter()
            .enumerate()
            .flat_map(|(i, cols)| cols.iter().map(move |&j| i * n + j))
            .map(|k| (w[k] - p[k]).abs())
            .fold(0.0, f64::max);
        std::mem::swap(&mut p, &mut w);
        if change <= tolerance {
            return Ok(p);
        }
    }
    Err(BeliefError::Numerical {
        step: "fractional Bethe",
        detail: format!("no fixed point within {max_iterations} iterations"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::ExactPermutationFilter;
    use crate::filter::{doubly_stochastic_residual, max_abs_difference, to_rows, IdentityFilter};
    use crate::information::InformationMatrix;
    use crate::workload::{generate, IdentityWorkloadSpec};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn methods_are_named_as_the_command_line_and_queries_name_them() {
        for name in ["auto", "exact", "metropolis", "sinkhorn", "bethe"] {
            let method = MarginalMethod::named(name, 100, 1).unwrap();
            assert_eq!(method.name(), name);
        }
        assert!(MarginalMethod::named("permanent", 100, 1).is_none());
    }

    fn by(method: MarginalMethod, n: usize, l: &[f64]) -> Vec<Vec<f64>> {
        to_rows(
            n,
            &information_marginals(n, l, &method, &SinkhornOptions::default()).unwrap(),
        )
    }

    /// Information matrices as the filter produces them: the paper's
    /// workload (reads with accuracy 0.9, mixes with α = ½), several ratios.
    fn realistic(n: usize, seed: u64) -> Vec<f64> {
        let ratio = [0.25, 1.0, 4.0][seed as usize % 3];
        let w = generate(&IdentityWorkloadSpec::paper(n, ratio, seed)).unwrap();
        let mut info = InformationMatrix::uniform(n).unwrap();
        for e in &w.events {
            info.apply(e).unwrap();
        }
        info.log_likelihoods().into_iter().flatten().collect()
    }

    fn exact(n: usize, l: &[f64]) -> Vec<Vec<f64>> {
        let rows = to_rows(n, l);
        ExactPermutationFilter::from_log_likelihoods(&rows)
            .unwrap()
            .marginals()
            .unwrap()
    }

    #[test]
    fn sinkhorn_takes_the_square_root_of_the_odds_for_two_tracks() {
        let l = [1.3, -0.2, 0.4, 2.0];
        let s = by(MarginalMethod::Sinkhorn, 2, &l);
        let e = exact(2, &l);
        let exact_odds = e[0][0] / e[0][1];
        let sinkhorn_odds = s[0][0] / s[0][1];
        assert!((sinkhorn_odds - exact_odds.sqrt()).abs() < 1e-9);
        assert!((exact_odds - (1.3f64 + 2.0 - 0.4 + 0.2).exp()).abs() < 1e-9);
    }

    #[test]
    fn sinkhorn_error_against_the_permanent() {
        // Measured worst |Δp| over 30 realistic matrices per N (seeded):
        // N=3 0.195, N=4 0.261, N=5 0.294, N=6 0.239 — the bias of the
        // module docs, largest when a track is torn between two identities.
        for n in 3..=6 {
            let mut worst: f64 = 0.0;
            for seed in 0..30 {
                let l = realistic(n, seed);
                let s = by(MarginalMethod::Sinkhorn, n, &l);
                assert!(doubly_stochastic_residual(&s) < 1e-9);
                worst = worst.max(max_abs_difference(&s, &exact(n, &l)));
            }
            assert!(worst < 0.35, "n={n}: {worst}");
        }
    }

    #[test]
    fn half_bethe_is_exact_for_two_tracks() {
        let l = [1.3, -0.2, 0.4, 2.0];
        let b = by(MarginalMethod::half_bethe(), 2, &l);
        let diff = max_abs_difference(&b, &exact(2, &l));
        assert!(diff < 1e-9, "{diff}");
    }

    #[test]
    fn half_bethe_error_against_the_permanent() {
        // Measured worst |Δp| over the 30 matrices per N of the Sinkhorn
        // test: N=3 0.067, N=4 0.077, N=5 0.112, N=6 0.141 (Sinkhorn 0.195,
        // 0.261, 0.294, 0.239 on the same matrices).
        for n in 3..=6 {
            let mut worst: f64 = 0.0;
            let mut worst_sinkhorn: f64 = 0.0;
            for seed in 0..30 {
                let l = realistic(n, seed);
                let e = exact(n, &l);
                let b = by(MarginalMethod::half_bethe(), n, &l);
                assert!(doubly_stochastic_residual(&b) < 1e-9);
                worst = worst.max(max_abs_difference(&b, &e));
                let s = by(MarginalMethod::Sinkhorn, n, &l);
                worst_sinkhorn = worst_sinkhorn.max(max_abs_difference(&s, &e));
            }
            assert!(worst < 0.2, "n={n}: {worst}");
            assert!(worst < worst_sinkhorn, "n={n}: {worst} vs {worst_sinkhorn}");
        }
    }

    #[test]
    fn metropolis_converges_to_the_permanent() {
        // Measured worst |Δp| (N = 6, 10 realistic matrices): 1e3 samples
        // 0.116, 1e4 0.036, 1e5 0.019 — roughly the 1/√samples rate.
        let n = 6;
        let mut errors = Vec::new();
        for samples in [1_000, 10_000, 100_000] {
            let mut worst: f64 = 0.0;
            for seed in 0..10 {
                let l = realistic(n, seed);
                let method = MarginalMethod::Metropolis {
                    samples,
                    burn_in: 1_000,
                    seed,
                };
                let m = by(method, n, &l);
                assert!(doubly_stochastic_residual(&m) < 1e-9);
                worst = worst.max(max_abs_difference(&m, &exact(n, &l)));
            }
            errors.push(worst);
        }
        assert!(errors[2] < 0.03, "{errors:?}");
        assert!(errors[2] < errors[0], "{errors:?}");
    }

    #[test]
    fn metropolis_is_reproducible_and_exact_on_a_point_mass() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let l: Vec<f64> = (0..25).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let method = MarginalMethod::Metropolis {
            samples: 500,
            burn_in: 10,
            seed: 9,
        };
        assert_eq!(by(method, 5, &l), by(method, 5, &l));
        // A very peaked belief: the chain never leaves the best assignment.
        let mut peaked = vec![0.0; 16];
        for (t, i) in [(0, 2), (1, 0), (2, 3), (3, 1)] {
            peaked[t * 4 + i] = 800.0;
        }
        let m = by(method, 4, &peaked);
        assert_eq!(m[0][2], 1.0);
        assert_eq!(m[3][1], 1.0);
        assert!(information_marginals(
            2,
            &[0.0; 4],
            &MarginalMethod::Metropolis {
                samples: 0,
                burn_in: 0,
                seed: 0
            },
            &SinkhornOptions::default()
        )
        .is_err());
    }

    /// A random information matrix with a known start and `mixes` random
    /// mixes of nearby tracks, and `reads` reads: blocks of several sizes.
    fn known_start_matrix(n: usize, seed: u64, mixes: usize, reads: usize) -> Vec<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut start: Vec<u32> = (0..n as u32).collect();
        for i in (1..n).rev() {
            start.swap(i, rng.gen_range(0..=i));
        }
        let mut info =
            InformationMatrix::from_assignment(&start, f64::INFINITY, Default::default()).unwrap();
        for _ in 0..mixes {
            let a = rng.gen_range(0..n);
            let b = (a + rng.gen_range(1..3.min(n))) % n;
            info.mix(idmesh_belief::Mix {
                a: a as u32,
                b: b as u32,
                swap: rng.gen_range(0.1..0.9),
            })
            .unwrap();
        }
        for _ in 0..reads {
            info.identify(crate::Identify {
                track: rng.gen_range(0..n) as u32,
                identity: rng.gen_range(0..n) as u32,
                accuracy: 0.9,
            })
            .unwrap();
        }
        info.log_likelihoods().concat()
    }

    #[test]
    fn exact_refuses_a_block_too_large_and_names_its_size() {
        let n = 30;
        let l = vec![0.0; n * n];
        let e =
            information_marginals(n, &l, &MarginalMethod::Exact, &Default::default()).unwrap_err();
        assert_eq!(
            e,
            BeliefError::TooLargeBlock {
                method: "exact marginals (permanent)",
                block: 30,
                tracks: 30,
                limit: MAX_PERMANENT_TRACKS
            }
        );
        assert!(e.to_string().contains("has 30 of the 30 tracks"), "{e}");
        // Auto answers it (half-Bethe on the one block of 30).
        let p = by(MarginalMethod::Auto, n, &l);
        assert!(doubly_stochastic_residual(&p) < 1e-9);
    }

    #[test]
    fn a_thousand_tracks_in_small_blocks_answer_exactly() {
        // n = 1000 with a known start and 600 local mixes: every method
        // answers, exact and auto agree, and the other methods are
        // doubly stochastic with zeros between blocks.
        let n = 1000;
        let l = known_start_matrix(n, 3, 600, 300);
        let opts = SinkhornOptions::default();
        let exact = block_marginals(n, &l, &MarginalMethod::Exact, &opts).unwrap();
        assert!(exact.largest_block() <= MAX_PERMANENT_TRACKS);
        assert!(exact.blocks.len() > 100, "{}", exact.blocks.len());
        let auto = block_marginals(n, &l, &MarginalMethod::Auto, &opts).unwrap();
        let (e, a) = (exact.dense(), auto.dense());
        if exact.largest_block() <= AUTO_EXACT_BLOCK {
            assert_eq!(e, a);
        }
        for method in [
            MarginalMethod::Sinkhorn,
            MarginalMethod::half_bethe(),
            MarginalMethod::Metropolis {
                samples: 2_000,
                burn_in: 200,
                seed: 1,
            },
        ] {
            let m = information_marginals(n, &l, &method, &opts).unwrap();
            for (x, y) in m.iter().zip(&e) {
                assert!(*y > 0.0 || *x == 0.0, "{}", method.name());
            }
            assert!(doubly_stochastic_residual(&to_rows(n, &m)) < 1e-8);
        }
    }

    #[test]
    fn scaling_refuses_a_block_too_large_and_names_its_size() {
        let n = MAX_SCALED_BLOCK + 1;
        let l = vec![0.0; n * n];
        for (method, name) in [
            (MarginalMethod::Sinkhorn, "sinkhorn marginals (scaling)"),
            (MarginalMethod::half_bethe(), "bethe marginals (scaling)"),
        ] {
            let e = block_marginals(n, &l, &method, &Default::default()).unwrap_err();
            assert_eq!(
                e,
                BeliefError::TooLargeBlock {
                    method: name,
                    block: n,
                    tracks: n,
                    limit: MAX_SCALED_BLOCK
                }
            );
        }
    }

    #[test]
    fn auto_samples_a_block_too_large_to_scale() {
        // Enough mixes percolate into one block of most tracks (a crowd):
        // auto is half-Bethe up to AUTO_BETHE_BLOCK tracks, and beyond it
        // exactly Metropolis with AUTO_STEPS_PER_TRACK steps per track,
        // seed 0 — an answer with rows and columns summing to 1 and zeros
        // between blocks.
        let n = 200;
        let l = known_start_matrix(n, 7, 1_000, 300);
        let opts = SinkhornOptions::default();
        let auto = block_marginals(n, &l, &MarginalMethod::Auto, &opts).unwrap();
        let (block, p) = auto.blocks.iter().max_by_key(|(b, _)| b.size()).unwrap();
        let k = block.size();
        assert!(k > AUTO_BETHE_BLOCK, "the largest block has {k} tracks");
        let sub = sub_matrix(n, &l, block);
        let steps = AUTO_STEPS_PER_TRACK * k;
        let run = crate::metropolis::metropolis_diagnosed(k, &sub, steps, steps / 10, 0).unwrap();
        assert_eq!(*p, run.marginals);
        // The answer says how far the sampled block is from converged; a
        // method that did not sample says nothing.
        let sampling = auto.sampling.expect("a sampled block");
        assert_eq!(sampling.blocks, 1);
        assert_eq!(sampling.half_difference, run.half_difference);
        assert!(sampling.half_difference > 0.0 && sampling.acceptance > 0.0);
        assert!(block_marginals(n, &l, &MarginalMethod::Sinkhorn, &opts)
            .unwrap()
            .sampling
            .is_none());
        assert!(doubly_stochastic_residual(&to_rows(n, &auto.dense())) < 1e-9);
        for (small, q) in auto.blocks.iter().filter(|(b, _)| b.size() > 1) {
            let j = small.size();
            if j <= AUTO_EXACT_BLOCK {
                let exact = marginals_from_log_likelihoods(j, &sub_matrix(n, &l, small)).unwrap();
                assert_eq!(*q, exact);
            }
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(48))]

        /// Block by block equals the exact filter over all n! assignments
        /// (exact, and auto, which is exact at these sizes); every other
        /// method equals itself run on each block alone, i.e. blocks change
        /// nothing but the cost.
        #[test]
        fn blocks_agree_with_the_exact_filter(
            n in 2usize..=8,
            seed in proptest::prelude::any::<u64>(),
            mixes in 0usize..10,
            reads in 0usize..10,
        ) {
            let l = known_start_matrix(n, seed, mixes, reads);
            let want = exact(n, &l);
            for method in [MarginalMethod::Exact, MarginalMethod::Auto] {
                let got = by(method, n, &l);
                proptest::prop_assert!(max_abs_difference(&got, &want) < 1e-9);
            }
            let opts = SinkhornOptions::default();
            for method in [MarginalMethod::Sinkhorn, MarginalMethod::half_bethe()] {
                let got = by(method, n, &l);
                let blocks = block_marginals(n, &l, &method, &opts).unwrap();
                for (block, p) in &blocks.blocks {
                    let sub = crate::blocks::sub_matrix(n, &l, block);
                    let alone = if block.size() == 1 {
                        vec![1.0]
                    } else {
                        one_block(block.size(), &sub, &method, &opts, &AtomicBool::new(false))
                            .unwrap()
                            .0
                    };
                    proptest::prop_assert_eq!(p, &alone);
                }
                proptest::prop_assert!(doubly_stochastic_residual(&got) < 1e-9);
                // Zero exactly where the exact belief is zero.
                for (x, y) in got.iter().flatten().zip(want.iter().flatten()) {
                    proptest::prop_assert!(*y > 0.0 || *x == 0.0);
                }
            }
        }
    }
}
