//! Which leader surveils each track, and the regional rule of the factored
//! belief that follows from it (docs/design/architecture.md, "Components that stay
//! in their region").
//!
//! The sensor gateway routes by [`Regions`] (a track belongs to the nearest
//! leader to its last position; to leader `track mod L` before any
//! position, or when some leader has no position; a stream whose first
//! lines place its tracks starts each with the leader nearest to that
//! place, [`Regions::starting`]), and `idmesh replay
//! --regions` runs the same function, so the centralized engine applies
//! the regional rule at the same events as the leaders: a mix of tracks in
//! two regions keeps their components apart
//! ([`FactoredBelief::mix_apart`]), and a track that changes region is
//! split off its component ([`FactoredBelief::split_off`]). The simulator
//! and the accuracy bench drive [`Regional`] line by line.

use idmesh_belief::{event_of, BeliefError, FactoredBelief, Field, Mix, Observe, PropertyFilter};
use idmesh_protocol::trace::Line;

/// The leaders' places and each track's surveilling leader.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Regions {
    /// Where each leader sits (None for all: tracks never change region).
    places: Option<Vec<(f64, f64)>>,
    owners: Vec<u16>,
}

impl Regions {
    /// `tracks` tracks among leaders at `places` (one per leader; a track
    /// goes to the nearest): each track starts with leader `track mod L`.
    pub fn new(places: &[Option<(f64, f64)>], tracks: usize) -> Self {
        let leaders = places.len().max(1);
        Regions {
            places: places.iter().copied().collect(),
            owners: (0..tracks).map(|t| (t % leaders) as u16).collect(),
        }
    }

    /// Like [`Regions::new`], but each track placed by the stream's
    /// leading `move` lines (those before its first other event, see
    /// [`leading_places`]) starts with the leader nearest to that place.
    /// Starting there rather than with leader `track mod L` spares a
    /// handover per track at its first move (an item at two leaders, and a
    /// component sent between them). Nothing has mixed before those moves,
    /// so the belief is the same either way: the centralized engine, which
    /// starts round robin, hands the tracks over at those moves by
    /// splitting off singletons, which changes nothing.
    /// Tracks beyond `leading` start round robin.
    pub fn starting(
        places: &[Option<(f64, f64)>],
        tracks: usize,
        leading: &[Option<(f64, f64)>],
    ) -> Self {
        let mut regions = Regions::new(places, tracks);
        for (track, place) in leading.iter().enumerate().take(tracks) {
            if let Some((x, y)) = *place {
                regions.moved(track as u32, x, y);
            }
        }
        regions
    }

    /// The leader surveilling each track now.
    pub fn owners(&self) -> &[u16] {
        &self.owners
    }

    pub fn owner(&self, track: u32) -> Option<u16> {
        self.owners.get(track as usize).copied()
    }

    /// The leader nearest to (x, y) (the first of equals); None when the
    /// leaders have no places.
    pub fn nearest(&self, x: f64, y: f64) -> Option<u16> {
        let mut best: Option<(f64, u16)> = None;
        for (i, &(lx, ly)) in self.places.as_deref()?.iter().enumerate() {
            let d = (lx - x).powi(2) + (ly - y).powi(2);
            if best.is_none_or(|(b, _)| d < b) {
                best = Some((d, i as u16));
            }
        }
        best.map(|b| b.1)
    }

    /// `track` is now at (x, y): its (old, new) leader if that changes it
    /// (a handover), which is then recorded.
    pub fn moved(&mut self, track: u32, x: f64, y: f64) -> Option<(u16, u16)> {
        let to = self.nearest(x, y)?;
        let slot = self.owners.get_mut(track as usize)?;
        let from = *slot;
        (from != to).then(|| {
            *slot = to;
            (from, to)
        })
    }
}

/// `leaders` places on a grid over the box from (x0, y0) to (x1, y1): the
/// centres of its cells, row by row, with as many columns as the square
/// root of `leaders` rounded up. Where a deployment that knows nothing
/// better puts its leaders (the loopback moves them on towards the crowd).
pub fn grid_places((x0, y0, x1, y1): (f64, f64, f64, f64), leaders: usize) -> Vec<(f64, f64)> {
    let columns = (leaders as f64).sqrt().ceil().max(1.0) as usize;
    let rows = leaders.div_ceil(columns);
    (0..leaders)
        .map(|i| {
            let (c, r) = (i % columns, i / columns);
            (
                x0 + (x1 - x0) * (c as f64 + 0.5) / columns as f64,
                y0 + (y1 - y0) * (r as f64 + 0.5) / rows as f64,
            )
        })
        .collect()
}

