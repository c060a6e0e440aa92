//! Sets handed from one leader to another (Algorithm 4's exchange at a
//! cross-leader mix, and the handover when a track changes region). A
//! transfer is tied to the seq of the item that caused it; the receiver
//! adds the sets at exactly that point of its own stream.
//!
//! On an identity stream the same transfer carries rows of the information
//! matrix (Shin et al., Section 4): at a cross-leader mix, each leader's
//! row of its mixed track as it was before the mix (both then compute the
//! same fit); at a handover, the row of the track that changes region.
//!
//! A leader role also keeps a copy of its state with its standby, the
//! process that would adopt the role if its own died: every snapshot it
//! writes goes to the standby ([`StandbyCopy`]), which writes it to its
//! own disk and acknowledges ([`StandbyStored`]). The role's durable mark
//! waits for that acknowledgement, so a host lost with its disk never
//! takes with it state the others have forgotten.
//!
//! Each message's rules ([`Valid`], and [`Bounds`] for a transfer) sit
//! below the types.

use super::bounds::{invalid, Bounds};
use super::factored::WireComponent;
use super::identity::WireTree;
use super::leader_to_sensor::Durable;
use super::valid::{distinct, require, MAX_SNAPSHOT_BYTES};
use super::{Valid, WireError};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Transfer {
    pub version: u16,
    /// Index of the sending leader.
    pub from: u16,
    pub seq: u64,
    pub sets: Vec<WireSet>,
    pub rows: Vec<WireRow>,
    /// Components of the factored belief (a factored stream; sets are
    /// then empty).
    pub components: Vec<WireComponent>,
    /// Trees of the factored identity belief, sent to the leader that
    /// mixes them (`Begin::factored_identity`).
    ///
    /// [`Begin::factored_identity`]: super::sensor_to_leader::Begin::factored_identity
    pub trees: Vec<WireTree>,
}
super::versioned!(Transfer, "transfer");

/// A set φ_{red|blue} with its mass on the absolute (log) scale.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireSet {
    pub red: Vec<u32>,
    pub blue: Vec<u32>,
    pub ln_mass: f64,
}

/// Row `track` of an information matrix: accumulated log-likelihoods, one
/// per identity.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireRow {
    pub track: u32,
    pub ln_likelihoods: Vec<f64>,
}

/// A restarted leader asks a peer for the transfers the peer sent it with
/// seq after `after` (sent while it was down, they were lost): postcard,
/// the payload of a get on `P/leader/<peer>/sent`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransfersWanted {
    pub version: u16,
    /// The sending role's epoch ([`super::epoch`]).
    pub epoch: u64,
    /// The asking leader's index.
    pub to: u16,
    pub after: u64,
}
super::versioned!(TransfersWanted, "transfers request");
super::epoch::epoched!(TransfersWanted);

/// Transfers in order: every transfer one input of the sender made for
/// this leader, put on `P/leader/<l>/transfer` as one message (a crowd's
/// batch hands several tracks to the same neighbour, and each message costs
/// both processes a wake-up); and the reply to a [`TransfersWanted`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TransfersSent {
    pub version: u16,
    /// The sending role's epoch ([`super::epoch`]).
    pub epoch: u64,
    pub transfers: Vec<Transfer>,
}
super::versioned!(TransfersSent, "transfers reply");
super::epoch::epoched!(TransfersSent);

/// A leader role's snapshot for its standby to keep: put on
/// `P/leader/<to>/standby`, where the process hosting role `to` (the one
/// that would adopt `role`) takes it, writes it to its own disk and
/// answers with a [`StandbyStored`]. Sent at every snapshot, and again
/// (the last one) when the standby changes or does not answer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StandbyCopy {
    pub version: u16,
    /// The role the snapshot is of.
    pub role: String,
    /// The role whose process keeps the copy: the heir of `role`, or
    /// `role` itself when the role goes home to its own process standing
    /// by.
    pub to: String,
    /// The snapshot's durable mark: what the role may let the others
    /// forget once the copy is kept.
    pub mark: Durable,
    /// The snapshot, as the role wrote it (at most
    /// [`MAX_SNAPSHOT_BYTES`]).
    pub state: Vec<u8>,
}
super::versioned!(StandbyCopy, "standby copy");

/// A standby's word that it keeps a role's snapshot on its disk (written
/// whole and fsynced): put on `P/leader/<role>/stored`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StandbyStored {
    pub version: u16,
    /// The role whose snapshot is kept.
    pub role: String,
    /// The role the copy was sent to (the standby, as the sender named it).
    pub standby: String,
    /// The process that stored it.
    pub host: String,
    /// The mark of the snapshot it stored.
    pub mark: Durable,
}
super::versioned!(StandbyStored, "standby acknowledgement");

