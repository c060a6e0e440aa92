//! What every message must be on its own, whoever receives it: the size
//! limits all messages share ([`MAX_TRACKS`] and the others) and the
//! helpers their rules are written with. Each message's own rules (finite,
//! non-negative likelihoods, probabilities in [0, 1], k ≤ n, distinct
//! tracks, items in seq order) are its [`Valid`] impl, in the message's
//! module beside its type, and [`decode`](super::decode) applies them, so
//! no process ever holds a message that breaks one. This module imports
//! nothing of the wire, so every message module can import it. The rules
//! that need the stream's field (a track below n, a leader index below L)
//! are [`Bounds`](super::bounds::Bounds)'.
//!
//! Every error names the message ([`Versioned::WHAT`](super::Versioned::WHAT))
//! and says where in it the fault is and what the value was.

#[doc(inline)]
pub use super::Valid;

/// The most tracks a stream may have. A `Begin` lists an owner per track
/// and every leader keeps a flag per track, so a stream of 10^9 tracks
/// would cost gigabytes before the first event; a million is two orders of
/// magnitude beyond anything the engine has been run on.
pub(crate) const MAX_TRACKS: u32 = 1 << 20;

/// The most tracks of an identity stream whose leaders hold the
/// information matrix: n × n numbers (4096² f64 = 128 MiB), spread over
/// the leaders. The factored identity belief (`Begin::factored_identity`)
/// grows with the mixes, not n², and takes streams up to [`MAX_TRACKS`].
pub const MAX_IDENTITY_TRACKS: u32 = 1 << 12;

/// The most leaders a stream may name: indices are `u16`.
pub(crate) const MAX_LEADERS: usize = 1 << 16;

/// The largest snapshot a leader role sends its standby
/// ([`StandbyCopy`](super::leader_to_leader::StandbyCopy)), 512 MiB: under
/// Zenoh's default largest message (`transport.link.rx.max_message_size`,
/// 1 GiB) and the journal's largest record, so a copy that passes here is
/// carried and written whole. A state that grows past it is not sent (the
/// role says so) and its durable mark stops moving.
pub const MAX_SNAPSHOT_BYTES: usize = 1 << 29;

/// `Err(sentence)` when `condition` fails: the rules read as a list.
pub(crate) fn require(condition: bool, problem: impl FnOnce() -> String) -> Result<(), String> {
    if condition {
        Ok(())
    } else {
        Err(problem())
    }
}

/// Distinct ids below `n`. Sorting a copy costs what the list costs, and
/// the list is bounded by the message's own bytes.
pub(crate) fn distinct_tracks(what: &str, tracks: &[u32], n: u32) -> Result<(), String> {
    if let Some(t) = tracks.iter().find(|&&t| t >= n) {
        return Err(format!("{what}: {t} is out of range (0..{n})"));
    }
    distinct(what, tracks)
}

/// No id twice.
pub(crate) fn distinct(what: &str, ids: &[u32]) -> Result<(), String> {
    let mut sorted = ids.to_vec();
    sorted.sort_unstable();
    match sorted.windows(2).find(|w| w[0] == w[1]) {
        Some(pair) => Err(format!("{what} lists {} twice", pair[0])),
        None => Ok(()),
    }
}
