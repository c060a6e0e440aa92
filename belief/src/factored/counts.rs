//! The count coupling between components.
//!
//! The belief is P(x) ∝ Π_C g_C(x ∩ C) · π(|x|). Component C enters the
//! coupling only through its count vector c_C[r] = Σ_{|y| = r} g_C(y), so
//! - the normalizer is Z = Σ_s π(s)·(⊛_C c_C)[s], and
//! - the weight a component's own red count r gets from everything else is
//!   R_{−C}(r) = Σ_s π(s)·(⊛_{C' ≠ C} c_{C'})[s − r].
//!
//! All leave-one-out weights come from one forward pass (prefix convolutions
//! F_i = c_1 ⊛ … ⊛ c_i) and one backward pass (B_i(m) = the weight of a count
//! m reached by the first i components, Σ_s (c_{i+1} ⊛ … ⊛ c_m)[s]·π(m + s)):
//! R_{−i}(r) = Σ_m F_{i−1}[m]·B_i(m + r). Cost O(n · Σ_C |C|).
//!
//! Every vector is kept scaled to a largest entry of 1 (the fast path). The
//! scales only matter across components, and each caller compares weights
//! within one component, so they are dropped. When a result lands so low
//! that entries flushed to zero on the way could matter (fields of about a
//! thousand tracks with an unknown count, or badly conflicting evidence), the
//! same computation is redone in log space.

use crate::event::{Field, RedCount};

/// A fast-path result whose scale fell below this (relative to the largest
/// entries of its inputs) is recomputed in log space: anything flushed on
/// the way is below 1e-308 of its own vector, so 1e-280 leaves 1e-28 of
/// relative slack, far below the tolerances anyone checks.
pub(crate) const FAST_FLOOR_LN: f64 = -644.7; // ln 1e-280

/// The prior weight π(s) of one red set of size s, s = 0..=n.
#[derive(Debug, Clone)]
pub(crate) struct CountPrior {
    /// ln π(s); −∞ where no set of size s is admissible.
    ln: Vec<f64>,
    /// π(s)/max π.
    scaled: Vec<f64>,
    /// How many counts below s π allows (s = 0..=n + 1), to ask in O(1)
    /// whether it allows any count in a range.
    allowed_below: Vec<usize>,
}

impl CountPrior {
    /// k known: π = [s = k]. A known initial red set fixes the count (mixing
    /// never changes it), so π = [s = |initial|] with weight 1, as the exact
    /// filter does. Unknown k, uniform start: π(s) = p(s)/C(n, s), p
    /// normalized, so that the prior mass is 1.
    pub(crate) fn new(field: &Field) -> Self {
        let n = field.tracks;
        let mut ln = vec![f64::NEG_INFINITY; n + 1];
        match (&field.initial_red, &field.red) {
            (Some(red), _) => ln[red.len()] = 0.0,
            (None, RedCount::Known(k)) => ln[*k] = 0.0,
            (None, RedCount::Unknown { prior }) => {
                let total: f64 = prior.iter().sum();
                // ln C(n, s) term by term (ln_binomial is O(s) a call).
                let mut ln_choose = 0.0;
                for (s, &p) in prior.iter().enumerate() {
                    if p > 0.0 {
                        ln[s] = (p / total).ln() - ln_choose;
                    }
                    if s < n {
                        ln_choose += ((n - s) as f64 / (s + 1) as f64).ln();
                    }
                }
            }
        }
        let ln_max = ln.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let scaled = ln.iter().map(|&l| (l - ln_max).exp()).collect();
        let mut allowed_below = vec![0];
        for l in &ln {
            let before = allowed_below[allowed_below.len() - 1];
            allowed_below.push(before + usize::from(l.is_finite()));
        }
        CountPrior {
            ln,
            scaled,
            allowed_below,
        }
    }

    /// Whether π allows one count only (k known, or a known start).
    pub(crate) fn is_point(&self) -> bool {
        self.ln.iter().filter(|l| l.is_finite()).count() == 1
    }

    /// Whether π allows some count in `from..=to`.
    pub(crate) fn allows_any(&self, from: usize, to: usize) -> bool {
        let n = self.ln.len() - 1;
        from <= to.min(n) && self.allowed_below[to.min(n) + 1] > self.allowed_below[from]
    }

