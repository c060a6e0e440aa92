//! Identities from properties (Jiang et al., *Property Management in
//! Wireless Sensor Networks with Overcomplete Radon Bases*, TOSN 2013,
//! Section 5.5 "Connection between Property Management and Identity
//! Management", evaluated in Table IV): code each of the n identities with
//! b binary properties, keep one property belief (a [`RadonBelief`] over
//! which tracks are "red") per bit, and combine the bits into identity
//! marginals.
//!
//! ## The code
//! Any b ≥ ⌈log₂ n⌉ distinct codewords work; more bits add redundancy.
//! [`BitCode::new`] picks a greedy *lexicode*: for the largest distance d it
//! can, it scans the words 0, 1, 2, … and keeps each word at Hamming
//! distance ≥ d from all kept ones, until it has n. Lexicodes are the
//! classic greedy construction of codes with large minimum distance; with
//! redundant bits, distinct identities then differ in several bits, so one
//! noisy bit belief does not confuse two identities. Word 0 is always
//! kept, so no bit is set for every identity; a bit set for none (possible
//! when n is far below 2^b) carries no information and gets no belief.
//! [`BitCode::from_words`] takes any other choice.
//!
//! ## Bit j as a property
//! Track t is red for bit j when its identity's codeword has bit j set, so
//! k_j = #{identities with bit j = 1} tracks are red. A known initial
//! assignment gives known initial red sets; otherwise each bit starts
//! uniform over its k_j-sets. A mix of tracks a and b mixes every bit
//! belief identically (the same targets swap).
//!
//! ## A read as one observation per bit
//! A read of identity r with accuracy α has likelihood λ(x) = α for true
//! identity x = r and w = (1 − α)/(n − 1) otherwise. A bit belief knows only
//! whether the track's bit is v, not which identity in the class
//! C_v = {x : code_x\[j\] = v} it is, so it needs P(read | bit = v) =
//! Σ_{x∈C_v} λ(x)·P(x | bit = v). We take P(x | bit = v) = 1/|C_v|, uniform
//! within the class — the independence assumption that lets each bit be
//! its own belief (the exact value depends on the other bits' beliefs). So
//!
//!   red  = P(read | bit = 1) = (Σ_{x: bit j = 1} λ(x)) / k_j,
//!   blue = P(read | bit = 0) = (Σ_{x: bit j = 0} λ(x)) / (n − k_j);
//!
//! if r's bit j is 1: red = (α + (k_j − 1)·w)/k_j, blue = w;
//! if it is 0: red = w, blue = (α + (n − k_j − 1)·w)/(n − k_j).
//! A perfect read (α = 1, w = 0) makes the bit certain. The approximation
//! is over- and under-confident in turn: the bits' likelihood ratios
//! multiply, so an identity differing from r in many bits is penalized more
//! than the true α/w, one differing in a single bit less.
//!
//! ## Combining the bits
//! score(t, i) = Π_j P(bit j of track t = code_i\[j\]) treats the bits of a
//! track as independent (computed in log space), and ignores that the
//! identities are one-to-one. Sinkhorn scaling to a doubly stochastic matrix
//! restores the one-to-one constraint (it is the closest doubly stochastic
//! matrix to the scores in relative entropy), giving the marginals. Bit
//! probabilities are floored at [`BIT_FLOOR`] first (see there).
//!
//! ## Cost
//! Without a budget every bit belief is exact, and exact Radon beliefs can
//! grow exponentially with mixing; for more than a few dozen tracks give
//! [`RadonOptions`] a [`idmesh_belief::Sparsify`] budget.

use super::event::{check_assignment, check_identify, check_mix, Identify};
use super::filter::{to_rows, IdentityFilter, Marginals};
use super::sinkhorn::{sinkhorn, SinkhornOptions};
use idmesh_belief::BeliefError;
use idmesh_belief::PropertyFilter;
use idmesh_belief::{Field, Mix, Observe};
use idmesh_belief::{RadonBelief, RadonOptions};

