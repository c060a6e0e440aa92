//! Running a scenario: build the motion, colour the targets, step the motion
//! and the extractor together, and lay down `move` and `truth` lines.
//!
//! Randomness: one seed, four independent ChaCha8 streams — motion (1),
//! colours (2), swap draws (3), sensor draws (4). So the motion of a seed is
//! the same whatever the distances, swap probability or sensor; changing
//! the mixing distance changes which encounters count as mixes, not where
//! people walk. An identity trace adds two more — the targets' identities
//! (5) and the identity reads (6) — so turning identities on changes no
//! other event.
//!
//! Time 0 is the first recorded step (after the warm-up of a synthetic
//! model; the window start of a replay). Events of step s are at s·dt
//! (rounded to the nanosecond), in
//! the order: mixes, observations, identity reads (kept apart in the
//! trace's identity part, woven in when written), moves (every
//! `move_interval`, from time 0, for every track whose target is present),
//! truth (every `truth_interval` after time 0, and at the last step).

use super::builder::{Scenario, DEFAULT_TARGETS};
use super::error::ScenarioError;
use super::identity::{IdentityReader, IdentityTrace};
use super::options::{Length, Model, RedChoice, SceneSource};
use super::progress::{Progress, Throttle};
use super::trace::{GeneratedTrace, TraceHeader};
use crate::events::{Extractor, SimEvent, TimedEvent};
use crate::motion::crowd::Crowd;
use crate::motion::pedestrians::{Replay, Scene, Window};
use crate::motion::waypoint::Waypoint;
use crate::motion::Motion;
use idmesh_extract::MeetingModel;
use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::sync::Arc;

const STREAM_MOTION: u64 = 1;
const STREAM_COLOURS: u64 = 2;
const STREAM_SWAPS: u64 = 3;
const STREAM_SENSOR: u64 = 4;
const STREAM_IDENTITIES: u64 = 5;
const STREAM_READS: u64 = 6;
const EPS: f64 = 1e-9;

fn stream(seed: u64, stream: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream);
    rng
}

/// The motion of a scenario, ready at time 0, and a line describing it.
pub(crate) struct BuiltMotion {
    pub motion: Box<dyn Motion>,
    pub description: String,
}

impl Scenario {
    /// The ground-truth motion of this scenario at time 0 (warm-up done,
    /// replay window chosen): stepping it reproduces exactly the positions
    /// the trace was extracted from. Useful to check or draw a trace.
    pub(crate) fn motion(&self) -> Result<BuiltMotion, ScenarioError> {
        self.validate()?;
        let rng = stream(self.seed, STREAM_MOTION);
        Ok(match &self.model {
            Model::Crowd(params) => {
                let n = self.targets.unwrap_or(DEFAULT_TARGETS);
                let field = self.field_for(n);
                let mut crowd = Crowd::new(n, field, self.dt, params.clone(), rng);
                crowd.warm_up(self.warmup);
                BuiltMotion {
                    motion: Box::new(crowd),
                    description: format!(
                        "social-force crowd of {n} in a {:.1} m x {:.1} m field",
                        field.width(),
                        field.height()
                    ),
                }
            }
            Model::Waypoint(params) => {
                let n = self.targets.unwrap_or(DEFAULT_TARGETS);
                let field = self.field_for(n);
                let mut m = Waypoint::new(n, field, self.dt, params.clone(), rng);
                m.warm_up(self.warmup);
                BuiltMotion {
                    motion: Box::new(m),
                    description: format!(
                        "random waypoint, {n} targets in a {:.1} m x {:.1} m field",
                        field.width(),
                        field.height()
                    ),
                }
            }
            Model::Pedestrians { scene, start } => {
                let scene: Arc<Scene> = match scene {
                    SceneSource::File { path, timing } => Arc::new(Scene::load(path, *timing)?),
                    SceneSource::Loaded(s) => s.clone(),
                };
                let window = Window::choose(&scene, &self.window_spec(*start))?;
                let description = format!(
                    "replay of {} ({} people, {:.1} s to {:.1} s of the scene)",
                    scene.source,
                    window.people.len(),
                    window.start,
                    window.end
                );
                BuiltMotion {
                    motion: Box::new(Replay::new(scene, window, self.dt)),
                    description,
                }
            }
        })
    }

