//! Regions fitted to the crowd and redrawn as it moves: the default way a
//! deployment shares its tracks among leaders.
//!
//! What a leader is sent follows from the tracks it surveils: under the
//! factored regional rule with shrinking interests, exactly the items on
//! them (docs/design/architecture.md, "Components that stay in their
//! region"). Fixed places, each track going to the nearest leader, share
//! out a field's *area*; a crowd meets most where it is densest, and real
//! crowds gather on paths and at doors, so one leader may be sent several
//! times an even share. Fitted regions share out the *items* instead.
//!
//! The cells are drawn by recursive coordinate bisection of the tracks'
//! last positions, each track weighted by the items it took part in during
//! the last window: a group of leaders is cut in two along the axis its
//! tracks spread over most, at the weighted quantile that gives each side
//! weight in proportion to its leaders. Every [`window`](Fitted::window)
//! items the rule counts what each leader was sent; when the busiest was
//! sent more than [`TOLERANCE`] times the mean, it draws the cells again
//! from that window's weights and gives each new cell to the leader that
//! already surveils most of its tracks, so that a redraw hands over as few
//! tracks as it can.
//!
//! A redraw hands over only the tracks seen lately (a `move` or an item
//! within the last [`RECENT_PER_LEADER`] items per leader): the others
//! keep their leaders. On a real scene most tracks are people who have
//! left; handing them over cost two items each and gained nothing.
//!
//! A track is surveilled from its first item on, not before
//! ([`crate::Regions::before`]): on a real scene people keep entering, take
//! part in two or three items each and leave, and a newcomer that started
//! with some leader was taken to its partner's at its first mix, an item
//! at the leader it left.
//!
//! Between redraws a track keeps its leader wherever it walks, until a mix
//! with a track of another leader takes both to the one of the two that
//! was sent fewer items since the stream began
//! ([`crate::Regions::before`]); its `move` lines only record where it is.
//! Counts of the whole stream, not of the window: a window's counts start
//! again at every redraw, and right after one they said nothing, so that
//! the first mixes of a window went to whichever leader came first.
//!
//! A handover costs an item at two leaders (and splits the track off its
//! component), a mix across two leaders an item at each: on crowds whose
//! targets cross many cells between their events, handing a track over at
//! every crossing, or at its next event in another cell, sent the busiest
//! leader more than keeping it, for no gain in accuracy (`cargo run
//! --release -p idmesh-placement --example balance -- TRACE` prints the
//! shares; docs/bench.md has the bench's).
//!
//! The rule is a function of the stream's lines alone: the sensor, `idmesh
//! replay` and the simulator run it line by line and reach the same owners
//! at the same lines, which is what makes a deployment's answer equal its
//! centralized twin's.

use serde::{Deserialize, Serialize};

/// A redraw happens when the busiest leader of a window was sent more
/// than this many times the mean (fewer redraws below it are not worth
/// their handovers: each is an item at two leaders and a split). Measured
/// with the balance example at 2, 4 and 8 leaders on random-waypoint
/// crowds of 60 to 2,000, social-force crowds of 100 and 1,000 and three
/// real scenes: at 1.2, eight leaders redrew so often that the handovers
/// outweighed the balance (busiest 1.69× an even share on 2,000 walkers,
/// 2.07× on a crowd of 1,000); at 1.35, 1.36× and 1.39×, and no crowd or
/// leader count worse by more than 0.01; at 1.5 the smallest crowd got
/// worse (8 leaders on 60 walkers: 2.02× against 1.85×).
pub const TOLERANCE: f64 = 1.35;

/// Items per leader in a window, by default: enough that the counts it
/// compares are not noise (about a tenth at 100).
pub(crate) const WINDOW_PER_LEADER: u64 = 100;

/// A redraw hands over only the tracks seen (moved, or took part in an
/// item) within the last this many items per leader. Measured with the
/// balance example on 27 traces (the bench's crowds, the five real scenes
/// at several seeds, random-waypoint and social-force crowds of 40 to
/// 1,000): 5 gave the lowest busiest share at 8 leaders on the dense ones
/// (univ, 1,000 walkers), 20 and 50 up to 0.15 more; on the sparse real
/// scenes it makes no difference.
pub(crate) const RECENT_PER_LEADER: u64 = 5;

