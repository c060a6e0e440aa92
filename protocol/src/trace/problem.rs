//! What can be wrong with one line of a trace, independent of where the line
//! is: every message names the line kind, the field and the offending value,
//! so that `FILE:LINE: reason` (see [`TraceError`](super::TraceError)) is
//! enough to fix the trace.

use thiserror::Error;

/// Why a line was rejected.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum Problem {
    #[error("empty line: a trace has one JSON object per line")]
    BlankLine,
    #[error("the trace is empty: it must start with a header line")]
    Empty,
    #[error("malformed JSON: {0}")]
    MalformedJson(String),
    #[error("a trace line must be a JSON object, got {0}")]
    NotAnObject(&'static str),
    #[error("the line has no `kind`")]
    MissingKind,
    #[error("`kind` must be a string, got {0}")]
    KindNotAString(String),
    #[error("unknown kind {0:?} (expected header, mix, observe, identify, move, truth or detect)")]
    UnknownKind(String),
    /// A field is missing or has the wrong type (serde's own words).
    #[error("{kind}: {message}")]
    BadField { kind: &'static str, message: String },

    #[error("{kind}: the first line must be the header")]
    HeaderNotFirst { kind: &'static str },
    #[error("header: a trace has exactly one header, and line {first} already is it")]
    SecondHeader { first: usize },
    #[error("header: format is {0:?}, expected \"idmesh-trace\"")]
    BadFormat(String),
    #[error("header: version {0} is not supported (this reader knows versions 1 and 2)")]
    BadVersion(u32),
    #[error("header: tracks = 0: there must be at least one track")]
    NoTracks,
    #[error("header: tracks = {0} is too many: track ids must fit in 32 bits")]
    TooManyTracks(usize),
    #[error("header: red = {red} but there are only {tracks} tracks (k must be <= n)")]
    TooManyRed { red: usize, tracks: usize },
    #[error("header: initial_red has {len} tracks but red = {red}")]
    InitialRedLength { len: usize, red: usize },
    #[error(
        "header: initial_red has {len} tracks but there are only {tracks} tracks (k must be <= n)"
    )]
    InitialRedTooLong { len: usize, tracks: usize },
    #[error(
        "header: identities = {identities} but there are {tracks} tracks (one identity per track)"
    )]
    IdentityCount { identities: usize, tracks: usize },

    #[error("{kind}: {field} = {track} is not a track: there are {tracks} tracks (0..{tracks})")]
    UnknownTrack {
        kind: &'static str,
        field: &'static str,
        track: u32,
        tracks: usize,
    },
    #[error("{kind}: {field} lists track {track} twice")]
    RepeatedTrack {
        kind: &'static str,
        field: &'static str,
        track: u32,
    },
    #[error("{kind}: {field} has {len} entries, expected one per track ({tracks})")]
    AssignmentLength {
        kind: &'static str,
        field: &'static str,
        len: usize,
        tracks: usize,
    },
    #[error("{kind}: {field}[{track}] = {identity} is not an identity: there are {identities} (0..{identities})")]
    AssignmentOutOfRange {
        kind: &'static str,
        field: &'static str,
        track: usize,
        identity: u32,
        identities: usize,
    },
    #[error("{kind}: {field} gives identity {identity} to both track {first} and track {second}")]
    AssignmentRepeats {
        kind: &'static str,
        field: &'static str,
        identity: u32,
        first: usize,
        second: usize,
    },

    #[error("{kind}: time = {time} is not a finite number")]
    NonFiniteTime { kind: &'static str, time: f64 },
    #[error("{kind}: time {time} is before time {previous} of line {previous_line}: times must be non-decreasing")]
    TimeGoesBack {
        kind: &'static str,
        time: f64,
        previous: f64,
        previous_line: usize,
    },

    #[error("mix: a = b = {0}: a mix needs two distinct tracks")]
    SelfMix(u32),
    #[error("mix: swap = {0} is not a probability in [0, 1]")]
    BadSwap(f64),
    #[error("observe: likelihood {which} = {value} is not a finite number")]
    NonFiniteLikelihood { which: &'static str, value: f64 },
    #[error("observe: likelihood {which} = {value} is negative")]
    NegativeLikelihood { which: &'static str, value: f64 },
    #[error(
        "observe: likelihoods red and blue are both 0: the observation is impossible either way"
    )]
    ZeroLikelihoods,
    #[error("identify: the header declares no identities")]
    NoIdentities,
    #[error("identify: identity = {identity} is out of range: there are {identities} identities (0..{identities})")]
    UnknownIdentity { identity: u32, identities: usize },
    #[error("identify: accuracy = {0} is not in (0, 1]")]
    BadAccuracy(f64),
    #[error("move: {field} = {value} is not a finite number")]
    NonFinitePosition { field: &'static str, value: f64 },
    #[error("detect: a version-{version} trace has no detect lines (they need version 2)")]
    DetectNeedsVersion2 { version: u32 },
    #[error("detect: {field} = {value} is not a finite number")]
    DetectNonFinitePosition { field: &'static str, value: f64 },
    #[error("detect: scores is empty: leave it out when there are no scores")]
    EmptyScores,
    #[error("detect: score {label:?} = {value} is not a number in [0, 1]")]
    BadScore { label: String, value: f64 },
    #[error("detect: scores sum to {sum}, not 1 (tolerance {tolerance})")]
    ScoresDoNotSumToOne { sum: f64, tolerance: f64 },
    #[error("detect: an identity read needs both identity and accuracy")]
    HalfIdentityRead,
    #[error("detect: an identity read needs a header that declares identities")]
    DetectNoIdentities,
    #[error("detect: identity = {identity} is out of range: there are {identities} identities (0..{identities})")]
    DetectUnknownIdentity { identity: u32, identities: usize },
    #[error("detect: accuracy = {0} is not in (0, 1]")]
    DetectBadAccuracy(f64),
    #[error("detect: a tracker's report, not an event: turn detect lines into events with `idmesh extract` first")]
    NotExtracted,
    #[error("truth: carries neither red nor identity")]
    EmptyTruth,
    #[error("truth: red has {len} tracks but the header says k = {red}")]
    TruthRedLength { len: usize, red: usize },
}
