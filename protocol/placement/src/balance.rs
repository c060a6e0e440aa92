//! Placing leaders so that each is sent about as many items.
//!
//! Under the factored regional rule with shrinking interests a leader is
//! sent exactly the items on the tracks it surveils (a mix goes to the
//! leaders of both tracks, a handover to the old and the new one), so what
//! each leader applies follows from the leaders' places and the stream
//! alone ([`Workload::items`]). Places that share out a crowd's positions
//! evenly (k-means) do not share out its items: a denser crowd meets more
//! often, so the leaders in the middle of it are sent most (on a
//! 1,000-target crowd through 8 leaders the busiest was sent 1.8× an even
//! share of what one leader applies, 1.37× the leaders' mean; after
//! balancing, 1.39× and 1.03×). [`balanced`]
//! moves the places until no leader is sent much more than the others,
//! counting the handovers that moving a border makes or saves.
//! docs/design/architecture.md ("Components that stay in their region") says why
//! the routing is exact.

use crate::regions::Leading;
use crate::Regions;
use idmesh_protocol::trace::Line;

/// A stream's events as they load leaders: where the leading `move` lines
/// place each track, then every event that routes an item or may move a
/// track to another region.
#[derive(Debug, Clone)]
pub struct Workload {
    tracks: usize,
    /// Where the leading moves place tracks (the sensor's start).
    leading: Leading,
    events: Vec<Load>,
}

#[derive(Debug, Clone, Copy)]
enum Load {
    Move {
        track: u32,
        x: f64,
        y: f64,
    },
    /// A mix: an item for the leaders of both tracks.
    Pair {
        a: u32,
        b: u32,
    },
    /// An observation or an identity read: an item for the track's leader.
    One {
        track: u32,
    },
}

impl Workload {
    /// An empty workload over `tracks` tracks.
    pub fn new(tracks: usize) -> Self {
        Workload {
            tracks,
            leading: Leading::new(tracks),
            events: Vec::new(),
        }
    }

    /// Takes the stream's next line (header and truth lines load nobody;
    /// lines on tracks beyond the header's are left out, as the sensor
    /// refuses them).
    pub fn push(&mut self, line: &Line) {
        if self.leading.take(line) {
            return;
        }
        let known = |t: u32| (t as usize) < self.tracks;
        let load = match line {
            Line::Move(m) => Load::Move {
                track: m.track,
                x: m.x,
                y: m.y,
            },
            Line::Mix(mix) => Load::Pair { a: mix.a, b: mix.b },
            Line::Observe(o) => Load::One { track: o.track },
            Line::Identify(read) => Load::One { track: read.track },
            Line::Header(_) | Line::Truth(_) => return,
        };
        let fits = match load {
            Load::Move { track, .. } | Load::One { track } => known(track),
            Load::Pair { a, b } => known(a) && known(b),
        };
        if fits {
            self.events.push(load);
        }
    }

    /// The items each leader at `places` would be sent (the `Begin` and
    /// cuts, which every leader gets, left out).
    pub fn items(&self, places: &[(f64, f64)]) -> Vec<u64> {
        let at: Vec<_> = places.iter().map(|&p| Some(p)).collect();
        let mut regions = Regions::starting(&at, self.tracks, &self.leading.places);
        let mut items = vec![0u64; places.len().max(1)];
        let owner = |regions: &Regions, t: u32| regions.owner(t).unwrap_or(0) as usize;
        for load in &self.events {
            match *load {
                Load::Move { track, x, y } => {
                    if let Some((from, to)) = regions.moved(track, x, y) {
                        items[from as usize] += 1;
                        items[to as usize] += 1;
                    }
                }
                Load::Pair { a, b } => {
                    let (a, b) = (owner(&regions, a), owner(&regions, b));
                    items[a] += 1;
                    if b != a {
                        items[b] += 1;
                    }
                }
                Load::One { track } => items[owner(&regions, track)] += 1,
            }
        }
        items
    }
}

/// How far a balancing round moves a place at first, as a fraction of the
/// places' spread, and how many times that step may halve.
const FIRST_STEP: f64 = 1.0 / 8.0;
const HALVINGS: u32 = 6;
/// Rounds at most: a round moves one place (or halves the step).
const ROUNDS: usize = 80;

