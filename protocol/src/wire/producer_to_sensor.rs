//! Live ingestion: any producer (a camera's tracker, a mote's gateway, a
//! Python script) hands a sensor trace lines on
//! `P/sensor/<name>/ingest?producer=<id>;counter=<c>` — a Zenoh get whose
//! payload is one or more lines of the trace format (`mix`, `observe`,
//! `move`, `identify`; JSON, one per line, as in `shared/spec/trace.md`),
//! the first numbered `c` in that producer's own count and each next line
//! one more. The reply is an [`IngestAck`] (JSON): which counters the
//! sensor put in its order, which it had already, which it refused and
//! why. A request it cannot read at all (no producer, a counter that is
//! not a number, a payload that is not UTF-8, a stream already finished)
//! gets an error reply saying why.
//!
//! The rules (the sensor's `gateway::ingest`, a pure state machine):
//! a producer's counters start at 0 and go up by one a line; a counter
//! below the next one expected is a duplicate (acknowledged again, applied
//! once); a counter above it is refused as out of order (not held: the
//! acknowledgement names `next`, the counter to send again from); a line
//! that breaks the format or the stream's header (an unknown track, a
//! likelihood out of range, a `truth` or second `header` line) is refused
//! with its reason and uses up its counter, so one bad line never stalls
//! a producer.
//!
//! One sensor of several ([`sensor_to_sensor`](super::sensor_to_sensor))
//! orders events by (time, producer, counter), so three rules change: a
//! producer's counters are its own across every sensor it feeds, so a
//! sensor sees them rise with gaps (a counter below the last one taken
//! that was never taken here is refused as out of order; one taken is a
//! duplicate, among the last 4,096); a line at or before the position the
//! sensor has passed is refused as late; and a request may say `time=T`
//! (nothing before T comes from this producer to this sensor) and
//! `finish` (no more events), with or without lines.

use serde::{Deserialize, Serialize};

/// The query parameter naming the producer.
pub const PRODUCER: &str = "producer";
/// The query parameter carrying the counter of the request's first line.
pub const COUNTER: &str = "counter";
/// One sensor of several: `time=<t>`, the producer gives this sensor
/// nothing before time `t` (its watermark moves there: events merge
/// without waiting for this sensor's next one).
pub const TIME: &str = "time";
/// One sensor of several: `finish`, the producers give this sensor no
/// more events (the stream ends once every sensor's have).
pub const FINISH: &str = "finish";

/// The sensor's answer to one ingest request (JSON).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct IngestAck {
    pub sensor: String,
    pub producer: String,
    /// The counter of the request's first line.
    pub first: u64,
    /// Lines in the request.
    pub lines: u64,
    /// Counters put in the sensor's order by this request, in order.
    pub accepted: Vec<u64>,
    /// Counters the sensor had already taken (accepted or refused) from
    /// this producer: nothing was done with them again.
    pub duplicates: Vec<u64>,
    /// Lines refused, each with why.
    pub errors: Vec<LineRefused>,
    /// The counter the sensor expects next from this producer.
    pub next: u64,
    /// Events in the sensor's order after this request: an answer whose
    /// watermark for this sensor is at least this includes every line
    /// accepted here.
    pub events: u64,
}

/// A line the sensor refused.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LineRefused {
    pub counter: u64,
    /// The line's number within the request, from 1.
    pub line: u64,
    pub reason: String,
}
