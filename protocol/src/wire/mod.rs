//! The messages of the distributed runtime, one module per direction (as in
//! dora's `coordinator_to_daemon`), all encoded with postcard and carrying
//! [`VERSION`]; the user-facing answers are JSON ([`query`]).
//!
//! - [`keys`] — every key expression, under a deployment prefix.
//! - [`sensor_to_leader`] — the sequenced event stream, in batches.
//! - [`leader_to_leader`] — sets handed over at a cross-leader mix or a move;
//!   a restarted leader's request for the transfers it missed; a role's
//!   snapshot for its standby, and the standby's acknowledgement.
//! - [`leader_to_sensor`] — a request to follow more tracks, from a seq on;
//!   a request for lost batches; how far a leader's state is safe (what
//!   the sensor and peers may stop keeping for it).
//! - [`coordinator_to_sensor`] — a request for a cut of the stream.
//! - [`producer_to_sensor`] — live ingestion: trace lines from any
//!   producer, and the acknowledgement (JSON).
//! - [`sensor_to_sensor`] — several sensors: each one's intake, for the
//!   others to merge into one order.
//! - [`sensor_to_standby`] — the sensor's journal, replicated to its
//!   standby, and the standby's acknowledgement.
//! - [`coordinator_to_leader`] — partial sums at a cut, and counters.
//! - [`epoch`] — the fence: the epoch every leader message (and every
//!   batch and reply of the sensor) carries, and the receivers' rule that
//!   refuses a former holder's.
//! - [`interest`] — the routing rule both ends of the event stream apply.
//! - [`query`] — what a user gets back, as JSON.
//!
//! Each message module also holds its messages' rules, beside their
//! types: what the message must be on its own (its [`Valid`] impl, which
//! [`decode`] checks, so a malformed message is an error, never a value)
//! and what it must be to fit a stream's field (its `check_*` method on
//! [`bounds::Bounds`]: tracks below n, leader indices below L, checked
//! where the field is known). What those rules share sits in two small
//! modules that import no message:
//! - [`valid`] — the size limits every message shares, and the helpers
//!   the rules are written with.
//! - [`bounds`] — the field ([`bounds::Bounds`]) and its two checks (a
//!   track, a leader index).

pub mod bounds;
pub mod coordinator_to_leader;
pub mod coordinator_to_sensor;
pub mod epoch;
pub mod factored;
pub mod identity;
pub mod interest;
pub mod keys;
pub mod leader_to_leader;
pub mod leader_to_sensor;
pub mod producer_to_sensor;
pub mod query;
pub mod sensor_to_leader;
pub mod sensor_to_sensor;
pub mod sensor_to_standby;
pub mod valid;

use serde::de::DeserializeOwned;
use serde::Serialize;

/// The version of every postcard message below; a receiver rejects others.
/// It moves when a message already on the wire changes (a field added,
/// removed or retyped); a new message alone leaves it (a receiver that
/// does not know the message has no key it comes on).
/// 4: the transfer key carries a `TransfersSent`, one input's transfers.
/// 5: a mix may take a track from another leader (`Item::Mix::handed`).
/// 6: tracks may start unheld and be adopted at their first item
/// (`sensor_to_leader::UNHELD`); answers list their passive parts
/// (`Partial::passive`).
/// 7: leaders may hold the factored identity belief
/// (`Begin::factored_identity`); transfers and answers carry its trees.
/// 8: every message a leader role sends carries the role's epoch, which
/// receivers fence on ([`epoch`]).
/// 9: what the sensor sends leaders (`Batch`, `Followed`, `Resent`)
/// carries the sensor role's epoch too: a sensor's standby may hold it.
/// 10: a cut's answer (`CutPlaced`) carries the sensor role's epoch,
/// which the coordinator fences on.
/// 11: the sensor's records for its standby (`Replicate`) carry the
/// sensor role's epoch, which the standby's takeover names.
/// 12: a factored stream's `Begin` says the crowd size it spreads above
/// (`FactoredStart::spread_above`); a smaller one is held whole.
pub const VERSION: u16 = 12;

/// Why bytes from the network were not a message.
#[derive(Debug, thiserror::Error)]
pub enum WireError {
    #[error("{what}: undecodable ({source})")]
    Decode {
        what: &'static str,
        source: postcard::Error,
    },
    #[error("{what}: version {found}, this build speaks {VERSION}")]
    Version { what: &'static str, found: u16 },
    #[error("{what}: {problem}")]
    Invalid { what: &'static str, problem: String },
}

/// A message that carries the protocol version.
pub trait Versioned {
    const WHAT: &'static str;
    fn version(&self) -> u16;
}

/// A message that can say whether it is well formed on its own.
pub trait Valid: Versioned {
    /// The first rule the message breaks, as a sentence that says where.
    fn problem(&self) -> Option<String>;

    /// [`Valid::problem`] as a [`WireError`] naming the message.
    fn validate(&self) -> Result<(), WireError> {
        match self.problem() {
            None => Ok(()),
            Some(problem) => Err(WireError::Invalid {
                what: Self::WHAT,
                problem,
            }),
        }
    }
}

pub fn encode<T: Serialize>(message: &T) -> Vec<u8> {
    // Serializing our own plain types into a Vec cannot fail.
    postcard::to_allocvec(message).unwrap_or_default()
}

/// Bytes from the network to a message: it must decode, carry this build's
/// [`VERSION`] and be well formed ([`Valid`]). Length prefixes cannot make
/// it allocate much more than `bytes` holds: serde caps what it reserves
/// ahead of a sequence at 1 MiB, and every element then needs its own bytes
/// (`tests/absurd_sizes.rs` measures it). Trailing bytes are ignored.
pub fn decode<T: DeserializeOwned + Valid>(bytes: &[u8]) -> Result<T, WireError> {
    let message: T = postcard::from_bytes(bytes).map_err(|source| WireError::Decode {
        what: T::WHAT,
        source,
    })?;
    if message.version() != VERSION {
        return Err(WireError::Version {
            what: T::WHAT,
            found: message.version(),
        });
    }
    message.validate()?;
    Ok(message)
}

macro_rules! versioned {
    ($t:ty, $what:literal) => {
        impl $crate::wire::Versioned for $t {
            const WHAT: &'static str = $what;
            fn version(&self) -> u16 {
                self.version
            }
        }
    };
}
pub(crate) use versioned;