/// Items with tracks before which no leader counts as busy
/// ([`Fitted::busy`]): the first few items' counts say nothing.
const BUSY_AFTER: u64 = 20;

/// The weight of a placed track that took part in nothing in the window,
/// so that quiet tracks still spread over the cells.
const QUIET_WEIGHT: f64 = 0.05;

/// A cell tree: a cut of the plane, or a leader's cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
enum Cell {
    Leaf(u16),
    Cut {
        /// 0: x, 1: y.
        axis: u8,
        /// Positions at or below go `low`.
        at: f64,
        low: Box<Cell>,
        high: Box<Cell>,
    },
}

impl Cell {
    fn leader_at(&self, (x, y): (f64, f64)) -> u16 {
        let mut cell = self;
        loop {
            match cell {
                Cell::Leaf(leader) => return *leader,
                Cell::Cut {
                    axis,
                    at,
                    low,
                    high,
                } => {
                    let v = if *axis == 0 { x } else { y };
                    cell = if v <= *at { low } else { high };
                }
            }
        }
    }

    /// Each leader's rectangle `[x0, y0, x1, y1]` within `bounds`: the
    /// cuts above a leaf narrow the bounds down to its cell. Indexed by
    /// leader; a leader with no leaf keeps None.
    fn rectangles(&self, bounds: [f64; 4], out: &mut [Option<[f64; 4]>]) {
        match self {
            Cell::Leaf(leader) => {
                if let Some(slot) = out.get_mut(usize::from(*leader)) {
                    *slot = Some(bounds);
                }
            }
            Cell::Cut {
                axis,
                at,
                low,
                high,
            } => {
                // A cut outside the bounds (the first cut of an empty
                // side lies at -inf) leaves one side empty, of no width.
                let a = usize::from(*axis).min(1);
                let at = at.clamp(bounds[a], bounds[a + 2]);
                let (mut below, mut above) = (bounds, bounds);
                below[a + 2] = at;
                above[a] = at;
                low.rectangles(below, out);
                high.rectangles(above, out);
            }
        }
    }

    fn relabel(&mut self, labels: &[u16]) {
        match self {
            Cell::Leaf(slot) => *slot = labels[*slot as usize],
            Cell::Cut { low, high, .. } => {
                low.relabel(labels);
                high.relabel(labels);
            }
        }
    }
}

/// A placed track as a cut sees it.
#[derive(Debug, Clone, Copy)]
struct Point {
    x: f64,
    y: f64,
    weight: f64,
}

/// Cells for `leaders` leaders (slots `first..first + leaders`) over
/// `points`.
fn bisect(points: &mut [Point], first: u16, leaders: u16) -> Cell {
    if leaders <= 1 {
        return Cell::Leaf(first);
    }
    let low_leaders = leaders / 2;
    let spread = |f: fn(&Point) -> f64| {
        let (lo, hi) = points
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(f(p)), hi.max(f(p)))
            });
        hi - lo
    };
    let axis = if points.is_empty() || spread(|p| p.x) >= spread(|p| p.y) {
        0
    } else {
        1
    };
    let coordinate = |p: &Point| if axis == 0 { p.x } else { p.y };
    points.sort_by(|a, b| coordinate(a).total_cmp(&coordinate(b)));
    let total: f64 = points.iter().map(|p| p.weight).sum();
    let wanted = total * f64::from(low_leaders) / f64::from(leaders);
    // The low side takes points until it holds its share of the weight;
    // the cut lies halfway to the next point.
    let mut held = 0.0;
    let mut split = 0usize;
    for p in points.iter() {
        if held >= wanted && split > 0 {
            break;
        }
        held += p.weight;
        split += 1;
    }
    let at = match (split.checked_sub(1).map(|i| &points[i]), points.get(split)) {
        (Some(last), Some(next)) => (coordinate(last) + coordinate(next)) / 2.0,
        (Some(last), None) => coordinate(last),
        (None, _) => f64::NEG_INFINITY,
    };
    let (low, high) = points.split_at_mut(split);
    Cell::Cut {
        axis,
        at,
        low: Box::new(bisect(low, first, low_leaders)),
        high: Box::new(bisect(high, first + low_leaders, leaders - low_leaders)),
    }
}