impl Valid for StandbyCopy {
    fn problem(&self) -> Option<String> {
        let checks = || -> Result<(), String> {
            require(!self.role.is_empty(), || "it names no role".into())?;
            require(!self.to.is_empty(), || "it names no standby".into())?;
            require(self.mark.leader == self.role, || {
                format!(
                    "the mark is of {}, the copy of {}",
                    self.mark.leader, self.role
                )
            })?;
            require(!self.state.is_empty(), || "an empty snapshot".into())?;
            require(self.state.len() <= MAX_SNAPSHOT_BYTES, || {
                format!(
                    "a snapshot of {} bytes (at most {MAX_SNAPSHOT_BYTES})",
                    self.state.len()
                )
            })
        };
        checks().err()
    }
}

impl Valid for StandbyStored {
    fn problem(&self) -> Option<String> {
        let checks = || -> Result<(), String> {
            require(!self.role.is_empty(), || "it names no role".into())?;
            require(!self.standby.is_empty(), || "it names no standby".into())?;
            require(!self.host.is_empty(), || "it names no process".into())?;
            require(self.mark.leader == self.role, || {
                format!(
                    "the mark is of {}, the copy of {}",
                    self.mark.leader, self.role
                )
            })
        };
        checks().err()
    }
}

impl Valid for Transfer {
    fn problem(&self) -> Option<String> {
        self.check().err()
    }
}

impl Transfer {
    fn check(&self) -> Result<(), String> {
        for (i, set) in self.sets.iter().enumerate() {
            set.check().map_err(|e| format!("set {i}: {e}"))?;
        }
        let tracks: Vec<u32> = self.rows.iter().map(|r| r.track).collect();
        distinct("rows", &tracks)?;
        for row in &self.rows {
            row.check()?;
        }
        for (i, c) in self.components.iter().enumerate() {
            c.check().map_err(|e| format!("component {i}: {e}"))?;
        }
        Ok(())
    }
}

impl WireSet {
    /// φ_{red|blue}: each list without repeats, no track both red and
    /// blue, a log mass that is a number below +∞ (−∞ is a zero mass).
    pub(crate) fn check(&self) -> Result<(), String> {
        distinct("red", &self.red)?;
        distinct("blue", &self.blue)?;
        if let Some(t) = self.red.iter().find(|t| self.blue.contains(t)) {
            return Err(format!("track {t} is both red and blue"));
        }
        require(
            !self.ln_mass.is_nan() && self.ln_mass != f64::INFINITY,
            || format!("log mass = {}", self.ln_mass),
        )
    }
}

impl WireRow {
    /// Accumulated log-likelihoods: numbers below +∞ (−∞ is an identity
    /// ruled out by a certain read).
    pub(crate) fn check(&self) -> Result<(), String> {
        match self
            .ln_likelihoods
            .iter()
            .position(|x| x.is_nan() || *x == f64::INFINITY)
        {
            Some(i) => Err(format!(
                "row of track {}: log-likelihood [{i}] = {}",
                self.track, self.ln_likelihoods[i]
            )),
            None => Ok(()),
        }
    }
}

impl Valid for TransfersWanted {
    fn problem(&self) -> Option<String> {
        None
    }
}

impl Valid for TransfersSent {
    fn problem(&self) -> Option<String> {
        self.transfers
            .iter()
            .enumerate()
            .find_map(|(i, t)| t.problem().map(|e| format!("transfer {i}: {e}")))
    }
}

impl Bounds {
    /// A transfer to leader `me`: from another leader of the stream, sets
    /// of its tracks, rows of n numbers only on an identity stream.
    pub fn check_transfer(&self, transfer: &Transfer, me: u16) -> Result<(), WireError> {
        self.check_parts(transfer.from, &transfer.sets, &transfer.rows, me)
            .and_then(|()| self.check_trees(&transfer.trees))
            .map_err(|problem| invalid("transfer", problem))
    }

    /// [`Bounds::check_transfer`] on a transfer kept in parts.
    pub(crate) fn check_parts(
        &self,
        from: u16,
        sets: &[WireSet],
        rows: &[WireRow],
        me: u16,
    ) -> Result<(), String> {
        self.leader("from", from)?;
        require(from != me, || format!("from = {from}, the receiver itself"))?;
        for (i, set) in sets.iter().enumerate() {
            for &t in set.red.iter().chain(&set.blue) {
                self.track(&format!("set {i} track"), t)?;
            }
        }
        require(rows.is_empty() || self.identities, || {
            "rows of an information matrix on a stream without identities".into()
        })?;
        self.check_rows(rows)
    }

