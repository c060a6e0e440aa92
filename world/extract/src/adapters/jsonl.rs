//! JSON lines: one report per line, in the trace format's own words — a
//! `move` line (a position) or a `detect` line (version 2: a position,
//! class scores, an identity read). A first line may be a `header`: its
//! `tracks` then declare the roster (tracker ids `0..tracks`) and its
//! `identities` turn identity reads on. Read line by line, so a tracker
//! can stream into `idmesh extract` on standard input.
//!
//! [`report_line`] is **the** reader of a line of reports: `idmesh
//! extract`, `idmesh replay --topology` and a sensor that extracts (its
//! trace file, standard input and ingest key) all decide with it what a
//! line is — a header, a report, a line to pass over, or a refusal saying
//! what is wrong — so that the offline twin and the deployment take and
//! refuse the same lines with the same words. What depends on the stream
//! so far (time order, the roster of the first frame, a track twice in a
//! frame) is the extractor's to decide, after it, in every path alike.
//!
//! Each line is decoded by the trace format's parser, so a malformed line
//! gets the same message as in a trace; under a header each report is
//! checked against it by the trace format's own rules (a `detect` line
//! needs a version-2 header, a track must be one of the header's).

use super::RowProblem;
use crate::extractor::Report;
use idmesh_protocol::trace::{Header, Line, Problem};

/// One line of a stream of reports, read.
#[derive(Debug, Clone, PartialEq)]
pub enum ReportLine {
    /// The stream's header (line 1 only).
    Header(Header),
    /// A report: a `move` or a `detect` line.
    Report(Line),
    /// A line allowed among reports that carries none: a `truth` line
    /// (ground truth of annotated data, for scoring only).
    Skip(Line),
}

/// Reads line `number` (1-based) of a stream of reports; `header` is the
/// stream's header once it has one. A header is allowed on line 1 only.
pub fn report_line(
    text: &str,
    number: usize,
    header: Option<&Header>,
) -> Result<ReportLine, RowProblem> {
    let text = text.strip_suffix('\n').unwrap_or(text);
    let text = text.strip_suffix('\r').unwrap_or(text);
    let line = Line::parse(text).map_err(RowProblem::Line)?;
    if let Line::Header(h) = &line {
        if number != 1 || header.is_some() {
            return Err(RowProblem::Malformed(
                "header: only the first line may be a header".into(),
            ));
        }
        h.validate().map_err(RowProblem::Line)?;
    }
    if let (Some(header), false) = (header, matches!(line, Line::Header(_))) {
        line.validate(header).map_err(RowProblem::Line)?;
    }
    match line {
        Line::Header(h) => Ok(ReportLine::Header(h)),
        Line::Move(_) => Ok(ReportLine::Report(line)),
        Line::Detect(ref d) => {
            if d.identity.is_some() != d.accuracy.is_some() {
                return Err(RowProblem::Line(Problem::HalfIdentityRead));
            }
            Ok(ReportLine::Report(line))
        }
        Line::Truth(_) => Ok(ReportLine::Skip(line)),
        other => Err(RowProblem::Malformed(format!(
            "{}: not a report: extraction takes what a tracker reports: send move and \
             detect lines (and a header first)",
            other.kind()
        ))),
    }
}

/// The report a `move` or `detect` line carries (`None` for any other).
pub fn report_of(line: &Line) -> Option<Report> {
    match line {
        Line::Move(m) => Some((*m).into()),
        Line::Detect(d) => Some(d.clone().into()),
        _ => None,
    }
}

/// One line of the input, as `idmesh extract` takes it.
#[derive(Debug, Clone, PartialEq)]
pub enum JsonlRow {
    Header(Header),
    Report(Report),
    Skip,
}

/// [`report_line`], with the report taken out of its line.
pub fn parse_line(
    text: &str,
    number: usize,
    header: Option<&Header>,
) -> Result<JsonlRow, RowProblem> {
    Ok(match report_line(text, number, header)? {
        ReportLine::Header(h) => JsonlRow::Header(h),
        ReportLine::Report(line) => match report_of(&line) {
            Some(report) => JsonlRow::Report(report),
            None => JsonlRow::Skip,
        },
        ReportLine::Skip(_) => JsonlRow::Skip,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extractor::IdentityRead;

    #[test]
    fn reports_and_a_header() {
        let header = r#"{"kind":"header","format":"idmesh-trace","version":2,"tracks":3}"#;
        assert!(matches!(parse_line(header, 1, None), Ok(JsonlRow::Header(h)) if h.tracks == 3));
        let row = parse_line(
            r#"{"kind":"detect","time":1,"track":2,"x":0.5,"y":1,"scores":{"red":0.8,"blue":0.2},"identity":1,"accuracy":0.9}"#,
            2,
            None,
        )
        .unwrap();
        let JsonlRow::Report(r) = row else {
            panic!("{row:?}")
        };
        assert_eq!(r.track, 2);
        assert_eq!(
            r.identity,
            Some(IdentityRead {
                identity: 1,
                accuracy: 0.9
            })
        );
        assert!(matches!(
            parse_line(
                r#"{"kind":"move","time":1,"track":2,"x":0.5,"y":1}"#,
                3,
                None
            ),
            Ok(JsonlRow::Report(_))
        ));
        let truth = r#"{"kind":"truth","time":1,"red":[0]}"#;
        assert_eq!(parse_line(truth, 4, None), Ok(JsonlRow::Skip));
    }

    #[test]
    fn what_is_not_a_report_is_named() {
        let v1 = Line::parse(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"red":1}"#,
        )
        .unwrap();
        let Line::Header(v1) = v1 else { unreachable!() };
        let cases = [
            (
                r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":0.5}"#,
                2,
                None,
                "mix: not a report",
            ),
            (
                r#"{"kind":"header","format":"idmesh-trace","version":2,"tracks":3}"#,
                2,
                None,
                "header: only the first line",
            ),
            ("{", 1, None, "malformed JSON"),
            (
                r#"{"kind":"detect","time":0,"track":1,"x":0,"y":0,"identity":1}"#,
                1,
                None,
                "detect: an identity read needs both",
            ),
            (
                r#"{"kind":"header","format":"idmesh-trace","version":9,"tracks":3}"#,
                1,
                None,
                "header: version 9",
            ),
            (
                r#"{"kind":"detect","time":0,"track":1,"x":0,"y":0}"#,
                2,
                Some(&v1),
                "detect: a version-1 trace has no detect lines",
            ),
            (
                r#"{"kind":"move","time":0,"track":7,"x":0,"y":0}"#,
                2,
                Some(&v1),
                "move: track = 7 is not a track",
            ),
            (
                r#"{"kind":"truth","time":0,"red":[0,1]}"#,
                2,
                Some(&v1),
                "truth: red has 2 tracks but the header says k = 1",
            ),
        ];
        for (text, line, header, want) in cases {
            let got = parse_line(text, line, header).unwrap_err().to_string();
            assert!(got.starts_with(want), "{got:?} vs {want:?}");
        }
        // Under a version-1 header a move line is a report.
        let r#move = r#"{"kind":"move","time":0,"track":1,"x":0,"y":0}"#;
        assert!(matches!(
            parse_line(r#move, 2, Some(&v1)),
            Ok(JsonlRow::Report(_))
        ));
    }
}
