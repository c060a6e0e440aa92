//! Sinkhorn scaling of a non-negative N × N matrix to a doubly stochastic
//! one (Sinkhorn–Knopp: alternately divide rows and columns by their sums).
//!
//! Used three times in the identity engine:
//! - the belief matrix renormalizes after every read (Shin et al., IPSN
//!   2005, Section 4: the normalization the information matrix postpones);
//! - the cheap approximate marginals of an information matrix: scale exp(L)
//!   ([`crate::marginals::MarginalMethod::Sinkhorn`]);
//! - the property-bits filter turns per-bit scores into identity marginals.
//!
//! Sinkhorn–Knopp converges (linearly) exactly when the matrix has *total
//! support*: every positive entry lies on some positive diagonal, i.e. in a
//! perfect matching of its positive pattern. An entry that is on no positive
//! diagonal tends to 0 in the limit but only like 1/k, so the iteration would
//! crawl. A perfect read (accuracy 1) produces exactly such entries. We
//! therefore first zero every entry on no positive diagonal (one perfect
//! matching, then the strongly connected components of the alternating-path
//! graph: O(N²)); this does not change the limit, which is supported on the
//! total-support part. A matrix with no positive diagonal at all cannot be
//! scaled and is refused.
//!
//! Even with total support, sweeps converge at the rate σ₂² of the limit,
//! which is close to 1 for beliefs that are nearly a permutation (the usual
//! case after a few reads). So after 100 sweeps we switch to damped Newton
//! steps on the convex dual (see `newton_step`), quadratically convergent,
//! for N ≤ [`MAX_NEWTON_TRACKS`]. An iteration that does not reach the
//! tolerance within the cap is reported as an error, never returned
//! silently.
//!
//! Every step after the pruning runs over the positive entries only
//! ([`Pattern`]): scaling multiplies entries, so a zero stays zero. An
//! information matrix with a known start is sparse even inside one large
//! block of mixed tracks — a track can carry only the identities that
//! reached it through a chain of mixes in time order (a simulated
//! crowd of 1,000 after 20 s is one block of 901 tracks with 16,000
//! possible pairs of its 810,000, at most 71 in a row) — so a sweep, a
//! Hessian product and a line-search point cost O(positive entries), not
//! O(N²).

use idmesh_belief::BeliefError;

/// When Sinkhorn scaling stops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SinkhornOptions {
    /// Stop when, with the columns summing to 1, every row sum is within
    /// this of 1; the rows are then divided by their sums, so the result
    /// has rows summing to 1 and columns within about this of 1.
    /// Default 1e-10.
    pub tolerance: f64,
    /// Give up (with an error) after this many iterations (sweeps plus
    /// Newton steps). Default 10,000.
    pub max_iterations: usize,
}

impl Default for SinkhornOptions {
    fn default() -> Self {
        SinkhornOptions {
            tolerance: 1e-10,
            max_iterations: 10_000,
        }
    }
}

impl SinkhornOptions {
    pub fn validate(&self) -> Result<(), BeliefError> {
        if !(self.tolerance > 0.0 && self.tolerance.is_finite()) || self.max_iterations == 0 {
            return Err(BeliefError::Unsupported {
                method: "sinkhorn",
                what: "a tolerance that is not positive and finite, or no iterations",
            });
        }
        Ok(())
    }
}

/// How a scaling went.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct SinkhornReport {
    /// Sweeps plus Newton steps done.
    pub iterations: usize,
    /// How many of them were Newton steps.
    pub newton_steps: usize,
    /// The largest |row sum − 1| at the end.
    pub residual: f64,
    /// Positive entries zeroed because they lie on no positive diagonal.
    pub pruned: usize,
}