/// The fitted-regions rule's state: the cells, where each track was last
/// seen, and the window's counts.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Fitted {
    leaders: u16,
    /// None until the first draw (no positions yet).
    cells: Option<Cell>,
    positions: Vec<Option<(f64, f64)>>,
    /// The items each track took part in during this window.
    activity: Vec<u32>,
    /// The items each leader was sent during this window.
    sent: Vec<u64>,
    items: u64,
    window_per_leader: u64,
    /// The items each leader was sent since the stream began.
    sent_so_far: Vec<u64>,
    /// Items with tracks since the stream began: the clock of `seen`.
    clock: u64,
    /// When each track was last seen (moved or in an item), by `clock`.
    seen: Vec<u64>,
    /// The box `[x0, y0, x1, y1]` of every position seen since the stream
    /// began (only ever growing): what a map's cells are cut to. Absent
    /// from snapshots taken before it was kept.
    #[serde(default)]
    extent: Option<[f64; 4]>,
}

impl Fitted {
    pub(crate) fn new(leaders: usize, tracks: usize, window_per_leader: u64) -> Self {
        let leaders = leaders.clamp(1, usize::from(u16::MAX)) as u16;
        Fitted {
            leaders,
            cells: None,
            positions: vec![None; tracks],
            activity: vec![0; tracks],
            sent: vec![0; usize::from(leaders)],
            items: 0,
            window_per_leader: window_per_leader.max(1),
            sent_so_far: vec![0; usize::from(leaders)],
            clock: 0,
            seen: vec![0; tracks],
            extent: None,
        }
    }

    /// The items `leader` was sent since the stream began.
    pub(crate) fn sent_so_far(&self, leader: u16) -> u64 {
        self.sent_so_far
            .get(usize::from(leader))
            .copied()
            .unwrap_or(0)
    }

    pub(crate) fn leaders(&self) -> usize {
        usize::from(self.leaders)
    }

    /// The leader sent fewest items so far (the lowest of equals).
    pub(crate) fn least_sent(&self) -> u16 {
        (0..self.leaders)
            .min_by_key(|&l| (self.sent_so_far(l), l))
            .unwrap_or(0)
    }

    /// Whether `leader` was sent more than [`TOLERANCE`] times the
    /// leaders' mean so far (never over the first [`BUSY_AFTER`] items).
    pub(crate) fn busy(&self, leader: u16) -> bool {
        let mean = self.sent_so_far.iter().sum::<u64>() as f64 / f64::from(self.leaders);
        self.clock >= BUSY_AFTER && self.sent_so_far(leader) as f64 > TOLERANCE * mean
    }

    /// Items per window.
    pub(crate) fn window(&self) -> u64 {
        self.window_per_leader * u64::from(self.leaders)
    }

    /// `track` is at (x, y) now.
    pub(crate) fn record(&mut self, track: u32, x: f64, y: f64) {
        if let Some(slot) = self.positions.get_mut(track as usize) {
            *slot = Some((x, y));
            self.seen[track as usize] = self.clock;
            let [x0, y0, x1, y1] = self.extent.unwrap_or([x, y, x, y]);
            self.extent = Some([x0.min(x), y0.min(y), x1.max(x), y1.max(y)]);
        }
    }

    /// `track` is at (x, y): the leader whose cell holds it (None before
    /// the first draw).
    pub(crate) fn place(&mut self, track: u32, x: f64, y: f64) -> Option<u16> {
        self.record(track, x, y);
        Some(self.cells.as_ref()?.leader_at((x, y)))
    }

