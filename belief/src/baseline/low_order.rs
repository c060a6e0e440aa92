//! The low-order Radon filters the paper compares against (Jiang et al.,
//! TOSN 2013, Section 5.5 "Comparative Methods", Table III "1st/2nd/3rd
//! Order Radon Basis"): the belief over k-sets is kept in
//! R(Φ_{j,k}) = span{φ_R : |R| ≤ j} (Section 4.1) and projected back onto it,
//! orthogonally in l2 over the k-sets, after every conditioning.
//!
//! ## Representation: j-th order marginals
//! An element g of R(Φ_j) is determined by M_j(S) = Σ_{x ⊇ S} g(x) over the
//! j-sets S (M_j = Φ_jᵀ g, and Φ_jᵀ is injective on R(Φ_j)), and the
//! orthogonal projector P onto R(Φ_j) keeps it (Φ_jᵀ P = Φ_jᵀ). So we store
//! M_j, densely by colex rank, and never form P:
//! - rollup (Section 3.3) is exact: Theorem 2 gives Φ_jᵀ T_k = T_j Φ_jᵀ for
//!   the symmetric swap kernel, i.e. M'(S) = (1 − s)·M(S) + s·M(S △ {a, b})
//!   for S holding exactly one of a, b;
//! - conditioning on L = blue + (red − blue)·φ_t (Section 3.4) needs one
//!   number outside M_j: M'_j(S) = red·M_j(S) for t ∈ S, else
//!   blue·M_j(S) + (red − blue)·M_{j+1}(S ∪ {t}), where M_{j+1} is that of the
//!   unique element of R(Φ_j) with these j-marginals — the projection.
//!
//! M_{j+1} of an element of R(Φ_j) is an S_n-equivariant linear function of
//! M_j, hence of the form M_{j+1}(T) = Σ_{u ≤ j} λ_u Σ_{U ⊆ T, |U| = u} M_u(U)
//! with M_u(U) = Σ_{R ⊇ U, |R| = j} M_j(R)/C(k − u, j − u). The λ_u depend on
//! (n, k, j) only and are fitted once, by least squares on the test
//! functions φ_Q (see [`lift_coefficients`]).
//!
//! ## Leaving the simplex
//! The projection is orthogonal in l2, not onto the probability simplex, so
//! the represented function goes negative on some k-sets and its marginals
//! leave [0, 1]; a later observation can then get a predicted probability
//! ≤ 0. This is the method itself, not rounding (the tests reproduce it
//! with the pseudoinverse of Φ_{j,k}): on the Table III workload
//! (colour-histogram sensor, half mixes) orders 1–3 get there after a few
//! hundred events, on streams the world could have produced.
//! [`LowOrderRepair::ShrinkToUniform`] is our addition, not the paper's: it
//! mixes the belief with the uniform one, which stays in R(Φ_j), just enough
//! to bring every marginal back into [0, 1] after every conditioning.
//!
//! ## An observation the projection gives probability ≤ 0
//! The paper's method cannot condition on it, and the filter cannot tell a
//! valid observation from an impossible one (the projection is not the
//! exact belief; even inside [0, 1] a marginal of exactly 0 or 1 may be
//! wrong). So, whatever the repair, the filter answers on by one rule: it
//! first mixes the belief with the uniform one, f ← (1 − ε)·f + ε·uniform,
//! with the least ε that brings every marginal into [0, 1] and gives the
//! observation at least [`OBSERVATION_FLOOR`] of the probability the
//! uniform belief gives it, then conditions as usual. The mix counts as a
//! repair ([`PropertyFilter::repairs`]). The method amplifies rounding by
//! the sighting's likelihood ratio; numbers that overflow, or marginals
//! that no longer sum to k (ratios of 10^200 can do either), are replaced
//! by the uniform belief, ε = 1, a repair too. With k = 0 or k = n the filter is
//! exact; a sighting the prior rules out there (a sure red when no target
//! is red) is set aside, as by every filter (`crate::repair`), and counted
//! with the repairs.
//!
//! The lower marginals M_0, …, M_{j−1} are kept alongside M_j as a cache:
//! they obey the same rollup and conditioning rules, with M_{u+1} at hand, so
//! keeping them costs less than re-deriving them after every event.

use super::{binomial_f64, Binomials, MAX_STATES};
use crate::error::BeliefError;
use crate::event::{Field, Mix, Observe};
use crate::filter::PropertyFilter;
use crate::repair;
use crate::weights::ln_binomial;
use nalgebra::{DMatrix, DVector};

const METHOD: &str = "low-order Radon";

/// Largest relative residual accepted from the λ fit; the system is
/// consistent in exact arithmetic, so anything above rounding is a bug.
const LIFT_TOLERANCE: f64 = 1e-8;

/// How far outside [0, 1] a marginal may stray before it counts as having
/// left: rounding in the exact cases stays far below this.
const SIMPLEX_SLACK: f64 = 1e-9;

/// The share of its uniform-belief probability an observation the
/// projection gives probability ≤ 0 gets back before it is conditioned on
/// (see the module documentation): small, so that the belief moves no
/// further from the projection than the observation forces.
pub(crate) const OBSERVATION_FLOOR: f64 = 1e-6;

/// What the filter does when a conditioning leaves a marginal outside [0, 1].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LowOrderRepair {
    /// Nothing: the paper's method as written.
    #[default]
    None,
    /// Replace f by (1 − ε)·f + ε·uniform with the least ε that brings every
    /// marginal into [0, 1]. Not in the paper; it keeps the filter running on
    /// long workloads.
    ShrinkToUniform,
}