/// Scales the row-major n × n `matrix` in place to doubly stochastic.
///
/// Errors (the matrix is then unspecified; callers work on a copy):
/// negative or non-finite entries ([`BeliefError::Numerical`]); no positive
/// diagonal ([`BeliefError::Degenerate`] with normalizer 0 — the permanent
/// is 0); no convergence within the cap ([`BeliefError::Numerical`]).
pub(crate) fn sinkhorn(
    n: usize,
    matrix: &mut [f64],
    options: &SinkhornOptions,
) -> Result<SinkhornReport, BeliefError> {
    scale_logged(n, matrix, options).map(|(report, _)| report)
}

/// ln of the diagonal scalings Sinkhorn applied: the result is
/// diag(e^row)·A·diag(e^col) (with the entries on no positive diagonal
/// zeroed, which changes no permutation product).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LogScaling {
    pub row: Vec<f64>,
    pub col: Vec<f64>,
}

/// [`sinkhorn`], also returning the scalings it applied.
pub(crate) fn scale_logged(
    n: usize,
    matrix: &mut [f64],
    options: &SinkhornOptions,
) -> Result<(SinkhornReport, LogScaling), BeliefError> {
    options.validate()?;
    check_entries(n, matrix)?;
    let mut logs = LogScaling {
        row: vec![0.0; n],
        col: vec![0.0; n],
    };
    scale_rows_to_max_one(n, matrix, &mut logs)?;
    let pruned = prune_to_total_support(n, matrix)?;
    let pattern = Pattern::of(n, matrix);

    // Phase 1: plain sweeps — O(N²) each, and enough for most matrices.
    let sweeps = options.max_iterations.min(SWEEPS_BEFORE_NEWTON);
    let mut iterations = 0;
    let mut residual = f64::INFINITY;
    while iterations < sweeps {
        iterations += 1;
        residual = sweep(n, &pattern, matrix, &mut logs);
        if residual <= options.tolerance {
            return Ok((
                SinkhornReport {
                    iterations,
                    newton_steps: 0,
                    residual,
                    pruned,
                },
                logs,
            ));
        }
        if !residual.is_finite() {
            break;
        }
    }
    // Phase 2: damped Newton, then sweeps again if Newton is not allowed.
    let mut newton_steps = 0;
    if residual.is_finite() {
        while iterations < options.max_iterations {
            iterations += 1;
            newton_steps += 1;
            let stepped = if n <= MAX_NEWTON_TRACKS {
                newton_step(n, &pattern, matrix, &mut logs)
            } else if n <= MAX_SCHUR_TRACKS {
                newton_schur_step(n, &pattern, matrix, &mut logs)
            } else {
                newton_cg_step(n, &pattern, matrix, &mut logs)
            };
            if !stepped {
                break;
            }
            residual = sweep(n, &pattern, matrix, &mut logs);
            if residual <= options.tolerance {
                return Ok((
                    SinkhornReport {
                        iterations,
                        newton_steps,
                        residual,
                        pruned,
                    },
                    logs,
                ));
            }
        }
    }
    while iterations < options.max_iterations && residual.is_finite() {
        iterations += 1;
        residual = sweep(n, &pattern, matrix, &mut logs);
        if residual <= options.tolerance {
            return Ok((
                SinkhornReport {
                    iterations,
                    newton_steps,
                    residual,
                    pruned,
                },
                logs,
            ));
        }
    }
    let residual = row_residual(n, matrix).max(column_residual(n, matrix));
    Err(BeliefError::Numerical {
        step: "sinkhorn",
        detail: format!(
            "no convergence to tolerance {} within {} iterations (residual {residual:e})",
            options.tolerance, options.max_iterations
        ),
    })
}

/// Refuses a matrix that is not n × n, or has a negative or non-finite
/// entry.
fn check_entries(n: usize, matrix: &[f64]) -> Result<(), BeliefError> {
    if n == 0 || matrix.len() != n * n {
        return Err(BeliefError::Numerical {
            step: "sinkhorn",
            detail: format!("expected {n} × {n} entries, got {}", matrix.len()),
        });
    }
    if let Some(&bad) = matrix.iter().find(|x| !(x.is_finite() && **x >= 0.0)) {
        return Err(BeliefError::Numerical {
            step: "sinkhorn",
            detail: format!("entry {bad} is negative or not finite"),
        });
    }
    Ok(())
}

