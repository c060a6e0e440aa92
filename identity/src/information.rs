//! The information matrix of Shin et al., *Lazy Inference on Object
//! Identities in Wireless Sensor Networks* (IPSN 2005), Section 3: keep
//! accumulated log-likelihoods L (N × N, row t = track t, the paper's column
//! t) with p(π) ∝ exp(Σ_t L\[t\]\[π(t)\]), and normalize only when a query
//! asks for marginals ([`crate::marginals`]).
//!
//! ## Evidence (Section 3.2): O(1), no normalization — the lazy part
//! A read of identity i on track t with accuracy a multiplies p(π) by a if
//! π(t) = i and by w = (1 − a)/(N − 1) otherwise. By Property 1 (adding a
//! constant to a row changes nothing) it is enough to add ln a − ln w to
//! the one entry L\[t\]\[i\]. A perfect read (a = 1, so w = 0) would add
//! +∞; it is taken as what it says instead, exactly: every other identity
//! is ruled out on the row (−∞, the form an exact known start takes, see
//! [`crate::support_mix`]). A perfect read of an identity the
//! row already rules out is refused ([`BeliefError::ImpossibleObservation`]):
//! the mixing rule keeps every pairing the exact belief allows, so no
//! assignment of positive probability is left.
//!
//! ## Mixing (Section 3.3)
//! Exact mixing gives q(π) = (1 − s)·p(π) + s·p(π∘(a b)). Fix the identity
//! on every track but a and b; then q depends on the pair (m, n) of
//! identities on (a, b) through
//!
//!   G(m, n) = ln((1 − s)·A_m·B_n + s·A_n·B_m),  A = exp L\[a\], B = exp L\[b\],
//!
//! and an information matrix changing only rows a, b into x, y represents
//! it exactly iff x_m + y_n = G(m, n) + const for all m ≠ n. That system is
//! overdetermined; we take its least-squares solution:
//!
//!   minimize Σ_{m≠n} (x_m + y_n − G(m, n))².
//!
//! **The paper's rule is the case s = ½.** The paper assumes α = ½, rows a
//! and b equal (x = y = β), and fits β_m + β_n ≈ γ_mn = ln((A_m B_n + A_n
//! B_m)/2) over unordered pairs: P·β = γ with P the C(N,2) × N matrix with
//! two ones per row, β = P†γ, "O(N⁴)". With s = ½, G is symmetric, the
//! two-row problem is symmetric in (x, y), and its minimum-norm solution has
//! x = y; restricted to x = y the objective is twice the paper's, so the
//! two coincide (tested to 1e-9). For s ≠ ½ the rows must differ (s = 0 is
//! no mix at all), which is why we fit them separately: this generalization
//! is ours, the paper only states α = ½.
//!
//! ### Closed form of the paper's rule, O(N²)
//! (PᵀP)_mm = N − 1 (pairs holding m), (PᵀP)_mn = 1 (the pair {m, n}), so
//! PᵀP = (N − 2)I + 11ᵀ. By Sherman–Morrison, for N ≥ 3,
//! (PᵀP)⁻¹ = (I − 11ᵀ/(2N − 2))/(N − 2). With r = Pᵀγ (r_m = Σ_{n≠m} γ_mn)
//! and 1ᵀr = 2Γ (Γ = Σ_{m<n} γ_mn):
//!
//!   β_m = (r_m − Γ/(N − 1)) / (N − 2).
//!
//! For N = 2, PᵀP = 11ᵀ is singular: one equation β_0 + β_1 = γ_01, whose
//! minimum-norm solution (what the SVD pseudoinverse returns) is
//! β_0 = β_1 = γ_01/2.
//!
//! ### Closed form of the two-row fit, O(N²)
//! With R_m = Σ_{n≠m} G(m, n), C_n = Σ_{m≠n} G(m, n), S = Σ_{m≠n} G(m, n),
//! the normal equations are (N − 1)x_m + Σy − y_m = R_m and
//! (N − 1)y_m + Σx − x_m = C_m. Summing gives (N − 1)(Σx + Σy) = S; adding
//! and subtracting the two equations of index m gives
//!
//!   x_m + y_m = (R_m + C_m − S/(N − 1)) / (N − 2),
//!   x_m − y_m = (R_m − C_m + Σx − Σy) / N.
//!
//! The solution is unique up to (x + c, y − c); the minimum-norm one (the
//! pseudoinverse's) has Σx = Σy. For N = 2 the two equations
//! x_0 + y_1 = G(0, 1), x_1 + y_0 = G(1, 0) have the minimum-norm solution
//! x_0 = y_1 = G(0,1)/2, x_1 = y_0 = G(1,0)/2. After fitting, each new row
//! is shifted to max 0 (Property 1) so that L stays bounded.
//!
//! ## When is it exact? (the paper's Theorem: "optimal for N ≤ 3")
//! What we can prove and what the tests check:
//! - N ≤ 2: always exact, for every swap probability: two equations
//!   x_0 + y_1 = G(0, 1), x_1 + y_0 = G(1, 0) in four unknowns.
//! - N = 3, s = ½: exact — the paper's case. For each identity k on the
//!   third track the pair on (a, b) is the complementary pair {m, n}, so the
//!   three equations x_m + x_n = γ_mn in three unknowns (the paper's
//!   d₁d₂ = (a₁b₂ + a₂b₁)/2, …) have an exact solution.
//! - N = 3, s ∉ {0, ½, 1}: **not exact**, and no information matrix can be:
//!   the functions π ↦ Σ_t L\[t\]\[π(t)\] span only the trivial and standard
//!   representations of S_3, so ln p of every information-matrix belief is
//!   orthogonal to the sign character: Σ_π sgn(π)·ln p(π) = 0. A mix with
//!   s ≠ ½ breaks that in general (tested with s = 0.2: marginals off by
//!   0.034 after one mix).
//! - N ≥ 4 (any s ∉ {0, 1}): an approximation (tested: 0.050 off after three
//!   mixes of a peaked 4 × 4 belief; on the paper's 6-object simulations
//!   about as accurate as the belief matrix or better, see the
//!   `paper_simulations` test).
//! - s ∈ {0, 1}: exact for every N (no change, or an exact swap of rows).
//!
//! These hold with *exact* marginals (the permanent) and for beliefs that
//! start in the family — uniform, or any finite L. A known initial
//! assignment is the limit of L\[t\]\[π₀(t)\] → ∞, which the least-squares
//! fit cannot take; [`InformationMatrix::from_assignment`] uses a finite
//! confidence instead.

