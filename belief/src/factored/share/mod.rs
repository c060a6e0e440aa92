//! A leader's part of a factored belief, and the count coupling the
//! coordinator evaluates from all the parts at a query.
//!
//! Under [`Coupling::Local`](super::Coupling::Local) nothing a mix or an observation does reads
//! anything beyond the components it touches (module documentation of
//! [`factored`](super)), so the components can be held by different
//! leaders: each applies the events of the components it holds, exactly as
//! the centralized belief does, provided a mix of two components finds both
//! in one place ([`FactoredShare::take`] and [`FactoredShare::put`] move
//! them). The belief is global only through the red count; that coupling is
//! evaluated where the design card puts global work, at the coordinator on
//! demand: each leader gives, per component it holds, the count vector and
//! one red-weight vector per track ([`CountPart`]), and
//! [`coupled_marginals`] convolves them with the prior π by the same code
//! the centralized belief's queries run ([`CouplingTree`] keeps that
//! convolution between queries, so a query redoes only what changed).
//!
//! A share is a whole [`FactoredBelief`] whose components not held here are
//! placeholders: never read (the local coupling reads no other component),
//! replaced when the real component arrives.
//!
//! A share that holds every track (the one leader of a deployment) is the
//! whole belief, and may weigh its splits by all of it
//! ([`Coupling::Coupled`](super::Coupling::Coupled)): then it computes
//! what the centralized belief with that rule computes, step for step.

mod coupling;

pub use coupling::{coupled_marginals, CouplingTree};

use super::table::{counts_of, Component};
use super::{FactoredBelief, FactoredOptions};
use crate::error::BeliefError;
use crate::event::{Field, Mix, Observe};
use crate::filter::PropertyFilter;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

/// The largest component a share accepts from elsewhere (the tables'
/// own limit, [`super::MAX_COMPONENT_LIMIT`]).
const MOST_TRACKS: usize = super::MAX_COMPONENT_LIMIT;

/// What a share of part of the belief cannot run.
const PART_COUPLED: &str =
    "a split weighed by the whole belief (the coupled rule) on a share of part of it";

/// One component as it moves between leaders: its table over the subsets
/// of `tracks` (bit i ↔ `tracks[i]`), the table's log scale, and when each
/// track last mixed (for [`SplitRule::Recent`](super::SplitRule::Recent):
/// only the order of these clocks matters).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HeldComponent {
    pub tracks: Vec<u32>,
    pub table: Vec<f64>,
    pub log_scale: f64,
    pub last_mix: Vec<u64>,
}

/// What one component tells the coordinator at a cut: its count vector
/// c[s] = Σ_{|y| = s} g(y) and, per track, w_t[s] = Σ_{|y| = s, t ∈ y} g(y).
/// P(t red) = Σ_s w_t[s]·R(s) / Σ_s c[s]·R(s), R the weight of the
/// component's red count from everything else. The wire's own type: a
/// leader sends what its share gives, and the coordinator couples what it
/// receives, without a copy.
pub type CountPart = idmesh_protocol::wire::factored::WireCounts;

/// The components one leader holds (see the module documentation).
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(try_from = "ShareForm", into = "ShareForm")]
pub struct FactoredShare {
    belief: FactoredBelief,
    held: Vec<bool>,
    /// The tracks held, in order: what a leader reads per transfer and per
    /// query is what it holds (about n/L tracks), never the whole field,
    /// or every leader would pay for all n tracks and L leaders would do
    /// L times the work of one.
    held_set: BTreeSet<u32>,
    /// The tracks of the components held here that changed since the last
    /// [`FactoredShare::take_changed`] (made, merged, split, relabelled,
    /// brought in): all a leader must look at to find the components left
    /// without its tracks, rather than all it holds at every handover.
    changed: Changed,
    /// Each held component's part as last given, by first track, and the
    /// tracks whose component changed since ([`FactoredShare::shared_parts`]).
    parts_given: PartsGiven,
}

