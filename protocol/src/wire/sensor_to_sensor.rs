//! Several sensors, one order: what sensors tell one another
//! (`P/sensor/<name>/intake`, a get carrying an [`IntakeWanted`]).
//!
//! Each sensor of a deployment with several takes events for its part of
//! the field (its producers, its standard input) into its own *intake*:
//! a list of entries, each at a [`Position`] — the event's time, then the
//! producer's id and counter — that only grows, and a watermark below
//! which it will take nothing more. Every sensor pulls every other's
//! intake and merges them all by position, the lowest first, once every
//! sensor's watermark has passed it. The merged order is the same at every
//! sensor with no sensor ordering anyone else's events: each routes the
//! merged stream through the same router (the same seqs, owners and
//! interests) and sends the batches of its own leaders
//! (docs/design/architecture.md, "Several sensors").
//!
//! What the intake's messages must be ([`Valid`]) sits below the types.

use super::versioned;
use super::Valid;
use serde::{Deserialize, Serialize};
use std::cmp::Ordering;

/// Where an intake entry sits in the order every sensor merges to: by
/// `time`, then `producer`, then `counter` — an event's own — then `sub`
/// and `sensor`, which only a cut has: a cut asked of a sensor sits just
/// after the last entry it took, at the next `sub`, under the sensor's
/// name. A trace fed by one producer in its own order is merged back into
/// that order, and an event two sensors both took (one producer, one
/// counter) sits at one position, so it is merged once.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Position {
    pub time: f64,
    pub producer: String,
    pub counter: u64,
    pub sub: u32,
    pub sensor: String,
}

impl Position {
    /// An event's position.
    pub fn event(time: f64, producer: &str, counter: u64) -> Self {
        Position {
            time,
            producer: producer.to_string(),
            counter,
            sub: 0,
            sensor: String::new(),
        }
    }

    /// Before every event at `time` or later (a watermark moved to a
    /// time: producers' ids are never empty).
    pub fn before(time: f64) -> Self {
        Position::event(time, "", 0)
    }

    /// The first position of the order (a watermark with nothing taken).
    pub fn start() -> Self {
        Position::before(f64::NEG_INFINITY)
    }

    /// A cut asked of `sensor` just after this position.
    pub fn cut_after(&self, sensor: &str) -> Self {
        Position {
            sub: self.sub.saturating_add(1),
            sensor: sensor.to_string(),
            ..self.clone()
        }
    }
}

impl Eq for Position {}

impl PartialOrd for Position {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Position {
    fn cmp(&self, other: &Self) -> Ordering {
        self.time
            .total_cmp(&other.time)
            .then_with(|| self.producer.cmp(&other.producer))
            .then_with(|| self.counter.cmp(&other.counter))
            .then_with(|| self.sub.cmp(&other.sub))
            .then_with(|| self.sensor.cmp(&other.sensor))
    }
}

/// What an intake entry holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Entry {
    /// An event line of the trace format (its JSON text).
    Line(String),
    /// A cut the coordinator asked this sensor for: placed where the
    /// first entry with its tag is merged ([`Entry::Cut::events`]: or,
    /// later, where the merged stream reaches that many events).
    Cut {
        tag: u64,
        rows: bool,
        events: Option<u64>,
    },
}

/// A slice of a sensor's intake, from entry `from` on (the reply to
/// an [`IntakeWanted`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntakeSlice {
    pub version: u16,
    pub sensor: String,
    /// The number of the first entry (entries are numbered from 0).
    pub from: u64,
    pub entries: Vec<(Position, Entry)>,
    /// The sensor takes nothing at or below this from now on.
    pub watermark: Position,
    /// The sensor takes no more events at all (its producers said so):
    /// the entries here are the last it has.
    pub finished: bool,
}
versioned!(IntakeSlice, "intake slice");

/// A sensor's request for another's intake (the get's payload).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct IntakeWanted {
    pub version: u16,
    /// Who asks.
    pub sensor: String,
    /// The number of the first entry wanted.
    pub from: u64,
    /// The asker's own watermark. A finished sensor takes no more events,
    /// only cuts asked of it, so it can promise to take nothing at or
    /// below this either, and moves its watermark there: cuts asked of the
    /// asker are merged without waiting for one asked of it.
    pub above: Position,
    /// What the asker knows of this sensor: its watermark and whether it
    /// is finished. A request with nothing new to answer (no entry past
    /// `from`, and these unchanged) is held until something is, or a
    /// while has passed: one request waits at the peer instead of many
    /// polling it.
    pub known: Position,
    pub known_finished: bool,
}
versioned!(IntakeWanted, "intake request");

impl Valid for IntakeWanted {
    fn problem(&self) -> Option<String> {
        if self.sensor.is_empty() {
            return Some("no sensor named".into());
        }
        self.above
            .time
            .is_nan()
            .then(|| "the watermark's time is not a number".to_string())
    }
}

impl Valid for IntakeSlice {
    fn problem(&self) -> Option<String> {
        let mut previous: Option<&Position> = None;
        for (i, (position, entry)) in self.entries.iter().enumerate() {
            let cut = matches!(entry, Entry::Cut { .. });
            if position.time.is_nan() || (!cut && position.time.is_infinite()) {
                return Some(format!(
                    "entry {i}: time {} is not a finite number",
                    position.time
                ));
            }
            if cut == (position.sub == 0 || position.sensor.is_empty()) {
                return Some(format!(
                    "entry {i}: a position {position:?} of the wrong kind"
                ));
            }
            if !cut && position.producer.is_empty() {
                return Some(format!("entry {i}: no producer"));
            }
            if previous.is_some_and(|p| position <= p) {
                return Some(format!("entry {i}: position {position:?} out of order"));
            }
            if *position > self.watermark {
                return Some(format!(
                    "entry {i}: position {position:?} past the watermark"
                ));
            }
            if let Entry::Line(text) = entry {
                if text.len() > 1 << 16 {
                    return Some(format!("entry {i}: a line of {} bytes", text.len()));
                }
            }
            previous = Some(position);
        }
        self.watermark
            .time
            .is_nan()
            .then(|| "the watermark's time is not a number".to_string())
    }
}
