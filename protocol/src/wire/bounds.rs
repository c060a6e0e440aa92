//! What a message must be to belong to a stream: every track below the n
//! of the stream's `Begin`, every leader index below the number of its
//! leaders, identity reads and rows only on an identity stream. A leader
//! knows these from its `Begin`, so it checks them at its door, before an
//! input is journaled or applied; the coordinator knows n from the cut.
//! The rules a message obeys on its own are [`valid`](super::valid)'s.

use super::coordinator_to_leader::Partial;
use super::identity::WireTree;
use super::leader_to_leader::{Transfer, WireRow, WireSet};
use super::sensor_to_leader::{Batch, Begin, Growth, Item, Sequenced};
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
    pub fn of(begin: &Begin) -> Self {
        Bounds {
            tracks: begin.tracks,
            leaders: begin.leaders.len(),
            identities: begin.identities,
            adopts: begin.factored.as_ref().is_some_and(|f| f.regional),
        }
    }

    fn track(&self, what: &str, track: u32) -> Result<(), String> {
        let n = self.tracks;
        require(track < n, || {
            format!("{what} = {track} is not a track (there are {n})")
        })
    }

    fn leader(&self, what: &str, index: u16) -> Result<(), String> {
        let l = self.leaders;
        require((index as usize) < l, || {
            format!("{what} = {index} is not a leader (there are {l})")
        })
    }

    /// One item of the stream against the field.
    pub fn check_item(&self, item: &Item) -> Result<(), String> {
        let adoptions = item.adoptions();
        require(adoptions.is_empty() || self.adopts, || {
            "an adoption on a stream whose tracks start held".into()
        })?;
        for (track, leader) in adoptions {
            self.leader(&format!("the adopter of track {track}"), leader)?;
        }
        match item {
            // Checked on its own; a second one is refused by the batch rules.
            Item::Begin(_) | Item::Cut { .. } => Ok(()),
            Item::Mix {
                a,
                b,
                owner_a,
                owner_b,
                handed,
                ..
            } => {
                self.track("mix a", *a)?;
                self.track("mix b", *b)?;
                self.leader("mix owner_a", *owner_a)?;
                if let Some(h) = handed {
                    self.leader("mix handed from", h.from)?;
                }
                self.leader("mix owner_b", *owner_b)
            }
            Item::Observe { track, growth, .. } => {
                self.track("observe track", *track)?;
                if let Growth::Meeting(tracks) = growth {
                    for &t in tracks {
                        self.track("observe growth track", t)?;
                    }
                }
                Ok(())
            }
            Item::Identify {
                track,
                identity,
                owner,
                ..
            } => {
                require(self.identities, || {
                    "an identity read on a stream without identities".into()
                })?;
                self.track("identify track", *track)?;
                self.track("identify identity", *identity)?;
                self.leader("identify owner", *owner)
            }
            Item::Handover { track, from, to } => {
                self.track("handover track", *track)?;
                self.leader("handover from", *from)?;
                self.leader("handover to", *to)
            }
        }
    }

    fn check_items(&self, items: &[Sequenced]) -> Result<(), String> {
        for (i, Sequenced { seq, item }) in items.iter().enumerate() {
            self.check_item(item)
                .map_err(|e| format!("item {i} (seq {seq}): {e}"))?;
        }
        Ok(())
    }

    /// A batch of this stream (a Begin it carries is the stream's own).
    pub fn check_batch(&self, batch: &Batch) -> Result<(), WireError> {
        self.check_items(&batch.items)
            .map_err(|problem| invalid("event batch", problem))
    }

    /// The items of a follow reply.
    pub fn check_followed(&self, items: &[Sequenced]) -> Result<(), WireError> {
        self.check_items(items)
            .map_err(|problem| invalid("follow reply", problem))
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

fn invalid(what: &'static str, problem: String) -> WireError {
    WireError::Invalid { what, problem }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::VERSION;

    fn bounds() -> Bounds {
        Bounds {
            tracks: 4,
            leaders: 2,
            identities: false,
            adopts: false,
        }
    }

    #[test]
    fn tracks_and_leaders_beyond_the_stream_are_named() {
        let e = bounds()
            .check_item(&Item::Mix {
                adopted: Vec::new(),
                a: 0,
                b: 4,
                swap: 0.5,
                owner_a: 0,
                owner_b: 1,
                handed: None,
            })
            .unwrap_err();
        assert_eq!(e, "mix b = 4 is not a track (there are 4)");
        let e = bounds()
            .check_item(&Item::Handover {
                track: 1,
                from: 0,
                to: 7,
            })
            .unwrap_err();
        assert_eq!(e, "handover to = 7 is not a leader (there are 2)");
        let e = bounds()
            .check_item(&Item::Observe {
                adopted_by: None,
                track: 1,
                red: 0.5,
                blue: 0.5,
                growth: Growth::Meeting(vec![2, 40]),
                global: false,
            })
            .unwrap_err();
        assert!(e.contains("growth track = 40"), "{e}");
        let e = bounds()
            .check_item(&Item::Identify {
                adopted: false,
                track: 1,
                identity: 1,
                accuracy: 0.9,
                owner: 0,
            })
            .unwrap_err();
        assert!(e.contains("without identities"), "{e}");
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
        assert!(bounds()
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
            let e = bounds().check_transfer(&t, 0).unwrap_err().to_string();
            assert!(e.starts_with("transfer: ") && e.contains(expected), "{e}");
        }
        let identities = Bounds {
            identities: true,
            ..bounds()
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
