//! Reports in, trace lines out. The [`Extractor`] groups reports into
//! frames (every report at one time is a frame; a frame closes when a
//! report with a later time arrives, or at [`Extractor::finish`]) and
//! senses each closed frame as the property paper's Section 6 does its
//! motion ([`FrameSensing`]):
//!
//! 1. `move` lines for every present track, every `move_interval` seconds;
//! 2. a `mix` for each pair that starts a meeting (ascending pairs), with
//!    the swap probability of the [`MeetingModel`](crate::MeetingModel);
//! 3. an `observe` for each isolated track with class scores that is due
//!    (ascending), likelihoods from the [`ScoreMapping`](crate::ScoreMapping);
//! 4. an `identify` for each identity read (ascending tracks).
//!
//! The first line out is the header (trace format version 2, one track
//! per roster entry), written when the roster is fixed.
//!
//! Determinism: within a frame, reports are taken in track order whatever
//! order they came in, so merging several tracker outputs in any order
//! that keeps time order gives the same events. Nothing is drawn at
//! random. The whole state (roster, contacts, look schedule, the open
//! frame, the previous frame's positions) serializes —
//! [`Extractor::snapshot`] and [`Extractor::restore`] — so a live sensor
//! can journal it and resume to the same output.
//!
//! A report that breaks a rule is refused with a [`ReportError`] and
//! leaves the state as it was; the caller counts it. The roster policy
//! (see [`roster`]) says what happens to a track that appears mid-stream.

pub(crate) mod config;
pub(crate) mod error;
pub(crate) mod report;
pub(crate) mod roster;

#[cfg(test)]
mod tests;

pub use config::ExtractorConfig;
pub use error::ReportError;
pub use report::{IdentityRead, Report};
pub use roster::{Roster, RosterPolicy};

use crate::frame::FrameSensing;
use crate::geometry::Vec2;
use crate::meetings::{CalibrationError, Entering, Meeting};
use idmesh_protocol::trace::{check_scores, Header, Identify, Line, Mix, Move, Observe};
use serde::{Deserialize, Serialize};
use std::collections::BTreeSet;

/// Tolerance on move times (seconds), as the simulator's.
const EPS: f64 = 1e-9;

/// The reports of one time, by tracker id.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Frame {
    time: f64,
    reports: Vec<Report>,
    /// The tracker ids reported in it: a second report of one is refused
    /// in O(log n), not by scanning the frame (quadratic at 10,000 tracks).
    #[serde(default)]
    ids: BTreeSet<u32>,
}

/// The event extractor; see the module docs.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Extractor {
    config: ExtractorConfig,
    policy: RosterPolicy,
    roster: Option<Roster>,
    sensing: Option<FrameSensing>,
    frame: Option<Frame>,
    /// Time of the last closed frame.
    closed: Option<f64>,
    /// Time of the first frame.
    start: Option<f64>,
    /// Each track's position in the previous closed frame, for velocities.
    previous: Vec<Option<Vec2>>,
    moves_done: u64,
    header_written: bool,
    /// Meetings since the last [`Extractor::take_meetings`].
    meetings: Vec<Meeting>,
    /// The input's own header, whose prior (red count, initial colours and
    /// identities) the output header carries ([`Extractor::with_prior`]).
    #[serde(default)]
    prior: Option<Header>,
    /// The red count the output header declares, over the prior's
    /// ([`Extractor::with_red`]).
    #[serde(default)]
    red: Option<usize>,
}

impl Extractor {
    /// An extractor with these settings and roster policy.
    pub fn new(config: ExtractorConfig, policy: RosterPolicy) -> Result<Self, CalibrationError> {
        config.validate()?;
        let mut extractor = Extractor {
            config,
            policy: policy.clone(),
            roster: None,
            sensing: None,
            frame: None,
            closed: None,
            start: None,
            previous: Vec::new(),
            moves_done: 0,
            header_written: false,
            meetings: Vec::new(),
            prior: None,
            red: None,
        };
        if let RosterPolicy::Declared(ids) = policy {
            if ids.is_empty() {
                return Err(CalibrationError::Invalid(
                    "a declared roster needs at least one track".into(),
                ));
            }
            extractor.fix_roster(Roster::of(ids));
        }
        Ok(extractor)
    }

    /// The extractor of a stream of reports that opens with `header` (JSON
    /// lines with a header, a sensor's stream, `idmesh replay --topology`):
    /// its tracks `0..tracks` are the roster, its identities turn identity
    /// reads on, its prior is carried ([`Extractor::with_prior`]).
    pub fn for_stream(
        mut config: ExtractorConfig,
        header: &Header,
    ) -> Result<Self, CalibrationError> {
        config.identities |= header.identities.is_some();
        let roster = RosterPolicy::Declared((0..header.tracks as u32).collect());
        Ok(Extractor::new(config, roster)?.with_prior(header))
    }

