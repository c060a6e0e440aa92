//! What each leader is sent, computed from a stream alone.
//!
//! Under the factored regional rule with shrinking interests a leader is
//! sent exactly the items on the tracks it surveils: a mix goes to the
//! leaders of both tracks, an observation or an identity read to the
//! track's, a handover to the old and the new one (docs/design/
//! architecture.md, "Components that stay in their region"). So the share
//! each leader gets follows from the stream and the region rule, which is
//! how `idmesh bench` and the tests check a rule's balance without a
//! deployment, and what a deployment's counters must then show.

use crate::regions::{Handover, RegionRule, Regions};
use idmesh_protocol::trace::Line;
use idmesh_protocol::wire::sensor_to_leader::UNHELD;

/// The items each of `leaders` leaders is sent by a stream of `lines` over
/// `tracks` tracks with regions by `rule` (the `Begin` and cuts, which
/// every leader gets, left out), as a sensor streaming them from a file
/// routes them: knowing the leading `move` lines ahead, so that the tracks
/// they place start with the leaders of their regions
/// ([`Regions::starting`]) rather than being handed over at the first
/// event.
pub fn items_sent<'a>(
    rule: &RegionRule,
    leaders: usize,
    tracks: usize,
    lines: impl IntoIterator<Item = &'a Line>,
) -> Vec<u64> {
    let lines: Vec<&Line> = lines.into_iter().collect();
    let leading = crate::leading_places(tracks, lines.iter().copied());
    let mut regions = Regions::starting(rule, leaders, tracks, &leading);
    let mut items = vec![0u64; leaders.max(1)];
    let known = |t: u32| (t as usize) < tracks;
    let handed = |items: &mut Vec<u64>, handovers: &[Handover]| {
        for h in handovers.iter().filter(|h| !h.rides) {
            items[usize::from(h.from)] += 1;
            items[usize::from(h.to)] += 1;
        }
    };
    for line in lines {
        let before = regions.before(line);
        handed(&mut items, &before);
        // A mix that takes a track is an item at the leader it leaves too
        // (an adoption leaves none).
        for h in before.iter().filter(|h| h.rides && h.from != UNHELD) {
            items[usize::from(h.from)] += 1;
        }
        let owner = |t: u32| usize::from(regions.owner(t).unwrap_or(0));
        match line {
            Line::Mix(m) if known(m.a) && known(m.b) => {
                let (a, b) = (owner(m.a), owner(m.b));
                items[a] += 1;
                if b != a {
                    items[b] += 1;
                }
            }
            Line::Observe(o) if known(o.track) => items[owner(o.track)] += 1,
            Line::Identify(r) if known(r.track) => items[owner(r.track)] += 1,
            _ => {}
        }
        let after = regions.after(line);
        handed(&mut items, &after);
    }
    items
}

/// The busiest leader's items over an even share of `single`, the items
/// one leader alone is sent: the scale-out figure the bench reports.
pub fn busiest_share(items: &[u64], single: u64) -> f64 {
    let busiest = items.iter().copied().max().unwrap_or(0) as f64;
    busiest * items.len() as f64 / single.max(1) as f64
}

/// A busiest share taken apart into its two causes, whose product it is:
/// how many items there are in all, and how unevenly they fall.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShareCauses {
    /// All the leaders' items over one leader's alone: above 1 by every
    /// mix across two leaders (an item at each) and every handover (an
    /// item at two), which no placement of few tracks a leader avoids.
    pub duplication: f64,
    /// The busiest leader's items over the leaders' mean: what placement
    /// decides.
    pub unevenness: f64,
}

/// The causes of [`busiest_share`]`(items, single)`.
pub fn share_causes(items: &[u64], single: u64) -> ShareCauses {
    let total: u64 = items.iter().sum();
    let busiest = items.iter().copied().max().unwrap_or(0) as f64;
    ShareCauses {
        duplication: total as f64 / single.max(1) as f64,
        unevenness: busiest * items.len() as f64 / total.max(1) as f64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_busiest_share_is_its_duplication_times_its_unevenness() {
        // Two leaders sent 6 and 4 items of a stream one leader alone is
        // sent 8 of: two items went to both.
        let causes = share_causes(&[6, 4], 8);
        assert_eq!(causes.duplication, 10.0 / 8.0);
        assert_eq!(causes.unevenness, 12.0 / 10.0);
        assert!((causes.duplication * causes.unevenness - busiest_share(&[6, 4], 8)).abs() < 1e-12);
        // Nothing sent: no division by zero.
        let none = share_causes(&[0, 0], 0);
        assert_eq!((none.duplication, none.unevenness), (0.0, 0.0));
    }

    #[test]
    fn tracks_placed_before_the_first_event_start_with_their_leaders() {
        use idmesh_protocol::trace::{Move, Observe};
        let at = |track, x| {
            Line::Move(Move {
                time: 0.0,
                track,
                x,
                y: 0.0,
            })
        };
        let seen = |track| {
            Line::Observe(Observe {
                time: 0.0,
                track,
                red: 0.8,
                blue: 0.2,
                sensor: None,
            })
        };
        // Tracks 0 and 1 start round robin with leaders 0 and 1 but stand
        // the other way round: a sensor that streams the file starts them
        // in their regions, so the two reads are one item each and no
        // handover is counted.
        let places = RegionRule::Fixed(vec![Some((0.0, 0.0)), Some((10.0, 0.0))]);
        let lines = [at(0, 9.0), at(1, 1.0), seen(0), seen(1)];
        assert_eq!(items_sent(&places, 2, 2, &lines), vec![1, 1]);
        // Placed only after the first event, track 0 is handed over (an
        // item at both leaders) and then read.
        let late = [seen(1), at(0, 9.0), seen(0)];
        assert_eq!(items_sent(&places, 2, 2, &late), vec![1, 3]);
    }
}
