//! The count coupling at the coordinator: every leader's [`CountPart`]s at
//! one cut, convolved with the prior π into the property marginals.
//!
//! [`coupled_marginals`] evaluates it from nothing. A [`CouplingTree`]
//! keeps the count tree between queries, the way the centralized belief
//! keeps its own: between two cuts most components have not changed, so a
//! query sets only the leaves of those that did and refreshes their paths,
//! and a query that finds nothing changed (a deployment at rest, asked
//! again) answers from what it computed last. The tree keeps its tilt as
//! the centralized belief does (re-aimed only when its evaluation is
//! unsafe), so both compute alike; nothing is computed between queries.

use super::{bad, CountPart, MOST_TRACKS};
use crate::error::BeliefError;
use crate::event::Field;
use crate::factored::contradiction::repaired_marginals;
use crate::factored::counts::CountPrior;
use crate::factored::coupling_weights;
use crate::factored::table::{drifted, weighted_sum};
use crate::factored::tree::{balancing_tilt, CountTree};
use std::sync::Arc;

/// The marginals of the factored belief whose components are `parts`
/// (from every leader at one cut): the count coupling with the prior π of
/// `field`, evaluated by the count tree as the centralized belief's query
/// does. The parts must cover every track of the field exactly once.
pub fn coupled_marginals(field: &Field, parts: &[CountPart]) -> Result<Vec<f64>, BeliefError> {
    CouplingTree::new(field.clone())?.marginals(parts.iter())
}

/// The count coupling kept between queries (see the module documentation).
#[derive(Debug)]
pub struct CouplingTree {
    field: Field,
    prior: CountPrior,
    tree: CountTree,
    /// The part in each leaf of `tree` (None: a free leaf).
    leaves: Vec<Option<Arc<CountPart>>>,
    /// The leaf of the part whose first track is t, by t (the parts are
    /// disjoint, so a first track names at most one).
    leaf_of: Vec<Option<usize>>,
    /// Leaves holding no part.
    free: Vec<usize>,
    /// The tree has been tilted at the parts it holds (at the first query).
    aimed: bool,
    /// The last answer, while no leaf has changed since.
    pub(super) last: Option<Vec<f64>>,
    /// Queries the contradiction rule answered.
    repairs: u64,
}

impl CouplingTree {
    /// An empty coupling for `field`: one leaf per track, enough for any
    /// set of components.
    pub fn new(field: Field) -> Result<Self, BeliefError> {
        field.validate()?;
        let prior = CountPrior::new(&field);
        let n = field.tracks;
        Ok(CouplingTree {
            tree: CountTree::new(vec![Vec::new(); n], 0.0, prior.is_point()),
            prior,
            leaves: vec![None; n],
            leaf_of: vec![None; n],
            free: (0..n).rev().collect(),
            aimed: false,
            last: None,
            repairs: 0,
            field,
        })
    }

    pub fn field(&self) -> &Field {
        &self.field
    }

