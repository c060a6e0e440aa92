//! Live ingestion, decided: which lines from producers enter the sensor's
//! order. A pure, synchronous state machine (no I/O, no clock) — the actor
//! only hands it the bytes of a request and sends back its answer.
//!
//! Two doors:
//! - **the ingest key** ([`Ingest::offer`]): lines from any producer, each
//!   numbered by the producer's own counter
//!   ([`producer_to_sensor`](idmesh_protocol::wire::producer_to_sensor)
//!   states the rules a producer sees). Per producer the sensor keeps only
//!   the next counter it expects: below it a line is a duplicate (taken
//!   once, acknowledged every time), above it out of order (refused, not
//!   held — the producer resends from `next`, which the answer names; a
//!   hold would buy nothing a producer that keeps its unacknowledged lines
//!   does not already have, and would cost memory an attacker chooses).
//!   Each line is checked on its own against the stream's header: times
//!   are not ordered across producers (the order is the sensor's, and the
//!   belief does not read times).
//! - **standard input** ([`Ingest::read`]): a trace piped in, checked line
//!   by line by the trace format's own [`Validator`] (header first, times
//!   non-decreasing), exactly as a trace file is; a bad line is refused
//!   with its line and counted, and the driver skips it or stops the
//!   sensor (`--max-errors`).
//!
//! With extraction on, both doors read a line of reports with the one
//! reader `idmesh extract` and `idmesh replay --topology` use
//! ([`report_line`](idmesh_extract::adapters::jsonl::report_line)): the
//! same lines taken, passed over and refused, in the same words; time
//! order is then the extractor's to decide, when the line is routed.
//!
//! Nothing here is lost on purpose: a line accepted is handed back to the
//! gateway, which routes it (gives it its seq) before the answer leaves.

use idmesh_protocol::trace::{Header, Line, Validator};
use idmesh_protocol::wire::coordinator_to_sensor::SensorStats;
use idmesh_protocol::wire::producer_to_sensor::{IngestAck, LineRefused};
use std::collections::{BTreeMap, VecDeque};

/// The most producers one sensor keeps a counter for: each costs a few
/// bytes for the sensor's life, and a producer id is chosen by whoever
/// connects.
pub(crate) const MAX_PRODUCERS: usize = 65_536;
/// The longest producer id.
pub(crate) const MAX_PRODUCER_ID: usize = 128;
/// The most lines one request may carry (a reply lists each).
pub(crate) const MAX_LINES: usize = 65_536;

/// Why a whole request was refused (an error reply; counted).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum IngestRefusal {
    #[error("no producer: say who sends the lines (`?producer=<id>;counter=<c>`)")]
    NoProducer,
    #[error("producer id of {0} bytes: at most {MAX_PRODUCER_ID}")]
    LongProducer(usize),
    #[error("no counter: number the first line (`?producer=<id>;counter=<c>`, from 0)")]
    NoCounter,
    #[error("counter {0:?} is not a whole number")]
    BadCounter(String),
    #[error("the payload is not UTF-8 text: {0}")]
    NotText(String),
    #[error("no lines in the request")]
    Empty,
    #[error("{0} lines in one request: at most {MAX_LINES}")]
    TooManyLines(usize),
    #[error("counters {first}.. overflow with {lines} lines")]
    CounterOverflow { first: u64, lines: usize },
    #[error("{MAX_PRODUCERS} producers already: no counter kept for {0:?}")]
    TooManyProducers(String),
    #[error("the stream is finished: it takes no more events")]
    Finished,
    #[error("time {0:?} is not a finite number")]
    BadTime(String),
    #[error("`time` and `finish` are for one sensor of several: this one is the only one")]
    OnlyMesh,
}

/// What a request was asked to do, as the actor read it off the query.
#[derive(Debug, Clone, Copy)]
pub struct Offer<'a> {
    pub producer: Option<&'a str>,
    pub counter: Option<&'a str>,
    pub payload: &'a [u8],
    /// One sensor of several (`;time=<t>`): the producer gives this
    /// sensor nothing before time `t` (after the request's lines).
    pub time: Option<&'a str>,
    /// One sensor of several (`;finish`): the producers give this sensor
    /// no more events (after the request's lines).
    pub finish: bool,
}

