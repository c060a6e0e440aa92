//! The exact filter over every admissible red set (Sections 3.1–3.4 of
//! Jiang et al., TOSN 2013): the Markov model of Fig. 2 run literally, with
//! the rollup of Section 3.3 (Table II) and the Bayes rule of Section 3.4.
//! It is exponential in n and exists to be the yardstick: the Radon engine
//! without pruning must agree with it, and every approximation is scored
//! against it.
//!
//! ## Layout
//! - k known: the C(n, k) k-sets in colex order, which is numeric order of
//!   their bit masks. Colex order nests: the k-sets of [0, m) are the first
//!   C(m, k) ranks, those without m − 1 before those with it. So the sets
//!   sharing their tracks ≥ m form one contiguous *region*, the kk-sets of
//!   [0, m) in colex order, and an update descends the regions from the top
//!   track down:
//!   - an observation of t finds runs of consecutive states that all hold t
//!     or all lack it;
//!   - a mix of lo < hi pairs a region of sets without hi with the region of
//!     sets with hi that agrees above lo; at lo the two sides are the same
//!     list of sets, so the pairs are two equally long slices.
//!
//!   Below [`LOW`] tracks the runs get short and the descent costs more
//!   than the work, so the regions of the LOW lowest tracks are handled by
//!   small precomputed patterns instead.
//! - k unknown: all 2^n subsets indexed by the mask itself; the runs are
//!   plain strides.

use super::{binomial_f64, Binomials};
use crate::error::BeliefError;
use crate::event::{Field, Mix, Observe, RedCount};
use crate::filter::PropertyFilter;
use crate::repair::{self, REPAIR_SHARE};
use std::ops::Range;

/// The most states a [`DenseFilter`] (and a
/// [`LowOrderFilter`](super::LowOrderFilter)) will allocate: 2^26 = 64 Mi
/// states, 512 MiB of f64.
pub const MAX_STATES: usize = 1 << 26;

/// The most tracks a [`DenseFilter`] handles: sets are u64 bit masks.
pub(crate) const MAX_TRACKS: usize = 64;

/// The least probability a state the events allow is stored with: the
/// smallest normal f64, so that a later sighting of likelihood ratio up to
/// 10^300 against it still finds a normal, positive predicted probability.
pub(crate) const SUPPORT_FLOOR: f64 = f64::MIN_POSITIVE;

/// `x`, or [`SUPPORT_FLOOR`] when its exact value is positive but rounded
/// below it (`positive` says whether the exact value is positive).
#[inline]
fn floored(x: f64, positive: bool) -> f64 {
    if positive && x < SUPPORT_FLOOR {
        SUPPORT_FLOOR
    } else {
        x
    }
}

/// Regions over the tracks below this are walked by precomputed patterns.
const LOW: usize = 8;

#[derive(Debug, Clone)]
enum Space {
    /// The k-sets of [0, n) in colex order.
    KSets {
        k: usize,
        binom: Binomials,
        low: LowPatterns,
    },
    /// Every subset of [0, n), indexed by its mask.
    Subsets,
}

/// Local ranks (x, y) of the two sets of each pair a mix blends.
type PairList = Vec<(u16, u16)>;

/// For the regions over [0, m0), m0 = min(n, LOW), indexed by the local
/// colex rank of a set within its region.
#[derive(Debug, Clone)]
struct LowPatterns {
    m0: usize,
    /// `holds[t][kk][i]`: whether the i-th kk-set of [0, m0) holds t.
    holds: Vec<Vec<Vec<bool>>>,
    /// `cross[lo][k1]`: for each (k1 − 1)-set B of [0, m0) − {lo}, the ranks
    /// of B ∪ {lo} among the k1-sets and of B among the (k1 − 1)-sets.
    cross: Vec<Vec<PairList>>,
    /// `inner[lo][hi][kk]` (lo < hi): for each (kk − 1)-set B of
    /// [0, m0) − {lo, hi}, the ranks of B ∪ {lo} and B ∪ {hi} among the
    /// kk-sets.
    inner: Vec<Vec<Vec<PairList>>>,
}

impl LowPatterns {
    fn new(n: usize, binom: &Binomials) -> Self {
        let m0 = n.min(LOW);
        let sets: Vec<Vec<u64>> = (0..=m0)
            .map(|kk| {
                let mut masks: Vec<u64> = (0u64..1 << m0)
                    .filter(|m| m.count_ones() as usize == kk)
                    .collect();
                masks.sort_unstable();
                masks
            })
            .collect();
        let local = |mask: u64| rank_mask(binom, mask) as u16;
        let holds = (0..m0)
            .map(|t| {
                sets.iter()
                    .map(|masks| masks.iter().map(|m| m & (1 << t) != 0).collect())
                    .collect()
            })
            .collect();
        let cross = (0..m0)
            .map(|lo| {
                (0..=m0)
                    .map(|k1| {
                        if k1 == 0 {
                            return Vec::new();
                        }
                        sets[k1 - 1]
                            .iter()
                            .filter(|b| *b & (1 << lo) == 0)
                            .map(|b| (local(b | 1 << lo), local(*b)))
                            .collect()
                    })
                    .collect()
            })
            .collect();
        let inner = (0..m0)
            .map(|lo| {
                (0..m0)
                    .map(|hi| {
                        (0..=m0)
                            .map(|kk| {
                                if hi <= lo || kk == 0 {
                                    return Vec::new();
                                }
                                let both = (1u64 << lo) | (1 << hi);
                                sets[kk - 1]
                                    .iter()
                                    .filter(|b| *b & both == 0)
                                    .map(|b| (local(b | 1 << lo), local(b | 1 << hi)))
                                    .collect()
                            })
                            .collect()
                    })
                    .collect()
            })
            .collect();
        LowPatterns {
            m0,
            holds,
            cross,
            inner,
        }
    }
}

