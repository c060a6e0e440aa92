//! ROS 2 tracker output: the messages trackers publish under ROS 2 —
//! `vision_msgs/msg/Detection2DArray`, `vision_msgs/msg/Detection3DArray`
//! and Autoware's `autoware_perception_msgs/msg/TrackedObjects` — decoded
//! from CDR and turned into the [`Report`]s every other adapter makes, so
//! that a sensor subscribed to a topic over rmw_zenoh, `idmesh extract
//! --format rosbag2` on a bag of it, and `idmesh replay --topology` on the
//! reports all feed the extractor the same thing.
//!
//! A message is one frame: every detection in it is at the message's
//! `header.stamp`. A detection's track is its id ([`tracks`]), its position
//! its box's centre (an object's pose) taken to metres by the topic's
//! `scale` and `offset`, its class scores its hypotheses' `class_id` →
//! `score` (renamed by the topic's `labels`).
//!
//! - [`geometry`], [`vision`], [`autoware`] — the messages, as serde structs
//!   in their fields' order.
//! - [`cdr`] — the CDR encapsulation around `cdr-encoding`.
//! - [`keys`] — rmw_zenoh's key of a topic.
//! - [`tracks`] — track ids to track numbers.
//! - [`bag`] — rosbag2 MCAP files, streamed.
//! - [`markers`] — `visualization_msgs/msg/MarkerArray`, what the
//!   deployment publishes for RViz.
//! - [`rmw`] — what rmw_zenoh expects beside a payload: the attachment, the
//!   liveliness tokens.

pub mod autoware;
pub mod bag;
pub mod cdr;
pub mod geometry;
pub mod keys;
pub mod markers;
pub mod rmw;
pub mod tracks;
pub mod vision;

use crate::extractor::Report;
use idmesh_protocol::trace::{Detect, Line, Move};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A tracker message type this adapter reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum MessageType {
    #[serde(rename = "vision_msgs/msg/Detection2DArray")]
    Detection2DArray,
    #[serde(rename = "vision_msgs/msg/Detection3DArray")]
    Detection3DArray,
    #[serde(rename = "autoware_perception_msgs/msg/TrackedObjects")]
    TrackedObjects,
}

impl MessageType {
    /// Every type, in the order the docs list them.
    pub const ALL: [MessageType; 3] = [
        MessageType::Detection2DArray,
        MessageType::Detection3DArray,
        MessageType::TrackedObjects,
    ];

    /// The ROS type name (`pkg/msg/Type`).
    pub fn ros_name(self) -> &'static str {
        match self {
            MessageType::Detection2DArray => "vision_msgs/msg/Detection2DArray",
            MessageType::Detection3DArray => "vision_msgs/msg/Detection3DArray",
            MessageType::TrackedObjects => "autoware_perception_msgs/msg/TrackedObjects",
        }
    }

    /// The type a ROS type name names, if this adapter reads it.
    pub fn from_ros_name(name: &str) -> Option<Self> {
        MessageType::ALL.into_iter().find(|t| t.ros_name() == name)
    }

    /// The DDS type name rmw_zenoh puts in the data key.
    pub fn dds_name(self) -> String {
        keys::dds_type_name(self.ros_name()).unwrap_or_default()
    }
}

fn one() -> f64 {
    1.0
}

/// One subscribed topic: which, of what type, and how its positions
/// become metres (`x_m = x · scale + offset[0]`, the same for y).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TopicOptions {
    /// The fully qualified topic, `/tracker/detections`.
    pub topic: String,
    #[serde(rename = "type")]
    pub kind: MessageType,
    /// Metres per unit of the message's positions (pixels for a 2-D
    /// detector).
    #[serde(default = "one")]
    pub scale: f64,
    /// Where the message's origin is, in metres.
    #[serde(default)]
    pub offset: [f64; 2],
    /// Class names as the belief's labels (`{ "person_red" = "red" }`);
    /// a class not listed keeps its name.
    #[serde(default)]
    pub labels: BTreeMap<String, String>,
}

impl TopicOptions {
    /// Options with the identity position mapping and no renamed labels.
    pub fn new(topic: &str, kind: MessageType) -> Self {
        TopicOptions {
            topic: topic.to_string(),
            kind,
            scale: 1.0,
            offset: [0.0, 0.0],
            labels: BTreeMap::new(),
        }
    }

    /// Checks the numbers.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err(format!(
                "topic {}: scale must be finite and > 0, got {}",
                self.topic, self.scale
            ));
        }
        if !self.offset.iter().all(|v| v.is_finite()) {
            return Err(format!("topic {}: offset must be finite", self.topic));
        }
        if keys::topic_part(&self.topic).is_empty() || self.topic.contains(['*', '$', '?', '#']) {
            return Err(format!("topic {:?}: not a ROS topic name", self.topic));
        }
        Ok(())
    }
}

