//! JSON lines: one report per line, in the trace format's own words — a
//! `move` line (a position) or a `detect` line (version 2: a position,
//! class scores, an identity read). A first line may be a `header`: its
//! `tracks` then declare the roster (tracker ids `0..tracks`) and its
//! `identities` turn identity reads on. Read line by line, so a tracker
//! can stream into `idmesh extract` on standard input.
//!
//! Each line is decoded by the trace format's parser, so a malformed line
//! gets the same message as in a trace; the values are checked by the
//! extractor (scores, positions, time order, roster).

use super::RowProblem;
use crate::extractor::Report;
use idmesh_protocol::trace::{Header, Line};

/// One line of the input.
#[derive(Debug, Clone, PartialEq)]
pub enum JsonlRow {
    Header(Header),
    Report(Report),
}

/// Decodes line `line` (1-based); a header is allowed on line 1 only.
pub fn parse_line(text: &str, line: usize) -> Result<JsonlRow, RowProblem> {
    let text = text.strip_suffix('\r').unwrap_or(text);
    match Line::parse(text).map_err(|p| RowProblem::Malformed(p.to_string()))? {
        Line::Header(header) if line == 1 => {
            header
                .validate()
                .map_err(|p| RowProblem::Malformed(p.to_string()))?;
            Ok(JsonlRow::Header(header))
        }
        Line::Header(_) => Err(RowProblem::Malformed(
            "header: only the first line may be a header".into(),
        )),
        Line::Move(m) => Ok(JsonlRow::Report(m.into())),
        Line::Detect(d) => {
            if d.identity.is_some() != d.accuracy.is_some() {
                return Err(RowProblem::Malformed(
                    "detect: an identity read needs both identity and accuracy".into(),
                ));
            }
            Ok(JsonlRow::Report(d.into()))
        }
        other => Err(RowProblem::Malformed(format!(
            "{}: not a report: the extractor takes move and detect lines (and a header first)",
            other.kind()
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::extractor::IdentityRead;

    #[test]
    fn reports_and_a_header() {
        let header = r#"{"kind":"header","format":"idmesh-trace","version":2,"tracks":3}"#;
        assert!(matches!(parse_line(header, 1), Ok(JsonlRow::Header(h)) if h.tracks == 3));
        let row = parse_line(
            r#"{"kind":"detect","time":1,"track":2,"x":0.5,"y":1,"scores":{"red":0.8,"blue":0.2},"identity":1,"accuracy":0.9}"#,
            2,
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
            parse_line(r#"{"kind":"move","time":1,"track":2,"x":0.5,"y":1}"#, 3),
            Ok(JsonlRow::Report(_))
        ));
    }

    #[test]
    fn what_is_not_a_report_is_named() {
        let cases = [
            (
                r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":0.5}"#,
                2,
                "mix: not a report",
            ),
            (
                r#"{"kind":"header","format":"idmesh-trace","version":2,"tracks":3}"#,
                2,
                "header: only the first line",
            ),
            ("{", 1, "malformed JSON"),
            (
                r#"{"kind":"detect","time":0,"track":1,"x":0,"y":0,"identity":1}"#,
                1,
                "detect: an identity read needs both",
            ),
            (
                r#"{"kind":"header","format":"idmesh-trace","version":9,"tracks":3}"#,
                1,
                "header: version 9",
            ),
        ];
        for (text, line, want) in cases {
            let got = parse_line(text, line).unwrap_err().to_string();
            assert!(got.starts_with(want), "{got:?} vs {want:?}");
        }
    }
}
