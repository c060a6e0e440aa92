//! The simulated sensor and tracker: fed the positions of every step, it
//! emits the `mix` and `observe` events of that step (Section 6 of the
//! paper) and keeps the ground truth — which target each track follows —
//! in step with the swaps it draws. It works as a tracker does, on
//! *tracks*: each step it places every track at the position of the target
//! it follows, and which pairs meet and which tracks are isolated is
//! `idmesh-extract`'s [`FrameSensing`] on those track positions, the swap
//! probability of a meeting is the extractor's [`MeetingModel`] of the
//! [`Meeting`] predicted from the tracks' last two positions. So the
//! positions it reports ([`Extractor::reports`]) fed to `idmesh-extract`'s
//! extractor give exactly its events: the simulator is the extractor plus
//! drawn swaps and sensor outcomes.
//!
//! Within a step, mixes come first (pairs in ascending track order, each
//! exchanging the targets of its two tracks with the meeting's swap
//! probability), then observations (isolated tracks in ascending order).
//! A swap shows from the next step on: at the step of a meeting, the
//! tracks are still where their targets were before it.

use super::assignment::Assignment;
use super::event::{SimEvent, TimedEvent};
use super::sensor_model::SensorModel;
use crate::geometry::Vec2;
use idmesh_extract::Entering;
use idmesh_extract::FrameSensing;
use idmesh_extract::{ExtractorConfig, Meeting, MeetingModel, Report};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;

/// How events are extracted from motion.
#[derive(Debug, Clone, PartialEq)]
pub struct ExtractionParams {
    /// Two targets closer than this mix (metres).
    pub mix_distance: f64,
    /// A mixed pair can mix again only after separating beyond
    /// `release_factor × mix_distance` (≥ 1).
    pub release_factor: f64,
    /// A target with nobody within this distance is isolated and can be
    /// observed (metres).
    pub observe_distance: f64,
    /// At most one observation per target per this many seconds.
    pub observe_interval: f64,
    /// How likely the tracker exchanges two meeting targets.
    pub meetings: MeetingModel,
    /// What an observation reports.
    pub sensor: SensorModel,
}

impl Default for ExtractionParams {
    /// The scenario defaults: mix within 1 m (release at 1.25 m), observe
    /// beyond 3.5 m at most every 3 s, swap 0.5, colour-histogram sensor.
    fn default() -> Self {
        ExtractionParams {
            mix_distance: 1.0,
            release_factor: 1.25,
            observe_distance: 3.5,
            observe_interval: 3.0,
            meetings: MeetingModel::Constant(0.5),
            sensor: SensorModel::colour_histogram(),
        }
    }
}

impl ExtractionParams {
    /// Checks that every parameter is usable; returns what is wrong.
    pub fn validate(&self) -> Result<(), String> {
        // These are the extractor's settings: checked by it, with its words.
        self.extractor_config()
            .validate()
            .map_err(|e| e.to_string())
    }

    /// The settings of `idmesh-extract`'s extractor that finds this
    /// simulator's events in the positions it reports (class scores read
    /// at temperature 1: the sensor's likelihoods as they are).
    pub fn extractor_config(&self) -> ExtractorConfig {
        ExtractorConfig {
            mix_distance: self.mix_distance,
            release_factor: self.release_factor,
            observe_distance: self.observe_distance,
            observe_interval: self.observe_interval,
            meeting_model: self.meetings,
            move_interval: None,
            ..ExtractorConfig::default()
        }
    }
}

/// Turns successive frames of positions into events.
#[derive(Debug, Clone)]
pub struct Extractor {
    params: ExtractionParams,
    is_red: Vec<bool>,
    assignment: Assignment,
    sensing: FrameSensing,
    swap_rng: ChaCha8Rng,
    sensor_rng: ChaCha8Rng,
    /// Each track's position at the last step with anyone present, and
    /// that step's time: the velocities of a meeting, as the extractor
    /// takes them from its previous frame.
    previous: Vec<Option<Vec2>>,
    previous_time: Option<f64>,
    /// What the tracker reported, when asked to keep it.
    reports: Option<Vec<Report>>,
    tracks: Vec<Option<Vec2>>,
    entering: Vec<Entering>,
    due: Vec<u32>,
}

