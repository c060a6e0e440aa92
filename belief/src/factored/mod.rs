//! A factored belief: a product of small exact beliefs over groups of tracks,
//! coupled only through the number of red targets.
//!
//! With a known initial assignment, mixing never changes how many red
//! targets a connected group of mixed tracks holds, so the exact belief
//! factorizes over the connected components of the mixing graph; with the
//! uniform prior the components are coupled only through the total count.
//! [`FactoredBelief`] keeps
//!
//! P(x) ∝ Π_C g_C(x ∩ C) · π(|x|),
//!
//! where the components C partition the tracks, each g_C is an exact dense
//! table over all 2^|C| subsets of C (with a log scale), and π(s) is the
//! prior weight of one red set of size s (k known: [s = k]; k unknown:
//! p(s)/C(n, s)). The private `tree` module evaluates the count coupling
//! lazily — nothing global happens until someone asks (the
//! information-matrix paper's lazy inference): an event touches only its
//! components' slots and marks one root path of a product tree of count
//! vectors dirty; a query recomputes the dirty nodes and walks the tree
//! down once. The private `counts` module keeps the eager evaluation for
//! what is not on a hot path (normalizer fallbacks, P(set all red), the
//! count posterior) and as the reference the tree is tested against.
//! How splits weigh the red count is [`Coupling`]: the true weight from
//! the rest of the belief, or the weight an uninformed rest of the field
//! would give (what leaders can compute; docs/design/beliefs.md, "The local
//! rule").
//!
//! - Mixing tracks of one component is the exact rollup on its table.
//! - Mixing tracks of two components merges them (outer product, then
//!   rollup) while the result has at most [`FactoredOptions::max_component`]
//!   tracks (and the tables fit [`FactoredOptions::max_numbers`]).
//!   Otherwise the pair is split back into two by moment matching (an
//!   M-projection, the assumed-density step of Boyen and Koller; see the
//!   private `split` module), along a partition chosen by [`SplitRule`].
//!   The default, [`SplitRule::LeastLoss`] with one round on components of
//!   at most 6 tracks, ranks the old cut and every exchange of one track
//!   between its halves by the information each split loses, from the
//!   marginal tables alone; [`SplitRule::Original`]
//!   never builds the 2^(|C1|+|C2|) merged table (the two marginal tables
//!   it needs have a closed form) and is cheaper, further from the exact
//!   filter (docs/coupling-accuracy.md measures both).
//! - An observation multiplies the observed track's component table by the
//!   likelihood. Tracks it leaves certain (marginal within
//!   [`FactoredOptions::certain`] of 0 or 1) are split off exactly.
//!
//! Until the first split the belief is exact: the tables hold the exact
//! belief of each connected component of the mixing graph.
//!
//! Two more projections serve the distributed runtime's *regional rule*
//! (docs/design/architecture.md, "Components that stay in their region"), which
//! keeps every component inside one leader's region so that it seldom has
//! to move: [`FactoredBelief::mix_apart`] projects a mix of two components
//! back onto them even where the merge would fit, and
//! [`FactoredBelief::split_off`] projects one track out of its component.
//! The belief knows nothing of regions: the caller decides when (the
//! leaders, and `idmesh_placement::Regional` for the centralized engine).

mod contradiction;
mod counts;
mod share;
mod split;
mod table;
mod tree;

use crate::error::BeliefError;
use crate::event::{Field, Mix, Observe};
use crate::filter::PropertyFilter;
use counts::CountPrior;
pub use share::{coupled_marginals, CountPart, CouplingTree, FactoredShare, HeldComponent};
use split::Weighted;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, MutexGuard};
use table::Component;
use tree::{CountTree, Reservoir};

/// The largest `max_component` with [`SplitRule::Original`], which never
/// builds a table larger than one component: 2^20 numbers (8 MiB) each.
pub(crate) const MAX_COMPONENT_LIMIT: usize = 20;

/// The largest `max_component` with the other rules, which build the merged
/// table of two components before splitting it: 2^24 numbers (128 MiB).
pub(crate) const MAX_COMPONENT_MERGED: usize = 12;

/// How a merged component too large to keep is cut in two.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SplitRule {
    /// The tracks stay where they were before the mix (the plain
    /// Boyen–Koller projection onto the old clusters).
    Original,
    /// The tracks that mixed most recently (the two just mixed first) stay
    /// together; the ones that have gone longest without mixing are pushed
    /// out.
    Recent,
    /// Start from the original partition, then exchange one track of one
    /// half with one of the other while the best such exchange lowers
    /// KL(P‖P′), the information the split loses; at most `rounds`
    /// exchanges. The default, with one round. It reads no clock (unlike
    /// [`Recent`](SplitRule::Recent)), so events on disjoint components
    /// commute.
    LeastLoss { rounds: usize },
}

/// Which count weights Q(s) a split matches its moments under.
///
/// The moment matching keeps P(x_A) and P(x_B) of the merged component's
/// part of the belief, P(x) ∝ g(x)·Q(|x|), where Q is the weight the rest of
/// the belief gives to the merged red count.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Coupling {
    /// Q is the true weight from every other component and π: the split
    /// preserves the marginals of the whole belief (the M-projection of
    /// Boyen–Koller). Each split reads Q, and each observation does too (to
    /// split off the tracks the count makes certain): by one walk down the
    /// count tree's root path (O(log #components) convolutions of windows
    /// as wide as the spread of the red count, so Θ(√n) work at least),
    /// and once the rest of the belief is a reservoir (its red count's
    /// variance at least 200, some 10,000 tracks in a Table III crowd) from
    /// the normal law of its count with its third cumulant, in O(|C|):
    /// within about 2·10⁻⁴ of the exact weights there, and closer as n
    /// grows.
    Coupled,
    /// Q(s) = Σ_K π(K)·C(n − m, K − s) on every count s the merged pair
    /// of m tracks can hold, 0 elsewhere: the weight an *uninformed* rest
    /// (every completion of the other n − m tracks alike under the prior)
    /// gives to the pair's count. A function of (n, π, m) and of the pair's
    /// own support only, so the split needs only what it splits and a soft
    /// observation only its component, and events on disjoint components
    /// commute. This is what leaders run when the factored belief is
    /// distributed (`FactoredShare`), so the centralized engine with this
    /// coupling computes what they compute.
    ///
    /// The same as [`Coupled`](Coupling::Coupled) whenever the merged count
    /// is fixed (a known start, until splits spread the counts): then the
    /// true Q is one number on the one count; and from the uniform prior
    /// until the first sighting, when the rest *is* uninformed. Against
    /// [`Flat`](Coupling::Flat) it keeps the prior's pull on the pair's
    /// count: a pair of m tracks among n holds s of the k red ones in
    /// C(m, s)·C(n − m, k − s) of the k-sets, and weighing every s alike
    /// lets the halves of a split believe in extreme counts more than the
    /// rest allows (most on small crowds, where m is a large share of n).
    /// What sightings taught the rest it cannot know: docs/design/beliefs.md,
    /// "The local rule", and docs/coupling-accuracy.md for what that costs.
    /// An observation reads only its component too, hard ones (a likelihood
    /// 0) included: one the prior alone rules out (it leaves more red
    /// tracks than π allows, or fewer) is set aside; one its own
    /// component rules out is taken by the repair rule (the component
    /// smoothed); one that only other components rule out is found at the
    /// next query, which answers by the contradiction rule (the
    /// `contradiction` module).
    Local,
    /// Q(s) = 1 on every count s the merged pair can hold, 0 elsewhere: the
    /// split matches the moments of the pair's own tables as if the rest of
    /// the belief did not care about their count. Local as
    /// [`Local`](Coupling::Local) is, and what leaders ran before it; kept
    /// to measure against.
    Flat,
}

