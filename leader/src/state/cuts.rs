//! Answers at consistent cuts: the partial sums a leader gives when a
//! `Cut` item reaches it in its stream (kept a while for late queries),
//! or where it rests once it has applied all it was sent.

use super::transfers::to_wire;
use super::*;
use idmesh_protocol::wire::factored::WireCounts;
use std::collections::{HashMap, HashSet};

/// How many recent cuts a leader keeps answers for.
const CUTS_KEPT: usize = 256;

impl Leader {
    /// The cut tagged `tag` (item `seq`, `events` trace events before it)
    /// reached this leader: its partial sums there, kept for late queries.
    pub(super) fn reach_cut(
        &mut self,
        seq: u64,
        tag: u64,
        events: u64,
        rows: bool,
    ) -> Result<Arc<Partial>, LeaderError> {
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
    pub fn cut(&self, tag: u64) -> Option<&Arc<Partial>> {
        self.cuts.iter().find(|p| p.tag == tag)
    }

    /// `answer` told as a change to this leader's answer at the cut tagged
    /// `base` ([`Partial::base`]): the components not in that answer as
    /// they are now, and the first tracks of its components gone. None if
    /// that answer is no longer kept or either is not factored.
    pub fn relative_to(&self, answer: &Partial, base: u64) -> Option<Partial> {
        let before = self.cut(base)?.components.as_ref()?;
        let now = answer.components.as_ref()?;
        let first = |c: &WireCounts| c.tracks.first().copied();
        let kept: HashMap<Option<u32>, &WireCounts> =
            before.iter().map(|c| (first(c), c)).collect();
        let firsts: HashSet<Option<u32>> = now.iter().map(first).collect();
        let changed = now
            .iter()
            .filter(|c| kept.get(&first(c)) != Some(c))
            .cloned()
            .collect();
        let gone = before
            .iter()
            .filter_map(|c| first(c).filter(|t| !firsts.contains(&Some(*t))))
            .collect();
        Some(Partial {
            components: Some(changed),
            base: Some(base),
            gone,
            version: answer.version,
            leader: answer.leader.clone(),
            cut: answer.cut,
            tag: answer.tag,
            events: answer.events,
            finished: answer.finished,
            log_scale: answer.log_scale,
            total: answer.total,
            outside: answer.outside,
            inside: answer.inside.clone(),
            coefficients: answer.coefficients,
            rows: answer.rows.clone(),
        })
    }

    /// The partial sums now, if the leader is at a quiet point: it has
    /// applied every item the sensor sent it and waits for no peer. Leaders
    /// quiet at the same seq together hold the belief at that seq (every
    /// set sent before it has been received), which is how the coordinator
    /// answers a finished stream without placing a cut.
    /// With `rows`, the leader's rows of the information matrix too.
    pub fn quiet(&self, rows: bool) -> Option<Arc<Partial>> {
        if self.waiting.is_some() || !self.queue.is_empty() {
            return None;
        }
        self.partial(self.frontier, 0, self.events, rows)
            .map(Arc::new)
    }

    /// [`Leader::quiet`], kept until an input changes anything.
    pub fn quiet_kept(&mut self, rows: bool) -> Option<Arc<Partial>> {
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
    pub(super) fn partial(&self, cut: u64, tag: u64, events: u64, rows: bool) -> Option<Partial> {
        let started = self.started.as_ref()?;
        let sums = started.share.partial_sums();
        let rows = match (&started.rows, rows) {
            (Some(held), true) => held
                .rows()
                .map(|(track, row)| to_wire(track, row))
                .collect(),
            _ => Vec::new(),
        };
        let components = started.factored.as_ref().map(|held| held.parts());
        let coefficients = match &started.factored {
            Some(held) => held.coefficients() as u64,
            None => sums.coefficients,
        };
        Some(Partial {
            components,
            base: None,
            gone: Vec::new(),
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
        })
    }
}

/// The answers kept, in a snapshot: each as itself (they are shared in
/// memory, never between cuts).
pub(super) mod kept {
    use super::{Arc, Partial, VecDeque};
    use serde::{Deserialize, Deserializer, Serializer};

    pub fn serialize<S: Serializer>(
        cuts: &VecDeque<Arc<Partial>>,
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.collect_seq(cuts.iter().map(|c| &**c))
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<VecDeque<Arc<Partial>>, D::Error> {
        let cuts = Vec::<Partial>::deserialize(d)?;
        Ok(cuts.into_iter().map(Arc::new).collect())
    }
}