/// Where each of `tracks` tracks is before the stream's first event other
/// than a `move`: the last of the leading `move` lines on it (None for a
/// track they do not place, or out of range).
pub fn leading_places<'a>(
    tracks: usize,
    lines: impl IntoIterator<Item = &'a Line>,
) -> Vec<Option<(f64, f64)>> {
    let mut leading = Leading::new(tracks);
    for line in lines {
        if leading.is_over() {
            break;
        }
        leading.take(line);
    }
    leading.places
}

/// The leading `move` lines of a stream, read line by line: what
/// [`leading_places`] returns, for a reader that goes on past them.
#[derive(Debug, Clone)]
pub(crate) struct Leading {
    pub(crate) places: Vec<Option<(f64, f64)>>,
    over: bool,
}

impl Leading {
    pub(crate) fn new(tracks: usize) -> Self {
        Leading {
            places: vec![None; tracks],
            over: false,
        }
    }

    /// Whether an event other than a `move` has come.
    pub(crate) fn is_over(&self) -> bool {
        self.over
    }

    /// Takes `line`: true if it was a leading `move` (it then placed its
    /// track), false once the leading moves are over.
    pub(crate) fn take(&mut self, line: &Line) -> bool {
        if self.over {
            return false;
        }
        match line {
            Line::Move(m) => {
                if let Some(place) = self.places.get_mut(m.track as usize) {
                    *place = Some((m.x, m.y));
                }
                return true;
            }
            line if line.is_event() => self.over = true,
            _ => {}
        }
        false
    }
}

/// A centralized factored belief under the regional rule, with the regions
/// the sensor gateway would route by: a mix of tracks in two regions is kept
/// apart, and a track that changes region ([`Regional::moved`], a trace's
/// `move` line) is split off its component.
#[derive(Debug)]
pub struct Regional {
    belief: FactoredBelief,
    regions: Regions,
}

impl Regional {
    pub fn new(belief: FactoredBelief, regions: Regions) -> Self {
        Regional { belief, regions }
    }

    pub fn belief(&self) -> &FactoredBelief {
        &self.belief
    }

    /// `track` is now at (x, y).
    pub fn moved(&mut self, track: u32, x: f64, y: f64) -> Result<(), BeliefError> {
        match self.regions.moved(track, x, y) {
            Some(_) => self.belief.split_off(track),
            None => Ok(()),
        }
    }

    /// Applies one trace line (lines without a belief event do nothing).
    pub fn apply_line(&mut self, line: &Line) -> Result<(), BeliefError> {
        match (line, event_of(line)) {
            (Line::Move(m), _) => self.moved(m.track, m.x, m.y),
            (_, Some(event)) => self.apply(&event),
            (_, None) => Ok(()),
        }
    }
}

impl PropertyFilter for Regional {
    fn field(&self) -> &Field {
        self.belief.field()
    }

    fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        if self.regions.owner(mix.a) == self.regions.owner(mix.b) {
            return self.belief.mix(mix);
        }
        if mix.swap == 1.0 {
            // A certain exchange across regions: both tracks leave their
            // components, so that the relabelled singletons can change
            // regions with their labels.
            self.belief.split_off(mix.a)?;
            self.belief.split_off(mix.b)?;
        }
        self.belief.mix_apart(mix)
    }

    fn observe(&mut self, observe: Observe) -> Result<(), BeliefError> {
        self.belief.observe(observe)
    }

    fn marginals(&self) -> Result<Vec<f64>, BeliefError> {
        self.belief.marginals()
    }

    fn coefficients(&self) -> usize {
        self.belief.coefficients()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_grid_puts_leaders_at_the_centres_of_its_cells_row_by_row() {
        let box_ = (0.0, 0.0, 30.0, 20.0);
        assert_eq!(grid_places(box_, 1), [(15.0, 10.0)]);
        // 3 leaders: 2 columns, 2 rows, the last row half full.
        assert_eq!(grid_places(box_, 3), [(7.5, 5.0), (22.5, 5.0), (7.5, 15.0)]);
        assert!(grid_places(box_, 0).is_empty());
    }

    #[test]
    fn tracks_start_round_robin_and_go_to_the_nearest_leader() {
        let mut r = Regions::new(&[Some((0.0, 0.0)), Some((10.0, 0.0))], 3);
        assert_eq!(r.owners(), &[0, 1, 0]);
        assert_eq!(r.moved(0, 9.0, 0.0), Some((0, 1)));
        assert_eq!(r.moved(0, 8.0, 0.0), None, "still nearest to leader 1");
        assert_eq!(r.moved(1, 1.0, 1.0), Some((1, 0)));
        assert_eq!(r.moved(7, 1.0, 1.0), None, "an unknown track");
        // Without places nobody moves.
        let mut fixed = Regions::new(&[None, Some((1.0, 1.0))], 2);
        assert_eq!(fixed.moved(0, 1.0, 1.0), None);
        assert_eq!(fixed.owners(), &[0, 1]);
    }

    #[test]
    fn a_stream_that_places_its_tracks_first_starts_them_in_their_regions() {
        use idmesh_protocol::trace::{Mix as MixLine, Move};
        let at = |track, x| {
            Line::Move(Move {
                time: 0.0,
                track,
                x,
                y: 0.0,
            })
        };
        let mix = Line::Mix(MixLine {
            time: 0.0,
            a: 0,
            b: 1,
            swap: 0.5,
        });
        // Track 0 is placed twice (the last counts), track 2 only after
        // the first mix: it is not placed.
        let lines = [at(0, 1.0), at(1, 9.0), at(0, 8.0), mix, at(2, 9.0)];
        let leading = leading_places(3, &lines);
        assert_eq!(leading, vec![Some((8.0, 0.0)), Some((9.0, 0.0)), None]);
        let places = [Some((0.0, 0.0)), Some((10.0, 0.0))];
        let r = Regions::starting(&places, 3, &leading);
        assert_eq!(r.owners(), &[1, 1, 0]);
        // The same as starting round robin and moving there.
        let mut moved = Regions::new(&places, 3);
        moved.moved(0, 8.0, 0.0);
        moved.moved(1, 9.0, 0.0);
        assert_eq!(moved, r);
        // Without places, round robin.
        assert_eq!(
            Regions::starting(&[None, None], 3, &leading).owners(),
            &[0, 1, 0]
        );
    }

    /// A little crowd: 12 tracks moving on a 10 × 10 field, mixing (some of
    /// the mixes certain exchanges), observed now and then (a fixed
    /// linear congruential sequence, so the test needs no generator).
    fn lines() -> Vec<Line> {
        use idmesh_protocol::trace::{Mix as MixLine, Move, Observe as ObserveLine};
        let mut state = 7u64;
        let mut next = |m: u64| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) % m
        };
        (0..400)
            .map(|e| {
                let time = e as f64;
                match next(3) {
                    0 => {
                        let a = next(12) as u32;
                        let b = (a + 1 + next(11) as u32) % 12;
                        // 0.1..=0.8, or now and then a certain exchange.
                        let swap = match next(10) {
                            0 => 1.0,
                            s => 0.1 + (s % 8) as f64 / 10.0,
                        };
                        Line::Mix(MixLine { time, a, b, swap })
                    }
                    1 => Line::Observe(ObserveLine {
                        time,
                        track: next(12) as u32,
                        red: 0.2 + next(7) as f64 / 10.0,
                        blue: 0.3,
                        sensor: None,
                    }),
                    _ => Line::Move(Move {
                        time,
                        track: next(12) as u32,
                        x: next(100) as f64 / 10.0,
                        y: next(100) as f64 / 10.0,
                    }),
                }
            })
            .collect()
    }

    fn belief() -> FactoredBelief {
        let field = Field::known(12, vec![0, 3, 5, 8, 11]);
        let options = idmesh_belief::FactoredOptions {
            coupling: idmesh_belief::Coupling::Local,
            max_component: 5,
            ..Default::default()
        };
        FactoredBelief::with_options(field, options).unwrap()
    }

    #[test]
    fn one_region_is_the_plain_belief_and_more_keep_components_in_theirs() {
        let mut plain = belief();
        let mut one = Regional::new(belief(), Regions::new(&[Some((5.0, 5.0))], 12));
        for line in &lines() {
            one.apply_line(line).unwrap();
            match line {
                Line::Mix(m) => plain
                    .mix(Mix {
                        a: m.a,
                        b: m.b,
                        swap: m.swap,
                    })
                    .unwrap(),
                Line::Observe(o) => plain
                    .observe(Observe {
                        track: o.track,
                        red: o.red,
                        blue: o.blue,
                    })
                    .unwrap(),
                _ => {}
            }
            assert_eq!(one.marginals().unwrap(), plain.marginals().unwrap());
        }
        let places = [Some((2.0, 2.0)), Some((8.0, 2.0)), Some((5.0, 8.0))];
        let mut three = Regional::new(belief(), Regions::new(&places, 12));
        for line in &lines() {
            three.apply_line(line).unwrap();
            for component in three.belief().components() {
                let owners: Vec<_> = component.iter().map(|&t| three.regions.owner(t)).collect();
                assert!(
                    owners.windows(2).all(|w| w[0] == w[1]),
                    "component {component:?} spans regions {owners:?}"
                );
            }
        }
        let stats = three.belief().stats();
        assert!(stats.kept_apart > 0 && stats.split_off > 0, "{stats:?}");
        assert!(three.belief().components().iter().any(|c| c.len() > 1));
    }
}
