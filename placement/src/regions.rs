//! Which leader surveils each track, and the regional rule of the factored
//! belief that follows from it (docs/design/architecture.md, "Components
//! that stay in their region").
//!
//! The sensor routes by [`Regions`]: by default cells fitted to the crowd
//! and redrawn as it moves ([`crate::Fitted`]); as an option, fixed places
//! (a track belongs to the leader nearest its last position). Under fitted
//! cells with mixes taken (a factored stream's regional rule) no leader
//! surveils a track before its first item, which adopts it
//! ([`Regions::before`]: docs/design/architecture.md, "Newcomers");
//! otherwise tracks start with leader `track mod L`, or, in a stream whose
//! first lines place them, in their regions ([`Regions::starting`]).
//! `idmesh replay` runs the
//! same function line by line, so the centralized engine applies the
//! regional rule at the same events as the leaders: a track handed over
//! is split off its component ([`FactoredBelief::split_off`]), a mix of
//! tracks of two leaders under fitted cells takes both to one of them (a
//! handover riding on the mix), and under fixed places keeps their
//! components apart ([`FactoredBelief::mix_apart`]). The simulator and the
//! accuracy evaluation drive [`Regional`] line by line too.

use crate::fitted::Fitted;
use idmesh_belief::{event_of, BeliefError, FactoredBelief, Field, Mix, Observe, PropertyFilter};
use idmesh_protocol::trace::Line;
use idmesh_protocol::wire::sensor_to_leader::{keeper, UNHELD};

/// How tracks are shared among leaders by where they are.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum RegionRule {
    /// Cells fitted to the crowd's items and redrawn as it moves
    /// ([`Fitted`]): the default, which shares out the items evenly. A
    /// window is `window_per_leader` items per leader
    /// ([`crate::fitted::WINDOW_PER_LEADER`] unless a test wants redraws sooner).
    Fitted { window_per_leader: u64 },
    /// Each track to the leader nearest its last position, the leaders
    /// sitting at these places (one per leader; None for every leader:
    /// tracks stay with leader `track mod L`).
    Fixed(Vec<Option<(f64, f64)>>),
}

impl RegionRule {
    /// Fitted cells with the default window.
    pub fn fitted() -> Self {
        RegionRule::Fitted {
            window_per_leader: crate::fitted::WINDOW_PER_LEADER,
        }
    }
}

/// A track changing leader: at a `move` into another region, at a redraw
/// of fitted cells, or at a mix of tracks of two leaders that takes both to
/// one of them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Handover {
    pub track: u32,
    pub from: u16,
    pub to: u16,
    /// It rides on the item it comes before rather than being an item of
    /// its own: a mix's (`Item::Mix::handed`), or, from [`UNHELD`], the
    /// first item of the track it adopts (`Item::adoptions`).
    pub rides: bool,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
enum Rule {
    Fitted(Fitted),
    /// Where each leader sits (None for all: tracks never change region).
    Fixed(Option<Vec<(f64, f64)>>),
}

/// Which leader surveils each track, and the rule that moves them.
///
/// A stream often opens with `move` lines that place its tracks before
/// anything happens (the leading moves). They only record places; at the
/// stream's first other event ([`Regions::before`]) the tracks they placed
/// go to their regions at once (fitted cells are first drawn then). A
/// sensor that knows the leading moves ahead (it streams a trace file)
/// starts there ([`Regions::starting`]) and reaches the same owners.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Regions {
    rule: Rule,
    owners: Vec<u16>,
    /// The places of the leading moves so far; None once another event
    /// has come.
    leading: Option<Vec<Option<(f64, f64)>>>,
    /// Whether the tracks the leading moves place are in their regions
    /// already ([`Regions::starting`]).
    assigned: bool,
    /// Whether a mix of tracks of two leaders takes both to one of them
    /// (fitted cells; see [`Regions::before`]).
    takes_mixes: bool,
    /// The leader a mix took a track from, until [`Regions::after`] counts
    /// the mix at it.
    ridden_from: Option<u16>,
    /// Whether each track is still unheld: no item has named it yet, and
    /// under fitted cells with mixes taken (a factored stream's regional
    /// rule) no leader surveils it before one does (see [`Regions::before`]).
    unheld: Vec<bool>,
}

