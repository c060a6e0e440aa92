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
use super::leader_to_leader::{Transfer, TransfersSent, TransfersWanted, WireRow, WireSet};
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

/// Distinct ids below `n`. Sorting a copy costs what the list costs, and
/// the list is bounded by the message's own bytes.
pub(crate) fn distinct_tracks(what: &str, tracks: &[u32], n: u32) -> Result<(), String> {
    if let Some(t) = tracks.iter().find(|&&t| t >= n) {
        return Err(format!("{what}: {t} is out of range (0..{n})"));
    }
    distinct(what, tracks)
}

/// No id twice.
pub(crate) fn distinct(what: &str, ids: &[u32]) -> Result<(), String> {
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