/// One detection of a message, before the topic's mapping.
#[derive(Debug, Clone, PartialEq)]
pub struct Detection {
    pub id: String,
    pub x: f64,
    pub y: f64,
    /// Class name and score, as the message lists them.
    pub classes: Vec<(String, f64)>,
}

/// Why a message gave no reports.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    #[error(transparent)]
    Cdr(#[from] cdr::CdrError),
    #[error("{0}")]
    Detection(String),
}

/// The decoder of one topic: its options and the track numbers given so
/// far.
#[derive(Debug, Clone)]
pub struct Decoder {
    options: TopicOptions,
    tracks: tracks::TrackIds,
}

impl Decoder {
    pub fn new(options: TopicOptions) -> Self {
        Decoder {
            options,
            tracks: tracks::TrackIds::default(),
        }
    }

    pub fn options(&self) -> &TopicOptions {
        &self.options
    }

    /// The named ids given track numbers so far, in number order
    /// ([`tracks::TrackIds::named`]).
    pub fn named(&self) -> &[String] {
        self.tracks.named()
    }

    /// Takes back the track numbers an earlier decoder of the topic gave
    /// named ids ([`tracks::TrackIds::restore`]), so that it goes on
    /// numbering as that one would have.
    pub fn restore_named(&mut self, ids: &[String]) -> Result<(), String> {
        self.tracks.restore(ids)
    }

    /// The reports one message (a CDR payload) makes, in track order; a
    /// message that is not one of the topic's type, or one of whose
    /// detections cannot be a report, makes none.
    pub fn decode(&mut self, payload: &[u8]) -> Result<Vec<Report>, DecodeError> {
        let (time, detections) = match self.options.kind {
            MessageType::Detection2DArray => {
                let m: vision::Detection2DArray = cdr::decode(payload)?;
                (m.header.stamp.seconds(), m.detections())
            }
            MessageType::Detection3DArray => {
                let m: vision::Detection3DArray = cdr::decode(payload)?;
                (m.header.stamp.seconds(), m.detections())
            }
            MessageType::TrackedObjects => {
                let m: autoware::TrackedObjects = cdr::decode(payload)?;
                (m.header.stamp.seconds(), m.detections())
            }
        };
        let mut reports = detections
            .into_iter()
            .map(|d| self.report(time, d))
            .collect::<Result<Vec<_>, _>>()
            .map_err(DecodeError::Detection)?;
        reports.sort_by_key(|r| r.track);
        Ok(reports)
    }

    fn report(&mut self, time: f64, detection: Detection) -> Result<Report, String> {
        let track = self.tracks.track(&detection.id)?;
        let [dx, dy] = self.options.offset;
        let scale = self.options.scale;
        let (x, y) = (detection.x * scale + dx, detection.y * scale + dy);
        if !(x.is_finite() && y.is_finite()) {
            return Err(format!("detection {}: position not finite", detection.id));
        }
        let scores = scores(&detection.classes, &self.options.labels)
            .map_err(|e| format!("detection {}: {e}", detection.id))?;
        Ok(Report {
            scores,
            ..Report::at(time, track, x, y)
        })
    }
}

/// The label a class score goes to when a detector's scores sum to less
/// than one (what it does not say).
pub const OTHER_LABEL: &str = "other";

/// A report as the line of the trace format that carries it: a `detect`
/// line when it has class scores or an identity read, else a `move` line
/// — what a sensor takes on its ingest key, and what `idmesh replay
/// --topology` reads back.
pub fn report_line(report: &Report) -> Line {
    if report.scores.is_none() && report.identity.is_none() {
        return Line::Move(Move {
            time: report.time,
            track: report.track,
            x: report.x,
            y: report.y,
        });
    }
    Line::Detect(Detect::from(report))
}

/// How far from one a sum of scores may be and still be one.
const ROUNDING: f64 = 1e-9;

/// Class scores as the trace format takes them: labels renamed, a
/// label's scores added, a sum short of one given to [`OTHER_LABEL`], a
/// sum over one scaled down to one. No class, no scores.
fn scores(
    classes: &[(String, f64)],
    labels: &BTreeMap<String, String>,
) -> Result<Option<BTreeMap<String, f64>>, String> {
    if classes.is_empty() {
        return Ok(None);
    }
    let mut out: BTreeMap<String, f64> = BTreeMap::new();
    for (class, score) in classes {
        if !(score.is_finite() && *score >= 0.0) {
            return Err(format!("class {class:?} has score {score}"));
        }
        let label = labels.get(class).unwrap_or(class);
        *out.entry(label.clone()).or_default() += score;
    }
    // A sum one but for rounding is one: the scores go through as the
    // detector wrote them.
    let sum: f64 = out.values().sum();
    if sum > 1.0 + ROUNDING {
        out.values_mut().for_each(|v| *v /= sum);
    } else if sum < 1.0 - ROUNDING {
        *out.entry(OTHER_LABEL.to_string()).or_default() += 1.0 - sum;
    }
    Ok(Some(out))
}

#[cfg(test)]
mod tests;