impl Coupling {
    /// Whether a split and an observation read only the components they
    /// touch (what a leader's share can run).
    pub fn is_local(self) -> bool {
        matches!(self, Coupling::Local | Coupling::Flat)
    }
}

/// The most tracks at which the eager (O(n²)-memory) evaluation of the
/// count coupling stands in for the count tree when the tree's weights
/// underflow.
pub(crate) const EAGER_LIMIT: usize = 4096;

/// The share of a component's (normalized) mass a repair gives to the
/// sets the prior allows.
const REPAIR_MASS: f64 = 1e-9;

/// Options of [`FactoredBelief`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FactoredOptions {
    /// The most tracks one component may hold: 1..=[`MAX_COMPONENT_LIMIT`]
    /// with [`SplitRule::Original`], 1..=[`MAX_COMPONENT_MERGED`] otherwise.
    /// A component of m tracks stores 2^m numbers.
    pub max_component: usize,
    /// The most numbers all tables together may hold after a mix (None = no
    /// limit beyond `max_component`). Must be at least 2n.
    pub max_numbers: Option<usize>,
    pub split: SplitRule,
    /// The count weights of the splits (and of the certainty test after a
    /// soft observation).
    pub coupling: Coupling,
    /// L1 tolerance of the moment matching on the marginals it preserves.
    pub tolerance: f64,
    /// Sinkhorn sweeps of the moment matching before it switches to Newton
    /// steps (which reach solutions at infinity quickly); if those fail too
    /// the mix reports [`BeliefError::Numerical`].
    pub max_sweeps: usize,
    /// A track whose other colour has odds of at most this (against its
    /// likely one) after an observation or a split is split off as certain,
    /// keeping those odds on its own. 0 (the default): only a track
    /// certain outright. Anything more drops the correlation between the
    /// unlikely colour and the rest of the component: a stream the world
    /// produced (a sighting that makes the truth a 10^-200 chance, then a
    /// certain one of it) can then leave no mass anywhere.
    pub certain: f64,
}

impl Default for FactoredOptions {
    fn default() -> Self {
        FactoredOptions {
            max_component: 6,
            max_numbers: None,
            split: SplitRule::LeastLoss { rounds: 1 },
            coupling: Coupling::Coupled,
            tolerance: 1e-12,
            max_sweeps: 200,
            certain: 0.0,
        }
    }
}

impl FactoredOptions {
    pub fn validate(&self, tracks: usize) -> Result<(), BeliefError> {
        let unsupported = |what| {
            Err(BeliefError::Unsupported {
                method: "factored",
                what,
            })
        };
        let limit = match self.split {
            SplitRule::Original => MAX_COMPONENT_LIMIT,
            _ => MAX_COMPONENT_MERGED,
        };
        if !(1..=limit).contains(&self.max_component) {
            return unsupported(
                "a max_component outside 1..=20 (1..=12 unless the rule is Original)",
            );
        }
        if self.max_numbers.is_some_and(|m| m < 2 * tracks) {
            return unsupported("a max_numbers below 2 per track");
        }
        if !(self.tolerance > 0.0 && self.tolerance.is_finite()) || self.max_sweeps == 0 {
            return unsupported("a non-positive tolerance or sweep limit");
        }
        if !(0.0..0.5).contains(&self.certain) {
            return unsupported("a certainty margin outside [0, 0.5)");
        }
        Ok(())
    }
}

/// Counters of what the belief did.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FactoredStats {
    pub events: u64,
    /// Mixes that merged two components into one.
    pub merges: u64,
    /// Mixes that merged two components and split them by moment matching.
    pub splits: u64,
    /// Tracks split off because they became certain.
    pub certain_splits: u64,
    /// Mixes kept apart ([`FactoredBelief::mix_apart`]) and tracks split
    /// off their components ([`FactoredBelief::split_off`]): the regional
    /// rule's approximations.
    pub kept_apart: u64,
    pub split_off: u64,
    /// Splits whose count scaling failed under their weights and were
    /// retried under the local or the flat ones (valid streams whose
    /// sightings contradict the truth again and again).
    pub retried_splits: u64,
    /// Sightings the belief held impossible: taken by smoothing their
    /// component where π allows them (see `observe_repaired`), set aside
    /// where it does not (see `set_aside`).
    pub repairs: u64,
    /// The most iterations (Sinkhorn sweeps + Newton steps) one moment
    /// matching needed.
    pub max_sweeps: usize,
    pub max_coefficients: usize,
    pub max_component: usize,
}

/// The factored belief (see the module documentation).
#[derive(Debug)]
pub struct FactoredBelief {
    field: Field,
    options: FactoredOptions,
    prior: CountPrior,
    /// The components in stable slots (`None`: free), so that an event
    /// touches only the slots of its components.
    comps: Vec<Option<Component>>,
    free: Vec<usize>,
    /// (slot, local bit) of every track.
    home: Vec<(usize, usize)>,
    /// Σ_C 2^|C|, kept as components come and go.
    numbers: usize,
    /// When each track last mixed (event number), for [`SplitRule::Recent`].
    last_mix: Vec<u64>,
    /// [`CountPrior::uninformed_rest`] by m, made when first needed (empty:
    /// not yet): the count weights of [`Coupling::Local`].
    uninformed: Vec<Vec<f64>>,
    /// The count coupling, evaluated when asked (see the `tree` module);
    /// behind a lock because a query caches its convolutions.
    tree: Mutex<CountTree>,
    /// Whether events keep the tree's leaves: a leader's share leaves
    /// them, since the coupling is the coordinator's, and the tree is
    /// built afresh if anything reads it ([`FactoredBelief::leave_tree`]).
    tree_kept: bool,
    /// Leaves changed since the tree was built (only when not kept).
    tree_stale: std::sync::atomic::AtomicBool,
    stats: FactoredStats,
    /// Queries answered by the contradiction rule (a query reads the
    /// belief through `&self`).
    query_repairs: AtomicU64,
}

impl Clone for FactoredBelief {
    fn clone(&self) -> Self {
        FactoredBelief {
            field: self.field.clone(),
            options: self.options.clone(),
            prior: self.prior.clone(),
            comps: self.comps.clone(),
            free: self.free.clone(),
            home: self.home.clone(),
            numbers: self.numbers,
            last_mix: self.last_mix.clone(),
            uninformed: self.uninformed.clone(),
            tree: Mutex::new(self.lock_tree().clone()),
            tree_kept: self.tree_kept,
            tree_stale: std::sync::atomic::AtomicBool::new(false),
            stats: self.stats.clone(),
            query_repairs: AtomicU64::new(self.query_repairs()),
        }
    }
}