/// A stretch of states, by whether they hold the observed track.
enum Piece<'a> {
    /// Consecutive states that all hold it (true) or all lack it.
    Run(Range<usize>, bool),
    /// Consecutive states from an offset, one flag per state.
    Pattern(usize, &'a [bool]),
}

/// The exact belief over red sets: one probability per admissible set.
///
/// With k known the states are the C(n, k) k-sets; with k unknown they are
/// all 2^n subsets, the prior weight of a set x being prior[|x|]/C(n, |x|).
/// Construction fails with [`BeliefError::TooLarge`] when the state count
/// exceeds [`MAX_STATES`] (2^26 states, 512 MiB; e.g. n = 40, k = 20 needs
/// 1.4·10^11) and with [`BeliefError::Unsupported`] beyond [`MAX_TRACKS`]
/// (64) tracks.
///
/// Each update costs O(states): a mix touches only the states holding
/// exactly one of its tracks, an observation touches every state once to
/// sum and once to scale. The belief is kept normalized; the normalizer is
/// kept in log space (see [`DenseFilter::log_normalizer`]).
///
/// A state the events allow never becomes 0: an update whose exact result
/// is positive stores at least [`SUPPORT_FLOOR`]. Sightings 10^200 times
/// likelier for the wrong colour take the truth below the smallest f64 in
/// two steps, and a later certain sighting may leave only it; flushed to 0,
/// the filter would have found no mass for a valid stream. The floor moves
/// a probability by at most 2.2·10^-308, so the belief is exact to that,
/// and its support (which sets have positive probability) is exact.
#[derive(Debug, Clone)]
pub struct DenseFilter {
    field: Field,
    space: Space,
    /// P(x) per state, summing to 1.
    probs: Vec<f64>,
    log_norm: f64,
    /// Sightings taken by the repair rule or set aside (`crate::repair`).
    repairs: u64,
}

impl DenseFilter {
    pub fn new(field: Field) -> Result<Self, BeliefError> {
        field.validate()?;
        let n = field.tracks;
        if n > MAX_TRACKS {
            return Err(BeliefError::Unsupported {
                method: "exact",
                what: "more than 64 tracks",
            });
        }
        let initial_mask = field.initial_red.as_ref().map(|red| mask_of(red));
        let (space, probs, log_norm) = match &field.red {
            RedCount::Known(k) => {
                let k = *k;
                let needed = binomial_f64(n, k);
                if needed > MAX_STATES as f64 {
                    return Err(BeliefError::TooLarge {
                        method: "exact",
                        needed,
                        limit: MAX_STATES,
                    });
                }
                let binom = Binomials::new(n, n);
                let states = binom.get(n, k);
                let (probs, log_norm) = match initial_mask {
                    Some(mask) => {
                        let mut probs = vec![0.0; states];
                        probs[rank_mask(&binom, mask)] = 1.0;
                        (probs, 0.0)
                    }
                    None => (vec![1.0 / states as f64; states], (states as f64).ln()),
                };
                let low = LowPatterns::new(n, &binom);
                (Space::KSets { k, binom, low }, probs, log_norm)
            }
            RedCount::Unknown { prior } => {
                if n >= usize::BITS as usize || (1usize << n) > MAX_STATES {
                    return Err(BeliefError::TooLarge {
                        method: "exact",
                        needed: 2f64.powi(n as i32),
                        limit: MAX_STATES,
                    });
                }
                let states = 1usize << n;
                let probs = match initial_mask {
                    Some(mask) => {
                        let mut probs = vec![0.0; states];
                        probs[mask as usize] = 1.0;
                        probs
                    }
                    None => {
                        // Every set of a size equally likely: prior[j]/C(n, j).
                        let total: f64 = prior.iter().sum();
                        let per_set: Vec<f64> = prior
                            .iter()
                            .enumerate()
                            .map(|(j, p)| p / total / binomial_f64(n, j))
                            .collect();
                        (0..states)
                            .map(|mask| per_set[mask.count_ones() as usize])
                            .collect()
                    }
                };
                // Weighted by the prior, the admissible sets count 1 in all.
                (Space::Subsets, probs, 0.0)
            }
        };
        Ok(DenseFilter {
            field,
            space,
            probs,
            log_norm,
            repairs: 0,
        })
    }

    /// ln Z, Z = Σ_x f(x) of the unnormalized belief: the prior mass (C(n, k)
    /// for the uniform prior with k known, 1 for a known initial set or a
    /// prior over the count) times the likelihood of every observation so
    /// far. Same meaning as [`RadonBelief::log_normalizer`](crate::RadonBelief::log_normalizer).
    pub fn log_normalizer(&self) -> f64 {
        self.log_norm + sum(&self.probs).ln()
    }

    /// P(every track of `tracks` is red). Repeated tracks count once.
    pub fn prob_all_red(&self, tracks: &[u32]) -> Result<f64, BeliefError> {
        for &t in tracks {
            self.field.check_track(t)?;
        }
        let want = mask_of(tracks);
        let total = self.checked_total()?;
        let mut sum = 0.0;
        self.for_each_state(|mask, p| {
            if mask & want == want {
                sum += p;
            }
        });
        Ok(sum / total)
    }

    /// P(the red tracks are exactly `tracks`); 0 for a set the field does not
    /// admit. Repeated tracks count once.
    #[cfg(test)]
    pub(crate) fn prob_red_set(&self, tracks: &[u32]) -> Result<f64, BeliefError> {
        for &t in tracks {
            self.field.check_track(t)?;
        }
        let mask = mask_of(tracks);
        let total = self.checked_total()?;
        let p = match &self.space {
            Space::KSets { k, binom, .. } => {
                if mask.count_ones() as usize != *k {
                    return Ok(0.0);
                }
                self.probs[rank_mask(binom, mask)]
            }
            Space::Subsets => self.probs[mask as usize],
        };
        Ok(p / total)
    }