    /// Whether `r`, weights computed for a component holding the count
    /// vector `own`, is zero at a count the component holds while the rest
    /// could complete it: a zero that is not a fact of the belief but an
    /// entry flushed on the way, where the component's own table may weigh
    /// 10^300 times more. Such weights would cut support the reads allow.
    /// `sums` are [`support_sums`] over every component, `own` included:
    /// the rest holds between their lowest and highest counts less own's.
    pub(crate) fn flushed(&self, own: &[f64], sums: (usize, usize), r: &[f64]) -> bool {
        let (own_lo, own_hi) = support(own).unwrap_or((0, 0));
        let rest = (sums.0 - own_lo, sums.1 - own_hi);
        own.iter()
            .zip(r)
            .enumerate()
            .any(|(s, (&c, &w))| c > 0.0 && w == 0.0 && self.allows_any(s + rest.0, s + rest.1))
    }

    /// ln π(s) for s = 0..=n (−∞ where no set of size s is admissible).
    pub(crate) fn ln_weights(&self) -> &[f64] {
        &self.ln
    }

    /// The weight Q(s), s = 0..=m, that an *uninformed* rest of n − m
    /// tracks gives to a red count s of m tracks: Σ_K π(K)·C(n − m, K − s),
    /// the prior mass of the rest's completions (every rest set alike,
    /// as under the uniform start). Scaled to a largest entry of 1; all
    /// zero where π leaves no completion. A function of (n, π, m) alone,
    /// so every leader and every replay compute the same numbers.
    /// O(n·m): callers keep it per m.
    pub(crate) fn uninformed_rest(&self, m: usize) -> Vec<f64> {
        let n = self.ln.len() - 1;
        let rest = n.saturating_sub(m);
        // ln C(rest, j) for j = 0..=rest, term by term.
        let mut ln_choose = Vec::with_capacity(rest + 1);
        let mut acc = 0.0;
        for j in 0..=rest {
            ln_choose.push(acc);
            if j < rest {
                acc += ((rest - j) as f64 / (j + 1) as f64).ln();
            }
        }
        let ln_q: Vec<f64> = (0..=m)
            .map(|s| {
                ln_sum_exp(
                    self.ln
                        .iter()
                        .enumerate()
                        .filter(|&(k, l)| l.is_finite() && k >= s && k - s <= rest)
                        .map(|(k, l)| l + ln_choose[k - s]),
                )
            })
            .collect();
        let max = ln_q.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if max == f64::NEG_INFINITY {
            return vec![0.0; m + 1];
        }
        ln_q.iter().map(|&l| (l - max).exp()).collect()
    }

    /// The count the tilt of the product tree aims the bulk at: k when it
    /// is known, else the count π and the binomial of n tracks favour most.
    pub(crate) fn target(&self) -> f64 {
        // One pass with ln C(n, s) built up term by term: ln_binomial is
        // O(s) a call, and n calls of it took minutes at n = 100,000.
        let n = self.ln.len() - 1;
        let (mut best, mut best_score) = (0, f64::NEG_INFINITY);
        let mut ln_choose = 0.0;
        for s in 0..=n {
            let score = self.ln[s] + ln_choose;
            if score > best_score {
                (best, best_score) = (s, score);
            }
            if s < n {
                ln_choose += ((n - s) as f64 / (s + 1) as f64).ln();
            }
        }
        best as f64
    }
}

/// The lowest and the highest count `counts` holds with positive weight;
/// `None` for an empty vector or one of zeros.
pub(crate) fn support(counts: &[f64]) -> Option<(usize, usize)> {
    let lo = counts.iter().position(|&x| x > 0.0)?;
    let hi = counts.iter().rposition(|&x| x > 0.0)?;
    Some((lo, hi))
}

/// The sums of the lowest and of the highest held counts of `counts`.
pub(crate) fn support_sums(counts: &[&[f64]]) -> (usize, usize) {
    counts
        .iter()
        .filter_map(|c| support(c))
        .fold((0, 0), |(lo, hi), (l, h)| (lo + l, hi + h))
}

/// a ⊛ b into `out` (resized).
fn convolve(a: &[f64], b: &[f64], out: &mut Vec<f64>) {
    out.clear();
    out.resize(a.len() + b.len() - 1, 0.0);
    for (r, &y) in b.iter().enumerate() {
        if y == 0.0 {
            continue;
        }
        for (o, &x) in out[r..].iter_mut().zip(a) {
            *o += x * y;
        }
    }
}