/// Scales every row to max 1 before any sweep, so sums neither overflow
/// nor vanish; an all-zero row is a matrix with no positive diagonal.
fn scale_rows_to_max_one(
    n: usize,
    matrix: &mut [f64],
    logs: &mut LogScaling,
) -> Result<(), BeliefError> {
    for (row, ln_row) in matrix.chunks_mut(n).zip(logs.row.iter_mut()) {
        let top = row.iter().copied().fold(0.0, f64::max);
        if top == 0.0 {
            return Err(BeliefError::Degenerate { normalizer: 0.0 });
        }
        row.iter_mut().for_each(|x| *x /= top);
        *ln_row -= top.ln();
    }
    Ok(())
}

/// Plain sweeps tried before Newton steps.
const SWEEPS_BEFORE_NEWTON: usize = 100;

/// Newton steps solve a 2N × 2N system by Cholesky, O(N³), up to this
/// size; above it the same Newton step is solved by preconditioned
/// conjugate gradients ([`newton_cg_step`]), O(N²) per CG iteration.
pub(crate) const MAX_NEWTON_TRACKS: usize = 400;

/// Above [`MAX_NEWTON_TRACKS`] and up to this size the Newton step is
/// solved through its N × N Schur complement ([`newton_schur_step`]):
/// a Cholesky eight times cheaper than the 2N × 2N one, about 0.1 s at
/// N = 1,000. (The 2N × 2N form stays below, so answers there are the
/// bits they were.)
pub(crate) const MAX_SCHUR_TRACKS: usize = 1_200;

/// The most conjugate-gradient iterations of one Newton–CG step.
const MAX_CG_ITERATIONS: usize = 200;

/// The positive entries of a row-major n × n matrix, row by row: where
/// scaling can change anything (a zero entry stays zero).
struct Pattern {
    /// `columns[i]`: the columns j with a positive (i, j), ascending.
    columns: Vec<Vec<usize>>,
}

impl Pattern {
    fn of(n: usize, matrix: &[f64]) -> Pattern {
        Pattern {
            columns: matrix
                .chunks(n)
                .map(|row| (0..n).filter(|&j| row[j] > 0.0).collect())
                .collect(),
        }
    }

    /// Every positive entry as (row, column, flat index).
    fn entries(&self, n: usize) -> impl Iterator<Item = (usize, usize, usize)> + '_ {
        self.columns
            .iter()
            .enumerate()
            .flat_map(move |(i, cols)| cols.iter().map(move |&j| (i, j, i * n + j)))
    }
}

/// One Sinkhorn sweep: divide columns, then rows, by their sums. Returns the
/// largest |row sum − 1| seen before the row division (columns were exact
/// then, so this measures how far from doubly stochastic the matrix was).
/// Afterwards rows are exact and columns are off by about that much.
fn sweep(n: usize, pattern: &Pattern, matrix: &mut [f64], logs: &mut LogScaling) -> f64 {
    let mut col = vec![0.0; n];
    for (_, j, k) in pattern.entries(n) {
        col[j] += matrix[k];
    }
    for (_, j, k) in pattern.entries(n) {
        matrix[k] /= col[j];
    }
    logs.col
        .iter_mut()
        .zip(&col)
        .for_each(|(l, c)| *l -= c.ln());
    let mut residual: f64 = 0.0;
    for (i, (cols, ln_row)) in pattern.columns.iter().zip(logs.row.iter_mut()).enumerate() {
        let row = &mut matrix[i * n..(i + 1) * n];
        let sum: f64 = cols.iter().map(|&j| row[j]).sum();
        residual = residual.max((sum - 1.0).abs());
        cols.iter().for_each(|&j| row[j] /= sum);
        *ln_row -= sum.ln();
    }
    residual
}

