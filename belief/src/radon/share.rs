//! A leader's share of a Radon belief: Section 5.4 run as a real system.
//!
//! Rollup (Algorithm 1) and conditioning (Algorithm 2, or the distributed
//! rule of Algorithm 5) act on the masses one atom at a time and linearly,
//! so the belief may be cut into shares held by different leaders: the sum
//! of the shares after an event is the shared-out belief after the event,
//! provided every share applies every event that touches its atoms. Nothing
//! here normalizes across shares or rejects an observation: a share may
//! legitimately lose all its mass (a certain sighting that rules out every
//! one of its sets) while the belief as a whole lives on. The common factor
//! of an observation (min(a, b), the paper's "b = 1") is left out, so every
//! share stays on the same scale without talking to the others; each keeps
//! its own log scale only so that its masses stay near 1.
//!
//! Queries never see a share's atoms: [`PartialSums`] are the three sums the
//! exact marginals of [`answer`](super::answer) are made of, added up across
//! shares by [`PartialSums::combine`].

use super::atom::Atom;
use super::condition::{floored_div, Conditioning, Growth, Update};
use super::omp::{heaviest, kept_by_pursuit, pursue, OmpOptions};
use super::rollup::rollup_masses;
use super::threshold::split_off_lightest;
use super::{OmpSchedule, RadonBelief, RadonOptions, Sparsify, SparsifyMethod};
use crate::error::BeliefError;
use crate::event::{Field, Mix, Observe};
use crate::weights::Weights;
use rustc_hash::FxHashMap;
use serde::{Deserialize, Serialize};

/// Part of a belief: some atoms with their masses, on a scale of its own.
/// Serialized (a leader's snapshot) as [`ShareForm`]: the weights are a
/// function of the field and are derived again.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(from = "ShareForm", into = "ShareForm")]
pub struct RadonShare {
    field: Field,
    weights: Weights,
    masses: FxHashMap<Atom, f64>,
    log_scale: f64,
    signed: bool,
    since_omp: OmpSchedule,
    omp_runs: u64,
}

/// A share as it is written down: everything but the derived weights.
#[derive(Serialize, Deserialize)]
struct ShareForm {
    field: Field,
    masses: Vec<(Atom, f64)>,
    log_scale: f64,
    signed: bool,
    since_omp: OmpSchedule,
    omp_runs: u64,
}

impl From<RadonShare> for ShareForm {
    fn from(share: RadonShare) -> Self {
        ShareForm {
            field: share.field,
            masses: share.masses.into_iter().collect(),
            log_scale: share.log_scale,
            signed: share.signed,
            since_omp: share.since_omp,
            omp_runs: share.omp_runs,
        }
    }
}

impl From<ShareForm> for RadonShare {
    fn from(form: ShareForm) -> Self {
        RadonShare {
            weights: Weights::new(form.field.tracks, &form.field.red),
            field: form.field,
            masses: form.masses.into_iter().collect(),
            log_scale: form.log_scale,
            signed: form.signed,
            since_omp: form.since_omp,
            omp_runs: form.omp_runs,
        }
    }
}

impl RadonShare {
    /// The whole start belief of `field` as one share (the same atoms as
    /// [`RadonBelief::with_options`], 1-sets instead of φ_∅ under the
    /// distributed rule with k known), to be split among the leaders.
    pub fn start(field: Field, options: &RadonOptions) -> Result<Self, BeliefError> {
        let options = RadonOptions {
            sparsify: None,
            ..options.clone()
        };
        let belief = RadonBelief::with_options(field, options)?;
        Ok(RadonShare {
            field: belief.field.clone(),
            weights: belief.weights.clone(),
            masses: belief.masses.clone(),
            log_scale: belief.log_scale,
            signed: belief.options.signed,
            since_omp: OmpSchedule::default(),
            omp_runs: 0,
        })
    }

    /// A share with no atoms.
    #[cfg(test)]
    pub(crate) fn empty(field: Field, signed: bool) -> Self {
        RadonShare {
            weights: Weights::new(field.tracks, &field.red),
            field,
            masses: FxHashMap::default(),
            log_scale: 0.0,
            signed,
            since_omp: OmpSchedule::default(),
            omp_runs: 0,
        }
    }

    /// How many times OMP has re-expressed part of this share.
    pub fn omp_runs(&self) -> u64 {
        self.omp_runs
    }

    pub fn field(&self) -> &Field {
        &self.field
    }

    pub fn len(&self) -> usize {
        self.masses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.masses.is_empty()
    }

