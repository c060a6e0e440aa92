//! The batches the sensor sent one leader, kept until the leader says its
//! state is safe past them (a [`Durable`] mark), so that a leader that
//! lost some — a gap in the numbers, or the time it was down — gets them
//! again, and a long stream keeps only what may still be asked for.

use idmesh_protocol::wire::leader_to_sensor::Durable;
use idmesh_protocol::wire::sensor_to_leader::Batch;
use std::collections::VecDeque;

#[derive(Debug, Default, serde::Serialize, serde::Deserialize)]
pub(crate) struct BatchLog {
    /// The number of the first batch kept.
    first: u64,
    batches: VecDeque<Batch>,
}

impl BatchLog {
    /// The number the next batch gets.
    pub(crate) fn next_number(&self) -> u64 {
        self.first + self.batches.len() as u64
    }

    pub(crate) fn push(&mut self, batch: Batch) {
        debug_assert_eq!(batch.number, self.next_number());
        self.batches.push_back(batch);
    }

    /// Every batch numbered `from` or later, or why they cannot all be had.
    pub fn from(&self, leader: &str, from: u64) -> Result<Vec<Batch>, String> {
        if from < self.first {
            return Err(format!(
                "{leader} asks for batches from {from}, but it said its state was safe through {} \
                 and those before were dropped",
                self.first
            ));
        }
        let skip = ((from - self.first) as usize).min(self.batches.len());
        Ok(self.batches.range(skip..).cloned().collect())
    }

    /// Drops the batches the leader will never ask for again.
    pub(crate) fn forget(&mut self, mark: &Durable) -> usize {
        let below = mark.batch.min(self.next_number());
        let drop = below.saturating_sub(self.first) as usize;
        self.batches.drain(..drop);
        self.first += drop as u64;
        drop
    }

    pub fn len(&self) -> usize {
        self.batches.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use idmesh_protocol::wire::VERSION;

    fn batch(number: u64) -> Batch {
        Batch {
            version: VERSION,
            epoch: 0,
            sensor: "s".into(),
            number,
            through: number,
            events: number,
            finished: false,
            items: Vec::new(),
        }
    }

    fn mark(batch: u64) -> Durable {
        Durable {
            epoch: 0,
            version: VERSION,
            leader: "l".into(),
            batch,
            position: 0,
        }
    }

    #[test]
    fn keeps_what_may_be_asked_for_and_refuses_what_was_dropped() {
        let mut log = BatchLog::default();
        for n in 0..10 {
            log.push(batch(n));
        }
        assert_eq!(log.forget(&mark(4)), 4);
        assert_eq!(log.len(), 6);
        let again: Vec<u64> = log.from("l", 7).unwrap().iter().map(|b| b.number).collect();
        assert_eq!(again, vec![7, 8, 9]);
        assert!(log.from("l", 3).unwrap_err().contains("safe through 4"));
        // A mark never drops what was not sent yet, and marks going back
        // drop nothing.
        assert_eq!(log.forget(&mark(99)), 6);
        assert_eq!(log.next_number(), 10);
        assert_eq!(log.forget(&mark(2)), 0);
        log.push(batch(10));
        assert_eq!(log.from("l", 10).unwrap().len(), 1);
    }
}