/// A belief over k-sets restricted to the Radon bases of order ≤ j, the
/// baseline of the paper's Table III.
///
/// Stores the marginals M_u(S) = Σ_{x ⊇ S} f(x) for every set S of size
/// u ≤ j (C(n, j) numbers at the top order, which is what
/// [`coefficients`](PropertyFilter::coefficients) reports), normalized to
/// M_0 = 1. The order used is min(j, k); j = k (or j ≥ n − k) is exact.
/// An observation costs O(C(n, j)·j) and a mix O(C(n − 2, j − 1)): n = 100,
/// j = 3 means 161,700 numbers at the top level. Memory is twice
/// Σ_{u ≤ j} C(n, u) f64 (the marginals and the working space of the
/// conditioning step); construction fails with [`BeliefError::TooLarge`]
/// when that sum exceeds [`MAX_STATES`](super::MAX_STATES).
///
/// The projection is orthogonal in l2, not onto the probability simplex: the
/// represented function may be negative on some k-sets, and its marginals
/// may leave [0, 1]. [`marginals`](PropertyFilter::marginals) clamps them for
/// reporting; they still sum to k before clamping.
///
/// k must be known.
#[derive(Debug, Clone)]
pub struct LowOrderFilter {
    field: Field,
    order: usize,
    repair: LowOrderRepair,
    /// How many conditionings needed a repair.
    repairs: u64,
    /// M_u/M_0 of the uniform belief: W(u)/W(0).
    uniform: Vec<f64>,
    binom: Binomials,
    /// `levels[u][rank(S)]` = M_u(S), scaled so that M_0 = 1.
    levels: Vec<Vec<f64>>,
    /// λ_0, …, λ_order.
    lift: Vec<f64>,
    /// Working space of the conditioning step, the shape of `levels`.
    scratch: Vec<Vec<f64>>,
    log_norm: f64,
}

impl LowOrderFilter {
    /// A filter of order `order` (≥ 1; the paper's 1, 2 and 3), starting from
    /// the field's known red set or the uniform prior.
    pub fn new(field: Field, order: usize) -> Result<Self, BeliefError> {
        Self::with_repair(field, order, LowOrderRepair::None)
    }

    /// As [`new`](Self::new), choosing what happens when the belief leaves
    /// the simplex.
    pub fn with_repair(
        field: Field,
        order: usize,
        repair: LowOrderRepair,
    ) -> Result<Self, BeliefError> {
        field.validate()?;
        let n = field.tracks;
        let Some(k) = field.red.known() else {
            return Err(BeliefError::Unsupported {
                method: METHOD,
                what: "an unknown number of red targets",
            });
        };
        if order == 0 {
            return Err(BeliefError::Unsupported {
                method: METHOD,
                what: "order 0",
            });
        }
        // With every track red the belief is certain, and order 1 holds it
        // exactly (the fit of a higher order's lift can be inconsistent
        // there: n = k = 4, order 2).
        let order = if k == n { order.min(1) } else { order.min(k) };
        let needed: f64 = (0..=order).map(|u| binomial_f64(n, u)).sum();
        if needed > MAX_STATES as f64 {
            return Err(BeliefError::TooLarge {
                method: METHOD,
                needed,
                limit: MAX_STATES,
            });
        }
        let (lift, _) = lift_coefficients(n, k, order)?;
        let binom = Binomials::new(n, order);
        let uniform = normalized_weights(n, k, order);
        let (levels, log_norm) = match &field.initial_red {
            None => (
                (0..=order)
                    .map(|u| vec![uniform[u]; binom.get(n, u)])
                    .collect(),
                ln_binomial(n, k),
            ),
            Some(red) => {
                // M_u(U) = [U ⊆ x0].
                let mut start: Vec<usize> = red.iter().map(|&t| t as usize).collect();
                start.sort_unstable();
                let mut levels: Vec<Vec<f64>> =
                    (0..=order).map(|u| vec![0.0; binom.get(n, u)]).collect();
                for (u, level) in levels.iter_mut().enumerate() {
                    let mut pick: Vec<usize> = (0..u).collect();
                    let mut set = vec![0usize; u];
                    loop {
                        for (s, &p) in set.iter_mut().zip(&pick) {
                            *s = start[p];
                        }
                        level[rank(&binom, &set)] = 1.0;
                        if !advance(&mut pick, k) {
                            break;
                        }
                    }
                }
                (levels, 0.0)
            }
        };
        let scratch = levels.iter().map(|l| vec![0.0; l.len()]).collect();
        Ok(LowOrderFilter {
            field,
            order,
            repair,
            repairs: 0,
            uniform,
            binom,
            levels,
            lift,
            scratch,
            log_norm,
        })
    }

    /// The order actually used: min(requested, k).
    #[cfg(test)]
    pub(crate) fn order(&self) -> usize {
        self.order
    }

    /// The method amplifies rounding by the likelihood ratio (10^200 for a
    /// contradicting sighting): numbers that overflowed, or whose marginals
    /// no longer sum to k (an identity of every element of R(Φ_j), so only
    /// rounding breaks it), are replaced by the uniform belief, the rule's
    /// ε = 1. Whether they were.
    fn reset_if_broken(&mut self) -> bool {
        let m0 = self.levels[0][0];
        let k = self.field.red.known().unwrap_or(0) as f64;
        let sum: f64 = if self.order >= 1 {
            self.levels[1].iter().sum()
        } else {
            k * m0
        };
        let broken = self.levels.iter().flatten().any(|m| !m.is_finite())
            || (sum - k * m0).abs() > 1e-6 * (1.0 + k) * m0.abs();
        if broken {
            for (level, &w) in self.levels.iter_mut().zip(&self.uniform) {
                level.fill(w);
            }
            self.repairs += 1;
        }
        broken
    }

    /// P(t red) = M_1({t})/M_0 as represented, not clamped: outside [0, 1]
    /// once the projection has left the simplex.
    pub fn raw_marginals(&self) -> Result<Vec<f64>, BeliefError> {
        let m0 = self.checked_mass()?;
        Ok(if self.order >= 1 {
            self.levels[1].iter().map(|m| m / m0).collect()
        } else {
            vec![self.lift[0]; self.field.tracks]
        })
    }

    /// Applies [`LowOrderRepair::ShrinkToUniform`] if a marginal has left
    /// [0, 1]; `levels` must be normalized.
    fn shrink_if_outside(&mut self) {
        let eps = self.simplex_shrink();
        self.shrink_by(eps);
    }

    /// The least ε for which (1 − ε)·f + ε·uniform has every marginal in
    /// [0, 1]; `levels` must be normalized.
    fn simplex_shrink(&self) -> f64 {
        if self.order == 0 {
            return 0.0;
        }
        let r = self.uniform[1];
        // r ∈ (0, 1) here: with k = 0 or k = n the order is 0 or the filter
        // is exact.
        let mut eps = 0.0f64;
        for &p in &self.levels[1] {
            if p < -SIMPLEX_SLACK {
                eps = eps.max(-p / (r - p));
            } else if p > 1.0 + SIMPLEX_SLACK {
                eps = eps.max((p - 1.0) / (p - r));
            }
        }
        eps
    }

