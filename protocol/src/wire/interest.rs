//! Who receives which item of the event stream. Part of the wire contract:
//! the sensor routes with it and each leader keeps the same record of what
//! it is sent, so both agree without talking.
//!
//! A leader's *interest* is every track that may appear in one of its sets,
//! its own tracks among them. It receives an item when the item may change
//! one of its sets; the sets an item creates only add the item's tracks to
//! the interest (a mix moves a set from a to b; an observation of t grows
//! sets into sets with t). Sets that arrive from another leader may carry
//! tracks beyond it: the receiver then asks the sensor to follow them
//! ([`leader_to_sensor`](super::leader_to_sensor)). On a Radon stream an
//! interest only grows; pruning can leave it larger than the sets need,
//! which costs traffic, not correctness.
//!
//! On a factored stream ([`Interest::fixed`]) no item grows it: a leader
//! needs exactly the tracks it surveils and the tracks of the components
//! it holds, so its interest changes only by the `Begin`, handovers, and
//! its own follow and unfollow requests. That is what lets it shrink: a
//! leader that sent a component away unfollows its tracks, and a crowd
//! that mixes everything with everything does not end with every leader
//! following every track. Under the regional rule a leader follows exactly
//! its region ([`Interest::of_region`]): a handover away ends the interest
//! in the track, with no request.

use super::sensor_to_leader::{Growth, Item};

#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Interest {
    leader: u16,
    follows: Vec<bool>,
    count: usize,
    /// This leader holds φ_∅ (k unknown under the distributed rule): every
    /// observation grows it.
    holds_empty: bool,
    /// Following this many tracks, the leader may hold a *saturated* set:
    /// k red tracks (the rest are then blue) or n − k blue ones. Such a
    /// set fixes every track, so an observation of any track changes it
    /// (conditioning multiplies it by the likelihood of its implicit
    /// colour), whatever the distributed rule says of growth.
    saturation: usize,
    /// Whether mixes and observations grow the interest (a Radon stream),
    /// or only the `Begin`, handovers and requests do (a factored one).
    grows: bool,
    /// Whether the interest is the leader's region: a handover away ends
    /// it ([`Interest::of_region`]).
    region: bool,
    /// Whether a read reaches every leader following its track, not only
    /// the track's owner: the leaders hold the factored identity belief,
    /// whose trees lie with the leader that last mixed them
    /// ([`Interest::reading_trees`]).
    reads_follow: bool,
}

impl Interest {
    pub fn new(leader: u16, tracks: usize, holds_empty: bool) -> Self {
        Interest {
            leader,
            follows: vec![false; tracks],
            count: 0,
            holds_empty,
            saturation: usize::MAX,
            grows: true,
            region: false,
            reads_follow: false,
        }
    }

    /// The same interest for a factored stream: no mix or observation
    /// grows it (see the module docs).
    pub fn fixed(mut self) -> Self {
        self.grows = false;
        self
    }

    /// The same fixed interest for a leader that follows exactly the
    /// tracks it surveils
    /// ([`FactoredStart::follows_regions`](super::factored::FactoredStart::follows_regions)):
    /// a handover away is the last item on the track the leader needs, so
    /// it ends the interest there, on the sensor's side and the leader's
    /// alike, with no unfollow request.
    pub fn of_region(mut self) -> Self {
        self.grows = false;
        self.region = true;
        self
    }

    /// The same interest on a stream whose leaders hold the factored
    /// identity belief: the holder of a track's tree follows the track,
    /// wherever it is surveilled, and must hear its reads.
    pub fn reading_trees(mut self) -> Self {
        self.reads_follow = true;
        self
    }

    /// Whether items grow this interest (false on a factored stream).
    pub fn grows(&self) -> bool {
        self.grows
    }

    /// The same interest for a field where sets of `size` tracks may fix
    /// every track: min(k, n − k) with k known; with a prior over counts,
    /// min(largest count, n − smallest count).
    pub fn saturating_at(mut self, size: usize) -> Self {
        self.saturation = size;
        self
    }

    /// Whether the leader may hold a set that fixes every track.
    pub fn saturated(&self) -> bool {
        self.count >= self.saturation
    }

    pub fn follows(&self, track: u32) -> bool {
        self.follows.get(track as usize).copied().unwrap_or(false)
    }

    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Adds a track; false if it was already followed or is out of range.
    pub fn add(&mut self, track: u32) -> bool {
        match self.follows.get_mut(track as usize) {
            Some(slot) if !*slot => {
                *slot = true;
                self.count += 1;
                true
            }
            _ => false,
        }
    }

    /// Drops a track; false if it was not followed.
    pub fn remove(&mut self, track: u32) -> bool {
        match self.follows.get_mut(track as usize) {
            Some(slot) if *slot => {
                *slot = false;
                self.count -= 1;
                true
            }
            _ => false,
        }
    }

