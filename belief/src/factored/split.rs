//! Splitting one table into two by moment matching (an M-projection, the
//! assumed-density step of Boyen–Koller).
//!
//! The merged component M has table g over x ⊆ M, and everything else weighs
//! its red count s through Q(s) (the other components and π), so its part of
//! the belief is P(x) ∝ g(x)·Q(|x|). For a partition M = A ∪ B we look for
//! g_A, g_B with P′(x) ∝ g_A(x_A)·g_B(x_B)·Q(|x_A| + |x_B|) having the same
//! marginals on x_A and on x_B as P: the closest such product in KL(P‖P′).
//!
//! P′(x_A) = g_A(x_A)·H_B(|x_A|) with H_B(r) = Σ_q c_B[q]·Q(r + q), so within
//! a count class g_A must be proportional to P(x_A): g_A(x_A) = P(x_A)·α_r,
//! g_B(x_B) = P(x_B)·β_q, r = |x_A|, q = |x_B|. What is left is a matrix
//! scaling problem on the (|A|+1)×(|B|+1) kernel K[r][q] = Q(r + q): find
//! u_r = p_A[r]·α_r, v_q = p_B[q]·β_q such that diag(u)·K·diag(v) has row
//! sums p_A and column sums p_B (the count marginals of P). Iterative
//! proportional fitting on the tables reduces to Sinkhorn on this kernel, so
//! a sweep costs O(|A|·|B|); the tables are touched once before and once
//! after. The problem is feasible (P's own joint count table is a solution
//! pattern), so Sinkhorn converges; it stops at an L1 error of `tolerance` on
//! the count marginals, which is also the L1 error of P′(x_A) against P(x_A).

use super::table::Component;
use crate::error::BeliefError;
use crate::support::floored;

/// P(x) ∝ g(x)·Q(|x|) over a merged table, with what every projection of it
/// needs.
#[derive(Debug, Clone)]
pub(crate) struct Weighted<'a> {
    merged: &'a Component,
    /// Q scaled against the merged counts (see [`balanced`](super::table::balanced)).
    q: Vec<f64>,
    /// g(x)·Q(|x|).
    w: Vec<f64>,
    total: f64,
}

/// The two halves of a split and how good it is.
#[derive(Debug, Clone)]
pub(crate) struct Projection {
    pub(crate) a: Component,
    pub(crate) b: Component,
    pub(crate) sweeps: usize,
}

/// pext: the bits of x selected by `mask`, packed low.
fn gather(x: usize, mask: usize) -> usize {
    let (mut out, mut bit, mut m) = (0usize, 0, mask);
    while m != 0 {
        let low = m & m.wrapping_neg();
        if x & low != 0 {
            out |= 1 << bit;
        }
        bit += 1;
        m ^= low;
    }
    out
}

/// Lookup tables so that gather(x, mask) = low[x & lo_mask] + high[x >> half].
struct Gather {
    half: usize,
    low: Vec<usize>,
    high: Vec<usize>,
}

impl Gather {
    fn new(mask: usize, bits: usize) -> Self {
        let half = bits / 2;
        let lo_mask = (1usize << half) - 1;
        let shift = (mask & lo_mask).count_ones();
        let low = (0..1usize << half)
            .map(|x| gather(x, mask & lo_mask))
            .collect();
        let high = (0..1usize << (bits - half))
            .map(|x| gather(x, mask >> half) << shift)
            .collect();
        Gather { half, low, high }
    }
}

/// Calls visit(x, index in A, index in B) for every x over `bits` bits.
fn for_each_split(bits: usize, part_a: usize, mut visit: impl FnMut(usize, usize, usize)) {
    let part_b = ((1usize << bits) - 1) & !part_a;
    let ga = Gather::new(part_a, bits);
    let gb = Gather::new(part_b, bits);
    let lows = ga.low.len();
    for (h, (&ha, &hb)) in ga.high.iter().zip(&gb.high).enumerate() {
        let base = h << ga.half;
        for l in 0..lows {
            visit(base + l, ha + ga.low[l], hb + gb.low[l]);
        }
    }
    debug_assert_eq!(ga.half, gb.half);
}

impl<'a> Weighted<'a> {
    /// `q[s]` for s = 0..=|M|, the weight of the merged red count.
    pub(crate) fn new(merged: &'a Component, q: &[f64]) -> Result<Self, BeliefError> {
        debug_assert_eq!(q.len(), merged.len() + 1);
        let q = super::table::balanced(&merged.counts, q);
        let w: Vec<f64> = merged
            .table
            .iter()
            .enumerate()
            .map(|(x, &g)| g * q[x.count_ones() as usize])
            .collect();
        let total: f64 = w.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return Err(BeliefError::Degenerate { normalizer: total });
        }
        Ok(Weighted {
            merged,
            q,
            w,
            total,
        })
    }

    /// The M-projection onto A = the local bits in `part_a` and B = the
    /// rest: at most `max_sweeps` Sinkhorn sweeps, then Newton steps. Fails
    /// with [`BeliefError::Numerical`] if the marginals are not matched to
    /// `tolerance` in the end.
    pub(crate) fn project(
        &self,
        part_a: usize,
        tolerance: f64,
        max_sweeps: usize,
    ) -> Result<Projection, BeliefError> {
        let bits = self.merged.len();
        let part_b = ((1usize << bits) - 1) & !part_a;
        debug_assert!(part_a.count_ones() > 0 && part_b.count_ones() > 0);
        let (pa, pb) = self.marginals(part_a);
        let tracks_of = |mask: usize| -> Vec<u32> {
            (0..bits)
                .filter(|b| mask & (1 << b) != 0)
                .map(|b| self.merged.tracks[b])
                .collect()
        };
        let log_mass = self.merged.log_scale + self.total.ln();
        let (a, b, sweeps) = fit(
            pa,
            pb,
            tracks_of(part_a),
            tracks_of(part_b),
            &self.q,
            log_mass,
            tolerance,
            max_sweeps,
        )?;
        Ok(Projection { a, b, sweeps })
    }
}