/// One damped Newton step on the convex dual of the scaling problem.
///
/// Writing the scaled matrix as P_ij = K_ij·e^{u_i + v_j}, doubly stochastic
/// P is the minimizer of f(u, v) = Σ_ij P_ij − Σ_i u_i − Σ_j v_j, whose
/// gradient is (row sums − 1, column sums − 1) and whose Hessian is
/// [[diag(r), P], [Pᵀ, diag(c)]]. Why Newton: Sinkhorn sweeps converge at
/// the rate σ₂(P)² (second singular value of the limit), which tends to 1
/// as the belief becomes nearly a permutation — exactly the peaked beliefs
/// identity tracking produces (10⁵ sweeps did not reach 1e-10 on a 2 × 2
/// belief with off-diagonal mass 3e-5). Newton converges quadratically near
/// the solution. The Hessian is singular along (1, −1) on each block of the
/// pattern (the scaling gauge), along which the gradient has no component,
/// so a tiny ridge makes it positive definite without changing the step
/// where it matters. Backtracking (Armijo) on f keeps every step a descent.
/// Returns false if no step could be made.
fn newton_step(n: usize, pattern: &Pattern, p: &mut [f64], logs: &mut LogScaling) -> bool {
    use nalgebra::{DMatrix, DVector};
    let dim = 2 * n;
    let mut h = DMatrix::<f64>::zeros(dim, dim);
    let mut g = DVector::<f64>::zeros(dim);
    for (i, j, k) in pattern.entries(n) {
        let x = p[k];
        h[(i, i)] += x;
        h[(n + j, n + j)] += x;
        h[(i, n + j)] = x;
        h[(n + j, i)] = x;
    }
    for k in 0..dim {
        g[k] = h[(k, k)] - 1.0;
    }
    let scale = (0..dim).map(|k| h[(k, k)]).fold(0.0, f64::max).max(1.0);
    let mut ridge = 1e-13 * scale;
    let step = loop {
        let mut hr = h.clone();
        for k in 0..dim {
            hr[(k, k)] += ridge;
        }
        if let Some(chol) = hr.cholesky() {
            break -chol.solve(&g);
        }
        ridge *= 100.0;
        if ridge > scale {
            return false;
        }
    };
    let step: Vec<f64> = step.iter().copied().collect();
    let g: Vec<f64> = g.iter().copied().collect();
    line_search(n, pattern, p, logs, &g, &step)
}

/// The Newton step of [`newton_step`], solved through the Schur
/// complement of the column block: with H = [[D_r, P], [Pᵀ, D_c]],
/// d_c = D_c⁻¹(−g_c − Pᵀ·d_r) and (D_r − P·D_c⁻¹·Pᵀ)·d_r = −g_r +
/// P·D_c⁻¹·g_c, an N × N system. Building it costs the sum over columns
/// of (positive entries in the column)², small for a crowd's sparse block.
fn newton_schur_step(n: usize, pattern: &Pattern, p: &mut [f64], logs: &mut LogScaling) -> bool {
    use nalgebra::{DMatrix, DVector};
    let mut diag = vec![0.0; 2 * n];
    let mut columns: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    for (i, j, k) in pattern.entries(n) {
        let x = p[k];
        diag[i] += x;
        diag[n + j] += x;
        columns[j].push((i, x));
    }
    let g: Vec<f64> = diag.iter().map(|d| d - 1.0).collect();
    let scale = diag.iter().copied().fold(0.0, f64::max).max(1.0);
    let mut ridge = 1e-13 * scale;
    let step = loop {
        let mut s = DMatrix::<f64>::zeros(n, n);
        let mut rhs = DVector::<f64>::zeros(n);
        for i in 0..n {
            s[(i, i)] = diag[i] + ridge;
            rhs[i] = -g[i];
        }
        for (j, column) in columns.iter().enumerate() {
            let c = diag[n + j] + ridge;
            for &(a, x) in column {
                rhs[a] += x * g[n + j] / c;
                for &(b, y) in column {
                    s[(a, b)] -= x * y / c;
                }
            }
        }
        if let Some(chol) = s.cholesky() {
            let d_r = chol.solve(&rhs);
            let mut step: Vec<f64> = d_r.iter().copied().collect();
            for (j, column) in columns.iter().enumerate() {
                let c = diag[n + j] + ridge;
                let through: f64 = column.iter().map(|&(i, x)| x * d_r[i]).sum();
                step.push((-g[n + j] - through) / c);
            }
            break step;
        }
        ridge *= 100.0;
        if ridge > scale {
            return false;
        }
    };
    line_search(n, pattern, p, logs, &g, &step)
}

