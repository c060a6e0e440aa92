use super::autoware::{ObjectClassification, TrackedObject, TrackedObjects, Uuid};
use super::bag::{BagOptions, BagRows};
use super::geometry::{Header, Time};
use super::vision::{
    BoundingBox2D, Detection2D, Detection2DArray, ObjectHypothesis, ObjectHypothesisWithPose,
    Point2D, Pose2D,
};
use super::*;

fn detection(id: &str, x: f64, y: f64, classes: &[(&str, f64)]) -> Detection2D {
    Detection2D {
        id: id.to_string(),
        bbox: BoundingBox2D {
            center: Pose2D {
                position: Point2D { x, y },
                theta: 0.0,
            },
            size_x: 10.0,
            size_y: 20.0,
        },
        results: classes
            .iter()
            .map(|(class, score)| ObjectHypothesisWithPose {
                hypothesis: ObjectHypothesis {
                    class_id: class.to_string(),
                    score: *score,
                },
                ..Default::default()
            })
            .collect(),
        ..Default::default()
    }
}

fn frame(sec: i32, detections: Vec<Detection2D>) -> Detection2DArray {
    Detection2DArray {
        header: Header {
            stamp: Time {
                sec,
                nanosec: 500_000_000,
            },
            frame_id: "camera".into(),
        },
        detections,
    }
}

#[test]
fn a_2d_array_becomes_reports_in_metres() {
    let mut options = TopicOptions::new("/det", MessageType::Detection2DArray);
    options.scale = 0.5;
    options.offset = [1.0, -1.0];
    options.labels.insert("person_red".into(), "red".into());
    let mut decoder = Decoder::new(options);
    let message = frame(
        2,
        vec![
            detection("3", 10.0, 4.0, &[("person_red", 0.6)]),
            detection("1", 0.0, 0.0, &[]),
        ],
    );
    let reports = decoder.decode(&cdr::encode(&message).unwrap()).unwrap();
    assert_eq!(reports.len(), 2);
    assert_eq!(reports[0], Report::at(2.5, 1, 1.0, -1.0));
    let r = &reports[1];
    assert_eq!((r.track, r.x, r.y), (3, 6.0, 1.0));
    let scores = r.scores.as_ref().unwrap();
    assert_eq!(scores["red"], 0.6);
    assert!((scores[OTHER_LABEL] - 0.4).abs() < 1e-12);
}

#[test]
fn scores_over_one_are_scaled_and_bad_ones_refused() {
    let mut decoder = Decoder::new(TopicOptions::new("/det", MessageType::Detection2DArray));
    let over = frame(0, vec![detection("0", 0.0, 0.0, &[("a", 1.5), ("b", 0.5)])]);
    let reports = decoder.decode(&cdr::encode(&over).unwrap()).unwrap();
    assert_eq!(reports[0].scores.as_ref().unwrap()["a"], 0.75);
    let nan = frame(0, vec![detection("0", 0.0, 0.0, &[("a", f64::NAN)])]);
    let e = decoder.decode(&cdr::encode(&nan).unwrap()).unwrap_err();
    assert!(e.to_string().contains("detection 0: class \"a\""), "{e}");
}