use super::event::{check_assignment, check_identify, check_mix, check_square, Identify};
use super::filter::{to_rows, IdentityFilter, Marginals};
use super::marginals::{
    block_marginals, block_marginals_stoppable, information_marginals, BlockMarginals,
    MarginalMethod,
};
use super::sinkhorn::SinkhornOptions;
use super::support_mix::fit_on_support;
use idmesh_belief::BeliefError;
use idmesh_belief::Mix;
use nalgebra::{DMatrix, DVector};
use std::sync::atomic::AtomicBool;

/// How the mixing least-squares problem is solved.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum MixSolver {
    /// The O(N²) closed form (the default).
    #[default]
    ClosedForm,
    /// The SVD pseudoinverse of the design matrix, as the paper writes it:
    /// O(N⁴) and more; a reference.
    PseudoInverse,
}

/// Options of an information matrix.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct InformationOptions {
    pub solver: MixSolver,
    /// What [`IdentityFilter::marginals`] computes. The default, exact,
    /// works up to [`crate::permanent::MAX_PERMANENT_TRACKS`]
    /// tracks; beyond, choose Metropolis or a Bethe/Sinkhorn estimate.
    pub marginals: MarginalMethod,
    /// For [`MarginalMethod::Sinkhorn`].
    pub sinkhorn: SinkhornOptions,
}

/// Accumulated log-likelihoods L, N × N.
#[derive(Debug, Clone, PartialEq)]
pub struct InformationMatrix {
    n: usize,
    /// Row-major; row t = track t.
    l: Vec<f64>,
    options: InformationOptions,
}

impl InformationMatrix {
    /// L = 0: the uniform belief, as in the paper.
    #[cfg(test)]
    pub(crate) fn uniform(n: usize) -> Result<Self, BeliefError> {
        Self::uniform_with(n, InformationOptions::default())
    }

    /// [`InformationMatrix::uniform`] with options.
    pub fn uniform_with(n: usize, options: InformationOptions) -> Result<Self, BeliefError> {
        if n == 0 {
            return Err(BeliefError::NoTracks);
        }
        options.sinkhorn.validate()?;
        Ok(InformationMatrix {
            n,
            l: vec![0.0; n * n],
            options,
        })
    }

    /// A belief given by its (finite) log-likelihoods, `l[t][i]`.
    pub fn from_log_likelihoods(
        l: &[Vec<f64>],
        options: InformationOptions,
    ) -> Result<Self, BeliefError> {
        let n = check_square(l)?;
        if let Some(&bad) = l
            .iter()
            .flatten()
            .find(|x| x.is_nan() || **x == f64::INFINITY)
        {
            return Err(BeliefError::Numerical {
                step: "information matrix",
                detail: format!("entry {bad} is neither finite nor −∞"),
            });
        }
        options.sinkhorn.validate()?;
        Ok(InformationMatrix {
            n,
            l: l.iter().flatten().copied().collect(),
            options,
        })
    }

    /// Track t carries `assignment[t]` with log-odds `confidence` against
    /// each other single identity: L\[t\]\[assignment\[t\]\] = confidence, 0
    /// elsewhere; `confidence` = +∞ ([`KNOWN_START_CONFIDENCE`]) is the
    /// exact known start, 0 on the known identity and −∞ elsewhere (see
    /// [`crate::blocks`]). A finite confidence is the paper's
    /// stand-in (e.g. 20 puts e^-20 on each wrong pairing), kept for
    /// comparison: docs/design/identity.md measures both.
    pub fn from_assignment(
        assignment: &[u32],
        confidence: f64,
        options: InformationOptions,
    ) -> Result<Self, BeliefError> {
        let n = assignment.len();
        if n == 0 {
            return Err(BeliefError::NoTracks);
        }
        check_assignment(n, assignment)?;
        if confidence.is_nan() || confidence == f64::NEG_INFINITY {
            return Err(BeliefError::Numerical {
                step: "information matrix",
                detail: format!("confidence {confidence} is neither finite nor +∞"),
            });
        }
        options.sinkhorn.validate()?;
        let l = assignment
            .iter()
            .flat_map(|&i| start_row(n, Some(i), confidence))
            .collect();
        Ok(InformationMatrix { n, l, options })
    }

