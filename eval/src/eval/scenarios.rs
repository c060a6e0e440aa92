//! The scenarios of the evaluation and the traces they make, held in memory
//! as `belief` events and truth lines.
//!
//! - A **crowd**: the social-force crowd of `idmesh_sim::Scenario`, n
//!   targets (k = n/2), run until a number of mix + observe
//!   events. Its share of mixing events is steered, as in the paper, by the
//!   two distances: one knob x ∈ [0, 1] sets the mixing distance to
//!   0.25 + 2.75x m and the observation distance to 2.5 + 3.5x m (both
//!   raise the share as x grows), and x is found by bisection on the
//!   generated trace of the same seed (the motion of a seed does not depend
//!   on the distances), to within 0.01 of the target share or the closest
//!   of 14 tries.
//! - A **pedestrian scene** of shared/data/pedestrians: each person one
//!   track, a window of at most `cap` people starting at a fraction of the
//!   scene, default distances.
//!
//! The swap probability and the sensor (the trace spec's colour histogram
//! or a symmetric sensor of accuracy a) are options of both, and so is the
//! [`Start`]: the red tracks at time 0 revealed (`Field::known`) or not
//! (`Field::uniform(n, k)`, the scenario's `.reveal_initial_red(false)`).
//! The start changes only what the filters are told, never the motion or
//! the events: a uniform-prior trace is the known-start trace of the same
//! spec with its field replaced ([`Trace::with_start`]).

use anyhow::{anyhow, Context, Result};
use idmesh_belief::{Event, Field, Mix, Observe};
use idmesh_protocol::trace::{self, Line};
use idmesh_sim::{data_dir, Scene, Timing};
use idmesh_sim::{GeneratedTrace, Scenario, SensorModel, SimEvent};
use std::collections::BTreeMap;
use std::sync::Arc;

/// The pedestrian scenes: name and file under the data directory (the
/// obsmat files where they exist, for their exact timing).
pub const SCENES: [(&str, &str); 5] = [
    ("eth", "eth/obsmat/obsmat.txt"),
    ("hotel", "hotel/obsmat/obsmat.txt"),
    ("zara01", "zara01/obsmat/obsmat.txt"),
    ("zara02", "zara02/obsmat/obsmat.txt"),
    ("univ", "univ/students001.txt"),
];

/// What an observation reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Sensor {
    /// The colour histogram of the trace spec (0.8/0.2 or 0.1/0.7).
    Histogram,
    /// Names the right colour with this probability.
    Symmetric(f64),
}

impl Sensor {
    fn model(&self) -> Result<SensorModel> {
        match *self {
            Sensor::Histogram => Ok(SensorModel::colour_histogram()),
            Sensor::Symmetric(a) => SensorModel::symmetric(a).map_err(|e| anyhow!(e)),
        }
    }
}

/// What the filters know at time 0 (k is known either way).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, clap::ValueEnum)]
pub enum Start {
    /// The red tracks at time 0 are revealed.
    Known,
    /// Nothing is revealed: every k-set is equally likely at time 0.
    Uniform,
}

impl Start {
    /// How the tables name it.
    pub fn label(&self) -> &'static str {
        match self {
            Start::Known => "known start",
            Start::Uniform => "uniform prior",
        }
    }
}

/// Where the motion comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum Source {
    /// A crowd of `n` run to `events` mix + observe events, its mixing
    /// share steered to `share` (`None`: default distances).
    Crowd {
        n: usize,
        events: usize,
        share: Option<f64>,
    },
    /// Window `window` of `windows` equal parts of a scene (it starts at
    /// window/windows of the scene's length), at most `cap` people.
    Pedestrians {
        scene: &'static str,
        cap: Option<usize>,
        window: usize,
        windows: usize,
    },
}

/// Everything that makes one trace.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ScenarioSpec {
    pub source: Source,
    pub swap: f64,
    pub sensor: Sensor,
    pub seed: u64,
    pub start: Start,
}

