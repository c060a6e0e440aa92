//! The trace lines of a generated trace's events, with the identity part
//! (see [`super::identity`]) woven in: `identify` lines placed by time
//! (within one step after the mixes and observations, before the moves and
//! the truth), and every `truth` line given the identity on each track,
//! which starts at the initial identities and follows every mix that
//! really exchanged its targets (the `exchanged` ground truth). Without an
//! identity part the lines are exactly [`event_line`] of every event.

use super::identity::{IdentityRead, IdentityTrace};
use super::trace::GeneratedTrace;
use super::trace_out::event_line;
use crate::events::{SimEvent, TimedEvent};
use idmesh_protocol::trace::{Identify, Line};
use std::iter::Peekable;
use std::slice::Iter;

/// Where reads go among the events of their step: after moves (0), mixes
/// (1) and observations (2), before truth (4).
const READ_RANK: u8 = 3;

fn rank(event: &SimEvent) -> u8 {
    match event {
        SimEvent::Move { .. } => 0,
        SimEvent::Mix { .. } => 1,
        SimEvent::Observe { .. } => 2,
        SimEvent::Truth { .. } => 4,
    }
}

/// The `identify` line of a read.
pub(crate) fn identify_line(read: &IdentityRead, accuracy: f64) -> Line {
    Line::Identify(Identify {
        time: read.time,
        track: read.track,
        identity: read.identity,
        accuracy,
    })
}

/// The identity on every track after each event, replayed from the
/// initial identities and the exchanges.
struct IdentityState<'a> {
    accuracy: f64,
    current: Vec<u32>,
    reads: Peekable<Iter<'a, IdentityRead>>,
}

/// Iterator over the non-header lines of a generated trace.
pub(crate) struct EventLines<'a> {
    events: Peekable<Iter<'a, TimedEvent>>,
    identity: Option<IdentityState<'a>>,
}

impl<'a> EventLines<'a> {
    pub(crate) fn new(trace: &'a GeneratedTrace) -> Self {
        EventLines {
            events: trace.events.iter().peekable(),
            identity: trace
                .identity
                .as_ref()
                .map(|id: &'a IdentityTrace| IdentityState {
                    accuracy: id.accuracy,
                    current: id.initial.clone(),
                    reads: id.reads.iter().peekable(),
                }),
        }
    }
}

impl Iterator for EventLines<'_> {
    type Item = Line;

    fn next(&mut self) -> Option<Line> {
        if let Some(id) = &mut self.identity {
            if let Some(read) = id.reads.peek() {
                let read_first = match self.events.peek() {
                    None => true,
                    Some(e) => {
                        read.time < e.time || (read.time == e.time && READ_RANK < rank(&e.event))
                    }
                };
                if read_first {
                    let read = id.reads.next().expect("peeked");
                    return Some(identify_line(read, id.accuracy));
                }
            }
        }
        let event = self.events.next()?;
        let mut line = event_line(event);
        if let Some(id) = &mut self.identity {
            match (&event.event, &mut line) {
                (
                    SimEvent::Mix {
                        a,
                        b,
                        exchanged: true,
                        ..
                    },
                    _,
                ) => id.current.swap(*a as usize, *b as usize),
                (SimEvent::Truth { .. }, Line::Truth(truth)) => {
                    truth.identity = Some(id.current.clone());
                }
                _ => {}
            }
        }
        Some(line)
    }
}
