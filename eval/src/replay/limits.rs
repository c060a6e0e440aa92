//! How big a filter may grow: the estimates by which the replays refuse a
//! setting that is exponential on the trace at hand (an exact Radon belief
//! of C(n, k) sets, exact bit beliefs of property bits) before building it.

/// C(n, k) as a float (infinite when it overflows; 1 when k > n).
pub(crate) fn binomial(n: usize, k: usize) -> f64 {
    let k = k.min(n - k.min(n));
    (0..k).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binomials_by_the_smaller_side() {
        assert_eq!(binomial(4, 2), 6.0);
        assert_eq!(binomial(10, 9), 10.0);
        assert_eq!(binomial(5, 0), 1.0);
        assert!((binomial(60, 30) / 1.1826458156486e17 - 1.0).abs() < 1e-9);
        assert!(binomial(2000, 1000).is_infinite());
    }
}
