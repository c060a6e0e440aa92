//! rosbag2 bags in MCAP (the default storage since ROS 2 Iron), read as a
//! stream: one record at a time through `mcap`'s sans-io reader, so
//! memory stays flat in the bag's length (a chunk at a time when the bag
//! is chunked). Every message of a channel whose schema is a type this
//! adapter reads ([`MessageType`]) is decoded into its reports; other
//! channels are passed over. A message that does not decode is a bad row,
//! named by its number in the bag (1-based, counting every message).

use super::{Decoder, MessageType, TopicOptions};
use crate::adapters::{Located, RowError};
use mcap::records::Record;
use mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader};
use std::collections::{HashMap, VecDeque};
use std::io::Read;

/// Which channels, and how their positions become metres.
#[derive(Debug, Clone, PartialEq)]
pub struct BagOptions {
    /// Only this topic (every readable one when `None`).
    pub topic: Option<String>,
    /// The mapping every read topic gets (its `topic` and `type` are the
    /// channel's).
    pub mapping: TopicOptions,
}

/// The rows of a bag, in the bag's order.
pub struct BagRows<R: Read> {
    input: R,
    linear: LinearReader,
    state: State,
}

/// What the records read so far set up, and the rows not yet handed out.
struct State {
    file: String,
    options: BagOptions,
    /// Schema id → the type it describes, if one this adapter reads.
    schemas: HashMap<u16, Option<MessageType>>,
    /// Channel id → its decoder, if its messages are read.
    channels: HashMap<u16, Option<Decoder>>,
    pending: VecDeque<Result<Located, RowError>>,
    messages: usize,
    done: bool,
}

impl<R: Read> BagRows<R> {
    pub fn new(input: R, file: &str, options: BagOptions) -> Self {
        BagRows {
            input,
            linear: LinearReader::new(),
            state: State {
                file: file.to_string(),
                options,
                schemas: HashMap::new(),
                channels: HashMap::new(),
                pending: VecDeque::new(),
                messages: 0,
                done: false,
            },
        }
    }

    /// Reads records until one makes rows or the bag ends.
    fn advance(&mut self) -> Result<(), String> {
        while self.state.pending.is_empty() {
            let event = match self.linear.next_event() {
                None => {
                    self.state.done = true;
                    return Ok(());
                }
                Some(event) => event.map_err(|e| format!("not an MCAP bag: {e}"))?,
            };
            match event {
                LinearReadEvent::ReadRequest(want) => {
                    let buffer = self.linear.insert(want);
                    let read = self
                        .input
                        .read(buffer)
                        .map_err(|e| format!("cannot read: {e}"))?;
                    self.linear.notify_read(read);
                }
                LinearReadEvent::Record { data, opcode } => {
                    let record = mcap::parse_record(opcode, data)
                        .map_err(|e| format!("not an MCAP bag: {e}"))?;
                    self.state.take(record);
                }
            }
        }
        Ok(())
    }
}

impl State {
    fn take(&mut self, record: Record<'_>) {
        match record {
            Record::Schema { header, .. } => {
                let kind = MessageType::from_ros_name(&header.name);
                self.schemas.insert(header.id, kind);
            }
            Record::Channel(channel) => {
                let kind = self.schemas.get(&channel.schema_id).copied().flatten();
                let wanted = self
                    .options
                    .topic
                    .as_ref()
                    .is_none_or(|t| *t == channel.topic);
                let decoder = kind.filter(|_| wanted && channel.message_encoding == "cdr");
                let decoder = decoder.map(|kind| {
                    Decoder::new(TopicOptions {
                        topic: channel.topic.clone(),
                        kind,
                        ..self.options.mapping.clone()
                    })
                });
                self.channels.insert(channel.id, decoder);
            }
            Record::Message { header, data } => {
                self.messages += 1;
                let line = self.messages;
                let Some(Some(decoder)) = self.channels.get_mut(&header.channel_id) else {
                    return;
                };
                match decoder.decode(&data) {
                    Ok(reports) => self.pending.extend(
                        reports
                            .into_iter()
                            .map(|report| Ok(Located { line, report })),
                    ),
                    Err(e) => {
                        let topic = &decoder.options().topic;
                        self.pending.push_back(Err(RowError::malformed(
                            &self.file,
                            line,
                            format!("{topic}: {e}"),
                        )))
                    }
                }
            }
            _ => {}
        }
    }
}

impl<R: Read> Iterator for BagRows<R> {
    type Item = Result<Located, RowError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.state.pending.is_empty() && !self.state.done {
            if let Err(reason) = self.advance() {
                // A bag that cannot be read on is one bad row, the last.
                self.state.done = true;
                let line = self.state.messages + 1;
                return Some(Err(RowError::malformed(&self.state.file, line, reason)));
            }
        }
        self.state.pending.pop_front()
    }
}
