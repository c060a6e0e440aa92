//! Autoware's `autoware_perception_msgs/msg/TrackedObjects`, as serde
//! structs in the messages' field order, and what a tracked object says —
//! its UUID the track, its pose the position, its classification the
//! class scores (labels by the message's constant names, lower case).

use super::geometry::{Header, Polygon, PoseWithCovariance, TwistWithCovariance, Vector3};
use super::Detection;
use serde::{Deserialize, Serialize};

/// `unique_identifier_msgs/msg/UUID`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Uuid {
    pub uuid: [u8; 16],
}

impl Uuid {
    /// The canonical 8-4-4-4-12 hexadecimal form.
    pub fn text(&self) -> String {
        let hex: String = self.uuid.iter().map(|b| format!("{b:02x}")).collect();
        format!(
            "{}-{}-{}-{}-{}",
            &hex[0..8],
            &hex[8..12],
            &hex[12..16],
            &hex[16..20],
            &hex[20..32]
        )
    }
}

/// `autoware_perception_msgs/msg/ObjectClassification`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ObjectClassification {
    pub label: u8,
    pub probability: f32,
}

/// The names of `ObjectClassification`'s label constants, by value.
pub const LABELS: [&str; 8] = [
    "unknown",
    "car",
    "truck",
    "bus",
    "trailer",
    "motorcycle",
    "bicycle",
    "pedestrian",
];

/// `autoware_perception_msgs/msg/TrackedObjectKinematics`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct TrackedObjectKinematics {
    pub pose_with_covariance: PoseWithCovariance,
    pub orientation_availability: u8,
    pub twist_with_covariance: TwistWithCovariance,
    pub acceleration_with_covariance: TwistWithCovariance,
    pub is_stationary: bool,
}

/// `autoware_perception_msgs/msg/Shape`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Shape {
    pub shape_type: u8,
    pub footprint: Polygon,
    pub dimensions: Vector3,
}

/// `autoware_perception_msgs/msg/TrackedObject`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TrackedObject {
    pub object_id: Uuid,
    pub existence_probability: f32,
    pub classification: Vec<ObjectClassification>,
    pub kinematics: TrackedObjectKinematics,
    pub shape: Shape,
}

/// `autoware_perception_msgs/msg/TrackedObjects`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TrackedObjects {
    pub header: Header,
    pub objects: Vec<TrackedObject>,
}

impl TrackedObjects {
    /// The objects, each at its pose's position.
    pub fn detections(&self) -> Vec<Detection> {
        self.objects
            .iter()
            .map(|o| {
                let at = o.kinematics.pose_with_covariance.pose.position;
                Detection {
                    id: o.object_id.text(),
                    x: at.x,
                    y: at.y,
                    classes: o
                        .classification
                        .iter()
                        .map(|c| (label_name(c.label), f64::from(c.probability)))
                        .collect(),
                }
            })
            .collect()
    }
}

fn label_name(label: u8) -> String {
    LABELS
        .get(usize::from(label))
        .map_or_else(|| label.to_string(), |name| (*name).to_string())
}
