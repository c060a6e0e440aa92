//! Separation quality, for testing FastICA and comparing it with
//! scikit-learn's: the Amari index of the global matrix P = W·A and the
//! best absolute correlation of every true source with an estimate.

use nalgebra::DMatrix;

/// The Amari index of a square or rectangular global matrix P (estimated
/// sources × true sources): 0 when P is a scaled permutation, up to 1 for
/// no separation at all. Normalised as in Amari, Cichocki & Yang (1996)
/// divided by 2n(n−1), the form most ICA benchmarks use.
pub fn amari_index(p: &DMatrix<f64>) -> f64 {
    let (r, c) = p.shape();
    if r == 0 || c == 0 {
        return 1.0;
    }
    let a = p.abs();
    let mut rows = 0.0;
    for i in 0..r {
        let row = a.row(i);
        let max = row.max();
        if max > 0.0 {
            rows += row.sum() / max - 1.0;
        }
    }
    let mut cols = 0.0;
    for j in 0..c {
        let col = a.column(j);
        let max = col.max();
        if max > 0.0 {
            cols += col.sum() / max - 1.0;
        }
    }
    // For a square P this is the usual 1/(2n(n−1)) normalisation.
    let denom = (r * (c.max(2) - 1) + c * (r.max(2) - 1)) as f64;
    (rows + cols) / denom
}

/// The Pearson correlation of two equally long series (0 if either is
/// constant).
pub(crate) fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    if n == 0 {
        return 0.0;
    }
    let ma = a[..n].iter().sum::<f64>() / n as f64;
    let mb = b[..n].iter().sum::<f64>() / n as f64;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for k in 0..n {
        let (x, y) = (a[k] - ma, b[k] - mb);
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    }
    if saa <= 0.0 || sbb <= 0.0 {
        0.0
    } else {
        sab / (saa * sbb).sqrt()
    }
}

/// For every true source (row of `truth`), the largest |corr| with any
/// estimated source (row of `estimate`).
pub fn max_abs_correlations(truth: &DMatrix<f64>, estimate: &DMatrix<f64>) -> Vec<f64> {
    let rows = |m: &DMatrix<f64>| -> Vec<Vec<f64>> {
        m.row_iter().map(|r| r.iter().copied().collect()).collect()
    };
    let t = rows(truth);
    let e = rows(estimate);
    t.iter()
        .map(|s| {
            e.iter()
                .map(|y| correlation(s, y).abs())
                .fold(0.0, f64::max)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn amari_of_permutation_is_zero_and_of_uniform_is_one() {
        let p = DMatrix::from_row_slice(3, 3, &[0.0, 2.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 5.0]);
        assert!(amari_index(&p) < 1e-15);
        let u = DMatrix::from_element(3, 3, 1.0);
        assert!((amari_index(&u) - 1.0).abs() < 1e-15);
    }

    #[test]
    fn correlations() {
        let a = [1.0, 2.0, 3.0, 4.0];
        let b = [-2.0, -4.0, -6.0, -8.0];
        assert!((correlation(&a, &b) + 1.0).abs() < 1e-15);
        assert_eq!(correlation(&a, &[1.0; 4]), 0.0);
        let t = DMatrix::from_row_slice(2, 4, &[1.0, 2.0, 3.0, 4.0, 1.0, -1.0, 1.0, -1.0]);
        let e = DMatrix::from_row_slice(1, 4, &[4.0, 3.0, 2.0, 1.0]);
        let c = max_abs_correlations(&t, &e);
        assert!((c[0] - 1.0).abs() < 1e-15 && c[1] < 0.5);
    }
}
