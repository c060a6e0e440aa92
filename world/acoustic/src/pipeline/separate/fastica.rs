//! FastICA (Hyvärinen & Oja 1997, the paper's reference [6]; the paper's
//! Section VI-A runs it for its separation step) written on `nalgebra`:
//! whitening by PCA, then fixed-point iterations on the whitened data,
//! either for all components at once with symmetric decorrelation
//! ("parallel" in scikit-learn's words) or one component at a time with
//! Gram–Schmidt deflation.
//!
//! The defaults are scikit-learn's (`fun="logcosh"`, `alpha=1`,
//! `tol=1e-4`, `max_iter=200`, parallel algorithm, unit-variance
//! whitening), so the two can be compared on the same mixtures
//! (`examples/acoustic_fastica_compare.rs`).
//!
//! Running out of iterations is an error ([`FastIcaError::NotConverged`]),
//! not a warning: the caller decides whether the last iterate (carried in
//! the error) is good enough.

use super::whitening::{whiten, Components, Whitening};
use nalgebra::{DMatrix, SymmetricEigen};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::fmt;

/// How the components are estimated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Algorithm {
    /// All components at once, re-orthogonalised after every step by
    /// W ← (W Wᵀ)^{-1/2} W. Errors do not accumulate from one component to
    /// the next; scikit-learn's default.
    Symmetric,
    /// One component after another, each kept orthogonal to the ones
    /// found before (Gram–Schmidt). Cheaper per step when only a few
    /// components are wanted; later components inherit earlier errors.
    Deflation,
}

impl fmt::Display for Algorithm {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Algorithm::Symmetric => "symmetric",
            Algorithm::Deflation => "deflation",
        })
    }
}

/// The contrast function G, given by its derivative g and g'.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Nonlinearity {
    /// G(u) = log cosh(αu)/α, g(u) = tanh(αu): a good general-purpose
    /// choice, robust to outliers (α in [1, 2]).
    LogCosh { alpha: f64 },
    /// G(u) = −exp(−u²/2), g(u) = u exp(−u²/2): better for very
    /// super-Gaussian sources or when robustness matters most.
    Exp,
    /// G(u) = u⁴/4, g(u) = u³: kurtosis; fast but sensitive to outliers.
    Cube,
}

impl Nonlinearity {
    /// Writes g(u) into `g` and returns the sum of g'(u) over `u`.
    #[inline(always)]
    fn apply(&self, u: &[f64], g: &mut [f64]) -> f64 {
        let mut sum_dg = 0.0;
        match *self {
            Nonlinearity::LogCosh { alpha } => {
                for (gi, &ui) in g.iter_mut().zip(u) {
                    let t = fast_tanh(alpha * ui);
                    *gi = t;
                    sum_dg += alpha * (1.0 - t * t);
                }
            }
            Nonlinearity::Exp => {
                for (gi, &ui) in g.iter_mut().zip(u) {
                    let u2 = ui * ui;
                    let e = (-0.5 * u2).exp();
                    *gi = ui * e;
                    sum_dg += (1.0 - u2) * e;
                }
            }
            Nonlinearity::Cube => {
                for (gi, &ui) in g.iter_mut().zip(u) {
                    let u2 = ui * ui;
                    *gi = u2 * ui;
                    sum_dg += 3.0 * u2;
                }
            }
        }
        sum_dg
    }
}

/// e^x for x ≤ 0, branch-free so that loops over slices vectorise:
/// Cody–Waite reduction x = k·ln 2 + r, |r| ≤ ln 2 / 2, a degree-12
/// Taylor polynomial for e^r (truncation < 2·10⁻¹⁶), and 2^k built in the
/// exponent bits. Inputs below −700 are clamped (the result underflows to
/// ~0 anyway).
#[inline(always)]
fn exp_nonpositive(x: f64) -> f64 {
    const LOG2E: f64 = std::f64::consts::LOG2_E;
    const LN2_HI: f64 = 6.931_471_803_691_238e-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_7e-10;
    // 1.5·2^52: adding it rounds to an integer held in the low mantissa bits.
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    let x = x.max(-700.0);
    let y = x * LOG2E + MAGIC;
    let k = y - MAGIC;
    let ki = (y.to_bits() as i64).wrapping_sub(MAGIC.to_bits() as i64);
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let mut p = 1.0 / 479_001_600.0;
    for c in [
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        0.5,
        1.0,
        1.0,
    ] {
        p = p * r + c;
    }
    p * f64::from_bits(((ki + 1023) as u64) << 52)
}