impl FactoredBelief {
    /// Every track its own component, with the default options.
    #[cfg(test)]
    pub(crate) fn new(field: Field) -> Result<Self, BeliefError> {
        Self::with_options(field, FactoredOptions::default())
    }

    pub fn with_options(field: Field, options: FactoredOptions) -> Result<Self, BeliefError> {
        field.validate()?;
        options.validate(field.tracks)?;
        let n = field.tracks;
        let comps: Vec<Component> = match &field.initial_red {
            Some(red) => {
                let mut is_red = vec![false; n];
                for &t in red {
                    is_red[t as usize] = true;
                }
                (0..n as u32)
                    .map(|t| {
                        if is_red[t as usize] {
                            Component::singleton(t, 0.0, 1.0)
                        } else {
                            Component::singleton(t, 1.0, 0.0)
                        }
                    })
                    .collect()
            }
            None => (0..n as u32)
                .map(|t| Component::singleton(t, 1.0, 1.0))
                .collect(),
        };
        let prior = CountPrior::new(&field);
        let counts: Vec<Vec<f64>> = comps.iter().map(|c| c.counts.clone()).collect();
        let tilt = tree::balancing_tilt(counts.iter().map(|c| &c[..]), prior.target());
        let tree = CountTree::new(counts, tilt, prior.is_point());
        let mut belief = FactoredBelief {
            field,
            options,
            prior,
            numbers: comps.iter().map(|c| c.table.len()).sum(),
            comps: comps.into_iter().map(Some).collect(),
            free: Vec::new(),
            home: vec![(0, 0); n],
            last_mix: vec![0; n],
            uninformed: Vec::new(),
            tree: Mutex::new(tree),
            tree_kept: true,
            tree_stale: std::sync::atomic::AtomicBool::new(false),
            stats: FactoredStats::default(),
            query_repairs: AtomicU64::new(0),
        };
        for slot in 0..n {
            belief.rehome(slot);
        }
        belief.stats.max_component = 1;
        belief.note_size();
        Ok(belief)
    }

    pub fn stats(&self) -> &FactoredStats {
        &self.stats
    }

    /// Queries the contradiction rule answered: the components together
    /// admitted no red count the prior allows.
    pub fn query_repairs(&self) -> u64 {
        self.query_repairs.load(Ordering::Relaxed)
    }

    /// The current partition of the tracks, each component in its local
    /// order.
    pub fn components(&self) -> Vec<Vec<u32>> {
        self.live().map(|c| c.tracks.clone()).collect()
    }

    fn live(&self) -> impl Iterator<Item = &Component> {
        self.comps.iter().flatten()
    }

    /// The component in `slot` (every track's home slot is live).
    fn comp(&self, slot: usize) -> &Component {
        self.comps[slot]
            .as_ref()
            .expect("a track's home slot is live")
    }