    /// f ← (1 − ε)·f + ε·uniform, `levels` normalized; counted as a repair.
    fn shrink_by(&mut self, eps: f64) {
        if eps == 0.0 {
            return;
        }
        for (level, &w) in self.levels.iter_mut().zip(&self.uniform) {
            for m in level.iter_mut() {
                *m = (1.0 - eps) * *m + eps * w;
            }
        }
        self.repairs += 1;
    }

    /// ln Z, Z = Σ_x f(x) of the unnormalized (projected) belief: C(n, k) for
    /// the uniform prior, 1 for a known initial set, times the likelihood of
    /// every observation so far as the projected belief predicts it.
    #[cfg(test)]
    pub(crate) fn log_normalizer(&self) -> f64 {
        self.log_norm + self.levels[0][0].ln()
    }

    /// P(every track of `tracks` is red) = M_{|S|}(S)/M_0, clamped to [0, 1];
    /// only for sets of at most `order()` distinct tracks.
    #[cfg(test)]
    pub(crate) fn prob_all_red(&self, tracks: &[u32]) -> Result<f64, BeliefError> {
        for &t in tracks {
            self.field.check_track(t)?;
        }
        let mut set: Vec<usize> = tracks.iter().map(|&t| t as usize).collect();
        set.sort_unstable();
        set.dedup();
        if set.len() > self.order {
            return Err(BeliefError::Unsupported {
                method: METHOD,
                what: "P(all red) for sets larger than the order",
            });
        }
        let m0 = self.checked_mass()?;
        Ok((self.levels[set.len()][rank(&self.binom, &set)] / m0).clamp(0.0, 1.0))
    }

    fn checked_mass(&self) -> Result<f64, BeliefError> {
        let m0 = self.levels[0][0];
        if m0.is_finite() && m0 > 0.0 {
            Ok(m0)
        } else {
            Err(BeliefError::Degenerate { normalizer: m0 })
        }
    }

    /// Fills `scratch[order][rank(S)]` with M_{j+1}(S ∪ {t}) for every j-set
    /// S ∌ t. The inner sum Σ_{U ⊆ S ∪ {t}} splits into U ⊆ S and U ∪ {t},
    /// U ⊆ S, so it is a subset sum over S of
    /// g(U) = λ_{|U|} M(U) + λ_{|U|+1} M(U ∪ {t}), built up one level at a
    /// time: with D_u(V) = g(V)/(j − u)! + Σ_{e ∈ V} D_{u−1}(V − e), each
    /// U ⊆ V is reached (|V| − |U|)! times, so D_j(S) = Σ_{U ⊆ S} g(U).
    fn lift_to(&mut self, t: usize) {
        let n = self.field.tracks;
        let j = self.order;
        let mut factorial = vec![1.0f64; j + 1];
        for i in 1..=j {
            factorial[i] = factorial[i - 1] * i as f64;
        }
        // The lower levels are small (C(n, j − 1) sets at most): set by set.
        let generic_levels = if j == 0 { 1 } else { j };
        let mut set: Vec<usize> = Vec::with_capacity(j);
        for u in 0..generic_levels {
            let (below, current) = self.scratch.split_at_mut(u);
            let current = &mut current[0];
            set.clear();
            set.extend(0..u);
            let mut r = 0;
            loop {
                if !set.contains(&t) {
                    let mut g = self.lift[u] * self.levels[u][r];
                    if u < j {
                        g += self.lift[u + 1] * self.levels[u + 1][rank_with(&self.binom, &set, t)];
                    }
                    let mut d = g / factorial[j - u];
                    if u > 0 {
                        let lower = &below[u - 1];
                        for p in 0..u {
                            d += lower[rank_without(&self.binom, &set, p)];
                        }
                    }
                    current[r] = d;
                }
                r += 1;
                if !advance(&mut set, n) {
                    break;
                }
            }
        }
        if j == 0 {
            return;
        }
        // The top level holds C(n, j) sets: block by block, where a block is
        // {c0} ∪ W for a fixed W and every c0 < min W. Removing W's element
        // at p from such sets gives ranks c0 + (a constant), so each term of
        // D_j is a slice of D_{j−1}; removing c0 gives W itself.
        let (below, current) = self.scratch.split_at_mut(j);
        let (lower, out) = (&below[j - 1], &mut current[0]);
        let top = &self.levels[j];
        let lam = self.lift[j];
        let mut shifts: Vec<usize> = Vec::with_capacity(j);
        for_each_block(&self.binom, n, j, |upper, start, width| {
            if upper.contains(&t) {
                return;
            }
            let alone = rank(&self.binom, upper);
            shifts.clear();
            shifts.extend((0..upper.len()).map(|p| rank_shifted_without(&self.binom, upper, p)));
            for range in around(width, t) {
                let block = &mut out[start + range.start..start + range.end];
                let own = &top[start + range.start..start + range.end];
                for (d, m) in block.iter_mut().zip(own) {
                    *d = lam * m + lower[alone];
                }
                for &shift in &shifts {
                    let from = &lower[shift + range.start..shift + range.end];
                    for (d, x) in block.iter_mut().zip(from) {
                        *d += x;
                    }
                }
            }
        });
    }
}

/// Calls `block(upper, start, width)` for every (u − 1)-set W = `upper`
/// (u ≥ 1): the u-sets {c0} ∪ W with c0 < min W (c0 < n when u = 1) have the
/// consecutive ranks start + c0, since C(c0, 1) = c0.
fn for_each_block(
    binom: &Binomials,
    n: usize,
    u: usize,
    mut block: impl FnMut(&[usize], usize, usize),
) {
    if u > n {
        return;
    }
    // Sets W holding 0 give empty blocks; {1, …, u − 1} is the first without.
    let mut upper: Vec<usize> = (1..u).collect();
    loop {
        let width = upper.first().copied().unwrap_or(n);
        let start: usize = upper
            .iter()
            .enumerate()
            .map(|(i, &c)| binom.get(c, i + 2))
            .sum();
        block(&upper, start, width);
        if !advance(&mut upper, n) {
            break;
        }
    }
}

