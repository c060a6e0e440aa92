//! ROS 2 tracker topics in: with `[sensor.ros2]`, the sensor subscribes to
//! each configured topic on the key rmw_zenoh publishes it under
//! (`<domain>/<topic>/<DDS type>/*`, any type hash: Jazzy's `RIHS01_…` and
//! Humble's `TypeHashNotSupported` alike), decodes every message with the
//! ROS 2 adapter of `idmesh-extract`, and offers its reports to its own
//! ingestion as the lines of a producer named after the topic
//! (`ros2:<topic>`, numbered on from the counter the sensor expects of
//! it, so a sensor resumed from its journal goes on), so they take the very path a
//! producer's lines take: the same checks, the same order, the same
//! journal, and the same events `idmesh replay --topology` derives from
//! those lines.
//!
//! A message that does not decode is counted (`ros2_bad` in the sensor's
//! stats), named in the log with its topic and sequence number (the
//! attachment's, as the publisher numbered it), and passed over: the topic
//! goes on.
//!
//! Named ids (names, UUIDs) are numbered by each topic's decoder in the
//! order they first appear, as `idmesh extract` numbers a bag's. Those
//! numbers are the sensor's state too: each one a message gives for the
//! first time is handed to the gateway ([`Ros2Input::newly_named`]), which
//! journals it before the lines that carry it, and a sensor resumed from
//! its journal gives them back to its decoders ([`Ros2Input::start`]), so
//! an id seen before a restart keeps its track and a new one gets the
//! next — not a number another id already has.

use crate::driver::GatewayError;
use idmesh_extract::adapters::ros2::rmw::Attachment;
use idmesh_extract::adapters::ros2::{keys, report_line, Decoder, TopicOptions};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use tokio::sync::mpsc;
use zenoh::Session;

/// `[sensor.ros2]`: the ROS domain and the topics to read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Config {
    /// The ROS domain id (`ROS_DOMAIN_ID`), the first chunk of every key.
    #[serde(default)]
    pub domain: u32,
    pub topics: Vec<TopicOptions>,
}

impl Ros2Config {
    /// Checks every topic's settings.
    pub fn validate(&self) -> Result<(), String> {
        if self.topics.is_empty() {
            return Err("[sensor.ros2] lists no topic".into());
        }
        self.topics.iter().try_for_each(TopicOptions::validate)
    }

    /// The key expression topic `t` is subscribed on.
    pub fn key(&self, t: &TopicOptions) -> String {
        keys::data_key(self.domain, &t.topic, &t.kind.dds_name(), "*")
    }
}

/// One message as it arrived: its topic's index, payload and attachment.
pub(crate) struct Message {
    topic: usize,
    payload: Vec<u8>,
    attachment: Option<Vec<u8>>,
}

/// Messages waiting for the sensor's task; the subscriptions push into it.
const QUEUE: usize = 1024;

/// The subscriptions and each topic's decoder and counter.
pub(crate) struct Ros2Input {
    messages: mpsc::Receiver<Message>,
    topics: Vec<Topic>,
}

struct Topic {
    decoder: Decoder,
    producer: String,
    /// Messages seen, for naming one without an attachment.
    seen: u64,
    /// How many of the decoder's named ids the gateway has been given.
    handed: usize,
}

/// A message's reports, as one ingest offer's parts.
pub(crate) struct Lines {
    pub producer: String,
    pub text: String,
}

/// Named ids a topic's decoder numbered for the first time: `ids[i]` is
/// track `first + i`.
#[derive(Debug, PartialEq)]
pub(crate) struct Named {
    pub producer: String,
    pub first: u32,
    pub ids: Vec<String>,
}

impl Ros2Input {
    /// Subscribes to every topic of `config`; each topic's decoder first
    /// takes back the track numbers `named` (by producer, from the
    /// journal) says it gave.
    pub(crate) async fn start(
        session: &Session,
        config: &Ros2Config,
        named: &BTreeMap<String, Vec<String>>,
    ) -> Result<Self, GatewayError> {
        let (sender, messages) = mpsc::channel(QUEUE);
        let input = Ros2Input::new(messages, config, named)?;
        for (index, options) in config.topics.iter().enumerate() {
            let key = config.key(options);
            let subscriber =
                session
                    .declare_subscriber(key.clone())
                    .await
                    .map_err(|e| GatewayError::Mesh {
                        what: "subscribe to a ROS 2 topic",
                        message: e.to_string(),
                    })?;
            tracing::info!(topic = %options.topic, %key, "reading a ROS 2 topic");
            let sender = sender.clone();
            // Forwarded with back-pressure: a message is never dropped
            // here, the tracker's stream is the belief's input.
            tokio::spawn(async move {
                while let Ok(sample) = subscriber.recv_async().await {
                    let message = Message {
                        topic: index,
                        payload: sample.payload().to_bytes().into_owned(),
                        attachment: sample.attachment().map(|a| a.to_bytes().into_owned()),
                    };
                    if sender.send(message).await.is_err() {
                        break;
                    }
                }
            });
        }
        Ok(input)
    }

