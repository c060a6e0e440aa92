//! The loop both replays share ([`drive`]): read a trace line by line,
//! hand each event the filter takes to it (the one conversion,
//! `idmesh_belief::from_trace`), write an answer at every `truth` line, and
//! name the line of every error, `FILE:LINE: kind: reason`; and what the
//! two replays measure and write the same way — the time inside the filter
//! ([`Timed`]), JSON Lines output, the summary's mean error.

use anyhow::{anyhow, Result};
use idmesh_belief::BeliefError;
use idmesh_protocol::trace::{Line, NumberedLine, TraceReader, Truth};
use serde::Serialize;
use std::io::{BufRead, Write};
use std::time::{Duration, Instant};
use tracing::debug;

/// One kind of replay: which lines are its events, how its filter takes
/// them, and what it answers at a `truth` line.
pub(crate) trait Replay {
    /// The engine event a line may carry.
    type Event;
    /// The JSON line written at a `truth` line.
    type Answer: Serialize;

    /// The event `line` carries for this filter; `None` for lines that do
    /// not bear on it (and the header and truth lines).
    fn event_of(line: &Line) -> Option<Self::Event>;

    /// Applies one event.
    fn apply(&mut self, event: &Self::Event) -> Result<(), BeliefError>;

    /// Every line, before its event is applied: nothing, unless the
    /// filter's regions depend on the stream (the regional rule).
    fn before(&mut self, _line: &Line) -> Result<(), BeliefError> {
        Ok(())
    }

    /// Every line, after its event is applied (see [`Replay::before`]).
    fn after(&mut self, _line: &Line) -> Result<(), BeliefError> {
        Ok(())
    }

    /// The answer at a `truth` line, scored against it where it says.
    fn answer(&mut self, truth: &Truth) -> Result<Self::Answer, BeliefError>;
}

/// Replays every line after the header of `reader` through `replay`,
/// writing its answers to `out`.
pub(crate) fn drive<R: BufRead, P: Replay>(
    reader: TraceReader<R>,
    replay: &mut P,
    out: &mut impl Write,
) -> Result<()> {
    let source = reader.source().to_string();
    let at = line_error(&source);
    for line in reader {
        let NumberedLine { number, line } = line?;
        // A tracker's report holds no event until `idmesh extract` has
        // derived it; replaying past it would lose its mixes silently.
        line.require_extracted()
            .map_err(|problem| anyhow!("{source}:{number}: {problem}"))?;
        replay
            .before(&line)
            .map_err(|e| at(number, line.kind(), e))?;
        if let Some(event) = P::event_of(&line) {
            replay
                .apply(&event)
                .map_err(|e| at(number, line.kind(), e))?;
        } else if let Line::Truth(truth) = &line {
            let answer = replay.answer(truth).map_err(|e| at(number, "truth", e))?;
            write_line(out, &answer)?;
        }
        replay
            .after(&line)
            .map_err(|e| at(number, line.kind(), e))?;
        debug!(line = number, kind = line.kind(), "line");
    }
    Ok(())
}

/// Writes one JSON Lines record.
pub(crate) fn write_line(out: &mut impl Write, value: &impl Serialize) -> Result<()> {
    serde_json::to_writer(&mut *out, value)
        .map_err(std::io::Error::from)
        .and_then(|()| out.write_all(b"\n"))
        .map_err(|e| anyhow!("cannot write the output: {e}"))
}

/// The `FILE:LINE: kind: reason` error of the replays, for trace `source`.
pub(crate) fn line_error(source: &str) -> impl Fn(usize, &str, BeliefError) -> anyhow::Error + '_ {
    move |line, kind, error| anyhow!("{source}:{line}: {kind}: {error}")
}

/// The mean error over the truth lines (None when there were none).
pub(crate) fn mean_error(errors: &[f64]) -> Option<f64> {
    (!errors.is_empty()).then(|| errors.iter().sum::<f64>() / errors.len() as f64)
}

/// Writes the summary line and flushes: the end of every replay.
pub(crate) fn finish(mut out: impl Write, summary: &impl Serialize) -> Result<()> {
    write_line(&mut out, summary)?;
    out.flush()
        .map_err(|e| anyhow!("cannot write the output: {e}"))
}

/// A filter with the bookkeeping of a replay: the time spent inside it
/// (building it, every event, every answer — and nothing else: reading and
/// printing excluded), and the events applied.
pub(crate) struct Timed<F: ?Sized> {
    pub filter: Box<F>,
    pub time: Duration,
    pub events: u64,
}

impl<F: ?Sized> Timed<F> {
    /// Builds the filter, on the clock.
    pub(crate) fn start<E>(build: impl FnOnce() -> Result<Box<F>, E>) -> Result<Self, E> {
        let clock = Instant::now();
        let filter = build()?;
        Ok(Timed {
            filter,
            time: clock.elapsed(),
            events: 0,
        })
    }