/// For V = {c0} ∪ `upper`, the rank of V minus upper[p], less c0.
fn rank_shifted_without(binom: &Binomials, upper: &[usize], p: usize) -> usize {
    upper
        .iter()
        .enumerate()
        .map(|(i, &c)| match i.cmp(&p) {
            std::cmp::Ordering::Less => binom.get(c, i + 2),
            std::cmp::Ordering::Equal => 0,
            std::cmp::Ordering::Greater => binom.get(c, i + 1),
        })
        .sum()
}

/// 0..width without t, as at most two ranges.
fn around(width: usize, t: usize) -> [std::ops::Range<usize>; 2] {
    if t < width {
        [0..t, t + 1..width]
    } else {
        [0..width, width..width]
    }
}

impl PropertyFilter for LowOrderFilter {
    fn field(&self) -> &Field {
        &self.field
    }

    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        self.field.check_mix(&mix)?;
        if mix.swap == 0.0 {
            return Ok(());
        }
        let n = self.field.tracks;
        let (lo, hi) = if mix.a < mix.b {
            (mix.a as usize, mix.b as usize)
        } else {
            (mix.b as usize, mix.a as usize)
        };
        let (swap, stay) = (mix.swap, 1.0 - mix.swap);
        // Pairs B ∪ {lo} ↔ B ∪ {hi}, B drawn from the other n − 2 tracks.
        for u in 1..=self.order {
            if u - 1 > n - 2 {
                break;
            }
            let level = &mut self.levels[u];
            let mut pick: Vec<usize> = (0..u - 1).collect();
            let mut base = vec![0usize; u - 1];
            loop {
                for (b, &p) in base.iter_mut().zip(&pick) {
                    let mut track = p;
                    if track >= lo {
                        track += 1;
                    }
                    if track >= hi {
                        track += 1;
                    }
                    *b = track;
                }
                let x = rank_with(&self.binom, &base, lo);
                let y = rank_with(&self.binom, &base, hi);
                let (fx, fy) = (level[x], level[y]);
                level[x] = stay * fx + swap * fy;
                level[y] = stay * fy + swap * fx;
                if !advance(&mut pick, n - 2) {
                    break;
                }
            }
        }
        Ok(())
    }

    fn observe(&mut self, observe: Observe) -> Result<(), BeliefError> {
        self.field.check_observe(&observe)?;
        if self.field.rules_out(&observe) {
            repair::note("low-order", &mut self.repairs, &observe, true);
            return Ok(());
        }
        let n = self.field.tracks;
        let t = observe.track as usize;
        let j = self.order;
        // (M_0, M_1({t})) as the projection holds them.
        let masses = |filter: &Self| {
            let m0 = filter.levels[0][0];
            let m1t = if j >= 1 {
                filter.levels[1][t]
            } else {
                filter.lift[0] * m0
            };
            (m0, m1t)
        };
        // Likelihoods scaled to a largest of 1 (the factor goes into the
        // normalizer), so that a sighting of likelihood 10^200 does not
        // overflow the predicted probability.
        let top = observe.red.max(observe.blue);
        let observe = Observe {
            red: observe.red / top,
            blue: observe.blue / top,
            ..observe
        };
        // The predicted probability of the sighting, times M_0, as the
        // masses with and without t: written blue·M_0 + (red − blue)·M_1
        // it cancels to 0 or below when the likelihoods are 10^16 apart.
        let predicted = |(m0, m1t): (f64, f64)| observe.blue * (m0 - m1t) + observe.red * m1t;
        let mut evidence = predicted(masses(self));
        let mut ruled = false;
        if evidence <= 0.0 && j >= 1 {
            // The projection rules the observation out; the rule of the
            // module documentation. `levels` are normalized (M_0 = 1) after
            // every observation and kept so by mixing.
            let r = self.uniform[1];
            let outside = |p: f64| {
                if p < 0.0 {
                    -p / (r - p)
                } else if p > 1.0 {
                    (p - 1.0) / (p - r)
                } else {
                    0.0
                }
            };
            let shrink = |p: f64, eps: f64| (1.0 - eps) * p + eps * r;
            // Every marginal into [0, 1] (up to the slack), then t's
            // exactly, then the floor.
            let eps = self.simplex_shrink();
            let p = shrink(self.levels[1][t], eps);
            let eps_t = outside(p);
            let p = shrink(p, eps_t).clamp(0.0, 1.0);
            let at = |p: f64| observe.blue * (1.0 - p) + observe.red * p;
            let (shrunk, uniform) = (at(p), at(r));
            let target = OBSERVATION_FLOOR * uniform;
            let more = if shrunk >= target {
                0.0
            } else {
                (target - shrunk) / (uniform - shrunk)
            };
            self.shrink_by(1.0 - (1.0 - eps) * (1.0 - eps_t) * (1.0 - more));
            // Rounding may leave t's marginal an ulp outside [0, 1]; the
            // rule predicts with it inside.
            let (m0, m1t) = masses(self);
            evidence = predicted((m0, m1t.clamp(0.0, m0)));
            ruled = true;
        }
        let m0 = self.levels[0][0];
        if !(evidence.is_finite() && evidence > 0.0) {
            return Err(BeliefError::ImpossibleObservation {
                probability: top * evidence / m0,
            });
        }
        // Nothing can fail from here on.
        self.log_norm += top.ln() + (evidence / m0).ln();
        let red = observe.red / evidence;
        let blue = observe.blue / evidence;
        // M'(S) = blue·M(S) + (red − blue)·M(S ∪ {t}), computed as
        // blue·(M(S) − M(S ∪ {t})) + red·M(S ∪ {t}): the sets without t,
        // and those with it. The first form cancels to 0 when red/blue is
        // below rounding (a sighting 10^200 times likelier blue of a track
        // surely red), the second keeps red·M.
        let lifted = observe.red != observe.blue && j < n;
        if lifted {
            self.lift_to(t);
        }
        let mut set: Vec<usize> = Vec::with_capacity(j);
        // Increasing u: level u reads the old level u + 1.
        let generic_levels = if j == 0 { 1 } else { j };
        for u in 0..generic_levels {
            let (level, above) = self.levels.split_at_mut(u + 1);
            let level = &mut level[u];
            set.clear();
            set.extend(0..u);
            let mut r = 0;
            loop {
                let m = level[r];
                level[r] = if set.contains(&t) {
                    red * m
                } else if u < j {
                    let with_t = above[0][rank_with(&self.binom, &set, t)];
                    blue * (m - with_t) + red * with_t
                } else if lifted {
                    let with_t = self.scratch[j][r];
                    blue * (m - with_t) + red * with_t
                } else {
                    blue * m
                };
                r += 1;
                if !advance(&mut set, n) {
                    break;
                }
            }
        }
        if j > 0 {
            let level = &mut self.levels[j];
            let lifted_top = &self.scratch[j];
            for_each_block(&self.binom, n, j, |upper, start, width| {
                let block = &mut level[start..start + width];
                if upper.contains(&t) {
                    for m in block.iter_mut() {
                        *m *= red;
                    }
                    return;
                }
                if t < width {
                    block[t] *= red;
                }
                for range in around(width, t) {
                    let part = &mut block[range.clone()];
                    if lifted {
                        let next = &lifted_top[start + range.start..start + range.end];
                        for (m, x) in part.iter_mut().zip(next) {
                            *m = blue * (*m - x) + red * x;
                        }
                    } else {
                        for m in part.iter_mut() {
                            *m *= blue;
                        }
                    }
                }
            });
        }
        if self.reset_if_broken() {
            return Ok(());
        }
        if ruled {
            // The rule's evidence differs from the projection's by rounding
            // at most: M_0 is back at 1 but for that.
            let m0 = self.levels[0][0];
            if m0.is_finite() && m0 > 0.0 {
                for level in &mut self.levels {
                    level.iter_mut().for_each(|m| *m /= m0);
                }
            }
        }
        if self.repair == LowOrderRepair::ShrinkToUniform {
            self.shrink_if_outside();
        }
        Ok(())
    }

    fn marginals(&self) -> Result<Vec<f64>, BeliefError> {
        let raw = self.raw_marginals()?;
        Ok(raw.into_iter().map(|p| p.clamp(0.0, 1.0)).collect())
    }

    fn coefficients(&self) -> usize {
        self.levels[self.order].len()
    }

    /// Updates that needed a [`LowOrderRepair`], and sightings the prior
    /// rules out, set aside (`crate::repair`).
    fn repairs(&self) -> u64 {
        self.repairs
    }
}