impl Weighted<'_> {
    /// KL(P‖P′) in nats of a projection along `part_a` (the reference the
    /// ranking by [`loss`](Weighted::loss) is tested against).
    #[cfg(test)]
    pub(crate) fn kl(&self, projection: &Projection, part_a: usize) -> f64 {
        let (a, b) = (&projection.a, &projection.b);
        let bits = self.merged.len();
        let (ln_t, ln_s) = (self.total.ln(), ln_pair_mass(&a.counts, &b.counts, &self.q));
        let mut kl = 0.0;
        for_each_split(bits, part_a, |x, ia, ib| {
            let w = self.w[x];
            if w > 0.0 {
                let p = w.ln() - ln_t;
                let p_prime =
                    (a.table[ia] * b.table[ib] * self.q[x.count_ones() as usize]).ln() - ln_s;
                kl += (w / self.total) * (p - p_prime);
            }
        });
        kl.max(0.0)
    }
    /// The marginal tables of P on x_A (A = the bits of `part_a`) and on
    /// x_B (the rest), normalized.
    fn marginals(&self, part_a: usize) -> (Vec<f64>, Vec<f64>) {
        let bits = self.merged.len();
        let na = part_a.count_ones() as usize;
        let mut pa = vec![0.0; 1 << na];
        let mut pb = vec![0.0; 1 << (bits - na)];
        for_each_split(bits, part_a, |x, ia, ib| {
            pa[ia] += self.w[x];
            pb[ib] += self.w[x];
        });
        for p in pa.iter_mut().chain(pb.iter_mut()) {
            *p /= self.total;
        }
        (pa, pb)
    }

    /// What the split along `part_a` loses: KL(P‖P′) less a constant of
    /// the merged table (−H(P) − E_P[ln Q], the same for every partition),
    /// so that partitions rank as their KL does. P′ keeps P's marginals on
    /// x_A and x_B, so E_P[ln P′] needs only those two tables:
    /// Σ p_A·ln g_A + Σ p_B·ln g_B − ln S′. No pass over the merged table
    /// beyond the marginals, and none of its logarithms.
    pub(crate) fn loss(
        &self,
        part_a: usize,
        tolerance: f64,
        max_sweeps: usize,
    ) -> Result<f64, BeliefError> {
        let (pa, pb) = self.marginals(part_a);
        loss_of(&pa, &pb, &self.q, tolerance, max_sweeps)
    }

    /// The exchange of one track of A = `part_a` with one of the rest that
    /// loses least, as (the new A, its [`loss`](Weighted::loss)). Every
    /// exchange's marginals come from the tables P(x_A, x_j) for j outside
    /// A and P(x_B, x_i) for i in A, all gathered in one pass over the
    /// merged table: |M| additions per entry instead of a pass per
    /// exchange.
    pub(crate) fn best_exchange(
        &self,
        part_a: usize,
        tolerance: f64,
        max_sweeps: usize,
    ) -> Result<Option<(usize, f64)>, BeliefError> {
        let bits = self.merged.len();
        let all = (1usize << bits) - 1;
        let part_b = all & !part_a;
        let in_a: Vec<usize> = (0..bits).filter(|b| part_a & (1 << b) != 0).collect();
        let in_b: Vec<usize> = (0..bits).filter(|b| part_b & (1 << b) != 0).collect();
        let (na, nb) = (in_a.len(), in_b.len());
        let mut with_b = vec![vec![0.0; 2 << na]; nb];
        let mut with_a = vec![vec![0.0; 2 << nb]; na];
        for_each_split(bits, part_a, |x, ia, ib| {
            let w = self.w[x];
            if w == 0.0 {
                return;
            }
            for (joint, &j) in with_b.iter_mut().zip(&in_b) {
                joint[ia | ((x >> j) & 1) << na] += w;
            }
            for (joint, &i) in with_a.iter_mut().zip(&in_a) {
                joint[ib | ((x >> i) & 1) << nb] += w;
            }
        });
        let mut best: Option<(usize, f64)> = None;
        for (joint_b, &i) in with_a.iter().zip(&in_a) {
            for (joint_a, &j) in with_b.iter().zip(&in_b) {
                let new_a = part_a ^ (1 << i) ^ (1 << j);
                let pa = regroup(joint_a, part_a, i, j, self.total);
                let pb = regroup(joint_b, part_b, j, i, self.total);
                let loss = loss_of(&pa, &pb, &self.q, tolerance, max_sweeps)?;
                if best.is_none_or(|(_, l)| loss < l) {
                    best = Some((new_a, loss));
                }
            }
        }
        Ok(best)
    }
}