    /// P(exactly j tracks are red) for j = 0..=n; a single 1 at k when k is
    /// known.
    pub fn count_posterior(&self) -> Result<Vec<f64>, BeliefError> {
        let total = self.checked_total()?;
        let mut posterior = vec![0.0; self.field.tracks + 1];
        self.for_each_state(|mask, p| posterior[mask.count_ones() as usize] += p);
        for p in &mut posterior {
            *p /= total;
        }
        Ok(posterior)
    }

    fn checked_total(&self) -> Result<f64, BeliefError> {
        let total = sum(&self.probs);
        if total.is_finite() && total > 0.0 {
            Ok(total)
        } else {
            Err(BeliefError::Degenerate { normalizer: total })
        }
    }

    /// Calls `visit(mask, p)` for every state in storage order.
    fn for_each_state(&self, mut visit: impl FnMut(u64, f64)) {
        match &self.space {
            Space::KSets { k, .. } => {
                // Colex rank order is numeric mask order, walked by Gosper's
                // hack; the empty set has no successor to compute.
                let mut mask: u64 = if *k == 0 { 0 } else { u64::MAX >> (64 - k) };
                let last = self.probs.len() - 1;
                for (rank, &p) in self.probs.iter().enumerate() {
                    visit(mask, p);
                    if rank < last {
                        mask = next_same_weight(mask);
                    }
                }
            }
            Space::Subsets => {
                for (mask, &p) in self.probs.iter().enumerate() {
                    visit(mask as u64, p);
                }
            }
        }
    }

    /// (mass of the states holding t, mass of the others).
    fn split_mass(&self, t: usize) -> (f64, f64) {
        let (mut with_t, mut without_t) = (0.0, 0.0);
        match &self.space {
            Space::KSets { k, binom, low } => {
                let probs = &self.probs;
                let n = self.field.tracks;
                pieces(binom, low, n, *k, 0, t, &mut |piece| match piece {
                    Piece::Run(run, holds) => {
                        let s = sum(&probs[run]);
                        if holds {
                            with_t += s;
                        } else {
                            without_t += s;
                        }
                    }
                    Piece::Pattern(at, holds) => {
                        let slice = &probs[at..at + holds.len()];
                        // Both sides summed, not one as the difference
                        // from the whole: that cancels a side 10^-16 of
                        // the other to 0, and a certain sighting of it
                        // then finds no mass.
                        let (with, without) = masked_sums(slice, holds);
                        with_t += with;
                        without_t += without;
                    }
                });
            }
            Space::Subsets => {
                let half = 1usize << t;
                for block in self.probs.chunks_exact(2 * half) {
                    without_t += sum(&block[..half]);
                    with_t += sum(&block[half..]);
                }
            }
        }
        (with_t, without_t)
    }

    /// Bayes' rule for one sighting; refused as impossible, the state
    /// unchanged, where the belief gives it probability 0.
    fn condition(&mut self, observe: Observe) -> Result<(), BeliefError> {
        let t = observe.track as usize;
        let (with_t, without_t) = self.split_mass(t);
        let total = with_t + without_t;
        // Likelihoods scaled to a largest of 1, so that the predicted
        // probability of a sighting likelier than 1 for one colour does not
        // overflow, nor one of a floored state underflow.
        let top = observe.red.max(observe.blue);
        let (red, blue) = (observe.red / top, observe.blue / top);
        let evidence = red * with_t + blue * without_t;
        if !(evidence.is_finite() && evidence > 0.0) {
            return Err(BeliefError::ImpossibleObservation {
                probability: top * evidence / total,
            });
        }
        let (red, blue) = (red / evidence, blue / evidence);
        // Exactly 0 only for a likelihood of 0 (see `SUPPORT_FLOOR`).
        let scale = |p: &mut f64, factor: f64| {
            let positive = *p > 0.0 && factor > 0.0;
            *p = floored(*p * factor, positive);
        };
        let probs = &mut self.probs;
        match &self.space {
            Space::KSets { k, binom, low } => {
                let n = self.field.tracks;
                pieces(binom, low, n, *k, 0, t, &mut |piece| match piece {
                    Piece::Run(run, holds) => {
                        let factor = if holds { red } else { blue };
                        for p in &mut probs[run] {
                            scale(p, factor);
                        }
                    }
                    Piece::Pattern(at, holds) => {
                        for (p, &h) in probs[at..at + holds.len()].iter_mut().zip(holds) {
                            scale(p, if h { red } else { blue });
                        }
                    }
                });
            }
            Space::Subsets => {
                for (mask, p) in probs.iter_mut().enumerate() {
                    scale(p, if mask >> t & 1 == 1 { red } else { blue });
                }
            }
        }
        self.log_norm += top.ln() + (evidence / total).ln();
        Ok(())
    }

    /// Gives [`REPAIR_SHARE`] of the mass to the uninformed prior: the
    /// uniform k-sets, or each set as the count prior weighs it.
    fn smooth(&mut self) {
        let keep = 1.0 - REPAIR_SHARE;
        match (&self.space, &self.field.red) {
            (Space::Subsets, RedCount::Unknown { prior }) => {
                let n = self.field.tracks;
                let total: f64 = prior.iter().sum();
                let per_set: Vec<f64> = (0..=n)
                    .map(|j| REPAIR_SHARE * prior[j] / total / binomial_f64(n, j))
                    .collect();
                for (mask, p) in self.probs.iter_mut().enumerate() {
                    *p = *p * keep + per_set[mask.count_ones() as usize];
                }
            }
            _ => {
                let per_set = REPAIR_SHARE / self.probs.len() as f64;
                for p in &mut self.probs {
                    *p = *p * keep + per_set;
                }
            }
        }
    }
}