/// A set of tracks with O(1) insertion, drained whole.
#[derive(Debug, Clone, Default)]
struct Changed {
    flagged: Vec<bool>,
    tracks: Vec<u32>,
}

impl Changed {
    fn new(n: usize) -> Self {
        Changed {
            flagged: vec![false; n],
            tracks: Vec::new(),
        }
    }

    fn insert(&mut self, track: u32) {
        if !std::mem::replace(&mut self.flagged[track as usize], true) {
            self.tracks.push(track);
        }
    }

    fn drain(&mut self) -> Vec<u32> {
        let tracks = std::mem::take(&mut self.tracks);
        for &t in &tracks {
            self.flagged[t as usize] = false;
        }
        tracks
    }
}

/// The parts a share last gave out, by the first track of their
/// component, and the tracks whose component changed (or stopped or
/// started being held) since: the next answer recomputes only the parts
/// starting at those, and gives every other one as the very same shared
/// part, so consecutive answers are compared by pointer. An answer at a
/// cut thus costs what changed since the last, not what is held: before,
/// every held component's table was compared with the one its part was made
/// from, and on the 10,000-target crowd that was most of a leader's work
/// during a stream queried every few milliseconds.
#[derive(Debug, Default)]
struct PartsGiven(std::sync::Mutex<Given>);

#[derive(Debug, Clone, Default)]
struct Given {
    parts: BTreeMap<u32, Arc<CountPart>>,
    /// Tracks whose component changed since `parts` was brought up to
    /// date: every track of a component before a change flags it, so the
    /// first tracks of the components gone and of those made are all here.
    changed: Changed,
}

impl Clone for PartsGiven {
    fn clone(&self) -> Self {
        PartsGiven(std::sync::Mutex::new(self.lock().clone()))
    }
}

