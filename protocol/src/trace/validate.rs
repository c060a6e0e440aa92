//! The spec's rules: what makes a header valid, what makes a line valid under
//! a header, and the rules about the sequence of lines (one header, first;
//! non-decreasing times). Both the reader and the writer apply them, so a
//! trace this crate writes is one it reads back.

use super::line::{
    Detect, Header, Identify, Line, Mix, Move, Observe, Truth, FORMAT, SCORE_SUM_TOLERANCE,
    SUPPORTED_VERSIONS,
};
use super::problem::Problem;

impl Header {
    /// Checks the header on its own.
    pub fn validate(&self) -> Result<(), Problem> {
        if self.format != FORMAT {
            return Err(Problem::BadFormat(self.format.clone()));
        }
        if !SUPPORTED_VERSIONS.contains(&self.version) {
            return Err(Problem::BadVersion(self.version));
        }
        if self.tracks == 0 {
            return Err(Problem::NoTracks);
        }
        if self.tracks as u64 > u64::from(u32::MAX) + 1 {
            return Err(Problem::TooManyTracks(self.tracks));
        }
        if let Some(red) = self.red {
            if red > self.tracks {
                return Err(Problem::TooManyRed {
                    red,
                    tracks: self.tracks,
                });
            }
        }
        if let Some(initial) = &self.initial_red {
            match self.red {
                Some(red) if initial.len() != red => {
                    return Err(Problem::InitialRedLength {
                        len: initial.len(),
                        red,
                    })
                }
                None if initial.len() > self.tracks => {
                    return Err(Problem::InitialRedTooLong {
                        len: initial.len(),
                        tracks: self.tracks,
                    })
                }
                _ => {}
            }
            check_track_set("header", "initial_red", initial, self.tracks)?;
        }
        if let Some(identities) = self.identities {
            if identities != self.tracks {
                return Err(Problem::IdentityCount {
                    identities,
                    tracks: self.tracks,
                });
            }
        }
        if let Some(assignment) = &self.initial_identity {
            check_assignment("header", "initial_identity", assignment, self.tracks)?;
        }
        Ok(())
    }

    /// Checks `track` is one of this trace's tracks.
    pub(crate) fn check_track(
        &self,
        kind: &'static str,
        field: &'static str,
        track: u32,
    ) -> Result<(), Problem> {
        if (track as usize) < self.tracks {
            Ok(())
        } else {
            Err(Problem::UnknownTrack {
                kind,
                field,
                track,
                tracks: self.tracks,
            })
        }
    }
}

impl Mix {
    pub fn validate(&self, header: &Header) -> Result<(), Problem> {
        header.check_track("mix", "a", self.a)?;
        header.check_track("mix", "b", self.b)?;
        if self.a == self.b {
            return Err(Problem::SelfMix(self.a));
        }
        if !(0.0..=1.0).contains(&self.swap) {
            return Err(Problem::BadSwap(self.swap));
        }
        Ok(())
    }
}

impl Observe {
    pub fn validate(&self, header: &Header) -> Result<(), Problem> {
        header.check_track("observe", "track", self.track)?;
        for (which, value) in [("red", self.red), ("blue", self.blue)] {
            if !value.is_finite() {
                return Err(Problem::NonFiniteLikelihood { which, value });
            }
            if value < 0.0 {
                return Err(Problem::NegativeLikelihood { which, value });
            }
        }
        if self.red == 0.0 && self.blue == 0.0 {
            return Err(Problem::ZeroLikelihoods);
        }
        Ok(())
    }
}

impl Identify {
    pub fn validate(&self, header: &Header) -> Result<(), Problem> {
        header.check_track("identify", "track", self.track)?;
        let Some(identities) = header.identities else {
            return Err(Problem::NoIdentities);
        };
        if self.identity as usize >= identities {
            return Err(Problem::UnknownIdentity {
                identity: self.identity,
                identities,
            });
        }
        if !(self.accuracy > 0.0 && self.accuracy <= 1.0) {
            return Err(Problem::BadAccuracy(self.accuracy));
        }
        Ok(())
    }
}