/// The Newton step of [`newton_step`] for large N, without forming the
/// Hessian: conjugate gradients on H·d = −g with H·v = (r∘v₁ + P·v₂,
/// Pᵀ·v₁ + c∘v₂), preconditioned by the diagonal (r, c) (Jacobi), each
/// iteration O(positive entries); stopped when the residual is a hundredth of ‖g‖
/// (inexact Newton: the line search keeps every step a descent, and the
/// next step corrects what this one left). Why: plain sweeps stall on
/// peaked beliefs above [`MAX_NEWTON_TRACKS`] (they failed at n = 500),
/// and Cholesky of a 2N × 2N matrix is O(N³).
fn newton_cg_step(n: usize, pattern: &Pattern, p: &mut [f64], logs: &mut LogScaling) -> bool {
    let dim = 2 * n;
    let mut diag = vec![0.0; dim];
    for (i, j, k) in pattern.entries(n) {
        let x = p[k];
        diag[i] += x;
        diag[n + j] += x;
    }
    let g: Vec<f64> = diag.iter().map(|d| d - 1.0).collect();
    let scale = diag.iter().copied().fold(0.0, f64::max).max(1.0);
    let ridge = 1e-12 * scale;
    let hess = |v: &[f64], out: &mut [f64]| {
        for k in 0..dim {
            out[k] = (diag[k] + ridge) * v[k];
        }
        for (i, j, k) in pattern.entries(n) {
            let x = p[k];
            out[i] += x * v[n + j];
            out[n + j] += x * v[i];
        }
    };
    let precondition =
        |r: &[f64]| -> Vec<f64> { r.iter().zip(&diag).map(|(x, d)| x / (d + ridge)).collect() };
    let norm = |v: &[f64]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let goal = 1e-2 * norm(&g);
    // Solve H·d = −g from d = 0.
    let mut d = vec![0.0; dim];
    let mut r: Vec<f64> = g.iter().map(|x| -x).collect();
    let mut z = precondition(&r);
    let mut dir = z.clone();
    let mut rz: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
    let mut hd = vec![0.0; dim];
    for _ in 0..MAX_CG_ITERATIONS {
        if norm(&r) <= goal {
            break;
        }
        hess(&dir, &mut hd);
        let curvature: f64 = dir.iter().zip(&hd).map(|(a, b)| a * b).sum();
        // Not positive, or NaN: CG cannot go on.
        if curvature.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            break;
        }
        let alpha = rz / curvature;
        for k in 0..dim {
            d[k] += alpha * dir[k];
            r[k] -= alpha * hd[k];
        }
        z = precondition(&r);
        let rz_next: f64 = r.iter().zip(&z).map(|(a, b)| a * b).sum();
        let beta = rz_next / rz;
        rz = rz_next;
        for k in 0..dim {
            dir[k] = z[k] + beta * dir[k];
        }
    }
    if d.iter().all(|&x| x == 0.0) {
        return false;
    }
    line_search(n, pattern, p, logs, &g, &d)
}

