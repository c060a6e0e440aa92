//! [`IdentityFilter`], the one interface every identity belief offers — the
//! exact filter over N! assignments, the belief matrix, the information
//! matrix and the property-bits filter — so tests, replay and benchmarks
//! treat them alike; plus small checks on marginal matrices.

use super::event::{check_identify, check_mix, Identify, IdentityEvent};
use super::sparse_marginals::SparseMarginals;
use idmesh_belief::BeliefError;
use idmesh_belief::Mix;

/// p\[t\]\[i\] = P(track t carries identity i), N rows of N entries.
pub(crate) type Marginals = Vec<Vec<f64>>;

/// A belief over which track carries which identity, updated event by event.
///
/// Every update is all-or-nothing: when it returns an error the filter is
/// exactly as it was before the call.
pub trait IdentityFilter {
    /// N: the number of tracks, which is also the number of identities.
    fn size(&self) -> usize;

    /// Tracks `a` and `b` came close; with probability `swap` their targets
    /// exchanged tracks.
    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError>;

    /// A sensor read an identity on a track.
    fn identify(&mut self, identify: Identify) -> Result<(), BeliefError>;

    /// p\[t\]\[i\] = P(track t carries identity i).
    fn marginals(&self) -> Result<Marginals, BeliefError>;

    /// The marginals by row ([`SparseMarginals`]): the dense ones, their
    /// zeros left out, unless the belief knows them row by row (the
    /// factored identity belief does, without ever forming N²).
    fn sparse_marginals(&self) -> Result<SparseMarginals, BeliefError> {
        SparseMarginals::from_dense(&self.marginals()?)
    }

    /// Applies one event (checked against the size first).
    fn apply(&mut self, event: &IdentityEvent) -> Result<(), BeliefError> {
        match *event {
            IdentityEvent::Mix(mix) => {
                check_mix(self.size(), &mix)?;
                self.mix(mix)
            }
            IdentityEvent::Identify(identify) => {
                check_identify(self.size(), &identify)?;
                self.identify(identify)
            }
        }
    }

    /// The one-to-one assignment with the largest Σ_t ln p\[t\]\[π(t)\]
    /// under the marginals: `result[t]` is the identity of track t.
    fn most_likely(&self) -> Result<Vec<u32>, BeliefError> {
        self.sparse_marginals()?.most_likely()
    }
}

/// The largest |row sum − 1| or |column sum − 1| of `p`: 0 for a doubly
/// stochastic matrix.
#[cfg(test)]
pub(crate) fn doubly_stochastic_residual(p: &[Vec<f64>]) -> f64 {
    let n = p.len();
    let mut worst: f64 = 0.0;
    for row in p {
        worst = worst.max((row.iter().sum::<f64>() - 1.0).abs());
    }
    for i in 0..n {
        let col: f64 = p.iter().map(|row| row.get(i).copied().unwrap_or(0.0)).sum();
        worst = worst.max((col - 1.0).abs());
    }
    worst
}

/// The largest |p\[t\]\[i\] − q\[t\]\[i\]|; ∞ when the shapes differ.
pub fn max_abs_difference(p: &[Vec<f64>], q: &[Vec<f64>]) -> f64 {
    if p.len() != q.len() || p.iter().zip(q).any(|(a, b)| a.len() != b.len()) {
        return f64::INFINITY;
    }
    p.iter()
        .zip(q)
        .flat_map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y).abs()))
        .fold(0.0, f64::max)
}

/// Turns a row-major flat n × n matrix into rows.
pub fn to_rows(n: usize, flat: &[f64]) -> Marginals {
    flat.chunks(n.max(1)).map(|row| row.to_vec()).collect()
}