    /// An item was sent to `leaders` on `tracks`.
    pub(crate) fn sent(&mut self, tracks: &[u32], leaders: &[u16]) {
        for &t in tracks {
            if let Some(a) = self.activity.get_mut(t as usize) {
                *a += 1;
                self.seen[t as usize] = self.clock;
            }
        }
        for &l in leaders {
            if let Some(s) = self.sent.get_mut(usize::from(l)) {
                *s += 1;
                self.sent_so_far[usize::from(l)] += 1;
            }
        }
        if !tracks.is_empty() {
            self.items += 1;
            self.clock += 1;
        }
    }

    /// Whether the window is over and its counts call for new cells: the
    /// first draw once some track is placed, then whenever the busiest
    /// leader was sent more than [`TOLERANCE`] times the mean. Starts the
    /// next window when it is over.
    pub(crate) fn window_over(&mut self) -> bool {
        if self.leaders < 2 || self.items < self.window() {
            return false;
        }
        let busiest = self.sent.iter().copied().max().unwrap_or(0) as f64;
        let mean = self.sent.iter().sum::<u64>() as f64 / f64::from(self.leaders);
        let due = match self.cells {
            None => self.positions.iter().any(Option::is_some),
            Some(_) => busiest > TOLERANCE * mean,
        };
        if !due {
            self.new_window();
        }
        due
    }

    fn new_window(&mut self) {
        self.activity.iter_mut().for_each(|a| *a = 0);
        self.sent.iter_mut().for_each(|s| *s = 0);
        self.items = 0;
    }

    /// Draws the cells again from the window's weights (every placed track
    /// alike if none took part in anything) over the tracks seen lately
    /// ([`RECENT_PER_LEADER`]) and returns each one's leader in them;
    /// `owners` are the leaders now, which the new cells keep where they
    /// can. Starts a new window.
    pub(crate) fn draw(&mut self, owners: &[u16]) -> Vec<(u32, u16)> {
        let lately = RECENT_PER_LEADER * u64::from(self.leaders);
        let placed: Vec<(u32, (f64, f64))> = self
            .positions
            .iter()
            .enumerate()
            .filter(|&(t, _)| self.clock - self.seen[t] <= lately)
            .filter_map(|(t, p)| p.map(|p| (t as u32, p)))
            .collect();
        let mut points: Vec<Point> = placed
            .iter()
            .map(|&(t, (x, y))| Point {
                x,
                y,
                weight: f64::from(self.activity[t as usize]) + QUIET_WEIGHT,
            })
            .collect();
        let mut cells = bisect(&mut points, 0, self.leaders);
        // Slot s's tracks now surveilled by leader l, then each slot to the
        // leader holding most of it (greedily, the largest first; ties to
        // the lowest slot and leader, so the result is the same anywhere).
        let leaders = usize::from(self.leaders);
        let mut overlap = vec![vec![0u64; leaders]; leaders];
        for &(t, p) in &placed {
            let slot = usize::from(cells.leader_at(p));
            if let Some(&owner) = owners.get(t as usize) {
                if usize::from(owner) < leaders {
                    overlap[slot][usize::from(owner)] += 1;
                }
            }
        }
        let mut pairs: Vec<(u64, usize, usize)> = (0..leaders)
            .flat_map(|s| (0..leaders).map(move |l| (s, l)))
            .map(|(s, l)| (overlap[s][l], s, l))
            .collect();
        pairs.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let mut labels = vec![None; leaders];
        let mut taken = vec![false; leaders];
        for (_, s, l) in pairs {
            if labels[s].is_none() && !taken[l] {
                labels[s] = Some(l as u16);
                taken[l] = true;
            }
        }
        let labels: Vec<u16> = labels
            .into_iter()
            .enumerate()
            .map(|(s, l)| l.unwrap_or(s as u16))
            .collect();
        cells.relabel(&labels);
        let owners = placed
            .iter()
            .map(|&(t, p)| (t, cells.leader_at(p)))
            .collect();
        self.cells = Some(cells);
        self.new_window();
        owners
    }