/// The λ_0, …, λ_j of M_{j+1}(T) = Σ_u λ_u Σ_{U ⊆ T, |U| = u} M_u(U) on
/// R(Φ_{j,k}), with the largest relative residual of the fit.
///
/// The test functions φ_Q (|Q| = q ≤ j) span R(Φ_j), and for φ_Q
/// M_i(U) = W(|Q ∪ U|) with W(i) = C(n − i, k − i); by symmetry only
/// v = |Q ∩ T| matters, giving one equation per (q, v):
/// Σ_u λ_u Σ_w C(v, w)·C(j + 1 − v, u − w)·W(q + u − w) = W(q + j + 1 − v).
/// W is used relative to W(0) to stay in range, rows and columns are
/// equilibrated, and the system is solved by SVD: it is consistent, but
/// rank-deficient when j > n − k (then any solution serves, as M_j only
/// ranges over a subspace).
pub(crate) fn lift_coefficients(
    n: usize,
    k: usize,
    j: usize,
) -> Result<(Vec<f64>, f64), BeliefError> {
    if j > k || k > n {
        return Err(BeliefError::Unsupported {
            method: METHOD,
            what: "an order above k",
        });
    }
    if j + 1 > n {
        // There is no (j + 1)-set to lift to.
        return Ok((vec![0.0; j + 1], 0.0));
    }
    let w = normalized_weights(n, k, 2 * j + 1);
    let mut rows: Vec<Vec<f64>> = Vec::new();
    let mut rhs: Vec<f64> = Vec::new();
    for q in 0..=j {
        let v_min = (q + j + 1).saturating_sub(n);
        for v in v_min..=q.min(j + 1) {
            let row: Vec<f64> = (0..=j)
                .map(|u| {
                    let w_min = u.saturating_sub(j + 1 - v);
                    (w_min..=v.min(u))
                        .map(|x| choose(v, x) * choose(j + 1 - v, u - x) * w[q + u - x])
                        .sum()
                })
                .collect();
            let b = w[q + j + 1 - v];
            let scale = row.iter().fold(b.abs(), |s, a| s.max(a.abs()));
            if scale > 0.0 {
                rows.push(row.iter().map(|a| a / scale).collect());
                rhs.push(b / scale);
            }
        }
    }
    if rows.is_empty() {
        return Ok((vec![0.0; j + 1], 0.0));
    }
    let column_scale: Vec<f64> = (0..=j)
        .map(|u| {
            let s = rows.iter().fold(0.0f64, |s, r| s.max(r[u].abs()));
            if s > 0.0 {
                s
            } else {
                1.0
            }
        })
        .collect();
    let a = DMatrix::from_fn(rows.len(), j + 1, |r, u| rows[r][u] / column_scale[u]);
    let b = DVector::from_column_slice(&rhs);
    let svd = a.svd(true, true);
    let largest = svd.singular_values.max();
    let scaled = svd
        .solve(&b, largest * 1e-12)
        .map_err(|detail| BeliefError::Numerical {
            step: "low-order lift fit",
            detail: detail.to_string(),
        })?;
    let lift: Vec<f64> = scaled
        .iter()
        .zip(&column_scale)
        .map(|(y, s)| y / s)
        .collect();
    let mut residual = 0.0f64;
    for (row, b) in rows.iter().zip(&rhs) {
        let terms = row.iter().zip(&lift).map(|(a, l)| a * l);
        let size = terms.clone().fold(1.0f64, |s, x| s.max(x.abs()));
        let value: f64 = terms.sum();
        residual = residual.max((value - b).abs() / size);
    }
    if residual > LIFT_TOLERANCE || lift.iter().any(|l| !l.is_finite()) {
        return Err(BeliefError::Numerical {
            step: "low-order lift fit",
            detail: format!("n={n}, k={k}, j={j}: residual {residual:e}, λ = {lift:?}"),
        });
    }
    Ok((lift, residual))
}