/// [`Weighted::loss`] from the two marginal tables.
fn loss_of(
    pa: &[f64],
    pb: &[f64],
    q: &[f64],
    tolerance: f64,
    max_sweeps: usize,
) -> Result<f64, BeliefError> {
    let (na, nb) = (
        pa.len().trailing_zeros() as usize,
        pb.len().trailing_zeros() as usize,
    );
    let count_a = super::table::counts_of(pa, na);
    let count_b = super::table::counts_of(pb, nb);
    let (alpha, beta, _) = scale_counts(q, &count_a, &count_b, tolerance, max_sweeps)?;
    let entropy: f64 = pa
        .iter()
        .chain(pb)
        .filter(|&&p| p > 0.0)
        .map(|&p| p * p.ln())
        .sum();
    let scaled = |c: &[f64], s: &[f64]| -> (f64, Vec<f64>) {
        let terms = c
            .iter()
            .zip(s)
            .filter(|(&c, _)| c > 0.0)
            .map(|(&c, &s)| c * s.ln())
            .sum();
        (terms, c.iter().zip(s).map(|(c, s)| c * s).collect())
    };
    let (terms_a, weighed_a) = scaled(&count_a, &alpha);
    let (terms_b, weighed_b) = scaled(&count_b, &beta);
    let loss = ln_pair_mass(&weighed_a, &weighed_b, q) - entropy - terms_a - terms_b;
    // A split whose scaling ran off to infinity ranks last.
    Ok(if loss.is_nan() { f64::INFINITY } else { loss })
}

/// A joint table over (x_S, x_t) — the bits of `set` packed low in their
/// order, the bit `extra` on top — summed over the bit `leaving` of S onto
/// the table of S − {leaving} + {extra} in its own bit order, divided by
/// `total`.
fn regroup(joint: &[f64], set: usize, leaving: usize, extra: usize, total: f64) -> Vec<f64> {
    let n = set.count_ones() as usize;
    let below = |bit: usize| (set & ((1usize << bit) - 1)).count_ones() as usize;
    // Where the leaving bit sits among S's, and where the new one lands
    // among the bits that stay.
    let out_at = below(leaving);
    let in_at = below(extra) - usize::from(leaving < extra);
    let low_mask = (1usize << n) - 1;
    let mut out = vec![0.0; joint.len() / 2];
    for (z, &p) in joint.iter().enumerate() {
        let (low, top) = (z & low_mask, z >> n);
        let kept = (low & ((1 << out_at) - 1)) | ((low >> (out_at + 1)) << out_at);
        let y = (kept & ((1 << in_at) - 1)) | (top << in_at) | ((kept >> in_at) << (in_at + 1));
        out[y] += p / total;
    }
    out
}

/// ln Σ_{r,q} c_A[r]·c_B[q]·Q(r + q), summed in log space: each factor is
/// scaled to its own vector, and their products can underflow where the
/// sum's terms do not all.
fn ln_pair_mass(ca: &[f64], cb: &[f64], q: &[f64]) -> f64 {
    let terms = ca.iter().enumerate().flat_map(|(r, &x)| {
        cb.iter()
            .enumerate()
            .filter(move |(s, &y)| x > 0.0 && y > 0.0 && q[r + s] > 0.0)
            .map(move |(s, &y)| x.ln() + y.ln() + q[r + s].ln())
    });
    ln_sum_exp(terms)
}

/// The two tables of the projection whose marginals are `pa` over
/// `tracks_a` and `pb` over `tracks_b` (each normalized), under the count
/// weight `q`; `log_mass` = ln of the mass e^L·Σ g·Q the pair must keep.
#[allow(clippy::too_many_arguments)]
pub(crate) fn fit(
    pa: Vec<f64>,
    pb: Vec<f64>,
    tracks_a: Vec<u32>,
    tracks_b: Vec<u32>,
    q: &[f64],
    log_mass: f64,
    tolerance: f64,
    max_sweeps: usize,
) -> Result<(Component, Component, usize), BeliefError> {
    let (na, nb) = (tracks_a.len(), tracks_b.len());
    let count_a = super::table::counts_of(&pa, na);
    let count_b = super::table::counts_of(&pb, nb);
    let (alpha, beta, sweeps) = scale_counts(q, &count_a, &count_b, tolerance, max_sweeps)?;
    let mut ga = pa;
    for (y, g) in ga.iter_mut().enumerate() {
        *g = floored(*g, alpha[y.count_ones() as usize]);
    }
    let mut gb = pb;
    for (y, g) in gb.iter_mut().enumerate() {
        *g = floored(*g, beta[y.count_ones() as usize]);
    }
    let ln_s_prime = ln_pair_mass(
        &super::table::counts_of(&ga, na),
        &super::table::counts_of(&gb, nb),
        q,
    );
    let a = Component::from_table(tracks_a, ga, log_mass - ln_s_prime)?;
    let b = Component::from_table(tracks_b, gb, 0.0)?;
    Ok((a, b, sweeps))
}

