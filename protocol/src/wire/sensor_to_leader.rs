//! The event stream from the sensor gateway to one leader.
//!
//! The sensor stamps every item with a sequence number that is global to the
//! deployment (the order in which the sensor read the events) and sends each
//! leader only the items that concern it (see [`interest`](super::interest)),
//! in batches, over one FIFO link: a leader that has a batch has every item
//! meant for it with a smaller seq. `through` says how far the stream has
//! got even when nothing in it was for this leader.
//!
//! The rules of the stream's messages sit beside them, below the types:
//! what a batch, an item and a `Begin` must be on their own ([`Valid`],
//! which [`decode`](super::decode) applies) and what an item must be to
//! fit the stream's field ([`Bounds`]).

use super::bounds::{invalid, Bounds};
use super::factored::FactoredStart;
use super::identity::MAX_GROUP as IDENTITY_GROUP;
use super::valid::{distinct_tracks, require, MAX_IDENTITY_TRACKS, MAX_LEADERS, MAX_TRACKS};
use super::{Valid, WireError};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Batch {
    pub version: u16,
    /// The epoch at which the sending process holds the sensor role
    /// ([`super::epoch`]; 0 without voters): a batch resent carries the
    /// epoch of the holder that resends it.
    pub epoch: u64,
    pub sensor: String,
    /// Counts batches to this leader from 0: a gap is a lost batch.
    pub number: u64,
    /// Every item for this leader with seq ≤ `through` is in this batch or
    /// an earlier one.
    pub through: u64,
    /// Trace events read through `through` (the watermark there).
    pub events: u64,
    /// The sensor has read its whole source: nothing comes after `through`.
    pub finished: bool,
    pub items: Vec<Sequenced>,
}
super::versioned!(Batch, "event batch");
super::epoch::epoched!(Batch);

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Sequenced {
    pub seq: u64,
    pub item: Item,
}

/// How an observation grows sets (the conditioning rule in force).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Growth {
    /// Exact conditioning: every set grows (Algorithm 2).
    All,
    /// The distributed rule: sets meeting these tracks (the observed
    /// track's mixing log) grow (Algorithm 5).
    Meeting(Vec<u32>),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Item {
    /// The start of the stream: the field and who owns which track.
    Begin(Begin),
    /// Targets on tracks a and b mixed. `owner_a`/`owner_b` are the leaders
    /// (indices into `Begin::leaders`) surveilling them at this point.
    /// `handed`: under the regional rule with fitted regions, a mix of
    /// tracks of two leaders takes both to one of them; the track that
    /// changes leader rides on the mix (handed over from `from` to the
    /// owners named, before the mix), so that the mix is one item at each
    /// of the two leaders, as a mix kept apart is. `adopted`: the tracks
    /// of the two (none, one or both) that no leader surveilled before
    /// this item, their first: each is adopted here by the owner named for
    /// it ([`Begin::owners`]).
    Mix {
        a: u32,
        b: u32,
        swap: f64,
        owner_a: u16,
        owner_b: u16,
        handed: Option<Handed>,
        adopted: Vec<u32>,
    },
    Observe {
        track: u32,
        red: f64,
        blue: f64,
        growth: Growth,
        /// Every leader must apply it: exact conditioning, or a certain
        /// sighting, which removes the sets that do not fix the track.
        global: bool,
        /// The track's first item: no leader surveilled it, and this one
        /// adopts it ([`Begin::owners`]).
        adopted_by: Option<u16>,
    },
    /// A sensor read `identity` on track `track` (identity streams), sent
    /// only to `owner`, the leader surveilling the track, which holds the
    /// track's row of the information matrix: evidence costs no message
    /// between leaders.
    Identify {
        track: u32,
        identity: u32,
        accuracy: f64,
        owner: u16,
        /// The track's first item: `owner` adopts it ([`Begin::owners`]).
        adopted: bool,
    },
    /// Track `track` left the region of leader `from` for that of `to`.
    Handover { track: u32, from: u16, to: u16 },
    /// A consistent cut asked for by a query: every leader computes its
    /// partial sums here. `events` counts the trace events before it; `tag`
    /// is the query's, so leaders asked for it before it reaches them know
    /// which cut to wait for. `rows`: an identity query, leaders add their
    /// rows of the information matrix to their answer.
    Cut { events: u64, tag: u64, rows: bool },
}

