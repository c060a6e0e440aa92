//! The [`Scenario`] builder: every option of a generated trace, with the
//! defaults of the paper's Section 6 experiments where it gives them (half
//! of the targets red, swap probability 0.5, about half of the events
//! mixes) and plain, documented choices where it does not.

use super::error::ScenarioError;
use super::identity::IdentityOptions;
use super::options::{Length, Model, RedChoice, SceneSource};
use crate::events::{ExtractionParams, SensorModel};
use crate::geometry::Rect;
use crate::motion::crowd::CrowdParams;
use crate::motion::pedestrians::{Timing, WindowSpec};
use crate::motion::waypoint::WaypointParams;
use idmesh_extract::MeetingModel;
use std::path::PathBuf;
use std::sync::Arc;

/// Default number of targets of the synthetic models.
pub(crate) const DEFAULT_TARGETS: usize = 20;
/// Default run length of the synthetic models, seconds.
pub(crate) const DEFAULT_DURATION: f64 = 300.0;
/// Default field area per target, m² (a 50 m × 50 m square for 100).
pub(crate) const DEFAULT_AREA_PER_TARGET: f64 = 25.0;
/// Default simulation step, seconds.
pub(crate) const DEFAULT_DT: f64 = 0.1;
/// Default warm-up of the synthetic models before time 0, seconds.
pub(crate) const DEFAULT_WARMUP: f64 = 10.0;
/// Default time limit of a run asked for a number of events, seconds.
pub(crate) const DEFAULT_EVENTS_WITHIN: f64 = 3600.0;

/// Everything that determines a generated trace. Build with one of the
/// model constructors and the option setters, then call
/// [`Scenario::generate`]. The same scenario (including its seed) always
/// generates the same trace.
///
/// | option | default |
/// |---|---|
/// | `targets` (n) | 20 for crowd / waypoint; pedestrians: everyone in the window (a cap otherwise) |
/// | `red` (k) | ⌊n/2⌋ drawn by the seed |
/// | `length` | 300 s for crowd / waypoint; pedestrians: to the end of the scene |
/// | `field` | square of 25 m² per target, origin (0, 0) |
/// | `dt` | 0.1 s (a replay is sampled at this step, interpolating its 0.4 s annotations) |
/// | `warmup` | 10 s (synthetic models only) |
/// | `mix_distance` | 1.0 m (release 1.25 × that) |
/// | `observe_distance` | 3.5 m |
/// | `observe_interval` | 3 s |
/// | `swap` | 0.5 |
/// | `sensor` | colour histogram (trace spec) |
/// | `truth_interval` | 1 s (and at the end) |
/// | `move_interval` | 1 s (`None` = no `move` lines) |
/// | `reveal_initial_red` | true |
/// | `identities` | false (no identity trace); read accuracy 0.9, `initial_identity` revealed |
/// | `seed` | 0 |
#[derive(Debug, Clone)]
pub struct Scenario {
    pub(super) model: Model,
    pub(super) targets: Option<usize>,
    pub(super) red: RedChoice,
    pub(super) length: Option<Length>,
    pub(super) field: Option<Rect>,
    pub(super) dt: f64,
    pub(super) warmup: f64,
    pub(super) extraction: ExtractionParams,
    pub(super) truth_interval: f64,
    pub(super) move_interval: Option<f64>,
    pub(super) reveal_initial_red: bool,
    pub(super) identity: IdentityOptions,
    pub(super) keep_reports: bool,
    pub(super) seed: u64,
}

impl Scenario {
    /// A scenario on `model` with every default.
    pub(crate) fn new(model: Model) -> Self {
        Scenario {
            model,
            targets: None,
            red: RedChoice::Half,
            length: None,
            field: None,
            dt: DEFAULT_DT,
            warmup: DEFAULT_WARMUP,
            extraction: ExtractionParams::default(),
            truth_interval: 1.0,
            move_interval: Some(1.0),
            reveal_initial_red: true,
            identity: IdentityOptions::default(),
            keep_reports: false,
            seed: 0,
        }
    }

    /// The social-force crowd with default parameters.
    pub fn crowd() -> Self {
        Scenario::new(Model::Crowd(CrowdParams::default()))
    }

    /// Random waypoint with default parameters.
    pub fn waypoint() -> Self {
        Scenario::new(Model::Waypoint(WaypointParams::default()))
    }

