//! The engines' values on the wire and back: one place for every
//! conversion between a belief's own form and its message form, so that
//! the leader that sends, the leader that receives and the coordinator
//! read them alike. A value from the wire is checked here only as far as
//! its own shape goes (its ranks and probabilities pair up, its tracks
//! exist); the share that takes it checks that it fits what it holds.

use idmesh_belief::Atom;
use idmesh_belief::HeldComponent;
use idmesh_belief::{BeliefError, TrackSet};
use idmesh_identity::factored::{Background, Group, HeldTree};
use idmesh_protocol::wire::factored::WireComponent;
use idmesh_protocol::wire::identity::{WireBackground, WireGroup, WireTree};
use idmesh_protocol::wire::leader_to_leader::{WireRow, WireSet};

/// A component as it goes on the wire.
pub fn to_wire_component(c: HeldComponent) -> WireComponent {
    WireComponent {
        tracks: c.tracks,
        table: c.table,
        log_scale: c.log_scale,
        last_mix: c.last_mix,
    }
}

/// A component from the wire (checked again by the share that takes it).
pub fn from_wire_component(c: WireComponent) -> HeldComponent {
    HeldComponent {
        tracks: c.tracks,
        table: c.table,
        log_scale: c.log_scale,
        last_mix: c.last_mix,
    }
}

/// A coefficient set of the Radon belief (its atom and log mass) as it
/// goes on the wire.
pub fn to_wire_set(atom: &Atom, ln_mass: f64) -> WireSet {
    WireSet {
        red: atom.red.tracks().to_vec(),
        blue: atom.blue.tracks().to_vec(),
        ln_mass,
    }
}

/// A coefficient set from the wire, on a stream of `tracks` tracks: its
/// tracks must exist and its log mass be a number below +∞.
pub fn from_wire_set(set: &WireSet, tracks: u32) -> Result<(Atom, f64), String> {
    if let Some(&t) = set.red.iter().chain(&set.blue).find(|&&t| t >= tracks) {
        return Err(format!("set with track {t} of {tracks}"));
    }
    if set.ln_mass.is_nan() || set.ln_mass == f64::INFINITY {
        return Err(format!("set with log mass {}", set.ln_mass));
    }
    let atom = Atom::new(
        TrackSet::from_tracks(set.red.iter().copied()),
        TrackSet::from_tracks(set.blue.iter().copied()),
    );
    Ok((atom, set.ln_mass))
}

/// Row `track` of the information matrix as it goes on the wire.
pub fn to_wire_row(track: u32, row: &[f64]) -> WireRow {
    WireRow {
        track,
        ln_likelihoods: row.to_vec(),
    }
}

/// A tree as it goes on the wire.
pub fn to_wire_tree(tree: HeldTree) -> WireTree {
    WireTree {
        groups: tree
            .groups
            .iter()
            .map(|g| {
                let (ranks, probs) = g.entries().unzip();
                WireGroup {
                    tracks: g.tracks().to_vec(),
                    identities: g.identities().to_vec(),
                    ranks,
                    probs,
                }
            })
            .collect(),
        backgrounds: tree
            .backgrounds
            .iter()
            .map(|(track, b)| WireBackground {
                track: *track,
                leak: b.leak(),
                shared: b.shared(),
                listed: b.listed_entries().collect(),
            })
            .collect(),
    }
}

/// A tree from the wire, its groups and rows checked (the share that takes
/// it checks that it fits).
pub fn from_wire_tree(tree: WireTree) -> Result<HeldTree, BeliefError> {
    let groups = tree
        .groups
        .into_iter()
        .map(|g| {
            if g.ranks.len() != g.probs.len() {
                return Err(BeliefError::BadComponent {
                    detail: format!(
                        "{} ranks and {} probabilities",
                        g.ranks.len(),
                        g.probs.len()
                    ),
                });
            }
            let entries = g.ranks.into_iter().zip(g.probs).collect();
            Group::from_parts(g.tracks, g.identities, entries)
        })
        .collect::<Result<Vec<_>, _>>()?;
    let backgrounds = tree
        .backgrounds
        .into_iter()
        .map(|b| Ok((b.track, Background::from_parts(b.leak, b.shared, b.listed)?)))
        .collect::<Result<Vec<_>, BeliefError>>()?;
    Ok(HeldTree {
        groups,
        backgrounds,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identity_options;
    use idmesh_belief::Mix;
    use idmesh_identity::factored::IdentityShare;
    use idmesh_identity::IdentityEvent;

    #[test]
    fn a_tree_crosses_the_wire_unchanged() {
        let options = identity_options(9);
        let mut share = IdentityShare::start(&[2, 0, 1, 3], options, |_| true).unwrap();
        for (a, b) in [(0, 1), (1, 2)] {
            share
                .apply(&IdentityEvent::Mix(Mix { a, b, swap: 0.3 }))
                .unwrap();
        }
        let tree = share.take(2).unwrap();
        let wire = to_wire_tree(tree.clone());
        assert_eq!(wire.check(4), Ok(()));
        assert_eq!(wire.tracks(4).collect::<Vec<_>>(), vec![0, 1, 2]);
        assert_eq!(from_wire_tree(wire.clone()).unwrap(), tree);
        // Only the assignments of non-zero probability travel.
        let dense: usize = tree.groups.iter().map(Group::assignments).sum();
        let nonzero: usize = tree.groups.iter().map(Group::support).sum();
        // Mixes of 0 with 1, then of 1 with 2: 4 of the 3! assignments.
        assert_eq!((wire.entries(), nonzero, dense), (4, 4, 6));
        let mut bad = wire;
        bad.groups[0].probs[0] += 0.5;
        assert!(from_wire_tree(bad).is_err(), "probabilities summing to 1.5");
    }
}