/// An offer judged: the lines to put in the order (in order), and the
/// answer once they are in (its `events` is set by the gateway).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Judged {
    pub accepted: Vec<Line>,
    pub ack: IngestAck,
}

#[derive(serde::Serialize, serde::Deserialize)]
pub(crate) struct Ingest {
    sensor: String,
    #[serde(with = "idmesh_protocol::trace::as_json")]
    header: Header,
    /// The next counter expected from each producer.
    next: BTreeMap<String, u64>,
    /// Standard input's trace rules (header first, times in order).
    stdin: Validator,
    /// One sensor of several: a producer's counters are its own across
    /// sensors (they go up, with gaps for the lines other sensors took),
    /// and the last [`RECENT_COUNTERS`] each producer had taken here tell a
    /// duplicate from a line that came too late.
    #[serde(default)]
    gapped: bool,
    #[serde(default)]
    recent: BTreeMap<String, VecDeque<u64>>,
    /// Extraction is on: the lines taken are a tracker's reports (`move`,
    /// `detect`), not events ([`crate::extraction`]).
    #[serde(default)]
    extracting: bool,
}

/// The counters remembered per producer when counters have gaps.
pub(crate) const RECENT_COUNTERS: usize = 4096;

/// What decides whether a line that passed every other rule enters the
/// order (the intake of one sensor of several: is it late?), given the
/// line, its text, its producer and its counter; by default every line.
pub(crate) type Admit<'a> = dyn FnMut(&Line, &str, &str, u64) -> Result<(), String> + 'a;

impl Ingest {
    /// Ingestion into the stream `header` describes.
    pub(crate) fn new(sensor: &str, header: &Header) -> Self {
        let mut stdin = Validator::new();
        // The header was checked when the stream started; a header that
        // failed here would fail the router first.
        let _ = stdin.check(&Line::Header(header.clone()), 1);
        Ingest {
            sensor: sensor.to_string(),
            header: header.clone(),
            next: BTreeMap::new(),
            stdin,
            gapped: false,
            recent: BTreeMap::new(),
            extracting: false,
        }
    }

    /// Lines are a tracker's reports from now on: `move` and `detect`
    /// lines are taken, events refused.
    pub(crate) fn extracting(&mut self) {
        self.extracting = true;
    }

    /// One ingested line of this stream: an event (a report, with
    /// extraction on), or why not.
    pub(crate) fn event(&self, text: &str) -> Result<Line, String> {
        taken(text, &self.header, self.extracting)
    }

    /// The counter `producer`'s next line must carry (0 for one not
    /// heard from).
    pub(crate) fn next_counter(&self, producer: &str) -> u64 {
        self.next.get(producer).copied().unwrap_or(0)
    }

    /// Counters with gaps: one sensor of several ([`Ingest::recent`]).
    pub(crate) fn gapped(&mut self) {
        self.gapped = true;
    }

    /// Judges one ingest request; counts what it refuses and takes in
    /// `stats`.
    pub(crate) fn offer(
        &mut self,
        offer: Offer<'_>,
        stats: &mut SensorStats,
    ) -> Result<Judged, IngestRefusal> {
        self.offer_admitted(offer, stats, &mut |_, _, _, _| Ok(()))
    }

    /// [`Ingest::offer`], each line that passes every rule also passing
    /// `admit` (refused with its reason, counted as late, if it does not).
    pub(crate) fn offer_admitted(
        &mut self,
        offer: Offer<'_>,
        stats: &mut SensorStats,
        admit: &mut Admit<'_>,
    ) -> Result<Judged, IngestRefusal> {
        let judged = self.judge(offer, stats, admit);
        if judged.is_err() {
            stats.rejected += 1;
        }
        judged
    }