    /// Changes how [`IdentityFilter::marginals`] answers.
    #[cfg(test)]
    pub(crate) fn set_marginal_method(&mut self, method: MarginalMethod) {
        self.options.marginals = method;
    }

    /// L as rows.
    pub fn log_likelihoods(&self) -> Vec<Vec<f64>> {
        to_rows(self.n, &self.l)
    }

    /// L, row-major (n² entries, finite or −∞), without a copy.
    pub fn entries(&self) -> &[f64] {
        &self.l
    }

    /// L\[t\]\[i\].
    pub fn get(&self, track: usize, identity: usize) -> Option<f64> {
        (track < self.n && identity < self.n).then(|| self.l[track * self.n + identity])
    }

    /// Marginals block by block (see [`crate::blocks`]): what a
    /// query at n = 10,000 should ask for — no n × n matrix is built.
    pub fn block_marginals(&self, method: &MarginalMethod) -> Result<BlockMarginals, BeliefError> {
        block_marginals(self.n, &self.l, method, &self.options.sinkhorn)
    }

    /// [`InformationMatrix::block_marginals`] that gives up with
    /// [`BeliefError::Stopped`] soon after `stop` is set (another thread's
    /// deadline).
    pub fn block_marginals_stoppable(
        &self,
        method: &MarginalMethod,
        stop: &AtomicBool,
    ) -> Result<BlockMarginals, BeliefError> {
        block_marginals_stoppable(self.n, &self.l, method, &self.options.sinkhorn, stop)
    }

    /// Marginals by a given method, whatever the configured one.
    pub fn marginals_with(&self, method: &MarginalMethod) -> Result<Marginals, BeliefError> {
        let m = information_marginals(self.n, &self.l, method, &self.options.sinkhorn)?;
        Ok(to_rows(self.n, &m))
    }
}

impl IdentityFilter for InformationMatrix {
    fn size(&self) -> usize {
        self.n
    }

    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        check_mix(self.n, &mix)?;
        let n = self.n;
        let (a, b) = (mix.a as usize, mix.b as usize);
        let row_a = &self.l[a * n..(a + 1) * n];
        let row_b = &self.l[b * n..(b + 1) * n];
        let Some((x, y)) = mixed_rows(row_a, row_b, mix.swap, self.options.solver)? else {
            return Ok(());
        };
        self.l[a * n..(a + 1) * n].copy_from_slice(&x);
        self.l[b * n..(b + 1) * n].copy_from_slice(&y);
        Ok(())
    }

    fn identify(&mut self, identify: Identify) -> Result<(), BeliefError> {
        let n = self.n;
        check_identify(n, &identify)?;
        let row = identify.track as usize * n;
        add_evidence(&mut self.l[row..row + n], &identify)
    }

    fn marginals(&self) -> Result<Marginals, BeliefError> {
        self.marginals_with(&self.options.marginals)
    }
}

/// The log-odds of a known initial identity against each other one: +∞,
/// the exact known start (0 on the known identity, −∞ elsewhere). The
/// mixing rule fits only the pairs of identities two tracks can carry
/// ([`crate::support_mix`]), so it needs no finite stand-in; the
/// finite 20 of earlier versions made the fit spend itself on impossible
/// pairs and the marginals confidently wrong (docs/design/identity.md,
/// "Calibration").
pub const KNOWN_START_CONFIDENCE: f64 = f64::INFINITY;

/// Row t of a start: 0 everywhere (uniform), or `confidence` on the known
/// identity (+∞: 0 on it and −∞ on every other).
pub(crate) fn start_row(n: usize, known: Option<u32>, confidence: f64) -> Vec<f64> {
    let Some(known) = known.filter(|&i| (i as usize) < n) else {
        return vec![0.0; n];
    };
    if confidence == f64::INFINITY {
        let mut row = vec![f64::NEG_INFINITY; n];
        row[known as usize] = 0.0;
        return row;
    }
    let mut row = vec![0.0; n];
    row[known as usize] = confidence;
    row
}

/// Evidence on the row of the read track (checked by the caller): adds
/// the read's log-odds to the one entry it names, the O(1) lazy update.
pub(crate) fn add_evidence(row: &mut [f64], identify: &Identify) -> Result<(), BeliefError> {
    let n = row.len();
    let odds = identify.log_odds(n);
    let read = identify.identity as usize;
    let slot = row.get_mut(read).ok_or(BeliefError::UnknownIdentity {
        identity: identify.identity,
        track: identify.track,
        identities: n,
    })?;
    if odds == f64::INFINITY {
        // A perfect read: likelihood 1 for the identity read, 0 for every
        // other, so exactly the row that rules the others out.
        if *slot == f64::NEG_INFINITY {
            return Err(BeliefError::ImpossibleObservation { probability: 0.0 });
        }
        for (i, x) in row.iter_mut().enumerate() {
            *x = if i == read { 0.0 } else { f64::NEG_INFINITY };
        }
        return Ok(());
    }
    if *slot == f64::NEG_INFINITY {
        // The track cannot carry the identity read: the read is equally
        // likely under every possible assignment and says nothing.
        return Ok(());
    }
    let next = *slot + odds;
    if !next.is_finite() {
        return Err(BeliefError::Numerical {
            step: "information matrix evidence",
            detail: format!("log-likelihood {next} is not finite"),
        });
    }
    *slot = next;
    Ok(())
}