/// One line of an in-memory trace.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Step {
    Event(Event),
    /// The true red tracks now.
    Truth(Vec<u32>),
    /// Where a track is: only the regional rule of a deployment
    /// ([`super::methods::Method::Deployed`]) reads it.
    Move {
        track: u32,
        x: f64,
        y: f64,
    },
}

impl Step {
    /// The trace line this step stands for (times left at 0: nothing that
    /// replays an in-memory trace reads them).
    pub(crate) fn line(&self) -> Line {
        match self {
            Step::Event(Event::Mix(m)) => Line::Mix(trace::Mix {
                time: 0.0,
                a: m.a,
                b: m.b,
                swap: m.swap,
            }),
            Step::Event(Event::Observe(o)) => Line::Observe(trace::Observe {
                time: 0.0,
                track: o.track,
                red: o.red,
                blue: o.blue,
                sensor: None,
            }),
            Step::Truth(red) => Line::Truth(trace::Truth {
                time: 0.0,
                red: Some(red.clone()),
                identity: None,
            }),
            &Step::Move { track, x, y } => Line::Move(trace::Move {
                time: 0.0,
                track,
                x,
                y,
            }),
        }
    }
}

/// Seconds between the `move` lines of a generated trace: where a live
/// sensor, and a deployed method's replay, find the tracks.
pub(crate) const MOVE_INTERVAL: f64 = 1.0;

/// Facts about a trace, for the tables.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct TraceInfo {
    pub tracks: usize,
    pub red: usize,
    pub mixes: usize,
    pub observations: usize,
    pub truths: usize,
    pub mix_share: f64,
    pub seconds_of_motion: f64,
    pub mix_distance: f64,
    pub observe_distance: f64,
}

/// A generated trace as the filters consume it.
#[derive(Debug, Clone)]
pub(crate) struct Trace {
    /// n, k and, with a known start, the red tracks at time 0.
    pub field: Field,
    /// The red tracks at time 0, whether or not the field reveals them.
    pub initial_red: Vec<u32>,
    pub steps: Vec<Step>,
    pub info: TraceInfo,
}

/// The pedestrian scenes, each parsed once and shared.
#[derive(Debug, Default)]
pub(crate) struct Scenes {
    loaded: BTreeMap<&'static str, Arc<Scene>>,
}

impl Scenes {
    /// Loads the scenes `specs` use (none when they use none).
    pub(crate) fn load_for(specs: &[ScenarioSpec]) -> Result<Scenes> {
        let mut scenes = Scenes::default();
        for spec in specs {
            if let Source::Pedestrians { scene, .. } = spec.source {
                if scenes.loaded.contains_key(scene) {
                    continue;
                }
                let file = SCENES
                    .iter()
                    .find(|(name, _)| *name == scene)
                    .map(|(_, file)| *file)
                    .with_context(|| format!("no pedestrian scene `{scene}`"))?;
                let path = data_dir().join(file);
                let loaded = Scene::load(&path, Timing::Auto)
                    .with_context(|| format!("cannot load scene {}", path.display()))?;
                scenes.loaded.insert(scene, Arc::new(loaded));
            }
        }
        Ok(scenes)
    }

    fn get(&self, scene: &str) -> Result<Arc<Scene>> {
        self.loaded
            .get(scene)
            .cloned()
            .with_context(|| format!("scene `{scene}` was not loaded"))
    }
}

/// Mixing and observation distances (metres) for the steering knob x.
pub(crate) fn distances(x: f64) -> (f64, f64) {
    (0.25 + 2.75 * x, 2.5 + 3.5 * x)
}

impl ScenarioSpec {
    /// The same scenario with another start.
    pub(crate) fn with_start(&self, start: Start) -> ScenarioSpec {
        ScenarioSpec {
            start,
            ..self.clone()
        }
    }