    fn judge(
        &mut self,
        offer: Offer<'_>,
        stats: &mut SensorStats,
        admit: &mut Admit<'_>,
    ) -> Result<Judged, IngestRefusal> {
        let Request {
            producer,
            first,
            lines,
        } = Request::read(&offer)?;
        if !self.next.contains_key(producer) && self.next.len() >= MAX_PRODUCERS {
            return Err(IngestRefusal::TooManyProducers(producer.to_string()));
        }
        let next = self.next.entry(producer.to_string()).or_insert_with(|| {
            stats.producers += 1;
            0
        });
        let mut judged = Judged {
            accepted: Vec::new(),
            ack: IngestAck {
                sensor: self.sensor.clone(),
                producer: producer.to_string(),
                first,
                lines: lines.len() as u64,
                ..IngestAck::default()
            },
        };
        for (i, text) in lines.iter().enumerate() {
            let counter = first + i as u64;
            let number = i as u64 + 1;
            let recent = self.recent.entry(producer.to_string()).or_default();
            if counter < *next && (!self.gapped || recent.contains(&counter)) {
                stats.duplicates += 1;
                judged.ack.duplicates.push(counter);
                continue;
            }
            if counter < *next || (counter > *next && !self.gapped) {
                stats.out_of_order += 1;
                stats.rejected += 1;
                let reason = if counter < *next {
                    format!(
                        "out of order: counter {counter} from {producer:?}, which is past it \
                         (at {next}) and never took it: a producer's counters go up"
                    )
                } else {
                    format!(
                        "out of order: counter {counter} from {producer:?}, which is at {next}: \
                         send again from {next}"
                    )
                };
                judged.ack.errors.push(LineRefused {
                    counter,
                    line: number,
                    reason,
                });
                continue;
            }
            // This line uses up its counter, taken or refused: one bad line
            // never stalls its producer.
            *next = counter + 1;
            let taken = taken(text, &self.header, self.extracting).and_then(|line| {
                admit(&line, text, producer, counter).inspect_err(|_| stats.late += 1)?;
                Ok(line)
            });
            match taken {
                Ok(line) => {
                    stats.ingested += 1;
                    judged.ack.accepted.push(counter);
                    judged.accepted.push(line);
                    if self.gapped {
                        if recent.len() >= RECENT_COUNTERS {
                            recent.pop_front();
                        }
                        recent.push_back(counter);
                    }
                }
                Err(reason) => {
                    stats.bad_lines += 1;
                    stats.rejected += 1;
                    tracing::warn!(%producer, counter, line = number, %reason, "ingested line refused");
                    judged.ack.errors.push(LineRefused {
                        counter,
                        line: number,
                        reason,
                    });
                }
            }
        }
        judged.ack.next = *next;
        Ok(judged)
    }

    /// Line `number` of a trace on standard input (the header was line
    /// 1): the line to route (`None` for a `truth` line, which carries no
    /// event), or why it was refused (`stdin:LINE: reason`; counted).
    pub fn read(
        &mut self,
        number: usize,
        text: &str,
        stats: &mut SensorStats,
    ) -> Result<Option<Line>, String> {
        let text = text.strip_suffix('\n').unwrap_or(text);
        let text = text.strip_suffix('\r').unwrap_or(text);
        let judged = if self.extracting {
            // Reports: read as every path reads them; time order is the
            // extractor's rule, decided when the line is routed.
            crate::extraction::Extraction::read(text, number, &self.header)
        } else {
            Line::parse(text)
                .and_then(|line| {
                    self.stdin.check(&line, number)?;
                    line.require_extracted()?;
                    Ok(line)
                })
                .map_err(|problem| problem.to_string())
        };
        match judged {
            Ok(Line::Truth(_)) => Ok(None),
            Ok(line) if self.extracting || line.is_event() => {
                stats.ingested += 1;
                Ok(Some(line))
            }
            Ok(_) => Ok(None),
            Err(problem) => {
                stats.bad_lines += 1;
                stats.rejected += 1;
                Err(format!("stdin:{number}: {problem}"))
            }
        }
    }
}

/// An ingest request's envelope, read and checked before any of its
/// lines is judged: who sent it, the counter of its first line, and its
/// lines (without their line ends).
struct Request<'a> {
    producer: &'a str,
    first: u64,
    lines: Vec<&'a str>,
}