/// Backtracking (Armijo) along `step` from the current scaling, on the dual
/// objective of [`newton_step`]; applies the step and returns true, or
/// false when no step length decreases it.
fn line_search(
    n: usize,
    pattern: &Pattern,
    p: &mut [f64],
    logs: &mut LogScaling,
    g: &[f64],
    step: &[f64],
) -> bool {
    if step.iter().any(|x| !x.is_finite()) {
        return false;
    }
    let f = |t: f64| -> f64 {
        let mut total = 0.0;
        for (i, j, k) in pattern.entries(n) {
            let x = p[k];
            if x > 0.0 {
                total += x * (t * (step[i] + step[n + j])).exp();
            }
        }
        total - t * step.iter().sum::<f64>()
    };
    let f0 = f(0.0);
    let slope: f64 = g.iter().zip(step).map(|(a, b)| a * b).sum();
    let mut t = 1.0;
    while t > 1e-12 {
        let ft = f(t);
        if ft.is_finite() && ft <= f0 + 0.25 * t * slope {
            for (i, j, k) in pattern.entries(n) {
                p[k] *= (t * (step[i] + step[n + j])).exp();
            }
            for i in 0..n {
                logs.row[i] += t * step[i];
                logs.col[i] += t * step[n + i];
            }
            return true;
        }
        t /= 2.0;
    }
    false
}

fn row_residual(n: usize, matrix: &[f64]) -> f64 {
    matrix
        .chunks(n)
        .map(|r| (r.iter().sum::<f64>() - 1.0).abs())
        .fold(0.0, f64::max)
}

/// Sinkhorn scaling of a matrix given by rows.
#[cfg(test)]
pub(crate) fn sinkhorn_rows(
    matrix: &[Vec<f64>],
    options: &SinkhornOptions,
) -> Result<(Vec<Vec<f64>>, SinkhornReport), BeliefError> {
    let n = super::event::check_square(matrix)?;
    let mut flat: Vec<f64> = matrix.iter().flatten().copied().collect();
    let report = sinkhorn(n, &mut flat, options)?;
    Ok((super::filter::to_rows(n, &flat), report))
}

fn column_residual(n: usize, matrix: &[f64]) -> f64 {
    (0..n)
        .map(|i| (matrix.iter().skip(i).step_by(n).sum::<f64>() - 1.0).abs())
        .fold(0.0, f64::max)
}

/// Zeroes every positive entry that lies on no positive diagonal; returns
/// how many. Refuses a matrix with no positive diagonal.
///
/// With a perfect matching M (row t ↔ column m(t)), an entry (t, j) with
/// j ≠ m(t) is in some perfect matching iff it closes an alternating cycle:
/// in the graph on columns with an edge m(t) → j for every positive (t, j),
/// iff m(t) and j are in the same strongly connected component.
fn prune_to_total_support(n: usize, matrix: &mut [f64]) -> Result<usize, BeliefError> {
    if matrix.iter().all(|&x| x > 0.0) {
        return Ok(0);
    }
    let row_of_col =
        perfect_matching(n, matrix).ok_or(BeliefError::Degenerate { normalizer: 0.0 })?;
    let mut col_of_row = vec![0usize; n];
    for (c, &r) in row_of_col.iter().enumerate() {
        col_of_row[r] = c;
    }
    let component = column_components(n, matrix, &row_of_col, &col_of_row);
    let mut pruned = 0;
    for t in 0..n {
        let home = component[col_of_row[t]];
        for j in 0..n {
            let x = &mut matrix[t * n + j];
            if *x > 0.0 && component[j] != home {
                *x = 0.0;
                pruned += 1;
            }
        }
    }
    Ok(pruned)
}