    /// The marginals of the belief whose components are `parts`, which must
    /// cover every track of the field exactly once; only the leaves whose
    /// parts differ from the last query's are recomputed.
    pub fn marginals<'a>(
        &mut self,
        parts: impl Iterator<Item = &'a CountPart> + Clone,
    ) -> Result<Vec<f64>, BeliefError> {
        let shared: Vec<Arc<CountPart>> = parts.map(|p| Arc::new(p.clone())).collect();
        self.marginals_shared(shared.iter())
    }

    /// [`CouplingTree::marginals`] of parts shared with whoever keeps them
    /// (the coordinator keeps each leader's last answer): a part that is
    /// the very one a leaf holds is neither checked nor compared again, so
    /// a query where few components changed costs little more than those.
    pub fn marginals_shared<'a>(
        &mut self,
        parts: impl Iterator<Item = &'a Arc<CountPart>> + Clone,
    ) -> Result<Vec<f64>, BeliefError> {
        self.check_parts(parts.clone())?;
        self.update(parts);
        if let Some(last) = &self.last {
            return Ok(last.clone());
        }
        if !self.aimed {
            let counts = self.leaves.iter().flatten().map(|p| &p.counts[..]);
            let tilt = balancing_tilt(counts, self.prior.target());
            self.tree.retilt(tilt, false);
            self.aimed = true;
        }
        let out = match self.evaluate() {
            Err(BeliefError::Degenerate { .. }) => self.repaired()?,
            done => done?,
        };
        self.last = Some(out.clone());
        Ok(out)
    }

    /// The leaf holding `part` itself (the same shared part), if any.
    fn holding(&self, part: &Arc<CountPart>) -> Option<usize> {
        let leaf = self
            .leaf_of
            .get(*part.tracks.first()? as usize)
            .copied()??;
        let held = self.leaves[leaf].as_ref()?;
        Arc::ptr_eq(held, part).then_some(leaf)
    }

    /// Every part well formed (a part a leaf already holds was checked when
    /// it came), and every track of the field in exactly one.
    fn check_parts<'a>(
        &self,
        parts: impl Iterator<Item = &'a Arc<CountPart>>,
    ) -> Result<(), BeliefError> {
        let n = self.field.tracks;
        let mut seen = vec![false; n];
        for p in parts {
            if self.holding(p).is_none() {
                check_part(&self.field, p)?;
            }
            for &t in &p.tracks {
                if std::mem::replace(&mut seen[t as usize], true) {
                    return Err(bad(format!("track {t} is in two components")));
                }
            }
        }
        if let Some(t) = seen.iter().position(|s| !s) {
            return Err(bad(format!("no component holds track {t}")));
        }
        Ok(())
    }

    /// Puts `parts` in the leaves: a part whose tracks held a leaf keeps it
    /// (set again only if its numbers changed), leaves of parts gone are
    /// freed, new parts take free leaves.
    fn update<'a>(&mut self, parts: impl Iterator<Item = &'a Arc<CountPart>>) {
        let mut kept = vec![false; self.leaves.len()];
        let mut new = Vec::new();
        for p in parts {
            if let Some(leaf) = self.holding(p) {
                kept[leaf] = true;
                continue;
            }
            let held = self.leaf_of[p.tracks[0] as usize]
                .filter(|&leaf| self.leaves[leaf].as_ref().map(|h| &h.tracks) == Some(&p.tracks));
            match held {
                Some(leaf) => {
                    kept[leaf] = true;
                    if self.leaves[leaf].as_deref() != Some(&**p) {
                        self.put(leaf, p.clone());
                    } else {
                        // The same numbers: shared from now on, so the
                        // next query finds it by pointer.
                        self.leaves[leaf] = Some(p.clone());
                    }
                }
                None => new.push(p),
            }
        }
        for (leaf, kept) in kept.into_iter().enumerate() {
            if kept {
                continue;
            }
            if let Some(old) = self.leaves[leaf].take() {
                if self.leaf_of[old.tracks[0] as usize] == Some(leaf) {
                    self.leaf_of[old.tracks[0] as usize] = None;
                }
                self.tree.set(leaf, Vec::new());
                self.last = None;
                self.free.push(leaf);
            }
        }
        for p in new {
            // Parts cover every track once, so there are never more of
            // them than leaves (one per track).
            let Some(leaf) = self.free.pop() else { break };
            self.leaf_of[p.tracks[0] as usize] = Some(leaf);
            self.put(leaf, p.clone());
        }
    }

    fn put(&mut self, leaf: usize, part: Arc<CountPart>) {
        self.tree.set(leaf, part.counts.clone());
        self.leaves[leaf] = Some(part);
        self.last = None;
    }

    /// Queries the contradiction rule answered (see the module of that
    /// name): the parts together admitted no red count π allows.
    pub fn repairs(&self) -> u64 {
        self.repairs
    }

    /// The answer of the contradiction rule, as the centralized belief's
    /// query gives it on the same parts; counted and logged once.
    fn repaired(&mut self) -> Result<Vec<f64>, BeliefError> {
        let parts: Vec<CountPart> = self
            .leaves
            .iter()
            .flatten()
            .map(|p| (**p).clone())
            .collect();
        let out = repaired_marginals(&self.prior, &parts, self.field.tracks)?;
        if self.repairs == 0 {
            tracing::warn!(
                "coordinator: the leaders' components together admit no red count the \
                 prior allows; answered by the contradiction rule (counted as a query \
                 repair; logged once)"
            );
        }
        self.repairs += 1;
        Ok(out)
    }

    /// One downward walk of the tree and each part's marginals.
    fn evaluate(&mut self) -> Result<Vec<f64>, BeliefError> {
        let counts: Vec<&[f64]> = self
            .leaves
            .iter()
            .flatten()
            .map(|p| &p.counts[..])
            .collect();
        let weights = coupling_weights(&mut self.tree, &self.prior, &counts, self.field.tracks)?;
        let mut out = vec![0.0; self.field.tracks];
        let dot = |v: &[f64], r: &[f64]| v.iter().zip(r).map(|(x, y)| x * y).sum::<f64>();
        for (p, r) in self.leaves.iter().flatten().zip(weights) {
            match r {
                Some(r) => {
                    // Sums as the centralized belief's query takes them
                    // (`Component::weighted_marginals`): in log space
                    // where the part and its weights have drifted apart.
                    let ln_max = drifted(&p.counts, &r);
                    let sum = |v: &[f64]| match ln_max {
                        Some(ln_max) => weighted_sum(v, &r, ln_max),
                        None => dot(v, &r),
                    };
                    let total = sum(&p.counts);
                    if total.is_nan() || total <= 0.0 {
                        return Err(BeliefError::Degenerate { normalizer: total });
                    }
                    for (&t, w) in p.tracks.iter().zip(&p.red) {
                        out[t as usize] = (sum(w) / total).clamp(0.0, 1.0);
                    }
                }
                None => {
                    // A single count held: the table's own marginals.
                    let total: f64 = p.counts.iter().sum();
                    if p.counts.iter().filter(|&&x| x > 0.0).count() != 1 || total <= 0.0 {
                        return Err(BeliefError::Degenerate { normalizer: 0.0 });
                    }
                    for (&t, w) in p.tracks.iter().zip(&p.red) {
                        out[t as usize] = (w.iter().sum::<f64>() / total).clamp(0.0, 1.0);
                    }
                }
            }
        }
        Ok(out)
    }
}

/// One part well formed: its numbers and tracks fit the field.
fn check_part(field: &Field, p: &CountPart) -> Result<(), BeliefError> {
    let m = p.tracks.len();
    if m == 0 || m > MOST_TRACKS || p.counts.len() != m + 1 || p.red.len() != m {
        return Err(bad(format!(
            "a part of {m} tracks with {} counts and {} red vectors",
            p.counts.len(),
            p.red.len()
        )));
    }
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite() && *x >= 0.0);
    if !finite(&p.counts) || p.red.iter().any(|w| w.len() != m + 1 || !finite(w)) {
        return Err(bad(format!(
            "a part of tracks {:?} with a weight that is negative, not finite, or \
             a red vector not of {} counts",
            p.tracks,
            m + 1
        )));
    }
    for &t in &p.tracks {
        field.check_track(t)?;
    }
    Ok(())
}