    fn lock_tree(&self) -> MutexGuard<'_, CountTree> {
        // A panic elsewhere cannot leave the tree half-updated in a way
        // that matters: every node it touched is still marked dirty.
        let mut tree = self.tree.lock().unwrap_or_else(|e| e.into_inner());
        if self
            .tree_stale
            .swap(false, std::sync::atomic::Ordering::Relaxed)
        {
            *tree = self.fresh_tree();
        }
        tree
    }

    /// The tree for writing (built afresh if it was left).
    fn tree_mut(&mut self) -> &mut CountTree {
        if std::mem::take(self.tree_stale.get_mut()) {
            let fresh = self.fresh_tree();
            *self.tree.get_mut().unwrap_or_else(|e| e.into_inner()) = fresh;
        }
        self.tree.get_mut().unwrap_or_else(|e| e.into_inner())
    }

    /// The count tree of the components as they are now.
    fn fresh_tree(&self) -> CountTree {
        let counts: Vec<Vec<f64>> = self
            .comps
            .iter()
            .map(|c| c.as_ref().map_or_else(Vec::new, |c| c.counts.clone()))
            .collect();
        let live = self.count_refs();
        let tilt = tree::balancing_tilt(live.iter().copied(), self.prior.target());
        CountTree::new(counts, tilt, self.prior.is_point())
    }

    /// Events no longer keep the count tree (a leader's share: its
    /// components are coupled at the coordinator, and the tree's upkeep,
    /// a few logarithms and exponentials per changed component, would be
    /// the share's alone to pay). Anything that reads the tree builds it
    /// afresh first, so every answer stays the same.
    pub(crate) fn leave_tree(&mut self) {
        self.tree_kept = false;
    }

    /// R_{−C} of the component in `slot` over the counts 0..`width` (the
    /// tree's leaf may hold a merged count vector wider than the slot's
    /// component): from the normal law of the rest's red count once the
    /// rest is a reservoir (O(width), see the `tree` module), re-tilting
    /// the tree once if its bulk has drifted from k; else through the count
    /// tree, re-tilted if its result is unsafe (first keeping the FFT, then
    /// without it), and by the eager log-space evaluation if it still is.
    fn leave_one_out(&self, slot: usize, width: usize) -> Result<Vec<f64>, BeliefError> {
        let mut tree = self.lock_tree();
        // Every fast answer is checked for entries flushed to zero where
        // the component holds mass: taken as they are, they would cut
        // support the reads allow (and the next sighting could find none).
        let prior = &self.prior;
        let trusted = |tree: &CountTree, r: Vec<f64>| (!tree.flushed(prior, slot, &r)).then_some(r);
        match tree.reservoir_leave_one_out(prior, slot, width) {
            Reservoir::Weights(r) => {
                if let Some(r) = trusted(&tree, r) {
                    return Ok(r);
                }
            }
            Reservoir::OffCentre => {
                self.retilt(&mut tree, false);
                if let Reservoir::Weights(r) = tree.reservoir_leave_one_out(prior, slot, width) {
                    if let Some(r) = trusted(&tree, r) {
                        return Ok(r);
                    }
                }
            }
            Reservoir::Declined => {}
        }
        if let Some(r) = tree.leave_one_out(prior, slot, width) {
            if let Some(r) = trusted(&tree, r) {
                return Ok(r);
            }
        }
        for exact in [false, true] {
            self.retilt(&mut tree, exact);
            if let Some(r) = tree.leave_one_out(prior, slot, width) {
                if let Some(r) = trusted(&tree, r) {
                    return Ok(r);
                }
            }
        }
        drop(tree);
        self.check_eager()?;
        let tree = self.lock_tree();
        let mut counts = Vec::new();
        let mut index = 0;
        for s in 0..self.comps.len() {
            let c = tree.counts(s);
            if s == slot {
                index = counts.len();
            }
            if !c.is_empty() {
                counts.push(c);
            }
        }
        self.prior
            .leave_one_out(&counts, index)
            .ok_or(BeliefError::Degenerate { normalizer: 0.0 })
    }

    /// See the free [`check_eager`].
    fn check_eager(&self) -> Result<(), BeliefError> {
        check_eager(self.field.tracks)
    }

    /// Re-aims the count tree's tilt at the current components (called when
    /// a query found the fast evaluation unsafe: observations and splits
    /// have moved the bulk of the red count away from where π puts it);
    /// `exact` also keeps every tail of its convolutions and stops using
    /// the FFT from now on (when re-aiming alone did not help).
    fn retilt(&self, tree: &mut CountTree, exact: bool) {
        retilt(tree, &self.count_refs(), &self.prior, exact);
    }

    /// ln Z, Z = Σ_x f(x) of the unnormalized belief: the prior mass times
    /// the likelihood of every observation so far (the meaning of
    /// [`DenseFilter::log_normalizer`](crate::DenseFilter::log_normalizer));
    /// exact until the first split, after which each split keeps the mass
    /// of what it replaces.
    pub fn log_normalizer(&self) -> f64 {
        let scales: f64 = self.live().map(|c| c.log_scale).sum();
        let fast = self.lock_tree().ln_total(&self.prior);
        scales + fast.unwrap_or_else(|| self.prior.ln_total(&self.count_refs()))
    }

    /// P(every track of `tracks` is red). Repeated tracks count once.
    pub fn prob_all_red(&self, tracks: &[u32]) -> Result<f64, BeliefError> {
        let mut need = vec![0usize; self.comps.len()];
        for &t in tracks {
            self.field.check_track(t)?;
            let (c, bit) = self.home[t as usize];
            need[c] |= 1 << bit;
        }
        let all = self.count_refs();
        let total = self.prior.ln_total(&all);
        if total == f64::NEG_INFINITY || total.is_nan() {
            return Err(BeliefError::Degenerate { normalizer: 0.0 });
        }
        let live = || {
            self.comps
                .iter()
                .zip(&need)
                .filter_map(|(c, m)| Some((c.as_ref()?, *m)))
        };
        let held: Vec<Vec<f64>> = live()
            .map(|(c, m)| {
                if m == 0 {
                    Vec::new()
                } else {
                    c.counts_holding(m)
                }
            })
            .collect();
        let restricted: Vec<&[f64]> = live()
            .zip(&held)
            .map(|((c, _), h)| if h.is_empty() { &c.counts[..] } else { &h[..] })
            .collect();
        Ok((self.prior.ln_total(&restricted) - total).exp().min(1.0))
    }

    /// P(exactly j tracks are red) for j = 0..=n.
    pub fn count_posterior(&self) -> Result<Vec<f64>, BeliefError> {
        self.prior
            .count_posterior(&self.count_refs())
            .ok_or(BeliefError::Degenerate { normalizer: 0.0 })
    }

    fn count_refs(&self) -> Vec<&[f64]> {
        self.live().map(|c| &c.counts[..]).collect()
    }

    fn rehome(&mut self, slot: usize) {
        let c = self.comps[slot].as_ref().expect("a live slot");
        for (bit, &t) in c.tracks.iter().enumerate() {
            self.home[t as usize] = (slot, bit);
        }
    }

    fn note_size(&mut self) {
        self.stats.max_coefficients = self.stats.max_coefficients.max(self.numbers);
    }

    /// Replaces the components in the slots `remove` by `add`: touches only
    /// those slots, their tracks and their leaves of the count tree.
    fn replace(&mut self, remove: &[usize], add: Vec<Component>) {
        let add: Vec<Component> = if self.options.coupling.is_local() {
            add
        } else {
            add.into_iter()
                .map(|c| self.without_excluded_counts(c))
                .collect()
        };
        let kept = self.tree_kept;
        if !kept {
            *self.tree_stale.get_mut() = true;
        }
        let tree = self.tree.get_mut().unwrap_or_else(|e| e.into_inner());
        for &slot in remove {
            if let Some(c) = self.comps[slot].take() {
                self.numbers -= c.table.len();
                self.free.push(slot);
                if kept {
                    tree.set(slot, Vec::new());
                }
            }
        }
        for c in add {
            let slot = self.free.pop().expect("never more components than tracks");
            self.numbers += c.table.len();
            self.stats.max_component = self.stats.max_component.max(c.len());
            if kept {
                tree.set(slot, c.counts.clone());
            }
            for (bit, &t) in c.tracks.iter().enumerate() {
                self.home[t as usize] = (slot, bit);
            }
            self.comps[slot] = Some(c);
        }
    }

    /// `c` without the sets whose red count no completion of the rest
    /// allows (they weigh nothing in the belief, so dropping them is exact;
    /// see the same step in `observe`). Under the coupled weights a merge
    /// (the outer product of two tables) or a split (tables fitted where Q
    /// is zero are free there) can leave such sets holding most of a
    /// table's scale: with a known count of one red target, a 3-track table
    /// ended up all red at 1 and the one set that matters at 10^-252, and
    /// the next sightings underflowed it to 0. Unchanged if nothing else
    /// would be left (the caller's checks then report it).
    fn without_excluded_counts(&mut self, c: Component) -> Component {
        let mut table = c.table.clone();
        if !self.drop_excluded_counts(&mut table, c.len()) {
            return c;
        }
        Component::from_table(c.tracks.clone(), table, c.log_scale).unwrap_or(c)
    }

    /// Zeroes the sets of a table over `m` tracks whose red count no
    /// completion of the rest allows; whether any of them had weight.
    fn drop_excluded_counts(&mut self, table: &mut [f64], m: usize) -> bool {
        let open = self.uninformed_support(m);
        let mut dropped = false;
        for (y, g) in table.iter_mut().enumerate() {
            if !open[y.count_ones() as usize] {
                dropped |= *g > 0.0;
                *g = 0.0;
            }
        }
        dropped
    }

    /// The count weights of a merged component of `width` − 1 tracks that
    /// replaces the ones in `ca` and `cb`, under the configured coupling.
    fn merged_weights(
        &mut self,
        ca: usize,
        cb: usize,
        merged_counts: Vec<f64>,
    ) -> Result<Vec<f64>, BeliefError> {
        let width = merged_counts.len();
        if self.options.coupling.is_local() {
            return Ok(self.local_weights(&merged_counts, true));
        }
        // Everything but the pair: the pair's leaves hold the merged
        // counts for the walk, then their own again (the caller replaces
        // them if the split goes through).
        let (c1, c2) = (self.comp(ca).counts.clone(), self.comp(cb).counts.clone());
        let tree = self.tree_mut();
        tree.set(cb, Vec::new());
        tree.set(ca, merged_counts);
        let q = self.leave_one_out(ca, width);
        let tree = self.tree_mut();
        tree.set(ca, c1);
        tree.set(cb, c2);
        q
    }

    /// [`FactoredBelief::local_weights`] of `coupling` (Local or Flat) on
    /// the counts a merged pair can hold, whatever the configured coupling.
    fn local_weights_as(&mut self, coupling: Coupling, counts: &[f64]) -> Vec<f64> {
        let configured = std::mem::replace(&mut self.options.coupling, coupling);
        let q = self.local_weights(counts, true);
        self.options.coupling = configured;
        q
    }

    /// Which red counts of m tracks some completion of the rest allows
    /// under π (whatever the coupling: a fact of the prior).
    fn uninformed_support(&mut self, m: usize) -> Vec<bool> {
        if self.uninformed.len() <= m {
            self.uninformed.resize(m + 1, Vec::new());
        }
        if self.uninformed[m].is_empty() {
            self.uninformed[m] = self.prior.uninformed_rest(m);
        }
        self.uninformed[m].iter().map(|&w| w > 0.0).collect()
    }

    /// The count weights of a local coupling for a component (or merged
    /// pair) whose count vector is `counts`: the uninformed rest's weight
    /// ([`Coupling::Local`]) or 1 ([`Coupling::Flat`]), zero on the counts
    /// it cannot hold when `support` (a split must not move mass to a count
    /// the merged table rules out: that keeps a fixed count fixed).
    fn local_weights(&mut self, counts: &[f64], support: bool) -> Vec<f64> {
        let m = counts.len() - 1;
        let prior: &[f64] = if self.options.coupling == Coupling::Local {
            if self.uninformed.len() <= m {
                self.uninformed.resize(m + 1, Vec::new());
            }
            if self.uninformed[m].is_empty() {
                self.uninformed[m] = self.prior.uninformed_rest(m);
            }
            &self.uninformed[m]
        } else {
            &[]
        };
        counts
            .iter()
            .enumerate()
            .map(|(s, &c)| {
                if support && c <= 0.0 {
                    0.0
                } else {
                    prior.get(s).copied().unwrap_or(1.0)
                }
            })
            .collect()
    }

    /// The mix of two tracks in different components (0 < swap < 1); with
    /// `may_merge` false the pair is projected back onto its two old
    /// components even when the merged one would fit.
    fn mix_across(&mut self, mix: Mix, may_merge: bool) -> Result<(), BeliefError> {
        let (ca, ba) = self.home[mix.a as usize];
        let (cb, bb) = self.home[mix.b as usize];
        let (c1, c2) = (self.comp(ca), self.comp(cb));
        if c1.len() == 1 && c2.len() == 1 && c1.table == c2.table {
            // Two interchangeable tracks: the mix changes nothing.
            return Ok(());
        }
        let others = self.numbers - c1.table.len() - c2.table.len();
        let (max, budget) = (self.options.max_component, self.options.max_numbers);
        let fits = |size: usize, extra: usize| {
            size <= max && budget.is_none_or(|b| others + extra + (1usize << size) <= b)
        };
        let size = c1.len() + c2.len();
        if may_merge && fits(size, 0) {
            let mut merged = c1.outer(c2);
            merged.rollup(ba, c1.len() + bb, mix.swap);
            self.stats.merges += 1;
            self.replace(&[ca, cb], vec![merged]);
            return Ok(());
        }
        // The weight Q of the merged red count from everything else (the
        // rollup keeps the merged count vector: c1 ⊛ c2).
        let mut merged_counts = vec![0.0; size + 1];
        for (r, &x) in c1.counts.iter().enumerate() {
            for (t, &y) in c2.counts.iter().enumerate() {
                merged_counts[r + t] += x * y;
            }
        }
        let q = self.merged_weights(ca, cb, merged_counts.clone())?;
        let pieces = match self.project_pair(mix, may_merge, others, &q) {
            Ok(pieces) => pieces,
            Err(e @ (BeliefError::Numerical { .. } | BeliefError::Degenerate { .. })) => {
                // Q spans more than f64 holds (sightings that contradict
                // the truth again and again make the rest's count weights
                // differ by 10^300 and more between adjacent counts): the
                // split retries under the local weights, then the flat
                // ones, which the pair's own tables keep in range. Both
                // read only the pair, so leaders and replay retry alike.
                let mut retried = Err(e);
                for fallback in [Coupling::Local, Coupling::Flat] {
                    if retried.is_ok() || fallback == self.options.coupling {
                        continue;
                    }
                    if fallback == Coupling::Local && self.options.coupling == Coupling::Flat {
                        continue;
                    }
                    let q = self.local_weights_as(fallback, &merged_counts);
                    if self.stats.retried_splits == 0 {
                        tracing::warn!(
                            ?fallback,
                            ?mix,
                            "factored: a split retried under other count weights \
                             (counted as a belief repair; logged once)"
                        );
                    }
                    retried = self.project_pair(mix, may_merge, others, &q);
                }
                self.stats.retried_splits += 1;
                retried?
            }
            Err(e) => return Err(e),
        };
        if may_merge {
            self.stats.splits += 1;
        } else {
            self.stats.kept_apart += 1;
        }
        self.replace(&[ca, cb], pieces);
        Ok(())
    }

    /// The pieces that replace the components of `mix.a` and `mix.b` when
    /// they are projected apart under the count weights `q`.
    fn project_pair(
        &mut self,
        mix: Mix,
        may_merge: bool,
        others: usize,
        q: &[f64],
    ) -> Result<Vec<Component>, BeliefError> {
        let (ca, ba) = self.home[mix.a as usize];
        let (cb, bb) = self.home[mix.b as usize];
        let (c1, c2) = (self.comp(ca), self.comp(cb));
        let (tol, sweeps) = (self.options.tolerance, self.options.max_sweeps);
        Ok(if self.options.split == SplitRule::Original || !may_merge {
            // Project onto the old pair without building the merged table.
            let (pa, pb, ln_total) = split::mixed_pair_marginals(c1, ba, c2, bb, mix.swap, q)?;
            // P(x_A), P(x_B) are the merged belief's marginals, and the
            // split keeps them: tracks certain there are certain after.
            // Keep at least one track in each half.
            let margin = self.options.certain;
            let certain = |p: &[f64], bits: usize| {
                let mut fixed = table::certain_odds(p, None, bits, margin);
                fixed.truncate(bits.saturating_sub(1));
                fixed
            };
            let certain_a = certain(&pa, c1.len());
            let certain_b = certain(&pb, c2.len());
            let log_mass = c1.log_scale + c2.log_scale + ln_total;
            let (a, b, used) = split::fit(
                pa,
                pb,
                c1.tracks.clone(),
                c2.tracks.clone(),
                q,
                log_mass,
                tol,
                sweeps,
            )?;
            self.stats.max_sweeps = self.stats.max_sweeps.max(used);
            let mut pieces = Vec::new();
            for (half, fixed) in [(a, certain_a), (b, certain_b)] {
                if fixed.is_empty() {
                    pieces.push(half);
                } else {
                    let (rest, singles) = half.restrict(&fixed)?;
                    self.stats.certain_splits += singles.len() as u64;
                    pieces.extend(singles);
                    pieces.push(rest);
                }
            }
            pieces
        } else {
            let mut merged = c1.outer(c2);
            merged.rollup(ba, c1.len() + bb, mix.swap);
            self.split_materialized(merged, q.to_vec(), ca, others, mix)?
        })
    }

    /// Splits a merged table by the configured rule, after splitting off
    /// the tracks it leaves certain (and keeping it whole if that is enough
    /// to fit).
    fn split_materialized(
        &mut self,
        mut merged: Component,
        mut q: Vec<f64>,
        ca: usize,
        others: usize,
        mix: Mix,
    ) -> Result<Vec<Component>, BeliefError> {
        let mut pieces = Vec::new();
        // The merged belief must have mass under Q (Weighted::new checks).
        Weighted::new(&merged, &q)?;
        let fixed =
            table::certain_odds(&merged.table, Some(&q), merged.len(), self.options.certain);
        if !fixed.is_empty() && fixed.len() < merged.len() {
            let (rest, singles) = merged.restrict(&fixed)?;
            let shift = fixed.iter().filter(|f| f.1).count();
            q = q[shift..shift + rest.len() + 1].to_vec();
            merged = rest;
            self.stats.certain_splits += singles.len() as u64;
            pieces = singles;
        }
        let extra = 2 * pieces.len();
        let fits = merged.len() <= self.options.max_component
            && self
                .options
                .max_numbers
                .is_none_or(|b| others + extra + (1usize << merged.len()) <= b);
        if fits {
            pieces.push(merged);
            return Ok(pieces);
        }
        let weighted = Weighted::new(&merged, &q)?;
        let side_a: usize = merged
            .tracks
            .iter()
            .enumerate()
            .filter(|(_, t)| self.home[**t as usize].0 == ca)
            .map(|(b, _)| 1usize << b)
            .sum();
        let projection = self.choose_split(&weighted, &merged, side_a, others + extra, mix)?;
        self.stats.max_sweeps = self.stats.max_sweeps.max(projection.sweeps);
        pieces.push(projection.a);
        pieces.push(projection.b);
        Ok(pieces)
    }

    /// A sighting the belief holds impossible although π allows it (a
    /// sure read of a colour the belief ruled out — on a valid stream only
    /// rounding in the tables and count weights can have ruled it out):
    /// the documented repair, as the identity belief's. The sighting's
    /// component takes 10⁻⁹ of its mass on the sets the prior allows
    /// (every set whose count some completion allows, alike) and the
    /// sighting is applied again; if the count weights of the rest still
    /// rule it out (the coupled weights: other components hold the count
    /// as certain), every component is smoothed so. Counted in
    /// [`FactoredStats::repairs`] and logged once. A sighting the prior
    /// alone rules out is refused here, the belief left as it was (the
    /// caller sets it aside).
    fn observe_repaired(&mut self, observe: Observe, probability: f64) -> Result<(), BeliefError> {
        let saved = self.clone();
        let (c, _) = self.home[observe.track as usize];
        self.smooth(&[c])?;
        let mut done = self.observe_in_component(observe);
        if matches!(done, Err(BeliefError::ImpossibleObservation { .. }))
            && !self.options.coupling.is_local()
        {
            let every: Vec<usize> = (0..self.comps.len())
                .filter(|&slot| self.comps[slot].is_some())
                .collect();
            self.smooth(&every)?;
            done = self.observe_in_component(observe);
        }
        match done {
            Ok(()) => {
                if self.stats.repairs == 0 {
                    tracing::warn!(
                        ?observe,
                        probability,
                        "factored: a sighting the belief held impossible was taken by \
                         smoothing (counted as a belief repair; logged once)"
                    );
                }
                self.stats.repairs += 1;
                Ok(())
            }
            Err(e) => {
                *self = saved;
                Err(e)
            }
        }
    }

    /// A sighting the prior alone rules out (a sure red where no target
    /// is red, a sure blue where all are): no set the belief could ever
    /// hold explains it, so it teaches nothing the belief can keep. It is
    /// set aside, the belief left as it was; counted in
    /// [`FactoredStats::repairs`] and logged once, so that a leader fed
    /// such a stream answers on.
    fn set_aside(&mut self, observe: Observe) {
        if self.stats.repairs == 0 {
            tracing::warn!(
                ?observe,
                "factored: a sighting the prior rules out was set aside \
                 (counted as a belief repair; logged once)"
            );
        }
        self.stats.repairs += 1;
    }

    /// Gives each component in `slots` [`REPAIR_MASS`] of its mass on
    /// every set whose count some completion of the rest allows.
    fn smooth(&mut self, slots: &[usize]) -> Result<(), BeliefError> {
        for &slot in slots {
            let c = self.comp(slot);
            let (tracks, log_scale) = (c.tracks.clone(), c.log_scale);
            let mut table = c.table.clone();
            let open = self.uninformed_support(tracks.len());
            for (y, g) in table.iter_mut().enumerate() {
                if open[y.count_ones() as usize] {
                    *g += REPAIR_MASS;
                }
            }
            let smoothed = Component::from_table(tracks, table, log_scale)?;
            self.replace(&[slot], vec![smoothed]);
        }
        Ok(())
    }

    /// A sighting applied to its component: the component's table times
    /// the likelihood, refused as impossible when no set the count weights
    /// allow is left.
    fn observe_in_component(&mut self, observe: Observe) -> Result<(), BeliefError> {
        let (c, bit) = self.home[observe.track as usize];
        let comp = self.comp(c);
        let mut table = comp.observed(bit, observe.red, observe.blue);
        // Sets whose red count no completion of the rest allows (more red
        // tracks than π admits, or fewer) weigh nothing in the belief:
        // dropping them is exact, and keeps them from holding the table's
        // scale while the sets that matter underflow (with k = 0, every
        // set with a red track, against a 10^-200 sighting of blue).
        let m = comp.len();
        self.drop_excluded_counts(&mut table, m);
        let comp = self.comp(c);
        let new_counts = table::counts_of(&table, comp.len());
        // Under the local coupling a sighting needs only its component,
        // so that a leader holding the component alone computes the same.
        let r = if self.options.coupling.is_local() {
            self.local_weights(&new_counts, false)
        } else {
            self.leave_one_out(c, new_counts.len())?
        };
        let r = table::balanced(&new_counts, &r);
        let dot = |v: &[f64]| v.iter().zip(&r).map(|(x, y)| x * y).sum::<f64>();
        let (before, after) = (dot(&self.comp(c).counts), dot(&new_counts));
        if after.is_nan() || after <= 0.0 {
            return Err(BeliefError::ImpossibleObservation {
                probability: if before > 0.0 { after / before } else { 0.0 },
            });
        }
        let comp = self.comp(c);
        let updated = Component::from_table(comp.tracks.clone(), table, comp.log_scale)?;
        let fixed = table::certain_odds(
            &updated.table,
            Some(&r),
            updated.len(),
            self.options.certain,
        );
        if !fixed.is_empty() {
            let (rest, singles) = if fixed.len() == updated.len() {
                // Everything certain: keep one track as the rest.
                updated.restrict(&fixed[1..])?
            } else {
                updated.restrict(&fixed)?
            };
            self.stats.certain_splits += singles.len() as u64;
            let mut add = singles;
            add.push(rest);
            self.replace(&[c], add);
        } else {
            self.replace(&[c], vec![updated]);
        }
        self.stats.events += 1;
        self.note_size();
        Ok(())
    }

    /// A mix as [`PropertyFilter::mix`] does it, except that tracks of two
    /// components are never merged: the mixed pair is projected back onto
    /// the two components (the moment matching of an oversized merge), so
    /// both keep their tracks. The regional rule runs this for a mix of
    /// tracks in two leaders' regions, so that no component comes to span
    /// regions (a mix inside one component, or a certain swap, is as
    /// usual).
    pub fn mix_apart(&mut self, mix: Mix) -> Result<(), BeliefError> {
        self.mix_with(mix, false)
    }

    /// Splits `track` off its component by moment matching (the
    /// M-projection onto {track} and the rest, under the configured
    /// coupling's count weights); nothing if it is alone. The regional rule
    /// runs this when a track is handed over to another leader's region.
    pub fn split_off(&mut self, track: u32) -> Result<(), BeliefError> {
        let (slot, bit) = *self
            .home
            .get(track as usize)
            .ok_or(BeliefError::UnknownTrack {
                track,
                tracks: self.field.tracks,
            })?;
        let comp = self.comp(slot);
        if comp.len() < 2 {
            return Ok(());
        }
        let width = comp.counts.len();
        let q = if self.options.coupling.is_local() {
            let counts = comp.counts.clone();
            self.local_weights(&counts, true)
        } else {
            self.leave_one_out(slot, width)?
        };
        let comp = self.comp(slot);
        let projection = Weighted::new(comp, &q)?.project(
            1 << bit,
            self.options.tolerance,
            self.options.max_sweeps,
        )?;
        self.stats.max_sweeps = self.stats.max_sweeps.max(projection.sweeps);
        self.stats.split_off += 1;
        self.replace(&[slot], vec![projection.a, projection.b]);
        Ok(())
    }

    pub(crate) fn mix_with(&mut self, mix: Mix, may_merge: bool) -> Result<(), BeliefError> {
        self.field.check_mix(&mix)?;
        if mix.swap == 0.0 {
            self.stats.events += 1;
            return Ok(());
        }
        let (a, b) = (mix.a as usize, mix.b as usize);
        let (ca, ba) = self.home[a];
        let (cb, bb) = self.home[b];
        if mix.swap == 1.0 {
            // The targets certainly exchanged tracks: relabel.
            for (slot, bit, track) in [(ca, ba, mix.b), (cb, bb, mix.a)] {
                let c = self.comps[slot].as_mut().expect("a live slot");
                c.tracks[bit] = track;
            }
            self.home.swap(a, b);
        } else if ca == cb {
            let c = self.comps[ca].as_mut().expect("a live slot");
            c.rollup(ba, bb, mix.swap);
        } else {
            self.mix_across(mix, may_merge)?;
        }
        self.stats.events += 1;
        self.last_mix[a] = self.stats.events;
        self.last_mix[b] = self.stats.events;
        self.note_size();
        Ok(())
    }

    /// The size of the first half of a split of m tracks: the largest that
    /// keeps both halves within `max_component` and the tables within
    /// `max_numbers`, else an even split.
    fn split_size(&self, m: usize, others: usize) -> usize {
        let max = self.options.max_component;
        let lo = m.div_ceil(2);
        let hi = max.min(m - 1);
        (lo..=hi)
            .rev()
            .find(|&a| {
                m - a <= max
                    && self
                        .options
                        .max_numbers
                        .is_none_or(|b| others + (1usize << a) + (1usize << (m - a)) <= b)
            })
            .unwrap_or(lo)
    }

    fn choose_split(
        &self,
        weighted: &Weighted,
        merged: &Component,
        original: usize,
        others: usize,
        mix: Mix,
    ) -> Result<split::Projection, BeliefError> {
        let m = merged.len();
        let (tol, sweeps) = (self.options.tolerance, self.options.max_sweeps);
        let original_ok = {
            let a = original.count_ones() as usize;
            a > 0 && a < m && a <= self.options.max_component && m - a <= self.options.max_component
        };
        // The first half of a cut: the `split_size` tracks that come first
        // by (their clock, latest first; then their number), the mixed
        // pair before all.
        let first_by = |clock: &dyn Fn(u32) -> u64| {
            let size = self.split_size(m, others);
            let mut order: Vec<usize> = (0..m).collect();
            order.sort_by_key(|&b| {
                let t = merged.tracks[b];
                let when = if t == mix.a || t == mix.b {
                    u64::MAX
                } else {
                    clock(t)
                };
                (std::cmp::Reverse(when), t)
            });
            order[..size].iter().map(|&b| 1usize << b).sum::<usize>()
        };
        let recent = || first_by(&|t| self.last_mix[t as usize]);
        // No clock, so that events on disjoint components commute.
        let paired = || first_by(&|_| 0);
        match self.options.split {
            SplitRule::Original if original_ok => weighted.project(original, tol, sweeps),
            SplitRule::Original | SplitRule::Recent => weighted.project(recent(), tol, sweeps),
            SplitRule::LeastLoss { rounds } => {
                // From the old cut (or, where certain tracks emptied a
                // side, the mixed pair and the lowest track numbers: no
                // clock, so that events on disjoint components commute),
                // exchanges ranked by the loss up to the merged table's
                // constant; only the chosen partition is projected.
                let mut best_part = if original_ok { original } else { paired() };
                let mut best = weighted.loss(best_part, tol, sweeps)?;
                for _ in 0..rounds {
                    match weighted.best_exchange(best_part, tol, sweeps)? {
                        Some((part, loss)) if loss < best - 1e-12 => {
                            (best_part, best) = (part, loss);
                        }
                        _ => break,
                    }
                }
                weighted.project(best_part, tol, sweeps)
            }
        }
    }
}