/// tanh(x) = sign(x)·(1 − e)/(1 + e) with e = e^{−2|x|}: one branch-free
/// exponential, accurate to a few 10⁻¹⁶ absolute. The nonlinearity is
/// evaluated n·T times per iteration — the hot loop of the separation step
/// — and `f64::tanh` (a libm call) keeps it from vectorising.
#[inline(always)]
fn fast_tanh(x: f64) -> f64 {
    let e = exp_nonpositive(-2.0 * x.abs());
    ((1.0 - e) / (1.0 + e)).copysign(x)
}

/// A dot product with four accumulators, which the compiler can keep in
/// SIMD registers (a single running sum cannot be reordered, so it would
/// not vectorise).
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..4 {
            acc[i] += x[i] * y[i];
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (x, y) in ra.iter().zip(rb) {
        s += x * y;
    }
    s
}

/// Samples processed per block: the block's rows of Z, W·Z and g(W·Z)
/// stay in cache while every row of W⁺ is accumulated from them.
const BLOCK: usize = 512;

/// The buffers of one symmetric iteration over blocks of samples.
struct SymScratch {
    n: usize,
    t: usize,
    block: usize,
    /// W, row-major n × n.
    w: Vec<f64>,
    /// W·Z and g(W·Z) for one block, n rows of `block`.
    u: Vec<f64>,
    g: Vec<f64>,
    /// Σ g'(w_i·z) and Σ g(W·Z)·Zᵀ over all samples.
    sum_dg: Vec<f64>,
    gz: Vec<f64>,
}

/// One pass over all samples: accumulates `sum_dg` and `gz` for the
/// current `w`. `rows` is Z row-major (n × T).
#[inline(always)]
fn sym_pass_generic(nl: Nonlinearity, rows: &[f64], s: &mut SymScratch) {
    let (n, t, block) = (s.n, s.t, s.block);
    s.sum_dg.iter_mut().for_each(|x| *x = 0.0);
    s.gz.iter_mut().for_each(|x| *x = 0.0);
    let mut start = 0;
    while start < t {
        let b = block.min(t - start);
        for i in 0..n {
            let ui = &mut s.u[i * block..i * block + b];
            ui.iter_mut().for_each(|x| *x = 0.0);
            for j in 0..n {
                let wij = s.w[i * n + j];
                for (x, zj) in ui.iter_mut().zip(&rows[j * t + start..j * t + start + b]) {
                    *x += wij * zj;
                }
            }
            s.sum_dg[i] += nl.apply(ui, &mut s.g[i * block..i * block + b]);
        }
        for i in 0..n {
            let gi = &s.g[i * block..i * block + b];
            for j in 0..n {
                s.gz[i * n + j] += dot(gi, &rows[j * t + start..j * t + start + b]);
            }
        }
        start += b;
    }
}

/// g over a column-major n × T matrix `u` (whole buffer, so the loop
/// vectorises), adding Σ g' per row into `dg`.
#[inline(always)]
fn apply_columns_generic(nl: Nonlinearity, n: usize, u: &[f64], g: &mut [f64], dg: &mut [f64]) {
    for (uc, gc) in u.chunks_exact(n).zip(g.chunks_exact_mut(n)) {
        for i in 0..n {
            dg[i] += nl.apply(&uc[i..i + 1], &mut gc[i..i + 1]);
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn apply_columns_avx2(nl: Nonlinearity, n: usize, u: &[f64], g: &mut [f64], dg: &mut [f64]) {
    apply_columns_generic(nl, n, u, g, dg)
}

fn apply_columns(nl: Nonlinearity, n: usize, u: &[f64], g: &mut [f64], dg: &mut [f64]) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU has the features (checked above).
            unsafe { apply_columns_avx2(nl, n, u, g, dg) };
            return;
        }
    }
    apply_columns_generic(nl, n, u, g, dg)
}

/// From this many components on, the symmetric iteration uses blocked
/// matrix products (`matrixmultiply`'s dgemm) instead of the fused loops,
/// which win only while W is tiny.
const GEMM_FROM: usize = 8;

