//! Exact marginals of the distribution an information matrix encodes, via
//! the matrix permanent (Shin et al., IPSN 2005, Section 3.4: "to compute
//! marginal probabilities, N! joint probabilities need to be computed
//! first" — the permanent does it in O(2^N·N) instead of O(N!·N)).
//!
//! With A = exp(L), p(π) = Π_t A\[t\]\[π(t)\] / perm(A), so
//!
//!   p\[t\]\[i\] = A\[t\]\[i\]·perm(A without row t and column i) / perm(A)
//!             = A\[t\]\[i\]·∂perm(A)/∂A\[t\]\[i\] / perm(A).
//!
//! ## Two formulas, both with all N² derivatives in one pass
//! **Ryser**: perm(A) = Σ_{S ⊆ columns} (−1)^{N−|S|} Π_r s_r(S), with
//! s_r(S) = Σ_{j∈S} A\[r\]\[j\], so ∂perm/∂A\[t\]\[i\] = Σ_{S ∋ i}
//! (−1)^{N−|S|} Π_{r≠t} s_r(S). Subsets are visited in Gray-code order (one
//! column enters or leaves per step, the row sums update in O(N)); the N
//! products Π_{r≠t} come from prefix and suffix products and go into
//! running sums R_t. Column i is in S over whole runs of steps: when it
//! enters we remember R, when it leaves we add the difference to the
//! gradient. So all N² marginals cost O(2^N·N), like one permanent.
//!
//! **Glynn**: perm(A) = 2^{1−N} Σ_{δ ∈ {±1}^N, δ₀ = 1} (Π_k δ_k)·Π_j c_j(δ),
//! c_j(δ) = Σ_i δ_i A\[i\]\[j\], and ∂perm/∂A\[t\]\[i\] = 2^{1−N} Σ_δ (Π δ)·δ_t·
//! Π_{j≠i} c_j(δ). Gray code over δ₁..δ_{N−1} (one row's sign flips per
//! step), running sums of the N products Π_{j≠i}, and the same run trick
//! per row (δ_t is constant between two flips of row t): O(2^{N−1}·N).
//!
//! ## Numerical safety, and which formula is used
//! The marginals do not change when rows and columns of A are scaled, so we
//! first scale A to doubly stochastic (Sinkhorn with Newton steps,
//! [`crate::sinkhorn`], the factors kept in log space for
//! ln perm). Then nothing overflows, perm(A) ≥ N!/N^N (van der Waerden),
//! and the error is the cancellation of the alternating sum, about
//! ε·Σ|terms|/perm. For Ryser the full-set term alone is 1 (the product of
//! the row sums), so at N = 20 near-uniform matrices lose ~10 digits; for
//! Glynn the terms are products of signed column sums, mostly far below 1,
//! and the loss is ~3 digits. We therefore use Glynn by default
//! ([`PermanentFormula`]); the tests measure both. The running row/column
//! sums are recomputed from scratch every 1024 steps so rounding does not
//! drift over the 2^N updates.
//!
//! Without this scaling (an early version balanced with 8 plain sweeps)
//! a nearly decomposable exp(L) — two tracks both sure of one identity —
//! made Ryser's terms ~1 while perm ~1e-17, and the N = 3 exactness test
//! failed at 3e-5.

use super::sinkhorn::{scale_logged, SinkhornOptions};
use idmesh_belief::BeliefError;

/// The most tracks the permanent method accepts (2^22·22 ≈ 10^8 steps).
pub const MAX_PERMANENT_TRACKS: usize = 22;

/// Which inclusion–exclusion formula computes the permanent.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) enum PermanentFormula {
    /// Ryser's formula, Gray-code order, O(2^N·N). Only the tests use it,
    /// to check Glynn against it.
    #[cfg(test)]
    Ryser,
    /// Glynn's formula, Gray-code order, O(2^{N−1}·N); more accurate on
    /// doubly stochastic matrices (see the module docs). The default.
    #[default]
    Glynn,
}

/// ln perm(A) and the marginals p\[t\]\[i\] (row-major) of the distribution
/// p(π) ∝ Π_t A\[t\]\[π(t)\], for a non-negative row-major n × n matrix, by
/// Glynn's formula.
pub(crate) fn permanent_marginals(n: usize, a: &[f64]) -> Result<(f64, Vec<f64>), BeliefError> {
    permanent_marginals_with(n, a, PermanentFormula::Glynn)
}

