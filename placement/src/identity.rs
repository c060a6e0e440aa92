//! Where the factored identity belief starts on a stream whose leaders
//! hold it (`Begin::factored_identity`), and its trees on the wire: what
//! the leaders and the coordinator must agree on about it.

use crate::PlacementError;
use idmesh_belief::BeliefError;
use idmesh_identity::factored::{Background, Group, HeldTree, IdentityShare};
use idmesh_identity::FactoredIdentityOptions;
use idmesh_protocol::wire::identity::{WireBackground, WireGroup, WireTree};
use idmesh_protocol::wire::sensor_to_leader::Begin;

/// The options of the factored identity belief a `Begin` names.
pub fn identity_options(cap: u32) -> FactoredIdentityOptions {
    FactoredIdentityOptions {
        max_group: cap as usize,
        ..FactoredIdentityOptions::default()
    }
}

/// Leader `me`'s part of the factored identity belief at the start (None
/// where the leaders keep rows of the information matrix instead): every
/// track alone with its known identity, held by the leader surveilling
/// it or, unheld, by its keeper.
pub fn start_identity(begin: &Begin, me: u16) -> Result<Option<IdentityShare>, PlacementError> {
    let (Some(cap), Some(initial)) = (begin.factored_identity, &begin.initial_identity) else {
        return Ok(None);
    };
    let share = IdentityShare::start(initial, identity_options(cap), |t| {
        begin.holds_at_start(t, me)
    })?;
    Ok(Some(share))
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
    use idmesh_belief::event::Mix;
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