    /// Every held atom with its mass relative to the share's scale.
    pub fn atoms(&self) -> impl Iterator<Item = (&Atom, f64)> + '_ {
        self.masses.iter().map(|(a, &m)| (a, m))
    }

    /// Rollup of a mix on this share's atoms.
    pub fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        self.field.check_mix(&mix)?;
        rollup_masses(&mut self.masses, mix);
        self.since_omp.mixed();
        Ok(())
    }

    /// Conditioning on an observation, growing the atoms `growth` says.
    pub fn observe(&mut self, observe: Observe, growth: Growth<'_>) -> Result<(), BeliefError> {
        self.field.check_observe(&observe)?;
        if let Growth::Meeting(partners) = growth {
            for &t in partners {
                self.field.check_track(t)?;
            }
        }
        self.since_omp.observed();
        let conditioning = Conditioning {
            weights: &self.weights,
            t: observe.track,
            update: Update::new(&observe, self.signed),
            growth,
        };
        conditioning.apply(&mut self.masses);
        self.rescale();
        Ok(())
    }

    /// Whether an observation of `t` changes atoms that do not involve it:
    /// a certain sighting (likelihood 0 on one side) removes them all, so
    /// every share must see it.
    pub fn observation_is_global(observe: &Observe, signed: bool) -> bool {
        Update::new(observe, signed).keep != 1.0
    }

    /// Takes out the atoms `leave` picks, with masses on the absolute scale
    /// (log mass), for another share to [`absorb`](Self::absorb).
    pub fn extract(&mut self, mut leave: impl FnMut(&Atom) -> bool) -> Vec<(Atom, f64)> {
        let log_scale = self.log_scale;
        self.masses
            .extract_if(|atom, _| leave(atom))
            .map(|(atom, m)| (atom, m.ln() + log_scale))
            .collect()
    }

    /// Adds atoms given with log masses on the absolute scale.
    pub fn absorb(&mut self, atoms: impl IntoIterator<Item = (Atom, f64)>) {
        let atoms: Vec<(Atom, f64)> = atoms.into_iter().collect();
        if atoms.is_empty() {
            return;
        }
        if self.masses.is_empty() {
            self.log_scale = atoms.iter().map(|x| x.1).fold(f64::NEG_INFINITY, f64::max);
        }
        for (atom, ln_mass) in atoms {
            let m = (ln_mass - self.log_scale).exp();
            if m != 0.0 {
                *self.masses.entry(atom).or_insert(0.0) += m;
            }
        }
        self.masses.retain(|_, m| *m != 0.0);
        self.rescale();
    }

    /// Keeps the `budget` heaviest atoms (Section 5.3.2): fully local.
    pub(crate) fn threshold(&mut self, budget: usize) -> usize {
        split_off_lightest(&mut self.masses, budget.max(1)).len()
    }

    /// Brings the share within `sparsify.budget` sets as the whole belief
    /// does (OMP after runs of mixing, then thresholding), on this share's
    /// atoms alone. OMP's atoms are subsets of the sets it re-expresses, so
    /// they touch only tracks the leader already follows; and since the
    /// shares add up to the belief, approximating each share approximates
    /// the sum. No leader needs to agree with another: each set has one
    /// holder. Nothing is normalized here (shares share one scale); the
    /// coordinator normalizes the sum. On a numerical failure of OMP the
    /// share is left as it was and thresholded.
    pub fn sparsify(&mut self, sparsify: &Sparsify) -> Result<(), BeliefError> {
        if self.masses.len() <= sparsify.budget {
            return Ok(());
        }
        let mut result = Ok(());
        if let SparsifyMethod::Overcomplete(omp) = &sparsify.method {
            if self.since_omp.due(omp) {
                self.since_omp.ran();
                result = self.pursue(sparsify.budget, omp);
            }
        }
        self.threshold(sparsify.budget);
        result
    }

    fn pursue(&mut self, budget: usize, options: &OmpOptions) -> Result<(), BeliefError> {
        let mut removed = split_off_lightest(&mut self.masses, kept_by_pursuit(budget, options));
        let targets = heaviest(&mut removed, options.targets);
        match pursue(&self.weights, targets, options) {
            Ok(atoms) => {
                for (atom, m) in atoms {
                    *self.masses.entry(atom).or_insert(0.0) += m;
                }
                self.masses.retain(|_, m| *m != 0.0);
                self.rescale();
                self.omp_runs += 1;
                Ok(())
            }
            Err(e) => {
                self.masses.extend(removed);
                Err(e)
            }
        }
    }

    /// The sums this share contributes to the marginals.
    pub fn partial_sums(&self) -> PartialSums {
        PartialSums::of(&self.masses, &self.weights, self.log_scale)
    }

    /// Keeps the masses near 1 so that no share overflows over long runs.
    fn rescale(&mut self) {
        let total: f64 = self.masses.values().map(|m| m.abs()).sum();
        if total.is_finite() && total > 0.0 {
            for m in self.masses.values_mut() {
                // Floored as the whole belief is: a possible atom stays.
                *m = floored_div(*m, total);
            }
            self.log_scale += total.ln();
        }
    }
}

