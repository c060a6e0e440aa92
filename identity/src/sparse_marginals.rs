//! Identity marginals stored by row, sparsely: for each track the
//! identities it may carry with their probabilities, and one probability
//! shared by every identity it does not list.
//!
//! A dense answer is N² numbers (800 MB at N = 10,000) although a track
//! can carry only the identities of the few people it met: the factored
//! identity belief ([`super::factored`]) knows a track's group (at most
//! nine identities), the identities its background row lists, and a
//! background probability common to all others; the information matrix's
//! marginals ([`super::marginals`]) are zero outside a track's block. This
//! is the form both answer in, what the coordinator serves and `idmesh
//! replay` writes, and what the scores ([`super::scoring`]) and the most
//! likely assignment read, so that a query at N = 10,000 touches the
//! entries the belief holds and not N².

use super::assignment::{most_likely_assignment, DENSE_ASSIGNMENT_LIMIT};
use super::filter::Marginals;
use super::sparse_assignment::{sparse_min_cost_assignment_with_rest, SparseRow};
use idmesh_belief::BeliefError;
pub use idmesh_protocol::wire::query::IdentityRow;
use serde::{Deserialize, Serialize};

/// N rows of [`IdentityRow`]: p\[t\]\[i\] = P(track t carries identity i).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SparseMarginals {
    n: usize,
    rows: Vec<IdentityRow>,
}

impl SparseMarginals {
    /// N rows over N identities, checked: identities in range and
    /// ascending, probabilities in [0, 1].
    pub fn new(rows: Vec<IdentityRow>) -> Result<Self, BeliefError> {
        let n = rows.len();
        if n == 0 {
            return Err(BeliefError::NoTracks);
        }
        for (t, row) in rows.iter().enumerate() {
            let bad = |detail: String| BeliefError::Numerical {
                step: "identity marginals",
                detail: format!("track {t}: {detail}"),
            };
            if let Some(p) = std::iter::once(row.rest)
                .chain(row.listed.iter().map(|&(_, p)| p))
                .find(|p| !(0.0..=1.0 + 1e-9).contains(p))
            {
                return Err(bad(format!("a probability of {p}")));
            }
            if let Some(&(i, _)) = row.listed.iter().find(|&&(i, _)| i as usize >= n) {
                return Err(bad(format!("identity {i} of {n}")));
            }
            if row.listed.windows(2).any(|w| w[0].0 >= w[1].0) {
                return Err(bad("identities listed out of order".into()));
            }
        }
        Ok(SparseMarginals { n, rows })
    }

    /// The rows of a dense matrix (non-zero entries listed).
    pub(crate) fn from_dense(p: &[Vec<f64>]) -> Result<Self, BeliefError> {
        super::event::check_square(p)?;
        Self::new(p.iter().map(|row| IdentityRow::from_dense(row)).collect())
    }

    /// N.
    pub fn size(&self) -> usize {
        self.n
    }

    /// The rows, by track.
    pub fn rows(&self) -> &[IdentityRow] {
        &self.rows
    }

    /// The rows, taken.
    pub fn into_rows(self) -> Vec<IdentityRow> {
        self.rows
    }

    /// The entries listed, over all rows.
    pub fn listed(&self) -> usize {
        self.rows.iter().map(|r| r.listed.len()).sum()
    }

    /// The N × N matrix (N² numbers: for small N and for tests).
    pub fn dense(&self) -> Marginals {
        self.rows.iter().map(|row| row.dense(self.n)).collect()
    }

    /// The largest |p\[t\]\[i\] − q\[t\]\[i\]| over every entry; ∞ when the
    /// sizes differ. Reads the listed entries of both and the rests.
    pub fn max_abs_difference(&self, other: &SparseMarginals) -> f64 {
        if self.n != other.n {
            return f64::INFINITY;
        }
        let mut worst: f64 = 0.0;
        for (a, b) in self.rows.iter().zip(&other.rows) {
            for &(i, p) in &a.listed {
                worst = worst.max((p - b.probability(i)).abs());
            }
            for &(i, q) in &b.listed {
                worst = worst.max((a.probability(i) - q).abs());
            }
            // The rests meet at an identity neither row lists, if any.
            if union_size(&a.listed, &b.listed) < self.n {
                worst = worst.max((a.rest - b.rest).abs());
            }
        }
        worst
    }