/// `places` moved so that the busiest leader is sent fewer items: each
/// round takes the busiest leader's region and lets the nearest of its
/// neighbours whose move helps step towards it (taking some of its
/// crowd), keeping the move if the busiest leader's items, or else their
/// spread, fall. Moves only ever help, so the result is never worse than
/// `places`; the same places and workload give the same result.
pub fn balanced(places: Vec<(f64, f64)>, workload: &Workload) -> Vec<(f64, f64)> {
    if places.len() < 2 || workload.events.is_empty() {
        return places;
    }
    let score = |items: &[u64]| {
        let most = items.iter().copied().max().unwrap_or(0);
        let spread: u128 = items.iter().map(|&i| (i as u128) * (i as u128)).sum();
        (most, spread)
    };
    let spread_of = |places: &[(f64, f64)]| {
        let (xs, ys): (Vec<f64>, Vec<f64>) = places.iter().copied().unzip();
        let extent = |v: &[f64]| {
            v.iter().copied().fold(f64::NEG_INFINITY, f64::max)
                - v.iter().copied().fold(f64::INFINITY, f64::min)
        };
        extent(&xs).max(extent(&ys))
    };
    let mut best = places;
    let mut items = workload.items(&best);
    let mut step = spread_of(&best) * FIRST_STEP;
    let mut halvings = 0;
    for _ in 0..ROUNDS {
        if step.is_nan() || step <= 0.0 {
            break;
        }
        let busiest = (0..items.len()).max_by_key(|&i| (items[i], std::cmp::Reverse(i)));
        let Some(busiest) = busiest else { break };
        let (hx, hy) = best[busiest];
        let mut neighbours: Vec<usize> = (0..best.len()).filter(|&j| j != busiest).collect();
        let distance = |j: usize| (best[j].0 - hx).hypot(best[j].1 - hy);
        neighbours.sort_by(|&i, &j| distance(i).total_cmp(&distance(j)));
        let mut moved = false;
        for j in neighbours {
            let d = distance(j);
            if d <= step {
                continue;
            }
            let mut tried = best.clone();
            let (jx, jy) = tried[j];
            tried[j] = (jx + (hx - jx) * step / d, jy + (hy - jy) * step / d);
            let tried_items = workload.items(&tried);
            if score(&tried_items) < score(&items) {
                (best, items, moved) = (tried, tried_items, true);
                break;
            }
        }
        if !moved {
            halvings += 1;
            if halvings > HALVINGS {
                break;
            }
            step /= 2.0;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use idmesh_protocol::trace::{Mix, Move, Observe};

    fn at(track: u32, x: f64, y: f64) -> Line {
        Line::Move(Move {
            time: 0.0,
            track,
            x,
            y,
        })
    }

    fn mix(a: u32, b: u32) -> Line {
        Line::Mix(Mix {
            time: 0.0,
            a,
            b,
            swap: 0.5,
        })
    }

    /// Items follow the regional routing: a mix at both leaders when its
    /// tracks are in two regions, an observation at its track's leader,
    /// a handover at the old and the new one; the leading moves place
    /// tracks without a handover.
    #[test]
    fn a_workload_counts_what_each_leader_is_sent() {
        let mut w = Workload::new(3);
        for line in [
            at(0, 0.0, 0.0),
            at(1, 0.0, 0.0),
            at(2, 10.0, 0.0),
            mix(0, 1),
            mix(1, 2),
            Line::Observe(Observe {
                time: 0.0,
                track: 2,
                red: 0.9,
                blue: 0.1,
                sensor: None,
            }),
            at(1, 9.0, 0.0),
            mix(1, 2),
            at(7, 9.0, 0.0),
        ] {
            w.push(&line);
        }
        // Leader 0 at the origin, leader 1 at x = 10: mix(0,1) at 0,
        // mix(1,2) at both, the observation at 1, the handover of 1 at
        // both, then mix(1,2) at 1.
        assert_eq!(w.items(&[(0.0, 0.0), (10.0, 0.0)]), vec![3, 4]);
    }

    /// A crowd whose meetings are all on one side: the leader there is
    /// sent nearly everything from places that split the positions evenly,
    /// and the balanced places share the items out without a leader worse
    /// off than the busiest was.
    #[test]
    fn balanced_places_share_out_a_crowd_that_meets_on_one_side() {
        let tracks = 40;
        let mut w = Workload::new(tracks);
        let x = |t: u32| f64::from(t) * 2.5;
        for t in 0..tracks as u32 {
            w.push(&at(t, x(t), 0.0));
        }
        // Tracks 0..20 (x < 50) meet their neighbours often; the others once.
        for round in 0..20 {
            for t in 0..19u32 {
                w.push(&mix(t, t + 1));
            }
            if round == 0 {
                for t in 20..39u32 {
                    w.push(&mix(t, t + 1));
                }
            }
        }
        let even = vec![(25.0, 0.0), (75.0, 0.0)];
        let before = w.items(&even);
        let after_places = balanced(even.clone(), &w);
        let after = w.items(&after_places);
        assert_eq!(after_places, balanced(even, &w));
        let most = |v: &[u64]| *v.iter().max().unwrap();
        assert!(
            most(&before) > 3 * most(&after) / 2,
            "{before:?} → {after:?}"
        );
        assert!(
            most(&after) * 10 < 12 * after.iter().sum::<u64>() / 2,
            "{after:?}"
        );
    }
}