/// One side of [`mixed_pair_marginals`]: P(x_1) (unnormalized) for the
/// table `g1` whose bit `i1` mixed with a bit of the other component, whose
/// count vectors split by that bit are `other[0]` (bit clear) and
/// `other[1]` (bit set), as (p, ln s): P(x_1) = p[x_1]·s, p's largest
/// entry about 1.
fn mixed_side(
    g1: &[f64],
    bits: usize,
    i1: usize,
    other: &[Vec<f64>; 2],
    swap: f64,
    q: &[f64],
) -> (Vec<f64>, f64) {
    let top = q.len() as isize;
    // ln Q(s), −∞ outside the counts the pair can hold.
    let ln_at = |s: isize| {
        if (0..top).contains(&s) {
            q[s as usize].ln()
        } else {
            f64::NEG_INFINITY
        }
    };
    // ln h[r], h[r] = Σ_q c[q]·Q(r + q + shift) for a count vector c, summed
    // in log space: the two tables and Q are each scaled to their own
    // largest entry, and where Q favours counts the tables hold only
    // faintly (both 10^-200 apart, after contradicting sightings) the
    // products of three would underflow to 0 though their ratios are fine.
    let weigh = |c: &[f64], shift: isize| -> Vec<f64> {
        (0..=bits)
            .map(|r| {
                ln_sum_exp(
                    c.iter()
                        .enumerate()
                        .filter(|(_, &x)| x > 0.0)
                        .map(|(s, &x)| x.ln() + ln_at(r as isize + s as isize + shift)),
                )
            })
            .collect()
    };
    let all: Vec<f64> = other[0].iter().zip(&other[1]).map(|(x, y)| x + y).collect();
    let h = weigh(&all, 0);
    // The part of the other side that trades with a set whose bit is α
    // holds the other bit 1 − α; it came from (or goes to) a set of the
    // other side with bit α, one red track more (α = 0) or fewer.
    let trade = [weigh(&other[1], 0), weigh(&other[0], 0)];
    let image = [weigh(&other[0], 1), weigh(&other[1], -1)];
    // One scale per count r for all five, so that h − swap·trade subtracts
    // numbers of one scale, as before.
    let scale: Vec<f64> = (0..=bits)
        .map(|r| {
            let m = [h[r], trade[0][r], trade[1][r], image[0][r], image[1][r]]
                .into_iter()
                .fold(f64::NEG_INFINITY, f64::max);
            if m.is_finite() {
                m
            } else {
                0.0
            }
        })
        .collect();
    let scaled = |v: &[f64], r: usize| (v[r] - scale[r]).exp();
    let e = 1usize << i1;
    let bracket: Vec<f64> = (0..g1.len())
        .map(|x| {
            let r = x.count_ones() as usize;
            let alpha = usize::from(x & e != 0);
            g1[x] * (scaled(&h, r) - swap * scaled(&trade[alpha], r))
                + swap * g1[x ^ e] * scaled(&image[alpha], r)
        })
        .collect();
    // P(x_1) = bracket·e^{scale[r]}: brought to a largest entry of about 1.
    let top = bracket
        .iter()
        .enumerate()
        .filter(|(_, &b)| b > 0.0)
        .map(|(x, &b)| b.ln() + scale[x.count_ones() as usize])
        .fold(f64::NEG_INFINITY, f64::max);
    if !top.is_finite() {
        return (vec![0.0; g1.len()], 0.0);
    }
    let p = bracket
        .iter()
        .enumerate()
        .map(|(x, &b)| b * (scale[x.count_ones() as usize] - top).exp())
        .collect();
    (p, top)
}

fn ln_sum_exp(terms: impl Iterator<Item = f64> + Clone) -> f64 {
    let max = terms.clone().fold(f64::NEG_INFINITY, f64::max);
    if max == f64::NEG_INFINITY {
        return max;
    }
    max + terms.map(|t| (t - max).exp()).sum::<f64>().ln()
}

/// Count vectors of a table split by one bit: [bit clear, bit set].
fn split_counts(table: &[f64], bits: usize, bit: usize) -> [Vec<f64>; 2] {
    let mut out = [vec![0.0; bits + 1], vec![0.0; bits + 1]];
    for (y, &g) in table.iter().enumerate() {
        out[(y >> bit) & 1][y.count_ones() as usize] += g;
    }
    out
}

