//! Binomial weights W(j) = Σ_x [α ⊆ x]·π(|x|) for a set α of size j: how many
//! admissible red sets a basis function φ_α covers, weighted by the prior over
//! the number of red targets. With k known, W(j) = C(n − j, k − j), the l1
//! norm of φ_α used throughout Section 5 (normalizing constant, thresholding,
//! OMP inner products ⟨φ_β, φ_α⟩ = W(|α ∪ β|)).
//!
//! These numbers overflow f64 long before n = 10,000 (C(10000, 5000) has
//! about 3000 digits), so they live in log space, and the engine works with
//! ratios W(j + 1)/W(j) = (k − j)/(n − j), which never overflow.
//!
//! With k unknown, the prior p over the count enters as π(k) = p(k)/C(n, k)
//! (every set of a given size equally likely); rollup and conditioning do not
//! depend on it (Section 5.5), only these weights do.

use crate::event::RedCount;

/// ln C(n, r) via the log-gamma-free sum of logs, exact enough (< 1e-12
/// relative) and monotone.
pub fn ln_binomial(n: usize, r: usize) -> f64 {
    if r > n {
        return f64::NEG_INFINITY;
    }
    let r = r.min(n - r);
    (0..r).map(|i| ((n - i) as f64 / (r - i) as f64).ln()).sum()
}

/// ln(e^a + e^b) without overflow.
fn ln_add(a: f64, b: f64) -> f64 {
    if a == f64::NEG_INFINITY {
        return b;
    }
    if b == f64::NEG_INFINITY {
        return a;
    }
    let (hi, lo) = if a > b { (a, b) } else { (b, a) };
    hi + (lo - hi).exp().ln_1p()
}

/// The table ln W(j) for j = 0..=max_red, for one field.
#[derive(Debug, Clone)]
pub struct Weights {
    tracks: usize,
    ln_w: Vec<f64>,
}

impl Weights {
    pub fn new(tracks: usize, red: &RedCount) -> Self {
        let ln_w = match red {
            RedCount::Known(k) => (0..=*k).map(|j| ln_binomial(tracks - j, k - j)).collect(),
            RedCount::Unknown { prior } => {
                let total: f64 = prior.iter().sum();
                let max = red.max_red();
                // ln[C(n−j, k−j)/C(n, k)] = ln[k!/(k−j)!] − ln[n!/(n−j)!], built up in j.
                let mut ln_w = vec![f64::NEG_INFINITY; max + 1];
                for (k, &p) in prior.iter().enumerate() {
                    if p <= 0.0 {
                        continue;
                    }
                    let mut term = (p / total).ln();
                    for (j, slot) in ln_w.iter_mut().enumerate().take(k + 1) {
                        if j > 0 {
                            term += ((k - j + 1) as f64 / (tracks - j + 1) as f64).ln();
                        }
                        *slot = ln_add(*slot, term);
                    }
                }
                ln_w
            }
        };
        Weights { tracks, ln_w }
    }

    pub fn tracks(&self) -> usize {
        self.tracks
    }

    /// The largest size a set can have and still cover an admissible red set.
    pub fn max_size(&self) -> usize {
        self.ln_w.len() - 1
    }

    /// ln W(j); −∞ when no admissible red set has j or more tracks.
    pub fn ln(&self, j: usize) -> f64 {
        self.ln_w.get(j).copied().unwrap_or(f64::NEG_INFINITY)
    }

    /// W(j + 1)/W(j): the share of the sets covered by φ_α (|α| = j) that
    /// also hold one given track outside α.
    pub fn ratio(&self, j: usize) -> f64 {
        if j + 1 >= self.ln_w.len() {
            0.0
        } else {
            (self.ln_w[j + 1] - self.ln_w[j]).exp()
        }
    }

    /// W(to)/W(from) for to ≥ from.
    pub fn ratio_between(&self, from: usize, to: usize) -> f64 {
        if to >= self.ln_w.len() {
            0.0
        } else {
            (self.ln_w[to] - self.ln_w[from]).exp()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_k_weights_are_binomials() {
        let w = Weights::new(10, &RedCount::Known(5));
        assert!((w.ln(0).exp() - 252.0).abs() < 1e-9);
        assert!((w.ln(2).exp() - 56.0).abs() < 1e-9);
        assert!((w.ratio(0) - 0.5).abs() < 1e-12);
        assert_eq!(w.ratio(5), 0.0);
        assert_eq!(w.ln(6), f64::NEG_INFINITY);
    }

    #[test]
    fn large_fields_stay_finite() {
        let w = Weights::new(10_000, &RedCount::Known(5_000));
        assert!(w.ln(0).is_finite() && w.ln(0) > 6000.0);
        assert!((w.ratio(0) - 0.5).abs() < 1e-12);
        assert!((w.ln(5000)).abs() < 1e-9);
    }

    #[test]
    fn unknown_k_with_binomial_prior_is_independent_halves() {
        // p(k) = C(n,k)/2^n makes every subset equally likely: W(j) = 2^-j.
        let n = 12;
        let prior: Vec<f64> = (0..=n)
            .map(|k| ln_binomial(n, k).exp() / 2f64.powi(n as i32))
            .collect();
        let w = Weights::new(n, &RedCount::Unknown { prior });
        for j in 0..=n {
            assert!((w.ln(j) - (j as f64) * 0.5f64.ln()).abs() < 1e-9, "j={j}");
        }
    }
}