/// The same pass compiled for AVX2 + FMA (4 doubles per instruction
/// instead of SSE2's 2), chosen at run time when the CPU has them.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn sym_pass_avx2(nl: Nonlinearity, rows: &[f64], s: &mut SymScratch) {
    sym_pass_generic(nl, rows, s)
}

fn sym_pass(nl: Nonlinearity, rows: &[f64], s: &mut SymScratch) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
        {
            // SAFETY: the CPU supports the features the function is
            // compiled for (checked just above); it is otherwise plain
            // safe Rust.
            unsafe { sym_pass_avx2(nl, rows, s) };
            return;
        }
    }
    sym_pass_generic(nl, rows, s)
}

/// Settings of one FastICA run. [`Default`] is scikit-learn's.
#[derive(Debug, Clone, PartialEq)]
pub struct FastIcaConfig {
    pub algorithm: Algorithm,
    pub nonlinearity: Nonlinearity,
    /// Stop when every unmixing vector changed by less than this
    /// (1 − |⟨w_new, w_old⟩|, the measure scikit-learn uses).
    pub tol: f64,
    /// Iteration cap (per component for deflation).
    pub max_iter: usize,
    /// How many whitened components to keep.
    pub components: Components,
    /// Seed of the random initial unmixing matrix.
    pub seed: u64,
}

impl Default for FastIcaConfig {
    fn default() -> Self {
        FastIcaConfig {
            algorithm: Algorithm::Symmetric,
            nonlinearity: Nonlinearity::LogCosh { alpha: 1.0 },
            tol: 1e-4,
            max_iter: 200,
            components: Components::All,
            seed: 0,
        }
    }
}

impl FastIcaConfig {
    /// Checks the settings; names the bad one.
    pub fn validate(&self) -> Result<(), FastIcaError> {
        if !(self.tol.is_finite() && self.tol > 0.0) {
            return Err(FastIcaError::InvalidConfig(format!(
                "tol must be finite and > 0, got {}",
                self.tol
            )));
        }
        if self.max_iter == 0 {
            return Err(FastIcaError::InvalidConfig("max_iter must be ≥ 1".into()));
        }
        if let Nonlinearity::LogCosh { alpha } = self.nonlinearity {
            if !(alpha.is_finite() && (1.0..=2.0).contains(&alpha)) {
                return Err(FastIcaError::InvalidConfig(format!(
                    "logcosh alpha must be in [1, 2], got {alpha}"
                )));
            }
        }
        self.components.validate()
    }
}

/// A separation: the estimated sources and the matrices that relate them
/// to the observations.
#[derive(Debug, Clone, PartialEq)]
pub struct IcaResult {
    /// Estimated sources, one per row (n × T), unit variance, zero mean.
    pub sources: DMatrix<f64>,
    /// Full unmixing matrix (n × m): `sources = unmixing · (X − mean)`.
    pub unmixing: DMatrix<f64>,
    /// Estimated mixing matrix (m × n): `X − mean ≈ mixing · sources`.
    pub mixing: DMatrix<f64>,
    /// The whitening step (mean, eigenvalues, kept components).
    pub whitening: Whitening,
    /// Fixed-point iterations made (the largest over components for
    /// deflation).
    pub iterations: usize,
}

/// What can go wrong in a separation.
#[derive(Debug, thiserror::Error)]
pub enum FastIcaError {
    #[error("FastICA input is {rows} channels × {cols} samples: need ≥ 1 channel and ≥ 2 samples")]
    Empty { rows: usize, cols: usize },
    #[error("FastICA input has the non-finite value {value} at channel {row}, sample {col}")]
    NonFinite { row: usize, col: usize, value: f64 },
    #[error("FastICA asked for {requested} components but the {channels}-channel data has only {rank} above the numerical floor")]
    RankDeficient {
        requested: usize,
        rank: usize,
        channels: usize,
    },
    #[error("FastICA found no component above the noise floor in {channels} channels")]
    NoComponents { channels: usize },
    #[error("invalid FastICA setting: {0}")]
    InvalidConfig(String),
    #[error("FastICA ({algorithm}) did not converge{}: change {change:.3e} still above tol {tol:.1e} after {iterations} iterations", match component { Some(c) => format!(" on component {c}"), None => String::new() })]
    NotConverged {
        algorithm: Algorithm,
        /// The deflation component that failed (`None` for symmetric).
        component: Option<usize>,
        iterations: usize,
        change: f64,
        tol: f64,
        /// The last iterate, for a caller that accepts it anyway.
        partial: Box<IcaResult>,
    },
}