/// Two rows of an information matrix: tracks a's and b's.
pub(crate) type RowPair = (Vec<f64>, Vec<f64>);

/// The rows of tracks a and b after a mix with swap probability `swap`,
/// each shifted to max 0; None when the mix changes nothing (s = 0). A
/// pure function of its inputs: two leaders that each hold one of the rows
/// and exchange them compute the same pair, bit for bit.
pub(crate) fn mixed_rows(
    row_a: &[f64],
    row_b: &[f64],
    swap: f64,
    solver: MixSolver,
) -> Result<Option<RowPair>, BeliefError> {
    if swap == 0.0 {
        return Ok(None);
    }
    let ruled_out = |row: &[f64]| row.contains(&f64::NEG_INFINITY);
    let (mut x, mut y) = if swap == 1.0 {
        // A sure swap is exact: exchange the rows.
        (row_b.to_vec(), row_a.to_vec())
    } else if ruled_out(row_a) || ruled_out(row_b) {
        if !(0.0..=1.0).contains(&swap) {
            return Err(BeliefError::BadSwap { swap });
        }
        if row_a.len() != row_b.len()
            || row_a
                .iter()
                .chain(row_b)
                .any(|x| x.is_nan() || *x == f64::INFINITY)
        {
            return Err(BeliefError::Numerical {
                step: "information matrix mixing",
                detail: "rows must be of one length, with entries finite or −∞".into(),
            });
        }
        fit_on_support(row_a, row_b, swap, solver)?
    } else {
        match solver {
            MixSolver::ClosedForm => fit_mixed_rows(row_a, row_b, swap)?,
            MixSolver::PseudoInverse => fit_mixed_rows_pinv(row_a, row_b, swap)?,
        }
    };
    shift_to_max_zero(&mut x)?;
    shift_to_max_zero(&mut y)?;
    Ok(Some((x, y)))
}

/// Adds a constant so the largest entry is 0 (Property 1: same belief);
/// −∞ entries (ruled-out identities) stay.
fn shift_to_max_zero(row: &mut [f64]) -> Result<(), BeliefError> {
    let top = row.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !top.is_finite() || row.iter().any(|x| x.is_nan() || *x == f64::INFINITY) {
        return Err(BeliefError::Numerical {
            step: "information matrix mixing",
            detail: format!("the fitted row has non-finite entries (max {top})"),
        });
    }
    row.iter_mut().for_each(|x| *x -= top);
    Ok(())
}

/// ln((1 − s)·e^u + s·e^v) without overflow; s ∈ [0, 1].
fn ln_mix(u: f64, v: f64, s: f64) -> f64 {
    if s == 0.0 {
        return u;
    }
    if s == 1.0 {
        return v;
    }
    let top = u.max(v);
    top + ((1.0 - s) * (u - top).exp() + s * (v - top).exp()).ln()
}

fn check_rows(a: &[f64], b: &[f64], swap: f64) -> Result<usize, BeliefError> {
    let n = a.len();
    if n < 2 || b.len() != n {
        return Err(BeliefError::Numerical {
            step: "information matrix mixing",
            detail: format!(
                "rows of lengths {} and {}; need two equal lengths ≥ 2",
                n,
                b.len()
            ),
        });
    }
    if a.iter().chain(b).any(|x| !x.is_finite()) {
        return Err(BeliefError::Numerical {
            step: "information matrix mixing",
            detail: "rows must be finite".into(),
        });
    }
    if !(0.0..=1.0).contains(&swap) {
        return Err(BeliefError::BadSwap { swap });
    }
    Ok(n)
}

/// G(m, n) = ln((1 − s)·A_m·B_n + s·A_n·B_m) for the rows a = ln A, b = ln B,
/// row-major n × n (the diagonal is unused and left 0).
fn pair_logs(a: &[f64], b: &[f64], swap: f64) -> Vec<f64> {
    let n = a.len();
    let mut g = vec![0.0; n * n];
    for m in 0..n {
        for k in 0..n {
            if m != k {
                g[m * n + k] = ln_mix(a[m] + b[k], a[k] + b[m], swap);
            }
        }
    }
    g
}

/// The paper's merged row (α = ½, rows a and b made equal), by the O(N²)
/// closed form β_m = (r_m − Γ/(N − 1))/(N − 2) (β = γ/2 for N = 2). Inputs
/// are the two rows of L (log space), finite, of equal length ≥ 2.
pub fn paper_merge(a: &[f64], b: &[f64]) -> Result<Vec<f64>, BeliefError> {
    let n = check_rows(a, b, 0.5)?;
    let g = pair_logs(a, b, 0.5);
    if n == 2 {
        return Ok(vec![g[1] / 2.0; 2]);
    }
    let r: Vec<f64> = (0..n)
        .map(|m| (0..n).filter(|&k| k != m).map(|k| g[m * n + k]).sum())
        .collect();
    let total_pairs = r.iter().sum::<f64>() / 2.0; // Γ
    let nf = n as f64;
    Ok(r.iter()
        .map(|&rm| (rm - total_pairs / (nf - 1.0)) / (nf - 2.0))
        .collect())
}