impl Regions {
    /// `tracks` tracks among `leaders` leaders by `rule`: under fitted
    /// cells each track starts unheld ([`UNHELD`], until its first item),
    /// under fixed places with leader `track mod L`.
    pub fn new(rule: &RegionRule, leaders: usize, tracks: usize) -> Self {
        let rule = match rule {
            RegionRule::Fitted { window_per_leader } => {
                Rule::Fitted(Fitted::new(leaders, tracks, *window_per_leader))
            }
            RegionRule::Fixed(places) => Rule::Fixed(places.iter().copied().collect()),
        };
        let leaders = leaders.max(1);
        let fitted = matches!(rule, Rule::Fitted(_));
        let regions = Regions {
            takes_mixes: fitted,
            rule,
            owners: vec![UNHELD; tracks],
            leading: Some(vec![None; tracks]),
            assigned: false,
            ridden_from: None,
            unheld: vec![true; tracks],
        };
        match fitted {
            true => regions,
            false => regions.held_round_robin(leaders),
        }
    }

    /// A crowd held whole by the first leader
    /// ([`FactoredStart::whole`](idmesh_protocol::wire::factored::FactoredStart::whole)):
    /// every track with leader 0 from the start and for good.
    pub fn whole(tracks: usize) -> Self {
        Regions::new(&RegionRule::Fixed(vec![None]), 1, tracks)
    }

    /// Every track held from the start, by leader `track mod L` (the one
    /// that would keep it unheld).
    fn held_round_robin(mut self, leaders: usize) -> Self {
        for (t, owner) in self.owners.iter_mut().enumerate() {
            *owner = keeper(t as u32, leaders);
        }
        self.unheld.iter_mut().for_each(|u| *u = false);
        self
    }

    /// The same regions, with every mix of tracks of two leaders left to
    /// both: for the streams whose leaders keep no regional components
    /// (Radon sets, or a factored belief without the regional rule), which
    /// know no mix that hands a track over.
    pub fn keeping_mixes_across(mut self) -> Self {
        self.takes_mixes = false;
        match &self.rule {
            Rule::Fitted(fitted) => {
                let leaders = fitted.leaders();
                self.held_round_robin(leaders)
            }
            Rule::Fixed(_) => self,
        }
    }

    /// Fixed places (see [`RegionRule::Fixed`]), one per leader.
    #[cfg(test)]
    pub(crate) fn fixed(places: &[Option<(f64, f64)>], tracks: usize) -> Self {
        Regions::new(&RegionRule::Fixed(places.to_vec()), places.len(), tracks)
    }

    /// Like [`Regions::new`], with the stream's leading `move` lines known
    /// ahead ([`leading_places`]): the tracks they place start in their
    /// regions, so that the stream's `Begin` names those owners and no
    /// track is handed over at its first event (an item at two leaders,
    /// and a component sent between them). The leading moves, when they
    /// come, change nothing; the owners from then on are those
    /// [`Regions::new`] reaches over the same lines. Under fitted cells
    /// with tracks unheld until their first item, the leading moves only
    /// draw the first cells.
    pub fn starting(
        rule: &RegionRule,
        leaders: usize,
        tracks: usize,
        leading: &[Option<(f64, f64)>],
    ) -> Self {
        let mut regions = Regions::new(rule, leaders, tracks);
        // Nothing known ahead (a stream fed live): its leading moves, if
        // any, are taken as they come, and placed at its first event.
        if !leading.iter().take(tracks).any(Option::is_some) {
            return regions;
        }
        if let Some(places) = &mut regions.leading {
            for (slot, place) in places.iter_mut().zip(leading) {
                *slot = *place;
            }
        }
        regions.assign();
        regions.assigned = true;
        regions
    }

    /// The tracks the leading moves placed go to their regions: the
    /// handovers that makes (none on a stream that places nothing).
    fn assign(&mut self) -> Vec<Handover> {
        let Some(leading) = self.leading.clone() else {
            return Vec::new();
        };
        let mut handovers = Vec::new();
        for (track, place) in leading.iter().enumerate() {
            if let Some((x, y)) = *place {
                handovers.extend(self.moved(track as u32, x, y));
            }
        }
        if leading.iter().any(Option::is_some) && !self.owners.is_empty() {
            handovers.extend(self.draw());
        }
        handovers
    }