    /// The output header carries `header`'s prior: its red count, initial
    /// red tracks, identities and initial identities. A stream of reports
    /// that opens with a header (JSON lines, a live sensor's trace) says
    /// what is known of its targets there, and the events extracted from
    /// it must be believed from that same start.
    pub fn with_prior(mut self, header: &Header) -> Self {
        self.prior = Some(header.clone());
        self
    }

    /// The output header declares `red` red targets (k) when given: a
    /// tracker's output says nothing of the property, and without k the
    /// belief has no prior to start from but one half.
    pub(crate) fn with_red(mut self, red: Option<usize>) -> Self {
        self.red = red.or(self.red);
        self
    }

    /// The roster, once fixed.
    pub(crate) fn roster(&self) -> Option<&Roster> {
        self.roster.as_ref()
    }

    /// Takes one report; appends to `out` the lines of any frame it
    /// closes. A refused report changes nothing.
    pub fn push(&mut self, report: Report, out: &mut Vec<Line>) -> Result<(), ReportError> {
        self.check(&report)?;
        if self.frame.as_ref().is_some_and(|f| report.time > f.time) {
            self.close_frame(out);
        }
        match &mut self.frame {
            Some(frame) => {
                frame.ids.insert(report.track);
                frame.reports.push(report);
            }
            None => {
                self.frame = Some(Frame {
                    time: report.time,
                    ids: BTreeSet::from([report.track]),
                    reports: vec![report],
                })
            }
        }
        Ok(())
    }

    /// Closes the open frame: the end of the reports (more may follow:
    /// a later frame).
    pub fn finish(&mut self, out: &mut Vec<Line>) {
        if self.frame.is_some() {
            self.close_frame(out);
        } else if !self.header_written && self.roster.is_some() {
            self.write_header(out);
        }
    }

    /// The meetings found since the last call, with their distances.
    pub fn take_meetings(&mut self) -> Vec<Meeting> {
        std::mem::take(&mut self.meetings)
    }

    /// The whole state as JSON.
    pub fn snapshot(&self) -> String {
        // Every float in the state is finite (reports are checked), so
        // JSON holds it exactly (serde_json's float_roundtrip).
        serde_json::to_string(self).expect("the extractor's state is plain data")
    }

    /// An extractor from a [`Extractor::snapshot`].
    pub fn restore(snapshot: &str) -> Result<Self, serde_json::Error> {
        serde_json::from_str(snapshot)
    }

    /// The rules a report must meet, checked before anything changes.
    /// Whether [`Extractor::push`] would take `report`, without taking it:
    /// a live sensor answers a producer before routing its lines.
    pub(crate) fn check(&self, report: &Report) -> Result<(), ReportError> {
        if !report.time.is_finite() {
            return Err(ReportError::NonFiniteTime { time: report.time });
        }
        for (field, value) in [("x", report.x), ("y", report.y)] {
            if !value.is_finite() {
                return Err(ReportError::NonFinitePosition { field, value });
            }
        }
        if let Some(scores) = &report.scores {
            check_scores(scores).map_err(ReportError::Scores)?;
        }
        let previous = self.frame.as_ref().map(|f| f.time).or(self.closed);
        if let Some(previous) = previous {
            if report.time < previous {
                return Err(ReportError::OutOfOrder {
                    time: report.time,
                    previous,
                });
            }
        }
        let same_frame = self.frame.as_ref().filter(|f| f.time == report.time);
        if same_frame.is_some_and(|f| f.ids.contains(&report.track)) {
            return Err(ReportError::DuplicateTrack {
                track: report.track,
                time: report.time,
            });
        }
        // The roster this report must be in: the fixed one, or the first
        // frame's ids when this report closes the first frame.
        let known = match (&self.roster, &self.frame) {
            (Some(roster), _) => Some((roster.track_of(report.track).is_some(), roster.len())),
            (None, Some(first)) if report.time > first.time => {
                Some((first.ids.contains(&report.track), first.reports.len()))
            }
            (None, _) => None,
        };
        if let Some((false, tracks)) = known {
            return Err(ReportError::UnknownTrack {
                track: report.track,
                tracks,
                fixed: match self.policy {
                    RosterPolicy::Declared(_) => "by declaration",
                    RosterPolicy::FirstFrame => "by the first frame",
                },
            });
        }
        if let Some(read) = report.identity {
            if !self.config.identities {
                return Err(ReportError::IdentitiesOff);
            }
            if !(read.accuracy > 0.0 && read.accuracy <= 1.0) {
                return Err(ReportError::BadAccuracy(read.accuracy));
            }
            // Identities are one per track; before the first frame fixes
            // the roster, the count is the first frame's tracks so far
            // (this one included), which only grows: a read accepted now
            // stays valid (one early in the first frame may be refused).
            let identities = match (&self.roster, known) {
                (Some(roster), _) => roster.len(),
                (None, Some((_, tracks))) => tracks,
                (None, None) => same_frame.map_or(0, |f| f.reports.len()) + 1,
            };
            if read.identity as usize >= identities {
                return Err(ReportError::UnknownIdentity {
                    identity: read.identity,
                    identities,
                });
            }
        }
        Ok(())
    }

