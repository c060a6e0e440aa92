//! How reports become events: the distances of the property paper's
//! Section 6 rules, the meeting model, the score mapping, and what the
//! output trace's header says.

use crate::meetings::{CalibrationError, MeetingModel};
use crate::observing::ScoreMapping;
use serde::{Deserialize, Serialize};

/// The extractor's settings. The defaults are the simulator's.
///
/// Written in a topology as `[sensor.extract]`: every field may be left
/// out (its default), an unknown one is an error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExtractorConfig {
    /// Two tracks closer than this meet (metres).
    pub mix_distance: f64,
    /// A pair that met meets again only after parting beyond
    /// `release_factor × mix_distance` (≥ 1): one meeting, one mix, even
    /// when two people hover at the threshold.
    pub release_factor: f64,
    /// A track with no other track within this distance is isolated and
    /// its class scores are observed (metres).
    pub observe_distance: f64,
    /// At most one observation per track per this many seconds.
    pub observe_interval: f64,
    /// The swap probability of a meeting.
    pub meeting_model: MeetingModel,
    /// Class scores to likelihoods.
    pub scores: ScoreMapping,
    /// `move` lines every this many seconds (from the first frame), for
    /// every present track; `None` writes none.
    pub move_interval: Option<f64>,
    /// Whether identity reads are expected: the header then declares one
    /// identity per track.
    pub identities: bool,
    /// The header's `source`.
    pub source: String,
}

impl Default for ExtractorConfig {
    fn default() -> Self {
        ExtractorConfig {
            mix_distance: 1.0,
            release_factor: 1.25,
            observe_distance: 3.5,
            observe_interval: 3.0,
            meeting_model: MeetingModel::default(),
            scores: ScoreMapping::default(),
            move_interval: Some(1.0),
            identities: false,
            source: "idmesh extract".into(),
        }
    }
}

impl ExtractorConfig {
    /// Checks every setting; says what is wrong.
    pub fn validate(&self) -> Result<(), CalibrationError> {
        let bad = |s: String| Err(CalibrationError::Invalid(s));
        if !(self.mix_distance.is_finite() && self.mix_distance > 0.0) {
            return bad(format!(
                "mixing distance must be finite and > 0, got {}",
                self.mix_distance
            ));
        }
        if !(self.release_factor.is_finite() && self.release_factor >= 1.0) {
            return bad(format!(
                "release factor must be finite and >= 1, got {}",
                self.release_factor
            ));
        }
        if !(self.observe_distance.is_finite() && self.observe_distance > 0.0) {
            return bad(format!(
                "observation distance must be finite and > 0, got {}",
                self.observe_distance
            ));
        }
        if !(self.observe_interval.is_finite() && self.observe_interval >= 0.0) {
            return bad(format!(
                "observation interval must be finite and >= 0, got {}",
                self.observe_interval
            ));
        }
        if let Some(m) = self.move_interval {
            if !(m.is_finite() && m >= 0.0) {
                return bad(format!("move interval must be finite and >= 0, got {m}"));
            }
        }
        self.meeting_model.validate()?;
        self.scores.validate()
    }

    /// `release_factor × mix_distance`.
    pub(crate) fn release_distance(&self) -> f64 {
        self.mix_distance * self.release_factor
    }
}
