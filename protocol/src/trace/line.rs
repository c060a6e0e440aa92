//! One Rust type per line kind of the trace format (shared/spec/trace.md,
//! version 2 in docs/guide/trace-format.md), field for field. Serializing a [`Line`] writes `kind` first and leaves
//! out absent optional fields; deserializing ignores fields it does not
//! know. These types say what a line *holds*; whether it is valid (in range,
//! consistent with the header) is [`validate`](super::validate)'s business.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The `format` every header carries, whatever its version.
pub const FORMAT: &str = "idmesh-trace";

/// The version [`Header::new`] writes: 1. A trace without `detect` lines is
/// a version-1 trace, so readers that predate version 2 still read it and
/// what `idmesh simulate` writes is byte for byte what it wrote before.
pub const VERSION: u32 = 1;

/// Version 2 adds the `detect` line: what a tracker reports (a position,
/// class scores, an identity read) before events are extracted from it.
pub const VERSION_2: u32 = 2;

/// Every version this crate reads.
pub(crate) const SUPPORTED_VERSIONS: [u32; 2] = [VERSION, VERSION_2];

/// How far the class scores of a `detect` line may sum from 1: scores
/// rounded to two decimals over a handful of labels stay inside it.
pub(crate) const SCORE_SUM_TOLERANCE: f64 = 0.01;

/// One line of a trace.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Line {
    Header(Header),
    Mix(Mix),
    Observe(Observe),
    Identify(Identify),
    Move(Move),
    Truth(Truth),
    /// Version 2 only.
    Detect(Detect),
}

/// `header` — exactly one, first.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// Always [`FORMAT`].
    pub format: String,
    /// Always [`VERSION`].
    pub version: u32,
    /// n, the number of tracks; track ids are `0 .. tracks`.
    pub tracks: usize,
    /// k, how many targets carry the property; `None` = unknown (unless
    /// `initial_red` fixes it, see [`Header::red_count`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub red: Option<usize>,
    /// The red tracks at time 0; `None` = uniform prior over the k-sets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial_red: Option<Vec<u32>>,
    /// Identity traces: the number of identities, one per track.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identities: Option<usize>,
    /// `initial_identity[t]` is the identity on track t at time 0; `None` =
    /// uniform prior over the n! assignments.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial_identity: Option<Vec<u32>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
}

impl Header {
    /// A version-1 header for `tracks` tracks with every optional field
    /// absent.
    pub fn new(tracks: usize) -> Self {
        Header {
            format: FORMAT.to_string(),
            version: VERSION,
            tracks,
            red: None,
            initial_red: None,
            identities: None,
            initial_identity: None,
            source: None,
            description: None,
        }
    }

    /// A version-2 header (one that may be followed by `detect` lines).
    pub fn new_v2(tracks: usize) -> Self {
        Header {
            version: VERSION_2,
            ..Header::new(tracks)
        }
    }

    /// k when the trace fixes it: `red`, or else the length of
    /// `initial_red`; `None` when the number of red targets is unknown.
    pub fn red_count(&self) -> Option<usize> {
        self.red
            .or_else(|| self.initial_red.as_ref().map(|red| red.len()))
    }
}

/// `mix` — targets on tracks `a` and `b` came close and exchanged tracks
/// with probability `swap` (the paper's 1 − p).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Mix {
    pub time: f64,
    pub a: u32,
    pub b: u32,
    pub swap: f64,
}

/// `observe` — a sensor saw the property of the target on `track`: `red` is
/// the likelihood of the observation if that target is red, `blue` if blue.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Observe {
    pub time: f64,
    pub track: u32,
    pub red: f64,
    pub blue: f64,
    /// Which sensor reported it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor: Option<String>,
}

/// `identify` — a sensor read `identity` on `track`; it is right with
/// probability `accuracy`, a wrong read spread evenly over the others.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Identify {
    pub time: f64,
    pub track: u32,
    pub identity: u32,
    pub accuracy: f64,
}

/// `move` — the position of a track, in metres.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Move {
    pub time: f64,
    pub track: u32,
    pub x: f64,
    pub y: f64,
}

/// `detect` (version 2) — what a tracker reported about `track` at `time`:
/// its position in metres, and optionally class scores and an identity
/// read. Events (`mix`, `observe`, `identify`) are extracted from detect
/// lines by `idmesh extract` (crate `idmesh-extract`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Detect {
    pub time: f64,
    pub track: u32,
    pub x: f64,
    pub y: f64,
    /// The classifier's scores, label to score in [0, 1], summing to 1
    /// (within [`SCORE_SUM_TOLERANCE`]), e.g. `{"red":0.83,"blue":0.17}`.
    /// A map sorted by label, so a line is written the same way every time.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scores: Option<BTreeMap<String, f64>>,
    /// An identity read on this track (needs `accuracy` and a header that
    /// declares `identities`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identity: Option<u32>,
    /// The probability that the read is right.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub accuracy: Option<f64>,
}

impl Detect {
    /// A detection with a position only.
    #[cfg(test)]
    pub(crate) fn at(time: f64, track: u32, x: f64, y: f64) -> Self {
        Detect {
            time,
            track,
            x,
            y,
            scores: None,
            identity: None,
            accuracy: None,
        }
    }
}

/// `truth` — ground truth at `time`: the red tracks, the identity on every
/// track, or both.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    pub time: f64,
    /// The k tracks that carry red targets now.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub red: Option<Vec<u32>>,
    /// `identity[t]` = identity of the target on track t now.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub identity: Option<Vec<u32>>,
}

impl Line {
    /// The `kind` tag of this line.
    pub fn kind(&self) -> &'static str {
        match self {
            Line::Header(_) => "header",
            Line::Mix(_) => "mix",
            Line::Observe(_) => "observe",
            Line::Identify(_) => "identify",
            Line::Move(_) => "move",
            Line::Truth(_) => "truth",
            Line::Detect(_) => "detect",
        }
    }

    /// Whether the line is an event of the stream — what the sensor
    /// gateway sequences and counts: every line but the header and the
    /// ground truth (`mix`, `observe`, `identify`, `move`, `detect`).
    pub fn is_event(&self) -> bool {
        !matches!(self, Line::Header(_) | Line::Truth(_))
    }

    /// The time of the line; `None` for the header, which has none.
    pub fn time(&self) -> Option<f64> {
        match self {
            Line::Header(_) => None,
            Line::Mix(l) => Some(l.time),
            Line::Observe(l) => Some(l.time),
            Line::Identify(l) => Some(l.time),
            Line::Move(l) => Some(l.time),
            Line::Truth(l) => Some(l.time),
            Line::Detect(l) => Some(l.time),
        }
    }
}

impl From<Header> for Line {
    fn from(line: Header) -> Self {
        Line::Header(line)
    }
}

impl From<Mix> for Line {
    fn from(line: Mix) -> Self {
        Line::Mix(line)
    }
}

impl From<Observe> for Line {
    fn from(line: Observe) -> Self {
        Line::Observe(line)
    }
}

impl From<Identify> for Line {
    fn from(line: Identify) -> Self {
        Line::Identify(line)
    }
}

impl From<Move> for Line {
    fn from(line: Move) -> Self {
        Line::Move(line)
    }
}

impl From<Truth> for Line {
    fn from(line: Truth) -> Self {
        Line::Truth(line)
    }
}

impl From<Detect> for Line {
    fn from(line: Detect) -> Self {
        Line::Detect(line)
    }
}