/// A perfect matching of the positive pattern (Kuhn's augmenting paths,
/// O(N³) dense): `result[column] = row`; None when there is none.
fn perfect_matching(n: usize, matrix: &[f64]) -> Option<Vec<usize>> {
    const FREE: usize = usize::MAX;
    let mut row_of_col = vec![FREE; n];
    let mut visited = vec![usize::MAX; n];
    for start in 0..n {
        // Iterative DFS over rows; `parent_col[r]` is the column through
        // which row r was reached.
        let mut stack: Vec<(usize, usize)> = vec![(start, 0)];
        let mut via: Vec<(usize, usize)> = Vec::new(); // (row, column) path
        let mut found = false;
        visited[start] = start;
        while let Some(&mut (r, ref mut next)) = stack.last_mut() {
            let mut advanced = false;
            while *next < n {
                let c = *next;
                *next += 1;
                if matrix[r * n + c] <= 0.0 {
                    continue;
                }
                let owner = row_of_col[c];
                if owner == FREE {
                    via.push((r, c));
                    found = true;
                    break;
                }
                if visited[owner] != start {
                    visited[owner] = start;
                    via.push((r, c));
                    stack.push((owner, 0));
                    advanced = true;
                    break;
                }
            }
            if found {
                break;
            }
            if !advanced {
                stack.pop();
                via.pop();
            }
        }
        if !found {
            return None;
        }
        // Flip the augmenting path: each (row, column) on it is matched.
        for &(r, c) in &via {
            row_of_col[c] = r;
        }
    }
    Some(row_of_col)
}