/// Divides by the largest entry; returns its log (−∞ when all are zero).
fn normalize_max(v: &mut [f64]) -> f64 {
    let max = v.iter().copied().fold(0.0, f64::max);
    if max > 0.0 && max.is_finite() {
        for x in v.iter_mut() {
            *x /= max;
        }
        max.ln()
    } else {
        f64::NEG_INFINITY
    }
}

fn ln_sum_exp(terms: impl Iterator<Item = f64> + Clone) -> f64 {
    let max = terms.clone().fold(f64::NEG_INFINITY, f64::max);
    if max == f64::NEG_INFINITY {
        return max;
    }
    max + terms.map(|t| (t - max).exp()).sum::<f64>().ln()
}

fn ln_vec(v: &[f64]) -> Vec<f64> {
    v.iter().map(|x| x.ln()).collect()
}

/// a ⊛ b in log space.
fn ln_convolve(a: &[f64], b: &[f64]) -> Vec<f64> {
    (0..a.len() + b.len() - 1)
        .map(|s| {
            let lo = s.saturating_sub(a.len() - 1);
            let hi = s.min(b.len() - 1);
            ln_sum_exp((lo..=hi).map(move |r| a[s - r] + b[r]))
        })
        .collect()
}

/// Scales a log vector to a largest entry of 1 and leaves the log domain;
/// `None` when every entry is −∞.
fn exp_normalized(v: &[f64]) -> Option<Vec<f64>> {
    let max = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if max == f64::NEG_INFINITY || max.is_nan() {
        return None;
    }
    Some(v.iter().map(|x| (x - max).exp()).collect())
}

impl CountPrior {
    /// R_{−j}, the weight of each red count r = 0..=|C_j| of component j
    /// from all the others and π, scaled to a largest entry of 1. `None`
    /// when every count of j is ruled out (the belief has no mass).
    pub(crate) fn leave_one_out(&self, counts: &[&[f64]], j: usize) -> Option<Vec<f64>> {
        let sums = support_sums(counts);
        match self.fast_leave_one_out(counts, j) {
            Some(r) if !self.flushed(counts[j], sums, &r) => Some(r),
            _ => self.ln_leave_one_out(counts, j),
        }
    }

    /// R_{−j} for every component j (see [`leave_one_out`](Self::leave_one_out)).
    pub(crate) fn all_leave_one_out(&self, counts: &[&[f64]]) -> Vec<Option<Vec<f64>>> {
        let sums = support_sums(counts);
        let trusted = |all: &Vec<Vec<f64>>| {
            all.iter()
                .zip(counts)
                .all(|(r, c)| !self.flushed(c, sums, r))
        };
        match self.fast_all(counts) {
            Some(all) if trusted(&all) => all.into_iter().map(Some).collect(),
            _ => self.ln_all(counts),
        }
    }

    /// ln Σ_s π(s)·(⊛ counts)[s], in log space (not on a hot path).
    pub(crate) fn ln_total(&self, counts: &[&[f64]]) -> f64 {
        let mut f = vec![0.0];
        for c in counts {
            f = ln_convolve(&f, &ln_vec(c));
        }
        ln_sum_exp(f.iter().enumerate().map(|(s, &x)| x + self.ln[s]))
    }

    /// P(|x| = s) for s = 0..=n, in log space (not on a hot path).
    pub(crate) fn count_posterior(&self, counts: &[&[f64]]) -> Option<Vec<f64>> {
        let mut f = vec![0.0];
        for c in counts {
            f = ln_convolve(&f, &ln_vec(c));
        }
        let joint: Vec<f64> = f.iter().enumerate().map(|(s, &x)| x + self.ln[s]).collect();
        let mut p = exp_normalized(&joint)?;
        let total: f64 = p.iter().sum();
        for x in &mut p {
            *x /= total;
        }
        Some(p)
    }

    /// Fast path of `leave_one_out`: G = ⊛_{i ≠ j} c_i, then
    /// R(r) = Σ_m G[m]·π(m + r).
    pub(crate) fn fast_leave_one_out(&self, counts: &[&[f64]], j: usize) -> Option<Vec<f64>> {
        let mut g = vec![1.0];
        let mut next = Vec::new();
        for (i, c) in counts.iter().enumerate() {
            if i == j {
                continue;
            }
            convolve(&g, c, &mut next);
            std::mem::swap(&mut g, &mut next);
            normalize_max(&mut g);
        }
        let width = counts[j].len();
        let mut r: Vec<f64> = (0..width)
            .map(|r| {
                g.iter()
                    .zip(&self.scaled[r..])
                    .map(|(x, p)| x * p)
                    .sum::<f64>()
            })
            .collect();
        (normalize_max(&mut r) >= FAST_FLOOR_LN).then_some(r)
    }