    /// Replay of the scene file at `path` (obsmat or four-column), timed
    /// as its README says ([`Timing::Auto`]), from its start.
    pub fn pedestrians(path: impl Into<PathBuf>) -> Self {
        Scenario::new(Model::Pedestrians {
            scene: SceneSource::File {
                path: path.into(),
                timing: Timing::Auto,
            },
            start: 0.0,
        })
    }

    /// Replay of an already loaded scene, from its start.
    pub fn pedestrians_loaded(scene: Arc<crate::motion::pedestrians::Scene>) -> Self {
        Scenario::new(Model::Pedestrians {
            scene: SceneSource::Loaded(scene),
            start: 0.0,
        })
    }

    /// Replaces the motion model, keeping every other option.
    pub fn with_model(mut self, model: Model) -> Self {
        self.model = model;
        self
    }

    /// n, the number of targets (tracks). For a pedestrian scene, a cap:
    /// the run ends before the (n+1)-th person arrives.
    pub fn targets(mut self, n: usize) -> Self {
        self.targets = Some(n);
        self
    }

    /// k, the number of red targets, drawn by the seed.
    pub fn red(mut self, k: usize) -> Self {
        self.red = RedChoice::Count(k);
        self
    }

    /// Exactly these tracks carry red targets at time 0.
    #[cfg(test)]
    pub(crate) fn red_tracks(mut self, tracks: Vec<u32>) -> Self {
        self.red = RedChoice::Tracks(tracks);
        self
    }

    /// Run for this many seconds of motion.
    pub fn duration(mut self, seconds: f64) -> Self {
        self.length = Some(Length::Duration(seconds));
        self
    }

    /// Run until `count` mix + observe events (within an hour of motion).
    pub fn events(mut self, count: usize) -> Self {
        self.length = Some(Length::Events {
            count,
            within: DEFAULT_EVENTS_WITHIN,
        });
        self
    }

    /// The field of the synthetic models: `[0, width] × [0, height]` metres.
    pub fn field(mut self, width: f64, height: f64) -> Self {
        self.field = Some(Rect::with_size(width, height));
        self
    }

    /// Simulation (and replay sampling) step, seconds.
    pub fn dt(mut self, seconds: f64) -> Self {
        self.dt = seconds;
        self
    }

    /// Two targets closer than this (metres) mix.
    pub fn mix_distance(mut self, metres: f64) -> Self {
        self.extraction.mix_distance = metres;
        self
    }

    /// A target with nobody within this distance (metres) can be observed.
    pub fn observe_distance(mut self, metres: f64) -> Self {
        self.extraction.observe_distance = metres;
        self
    }

    /// At most one observation per target per this many seconds.
    pub fn observe_interval(mut self, seconds: f64) -> Self {
        self.extraction.observe_interval = seconds;
        self
    }

    /// Probability that a mix exchanges its two targets' tracks.
    pub fn swap(mut self, probability: f64) -> Self {
        self.extraction.meetings = MeetingModel::Constant(probability);
        self
    }

    /// How likely a meeting is to exchange its two targets' tracks (a
    /// constant, or from the meeting's closest distance and speed).
    pub fn meetings(mut self, model: MeetingModel) -> Self {
        self.extraction.meetings = model;
        self
    }

    /// Keep what the simulated tracker reports (every track's position
    /// each step, class scores where the sensor saw a colour) in
    /// [`GeneratedTrace::reports`](super::GeneratedTrace::reports).
    pub fn tracker_reports(mut self, keep: bool) -> Self {
        self.keep_reports = keep;
        self
    }

    pub fn sensor(mut self, model: SensorModel) -> Self {
        self.extraction.sensor = model;
        self
    }

    /// A `truth` line every this many seconds (and one at the end).
    pub fn truth_interval(mut self, seconds: f64) -> Self {
        self.truth_interval = seconds;
        self
    }

    /// `move` lines for every present track every this many seconds
    /// (from time 0); `None` = none.
    pub fn move_interval(mut self, seconds: Option<f64>) -> Self {
        self.move_interval = seconds;
        self
    }

    /// Whether the header carries the red tracks at time 0.
    pub fn reveal_initial_red(mut self, reveal: bool) -> Self {
        self.reveal_initial_red = reveal;
        self
    }

    /// Whether to write an identity trace: every target carries an
    /// identity, RFID-like readers read isolated targets, and the trace gets
    /// `identities`, `initial_identity`, `identify` lines and `truth`
    /// identities (see [`super::identity`]). The other events do not change.
    pub fn identities(mut self, on: bool) -> Self {
        self.identity.enabled = on;
        self
    }

