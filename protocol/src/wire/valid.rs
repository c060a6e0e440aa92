//! What every message must be on its own, whoever receives it: the rules
//! that need no knowledge of the stream (finite, non-negative likelihoods,
//! probabilities in [0, 1], k ≤ n, distinct tracks, items in seq order,
//! sizes within [`MAX_TRACKS`]). [`decode`](super::decode) applies them, so
//! no process ever holds a message that breaks one. The rules that need the
//! stream's field (a track below n, a leader index below L) are
//! [`bounds`](super::bounds)'.
//!
//! Every error names the message ([`Versioned::WHAT`]) and says where in it
//! the fault is and what the value was.

use super::coordinator_to_leader::Partial;
use super::coordinator_to_sensor::CutPlaced;
use super::identity::MAX_GROUP as IDENTITY_GROUP;
use super::leader_to_leader::{Transfer, TransfersSent, TransfersWanted, WireRow, WireSet};
use super::leader_to_sensor::{Durable, Follow, Followed, Progress, Resend, Resent, Unfollow};
use super::sensor_to_leader::{Batch, Begin, Item, Sequenced, UNHELD};
use super::sensor_to_sensor::{Entry, IntakeSlice, IntakeWanted};
use super::{Versioned, WireError};

/// The most tracks a stream may have. A `Begin` lists an owner per track
/// and every leader keeps a flag per track, so a stream of 10^9 tracks
/// would cost gigabytes before the first event; a million is two orders of
/// magnitude beyond anything the engine has been run on.
pub const MAX_TRACKS: u32 = 1 << 20;

/// The most tracks of an identity stream whose leaders hold the
/// information matrix: n × n numbers (4096² f64 = 128 MiB), spread over
/// the leaders. The factored identity belief (`Begin::factored_identity`)
/// grows with the mixes, not n², and takes streams up to [`MAX_TRACKS`].
pub const MAX_IDENTITY_TRACKS: u32 = 1 << 12;

/// The most leaders a stream may name: indices are `u16`.
pub const MAX_LEADERS: usize = 1 << 16;

/// A message that can say whether it is well formed on its own.
pub trait Valid: Versioned {
    /// The first rule the message breaks, as a sentence that says where.
    fn problem(&self) -> Option<String>;

    /// [`Valid::problem`] as a [`WireError`] naming the message.
    fn validate(&self) -> Result<(), WireError> {
        match self.problem() {
            None => Ok(()),
            Some(problem) => Err(WireError::Invalid {
                what: Self::WHAT,
                problem,
            }),
        }
    }
}