#[test]
fn a_truncated_message_is_an_error_not_a_panic() {
    let mut decoder = Decoder::new(TopicOptions::new("/det", MessageType::Detection2DArray));
    let bytes = cdr::encode(&frame(1, vec![detection("0", 1.0, 1.0, &[("a", 1.0)])])).unwrap();
    for cut in 0..bytes.len() {
        assert!(decoder.decode(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    // And the decoder goes on.
    assert_eq!(decoder.decode(&bytes).unwrap().len(), 1);
}

#[test]
fn tracked_objects_number_their_uuids_in_order() {
    let object = |byte: u8, label: u8| TrackedObject {
        object_id: Uuid { uuid: [byte; 16] },
        classification: vec![ObjectClassification {
            label,
            probability: 1.0,
        }],
        ..Default::default()
    };
    let message = TrackedObjects {
        header: Header::default(),
        objects: vec![object(9, 7), object(2, 1)],
    };
    let mut decoder = Decoder::new(TopicOptions::new("/objects", MessageType::TrackedObjects));
    let reports = decoder.decode(&cdr::encode(&message).unwrap()).unwrap();
    // The first UUID seen is track 0, whatever its bytes.
    assert_eq!(reports[0].track, 0);
    assert_eq!(reports[0].scores.as_ref().unwrap()["pedestrian"], 1.0);
    assert_eq!(reports[1].scores.as_ref().unwrap()["car"], 1.0);
}

#[test]
fn a_bag_is_read_message_by_message() {
    let mut bytes = Vec::new();
    {
        let mut writer = mcap::Writer::new(std::io::Cursor::new(&mut bytes)).unwrap();
        let schema = writer
            .add_schema("vision_msgs/msg/Detection2DArray", "ros2msg", b"")
            .unwrap();
        let channel = writer
            .add_channel(schema, "/det", "cdr", &Default::default())
            .unwrap();
        for sec in 0..3 {
            let message = frame(sec, vec![detection("0", 1.0, 2.0, &[])]);
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: sec as u32,
                log_time: sec as u64,
                publish_time: sec as u64,
            };
            let mut data = cdr::encode(&message).unwrap();
            if sec == 1 {
                data.truncate(9);
            }
            writer.write_to_known_channel(&header, &data).unwrap();
        }
        writer.finish().unwrap();
    }
    let options = BagOptions {
        topic: None,
        mapping: TopicOptions::new("", MessageType::Detection2DArray),
    };
    let rows: Vec<_> = BagRows::new(&bytes[..], "bag.mcap", options).collect();
    assert_eq!(rows.len(), 3);
    assert_eq!(rows[0].as_ref().unwrap().report.time, 0.5);
    let bad = rows[1].as_ref().unwrap_err().to_string();
    assert!(bad.starts_with("bag.mcap:2: /det: bad CDR"), "{bad}");
    assert_eq!(rows[2].as_ref().unwrap().line, 3);
    let garbage: Vec<_> = BagRows::new(&b"not a bag"[..], "x", rows_options()).collect();
    assert_eq!(garbage.len(), 1);
    assert!(garbage[0].is_err());
}

fn rows_options() -> BagOptions {
    BagOptions {
        topic: None,
        mapping: TopicOptions::new("", MessageType::Detection2DArray),
    }
}

#[test]
fn a_3d_array_is_read_at_its_boxes_centres() {
    use super::geometry::{Point, Pose};
    use super::vision::{BoundingBox3D, Detection3D, Detection3DArray};
    let detection = |id: &str, x: f64| Detection3D {
        id: id.to_string(),
        bbox: BoundingBox3D {
            center: Pose {
                position: Point { x, y: -x, z: 9.0 },
                ..Default::default()
            },
            ..Default::default()
        },
        results: vec![ObjectHypothesisWithPose {
            hypothesis: ObjectHypothesis {
                class_id: "red".into(),
                score: 1.0,
            },
            ..Default::default()
        }],
        ..Default::default()
    };
    let message = Detection3DArray {
        header: Header {
            stamp: Time { sec: 4, nanosec: 0 },
            frame_id: "map".into(),
        },
        detections: vec![detection("b", 2.0), detection("a", 1.0)],
    };
    let mut options = TopicOptions::new("/det3d", MessageType::Detection3DArray);
    options.offset = [10.0, 0.0];
    let mut decoder = Decoder::new(options);
    let reports = decoder.decode(&cdr::encode(&message).unwrap()).unwrap();
    // Named ids: "b" came first, so it is track 0.
    assert_eq!(
        (reports[0].track, reports[0].x, reports[0].y),
        (0, 12.0, -2.0)
    );
    assert_eq!((reports[1].track, reports[1].x), (1, 11.0));
    assert_eq!(reports[0].time, 4.0);
    // A 2-D decoder refuses a 3-D message rather than misreading it.
    let mut wrong = Decoder::new(TopicOptions::new("/det3d", MessageType::Detection2DArray));
    assert!(wrong.decode(&cdr::encode(&message).unwrap()).is_err());
}

#[test]
fn a_report_is_a_detect_line_with_scores_else_a_move_line() {
    let plain = Report::at(1.0, 2, 3.0, 4.0);
    assert_eq!(report_line(&plain).kind(), "move");
    let scored = Report {
        scores: Some([("red".to_string(), 1.0)].into()),
        ..plain
    };
    let line = report_line(&scored);
    assert_eq!(line.kind(), "detect");
    let text = serde_json::to_string(&line).unwrap();
    let back = crate::adapters::jsonl::parse_line(&text, 2, None).unwrap();
    assert_eq!(back, crate::adapters::jsonl::JsonlRow::Report(scored));
}

#[test]
fn topic_options_are_checked() {
    let mut options = TopicOptions::new("/det", MessageType::Detection2DArray);
    assert_eq!(options.validate(), Ok(()));
    options.scale = 0.0;
    assert!(options.validate().is_err());
    options.scale = 1.0;
    options.topic = "/det/*".into();
    assert!(options.validate().is_err());
    let toml_like: TopicOptions = serde_json::from_str(
        r#"{"topic":"/objects","type":"autoware_perception_msgs/msg/TrackedObjects"}"#,
    )
    .unwrap();
    assert_eq!(toml_like.scale, 1.0);
    assert!(
        serde_json::from_str::<TopicOptions>(r#"{"topic":"/x","type":"std_msgs/msg/String"}"#)
            .is_err()
    );
}

/// A reader that counts the bytes taken from it.
struct Counting<'a> {
    bytes: &'a [u8],
    taken: std::rc::Rc<std::cell::Cell<usize>>,
}

impl std::io::Read for Counting<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = std::io::Read::read(&mut self.bytes, buf)?;
        self.taken.set(self.taken.get() + n);
        Ok(n)
    }
}

