//! Orthogonal Matching Pursuit over the adaptively downsampled Radon
//! dictionary (Section 5.3.1, Algorithm 3).
//!
//! The dictionary is {β ⊆ α : |α − β| ≤ s, α a set of the target}: the sets
//! themselves and their subsets up to s elements smaller, which is what lets
//! OMP move mass to lower-order sets (Example 5.2). Atoms are normalized,
//! ψ_β = φ_β/√W(|β|), so correlations compare sets of different sizes fairly;
//! their inner products are ⟨ψ_β, ψ_γ⟩ = W(|β ∪ γ|)/√(W(|β|)·W(|γ|)) ∈ [0, 1],
//! and ⟨ψ_β, f⟩ = Σ_α m_α·W(|α ∪ β|)/W(|α|)/√W(|β|) — all ratios of binomials,
//! evaluated in log space.
//!
//! ## Positivity
//! The paper keeps coefficients positive "by projecting on the positive
//! cone" (Section 5.5). We fit in the cone spanned by the selected atoms: the
//! least-squares step is a non-negative least squares solved by an active set
//! (Lawson–Hanson without the interpolation step): solve on the support by
//! Cholesky; while some coefficient is negative, drop the most negative atom
//! from the support (and never select it again in this run) and solve again.
//! Every atom is a non-negative function, so the approximation is a
//! non-negative function whatever the signs in the target were.

use super::RadonBelief;
use crate::error::BeliefError;
use crate::track_set::TrackSet;
use crate::weights::Weights;
use nalgebra::{DMatrix, DVector};
use rustc_hash::FxHashSet;

/// Knobs of one OMP run.
#[derive(Debug, Clone, PartialEq)]
pub struct OmpOptions {
    /// s: how many elements smaller than a target set a candidate may be.
    pub depth: usize,
    /// The most atoms one run may add.
    pub atoms: usize,
    /// How many of the sets thresholding would drop OMP re-expresses (the
    /// heaviest of them); the rest are dropped.
    pub targets: usize,
    /// The largest downsampled dictionary one run builds.
    pub max_candidates: usize,
    /// Stop when no correlation exceeds this share of the first one.
    pub tolerance: f64,
    /// The fewest events between two runs in a belief (see `sparsify`).
    pub every: u32,
}

impl OmpOptions {
    /// Defaults scaled to a coefficient budget.
    pub fn for_budget(budget: usize) -> Self {
        let atoms = (budget / 16).clamp(2, 64).min(budget);
        OmpOptions {
            depth: 1,
            atoms,
            targets: 4 * atoms,
            max_candidates: 8192,
            tolerance: 1e-9,
            every: 16,
        }
    }

    pub fn validate(&self, budget: usize) -> Result<(), BeliefError> {
        if self.atoms == 0 || self.atoms > budget {
            return Err(BeliefError::Unsupported {
                method: "OMP",
                what: "a number of atoms per run of 0 or above the budget",
            });
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(BeliefError::Unsupported {
                method: "OMP",
                what: "a negative or non-finite tolerance",
            });
        }
        Ok(())
    }
}

/// The downsampled dictionary for a target: its sets and their subsets down
/// to `depth` elements smaller, heaviest targets first, at most `max`.
fn candidates(target: &[(TrackSet, f64)], depth: usize, max: usize) -> Vec<TrackSet> {
    let mut seen: FxHashSet<TrackSet> = FxHashSet::default();
    let mut out = Vec::new();
    for (set, _) in target {
        let mut layer = vec![set.clone()];
        for level in 0..=depth {
            let mut next = Vec::new();
            for beta in layer {
                if out.len() >= max {
                    return out;
                }
                if level < depth {
                    for &t in beta.tracks() {
                        next.push(beta.without(t));
                    }
                }
                if seen.insert(beta.clone()) {
                    out.push(beta);
                }
            }
            layer = next;
        }
    }
    out
}

