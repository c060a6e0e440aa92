//! # idmesh-placement — who holds what, and how the parts add up
//!
//! Three processes must agree on the same few facts without talking, and
//! without depending on one another's process crates:
//! - at the stream's `Begin`, which leader holds which coefficient set and
//!   hence which tracks each leader follows (its [`Interest`]): the leader
//!   starts from its share ([`start`]), the sensor gateway routes the first
//!   items by the same interests ([`interests`]);
//! - the field a `Begin` describes (`idmesh_belief::field_of`, the same
//!   function `idmesh replay` reads a trace header with);
//! - how the leaders' partial sums at one cut add up to the answer
//!   ([`combine`]), which the coordinator computes;
//! - how the engines' values go on the wire and come back (`wire`): a
//!   factored component, an identity tree, a Radon set, an information
//!   row, the same for the leader that sends and the one (or the
//!   coordinator) that receives;
//! - which leader surveils each track as targets move ([`Regions`]: by
//!   default cells fitted to the crowd and redrawn as it moves, so that
//!   each leader is sent about as many items, [`Fitted`]), and the
//!   factored belief's regional rule that follows from it ([`Regional`]),
//!   run by the sensor, the leaders and `idmesh replay`.
//!
//! docs/design/architecture.md ("Who holds what", "Queries") says why the shares
//! add up: rollup and conditioning act on the Radon masses atom by atom and
//! linearly (Section 5.4 of the property-management paper).

mod fitted;
mod identity;
mod load;
mod regions;
mod wire;

// Which leader surveils each track: the regions, fitted to the crowd.
pub use fitted::{Fitted, TOLERANCE};
pub use regions::{grid_places, leading_places, Handover, RegionRule, Regional, Regions};
// The identity belief a deployment starts from.
pub use identity::{identity_options, start_identity};
// How evenly the leaders are loaded.
pub use load::{busiest_share, items_sent, share_causes, ShareCauses};
// Shares of the beliefs to and from their wire form.
pub use wire::{
    from_wire_component, from_wire_set, from_wire_tree, to_wire_component, to_wire_row,
    to_wire_set, to_wire_tree,
};

use idmesh_belief::FactoredShare;
use idmesh_belief::{field_of, BeliefError, Coupling, FactoredOptions, Field, RedCount, SplitRule};
use idmesh_belief::{PartialSums, RadonOptions, RadonShare};
use idmesh_protocol::wire::coordinator_to_leader::Partial;
use idmesh_protocol::wire::factored::{FactoredStart, WireSplit};
use idmesh_protocol::wire::interest::Interest;
use idmesh_protocol::wire::sensor_to_leader::{Begin, Item, UNHELD};

/// Why a share could not be placed.
#[derive(Debug, thiserror::Error)]
pub enum PlacementError {
    #[error(
        "a Begin whose owners ({owners}) do not match its {tracks} tracks and {leaders} leaders"
    )]
    Owners {
        owners: usize,
        tracks: u32,
        leaders: usize,
    },
    #[error(transparent)]
    Belief(#[from] BeliefError),
}

/// Leader `me`'s share of the start belief and its interest: each set
/// starts with the leader of its first track, φ_∅ with leader 0. The sensor
/// computes the same ([`interests`]) to route the first items.
pub fn start(begin: &Begin, me: u16) -> Result<(RadonShare, Interest), PlacementError> {
    let tracks = begin.tracks as usize;
    if begin.owners.len() != tracks
        || begin
            .owners
            .iter()
            .any(|&o| o as usize >= begin.leaders.len() && o != UNHELD)
        || (begin.owners.contains(&UNHELD) && !begin.factored.is_some_and(|f| f.regional))
    {
        return Err(PlacementError::Owners {
            owners: begin.owners.len(),
            tracks: begin.tracks,
            leaders: begin.leaders.len(),
        });
    }
    let options = RadonOptions {
        distributed_rule: begin.distributed_rule,
        ..RadonOptions::default()
    };
    let mut share = RadonShare::start(field_of(begin), &options)?;
    if let Some(factored) = &begin.factored {
        // The leader holds components instead ([`start_factored`]); it
        // starts following its own tracks, the tracks of its components.
        share.extract(|_| true);
        let mut interest = Interest::new(me, tracks, false);
        if factored.follows_regions() {
            interest = interest.of_region();
        } else if factored.shrink {
            interest = interest.fixed();
        }
        if begin.factored_identity.is_some() {
            interest = interest.reading_trees();
        }
        interest.note(&Item::Begin(begin.clone()));
        return Ok((share, interest));
    }
    let owners = &begin.owners;
    share.extract(|atom| atom.tracks().min().map(|t| owners[t as usize]).unwrap_or(0) != me);
    let holds_empty = share.atoms().any(|(a, _)| a.tracks().next().is_none());
    let mut interest =
        Interest::new(me, tracks, holds_empty).saturating_at(saturation(&field_of(begin)));
    for (atom, _) in share.atoms() {
        for t in atom.tracks() {
            interest.add(t);
        }
    }
    interest.note(&Item::Begin(begin.clone()));
    Ok((share, interest))
}