/// Strongly connected components (Kosaraju, iterative) of the graph on
/// columns with an edge m(t) → j for each positive entry (t, j).
fn column_components(
    n: usize,
    matrix: &[f64],
    row_of_col: &[usize],
    col_of_row: &[usize],
) -> Vec<usize> {
    // Pass 1: finish order on the graph.
    let mut seen = vec![false; n];
    let mut order = Vec::with_capacity(n);
    for root in 0..n {
        if seen[root] {
            continue;
        }
        seen[root] = true;
        let mut stack = vec![(root, 0usize)];
        while let Some(&mut (c, ref mut next)) = stack.last_mut() {
            let r = row_of_col[c];
            let mut pushed = false;
            while *next < n {
                let j = *next;
                *next += 1;
                if matrix[r * n + j] > 0.0 && !seen[j] {
                    seen[j] = true;
                    stack.push((j, 0));
                    pushed = true;
                    break;
                }
            }
            if !pushed {
                order.push(c);
                stack.pop();
            }
        }
    }
    // Pass 2: components on the reversed graph, in reverse finish order.
    // The predecessors of column j are m(r) for rows r with (r, j) > 0.
    let mut component = vec![usize::MAX; n];
    let mut count = 0;
    for &root in order.iter().rev() {
        if component[root] != usize::MAX {
            continue;
        }
        component[root] = count;
        let mut stack = vec![root];
        while let Some(j) = stack.pop() {
            for r in 0..n {
                let c = col_of_row[r];
                if matrix[r * n + j] > 0.0 && component[c] == usize::MAX {
                    component[c] = count;
                    stack.push(c);
                }
            }
        }
        count += 1;
    }
    component
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::doubly_stochastic_residual;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn scales_positive_matrices() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for n in 1..=12 {
            let m: Vec<Vec<f64>> = (0..n)
                .map(|_| (0..n).map(|_| rng.gen_range(0.01..10.0)).collect())
                .collect();
            let (s, report) = sinkhorn_rows(&m, &SinkhornOptions::default()).unwrap();
            assert!(doubly_stochastic_residual(&s) < 1e-9, "n={n}");
            assert_eq!(report.pruned, 0);
            // Scaling keeps cross ratios: s00·s11/(s01·s10) is invariant.
            if n >= 2 {
                let before = m[0][0] * m[1][1] / (m[0][1] * m[1][0]);
                let after = s[0][0] * s[1][1] / (s[0][1] * s[1][0]);
                assert!((before / after - 1.0).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn prunes_entries_on_no_positive_diagonal() {
        // Row 0 is pinned to column 0 (a perfect read): (1, 0) and (2, 0)
        // lie on no positive diagonal. Plain Sinkhorn would crawl.
        let m = vec![
            vec![1.0, 0.0, 0.0],
            vec![0.3, 0.5, 0.2],
            vec![0.2, 0.2, 0.6],
        ];
        let (s, report) = sinkhorn_rows(&m, &SinkhornOptions::default()).unwrap();
        assert_eq!(report.pruned, 2);
        assert!(doubly_stochastic_residual(&s) < 1e-9);
        assert_eq!(s[1][0], 0.0);
        assert_eq!(s[0][0], 1.0);
        assert!(report.iterations < 100);
    }

    #[test]
    fn refuses_what_cannot_be_scaled() {
        let opts = SinkhornOptions::default();
        // No positive diagonal: two rows can only use column 0.
        let m = vec![
            vec![1.0, 0.0, 0.0],
            vec![1.0, 0.0, 0.0],
            vec![0.2, 0.2, 0.6],
        ];
        assert_eq!(
            sinkhorn_rows(&m, &opts).unwrap_err(),
            BeliefError::Degenerate { normalizer: 0.0 }
        );
        assert!(sinkhorn_rows(&[vec![-1.0]], &opts).is_err());
        assert!(sinkhorn_rows(&[vec![f64::NAN]], &opts).is_err());
        // A cap too small to converge is an error, not a silent answer.
        let hard = vec![vec![1.0, 1e-6], vec![1.0, 1.0]];
        let tight = SinkhornOptions {
            tolerance: 1e-14,
            max_iterations: 2,
        };
        assert!(matches!(
            sinkhorn_rows(&hard, &tight),
            Err(BeliefError::Numerical {
                step: "sinkhorn",
                ..
            })
        ));
        assert!(SinkhornOptions {
            tolerance: 0.0,
            max_iterations: 1
        }
        .validate()
        .is_err());
    }

    #[test]
    fn peaked_matrices_above_the_cholesky_size_converge() {
        // A permutation with pairs mixed and e^-20 elsewhere, n = 450:
        // the shape that stalled plain sweeps. Newton through
        // the Schur complement, and Newton–CG beyond it, converge to the
        // default tolerance.
        for n in [MAX_NEWTON_TRACKS + 50, MAX_SCHUR_TRACKS + 50] {
            peaked_converges(n);
        }
    }

    fn peaked_converges(n: usize) {
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let mut m = vec![(-20f64).exp(); n * n];
        for t in 0..n {
            m[t * n + t] = 1.0;
        }
        for t in (0..n - 1).step_by(3) {
            let x = rng.gen_range(0.01..1.0);
            m[t * n + t + 1] = x;
            m[(t + 1) * n + t] = x;
        }
        let report = sinkhorn(n, &mut m, &SinkhornOptions::default()).unwrap();
        assert!(report.newton_steps > 0, "{report:?}");
        assert!(report.residual <= 1e-10);
        assert!(column_residual(n, &m) < 1e-9);
    }

    #[test]
    fn the_schur_step_is_the_full_newton_step() {
        // Both solve the same 2N × 2N system: from the same start, one
        // step of each lands on the same scaling.
        let n = 30;
        let mut rng = ChaCha8Rng::seed_from_u64(8);
        let mut m: Vec<f64> = (0..n * n)
            .map(|_| {
                if rng.gen_bool(0.3) {
                    rng.gen_range(0.001..1.0)
                } else {
                    0.0
                }
            })
            .collect();
        for t in 0..n {
            m[t * n + t] = 1.0; // a positive diagonal: total support
        }
        let start = |m: &[f64]| {
            let mut a = m.to_vec();
            let pattern = Pattern::of(n, &a);
            let mut logs = LogScaling {
                row: vec![0.0; n],
                col: vec![0.0; n],
            };
            sweep(n, &pattern, &mut a, &mut logs);
            (a, pattern, logs)
        };
        let (mut full, pattern, mut full_logs) = start(&m);
        let (mut schur, _, mut schur_logs) = start(&m);
        assert!(newton_step(n, &pattern, &mut full, &mut full_logs));
        assert!(newton_schur_step(n, &pattern, &mut schur, &mut schur_logs));
        for (a, b) in full.iter().zip(&schur) {
            assert!((a - b).abs() < 1e-9, "{a} vs {b}");
        }
    }
}