/// W(i)/W(0) = Π_{l < i} (k − l)/(n − l) for i = 0..=top; 0 past k.
fn normalized_weights(n: usize, k: usize, top: usize) -> Vec<f64> {
    let mut w = Vec::with_capacity(top + 1);
    let mut x = 1.0;
    for i in 0..=top {
        if i > k {
            x = 0.0;
        } else if i > 0 {
            x *= (k - i + 1) as f64 / (n - i + 1) as f64;
        }
        w.push(x);
    }
    w
}

/// C(n, r) for the small arguments of the lift equations.
fn choose(n: usize, r: usize) -> f64 {
    if r > n {
        return 0.0;
    }
    (0..r.min(n - r)).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64)
}

/// Colex rank of a sorted set: Σ_i C(c_i, i + 1).
fn rank(binom: &Binomials, set: &[usize]) -> usize {
    set.iter()
        .enumerate()
        .map(|(i, &c)| binom.get(c, i + 1))
        .sum()
}

/// Rank of the sorted set with its element at position `skip` removed.
fn rank_without(binom: &Binomials, set: &[usize], skip: usize) -> usize {
    let mut r = 0;
    for (i, &c) in set.iter().enumerate() {
        if i < skip {
            r += binom.get(c, i + 1);
        } else if i > skip {
            r += binom.get(c, i);
        }
    }
    r
}

/// Rank of the sorted set with `extra` (not in it) added.
fn rank_with(binom: &Binomials, set: &[usize], extra: usize) -> usize {
    let mut r = 0;
    let mut shift = 1;
    for (i, &c) in set.iter().enumerate() {
        if shift == 1 && c > extra {
            r += binom.get(extra, i + 1);
            shift = 2;
        }
        r += binom.get(c, i + shift);
    }
    if shift == 1 {
        r += binom.get(extra, set.len() + 1);
    }
    r
}

