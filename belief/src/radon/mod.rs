//! The core of idmesh: a sparse, lazy (unnormalized) belief over which k of n
//! tracks are red, written on the overcomplete Radon dictionary of Jiang et
//! al., *Property Management in Wireless Sensor Networks with Overcomplete
//! Radon Bases* (TOSN 2013), Section 4.2:
//!
//! f = Σ_α c_α φ_α, over sets α with |α| ≤ k, where φ_α(x) = [α ⊆ x].
//!
//! Our atoms may also fix tracks blue (φ_{α|β}, see [`atom`](self::atom)),
//! which keeps every coefficient positive under blue-favouring sightings;
//! with `RadonOptions::signed` the engine stays in the paper's dictionary and
//! such sightings produce negative coefficients, exactly as Algorithm 2 does.
//!
//! ## Representation: masses, not coefficients
//! We store, for each atom, its *mass* m_α = c_α·W(|α|) — the l1 contribution
//! of c_α φ_α to f (Section 5.3.2), W(j) = C(n − j, k − j) — times a global scale
//! e^{log_scale}. Every update then needs only the ratios W(j + 1)/W(j) =
//! (k − j)/(n − j), so nothing overflows for n up to 10,000 even though W(0)
//! has thousands of digits. The masses are renormalized to sum 1 after every
//! conditioning and sparsification, the factor going into `log_scale`: the
//! belief stays lazy (the normalizing constant is kept, not discarded) and
//! numerically sound over millions of events.
//!
//! ## Files
//! - [`rollup`](self::rollup) — Algorithm 1, mixing.
//! - [`condition`](self::condition) — Algorithm 2 for likelihoods in
//!   span{φ_∅, φ_t}, with the distributed rule of Section 5.4 as an option.
//! - [`answer`](self::answer) — exact marginals, P(set all red), normalizer.
//! - [`dense`](self::dense) — the unbudgeted belief never holds more
//!   coefficients than there are red sets.
//! - [`threshold`](self::threshold), [`omp`](self::omp) — Section 5.3.
//! - [`sparsify`](self::sparsify) — when to run which approximation.
//! - [`share`](self::share) — a leader's share of the belief and the partial
//!   sums queries are answered from (Section 5.4 as a distributed system).
//! - [`mixing_log`](self::mixing_log) — per-track mixing partners since the
//!   last observation, for the distributed rule.

mod answer;
mod atom;
mod condition;
mod dense;
mod mixing_log;
mod omp;
mod rollup;
mod share;
mod sparsify;
mod threshold;

pub use atom::Atom;
pub use condition::Growth;
pub use mixing_log::MixingLog;
pub use share::{PartialSums, RadonShare};
pub use sparsify::Sparsify;
pub(crate) use sparsify::{OmpSchedule, SparsifyMethod};

use crate::error::BeliefError;
use crate::event::{Field, Mix, Observe};
use crate::filter::PropertyFilter;
use crate::repair;
use crate::track_set::TrackSet;
use crate::weights::Weights;
use rustc_hash::FxHashMap;

/// Options of the Radon engine. The default prunes nothing and conditions
/// exactly, so the belief is exact.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RadonOptions {
    /// Sparse approximation once the coefficient count exceeds a budget.
    pub sparsify: Option<Sparsify>,
    /// Condition with the distributed rule of Section 5.4: an observation of
    /// t only adds {t} ∪ β for sets β that meet the tracks t mixed with since
    /// t was last observed. An approximation; off = exact Algorithm 2.
    pub distributed_rule: bool,
    /// Stay in the paper's dictionary (Radon atoms only): a sighting that
    /// favours blue then adds negative coefficients. Off = such a sighting
    /// fixes the track blue in a positive atom instead (see `atom`). A
    /// sighting favouring blue by more than
    /// [`SIGNED_CANCELLATION`] takes the
    /// positive atom in either form: the signed one would cancel it away.
    pub signed: bool,
}