/// FastICA with a fixed configuration.
#[derive(Debug, Clone, Default)]
pub struct FastIca {
    pub config: FastIcaConfig,
}

impl FastIca {
    pub fn new(config: FastIcaConfig) -> Self {
        FastIca { config }
    }

    /// Separates `x` (m channels × T samples, one observation per row).
    pub fn fit(&self, x: &DMatrix<f64>) -> Result<IcaResult, FastIcaError> {
        self.config.validate()?;
        let (whitening, z) = whiten(x, &self.config.components)?;
        self.fit_whitened(whitening, z)
    }

    /// Separates data already whitened by [`whiten`]: `z` is n × T with
    /// identity covariance. Lets a caller look at the eigenvalues (and skip
    /// silent data) before paying for the iterations.
    pub(crate) fn fit_whitened(
        &self,
        whitening: Whitening,
        z: DMatrix<f64>,
    ) -> Result<IcaResult, FastIcaError> {
        let n = z.nrows();
        if n == 0 {
            return Err(FastIcaError::NoComponents {
                channels: whitening.mean.len(),
            });
        }
        let mut rng = ChaCha8Rng::seed_from_u64(self.config.seed);
        let w0 = DMatrix::from_fn(n, n, |_, _| standard_normal(&mut rng));
        let outcome = match self.config.algorithm {
            Algorithm::Symmetric => self.symmetric(&z, w0),
            Algorithm::Deflation => self.deflation(&z, w0),
        };
        let finish = |w: DMatrix<f64>, iterations: usize| {
            let sources = &w * &z;
            let unmixing = &w * &whitening.whitener;
            // W is orthogonal, so the dewhitener times Wᵀ inverts it.
            let mixing = &whitening.dewhitener * w.transpose();
            IcaResult {
                sources,
                unmixing,
                mixing,
                whitening: whitening.clone(),
                iterations,
            }
        };
        match outcome {
            Ok((w, iterations)) => Ok(finish(w, iterations)),
            Err(stall) => Err(FastIcaError::NotConverged {
                algorithm: self.config.algorithm,
                component: stall.component,
                iterations: stall.iterations,
                change: stall.change,
                tol: self.config.tol,
                partial: Box::new(finish(stall.w, stall.iterations)),
            }),
        }
    }

    /// Symmetric (parallel) FastICA: W⁺ = E{g(WZ) Zᵀ} − diag(E{g'(WZ)}) W,
    /// then W ← (W⁺ W⁺ᵀ)^{-1/2} W⁺.
    fn symmetric(
        &self,
        z: &DMatrix<f64>,
        w0: DMatrix<f64>,
    ) -> Result<(DMatrix<f64>, usize), Stall> {
        let (n, t) = z.shape();
        let nl = self.config.nonlinearity;
        // nalgebra is column-major: the transpose's columns are the rows of
        // Z, so each whitened channel is one contiguous slice. The loop
        // below works on such slices with no allocation per iteration — at
        // the pipeline's sizes (n ≈ 1–6, T = 100) the overhead of general
        // matrix products would dominate.
        let zt = z.transpose();
        let rows = zt.as_slice();
        let inv_t = 1.0 / t as f64;
        if n >= GEMM_FROM {
            return self.symmetric_gemm(z, &zt, w0);
        }
        let mut w = sym_decorrelate(&w0);
        let mut w1 = DMatrix::<f64>::zeros(n, n);
        let block = BLOCK.min(t);
        let mut scratch = SymScratch {
            n,
            t,
            block,
            w: vec![0.0; n * n],
            u: vec![0.0; n * block],
            g: vec![0.0; n * block],
            sum_dg: vec![0.0; n],
            gz: vec![0.0; n * n],
        };
        let mut change = f64::INFINITY;
        for it in 1..=self.config.max_iter {
            for i in 0..n {
                for j in 0..n {
                    scratch.w[i * n + j] = w[(i, j)];
                }
            }
            sym_pass(nl, rows, &mut scratch);
            for i in 0..n {
                for j in 0..n {
                    w1[(i, j)] =
                        scratch.gz[i * n + j] * inv_t - scratch.sum_dg[i] * inv_t * w[(i, j)];
                }
            }
            let next = sym_decorrelate(&w1);
            // max_i | |⟨w⁺_i, w_i⟩| − 1 |
            change = (0..n)
                .map(|i| {
                    let d: f64 = (0..n).map(|j| next[(i, j)] * w[(i, j)]).sum();
                    (d.abs() - 1.0).abs()
                })
                .fold(0.0, f64::max);
            w = next;
            if change < self.config.tol {
                return Ok((w, it));
            }
        }
        Err(Stall {
            w,
            iterations: self.config.max_iter,
            change,
            component: None,
        })
    }