impl Move {
    pub fn validate(&self, header: &Header) -> Result<(), Problem> {
        header.check_track("move", "track", self.track)?;
        for (field, value) in [("x", self.x), ("y", self.y)] {
            if !value.is_finite() {
                return Err(Problem::NonFinitePosition { field, value });
            }
        }
        Ok(())
    }
}

impl Detect {
    /// Version 2 only; the position must be finite, scores (when present)
    /// a non-empty map of probabilities summing to 1 within
    /// [`SCORE_SUM_TOLERANCE`], an identity read both fields or neither.
    pub fn validate(&self, header: &Header) -> Result<(), Problem> {
        if header.version < super::line::VERSION_2 {
            return Err(Problem::DetectNeedsVersion2 {
                version: header.version,
            });
        }
        header.check_track("detect", "track", self.track)?;
        for (field, value) in [("x", self.x), ("y", self.y)] {
            if !value.is_finite() {
                return Err(Problem::DetectNonFinitePosition { field, value });
            }
        }
        if let Some(scores) = &self.scores {
            check_scores(scores)?;
        }
        match (self.identity, self.accuracy) {
            (None, None) => {}
            (Some(identity), Some(accuracy)) => {
                let Some(identities) = header.identities else {
                    return Err(Problem::DetectNoIdentities);
                };
                if identity as usize >= identities {
                    return Err(Problem::DetectUnknownIdentity {
                        identity,
                        identities,
                    });
                }
                if !(accuracy > 0.0 && accuracy <= 1.0) {
                    return Err(Problem::DetectBadAccuracy(accuracy));
                }
            }
            _ => return Err(Problem::HalfIdentityRead),
        }
        Ok(())
    }
}

/// Class scores: non-empty, each in [0, 1], summing to 1 within
/// [`SCORE_SUM_TOLERANCE`]. Public so that adapters reading scores from
/// other formats apply the same rule.
pub fn check_scores(scores: &std::collections::BTreeMap<String, f64>) -> Result<(), Problem> {
    if scores.is_empty() {
        return Err(Problem::EmptyScores);
    }
    for (label, &value) in scores {
        if !(value.is_finite() && (0.0..=1.0).contains(&value)) {
            return Err(Problem::BadScore {
                label: label.clone(),
                value,
            });
        }
    }
    let sum: f64 = scores.values().sum();
    if (sum - 1.0).abs() > SCORE_SUM_TOLERANCE {
        return Err(Problem::ScoresDoNotSumToOne {
            sum,
            tolerance: SCORE_SUM_TOLERANCE,
        });
    }
    Ok(())
}

impl Truth {
    pub fn validate(&self, header: &Header) -> Result<(), Problem> {
        if self.red.is_none() && self.identity.is_none() {
            return Err(Problem::EmptyTruth);
        }
        if let Some(red) = &self.red {
            if let Some(k) = header.red_count() {
                if red.len() != k {
                    return Err(Problem::TruthRedLength {
                        len: red.len(),
                        red: k,
                    });
                }
            }
            check_track_set("truth", "red", red, header.tracks)?;
        }
        if let Some(assignment) = &self.identity {
            check_assignment("truth", "identity", assignment, header.tracks)?;
        }
        Ok(())
    }
}

impl Line {
    /// Checks a line other than the header against the trace's header (a
    /// header is checked on its own, [`Header::validate`]).
    pub fn validate(&self, header: &Header) -> Result<(), Problem> {
        if let Some(time) = self.time() {
            if !time.is_finite() {
                return Err(Problem::NonFiniteTime {
                    kind: self.kind(),
                    time,
                });
            }
        }
        match self {
            Line::Header(h) => h.validate(),
            Line::Mix(l) => l.validate(header),
            Line::Observe(l) => l.validate(header),
            Line::Identify(l) => l.validate(header),
            Line::Move(l) => l.validate(header),
            Line::Truth(l) => l.validate(header),
            Line::Detect(l) => l.validate(header),
        }
    }
}