    fn ln_leave_one_out(&self, counts: &[&[f64]], j: usize) -> Option<Vec<f64>> {
        let mut g = vec![0.0];
        for (i, c) in counts.iter().enumerate() {
            if i != j {
                g = ln_convolve(&g, &ln_vec(c));
            }
        }
        let r: Vec<f64> = (0..counts[j].len())
            .map(|r| ln_sum_exp(g.iter().enumerate().map(move |(m, &x)| x + self.ln[m + r])))
            .collect();
        exp_normalized(&r)
    }

    /// Fast path of `all_leave_one_out`; `None` when any result is unsafe.
    pub(crate) fn fast_all(&self, counts: &[&[f64]]) -> Option<Vec<Vec<f64>>> {
        let k = counts.len();
        // Prefix convolutions F_0 = [1], F_i = F_{i−1} ⊛ c_i, each scaled.
        let mut prefix: Vec<Vec<f64>> = Vec::with_capacity(k);
        let mut f = vec![1.0];
        for c in counts {
            let mut next = Vec::new();
            convolve(&f, c, &mut next);
            normalize_max(&mut next);
            prefix.push(std::mem::replace(&mut f, next));
        }
        // Backward: B_k = π; B_{i−1}(m) = Σ_r c_i[r]·B_i(m + r) over the
        // counts m the first i − 1 components can reach.
        let mut back = self.scaled.clone();
        // Σ of the logs of the scales dropped from `back`: a flushed entry
        // of an earlier B weighs that much more now.
        let mut back_drop = 0.0;
        let mut out = vec![Vec::new(); k];
        for i in (0..k).rev() {
            let fi = &prefix[i];
            let c = counts[i];
            let mut r: Vec<f64> = (0..c.len())
                .map(|r| fi.iter().zip(&back[r..]).map(|(x, b)| x * b).sum::<f64>())
                .collect();
            if normalize_max(&mut r) + back_drop < FAST_FLOOR_LN {
                return None;
            }
            out[i] = r;
            if i > 0 {
                let reach = fi.len();
                let mut prev: Vec<f64> = (0..reach)
                    .map(|m| c.iter().zip(&back[m..]).map(|(x, b)| x * b).sum::<f64>())
                    .collect();
                back_drop += normalize_max(&mut prev);
                if back_drop < FAST_FLOOR_LN {
                    return None;
                }
                back = prev;
            }
        }
        Some(out)
    }