    /// Runs `work` on the filter, on the clock.
    pub fn time<T>(&mut self, work: impl FnOnce(&mut F) -> T) -> T {
        let clock = Instant::now();
        let result = work(&mut self.filter);
        self.time += clock.elapsed();
        result
    }

    /// Applies one event with `apply`, on the clock, and counts it.
    pub fn apply<E>(&mut self, apply: impl FnOnce(&mut F) -> Result<(), E>) -> Result<(), E> {
        self.time(apply)?;
        self.events += 1;
        Ok(())
    }
}

/// A replay's output lines, parsed, or its error as text (for tests).
#[cfg(test)]
pub(crate) fn output_lines(
    replay: impl FnOnce(&mut Vec<u8>) -> Result<()>,
) -> Result<Vec<serde_json::Value>, String> {
    let mut out = Vec::new();
    replay(&mut out).map_err(|e| format!("{e:#}"))?;
    String::from_utf8(out)
        .map_err(|e| e.to_string())?
        .lines()
        .map(|l| serde_json::from_str(l).map_err(|e| e.to_string()))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Counts the mixes it is given and answers the count at a truth line;
    /// refuses a mix of track 9.
    struct Mixes(u32);

    impl Replay for Mixes {
        type Event = u32;
        type Answer = (f64, u32);

        fn event_of(line: &Line) -> Option<u32> {
            match line {
                Line::Mix(mix) => Some(mix.b),
                _ => None,
            }
        }

        fn apply(&mut self, b: &u32) -> Result<(), BeliefError> {
            if *b == 9 {
                return Err(BeliefError::NoTracks);
            }
            self.0 += 1;
            Ok(())
        }

        fn answer(&mut self, truth: &Truth) -> Result<(f64, u32), BeliefError> {
            Ok((truth.time, self.0))
        }
    }

    const HEADER: &str =
        r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":10,"red":1}"#;

    fn run(body: &str) -> Result<String, String> {
        let trace = format!("{HEADER}\n{body}");
        let mut reader = TraceReader::new(trace.as_bytes(), "t.jsonl");
        reader.read_header().map_err(|e| e.to_string())?;
        let mut out = Vec::new();
        drive(reader, &mut Mixes(0), &mut out).map_err(|e| format!("{e:#}"))?;
        Ok(String::from_utf8(out).unwrap())
    }

    #[test]
    fn events_are_applied_in_order_and_skipped_lines_are_skipped() {
        let out = run(concat!(
            r#"{"kind":"mix","time":1,"a":0,"b":1,"swap":0.5}"#,
            "\n",
            r#"{"kind":"move","time":1,"track":0,"x":0,"y":0}"#,
            "\n",
            r#"{"kind":"truth","time":1,"red":[0]}"#,
            "\n",
            r#"{"kind":"mix","time":2,"a":0,"b":2,"swap":0.5}"#,
            "\n",
            r#"{"kind":"observe","time":2,"track":0,"red":1,"blue":0}"#,
            "\n",
            r#"{"kind":"truth","time":3,"red":[0]}"#,
            "\n",
        ))
        .unwrap();
        assert_eq!(out, "[1.0,1]\n[3.0,2]\n");
    }

    #[test]
    fn a_detect_line_is_refused_not_skipped() {
        let trace = format!(
            "{}\n{}\n",
            r#"{"kind":"header","format":"idmesh-trace","version":2,"tracks":10}"#,
            r#"{"kind":"detect","time":1,"track":0,"x":0,"y":0}"#
        );
        let mut reader = TraceReader::new(trace.as_bytes(), "t.jsonl");
        reader.read_header().unwrap();
        let error = drive(reader, &mut Mixes(0), &mut Vec::new()).unwrap_err();
        assert!(
            format!("{error:#}").starts_with("t.jsonl:2: detect: a tracker's report, not an event"),
            "{error:#}"
        );
    }

    #[test]
    fn a_refused_event_names_its_line_and_kind() {
        let error = run(concat!(
            r#"{"kind":"mix","time":1,"a":0,"b":1,"swap":0.5}"#,
            "\n",
            r#"{"kind":"mix","time":1,"a":0,"b":9,"swap":0.5}"#,
            "\n",
        ))
        .unwrap_err();
        assert!(error.starts_with("t.jsonl:3: mix: "), "{error}");
    }

    #[test]
    fn the_clock_counts_the_events_applied() {
        let mut timed: Timed<Vec<u32>> =
            Timed::start(|| Ok::<_, BeliefError>(Box::new(Vec::new()))).unwrap();
        timed
            .apply(|v| {
                v.push(1);
                Ok::<_, BeliefError>(())
            })
            .unwrap();
        assert!(timed
            .apply(|_| Err::<(), _>(BeliefError::NoTracks))
            .is_err());
        assert_eq!((timed.events, timed.filter.len()), (1, 1));
        assert_eq!(mean_error(&[]), None);
        assert_eq!(mean_error(&[0.25, 0.75]), Some(0.5));
    }
}
