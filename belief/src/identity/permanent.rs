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
//! Ryser's formula, perm(A) = Σ_{S ⊆ columns} (−1)^{N−|S|} Π_r s_r(S) with
//! s_r(S) = Σ_{j∈S} A\[r\]\[j\], gives the derivative term by term:
//! ∂perm/∂A\[t\]\[i\] = Σ_{S ∋ i} (−1)^{N−|S|} Π_{r≠t} s_r(S). We visit the
//! subsets in Gray-code order (one column enters or leaves per step, so the
//! row sums update in O(N)), compute the N products Π_{r≠t} from prefix and
//! suffix products, and add them to running sums R_t. Column i is in S over
//! whole runs of steps; when it enters we remember R, when it leaves we add
//! the difference. So all N² marginals cost O(2^N·N) time, the same as one
//! permanent, and O(N²) memory.
//!
//! Numerical safety: the marginals do not change when rows and columns of A
//! are scaled, so we first bring A close to doubly stochastic (a few
//! Sinkhorn sweeps, the factors kept in log space for ln perm). Then every
//! Ryser term is at most 1 in size and nothing overflows; the remaining
//! error is the cancellation inherent in the alternating sum, at worst
//! about ε·Σ_S |term| / perm(A). For a near-uniform 20 × 20 matrix that is
//! ~1e-6 relative (perm ≈ 20!/20^20 ≈ 2e-8); for the peaked matrices
//! identity tracking produces it is far smaller. The tests measure it.

use crate::error::BeliefError;

/// The most tracks the permanent method accepts (2^22·22 ≈ 10^8 steps).
pub const MAX_PERMANENT_TRACKS: usize = 22;

/// ln perm(A) and the marginals p\[t\]\[i\] (row-major) of the distribution
/// p(π) ∝ Π_t A\[t\]\[π(t)\], for a non-negative row-major n × n matrix.
pub fn permanent_marginals(n: usize, a: &[f64]) -> Result<(f64, Vec<f64>), BeliefError> {
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
    let (scaled, ln_scale) = balance(n, a)?;
    let (perm, d) = ryser_with_gradient(n, &scaled);
    if !(perm > 0.0 && perm.is_finite()) {
        return Err(BeliefError::Degenerate { normalizer: perm });
    }
    let marginals = scaled
        .iter()
        .zip(&d)
        // Rounding can leave a tiny negative where the truth is 0.
        .map(|(&x, &g)| (x * g / perm).max(0.0))
        .collect();
    Ok((perm.ln() + ln_scale, marginals))
}

/// ln perm(A) of a non-negative row-major n × n matrix (−∞ when 0 is
/// reported as [`BeliefError::Degenerate`]).
pub fn ln_permanent(n: usize, a: &[f64]) -> Result<f64, BeliefError> {
    permanent_marginals(n, a).map(|(ln_perm, _)| ln_perm)
}