/// Bit probabilities are clamped to [this, 1 − this] before they are
/// combined. Under a coefficient budget a bit belief can become spuriously
/// certain; a hard 0 would then rule out the true assignment and can leave
/// the score matrix with no positive diagonal (seen at n = 100, 9 bits,
/// budget 200). The floor changes exact answers by ~1e-12.
pub(crate) const BIT_FLOOR: f64 = 1e-12;

/// The longest code [`BitCode::new`] searches (it scans up to 2^b words).
pub(crate) const MAX_CODE_BITS: usize = 16;

/// n distinct b-bit codewords, one per identity.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BitCode {
    bits: usize,
    words: Vec<u64>,
}

impl BitCode {
    /// ⌈log₂ n⌉, at least 1: the fewest bits that give n distinct words.
    pub fn min_bits(identities: usize) -> usize {
        let mut bits = 1;
        while (1usize << bits) < identities {
            bits += 1;
        }
        bits
    }

    /// The greedy lexicode with the largest minimum distance (module docs).
    pub fn new(identities: usize, bits: usize) -> Result<Self, BeliefError> {
        if identities == 0 {
            return Err(BeliefError::NoTracks);
        }
        if bits < Self::min_bits(identities) || bits > MAX_CODE_BITS {
            return Err(BeliefError::Unsupported {
                method: "bit code",
                what: "a bit count below ⌈log₂ n⌉ or above 16",
            });
        }
        for distance in (1..=bits as u32).rev() {
            let mut words: Vec<u64> = Vec::with_capacity(identities);
            for w in 0..(1u64 << bits) {
                if words.iter().all(|&v| (v ^ w).count_ones() >= distance) {
                    words.push(w);
                    if words.len() == identities {
                        return Ok(BitCode { bits, words });
                    }
                }
            }
        }
        // Distance 1 keeps every word, and 2^bits ≥ identities.
        Err(BeliefError::Unsupported {
            method: "bit code",
            what: "fewer words than identities",
        })
    }

    /// A code given by its words (distinct, each below 2^bits).
    pub fn from_words(words: Vec<u64>, bits: usize) -> Result<Self, BeliefError> {
        if words.is_empty() {
            return Err(BeliefError::NoTracks);
        }
        let mut sorted = words.clone();
        sorted.sort_unstable();
        sorted.dedup();
        if bits == 0
            || bits > 63
            || sorted.len() != words.len()
            || words.iter().any(|&w| w >> bits != 0)
        {
            return Err(BeliefError::Unsupported {
                method: "bit code",
                what: "words that are not distinct or do not fit the bit count",
            });
        }
        Ok(BitCode { bits, words })
    }

    pub fn identities(&self) -> usize {
        self.words.len()
    }

    pub fn bits(&self) -> usize {
        self.bits
    }

    /// The codeword of `identity` (< identities).
    #[cfg(test)]
    pub(crate) fn word(&self, identity: usize) -> u64 {
        self.words[identity]
    }

    /// Bit j of identity i's codeword.
    pub(crate) fn bit(&self, identity: usize, j: usize) -> bool {
        self.words[identity] >> j & 1 == 1
    }

    /// k_j: how many identities have bit j set.
    pub fn red_count(&self, j: usize) -> usize {
        self.words.iter().filter(|&&w| w >> j & 1 == 1).count()
    }

    /// The smallest Hamming distance between two codewords (b + 1 for a
    /// single identity).
    pub fn min_distance(&self) -> u32 {
        let mut best = self.bits as u32 + 1;
        for (k, &v) in self.words.iter().enumerate() {
            for &w in &self.words[k + 1..] {
                best = best.min((v ^ w).count_ones());
            }
        }
        best
    }
}

/// Identity beliefs from one Radon property belief per code bit.
#[derive(Debug, Clone)]
pub struct PropertyBitsFilter {
    code: BitCode,
    /// One belief per bit; None for a bit no identity (or every identity)
    /// has, which is known everywhere and carries no information.
    beliefs: Vec<Option<RadonBelief>>,
    sinkhorn: SinkhornOptions,
}