impl PropertyFilter for FactoredBelief {
    fn field(&self) -> &Field {
        &self.field
    }

    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        self.mix_with(mix, true)
    }

    fn observe(&mut self, observe: Observe) -> Result<(), BeliefError> {
        self.field.check_observe(&observe)?;
        match self.observe_in_component(observe) {
            Err(BeliefError::ImpossibleObservation { probability }) => {
                match self.observe_repaired(observe, probability) {
                    Err(BeliefError::ImpossibleObservation { .. }) => {
                        self.set_aside(observe);
                        Ok(())
                    }
                    done => done,
                }
            }
            done => done,
        }
    }

    /// One downward walk of the count tree (after recomputing what the
    /// events since the last query made dirty), then each component's
    /// marginals under its weights.
    /// A belief whose components together admit no count π allows (a
    /// stream that contradicts itself across components) is answered by
    /// the contradiction rule (the `contradiction` module), counted in
    /// [`FactoredBelief::query_repairs`] and logged once.
    fn marginals(&self) -> Result<Vec<f64>, BeliefError> {
        let all = {
            let mut tree = self.lock_tree();
            coupling_weights(
                &mut tree,
                &self.prior,
                &self.count_refs(),
                self.field.tracks,
            )
        };
        match all.and_then(|all| self.marginals_under(all)) {
            Err(BeliefError::Degenerate { .. }) => {
                let parts: Vec<CountPart> = self.live().map(share::count_part).collect();
                let out =
                    contradiction::repaired_marginals(&self.prior, &parts, self.field.tracks)?;
                if self.query_repairs.fetch_add(1, Ordering::Relaxed) == 0 {
                    tracing::warn!(
                        "factored: the components together admit no red count the prior \
                         allows; answered by the contradiction rule (counted as a query \
                         repair; logged once)"
                    );
                }
                Ok(out)
            }
            done => done,
        }
    }

    /// Σ_C 2^|C|: the numbers in the tables (the per-component log scales
    /// and count vectors are derived bookkeeping and not counted).
    fn coefficients(&self) -> usize {
        self.numbers
    }

    /// Sightings taken by the repair rule or set aside, and queries
    /// answered by the contradiction rule.
    fn repairs(&self) -> u64 {
        self.stats.repairs + self.query_repairs()
    }
}

