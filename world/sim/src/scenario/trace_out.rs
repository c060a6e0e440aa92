//! Writing a [`GeneratedTrace`] as a trace file (shared/spec/trace.md,
//! version 1), through the validating [`TraceWriter`] of `idmesh-protocol`,
//! so a generated trace is always one the replay accepts.
//!
//! The mapping is field for field: the header carries `tracks`, `red`,
//! `initial_red` (when revealed), `source` and `description`; `mix` drops
//! the ground-truth `exchanged` flag (a trace's mix line says only what the
//! tracker knows); `truth` carries `red` only. `move` positions are rounded
//! to 0.1 mm, which is all a leader placing tracks needs and keeps files
//! small. An identity trace (scenario option `identities`) also carries
//! `identities` and `initial_identity` (when revealed) in the header,
//! `identify` lines, and `identity` on every `truth` line.

use super::trace::GeneratedTrace;
use crate::events::{SimEvent, TimedEvent};
use idmesh_protocol::trace::{
    Detect, Header, Line, Mix, Move, Observe, TraceError, TraceWriter, Truth,
};
use std::io::Write;

/// The `header` line of a generated trace.
pub(crate) fn header_line(trace: &GeneratedTrace) -> Line {
    let h = &trace.header;
    let mut header = Header::new(h.tracks);
    header.red = Some(h.red);
    header.initial_red = h.initial_red.clone();
    header.source = Some(h.source.clone());
    header.description = Some(h.description.clone());
    if let Some(identity) = &trace.identity {
        header.identities = Some(h.tracks);
        header.initial_identity = identity.reveal_initial.then(|| identity.initial.clone());
    }
    Line::Header(header)
}

/// The trace line of one event.
pub fn event_line(e: &TimedEvent) -> Line {
    let time = e.time;
    match &e.event {
        SimEvent::Mix { a, b, swap, .. } => Line::Mix(Mix {
            time,
            a: *a,
            b: *b,
            swap: *swap,
        }),
        SimEvent::Observe { track, red, blue } => Line::Observe(Observe {
            time,
            track: *track,
            red: *red,
            blue: *blue,
            sensor: None,
        }),
        SimEvent::Move { track, x, y } => Line::Move(Move {
            time,
            track: *track,
            x: round_position(*x),
            y: round_position(*y),
        }),
        SimEvent::Truth { red } => Line::Truth(Truth {
            time,
            red: Some(red.clone()),
            identity: None,
        }),
    }
}

/// Every line of the trace, header first (with the `identify` lines and
/// `truth` identities of an identity trace, see [`super::identity_out`]).
pub fn lines(trace: &GeneratedTrace) -> impl Iterator<Item = Line> + '_ {
    std::iter::once(header_line(trace)).chain(super::identity_out::EventLines::new(trace))
}

/// Writes the whole trace to `output` (wrap a file in a `BufWriter`);
/// `sink` names it in errors (`FILE:LINE: reason`). Returns the output,
/// flushed.
pub fn write_trace<W: Write>(
    trace: &GeneratedTrace,
    output: W,
    sink: impl Into<String>,
) -> Result<W, TraceError> {
    let mut writer = TraceWriter::new(output, sink);
    for line in lines(trace) {
        writer.write(&line)?;
    }
    writer.finish()
}

/// Writes what the simulated tracker reported (a scenario with
/// [`tracker_reports`](super::Scenario::tracker_reports) on) as a
/// version-2 trace: the trace's header (tracks, red count, what the prior
/// reveals) and one `detect` line per report, positions unrounded so that
/// `idmesh extract` measures the distances the simulator measured. `None`
/// when the scenario kept no reports.
pub fn write_tracker_output<W: Write>(
    trace: &GeneratedTrace,
    output: W,
    sink: impl Into<String>,
) -> Option<Result<W, TraceError>> {
    let reports = trace.reports.as_ref()?;
    Some(write_reports(
        trace,
        reports,
        TraceWriter::new(output, sink),
    ))
}

fn write_reports<W: Write>(
    trace: &GeneratedTrace,
    reports: &[idmesh_extract::Report],
    mut writer: TraceWriter<W>,
) -> Result<W, TraceError> {
    let Line::Header(mut header) = header_line(trace) else {
        unreachable!("header_line makes a header");
    };
    header.version = idmesh_protocol::trace::VERSION_2;
    header.source = Some(format!("{} (tracker output)", trace.header.source));
    writer.write(&Line::Header(header))?;
    for r in reports {
        writer.write(&Line::Detect(Detect::from(r)))?;
    }
    writer.finish()
}

fn round_position(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;
    use idmesh_protocol::trace::TraceReader;

    #[test]
    fn a_written_trace_reads_back_line_for_line() {
        let trace = Scenario::crowd()
            .targets(12)
            .duration(30.0)
            .seed(9)
            .generate()
            .unwrap();
        let bytes = write_trace(&trace, Vec::new(), "generated.jsonl").unwrap();
        let text = String::from_utf8(bytes).unwrap();
        let first = text.lines().next().unwrap();
        assert!(
            first.starts_with(
                r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":12,"red":6,"initial_red":["#
            ),
            "{first}"
        );
        assert!(!text.contains("exchanged"));
        let read: Vec<Line> = TraceReader::new(text.as_bytes(), "generated.jsonl")
            .map(|l| l.unwrap().line)
            .collect();
        let written: Vec<Line> = lines(&trace).collect();
        assert_eq!(read, written);
        assert_eq!(read.len(), trace.events.len() + 1);
        let mix = text
            .lines()
            .find(|l| l.contains(r#""kind":"mix""#))
            .unwrap();
        assert!(mix.starts_with(r#"{"kind":"mix","time":"#), "{mix}");
        assert!(mix.contains(r#","swap":0.5}"#), "{mix}");
        let observe = text
            .lines()
            .find(|l| l.contains(r#""kind":"observe""#))
            .unwrap();
        assert!(
            observe.ends_with(r#""red":0.8,"blue":0.2}"#)
                || observe.ends_with(r#""red":0.1,"blue":0.7}"#),
            "{observe}"
        );
    }

    #[test]
    fn a_bad_event_is_refused_with_its_line() {
        let mut trace = Scenario::waypoint()
            .targets(4)
            .duration(5.0)
            .generate()
            .unwrap();
        trace.events.insert(
            0,
            TimedEvent {
                time: 0.0,
                event: SimEvent::Mix {
                    a: 1,
                    b: 1,
                    swap: 0.5,
                    exchanged: false,
                },
            },
        );
        let err = write_trace(&trace, Vec::new(), "bad.jsonl").unwrap_err();
        assert!(err.to_string().starts_with("bad.jsonl:2: "), "{err}");
    }
}
