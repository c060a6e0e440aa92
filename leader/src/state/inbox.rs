//! The leader's inbox: batches applied in number order (duplicates
//! dropped, a gap held until the missing batch comes), items queued by
//! seq and applied strictly in order, transfers and follow replies
//! waited for where an item needs them.

use super::*;

impl Leader {
    /// A batch of the event stream arrived. Batches are applied in number
    /// order: one seen before is dropped (counted as a duplicate), one
    /// ahead of a missing one waits for it ([`Leader::missing_batches`]
    /// says which to ask the sensor for again).
    pub fn batch(&mut self, batch: Batch, bytes: usize) -> Result<Vec<Action>, LeaderError> {
        self.resting = None;
        if batch.number < self.next_batch || self.ahead.contains_key(&batch.number) {
            self.stats.duplicates += 1;
            return Ok(Vec::new());
        }
        if batch.number > self.next_batch {
            if self.ahead.is_empty() {
                self.stats.gaps += 1;
            }
            self.ahead.insert(batch.number, (batch, bytes));
            return Ok(Vec::new());
        }
        let mut actions = self.take_batch(batch, bytes)?;
        while let Some(entry) = self.ahead.first_entry() {
            if *entry.key() != self.next_batch {
                break;
            }
            let (batch, bytes) = entry.remove();
            // Held before the Begin, it was checked on its own only: a
            // misfit is dropped like a lost batch and asked for again at
            // once (the real one may yet come; waiting for the next gap
            // could wait for ever at the stream's end).
            if let Some(Err(e)) = self.bounds().map(|b| b.check_batch(&batch)) {
                tracing::warn!(leader = %self.name, number = batch.number, error = %e, "batch rejected");
                self.stats.rejected += 1;
                self.refetch = true;
                break;
            }
            actions.extend(self.take_batch(batch, bytes)?);
        }
        Ok(actions)
    }

    /// The sensor that sends this leader its batches, as it names itself
    /// (None before the first).
    pub(crate) fn sensor(&self) -> Option<&str> {
        self.sensor.as_deref()
    }

    /// The first batch number missing before one that arrived, if any.
    pub fn missing_batches(&self) -> Option<u64> {
        (!self.ahead.is_empty() || self.refetch).then_some(self.next_batch)
    }

    /// Applies the next batch in number order.
    pub(super) fn take_batch(
        &mut self,
        batch: Batch,
        bytes: usize,
    ) -> Result<Vec<Action>, LeaderError> {
        self.next_batch += 1;
        self.refetch = false;
        if self.sensor.as_deref() != Some(batch.sensor.as_str()) {
            self.sensor = Some(batch.sensor.clone());
        }
        self.stats.batches += 1;
        self.stats.bytes_received += bytes as u64;
        for Sequenced { seq, item } in batch.items {
            if seq > self.position {
                self.queue.insert(seq, item);
            }
            self.frontier = self.frontier.max(seq);
        }
        self.frontier = self.frontier.max(batch.through);
        self.events = batch.events;
        self.finished = batch.finished;
        self.advance()
    }

    /// Sets from another leader arrived. A leader never passes an item
    /// whose transfer it waits for, so one for an item already passed, or
    /// already here, is a duplicate (a restarted peer resends what it
    /// sent): dropped and counted.
    pub fn transfer(
        &mut self,
        transfer: Transfer,
        bytes: usize,
    ) -> Result<Vec<Action>, LeaderError> {
        self.resting = None;
        let key = (transfer.seq, transfer.from);
        let pending = self.pending.iter().any(|p| (p.seq, p.from) == key);
        if (transfer.seq <= self.position && !pending)
            || self.transfers.contains_key(&key)
            || self.taken.contains(&key)
        {
            self.stats.duplicates += 1;
            return Ok(Vec::new());
        }
        self.stats.transfers_received += 1;
        self.stats.bytes_received += bytes as u64;
        self.transfers
            .insert((transfer.seq, transfer.from), transfer);
        self.pending_checked = false;
        self.advance()
    }

    /// The sensor answered a follow request: the items this leader missed.
    pub fn followed(&mut self, items: Vec<Sequenced>) -> Result<Vec<Action>, LeaderError> {
        self.resting = None;
        let Some(Waiting::Follow { seq }) = self.waiting else {
            return Err(LeaderError::Unexpected("a follow reply nobody asked for"));
        };
        self.asked = None;
        for Sequenced { seq: s, item } in items {
            if s > seq {
                self.queue.insert(s, item);
            }
        }
        self.waiting = None;
        self.finish(seq);
        self.advance()
    }