impl<'a> Request<'a> {
    fn read(offer: &Offer<'a>) -> Result<Self, IngestRefusal> {
        let producer = offer
            .producer
            .filter(|p| !p.is_empty())
            .ok_or(IngestRefusal::NoProducer)?;
        if producer.len() > MAX_PRODUCER_ID {
            return Err(IngestRefusal::LongProducer(producer.len()));
        }
        let counter = offer.counter.ok_or(IngestRefusal::NoCounter)?;
        let first: u64 = counter
            .parse()
            .map_err(|_| IngestRefusal::BadCounter(counter.to_string()))?;
        let text = std::str::from_utf8(offer.payload)
            .map_err(|e| IngestRefusal::NotText(e.to_string()))?;
        let text = text.strip_suffix('\n').unwrap_or(text);
        if text.is_empty() {
            return Err(IngestRefusal::Empty);
        }
        let lines: Vec<&str> = text
            .split('\n')
            .map(|l| l.strip_suffix('\r').unwrap_or(l))
            .collect();
        if lines.len() > MAX_LINES {
            return Err(IngestRefusal::TooManyLines(lines.len()));
        }
        if first.checked_add(lines.len() as u64).is_none() {
            return Err(IngestRefusal::CounterOverflow {
                first,
                lines: lines.len(),
            });
        }
        Ok(Request {
            producer,
            first,
            lines,
        })
    }
}

/// One ingested line: an event of this stream (a report, with
/// extraction on), or why not.
fn taken(text: &str, header: &Header, extracting: bool) -> Result<Line, String> {
    if !extracting {
        return event(text, header);
    }
    crate::extraction::Extraction::read(text, 0, header)
}

