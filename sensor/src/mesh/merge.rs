//! Every sensor's intake merged into one order: the entry at the lowest
//! [`Position`] goes first, once no sensor can still take one below it
//! (each sensor's watermark has passed it).
//! Every sensor merges the same entries by the same rule, so every sensor
//! gets the same order, whatever the order its peers' slices came in — no
//! sensor sequences another's events. Two entries at one position are one
//! event that two sensors took (one producer, one counter): merged once.

use idmesh_protocol::wire::sensor_to_sensor::{Entry, Position};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct Merge {
    /// Every sensor, in the topology's order.
    sensors: Vec<String>,
    /// Entries received from each and not merged yet.
    queues: Vec<VecDeque<(Position, Entry)>>,
    /// Entries received from each (its intake's numbering).
    received: Vec<u64>,
    watermarks: Vec<Position>,
    finished: Vec<bool>,
    /// The position merged last.
    last: Option<Position>,
    /// Events merged from each sensor's intake.
    merged: Vec<u64>,
    /// Events merged twice (at one position), applied once.
    twice: u64,
}

impl Merge {
    pub(crate) fn new(sensors: &[String]) -> Self {
        let n = sensors.len();
        Merge {
            sensors: sensors.to_vec(),
            queues: (0..n).map(|_| VecDeque::new()).collect(),
            received: vec![0; n],
            watermarks: vec![Position::start(); n],
            finished: vec![false; n],
            last: None,
            merged: vec![0; n],
            twice: 0,
        }
    }

    pub(crate) fn sensors(&self) -> &[String] {
        &self.sensors
    }

    pub fn index(&self, sensor: &str) -> Option<usize> {
        self.sensors.iter().position(|s| s == sensor)
    }

    /// Sensor `i`'s watermark as this merge knows it, and whether it is
    /// finished.
    pub(crate) fn known(&self, i: usize) -> (&Position, bool) {
        (&self.watermarks[i], self.finished[i])
    }

    /// Entries received from sensor `i` so far: where to fetch from.
    pub(crate) fn received(&self, i: usize) -> u64 {
        self.received[i]
    }

    /// Sensor `i`'s entries numbered from `from` on, its watermark and
    /// whether it is finished. Entries received before are skipped (a
    /// slice asked for twice); a slice that starts past the next number is
    /// refused (entries between would be missing). Whether anything new
    /// came.
    pub(crate) fn receive(
        &mut self,
        i: usize,
        from: u64,
        entries: Vec<(Position, Entry)>,
        watermark: Position,
        finished: bool,
    ) -> Result<bool, String> {
        let next = self.received[i];
        if from > next {
            return Err(format!(
                "a slice of {:?} from entry {from}, but entry {next} is the next wanted",
                self.sensors[i]
            ));
        }
        let skip = usize::try_from(next - from).unwrap_or(usize::MAX);
        let mut changed = false;
        for (position, entry) in entries.into_iter().skip(skip) {
            if self.queues[i].back().is_some_and(|(p, _)| position <= *p)
                || self.last.as_ref().is_some_and(|l| position < *l)
            {
                return Err(format!(
                    "{:?} gave entry {} at {position:?}, out of its order",
                    self.sensors[i], self.received[i]
                ));
            }
            self.queues[i].push_back((position, entry));
            self.received[i] += 1;
            changed = true;
        }
        if watermark > self.watermarks[i] {
            self.watermarks[i] = watermark;
            changed = true;
        }
        if finished && !self.finished[i] {
            self.finished[i] = true;
            changed = true;
        }
        Ok(changed)
    }

    /// The next entry of the merged order, and the sensor it came from;
    /// None until some sensor's watermark lets one go.
    pub(crate) fn release(&mut self) -> Option<(usize, Entry)> {
        loop {
            let (i, head) = self
                .queues
                .iter()
                .enumerate()
                .filter_map(|(i, q)| q.front().map(|(p, _)| (i, p)))
                .min_by(|a, b| a.1.cmp(b.1))?;
            // A finished sensor still takes cuts asked of it, so it holds
            // the merge like any other until its watermark has passed
            // (peers move it: `IntakeWanted::above`).
            let held = (0..self.sensors.len()).any(|j| j != i && self.watermarks[j] < *head);
            if held {
                return None;
            }
            let (position, entry) = self.queues[i].pop_front()?;
            if self.last.as_ref() == Some(&position) {
                self.twice += 1;
                continue;
            }
            self.last = Some(position);
            if matches!(entry, Entry::Line(_)) {
                self.merged[i] += 1;
            }
            return Some((i, entry));
        }
    }

    /// Every sensor is finished and everything it took is merged: the
    /// stream is over.
    pub(crate) fn complete(&self) -> bool {
        self.finished.iter().all(|&f| f) && self.queues.iter().all(VecDeque::is_empty)
    }

    /// The sensors the merge waits for: nothing queued, and a watermark
    /// below the lowest entry queued (with nothing queued at all: every
    /// sensor not finished).
    pub(crate) fn waiting_for(&self) -> Vec<String> {
        let lowest = self
            .queues
            .iter()
            .filter_map(|q| q.front().map(|(p, _)| p))
            .min();
        (0..self.sensors.len())
            .filter(|&j| {
                self.queues[j].is_empty()
                    && lowest.map_or(!self.finished[j], |l| self.watermarks[j] < *l)
            })
            .map(|j| self.sensors[j].clone())
            .collect()
    }