impl PropertyFilter for DenseFilter {
    fn field(&self) -> &Field {
        &self.field
    }

    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        self.field.check_mix(&mix)?;
        if mix.swap == 0.0 {
            return Ok(());
        }
        let (lo, hi) = if mix.a < mix.b {
            (mix.a as usize, mix.b as usize)
        } else {
            (mix.b as usize, mix.a as usize)
        };
        let swap = mix.swap;
        let stay = 1.0 - swap;
        let probs = &mut self.probs;
        let blend = |fx: &mut f64, fy: &mut f64| {
            let (x, y) = (*fx, *fy);
            // Positive exactly when either state was (stay, swap > 0 here
            // unless swap = 1, which moves values exactly).
            let either = x > 0.0 || y > 0.0;
            *fx = stay * x + swap * y;
            *fy = stay * y + swap * x;
            if either && stay > 0.0 {
                *fx = floored(*fx, true);
                *fy = floored(*fy, true);
            }
        };
        // x holds lo but not hi, y = x △ {lo, hi}; x always ranks below y.
        let mut visit = |pairs: Pairs| match pairs {
            Pairs::Runs(x_start, y_start, len) => {
                let (left, right) = probs.split_at_mut(y_start);
                for (x, y) in left[x_start..x_start + len]
                    .iter_mut()
                    .zip(&mut right[..len])
                {
                    blend(x, y);
                }
            }
            Pairs::Listed(x_base, y_base, list) => {
                let (left, right) = probs.split_at_mut(y_base);
                let xs = &mut left[x_base..];
                for &(dx, dy) in list {
                    blend(&mut xs[dx as usize], &mut right[dy as usize]);
                }
            }
            Pairs::Within(base, list) => {
                let region = &mut probs[base..];
                for &(dx, dy) in list {
                    let (left, right) = region.split_at_mut(dy as usize);
                    blend(&mut left[dx as usize], &mut right[0]);
                }
            }
        };
        match &self.space {
            Space::KSets { k, binom, low } => {
                let walk = PairWalk { binom, low, lo, hi };
                walk.above(self.field.tracks, *k, 0, &mut visit);
            }
            Space::Subsets => {
                let len = 1usize << lo;
                let total = 1usize << self.field.tracks;
                for base in (0..total).step_by(2 << hi) {
                    for low in (0..1usize << hi).step_by(2 << lo) {
                        visit(Pairs::Runs(base + low + len, base + (1 << hi) + low, len));
                    }
                }
            }
        }
        Ok(())
    }

    /// By the repair rule where the belief rules the sighting out
    /// (`crate::repair`). After a repair [`DenseFilter::log_normalizer`]
    /// no longer is the evidence of the stream: the stream had none.
    fn observe(&mut self, observe: Observe) -> Result<(), BeliefError> {
        self.field.check_observe(&observe)?;
        if self.field.rules_out(&observe) {
            repair::note("exact", &mut self.repairs, &observe, true);
            return Ok(());
        }
        match self.condition(observe) {
            Err(BeliefError::ImpossibleObservation { .. }) => {
                // The prior allows the sighting, so after the smoothing
                // its probability is at least REPAIR_SHARE times the
                // prior's: the second conditioning cannot find it
                // impossible.
                self.smooth();
                self.condition(observe)?;
                repair::note("exact", &mut self.repairs, &observe, false);
                Ok(())
            }
            done => done,
        }
    }

    fn marginals(&self) -> Result<Vec<f64>, BeliefError> {
        let total = self.checked_total()?;
        let n = self.field.tracks;
        let mut marginals = vec![0.0; n];
        self.for_each_state(|mut mask, p| {
            while mask != 0 {
                marginals[mask.trailing_zeros() as usize] += p;
                mask &= mask - 1;
            }
        });
        for m in &mut marginals {
            // A sum of most of the mass may round an ulp above the total.
            *m = (*m / total).min(1.0);
        }
        Ok(marginals)
    }

    fn coefficients(&self) -> usize {
        self.probs.len()
    }

    fn repairs(&self) -> u64 {
        self.repairs
    }
}

/// Σ xs in eight interleaved partial sums: one running sum would make every
/// addition wait for the previous one.
fn sum(xs: &[f64]) -> f64 {
    let mut acc = [0.0f64; 8];
    let chunks = xs.chunks_exact(8);
    let rest: f64 = chunks.remainder().iter().sum();
    for chunk in chunks {
        for (a, x) in acc.iter_mut().zip(chunk) {
            *a += x;
        }
    }
    acc.iter().sum::<f64>() + rest
}

/// (Σ xs[i] over the i with flags[i], Σ over the others), each in eight
/// interleaved partial sums as [`sum`] does it.
fn masked_sums(xs: &[f64], flags: &[bool]) -> (f64, f64) {
    let (mut with, mut without) = ([0.0f64; 8], [0.0f64; 8]);
    let chunks = xs.chunks_exact(8).zip(flags.chunks_exact(8));
    let tail = xs.len() - xs.len() % 8;
    let (mut rest_with, mut rest_without) = (0.0, 0.0);
    for (x, &f) in xs[tail..].iter().zip(&flags[tail..]) {
        if f {
            rest_with += x;
        } else {
            rest_without += x;
        }
    }
    for (chunk, flag) in chunks {
        for (i, (x, &f)) in chunk.iter().zip(flag).enumerate() {
            with[i] += if f { *x } else { 0.0 };
            without[i] += if f { 0.0 } else { *x };
        }
    }
    (
        with.iter().sum::<f64>() + rest_with,
        without.iter().sum::<f64>() + rest_without,
    )
}

/// The bit mask of a set of (checked) track ids.
fn mask_of(tracks: &[u32]) -> u64 {
    tracks.iter().fold(0u64, |m, &t| m | (1u64 << t))
}

/// Colex rank of a k-set: Σ_i C(c_i, i + 1) over its elements c_0 < c_1 < ….
fn rank_mask(binom: &Binomials, mut mask: u64) -> usize {
    let mut rank = 0;
    let mut i = 1;
    while mask != 0 {
        rank += binom.get(mask.trailing_zeros() as usize, i);
        mask &= mask - 1;
        i += 1;
    }
    rank
}