impl Extractor {
    /// `is_red[i]` is the colour of target i; track t starts on target t.
    /// Swap draws come from `swap_rng`, sensor draws from `sensor_rng`.
    /// Panics on invalid parameters (the scenario builder checks them).
    pub(crate) fn new(
        params: ExtractionParams,
        is_red: Vec<bool>,
        swap_rng: ChaCha8Rng,
        sensor_rng: ChaCha8Rng,
    ) -> Self {
        if let Err(e) = params.validate() {
            panic!("{e}");
        }
        let n = is_red.len();
        Extractor {
            sensing: FrameSensing::new(
                n,
                params.mix_distance,
                params.mix_distance * params.release_factor,
                params.observe_distance,
                params.observe_interval,
            ),
            params,
            is_red,
            assignment: Assignment::identity(n),
            swap_rng,
            sensor_rng,
            previous: vec![None; n],
            previous_time: None,
            reports: None,
            tracks: vec![None; n],
            entering: Vec::new(),
            due: Vec::new(),
        }
    }

    /// Keeps what the simulated tracker reports each step — every present
    /// track's position, with class scores `{"red": s, "blue": 1 − s}`
    /// where the sensor saw a colour (s the sensor's red likelihood,
    /// normalised) — for [`Extractor::take_reports`].
    pub(crate) fn keep_reports(mut self) -> Self {
        self.reports = Some(Vec::new());
        self
    }

    /// The reports kept since the last call (empty unless
    /// [`Extractor::keep_reports`]).
    pub(crate) fn take_reports(&mut self) -> Vec<Report> {
        self.reports
            .as_mut()
            .map(std::mem::take)
            .unwrap_or_default()
    }

    /// Extracts the events of the step at `time` from the targets'
    /// `positions`, appending at most `limit` of them to `out`; returns how
    /// many it appended. When the limit cuts a step short, the rest of
    /// that step is dropped (including its swaps), so the truth matches
    /// the events kept.
    pub(crate) fn step(
        &mut self,
        time: f64,
        positions: &[Option<Vec2>],
        out: &mut Vec<TimedEvent>,
        limit: usize,
    ) -> usize {
        debug_assert_eq!(positions.len(), self.is_red.len());
        for (track, slot) in self.tracks.iter_mut().enumerate() {
            *slot = positions[self.assignment.target_on(track) as usize];
        }
        self.entering.clear();
        self.due.clear();
        // Every track is eligible: the simulated sensor looks at any
        // isolated track (and may see nothing, an outcome that reports
        // nothing).
        self.sensing.sense(
            time,
            &self.tracks,
            |_| true,
            &mut self.entering,
            &mut self.due,
        );
        let first_report = self.reports.as_ref().map_or(0, Vec::len);
        if let Some(reports) = &mut self.reports {
            for (track, p) in self.tracks.iter().enumerate() {
                if let Some(p) = p {
                    reports.push(Report::at(time, track as u32, p.x, p.y));
                }
            }
        }
        let dt = self.previous_time.map(|t| time - t).filter(|&dt| dt > 0.0);
        let mut added = 0;
        for e in &self.entering {
            if added == limit {
                break;
            }
            let (a, b) = (e.a as usize, e.b as usize);
            let (Some(pa), Some(pb)) = (self.tracks[a], self.tracks[b]) else {
                continue;
            };
            let velocity = |i: usize, now: Vec2| -> Option<Vec2> {
                let before = self.previous[i]?;
                dt.map(|dt| (now - before) * (1.0 / dt))
            };
            let meeting =
                Meeting::predict(time, (e.a, pa, velocity(a, pa)), (e.b, pb, velocity(b, pb)));
            let swap = self.params.meetings.swap(&meeting);
            let exchanged = self.swap_rng.gen::<f64>() < swap;
            if exchanged {
                let (i, j) = (self.assignment.target_on(a), self.assignment.target_on(b));
                self.assignment.exchange_targets(i as usize, j as usize);
            }
            out.push(TimedEvent {
                time,
                event: SimEvent::Mix {
                    a: e.a,
                    b: e.b,
                    swap,
                    exchanged,
                },
            });
            added += 1;
        }
        for &track in &self.due {
            if added == limit {
                break;
            }
            // An isolated track met nobody this step: it still follows the
            // target it followed when the step began.
            let target = self.assignment.target_on(track as usize) as usize;
            if let Some((red, blue)) = self
                .params
                .sensor
                .observe(&mut self.sensor_rng, self.is_red[target])
            {
                if let Some(reports) = &mut self.reports {
                    let s = red / (red + blue);
                    // This step's reports are in ascending track order.
                    let step_reports = &mut reports[first_report..];
                    let at = step_reports
                        .binary_search_by_key(&track, |r| r.track)
                        .expect("an isolated track is present");
                    step_reports[at].scores = Some(BTreeMap::from([
                        ("red".to_string(), s),
                        ("blue".to_string(), 1.0 - s),
                    ]));
                }
                out.push(TimedEvent {
                    time,
                    event: SimEvent::Observe { track, red, blue },
                });
                added += 1;
            }
        }
        if self.tracks.iter().any(Option::is_some) {
            self.previous.clone_from(&self.tracks);
            self.previous_time = Some(time);
        }
        added
    }