impl FactoredBelief {
    /// Each component's marginals under its count weights `all` (by live
    /// component, `None` where it holds a single count).
    fn marginals_under(&self, all: Vec<Option<Vec<f64>>>) -> Result<Vec<f64>, BeliefError> {
        let mut out = vec![0.0; self.field.tracks];
        for (c, r) in self.live().zip(all) {
            let Some(r) = r else {
                // A single count held (the tree skips those): the table's
                // own marginals.
                if c.counts.iter().filter(|&&x| x > 0.0).count() != 1 {
                    return Err(BeliefError::Degenerate { normalizer: 0.0 });
                }
                c.write_marginals(&mut out);
                continue;
            };
            let (m, total) = c.weighted_marginals(&r);
            if total.is_nan() || total <= 0.0 {
                return Err(BeliefError::Degenerate { normalizer: total });
            }
            for (&t, p) in c.tracks.iter().zip(m) {
                out[t as usize] = p.clamp(0.0, 1.0);
            }
        }
        Ok(out)
    }
}

/// Re-aims `tree`'s tilt at the components' count vectors `counts` (see
/// [`FactoredBelief::retilt`]).
fn retilt(tree: &mut CountTree, counts: &[&[f64]], prior: &CountPrior, exact: bool) {
    let t = tree::balancing_tilt(counts.iter().copied(), prior.target());
    tracing::debug!(
        from = tree.ln_tilt(),
        to = t,
        exact,
        "factored: re-tilting the count tree"
    );
    tree.retilt(t, exact);
}

