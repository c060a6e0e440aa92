//! `visualization_msgs/msg/MarkerArray`: what a deployment publishes for
//! RViz — per track a sphere at its last position coloured from P(red)
//! (blue at 0, red at 1), and a text above it with the track's likely
//! identity and its probability.

use super::geometry::{Duration, Header, Point, Pose, Time, Vector3};
use serde::{Deserialize, Serialize};

/// The REP 2011 hash of `visualization_msgs/msg/MarkerArray`'s type
/// description (Jazzy and newer; tests check it against an independent
/// implementation).
pub const MARKER_ARRAY_HASH: &str =
    "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf";

/// The ROS type name.
pub const MARKER_ARRAY: &str = "visualization_msgs/msg/MarkerArray";

/// `std_msgs/msg/ColorRGBA`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ColorRgba {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}

/// `visualization_msgs/msg/UVCoordinate`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct UvCoordinate {
    pub u: f32,
    pub v: f32,
}

/// `sensor_msgs/msg/CompressedImage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    pub header: Header,
    pub format: String,
    pub data: Vec<u8>,
}

/// `visualization_msgs/msg/MeshFile`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshFile {
    pub filename: String,
    pub data: Vec<u8>,
}

/// `visualization_msgs/msg/Marker` (Jazzy's fields).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Marker {
    pub header: Header,
    pub ns: String,
    pub id: i32,
    pub marker_type: i32,
    pub action: i32,
    pub pose: Pose,
    pub scale: Vector3,
    pub color: ColorRgba,
    pub lifetime: Duration,
    pub frame_locked: bool,
    pub points: Vec<Point>,
    pub colors: Vec<ColorRgba>,
    pub texture_resource: String,
    pub texture: CompressedImage,
    pub uv_coordinates: Vec<UvCoordinate>,
    pub text: String,
    pub mesh_resource: String,
    pub mesh_file: MeshFile,
    pub mesh_use_embedded_materials: bool,
}

/// `visualization_msgs/msg/MarkerArray`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MarkerArray {
    pub markers: Vec<Marker>,
}

/// `Marker.SPHERE`, `Marker.TEXT_VIEW_FACING`, `Marker.ADD`,
/// `Marker.DELETEALL`.
pub const SPHERE: i32 = 2;
pub const TEXT_VIEW_FACING: i32 = 3;
pub const ADD: i32 = 0;
pub const DELETEALL: i32 = 3;

/// The namespaces of the two markers of a track.
pub const TRACKS_NS: &str = "idmesh/tracks";
pub const LABELS_NS: &str = "idmesh/identities";

/// One track as the markers show it.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackView {
    pub track: u32,
    pub at: [f64; 2],
    pub p_red: f64,
    /// The likely identity and its probability, when identities are
    /// tracked.
    pub identity: Option<(u32, f64)>,
}

/// A sphere's colour for P(red): blue at 0, red at 1, linear between.
pub fn colour(p_red: f64) -> ColorRgba {
    let p = p_red.clamp(0.0, 1.0) as f32;
    ColorRgba {
        r: p,
        g: 0.0,
        b: 1.0 - p,
        a: 1.0,
    }
}

/// The text above a track.
pub fn label(view: &TrackView) -> String {
    match view.identity {
        Some((identity, p)) => format!("track {}: id {identity} ({p:.2})", view.track),
        None => format!("track {}: P(red) {:.2}", view.track, view.p_red),
    }
}

/// The array: a `DELETEALL` first (a track gone from the answer leaves no
/// stale marker), then a sphere and a text per track, in `frame`, at
/// `stamp`.
pub fn marker_array(views: &[TrackView], frame: &str, stamp: Time) -> MarkerArray {
    let header = Header {
        stamp,
        frame_id: frame.to_string(),
    };
    let mut markers = vec![Marker {
        header: header.clone(),
        action: DELETEALL,
        ..Marker::default()
    }];
    for view in views {
        let position = Point {
            x: view.at[0],
            y: view.at[1],
            z: 0.0,
        };
        let sphere = Marker {
            header: header.clone(),
            ns: TRACKS_NS.to_string(),
            id: view.track as i32,
            marker_type: SPHERE,
            action: ADD,
            pose: Pose {
                position,
                ..Pose::default()
            },
            scale: Vector3 {
                x: 0.5,
                y: 0.5,
                z: 0.5,
            },
            color: colour(view.p_red),
            ..Marker::default()
        };
        let text = Marker {
            ns: LABELS_NS.to_string(),
            marker_type: TEXT_VIEW_FACING,
            pose: Pose {
                position: Point { z: 0.6, ..position },
                ..Pose::default()
            },
            scale: Vector3 {
                x: 0.0,
                y: 0.0,
                z: 0.3,
            },
            color: ColorRgba {
                r: 1.0,
                g: 1.0,
                b: 1.0,
                a: 1.0,
            },
            text: label(view),
            ..sphere.clone()
        };
        markers.push(sphere);
        markers.push(text);
    }
    MarkerArray { markers }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adapters::ros2::cdr;

    #[test]
    fn an_array_round_trips_with_its_tracks() {
        let views = [TrackView {
            track: 2,
            at: [1.5, -2.0],
            p_red: 0.75,
            identity: Some((4, 0.9)),
        }];
        let array = marker_array(&views, "map", Time { sec: 1, nanosec: 2 });
        assert_eq!(array.markers.len(), 3);
        assert_eq!(array.markers[0].action, DELETEALL);
        assert_eq!(array.markers[1].color.r, 0.75);
        assert_eq!(array.markers[2].text, "track 2: id 4 (0.90)");
        let bytes = cdr::encode(&array).unwrap();
        assert_eq!(cdr::decode::<MarkerArray>(&bytes).unwrap(), array);
    }
}