    /// Each leader's place for a map: the centre of its cell (within the
    /// box of every track seen so far), or before the first draw the mean
    /// position of the placed tracks it surveils (None for a leader
    /// surveilling none). Not the mean after a draw: tracks keep their
    /// leader wherever they walk until the next draw, so the means of
    /// leaders drift together to the middle of the crowd and say nothing
    /// of where each one's region is.
    pub(crate) fn places(&self, owners: &[u16]) -> Vec<Option<(f64, f64)>> {
        if let Some(cells) = self.cells() {
            let centre = |r: [f64; 4]| ((r[0] + r[2]) / 2.0, (r[1] + r[3]) / 2.0);
            return cells.into_iter().map(|c| c.map(centre)).collect();
        }
        let mut sums = vec![(0.0, 0.0, 0u32); usize::from(self.leaders)];
        for (t, p) in self.positions.iter().enumerate() {
            if let (Some((x, y)), Some(&o)) = (p, owners.get(t)) {
                if let Some(s) = sums.get_mut(usize::from(o)) {
                    *s = (s.0 + x, s.1 + y, s.2 + 1);
                }
            }
        }
        sums.into_iter()
            .map(|(x, y, n)| (n > 0).then(|| (x / f64::from(n), y / f64::from(n))))
            .collect()
    }

