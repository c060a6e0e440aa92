//! Answers at consistent cuts: the partial sums a leader gives when a
//! `Cut` item reaches it in its stream (kept a while for late queries),
//! or where it rests once it has applied all it was sent.

use super::*;
use idmesh_belief::CountPart;
use idmesh_placement::{to_wire_row, to_wire_tree};
use std::sync::OnceLock;

/// How many recent cuts a leader keeps answers for.
const CUTS_KEPT: usize = 256;

/// A leader's answer at a cut or where it rests, as it keeps it: its sums,
/// and on a factored stream its components' parts, each shared with the
/// answers before it where the component did not change. The wire's
/// [`Partial`] is made from it when asked: whole once
/// ([`Answer::whole`]), or as the change since an answer the coordinator
/// keeps ([`Leader::relative_to`]).
#[derive(Debug)]
pub struct Answer {
    /// The sums, without the components (in `parts`).
    pub sums: Partial,
    pub parts: Option<Vec<Arc<CountPart>>>,
    whole: OnceLock<Arc<Partial>>,
}

/// Equal when they say the same: the same sums and the same parts.
impl PartialEq for Answer {
    fn eq(&self, other: &Self) -> bool {
        self.sums == other.sums && self.parts == other.parts
    }
}

impl Answer {
    fn new(sums: Partial, parts: Option<Vec<Arc<CountPart>>>) -> Self {
        Answer {
            sums: Partial {
                components: None,
                ..sums
            },
            parts,
            whole: OnceLock::new(),
        }
    }

    pub(crate) fn tag(&self) -> u64 {
        self.sums.tag
    }

    /// The answer whole, as the wire carries it (made once, then shared).
    pub fn whole(&self) -> Arc<Partial> {
        self.whole
            .get_or_init(|| Arc::new(self.made_whole()))
            .clone()
    }

    /// The same answer from a holder at `epoch`.
    pub(super) fn restamped(&self, epoch: u64) -> Answer {
        Answer::new(
            Partial {
                epoch,
                ..self.sums.clone()
            },
            self.parts.clone(),
        )
    }

    fn made_whole(&self) -> Partial {
        Partial {
            components: self
                .parts
                .as_ref()
                .map(|parts| parts.iter().map(|p| (**p).clone()).collect()),
            ..self.sums.clone()
        }
    }
}

impl Leader {
    /// The cut tagged `tag` (item `seq`, `events` trace events before it)
    /// reached this leader: its partial sums there, kept for late queries.
    pub(super) fn reach_cut(
        &mut self,
        seq: u64,
        tag: u64,
        events: u64,
        rows: bool,
    ) -> Result<Arc<Answer>, LeaderError> {
        // Shared, not copied: the same answer goes to every query for this
        // cut, and a factored leader's holds every component's counts.
        let partial = Arc::new(
            self.partial(seq, tag, events, rows)
                .ok_or(LeaderError::Unexpected("a cut before the stream's Begin"))?,
        );
        if self.cuts.len() == CUTS_KEPT {
            self.cuts.pop_front();
        }
        self.cuts.push_back(partial.clone());
        Ok(partial)
    }

    /// The answer at the cut tagged `tag`, if this leader has passed it
    /// recently.
    pub(crate) fn cut(&self, tag: u64) -> Option<&Arc<Answer>> {
        self.cuts.iter().find(|p| p.tag() == tag)
    }

    /// `answer` told as a change to this leader's answer at the cut tagged
    /// `base` ([`Partial::base`]): the components not in that answer as
    /// they are now, and the first tracks of its components gone. None if
    /// that answer is no longer kept or either is not factored.
    pub(crate) fn relative_to(&self, answer: &Answer, base: u64) -> Option<Partial> {
        let before = self.cut(base)?.parts.as_ref()?;
        let now = answer.parts.as_ref()?;
        let (changed, gone) = changes(before, now);
        Some(Partial {
            components: Some(changed),
            base: Some(base),
            gone,
            ..answer.sums.clone()
        })
    }

    /// The partial sums now, if the leader is at a quiet point: it has
    /// applied every item the sensor sent it and waits for no peer. Leaders
    /// quiet at the same seq together hold the belief at that seq (every
    /// set sent before it has been received), which is how the coordinator
    /// answers a finished stream without placing a cut.
    /// With `rows`, the leader's rows of the information matrix too.
    pub fn quiet(&self, rows: bool) -> Option<Arc<Answer>> {
        if !self.is_quiet() {
            return None;
        }
        self.partial(self.frontier, 0, self.events, rows)
            .map(Arc::new)
    }

    /// Whether the leader is at a quiet point: it has applied every item
    /// it was sent, and waits for no peer (stopped, or with a transfer
    /// pending).
    pub(super) fn is_quiet(&self) -> bool {
        self.waiting.is_none() && self.queue.is_empty() && self.pending.is_empty()
    }

