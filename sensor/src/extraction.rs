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

use idmesh_extract::{Extractor, ExtractorConfig, Report, RosterPolicy};
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
    /// tracks `0..n` are the roster, its prior carried.
    pub fn new(config: ExtractorConfig, header: &Header) -> Result<Self, String> {
        let roster = RosterPolicy::Declared((0..header.tracks as u32).collect());
        let extractor = Extractor::new(config, roster)
            .map_err(|e| format!("extraction settings: {e}"))?
            .with_prior(header);
        Ok(Extraction { extractor })
    }

    /// Whether `line` is something this stage takes: a report, or a
    /// `truth` line (which carries no event and is passed over).
    pub fn admits(line: &Line) -> Result<(), String> {
        match line {
            Line::Move(_) | Line::Detect(_) | Line::Truth(_) => Ok(()),
            other => Err(format!(
                "{}: this sensor extracts its events from what a tracker reports \
                 (extraction is on in its topology): send move and detect lines",
                other.kind()
            )),
        }
    }

    /// Takes one line; the stream lines it completes (a frame closes when
    /// a report of a later time arrives), or why the report is refused
    /// (nothing changed).
    pub fn take(&mut self, line: &Line) -> Result<Vec<Line>, String> {
        Self::admits(line)?;
        let report: Report = match line {
            Line::Move(m) => (*m).into(),
            Line::Detect(d) => d.clone().into(),
            _ => return Ok(Vec::new()),
        };
        let mut out = Vec::new();
        self.extractor
            .push(report, &mut out)
            .map_err(|e| format!("{}: {e}", line.kind()))?;
        Ok(events_only(out))
    }

    /// The reports are over: the lines of the frame still open.
    pub fn finish(&mut self) -> Vec<Line> {
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
