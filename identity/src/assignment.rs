//! Answers about one assignment: the most likely one-to-one assignment of
//! identities to tracks given marginals (the Hungarian algorithm), and the
//! error measure that scores a predicted assignment against the truth.
//!
//! Maximizing Σ_t ln p\[t\]\[π(t)\] over permutations π is the assignment
//! problem with costs −ln p. We solve it with the O(N³) shortest augmenting
//! path form of the Hungarian algorithm (Kuhn–Munkres with potentials), and
//! large sparse blocks with its sparse form
//! ([`super::sparse_assignment`]).

use super::blocks::{blocks, Block};
use super::event::check_square;
use super::sparse_assignment::{sparse_min_cost_assignment, SparseRow};
use idmesh_belief::BeliefError;

/// The permutation π maximizing Σ_t ln p\[t\]\[π(t)\]: `result[t]` is the
/// identity assigned to track t.
///
/// Entries that are 0, negative or not finite count as probability 0: their
/// cost is set larger than the total cost of any assignment made of positive
/// entries alone, so an assignment through a zero is chosen only when every
/// assignment has one. Ties go to the assignment the algorithm meets first,
/// which is deterministic.
///
/// The problem splits over the blocks of positive entries
/// ([`crate::blocks`]): when every block has as many tracks as
/// identities, each is solved on its own (O(Σ k³) instead of O(n³): at
/// n = 10,000 with small blocks, milliseconds instead of hours).
pub fn most_likely_assignment(p: &[Vec<f64>]) -> Result<Vec<u32>, BeliefError> {
    let n = check_square(p)?;
    let positive = |t: usize, i: usize| p[t][i] > 0.0 && p[t][i].is_finite();
    let parts = blocks(n, positive);
    if parts.len() > 1 && parts.iter().all(Block::is_balanced) {
        let mut out = vec![0u32; n];
        for block in &parts {
            let sub: Vec<Vec<f64>> = block
                .tracks
                .iter()
                .map(|&t| block.identities.iter().map(|&i| p[t][i]).collect())
                .collect();
            let local = whole_assignment(&sub)?;
            for (r, &c) in local.iter().enumerate() {
                out[block.tracks[r]] = block.identities[c as usize] as u32;
            }
        }
        return Ok(out);
    }
    whole_assignment(p)
}

/// The largest matrix solved by the dense Hungarian algorithm; larger ones
/// by the sparse solver over their positive entries
/// ([`super::sparse_assignment`]), O(k³) against about O(k · m log k): a
/// crowd's block of 9,590 tracks took about two minutes densely.
pub(crate) const DENSE_ASSIGNMENT_LIMIT: usize = 200;

/// [`most_likely_assignment`] by one Hungarian run over the whole matrix
/// (over its positive entries only when it is large and they hold an
/// assignment).
fn whole_assignment(p: &[Vec<f64>]) -> Result<Vec<u32>, BeliefError> {
    let n = check_square(p)?;
    if n > DENSE_ASSIGNMENT_LIMIT {
        let rows: Vec<SparseRow> = p
            .iter()
            .map(|row| {
                row.iter()
                    .enumerate()
                    .filter(|&(_, &x)| x > 0.0 && x.is_finite())
                    .map(|(i, &x)| (i as u32, -x.ln()))
                    .collect()
            })
            .collect();
        if let Some(assignment) = sparse_min_cost_assignment(&rows) {
            return Ok(assignment);
        }
    }
    // −ln of the smallest positive f64 is about 744.4, so any assignment of
    // positive entries costs less than 745·n < this.
    let zero_cost = 750.0 * (n as f64 + 1.0);
    let cost: Vec<f64> = p
        .iter()
        .flat_map(|row| row.iter())
        .map(|&x| {
            if x > 0.0 && x.is_finite() {
                -x.ln()
            } else {
                zero_cost
            }
        })
        .collect();
    Ok(min_cost_assignment(n, &cost))
}