    /// P(an identity read is right), in (0, 1]; default 0.9. A wrong read
    /// is one of the other identities, each equally likely.
    pub fn identity_accuracy(mut self, accuracy: f64) -> Self {
        self.identity.accuracy = accuracy;
        self
    }

    /// Whether the header of an identity trace carries `initial_identity`
    /// (default true; false = uniform prior over the n! assignments).
    pub fn reveal_initial_identity(mut self, reveal: bool) -> Self {
        self.identity.reveal_initial = reveal;
        self
    }

    /// For a pedestrian scene: start this many seconds after its first
    /// annotation. Ignored by the synthetic models.
    pub fn start(mut self, seconds: f64) -> Self {
        if let Model::Pedestrians { start, .. } = &mut self.model {
            *start = seconds;
        }
        self
    }

    pub fn seed(mut self, seed: u64) -> Self {
        self.seed = seed;
        self
    }

    pub fn model(&self) -> &Model {
        &self.model
    }

    pub fn extraction_params(&self) -> &ExtractionParams {
        &self.extraction
    }

    /// The field the synthetic models use for `n` targets.
    pub(crate) fn field_for(&self, n: usize) -> Rect {
        self.field.unwrap_or_else(|| {
            let side = (n.max(1) as f64 * DEFAULT_AREA_PER_TARGET).sqrt();
            Rect::with_size(side, side)
        })
    }

    /// The run length, defaults resolved (`None` = a replay to its end).
    pub(crate) fn length_value(&self) -> Option<Length> {
        match (&self.length, &self.model) {
            (Some(l), _) => Some(*l),
            (None, Model::Pedestrians { .. }) => None,
            (None, _) => Some(Length::Duration(DEFAULT_DURATION)),
        }
    }

    /// The window of a pedestrian replay (its `max_duration` comes from a
    /// duration length).
    pub(super) fn window_spec(&self, start: f64) -> WindowSpec {
        WindowSpec {
            start,
            max_people: self.targets,
            max_duration: match self.length_value() {
                Some(Length::Duration(d)) => Some(d),
                Some(Length::Events { within, .. }) => Some(within),
                None => None,
            },
        }
    }

    /// Checks every option that does not depend on the motion.
    pub fn validate(&self) -> Result<(), ScenarioError> {
        let bad = |m: String| Err(ScenarioError::Invalid(m));
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return bad(format!("dt must be finite and > 0, got {}", self.dt));
        }
        if !(self.warmup.is_finite() && self.warmup >= 0.0) {
            return bad(format!(
                "warm-up must be finite and >= 0, got {}",
                self.warmup
            ));
        }
        if !(self.truth_interval.is_finite() && self.truth_interval > 0.0) {
            return bad(format!(
                "truth interval must be finite and > 0, got {}",
                self.truth_interval
            ));
        }
        if let Some(m) = self.move_interval {
            if !(m.is_finite() && m > 0.0) {
                return bad(format!("move interval must be finite and > 0, got {m}"));
            }
        }
        match self.length_value() {
            Some(Length::Duration(d)) if !(d.is_finite() && d > 0.0) => {
                return bad(format!("duration must be finite and > 0, got {d}"));
            }
            Some(Length::Events { count, within }) => {
                if count == 0 {
                    return bad("a run of 0 events".into());
                }
                if !(within.is_finite() && within > 0.0) {
                    return bad(format!(
                        "event time limit must be finite and > 0, got {within}"
                    ));
                }
            }
            _ => {}
        }
        if self.targets == Some(0) {
            return bad("there must be at least one target".into());
        }
        self.extraction.validate().map_err(ScenarioError::Invalid)?;
        self.identity.validate().map_err(ScenarioError::Invalid)?;
        match &self.model {
            Model::Crowd(p) => p.validate().map_err(ScenarioError::Invalid)?,
            Model::Waypoint(p) => p.validate().map_err(ScenarioError::Invalid)?,
            Model::Pedestrians { start, .. } => {
                if !(start.is_finite() && *start >= 0.0) {
                    return bad(format!("scene start must be finite and >= 0, got {start}"));
                }
            }
        }
        if !matches!(self.model, Model::Pedestrians { .. }) {
            let n = self.targets.unwrap_or(DEFAULT_TARGETS);
            let field = self.field_for(n);
            if !field.is_valid() {
                return bad(format!("the field {field:?} is empty"));
            }
        }
        Ok(())
    }
}