    fn fix_roster(&mut self, roster: Roster) {
        let n = roster.len();
        let c = &self.config;
        self.sensing = Some(FrameSensing::new(
            n,
            c.mix_distance,
            c.release_distance(),
            c.observe_distance,
            c.observe_interval,
        ));
        self.previous = vec![None; n];
        self.roster = Some(roster);
    }

    fn write_header(&mut self, out: &mut Vec<Line>) {
        let n = self.roster.as_ref().map_or(0, Roster::len);
        let c = &self.config;
        let mut header = Header::new_v2(n);
        header.identities = c.identities.then_some(n);
        if let Some(prior) = &self.prior {
            header.red = prior.red;
            header.initial_red = prior.initial_red.clone();
            header.identities = prior.identities.or(header.identities);
            header.initial_identity = prior.initial_identity.clone();
        }
        if self.red.is_some() {
            header.red = self.red;
        }
        header.source = Some(c.source.clone());
        header.description = Some(format!(
            "extracted: mix within {} m (release at {} m), observe beyond {} m at most every {} s, \
             meetings {}, scores of {:?} at temperature {}",
            c.mix_distance,
            c.release_distance(),
            c.observe_distance,
            c.observe_interval,
            serde_json::to_string(&c.meeting_model).unwrap_or_default(),
            c.scores.label,
            c.scores.temperature
        ));
        out.push(header.into());
        self.header_written = true;
    }

    fn close_frame(&mut self, out: &mut Vec<Line>) {
        let Some(frame) = self.frame.take() else {
            return;
        };
        if self.roster.is_none() {
            self.fix_roster(Roster::of(frame.reports.iter().map(|r| r.track)));
        }
        if !self.header_written {
            self.write_header(out);
        }
        let time = frame.time;
        let start = *self.start.get_or_insert(time);
        let roster = self.roster.as_ref().expect("fixed above");
        let n = roster.len();
        let mut by_track: Vec<Option<&Report>> = vec![None; n];
        for report in &frame.reports {
            // Checked on the way in: every report's id is in the roster.
            if let Some(track) = roster.track_of(report.track) {
                by_track[track as usize] = Some(report);
            }
        }
        let positions: Vec<Option<Vec2>> = by_track
            .iter()
            .map(|r| r.map(|r| Vec2::new(r.x, r.y)))
            .collect();

        if let Some(interval) = self.config.move_interval {
            let since = time - start;
            if since >= self.moves_done as f64 * interval - EPS {
                for (track, p) in positions.iter().enumerate() {
                    if let Some(p) = p {
                        out.push(Line::Move(Move {
                            time,
                            track: track as u32,
                            x: p.x,
                            y: p.y,
                        }));
                    }
                }
                self.moves_done = if interval > 0.0 {
                    ((since + EPS) / interval).floor() as u64 + 1
                } else {
                    0
                };
            }
        }

        let mut entering: Vec<Entering> = Vec::new();
        let mut due: Vec<u32> = Vec::new();
        let sensing = self.sensing.as_mut().expect("fixed with the roster");
        sensing.sense(
            time,
            &positions,
            |i| by_track[i].is_some_and(|r| r.scores.is_some()),
            &mut entering,
            &mut due,
        );
        let dt = self.closed.map(|c| time - c).filter(|&dt| dt > 0.0);
        let velocity = |i: usize| -> Option<Vec2> {
            let (now, before) = (positions[i]?, self.previous[i]?);
            dt.map(|dt| (now - before) * (1.0 / dt))
        };
        for e in &entering {
            let (a, b) = (e.a as usize, e.b as usize);
            let (Some(pa), Some(pb)) = (positions[a], positions[b]) else {
                continue;
            };
            let meeting = Meeting::predict(time, (e.a, pa, velocity(a)), (e.b, pb, velocity(b)));
            out.push(Line::Mix(Mix {
                time,
                a: e.a,
                b: e.b,
                swap: self.config.meeting_model.swap(&meeting),
            }));
            self.meetings.push(meeting);
        }
        for &track in &due {
            if let Some(scores) = by_track[track as usize].and_then(|r| r.scores.as_ref()) {
                let (red, blue) = self.config.scores.likelihoods(scores);
                out.push(Line::Observe(Observe {
                    time,
                    track,
                    red,
                    blue,
                    sensor: None,
                }));
            }
        }
        for (track, report) in by_track.iter().enumerate() {
            if let Some(read) = report.and_then(|r| r.identity) {
                out.push(Line::Identify(Identify {
                    time,
                    track: track as u32,
                    identity: read.identity,
                    accuracy: read.accuracy,
                }));
            }
        }
        self.previous = positions;
        self.closed = Some(time);
    }
}