/// [`permanent_marginals`] with a chosen formula.
pub(crate) fn permanent_marginals_with(
    n: usize,
    a: &[f64],
    formula: PermanentFormula,
) -> Result<(f64, Vec<f64>), BeliefError> {
    if n == 0 {
        return Err(BeliefError::NoTracks);
    }
    if n > MAX_PERMANENT_TRACKS {
        return Err(BeliefError::TooLarge {
            method: "exact marginals (permanent)",
            needed: 2f64.powi(n as i32),
            limit: 1 << MAX_PERMANENT_TRACKS,
        });
    }
    if a.len() != n * n {
        return Err(BeliefError::Numerical {
            step: "permanent",
            detail: format!("expected {n} × {n} entries, got {}", a.len()),
        });
    }
    if let Some(&bad) = a.iter().find(|x| !(x.is_finite() && **x >= 0.0)) {
        return Err(BeliefError::Numerical {
            step: "permanent",
            detail: format!("entry {bad} is negative or not finite"),
        });
    }
    // Doubly stochastic to a loose tolerance is all the accuracy needs.
    let mut scaled = a.to_vec();
    let options = SinkhornOptions {
        tolerance: 1e-6,
        max_iterations: 1_000,
    };
    let (_, logs) = scale_logged(n, &mut scaled, &options)?;
    let ln_scale: f64 = logs.row.iter().chain(&logs.col).sum();
    // Glynn's sums carry a factor 2^{N−1}; it cancels in the marginals.
    let (perm, grad, ln_factor) = match formula {
        #[cfg(test)]
        PermanentFormula::Ryser => {
            let (perm, grad) = ryser_with_gradient(n, &scaled);
            (perm, grad, 0.0)
        }
        PermanentFormula::Glynn => {
            let (perm, grad) = glynn_with_gradient(n, &scaled);
            (perm, grad, (n as f64 - 1.0) * std::f64::consts::LN_2)
        }
    };
    if !(perm > 0.0 && perm.is_finite()) {
        return Err(BeliefError::Degenerate { normalizer: perm });
    }
    let marginals = scaled
        .iter()
        .zip(&grad)
        // Rounding can leave a tiny negative where the truth is 0.
        .map(|(&x, &g)| (x * g / perm).max(0.0))
        .collect();
    Ok((perm.ln() - ln_factor - ln_scale, marginals))
}

/// Marginals of p(π) ∝ exp(Σ_t l\[t·n + π(t)\]) (row-major; entries finite
/// or −∞).
pub(crate) fn marginals_from_log_likelihoods(n: usize, l: &[f64]) -> Result<Vec<f64>, BeliefError> {
    let a = exp_rows(n, l)?;
    permanent_marginals(n, &a).map(|(_, m)| m)
}

/// exp(l − row max) row by row: the same distribution, with entries in
/// [0, 1] (Property 1 of the paper: adding a constant to a row changes
/// nothing). Refuses NaN, +∞ and rows that are all −∞.
pub(crate) fn exp_rows(n: usize, l: &[f64]) -> Result<Vec<f64>, BeliefError> {
    if n == 0 || l.len() != n * n {
        return Err(BeliefError::Numerical {
            step: "information matrix",
            detail: format!("expected {n} × {n} entries, got {}", l.len()),
        });
    }
    let mut a = Vec::with_capacity(n * n);
    for row in l.chunks(n) {
        if let Some(&bad) = row.iter().find(|x| x.is_nan() || **x == f64::INFINITY) {
            return Err(BeliefError::Numerical {
                step: "information matrix",
                detail: format!("entry {bad} is not finite or −∞"),
            });
        }
        let top = row.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if top == f64::NEG_INFINITY {
            return Err(BeliefError::Degenerate { normalizer: 0.0 });
        }
        a.extend(row.iter().map(|&x| (x - top).exp()));
    }
    Ok(a)
}

/// Steps between recomputations of the running sums from scratch.
const RESYNC: u64 = 1024;

/// Fills `excl[t] = Π_{r≠t} v[r]` and returns Π_r v[r] (prefix and suffix
/// products: no division, so zeros are fine).
fn products(v: &[f64], prefix: &mut [f64], excl: &mut [f64]) -> f64 {
    let n = v.len();
    prefix[0] = 1.0;
    for r in 0..n {
        prefix[r + 1] = prefix[r] * v[r];
    }
    let mut suffix = 1.0;
    for r in (0..n).rev() {
        excl[r] = prefix[r] * suffix;
        suffix *= v[r];
    }
    prefix[n]
}