/// OMP on a target given by masses m_α (m = c·W(|α|)): returns at most
/// `options.atoms` sets with non-negative masses whose sum of φ's best fits
/// the target in l2 over the admissible red sets.
pub fn pursue(
    weights: &Weights,
    target: &[(TrackSet, f64)],
    options: &OmpOptions,
) -> Result<Vec<(TrackSet, f64)>, BeliefError> {
    let dictionary = candidates(target, options.depth, options.max_candidates);
    if dictionary.is_empty() {
        return Ok(Vec::new());
    }
    // Correlations carry a common factor √W_ref so that they stay in range.
    let (lo, hi) = dictionary.iter().fold((usize::MAX, 0), |(lo, hi), b| {
        (lo.min(b.len()), hi.max(b.len()))
    });
    let ln_ref = 0.5 * (weights.ln(lo) + weights.ln(hi));
    let half: Vec<f64> = dictionary
        .iter()
        .map(|b| 0.5 * (weights.ln(b.len()) - ln_ref))
        .collect();
    let gram = |i: usize, j: usize| -> f64 {
        let (b, g) = (&dictionary[i], &dictionary[j]);
        let u = b.union_len(g);
        (weights.ln(u) - 0.5 * weights.ln(b.len()) - 0.5 * weights.ln(g.len())).exp()
    };
    let projections: Vec<f64> = dictionary
        .iter()
        .zip(&half)
        .map(|(beta, h)| {
            let sum: f64 = target
                .iter()
                .map(|(alpha, m)| m * weights.ratio_between(alpha.len(), alpha.union_len(beta)))
                .sum();
            sum * (-h).exp()
        })
        .collect();
    if projections.iter().any(|x| !x.is_finite()) {
        return Err(BeliefError::Numerical {
            step: "OMP",
            detail: "a correlation overflowed; the target spans too many set sizes".into(),
        });
    }

    let mut correlation = projections.clone();
    let mut support: Vec<usize> = Vec::new();
    let mut columns: Vec<Vec<f64>> = Vec::new();
    let mut excluded = vec![false; dictionary.len()];
    let mut solution: Vec<f64> = Vec::new();
    let first = correlation.iter().cloned().fold(0.0, f64::max);
    if first <= 0.0 {
        return Ok(Vec::new());
    }

    while support.len() < options.atoms {
        let best = (0..dictionary.len())
            .filter(|&i| !excluded[i])
            .max_by(|&x, &y| correlation[x].total_cmp(&correlation[y]));
        let Some(best) = best else { break };
        if correlation[best] <= options.tolerance * first {
            break;
        }
        excluded[best] = true;
        support.push(best);
        columns.push((0..dictionary.len()).map(|i| gram(i, best)).collect());

        // Non-negative least squares on the support (see the module docs).
        loop {
            let size = support.len();
            let g = DMatrix::from_fn(size, size, |r, c| columns[c][support[r]]);
            let b = DVector::from_iterator(size, support.iter().map(|&i| projections[i]));
            let solved = g.cholesky().map(|ch| ch.solve(&b));
            match solved {
                None => {
                    // The new atom is a combination of the others: useless.
                    support.pop();
                    columns.pop();
                    break;
                }
                Some(x) => {
                    let (worst, &value) = x
                        .iter()
                        .enumerate()
                        .min_by(|a, b| a.1.total_cmp(b.1))
                        .expect("support is not empty");
                    if value < 0.0 {
                        support.remove(worst);
                        columns.remove(worst);
                        if support.is_empty() {
                            solution.clear();
                            break;
                        }
                        continue;
                    }
                    solution = x.iter().copied().collect();
                    break;
                }
            }
        }
        if support.is_empty() {
            correlation.clone_from(&projections);
            continue;
        }
        for (i, c) in correlation.iter_mut().enumerate() {
            *c = projections[i]
                - solution
                    .iter()
                    .zip(&columns)
                    .map(|(x, col)| x * col[i])
                    .sum::<f64>();
        }
    }

    Ok(support
        .iter()
        .zip(&solution)
        .filter(|(_, &x)| x > 0.0)
        .map(|(&i, &x)| (dictionary[i].clone(), x * half[i].exp()))
        .collect())
}