    /// Generates the trace.
    pub fn generate(&self) -> Result<GeneratedTrace, ScenarioError> {
        self.generate_with_progress(&mut |_, _| {})
    }

    /// Generates the trace, reporting progress as `progress(done, total)`
    /// (see [`super::progress`]).
    pub fn generate_with_progress(
        &self,
        progress: Progress<'_>,
    ) -> Result<GeneratedTrace, ScenarioError> {
        let BuiltMotion {
            mut motion,
            description: motion_description,
        } = self.motion()?;
        let n = motion.targets();
        let is_red = self.colours(n)?;
        let k = is_red.iter().filter(|&&r| r).count();
        let mut extractor = Extractor::new(
            self.extraction.clone(),
            is_red,
            stream(self.seed, STREAM_SWAPS),
            stream(self.seed, STREAM_SENSOR),
        );
        if self.keep_reports {
            extractor = extractor.keep_reports();
        }
        let true_initial_red = extractor.red_tracks();
        let mut reader = self.identity.enabled.then(|| {
            IdentityReader::new(
                &self.identity,
                &self.extraction,
                n,
                stream(self.seed, STREAM_IDENTITIES),
                stream(self.seed, STREAM_READS),
            )
        });
        let dt = motion.dt();

        // How far to run, and what progress counts.
        let (mut last_step, event_goal) = match self.length_value() {
            Some(Length::Duration(d)) => (steps_in(d, dt), None),
            Some(Length::Events { count, within }) => (steps_in(within, dt), Some(count)),
            None => (u64::MAX, None),
        };
        if let Some(max) = motion.max_steps() {
            last_step = last_step.min(max);
        }
        let total = event_goal.map_or(last_step, |c| c as u64);
        let mut progress = Throttle::new(progress, total);

        let mut events: Vec<TimedEvent> = Vec::new();
        let mut sensing = 0usize;
        // Moves at j·move_interval (j ≥ 0), truths at j·truth_interval (j ≥ 1):
        // multiples, not running sums, so long runs do not drift.
        let mut moves_done = 0u64;
        let mut truths_done = 0u64;
        let mut last_truth_step = None;
        let mut step = 0u64;
        loop {
            let time = step_time(step, dt);
            // Where the tracks are goes before what the step's sensing
            // saw: a stream's first lines then place every track, and a
            // deployment starts each with the leader of its region
            // (`idmesh_placement::Regions::starting`).
            if let Some(interval) = self.move_interval {
                if time >= moves_done as f64 * interval - EPS {
                    let positions = motion.positions();
                    for track in 0..n {
                        let target = extractor.assignment().target_on(track) as usize;
                        if let Some(p) = positions[target] {
                            events.push(TimedEvent {
                                time,
                                event: SimEvent::Move {
                                    track: track as u32,
                                    x: p.x,
                                    y: p.y,
                                },
                            });
                        }
                    }
                    moves_done = ((time + EPS) / interval).floor() as u64 + 1;
                }
            }
            let limit = event_goal.map_or(usize::MAX, |c| c - sensing);
            sensing += extractor.step(time, motion.positions(), &mut events, limit);
            if let Some(reader) = &mut reader {
                reader.step(time, motion.positions(), extractor.assignment());
            }
            let goal_reached = event_goal.is_some_and(|c| sensing >= c);
            let last = goal_reached || step >= last_step;
            let truth_due = (truths_done + 1) as f64 * self.truth_interval;
            if (step > 0 && time >= truth_due - EPS) || last {
                events.push(TimedEvent {
                    time,
                    event: SimEvent::Truth {
                        red: extractor.red_tracks(),
                    },
                });
                last_truth_step = Some(step);
                truths_done = ((time + EPS) / self.truth_interval).floor() as u64;
            }
            progress.report(event_goal.map_or(step, |_| sensing as u64));
            if last {
                break;
            }
            if !motion.advance() {
                // A replay ended earlier than its announced length.
                if last_truth_step != Some(step) {
                    events.push(TimedEvent {
                        time,
                        event: SimEvent::Truth {
                            red: extractor.red_tracks(),
                        },
                    });
                }
                break;
            }
            step += 1;
        }
        let duration = step_time(step, dt);
        if let Some(count) = event_goal {
            if sensing < count {
                return Err(ScenarioError::TooFewEvents {
                    wanted: count,
                    got: sensing,
                    seconds: duration,
                    ended: motion.max_steps().is_some_and(|m| step >= m),
                });
            }
        }
        progress.finish();

        let x = &self.extraction;
        let mut description = format!(
            "{motion_description}; {n} tracks, {k} red; dt {dt} s; mix within {} m \
             ({}), observe beyond {} m at most every {} s; seed {}",
            x.mix_distance,
            describe_meetings(&x.meetings),
            x.observe_distance,
            x.observe_interval,
            self.seed
        );
        if reader.is_some() {
            description.push_str(&format!(
                "; identities read with accuracy {}",
                self.identity.accuracy
            ));
        }
        let identity = reader.map(|r| r.finish(self.identity.reveal_initial));
        let reports = self.keep_reports.then(|| {
            let mut reports = extractor.take_reports();
            if let Some(identity) = &identity {
                with_reads(&mut reports, identity);
            }
            reports
        });
        Ok(GeneratedTrace {
            header: TraceHeader {
                tracks: n,
                red: k,
                initial_red: self.reveal_initial_red.then(|| true_initial_red.clone()),
                source: format!("idmesh-sensor {} scenario", self.model.name()),
                description,
            },
            events,
            true_initial_red,
            duration,
            identity,
            reports,
        })
    }