impl PropertyBitsFilter {
    /// Starts from a known assignment (`initial[t]` = identity on track t)
    /// or, with None, from the uniform prior. `options` (e.g. a coefficient
    /// budget) apply to every bit belief.
    pub fn new(
        code: BitCode,
        initial: Option<&[u32]>,
        options: RadonOptions,
    ) -> Result<Self, BeliefError> {
        let n = code.identities();
        if let Some(assignment) = initial {
            check_assignment(n, assignment)?;
        }
        let mut beliefs = Vec::with_capacity(code.bits());
        for j in 0..code.bits() {
            let k = code.red_count(j);
            if k == 0 || k == n {
                beliefs.push(None);
                continue;
            }
            let field = match initial {
                Some(assignment) => Field::known(
                    n,
                    (0..n as u32)
                        .filter(|&t| code.bit(assignment[t as usize] as usize, j))
                        .collect(),
                ),
                None => Field::uniform(n, k),
            };
            beliefs.push(Some(RadonBelief::with_options(field, options.clone())?));
        }
        Ok(PropertyBitsFilter {
            code,
            beliefs,
            sinkhorn: SinkhornOptions::default(),
        })
    }

    /// Radon coefficients held over all bits.
    pub fn coefficients(&self) -> usize {
        self.beliefs
            .iter()
            .flatten()
            .map(|b| b.coefficients())
            .sum()
    }

    /// `result[j][t]` = P(bit j of track t's identity is 1).
    pub(crate) fn bit_marginals(&self) -> Result<Vec<Vec<f64>>, BeliefError> {
        let n = self.code.identities();
        (0..self.code.bits())
            .map(|j| match &self.beliefs[j] {
                Some(belief) => belief.marginals(),
                None => Ok(vec![
                    if self.code.red_count(j) == n {
                        1.0
                    } else {
                        0.0
                    };
                    n
                ]),
            })
            .collect()
    }

    /// The per-bit observation of a read, from the read model (module
    /// docs); None for a constant bit.
    fn bit_observation(&self, identify: &Identify, j: usize) -> Option<Observe> {
        let n = self.code.identities();
        let k = self.code.red_count(j);
        if k == 0 || k == n {
            return None;
        }
        let (right, wrong) = (identify.accuracy, identify.wrong_read_likelihood(n));
        let (red, blue) = if self.code.bit(identify.identity as usize, j) {
            ((right + (k as f64 - 1.0) * wrong) / k as f64, wrong)
        } else {
            (
                wrong,
                (right + (n - k) as f64 * wrong - wrong) / (n - k) as f64,
            )
        };
        Some(Observe {
            track: identify.track,
            red,
            blue,
        })
    }
}