    /// The decoders of `config`'s topics, reading `messages`, each given
    /// back the numbers `named` lists for its producer.
    fn new(
        messages: mpsc::Receiver<Message>,
        config: &Ros2Config,
        named: &BTreeMap<String, Vec<String>>,
    ) -> Result<Self, GatewayError> {
        let mut topics = Vec::with_capacity(config.topics.len());
        for options in &config.topics {
            let producer = format!("ros2:{}", options.topic);
            let mut decoder = Decoder::new(options.clone());
            let restored = named.get(&producer).map_or(&[][..], Vec::as_slice);
            decoder
                .restore_named(restored)
                .map_err(|problem| GatewayError::TrackIds {
                    producer: producer.clone(),
                    problem,
                })?;
            if !restored.is_empty() {
                tracing::info!(%producer, named = restored.len(),
                    "the track numbers of named ids, as the journal has them");
            }
            topics.push(Topic {
                decoder,
                producer,
                seen: 0,
                handed: restored.len(),
            });
        }
        Ok(Ros2Input { messages, topics })
    }

    /// The next message (never `None` while the sensor runs).
    pub(crate) async fn next(&mut self) -> Option<Message> {
        self.messages.recv().await
    }

    /// A message's reports as lines to ingest, or none (a message without
    /// detections, or one that does not decode: then the reason, with the
    /// topic and sequence number, is logged, and `Err` tells the caller to
    /// count it).
    pub(crate) fn lines(&mut self, message: Message) -> Result<Option<Lines>, ()> {
        let Some(topic) = self.topics.get_mut(message.topic) else {
            return Ok(None);
        };
        topic.seen += 1;
        let reports = match topic.decoder.decode(&message.payload) {
            Ok(reports) => reports,
            Err(error) => {
                let sequence = message
                    .attachment
                    .as_deref()
                    .and_then(Attachment::sequence_of);
                tracing::warn!(topic = %topic.decoder.options().topic, ?sequence,
                    received = topic.seen, %error, "a ROS 2 message refused");
                return Err(());
            }
        };
        if reports.is_empty() {
            return Ok(None);
        }
        let mut text = String::new();
        for report in &reports {
            // A line the trace format wrote itself: it serializes.
            let line = serde_json::to_string(&report_line(report)).unwrap_or_default();
            text.push_str(&line);
            text.push('\n');
        }
        Ok(Some(Lines {
            producer: topic.producer.clone(),
            text,
        }))
    }