impl Line {
    /// Refuses a `detect` line where a stream of events is expected (the
    /// sensor gateway, a replay): detect lines are a tracker's reports,
    /// which `idmesh extract` turns into events, and dropping them quietly
    /// would lose every mix and observation they hold.
    pub fn require_extracted(&self) -> Result<(), Problem> {
        match self {
            Line::Detect(_) => Err(Problem::NotExtracted),
            _ => Ok(()),
        }
    }
}

/// Distinct ids, each a track.
fn check_track_set(
    kind: &'static str,
    field: &'static str,
    tracks: &[u32],
    n: usize,
) -> Result<(), Problem> {
    for &track in tracks {
        if track as usize >= n {
            return Err(Problem::UnknownTrack {
                kind,
                field,
                track,
                tracks: n,
            });
        }
    }
    let mut sorted = tracks.to_vec();
    sorted.sort_unstable();
    if let Some(pair) = sorted.windows(2).find(|pair| pair[0] == pair[1]) {
        return Err(Problem::RepeatedTrack {
            kind,
            field,
            track: pair[0],
        });
    }
    Ok(())
}

/// A permutation of `0..n`: `assignment[t]` is the identity on track t.
fn check_assignment(
    kind: &'static str,
    field: &'static str,
    assignment: &[u32],
    n: usize,
) -> Result<(), Problem> {
    if assignment.len() != n {
        return Err(Problem::AssignmentLength {
            kind,
            field,
            len: assignment.len(),
            tracks: n,
        });
    }
    let mut holder: Vec<Option<usize>> = vec![None; n];
    for (track, &identity) in assignment.iter().enumerate() {
        let Some(slot) = holder.get_mut(identity as usize) else {
            return Err(Problem::AssignmentOutOfRange {
                kind,
                field,
                track,
                identity,
                identities: n,
            });
        };
        if let Some(first) = *slot {
            return Err(Problem::AssignmentRepeats {
                kind,
                field,
                identity,
                first,
                second: track,
            });
        }
        *slot = Some(track);
    }
    Ok(())
}

/// The rules about the sequence of lines: exactly one header, first, and
/// non-decreasing times. Feed it every line in order.
#[derive(Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct Validator {
    #[serde(with = "super::as_json")]
    header: Option<(Header, usize)>,
    last_time: Option<(f64, usize)>,
}

impl Validator {
    pub fn new() -> Self {
        Self::default()
    }

    /// The header, once it has been accepted.
    pub fn header(&self) -> Option<&Header> {
        self.header.as_ref().map(|(header, _)| header)
    }

    /// Checks line `number` (1-based) and, when it is valid, records it.
    pub fn check(&mut self, line: &Line, number: usize) -> Result<(), Problem> {
        let header = match (&self.header, line) {
            (Some((_, first)), Line::Header(_)) => {
                return Err(Problem::SecondHeader { first: *first })
            }
            (None, Line::Header(header)) => {
                header.validate()?;
                self.header = Some((header.clone(), number));
                return Ok(());
            }
            (None, other) => return Err(Problem::HeaderNotFirst { kind: other.kind() }),
            (Some((header, _)), _) => header,
        };
        line.validate(header)?;
        if let Some(time) = line.time() {
            if let Some((previous, previous_line)) = self.last_time {
                if time < previous {
                    return Err(Problem::TimeGoesBack {
                        kind: line.kind(),
                        time,
                        previous,
                        previous_line,
                    });
                }
            }
            self.last_time = Some((time, number));
        }
        Ok(())
    }

    /// Checks the trace may end here (it had its header).
    pub(crate) fn finish(&self) -> Result<(), Problem> {
        match self.header {
            Some(_) => Ok(()),
            None => Err(Problem::Empty),
        }
    }
}