    /// Fitted cells drawn again, each placed track to the leader of its
    /// new cell: the handovers that makes (none under fixed places).
    fn draw(&mut self) -> Vec<Handover> {
        let Rule::Fitted(fitted) = &mut self.rule else {
            return Vec::new();
        };
        let mut handovers = Vec::new();
        for (track, to) in fitted.draw(&self.owners) {
            if self.unheld[track as usize] {
                // Nobody surveils it to hand it over: its first item will.
                continue;
            }
            let slot = &mut self.owners[track as usize];
            if *slot != to {
                handovers.push(Handover {
                    track,
                    from: *slot,
                    to,
                    rides: false,
                });
                *slot = to;
            }
        }
        handovers
    }

    /// The leader surveilling each track now.
    pub fn owners(&self) -> &[u16] {
        &self.owners
    }

    pub fn owner(&self, track: u32) -> Option<u16> {
        self.owners.get(track as usize).copied()
    }

    /// Where each leader is, for a map: its place, or under fitted cells
    /// the centre of its cell (see [`Regions::cells`]).
    pub fn places(&self) -> Vec<Option<(f64, f64)>> {
        match &self.rule {
            Rule::Fitted(fitted) => fitted.places(&self.owners),
            Rule::Fixed(Some(places)) => places.iter().map(|&p| Some(p)).collect(),
            Rule::Fixed(None) => Vec::new(),
        }
    }

    /// Each leader's region as a rectangle `[x0, y0, x1, y1]` for a map,
    /// under fitted cells once drawn (cut to the box of the tracks seen so
    /// far); empty otherwise (fixed places: a leader's region is the
    /// points nearer to it than to any other, which a map draws itself).
    pub fn cells(&self) -> Vec<Option<[f64; 4]>> {
        match &self.rule {
            Rule::Fitted(fitted) => fitted.cells().unwrap_or_default(),
            Rule::Fixed(_) => Vec::new(),
        }
    }

    /// The fixed place nearest to (x, y) (the first of equals).
    fn nearest(places: &[(f64, f64)], x: f64, y: f64) -> Option<u16> {
        let mut best: Option<(f64, u16)> = None;
        for (i, &(lx, ly)) in places.iter().enumerate() {
            let d = (lx - x).powi(2) + (ly - y).powi(2);
            if best.is_none_or(|(b, _)| d < b) {
                best = Some((d, i as u16));
            }
        }
        best.map(|b| b.1)
    }

    /// `track` is now at (x, y): its handover if that changes its leader,
    /// which is then recorded (fitted cells not drawn yet: none).
    fn moved(&mut self, track: u32, x: f64, y: f64) -> Option<Handover> {
        let to = match &mut self.rule {
            Rule::Fixed(places) => Regions::nearest(places.as_deref()?, x, y)?,
            Rule::Fitted(fitted) => fitted.place(track, x, y)?,
        };
        if self.unheld.get(track as usize).copied().unwrap_or(false) {
            return None;
        }
        let slot = self.owners.get_mut(track as usize)?;
        let from = *slot;
        (from != to).then(|| {
            *slot = to;
            Handover {
                track,
                from,
                to,
                rides: false,
            }
        })
    }