    /// Generates the trace (deterministic).
    pub(crate) fn generate(&self, scenes: &Scenes) -> Result<Trace> {
        Ok(self.generated(scenes, Some(MOVE_INTERVAL))?.1)
    }

    /// The trace as a file carries it, with `move` lines every `moves`
    /// seconds (a live sensor routes tracks to leaders by them), beside
    /// the in-memory trace the filters replay. Moves draw no randomness:
    /// the mixes, observations and truths are those of
    /// [`ScenarioSpec::generate`] whatever `moves` is.
    pub(crate) fn generated(
        &self,
        scenes: &Scenes,
        moves: Option<f64>,
    ) -> Result<(GeneratedTrace, Trace)> {
        let sensor = self.sensor.model()?;
        let base = |s: Scenario| {
            s.swap(self.swap)
                .sensor(sensor.clone())
                .seed(self.seed)
                .move_interval(moves)
                .reveal_initial_red(self.start == Start::Known)
        };
        match &self.source {
            Source::Crowd { n, events, share } => {
                let crowd = |x: Option<f64>| -> Result<(GeneratedTrace, f64, f64)> {
                    let mut s = base(Scenario::crowd().targets(*n).events(*events));
                    let (mix, observe) = match x {
                        Some(x) => distances(x),
                        None => {
                            let p = s.extraction_params();
                            (p.mix_distance, p.observe_distance)
                        }
                    };
                    s = s.mix_distance(mix).observe_distance(observe);
                    let trace = s
                        .generate()
                        .with_context(|| format!("crowd of {n}, seed {}", self.seed))?;
                    Ok((trace, mix, observe))
                };
                let (trace, mix, observe) = match share {
                    None => crowd(None)?,
                    Some(target) => steer(*target, |x| crowd(Some(x)))?,
                };
                let converted = convert(&trace, mix, observe);
                Ok((trace, converted))
            }
            Source::Pedestrians {
                scene,
                cap,
                window,
                windows,
            } => {
                let loaded = self.get_scene(scenes, scene)?;
                let start = loaded.duration() * *window as f64 / (*windows).max(1) as f64;
                let mut s = base(Scenario::pedestrians_loaded(loaded)).start(start);
                if let Some(cap) = cap {
                    s = s.targets(*cap);
                }
                let p = s.extraction_params().clone();
                let trace = s
                    .generate()
                    .with_context(|| format!("scene {scene} from {start:.0} s"))?;
                let converted = convert(&trace, p.mix_distance, p.observe_distance);
                Ok((trace, converted))
            }
        }
    }

    fn get_scene(&self, scenes: &Scenes, scene: &str) -> Result<Arc<Scene>> {
        scenes.get(scene)
    }
}

/// Bisection on the knob x for a mixing share of `target`.
fn steer(
    target: f64,
    mut generate: impl FnMut(f64) -> Result<(GeneratedTrace, f64, f64)>,
) -> Result<(GeneratedTrace, f64, f64)> {
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    let mut best: Option<(f64, (GeneratedTrace, f64, f64))> = None;
    for _ in 0..14 {
        let x = 0.5 * (lo + hi);
        let made = generate(x)?;
        let share = made.0.stats().mix_share;
        let miss = (share - target).abs();
        if share < target {
            lo = x;
        } else {
            hi = x;
        }
        if best.as_ref().is_none_or(|(m, _)| miss < *m) {
            best = Some((miss, made));
        }
        if miss <= 0.01 {
            break;
        }
    }
    Ok(best.expect("at least one try").1)
}

impl Trace {
    /// The same trace told another start: the field only.
    pub(crate) fn with_start(&self, start: Start) -> Trace {
        let (n, k) = (self.field.tracks, self.info.red);
        Trace {
            field: match start {
                Start::Known => Field::known(n, self.initial_red.clone()),
                Start::Uniform => Field::uniform(n, k),
            },
            ..self.clone()
        }
    }
}