/// One ingested line: an event of this stream, or why not.
pub(crate) fn event(text: &str, header: &Header) -> Result<Line, String> {
    let line = Line::parse(text).map_err(|p| p.to_string())?;
    line.require_extracted().map_err(|p| p.to_string())?;
    if !line.is_event() {
        return Err(format!(
            "{}: not an event: the sensor takes mix, observe, move and identify lines",
            line.kind()
        ));
    }
    line.validate(header).map_err(|p| p.to_string())?;
    Ok(line)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header() -> Header {
        let line = Line::parse(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":4,"red":2}"#,
        )
        .unwrap();
        match line {
            Line::Header(h) => h,
            _ => unreachable!(),
        }
    }

    fn mix(a: u32, b: u32) -> String {
        format!(r#"{{"kind":"mix","time":1.0,"a":{a},"b":{b},"swap":0.5}}"#)
    }

    fn offer<'a>(producer: &'a str, counter: &'a str, payload: &'a str) -> Offer<'a> {
        Offer {
            producer: Some(producer),
            counter: Some(counter),
            payload: payload.as_bytes(),
            time: None,
            finish: false,
        }
    }

    fn ingest() -> (Ingest, SensorStats) {
        (Ingest::new("sensor-0", &header()), SensorStats::default())
    }

    #[test]
    fn lines_in_counter_order_are_accepted_and_acknowledged() {
        let (mut ingest, mut stats) = ingest();
        let payload = format!("{}\n{}\n", mix(0, 1), mix(2, 3));
        let judged = ingest
            .offer(offer("cam", "0", &payload), &mut stats)
            .unwrap();
        assert_eq!(judged.accepted.len(), 2);
        assert_eq!(judged.ack.accepted, vec![0, 1]);
        assert_eq!(judged.ack.next, 2);
        assert_eq!(judged.ack.lines, 2);
        assert!(judged.ack.errors.is_empty() && judged.ack.duplicates.is_empty());
        let judged = ingest
            .offer(offer("cam", "2", &mix(1, 2)), &mut stats)
            .unwrap();
        assert_eq!(judged.ack.accepted, vec![2]);
        assert_eq!((stats.ingested, stats.producers, stats.rejected), (3, 1, 0));
    }

    #[test]
    fn a_detect_line_is_refused_with_where_to_go() {
        let detect = r#"{"kind":"detect","time":1,"track":0,"x":0,"y":0}"#;
        let error = event(detect, &header()).unwrap_err();
        assert!(
            error.starts_with("detect: a tracker's report, not an event"),
            "{error}"
        );
    }

    #[test]
    fn a_line_sent_again_is_acknowledged_and_not_taken_twice() {
        let (mut ingest, mut stats) = ingest();
        let payload = format!("{}\n{}", mix(0, 1), mix(2, 3));
        ingest
            .offer(offer("cam", "0", &payload), &mut stats)
            .unwrap();
        // The whole history again, and one line past it.
        let again = format!("{}\n{}\n{}", mix(0, 1), mix(2, 3), mix(0, 3));
        let judged = ingest.offer(offer("cam", "0", &again), &mut stats).unwrap();
        assert_eq!(judged.ack.duplicates, vec![0, 1]);
        assert_eq!(judged.ack.accepted, vec![2]);
        assert_eq!(judged.accepted.len(), 1);
        assert_eq!(
            (stats.ingested, stats.duplicates, stats.rejected),
            (3, 2, 0)
        );
    }

    #[test]
    fn a_counter_ahead_of_the_producer_is_refused_naming_where_to_resend_from() {
        let (mut ingest, mut stats) = ingest();
        ingest
            .offer(offer("cam", "0", &mix(0, 1)), &mut stats)
            .unwrap();
        let judged = ingest
            .offer(offer("cam", "5", &mix(0, 1)), &mut stats)
            .unwrap();
        assert!(judged.accepted.is_empty());
        assert_eq!(judged.ack.next, 1);
        let error = &judged.ack.errors[0];
        assert_eq!((error.counter, error.line), (5, 1));
        assert!(error.reason.contains("out of order") && error.reason.contains("from 1"));
        assert_eq!((stats.out_of_order, stats.rejected), (1, 1));
        // Resent from 1, it is taken.
        let judged = ingest
            .offer(offer("cam", "1", &mix(0, 1)), &mut stats)
            .unwrap();
        assert_eq!(judged.ack.accepted, vec![1]);
    }

    #[test]
    fn producers_count_on_their_own() {
        let (mut ingest, mut stats) = ingest();
        ingest
            .offer(offer("a", "0", &mix(0, 1)), &mut stats)
            .unwrap();
        let judged = ingest
            .offer(offer("b", "0", &mix(0, 1)), &mut stats)
            .unwrap();
        assert_eq!(judged.ack.accepted, vec![0]);
        assert_eq!(stats.producers, 2);
    }

    #[test]
    fn a_bad_line_is_refused_with_its_line_and_reason_and_uses_up_its_counter() {
        let (mut ingest, mut stats) = ingest();
        let payload = [
            mix(0, 1),
            r#"{"kind":"observe","time":1,"track":9,"red":0.8,"blue":0.2}"#.to_string(),
            "not json".to_string(),
            r#"{"kind":"truth","time":1,"red":[0,1]}"#.to_string(),
            mix(2, 3),
        ]
        .join("\n");
        let judged = ingest
            .offer(offer("cam", "0", &payload), &mut stats)
            .unwrap();
        assert_eq!(judged.ack.accepted, vec![0, 4]);
        let lines: Vec<u64> = judged.ack.errors.iter().map(|e| e.line).collect();
        assert_eq!(lines, vec![2, 3, 4]);
        assert!(judged.ack.errors[0]
            .reason
            .contains("track = 9 is not a track"));
        assert!(judged.ack.errors[1].reason.contains("malformed JSON"));
        assert!(judged.ack.errors[2].reason.contains("not an event"));
        assert_eq!(judged.ack.next, 5);
        assert_eq!((stats.bad_lines, stats.rejected, stats.ingested), (3, 3, 2));
    }

    #[test]
    fn a_request_that_cannot_be_read_is_refused_whole_and_counted() {
        let (mut ingest, mut stats) = ingest();
        let line = mix(0, 1);
        let max = u64::MAX.to_string();
        let cases = [
            (
                Offer {
                    producer: None,
                    counter: Some("0"),
                    payload: line.as_bytes(),
                    time: None,
                    finish: false,
                },
                IngestRefusal::NoProducer,
            ),
            (
                Offer {
                    producer: Some("cam"),
                    counter: None,
                    payload: line.as_bytes(),
                    time: None,
                    finish: false,
                },
                IngestRefusal::NoCounter,
            ),
            (
                offer("cam", "-1", &line),
                IngestRefusal::BadCounter("-1".into()),
            ),
            (offer("cam", "0", ""), IngestRefusal::Empty),
            (
                Offer {
                    producer: Some("cam"),
                    counter: Some("0"),
                    payload: &[0xff, 0xfe],
                    time: None,
                    finish: false,
                },
                IngestRefusal::NotText("invalid utf-8 sequence of 1 bytes from index 0".into()),
            ),
            (
                offer("cam", &max, &line),
                IngestRefusal::CounterOverflow {
                    first: u64::MAX,
                    lines: 1,
                },
            ),
        ];
        let n = cases.len() as u64;
        for (offer, refusal) in cases {
            assert_eq!(ingest.offer(offer, &mut stats).unwrap_err(), refusal);
        }
        assert_eq!(stats.rejected, n);
        // Nothing was taken: the producer still starts at 0.
        let judged = ingest.offer(offer("cam", "0", &line), &mut stats).unwrap();
        assert_eq!(judged.ack.accepted, vec![0]);
    }

    #[test]
    fn standard_input_follows_the_trace_rules_and_skips_a_bad_line() {
        let (mut ingest, mut stats) = ingest();
        let later = r#"{"kind":"mix","time":5.0,"a":0,"b":1,"swap":0.5}"#;
        assert!(ingest.read(2, later, &mut stats).unwrap().is_some());
        // Time goes back: refused, named by its line.
        let e = ingest.read(3, &mix(0, 1), &mut stats).unwrap_err();
        assert!(e.starts_with("stdin:3: ") && e.contains("time"), "{e}");
        let truth = r#"{"kind":"truth","time":6,"red":[0,1]}"#;
        assert_eq!(ingest.read(4, truth, &mut stats), Ok(None));
        assert_eq!((stats.ingested, stats.bad_lines, stats.rejected), (1, 1, 1));
    }

    /// With extraction on, the ingest key and standard input read a line
    /// of reports as `idmesh extract` reads it: the same refusals, in the
    /// same words, and a `truth` line passed over.
    #[test]
    fn reports_are_read_as_idmesh_extract_reads_them_on_both_doors() {
        let header = header();
        let lines = [
            r#"{"kind":"detect","time":1,"track":0,"x":0,"y":0}"#,
            r#"{"kind":"move","time":1,"track":9,"x":0,"y":0}"#,
            r#"{"kind":"move","time":1,"#,
            r#"{"kind":"mix","time":1,"a":0,"b":1,"swap":0.5}"#,
            r#"{"kind":"detect","time":1,"track":0,"x":0,"y":0,"scores":{"red":0.9}}"#,
        ];
        for (i, text) in lines.iter().enumerate() {
            let want = idmesh_extract::adapters::jsonl::parse_line(text, i + 2, Some(&header))
                .unwrap_err()
                .to_string();
            let (mut ingest, mut stats) = ingest();
            ingest.extracting();
            let judged = ingest.offer(offer("cam", "0", text), &mut stats).unwrap();
            assert_eq!(judged.ack.errors[0].reason, want, "the ingest key");
            let read = ingest.read(i + 2, text, &mut stats).unwrap_err();
            assert_eq!(read, format!("stdin:{}: {want}", i + 2), "standard input");
        }
        let (mut ingest, mut stats) = ingest();
        ingest.extracting();
        let truth = r#"{"kind":"truth","time":6,"red":[0,1]}"#;
        assert_eq!(ingest.read(2, truth, &mut stats), Ok(None));
        let r#move = r#"{"kind":"move","time":1,"track":1,"x":0,"y":0}"#;
        assert!(ingest.read(3, r#move, &mut stats).unwrap().is_some());
    }
}