    /// The colour of each target for `n` targets.
    fn colours(&self, n: usize) -> Result<Vec<bool>, ScenarioError> {
        let mut is_red = vec![false; n];
        let k = match &self.red {
            RedChoice::Half => n / 2,
            RedChoice::Count(k) => *k,
            #[cfg(test)]
            RedChoice::Tracks(tracks) => {
                for &t in tracks {
                    let slot = is_red.get_mut(t as usize).ok_or_else(|| {
                        ScenarioError::Invalid(format!(
                            "red track {t} is out of range: there are {n} tracks"
                        ))
                    })?;
                    if *slot {
                        return Err(ScenarioError::Invalid(format!(
                            "red track {t} is listed twice"
                        )));
                    }
                    *slot = true;
                }
                return Ok(is_red);
            }
        };
        if k > n {
            return Err(ScenarioError::Invalid(format!(
                "{k} red targets cannot be among {n} targets"
            )));
        }
        let mut ids: Vec<usize> = (0..n).collect();
        ids.shuffle(&mut stream(self.seed, STREAM_COLOURS));
        for &i in &ids[..k] {
            is_red[i] = true;
        }
        Ok(is_red)
    }
}

/// Puts each identity read on the report of its track at its time: the
/// tracker reports the badge it read with the position.
fn with_reads(reports: &mut [idmesh_extract::Report], identity: &IdentityTrace) {
    // Reports are in time order, a step's in track order; a step's reads
    // are in target order, so sorted first.
    let mut reads: Vec<_> = identity.reads.iter().collect();
    reads.sort_by(|a, b| {
        (a.time, a.track)
            .partial_cmp(&(b.time, b.track))
            .expect("finite times")
    });
    let mut at = 0;
    for read in reads {
        while at < reports.len() && (reports[at].time, reports[at].track) < (read.time, read.track)
        {
            at += 1;
        }
        if let Some(report) = reports
            .get_mut(at)
            .filter(|r| (r.time, r.track) == (read.time, read.track))
        {
            report.identity = Some(idmesh_extract::IdentityRead {
                identity: read.identity,
                accuracy: identity.accuracy,
            });
        }
    }
}

/// How the trace's description names the meeting model: `swap 0.5` for a
/// constant (as traces always said), the formula's parameters otherwise.
fn describe_meetings(model: &MeetingModel) -> String {
    match *model {
        MeetingModel::Constant(p) => format!("swap {p}"),
        MeetingModel::Approach { p_max, sigma, v0 } => {
            format!("swap by approach: p_max {p_max}, sigma {sigma} m, v0 {v0} m/s")
        }
    }
}

/// The time of a step, rounded to the nanosecond so that traces read
/// `0.3`, not `0.30000000000000004`.
fn step_time(step: u64, dt: f64) -> f64 {
    (step as f64 * dt * 1e9).round() / 1e9
}

/// The index of the last step at or before `seconds`.
fn steps_in(seconds: f64, dt: f64) -> u64 {
    (seconds / dt + EPS).floor() as u64
}