/// Marginals of p(π) ∝ exp(Σ_t l\[t\]\[π(t)\]) (row-major; entries finite
/// or −∞).
pub fn marginals_from_log_likelihoods(n: usize, l: &[f64]) -> Result<Vec<f64>, BeliefError> {
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

/// A·diag scaled towards doubly stochastic by a few Sinkhorn sweeps, and
/// ln of the factor taken out (perm(A) = perm(scaled)·e^{factor}).
fn balance(n: usize, a: &[f64]) -> Result<(Vec<f64>, f64), BeliefError> {
    let mut m = a.to_vec();
    let mut ln_scale = 0.0;
    let mut col = vec![0.0; n];
    // Convergence is not needed — only entries of moderate size — so a
    // fixed, small number of sweeps.
    for _ in 0..8 {
        for row in m.chunks_mut(n) {
            let sum: f64 = row.iter().sum();
            if !(sum > 0.0) {
                return Err(BeliefError::Degenerate { normalizer: 0.0 });
            }
            row.iter_mut().for_each(|x| *x /= sum);
            ln_scale += sum.ln();
        }
        col.iter_mut().for_each(|c| *c = 0.0);
        for row in m.chunks(n) {
            col.iter_mut().zip(row).for_each(|(c, &x)| *c += x);
        }
        if col.iter().any(|&c| !(c > 0.0)) {
            return Err(BeliefError::Degenerate { normalizer: 0.0 });
        }
        for row in m.chunks_mut(n) {
            row.iter_mut().zip(&col).for_each(|(x, &c)| *x /= c);
        }
        ln_scale += col.iter().map(|c| c.ln()).sum::<f64>();
    }
    Ok((m, ln_scale))
}

/// Ryser's formula in Gray-code order, with the gradient: returns perm(A)
/// and d\[t·n + i\] = ∂perm/∂A\[t\]\[i\].
fn ryser_with_gradient(n: usize, a: &[f64]) -> (f64, Vec<f64>) {
    let mut sums = vec![0.0f64; n]; // s_r(S)
    let mut running = vec![0.0f64; n]; // R_t: Σ over steps so far
    let mut entered = vec![0.0f64; n * n]; // R_t when column i entered
    let mut grad = vec![0.0f64; n * n];
    let mut prefix = vec![1.0f64; n + 1];
    let mut suffix = vec![1.0f64; n + 1];
    let mut perm = 0.0f64;
    let mut gray: u64 = 0;
    for k in 1u64..(1u64 << n) {
        let j = k.trailing_zeros() as usize;
        let bit = 1u64 << j;
        gray ^= bit;
        let entering = gray & bit != 0;
        // Close or open column j's run, with R before this step's term.
        if entering {
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
        for r in 0..n {
            prefix[r + 1] = prefix[r] * sums[r];
        }
        for r in (0..n).rev() {
            suffix[r] = suffix[r + 1] * sums[r];
        }
        let size = gray.count_ones() as usize;
        let sign = if (n - size) % 2 == 0 { 1.0 } else { -1.0 };
        perm += sign * prefix[n];
        for t in 0..n {
            running[t] += sign * prefix[t] * suffix[t + 1];
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identity::exact::ExactPermutationFilter;
    use crate::identity::filter::{doubly_stochastic_residual, max_abs_difference, to_rows, IdentityFilter};
    use crate::identity::permutation::Permutations;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

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
        for n in 1..=8 {
            let a: Vec<f64> = (0..n * n).map(|_| rng.gen_range(0.0..3.0)).collect();
            let want = brute_permanent(n, &a);
            let got = ln_permanent(n, &a).unwrap().exp();
            assert!((got / want - 1.0).abs() < 1e-12, "n={n}: {got} vs {want}");
        }
        // perm of the all-ones matrix is n!.
        let ones = vec![1.0; 10 * 10];
        assert!((ln_permanent(10, &ones).unwrap() - 3_628_800f64.ln()).abs() < 1e-12);
    }

    #[test]
    fn marginals_match_the_exact_filter() {
        // Measured: worst difference ~1e-15 for n ≤ 9 with L in ±5.
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        for n in 1..=9 {
            for spread in [0.1, 2.0, 5.0] {
                let l = random_l(&mut rng, n, spread);
                let flat: Vec<f64> = l.iter().flatten().copied().collect();
                let got = to_rows(n, &marginals_from_log_likelihoods(n, &flat).unwrap());
                let want = ExactPermutationFilter::from_log_likelihoods(&l)
                    .unwrap()
                    .marginals()
                    .unwrap();
                let diff = max_abs_difference(&got, &want);
                assert!(diff < 1e-12, "n={n} spread={spread}: {diff}");
            }
        }
    }

    #[test]
    fn zeros_and_degenerate_matrices() {
        // A permutation matrix: its one assignment has probability 1.
        let a = vec![0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0];
        let (ln_perm, m) = permanent_marginals(3, &a).unwrap();
        assert!(ln_perm.abs() < 1e-12);
        assert_eq!(m, a);
        // No positive diagonal.
        let b = vec![1.0, 1.0, 0.0, 0.0];
        assert!(matches!(
            permanent_marginals(2, &b),
            Err(BeliefError::Degenerate { .. })
        ));
        assert!(permanent_marginals(2, &[1.0, f64::NAN, 1.0, 1.0]).is_err());
        assert!(matches!(
            permanent_marginals(23, &vec![1.0; 23 * 23]),
            Err(BeliefError::TooLarge { .. })
        ));
    }

    #[test]
    fn twenty_tracks_stay_doubly_stochastic() {
        // No brute force at n = 20; the row and column sums are an exact
        // identity (Laplace expansion), so their error measures the
        // cancellation. Measured ~1e-9 for a near-uniform matrix (the worst
        // case), far less for peaked ones.
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for spread in [0.01, 3.0] {
            let l: Vec<f64> = (0..400).map(|_| rng.gen_range(-spread..spread)).collect();
            let m = to_rows(20, &marginals_from_log_likelihoods(20, &l).unwrap());
            let residual = doubly_stochastic_residual(&m);
            assert!(residual < 1e-6, "spread {spread}: {residual}");
        }
    }
}