/// A generated trace as `belief` events and truth lines; the field is
/// known or uniform as the trace's header reveals the red tracks or not.
pub(crate) fn convert(trace: &GeneratedTrace, mix_distance: f64, observe_distance: f64) -> Trace {
    let stats = trace.stats();
    let steps = trace
        .events
        .iter()
        .map(|e| match &e.event {
            SimEvent::Mix { a, b, swap, .. } => Step::Event(Event::Mix(Mix {
                a: *a,
                b: *b,
                swap: *swap,
            })),
            SimEvent::Observe { track, red, blue } => Step::Event(Event::Observe(Observe {
                track: *track,
                red: *red,
                blue: *blue,
            })),
            SimEvent::Truth { red } => Step::Truth(red.clone()),
            &SimEvent::Move { track, x, y } => Step::Move { track, x, y },
        })
        .collect();
    let field = match &trace.header.initial_red {
        Some(red) => Field::known(trace.header.tracks, red.clone()),
        None => Field::uniform(trace.header.tracks, trace.header.red),
    };
    Trace {
        field,
        initial_red: trace.true_initial_red.clone(),
        steps,
        info: TraceInfo {
            tracks: trace.header.tracks,
            red: trace.header.red,
            mixes: stats.mixes,
            observations: stats.observations,
            truths: stats.truths,
            mix_share: stats.mix_share,
            seconds_of_motion: trace.duration,
            mix_distance,
            observe_distance,
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_crowd_is_steered_to_its_mixing_share() {
        for target in [0.25, 0.75] {
            let spec = ScenarioSpec {
                source: Source::Crowd {
                    n: 10,
                    events: 300,
                    share: Some(target),
                },
                swap: 0.5,
                sensor: Sensor::Histogram,
                seed: 1,
                start: Start::Known,
            };
            let trace = spec.generate(&Scenes::default()).unwrap();
            assert!(
                (trace.info.mix_share - target).abs() < 0.05,
                "{target}: {:?}",
                trace.info
            );
            assert_eq!(trace.info.mixes + trace.info.observations, 300);
            let events = trace
                .steps
                .iter()
                .filter(|s| matches!(s, Step::Event(_)))
                .count();
            assert_eq!(events, 300);
            assert!(trace.info.truths > 0);
            assert_eq!(trace.field.red.known(), Some(5));
            // Same spec, same trace.
            let again = spec.generate(&Scenes::default()).unwrap();
            assert_eq!(again.steps, trace.steps);
            // The uniform prior: the same events, nothing revealed.
            let uniform = spec
                .with_start(Start::Uniform)
                .generate(&Scenes::default())
                .unwrap();
            assert_eq!(uniform.steps, trace.steps);
            assert_eq!(uniform.field, Field::uniform(10, 5));
            assert_eq!(uniform.initial_red, trace.initial_red);
            assert_eq!(trace.with_start(Start::Uniform).field, uniform.field);
            assert_eq!(uniform.with_start(Start::Known).field, trace.field);
            // With move lines: the same trace for the filters.
            let (file, with_moves) = spec.generated(&Scenes::default(), Some(1.0)).unwrap();
            assert!(file.stats().moves > 0);
            assert_eq!(with_moves.steps, trace.steps);
            assert_eq!(with_moves.field, trace.field);
        }
    }

    #[test]
    fn a_pedestrian_window() {
        let spec = ScenarioSpec {
            source: Source::Pedestrians {
                scene: "zara01",
                cap: Some(20),
                window: 0,
                windows: 1,
            },
            swap: 0.5,
            sensor: Sensor::Symmetric(0.9),
            seed: 0,
            start: Start::Known,
        };
        let scenes = Scenes::load_for(std::slice::from_ref(&spec)).unwrap();
        let trace = spec.generate(&scenes).unwrap();
        assert_eq!(trace.info.tracks, 20);
        assert!(trace.info.mixes > 0 && trace.info.observations > 0);
    }
}