/// R_{−C} for every live component, in the order of `counts` (the live
/// leaves of `tree`, in slot order): one downward walk of the count tree,
/// re-tilted if unsafe (first keeping the FFT, then without it), and the
/// eager log-space evaluation if it still is. `None` for a component that
/// holds a single count (its marginals are its table's own). One code for
/// the belief's queries and for the coordinator's
/// ([`coupled_marginals`](share::coupled_marginals)), so both compute alike.
fn coupling_weights(
    tree: &mut CountTree,
    prior: &CountPrior,
    counts: &[&[f64]],
    tracks: usize,
) -> Result<Vec<Option<Vec<f64>>>, BeliefError> {
    // Checked as one slot's weights are (see `leave_one_out`).
    let trusted = |tree: &CountTree, all: Vec<Option<Vec<f64>>>| {
        let flushed = all
            .iter()
            .enumerate()
            .any(|(slot, r)| r.as_ref().is_some_and(|r| tree.flushed(prior, slot, r)));
        (!flushed).then_some(all)
    };
    let mut all = tree.all_leave_one_out(prior).and_then(|a| trusted(tree, a));
    for exact in [false, true] {
        if all.is_some() {
            break;
        }
        retilt(tree, counts, prior, exact);
        all = tree.all_leave_one_out(prior).and_then(|a| trusted(tree, a));
    }
    let mut by_live: Vec<Option<Vec<f64>>> = match all {
        Some(by_slot) => by_slot
            .into_iter()
            .enumerate()
            .filter(|(s, _)| !tree.counts(*s).is_empty())
            .map(|(_, r)| r)
            .collect(),
        None => {
            check_eager(tracks)?;
            prior.all_leave_one_out(counts)
        }
    };
    // With k known the components' expected counts must sum to k. Tables
    // and weights that lean 10^100 a track apart (long streams of
    // sightings against the truth) can leave a weight the tree computed
    // with rounding far above its own size where a count vector is huge:
    // not flushed to 0, but wrong. The log-space evaluation is exact there.
    if prior.is_point() && tracks <= EAGER_LIMIT && !counts_sum_to(prior.target(), counts, &by_live)
    {
        tracing::debug!("factored: the count tree's weights missed k; evaluated in log space");
        // Not the eager fast path first: it rounds as the tree does.
        by_live = prior.ln_all(counts);
    }
    // Where every component holds a single count no weight was computed,
    // so nothing above has checked their sum against π.
    if by_live.iter().all(Option::is_none) && !fixed_total_allowed(prior, counts) {
        return Err(BeliefError::Degenerate { normalizer: 0.0 });
    }
    Ok(by_live)
}