/// The paper's merged row by its own formula, β = P†γ with the SVD
/// pseudoinverse of the C(N,2) × N pair matrix P: the reference for
/// [`paper_merge`].
pub fn paper_merge_pinv(a: &[f64], b: &[f64]) -> Result<Vec<f64>, BeliefError> {
    let n = check_rows(a, b, 0.5)?;
    let g = pair_logs(a, b, 0.5);
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|m| (m + 1..n).map(move |k| (m, k)))
        .collect();
    let mut p = DMatrix::<f64>::zeros(pairs.len(), n);
    let mut gamma = DVector::<f64>::zeros(pairs.len());
    for (row, &(m, k)) in pairs.iter().enumerate() {
        p[(row, m)] = 1.0;
        p[(row, k)] = 1.0;
        gamma[row] = g[m * n + k];
    }
    let pinv = checked_pseudo_inverse(p)?;
    Ok((pinv * gamma).iter().copied().collect())
}

/// The two new rows (x, y) of L after tracks with rows a, b mix with swap
/// probability `swap`: the minimum-norm least-squares fit of
/// x_m + y_n ≈ G(m, n), by the O(N²) closed form of the module docs.
pub(crate) fn fit_mixed_rows(
    a: &[f64],
    b: &[f64],
    swap: f64,
) -> Result<(Vec<f64>, Vec<f64>), BeliefError> {
    let n = check_rows(a, b, swap)?;
    let g = pair_logs(a, b, swap);
    if n == 2 {
        return Ok((vec![g[1] / 2.0, g[2] / 2.0], vec![g[2] / 2.0, g[1] / 2.0]));
    }
    let mut r = vec![0.0; n];
    let mut c = vec![0.0; n];
    for m in 0..n {
        for k in 0..n {
            if m != k {
                r[m] += g[m * n + k];
                c[k] += g[m * n + k];
            }
        }
    }
    let s: f64 = r.iter().sum();
    let nf = n as f64;
    let mut x = vec![0.0; n];
    let mut y = vec![0.0; n];
    for m in 0..n {
        let sum = (r[m] + c[m] - s / (nf - 1.0)) / (nf - 2.0);
        let diff = (r[m] - c[m]) / nf;
        x[m] = (sum + diff) / 2.0;
        y[m] = (sum - diff) / 2.0;
    }
    Ok((x, y))
}

/// [`fit_mixed_rows`] by the SVD pseudoinverse of the N(N − 1) × 2N design
/// matrix: the reference implementation.
pub(crate) fn fit_mixed_rows_pinv(
    a: &[f64],
    b: &[f64],
    swap: f64,
) -> Result<(Vec<f64>, Vec<f64>), BeliefError> {
    let n = check_rows(a, b, swap)?;
    let g = pair_logs(a, b, swap);
    let rows = n * (n - 1);
    let mut design = DMatrix::<f64>::zeros(rows, 2 * n);
    let mut rhs = DVector::<f64>::zeros(rows);
    let mut row = 0;
    for m in 0..n {
        for k in 0..n {
            if m != k {
                design[(row, m)] = 1.0;
                design[(row, n + k)] = 1.0;
                rhs[row] = g[m * n + k];
                row += 1;
            }
        }
    }
    let pinv = checked_pseudo_inverse(design)?;
    let sol = pinv * rhs;
    Ok((
        sol.iter().take(n).copied().collect(),
        sol.iter().skip(n).copied().collect(),
    ))
}