/// Counters a user of the engine may want to see.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RadonStats {
    pub events: u64,
    pub max_coefficients: usize,
    pub thresholdings: u64,
    pub omp_runs: u64,
    /// Sightings the belief had ruled out, taken after moving a share of
    /// it to the uniform one (see `sparsify`).
    pub restorations: u64,
    /// Sightings the prior rules out, set aside (`crate::repair`).
    pub set_aside: u64,
}

/// A belief over red sets on the overcomplete Radon dictionary.
#[derive(Debug, Clone)]
pub struct RadonBelief {
    field: Field,
    weights: Weights,
    masses: FxHashMap<Atom, f64>,
    log_scale: f64,
    options: RadonOptions,
    mixing_log: MixingLog,
    stats: RadonStats,
    since_omp: OmpSchedule,
}

impl RadonBelief {
    /// An exact belief (nothing pruned, exact conditioning).
    pub fn new(field: Field) -> Result<Self, BeliefError> {
        Self::with_options(field, RadonOptions::default())
    }

    pub fn with_options(field: Field, options: RadonOptions) -> Result<Self, BeliefError> {
        field.validate()?;
        if let Some(sparsify) = &options.sparsify {
            sparsify.validate()?;
        }
        let weights = Weights::new(field.tracks, &field.red);
        let mut masses = FxHashMap::default();
        let start = match &field.initial_red {
            // With k unknown a known start must also fix every other track
            // blue: φ_{x0} alone would allow any superset of x0.
            Some(red) if field.red.known().is_none() => {
                let red = TrackSet::from_tracks(red.iter().copied());
                let blue = (0..field.tracks as u32)
                    .filter(|t| !red.contains(*t))
                    .collect();
                Atom::new(red, blue)
            }
            Some(red) => Atom::radon(TrackSet::from_tracks(red.iter().copied())),
            None => Atom::default(),
        };
        let (i, o) = start.sizes();
        let log_scale = weights.ln2(i, o);
        masses.insert(start, 1.0);
        let mixing_log = MixingLog::new(field.tracks);
        let mut belief = RadonBelief {
            field,
            weights,
            masses,
            log_scale,
            options,
            mixing_log,
            stats: RadonStats {
                max_coefficients: 1,
                ..RadonStats::default()
            },
            since_omp: OmpSchedule::default(),
        };
        belief.expand_empty();
        Ok(belief)
    }

    /// Under the distributed rule, Section 5.4 keeps every 1-set and never
    /// the empty set: φ_∅ = (1/k)·Σ_t φ_{t} when k is known. An atom that
    /// fixes no track meets no mixing log, so kept as φ_∅ it would never
    /// grow and the belief would stay uniform forever. With k unknown the
    /// identity does not hold (Σ_t φ_t = |x|·φ_∅), and the rule grows the
    /// empty atom on every observation instead (see `condition`).
    fn expand_empty(&mut self) {
        // With k = 0 the identity has no 1-sets to spread over: the belief
        // is the empty set, φ_∅ alone.
        if !self.options.distributed_rule || self.field.red.known().is_none_or(|k| k == 0) {
            return;
        }
        let Some(mass) = self.masses.remove(&Atom::default()) else {
            return;
        };
        // Each of the n singletons carries 1/k of the coefficient, i.e.
        // 1/n of the mass (W(1)/W(0) = k/n).
        let share = mass / self.field.tracks as f64;
        for t in 0..self.field.tracks as u32 {
            *self
                .masses
                .entry(Atom::radon(TrackSet::singleton(t)))
                .or_insert(0.0) += share;
        }
        self.masses.retain(|_, m| *m != 0.0);
    }

    /// A belief given directly by Radon coefficients c_α (the paper's
    /// notation), e.g. to start from a worked example.
    #[cfg(test)]
    pub(crate) fn from_coefficients(
        field: Field,
        options: RadonOptions,
        coefficients: impl IntoIterator<Item = (TrackSet, f64)>,
    ) -> Result<Self, BeliefError> {
        let mut belief = Self::with_options(field, options)?;
        belief.masses.clear();
        belief.log_scale = 0.0;
        for (set, c) in coefficients {
            for &t in set.tracks() {
                belief.field.check_track(t)?;
            }
            let ln_w = belief.weights.ln(set.len());
            if c != 0.0 && ln_w.is_finite() {
                *belief.masses.entry(Atom::radon(set)).or_insert(0.0) += c * ln_w.exp();
            }
        }
        belief.expand_empty();
        belief.renormalize()?;
        Ok(belief)
    }