#[test]
fn a_bag_is_streamed_not_read_whole() {
    let mut bytes = Vec::new();
    {
        let options = mcap::WriteOptions::new()
            .compression(None)
            .chunk_size(Some(64 * 1024));
        let mut writer = options.create(std::io::Cursor::new(&mut bytes)).unwrap();
        let schema = writer
            .add_schema("vision_msgs/msg/Detection2DArray", "ros2msg", b"")
            .unwrap();
        let channel = writer
            .add_channel(schema, "/det", "cdr", &Default::default())
            .unwrap();
        for sec in 0..20_000 {
            let message = frame(sec, vec![detection("0", 1.0, 2.0, &[("red", 1.0)])]);
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: sec as u32,
                log_time: sec as u64,
                publish_time: sec as u64,
            };
            writer
                .write_to_known_channel(&header, &cdr::encode(&message).unwrap())
                .unwrap();
        }
        writer.finish().unwrap();
    }
    let taken = std::rc::Rc::new(std::cell::Cell::new(0));
    let input = Counting {
        bytes: &bytes,
        taken: taken.clone(),
    };
    let mut rows = BagRows::new(input, "long.mcap", rows_options());
    assert!(rows.next().unwrap().is_ok());
    // The first report came from the first chunk, not the whole file.
    assert!(
        taken.get() < bytes.len() / 10,
        "{} of {} bytes read for the first report",
        taken.get(),
        bytes.len()
    );
    assert_eq!(rows.count(), 19_999);
}

#[test]
fn an_absurd_length_is_an_error_at_once() {
    // Header: stamp (8 bytes), frame_id "" (length 1, a NUL, padding),
    // then a sequence that claims four billion detections.
    let mut payload = vec![0, 1, 0, 0];
    payload.extend_from_slice(&[0; 8]);
    payload.extend_from_slice(&1u32.to_le_bytes());
    payload.extend_from_slice(&[0, 0, 0, 0]);
    payload.extend_from_slice(&u32::MAX.to_le_bytes());
    let mut decoder = Decoder::new(TopicOptions::new("/det", MessageType::Detection2DArray));
    let started = std::time::Instant::now();
    assert!(decoder.decode(&payload).is_err());
    assert!(started.elapsed() < std::time::Duration::from_secs(1));
}