/// Whether the components' expected red counts under their weights
/// (`None`: the one count the component holds) sum to `k`.
fn counts_sum_to(k: f64, counts: &[&[f64]], weights: &[Option<Vec<f64>>]) -> bool {
    let mut total = 0.0;
    for (c, r) in counts.iter().zip(weights) {
        total += match r {
            Some(r) => {
                // Taken as the marginals are (`Component::weighted_marginals`):
                // term by term in log space where the component drifted.
                let ln_max = table::drifted(c, r);
                let (mut mass, mut mean) = (0.0, 0.0);
                for (s, (&x, &w)) in c.iter().zip(r).enumerate() {
                    let term = match ln_max {
                        Some(ln_max) if x > 0.0 && w > 0.0 => (x.ln() + w.ln() - ln_max).exp(),
                        Some(_) => 0.0,
                        None => x * w,
                    };
                    mass += term;
                    mean += s as f64 * term;
                }
                if !(mass > 0.0 && mass.is_finite()) {
                    // No mass: a contradiction, which the caller finds.
                    return true;
                }
                mean / mass
            }
            None => held_count(c) as f64,
        };
    }
    (total - k).abs() <= 1e-9 * (1.0 + k)
}

/// The one count a component that holds a single count holds.
fn held_count(counts: &[f64]) -> usize {
    counts.iter().position(|&x| x > 0.0).unwrap_or(0)
}

/// Whether π allows the red count of components that each hold a single
/// count (the sum of those counts).
fn fixed_total_allowed(prior: &CountPrior, counts: &[&[f64]]) -> bool {
    let total: usize = counts.iter().map(|c| held_count(c)).sum();
    prior.ln_weights().get(total).is_some_and(|l| l.is_finite())
}

/// The eager evaluation keeps a convolution per component, O(n²) numbers:
/// past [`EAGER_LIMIT`] tracks a belief the count tree cannot evaluate
/// safely is reported instead.
fn check_eager(tracks: usize) -> Result<(), BeliefError> {
    if tracks <= EAGER_LIMIT {
        return Ok(());
    }
    Err(BeliefError::Numerical {
        step: "factored count coupling",
        detail: format!(
            "the count tree's weights underflow even re-tilted, and the eager \
             evaluation would need O(n²) memory at n = {tracks}"
        ),
    })
}

#[cfg(test)]
mod tests;