    /// Which target is on which track now.
    pub(crate) fn assignment(&self) -> &Assignment {
        &self.assignment
    }

    /// The tracks carrying red targets now, ascending.
    pub(crate) fn red_tracks(&self) -> Vec<u32> {
        self.assignment.red_tracks(&self.is_red)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn a_certain_swap_moves_the_colour_to_the_other_track() {
        let params = ExtractionParams {
            meetings: MeetingModel::Constant(1.0),
            ..Default::default()
        };
        let rng = || ChaCha8Rng::seed_from_u64(1);
        let mut x = Extractor::new(params, vec![true, false, false], rng(), rng());
        let mut out = Vec::new();
        let far = [
            Some(Vec2::new(0.0, 0.0)),
            Some(Vec2::new(10.0, 0.0)),
            Some(Vec2::new(20.0, 0.0)),
        ];
        x.step(0.0, &far, &mut out, usize::MAX);
        assert!(out
            .iter()
            .all(|e| matches!(e.event, SimEvent::Observe { .. })));
        out.clear();
        let close = [
            Some(Vec2::new(0.0, 0.0)),
            Some(Vec2::new(0.5, 0.0)),
            Some(Vec2::new(20.0, 0.0)),
        ];
        x.step(0.1, &close, &mut out, usize::MAX);
        assert_eq!(
            out[0].event,
            SimEvent::Mix {
                a: 0,
                b: 1,
                swap: 1.0,
                exchanged: true
            }
        );
        assert_eq!(x.red_tracks(), vec![1]);
        assert_eq!(x.assignment().target_on(1), 0);
    }

    #[test]
    fn a_limit_cuts_the_step() {
        let params = ExtractionParams {
            meetings: MeetingModel::Constant(1.0),
            ..Default::default()
        };
        let rng = || ChaCha8Rng::seed_from_u64(1);
        let mut x = Extractor::new(params, vec![true, false, false, false], rng(), rng());
        let positions = [
            Some(Vec2::new(0.0, 0.0)),
            Some(Vec2::new(0.5, 0.0)),
            Some(Vec2::new(10.0, 0.0)),
            Some(Vec2::new(10.5, 0.0)),
        ];
        let mut out = Vec::new();
        assert_eq!(x.step(0.0, &positions, &mut out, 1), 1);
        assert_eq!(out.len(), 1);
        assert_eq!(x.red_tracks(), vec![1]);
    }
}
