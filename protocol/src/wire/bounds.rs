//! What a message must be to belong to a stream: every track below the n
//! of the stream's `Begin`, every leader index below the number of its
//! leaders, identity reads and rows only on an identity stream. A leader
//! knows these from its `Begin`, so it checks them at its door, before an
//! input is journaled or applied; the coordinator knows n from the cut.
//! The rules a message obeys on its own are [`valid`](super::valid)'s.

use super::coordinator_to_leader::Partial;
use super::identity::WireTree;
use super::leader_to_leader::{Transfer, WireRow, WireSet};
use super::valid::require;
use super::WireError;

/// The size of a stream's field, from its `Begin`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bounds {
    /// n: tracks are `0..tracks` (identities too, on an identity stream).
    pub tracks: u32,
    /// L: leader indices are `0..leaders`.
    pub leaders: usize,
    pub identities: bool,
    /// Tracks may start unheld and be adopted ([`super::sensor_to_leader::UNHELD`]): a factored
    /// stream under the regional rule.
    pub adopts: bool,
}

impl Bounds {
    pub(crate) fn track(&self, what: &str, track: u32) -> Result<(), String> {
        let n = self.tracks;
        require(track < n, || {
            format!("{what} = {track} is not a track (there are {n})")
        })
    }

    pub(crate) fn leader(&self, what: &str, index: u16) -> Result<(), String> {
        let l = self.leaders;
        require((index as usize) < l, || {
            format!("{what} = {index} is not a leader (there are {l})")
        })
    }

    /// A transfer to leader `me`: from another leader of the stream, sets
    /// of its tracks, rows of n numbers only on an identity stream.
    pub fn check_transfer(&self, transfer: &Transfer, me: u16) -> Result<(), WireError> {
        self.check_parts(transfer.from, &transfer.sets, &transfer.rows, me)
            .and_then(|()| self.check_trees(&transfer.trees))
            .map_err(|problem| invalid("transfer", problem))
    }

    /// [`Bounds::check_transfer`] on a transfer kept in parts.
    pub fn check_parts(
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

    /// Trees of the factored identity belief, on an identity stream only.
    fn check_trees(&self, trees: &[WireTree]) -> Result<(), String> {
        require(trees.is_empty() || self.identities, || {
            "trees of a factored identity belief on a stream without identities".into()
        })?;
        for (i, tree) in trees.iter().enumerate() {
            tree.check(self.tracks)
                .map_err(|e| format!("tree {i}: {e}"))?;
        }
        Ok(())
    }

    fn check_rows(&self, rows: &[WireRow]) -> Result<(), String> {
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

    /// A leader's partial sums for a query about this field.
    pub fn check_partial(&self, partial: &Partial) -> Result<(), WireError> {
        let check = || -> Result<(), String> {
            for &(t, _) in &partial.inside {
                self.track("inside track", t)?;
            }
            for &t in &partial.gone {
                self.track("gone component's track", t)?;
            }
            self.check_rows(&partial.rows)?;
            self.check_trees(&partial.trees)
        };
        check().map_err(|problem| invalid("partial sums", problem))
    }
}

pub(crate) fn invalid(what: &'static str, problem: String) -> WireError {
    WireError::Invalid { what, problem }
}

/// The field the tests of every message's bounds share: 4 tracks, 2
/// leaders, no identities, tracks held from the start.
#[cfg(test)]
impl Bounds {
    pub(crate) fn of_tests() -> Self {
        Bounds {
            tracks: 4,
            leaders: 2,
            identities: false,
            adopts: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::VERSION;

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