    /// Events merged from each sensor, in the topology's order.
    pub(crate) fn merged(&self) -> &[u64] {
        &self.merged
    }

    /// Events merged twice and applied once.
    pub(crate) fn twice(&self) -> u64 {
        self.twice
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn line(time: f64, counter: u64) -> (Position, Entry) {
        (
            Position::event(time, "p", counter),
            Entry::Line(format!("{counter}")),
        )
    }

    fn drain(merge: &mut Merge) -> Vec<String> {
        std::iter::from_fn(|| merge.release())
            .map(|(_, e)| match e {
                Entry::Line(t) => t,
                Entry::Cut { tag, .. } => format!("cut {tag}"),
            })
            .collect()
    }

    #[test]
    fn nothing_passes_a_sensor_whose_watermark_is_behind() {
        let sensors = ["a".to_string(), "b".to_string()];
        let mut merge = Merge::new(&sensors);
        let w = |t: f64| Position::before(t);
        merge
            .receive(0, 0, vec![line(1.0, 0), line(3.0, 2)], w(3.5), false)
            .expect("in order");
        assert!(drain(&mut merge).is_empty());
        assert_eq!(merge.waiting_for(), vec!["b".to_string()]);
        merge
            .receive(1, 0, vec![line(2.0, 1)], w(2.5), false)
            .expect("in order");
        assert_eq!(drain(&mut merge), ["0", "1"]);
        // Finished, b still holds the merge at its watermark ...
        merge.receive(1, 1, vec![], w(2.5), true).expect("in order");
        assert!(drain(&mut merge).is_empty());
        // ... until a peer's request moves it (a finished sensor takes
        // only cuts, and promises none below the asker's watermark).
        merge.receive(1, 1, vec![], w(3.5), true).expect("in order");
        assert_eq!(drain(&mut merge), ["2"]);
        assert!(!merge.complete());
        merge.receive(0, 2, vec![], w(4.0), true).expect("in order");
        assert!(merge.complete());
        assert_eq!(merge.merged(), [2, 1]);
    }

    #[test]
    fn one_event_taken_by_two_sensors_is_merged_once_and_a_gap_is_refused() {
        let sensors = ["a".to_string(), "b".to_string()];
        let mut merge = Merge::new(&sensors);
        let end = Position::before(9.0);
        merge
            .receive(0, 0, vec![line(1.0, 0)], end.clone(), true)
            .expect("in order");
        assert!(merge
            .receive(1, 1, vec![line(1.0, 0)], end.clone(), true)
            .is_err());
        merge
            .receive(1, 0, vec![line(1.0, 0)], end.clone(), true)
            .expect("in order");
        // The same slice again changes nothing.
        assert!(!merge
            .receive(1, 0, vec![line(1.0, 0)], end, true)
            .expect("in order"));
        assert_eq!(drain(&mut merge), ["0"]);
        assert_eq!(merge.twice(), 1);
    }

    proptest! {
        /// Whatever the order and size of the slices each sensor's
        /// entries come in, the merged order is the order of positions.
        #[test]
        fn every_delivery_merges_to_the_order_of_positions(
            owners in proptest::collection::vec(0usize..3, 1..40),
            chunks in proptest::collection::vec((0usize..3, 1usize..5), 1..80),
        ) {
            let sensors: Vec<String> = ["a", "b", "c"].iter().map(|s| s.to_string()).collect();
            let intakes: Vec<Vec<(Position, Entry)>> = (0..3)
                .map(|s| {
                    owners
                        .iter()
                        .enumerate()
                        .filter(|(_, &o)| o == s)
                        .map(|(i, _)| line((i / 2) as f64, i as u64))
                        .collect()
                })
                .collect();
            let mut merge = Merge::new(&sensors);
            let mut sent = [0usize; 3];
            let mut out = Vec::new();
            let deliver = |merge: &mut Merge, s: usize, upto: usize, sent: &mut [usize; 3]| {
                let from = sent[s];
                let all = upto == intakes[s].len();
                // A finished intake's watermark is moved past everything
                // by its peers' requests.
                let watermark = if all {
                    Position::before(1e9)
                } else if upto == 0 {
                    Position::start()
                } else {
                    intakes[s][upto - 1].0.clone()
                };
                merge
                    .receive(s, from as u64, intakes[s][from..upto].to_vec(), watermark, all)
                    .expect("in order");
                sent[s] = upto;
            };
            for (s, n) in chunks {
                let upto = (sent[s] + n).min(intakes[s].len());
                deliver(&mut merge, s, upto, &mut sent);
                out.extend(drain(&mut merge));
            }
            for (s, intake) in intakes.iter().enumerate() {
                deliver(&mut merge, s, intake.len(), &mut sent);
            }
            out.extend(drain(&mut merge));
            prop_assert!(merge.complete());
            let expected: Vec<String> = (0..owners.len()).map(|i| i.to_string()).collect();
            prop_assert_eq!(out, expected);
        }
    }
}