    pub fn stats(&self) -> &RadonStats {
        &self.stats
    }

    /// The Radon coefficient c_α of φ_α in the paper's units (f = Σ c_α φ_α),
    /// 0 for a set not held. Finite only while c_α fits an f64.
    #[cfg(test)]
    pub(crate) fn coefficient(&self, set: &TrackSet) -> f64 {
        self.coefficient_of(&Atom::radon(set.clone()))
    }

    /// The coefficient of any atom, in the paper's units.
    #[cfg(test)]
    pub(crate) fn coefficient_of(&self, atom: &Atom) -> f64 {
        match self.masses.get(atom) {
            Some(&m) => m * (self.log_scale - self.ln_weight(atom)).exp(),
            None => 0.0,
        }
    }

    /// Every held atom with its coefficient, in the paper's units.
    pub fn coefficients_iter(&self) -> impl Iterator<Item = (&Atom, f64)> + '_ {
        self.masses
            .iter()
            .map(|(a, &m)| (a, m * (self.log_scale - self.ln_weight(a)).exp()))
    }

    /// Every held atom with its share of the total mass (sums to 1).
    #[cfg(test)]
    pub(crate) fn masses(&self) -> impl Iterator<Item = (&Atom, f64)> + '_ {
        let total = self.total_mass();
        self.masses.iter().map(move |(a, &m)| (a, m / total))
    }

    fn ln_weight(&self, atom: &Atom) -> f64 {
        let (red, blue) = atom.sizes();
        self.weights.ln2(red, blue)
    }

    fn total_mass(&self) -> f64 {
        self.masses.values().sum()
    }

    /// Divides the masses by their sum and moves the factor into the scale.
    fn renormalize(&mut self) -> Result<(), BeliefError> {
        let total = self.total_mass();
        if !(total.is_finite() && total > 0.0) {
            return Err(BeliefError::Degenerate { normalizer: total });
        }
        for m in self.masses.values_mut() {
            // Floored as conditioning is (`crate::support`): an
            // atom 10^-300 of a total above 1 stays possible.
            *m = condition::floored_div(*m, total);
        }
        self.log_scale += total.ln();
        Ok(())
    }

    fn note_size(&mut self) {
        self.stats.max_coefficients = self.stats.max_coefficients.max(self.masses.len());
    }

    /// Runs the configured sparse approximation if the budget is exceeded.
    fn maybe_sparsify(&mut self) -> Result<(), BeliefError> {
        let Some(sparsify) = self.options.sparsify.clone() else {
            return Ok(());
        };
        if self.masses.len() <= sparsify.budget {
            return Ok(());
        }
        self.sparsify_now(&sparsify)
    }
}

impl PropertyFilter for RadonBelief {
    fn field(&self) -> &Field {
        &self.field
    }

    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        self.field.check_mix(&mix)?;
        self.rollup(mix);
        self.mixing_log.record(mix.a, mix.b);
        self.stats.events += 1;
        self.since_omp.mixed();
        self.bound_by_dense();
        self.note_size();
        self.maybe_sparsify()
    }

    fn observe(&mut self, observe: Observe) -> Result<(), BeliefError> {
        self.field.check_observe(&observe)?;
        if self.field.rules_out(&observe) {
            repair::note("radon", &mut self.stats.set_aside, &observe, true);
            return Ok(());
        }
        self.condition(observe)?;
        self.mixing_log.clear(observe.track);
        self.stats.events += 1;
        self.since_omp.observed();
        self.bound_by_dense();
        self.note_size();
        self.maybe_sparsify()
    }

    fn marginals(&self) -> Result<Vec<f64>, BeliefError> {
        self.exact_marginals()
    }

    fn coefficients(&self) -> usize {
        self.masses.len()
    }

    fn repairs(&self) -> u64 {
        self.stats.restorations + self.stats.set_aside
    }
}