/// The track a mix takes from another leader ([`Item::Mix`]): it was
/// surveilled by `from` until this item.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Handed {
    pub track: u32,
    pub from: u16,
}

/// The owner of a track no leader surveils yet ([`Begin::owners`]).
pub const UNHELD: u16 = u16::MAX;

/// Of `leaders` leaders, the one that keeps an unheld `track`'s start
/// component and row ([`Begin::owners`]): `track mod L`.
pub fn keeper(track: u32, leaders: usize) -> u16 {
    (track as usize % leaders.max(1)) as u16
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Begin {
    pub tracks: u32,
    /// k, when known.
    pub red: Option<u32>,
    pub initial_red: Option<Vec<u32>>,
    /// The leaders' names, in the order the indices refer to.
    pub leaders: Vec<String>,
    /// The owner (leader index) of every track at the start, or
    /// [`UNHELD`]: on a factored stream under the regional rule a track
    /// is surveilled from its first item on, which adopts it
    /// ([`Item::adoptions`]; docs/design/architecture.md, "Newcomers"). Until then its start component is kept, followed by
    /// nobody, by its *keeper* ([`Begin::keeper`]), which gives it as a
    /// passive part in its answers ([`Partial::passive`](super::coordinator_to_leader::Partial::passive)).
    pub owners: Vec<u16>,
    pub distributed_rule: bool,
    /// Each leader's coefficient budget (0 = no pruning).
    pub budget: u32,
    /// Over budget, re-express with OMP after runs of mixing before
    /// thresholding (the overcomplete method), each leader on its own sets.
    pub omp: bool,
    /// An identity stream (one identity per track): each leader keeps the
    /// rows of the information matrix of the tracks it surveils.
    pub identities: bool,
    /// The known identity on every track at the start; None = uniform.
    pub initial_identity: Option<Vec<u32>>,
    /// The leaders hold the factored belief with these settings (None:
    /// the Radon belief).
    pub factored: Option<FactoredStart>,
    /// On an identity stream with a known start and the factored belief,
    /// the leaders hold the factored identity belief (docs/design/identity.md)
    /// with groups of at most this many slots (2..=9) instead of the rows
    /// of the information matrix: each linked tree of groups whole, at one
    /// leader. None: the rows.
    pub factored_identity: Option<u32>,
}

impl Begin {
    /// The leader that keeps the start component (and row) of `track` while
    /// no leader surveils it ([`Begin::owners`]): [`keeper`].
    pub fn keeper(&self, track: u32) -> u16 {
        keeper(track, self.leaders.len())
    }

    /// Whether `track` starts unheld ([`UNHELD`]).
    pub fn starts_unheld(&self, track: u32) -> bool {
        self.owners.get(track as usize) == Some(&UNHELD)
    }

    /// Whether the first leader holds the whole factored belief
    /// ([`FactoredStart::whole`]): false on a Radon stream.
    pub fn held_whole(&self) -> bool {
        self.factored
            .as_ref()
            .is_some_and(|f| f.whole(self.tracks, self.leaders.len()))
    }

    /// Whether leader `me` holds the start component (and row) of `track`:
    /// it surveils the track, or keeps it unheld.
    pub fn holds_at_start(&self, track: u32, me: u16) -> bool {
        match self.owners.get(track as usize) {
            Some(&UNHELD) => self.keeper(track) == me,
            Some(&owner) => owner == me,
            None => false,
        }
    }
}

impl Item {
    /// The tracks this item adopts, each with the leader adopting it: the
    /// tracks it is the first item of on a stream whose tracks start
    /// unheld ([`Begin::owners`]). The adopting leader takes the track's
    /// start component and row before applying the item.
    pub fn adoptions(&self) -> Vec<(u32, u16)> {
        match self {
            Item::Mix {
                a,
                b,
                owner_a,
                owner_b,
                adopted,
                ..
            } => adopted
                .iter()
                .map(|&t| (t, if t == *a { *owner_a } else { *owner_b }))
                .filter(|&(t, _)| t == *a || t == *b)
                .collect(),
            Item::Observe {
                track,
                adopted_by: Some(leader),
                ..
            } => vec![(*track, *leader)],
            Item::Identify {
                track,
                owner,
                adopted: true,
                ..
            } => vec![(*track, *owner)],
            _ => Vec::new(),
        }
    }
}

// What a message of the stream must be on its own.

impl Valid for Batch {
    fn problem(&self) -> Option<String> {
        self.check().err()
    }
}

impl Batch {
    fn check(&self) -> Result<(), String> {
        // Batch 0 opens the stream with its Begin (the sensor queues it
        // first); a Begin anywhere else would restart a leader's state.
        if self.number == 0 {
            require(
                matches!(
                    self.items.first(),
                    Some(Sequenced {
                        item: Item::Begin(_),
                        ..
                    })
                ),
                || "batch 0 must start with the stream's Begin".into(),
            )?;
        }
        check_items(&self.items, self.number == 0)?;
        if let Some(last) = self.items.last() {
            require(last.seq <= self.through, || {
                format!(
                    "item seq {} is after the batch's through = {}",
                    last.seq, self.through
                )
            })?;
        }
        // A batch that opens the stream can be checked against it at once.
        if let Some(Sequenced {
            item: Item::Begin(begin),
            ..
        }) = self.items.first()
        {
            let bounds = Bounds::of(begin);
            for (i, s) in self.items.iter().enumerate().skip(1) {
                bounds
                    .check_item(&s.item)
                    .map_err(|e| format!("item {i} (seq {}): {e}", s.seq))?;
            }
        }
        Ok(())
    }
}

/// Items in strictly increasing seq order from 1, each well formed; a
/// Begin only first, and only where `begin_allowed`.
pub(crate) fn check_items(items: &[Sequenced], begin_allowed: bool) -> Result<(), String> {
    let mut previous = 0u64;
    for (i, Sequenced { seq, item }) in items.iter().enumerate() {
        require(*seq > previous, || {
            format!(
                "item {i}: seq {seq} does not follow seq {previous} (seqs start at 1 and increase)"
            )
        })?;
        previous = *seq;
        if matches!(item, Item::Begin(_)) {
            require(begin_allowed && i == 0, || {
                format!("item {i} (seq {seq}): a Begin may only open batch 0")
            })?;
        }
        item.check()
            .map_err(|e| format!("item {i} (seq {seq}): {e}"))?;
    }
    Ok(())
}

impl Item {
    /// The rules of one item on its own.
    pub(crate) fn check(&self) -> Result<(), String> {
        match self {
            Item::Begin(begin) => begin.check(),
            Item::Mix {
                a,
                b,
                swap,
                owner_a,
                owner_b,
                handed,
                adopted,
            } => {
                require(a != b, || format!("mix of track {a} with itself"))?;
                let named = |t: &u32| t == a || t == b;
                require(adopted.len() <= 2 && adopted.iter().all(named), || {
                    format!("mix of tracks {a} and {b} adopts tracks {adopted:?}")
                })?;
                require(adopted.len() < 2 || adopted[0] != adopted[1], || {
                    format!("mix adopts track {} twice", adopted[0])
                })?;
                if let Some(h) = handed {
                    require(!adopted.contains(&h.track), || {
                        format!("mix both hands over and adopts track {}", h.track)
                    })?;
                }
                if let Some(h) = handed {
                    require(*swap > 0.0 && *swap < 1.0, || {
                        format!("mix handing a track over with swap {swap}, not in (0, 1)")
                    })?;
                    require(h.track == *a || h.track == *b, || {
                        format!("mix of tracks {a} and {b} hands over track {}", h.track)
                    })?;
                    require(owner_a == owner_b && h.from != *owner_a, || {
                        format!(
                            "mix handing track {} from leader {} must name one other owner, got {owner_a} and {owner_b}",
                            h.track, h.from
                        )
                    })?;
                }
                probability("mix swap", *swap)
            }
            Item::Observe { red, blue, .. } => likelihoods(*red, *blue),
            Item::Identify { accuracy, .. } => require(*accuracy > 0.0 && *accuracy <= 1.0, || {
                format!("identify accuracy = {accuracy} is not in (0, 1]")
            }),
            Item::Handover { track, from, to } => require(from != to, || {
                format!("handover of track {track} from leader {from} to itself")
            }),
            Item::Cut { .. } => Ok(()),
        }
    }
}

/// A probability: a number in [0, 1] (NaN is not).
fn probability(what: &str, p: f64) -> Result<(), String> {
    require((0.0..=1.0).contains(&p), || {
        format!("{what} = {p} is not a probability in [0, 1]")
    })
}

/// An observation's two likelihoods: finite, non-negative, not both 0
/// (the trace spec's rules for `observe`).
fn likelihoods(red: f64, blue: f64) -> Result<(), String> {
    for (which, value) in [("red", red), ("blue", blue)] {
        require(value.is_finite() && value >= 0.0, || {
            format!("observe likelihood {which} = {value} is not a finite number >= 0")
        })?;
    }
    require(red > 0.0 || blue > 0.0, || {
        "observe likelihoods red and blue are both 0".into()
    })
}

impl Begin {
    /// The field and the leaders, consistent: n in 1..=MAX_TRACKS, k ≤ n,
    /// one owner per track among the leaders, distinct leader names.
    pub fn check(&self) -> Result<(), String> {
        let n = self.tracks;
        require((1..=MAX_TRACKS).contains(&n), || {
            format!("begin tracks = {n} is not in 1..={MAX_TRACKS}")
        })?;
        if self.identities && self.factored_identity.is_none() {
            require(n <= MAX_IDENTITY_TRACKS, || {
                format!(
                    "begin: an identity stream of {n} tracks held as an information matrix (at \
                     most {MAX_IDENTITY_TRACKS}: n × n numbers; with a known start the factored \
                     identity belief takes any size)"
                )
            })?;
        }
        if let Some(k) = self.red {
            require(k <= n, || {
                format!("begin red = {k} > tracks = {n} (k must be <= n)")
            })?;
        }
        if let Some(initial) = &self.initial_red {
            if let Some(k) = self.red {
                require(initial.len() == k as usize, || {
                    format!(
                        "begin initial_red has {} tracks but red = {k}",
                        initial.len()
                    )
                })?;
            }
            distinct_tracks("begin initial_red", initial, n)?;
        }
        let leaders = self.leaders.len();
        require((1..=MAX_LEADERS).contains(&leaders), || {
            format!("begin names {leaders} leaders (1..={MAX_LEADERS})")
        })?;
        let mut names: Vec<&str> = self.leaders.iter().map(String::as_str).collect();
        names.sort_unstable();
        if let Some(pair) = names.windows(2).find(|w| w[0] == w[1]) {
            return Err(format!("begin names leader {:?} twice", pair[0]));
        }
        require(self.owners.len() == n as usize, || {
            format!(
                "begin has {} owners for {n} tracks (one per track)",
                self.owners.len()
            )
        })?;
        // Unheld tracks only where a first item can adopt them.
        let adopts = self.factored.as_ref().is_some_and(|f| f.regional);
        if let Some((t, o)) = self
            .owners
            .iter()
            .enumerate()
            .find(|(_, &o)| o as usize >= leaders && !(o == UNHELD && adopts))
        {
            return Err(match *o {
                UNHELD => format!(
                    "begin owners[{t}] is unheld, which only a factored stream under the regional rule allows"
                ),
                _ => format!("begin owners[{t}] = {o} is not a leader (there are {leaders})"),
            });
        }
        if let Some(assignment) = &self.initial_identity {
            require(assignment.len() == n as usize, || {
                format!(
                    "begin initial_identity has {} entries for {n} tracks",
                    assignment.len()
                )
            })?;
            distinct_tracks("begin initial_identity", assignment, n)?;
        }
        if let Some(factored) = &self.factored {
            factored.check()?;
        }
        let elsewhere = self.owners.iter().position(|&o| o != 0);
        if let Some(t) = elsewhere.filter(|_| self.held_whole()) {
            return Err(format!(
                "begin owners[{t}] = {}: a crowd of {n} tracks (spread_above = {}) is held \
                 whole by the first leader",
                self.owners[t],
                self.factored.as_ref().map_or(0, |f| f.spread_above)
            ));
        }
        if let Some(cap) = self.factored_identity {
            require((2..=IDENTITY_GROUP).contains(&cap), || {
                format!("begin factored_identity = {cap} is not in 2..={IDENTITY_GROUP}")
            })?;
            require(
                self.identities && self.initial_identity.is_some() && self.factored.is_some(),
                || {
                    "begin factored_identity needs an identity stream with a known start \
                     (initial_identity) on the factored belief"
                        .into()
                },
            )?;
        }
        Ok(())
    }
}

// What an item must be to fit the stream's field.

impl Bounds {
    /// The field of the stream `begin` opens.
    pub fn of(begin: &Begin) -> Self {
        Bounds {
            tracks: begin.tracks,
            leaders: begin.leaders.len(),
            identities: begin.identities,
            adopts: begin.factored.as_ref().is_some_and(|f| f.regional),
        }
    }

    /// One item of the stream against the field.
    pub(crate) fn check_item(&self, item: &Item) -> Result<(), String> {
        let adoptions = item.adoptions();
        require(adoptions.is_empty() || self.adopts, || {
            "an adoption on a stream whose tracks start held".into()
        })?;
        for (track, leader) in adoptions {
            self.leader(&format!("the adopter of track {track}"), leader)?;
        }
        match item {
            // Checked on its own; a second one is refused by the batch rules.
            Item::Begin(_) | Item::Cut { .. } => Ok(()),
            Item::Mix {
                a,
                b,
                owner_a,
                owner_b,
                handed,
                ..
            } => {
                self.track("mix a", *a)?;
                self.track("mix b", *b)?;
                self.leader("mix owner_a", *owner_a)?;
                if let Some(h) = handed {
                    self.leader("mix handed from", h.from)?;
                }
                self.leader("mix owner_b", *owner_b)
            }
            Item::Observe { track, growth, .. } => {
                self.track("observe track", *track)?;
                if let Growth::Meeting(tracks) = growth {
                    for &t in tracks {
                        self.track("observe growth track", t)?;
                    }
                }
                Ok(())
            }
            Item::Identify {
                track,
                identity,
                owner,
                ..
            } => {
                require(self.identities, || {
                    "an identity read on a stream without identities".into()
                })?;
                self.track("identify track", *track)?;
                self.track("identify identity", *identity)?;
                self.leader("identify owner", *owner)
            }
            Item::Handover { track, from, to } => {
                self.track("handover track", *track)?;
                self.leader("handover from", *from)?;
                self.leader("handover to", *to)
            }
        }
    }

    /// Every item against the field, naming the one that does not fit.
    pub(crate) fn check_items(&self, items: &[Sequenced]) -> Result<(), String> {
        for (i, Sequenced { seq, item }) in items.iter().enumerate() {
            self.check_item(item)
                .map_err(|e| format!("item {i} (seq {seq}): {e}"))?;
        }
        Ok(())
    }

    /// A batch of this stream (a Begin it carries is the stream's own).
    pub fn check_batch(&self, batch: &Batch) -> Result<(), WireError> {
        self.check_items(&batch.items)
            .map_err(|problem| invalid("event batch", problem))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::wire::{decode, encode, VERSION};

    fn begin() -> Begin {
        Begin {
            factored_identity: None,
            factored: None,
            tracks: 4,
            red: Some(2),
            initial_red: Some(vec![0, 1]),
            leaders: vec!["a".into(), "b".into()],
            owners: vec![0, 0, 1, 1],
            distributed_rule: false,
            budget: 0,
            omp: false,
            identities: false,
            initial_identity: None,
        }
    }

    fn batch(number: u64, items: Vec<Item>) -> Batch {
        let first = if number == 0 { 1 } else { 2 };
        Batch {
            version: VERSION,
            epoch: 0,
            sensor: "s".into(),
            number,
            through: first + items.len() as u64,
            events: 0,
            finished: false,
            items: items
                .into_iter()
                .enumerate()
                .map(|(i, item)| Sequenced {
                    seq: first + i as u64,
                    item,
                })
                .collect(),
        }
    }

    fn mix(swap: f64) -> Item {
        Item::Mix {
            adopted: Vec::new(),
            a: 0,
            b: 2,
            swap,
            owner_a: 0,
            owner_b: 1,
            handed: None,
        }
    }

    fn observe(red: f64, blue: f64) -> Item {
        Item::Observe {
            adopted_by: None,
            track: 1,
            red,
            blue,
            growth: Growth::All,
            global: true,
        }
    }

    /// The error `decode` gives for a batch, as text.
    fn rejected(b: &Batch) -> String {
        match decode::<Batch>(&encode(b)) {
            Err(WireError::Invalid { what, problem }) => format!("{what}: {problem}"),
            other => panic!("expected a rejection, got {other:?}"),
        }
    }

    #[test]
    fn well_formed_batches_decode() {
        let first = batch(0, vec![Item::Begin(begin()), mix(0.5), observe(0.8, 0.2)]);
        assert_eq!(decode::<Batch>(&encode(&first)).unwrap(), first);
        let later = batch(3, vec![mix(0.0), mix(1.0), observe(0.0, 1.0)]);
        assert_eq!(decode::<Batch>(&encode(&later)).unwrap(), later);
    }

    #[test]
    fn bad_numbers_are_rejected_and_the_error_says_where() {
        for (swap, shown) in [(1.5, "1.5"), (-0.1, "-0.1"), (f64::NAN, "NaN")] {
            let e = rejected(&batch(2, vec![mix(0.5), mix(swap)]));
            assert!(
                e.contains("event batch") && e.contains("item 1 (seq 3)"),
                "{e}"
            );
            assert!(e.contains(&format!("swap = {shown}")), "{e}");
        }
        for (red, blue) in [
            (f64::NAN, 0.5),
            (f64::INFINITY, 0.5),
            (0.5, f64::NEG_INFINITY),
            (-0.2, 0.5),
            (0.0, 0.0),
        ] {
            let e = rejected(&batch(2, vec![observe(red, blue)]));
            assert!(e.contains("observe likelihood"), "{e}");
        }
        let e = rejected(&batch(
            2,
            vec![Item::Identify {
                adopted: false,
                track: 0,
                identity: 0,
                accuracy: 0.0,
                owner: 0,
            }],
        ));
        assert!(e.contains("accuracy = 0"), "{e}");
    }

    /// A factored crowd of at most `spread_above` tracks among several
    /// leaders is the first leader's: a `Begin` giving a track to another
    /// is refused; spread, it is not; one leader holds any crowd whole.
    #[test]
    fn a_crowd_held_whole_is_the_first_leaders_alone() {
        let factored = |spread_above| crate::wire::factored::FactoredStart {
            max_component: 6,
            split: crate::wire::factored::WireSplit::Original,
            shrink: true,
            regional: true,
            spread_above,
        };
        let whole = Begin {
            factored: Some(factored(4)),
            ..begin()
        };
        assert!(whole.held_whole());
        let e = whole.check().unwrap_err();
        assert!(
            e.contains("owners[2] = 1") && e.contains("held whole"),
            "{e}"
        );
        let gathered = Begin {
            owners: vec![0; 4],
            ..whole
        };
        assert_eq!(gathered.check(), Ok(()));
        let spread = Begin {
            factored: Some(factored(3)),
            ..begin()
        };
        assert!(!spread.held_whole() && spread.check().is_ok());
        let one = Begin {
            leaders: vec!["a".into()],
            owners: vec![0; 4],
            ..spread
        };
        assert!(one.held_whole());
        assert!(!begin().held_whole(), "a Radon stream is never held whole");
    }

    #[test]
    fn a_begin_must_describe_a_field_it_can_hold() {
        let cases: Vec<(Begin, &str)> = vec![
            (
                Begin {
                    red: Some(5),
                    initial_red: None,
                    ..begin()
                },
                "k must be <= n",
            ),
            (
                Begin {
                    tracks: 0,
                    owners: vec![],
                    initial_red: None,
                    red: None,
                    ..begin()
                },
                "tracks = 0",
            ),
            (
                Begin {
                    tracks: 2_000_000_000,
                    ..begin()
                },
                "tracks = 2000000000",
            ),
            (
                Begin {
                    owners: vec![0, 0, 1],
                    ..begin()
                },
                "3 owners for 4 tracks",
            ),
            (
                Begin {
                    owners: vec![0, 0, 1, 2],
                    ..begin()
                },
                "owners[3] = 2",
            ),
            (
                Begin {
                    initial_red: Some(vec![0, 0]),
                    ..begin()
                },
                "lists 0 twice",
            ),
            (
                Begin {
                    initial_red: Some(vec![0, 7]),
                    ..begin()
                },
                "7 is out of range",
            ),
            (
                Begin {
                    leaders: vec!["a".into(), "a".into()],
                    ..begin()
                },
                "leader \"a\" twice",
            ),
            (
                Begin {
                    identities: true,
                    initial_identity: Some(vec![0, 1, 1, 2]),
                    ..begin()
                },
                "initial_identity lists 1 twice",
            ),
        ];
        for (b, expected) in cases {
            let e = rejected(&batch(0, vec![Item::Begin(b)]));
            assert!(e.contains(expected), "{e} (wanted {expected:?})");
        }
    }

    #[test]
    fn the_order_of_a_stream_is_checked() {
        let no_begin = rejected(&batch(0, vec![mix(0.5)]));
        assert!(
            no_begin.contains("must start with the stream's Begin"),
            "{no_begin}"
        );
        let second = rejected(&batch(4, vec![Item::Begin(begin())]));
        assert!(second.contains("may only open batch 0"), "{second}");
        let mut backwards = batch(2, vec![mix(0.5), mix(0.5)]);
        backwards.items[1].seq = 1;
        assert!(rejected(&backwards).contains("does not follow"));
        let mut ahead = batch(2, vec![mix(0.5)]);
        ahead.through = 1;
        assert!(rejected(&ahead).contains("after the batch's through"));
        // Batch 0 is checked against its own Begin.
        let outside = rejected(&batch(
            0,
            vec![
                Item::Begin(begin()),
                Item::Mix {
                    adopted: Vec::new(),
                    a: 0,
                    b: 9,
                    swap: 0.5,
                    owner_a: 0,
                    owner_b: 1,
                    handed: None,
                },
            ],
        ));
        assert!(outside.contains("mix b = 9 is not a track"), "{outside}");
    }

    #[test]
    fn tracks_and_leaders_beyond_the_stream_are_named() {
        let e = Bounds::of_tests()
            .check_item(&Item::Mix {
                adopted: Vec::new(),
                a: 0,
                b: 4,
                swap: 0.5,
                owner_a: 0,
                owner_b: 1,
                handed: None,
            })
            .unwrap_err();
        assert_eq!(e, "mix b = 4 is not a track (there are 4)");
        let e = Bounds::of_tests()
            .check_item(&Item::Handover {
                track: 1,
                from: 0,
                to: 7,
            })
            .unwrap_err();
        assert_eq!(e, "handover to = 7 is not a leader (there are 2)");
        let e = Bounds::of_tests()
            .check_item(&Item::Observe {
                adopted_by: None,
                track: 1,
                red: 0.5,
                blue: 0.5,
                growth: Growth::Meeting(vec![2, 40]),
                global: false,
            })
            .unwrap_err();
        assert!(e.contains("growth track = 40"), "{e}");
        let e = Bounds::of_tests()
            .check_item(&Item::Identify {
                adopted: false,
                track: 1,
                identity: 1,
                accuracy: 0.9,
                owner: 0,
            })
            .unwrap_err();
        assert!(e.contains("without identities"), "{e}");
    }
}