/// The count coupling of the factored belief's splits: the best their
/// holders can compute. One holder of the whole belief (a deployment of
/// one leader, or of a crowd small enough to be held whole:
/// [`FactoredStart::whole`]) weighs by all of it (the coupled rule, what
/// `idmesh replay` runs by default); each of several leaders sharing it
/// runs the local rule, which needs nothing beyond the components an
/// event touches (what `idmesh replay --leaders N` runs on a crowd it
/// spreads). docs/design/beliefs.md, "Who weighs a split", says why and
/// what each costs.
pub fn split_coupling(whole: bool) -> Coupling {
    match whole {
        true => Coupling::Coupled,
        false => Coupling::Local,
    }
}

/// The factored belief's options a `Begin`'s settings name, held `whole`
/// or shared (its coupling: [`split_coupling`]).
pub fn factored_options(start: &FactoredStart, whole: bool) -> FactoredOptions {
    FactoredOptions {
        max_component: start.max_component as usize,
        split: match start.split {
            WireSplit::Original => SplitRule::Original,
            WireSplit::Recent => SplitRule::Recent,
            WireSplit::LeastLoss { rounds } => SplitRule::LeastLoss {
                rounds: rounds as usize,
            },
        },
        coupling: split_coupling(whole),
        ..FactoredOptions::default()
    }
}

/// Leader `me`'s components at the start of a factored stream (None on a
/// Radon stream): every track alone, each held by the leader surveilling
/// it, or, unheld, by its keeper ([`Begin::keeper`]) as a passive one.
pub fn start_factored(begin: &Begin, me: u16) -> Result<Option<FactoredShare>, PlacementError> {
    let Some(settings) = &begin.factored else {
        return Ok(None);
    };
    // Held whole, the first leader holds every track and the others none.
    let options = factored_options(settings, begin.held_whole() && me == 0);
    let share = FactoredShare::start(field_of(begin), options, |t| begin.holds_at_start(t, me))?;
    Ok(Some(share))
}

/// The size of a set that fixes every track of `field`: k red tracks (the
/// others are blue) or n − k blue ones; with a prior over counts, the
/// largest count allowed or n − the smallest.
pub(crate) fn saturation(field: &Field) -> usize {
    let n = field.tracks;
    match &field.red {
        RedCount::Known(k) => (*k).min(n - k.min(&n)),
        RedCount::Unknown { prior } => {
            let most = prior.iter().rposition(|&p| p > 0.0).unwrap_or(n);
            let least = prior.iter().position(|&p| p > 0.0).unwrap_or(0);
            most.min(n.saturating_sub(least))
        }
    }
}

/// Every leader's interest at the `Begin`, in the stream's order.
pub fn interests(begin: &Begin) -> Result<Vec<Interest>, PlacementError> {
    (0..begin.leaders.len())
        .map(|me| start(begin, me as u16).map(|(_, interest)| interest))
        .collect()
}

/// The answer to a query from every leader's partial sums.
pub fn combine(parts: &[Partial]) -> PartialSums {
    let sums: Vec<PartialSums> = parts
        .iter()
        .map(|p| PartialSums {
            log_scale: p.log_scale,
            total: p.total,
            outside: p.outside,
            inside: p.inside.clone(),
            coefficients: p.coefficients,
        })
        .collect();
    PartialSums::combine(&sums)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn begin(leaders: usize, owners: Vec<u16>, red: Option<u32>) -> Begin {
        Begin {
            factored_identity: None,
            factored: None,
            tracks: owners.len() as u32,
            red,
            initial_red: None,
            leaders: (0..leaders).map(|l| format!("leader-{l}")).collect(),
            owners,
            distributed_rule: true,
            budget: 0,
            omp: false,
            identities: false,
            initial_identity: None,
        }
    }

    /// The shares of every leader add up to the whole start belief, and
    /// each leader follows exactly the tracks of its sets.
    #[test]
    fn the_start_shares_add_up_to_the_start_belief() {
        let begin = begin(3, vec![0, 1, 2, 0, 1], Some(2));
        let whole = RadonShare::start(field_of(&begin), &RadonOptions::default()).unwrap();
        let mut parts = Vec::new();
        for me in 0..3u16 {
            let (share, interest) = start(&begin, me).unwrap();
            for (atom, _) in share.atoms() {
                assert!(atom.tracks().all(|t| interest.follows(t)));
                assert_eq!(begin.owners[atom.tracks().min().unwrap() as usize], me);
            }
            parts.push(share.partial_sums());
        }
        let sum = PartialSums::combine(&parts).marginals(5).unwrap();
        let want = whole.partial_sums().marginals(5).unwrap();
        for (a, b) in sum.iter().zip(&want) {
            assert!((a - b).abs() < 1e-12, "{sum:?} vs {want:?}");
        }
        assert!((sum.iter().sum::<f64>() - 2.0).abs() < 1e-12);
        assert_eq!(interests(&begin).unwrap().len(), 3);
    }

    #[test]
    fn owners_that_do_not_fit_are_refused_by_name() {
        let bad = begin(2, vec![0, 2], Some(1));
        let e = start(&bad, 0).unwrap_err().to_string();
        assert!(e.contains("2 tracks and 2 leaders"), "{e}");
    }

    #[test]
    fn an_unknown_count_means_the_uniform_prior_over_counts() {
        let b = begin(1, vec![0, 0, 0], None);
        assert_eq!(field_of(&b).red, RedCount::unknown_uniform(3));
        let (share, interest) = start(&b, 0).unwrap();
        assert!(share.atoms().any(|(a, _)| a.tracks().next().is_none()));
        assert_eq!(interest.len(), 3);
    }
}