/// The next larger mask with the same number of set bits (Gosper's hack,
/// with a shift in place of the division). `mask` must be non-zero and not
/// the last such mask below 2^64.
fn next_same_weight(mask: u64) -> u64 {
    let low = mask & mask.wrapping_neg();
    let ripple = mask.wrapping_add(low);
    (((ripple ^ mask) >> 2) >> low.trailing_zeros()) | ripple
}

/// Walks the region of kk-sets of [0, m) stored from `offset` on and reports
/// it as pieces by whether the states hold t.
fn pieces<'a>(
    binom: &Binomials,
    low: &'a LowPatterns,
    m: usize,
    kk: usize,
    offset: usize,
    t: usize,
    visit: &mut impl FnMut(Piece<'a>),
) {
    if kk > m {
        return;
    }
    if m <= t {
        visit(Piece::Run(offset..offset + binom.get(m, kk), false));
        return;
    }
    // One set left: the empty one, or all of [0, m), which holds t.
    if kk == 0 || kk == m {
        visit(Piece::Run(offset..offset + 1, kk != 0));
        return;
    }
    if m == low.m0 {
        visit(Piece::Pattern(offset, &low.holds[t][kk]));
        return;
    }
    let without_top = binom.get(m - 1, kk);
    if m - 1 == t {
        visit(Piece::Run(offset..offset + without_top, false));
        visit(Piece::Run(
            offset + without_top..offset + binom.get(m, kk),
            true,
        ));
        return;
    }
    pieces(binom, low, m - 1, kk, offset, t, visit);
    pieces(binom, low, m - 1, kk - 1, offset + without_top, t, visit);
}

/// Pairs (x, y = x △ {lo, hi}) of a mix, x holding lo and not hi.
enum Pairs<'a> {
    /// x_start.., y_start.., both `len` long, in step.
    Runs(usize, usize, usize),
    /// (x_base + dx, y_base + dy) for each listed (dx, dy).
    Listed(usize, usize, &'a [(u16, u16)]),
    /// (base + dx, base + dy) for each listed (dx, dy).
    Within(usize, &'a [(u16, u16)]),
}

struct PairWalk<'a> {
    binom: &'a Binomials,
    low: &'a LowPatterns,
    lo: usize,
    hi: usize,
}