/// The marginal tables P(x_1), P(x_2) (normalized) and ln T, T = Σ g′·Q the mass
/// of the merged model right after a mix of bit `i1` of `c1` with bit `i2`
/// of `c2`, without building the 2^(|C1|+|C2|) table: the rolled-up table
/// is g1·g2 except where the two bits differ, where a share `swap` of the
/// weight moves to the image with both bits flipped (same red count), so
/// each marginal needs only the other side's count vectors split by its
/// mixed bit. O(2^|C1| + 2^|C2| + |C1|·|C2|).
pub(crate) fn mixed_pair_marginals(
    c1: &Component,
    i1: usize,
    c2: &Component,
    i2: usize,
    swap: f64,
    q: &[f64],
) -> Result<(Vec<f64>, Vec<f64>, f64), BeliefError> {
    let split1 = split_counts(&c1.table, c1.len(), i1);
    let split2 = split_counts(&c2.table, c2.len(), i2);
    let (mut p1, ln_scale) = mixed_side(&c1.table, c1.len(), i1, &split2, swap, q);
    let (mut p2, _) = mixed_side(&c2.table, c2.len(), i2, &split1, swap, q);
    let total: f64 = p1.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return Err(BeliefError::Degenerate { normalizer: total });
    }
    let total2: f64 = p2.iter().sum();
    for p in &mut p1 {
        *p = (*p / total).max(0.0);
    }
    for p in &mut p2 {
        *p = (*p / total2).max(0.0);
    }
    Ok((p1, p2, total.ln() + ln_scale))
}

/// Count-space IPF: α_r, β_q such that J[r][q] = p_A[r]·α_r·K[r][q]·β_q·p_B[q],
/// K[r][q] = Q(r + q), has row sums p_A and column sums p_B to `tolerance`
/// (L1 over both). Returns (α, β, iterations).
///
/// Sinkhorn sweeps first (`max_sweeps` at most). They converge linearly when
/// the solution is interior, but only as O(1/t) when it lies at infinity:
/// when the merged table's own count support is narrower than Q allows (a
/// mix of a certain track, say), every matrix with these margins has zeros
/// where K has none, and the product family reaches them only in the limit.
/// Then a damped Newton method on the convex dual
/// F(x, y) = Σ K[r][q]·e^{x_r + y_q} − Σ p_A·x − Σ p_B·y finishes the job:
/// along an escape direction F behaves like e^{−t} and Newton steps by a
/// constant, so the error falls geometrically.
fn scale_counts(
    q: &[f64],
    pa: &[f64],
    pb: &[f64],
    tolerance: f64,
    max_sweeps: usize,
) -> Result<(Vec<f64>, Vec<f64>, usize), BeliefError> {
    let k = |r: usize, s: usize| q[r + s];
    let mut u = vec![0.0; pa.len()];
    let mut v: Vec<f64> = pb
        .iter()
        .map(|&p| if p > 0.0 { 1.0 } else { 0.0 })
        .collect();
    let infeasible = |what: &str| BeliefError::Numerical {
        step: "factored split",
        detail: format!("the count marginal of {what} is not reachable under the count weights"),
    };
    let mut sweeps = 0;
    let mut err = f64::INFINITY;
    let times_v =
        |v: &[f64], r: usize| -> f64 { v.iter().enumerate().map(|(s, &vs)| k(r, s) * vs).sum() };
    // K·v of the current v: the next u's denominator and this sweep's
    // error on the rows, computed once for both.
    let mut kv: Vec<f64> = (0..pa.len()).map(|r| times_v(&v, r)).collect();
    while sweeps < max_sweeps {
        sweeps += 1;
        for (r, ur) in u.iter_mut().enumerate() {
            *ur = if pa[r] > 0.0 {
                if !(kv[r] > 0.0 && kv[r].is_finite()) {
                    return Err(infeasible("A"));
                }
                pa[r] / kv[r]
            } else {
                0.0
            };
        }
        // v from u: the columns match exactly; the rows are off by `err`.
        for (s, vs) in v.iter_mut().enumerate() {
            let ku: f64 = u.iter().enumerate().map(|(r, &ur)| k(r, s) * ur).sum();
            *vs = if pb[s] > 0.0 {
                if !(ku > 0.0 && ku.is_finite()) {
                    return Err(infeasible("B"));
                }
                pb[s] / ku
            } else {
                0.0
            };
        }
        for (r, kr) in kv.iter_mut().enumerate() {
            *kr = times_v(&v, r);
        }
        err = u
            .iter()
            .zip(&kv)
            .zip(pa)
            .map(|((&ur, &kr), &p)| (ur * kr - p).abs())
            .sum();
        if err <= tolerance {
            break;
        }
    }
    let (mut x, mut y): (Vec<f64>, Vec<f64>) = (
        u.iter().map(|v| v.ln()).collect(),
        v.iter().map(|v| v.ln()).collect(),
    );
    let mut iterations = sweeps;
    if err.is_nan() || err > tolerance {
        iterations += newton(q, pa, pb, &mut x, &mut y, tolerance)?;
    }
    let alpha = x
        .iter()
        .zip(pa)
        .map(|(&x, &p)| if p > 0.0 { x.exp() / p } else { 0.0 })
        .collect();
    let beta = y
        .iter()
        .zip(pb)
        .map(|(&y, &p)| if p > 0.0 { y.exp() / p } else { 0.0 })
        .collect();
    Ok((alpha, beta, iterations))
}

/// Most Newton steps before giving up.
const MAX_NEWTON: usize = 200;

