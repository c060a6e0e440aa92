//! The leader's door: bytes from the network become inputs of the state
//! machine only once they decode, are well formed on their own
//! ([`decode`] checks [`Valid`](idmesh_protocol::wire::Valid)) and fit the
//! stream the leader knows ([`Bounds`](idmesh_protocol::wire::bounds::Bounds):
//! tracks below n, leader indices below L). Both kinds of rule of a
//! message sit beside its type in idmesh-protocol (a batch's in
//! `wire::sensor_to_leader`), so a check here is one call away from them. What fails is rejected before it is journaled or applied, so
//! one bad message from the network leaves the leader's state as it was
//! and costs it nothing but a log line and a count: it is not a failure of
//! the leader, which keeps `failure` for its own inconsistencies (a journal
//! it cannot write, an input it admitted but cannot apply).
//!
//! A batch numbered ahead of a missing one, met before the stream's Begin,
//! can only be checked on its own here; [`Leader::batch`] checks it
//! against the field when its turn comes, and so does the Begin for
//! transfers that came before it.

use crate::error::LeaderError;
use crate::journal::Kind;
use crate::state::{Action, Leader};
use idmesh_protocol::wire::leader_to_leader::{Transfer, TransfersSent};
use idmesh_protocol::wire::leader_to_sensor::Followed;
use idmesh_protocol::wire::sensor_to_leader::{Batch, Item, Sequenced};
use idmesh_protocol::wire::{decode, WireError};

/// An input that passed the door.
#[derive(Debug, Clone, PartialEq)]
pub enum Input {
    Batch(Batch),
    /// What a peer sent at once, in order (one step's transfers for this
    /// leader: [`crate::machine::Output::Send`]).
    Transfers {
        epoch: u64,
        transfers: Vec<Transfer>,
    },
    Followed(Followed),
}

/// Decodes and checks input `bytes` of `kind` against what `leader` knows.
pub fn admit(leader: &Leader, kind: Kind, bytes: &[u8]) -> Result<Input, WireError> {
    match kind {
        Kind::Batch => {
            let batch = decode::<Batch>(bytes)?;
            // Batch 0 carries the stream's Begin and was checked against
            // it by `decode`; any other against the Begin the leader has.
            match batch.items.first() {
                Some(Sequenced {
                    item: Item::Begin(begin),
                    ..
                }) => {
                    if !begin.leaders.iter().any(|l| l == leader.name()) {
                        return Err(WireError::Invalid {
                            what: "event batch",
                            problem: format!(
                                "a Begin whose leaders {:?} do not include {}",
                                begin.leaders,
                                leader.name()
                            ),
                        });
                    }
                }
                _ => {
                    if let Some(bounds) = leader.bounds() {
                        bounds.check_batch(&batch)?;
                    }
                }
            }
            Ok(Input::Batch(batch))
        }
        Kind::Transfer => {
            let TransfersSent {
                epoch, transfers, ..
            } = decode::<TransfersSent>(bytes)?;
            if let (Some(bounds), Some(me)) = (leader.bounds(), leader.index()) {
                for transfer in &transfers {
                    bounds.check_transfer(transfer, me)?;
                }
            }
            Ok(Input::Transfers { epoch, transfers })
        }
        Kind::Followed => {
            let followed = decode::<Followed>(bytes)?;
            // Only a leader that has begun asks to follow.
            let bounds = leader.bounds().ok_or_else(|| WireError::Invalid {
                what: "follow reply",
                problem: "a reply before the stream's Begin".into(),
            })?;
            bounds.check_followed(&followed.items)?;
            Ok(Input::Followed(followed))
        }
        Kind::Rejected => Err(WireError::Invalid {
            what: "journal entry",
            problem: "a refusal is not an input".into(),
        }),
    }
}

/// Applies an admitted input of `bytes` bytes.
pub fn apply(leader: &mut Leader, input: Input, bytes: usize) -> Result<Vec<Action>, LeaderError> {
    match input {
        Input::Batch(batch) => leader.batch(batch, bytes),
        Input::Transfers { transfers, .. } => {
            let mut actions = Vec::new();
            // The message's bytes are counted once, with its first.
            let mut size = bytes;
            for transfer in transfers {
                actions.extend(leader.transfer(transfer, std::mem::take(&mut size))?);
            }
            Ok(actions)
        }
        Input::Followed(followed) => leader.followed(followed.items),
    }
}