    /// Takes one line of the stream before the item it routes (if any)
    /// goes out: at the first event after the leading moves, the
    /// handovers that put the tracks they placed in their regions; at a
    /// mix of tracks of two leaders (0 < swap < 1) under fitted cells, the
    /// handover that takes both to the leader that was sent fewer items
    /// since the stream began (a's on a tie), riding on the mix; at the
    /// first item on a track nobody surveils yet, its adoption.
    ///
    /// Adoption (a handover from [`UNHELD`] riding on the track's first
    /// item, which names the adopter: no item of its own): a newcomer
    /// meeting a track joins that track's leader unless that leader was
    /// sent more than [`crate::TOLERANCE`] times the mean so far; alone
    /// (a first observation or read), with another newcomer, or when the
    /// partner's leader is busy, it goes to the leader sent fewest items
    /// so far. Not to the leader of its cell: people enter a real scene
    /// through a few doors, and the doors' leaders became the busiest.
    ///
    /// Why take them: a mix across two leaders is an item at each either
    /// way, but kept apart it leaves the two tracks, which have just met
    /// and walk on together, with two leaders, so their next meetings are
    /// across too; the component of the one handed over is sent once
    /// instead of there and back. It helps most on real scenes, where
    /// people walk in groups (the balance example prints the shares).
    pub fn before(&mut self, line: &Line) -> Vec<Handover> {
        if !line.is_event() || matches!(line, Line::Move(_)) {
            return Vec::new();
        }
        let mut handovers = Vec::new();
        if self.leading.is_some() {
            if !self.assigned {
                handovers = self.assign();
            }
            self.leading = None;
            self.assigned = true;
        }
        let unheld = |t: u32| self.unheld.get(t as usize).copied().unwrap_or(false);
        match line {
            Line::Mix(mix) => match (unheld(mix.a), unheld(mix.b)) {
                (false, false) => handovers.extend(self.take(mix.a, mix.b, mix.swap)),
                (true, true) => {
                    let to = self.least_sent();
                    handovers.extend(self.adopt(mix.a, to));
                    handovers.extend(self.adopt(mix.b, to));
                }
                (true, false) => handovers.extend(self.join(mix.a, mix.b)),
                (false, true) => handovers.extend(self.join(mix.b, mix.a)),
            },
            Line::Observe(o) if unheld(o.track) => {
                let to = self.least_sent();
                handovers.extend(self.adopt(o.track, to));
            }
            Line::Identify(read) if unheld(read.track) => {
                let to = self.least_sent();
                handovers.extend(self.adopt(read.track, to));
            }
            _ => {}
        }
        handovers
    }

    /// The leader sent fewest items so far (the lowest of equals), where a
    /// newcomer goes that joins nobody's leader.
    fn least_sent(&self) -> u16 {
        match &self.rule {
            Rule::Fitted(fitted) => fitted.least_sent(),
            Rule::Fixed(_) => 0,
        }
    }

    /// Newcomer `track` meets `partner` at its first item: it joins the
    /// partner's leader, unless that leader was sent more than
    /// [`crate::TOLERANCE`] times the mean so far (then the least sent).
    fn join(&mut self, track: u32, partner: u32) -> Option<Handover> {
        let Rule::Fitted(fitted) = &self.rule else {
            return None;
        };
        let theirs = self.owners[partner as usize];
        let to = match fitted.busy(theirs) {
            true => fitted.least_sent(),
            false => theirs,
        };
        self.adopt(track, to)
    }

    /// `track`, which nobody surveilled, goes to leader `to`: a handover
    /// from [`UNHELD`] riding on the item it comes before, its first (the
    /// item adopts it: `Item::adoptions`), so no item of its own.
    fn adopt(&mut self, track: u32, to: u16) -> Option<Handover> {
        let slot = self.unheld.get_mut(track as usize)?;
        *slot = false;
        self.owners[track as usize] = to;
        Some(Handover {
            track,
            from: UNHELD,
            to,
            rides: true,
        })
    }

    /// The handover a mix of `a` and `b` makes, if it takes them both to
    /// one leader (see [`Regions::before`]).
    fn take(&mut self, a: u32, b: u32, swap: f64) -> Option<Handover> {
        let Rule::Fitted(fitted) = &self.rule else {
            return None;
        };
        if !(self.takes_mixes && uncertain(swap)) {
            return None;
        }
        let (owner_a, owner_b) = (self.owner(a)?, self.owner(b)?);
        if owner_a == owner_b {
            return None;
        }
        let (track, from, to) = if fitted.sent_so_far(owner_a) <= fitted.sent_so_far(owner_b) {
            (b, owner_b, owner_a)
        } else {
            (a, owner_a, owner_b)
        };
        self.owners[track as usize] = to;
        self.ridden_from = Some(from);
        Some(Handover {
            track,
            from,
            to,
            rides: true,
        })
    }

