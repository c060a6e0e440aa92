//! A whole extraction run, as `idmesh extract` does it: rows from an
//! adapter into the [`Extractor`], the lines it emits through the trace
//! format's validating writer, and a [`Tally`] of what went in and out.
//!
//! Bad rows: each is counted by reason and its `FILE:LINE: reason` kept.
//! With `max_errors` = 0 the first bad row ends the run with that error;
//! with N > 0 the run goes on past up to N bad rows and fails at the
//! (N + 1)-th ([`ErrorBudget`], as a sensor reading its own input). A bad
//! row is never skipped silently.

use crate::adapters::jsonl::{parse_line, report_line, report_of, JsonlRow, ReportLine};
use crate::adapters::{ErrorBudget, Located, RowError, RowProblem, Rows, Stopped};
use crate::extractor::{Extractor, ExtractorConfig, RosterPolicy};
use crate::meetings::CalibrationError;
use idmesh_protocol::trace::{Header, Line, Problem, TraceError, TraceWriter};
use std::collections::BTreeMap;
use std::io::{BufRead, Write};
use thiserror::Error;

/// What a run read and wrote.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Tally {
    /// Reports taken by the extractor.
    pub reports: usize,
    /// Lines written, by kind (header included).
    pub lines: BTreeMap<&'static str, usize>,
    /// Bad rows, by reason.
    pub rejected: BTreeMap<&'static str, usize>,
    /// The bad rows' messages, `FILE:LINE: reason`, in input order.
    pub errors: Vec<String>,
    /// How many tracks the trace has.
    pub tracks: usize,
}

impl Tally {
    pub fn rejected_total(&self) -> usize {
        self.rejected.values().sum()
    }

    /// `mix`, `observe` and `identify` lines.
    pub fn events(&self) -> usize {
        ["mix", "observe", "identify"]
            .iter()
            .map(|k| self.lines.get(k).copied().unwrap_or(0))
            .sum()
    }
}