/// The Hungarian algorithm on a finite, row-major n × n cost matrix: the
/// permutation (row → column) of least total cost.
pub(crate) fn min_cost_assignment(n: usize, cost: &[f64]) -> Vec<u32> {
    // 1-based potentials u (rows), v (columns); col_row[j] = row matched to
    // column j (0 = none); column 0 is the virtual start of each search.
    let mut u = vec![0.0f64; n + 1];
    let mut v = vec![0.0f64; n + 1];
    let mut col_row = vec![0usize; n + 1];
    let mut way = vec![0usize; n + 1];
    for row in 1..=n {
        col_row[0] = row;
        let mut j0 = 0usize;
        let mut min_v = vec![f64::INFINITY; n + 1];
        let mut used = vec![false; n + 1];
        loop {
            used[j0] = true;
            let i0 = col_row[j0];
            let mut delta = f64::INFINITY;
            let mut j1 = 0usize;
            for j in 1..=n {
                if used[j] {
                    continue;
                }
                let cur = cost[(i0 - 1) * n + (j - 1)] - u[i0] - v[j];
                if cur < min_v[j] {
                    min_v[j] = cur;
                    way[j] = j0;
                }
                if min_v[j] < delta {
                    delta = min_v[j];
                    j1 = j;
                }
            }
            if j1 == 0 {
                // Only reachable with non-finite costs, which callers never
                // pass; stop rather than loop.
                break;
            }
            for j in 0..=n {
                if used[j] {
                    u[col_row[j]] += delta;
                    v[j] -= delta;
                } else {
                    min_v[j] -= delta;
                }
            }
            j0 = j1;
            if col_row[j0] == 0 {
                break;
            }
        }
        // Flip the augmenting path back to the start.
        while j0 != 0 {
            let j1 = way[j0];
            col_row[j0] = col_row[j1];
            j0 = j1;
        }
    }
    let mut assignment = vec![0u32; n];
    for j in 1..=n {
        if col_row[j] > 0 {
            assignment[col_row[j] - 1] = (j - 1) as u32;
        }
    }
    assignment
}

/// The fraction of tracks whose predicted identity differs from the truth
/// (`truth[t]` = identity on track t). A track missing from `predicted`
/// counts as wrong; an empty truth has error 0.
pub fn identity_error(predicted: &[u32], truth: &[u32]) -> f64 {
    if truth.is_empty() {
        return 0.0;
    }
    let wrong = truth
        .iter()
        .enumerate()
        .filter(|&(t, &i)| predicted.get(t) != Some(&i))
        .count();
    wrong as f64 / truth.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::permutation::Permutations;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn brute_force(p: &[Vec<f64>]) -> f64 {
        let n = p.len();
        let perms = Permutations::new(n).unwrap();
        (0..perms.count())
            .map(|r| {
                perms
                    .get(r)
                    .iter()
                    .enumerate()
                    .map(|(t, &i)| p[t][i as usize].ln())
                    .sum::<f64>()
            })
            .fold(f64::NEG_INFINITY, f64::max)
    }

    #[test]
    fn block_by_block_matches_brute_force() {
        // Random block-diagonal patterns under a random relabelling: the
        // split solve finds an assignment as good as the best over all n!.
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for n in 2..=7 {
            for _ in 0..20 {
                let group: Vec<usize> = (0..n).map(|_| rng.gen_range(0..3)).collect();
                let mut ids: Vec<usize> = (0..n).collect();
                for i in (1..n).rev() {
                    ids.swap(i, rng.gen_range(0..=i));
                }
                let p: Vec<Vec<f64>> = (0..n)
                    .map(|t| {
                        (0..n)
                            .map(|i| {
                                if group[t] == group[ids[i]] {
                                    rng.gen_range(0.001..1.0)
                                } else {
                                    0.0
                                }
                            })
                            .collect()
                    })
                    .collect();
                let best = most_likely_assignment(&p).unwrap();
                let score: f64 = best
                    .iter()
                    .enumerate()
                    .map(|(t, &i)| p[t][i as usize].ln())
                    .sum();
                assert!((score - brute_force(&p)).abs() < 1e-9, "n={n}");
            }
        }
    }

    #[test]
    fn hungarian_matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for n in 1..=7 {
            for _ in 0..20 {
                let p: Vec<Vec<f64>> = (0..n)
                    .map(|_| (0..n).map(|_| rng.gen_range(0.001..1.0)).collect())
                    .collect();
                let best = most_likely_assignment(&p).unwrap();
                let mut seen = best.clone();
                seen.sort_unstable();
                assert_eq!(seen, (0..n as u32).collect::<Vec<_>>());
                let score: f64 = best
                    .iter()
                    .enumerate()
                    .map(|(t, &i)| p[t][i as usize].ln())
                    .sum();
                assert!((score - brute_force(&p)).abs() < 1e-9, "n={n}");
            }
        }
    }

    #[test]
    fn zeros_are_avoided_when_possible() {
        // The diagonal has the largest entries but one of them is 0.
        let p = vec![
            vec![0.0, 0.1, 0.1],
            vec![0.1, 0.9, 0.1],
            vec![0.1, 0.1, 0.9],
        ];
        let best = most_likely_assignment(&p).unwrap();
        assert_ne!(best[0], 0);
        assert_eq!(most_likely_assignment(&[vec![0.0]]).unwrap(), vec![0]);
        assert!(most_likely_assignment(&[vec![1.0, 0.0]]).is_err());
    }

    #[test]
    fn error_is_the_share_of_wrong_tracks() {
        assert_eq!(identity_error(&[0, 1, 2, 3], &[0, 1, 2, 3]), 0.0);
        assert_eq!(identity_error(&[1, 0, 2, 3], &[0, 1, 2, 3]), 0.5);
        assert_eq!(identity_error(&[0], &[0, 1]), 0.5);
        assert_eq!(identity_error(&[], &[]), 0.0);
    }
}