/// Ryser's formula in Gray-code order, with the gradient: returns perm(A)
/// and d\[t·n + i\] = ∂perm/∂A\[t\]\[i\].
#[cfg(test)]
fn ryser_with_gradient(n: usize, a: &[f64]) -> (f64, Vec<f64>) {
    let mut sums = vec![0.0f64; n]; // s_r(S)
    let mut running = vec![0.0f64; n]; // R_t: Σ over steps so far
    let mut entered = vec![0.0f64; n * n]; // R_t when column i entered
    let mut grad = vec![0.0f64; n * n];
    let mut prefix = vec![1.0f64; n + 1];
    let mut excl = vec![0.0f64; n];
    let mut perm = 0.0f64;
    let mut gray: u64 = 0;
    for k in 1u64..(1u64 << n) {
        let j = k.trailing_zeros() as usize;
        let bit = 1u64 << j;
        gray ^= bit;
        // Close or open column j's run, with R before this step's term.
        if gray & bit != 0 {
            for t in 0..n {
                entered[t * n + j] = running[t];
                sums[t] += a[t * n + j];
            }
        } else {
            for t in 0..n {
                grad[t * n + j] += running[t] - entered[t * n + j];
                sums[t] -= a[t * n + j];
            }
        }
        if k % RESYNC == 0 {
            for (t, s) in sums.iter_mut().enumerate() {
                *s = (0..n)
                    .filter(|&c| gray & (1u64 << c) != 0)
                    .map(|c| a[t * n + c])
                    .sum();
            }
        }
        let full = products(&sums, &mut prefix, &mut excl);
        let size = gray.count_ones() as usize;
        // Parity by bit test (`is_multiple_of` needs Rust 1.87; MSRV is 1.85).
        let sign = if (n - size) & 1 == 0 { 1.0 } else { -1.0 };
        perm += sign * full;
        for t in 0..n {
            running[t] += sign * excl[t];
        }
    }
    // Columns still in S at the end close their runs now.
    for j in 0..n {
        if gray & (1u64 << j) != 0 {
            for t in 0..n {
                grad[t * n + j] += running[t] - entered[t * n + j];
            }
        }
    }
    (perm, grad)
}

