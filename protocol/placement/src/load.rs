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

/// The items each of `leaders` leaders is sent by a stream of `lines` over
/// `tracks` tracks with regions by `rule` (the `Begin` and cuts, which
/// every leader gets, left out).
pub fn items_sent<'a>(
    rule: &RegionRule,
    leaders: usize,
    tracks: usize,
    lines: impl IntoIterator<Item = &'a Line>,
) -> Vec<u64> {
    let mut regions = Regions::new(rule, leaders, tracks);
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
        // A mix that takes a track is an item at the leader it leaves too.
        for h in before.iter().filter(|h| h.rides) {
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