/// Steps a sorted set of distinct values below `n` to its colex successor;
/// false (set unchanged) when it was the last.
fn advance(set: &mut [usize], n: usize) -> bool {
    let len = set.len();
    for i in 0..len {
        let limit = if i + 1 < len { set[i + 1] } else { n };
        if set[i] + 1 < limit {
            set[i] += 1;
            for (l, x) in set[..i].iter_mut().enumerate() {
                *x = l;
            }
            return true;
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::baseline::DenseFilter;
    use crate::event::{Event, RedCount};
    use crate::workload::{generate, WorkloadSpec};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn spec(n: usize, k: usize, mix_share: f64, seed: u64) -> WorkloadSpec {
        WorkloadSpec {
            tracks: n,
            red: k,
            events: 150,
            mix_share,
            swap: 0.35,
            neighbourhood: n,
            seed,
        }
    }

    fn run_both(field: Field, order: usize, events: &[Event], tol: f64, check_pairs: bool) {
        let mut dense = DenseFilter::new(field.clone()).unwrap();
        // The repair must never fire where the filter is exact.
        let mut low =
            LowOrderFilter::with_repair(field, order, LowOrderRepair::ShrinkToUniform).unwrap();
        let n = dense.field().tracks as u32;
        for (i, event) in events.iter().enumerate() {
            dense.apply(event).unwrap();
            low.apply(event).unwrap();
            let (d, l) = (dense.marginals().unwrap(), low.marginals().unwrap());
            for (a, b) in d.iter().zip(&l) {
                assert!((a - b).abs() < tol, "event {i}: {d:?} vs {l:?}");
            }
            if check_pairs && low.order() >= 2 {
                for a in 0..n {
                    for b in a + 1..n {
                        let (pd, pl) = (
                            dense.prob_all_red(&[a, b]).unwrap(),
                            low.prob_all_red(&[a, b]).unwrap(),
                        );
                        assert!((pd - pl).abs() < tol, "event {i}, {{{a},{b}}}");
                    }
                }
            }
        }
        assert!(
            (dense.log_normalizer() - low.log_normalizer()).abs() < 1e-9,
            "{} vs {}",
            dense.log_normalizer(),
            low.log_normalizer()
        );
        assert_eq!(low.repairs(), 0);
    }

    #[test]
    fn exact_when_the_order_reaches_k() {
        for (n, k, order, seed) in [(6, 2, 2, 1), (6, 2, 5, 2), (7, 3, 3, 3), (5, 1, 1, 4)] {
            let work = generate(&spec(n, k, 0.5, seed));
            run_both(Field::uniform(n, k), order, &work.events, 1e-9, true);
            run_both(
                Field::known(n, work.initial_red.clone()),
                order,
                &work.events,
                1e-9,
                true,
            );
        }
    }

    /// R(Φ_{j,k}) is everything once j ≥ n − k, though j < k.
    #[test]
    fn exact_when_the_order_reaches_n_minus_k() {
        for (n, k, order, seed) in [(6, 4, 2, 5), (7, 5, 2, 6), (5, 3, 2, 7), (6, 5, 1, 8)] {
            let work = generate(&spec(n, k, 0.5, seed));
            run_both(Field::uniform(n, k), order, &work.events, 1e-9, true);
            run_both(
                Field::known(n, work.initial_red.clone()),
                order,
                &work.events,
                1e-9,
                true,
            );
        }
    }

    /// Without observations nothing is projected away: M_j evolves exactly,
    /// for any order.
    #[test]
    fn rollup_commutes_with_the_projection() {
        for order in 1..=3 {
            let work = generate(&spec(8, 4, 1.0, 10 + order as u64));
            run_both(
                Field::known(8, work.initial_red.clone()),
                order,
                &work.events,
                1e-12,
                true,
            );
        }
    }

    #[test]
    fn low_orders_are_approximate_once_observations_arrive() {
        let work = generate(&spec(8, 4, 0.5, 20));
        let field = Field::known(8, work.initial_red.clone());
        let mut dense = DenseFilter::new(field.clone()).unwrap();
        let mut low = LowOrderFilter::new(field, 1).unwrap();
        let mut worst = 0.0f64;
        for event in &work.events {
            dense.apply(event).unwrap();
            low.apply(event).unwrap();
            let (d, l) = (dense.marginals().unwrap(), low.marginals().unwrap());
            for (a, b) in d.iter().zip(&l) {
                worst = worst.max((a - b).abs());
            }
        }
        assert!(worst > 1e-3, "order 1 tracked the exact filter: {worst}");
    }

    /// On the Table III workload the pure method leaves the simplex until an
    /// observation gets a negative predicted probability, which it takes
    /// only by the rule for such observations (a repair); the shrink repair
    /// keeps every marginal in [0, 1] and the run going.
    #[test]
    fn shrink_repair_keeps_the_table3_workload_running() {
        let (n, k) = (20, 10);
        let work = generate(&WorkloadSpec::table3(n, 5));
        let field = Field::known(n, work.initial_red.clone());
        let mut pure_failed = 0;
        for order in 1..=3 {
            let mut pure = LowOrderFilter::new(field.clone(), order).unwrap();
            for e in &work.events {
                pure.apply(e).unwrap();
            }
            if pure.repairs() > 0 {
                pure_failed += 1;
            }
            let mut repaired =
                LowOrderFilter::with_repair(field.clone(), order, LowOrderRepair::ShrinkToUniform)
                    .unwrap();
            for event in &work.events {
                repaired.apply(event).unwrap();
                let raw = repaired.raw_marginals().unwrap();
                assert!(
                    raw.iter().all(|p| (-1e-9..=1.0 + 1e-9).contains(p)),
                    "{raw:?}"
                );
                assert!((raw.iter().sum::<f64>() - k as f64).abs() < 1e-8);
            }
            assert!(repaired.repairs() > 0);
            assert!(repaired.log_normalizer().is_finite());
        }
        assert!(pure_failed > 0);
    }

    #[test]
    fn order_one_marginals_sum_to_k() {
        let work = generate(&spec(10, 5, 0.5, 30));
        let mut low = LowOrderFilter::new(Field::known(10, work.initial_red.clone()), 1).unwrap();
        assert_eq!(low.coefficients(), 10);
        for event in work.events.iter().take(25) {
            low.apply(event).unwrap();
            let raw: f64 = low.levels[1].iter().sum::<f64>() / low.levels[0][0];
            assert!((raw - 5.0).abs() < 1e-9, "{raw}");
        }
        let p = low.marginals().unwrap();
        assert!(p.iter().all(|x| (0.0..=1.0).contains(x)));
        assert!((p.iter().sum::<f64>() - 5.0).abs() < 1e-9, "{p:?}");
    }

    /// The fit is consistent, and the fitted formula gives M_{j+1} of random
    /// elements of R(Φ_j), checked against brute force over the k-sets.
    #[test]
    fn lift_fit_is_consistent_and_correct() {
        let mut rng = ChaCha8Rng::seed_from_u64(40);
        for (n, k, j) in [
            (7, 3, 1),
            (7, 3, 2),
            (8, 4, 3),
            (9, 4, 2),
            (6, 4, 2),
            (6, 4, 3),
            (6, 3, 3),
            (10, 2, 1),
        ] {
            let (lift, residual) = lift_coefficients(n, k, j).unwrap();
            assert!(residual < 1e-12, "({n},{k},{j}): {residual}");
            let ksets: Vec<u32> = (0u32..1 << n)
                .filter(|x| x.count_ones() as usize == k)
                .collect();
            let jsets: Vec<u32> = (0u32..1 << n)
                .filter(|x| x.count_ones() as usize == j)
                .collect();
            let coef: Vec<f64> = jsets.iter().map(|_| rng.gen_range(-1.0..1.0)).collect();
            let f: Vec<f64> = ksets
                .iter()
                .map(|&x| {
                    jsets
                        .iter()
                        .zip(&coef)
                        .filter(|(r, _)| *r & x == **r)
                        .map(|(_, c)| c)
                        .sum()
                })
                .collect();
            let marginal = |s: u32| -> f64 {
                ksets
                    .iter()
                    .zip(&f)
                    .filter(|(x, _)| *x & s == s)
                    .map(|(_, v)| v)
                    .sum()
            };
            let mut worst = 0.0f64;
            for t in (0u32..1 << n).filter(|x| x.count_ones() as usize == j + 1) {
                let mut predicted = 0.0;
                for u in (0..t).filter(|u| u & t == *u) {
                    predicted += lift[u.count_ones() as usize] * marginal(u);
                }
                worst = worst.max((predicted - marginal(t)).abs());
            }
            assert!(worst < 1e-9, "({n},{k},{j}): {worst}, λ = {lift:?}");
        }
        for (n, k, j) in [
            (20, 10, 3),
            (60, 30, 3),
            (100, 50, 3),
            (100, 50, 1),
            (1000, 3, 3),
        ] {
            let (_, residual) = lift_coefficients(n, k, j).unwrap();
            assert!(residual < 1e-10, "({n},{k},{j}): {residual}");
        }
    }

    /// The filter against the definition: the full belief over the k-sets,
    /// conditioned exactly and then projected with the pseudoinverse of
    /// Φ_{j,k}. Raw (unclamped) marginals and normalizers must agree, and
    /// so must the verdict when the projected belief predicts a
    /// non-positive probability for an observation.
    #[test]
    fn matches_the_brute_force_projection() {
        for (n, k, order, seed) in [
            (10, 5, 1, 50),
            (10, 5, 2, 51),
            (9, 4, 3, 52),
            (10, 3, 2, 53),
        ] {
            let ksets: Vec<u32> = (0u32..1 << n)
                .filter(|x| x.count_ones() as usize == k)
                .collect();
            let jsets: Vec<u32> = (0u32..1 << n)
                .filter(|x| x.count_ones() as usize == order)
                .collect();
            let phi = DMatrix::from_fn(ksets.len(), jsets.len(), |r, c| {
                f64::from(u8::from(jsets[c] & ksets[r] == jsets[c]))
            });
            let projector = &phi * phi.clone().pseudo_inverse(1e-10).unwrap();
            let work = generate(&WorkloadSpec {
                events: 300,
                ..spec(n, k, 0.5, seed)
            });
            let start = Field::known(n, work.initial_red.clone());
            let mut low = LowOrderFilter::new(start, order).unwrap();
            let x0: u32 = work.initial_red.iter().map(|t| 1u32 << t).sum();
            // The filter only ever holds the projection of the start.
            let delta = DVector::from_iterator(
                ksets.len(),
                ksets.iter().map(|&x| f64::from(u8::from(x == x0))),
            );
            let mut f = &projector * delta;
            let mut log_z = 0.0f64;
            for (i, event) in work.events.iter().enumerate() {
                match *event {
                    Event::Mix(Mix { a, b, swap }) => {
                        let both = (1u32 << a) | (1 << b);
                        let old = f.clone();
                        for (r, &x) in ksets.iter().enumerate() {
                            if (x & both).count_ones() == 1 {
                                let partner = ksets.binary_search(&(x ^ both)).unwrap();
                                f[r] = (1.0 - swap) * old[r] + swap * old[partner];
                            }
                        }
                        low.mix(Mix { a, b, swap }).unwrap();
                    }
                    Event::Observe(obs) => {
                        let total = f.sum();
                        for (r, &x) in ksets.iter().enumerate() {
                            f[r] *= if x >> obs.track & 1 == 1 {
                                obs.red
                            } else {
                                obs.blue
                            };
                        }
                        f = &projector * &f;
                        let evidence = f.sum() / total;
                        low.observe(obs).unwrap();
                        if evidence <= 0.0 {
                            // Taken by the rule, not the projection: the
                            // brute force has nothing left to compare.
                            assert_eq!(low.repairs(), 1, "({n},{k},{order}) event {i}");
                            break;
                        }
                        log_z += evidence.ln();
                        f /= f.sum();
                    }
                }
                for t in 0..n {
                    let exact: f64 = ksets
                        .iter()
                        .zip(f.iter())
                        .filter(|(x, _)| *x >> t & 1 == 1)
                        .map(|(_, v)| v)
                        .sum::<f64>()
                        / f.sum();
                    let raw = low.levels[1][t] / low.levels[0][0];
                    assert!(
                        (exact - raw).abs() < 1e-8,
                        "({n},{k},{order}) event {i}, track {t}"
                    );
                }
                assert!((low.log_normalizer() - log_z).abs() < 1e-8);
            }
        }
    }

    #[test]
    fn ranks_are_colex() {
        let binom = Binomials::new(7, 3);
        let mut set = vec![0, 1, 2];
        let mut r = 0;
        loop {
            assert_eq!(rank(&binom, &set), r);
            for p in 0..3 {
                let mut less = set.clone();
                less.remove(p);
                assert_eq!(rank_without(&binom, &set, p), rank(&binom, &less));
            }
            r += 1;
            if !advance(&mut set, 7) {
                break;
            }
        }
        assert_eq!(r, 35);
        let pair = [1, 4];
        for extra in [0, 2, 3, 5, 6] {
            let mut more = vec![1, 4, extra];
            more.sort_unstable();
            assert_eq!(rank_with(&binom, &pair, extra), rank(&binom, &more));
        }
    }

    #[test]
    fn refuses_what_it_cannot_do() {
        let unknown = Field {
            tracks: 5,
            red: RedCount::unknown_uniform(5),
            initial_red: None,
        };
        assert!(matches!(
            LowOrderFilter::new(unknown, 1),
            Err(BeliefError::Unsupported { .. })
        ));
        assert!(matches!(
            LowOrderFilter::new(Field::uniform(5, 2), 0),
            Err(BeliefError::Unsupported { .. })
        ));
        assert!(matches!(
            LowOrderFilter::new(Field::uniform(10_000, 5_000), 3),
            Err(BeliefError::TooLarge { .. })
        ));
        let low = LowOrderFilter::new(Field::uniform(5, 2), 3).unwrap();
        assert_eq!(low.order(), 2);
        assert_eq!(low.coefficients(), 10);
        assert!(low.prob_all_red(&[0, 1, 2]).is_err());
    }

    #[test]
    fn no_red_or_all_red_is_certain() {
        for k in [0, 5] {
            let mut low = LowOrderFilter::new(Field::uniform(5, k), 2).unwrap();
            low.mix(Mix {
                a: 0,
                b: 4,
                swap: 0.5,
            })
            .unwrap();
            low.observe(Observe {
                track: 2,
                red: 0.9,
                blue: 0.2,
            })
            .unwrap();
            let want = if k == 0 { 0.0 } else { 1.0 };
            assert!(low.marginals().unwrap().iter().all(|p| *p == want));
            let likelihood: f64 = if k == 0 { 0.2 } else { 0.9 };
            assert!((low.log_normalizer() - likelihood.ln()).abs() < 1e-15);
        }
    }

    /// A certain sighting of a track the belief holds blue for sure: the
    /// filter cannot tell it from a valid one its projection lost, so it
    /// takes it by the rule (a mix with the uniform belief) and believes it.
    #[test]
    fn a_sighting_the_belief_rules_out_is_taken_by_the_rule() {
        let mut low = LowOrderFilter::new(Field::known(4, vec![0, 1]), 1).unwrap();
        low.mix(Mix {
            a: 0,
            b: 2,
            swap: 0.5,
        })
        .unwrap();
        assert_eq!(low.raw_marginals().unwrap()[3], 0.0);
        low.observe(Observe {
            track: 3,
            red: 1.0,
            blue: 0.0,
        })
        .unwrap();
        assert_eq!(low.repairs(), 1);
        let p = low.raw_marginals().unwrap();
        assert!((p[3] - 1.0).abs() < 1e-9, "{p:?}");
        assert!((p.iter().sum::<f64>() - 2.0).abs() < 1e-9);
        assert!(low.log_normalizer().is_finite());
    }

    /// Release-mode timing for the report.
    /// `cargo test -p idmesh-belief --release low_order_timing -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn low_order_timing_n100_k50_order3() {
        let work = generate(&WorkloadSpec::table3(100, 5));
        let field = Field::known(100, work.initial_red.clone());
        let mut low =
            LowOrderFilter::with_repair(field, 3, LowOrderRepair::ShrinkToUniform).unwrap();
        let start = std::time::Instant::now();
        for event in &work.events {
            low.apply(event).unwrap();
        }
        let elapsed = start.elapsed();
        let p = low.marginals().unwrap();
        println!(
            "low-order j=3 n=100 k=50, 1000 events: {elapsed:?} ({} repairs, marginal sum {})",
            low.repairs(),
            p.iter().sum::<f64>()
        );
    }
}