    /// The symmetric iteration with whole-matrix products, for larger n.
    fn symmetric_gemm(
        &self,
        z: &DMatrix<f64>,
        zt: &DMatrix<f64>,
        w0: DMatrix<f64>,
    ) -> Result<(DMatrix<f64>, usize), Stall> {
        let (n, t) = z.shape();
        let nl = self.config.nonlinearity;
        let inv_t = 1.0 / t as f64;
        let mut w = sym_decorrelate(&w0);
        let mut wz = DMatrix::<f64>::zeros(n, t);
        let mut g = DMatrix::<f64>::zeros(n, t);
        let mut gzt = DMatrix::<f64>::zeros(n, n);
        let mut dg = vec![0.0; n];
        let mut change = f64::INFINITY;
        for it in 1..=self.config.max_iter {
            w.mul_to(z, &mut wz);
            dg.iter_mut().for_each(|x| *x = 0.0);
            apply_columns(nl, n, wz.as_slice(), g.as_mut_slice(), &mut dg);
            g.mul_to(zt, &mut gzt);
            let w1 = DMatrix::from_fn(n, n, |i, j| gzt[(i, j)] * inv_t - dg[i] * inv_t * w[(i, j)]);
            let next = sym_decorrelate(&w1);
            change = (0..n)
                .map(|i| {
                    let d: f64 = (0..n).map(|j| next[(i, j)] * w[(i, j)]).sum();
                    (d.abs() - 1.0).abs()
                })
                .fold(0.0, f64::max);
            w = next;
            if change < self.config.tol {
                return Ok((w, it));
            }
        }
        Err(Stall {
            w,
            iterations: self.config.max_iter,
            change,
            component: None,
        })
    }

    /// Deflation FastICA: w⁺ = E{z g(wᵀz)} − E{g'(wᵀz)} w, orthogonalised
    /// against the components already found, normalised.
    fn deflation(
        &self,
        z: &DMatrix<f64>,
        w0: DMatrix<f64>,
    ) -> Result<(DMatrix<f64>, usize), Stall> {
        let (n, t) = z.shape();
        let nl = self.config.nonlinearity;
        let zt = z.transpose();
        let rows = zt.as_slice();
        let row = |j: usize| &rows[j * t..(j + 1) * t];
        let inv_t = 1.0 / t as f64;
        let mut w = DMatrix::<f64>::zeros(n, n);
        let mut u = vec![0.0; t];
        let mut gu = vec![0.0; t];
        let mut max_iters = 0;
        for p in 0..n {
            let mut wp: Vec<f64> = w0.row(p).iter().copied().collect();
            gram_schmidt(&mut wp, &w, p);
            normalize(&mut wp);
            let mut converged = false;
            let mut change = f64::INFINITY;
            let mut it = 0;
            let mut w1 = vec![0.0; n];
            while it < self.config.max_iter {
                it += 1;
                u.iter_mut().for_each(|x| *x = 0.0);
                for (j, &wj) in wp.iter().enumerate() {
                    for (x, zj) in u.iter_mut().zip(row(j)) {
                        *x += wj * zj;
                    }
                }
                let mean_dg = nl.apply(&u, &mut gu) * inv_t;
                for (j, w1j) in w1.iter_mut().enumerate() {
                    *w1j = dot(&gu, row(j)) * inv_t - mean_dg * wp[j];
                }
                gram_schmidt(&mut w1, &w, p);
                normalize(&mut w1);
                let d: f64 = w1.iter().zip(&wp).map(|(a, b)| a * b).sum();
                change = (d.abs() - 1.0).abs();
                wp.copy_from_slice(&w1);
                if change < self.config.tol {
                    converged = true;
                    break;
                }
            }
            for i in 0..n {
                w[(p, i)] = wp[i];
            }
            max_iters = max_iters.max(it);
            if !converged {
                return Err(Stall {
                    w,
                    iterations: it,
                    change,
                    component: Some(p),
                });
            }
        }
        Ok((w, max_iters))
    }
}

