//! The least-squares mixing rule of [`crate::information`] for
//! rows that rule identities out (entries −∞: "this track cannot carry that
//! identity", as a known start says of every identity but one).
//!
//! A mix of tracks a and b asks for rows x, y with x_m + y_n ≈ G(m, n) =
//! ln((1 − s)·A_m·B_n + s·A_n·B_m) for the pairs (m, n) of identities the
//! two tracks can carry after the mix. With −∞ entries some G(m, n) are
//! −∞ (both tracks cannot carry that pair): those pairs are no equations —
//! the other tracks' rows already rule them out or the permanent gives them
//! no weight — and the fit is over the finite pairs F only:
//!
//!   minimize Σ_{(m,n) ∈ F} (x_m + y_n − G(m, n))².
//!
//! Three cases, by the supports Sa, Sb (finite entries) of the two rows:
//! - **Both rows finite on U = Sa ∪ Sb**: every pair of U is an equation;
//!   the O(|U|²) closed form on U, −∞ outside.
//! - **Disjoint supports** (two blocks meet for the first time, see
//!   [`crate::blocks`]): G(m, n) = ln(1 − s) + a_m + b_n for
//!   m ∈ Sa, n ∈ Sb and ln s + a_n + b_m for m ∈ Sb, n ∈ Sa: additive, so
//!   x = ln(1 − s) + a on Sa, ln s + b on Sb; y = b on Sb, a on Sa is an
//!   **exact** fit. Pairs inside Sa get weight too, but the other tracks of
//!   a's block hold all of Sa but one identity, so no assignment uses them:
//!   the merge of two blocks is exact.
//! - **Otherwise**: alternating least squares (x from y, y from x, each
//!   the mean residual of its row or column of F — block coordinate
//!   descent on a convex quadratic, so the residual never grows), until no
//!   entry moves more than 1e-11 or after [`MAX_SWEEPS`] sweeps.

use super::information::{fit_mixed_rows, fit_mixed_rows_pinv, MixSolver, RowPair};
use idmesh_belief::BeliefError;

/// The most alternating sweeps of the general case.
pub(crate) const MAX_SWEEPS: usize = 2_000;

/// ln((1 − s)·e^u + s·e^v) without overflow, −∞ allowed; s ∈ (0, 1).
fn ln_mix(u: f64, v: f64, s: f64) -> f64 {
    let top = u.max(v);
    if top == f64::NEG_INFINITY {
        return top;
    }
    top + ((1.0 - s) * (u - top).exp() + s * (v - top).exp()).ln()
}

/// The rows after a mix with swap s ∈ (0, 1) of rows with −∞ entries (see
/// the module docs); entries outside Sa ∪ Sb stay −∞. Not yet shifted.
pub(crate) fn fit_on_support(
    a: &[f64],
    b: &[f64],
    swap: f64,
    solver: MixSolver,
) -> Result<RowPair, BeliefError> {
    let n = a.len();
    let fin = |x: f64| x > f64::NEG_INFINITY;
    let union: Vec<usize> = (0..n).filter(|&i| fin(a[i]) || fin(b[i])).collect();
    let k = union.len();
    if k < 2 {
        // Two tracks, fewer than two identities between them.
        return Err(BeliefError::Degenerate { normalizer: 0.0 });
    }
    let au: Vec<f64> = union.iter().map(|&i| a[i]).collect();
    let bu: Vec<f64> = union.iter().map(|&i| b[i]).collect();
    let (xu, yu) = if au.iter().chain(&bu).all(|&x| fin(x)) {
        match solver {
            MixSolver::ClosedForm => fit_mixed_rows(&au, &bu, swap)?,
            MixSolver::PseudoInverse => fit_mixed_rows_pinv(&au, &bu, swap)?,
        }
    } else if au.iter().zip(&bu).all(|(&x, &y)| !(fin(x) && fin(y))) {
        let (keep, move_) = ((1.0 - swap).ln(), swap.ln());
        let x = au
            .iter()
            .zip(&bu)
            .map(|(&p, &q)| if fin(p) { keep + p } else { move_ + q })
            .collect();
        let y = au
            .iter()
            .zip(&bu)
            .map(|(&p, &q)| if fin(q) { q } else { p })
            .collect();
        (x, y)
    } else {
        alternating_fit(&au, &bu, swap)
    };
    let mut x = vec![f64::NEG_INFINITY; n];
    let mut y = vec![f64::NEG_INFINITY; n];
    for (j, &i) in union.iter().enumerate() {
        x[i] = xu[j];
        y[i] = yu[j];
    }
    Ok((x, y))
}

