//! Binomial weights: how many admissible red sets a dictionary atom covers.
//!
//! The Radon atom φ_α (|α| = i) covers W(i) = C(n − i, k − i) k-sets — the l1
//! norm used throughout Section 5 (normalizing constant, thresholding, OMP
//! inner products ⟨φ_β, φ_α⟩ = W(|α ∪ β|)). Our dictionary also has atoms that
//! fix some tracks blue (see [`crate::radon::atom`]); an atom with i red and
//! o blue tracks covers W(i, o) = C(n − i − o, k − i) k-sets, and W(i) = W(i, 0).
//!
//! These numbers overflow f64 long before n = 10,000 (C(10000, 5000) has
//! about 3000 digits), so they live in log space, and the engine mostly works
//! with ratios such as W(i + 1, o)/W(i, o) = (k − i)/(n − i − o), which never
//! overflow.
//!
//! With k unknown, a prior p over the count enters as π(k) = p(k)/C(n, k)
//! (every set of a given size equally likely), W(i, o) = Σ_k π(k)·C(n−i−o, k−i);
//! rollup and conditioning do not depend on it (Section 5.5), only these
//! weights do.

use crate::event::RedCount;
use rustc_hash::FxHashMap;
use std::cell::RefCell;

/// ln C(n, r) by a sum of logs: exact to ~1e-13 relative, no tables.
pub(crate) fn ln_binomial(n: usize, r: usize) -> f64 {
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

#[derive(Debug, Clone)]
enum Count {
    Known(usize),
    /// ln p(k) − ln C(n, k) for every k with p(k) > 0.
    Unknown(Vec<(usize, f64)>),
}

/// The weights of one field.
#[derive(Debug, Clone)]
pub(crate) struct Weights {
    tracks: usize,
    count: Count,
    /// ln n! for n = 0..=tracks, so that ln C is three lookups.
    ln_factorial: Vec<f64>,
    /// ln W(i, o) for unknown k, computed on first use (O(n) each).
    cache: RefCell<FxHashMap<(usize, usize), f64>>,
}

impl Weights {
    pub(crate) fn new(tracks: usize, red: &RedCount) -> Self {
        let mut ln_factorial = Vec::with_capacity(tracks + 1);
        let mut acc = 0.0;
        ln_factorial.push(0.0);
        for i in 1..=tracks {
            acc += (i as f64).ln();
            ln_factorial.push(acc);
        }
        let count = match red {
            RedCount::Known(k) => Count::Known(*k),
            RedCount::Unknown { prior } => {
                let total: f64 = prior.iter().sum();
                Count::Unknown(
                    prior
                        .iter()
                        .enumerate()
                        .filter(|(_, p)| **p > 0.0)
                        .map(|(k, p)| (k, (p / total).ln() - ln_binomial(tracks, k)))
                        .collect(),
                )
            }
        };
        Weights {
            tracks,
            count,
            ln_factorial,
            cache: RefCell::new(FxHashMap::default()),
        }
    }

    pub fn tracks(&self) -> usize {
        self.tracks
    }

    fn ln_c(&self, n: usize, r: usize) -> f64 {
        if r > n {
            f64::NEG_INFINITY
        } else {
            self.ln_factorial[n] - self.ln_factorial[r] - self.ln_factorial[n - r]
        }
    }

    /// ln W(i, o); −∞ when no admissible red set has i red tracks and o
    /// other tracks blue.
    pub(crate) fn ln2(&self, red: usize, blue: usize) -> f64 {
        if red + blue > self.tracks {
            return f64::NEG_INFINITY;
        }
        match &self.count {
            Count::Known(k) => {
                if red > *k || blue > self.tracks - k {
                    f64::NEG_INFINITY
                } else {
                    self.ln_c(self.tracks - red - blue, k - red)
                }
            }
            Count::Unknown(terms) => {
                if let Some(v) = self.cache.borrow().get(&(red, blue)) {
                    return *v;
                }
                let free = self.tracks - red - blue;
                let v = terms
                    .iter()
                    .filter(|(k, _)| *k >= red && *k - red <= free)
                    .fold(f64::NEG_INFINITY, |acc, (k, lp)| {
                        ln_add(acc, lp + self.ln_c(free, k - red))
                    });
                self.cache.borrow_mut().insert((red, blue), v);
                v
            }
        }
    }

    /// ln W(j) = ln W(j, 0), the Radon atom of j tracks.
    #[cfg(test)]
    pub(crate) fn ln(&self, j: usize) -> f64 {
        self.ln2(j, 0)
    }

    /// W(i + 1, o)/W(i, o): the share of the sets an atom covers in which one
    /// given free track is red.
    pub(crate) fn ratio_red(&self, red: usize, blue: usize) -> f64 {
        match &self.count {
            Count::Known(k) => {
                let free = self.tracks.saturating_sub(red + blue);
                if red >= *k || free == 0 {
                    0.0
                } else {
                    (k - red) as f64 / free as f64
                }
            }
            Count::Unknown(_) => self.ratio_between((red, blue), (red + 1, blue)),
        }
    }

    /// W(i, o + 1)/W(i, o): the share in which one given free track is blue.
    pub(crate) fn ratio_blue(&self, red: usize, blue: usize) -> f64 {
        match &self.count {
            Count::Known(k) => {
                let free = self.tracks.saturating_sub(red + blue);
                if free == 0 || blue >= self.tracks - k {
                    0.0
                } else {
                    (self.tracks - k - blue) as f64 / free as f64
                }
            }
            Count::Unknown(_) => self.ratio_between((red, blue), (red, blue + 1)),
        }
    }

    /// W(j + 1)/W(j) for Radon atoms.
    #[cfg(test)]
    pub(crate) fn ratio(&self, j: usize) -> f64 {
        self.ratio_red(j, 0)
    }

    /// W(to)/W(from) for (red, blue) sizes; 0 when `to` covers nothing.
    pub(crate) fn ratio_between(&self, from: (usize, usize), to: (usize, usize)) -> f64 {
        let hi = self.ln2(to.0, to.1);
        if hi == f64::NEG_INFINITY {
            0.0
        } else {
            (hi - self.ln2(from.0, from.1)).exp()
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
        assert!((w.ln2(1, 2).exp() - 35.0).abs() < 1e-9); // C(7, 4)
        assert!((w.ratio(0) - 0.5).abs() < 1e-12);
        assert!((w.ratio_blue(1, 2) - 3.0 / 7.0).abs() < 1e-15);
        assert_eq!(w.ratio(5), 0.0);
        assert_eq!(w.ln(6), f64::NEG_INFINITY);
        assert_eq!(w.ln2(0, 6), f64::NEG_INFINITY);
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
        // p(k) = C(n,k)/2^n makes every subset equally likely: W(i, o) = 2^-(i+o).
        let n = 12;
        let prior: Vec<f64> = (0..=n)
            .map(|k| ln_binomial(n, k).exp() / 2f64.powi(n as i32))
            .collect();
        let w = Weights::new(n, &RedCount::Unknown { prior });
        for i in 0..=n {
            for o in 0..=(n - i) {
                assert!(
                    (w.ln2(i, o) - ((i + o) as f64) * 0.5f64.ln()).abs() < 1e-9,
                    "i={i} o={o}"
                );
            }
        }
        assert!((w.ratio_red(3, 2) - 0.5).abs() < 1e-9);
    }
}
