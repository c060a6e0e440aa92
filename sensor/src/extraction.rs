//! The sensor's extraction stage: a sensor whose topology turns
//! extraction on takes what a tracker reports — `move` and `detect` lines
//! — and routes the events `idmesh-extract` derives from them (property
//! paper, Section 6: a mix when two tracks meet, an observation of an
//! isolated track's class scores, an identity read), instead of events.
//!
//! It runs on the stream's one order: after the merge when several
//! sensors each take part of the reports, so every sensor derives the
//! same events, and a meeting of two tracks reported to two sensors is
//! one mix. It runs the very [`Extractor`] `idmesh extract` runs, from the
//! stream's header (its tracks are the roster, its prior the output's), so
//! a deployment fed positions serves what `idmesh replay` computes from
//! `idmesh extract`'s trace of the same positions.
//!
//! Its state is part of the gateway's journaled state: a restored sensor
//! feeds the same reports through again and reaches the same extractor.

use idmesh_extract::adapters::jsonl::{report_line, report_of, ReportLine};
use idmesh_extract::{Extractor, ExtractorConfig};
use idmesh_protocol::trace::{Header, Line};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// The extractor a sensor runs, and what it takes.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Extraction {
    /// Kept as the extractor's own snapshot (JSON): the gateway's state
    /// is written with postcard, which cannot write every serde shape.
    #[serde(serialize_with = "as_snapshot", deserialize_with = "from_snapshot")]
    extractor: Extractor,
}

fn as_snapshot<S: Serializer>(extractor: &Extractor, s: S) -> Result<S::Ok, S::Error> {
    extractor.snapshot().serialize(s)
}

fn from_snapshot<'de, D: Deserializer<'de>>(d: D) -> Result<Extractor, D::Error> {
    let text = String::deserialize(d)?;
    Extractor::restore(&text).map_err(serde::de::Error::custom)
}

impl Extraction {
    /// Extraction by `config` for the stream `header` describes: its
    /// tracks `0..n` are the roster, its identities and prior carried
    /// ([`Extractor::for_stream`], as `idmesh extract` and `idmesh replay
    /// --topology` make theirs).
    pub fn new(config: ExtractorConfig, header: &Header) -> Result<Self, String> {
        let extractor = Extractor::for_stream(config, header)
            .map_err(|e| format!("extraction settings: {e}"))?;
        Ok(Extraction { extractor })
    }

    /// One line of reports, read as every path reads it
    /// ([`report_line`], the reader `idmesh extract` uses): the line to
    /// put in the order (a report, or a `truth` line that carries
    /// nothing), or why not. `number` is its line in the input.
    pub fn read(text: &str, number: usize, header: &Header) -> Result<Line, String> {
        match report_line(text, number, Some(header)) {
            Ok(ReportLine::Report(line) | ReportLine::Skip(line)) => Ok(line),
            // Under a header the reader refuses another; kept total.
            Ok(ReportLine::Header(_)) => Err("header: the stream has its header".into()),
            Err(problem) => Err(problem.to_string()),
        }
    }

    /// Takes one line; the stream lines it completes (a frame closes when
    /// a report of a later time arrives), or why the report is refused
    /// (nothing changed). A line that is no report (`truth`) completes
    /// nothing.
    pub fn take(&mut self, line: &Line) -> Result<Vec<Line>, String> {
        let Some(report) = report_of(line) else {
            return Ok(Vec::new());
        };
        let mut out = Vec::new();
        self.extractor
            .push(report, &mut out)
            .map_err(|e| e.to_string())?;
        Ok(events_only(out))
    }

    /// The reports are over: the lines of the frame still open.
    pub(crate) fn finish(&mut self) -> Vec<Line> {
        let mut out = Vec::new();
        self.extractor.finish(&mut out);
        events_only(out)
    }
}

/// The stream has its header already (the one the extractor was made
/// from): only the lines after it go on.
fn events_only(mut lines: Vec<Line>) -> Vec<Line> {
    lines.retain(|l| !matches!(l, Line::Header(_)));
    lines
}