    /// The followed tracks, in order.
    pub fn tracks(&self) -> impl Iterator<Item = u32> + '_ {
        self.follows
            .iter()
            .enumerate()
            .filter(|x| *x.1)
            .map(|x| x.0 as u32)
    }

    fn meets(&self, tracks: &[u32]) -> bool {
        tracks.iter().any(|&t| self.follows(t))
    }

    /// Whether this leader is sent `item`: the item may change one of its
    /// sets, or adopts a track here.
    pub fn receives(&self, item: &Item) -> bool {
        if item.adoptions().iter().any(|&(_, l)| l == self.leader) {
            return true;
        }
        match item {
            Item::Begin(_) | Item::Cut { .. } => true,
            Item::Mix {
                a, b, handed: None, ..
            } => self.follows(*a) || self.follows(*b),
            Item::Mix {
                a,
                b,
                handed: Some(handed),
                ..
            } => self.follows(*a) || self.follows(*b) || handed.from == self.leader,
            Item::Observe {
                track,
                growth,
                global,
                ..
            } => {
                *global
                    || self.holds_empty
                    || self.saturated()
                    || self.follows(*track)
                    || matches!(growth, Growth::Meeting(p) if self.meets(p))
            }
            Item::Handover { from, to, .. } => *from == self.leader || *to == self.leader,
            Item::Identify { owner, track, .. } => {
                *owner == self.leader || (self.reads_follow && self.follows(*track))
            }
        }
    }

    /// Grows the interest by what `item` may add to this leader's sets.
    /// Call for every item this leader receives, in seq order.
    pub fn note(&mut self, item: &Item) {
        // A track adopted here is this leader's from now on.
        for (track, leader) in item.adoptions() {
            if leader == self.leader {
                self.add(track);
            }
        }
        match item {
            Item::Begin(begin) => {
                for (t, &owner) in begin.owners.iter().enumerate() {
                    if owner == self.leader {
                        self.add(t as u32);
                    }
                }
            }
            Item::Mix {
                handed: Some(handed),
                owner_a,
                ..
            } => {
                // The handover riding on the mix, as `Item::Handover`.
                if *owner_a == self.leader {
                    self.add(handed.track);
                } else if handed.from == self.leader && self.region && !self.reads_follow {
                    self.remove(handed.track);
                }
            }
            Item::Mix { .. } | Item::Observe { .. } if !self.grows => {}
            Item::Mix { a, b, .. } => {
                if self.follows(*a) || self.follows(*b) {
                    self.add(*a);
                    self.add(*b);
                }
            }
            Item::Observe { track, growth, .. } => {
                let grows = match growth {
                    Growth::All => true,
                    Growth::Meeting(p) => self.holds_empty || self.meets(p),
                };
                if grows {
                    self.add(*track);
                }
            }
            Item::Handover { track, from, to } => {
                if *to == self.leader {
                    self.add(*track);
                } else if *from == self.leader && self.region && !self.reads_follow {
                    self.remove(*track);
                }
            }
            // A read changes one row of the information matrix, no set.
            Item::Cut { .. } | Item::Identify { .. } => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mix(a: u32, b: u32) -> Item {
        Item::Mix {
            adopted: Vec::new(),
            a,
            b,
            swap: 0.5,
            owner_a: 0,
            owner_b: 0,
            handed: None,
        }
    }

    #[test]
    fn a_mix_reaches_followers_of_either_track_and_spreads_interest() {
        let mut i = Interest::new(1, 6, false);
        i.add(2);
        assert!(!i.receives(&mix(0, 1)));
        assert!(i.receives(&mix(2, 5)));
        i.note(&mix(2, 5));
        assert!(i.follows(5) && i.len() == 2);
        i.note(&mix(0, 1));
        assert!(!i.follows(0));
    }

    #[test]
    fn the_distributed_rule_reaches_holders_of_the_mixing_log() {
        let mut i = Interest::new(0, 6, false);
        i.add(4);
        let observe = |track, partners: Vec<u32>| Item::Observe {
            adopted_by: None,
            track,
            red: 0.8,
            blue: 0.2,
            growth: Growth::Meeting(partners),
            global: false,
        };
        assert!(!i.receives(&observe(1, vec![2, 3])));
        assert!(i.receives(&observe(1, vec![4])));
        i.note(&observe(1, vec![4]));
        assert!(i.follows(1));
    }

    #[test]
    fn a_fixed_interest_is_not_grown_by_items_and_can_shrink() {
        let mut i = Interest::new(0, 6, false).fixed();
        i.add(2);
        assert!(i.receives(&mix(2, 5)));
        i.note(&mix(2, 5));
        assert!(!i.follows(5) && i.len() == 1);
        i.note(&Item::Handover {
            track: 4,
            from: 1,
            to: 0,
        });
        assert!(i.follows(4) && i.len() == 2);
        assert!(i.remove(2) && !i.remove(2));
        assert!(!i.follows(2) && i.len() == 1);
        // A handover away leaves a fixed interest as it was (the leader
        // asks to unfollow); an interest of a region drops the track.
        let away = Item::Handover {
            track: 4,
            from: 0,
            to: 1,
        };
        i.note(&away);
        assert!(i.follows(4));
        let mut region = Interest::new(0, 6, false).of_region();
        region.note(&Item::Handover {
            track: 4,
            from: 1,
            to: 0,
        });
        assert!(!region.grows() && region.follows(4));
        assert!(region.receives(&away));
        region.note(&away);
        assert!(!region.follows(4) && region.is_empty());
    }

    /// With k = 2 of 6, a leader following two tracks may hold {a, b} red,
    /// which says every other track is blue: every observation changes it.
    #[test]
    fn a_leader_that_may_hold_a_saturated_set_hears_every_observation() {
        let mut i = Interest::new(0, 6, false).saturating_at(2);
        let far = Item::Observe {
            adopted_by: None,
            track: 5,
            red: 0.8,
            blue: 0.2,
            growth: Growth::Meeting(vec![3]),
            global: false,
        };
        i.add(0);
        assert!(!i.saturated() && !i.receives(&far));
        i.add(1);
        assert!(i.saturated() && i.receives(&far));
        // It is not grown by it: a saturated set fixes 5 already.
        i.note(&far);
        assert!(!i.follows(5));
    }
}