/// Σ m, Σ m·W(|α|+1)/W(|α|) and, per track, the part of P(t red)·Z that
/// depends on the atoms fixing t — all times e^{log_scale}. The marginals
/// of a belief are these sums added over its shares:
/// P(t red) = (outside + inside[t]) / total.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PartialSums {
    pub log_scale: f64,
    pub total: f64,
    pub outside: f64,
    /// (track, sum) for the tracks some atom fixes, sorted by track.
    pub inside: Vec<(u32, f64)>,
    pub coefficients: u64,
}

impl PartialSums {
    pub(super) fn of(masses: &FxHashMap<Atom, f64>, weights: &Weights, log_scale: f64) -> Self {
        let mut total = 0.0;
        let mut outside = 0.0;
        let mut inside: FxHashMap<u32, f64> = FxHashMap::default();
        for (atom, &m) in masses {
            let (i, o) = atom.sizes();
            let ratio = weights.ratio_red(i, o);
            total += m;
            outside += m * ratio;
            for &t in atom.red.tracks() {
                *inside.entry(t).or_insert(0.0) += m * (1.0 - ratio);
            }
            for &t in atom.blue.tracks() {
                *inside.entry(t).or_insert(0.0) -= m * ratio;
            }
        }
        let mut inside: Vec<(u32, f64)> = inside.into_iter().collect();
        inside.sort_unstable_by_key(|x| x.0);
        PartialSums {
            log_scale,
            total,
            outside,
            inside,
            coefficients: masses.len() as u64,
        }
    }

    /// The sums of several shares, on the scale of the largest.
    pub fn combine(parts: &[PartialSums]) -> PartialSums {
        let live = parts.iter().filter(|p| p.total != 0.0);
        let log_scale = live
            .clone()
            .map(|p| p.log_scale)
            .fold(f64::NEG_INFINITY, f64::max);
        let mut sum = PartialSums {
            log_scale: if log_scale.is_finite() {
                log_scale
            } else {
                0.0
            },
            coefficients: parts.iter().map(|p| p.coefficients).sum(),
            ..PartialSums::default()
        };
        let mut inside: FxHashMap<u32, f64> = FxHashMap::default();
        for part in live {
            let f = (part.log_scale - sum.log_scale).exp();
            sum.total += f * part.total;
            sum.outside += f * part.outside;
            for &(t, x) in &part.inside {
                *inside.entry(t).or_insert(0.0) += f * x;
            }
        }
        sum.inside = inside.into_iter().collect();
        sum.inside.sort_unstable_by_key(|x| x.0);
        sum
    }

