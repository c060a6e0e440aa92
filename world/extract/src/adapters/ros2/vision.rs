//! `vision_msgs` (ROS 2 Humble and newer): `Detection2DArray` and
//! `Detection3DArray`, as serde structs in the messages' field order, and
//! what a detection says — its `id` the track, its box's centre the
//! position, its hypotheses the class scores.

use super::geometry::{Header, Pose, PoseWithCovariance, Vector3};
use super::Detection;
use serde::{Deserialize, Serialize};

/// `vision_msgs/msg/ObjectHypothesis`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ObjectHypothesis {
    pub class_id: String,
    pub score: f64,
}

/// `vision_msgs/msg/ObjectHypothesisWithPose`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ObjectHypothesisWithPose {
    pub hypothesis: ObjectHypothesis,
    pub pose: PoseWithCovariance,
}

/// `vision_msgs/msg/Point2D`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point2D {
    pub x: f64,
    pub y: f64,
}

/// `vision_msgs/msg/Pose2D`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose2D {
    pub position: Point2D,
    pub theta: f64,
}

/// `vision_msgs/msg/BoundingBox2D`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct BoundingBox2D {
    pub center: Pose2D,
    pub size_x: f64,
    pub size_y: f64,
}

/// `vision_msgs/msg/Detection2D`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Detection2D {
    pub header: Header,
    pub results: Vec<ObjectHypothesisWithPose>,
    pub bbox: BoundingBox2D,
    pub id: String,
}

/// `vision_msgs/msg/Detection2DArray`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Detection2DArray {
    pub header: Header,
    pub detections: Vec<Detection2D>,
}

/// `vision_msgs/msg/BoundingBox3D`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct BoundingBox3D {
    pub center: Pose,
    pub size: Vector3,
}

/// `vision_msgs/msg/Detection3D`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Detection3D {
    pub header: Header,
    pub results: Vec<ObjectHypothesisWithPose>,
    pub bbox: BoundingBox3D,
    pub id: String,
}

/// `vision_msgs/msg/Detection3DArray`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Detection3DArray {
    pub header: Header,
    pub detections: Vec<Detection3D>,
}

/// A detection of either array: its id, its box centre's x and y, its
/// hypotheses.
fn detection(id: &str, x: f64, y: f64, results: &[ObjectHypothesisWithPose]) -> Detection {
    Detection {
        id: id.to_string(),
        x,
        y,
        classes: results
            .iter()
            .map(|r| (r.hypothesis.class_id.clone(), r.hypothesis.score))
            .collect(),
    }
}

impl Detection2DArray {
    /// The detections, each at its box's centre (image units).
    pub fn detections(&self) -> Vec<Detection> {
        let at = |d: &Detection2D| d.bbox.center.position;
        self.detections
            .iter()
            .map(|d| detection(&d.id, at(d).x, at(d).y, &d.results))
            .collect()
    }
}

impl Detection3DArray {
    /// The detections, each at its box's centre (x and y of the frame).
    pub fn detections(&self) -> Vec<Detection> {
        let at = |d: &Detection3D| d.bbox.center.position;
        self.detections
            .iter()
            .map(|d| detection(&d.id, at(d).x, at(d).y, &d.results))
            .collect()
    }
}
