//! Errors of the engine: every one names what was wrong and with which value,
//! and an update that fails leaves the belief exactly as it was.

use thiserror::Error;

/// What can go wrong when a belief is set up, updated or asked.
#[derive(Debug, Error, Clone, PartialEq)]
pub enum BeliefError {
    #[error("track {track} is out of range: there are {tracks} tracks (0..{tracks})")]
    UnknownTrack { track: u32, tracks: usize },
    #[error("a mix needs two distinct tracks, got {track} twice")]
    SelfMix { track: u32 },
    #[error("swap probability {swap} is not in [0, 1]")]
    BadSwap { swap: f64 },
    #[error("likelihoods red={red}, blue={blue} are invalid: both must be finite and >= 0, and not both 0")]
    BadLikelihood { red: f64, blue: f64 },
    #[error("identity read {identity} on track {track} is out of range: there are {identities} identities")]
    UnknownIdentity {
        identity: u32,
        track: u32,
        identities: usize,
    },
    #[error("read accuracy {accuracy} is not in (0, 1]")]
    BadAccuracy { accuracy: f64 },
    #[error("{red} red targets cannot be among {tracks} tracks")]
    TooManyRed { red: usize, tracks: usize },
    #[error("there must be at least one track")]
    NoTracks,
    #[error("the initial red tracks must be {expected} distinct tracks, got {got:?}")]
    BadInitialRed { expected: usize, got: Vec<u32> },
    #[error("the initial assignment must be a permutation of 0..{tracks}, got {got:?}")]
    BadInitialIdentity { tracks: usize, got: Vec<u32> },
    #[error("the prior over the number of red targets must have {expected} finite, non-negative weights with a positive sum")]
    BadCountPrior { expected: usize },
    #[error("the observation has probability {probability} under the current belief: it contradicts everything the belief allows")]
    ImpossibleObservation { probability: f64 },
    #[error(
        "the belief has no positive mass left (normalizer {normalizer}); it cannot be normalized"
    )]
    Degenerate { normalizer: f64 },
    #[error("{method} needs {needed} states, more than its limit of {limit}")]
    TooLarge {
        method: &'static str,
        needed: f64,
        limit: usize,
    },
    #[error("{method} answers blocks of at most {limit} tracks; the largest block of tracks mixed with each other here has {block} of the {tracks} tracks")]
    TooLargeBlock {
        method: &'static str,
        block: usize,
        tracks: usize,
        limit: usize,
    },
    #[error("{what} is not supported by {method}")]
    Unsupported {
        method: &'static str,
        what: &'static str,
    },
    #[error("a factored component held elsewhere does not fit: {detail}")]
    BadComponent { detail: String },
    #[error("numerical failure in {step}: {detail}")]
    Numerical { step: &'static str, detail: String },
    #[error("{method} was stopped before it finished")]
    Stopped { method: &'static str },
}