    /// Each leader's cell `[x0, y0, x1, y1]`, cut to the box of every
    /// position seen since the stream began (cells reach to infinity; a
    /// map shows the field). None before the first draw.
    pub(crate) fn cells(&self) -> Option<Vec<Option<[f64; 4]>>> {
        let (tree, extent) = (self.cells.as_ref()?, self.extent?);
        let mut out = vec![None; usize::from(self.leaders)];
        tree.rectangles(extent, &mut out);
        Some(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn points(coords: &[(f64, f64, f64)]) -> Vec<Point> {
        coords
            .iter()
            .map(|&(x, y, weight)| Point { x, y, weight })
            .collect()
    }

    #[test]
    fn bisection_gives_each_cell_an_equal_weight() {
        // A dense middle: many points near (5, 5), a few far out.
        let mut coords = Vec::new();
        for i in 0..40 {
            let d = f64::from(i % 10) / 10.0;
            coords.push((5.0 + d - 0.5, 5.0 + f64::from(i / 10) / 10.0, 1.0));
        }
        coords.extend([
            (0.0, 0.0, 1.0),
            (10.0, 0.0, 1.0),
            (0.0, 10.0, 1.0),
            (10.0, 10.0, 1.0),
        ]);
        let mut pts = points(&coords);
        let cells = bisect(&mut pts, 0, 4);
        let mut weight = [0.0; 4];
        for &(x, y, w) in &coords {
            weight[usize::from(cells.leader_at((x, y)))] += w;
        }
        assert!(weight.iter().all(|&w| w == 11.0), "{weight:?}");
    }

    #[test]
    fn a_leaders_place_is_the_centre_of_its_cell_not_of_its_tracks() {
        // Four tracks in the corners of a 10 × 4 field, two leaders: the
        // cut falls at x = 5 between the pairs.
        let mut fitted = Fitted::new(2, 4, WINDOW_PER_LEADER);
        for (t, (x, y)) in [(0.0, 0.0), (1.0, 4.0), (9.0, 0.0), (10.0, 4.0)]
            .into_iter()
            .enumerate()
        {
            fitted.place(t as u32, x, y);
        }
        assert_eq!(fitted.cells(), None);
        fitted.draw(&[0, 0, 1, 1]);
        let cells = fitted.cells().unwrap();
        assert_eq!(
            cells,
            vec![Some([0.0, 0.0, 5.0, 4.0]), Some([5.0, 0.0, 10.0, 4.0])]
        );
        // Both of leader 0's tracks walk into leader 1's cell and stay
        // with leader 0 until the next draw: its place stays in its cell.
        fitted.place(0, 9.5, 1.0);
        fitted.place(1, 9.5, 3.0);
        assert_eq!(
            fitted.places(&[0, 0, 1, 1]),
            vec![Some((2.5, 2.0)), Some((7.5, 2.0))]
        );
    }

    #[test]
    fn three_leaders_cut_one_third_off() {
        let coords: Vec<_> = (0..30).map(|i| (f64::from(i), 0.0, 1.0)).collect();
        let cells = bisect(&mut points(&coords), 0, 3);
        let mut count = [0; 3];
        for &(x, y, _) in &coords {
            count[usize::from(cells.leader_at((x, y)))] += 1;
        }
        assert_eq!(count, [10, 10, 10]);
    }

    #[test]
    fn a_redraw_keeps_tracks_with_the_leaders_that_hold_them() {
        let mut fitted = Fitted::new(2, 4, WINDOW_PER_LEADER);
        for (t, x) in [0.0, 1.0, 8.0, 9.0].into_iter().enumerate() {
            fitted.place(t as u32, x, 0.0);
        }
        // Leaders 1 and 0 hold the left and right pairs: the new cells
        // are labelled so that nobody changes hands.
        let owners = [1, 1, 0, 0];
        let drawn = fitted.draw(&owners);
        assert_eq!(drawn, vec![(0, 1), (1, 1), (2, 0), (3, 0)]);
        assert_eq!(fitted.place(0, 9.5, 0.0), Some(0));
    }

    #[test]
    fn a_window_redraws_only_when_a_leader_is_much_busier() {
        let mut fitted = Fitted::new(2, 2, WINDOW_PER_LEADER);
        fitted.place(0, 0.0, 0.0);
        fitted.place(1, 1.0, 0.0);
        for _ in 0..fitted.window() {
            fitted.sent(&[0], &[0]);
        }
        assert!(fitted.window_over(), "the first draw is due");
        fitted.draw(&[0, 1]);
        for i in 0..fitted.window() {
            fitted.sent(&[(i % 2) as u32], &[(i % 2) as u16]);
        }
        assert!(!fitted.window_over(), "an even window");
        for _ in 0..fitted.window() {
            fitted.sent(&[0], &[0]);
        }
        assert!(fitted.window_over(), "all on one leader");
    }

    #[test]
    fn a_redraw_hands_over_only_the_tracks_seen_lately() {
        let mut fitted = Fitted::new(2, 4, WINDOW_PER_LEADER);
        for (t, x) in [0.0, 1.0, 8.0, 9.0].into_iter().enumerate() {
            fitted.place(t as u32, x, 0.0);
        }
        // Tracks 0 and 3 go on meeting; 1 and 2 have left (no move, no
        // item for more than RECENT_PER_LEADER items per leader).
        let lately = RECENT_PER_LEADER * 2;
        for _ in 0..=lately {
            fitted.sent(&[0, 3], &[0, 1]);
        }
        let drawn = fitted.draw(&[0, 0, 1, 1]);
        let tracks: Vec<u32> = drawn.iter().map(|&(t, _)| t).collect();
        assert_eq!(tracks, vec![0, 3]);
        // A move counts as seen.
        fitted.place(1, 1.0, 0.0);
        let tracks: Vec<u32> = fitted.draw(&[0, 0, 1, 1]).iter().map(|&(t, _)| t).collect();
        assert_eq!(tracks, vec![0, 1, 3]);
    }

    #[test]
    fn the_counts_so_far_outlive_the_window() {
        let mut fitted = Fitted::new(2, 2, WINDOW_PER_LEADER);
        fitted.place(0, 0.0, 0.0);
        fitted.place(1, 1.0, 0.0);
        for _ in 0..fitted.window() {
            fitted.sent(&[0], &[0]);
        }
        assert!(fitted.window_over());
        fitted.draw(&[0, 1]);
        assert_eq!(fitted.sent, vec![0, 0], "a new window");
        assert_eq!(
            (fitted.sent_so_far(0), fitted.sent_so_far(1)),
            (fitted.window(), 0)
        );
    }
}