impl RadonBelief {
    /// Enforces the budget with OMP (Section 5.3.1): the heaviest
    /// `budget − atoms` sets are kept as they are, the heaviest `targets` of
    /// the rest are re-expressed by at most `atoms` atoms (OMP warm-started
    /// with the kept sets fixed in its support), the remainder is dropped.
    pub(super) fn pursue(
        &mut self,
        budget: usize,
        options: &OmpOptions,
    ) -> Result<(), BeliefError> {
        let before = self.clone();
        let keep = budget.saturating_sub(options.atoms).max(1);
        let mut dropped = self.split_off_lightest(keep);
        dropped.truncate(options.targets);
        let result = pursue(&self.weights, &dropped, options).and_then(|atoms| {
            for (set, m) in atoms {
                *self.masses.entry(set).or_insert(0.0) += m;
            }
            self.masses.retain(|_, m| *m != 0.0);
            self.stats.omp_runs += 1;
            self.renormalize()
        });
        result.inspect_err(|_| *self = before)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::event::RedCount;

    fn set(t: &[u32]) -> TrackSet {
        TrackSet::from_tracks(t.iter().copied())
    }

    /// Example 5.2 (0-based): φ_{0,1}·½ + φ_{1,2}·¼ + φ_{1,3}·¼ with n = 4,
    /// k = 2 is exactly φ_{1}·¼ + φ_{0,1}·¼, and OMP finds that.
    #[test]
    fn example_5_2_moves_mass_to_a_lower_order_set() {
        let weights = Weights::new(4, &RedCount::Known(2));
        // W(2) = 1, so masses equal coefficients for 2-sets.
        let target = vec![
            (set(&[0, 1]), 0.5),
            (set(&[1, 2]), 0.25),
            (set(&[1, 3]), 0.25),
        ];
        let options = OmpOptions {
            atoms: 2,
            ..OmpOptions::for_budget(32)
        };
        let mut atoms = pursue(&weights, &target, &options).unwrap();
        atoms.sort_by(|a, b| a.0.cmp(&b.0));
        assert_eq!(atoms.len(), 2, "{atoms:?}");
        assert_eq!(atoms[0].0, set(&[0, 1]));
        assert!((atoms[0].1 - 0.25).abs() < 1e-12);
        assert_eq!(atoms[1].0, set(&[1]));
        // c_{1} = ¼ is a mass of ¼·W(1) = ¾.
        assert!((atoms[1].1 - 0.75).abs() < 1e-12);
    }

    #[test]
    fn candidates_go_down_depth_levels_without_repeats() {
        let d = candidates(&[(set(&[0, 1, 2]), 1.0), (set(&[1, 2, 3]), 1.0)], 1, 100);
        assert_eq!(d.len(), 2 + 5); // two sets, subsets {0,1},{0,2},{1,2},{1,3},{2,3}
        let d2 = candidates(&[(set(&[0, 1, 2]), 1.0)], 2, 100);
        assert_eq!(d2.len(), 1 + 3 + 3);
    }

    #[test]
    fn fit_is_non_negative_even_for_signed_targets() {
        let weights = Weights::new(6, &RedCount::Known(3));
        let target = vec![
            (set(&[0, 1]), 0.6),
            (set(&[0, 1, 2]), -0.2),
            (set(&[3]), 0.3),
        ];
        let atoms = pursue(&weights, &target, &OmpOptions::for_budget(64)).unwrap();
        assert!(!atoms.is_empty());
        assert!(atoms.iter().all(|(_, m)| *m > 0.0));
    }
}
