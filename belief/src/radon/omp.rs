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

use super::atom::Atom;
use super::RadonBelief;
use crate::error::BeliefError;
use crate::weights::Weights;
use nalgebra::{DMatrix, DVector};
use rustc_hash::FxHashSet;

/// Knobs of one OMP run.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct OmpOptions {
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
    pub(crate) fn for_budget(budget: usize) -> Self {
        let atoms = (budget / 16).clamp(2, 64).min(budget);
        OmpOptions {
            depth: 1,
            atoms,
            targets: 2 * atoms,
            max_candidates: 8192,
            tolerance: 1e-9,
            every: 24,
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

/// The downsampled dictionary for a target: its atoms and their sub-atoms
/// down to `depth` tracks fewer, heaviest targets first, at most `max`.
fn candidates(target: &[(Atom, f64)], depth: usize, max: usize) -> Vec<Atom> {
    let mut seen: FxHashSet<Atom> = FxHashSet::default();
    let mut out = Vec::new();
    for (atom, _) in target {
        let mut layer = vec![atom.clone()];
        for level in 0..=depth {
            let mut next = Vec::new();
            for beta in layer {
                if out.len() >= max {
                    return out;
                }
                if level < depth {
                    for &t in beta.red.tracks() {
                        next.push(Atom::new(beta.red.without(t), beta.blue.clone()));
                    }
                    for &t in beta.blue.tracks() {
                        next.push(Atom::new(beta.red.clone(), beta.blue.without(t)));
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

/// Atoms packed as bit masks (red, blue) when the field is small enough, so
/// that the union sizes that dominate OMP are a few popcounts; sorted
/// merges otherwise.
struct Packed<'a> {
    atoms: Vec<&'a Atom>,
    words: usize,
    bits: Vec<u64>,
}

impl<'a> Packed<'a> {
    const MAX_WORDS: usize = 16;

    fn new(atoms: impl Iterator<Item = &'a Atom>, tracks: usize) -> Self {
        let atoms: Vec<&Atom> = atoms.collect();
        let words = tracks.div_ceil(64);
        let mut bits = Vec::new();
        if words <= Self::MAX_WORDS {
            bits = vec![0u64; 2 * words * atoms.len()];
            for (i, atom) in atoms.iter().enumerate() {
                let base = 2 * words * i;
                for &t in atom.red.tracks() {
                    bits[base + (t as usize) / 64] |= 1u64 << (t % 64);
                }
                for &t in atom.blue.tracks() {
                    bits[base + words + (t as usize) / 64] |= 1u64 << (t % 64);
                }
            }
        }
        Packed { atoms, words, bits }
    }

    fn sizes(&self, i: usize) -> (usize, usize) {
        self.atoms[i].sizes()
    }

    /// The sizes (red, blue) of the product of two atoms, None when they
    /// contradict each other (a track red in one and blue in the other).
    fn product(&self, i: usize, other: &Packed, j: usize) -> Option<(usize, usize)> {
        if self.bits.is_empty() || other.bits.is_empty() {
            let (a, b) = (self.atoms[i], other.atoms[j]);
            if a.red.intersection_len(&b.blue) > 0 || b.red.intersection_len(&a.blue) > 0 {
                return None;
            }
            return Some((a.red.union_len(&b.red), a.blue.union_len(&b.blue)));
        }
        let w = self.words;
        let a = &self.bits[2 * w * i..2 * w * (i + 1)];
        let b = &other.bits[2 * w * j..2 * w * (j + 1)];
        let (mut red, mut blue) = (0, 0);
        for x in 0..w {
            let r = a[x] | b[x];
            let l = a[w + x] | b[w + x];
            if r & l != 0 {
                return None;
            }
            red += r.count_ones() as usize;
            blue += l.count_ones() as usize;
        }
        Some((red, blue))
    }
}

/// W(i, o) for every size pair a run can meet, relative to a reference, so
/// that a ratio of weights is one division instead of two logarithms and an
/// exponential. Falls back to the logarithms when the weights span more than
/// an f64 can hold.
struct RatioTable<'a> {
    weights: &'a Weights,
    blue_sizes: usize,
    values: Vec<f64>,
}

impl<'a> RatioTable<'a> {
    fn new(weights: &'a Weights, dictionary: &[Atom], target: &[(Atom, f64)]) -> Self {
        let max = |f: &dyn Fn(&Atom) -> usize| {
            dictionary
                .iter()
                .map(f)
                .chain(target.iter().map(|(a, _)| f(a)))
                .max()
                .unwrap_or(0)
        };
        let n = weights.tracks();
        let reds = (2 * max(&|a| a.red.len())).min(n) + 1;
        let blues = (2 * max(&|a| a.blue.len())).min(n) + 1;
        let ln: Vec<f64> = (0..reds * blues)
            .map(|x| weights.ln2(x / blues, x % blues))
            .collect();
        let finite = ln.iter().filter(|v| v.is_finite());
        let hi = finite.clone().fold(f64::NEG_INFINITY, |a, &b| a.max(b));
        let lo = finite.fold(f64::INFINITY, |a, &b| a.min(b));
        let values = if hi - lo < 600.0 {
            ln.iter().map(|v| (v - hi).exp()).collect()
        } else {
            Vec::new()
        };
        RatioTable {
            weights,
            blue_sizes: blues,
            values,
        }
    }

    /// W(to)/W(from).
    fn ratio(&self, from: (usize, usize), to: (usize, usize)) -> f64 {
        let at = |(i, o): (usize, usize)| i * self.blue_sizes + o;
        match (self.values.get(at(from)), self.values.get(at(to))) {
            (Some(f), Some(t))
                if !self.values.is_empty()
                    && o_fits(from, self.blue_sizes)
                    && o_fits(to, self.blue_sizes) =>
            {
                t / f
            }
            _ => self.weights.ratio_between(from, to),
        }
    }
}

fn o_fits((_, o): (usize, usize), blue_sizes: usize) -> bool {
    o < blue_sizes
}

/// How many of the heaviest sets an OMP run keeps as they are: the budget
/// less the atoms the run may add.
pub(super) fn kept_by_pursuit(budget: usize, options: &OmpOptions) -> usize {
    budget.saturating_sub(options.atoms).max(1)
}

/// The `count` heaviest of `removed`, heaviest first, ties by atom so that
/// runs are deterministic: what OMP re-expresses.
pub(super) fn heaviest(removed: &mut [(Atom, f64)], count: usize) -> &[(Atom, f64)] {
    let count = count.min(removed.len());
    if count > 0 && count < removed.len() {
        removed.select_nth_unstable_by(count - 1, |x, y| y.1.abs().total_cmp(&x.1.abs()));
    }
    removed[..count]
        .sort_unstable_by(|x, y| y.1.abs().total_cmp(&x.1.abs()).then_with(|| x.0.cmp(&y.0)));
    &removed[..count]
}

/// OMP on a target given by masses m (m = c·W): returns at most
/// `options.atoms` atoms with non-negative masses whose sum best fits the
/// target in l2 over the admissible red sets.
pub(crate) fn pursue(
    weights: &Weights,
    target: &[(Atom, f64)],
    options: &OmpOptions,
) -> Result<Vec<(Atom, f64)>, BeliefError> {
    let dictionary = candidates(target, options.depth, options.max_candidates);
    if dictionary.is_empty() {
        return Ok(Vec::new());
    }
    let ln_w = |(i, o): (usize, usize)| weights.ln2(i, o);
    // Correlations carry a common factor √W_ref so that they stay in range.
    let (lo, hi) = dictionary
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), b| {
            let w = ln_w(b.sizes());
            (lo.min(w), hi.max(w))
        });
    let ln_ref = 0.5 * (lo + hi);
    let ln_half: Vec<f64> = dictionary.iter().map(|b| 0.5 * ln_w(b.sizes())).collect();
    let half: Vec<f64> = ln_half.iter().map(|h| h - 0.5 * ln_ref).collect();
    let packed = Packed::new(dictionary.iter(), weights.tracks());
    let packed_target = Packed::new(target.iter().map(|(a, _)| a), weights.tracks());
    let table = RatioTable::new(weights, &dictionary, target);
    let gram = |i: usize, j: usize| -> f64 {
        match packed.product(i, &packed, j) {
            Some(sizes) => (ln_w(sizes) - ln_half[i] - ln_half[j]).exp(),
            None => 0.0,
        }
    };
    let projections: Vec<f64> = (0..dictionary.len())
        .map(|i| {
            let sum: f64 = target
                .iter()
                .enumerate()
                .filter_map(|(a, (_, m))| {
                    let to = packed.product(i, &packed_target, a)?;
                    Some(m * table.ratio(packed_target.sizes(a), to))
                })
                .sum();
            sum * (-half[i]).exp()
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
    /// `budget − atoms` atoms are kept as they are (OMP warm-started with
    /// them fixed in its support), the heaviest `targets` of the rest are
    /// re-expressed by at most `atoms` atoms, and the remainder is dropped.
    pub(super) fn pursue(
        &mut self,
        budget: usize,
        options: &OmpOptions,
    ) -> Result<(), BeliefError> {
        let before = self.clone();
        let mut removed = self.split_off_lightest(kept_by_pursuit(budget, options));
        let targets = heaviest(&mut removed, options.targets);
        let result = pursue(&self.weights, targets, options).and_then(|atoms| {
            for (atom, m) in atoms {
                *self.masses.entry(atom).or_insert(0.0) += m;
            }
            self.masses.retain(|_, m| *m != 0.0);
            self.expand_empty();
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

    use crate::track_set::TrackSet;

    fn set(t: &[u32]) -> Atom {
        Atom::radon(TrackSet::from_tracks(t.iter().copied()))
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