    /// Rows of the information matrix: of tracks of the field, n numbers each.
    pub(crate) fn check_rows(&self, rows: &[WireRow]) -> Result<(), String> {
        for row in rows {
            self.track("row track", row.track)?;
            require(row.ln_likelihoods.len() == self.tracks as usize, || {
                format!(
                    "row of track {} has {} numbers for {} identities",
                    row.track,
                    row.ln_likelihoods.len(),
                    self.tracks
                )
            })?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{decode, encode, VERSION};

    #[test]
    fn transfers_are_checked() {
        let transfer = |set: WireSet, rows: Vec<WireRow>| Transfer {
            trees: Vec::new(),
            components: Vec::new(),
            version: VERSION,
            from: 0,
            seq: 3,
            sets: vec![set],
            rows,
        };
        let set = |red: Vec<u32>, blue: Vec<u32>, ln_mass: f64| WireSet { red, blue, ln_mass };
        let ok = transfer(set(vec![1], vec![2], f64::NEG_INFINITY), vec![]);
        assert_eq!(decode::<Transfer>(&encode(&ok)).unwrap(), ok);
        for (bad, expected) in [
            (
                transfer(set(vec![1, 1], vec![], 0.0), vec![]),
                "red lists 1 twice",
            ),
            (
                transfer(set(vec![1], vec![1], 0.0), vec![]),
                "both red and blue",
            ),
            (
                transfer(set(vec![1], vec![], f64::NAN), vec![]),
                "log mass = NaN",
            ),
            (
                transfer(
                    set(vec![], vec![], 0.0),
                    vec![WireRow {
                        track: 0,
                        ln_likelihoods: vec![0.0, f64::NAN],
                    }],
                ),
                "log-likelihood [1] = NaN",
            ),
        ] {
            let e = decode::<Transfer>(&encode(&bad)).unwrap_err().to_string();
            assert!(e.starts_with("transfer: ") && e.contains(expected), "{e}");
        }
    }

    #[test]
    fn standby_copies_and_their_acknowledgements_are_checked() {
        let mark = |leader: &str| Durable {
            epoch: 0,
            version: VERSION,
            leader: leader.into(),
            batch: 4,
            position: 17,
        };
        let copy = StandbyCopy {
            version: VERSION,
            role: "l1".into(),
            to: "l2".into(),
            mark: mark("l1"),
            state: vec![1, 2, 3],
        };
        assert_eq!(decode::<StandbyCopy>(&encode(&copy)).unwrap(), copy);
        for (bad, expected) in [
            (
                StandbyCopy {
                    mark: mark("l0"),
                    ..copy.clone()
                },
                "the mark is of l0",
            ),
            (
                StandbyCopy {
                    state: vec![],
                    ..copy.clone()
                },
                "an empty snapshot",
            ),
            (
                StandbyCopy {
                    role: String::new(),
                    ..copy.clone()
                },
                "names no role",
            ),
        ] {
            let e = decode::<StandbyCopy>(&encode(&bad))
                .unwrap_err()
                .to_string();
            assert!(
                e.starts_with("standby copy: ") && e.contains(expected),
                "{e}"
            );
        }
        let stored = StandbyStored {
            version: VERSION,
            role: "l1".into(),
            standby: "l2".into(),
            host: "l2".into(),
            mark: mark("l1"),
        };
        assert_eq!(decode::<StandbyStored>(&encode(&stored)).unwrap(), stored);
        let bad = StandbyStored {
            host: String::new(),
            ..stored
        };
        let e = decode::<StandbyStored>(&encode(&bad))
            .unwrap_err()
            .to_string();
        assert!(e.contains("names no process"), "{e}");
    }

    #[test]
    fn transfers_come_from_a_peer_with_sets_of_the_field() {
        let transfer = |from, red: Vec<u32>, rows: Vec<WireRow>| Transfer {
            trees: Vec::new(),
            components: Vec::new(),
            version: VERSION,
            from,
            seq: 3,
            sets: vec![WireSet {
                red,
                blue: vec![],
                ln_mass: 0.0,
            }],
            rows,
        };
        assert!(Bounds::of_tests()
            .check_transfer(&transfer(1, vec![3], vec![]), 0)
            .is_ok());
        for (t, expected) in [
            (transfer(0, vec![3], vec![]), "the receiver itself"),
            (transfer(5, vec![3], vec![]), "from = 5"),
            (transfer(1, vec![4], vec![]), "set 0 track = 4"),
            (
                transfer(
                    1,
                    vec![],
                    vec![WireRow {
                        track: 0,
                        ln_likelihoods: vec![0.0; 4],
                    }],
                ),
                "without identities",
            ),
        ] {
            let e = Bounds::of_tests()
                .check_transfer(&t, 0)
                .unwrap_err()
                .to_string();
            assert!(e.starts_with("transfer: ") && e.contains(expected), "{e}");
        }
        let identities = Bounds {
            identities: true,
            ..Bounds::of_tests()
        };
        let short_row = transfer(
            1,
            vec![],
            vec![WireRow {
                track: 2,
                ln_likelihoods: vec![0.0; 3],
            }],
        );
        let e = identities.check_transfer(&short_row, 0).unwrap_err();
        assert!(e.to_string().contains("3 numbers for 4 identities"), "{e}");
    }
}
