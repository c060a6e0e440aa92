//! PCA whitening, the first half of FastICA: centre every channel, rotate
//! onto the eigenvectors of the channel covariance and scale each kept
//! direction to unit variance. Choosing how many directions to keep is
//! also where the separation step drops what is only sensor noise (see
//! [`Components::AboveFloor`]).

use super::fastica::FastIcaError;
use nalgebra::{DMatrix, DVector, SymmetricEigen};

/// How many whitened directions to keep.
#[derive(Debug, Clone, PartialEq)]
pub enum Components {
    /// Every direction with non-negligible variance (scikit-learn keeps
    /// all; directions below 1e-12 of the largest variance would only
    /// amplify rounding errors and are dropped).
    All,
    /// Exactly this many; an error if the data has a lower rank.
    Fixed(usize),
    /// Directions whose variance exceeds `floor` (absolute), at most `max`.
    /// With `floor` a few times the sensor noise variance this keeps one
    /// direction per source the group really hears, which is what makes
    /// thousands of separations per second possible (Section IV-B does not
    /// say how many components its FastICA kept; the noise directions it
    /// would have produced are removed by clustering and selection anyway).
    AboveFloor { floor: f64, max: usize },
}

impl Components {
    pub fn validate(&self) -> Result<(), FastIcaError> {
        match *self {
            Components::All => Ok(()),
            Components::Fixed(0) => Err(FastIcaError::InvalidConfig(
                "a fixed number of components must be ≥ 1".into(),
            )),
            Components::Fixed(_) => Ok(()),
            Components::AboveFloor { floor, max } => {
                if !(floor.is_finite() && floor >= 0.0) || max == 0 {
                    Err(FastIcaError::InvalidConfig(format!(
                        "components above floor {floor} (max {max}): need a finite floor ≥ 0 and max ≥ 1"
                    )))
                } else {
                    Ok(())
                }
            }
        }
    }
}

/// The whitening of one data matrix.
#[derive(Debug, Clone, PartialEq)]
pub struct Whitening {
    /// Channel means removed first (m).
    pub mean: DVector<f64>,
    /// Covariance eigenvalues, all m of them, largest first.
    pub eigenvalues: Vec<f64>,
    /// n × m: whitened = whitener · (X − mean).
    pub whitener: DMatrix<f64>,
    /// m × n: (X − mean) ≈ dewhitener · whitened (exact if n = rank).
    pub dewhitener: DMatrix<f64>,
}

impl Whitening {
    /// Number of kept directions (n).
    pub(crate) fn components(&self) -> usize {
        self.whitener.nrows()
    }
}

/// Checks `x` (m × T) and returns its whitening and the whitened data
/// (n × T, identity covariance with the 1/T convention).
pub(crate) fn whiten(
    x: &DMatrix<f64>,
    components: &Components,
) -> Result<(Whitening, DMatrix<f64>), FastIcaError> {
    let (m, t) = x.shape();
    if m == 0 || t < 2 {
        return Err(FastIcaError::Empty { rows: m, cols: t });
    }
    // Column-major: walk columns for speed, report (row, col).
    for (k, col) in x.column_iter().enumerate() {
        for (i, &v) in col.iter().enumerate() {
            if !v.is_finite() {
                return Err(FastIcaError::NonFinite {
                    row: i,
                    col: k,
                    value: v,
                });
            }
        }
    }
    let mean = x.column_mean();
    let mut xc = x.clone();
    for mut col in xc.column_iter_mut() {
        col -= &mean;
    }
    let cov = (&xc * xc.transpose()) / t as f64;
    let eig = SymmetricEigen::new(cov);
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let eigenvalues: Vec<f64> = order.iter().map(|&i| eig.eigenvalues[i]).collect();
    let top = eigenvalues[0].max(0.0);
    let numerical_floor = top * 1e-12;
    let rank = eigenvalues
        .iter()
        .filter(|&&l| l > numerical_floor && l > 0.0)
        .count();
    let n = match *components {
        Components::All => rank,
        Components::Fixed(n) => {
            if n > rank {
                return Err(FastIcaError::RankDeficient {
                    requested: n,
                    rank,
                    channels: m,
                });
            }
            n
        }
        Components::AboveFloor { floor, max } => eigenvalues
            .iter()
            .take(rank.min(max))
            .filter(|&&l| l > floor)
            .count(),
    };
    let mut whitener = DMatrix::<f64>::zeros(n, m);
    let mut dewhitener = DMatrix::<f64>::zeros(m, n);
    for (r, &i) in order.iter().take(n).enumerate() {
        let s = eig.eigenvalues[i].sqrt();
        for c in 0..m {
            let e = eig.eigenvectors[(c, i)];
            whitener[(r, c)] = e / s;
            dewhitener[(c, r)] = e * s;
        }
    }
    let z = &whitener * &xc;
    Ok((
        Whitening {
            mean,
            eigenvalues,
            whitener,
            dewhitener,
        },
        z,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn whitened_data_has_identity_covariance() {
        let x = DMatrix::from_fn(3, 400, |i, k| {
            let t = k as f64;
            match i {
                0 => (t * 0.1).sin() + 2.0,
                1 => (t * 0.1).sin() * 0.5 + (t * 0.37).cos(),
                _ => (t * 0.37).cos() - 1.0,
            }
        });
        let (w, z) = whiten(&x, &Components::All).unwrap();
        assert_eq!(w.components(), 2, "rank 2: {:?}", w.eigenvalues);
        let cov = (&z * z.transpose()) / 400.0;
        assert!((cov - DMatrix::identity(2, 2)).abs().max() < 1e-9);
        assert!(w.eigenvalues.windows(2).all(|p| p[0] >= p[1]));
        let (w, _) = whiten(&x, &Components::AboveFloor { floor: 0.9, max: 3 }).unwrap();
        assert_eq!(w.components(), 1, "{:?}", w.eigenvalues);
        let (w, _) = whiten(&x, &Components::AboveFloor { floor: 1e6, max: 3 }).unwrap();
        assert_eq!(w.components(), 0);
    }
}