    /// [`all_leave_one_out`](Self::all_leave_one_out) in log space only:
    /// for weights the fast path computed within its own checks yet wrong
    /// (the caller's sum test found them out).
    pub(crate) fn ln_all(&self, counts: &[&[f64]]) -> Vec<Option<Vec<f64>>> {
        let k = counts.len();
        let logs: Vec<Vec<f64>> = counts.iter().map(|c| ln_vec(c)).collect();
        let mut prefix = Vec::with_capacity(k);
        let mut f = vec![0.0];
        for c in &logs {
            let next = ln_convolve(&f, c);
            prefix.push(std::mem::replace(&mut f, next));
        }
        let mut back = self.ln.clone();
        let mut out = vec![None; k];
        for i in (0..k).rev() {
            let fi: &Vec<f64> = &prefix[i];
            let c = &logs[i];
            let r: Vec<f64> = (0..c.len())
                .map(|r| ln_sum_exp(fi.iter().zip(&back[r..]).map(|(x, b)| x + b)))
                .collect();
            out[i] = exp_normalized(&r);
            if i > 0 {
                back = (0..fi.len())
                    .map(|m| ln_sum_exp(c.iter().zip(&back[m..]).map(|(x, b)| x + b)))
                    .collect();
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute_leave_one_out(prior: &CountPrior, counts: &[&[f64]], j: usize) -> Vec<f64> {
        let mut g = vec![1.0];
        for (i, c) in counts.iter().enumerate() {
            if i != j {
                let mut next = Vec::new();
                convolve(&g, c, &mut next);
                g = next;
            }
        }
        let mut r: Vec<f64> = (0..counts[j].len())
            .map(|r| {
                g.iter()
                    .enumerate()
                    .map(|(m, x)| x * prior.ln[m + r].exp())
                    .sum()
            })
            .collect();
        normalize_max(&mut r);
        r
    }

    fn close(a: &[f64], b: &[f64], tol: f64) {
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            assert!((x - y).abs() <= tol, "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn every_path_agrees_with_brute_force() {
        let field = Field {
            tracks: 7,
            red: RedCount::Unknown {
                prior: vec![0.1, 0.2, 0.05, 0.3, 0.1, 0.1, 0.1, 0.05],
            },
            initial_red: None,
        };
        for prior in [
            CountPrior::new(&field),
            CountPrior::new(&Field::uniform(7, 3)),
        ] {
            let c1 = [0.2, 0.5, 0.3];
            let c2 = [0.6, 0.4];
            let c3 = [0.1, 0.0, 0.7, 0.2];
            let c4 = [0.0, 1.0];
            let counts: Vec<&[f64]> = vec![&c1, &c2, &c3, &c4];
            let fast = prior.fast_all(&counts).unwrap();
            let slow = prior.ln_all(&counts);
            for j in 0..counts.len() {
                let want = brute_leave_one_out(&prior, &counts, j);
                close(&fast[j], &want, 1e-12);
                close(slow[j].as_ref().unwrap(), &want, 1e-12);
                close(&prior.fast_leave_one_out(&counts, j).unwrap(), &want, 1e-12);
                close(&prior.ln_leave_one_out(&counts, j).unwrap(), &want, 1e-12);
            }
        }
    }

    #[test]
    fn a_thousand_tracks_with_unknown_count_stay_finite() {
        let n = 1000;
        let field = Field {
            tracks: n,
            red: RedCount::unknown_uniform(n),
            initial_red: None,
        };
        let prior = CountPrior::new(&field);
        let half = [0.5, 0.5];
        let tilted = [0.9, 0.1];
        let counts: Vec<&[f64]> = (0..n)
            .map(|i| if i % 3 == 0 { &tilted[..] } else { &half[..] })
            .collect();
        let all = prior.all_leave_one_out(&counts);
        for r in &all {
            let r = r.as_ref().unwrap();
            assert!(r.iter().all(|x| x.is_finite() && *x >= 0.0));
            assert!((r.iter().copied().fold(0.0, f64::max) - 1.0).abs() < 1e-12);
        }
        let one = prior.leave_one_out(&counts, 10).unwrap();
        close(&one, all[10].as_ref().unwrap(), 1e-9);
        assert!(prior.ln_total(&counts).is_finite());
    }

    /// A zero where the component holds mass and the rest could complete
    /// the count is flushed; a zero the rest's supports explain (the rest
    /// holds at least one red track) or a count the component does not
    /// hold is a fact.
    #[test]
    fn only_zeros_nothing_explains_are_flushed() {
        let field = Field::uniform(6, 2);
        let prior = CountPrior::new(&field);
        let own = [1e-200, 1.0, 0.0];
        // The rest can hold 0 to 3 red: counts 0, 1 of the component are
        // completed (k = 2), so a zero weight there is flushed.
        // (The sums count the component's own 0..=1 too.)
        assert!(prior.flushed(&own, (0, 4), &[1.0, 0.0, 0.0]));
        assert!(prior.flushed(&own, (0, 4), &[0.0, 1.0, 0.0]));
        // The rest holds exactly 2 red: only count 0 is completed.
        assert!(!prior.flushed(&own, (2, 3), &[1.0, 0.0, 0.0]));
        // Count 2 is not held: its zero says nothing.
        assert!(!prior.flushed(&own, (0, 4), &[1.0, 1.0, 0.0]));
        // Both other tracks red is 10^-400 (0 in the fast path's product)
        // against 10^-200 for one of them: the weight of the component's
        // count 0 is 10^-200 of its count 1's, not 0.
        let a = [1.0, 1e-200];
        let b = [1.0, 1e-200];
        let c = [1.0, 1.0];
        assert_eq!(prior.fast_leave_one_out(&[&a, &b, &c], 2).unwrap()[0], 0.0);
        let r = prior.leave_one_out(&[&a, &b, &c], 2).unwrap();
        assert!(r[1] == 1.0 && r[0] > 1e-202 && r[0] < 1e-199, "{r:?}");
    }
}