/// Glynn's formula in Gray-code order, with the gradient: returns
/// 2^{N−1}·perm(A) and 2^{N−1}·∂perm/∂A (the common factor cancels in the
/// marginals).
fn glynn_with_gradient(n: usize, a: &[f64]) -> (f64, Vec<f64>) {
    let mut delta = vec![1.0f64; n];
    // c_j = Σ_i δ_i A[i][j]; all δ = +1 at the start.
    let mut cols = vec![0.0f64; n];
    for row in a.chunks(n) {
        cols.iter_mut().zip(row).for_each(|(c, &x)| *c += x);
    }
    let mut running = vec![0.0f64; n]; // R_i = Σ_states σ·Π_{j≠i} c_j
    let mut run_start = vec![0.0f64; n * n]; // R when row t's run began
    let mut grad = vec![0.0f64; n * n];
    let mut prefix = vec![1.0f64; n + 1];
    let mut excl = vec![0.0f64; n];
    let mut perm = 0.0f64;
    let mut sign = 1.0f64;
    for k in 0u64..(1u64 << (n - 1)) {
        if k > 0 {
            let t = k.trailing_zeros() as usize + 1;
            // Close row t's run with its old sign, then flip it.
            for i in 0..n {
                grad[t * n + i] += delta[t] * (running[i] - run_start[t * n + i]);
                run_start[t * n + i] = running[i];
            }
            delta[t] = -delta[t];
            sign = -sign;
            if k % RESYNC == 0 {
                cols.iter_mut().for_each(|c| *c = 0.0);
                for (row, &d) in a.chunks(n).zip(&delta) {
                    cols.iter_mut().zip(row).for_each(|(c, &x)| *c += d * x);
                }
            } else {
                let row = &a[t * n..(t + 1) * n];
                let twice = 2.0 * delta[t];
                cols.iter_mut().zip(row).for_each(|(c, &x)| *c += twice * x);
            }
        }
        let full = products(&cols, &mut prefix, &mut excl);
        perm += sign * full;
        for i in 0..n {
            running[i] += sign * excl[i];
        }
    }
    for t in 0..n {
        for i in 0..n {
            grad[t * n + i] += delta[t] * (running[i] - run_start[t * n + i]);
        }
    }
    (perm, grad)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::ExactPermutationFilter;
    use crate::filter::{doubly_stochastic_residual, max_abs_difference, to_rows, IdentityFilter};
    use crate::permutation::Permutations;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    const BOTH: [PermanentFormula; 2] = [PermanentFormula::Ryser, PermanentFormula::Glynn];

    fn brute_permanent(n: usize, a: &[f64]) -> f64 {
        let perms = Permutations::new(n).unwrap();
        (0..perms.count())
            .map(|r| {
                perms
                    .get(r)
                    .iter()
                    .enumerate()
                    .map(|(t, &i)| a[t * n + i as usize])
                    .product::<f64>()
            })
            .sum()
    }

    fn random_l(rng: &mut ChaCha8Rng, n: usize, spread: f64) -> Vec<Vec<f64>> {
        (0..n)
            .map(|_| (0..n).map(|_| rng.gen_range(-spread..spread)).collect())
            .collect()
    }

    #[test]
    fn permanent_matches_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for formula in BOTH {
            for n in 1..=8 {
                let a: Vec<f64> = (0..n * n).map(|_| rng.gen_range(0.0..3.0)).collect();
                let want = brute_permanent(n, &a);
                let got = permanent_marginals_with(n, &a, formula).unwrap().0.exp();
                assert!(
                    (got / want - 1.0).abs() < 1e-12,
                    "{formula:?} n={n}: {got} vs {want}"
                );
            }
            // perm of the all-ones matrix is n!; the uniform matrix is the
            // worst case for cancellation (measured error 3e-13 Ryser, 2e-15
            // Glynn).
            let ones = vec![1.0; 10 * 10];
            let ln_perm = permanent_marginals_with(10, &ones, formula).unwrap().0;
            assert!((ln_perm - 3_628_800f64.ln()).abs() < 1e-10, "{formula:?}");
        }
    }

    #[test]
    fn marginals_match_the_exact_filter() {
        // Measured worst differences for n ≤ 9, L uniform in ±spread with
        // spread 0.1, 2, 5 and 40 (nearly decomposable): Ryser 3.3e-13,
        // Glynn 4.0e-13 — at this size both are at the exact filter's own
        // rounding level; Glynn's advantage shows at n = 20 (below).
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for formula in BOTH {
            let mut worst: f64 = 0.0;
            for n in 1..=9 {
                for spread in [0.1, 2.0, 5.0, 40.0] {
                    let l = random_l(&mut rng, n, spread);
                    let a = exp_rows(n, &l.concat()).unwrap();
                    let got = to_rows(n, &permanent_marginals_with(n, &a, formula).unwrap().1);
                    let want = ExactPermutationFilter::from_log_likelihoods(&l)
                        .unwrap()
                        .marginals()
                        .unwrap();
                    worst = worst.max(max_abs_difference(&got, &want));
                }
            }
            assert!(worst < 1e-11, "{formula:?}: {worst}");
        }
    }

    #[test]
    fn zeros_and_degenerate_matrices() {
        for formula in BOTH {
            // A permutation matrix: its one assignment has probability 1.
            let a = vec![0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0];
            let (ln_perm, m) = permanent_marginals_with(3, &a, formula).unwrap();
            assert!(ln_perm.abs() < 1e-12);
            assert_eq!(m, a);
            // No positive diagonal.
            let b = vec![1.0, 1.0, 0.0, 0.0];
            assert!(matches!(
                permanent_marginals_with(2, &b, formula),
                Err(BeliefError::Degenerate { .. })
            ));
        }
        assert!(permanent_marginals(2, &[1.0, f64::NAN, 1.0, 1.0]).is_err());
        assert!(matches!(
            permanent_marginals(23, &vec![1.0; 23 * 23]),
            Err(BeliefError::TooLarge { .. })
        ));
    }

    #[test]
    fn twenty_tracks_stay_doubly_stochastic() {
        // No brute force at n = 20; the row and column sums of the marginals
        // are an exact identity (Laplace expansion), so their error measures
        // the cancellation. Measured residuals (near-uniform, peaked):
        // Ryser 1.5e-7, 2.8e-8; Glynn 1.2e-12, 1.3e-13.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for formula in BOTH {
            for spread in [0.01, 3.0] {
                let l: Vec<f64> = (0..400).map(|_| rng.gen_range(-spread..spread)).collect();
                let a = exp_rows(20, &l).unwrap();
                let m = to_rows(20, &permanent_marginals_with(20, &a, formula).unwrap().1);
                let residual = doubly_stochastic_residual(&m);
                let bound = match formula {
                    PermanentFormula::Ryser => 1e-5,
                    PermanentFormula::Glynn => 1e-9,
                };
                assert!(residual < bound, "{formula:?} spread {spread}: {residual}");
            }
        }
    }
}