/// Least squares over the finite pairs by alternating means (the general
/// case of the module docs). Unknowns with no equation stay −∞.
fn alternating_fit(a: &[f64], b: &[f64], swap: f64) -> RowPair {
    let k = a.len();
    let mut g = vec![f64::NEG_INFINITY; k * k];
    for m in 0..k {
        for j in 0..k {
            if m != j {
                g[m * k + j] = ln_mix(a[m] + b[j], a[j] + b[m], swap);
            }
        }
    }
    let fin = |x: f64| x > f64::NEG_INFINITY;
    let mut x = vec![f64::NEG_INFINITY; k];
    let mut y: Vec<f64> = (0..k)
        .map(|j| {
            if (0..k).any(|m| fin(g[m * k + j])) {
                0.0
            } else {
                f64::NEG_INFINITY
            }
        })
        .collect();
    for _ in 0..MAX_SWEEPS {
        let mut moved: f64 = 0.0;
        for m in 0..k {
            let (mut sum, mut count) = (0.0, 0usize);
            for j in 0..k {
                let v = g[m * k + j];
                if fin(v) {
                    sum += v - y[j];
                    count += 1;
                }
            }
            if count > 0 {
                let next = sum / count as f64;
                if fin(x[m]) {
                    moved = moved.max((next - x[m]).abs());
                } else {
                    moved = f64::INFINITY;
                }
                x[m] = next;
            }
        }
        for j in 0..k {
            let (mut sum, mut count) = (0.0, 0usize);
            for m in 0..k {
                let v = g[m * k + j];
                if fin(v) {
                    sum += v - x[m];
                    count += 1;
                }
            }
            if count > 0 {
                let next = sum / count as f64;
                moved = moved.max((next - y[j]).abs());
                y[j] = next;
            }
        }
        if moved <= 1e-11 {
            break;
        }
    }
    (x, y)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::ExactPermutationFilter;
    use crate::filter::{max_abs_difference, IdentityFilter};
    use crate::information::{InformationMatrix, InformationOptions};
    use crate::workload::{generate, IdentityWorkloadSpec};
    use crate::IdentityEvent;
    use idmesh_belief::Mix;
    use proptest::prelude::*;

    const NO: f64 = f64::NEG_INFINITY;

    #[test]
    fn merging_two_blocks_is_exact() {
        // Blocks {0, 1} (mixed already) and {2}; then 1 meets 2.
        let start = [1u32, 0, 2];
        let mut info =
            InformationMatrix::from_assignment(&start, f64::INFINITY, Default::default()).unwrap();
        let mut exact = ExactPermutationFilter::from_assignment(&start).unwrap();
        for (a, b, swap) in [(0, 1, 0.3), (1, 2, 0.6), (2, 0, 0.5)] {
            let mix = Mix { a, b, swap };
            info.mix(mix).unwrap();
            exact.mix(mix).unwrap();
            let d = max_abs_difference(&info.marginals().unwrap(), &exact.marginals().unwrap());
            assert!(d < 1e-9, "after {mix:?}: {d}");
        }
    }

    #[test]
    fn rows_with_no_common_identity_pair_are_degenerate() {
        let a = [0.0, NO, NO];
        assert_eq!(
            fit_on_support(&a, &a, 0.5, MixSolver::ClosedForm),
            Err(BeliefError::Degenerate { normalizer: 0.0 })
        );
    }

    #[test]
    fn the_general_case_fits_what_it_can_exactly() {
        // Row a holds {0, 1}, row b {0, 1, 2}: the pair (2, 2) is no
        // equation, (2, n) and (m, 2) are. Every residual of the fit is
        // smaller than the residual of the start (x = a, y = b).
        let a = [0.0, -1.0, NO];
        let b = [-0.5, 0.0, -2.0];
        let (x, y) = fit_on_support(&a, &b, 0.4, MixSolver::ClosedForm).unwrap();
        assert!(x.iter().chain(&y).all(|v| v.is_finite()));
        let residual = |x: &[f64], y: &[f64]| -> f64 {
            let mut total = 0.0;
            for m in 0..3 {
                for j in 0..3 {
                    let g = ln_mix(a[m] + b[j], a[j] + b[m], 0.4);
                    if m != j && g.is_finite() {
                        total += (x[m] + y[j] - g).powi(2);
                    }
                }
            }
            total
        };
        let fitted = residual(&x, &y);
        assert!(fitted < residual(&[0.0, -1.0, 0.0], &b), "{fitted}");
        // And it is a minimum: moving any single entry makes it worse.
        for e in 0..6 {
            for step in [-1e-3, 1e-3] {
                let (mut x2, mut y2) = (x.clone(), y.clone());
                if e < 3 {
                    x2[e] += step;
                } else {
                    y2[e - 3] += step;
                }
                assert!(residual(&x2, &y2) >= fitted - 1e-12);
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// From a known start, mixes alone: every mix that joins two blocks
        /// is exact, and a mix inside a block is the least-squares rule;
        /// for blocks of at most 3 tracks (α = ½) that is exact too
        /// (the paper's N ≤ 3 theorem, per block).
        #[test]
        fn known_start_small_blocks_are_exact(
            seed in any::<u64>(),
            n in 2usize..=7,
        ) {
            let w = generate(&IdentityWorkloadSpec {
                tracks: n,
                events: 12,
                mix_share: 1.0,
                swap: 0.5,
                accuracy: 0.9,
                neighbourhood: 2,
                seed,
            }).unwrap();
            let mut info = InformationMatrix::from_assignment(
                &w.initial, f64::INFINITY, InformationOptions::default()).unwrap();
            let mut exact = ExactPermutationFilter::from_assignment(&w.initial).unwrap();
            for e in &w.events {
                info.apply(e).unwrap();
                exact.apply(e).unwrap();
                let IdentityEvent::Mix(_) = e else { continue };
                let l: Vec<f64> = info.log_likelihoods().concat();
                let largest = crate::blocks::blocks_of_log_likelihoods(n, &l)
                    .iter().map(|b| b.size()).max().unwrap();
                if largest <= 3 {
                    let d = max_abs_difference(
                        &info.marginals().unwrap(), &exact.marginals().unwrap());
                    prop_assert!(d < 1e-9, "{d}");
                }
            }
        }
    }
}
