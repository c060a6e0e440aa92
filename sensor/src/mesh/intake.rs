//! One sensor's intake: the entries it took itself, in the order of their
//! [`Position`]s, numbered from 0, and its watermark — nothing at or below
//! it is taken any more. The other sensors fetch it from a number on
//! (`P/sensor/<name>/intake?from=<i>`); entries every one of them has
//! fetched are forgotten.

use idmesh_protocol::wire::sensor_to_sensor::{Entry, IntakeSlice, Position};
use idmesh_protocol::wire::VERSION;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, VecDeque};

/// The most entries one slice carries.
pub(crate) const SLICE_ENTRIES: usize = 4096;

#[derive(Debug, Serialize, Deserialize)]
pub(crate) struct Intake {
    /// The number of the first entry still kept.
    base: u64,
    entries: VecDeque<(Position, Entry)>,
    watermark: Position,
    finished: bool,
    /// The other sensors, and the highest entry number each has asked
    /// from (absent: not asked yet).
    fetched: BTreeMap<String, Option<u64>>,
}

impl Intake {
    /// An empty intake that the sensors `peers` fetch.
    pub(crate) fn new(peers: &[String]) -> Self {
        Intake {
            base: 0,
            entries: VecDeque::new(),
            watermark: Position::start(),
            finished: false,
            fetched: peers.iter().map(|p| (p.clone(), None)).collect(),
        }
    }

    /// Entries taken so far.
    pub(crate) fn taken(&self) -> u64 {
        self.base + self.entries.len() as u64
    }

    pub(crate) fn watermark(&self) -> &Position {
        &self.watermark
    }

    pub(crate) fn finished(&self) -> bool {
        self.finished
    }

    /// Why an event at `position` cannot be taken, if it cannot.
    pub(crate) fn refuses(&self, position: &Position) -> Option<String> {
        if self.finished {
            return Some("this sensor's intake is finished: it takes no more events".into());
        }
        (*position <= self.watermark).then(|| {
            format!(
                "late: time {} from {:?} (counter {}) is not after this sensor's last position \
                 (time {}, from {:?}, counter {}): a sensor takes each producer's events in \
                 order of time, then counter",
                position.time,
                position.producer,
                position.counter,
                self.watermark.time,
                self.watermark.producer,
                self.watermark.counter
            )
        })
    }

    /// Takes an event (one [`Intake::refuses`] passed).
    pub fn take(&mut self, position: Position, line: String) {
        debug_assert!(self.refuses(&position).is_none());
        self.watermark = position.clone();
        self.entries.push_back((position, Entry::Line(line)));
    }

    /// Takes a cut asked of sensor `sensor`, just after the last position:
    /// its position.
    pub(crate) fn cut(
        &mut self,
        sensor: &str,
        tag: u64,
        rows: bool,
        events: Option<u64>,
    ) -> Position {
        let position = self.watermark.cut_after(sensor);
        self.watermark = position.clone();
        self.entries
            .push_back((position.clone(), Entry::Cut { tag, rows, events }));
        position
    }

    /// A producer will give nothing before `time`: the watermark moves
    /// there if that is ahead. Whether it moved.
    pub(crate) fn tick(&mut self, time: f64) -> bool {
        let to = Position::before(time);
        let ahead = time.is_finite() && to > self.watermark && !self.finished;
        if ahead {
            self.watermark = to;
        }
        ahead
    }

    /// A finished intake moves its watermark to `above`, if that is ahead
    /// (see `IntakeWanted::above`). Whether it moved.
    pub(crate) fn raise(&mut self, above: &Position) -> bool {
        let ahead = self.finished && *above > self.watermark;
        if ahead {
            self.watermark = above.clone();
        }
        ahead
    }

    /// The producers say no more events come.
    pub(crate) fn finish(&mut self) {
        self.finished = true;
    }