    /// The one-to-one assignment of largest Σ_t ln p\[t\]\[π(t)\]:
    /// `result[t]` is the identity of track t. Small N densely (as
    /// [`most_likely_assignment`]); beyond, over the listed entries with
    /// each row's rest as the cost of every identity it does not list,
    /// exactly ([`sparse_min_cost_assignment_with_rest`]).
    pub fn most_likely(&self) -> Result<Vec<u32>, BeliefError> {
        if self.n <= DENSE_ASSIGNMENT_LIMIT {
            return most_likely_assignment(&self.dense());
        }
        let cost = |p: f64| if p > 0.0 { -p.ln() } else { f64::INFINITY };
        let rows: Vec<SparseRow> = self
            .rows
            .iter()
            .map(|row| {
                row.listed
                    .iter()
                    .filter(|&&(_, p)| p > 0.0)
                    .map(|&(i, p)| (i, cost(p)))
                    .collect()
            })
            .collect();
        let rest: Vec<f64> = self.rows.iter().map(|row| cost(row.rest)).collect();
        sparse_min_cost_assignment_with_rest(&rows, &rest).ok_or(BeliefError::Numerical {
            step: "most likely assignment",
            detail: "the identities the rows list hold no one-to-one assignment".into(),
        })
    }
}

/// How many identities two ascending lists hold between them.
fn union_size(a: &[(u32, f64)], b: &[(u32, f64)]) -> usize {
    let (mut i, mut j, mut count) = (0, 0, 0);
    while i < a.len() || j < b.len() {
        match (a.get(i), b.get(j)) {
            (Some(x), Some(y)) if x.0 == y.0 => (i, j) = (i + 1, j + 1),
            (Some(x), Some(y)) if x.0 < y.0 => i += 1,
            (Some(_), None) => i += 1,
            _ => j += 1,
        }
        count += 1;
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_read_as_their_dense_form() {
        let row = IdentityRow::collect(0.1, vec![(3, 0.2), (1, 0.3), (3, 0.2)]);
        assert_eq!(row.listed, vec![(1, 0.3), (3, 0.4)]);
        assert_eq!(row.probability(3), 0.4);
        assert_eq!(row.probability(0), 0.1);
        assert_eq!(row.dense(4), vec![0.1, 0.3, 0.1, 0.4]);
        assert!((row.total(4) - 0.9).abs() < 1e-15);
        let p = vec![vec![0.0, 1.0], vec![1.0, 0.0]];
        let sparse = SparseMarginals::from_dense(&p).unwrap();
        assert_eq!(sparse.dense(), p);
        assert_eq!(sparse.listed(), 2);
        assert_eq!(sparse.most_likely().unwrap(), vec![1, 0]);
        assert_eq!(sparse.max_abs_difference(&sparse), 0.0);
    }

    #[test]
    fn bad_rows_are_refused_by_track() {
        let out_of_range = vec![IdentityRow::collect(0.0, vec![(2, 1.0)]); 2];
        let e = SparseMarginals::new(out_of_range).unwrap_err();
        assert!(e.to_string().contains("track 0: identity 2 of 2"), "{e}");
        let unordered = IdentityRow {
            rest: 0.0,
            listed: vec![(1, 0.5), (0, 0.5)],
        };
        assert!(SparseMarginals::new(vec![IdentityRow::default(), unordered]).is_err());
        let negative = IdentityRow {
            rest: -0.5,
            listed: vec![],
        };
        assert!(SparseMarginals::new(vec![negative]).is_err());
        assert!(SparseMarginals::new(vec![]).is_err());
    }

    #[test]
    fn the_sparse_assignment_equals_the_dense_one_beyond_the_dense_limit() {
        // n = 300: pairs of tracks that may have swapped, every other
        // identity at a small rest.
        let n = 300;
        let rows: Vec<IdentityRow> = (0..n as u32)
            .map(|t| {
                let partner = t ^ 1;
                let (own, swap) = if t % 4 < 2 { (0.7, 0.3) } else { (0.4, 0.6) };
                IdentityRow::collect(1e-6, vec![(t, own), (partner, swap)])
            })
            .collect();
        let sparse = SparseMarginals::new(rows).unwrap();
        let dense = most_likely_assignment(&sparse.dense()).unwrap();
        assert_eq!(sparse.most_likely().unwrap(), dense);
        assert_eq!(dense[0], 0);
        assert_eq!(dense[2], 3);
    }
}