    /// Takes one line of the stream after the item it routes (if any) has
    /// gone to the owners it had: the handovers it makes, in order — a
    /// `move`'s into another region, then those of a redraw of fitted
    /// cells when the line ends a window that calls for one. Every
    /// process that follows owners (the sensor, `idmesh replay`, the
    /// simulator) calls [`Regions::before`] and this on the same lines, in
    /// the same order.
    pub fn after(&mut self, line: &Line) -> Vec<Handover> {
        let known = |t: u32| (t as usize) < self.owners.len();
        let mut handovers = Vec::new();
        match line {
            Line::Move(m) if known(m.track) => match &mut self.leading {
                Some(leading) => leading[m.track as usize] = Some((m.x, m.y)),
                // A track keeps its leader between redraws of fitted
                // cells, wherever it walks (see `crate::fitted`).
                None => match &mut self.rule {
                    Rule::Fitted(fitted) => fitted.record(m.track, m.x, m.y),
                    Rule::Fixed(_) => handovers.extend(self.moved(m.track, m.x, m.y)),
                },
            },
            Line::Mix(mix) if known(mix.a) && known(mix.b) => {
                let (a, b) = (self.owners[mix.a as usize], self.owners[mix.b as usize]);
                if let Rule::Fitted(fitted) = &mut self.rule {
                    // A mix that took a track was an item at its old
                    // leader too.
                    let mut leaders = vec![a];
                    leaders.extend((b != a).then_some(b));
                    leaders.extend(self.ridden_from.take());
                    fitted.sent(&[mix.a, mix.b], &leaders);
                }
            }
            Line::Observe(o) if known(o.track) => self.sent_one(o.track),
            Line::Identify(read) if known(read.track) => self.sent_one(read.track),
            _ => {}
        }
        let Rule::Fitted(fitted) = &mut self.rule else {
            return handovers;
        };
        for h in &handovers {
            fitted.sent(&[], &[h.from, h.to]);
        }
        if fitted.window_over() {
            let redrawn = self.draw();
            if let Rule::Fitted(fitted) = &mut self.rule {
                for h in &redrawn {
                    fitted.sent(&[], &[h.from, h.to]);
                }
            }
            handovers.extend(redrawn);
        }
        handovers
    }

    fn sent_one(&mut self, track: u32) {
        let owner = self.owners[track as usize];
        if let Rule::Fitted(fitted) = &mut self.rule {
            fitted.sent(&[track], &[owner]);
        }
    }
}