impl PartsGiven {
    /// None given yet, and every track of `changed` to look at first.
    fn new(changed: Changed) -> Self {
        PartsGiven(std::sync::Mutex::new(Given {
            parts: BTreeMap::new(),
            changed,
        }))
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Given> {
        // Only ever filled with whole entries: a panic cannot leave one
        // half-written.
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The component of `track` changed, or its holding did.
    fn flag(&mut self, track: u32) {
        self.0
            .get_mut()
            .unwrap_or_else(|e| e.into_inner())
            .changed
            .insert(track);
    }
}

/// A share as a snapshot writes it: the field, the options and the
/// components held (placeholders are rebuilt).
#[derive(Serialize, Deserialize)]
struct ShareForm {
    field: Field,
    options: FactoredOptions,
    components: Vec<HeldComponent>,
}

impl From<FactoredShare> for ShareForm {
    fn from(share: FactoredShare) -> Self {
        ShareForm {
            components: share.components(),
            field: share.belief.field.clone(),
            options: share.belief.options.clone(),
        }
    }
}

impl TryFrom<ShareForm> for FactoredShare {
    type Error = BeliefError;
    fn try_from(form: ShareForm) -> Result<Self, BeliefError> {
        let n = form.field.tracks;
        let mut share = FactoredShare::start_holding(form.field, form.options, vec![false; n])?;
        share.put(form.components)?;
        share.check_whole()?;
        Ok(share)
    }
}

impl FactoredShare {
    /// The start belief's components of the tracks `held` says are this
    /// leader's (every track starts alone). The options must use no
    /// `max_numbers`, which would need the whole belief, and a local
    /// coupling unless this share holds every track: the one holder of
    /// the whole belief (a deployment of one leader) weighs its splits by
    /// all of it, as `idmesh replay` does ([`Coupling::Coupled`](super::Coupling::Coupled)), and so
    /// gives no component away.
    pub fn start(
        field: Field,
        options: FactoredOptions,
        held: impl Fn(u32) -> bool,
    ) -> Result<Self, BeliefError> {
        let n = field.tracks;
        let held: Vec<bool> = (0..n as u32).map(held).collect();
        if !options.coupling.is_local() && held.contains(&false) {
            return Err(unsupported(PART_COUPLED));
        }
        Self::start_holding(field, options, held)
    }

    fn start_holding(
        field: Field,
        options: FactoredOptions,
        held: Vec<bool>,
    ) -> Result<Self, BeliefError> {
        if options.max_numbers.is_some() {
            return Err(unsupported(
                "a limit on the numbers of all components together",
            ));
        }
        let n = field.tracks;
        let mut belief = FactoredBelief::with_options(field, options)?;
        if belief.options.coupling.is_local() {
            // Its components are coupled at the coordinator, never here.
            belief.leave_tree();
        }
        let held_set: BTreeSet<u32> = (0..n as u32).filter(|&t| held[t as usize]).collect();
        // Nothing is known of the components yet: the first look reads all.
        let mut changed = Changed::new(n);
        for &t in &held_set {
            changed.insert(t);
        }
        Ok(FactoredShare {
            belief,
            parts_given: PartsGiven::new(changed.clone()),
            held_set,
            held,
            changed,
        })
    }

    pub fn field(&self) -> &Field {
        &self.belief.field
    }

    /// Whether the component of `track` is held here.
    pub fn holds(&self, track: u32) -> bool {
        self.held.get(track as usize).copied().unwrap_or(false)
    }

    /// The tracks of the component of `track` (held here or not: a
    /// placeholder's are stale).
    pub fn component_of(&self, track: u32) -> Vec<u32> {
        let (slot, _) = self.belief.home[track as usize];
        self.belief.comp(slot).tracks.clone()
    }

    /// The tracks whose components are held here, in order.
    pub fn held_tracks(&self) -> impl Iterator<Item = u32> + '_ {
        self.held_set.iter().copied()
    }

    /// Tracks whose components are held here.
    #[cfg(test)]
    pub(crate) fn tracks_held(&self) -> usize {
        self.held_set.len()
    }

    fn set_held(&mut self, track: u32, held: bool) {
        self.parts_given.flag(track);
        self.held[track as usize] = held;
        match held {
            true => self.held_set.insert(track),
            false => self.held_set.remove(&track),
        };
    }

    /// Σ 2^|C| over the components held.
    pub fn coefficients(&self) -> usize {
        self.held_comps().map(|c| c.table.len()).sum()
    }

    /// The centralized belief's counters as far as this share ran them.
    pub fn stats(&self) -> &super::FactoredStats {
        self.belief.stats()
    }

    /// The components held here, each once (at its first track), in the
    /// order of their first tracks' positions among the held tracks.
    fn held_comps(&self) -> impl Iterator<Item = &Component> {
        self.held_set.iter().filter_map(|&t| {
            let c = self.belief.comp(self.belief.home[t as usize].0);
            (c.tracks.first() == Some(&t)).then_some(c)
        })
    }

    /// Mix `mix`, the `when`-th item of the stream (any clock that grows
    /// along the stream: only the order of the clocks matters to the
    /// Recent split). A certain swap relabels whichever of the two
    /// components are held here; any other mix needs both held here.
    pub fn mix(&mut self, mix: Mix, when: u64) -> Result<(), BeliefError> {
        self.mix_with(mix, when, true)
    }

    /// [`FactoredShare::mix`] with [`FactoredBelief::mix_apart`]: the
    /// regional rule's mix of tracks in two leaders' regions.
    pub fn mix_apart(&mut self, mix: Mix, when: u64) -> Result<(), BeliefError> {
        self.mix_with(mix, when, false)
    }

    /// [`FactoredBelief::split_off`] on a component held here (the regional
    /// rule's handover); nothing for a track whose component is elsewhere.
    pub fn split_off(&mut self, track: u32) -> Result<(), BeliefError> {
        if !self.holds(track) {
            return Ok(());
        }
        // Its pieces are made of the tracks it has now.
        self.note_changed(track);
        self.belief.split_off(track)
    }

    /// The component of `track`, if held here, changes (or changed).
    fn note_changed(&mut self, track: u32) {
        if self.holds(track) {
            let (slot, _) = self.belief.home[track as usize];
            for &t in &self.belief.comp(slot).tracks {
                self.changed.insert(t);
                self.parts_given.flag(t);
            }
        }
    }

    fn mix_with(&mut self, mix: Mix, when: u64, may_merge: bool) -> Result<(), BeliefError> {
        self.belief.field.check_mix(&mix)?;
        self.check_whole()?;
        let (a, b) = (mix.a as usize, mix.b as usize);
        if mix.swap != 1.0 && mix.swap != 0.0 && !(self.held[a] && self.held[b]) {
            return Err(BeliefError::BadComponent {
                detail: format!(
                    "a mix of tracks {} and {} on a leader that does not hold both",
                    mix.a, mix.b
                ),
            });
        }
        // A merge, and any split after it, makes its components of the
        // tracks these hold now.
        self.note_changed(mix.a);
        self.note_changed(mix.b);
        self.belief.mix_with(mix, may_merge)?;
        if mix.swap == 1.0 {
            if self.held[a] != self.held[b] {
                let (ha, hb) = (self.held[a], self.held[b]);
                self.set_held(mix.a, hb);
                self.set_held(mix.b, ha);
            }
            // A relabel brings a track into a component held here.
            self.note_changed(mix.a);
            self.note_changed(mix.b);
        }
        if mix.swap != 0.0 {
            self.belief.last_mix[a] = when;
            self.belief.last_mix[b] = when;
        }
        Ok(())
    }

    /// Takes in the start component of `track`, which no item has touched
    /// yet and no leader held (a deployment's newcomer, adopted at its
    /// first item: docs/design/architecture.md, "Newcomers"). Nobody sends
    /// it: an untouched track is alone with its start table, and so is its
    /// placeholder here, which only this share's own events could change.
    pub fn adopt(&mut self, track: u32) -> Result<(), BeliefError> {
        self.belief.field.check_track(track)?;
        if self.holds(track) {
            return Err(bad(format!("track {track}, whose component is held here")));
        }
        let (slot, _) = self.belief.home[track as usize];
        if self.belief.comp(slot).tracks != [track] {
            return Err(bad(format!(
                "track {track} to adopt is not alone: it has met another track"
            )));
        }
        self.set_held(track, true);
        self.changed.insert(track);
        Ok(())
    }

    /// Drops the start component of `track`, kept here for a track no
    /// leader surveilled and adopted elsewhere since (a keeper's passive
    /// component, [`FactoredShare::adopt`]). Refused for a track that met
    /// another here.
    pub fn drop_start(&mut self, track: u32) -> Result<(), BeliefError> {
        let (slot, _) = self.belief.home[track as usize];
        if !self.holds(track) || self.belief.comp(slot).tracks != [track] {
            return Err(bad(format!(
                "track {track} is not held here alone, as a start component is"
            )));
        }
        self.set_held(track, false);
        Ok(())
    }

    /// An observation of a track whose component is held here.
    pub fn observe(&mut self, observe: Observe) -> Result<(), BeliefError> {
        self.belief.field.check_observe(&observe)?;
        if !self.held[observe.track as usize] {
            return Err(BeliefError::BadComponent {
                detail: format!(
                    "an observation of track {} on a leader that does not hold it",
                    observe.track
                ),
            });
        }
        self.check_whole()?;
        // Tracks it makes certain split off its component.
        self.note_changed(observe.track);
        self.belief.observe(observe)
    }

    /// A share whose splits are weighed by the whole belief must hold all
    /// of it: a placeholder would weigh as if it were the component.
    fn check_whole(&self) -> Result<(), BeliefError> {
        if self.belief.options.coupling.is_local() || self.held_set.len() == self.held.len() {
            return Ok(());
        }
        Err(unsupported(PART_COUPLED))
    }

    /// Takes out the components held here whose tracks `pick` chooses
    /// (their slots stay as placeholders).
    pub fn take(&mut self, mut pick: impl FnMut(&[u32]) -> bool) -> Vec<HeldComponent> {
        let chosen: Vec<HeldComponent> = self
            .held_comps()
            .filter(|c| pick(&c.tracks))
            .map(|c| self.held_form(c))
            .collect();
        self.let_go(chosen)
    }

    /// [`FactoredShare::take`] among the components of `tracks` only (the
    /// ones a mix or a relabel touches): reads those, not all held here.
    pub fn take_of(
        &mut self,
        tracks: &[u32],
        mut pick: impl FnMut(&[u32]) -> bool,
    ) -> Vec<HeldComponent> {
        let mut slots: Vec<usize> = tracks
            .iter()
            .filter(|&&t| self.holds(t))
            .map(|&t| self.belief.home[t as usize].0)
            .collect();
        slots.sort_unstable();
        slots.dedup();
        let chosen: Vec<HeldComponent> = slots
            .into_iter()
            .map(|slot| self.belief.comp(slot))
            .filter(|c| pick(&c.tracks))
            .map(|c| self.held_form(c))
            .collect();
        self.let_go(chosen)
    }

    /// [`FactoredShare::take`] among the components that changed since the
    /// last call and those of `released`, the tracks whose standing with
    /// the caller changed meanwhile. Gives what `take(pick)` gives, reading
    /// only those, for a `pick` that depends on a component's tracks and on
    /// what the caller knows of each track, provided `pick` refused every
    /// component the last call left held, and what the caller knows changed
    /// only for `released`: a component neither changed nor of a released
    /// track is the one `pick` refused then. The first call reads every
    /// component held.
    pub fn take_changed(
        &mut self,
        released: &[u32],
        pick: impl FnMut(&[u32]) -> bool,
    ) -> Vec<HeldComponent> {
        let mut tracks = self.changed.drain();
        tracks.extend_from_slice(released);
        let mut taken = self.take_of(&tracks, pick);
        // In `take`'s order: by the tracks the components are found at.
        taken.sort_unstable_by_key(|c| c.tracks[0]);
        taken
    }

    /// `taken` are no longer held here.
    fn let_go(&mut self, taken: Vec<HeldComponent>) -> Vec<HeldComponent> {
        for c in &taken {
            for &t in &c.tracks {
                self.set_held(t, false);
            }
        }
        taken
    }

    /// The components held here, as they would move.
    pub(crate) fn components(&self) -> Vec<HeldComponent> {
        self.held_comps().map(|c| self.held_form(c)).collect()
    }

    fn held_form(&self, c: &Component) -> HeldComponent {
        HeldComponent {
            tracks: c.tracks.clone(),
            table: c.table.clone(),
            log_scale: c.log_scale,
            last_mix: c
                .tracks
                .iter()
                .map(|&t| self.belief.last_mix[t as usize])
                .collect(),
        }
    }

    /// Components from another leader: checked, then each replaces the
    /// placeholders of its tracks (their other tracks become placeholders
    /// of their own). None of their tracks may be held here already.
    pub fn put(&mut self, components: Vec<HeldComponent>) -> Result<(), BeliefError> {
        for c in &components {
            self.check(c)?;
        }
        let mut coming: Vec<u32> = components.iter().flat_map(|c| c.tracks.clone()).collect();
        coming.sort_unstable();
        if let Some(w) = coming.windows(2).find(|w| w[0] == w[1]) {
            return Err(bad(format!("track {} comes in two components", w[0])));
        }
        for c in components {
            let mut slots: Vec<usize> = c
                .tracks
                .iter()
                .map(|&t| self.belief.home[t as usize].0)
                .collect();
            slots.sort_unstable();
            slots.dedup();
            let mut add: Vec<Component> = slots
                .iter()
                .flat_map(|&s| self.belief.comp(s).tracks.clone())
                .filter(|t| !c.tracks.contains(t))
                .map(|t| Component::singleton(t, 1.0, 1.0))
                .collect();
            for (&t, &when) in c.tracks.iter().zip(&c.last_mix) {
                self.set_held(t, true);
                self.changed.insert(t);
                self.belief.last_mix[t as usize] = when;
            }
            // Built as it was sent (no renormalizing): the receiver holds
            // bit for bit what the sender held.
            let counts = counts_of(&c.table, c.tracks.len());
            add.push(Component {
                tracks: c.tracks,
                table: c.table,
                log_scale: c.log_scale,
                counts,
            });
            self.belief.replace(&slots, add);
        }
        Ok(())
    }

    fn check(&self, c: &HeldComponent) -> Result<(), BeliefError> {
        let m = c.tracks.len();
        if m == 0 || m > MOST_TRACKS {
            return Err(bad(format!(
                "a component of {m} tracks (1..={MOST_TRACKS})"
            )));
        }
        if c.table.len() != 1 << m || c.last_mix.len() != m {
            return Err(bad(format!(
                "a component of {m} tracks with {} numbers and {} clocks",
                c.table.len(),
                c.last_mix.len()
            )));
        }
        for &t in &c.tracks {
            self.belief.field.check_track(t)?;
            if self.held[t as usize] {
                return Err(bad(format!("track {t}, whose component is held here")));
            }
        }
        let mut sorted = c.tracks.clone();
        sorted.sort_unstable();
        if sorted.windows(2).any(|w| w[0] == w[1]) {
            return Err(bad(format!(
                "a component with a track twice: {:?}",
                c.tracks
            )));
        }
        let total: f64 = c.table.iter().sum();
        if c.table.iter().any(|g| !(g.is_finite() && *g >= 0.0)) || total <= 0.0 {
            return Err(bad(format!(
                "a table with a negative, infinite or NaN weight, or none (tracks {:?})",
                c.tracks
            )));
        }
        if !c.log_scale.is_finite() {
            return Err(bad(format!("a log scale of {}", c.log_scale)));
        }
        Ok(())
    }

    /// Per component held here, its count vector and per-track red-weight
    /// vectors (what the coordinator couples at a query).
    pub fn parts(&self) -> Vec<CountPart> {
        self.held_comps().map(count_part).collect()
    }

    /// [`FactoredShare::parts`], each shared: a component unchanged since
    /// the last call (same tracks, same table) gives the same part, so
    /// only the parts of components that changed are computed, and two
    /// answers are compared by pointer where they agree.
    pub fn shared_parts(&self) -> Vec<Arc<CountPart>> {
        let mut given = self.parts_given.lock();
        let given = &mut *given;
        for t in given.changed.drain() {
            given.parts.remove(&t);
            if !self.holds(t) {
                continue;
            }
            let c = self.belief.comp(self.belief.home[t as usize].0);
            if c.tracks.first() == Some(&t) {
                given.parts.insert(t, Arc::new(count_part(c)));
            }
        }
        given.parts.values().cloned().collect()
    }
}

fn bad(detail: String) -> BeliefError {
    BeliefError::BadComponent { detail }
}

fn unsupported(what: &'static str) -> BeliefError {
    BeliefError::Unsupported {
        method: "a leader's factored belief",
        what,
    }
}

/// The [`CountPart`] of one component.
pub(super) fn count_part(c: &Component) -> CountPart {
    CountPart {
        tracks: c.tracks.clone(),
        counts: c.counts.clone(),
        red: c.red_by_count(),
    }
}

#[cfg(test)]
mod tests;