/// The Moore–Penrose pseudoinverse by nalgebra's SVD, checked.
///
/// nalgebra 0.33's SVD returns wrong singular values for some of these
/// rank-deficient 0/1 designs (the two-row design at N = 8 and N = 12: top
/// singular value 3.85 instead of √14; upstream issue
/// dimforge/nalgebra#1172). So we check the Penrose identity D·D⁺·D = D
/// and, when it fails, compute D⁺ = (DᵀD)⁺Dᵀ from the symmetric
/// eigendecomposition of DᵀD instead — the same matrix in exact arithmetic.
/// If both fail the reference reports an error rather than a wrong answer.
fn checked_pseudo_inverse(design: DMatrix<f64>) -> Result<DMatrix<f64>, BeliefError> {
    let holds = |pinv: &DMatrix<f64>| (&design * pinv * &design - &design).abs().max() < 1e-9;
    if let Ok(pinv) = design.clone().pseudo_inverse(1e-9) {
        if holds(&pinv) {
            return Ok(pinv);
        }
    }
    let gram = design.transpose() * &design;
    let eigen = nalgebra::SymmetricEigen::new(gram);
    let inverted = eigen
        .eigenvalues
        .map(|l| if l.abs() > 1e-9 { 1.0 / l } else { 0.0 });
    let pinv = &eigen.eigenvectors
        * DMatrix::from_diagonal(&inverted)
        * eigen.eigenvectors.transpose()
        * design.transpose();
    if holds(&pinv) {
        Ok(pinv)
    } else {
        Err(BeliefError::Numerical {
            step: "pseudoinverse",
            detail: "neither the SVD nor the eigendecomposition gave D·D⁺·D = D".into(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exact::ExactPermutationFilter;
    use crate::filter::max_abs_difference;
    use crate::permutation::Permutations;
    use crate::workload::{generate, IdentityWorkloadSpec};
    use proptest::prelude::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn max_diff(x: &[f64], y: &[f64]) -> f64 {
        x.iter()
            .zip(y)
            .map(|(p, q)| (p - q).abs())
            .fold(0.0, f64::max)
    }

    fn random_rows(rng: &mut ChaCha8Rng, n: usize, spread: f64) -> (Vec<f64>, Vec<f64>) {
        let mut row = || {
            (0..n)
                .map(|_| rng.gen_range(-spread..spread))
                .collect::<Vec<_>>()
        };
        (row(), row())
    }

    /// Runs the same events through an information matrix (exact marginals)
    /// and the exact filter started from the same L; returns the largest
    /// marginal difference seen.
    fn run_against_exact(l0: &[Vec<f64>], events: &[crate::IdentityEvent]) -> f64 {
        let mut info =
            InformationMatrix::from_log_likelihoods(l0, InformationOptions::default()).unwrap();
        let mut exact = ExactPermutationFilter::from_log_likelihoods(l0).unwrap();
        let mut worst: f64 = 0.0;
        for e in events {
            info.apply(e).unwrap();
            exact.apply(e).unwrap();
            let d = max_abs_difference(&info.marginals().unwrap(), &exact.marginals().unwrap());
            worst = worst.max(d);
        }
        worst
    }

    #[test]
    fn paper_closed_form_matches_pseudoinverse() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for n in 2..=9 {
            for spread in [0.5, 5.0, 30.0] {
                let (a, b) = random_rows(&mut rng, n, spread);
                let closed = paper_merge(&a, &b).unwrap();
                let pinv = paper_merge_pinv(&a, &b).unwrap();
                assert!(max_diff(&closed, &pinv) < 1e-9, "n={n} spread={spread}");
            }
        }
    }

    #[test]
    fn sizes_where_nalgebra_svd_fails_still_match() {
        // nalgebra 0.33's SVD gets the two-row design wrong at N = 8 and 12
        // (D·D⁺·D ≠ D by 7e-3); the checked pseudoinverse falls back to the
        // eigendecomposition there.
        let mut rng = ChaCha8Rng::seed_from_u64(12);
        for n in [8, 12] {
            let (a, b) = random_rows(&mut rng, n, 1.0);
            for swap in [0.0, 0.3, 0.5] {
                let (x, y) = fit_mixed_rows(&a, &b, swap).unwrap();
                let (px, py) = fit_mixed_rows_pinv(&a, &b, swap).unwrap();
                assert!(max_diff(&x, &px) < 1e-9 && max_diff(&y, &py) < 1e-9);
            }
        }
    }

    #[test]
    fn two_row_fit_at_one_half_is_the_papers_rule() {
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        for n in 2..=8 {
            let (a, b) = random_rows(&mut rng, n, 4.0);
            let beta = paper_merge(&a, &b).unwrap();
            let (x, y) = fit_mixed_rows(&a, &b, 0.5).unwrap();
            assert!(
                max_diff(&x, &beta) < 1e-9 && max_diff(&y, &beta) < 1e-9,
                "n={n}"
            );
        }
    }

    #[test]
    fn paper_three_track_example() {
        // Slides: L*_p = [a b c] (columns there, rows here); after the mix
        // d1·d2 = (a1 b2 + a2 b1)/2 etc. hold exactly for N = 3.
        let (a, b) = (vec![0.3, -1.0, 2.0], vec![1.5, 0.2, -0.7]);
        let d = paper_merge(&a, &b).unwrap();
        let e = |v: &[f64], i: usize| v[i].exp();
        for (m, k) in [(0, 1), (0, 2), (1, 2)] {
            let want = (e(&a, m) * e(&b, k) + e(&a, k) * e(&b, m)) / 2.0;
            assert!(((d[m] + d[k]).exp() / want - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn exact_for_three_tracks_at_one_half() {
        // Start from uniform, or from a finite known-assignment stand-in.
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        for n in 1..=3 {
            for seed in 0..20 {
                let w = generate(&IdentityWorkloadSpec {
                    events: 40,
                    ..IdentityWorkloadSpec::paper(n, 1.0, seed)
                })
                .unwrap();
                let zero = vec![vec![0.0; n]; n];
                assert!(run_against_exact(&zero, &w.events) < 1e-9);
                let l0: Vec<Vec<f64>> = (0..n)
                    .map(|_| (0..n).map(|_| rng.gen_range(-3.0..3.0)).collect())
                    .collect();
                assert!(run_against_exact(&l0, &w.events) < 1e-9);
            }
        }
    }

    #[test]
    fn exact_for_two_tracks_at_any_swap() {
        for swap in [0.0, 0.1, 0.37, 0.5, 0.8, 1.0] {
            for seed in 0..10 {
                let w = generate(&IdentityWorkloadSpec {
                    swap,
                    events: 40,
                    ..IdentityWorkloadSpec::paper(2, 1.0, seed)
                })
                .unwrap();
                let l0 = vec![vec![2.0, 0.0], vec![0.0, 0.5]];
                assert!(run_against_exact(&l0, &w.events) < 1e-9, "swap {swap}");
            }
        }
    }

    /// Σ_π sgn(π)·ln p(π): 0 for every belief an information matrix can
    /// hold when N = 3.
    fn sign_component(exact: &ExactPermutationFilter) -> f64 {
        let perms = Permutations::new(3).unwrap();
        let sign = |p: &[u8]| {
            let inversions = (0..3)
                .flat_map(|i| (i + 1..3).map(move |j| (i, j)))
                .filter(|&(i, j)| p[i] > p[j])
                .count();
            if inversions % 2 == 0 {
                1.0
            } else {
                -1.0
            }
        };
        exact
            .probabilities()
            .iter()
            .enumerate()
            .map(|(r, &p)| sign(perms.get(r)) * p.ln())
            .sum()
    }

    #[test]
    fn not_exact_for_three_tracks_off_one_half() {
        // The paper's theorem needs α = ½. With s = 0.2 the exact belief
        // leaves the family every information matrix lies in.
        let l0 = vec![
            vec![2.0, 0.0, 0.0],
            vec![0.0, 2.0, 0.0],
            vec![0.0, 0.0, 2.0],
        ];
        let mut exact = ExactPermutationFilter::from_log_likelihoods(&l0).unwrap();
        assert!(sign_component(&exact).abs() < 1e-12);
        let mix = Mix {
            a: 0,
            b: 1,
            swap: 0.2,
        };
        exact.mix(mix).unwrap();
        let off = sign_component(&exact);
        assert!(off.abs() > 0.1, "{off}");
        let mut info =
            InformationMatrix::from_log_likelihoods(&l0, InformationOptions::default()).unwrap();
        info.mix(mix).unwrap();
        let d = max_abs_difference(&info.marginals().unwrap(), &exact.marginals().unwrap());
        // Measured 0.034.
        assert!(d > 0.01, "{d}");
        // At s = ½ the same start stays in the family.
        let mut half = ExactPermutationFilter::from_log_likelihoods(&l0).unwrap();
        half.mix(Mix { swap: 0.5, ..mix }).unwrap();
        assert!(sign_component(&half).abs() < 1e-9);
    }

    #[test]
    fn not_exact_for_four_tracks() {
        let l0: Vec<Vec<f64>> = (0..4)
            .map(|t| (0..4).map(|i| if t == i { 3.0 } else { 0.0 }).collect())
            .collect();
        let mut exact = ExactPermutationFilter::from_log_likelihoods(&l0).unwrap();
        let mut info =
            InformationMatrix::from_log_likelihoods(&l0, InformationOptions::default()).unwrap();
        for (a, b) in [(0, 1), (1, 2), (2, 3)] {
            let mix = Mix { a, b, swap: 0.5 };
            exact.mix(mix).unwrap();
            info.mix(mix).unwrap();
        }
        let d = max_abs_difference(&info.marginals().unwrap(), &exact.marginals().unwrap());
        // Measured 0.050.
        assert!(d > 1e-3, "{d}");
    }

    /// Mean over `seeds` paper-style streams (50 events, accuracy 0.9,
    /// α = ½) of the mean |Δp| against the exact filter after the last
    /// event, for a filter built by `make`.
    fn paper_error(
        n: usize,
        ratio: f64,
        seeds: u64,
        make: &dyn Fn() -> Box<dyn IdentityFilter>,
    ) -> f64 {
        let mut total = 0.0;
        for seed in 0..seeds {
            let w = generate(&IdentityWorkloadSpec::paper(n, ratio, seed)).unwrap();
            let mut exact = ExactPermutationFilter::uniform(n).unwrap();
            let mut filter = make();
            for e in &w.events {
                exact.apply(e).unwrap();
                filter.apply(e).unwrap();
            }
            let (p, q) = (filter.marginals().unwrap(), exact.marginals().unwrap());
            let sum: f64 = p
                .iter()
                .flatten()
                .zip(q.iter().flatten())
                .map(|(x, y)| (x - y).abs())
                .sum();
            total += sum / (n * n) as f64;
        }
        total / seeds as f64
    }

    /// An information matrix answering with `method`.
    fn info_with(n: usize, method: MarginalMethod) -> Box<dyn IdentityFilter> {
        let mut info = InformationMatrix::uniform(n).unwrap();
        info.set_marginal_method(method);
        Box::new(info)
    }

    #[test]
    fn paper_simulations() {
        // The paper's Figs. 3 and 4 (N = 3 and 6, 50 events from uniform,
        // accuracy 0.9, α = ½, several mix/read ratios), error = mean |Δp|
        // against the exact filter after the last event, mean of 20 seeded
        // streams. Measured:
        //
        //   N ratio | belief matrix | info exact | info Metropolis 1e4 | info half-Bethe
        //   3  0.25 |        0.0189 |      3e-17 |              0.0011 |          0.0014
        //   3  1    |        0.0500 |      1e-16 |              0.0037 |          0.0111
        //   3  4    |        0.0370 |      9e-17 |              0.0035 |          0.0092
        //   6  0.25 |        0.0105 |     0.0082 |              0.0095 |          0.0092
        //   6  1    |        0.0447 |     0.0345 |              0.0356 |          0.0406
        //   6  4    |        0.0247 |     0.0142 |              0.0165 |          0.0169
        //
        // As the paper reports, the information matrix is at least as good
        // as the belief matrix and Metropolis costs little accuracy; for
        // N = 3 it is exact.
        let metropolis = MarginalMethod::Metropolis {
            samples: 10_000,
            burn_in: 1_000,
            seed: 1,
        };
        for (n, ratio) in [(3, 0.25), (3, 1.0), (3, 4.0), (6, 0.25), (6, 1.0), (6, 4.0)] {
            let [belief, exact, sampled, bethe] = [
                paper_error(n, ratio, 20, &|| {
                    Box::new(crate::belief_matrix::BeliefMatrix::uniform(n).unwrap())
                }),
                paper_error(n, ratio, 20, &|| info_with(n, MarginalMethod::Exact)),
                paper_error(n, ratio, 20, &|| info_with(n, metropolis)),
                paper_error(n, ratio, 20, &|| info_with(n, MarginalMethod::half_bethe())),
            ];
            if n == 3 {
                assert!(exact < 1e-12, "{exact}");
            }
            assert!(exact <= belief, "n={n} ratio={ratio}: {exact} vs {belief}");
            assert!(sampled < exact + 0.005, "n={n} ratio={ratio}: {sampled}");
            assert!(bethe < 0.05 && belief < 0.06, "n={n} ratio={ratio}");
        }
    }

    #[test]
    fn evidence_touches_one_entry_and_perfect_reads_rule_out_the_rest() {
        let mut info = InformationMatrix::uniform(4).unwrap();
        info.identify(Identify {
            track: 2,
            identity: 1,
            accuracy: 0.9,
        })
        .unwrap();
        let l = info.log_likelihoods();
        assert!((l[2][1] - (0.9f64 / (0.1 / 3.0)).ln()).abs() < 1e-12);
        assert_eq!(l.iter().flatten().filter(|&&x| x != 0.0).count(), 1);
        info.identify(Identify {
            track: 0,
            identity: 0,
            accuracy: 1.0,
        })
        .unwrap();
        let l = info.log_likelihoods();
        assert_eq!(l[0][0], 0.0);
        assert!(l[0][1..].iter().all(|&x| x == f64::NEG_INFINITY));
        let p = info.marginals().unwrap();
        assert_eq!(p[0][0], 1.0);
        assert!(p[1..].iter().all(|row| row[0] == 0.0));
        let before = info.clone();
        // Identity 1 is ruled out on track 0 now: a perfect read of it is
        // impossible, and refused without a change.
        assert!(matches!(
            info.identify(Identify {
                track: 0,
                identity: 1,
                accuracy: 1.0
            }),
            Err(BeliefError::ImpossibleObservation { .. })
        ));
        assert!(info
            .mix(Mix {
                a: 0,
                b: 9,
                swap: 0.5
            })
            .is_err());
        assert_eq!(info, before);
    }

    #[test]
    fn pseudo_inverse_solver_gives_the_same_filter() {
        let w = generate(&IdentityWorkloadSpec::paper(5, 1.0, 4)).unwrap();
        let mut closed = InformationMatrix::uniform(5).unwrap();
        let mut pinv = InformationMatrix::uniform_with(
            5,
            InformationOptions {
                solver: MixSolver::PseudoInverse,
                ..Default::default()
            },
        )
        .unwrap();
        for e in &w.events {
            closed.apply(e).unwrap();
            pinv.apply(e).unwrap();
        }
        let (x, y) = (closed.log_likelihoods(), pinv.log_likelihoods());
        assert!(max_abs_difference(&x, &y) < 1e-9);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(128))]

        /// The O(N²) closed forms equal the pseudoinverse solutions.
        #[test]
        fn closed_form_equals_pseudoinverse(
            n in 2usize..=8,
            seed in any::<u64>(),
            spread in 0.01f64..20.0,
            swap in 0.0f64..=1.0,
        ) {
            let mut rng = ChaCha8Rng::seed_from_u64(seed);
            let (a, b) = random_rows(&mut rng, n, spread);
            let (x, y) = fit_mixed_rows(&a, &b, swap).unwrap();
            let (px, py) = fit_mixed_rows_pinv(&a, &b, swap).unwrap();
            prop_assert!(max_diff(&x, &px) < 1e-9 && max_diff(&y, &py) < 1e-9);
            let beta = paper_merge(&a, &b).unwrap();
            let pbeta = paper_merge_pinv(&a, &b).unwrap();
            prop_assert!(max_diff(&beta, &pbeta) < 1e-9);
        }

        /// N ≤ 3 with the paper's α = ½ (any N ≤ 2 swap): the information
        /// matrix with exact marginals is the exact filter.
        #[test]
        fn exact_for_small_n(
            n in 1usize..=3,
            seed in any::<u64>(),
            mix_share in 0.0f64..=1.0,
            accuracy in 0.05f64..0.999,
            swap in 0.0f64..=1.0,
            start in proptest::collection::vec(-4.0f64..4.0, 9),
        ) {
            let swap = if n == 3 { 0.5 } else { swap };
            let w = generate(&IdentityWorkloadSpec {
                tracks: n,
                events: 30,
                mix_share,
                swap,
                accuracy,
                neighbourhood: n,
                seed,
            }).unwrap();
            let l0: Vec<Vec<f64>> = start.chunks(3).take(n).map(|r| r[..n].to_vec()).collect();
            prop_assert!(run_against_exact(&l0, &w.events) < 1e-9);
        }
    }
}