    /// Applies queued items in seq order until one must wait; then asks
    /// the sensor once to stop routing what the leader no longer needs.
    pub(super) fn advance(&mut self) -> Result<Vec<Action>, LeaderError> {
        let mut actions = self.apply_queued()?;
        self.flush_unfollows(&mut actions)?;
        Ok(actions)
    }

    fn apply_queued(&mut self) -> Result<Vec<Action>, LeaderError> {
        let mut actions = Vec::new();
        loop {
            match self.waiting {
                Some(Waiting::Transfer { seq, from }) => {
                    match self.transfers.remove(&(seq, from)) {
                        Some(transfer) => {
                            self.taken.push((seq, from));
                            self.waiting = None;
                            self.receive_rows(transfer.rows)?;
                            self.receive_sets(seq, transfer.sets, &mut actions)?;
                            self.receive_components(transfer.components)?;
                            self.receive_trees(transfer.trees)?;
                            let new_tracks = self.follow_held()?;
                            if !new_tracks.is_empty() {
                                self.follow(seq, new_tracks, &mut actions)?;
                            }
                            if self.waiting.is_some() {
                                return Ok(actions);
                            }
                            self.finish(seq);
                        }
                        None => return Ok(actions),
                    }
                }
                Some(Waiting::Components {
                    seq,
                    mix,
                    back,
                    partner,
                    handed,
                }) => {
                    // Whoever held them sent them at this item.
                    let mut here: Vec<(u64, u16)> = self
                        .transfers
                        .keys()
                        .filter(|key| key.0 == seq)
                        .copied()
                        .collect();
                    here.sort_unstable();
                    for key in here {
                        if let Some(transfer) = self.transfers.remove(&key) {
                            self.taken.push(key);
                            let row_from = row_from(mix, partner, handed);
                            self.receive_partner_row(mix, row_from, key.1, transfer.rows)?;
                            self.receive_components(transfer.components)?;
                            self.receive_trees(transfer.trees)?;
                        }
                    }
                    if !self.ready_to_mix(mix, row_from(mix, partner, handed))? {
                        return Ok(actions);
                    }
                    self.waiting = None;
                    self.factored_mix_here(seq, mix, back, partner, &mut actions)?;
                    let new_tracks = self.follow_held()?;
                    if !new_tracks.is_empty() {
                        self.follow(seq, new_tracks, &mut actions)?;
                        return Ok(actions);
                    }
                    self.finish(seq);
                }
                Some(Waiting::Follow { .. }) => return Ok(actions),
                None => {}
            }
            self.take_pending()?;
            let Some((&seq, item)) = self.queue.first_key_value() else {
                return Ok(actions);
            };
            if seq > self.frontier || self.needs_pending(item) {
                return Ok(actions);
            }
            let Some(item) = self.queue.remove(&seq) else {
                return Ok(actions);
            };
            let _span = tracing::debug_span!("item", leader = %self.name, seq).entered();
            self.apply(seq, item, &mut actions)?;
            if self.waiting.is_none() {
                self.finish(seq);
            }
        }
    }

    /// The follow request still waiting for the sensor's answer.
    pub fn pending_follow(&self) -> Option<&Follow> {
        self.asked.as_ref()
    }

    /// The item and the peer whose transfer this leader waits for: the
    /// one it is stopped for, or else the first pending one's (not stopped
    /// for yet, but one lost on the way must be asked for again).
    pub fn waiting_for_transfer(&self) -> Option<(u64, u16)> {
        match self.waiting {
            Some(Waiting::Transfer { seq, from }) => Some((seq, from)),
            _ => self.first_pending(),
        }
    }

    /// The item whose components this leader waits for, from whichever
    /// peers hold them (a factored stream), if it is stopped for them.
    pub fn waiting_for_components(&self) -> Option<u64> {
        match self.waiting {
            Some(Waiting::Components { seq, .. }) => Some(seq),
            _ => None,
        }
    }
}

/// Whose row of which track a mix waits for: the partner's of b across
/// two leaders, or the row of the track the mix takes, from its old leader.
pub(super) fn row_from(
    mix: Mix,
    partner: Option<u16>,
    handed: Option<Handed>,
) -> Option<(u16, u32)> {
    partner
        .map(|p| (p, mix.b))
        .or(handed.map(|h| (h.from, h.track)))
}
