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

use crate::driver::GatewayError;
use idmesh_extract::adapters::ros2::rmw::Attachment;
use idmesh_extract::adapters::ros2::{keys, report_line, Decoder, TopicOptions};
use serde::{Deserialize, Serialize};
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
}

/// A message's reports, as one ingest offer's parts.
pub(crate) struct Lines {
    pub producer: String,
    pub text: String,
}

impl Ros2Input {
    /// Subscribes to every topic of `config`.
    pub(crate) async fn start(
        session: &Session,
        config: &Ros2Config,
    ) -> Result<Self, GatewayError> {
        let (sender, messages) = mpsc::channel(QUEUE);
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
        Ok(Ros2Input::new(messages, config))
    }

    /// The decoders of `config`'s topics, reading `messages`.
    fn new(messages: mpsc::Receiver<Message>, config: &Ros2Config) -> Self {
        let topics = config
            .topics
            .iter()
            .map(|options| Topic {
                decoder: Decoder::new(options.clone()),
                producer: format!("ros2:{}", options.topic),
                seen: 0,
            })
            .collect();
        Ros2Input { messages, topics }
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use idmesh_extract::adapters::ros2::vision::{Detection2D, Detection2DArray};
    use idmesh_extract::adapters::ros2::{cdr, MessageType};

    fn input() -> Ros2Input {
        let config = Ros2Config {
            domain: 3,
            topics: vec![TopicOptions::new("/det", MessageType::Detection2DArray)],
        };
        assert_eq!(
            config.key(&config.topics[0]),
            "3/det/vision_msgs::msg::dds_::Detection2DArray_/*"
        );
        Ros2Input::new(mpsc::channel(1).1, &config)
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
