//! Yardsticks for the Radon engine: the filters the paper compares its
//! overcomplete-basis method against (Jiang et al., TOSN 2013, Section 6,
//! Table III), so that replays and benchmarks can measure what the sparse
//! representation costs in accuracy and saves in time and memory.
//!
//! - [`DenseFilter`](dense::DenseFilter) — the exact filter of Section 3: the
//!   full distribution over every admissible red set, updated by the rollup of
//!   Section 3.3 and the Bayes rule of Section 3.4. Exponential in n; the
//!   ground truth every approximation is judged by ("5th-order Radon basis" in
//!   the paper's small-scale experiment).
//! - [`LowOrderFilter`](low_order::LowOrderFilter) — the comparison method of
//!   Section 5.5 ("Comparative Methods") and Table III ("1st/2nd/3rd Order
//!   Radon Basis"): the belief is kept in the range of the order-j Radon
//!   matrix Φ_{j,k} of Section 4.1 and projected back onto it after every
//!   conditioning. Polynomial in n, blind to peaky beliefs.
//!
//! Both store their numbers densely, indexed by the colex rank of a set (the
//! combinatorial number system), whose binomial table lives here.

mod dense;
mod low_order;

pub use dense::{DenseFilter, MAX_STATES};
pub use low_order::{LowOrderFilter, LowOrderRepair};

/// Binomial coefficients C(c, i) for c ≤ `top`, i ≤ `width`, saturating at
/// `usize::MAX` so that size checks can run before anything is allocated.
/// Colex rank of a set c_0 < c_1 < … < c_{m−1} is Σ_i C(c_i, i + 1): the
/// number of m-sets that precede it when sets are compared by their largest
/// differing element.
#[derive(Debug, Clone)]
pub(crate) struct Binomials {
    width: usize,
    table: Vec<usize>,
}

impl Binomials {
    pub(crate) fn new(top: usize, width: usize) -> Self {
        let stride = width + 1;
        let mut table = vec![0usize; (top + 1) * stride];
        for c in 0..=top {
            table[c * stride] = 1;
            for i in 1..=width.min(c) {
                let above = table[(c - 1) * stride + i - 1];
                let left = if i < c {
                    table[(c - 1) * stride + i]
                } else {
                    0
                };
                table[c * stride + i] = above.saturating_add(left);
            }
        }
        Binomials { width, table }
    }

    /// C(c, i); 0 when i > c. Callers stay within the table's bounds.
    #[inline]
    pub(crate) fn get(&self, c: usize, i: usize) -> usize {
        self.table[c * (self.width + 1) + i]
    }
}

/// C(n, r) as an f64 (for size checks and error reports; may be +∞).
pub(crate) fn binomial_f64(n: usize, r: usize) -> f64 {
    crate::weights::ln_binomial(n, r).exp().round()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binomial_table_matches_pascal_and_saturates() {
        let b = Binomials::new(64, 64);
        assert_eq!(b.get(4, 2), 6);
        assert_eq!(b.get(20, 10), 184_756);
        assert_eq!(b.get(3, 5), 0);
        assert_eq!(b.get(64, 32), 1_832_624_140_942_590_534);
        let wide = Binomials::new(200, 100);
        assert_eq!(wide.get(200, 100), usize::MAX);
        assert_eq!(binomial_f64(40, 20), 137_846_528_820.0);
    }
}