/// Why a run stopped.
#[derive(Debug, Error)]
pub enum RunError {
    /// A bad row: the first, or the first past `--max-errors`.
    #[error(transparent)]
    Bad(#[from] Stopped<RowError>),
    /// The settings are unusable.
    #[error("{0}")]
    Config(#[from] CalibrationError),
    /// The stream's first line is not a valid header.
    #[error("{0}")]
    Header(RowError),
    /// Reading the input failed.
    #[error("{file}:{line}: {source}")]
    Read {
        file: String,
        line: usize,
        source: std::io::Error,
    },
    /// Writing the trace failed (or, a bug, the extractor wrote an
    /// invalid line).
    #[error(transparent)]
    Write(#[from] TraceError),
    /// The input held no report and no header: there is no trace to
    /// write.
    #[error("{0}: no reports and no header: nothing to extract")]
    NoReports(String),
}

/// Drives one run: an extractor (made once the roster is known), the
/// writer, the tally.
pub struct Run<W: Write> {
    config: ExtractorConfig,
    extractor: Option<Extractor>,
    writer: TraceWriter<W>,
    tally: Tally,
    budget: ErrorBudget,
    out: Vec<Line>,
    red: Option<usize>,
}

impl<W: Write> Run<W> {
    /// A run writing to `output` (named `sink` in errors).
    pub fn new(
        config: ExtractorConfig,
        output: W,
        sink: &str,
        max_errors: usize,
    ) -> Result<Self, RunError> {
        config.validate()?;
        Ok(Run {
            config,
            extractor: None,
            writer: TraceWriter::new(output, sink.to_string()),
            tally: Tally::default(),
            budget: ErrorBudget::new(max_errors),
            out: Vec::new(),
            red: None,
        })
    }

    /// The trace's header declares `red` red targets (`--red`).
    pub fn with_red(mut self, red: Option<usize>) -> Self {
        self.red = red;
        self
    }

    /// Fixes the roster policy; call once, before the first row.
    pub(crate) fn start(&mut self, policy: RosterPolicy) -> Result<(), RunError> {
        self.extractor = Some(Extractor::new(self.config.clone(), policy)?.with_red(self.red));
        Ok(())
    }

    /// Starts with the roster `header` declares (`0..tracks`), its
    /// identities and its prior carried to the output header
    /// ([`Extractor::for_stream`]).
    pub fn start_from(&mut self, header: &Header) -> Result<(), RunError> {
        self.extractor =
            Some(Extractor::for_stream(self.config.clone(), header)?.with_red(self.red));
        Ok(())
    }

    /// One row of the input.
    pub fn row(&mut self, file: &str, row: Result<Located, RowError>) -> Result<(), RunError> {
        let located = match row {
            Ok(located) => located,
            Err(e) => return self.reject(e),
        };
        let extractor = match &mut self.extractor {
            Some(x) => x,
            None => {
                self.start(RosterPolicy::FirstFrame)?;
                self.extractor.as_mut().expect("just started")
            }
        };
        match extractor.push(located.report, &mut self.out) {
            Ok(()) => {
                self.tally.reports += 1;
                self.flush()
            }
            Err(e) => self.reject(RowError::report(file, located.line, e)),
        }
    }

    fn reject(&mut self, error: RowError) -> Result<(), RunError> {
        *self
            .tally
            .rejected
            .entry(error.problem.reason())
            .or_default() += 1;
        let error = self.budget.spend(error)?;
        self.tally.errors.push(error.to_string());
        Ok(())
    }

    fn flush(&mut self) -> Result<(), RunError> {
        for line in self.out.drain(..) {
            self.writer.write(&line)?;
            *self.tally.lines.entry(line.kind()).or_default() += 1;
        }
        Ok(())
    }

    /// Ends the run: the last frame, the tally.
    pub fn finish(mut self, file: &str) -> Result<Tally, RunError> {
        let Some(extractor) = &mut self.extractor else {
            return Err(RunError::NoReports(file.to_string()));
        };
        extractor.finish(&mut self.out);
        // A roster a header declared makes a trace of its own (the prior
        // alone when no report was taken); without one, no report is no
        // trace.
        let Some(roster) = extractor.roster() else {
            return Err(RunError::NoReports(file.to_string()));
        };
        self.tally.tracks = roster.len();
        self.flush()?;
        self.writer.flush()?;
        Ok(self.tally)
    }
}

/// Extracts from rows in time order (a file's, or a stream's), under the
/// roster `policy`: declared ids (an empty list declares nothing: the
/// rows' errors say why there are none), or the first frame's.
pub fn extract_rows<W: Write>(
    rows: impl IntoIterator<Item = Result<Located, RowError>>,
    file: &str,
    mut run: Run<W>,
    policy: RosterPolicy,
) -> Result<Tally, RunError> {
    match policy {
        RosterPolicy::Declared(ids) if ids.is_empty() => {}
        policy => run.start(policy)?,
    }
    for row in rows {
        run.row(file, row)?;
    }
    run.finish(file)
}

/// Every track id among the good rows of a file read whole.
pub fn every_id(rows: &Rows) -> Vec<u32> {
    rows.iter()
        .filter_map(|r| r.as_ref().ok().map(|l| l.report.track))
        .collect()
}

/// Extracts from JSON lines, one at a time (a tracker may stream them),
/// each read by [`report_line`](crate::adapters::jsonl::report_line), the
/// reader a sensor that extracts uses too. A header on line 1 declares
/// the roster `0..tracks` (and identities), and each report is checked
/// against it; without one the roster is the first frame's.
pub fn extract_jsonl<W: Write>(
    input: impl BufRead,
    file: &str,
    mut run: Run<W>,
) -> Result<Tally, RunError> {
    let mut header: Option<Header> = None;
    for (index, text) in input.lines().enumerate() {
        let line = index + 1;
        let text = text.map_err(|source| RunError::Read {
            file: file.to_string(),
            line,
            source,
        })?;
        match parse_line(&text, line, header.as_ref()) {
            Ok(JsonlRow::Header(h)) => {
                run.start_from(&h)?;
                header = Some(h);
            }
            Ok(JsonlRow::Report(report)) => run.row(file, Ok(Located { line, report }))?,
            Ok(JsonlRow::Skip) => {}
            Err(problem) => run.row(
                file,
                Err(RowError {
                    file: file.to_string(),
                    line,
                    problem,
                }),
            )?,
        }
    }
    run.finish(file)
}

/// A stream of reports as a sensor that extracts reads its trace file,
/// and `idmesh replay --topology` the same file: what it keeps, and the
/// bad lines it went past.
#[derive(Debug, Clone, PartialEq)]
pub struct Reports {
    /// The stream's header: its tracks, its prior.
    pub header: Header,
    /// The reports the stream's extractor takes, in order, with their
    /// line numbers.
    pub lines: Vec<(usize, Line)>,
    /// The bad lines skipped within `--max-errors`, `FILE:LINE: reason`.
    pub skipped: Vec<String>,
}

/// Reads a stream of reports that opens with its header: each line by
/// [`report_line`](crate::adapters::jsonl::report_line), each report
/// through an extractor for the stream ([`Extractor::for_stream`]), so
/// that a report the extractor refuses (out of time order, a track twice
/// in a frame) is a bad line here, named by its line, as on standard
/// input. A `truth` line is passed over. Bad lines: as [`Run`]'s, up to
/// `max_errors` skipped and named, the next one stops the reading.
pub fn read_reports(
    input: impl BufRead,
    file: &str,
    config: &ExtractorConfig,
    max_errors: usize,
) -> Result<Reports, RunError> {
    let at = |line: usize, problem: RowProblem| RowError {
        file: file.to_string(),
        line,
        problem,
    };
    let read = |line: usize| {
        move |source| RunError::Read {
            file: file.to_string(),
            line,
            source,
        }
    };
    let mut input = input.lines();
    let first = match input.next() {
        None => return Err(RunError::Header(at(1, RowProblem::Line(Problem::Empty)))),
        Some(text) => text.map_err(read(1))?,
    };
    let header = match report_line(&first, 1, None) {
        Ok(ReportLine::Header(header)) => header,
        Ok(ReportLine::Report(line) | ReportLine::Skip(line)) => {
            let kind = line.kind();
            return Err(RunError::Header(at(
                1,
                RowProblem::Line(Problem::HeaderNotFirst { kind }),
            )));
        }
        Err(problem) => return Err(RunError::Header(at(1, problem))),
    };
    let mut extractor = Extractor::for_stream(config.clone(), &header)?;
    let mut budget = ErrorBudget::new(max_errors);
    let (mut lines, mut skipped, mut out) = (Vec::new(), Vec::new(), Vec::new());
    for (index, text) in input.enumerate() {
        let number = index + 2;
        let text = text.map_err(read(number))?;
        let problem = match report_line(&text, number, Some(&header)) {
            Ok(ReportLine::Report(line)) => {
                let Some(report) = report_of(&line) else {
                    continue;
                };
                match extractor.push(report, &mut out) {
                    Ok(()) => {
                        out.clear();
                        lines.push((number, line));
                        continue;
                    }
                    Err(e) => RowProblem::Report(e),
                }
            }
            Ok(ReportLine::Skip(_)) => continue,
            // The reader takes a header on line 1 only.
            Ok(ReportLine::Header(_)) => continue,
            Err(problem) => problem,
        };
        let error = budget.spend(at(number, problem))?;
        skipped.push(error.to_string());
    }
    Ok(Reports {
        header,
        lines,
        skipped,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn jsonl(text: &str, max_errors: usize) -> Result<(Tally, String), RunError> {
        let mut out = Vec::new();
        let run = Run::new(
            ExtractorConfig::default(),
            &mut out,
            "out.jsonl",
            max_errors,
        )?;
        let tally = extract_jsonl(text.as_bytes(), "in.jsonl", run)?;
        Ok((tally, String::from_utf8(out).unwrap()))
    }

    const GOOD: &str = r#"{"kind":"move","time":0,"track":4,"x":0,"y":0}
{"kind":"move","time":0,"track":5,"x":3,"y":0}
{"kind":"detect","time":1,"track":4,"x":0,"y":0,"scores":{"red":0.9,"blue":0.1}}
{"kind":"move","time":1,"track":5,"x":0.5,"y":0}
"#;

    #[test]
    fn a_stream_becomes_a_trace() {
        let (tally, trace) = jsonl(GOOD, 0).unwrap();
        assert_eq!(tally.reports, 4);
        assert_eq!(tally.tracks, 2);
        assert_eq!(tally.lines["mix"], 1);
        assert_eq!(tally.lines["header"], 1);
        assert!(
            trace.starts_with(r#"{"kind":"header","format":"idmesh-trace","version":2,"tracks":2"#)
        );
    }

    #[test]
    fn bad_rows_are_counted_by_reason_or_stop_the_run() {
        let bad = format!(
            "{GOOD}{}\n{}\n{}\n{}\n",
            r#"{"kind":"move","time":0.5,"track":4,"x":0,"y":0}"#,
            r#"{"kind":"move","time":2,"track":9,"x":0,"y":0}"#,
            r#"{"kind":"detect","time":2,"track":4,"x":0,"y":0,"scores":{"red":0.9,"blue":0.3}}"#,
            r#"{"kind":"mix","time":2,"a":0,"b":1,"swap":0.5}"#
        );
        let (tally, _) = jsonl(&bad, 4).unwrap();
        assert_eq!(tally.rejected_total(), 4);
        assert_eq!(
            tally.rejected,
            BTreeMap::from([
                ("bad scores", 1),
                ("malformed row", 1),
                ("out of time order", 1),
                ("unknown track", 1)
            ])
        );
        assert!(tally.errors[0].starts_with("in.jsonl:5: time 0.5 is before time 1"));
        assert!(tally.errors[1].starts_with("in.jsonl:6: track 9 is not in the roster"));
        let first = jsonl(&bad, 0).unwrap_err().to_string();
        assert!(first.starts_with("in.jsonl:5: time 0.5"), "{first}");
        let too_many = jsonl(&bad, 3).unwrap_err().to_string();
        assert!(
            too_many.starts_with("in.jsonl:8: mix: not a report"),
            "{too_many}"
        );
        assert!(
            too_many.ends_with("(bad line 4: more than --max-errors 3)"),
            "{too_many}"
        );
    }

    #[test]
    fn a_header_declares_the_roster() {
        let text = format!(
            "{}\n{}\n",
            r#"{"kind":"header","format":"idmesh-trace","version":2,"tracks":3,"identities":3}"#,
            r#"{"kind":"detect","time":0,"track":2,"x":0,"y":0,"identity":1,"accuracy":0.8}"#
        );
        let (tally, trace) = jsonl(&text, 0).unwrap();
        assert_eq!((tally.tracks, tally.lines["identify"]), (3, 1));
        assert!(trace.contains(r#""identities":3"#));
        assert!(matches!(jsonl("", 0), Err(RunError::NoReports(_))));
        // A header alone is the prior alone.
        let header = r#"{"kind":"header","format":"idmesh-trace","version":2,"tracks":3,"red":1}"#;
        let (tally, trace) = jsonl(header, 0).unwrap();
        assert_eq!(
            (tally.reports, tally.tracks, trace.lines().count()),
            (0, 3, 1)
        );
    }
}