/// Damped Newton on the dual of the scaling problem, from (x, y) = (ln u,
/// ln v); rows and columns with zero target stay at −∞. The last live
/// column is held fixed (the gauge x + c, y − c changes nothing).
fn newton(
    q: &[f64],
    pa: &[f64],
    pb: &[f64],
    x: &mut [f64],
    y: &mut [f64],
    tolerance: f64,
) -> Result<usize, BeliefError> {
    use nalgebra::{DMatrix, DVector};
    let rows: Vec<usize> = (0..pa.len()).filter(|&r| pa[r] > 0.0).collect();
    let cols: Vec<usize> = (0..pb.len()).filter(|&s| pb[s] > 0.0).collect();
    let free_cols = &cols[..cols.len() - 1];
    let dim = rows.len() + free_cols.len();
    let lnk: Vec<f64> = q.iter().map(|v| v.ln()).collect();
    // J, its margins, and F at (x, y).
    let eval = |x: &[f64], y: &[f64]| {
        let mut j = vec![vec![0.0; pb.len()]; pa.len()];
        let mut f = 0.0;
        for &r in &rows {
            for &s in &cols {
                let e = (lnk[r + s] + x[r] + y[s]).exp();
                j[r][s] = e;
                f += e;
            }
            f -= pa[r] * x[r];
        }
        for &s in &cols {
            f -= pb[s] * y[s];
        }
        (j, f)
    };
    let margins_error = |j: &[Vec<f64>]| -> (Vec<f64>, Vec<f64>, f64) {
        let rs: Vec<f64> = j.iter().map(|row| row.iter().sum()).collect();
        let cs: Vec<f64> = (0..pb.len())
            .map(|s| j.iter().map(|row| row[s]).sum())
            .collect();
        let err = rs.iter().zip(pa).map(|(a, b)| (a - b).abs()).sum::<f64>()
            + cs.iter().zip(pb).map(|(a, b)| (a - b).abs()).sum::<f64>();
        (rs, cs, err)
    };
    let (mut j, mut f) = eval(x, y);
    for step in 1..=MAX_NEWTON {
        let (rs, cs, err) = margins_error(&j);
        if err <= tolerance {
            return Ok(step - 1);
        }
        if !f.is_finite() {
            break;
        }
        let mut grad = DVector::zeros(dim);
        let mut hess = DMatrix::zeros(dim, dim);
        for (i, &r) in rows.iter().enumerate() {
            grad[i] = rs[r] - pa[r];
            hess[(i, i)] = rs[r];
            for (l, &s) in free_cols.iter().enumerate() {
                hess[(i, rows.len() + l)] = j[r][s];
                hess[(rows.len() + l, i)] = j[r][s];
            }
        }
        for (l, &s) in free_cols.iter().enumerate() {
            grad[rows.len() + l] = cs[s] - pb[s];
            hess[(rows.len() + l, rows.len() + l)] = cs[s];
        }
        // A whisper of damping keeps the system solvable when some
        // directions have (numerically) no curvature left.
        let mut lambda = 1e-16;
        let dir = loop {
            let mut h = hess.clone();
            for i in 0..dim {
                h[(i, i)] += lambda;
            }
            if let Some(ch) = h.cholesky() {
                break -ch.solve(&grad);
            }
            lambda *= 100.0;
            if lambda > 1.0 {
                break -grad.clone();
            }
        };
        let slope = grad.dot(&dir);
        let mut t = 1.0;
        let mut moved = false;
        for _ in 0..80 {
            let (mut nx, mut ny) = (x.to_vec(), y.to_vec());
            for (i, &r) in rows.iter().enumerate() {
                nx[r] += t * dir[i];
            }
            for (l, &s) in free_cols.iter().enumerate() {
                ny[s] += t * dir[rows.len() + l];
            }
            let (nj, nf) = eval(&nx, &ny);
            // Near the end F moves by less than its rounding; then the step
            // must shrink the margin error instead.
            let flat = (nf - f).abs() <= 1e-13 * (1.0 + f.abs());
            if nf.is_finite()
                && (nf <= f + 1e-4 * t * slope || (flat && margins_error(&nj).2 < err))
            {
                x.copy_from_slice(&nx);
                y.copy_from_slice(&ny);
                (j, f) = (nj, nf);
                moved = true;
                break;
            }
            t /= 2.0;
        }
        if !moved {
            break;
        }
    }
    let (_, _, err) = margins_error(&j);
    if err <= tolerance {
        return Ok(MAX_NEWTON);
    }
    Err(BeliefError::Numerical {
        step: "factored split",
        detail: format!(
            "moment matching did not converge: L1 error {err:e} on the count marginals"
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn gather_packs_selected_bits() {
        assert_eq!(gather(0b1011, 0b1010), 0b11);
        assert_eq!(gather(0b0100, 0b1110), 0b010);
        let g = Gather::new(0b10110, 5);
        for x in 0..32 {
            assert_eq!(g.low[x & 0b11] + g.high[x >> 2], gather(x, 0b10110));
        }
    }

    fn marginal(table: &[f64], q: &[f64], bits: usize, part: usize) -> Vec<f64> {
        let mut out = vec![0.0; 1 << part.count_ones()];
        let mut total = 0.0;
        for x in 0..1usize << bits {
            let w = table[x] * q[x.count_ones() as usize];
            out[gather(x, part)] += w;
            total += w;
        }
        out.iter().map(|v| v / total).collect()
    }

    /// The projection keeps both marginal tables of P(x) ∝ g(x)·Q(|x|).
    #[test]
    fn projection_preserves_both_marginals_on_random_tables() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for case in 0..200 {
            let bits = rng.gen_range(2..=9);
            let table: Vec<f64> = (0..1 << bits)
                .map(|_| {
                    if rng.gen::<f64>() < 0.1 {
                        0.0
                    } else {
                        rng.gen()
                    }
                })
                .collect();
            let mut q: Vec<f64> = (0..=bits).map(|_| rng.gen::<f64>()).collect();
            if case % 3 == 0 {
                // A count window, as with k known.
                let lo = rng.gen_range(0..=bits);
                for (s, x) in q.iter_mut().enumerate() {
                    if s < lo || s > lo + 2 {
                        *x = 0.0;
                    }
                }
            }
            let tracks: Vec<u32> = (0..bits as u32).collect();
            let Ok(merged) = Component::from_table(tracks, table, 0.0) else {
                continue;
            };
            let Ok(weighted) = Weighted::new(&merged, &q) else {
                continue;
            };
            let part_a = rng.gen_range(1..(1usize << bits) - 1);
            let part_b = ((1 << bits) - 1) & !part_a;
            let p = weighted.project(part_a, 1e-12, 100_000).unwrap();
            // Rebuild P′ over the merged order.
            let mut prime = vec![0.0; 1 << bits];
            for (x, v) in prime.iter_mut().enumerate() {
                *v = p.a.table[gather(x, part_a)] * p.b.table[gather(x, part_b)];
            }
            for (want, got) in [
                (
                    marginal(&merged.table, &q, bits, part_a),
                    marginal(&prime, &q, bits, part_a),
                ),
                (
                    marginal(&merged.table, &q, bits, part_b),
                    marginal(&prime, &q, bits, part_b),
                ),
            ] {
                for (x, y) in want.iter().zip(&got) {
                    assert!((x - y).abs() < 1e-9, "case {case}: {want:?} vs {got:?}");
                }
            }
            assert!(weighted.kl(&p, part_a) >= 0.0);
            // The mass the component contributes is kept.
            let mass = |t: &[f64], ln: f64| {
                ln + t
                    .iter()
                    .enumerate()
                    .map(|(x, g)| g * q[x.count_ones() as usize])
                    .sum::<f64>()
                    .ln()
            };
            let before = mass(&merged.table, merged.log_scale);
            let after = mass(&prime, p.a.log_scale + p.b.log_scale);
            assert!((before - after).abs() < 1e-9, "case {case}");
        }
    }

    /// The closed-form marginals after a mix across two components equal
    /// those of the materialized merged table, and so does the split.
    #[test]
    fn mixed_pair_marginals_match_the_merged_table() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for case in 0..300 {
            let (n1, n2) = (rng.gen_range(1..=5), rng.gen_range(1..=5));
            let mut table = |n: usize| -> Vec<f64> {
                (0..1 << n)
                    .map(|_| {
                        if rng.gen::<f64>() < 0.15 {
                            0.0
                        } else {
                            rng.gen()
                        }
                    })
                    .collect()
            };
            let (t1, t2) = (table(n1), table(n2));
            let Ok(c1) = Component::from_table((0..n1 as u32).collect(), t1, 0.3) else {
                continue;
            };
            let Ok(c2) = Component::from_table((10..10 + n2 as u32).collect(), t2, -1.1) else {
                continue;
            };
            let mut q: Vec<f64> = (0..=n1 + n2).map(|_| rng.gen::<f64>()).collect();
            if case % 2 == 0 {
                let lo = rng.gen_range(0..=n1 + n2);
                for (s, x) in q.iter_mut().enumerate() {
                    if s < lo || s > lo + 1 {
                        *x = 0.0;
                    }
                }
            }
            let (i1, i2) = (rng.gen_range(0..n1), rng.gen_range(0..n2));
            let swap = [0.5, 1.0, rng.gen::<f64>()][case % 3];
            let mut merged = c1.outer(&c2);
            merged.rollup(i1, n1 + i2, swap);
            let Ok(weighted) = Weighted::new(&merged, &q) else {
                assert!(mixed_pair_marginals(&c1, i1, &c2, i2, swap, &q).is_err());
                continue;
            };
            let (p1, p2, ln_total) = mixed_pair_marginals(&c1, i1, &c2, i2, swap, &q).unwrap();
            let total = ln_total.exp();
            let low = (1usize << n1) - 1;
            let (want1, want2) = (
                marginal(&merged.table, &q, n1 + n2, low),
                marginal(&merged.table, &q, n1 + n2, !low & ((1 << (n1 + n2)) - 1)),
            );
            for (x, y) in p1.iter().zip(&want1).chain(p2.iter().zip(&want2)) {
                assert!((x - y).abs() < 1e-12, "case {case}: {p1:?} vs {want1:?}");
            }
            assert!((total - weighted.total).abs() < 1e-12 * weighted.total);
            let Ok(slow) = weighted.project(low, 1e-12, 200) else {
                continue;
            };
            let log_mass = c1.log_scale + c2.log_scale + total.ln();
            let (a, b, _) = fit(
                p1,
                p2,
                c1.tracks.clone(),
                c2.tracks.clone(),
                &q,
                log_mass,
                1e-12,
                200,
            )
            .unwrap();
            for (x, y) in a.table.iter().zip(&slow.a.table) {
                assert!((x - y).abs() < 1e-9, "case {case}");
            }
            for (x, y) in b.table.iter().zip(&slow.b.table) {
                assert!((x - y).abs() < 1e-9, "case {case}");
            }
            // Both keep the mass e^L·Σ g·Q of the merged table.
            let mass = |a: &Component, b: &Component| {
                a.log_scale + b.log_scale + ln_pair_mass(&a.counts, &b.counts, &q)
            };
            assert!((mass(&a, &b) - log_mass).abs() < 1e-9, "case {case}");
            assert!(
                (mass(&slow.a, &slow.b) - log_mass).abs() < 1e-9,
                "case {case}"
            );
        }
    }

    /// The loss ranks partitions as KL(P‖P′) does: it differs from the KL
    /// by one constant of the merged table, and the best exchange found
    /// from the joint tables is the best of trying each exchange.
    #[test]
    fn loss_ranks_partitions_as_their_kl_and_finds_the_best_exchange() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for case in 0..120 {
            let bits = rng.gen_range(3..=9);
            let table: Vec<f64> = (0..1 << bits)
                .map(|_| {
                    if rng.gen::<f64>() < 0.1 {
                        0.0
                    } else {
                        rng.gen()
                    }
                })
                .collect();
            let q: Vec<f64> = if case % 2 == 0 {
                (0..=bits).map(|_| rng.gen::<f64>() + 0.01).collect()
            } else {
                // k known: one count, as a window of the field's counts.
                let k = rng.gen_range(1..bits);
                (0..=bits).map(|s| f64::from(u8::from(s == k))).collect()
            };
            let tracks: Vec<u32> = (0..bits as u32).collect();
            let Ok(merged) = Component::from_table(tracks, table, 0.0) else {
                continue;
            };
            let Ok(weighted) = Weighted::new(&merged, &q) else {
                continue;
            };
            let all = (1usize << bits) - 1;
            let a_size = rng.gen_range(1..bits);
            let part_a =
                (0..a_size).fold(0usize, |m, b| m | 1 << b) << rng.gen_range(0..=bits - a_size);
            let both = |part: usize| -> Option<(f64, f64)> {
                let p = weighted.project(part, 1e-12, 100_000).ok()?;
                let loss = weighted.loss(part, 1e-12, 100_000).ok()?;
                Some((weighted.kl(&p, part), loss))
            };
            let Some((kl0, loss0)) = both(part_a) else {
                continue;
            };
            let constant = kl0 - loss0;
            let mut brute: Option<(usize, f64)> = None;
            for i in (0..bits).filter(|i| part_a & (1 << i) != 0) {
                for j in (0..bits).filter(|j| part_a & (1 << j) == 0) {
                    let part = part_a ^ (1 << i) ^ (1 << j);
                    let Some((kl, loss)) = both(part) else {
                        continue;
                    };
                    assert!(
                        (kl - loss - constant).abs() < 1e-8,
                        "case {case}: part {part:b}: KL {kl} vs loss {loss} + {constant}"
                    );
                    if brute.is_none_or(|(_, l)| kl < l) {
                        brute = Some((part, kl));
                    }
                }
            }
            let (part, loss) = weighted
                .best_exchange(part_a, 1e-12, 100_000)
                .unwrap()
                .unwrap();
            let (_, kl) = brute.unwrap();
            assert!(part & !all == 0 && part.count_ones() as usize == a_size);
            assert!(
                (loss + constant - kl).abs() < 1e-8,
                "case {case}: best exchange loses {} against {kl}",
                loss + constant
            );
        }
    }

    /// A product table is its own projection, with KL 0.
    #[test]
    fn a_product_is_a_fixed_point() {
        let a = Component::from_table(vec![0, 1], vec![0.1, 0.2, 0.3, 0.4], 0.0).unwrap();
        let b = Component::from_table(vec![2, 3], vec![0.4, 0.1, 0.3, 0.2], 0.0).unwrap();
        let merged = a.outer(&b);
        let q = [0.0, 0.5, 1.0, 0.7, 0.0];
        let weighted = Weighted::new(&merged, &q).unwrap();
        let p = weighted.project(0b0011, 1e-12, 1000).unwrap();
        assert!(weighted.kl(&p, 0b0011).abs() < 1e-12);
        for (x, y) in p.a.table.iter().zip(&a.table) {
            assert!((x - y).abs() < 1e-9);
        }
        for (x, y) in p.b.table.iter().zip(&b.table) {
            assert!((x - y).abs() < 1e-9);
        }
    }
}