impl IdentityFilter for PropertyBitsFilter {
    fn size(&self) -> usize {
        self.code.identities()
    }

    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        check_mix(self.size(), &mix)?;
        // All bits or none: update copies, then commit.
        let mut next = self.beliefs.clone();
        for belief in next.iter_mut().flatten() {
            belief.mix(mix)?;
        }
        self.beliefs = next;
        Ok(())
    }

    fn identify(&mut self, identify: Identify) -> Result<(), BeliefError> {
        check_identify(self.size(), &identify)?;
        let mut next = self.beliefs.clone();
        for (j, belief) in next.iter_mut().enumerate() {
            if let (Some(belief), Some(observe)) = (belief, self.bit_observation(&identify, j)) {
                belief.observe(observe)?;
            }
        }
        self.beliefs = next;
        Ok(())
    }

    fn marginals(&self) -> Result<Marginals, BeliefError> {
        let n = self.size();
        let bits = self.bit_marginals()?;
        // ln score(t, i) = Σ_j ln P(bit j of t = code_i[j]).
        let mut score = vec![0.0f64; n * n];
        for t in 0..n {
            for i in 0..n {
                score[t * n + i] = (0..self.code.bits())
                    .map(|j| {
                        let red = bits[j][t].clamp(BIT_FLOOR, 1.0 - BIT_FLOOR);
                        if self.code.bit(i, j) {
                            red.ln()
                        } else {
                            (1.0 - red).ln()
                        }
                    })
                    .sum();
            }
        }
        for row in score.chunks_mut(n) {
            let top = row.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            if top == f64::NEG_INFINITY {
                return Err(BeliefError::Degenerate { normalizer: 0.0 });
            }
            row.iter_mut().for_each(|x| *x = (*x - top).exp());
        }
        sinkhorn(n, &mut score, &self.sinkhorn)?;
        Ok(to_rows(n, &score))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::assignment::identity_error;
    use crate::exact::ExactPermutationFilter;
    use crate::filter::doubly_stochastic_residual;
    use crate::workload::{generate, IdentityWorkloadSpec};
    use crate::IdentityEvent;
    use idmesh_belief::Sparsify;

    #[test]
    fn codes_are_distinct_and_spread() {
        assert_eq!(BitCode::min_bits(1), 1);
        assert_eq!(BitCode::min_bits(8), 3);
        assert_eq!(BitCode::min_bits(9), 4);
        for (n, b) in [
            (1, 1),
            (5, 3),
            (8, 3),
            (8, 6),
            (20, 5),
            (20, 9),
            (100, 7),
            (100, 12),
        ] {
            let code = BitCode::new(n, b).unwrap();
            let mut words: Vec<u64> = (0..n).map(|i| code.word(i)).collect();
            words.sort_unstable();
            words.dedup();
            assert_eq!(words.len(), n);
            assert!(words.iter().all(|&w| w < 1 << b));
            assert!(code.min_distance() >= 1);
        }
        // Redundancy buys distance: 4 identities in 3 bits → the even-weight
        // code, distance 2; in 6 bits, distance 3 or more.
        assert_eq!(BitCode::new(4, 3).unwrap().min_distance(), 2);
        assert!(BitCode::new(4, 6).unwrap().min_distance() >= 3);
        assert!(BitCode::new(9, 3).is_err());
        assert!(BitCode::new(4, 17).is_err());
        assert!(BitCode::from_words(vec![1, 1], 2).is_err());
        assert!(BitCode::from_words(vec![1, 4], 2).is_err());
    }

    #[test]
    fn per_bit_likelihoods_follow_the_read_model() {
        // 4 identities, words 0, 3, 5, 6 (bits: k_j = 2 each).
        let code = BitCode::new(4, 3).unwrap();
        let f = PropertyBitsFilter::new(code, None, RadonOptions::default()).unwrap();
        let read = Identify {
            track: 0,
            identity: 1, // word 3 = bits 0 and 1 set
            accuracy: 0.7,
        };
        let w = 0.1;
        let o = f.bit_observation(&read, 0).unwrap();
        assert!((o.red - (0.7 + w) / 2.0).abs() < 1e-15);
        assert!((o.blue - w).abs() < 1e-15);
        let o = f.bit_observation(&read, 2).unwrap();
        assert!((o.red - w).abs() < 1e-15);
        assert!((o.blue - (0.7 + w) / 2.0).abs() < 1e-15);
    }

    #[test]
    fn perfect_reads_without_mixing_recover_every_identity() {
        for (n, b) in [(5, 3), (8, 3), (8, 6), (12, 7)] {
            // 7 is coprime to every n here, so this is a permutation.
            let truth: Vec<u32> = (0..n as u32).map(|t| (t * 7 + 2) % n as u32).collect();
            let code = BitCode::new(n, b).unwrap();
            let mut f = PropertyBitsFilter::new(code, None, RadonOptions::default()).unwrap();
            for (t, &i) in truth.iter().enumerate() {
                f.identify(Identify {
                    track: t as u32,
                    identity: i,
                    accuracy: 1.0,
                })
                .unwrap();
            }
            let m = f.marginals().unwrap();
            for (t, &i) in truth.iter().enumerate() {
                assert!((m[t][i as usize] - 1.0).abs() < 1e-9, "n={n} b={b}");
            }
            assert_eq!(f.most_likely().unwrap(), truth);
        }
    }

    #[test]
    fn known_start_without_events_is_the_start() {
        let start = [2, 0, 3, 1, 4];
        let f = PropertyBitsFilter::new(
            BitCode::new(5, 4).unwrap(),
            Some(&start),
            RadonOptions::default(),
        )
        .unwrap();
        assert_eq!(f.most_likely().unwrap(), start.to_vec());
        let m = f.marginals().unwrap();
        assert!((m[0][2] - 1.0).abs() < 1e-9);
    }

    #[test]
    fn a_read_the_belief_rules_out_is_taken_by_the_repair_rule() {
        let start = [0, 1, 2, 3];
        let mut f = PropertyBitsFilter::new(
            BitCode::new(4, 2).unwrap(),
            Some(&start),
            RadonOptions::default(),
        )
        .unwrap();
        let before = f.bit_marginals().unwrap();
        // Identity 3 = word 3 is certainly not on track 0 (word 0): each
        // bit's belief takes the sure read by the property filters' repair
        // rule, and track 0's bits are then word 3's.
        f.identify(Identify {
            track: 0,
            identity: 3,
            accuracy: 1.0,
        })
        .unwrap();
        let after = f.bit_marginals().unwrap();
        assert_ne!(after, before);
        for (j, bits) in after.iter().enumerate() {
            let want = if f.code.bit(3, j) { 1.0 } else { 0.0 };
            assert!((bits[0] - want).abs() < 1e-9, "bit {j}: {bits:?}");
        }
        // A bad event is still refused.
        assert!(f
            .mix(Mix {
                a: 0,
                b: 4,
                swap: 0.5
            })
            .is_err());
    }

    /// Mean identity error of the most likely assignment over a stream.
    fn mean_error(
        filter: &mut dyn IdentityFilter,
        events: &[IdentityEvent],
        truth: &[Vec<u32>],
    ) -> f64 {
        let mut total = 0.0;
        for (e, t) in events.iter().zip(truth) {
            filter.apply(e).unwrap();
            total += identity_error(&filter.most_likely().unwrap(), t);
        }
        total / events.len() as f64
    }

    #[test]
    fn with_mixing_it_beats_chance() {
        // N = 8 (chance error 7/8), reads of accuracy 0.9, half the events
        // mixes with swap ½ between nearby tracks. Measured mean error of
        // the most likely assignment over 4 streams of 200 events: exact
        // filter 0.353; 3 bits 0.425; 6 bits 0.378; 6 bits with at most 20
        // Radon coefficients per bit 0.381.
        let n = 8;
        let mut sums = [0.0f64; 4];
        for seed in 0..4 {
            let spec = IdentityWorkloadSpec {
                tracks: n,
                events: 200,
                mix_share: 0.5,
                swap: 0.5,
                accuracy: 0.9,
                neighbourhood: 2,
                seed,
            };
            let w = generate(&spec).unwrap();
            let mut exact = ExactPermutationFilter::from_assignment(&w.initial).unwrap();
            sums[0] += mean_error(&mut exact, &w.events, &w.truth);
            for (k, (b, budget)) in [(3, None), (6, None), (6, Some(20))]
                .into_iter()
                .enumerate()
            {
                let options = RadonOptions {
                    sparsify: budget.map(Sparsify::threshold),
                    ..RadonOptions::default()
                };
                let mut f =
                    PropertyBitsFilter::new(BitCode::new(n, b).unwrap(), Some(&w.initial), options)
                        .unwrap();
                sums[k + 1] += mean_error(&mut f, &w.events, &w.truth);
                let m = f.marginals().unwrap();
                assert!(doubly_stochastic_residual(&m) < 1e-9);
            }
        }
        let means: Vec<f64> = sums.iter().map(|s| s / 4.0).collect();
        for &m in &means[1..] {
            assert!(m < 0.5, "{means:?}");
        }
        // Redundant bits help.
        assert!(means[2] < means[1], "{means:?}");
    }
}