/// The state at which the iterations were given up.
struct Stall {
    w: DMatrix<f64>,
    iterations: usize,
    change: f64,
    component: Option<usize>,
}

/// W ← (W Wᵀ)^{-1/2} W, the symmetric orthogonalisation that treats every
/// row alike.
fn sym_decorrelate(w: &DMatrix<f64>) -> DMatrix<f64> {
    let wwt = w * w.transpose();
    let eig = SymmetricEigen::new(wwt);
    let n = w.nrows();
    let mut scaled = eig.eigenvectors.clone();
    for j in 0..n {
        // A (numerically) singular W W^T can only come from a degenerate
        // start; the floor keeps the step finite and the next iteration
        // repairs it.
        let s = 1.0 / eig.eigenvalues[j].max(1e-300).sqrt();
        for i in 0..n {
            scaled[(i, j)] *= s;
        }
    }
    scaled * eig.eigenvectors.transpose() * w
}

fn gram_schmidt(w: &mut [f64], basis: &DMatrix<f64>, rows: usize) {
    for r in 0..rows {
        let d: f64 = (0..w.len()).map(|i| w[i] * basis[(r, i)]).sum();
        for (i, wi) in w.iter_mut().enumerate() {
            *wi -= d * basis[(r, i)];
        }
    }
}

fn normalize(w: &mut [f64]) {
    let norm = w.iter().map(|v| v * v).sum::<f64>().sqrt();
    if norm > 0.0 {
        w.iter_mut().for_each(|v| *v /= norm);
    }
}