    /// The named ids numbered since the last call, by topic: journal them
    /// before the lines that carry them are offered. (A message that did
    /// not decode may have numbered some too, before the detection that
    /// failed, as a bag's reader does: they are kept alike.)
    pub(crate) fn newly_named(&mut self) -> Vec<Named> {
        let mut out = Vec::new();
        for topic in &mut self.topics {
            let named = topic.decoder.named();
            if named.len() > topic.handed {
                out.push(Named {
                    producer: topic.producer.clone(),
                    first: topic.handed as u32,
                    ids: named[topic.handed..].to_vec(),
                });
                topic.handed = named.len();
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use idmesh_extract::adapters::ros2::vision::{Detection2D, Detection2DArray};
    use idmesh_extract::adapters::ros2::{cdr, MessageType};

    fn config() -> Ros2Config {
        Ros2Config {
            domain: 3,
            topics: vec![TopicOptions::new("/det", MessageType::Detection2DArray)],
        }
    }

    fn input() -> Ros2Input {
        let config = config();
        assert_eq!(
            config.key(&config.topics[0]),
            "3/det/vision_msgs::msg::dds_::Detection2DArray_/*"
        );
        Ros2Input::new(mpsc::channel(1).1, &config, &BTreeMap::new()).unwrap()
    }

    /// A message of detections with these ids, the i-th at x = i.
    fn of(ids: &[&str]) -> Message {
        let message = Detection2DArray {
            detections: ids
                .iter()
                .enumerate()
                .map(|(i, id)| {
                    let mut d = Detection2D {
                        id: id.to_string(),
                        ..Default::default()
                    };
                    d.bbox.center.position.x = i as f64;
                    d
                })
                .collect(),
            ..Default::default()
        };
        Message {
            topic: 0,
            payload: cdr::encode(&message).unwrap(),
            attachment: None,
        }
    }

    /// The track each id of a message became (found by its x).
    fn tracks(input: &mut Ros2Input, ids: &[&str]) -> BTreeMap<String, u64> {
        let lines = input.lines(of(ids)).unwrap().unwrap();
        lines
            .text
            .lines()
            .map(|l| {
                let line: serde_json::Value = serde_json::from_str(l).unwrap();
                let i = line["x"].as_f64().unwrap() as usize;
                (ids[i].to_string(), line["track"].as_u64().unwrap())
            })
            .collect()
    }

    fn numbered(pairs: &[(&str, u64)]) -> BTreeMap<String, u64> {
        pairs.iter().map(|&(id, n)| (id.to_string(), n)).collect()
    }

    /// The named ids' numbers are handed out once each, as they are
    /// first given; an input started again with them numbers as the first
    /// would have gone on numbering, whatever order the ids come in now.
    #[test]
    fn named_ids_are_handed_out_once_and_an_input_given_them_back_goes_on() {
        let mut first = input();
        let given = numbered(&[("walker", 0), ("cart", 1)]);
        assert_eq!(tracks(&mut first, &["walker", "cart"]), given);
        let named = first.newly_named();
        assert_eq!(
            named,
            [Named {
                producer: "ros2:/det".into(),
                first: 0,
                ids: vec!["walker".into(), "cart".into()],
            }]
        );
        assert_eq!(tracks(&mut first, &["cart", "walker"]), given);
        assert!(first.newly_named().is_empty(), "nothing new");
        let journaled = BTreeMap::from([("ros2:/det".to_string(), named[0].ids.clone())]);
        let mut again = Ros2Input::new(mpsc::channel(1).1, &config(), &journaled).unwrap();
        let mut whole = first;
        // Reports come in track order: a new id first in the message
        // still takes the next number.
        let ids = ["late", "cart", "walker"];
        assert_eq!(tracks(&mut again, &ids), tracks(&mut whole, &ids));
        let now = numbered(&[("walker", 0), ("cart", 1), ("late", 2)]);
        assert_eq!(tracks(&mut again, &ids), now);
        assert_eq!(again.newly_named(), whole.newly_named());
        // A journal of another topic's names, or none, leaves this one be.
        let other = BTreeMap::from([("ros2:/other".to_string(), vec!["x".to_string()])]);
        let mut fresh = Ros2Input::new(mpsc::channel(1).1, &config(), &other).unwrap();
        assert_eq!(tracks(&mut fresh, &["late"]), numbered(&[("late", 0)]));
        // Names no decoder gives (a whole number) are refused, naming
        // the topic.
        let bad = BTreeMap::from([("ros2:/det".to_string(), vec!["7".to_string()])]);
        let error = Ros2Input::new(mpsc::channel(1).1, &config(), &bad)
            .err()
            .expect("refused")
            .to_string();
        assert!(
            error.contains("ros2:/det") && error.contains("\"7\""),
            "{error}"
        );
    }

    #[test]
    fn a_message_becomes_its_topics_lines_and_a_bad_one_an_error() {
        let mut input = input();
        let message = Detection2DArray {
            detections: vec![Detection2D {
                id: "2".into(),
                ..Default::default()
            }],
            ..Default::default()
        };
        let payload = cdr::encode(&message).unwrap();
        let lines = input
            .lines(Message {
                topic: 0,
                payload: payload.clone(),
                attachment: None,
            })
            .unwrap()
            .unwrap();
        assert_eq!(lines.producer, "ros2:/det");
        assert_eq!(
            lines.text,
            "{\"kind\":\"move\",\"time\":0.0,\"track\":2,\"x\":0.0,\"y\":0.0}\n"
        );
        let bad = Message {
            topic: 0,
            payload: payload[..payload.len() - 3].to_vec(),
            attachment: None,
        };
        assert!(input.lines(bad).is_err());
        let empty = cdr::encode(&Detection2DArray::default()).unwrap();
        let none = Message {
            topic: 0,
            payload: empty,
            attachment: None,
        };
        assert!(matches!(input.lines(none), Ok(None)));
    }

    #[test]
    fn a_config_without_topics_is_refused() {
        let config = Ros2Config {
            domain: 0,
            topics: vec![],
        };
        assert!(config.validate().is_err());
    }
}
