//! The generator's own event representation: a time-ordered list of
//! [`TimedEvent`]s. It mirrors the `mix`, `observe`, `move` and `truth`
//! lines of the trace format (shared/spec/trace.md) without depending on
//! how they are written; `crate::scenario::trace_out` converts.

/// One event of a generated trace.
#[derive(Debug, Clone, PartialEq)]
pub enum SimEvent {
    /// The targets on tracks `a` and `b` came within the mixing distance;
    /// the tracker exchanged them with probability `swap`. `exchanged` is
    /// the ground truth of that draw (whether the targets really changed
    /// tracks); it is not part of the trace's `mix` line.
    Mix {
        a: u32,
        b: u32,
        swap: f64,
        exchanged: bool,
    },
    /// A sensor saw the colour of the target on `track`: `red` and `blue`
    /// are the likelihoods of this observation for a red and a blue target.
    Observe { track: u32, red: f64, blue: f64 },
    /// Track `track` is at (x, y) metres.
    Move { track: u32, x: f64, y: f64 },
    /// Ground truth: the tracks carrying red targets now, ascending.
    Truth { red: Vec<u32> },
}

impl SimEvent {
    /// The trace `kind` of this event.
    pub fn kind(&self) -> &'static str {
        match self {
            SimEvent::Mix { .. } => "mix",
            SimEvent::Observe { .. } => "observe",
            SimEvent::Move { .. } => "move",
            SimEvent::Truth { .. } => "truth",
        }
    }

    /// `mix` and `observe` are the events a property filter consumes.
    #[cfg(test)]
    pub(crate) fn is_sensing(&self) -> bool {
        matches!(self, SimEvent::Mix { .. } | SimEvent::Observe { .. })
    }
}

/// An event at a time, seconds from the start of the run.
#[derive(Debug, Clone, PartialEq)]
pub struct TimedEvent {
    pub time: f64,
    pub event: SimEvent,
}