    /// The entries from number `from` on (at most [`SLICE_ENTRIES`]), for
    /// sensor `peer`, whose watermark is `above` (a finished intake moves
    /// its own there: see `IntakeWanted`); every entry all peers have
    /// asked past is forgotten. Whether the request changed the intake
    /// (what to journal).
    pub(crate) fn slice(
        &mut self,
        sensor: &str,
        peer: &str,
        from: u64,
        above: &Position,
    ) -> Result<(IntakeSlice, bool), String> {
        if !self.fetched.contains_key(peer) {
            return Err(format!("{peer:?} is not a sensor of this deployment"));
        }
        if from > self.taken() {
            return Err(format!(
                "entry {from} asked for, but this sensor has taken {}",
                self.taken()
            ));
        }
        if from < self.base {
            return Err(format!(
                "entries before {} are forgotten: every sensor asked past them",
                self.base
            ));
        }
        let mut changed = self.raise(above);
        if let Some(asked) = self.fetched.get_mut(peer) {
            changed |= asked.is_none_or(|a| from > a);
            *asked = Some(asked.unwrap_or(0).max(from));
        }
        let skip = (from - self.base) as usize;
        let entries: Vec<_> = self
            .entries
            .iter()
            .skip(skip)
            .take(SLICE_ENTRIES)
            .cloned()
            .collect();
        let all_sent = skip + entries.len() == self.entries.len();
        let slice = IntakeSlice {
            version: VERSION,
            sensor: sensor.to_string(),
            from,
            entries,
            // Only a slice that ends at the last entry can vouch for the
            // watermark: entries between would fall below it.
            watermark: if all_sent {
                self.watermark.clone()
            } else {
                self.entries[skip + SLICE_ENTRIES - 1].0.clone()
            },
            finished: self.finished && all_sent,
        };
        self.forget();
        Ok((slice, changed))
    }

    /// Drops the entries every peer has asked past.
    fn forget(&mut self) {
        let Some(everyone) = self
            .fetched
            .values()
            .copied()
            .collect::<Option<Vec<u64>>>()
            .and_then(|asked| asked.into_iter().min())
        else {
            return;
        };
        while self.base < everyone && self.entries.pop_front().is_some() {
            self.base += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peers() -> Vec<String> {
        vec!["east".into(), "west".into()]
    }

    #[test]
    fn a_late_event_is_refused_and_a_cut_sits_after_the_last_event() {
        let mut intake = Intake::new(&peers());
        intake.take(Position::event(1.0, "cam", 0), "a".into());
        assert!(intake.refuses(&Position::event(0.5, "cam", 1)).is_some());
        assert!(intake.refuses(&Position::event(1.0, "cam", 0)).is_some());
        assert!(intake.refuses(&Position::event(1.0, "cam", 1)).is_none());
        let cut = intake.cut("north", 7, false, None);
        assert!(cut > Position::event(1.0, "cam", 0));
        assert!(cut < Position::event(1.0, "cam", 1));
        assert!(intake.refuses(&Position::event(1.0, "cam", 1)).is_none());
        assert!(intake.tick(2.0));
        assert!(!intake.tick(1.5));
        assert!(intake.refuses(&Position::event(1.9, "cam", 9)).is_some());
        assert!(intake.refuses(&Position::event(2.0, "cam", 9)).is_none());
    }

    #[test]
    fn entries_are_forgotten_once_every_peer_asked_past_them() {
        let mut intake = Intake::new(&peers());
        for i in 0..5 {
            intake.take(Position::event(i as f64, "cam", i), format!("{i}"));
        }
        let (slice, _) = intake
            .slice("north", "east", 3, &Position::start())
            .expect("slice");
        assert_eq!(slice.entries.len(), 2);
        assert_eq!(slice.watermark, Position::event(4.0, "cam", 4));
        // West has not asked yet: nothing is forgotten.
        assert!(intake.slice("north", "east", 0, &Position::start()).is_ok());
        intake
            .slice("north", "west", 2, &Position::start())
            .expect("slice");
        // Both asked from at least 2 (east's highest is 3).
        assert!(intake
            .slice("north", "west", 1, &Position::start())
            .is_err());
        assert!(intake.slice("north", "west", 2, &Position::start()).is_ok());
        assert!(intake
            .slice("north", "south", 2, &Position::start())
            .is_err());
        assert!(intake
            .slice("north", "west", 6, &Position::start())
            .is_err());
    }

    #[test]
    fn a_slice_cut_short_vouches_only_for_its_last_entry() {
        let mut intake = Intake::new(&peers());
        let n = SLICE_ENTRIES as u64 + 3;
        for i in 0..n {
            intake.take(Position::event(i as f64, "cam", i), String::new());
        }
        intake.finish();
        let (first, _) = intake
            .slice("north", "east", 0, &Position::start())
            .expect("slice");
        assert_eq!(first.entries.len(), SLICE_ENTRIES);
        assert!(!first.finished);
        assert_eq!(first.watermark, first.entries[SLICE_ENTRIES - 1].0);
        let (rest, _) = intake
            .slice("north", "east", SLICE_ENTRIES as u64, &Position::start())
            .expect("slice");
        assert_eq!(rest.entries.len(), 3);
        assert!(rest.finished);
    }
}