    /// P(track t is red) for t in 0..tracks.
    pub fn marginals(&self, tracks: usize) -> Result<Vec<f64>, BeliefError> {
        if !(self.total.is_finite() && self.total > 0.0) {
            return Err(BeliefError::Degenerate {
                normalizer: self.total,
            });
        }
        let mut p = vec![self.outside; tracks];
        for &(t, x) in &self.inside {
            if let Some(slot) = p.get_mut(t as usize) {
                *slot += x;
            }
        }
        // A sum of most of the mass may round an ulp outside [0, 1].
        Ok(p.into_iter()
            .map(|x| (x / self.total).clamp(0.0, 1.0))
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::filter::PropertyFilter;
    use crate::workload::WorkloadSpec;
    use crate::Event;

    /// Cutting a belief into shares by any rule and running every event on
    /// every share gives the marginals of the whole, for exact conditioning
    /// and for the distributed rule alike.
    #[test]
    fn shares_add_up_to_the_whole() {
        for distributed_rule in [false, true] {
            let options = RadonOptions {
                distributed_rule,
                ..RadonOptions::default()
            };
            let spec = WorkloadSpec {
                tracks: 9,
                red: 3,
                events: 60,
                ..WorkloadSpec::table3(9, 7)
            };
            let workload = crate::workload::generate(&spec);
            let field = Field::uniform(9, 3);
            let events = workload.events;
            let mut whole = RadonBelief::with_options(field.clone(), options.clone()).unwrap();
            let mut start = RadonShare::start(field.clone(), &options).unwrap();
            let mut shares: Vec<RadonShare> = (0..3)
                .map(|_| RadonShare::empty(field.clone(), false))
                .collect();
            let atoms = start.extract(|_| true);
            for (i, (atom, m)) in atoms.into_iter().enumerate() {
                shares[i % 3].absorb([(atom, m)]);
            }
            let mut log = crate::radon::MixingLog::new(field.tracks);
            for (step, event) in events.iter().enumerate() {
                match *event {
                    Event::Mix(mix) => {
                        whole.mix(mix).unwrap();
                        log.record(mix.a, mix.b);
                        for s in &mut shares {
                            s.mix(mix).unwrap();
                        }
                    }
                    Event::Observe(o) => {
                        whole.observe(o).unwrap();
                        let partners = log.partners(o.track).to_vec();
                        for s in &mut shares {
                            let growth = if distributed_rule {
                                Growth::Meeting(&partners)
                            } else {
                                Growth::All
                            };
                            s.observe(o, growth).unwrap();
                        }
                        log.clear(o.track);
                    }
                }
                // Move some atoms between shares now and then: a handover.
                if step % 7 == 3 {
                    let moved = shares[0].extract(|a| a.red.len() % 2 == 0);
                    shares[1].absorb(moved);
                }
                let parts: Vec<PartialSums> = shares.iter().map(|s| s.partial_sums()).collect();
                let p = PartialSums::combine(&parts)
                    .marginals(field.tracks)
                    .unwrap();
                let q = whole.marginals().unwrap();
                for (x, y) in p.iter().zip(&q) {
                    assert!((x - y).abs() < 1e-9, "step {step}: {p:?} vs {q:?}");
                }
            }
        }
    }

    /// A share holding the whole belief, sparsified with the belief's own
    /// rule (thresholding, or OMP after runs of mixing), keeps the belief's
    /// marginals: the leaders run the paper's approximation, not another.
    #[test]
    fn one_share_sparsified_is_the_sparsified_belief() {
        // Thresholding from a uniform start with fair swaps, where many sets
        // tie by symmetry; OMP, whose greedy choices rounding can still
        // flip between near-equal candidates, from a known start with
        // unfair swaps.
        let runs = [
            (Sparsify::threshold(12), Field::uniform(9, 3), 0.5),
            (
                Sparsify::overcomplete(12),
                Field::known(9, vec![0, 4, 7]),
                0.37,
            ),
        ];
        for (sparsify, field, swap) in runs {
            let options = RadonOptions {
                distributed_rule: true,
                sparsify: Some(sparsify.clone()),
                ..RadonOptions::default()
            };
            let spec = WorkloadSpec {
                tracks: 9,
                red: 3,
                events: 200,
                swap,
                ..WorkloadSpec::table3(9, 11)
            };
            let workload = crate::workload::generate(&spec);
            let mut whole = RadonBelief::with_options(field.clone(), options.clone()).unwrap();
            let mut share = RadonShare::start(field.clone(), &options).unwrap();
            let mut log = crate::radon::MixingLog::new(field.tracks);
            for (step, event) in workload.events.iter().enumerate() {
                match *event {
                    Event::Mix(mix) => {
                        whole.mix(mix).unwrap();
                        log.record(mix.a, mix.b);
                        share.mix(mix).unwrap();
                    }
                    Event::Observe(o) => {
                        whole.observe(o).unwrap();
                        share
                            .observe(o, Growth::Meeting(log.partners(o.track)))
                            .unwrap();
                        log.clear(o.track);
                    }
                }
                share.sparsify(&sparsify).unwrap();
                assert!(share.len() <= 12);
                let p = share.partial_sums().marginals(field.tracks).unwrap();
                let q = whole.marginals().unwrap();
                for (x, y) in p.iter().zip(&q) {
                    assert!(
                        (x - y).abs() < 1e-9,
                        "{sparsify:?} step {step}: {p:?} vs {q:?}"
                    );
                }
            }
            if matches!(sparsify.method, SparsifyMethod::Overcomplete(_)) {
                assert!(
                    whole.stats().omp_runs > 0,
                    "OMP never ran: the test shows nothing"
                );
            }
        }
    }
}