/// Whether a mix's swap is uncertain: only such a mix can carry a track
/// that changes leader (a certain one relabels, a swap of 0 is no event).
fn uncertain(swap: f64) -> bool {
    swap > 0.0 && swap < 1.0
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

    #[cfg(test)]
    pub(crate) fn belief(&self) -> &FactoredBelief {
        &self.belief
    }

    /// Before `line`'s event: the tracks handed over then
    /// ([`Regions::before`]) are split off their components.
    pub fn before(&mut self, line: &Line) -> Result<(), BeliefError> {
        // An adopted track was alone already.
        for handover in self.regions.before(line) {
            if handover.from != UNHELD {
                self.belief.split_off(handover.track)?;
            }
        }
        Ok(())
    }

    /// After `line`'s event: the tracks it hands over ([`Regions::after`])
    /// are split off their components.
    pub fn after(&mut self, line: &Line) -> Result<(), BeliefError> {
        for handover in self.regions.after(line) {
            self.belief.split_off(handover.track)?;
        }
        Ok(())
    }

    /// Applies one trace line: the handovers before it, its event, the
    /// handovers after it.
    pub fn apply_line(&mut self, line: &Line) -> Result<(), BeliefError> {
        self.before(line)?;
        if let Some(event) = event_of(line) {
            self.apply(&event)?;
        }
        self.after(line)
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
    use idmesh_protocol::trace::{Mix as MixLine, Observe as ObserveLine};

    /// An observation of `track`.
    fn seen(track: u32) -> Line {
        Line::Observe(ObserveLine {
            time: 0.0,
            track,
            red: 0.8,
            blue: 0.2,
            sensor: None,
        })
    }

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
        let mut r = Regions::fixed(&[Some((0.0, 0.0)), Some((10.0, 0.0))], 3);
        assert_eq!(r.owners(), &[0, 1, 0]);
        let h = |track, from, to| {
            Some(Handover {
                track,
                from,
                to,
                rides: false,
            })
        };
        assert_eq!(r.moved(0, 9.0, 0.0), h(0, 0, 1));
        assert_eq!(r.moved(0, 8.0, 0.0), None, "still nearest to leader 1");
        assert_eq!(r.moved(1, 1.0, 1.0), h(1, 1, 0));
        assert_eq!(r.moved(7, 1.0, 1.0), None, "an unknown track");
        // Without places nobody moves.
        let mut fixed = Regions::fixed(&[None, Some((1.0, 1.0))], 2);
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
        let places = RegionRule::Fixed(vec![Some((0.0, 0.0)), Some((10.0, 0.0))]);
        let r = Regions::starting(&places, 2, 3, &leading);
        assert_eq!(r.owners(), &[1, 1, 0]);
        // The same as starting round robin and moving there.
        let mut moved = Regions::new(&places, 2, 3);
        moved.moved(0, 8.0, 0.0);
        moved.moved(1, 9.0, 0.0);
        assert_eq!(moved.owners(), r.owners());
        // And the same as taking the lines one by one: the leading moves
        // place, the mix puts them in their regions before it.
        let mut taken = Regions::new(&places, 2, 3);
        let handed: Vec<_> = lines
            .iter()
            .flat_map(|l| {
                let mut h = taken.before(l);
                h.extend(taken.after(l));
                h
            })
            .collect();
        assert_eq!(taken.owners(), &[1, 1, 1], "2 moved after the mix");
        assert_eq!(handed.len(), 2);
        // Without places, round robin.
        let none = RegionRule::Fixed(vec![None, None]);
        assert_eq!(
            Regions::starting(&none, 2, 3, &leading).owners(),
            &[0, 1, 0]
        );
        // Under fitted cells nobody surveils a track before its first
        // item: the leading moves only draw the cells.
        let fitted = Regions::starting(&RegionRule::fitted(), 2, 3, &leading);
        assert_eq!(fitted.owners(), &[UNHELD; 3]);
        let mut taken = Regions::new(&RegionRule::fitted(), 2, 3);
        for line in &lines {
            taken.before(line);
            taken.after(line);
        }
        let mut started = fitted.clone();
        for line in &lines[..3] {
            assert!(started.before(line).is_empty() && started.after(line).is_empty());
        }
        // The mix of 0 and 1, both new, adopts both: to the leader sent
        // fewest items (both none: the lowest).
        let adopt = |track| Handover {
            track,
            from: UNHELD,
            to: 0,
            rides: true,
        };
        assert_eq!(started.before(&lines[3]), vec![adopt(0), adopt(1)]);
        assert!(started.after(&lines[3]).is_empty());
        // A stream that keeps mixes across (no regional components) holds
        // every track from the start, round robin, and takes nothing.
        let mut across = fitted.clone().keeping_mixes_across();
        for line in &lines[..4] {
            assert!(across.before(line).is_empty() && across.after(line).is_empty());
        }
        assert_eq!(across.owners(), &[0, 1, 0]);
        // Track 2's move after the mix only records where it is: it is
        // still new.
        assert_eq!(started.after(&lines[4]), vec![]);
        assert_eq!(started.owners(), &[0, 0, UNHELD]);
        assert_eq!(taken, started, "the same state either way");
        // A sensor fed live knows no leading moves ahead: it starts as the
        // replay does and reaches the same state over the same lines.
        let mut live = Regions::starting(&RegionRule::fitted(), 2, 3, &[]);
        for line in &lines {
            live.before(line);
            live.after(line);
        }
        assert_eq!(live, taken, "a live start is the replay's");
    }

    #[test]
    fn a_mix_across_two_leaders_goes_to_the_one_sent_fewer_items_so_far() {
        let leading = [Some((0.0, 0.0)), Some((10.0, 0.0))];
        let mut r = Regions::starting(&RegionRule::fitted(), 2, 2, &leading);
        // Each first seen alone: adopted by the leader sent fewest items.
        for track in [0, 1] {
            r.before(&seen(track));
            r.after(&seen(track));
        }
        let (busy, quiet) = (r.owner(0).unwrap(), r.owner(1).unwrap());
        assert_eq!((busy, quiet), (0, 1));
        // Track 0's leader is sent a whole window of items (100 a leader):
        // the window's end starts its counts again, so they are even at
        // the mix; the stream's are not.
        for _ in 0..200 {
            r.before(&seen(0));
            r.after(&seen(0));
        }
        let mix = Line::Mix(MixLine {
            time: 1.0,
            a: 0,
            b: 1,
            swap: 0.5,
        });
        let (busy, quiet) = (r.owner(0).unwrap(), r.owner(1).unwrap());
        assert_ne!(busy, quiet, "a redraw keeps them apart");
        let ride = Handover {
            track: 0,
            from: busy,
            to: quiet,
            rides: true,
        };
        assert_eq!(r.before(&mix), vec![ride]);
    }

    /// Under fitted cells a track is surveilled from its first item on,
    /// which adopts it (no item of its own): alone, by the leader sent
    /// fewest items so far; meeting a track, by that track's leader,
    /// unless that leader is busy.
    #[test]
    fn a_newcomer_joins_the_track_it_meets_unless_its_leader_is_busy() {
        let mix = |a, b, swap| {
            Line::Mix(MixLine {
                time: 0.0,
                a,
                b,
                swap,
            })
        };
        let adopt = |track, to| Handover {
            track,
            from: UNHELD,
            to,
            rides: true,
        };
        let mut r = Regions::new(&RegionRule::fitted(), 3, 7);
        assert_eq!(r.owners(), &[UNHELD; 7]);
        let mut step = |line: &Line| {
            let mut handovers = r.before(line);
            handovers.extend(r.after(line));
            handovers
        };
        assert_eq!(step(&seen(0)), vec![adopt(0, 0)]);
        assert_eq!(step(&seen(1)), vec![adopt(1, 1)]);
        // Meeting 1: to 1's leader, whatever the swap.
        assert_eq!(step(&mix(2, 1, 0.5)), vec![adopt(2, 1)]);
        assert_eq!(step(&mix(3, 1, 1.0)), vec![adopt(3, 1)]);
        // Leader 1 is sent far more than the mean: a newcomer meeting its
        // track goes to the least sent instead, and the mix is across.
        for _ in 0..30 {
            assert!(step(&seen(1)).is_empty());
        }
        assert_eq!(step(&mix(4, 1, 0.5)), vec![adopt(4, 2)]);
        // Two newcomers: both to the least sent (of equals the lowest).
        assert_eq!(step(&mix(5, 6, 0.5)), vec![adopt(5, 0), adopt(6, 0)]);
        assert_eq!(r.owners(), &[0, 1, 1, 1, 2, 0, 0]);
        // What each leader was sent, as `items_sent` counts it: the items
        // on its tracks, the mix across at both, adoptions nothing.
        let lines: Vec<Line> = [seen(0), seen(1), mix(2, 1, 0.5), mix(3, 1, 1.0)]
            .into_iter()
            .chain((0..30).map(|_| seen(1)))
            .chain([mix(4, 1, 0.5), mix(5, 6, 0.5)])
            .collect();
        assert_eq!(
            crate::items_sent(&RegionRule::fitted(), 3, 7, &lines),
            vec![2, 34, 1]
        );
    }

    /// A little crowd: 12 tracks moving on a 10 × 10 field, mixing (some of
    /// the mixes certain exchanges), observed now and then (a fixed
    /// linear congruential sequence, so the test needs no generator).
    fn lines(count: usize) -> Vec<Line> {
        use idmesh_protocol::trace::{Mix as MixLine, Move, Observe as ObserveLine};
        let mut state = 7u64;
        let mut next = |m: u64| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) % m
        };
        (0..count)
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
        let mut one = Regional::new(belief(), Regions::fixed(&[Some((5.0, 5.0))], 12));
        for line in &lines(400) {
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
        let fixed = Regional::new(belief(), Regions::fixed(&places, 12));
        let fitted = Regional::new(belief(), Regions::new(&RegionRule::fitted(), 3, 12));
        // The fitted cells' first window is 300 items long. Fixed places
        // keep mixes across regions apart; fitted cells take both tracks
        // to one leader, splitting the one handed over off its component.
        keeps_components_in_their_regions(fixed, 400, true);
        keeps_components_in_their_regions(fitted, 1500, false);
    }

    fn keeps_components_in_their_regions(mut three: Regional, count: usize, apart: bool) {
        for line in &lines(count) {
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
        assert_eq!(stats.kept_apart > 0, apart, "{stats:?}");
        assert!(stats.split_off > 0, "{stats:?}");
        assert!(three.belief().components().iter().any(|c| c.len() > 1));
    }
}