/// `Err(sentence)` when `condition` fails: the rules below read as a list.
pub(crate) fn require(condition: bool, problem: impl FnOnce() -> String) -> Result<(), String> {
    if condition {
        Ok(())
    } else {
        Err(problem())
    }
}

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
            let bounds = super::bounds::Bounds::of(begin);
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
fn check_items(items: &[Sequenced], begin_allowed: bool) -> Result<(), String> {
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
    pub fn check(&self) -> Result<(), String> {
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

/// Distinct ids below `n`. Sorting a copy costs what the list costs, and
/// the list is bounded by the message's own bytes.
pub(crate) fn distinct_tracks(what: &str, tracks: &[u32], n: u32) -> Result<(), String> {
    if let Some(t) = tracks.iter().find(|&&t| t >= n) {
        return Err(format!("{what}: {t} is out of range (0..{n})"));
    }
    distinct(what, tracks)
}

/// No id twice.
fn distinct(what: &str, ids: &[u32]) -> Result<(), String> {
    let mut sorted = ids.to_vec();
    sorted.sort_unstable();
    match sorted.windows(2).find(|w| w[0] == w[1]) {
        Some(pair) => Err(format!("{what} lists {} twice", pair[0])),
        None => Ok(()),
    }
}

impl Valid for Transfer {
    fn problem(&self) -> Option<String> {
        self.check().err()
    }
}

impl Transfer {
    fn check(&self) -> Result<(), String> {
        for (i, set) in self.sets.iter().enumerate() {
            set.check().map_err(|e| format!("set {i}: {e}"))?;
        }
        let tracks: Vec<u32> = self.rows.iter().map(|r| r.track).collect();
        distinct("rows", &tracks)?;
        for row in &self.rows {
            row.check()?;
        }
        for (i, c) in self.components.iter().enumerate() {
            c.check().map_err(|e| format!("component {i}: {e}"))?;
        }
        Ok(())
    }
}

impl WireSet {
    /// φ_{red|blue}: each list without repeats, no track both red and
    /// blue, a log mass that is a number below +∞ (−∞ is a zero mass).
    pub fn check(&self) -> Result<(), String> {
        distinct("red", &self.red)?;
        distinct("blue", &self.blue)?;
        if let Some(t) = self.red.iter().find(|t| self.blue.contains(t)) {
            return Err(format!("track {t} is both red and blue"));
        }
        require(
            !self.ln_mass.is_nan() && self.ln_mass != f64::INFINITY,
            || format!("log mass = {}", self.ln_mass),
        )
    }
}

impl WireRow {
    /// Accumulated log-likelihoods: numbers below +∞ (−∞ is an identity
    /// ruled out by a certain read).
    pub fn check(&self) -> Result<(), String> {
        match self
            .ln_likelihoods
            .iter()
            .position(|x| x.is_nan() || *x == f64::INFINITY)
        {
            Some(i) => Err(format!(
                "row of track {}: log-likelihood [{i}] = {}",
                self.track, self.ln_likelihoods[i]
            )),
            None => Ok(()),
        }
    }
}

impl Valid for TransfersWanted {
    fn problem(&self) -> Option<String> {
        None
    }
}

impl Valid for TransfersSent {
    fn problem(&self) -> Option<String> {
        self.transfers
            .iter()
            .enumerate()
            .find_map(|(i, t)| t.problem().map(|e| format!("transfer {i}: {e}")))
    }
}

impl Valid for Follow {
    fn problem(&self) -> Option<String> {
        distinct("follow tracks", &self.tracks).err()
    }
}

impl Valid for Unfollow {
    fn problem(&self) -> Option<String> {
        distinct("unfollow tracks", &self.tracks).err()
    }
}

impl Valid for Followed {
    fn problem(&self) -> Option<String> {
        check_items(&self.items, false).err()
    }
}

impl Valid for Resend {
    fn problem(&self) -> Option<String> {
        self.leader
            .is_empty()
            .then(|| "a resend request names no leader".into())
    }
}

impl Valid for Durable {
    fn problem(&self) -> Option<String> {
        self.leader
            .is_empty()
            .then(|| "a durable mark names no leader".into())
    }
}

impl Valid for Progress {
    fn problem(&self) -> Option<String> {
        self.leader
            .is_empty()
            .then(|| "a progress mark names no leader".into())
    }
}

impl Valid for Resent {
    fn problem(&self) -> Option<String> {
        let mut previous: Option<u64> = None;
        for (i, batch) in self.batches.iter().enumerate() {
            if previous.is_some_and(|p| batch.number <= p) {
                return Some(format!("batch {i}: number {} out of order", batch.number));
            }
            previous = Some(batch.number);
            if let Some(e) = batch.problem() {
                return Some(format!("batch {i} (number {}): {e}", batch.number));
            }
        }
        None
    }
}

impl Valid for Partial {
    fn problem(&self) -> Option<String> {
        self.check().err()
    }
}

impl Partial {
    fn check(&self) -> Result<(), String> {
        // The scale of an empty share is whatever it was left at; its sums
        // are 0. Anything not a number would poison the coordinator's sum.
        require(
            !self.log_scale.is_nan() && self.log_scale != f64::INFINITY,
            || format!("log scale = {}", self.log_scale),
        )?;
        for (what, value) in [("total", self.total), ("outside", self.outside)] {
            require(value.is_finite(), || format!("{what} = {value}"))?;
        }
        let mut previous: Option<u32> = None;
        for &(t, x) in &self.inside {
            require(previous.is_none_or(|p| t > p), || {
                format!("inside: track {t} out of order or repeated")
            })?;
            require(t < MAX_TRACKS, || {
                format!("inside: track {t} is out of range")
            })?;
            require(x.is_finite(), || format!("inside: track {t} = {x}"))?;
            previous = Some(t);
        }
        let tracks: Vec<u32> = self.rows.iter().map(|r| r.track).collect();
        distinct("rows", &tracks)?;
        for row in &self.rows {
            row.check()?;
        }
        for (i, c) in self.components.iter().flatten().enumerate() {
            c.check().map_err(|e| format!("component {i}: {e}"))?;
        }
        require(self.base.is_none() || self.components.is_some(), || {
            "a change to a base answer without components".into()
        })?;
        require(self.base.is_some() || self.gone.is_empty(), || {
            "components gone without a base answer".into()
        })?;
        distinct("gone", &self.gone)?;
        require(self.passive.windows(2).all(|w| w[0] < w[1]), || {
            "passive: tracks out of order or repeated".into()
        })?;
        for (what, tracks) in [("gone", &self.gone), ("passive", &self.passive)] {
            if let Some(t) = tracks.iter().find(|&&t| t >= MAX_TRACKS) {
                return Err(format!("{what}: track {t} is out of range"));
            }
        }
        Ok(())
    }
}

impl Valid for CutPlaced {
    fn problem(&self) -> Option<String> {
        let n = self.tracks;
        if !(1..=MAX_TRACKS).contains(&n) {
            return Some(format!("tracks = {n} is not in 1..={MAX_TRACKS}"));
        }
        match self.red {
            Some(k) if k > n => Some(format!("red = {k} > tracks = {n}")),
            _ => None,
        }
    }
}

impl Valid for IntakeWanted {
    fn problem(&self) -> Option<String> {
        if self.sensor.is_empty() {
            return Some("no sensor named".into());
        }
        self.above
            .time
            .is_nan()
            .then(|| "the watermark's time is not a number".to_string())
    }
}

impl Valid for IntakeSlice {
    fn problem(&self) -> Option<String> {
        let mut previous: Option<&super::sensor_to_sensor::Position> = None;
        for (i, (position, entry)) in self.entries.iter().enumerate() {
            let cut = matches!(entry, Entry::Cut { .. });
            if position.time.is_nan() || (!cut && position.time.is_infinite()) {
                return Some(format!(
                    "entry {i}: time {} is not a finite number",
                    position.time
                ));
            }
            if cut == (position.sub == 0 || position.sensor.is_empty()) {
                return Some(format!(
                    "entry {i}: a position {position:?} of the wrong kind"
                ));
            }
            if !cut && position.producer.is_empty() {
                return Some(format!("entry {i}: no producer"));
            }
            if previous.is_some_and(|p| position <= p) {
                return Some(format!("entry {i}: position {position:?} out of order"));
            }
            if *position > self.watermark {
                return Some(format!(
                    "entry {i}: position {position:?} past the watermark"
                ));
            }
            if let Entry::Line(text) = entry {
                if text.len() > 1 << 16 {
                    return Some(format!("entry {i}: a line of {} bytes", text.len()));
                }
            }
            previous = Some(position);
        }
        self.watermark
            .time
            .is_nan()
            .then(|| "the watermark's time is not a number".to_string())
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
            growth: crate::wire::sensor_to_leader::Growth::All,
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
    fn transfers_partials_and_cuts_are_checked() {
        let transfer = |set: WireSet, rows: Vec<WireRow>| Transfer {
            trees: Vec::new(),
            components: Vec::new(),
            version: VERSION,
            from: 0,
            seq: 3,
            sets: vec![set],
            rows,
        };
        let set = |red: Vec<u32>, blue: Vec<u32>, ln_mass: f64| WireSet { red, blue, ln_mass };
        let ok = transfer(set(vec![1], vec![2], f64::NEG_INFINITY), vec![]);
        assert_eq!(decode::<Transfer>(&encode(&ok)).unwrap(), ok);
        for (bad, expected) in [
            (
                transfer(set(vec![1, 1], vec![], 0.0), vec![]),
                "red lists 1 twice",
            ),
            (
                transfer(set(vec![1], vec![1], 0.0), vec![]),
                "both red and blue",
            ),
            (
                transfer(set(vec![1], vec![], f64::NAN), vec![]),
                "log mass = NaN",
            ),
            (
                transfer(
                    set(vec![], vec![], 0.0),
                    vec![WireRow {
                        track: 0,
                        ln_likelihoods: vec![0.0, f64::NAN],
                    }],
                ),
                "log-likelihood [1] = NaN",
            ),
        ] {
            let e = decode::<Transfer>(&encode(&bad)).unwrap_err().to_string();
            assert!(e.starts_with("transfer: ") && e.contains(expected), "{e}");
        }
        let partial = Partial {
            trees: Vec::new(),
            components: None,
            base: None,
            gone: Vec::new(),
            passive: Vec::new(),
            version: VERSION,
            leader: "a".into(),
            cut: 1,
            tag: 0,
            events: 0,
            finished: false,
            log_scale: 0.0,
            total: 1.0,
            outside: 0.25,
            inside: vec![(0, 0.5), (3, 0.25)],
            coefficients: 2,
            rows: vec![],
        };
        assert!(decode::<Partial>(&encode(&partial)).is_ok());
        let bad = Partial {
            inside: vec![(3, 0.5), (0, 0.25)],
            ..partial.clone()
        };
        assert!(decode::<Partial>(&encode(&bad)).is_err());
        let bad = Partial {
            total: f64::INFINITY,
            ..partial.clone()
        };
        assert!(decode::<Partial>(&encode(&bad)).is_err());
        // A change to a base answer: only of components, each track gone once.
        let change = Partial {
            components: Some(Vec::new()),
            base: Some(7),
            gone: vec![2, 5],
            ..partial.clone()
        };
        assert!(decode::<Partial>(&encode(&change)).is_ok());
        for (bad, expected) in [
            (
                Partial {
                    gone: vec![2, 2],
                    ..change.clone()
                },
                "gone",
            ),
            (
                Partial {
                    components: None,
                    ..change.clone()
                },
                "without components",
            ),
            (
                Partial {
                    base: None,
                    ..change
                },
                "without a base",
            ),
        ] {
            let e = decode::<Partial>(&encode(&bad)).unwrap_err().to_string();
            assert!(e.contains(expected), "{e}");
        }
        let cut = CutPlaced {
            version: VERSION,
            sensor: "s".into(),
            seq: 1,
            events: 0,
            leaders: vec!["a".into()],
            tracks: 4,
            red: Some(5),
            finished: false,
            identities: false,
            origins: Vec::new(),
        };
        assert!(decode::<CutPlaced>(&encode(&cut))
            .unwrap_err()
            .to_string()
            .contains("red = 5"));
    }
}