/// A standard normal draw (Box–Muller), so that initial matrices do not
/// depend on `rand_distr`.
pub(crate) fn standard_normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = 1.0 - rng.gen::<f64>(); // (0, 1]
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::separation::{amari_index, max_abs_correlations};

    /// Four independent, non-Gaussian sources of different kinds.
    fn sources(t: usize, seed: u64) -> DMatrix<f64> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        DMatrix::from_fn(4, t, |i, k| {
            let x = k as f64;
            match i {
                0 => (x * 0.05).sin(),
                1 => {
                    if (x * 0.013).sin() > 0.0 {
                        1.0
                    } else {
                        -1.0
                    }
                }
                2 => {
                    // Laplace.
                    let u: f64 = rng.gen::<f64>() - 0.5;
                    -u.signum() * (1.0 - 2.0 * u.abs()).max(1e-300).ln()
                }
                _ => rng.gen::<f64>() * 2.0 - 1.0,
            }
        })
    }

    fn mixture(m: usize, s: &DMatrix<f64>, seed: u64) -> (DMatrix<f64>, DMatrix<f64>) {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let a = DMatrix::from_fn(m, s.nrows(), |_, _| rng.gen::<f64>() * 2.0 - 1.0);
        (&a * s, a)
    }

    fn check(config: FastIcaConfig, m: usize) {
        let s = sources(2000, 1);
        let (x, a) = mixture(m, &s, 2);
        let result = FastIca::new(config.clone()).fit(&x).unwrap();
        assert_eq!(result.sources.nrows(), 4);
        let corr = max_abs_correlations(&s, &result.sources);
        assert!(corr.iter().all(|&c| c > 0.95), "{config:?}: {corr:?}");
        let p = &result.unmixing * &a;
        let amari = amari_index(&p);
        assert!(amari < 0.05, "{config:?}: amari {amari}");
        // Unit-variance, zero-mean outputs; the mixing matrix reproduces X.
        for row in result.sources.row_iter() {
            let mean = row.mean();
            let var = row.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / row.len() as f64;
            assert!(
                mean.abs() < 1e-9 && (var - 1.0).abs() < 1e-6,
                "{mean} {var}"
            );
        }
        let centred = DMatrix::from_fn(x.nrows(), x.ncols(), |i, k| {
            x[(i, k)] - result.whitening.mean[i]
        });
        let back = &result.mixing * &result.sources;
        assert!((back - centred).abs().max() < 1e-8);
    }

    #[test]
    fn symmetric_recovers_four_sources() {
        check(FastIcaConfig::default(), 4);
    }

    #[test]
    fn deflation_recovers_four_sources() {
        check(
            FastIcaConfig {
                algorithm: Algorithm::Deflation,
                ..FastIcaConfig::default()
            },
            4,
        );
    }

    #[test]
    fn every_nonlinearity_works_with_more_sensors_than_sources() {
        for nonlinearity in [
            Nonlinearity::LogCosh { alpha: 1.5 },
            Nonlinearity::Exp,
            Nonlinearity::Cube,
        ] {
            for algorithm in [Algorithm::Symmetric, Algorithm::Deflation] {
                check(
                    FastIcaConfig {
                        algorithm,
                        nonlinearity,
                        components: Components::Fixed(4),
                        seed: 7,
                        ..FastIcaConfig::default()
                    },
                    7,
                );
            }
        }
    }

    #[test]
    fn iteration_cap_is_an_error_with_the_last_iterate() {
        let s = sources(500, 3);
        let (x, _) = mixture(4, &s, 4);
        for algorithm in [Algorithm::Symmetric, Algorithm::Deflation] {
            let ica = FastIca::new(FastIcaConfig {
                algorithm,
                max_iter: 1,
                tol: 1e-14,
                ..FastIcaConfig::default()
            });
            match ica.fit(&x) {
                Err(FastIcaError::NotConverged {
                    iterations,
                    change,
                    partial,
                    component,
                    ..
                }) => {
                    assert_eq!(iterations, 1);
                    assert!(change > 1e-14);
                    assert_eq!(partial.sources.shape(), (4, 500));
                    assert_eq!(component.is_some(), algorithm == Algorithm::Deflation);
                }
                other => panic!("{algorithm}: expected NotConverged, got {other:?}"),
            }
        }
    }

    #[test]
    fn bad_input_is_named() {
        let ica = FastIca::default();
        let empty = DMatrix::<f64>::zeros(3, 1);
        assert!(matches!(
            ica.fit(&empty),
            Err(FastIcaError::Empty { rows: 3, cols: 1 })
        ));
        let mut x = DMatrix::from_fn(2, 10, |i, k| (i + k) as f64);
        x[(1, 4)] = f64::NAN;
        let err = ica.fit(&x).unwrap_err();
        assert!(err.to_string().contains("channel 1, sample 4"), "{err}");
        let bad = FastIca::new(FastIcaConfig {
            tol: 0.0,
            ..FastIcaConfig::default()
        });
        assert!(bad.fit(&x).unwrap_err().to_string().contains("tol"));
        // Two identical channels have rank 1.
        let s = sources(200, 5);
        let x = DMatrix::from_fn(2, 200, |_, k| s[(0, k)]);
        let fixed = FastIca::new(FastIcaConfig {
            components: Components::Fixed(2),
            ..FastIcaConfig::default()
        });
        assert!(matches!(
            fixed.fit(&x),
            Err(FastIcaError::RankDeficient { rank: 1, .. })
        ));
    }

    #[test]
    fn same_seed_same_result() {
        let s = sources(300, 8);
        let (x, _) = mixture(4, &s, 9);
        let a = FastIca::default().fit(&x).unwrap();
        let b = FastIca::default().fit(&x).unwrap();
        assert_eq!(a, b);
    }

    #[test]
    fn fast_tanh_and_exp_match_std() {
        let mut x = -25.0;
        while x < 25.0 {
            assert!((fast_tanh(x) - x.tanh()).abs() < 4e-16, "{x}");
            x += 0.001_3;
        }
        assert_eq!(fast_tanh(0.0), 0.0);
        assert_eq!(fast_tanh(1e9), 1.0);
        assert_eq!(fast_tanh(-1e9), -1.0);
        // Absolute, not relative, accuracy near 0 (1 − e cancels): ample for g.
        assert!((fast_tanh(1e-10) - 1e-10).abs() < 2e-16);
        let mut x = -700.0;
        while x <= 0.0 {
            let (a, b) = (exp_nonpositive(x), x.exp());
            assert!((a - b).abs() <= 4e-16 * b, "{x}: {a} vs {b}");
            x += 0.37;
        }
        let a: Vec<f64> = (0..103).map(|i| i as f64 * 0.5).collect();
        let b: Vec<f64> = (0..103).map(|i| 1.0 - i as f64).collect();
        let naive: f64 = a.iter().zip(&b).map(|(x, y)| x * y).sum();
        assert!((dot(&a, &b) - naive).abs() < 1e-9);
    }
}