impl<'a> PairWalk<'a> {
    /// Descends the kk-sets of [0, m) at `offset` to track hi, where they
    /// split into the sets without hi (the x side) and those with it (the
    /// y side).
    fn above(&self, m: usize, kk: usize, offset: usize, visit: &mut impl FnMut(Pairs<'a>)) {
        // No set here holds exactly one of lo, hi when it holds none or all
        // of the tracks below m.
        if kk == 0 || kk >= m {
            return;
        }
        if m == self.low.m0 {
            visit(Pairs::Within(offset, &self.low.inner[self.lo][self.hi][kk]));
            return;
        }
        let without_top = self.binom.get(m - 1, kk);
        if m - 1 > self.hi {
            self.above(m - 1, kk, offset, visit);
            self.above(m - 1, kk - 1, offset + without_top, visit);
        } else {
            self.between(self.hi, kk, offset, offset + without_top, visit);
        }
    }

    /// Two regions that agree on every track ≥ m: the x side holds k1 of the
    /// tracks below m and must still take lo; the y side holds k1 − 1 and
    /// must avoid lo. Tracks strictly between lo and hi are taken by both or
    /// neither, so the descent is in lockstep; at lo both sides become the
    /// (k1 − 1)-sets of [0, lo) — identical runs.
    fn between(
        &self,
        m: usize,
        k1: usize,
        x_offset: usize,
        y_offset: usize,
        visit: &mut impl FnMut(Pairs<'a>),
    ) {
        if k1 == 0 || k1 > m {
            return;
        }
        if k1 == m {
            // x = [0, m), y = x − {lo}, ranked m − 1 − lo among the
            // (m − 1)-sets of [0, m).
            visit(Pairs::Runs(x_offset, y_offset + m - 1 - self.lo, 1));
            return;
        }
        if m == self.low.m0 {
            visit(Pairs::Listed(
                x_offset,
                y_offset,
                &self.low.cross[self.lo][k1],
            ));
            return;
        }
        let below = m - 1;
        if below > self.lo {
            self.between(below, k1, x_offset, y_offset, visit);
            if k1 >= 2 {
                let x_skip = self.binom.get(below, k1);
                let y_skip = self.binom.get(below, k1 - 1);
                self.between(below, k1 - 1, x_offset + x_skip, y_offset + y_skip, visit);
            }
        } else {
            let x_skip = self.binom.get(self.lo, k1);
            let len = self.binom.get(self.lo, k1 - 1);
            visit(Pairs::Runs(x_offset + x_skip, y_offset, len));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::event::Event;
    use crate::radon::RadonBelief;
    use crate::workload::{generate, WorkloadSpec};

    fn mix(a: u32, b: u32, swap: f64) -> Mix {
        Mix { a, b, swap }
    }

    fn close(got: &[f64], want: &[f64], tol: f64) {
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() <= tol, "got {got:?}, want {want:?}");
        }
    }

    /// Brute force: the sets of the space in storage order.
    fn masks(filter: &DenseFilter) -> Vec<u64> {
        let mut out = Vec::new();
        filter.for_each_state(|m, _| out.push(m));
        out
    }

    #[test]
    fn storage_order_is_colex_rank() {
        let filter = DenseFilter::new(Field::uniform(7, 3)).unwrap();
        let Space::KSets { binom, .. } = &filter.space else {
            panic!("k is known")
        };
        let all = masks(&filter);
        assert_eq!(all.len(), 35);
        for (rank, &m) in all.iter().enumerate() {
            assert_eq!(m.count_ones(), 3);
            assert_eq!(rank_mask(binom, m), rank);
        }
        assert!(all.windows(2).all(|w| w[0] < w[1]));
    }

    /// Table II (0-based): {0,1} red; 0 and 2 mix, then 2 and 3, each swap
    /// with probability ½.
    #[test]
    fn table_ii_rollup() {
        let mut filter = DenseFilter::new(Field::known(4, vec![0, 1])).unwrap();
        filter.mix(mix(0, 2, 0.5)).unwrap();
        assert!((filter.prob_red_set(&[0, 1]).unwrap() - 0.5).abs() < 1e-15);
        assert!((filter.prob_red_set(&[1, 2]).unwrap() - 0.5).abs() < 1e-15);
        filter.mix(mix(2, 3, 0.5)).unwrap();
        let want = [
            (vec![0, 1], 0.5),
            (vec![0, 2], 0.0),
            (vec![0, 3], 0.0),
            (vec![1, 2], 0.25),
            (vec![1, 3], 0.25),
            (vec![2, 3], 0.0),
        ];
        for (set, p) in want {
            assert!(
                (filter.prob_red_set(&set).unwrap() - p).abs() < 1e-15,
                "{set:?}"
            );
        }
        close(&filter.marginals().unwrap(), &[0.5, 1.0, 0.25, 0.25], 1e-15);
        assert!(filter.log_normalizer().abs() < 1e-15);

        // Table I's last event: red seen on track 2 for certain.
        filter
            .observe(Observe {
                track: 2,
                red: 1.0,
                blue: 0.0,
            })
            .unwrap();
        assert_eq!(filter.prob_red_set(&[1, 2]).unwrap(), 1.0);
        close(&filter.marginals().unwrap(), &[0.0, 1.0, 1.0, 0.0], 0.0);
        assert_eq!(filter.predicted_red().unwrap(), vec![1, 2]);
        assert!((filter.log_normalizer() - 0.25f64.ln()).abs() < 1e-15);
    }

    #[test]
    fn swap_zero_and_one_are_exact() {
        let mut filter = DenseFilter::new(Field::known(5, vec![0, 3])).unwrap();
        filter.mix(mix(0, 1, 0.0)).unwrap();
        assert_eq!(filter.prob_red_set(&[0, 3]).unwrap(), 1.0);
        filter.mix(mix(4, 0, 1.0)).unwrap();
        assert_eq!(filter.prob_red_set(&[3, 4]).unwrap(), 1.0);
        close(
            &filter.marginals().unwrap(),
            &[0.0, 0.0, 0.0, 1.0, 1.0],
            0.0,
        );
    }

    #[test]
    fn blue_zero_observation_removes_sets_without_the_track() {
        let mut filter = DenseFilter::new(Field::uniform(6, 3)).unwrap();
        filter.mix(mix(1, 4, 0.3)).unwrap();
        filter
            .observe(Observe {
                track: 4,
                red: 0.7,
                blue: 0.0,
            })
            .unwrap();
        let all = masks(&filter);
        for (&m, &p) in all.iter().zip(&filter.probs) {
            if m & (1 << 4) == 0 {
                assert_eq!(p, 0.0, "mask {m:b}");
            } else {
                assert!((p - 1.0 / 10.0).abs() < 1e-15, "mask {m:b}");
            }
        }
        assert!((filter.marginals().unwrap()[4] - 1.0).abs() < 1e-15);
        // Z = C(6,3)·(½·0.7): half the sets hold track 4.
        assert!((filter.log_normalizer() - (20.0f64 * 0.5 * 0.7).ln()).abs() < 1e-12);
    }

    #[test]
    fn rollup_preserves_total_and_the_count() {
        for field in [Field::uniform(9, 4), Field::known(9, vec![0, 2, 7])] {
            let mut filter = DenseFilter::new(field).unwrap();
            filter
                .observe(Observe {
                    track: 3,
                    red: 0.9,
                    blue: 0.2,
                })
                .unwrap();
            let before = filter.log_normalizer();
            let k = filter.field().red.known().unwrap() as f64;
            for (a, b, s) in [(0, 8, 0.5), (3, 2, 0.25), (7, 1, 0.9), (5, 4, 1.0)] {
                filter.mix(mix(a, b, s)).unwrap();
                assert!((filter.probs.iter().sum::<f64>() - 1.0).abs() < 1e-14);
                let sum: f64 = filter.marginals().unwrap().iter().sum();
                assert!((sum - k).abs() < 1e-12);
            }
            assert!((filter.log_normalizer() - before).abs() < 1e-14);
        }
    }

    /// n = 3, every count equally likely (so ∅ and {0,1,2} weigh ¼, each
    /// singleton and pair 1/12). Red seen on 0 (0.9 vs 0.1): P(0) = 0.9,
    /// P(1) = P(2) = (0.1 + 0.9 + 0.1)/12 + 0.9/4, over Z = ½; then 0 and 1
    /// mix evenly, averaging their marginals.
    #[test]
    fn unknown_count_matches_hand_computation() {
        let field = Field {
            tracks: 3,
            red: RedCount::unknown_uniform(3),
            initial_red: None,
        };
        let mut filter = DenseFilter::new(field).unwrap();
        assert_eq!(filter.coefficients(), 8);
        close(&filter.marginals().unwrap(), &[0.5, 0.5, 0.5], 1e-15);
        filter
            .observe(Observe {
                track: 0,
                red: 0.9,
                blue: 0.1,
            })
            .unwrap();
        let other = (1.1 / 12.0 + 0.225) / 0.5;
        close(&filter.marginals().unwrap(), &[0.9, other, other], 1e-14);
        assert!((filter.log_normalizer() - 0.5f64.ln()).abs() < 1e-14);
        filter.mix(mix(1, 0, 0.5)).unwrap();
        let avg = (0.9 + other) / 2.0;
        close(&filter.marginals().unwrap(), &[avg, avg, other], 1e-14);
        // The count posterior: ∅ ∝ ¼·0.1, {0,1,2} ∝ ¼·0.9, size 1 ∝
        // (0.9 + 0.1 + 0.1)/12, size 2 ∝ (0.9 + 0.9 + 0.1)/12.
        let count = filter.count_posterior().unwrap();
        close(
            &count,
            &[0.025 / 0.5, 1.1 / 12.0 / 0.5, 1.9 / 12.0 / 0.5, 0.225 / 0.5],
            1e-14,
        );
    }

    #[test]
    fn unknown_count_with_known_start_is_a_delta() {
        let field = Field {
            tracks: 5,
            red: RedCount::unknown_uniform(5),
            initial_red: Some(vec![1, 3]),
        };
        let mut filter = DenseFilter::new(field).unwrap();
        assert_eq!(filter.prob_red_set(&[1, 3]).unwrap(), 1.0);
        filter.mix(mix(3, 4, 0.25)).unwrap();
        assert!((filter.prob_red_set(&[1, 4]).unwrap() - 0.25).abs() < 1e-15);
        close(
            &filter.marginals().unwrap(),
            &[0.0, 1.0, 0.0, 0.75, 0.25],
            1e-15,
        );
        assert!((filter.prob_all_red(&[1, 3]).unwrap() - 0.75).abs() < 1e-15);
    }

    #[test]
    fn no_red_or_all_red_is_certain() {
        for k in [0, 10] {
            let mut filter = DenseFilter::new(Field::uniform(10, k)).unwrap();
            assert_eq!(filter.coefficients(), 1);
            filter.mix(mix(0, 9, 0.5)).unwrap();
            filter
                .observe(Observe {
                    track: 9,
                    red: 0.9,
                    blue: 0.2,
                })
                .unwrap();
            let want = if k == 0 { 0.0 } else { 1.0 };
            close(&filter.marginals().unwrap(), &[want; 10], 0.0);
            let likelihood: f64 = if k == 0 { 0.2 } else { 0.9 };
            assert!((filter.log_normalizer() - likelihood.ln()).abs() < 1e-15);
        }
    }

    #[test]
    fn refuses_too_many_states() {
        let err = DenseFilter::new(Field::uniform(40, 20)).unwrap_err();
        assert_eq!(
            err,
            BeliefError::TooLarge {
                method: "exact",
                needed: 137_846_528_820.0,
                limit: MAX_STATES,
            }
        );
        let unknown = Field {
            tracks: 27,
            red: RedCount::unknown_uniform(27),
            initial_red: None,
        };
        assert!(matches!(
            DenseFilter::new(unknown),
            Err(BeliefError::TooLarge {
                limit: MAX_STATES,
                ..
            })
        ));
        assert!(matches!(
            DenseFilter::new(Field::uniform(65, 1)),
            Err(BeliefError::Unsupported { .. })
        ));
        // The edge of the mask width still works.
        let edge = DenseFilter::new(Field::known(64, vec![0, 63])).unwrap();
        assert_eq!(edge.coefficients(), 2016);
    }

    fn sure_red(track: u32) -> Observe {
        Observe {
            track,
            red: 1.0,
            blue: 0.0,
        }
    }

    #[test]
    fn a_contradicting_sighting_is_taken_by_the_repair_rule() {
        let mut filter = DenseFilter::new(Field::known(4, vec![0, 1])).unwrap();
        filter.mix(mix(0, 2, 0.5)).unwrap();
        // Track 3 is surely blue; a sure red on it is taken after the
        // belief gives 1e-9 of its mass to the uniform k-sets.
        filter.observe(sure_red(3)).unwrap();
        let p = filter.marginals().unwrap();
        assert!((p[3] - 1.0).abs() < 1e-12, "{p:?}");
        assert!((p.iter().sum::<f64>() - 2.0).abs() < 1e-12);
        // No set the belief held has track 3 red: the uniform share
        // decides which track is red beside it.
        assert!(
            p[..3].iter().all(|q| (q - 1.0 / 3.0).abs() < 1e-12),
            "{p:?}"
        );
        assert_eq!(filter.repairs(), 1);
        // Bad events are refused before anything changes.
        let probs = filter.probs.clone();
        assert!(filter.mix(mix(1, 1, 0.5)).is_err());
        assert!(filter.apply(&Event::Mix(mix(0, 9, 0.5))).is_err());
        assert_eq!(filter.probs, probs);
    }

    #[test]
    fn a_sighting_the_prior_rules_out_is_set_aside() {
        let mut filter = DenseFilter::new(Field::uniform(4, 0)).unwrap();
        let (probs, log_norm) = (filter.probs.clone(), filter.log_normalizer());
        filter.observe(sure_red(3)).unwrap();
        assert_eq!(filter.probs, probs);
        assert_eq!(filter.log_normalizer(), log_norm);
        assert_eq!(filter.repairs(), 1);
        // With the count unknown the smoothing follows the count prior.
        let field = Field {
            tracks: 3,
            red: RedCount::Unknown {
                prior: vec![0.5, 0.5, 0.0, 0.0],
            },
            initial_red: Some(vec![]),
        };
        let mut filter = DenseFilter::new(field).unwrap();
        filter
            .observe(Observe {
                track: 2,
                red: 1.0,
                blue: 0.0,
            })
            .unwrap();
        let p = filter.marginals().unwrap();
        assert!((p[2] - 1.0).abs() < 1e-12 && p[0] < 1e-12, "{p:?}");
        assert_eq!(filter.count_posterior().unwrap()[2], 0.0);
        filter
            .observe(Observe {
                track: 0,
                red: 1.0,
                blue: 0.0,
            })
            .unwrap();
        assert_eq!(filter.repairs(), 2);
        let p = filter.marginals().unwrap();
        assert!((p[0] - 1.0).abs() < 1e-12 && p[2] < 1e-6, "{p:?}");
    }

    /// A naive filter over all 2^n masks (zero off the admissible sets).
    fn naive_step(f: &mut [f64], event: &Event) {
        match *event {
            Event::Mix(Mix { a, b, swap }) => {
                let old = f.to_vec();
                let both = (1usize << a) | (1 << b);
                for (x, v) in f.iter_mut().enumerate() {
                    if (x & both).count_ones() == 1 {
                        *v = (1.0 - swap) * old[x] + swap * old[x ^ both];
                    }
                }
            }
            Event::Observe(Observe { track, red, blue }) => {
                for (x, v) in f.iter_mut().enumerate() {
                    *v *= if x >> track & 1 == 1 { red } else { blue };
                }
                let total: f64 = f.iter().sum();
                for v in f.iter_mut() {
                    *v /= total;
                }
            }
        }
    }

    /// Fields wider than the precomputed low patterns exercise every branch
    /// of the region descent; a naive filter is the reference.
    #[test]
    fn matches_a_naive_filter_on_wide_fields() {
        for (n, k, start, seed) in [
            (12, 5, false, 1),
            (12, 5, true, 2),
            (13, 1, false, 3),
            (11, 10, false, 4),
            (10, 8, true, 5),
            (9, 3, false, 6),
        ] {
            let work = generate(&WorkloadSpec {
                tracks: n,
                red: k,
                events: 200,
                mix_share: 0.6,
                swap: 0.3,
                neighbourhood: n,
                seed,
            });
            let field = if start {
                Field::known(n, work.initial_red.clone())
            } else {
                Field::uniform(n, k)
            };
            let mut filter = DenseFilter::new(field).unwrap();
            let mut naive = vec![0.0; 1 << n];
            for (x, v) in naive.iter_mut().enumerate() {
                if x.count_ones() as usize == k {
                    let is_start = x as u64 == mask_of(&work.initial_red);
                    *v = if !start {
                        1.0 / filter.coefficients() as f64
                    } else if is_start {
                        1.0
                    } else {
                        0.0
                    };
                }
            }
            for (i, event) in work.events.iter().enumerate() {
                filter.apply(event).unwrap();
                naive_step(&mut naive, event);
                let all = masks(&filter);
                for (m, p) in all.iter().zip(&filter.probs) {
                    let want = naive[*m as usize];
                    assert!((p - want).abs() < 1e-12, "n={n} k={k} event {i}: {m:b}");
                }
            }
        }
    }

    #[test]
    fn unknown_count_matches_a_naive_filter() {
        let n = 10;
        let field = Field {
            tracks: n,
            red: RedCount::unknown_uniform(n),
            initial_red: None,
        };
        let mut filter = DenseFilter::new(field).unwrap();
        let mut naive = filter.probs.clone();
        let work = generate(&WorkloadSpec {
            tracks: n,
            red: 4,
            events: 200,
            mix_share: 0.6,
            swap: 0.3,
            neighbourhood: n,
            seed: 9,
        });
        for event in &work.events {
            filter.apply(event).unwrap();
            naive_step(&mut naive, event);
        }
        close(&filter.probs, &naive, 1e-12);
    }

    /// The dense filter and the unpruned Radon engine are both exact, so
    /// they must agree on everything they can both answer.
    #[test]
    fn agrees_with_the_exact_radon_engine() {
        for (n, k, start, seed) in [(8, 3, true, 1), (8, 3, false, 2), (7, 5, false, 3)] {
            let spec = WorkloadSpec {
                tracks: n,
                red: k,
                events: 120,
                mix_share: 0.5,
                swap: 0.3,
                neighbourhood: n,
                seed,
            };
            let work = generate(&spec);
            let field = if start {
                Field::known(n, work.initial_red.clone())
            } else {
                Field::uniform(n, k)
            };
            let mut dense = DenseFilter::new(field.clone()).unwrap();
            let mut radon = RadonBelief::new(field).unwrap();
            for event in &work.events {
                dense.apply(event).unwrap();
                radon.apply(event).unwrap();
            }
            close(
                &dense.marginals().unwrap(),
                &radon.marginals().unwrap(),
                1e-9,
            );
            assert!((dense.log_normalizer() - radon.log_normalizer()).abs() < 1e-9);
            let pair = [0u32, 1];
            let radon_pair = radon
                .prob_all_red(&crate::track_set::TrackSet::from_tracks(pair))
                .unwrap();
            assert!((dense.prob_all_red(&pair).unwrap() - radon_pair).abs() < 1e-9);
        }
    }

    #[test]
    fn unknown_count_agrees_with_the_exact_radon_engine() {
        let n = 6;
        let prior = vec![0.05, 0.1, 0.2, 0.3, 0.2, 0.1, 0.05];
        let field = Field {
            tracks: n,
            red: RedCount::Unknown { prior },
            initial_red: None,
        };
        let work = generate(&WorkloadSpec {
            tracks: n,
            red: 3,
            events: 80,
            mix_share: 0.5,
            swap: 0.4,
            neighbourhood: n,
            seed: 11,
        });
        let mut dense = DenseFilter::new(field.clone()).unwrap();
        let mut radon = RadonBelief::new(field).unwrap();
        for event in &work.events {
            dense.apply(event).unwrap();
            radon.apply(event).unwrap();
        }
        close(
            &dense.marginals().unwrap(),
            &radon.marginals().unwrap(),
            1e-9,
        );
        close(
            &dense.count_posterior().unwrap(),
            &radon.count_posterior().unwrap(),
            1e-9,
        );
        assert!((dense.log_normalizer() - radon.log_normalizer()).abs() < 1e-9);
    }

    /// Release-mode timing for the report: n = 20, k = 10, the Table III
    /// workload. `cargo test -p idmesh-belief --release dense_timing -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn dense_timing_n20_k10() {
        let work = generate(&WorkloadSpec::table3(20, 5));
        let mut filter = DenseFilter::new(Field::known(20, work.initial_red.clone())).unwrap();
        let start = std::time::Instant::now();
        for event in &work.events {
            filter.apply(event).unwrap();
        }
        let elapsed = start.elapsed();
        let p = filter.marginals().unwrap();
        println!(
            "dense n=20 k=10, 1000 events: {elapsed:?} (marginal sum {})",
            p.iter().sum::<f64>()
        );
    }
}