    /// [`Leader::quiet`], kept until an input changes anything.
    pub(crate) fn quiet_kept(&mut self, rows: bool) -> Option<Arc<Answer>> {
        if let Some((kept_rows, answer)) = &self.resting {
            if *kept_rows == rows {
                return Some(answer.clone());
            }
        }
        let answer = self.quiet(rows)?;
        self.resting = Some((rows, answer.clone()));
        Some(answer)
    }

    /// The partial sums of the share as it is (None before the Begin),
    /// with the rows held when `rows` asks for them.
    pub(super) fn partial(&self, cut: u64, tag: u64, events: u64, rows: bool) -> Option<Answer> {
        let started = self.started.as_ref()?;
        let sums = started.share.partial_sums();
        let asked = rows;
        let rows = match (&started.rows, rows) {
            (Some(held), true) => held
                .rows()
                .map(|(track, row)| to_wire_row(track, row))
                .collect(),
            _ => Vec::new(),
        };
        let trees = match &started.trees {
            Some(held) if asked => held.held_trees().into_iter().map(to_wire_tree).collect(),
            _ => Vec::new(),
        };
        let parts = started.factored.as_ref().map(|held| held.shared_parts());
        // Σ 2^|C| over the components: each part's table size.
        let coefficients = match &parts {
            Some(parts) => parts.iter().map(|p| 1u64 << p.tracks.len()).sum(),
            None => sums.coefficients,
        };
        let sums = Partial {
            epoch: self.epoch,
            trees,
            components: None,
            base: None,
            gone: Vec::new(),
            passive: started.passive.iter().copied().collect(),
            version: VERSION,
            leader: self.name.clone(),
            cut,
            tag,
            events,
            finished: self.finished,
            log_scale: sums.log_scale,
            total: sums.total,
            outside: sums.outside,
            inside: sums.inside,
            coefficients,
            rows,
        };
        Some(Answer::new(sums, parts))
    }
}

/// The parts of `now` not in `before` as they are (cloned for the wire),
/// and the first tracks of `before`'s parts that start none in `now`. A
/// share gives its parts in the order of their first tracks, so the two
/// are walked side by side; an unchanged part is the same shared one, so
/// most comparisons are of pointers.
pub(super) fn changes(
    before: &[Arc<CountPart>],
    now: &[Arc<CountPart>],
) -> (Vec<CountPart>, Vec<u32>) {
    let first = |c: &Arc<CountPart>| c.tracks.first().copied().unwrap_or(u32::MAX);
    let ordered = |parts: &[Arc<CountPart>]| parts.windows(2).all(|w| first(&w[0]) <= first(&w[1]));
    if !(ordered(before) && ordered(now)) {
        // Not as a share gives them: put in that order first.
        let sorted = |parts: &[Arc<CountPart>]| {
            let mut parts = parts.to_vec();
            parts.sort_by_key(first);
            parts
        };
        return changes(&sorted(before), &sorted(now));
    }
    let (mut changed, mut gone) = (Vec::new(), Vec::new());
    let (mut i, mut j) = (0, 0);
    loop {
        match (before.get(i), now.get(j)) {
            (Some(b), Some(n)) if first(b) == first(n) => {
                if !(Arc::ptr_eq(b, n) || **b == **n) {
                    changed.push((**n).clone());
                }
                i += 1;
                j += 1;
            }
            (Some(b), Some(n)) if first(b) < first(n) => {
                gone.push(first(b));
                i += 1;
            }
            (Some(b), None) => {
                gone.push(first(b));
                i += 1;
            }
            (_, Some(n)) => {
                changed.push((**n).clone());
                j += 1;
            }
            (None, None) => break,
        }
    }
    (changed, gone)
}

/// The answers kept, in a snapshot: each whole, as the wire carries it
/// (in memory their parts are shared between answers).
pub(super) mod kept {
    use super::{Answer, Arc, Partial, VecDeque};
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    /// An answer written whole: the copy a query already made, or one made
    /// for the snapshot and dropped after it (not kept beside the parts).
    enum Whole<'a> {
        Kept(&'a Partial),
        Made(Box<Partial>),
    }

    impl Serialize for Whole<'_> {
        fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            match self {
                Whole::Kept(p) => p.serialize(s),
                Whole::Made(p) => p.serialize(s),
            }
        }
    }

    pub fn serialize<S: Serializer>(cuts: &VecDeque<Arc<Answer>>, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(cuts.iter().map(|c| match c.whole.get() {
            Some(whole) => Whole::Kept(whole),
            None => Whole::Made(Box::new(c.made_whole())),
        }))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<VecDeque<Arc<Answer>>, D::Error> {
        let cuts = Vec::<Partial>::deserialize(d)?;
        Ok(cuts
            .into_iter()
            .map(|mut p| {
                let parts = p
                    .components
                    .take()
                    .map(|c| c.into_iter().map(Arc::new).collect());
                Arc::new(Answer::new(p, parts))
            })
            .collect())
    }
}
