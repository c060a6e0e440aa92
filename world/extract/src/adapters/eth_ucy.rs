//! The two annotation formats of `shared/data/pedestrians` (see its README),
//! told apart by their number of columns:
//!
//! - **obsmat** (ETH "Format B"), 8 whitespace-separated numbers per row:
//!   `frame ped_id pos_x pos_z pos_y v_x v_z v_y`; the ground plane is
//!   (pos_x, pos_y), `pos_z` and the velocities are read but unused.
//! - **four-column** (Social-LSTM / sgan / Trajectron++ "Format A"), 4
//!   numbers per row: `frame ped_id x y`.
//!
//! Frames and pedestrian ids are integers that may be written as floats
//! (`7.8000000e+02`). Blank lines are skipped; every other row must have the
//! same number of columns as the first. Rows are returned with their 1-based
//! line numbers so later checks can still point at the file.
//!
//! The simulator replays these files ([`parse_rows`], all or nothing); the
//! extractor reads them as a tracker's reports ([`read`], every bad row
//! counted). One parser serves both.

use super::{check_fps, frame_time, Located, RowError, Rows};
use crate::extractor::Report;
use crate::geometry::Vec2;

/// Which annotation format a file is in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SceneFormat {
    /// 8 columns: `frame ped_id pos_x pos_z pos_y v_x v_z v_y`.
    Obsmat,
    /// 4 columns: `frame ped_id x y`.
    FourColumn,
}

impl SceneFormat {
    pub(crate) fn columns(self) -> usize {
        match self {
            SceneFormat::Obsmat => 8,
            SceneFormat::FourColumn => 4,
        }
    }

    /// What the format is called in messages.
    pub(crate) fn name(self) -> &'static str {
        match self {
            SceneFormat::Obsmat => "obsmat: frame ped_id pos_x pos_z pos_y v_x v_z v_y",
            SceneFormat::FourColumn => "biwi: frame ped_id x y",
        }
    }

    fn other(self) -> SceneFormat {
        match self {
            SceneFormat::Obsmat => SceneFormat::FourColumn,
            SceneFormat::FourColumn => SceneFormat::Obsmat,
        }
    }

    fn column_name(self, c: usize) -> &'static str {
        const OBSMAT: [&str; 8] = [
            "frame", "ped_id", "pos_x", "pos_z", "pos_y", "v_x", "v_z", "v_y",
        ];
        const FOUR: [&str; 4] = ["frame", "ped_id", "x", "y"];
        match self {
            SceneFormat::Obsmat => OBSMAT[c],
            SceneFormat::FourColumn => FOUR[c],
        }
    }
}

/// One annotated row: pedestrian `id` at ground position `pos` in `frame`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Row {
    /// 1-based line number in the file.
    pub line: usize,
    pub frame: u64,
    pub id: u32,
    pub pos: Vec2,
}

/// Parses the text of a scene file, stopping at the first bad row (the
/// simulator's replay wants the whole scene or nothing). `file` only names
/// it in errors.
pub fn parse_rows(text: &str, file: &str) -> Result<(SceneFormat, Vec<Row>), RowError> {
    let mut reader = RowReader::default();
    let mut rows = Vec::new();
    let mut last_line = 0;
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        last_line = line;
        match reader.row(line, raw) {
            Ok(Some(row)) => rows.push(row),
            Ok(None) => {}
            Err(reason) => return Err(RowError::malformed(file, line, reason)),
        }
    }
    match reader.format {
        Some((fmt, _)) => Ok((fmt, rows)),
        None => Err(RowError::malformed(
            file,
            last_line + 1,
            "no trajectory rows in the file",
        )),
    }
}

/// Every row of an annotation file as a report at `fps` frames per
/// second (frame f at time f / fps; ETH's obsmat is at 15 fps, the other
/// scenes at 25), in time order (bad rows first), or an error naming its
/// line — the extractor's reading,
/// which counts bad rows and goes on. The file must be in `expected`
/// format (told apart by the first row's columns).
pub fn read(text: &str, file: &str, fps: f64, expected: SceneFormat) -> Result<Rows, RowError> {
    check_fps(fps).map_err(|reason| RowError::malformed(file, 0, reason))?;
    let mut reader = RowReader::default();
    let mut rows = Vec::new();
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        match reader.row(line, raw) {
            Ok(Some(row)) => {
                if row.line == reader.format.map_or(0, |(_, first)| first) {
                    let found = reader.format.map(|(f, _)| f);
                    if found != Some(expected) {
                        return Err(RowError::malformed(
                            file,
                            line,
                            format!(
                                "expected {} columns ({}), got {}",
                                expected.columns(),
                                expected.name(),
                                expected.other().columns()
                            ),
                        ));
                    }
                }
                rows.push(Ok(Located {
                    line,
                    report: Report::at(
                        frame_time(row.frame as f64, fps),
                        row.id,
                        row.pos.x,
                        row.pos.y,
                    ),
                }));
            }
            Ok(None) => {}
            Err(reason) => rows.push(Err(RowError::malformed(file, line, reason))),
        }
    }
    // Annotation files need not be in time order: the UCY obsmat files
    // list one person after another. Reports go to the extractor by time
    // (stably, so a frame keeps its file order); bad rows first, each
    // still named by its line.
    let key = |row: &Result<Located, RowError>| match row {
        Ok(located) => located.report.time,
        Err(_) => f64::NEG_INFINITY,
    };
    rows.sort_by(|a, b| key(a).total_cmp(&key(b)));
    Ok(rows)
}

/// The format of a file, fixed by its first row, and the rows one by one.
#[derive(Debug, Default)]
struct RowReader {
    /// The format and the line that fixed it.
    format: Option<(SceneFormat, usize)>,
}

impl RowReader {
    /// Row `line` (1-based): `None` for a blank line.
    fn row(&mut self, line: usize, raw: &str) -> Result<Option<Row>, String> {
        let fields: Vec<&str> = raw.split_whitespace().collect();
        if fields.is_empty() {
            return Ok(None);
        }
        let fmt = match self.format {
            Some((fmt, first_line)) => {
                if fields.len() != fmt.columns() {
                    return Err(format!(
                        "expected {} columns like line {first_line}, got {}",
                        fmt.columns(),
                        fields.len()
                    ));
                }
                fmt
            }
            None => {
                let fmt = match fields.len() {
                    8 => SceneFormat::Obsmat,
                    4 => SceneFormat::FourColumn,
                    n => {
                        return Err(format!(
                            "expected 4 columns (frame ped_id x y) or 8 columns \
                             (obsmat: frame ped_id pos_x pos_z pos_y v_x v_z v_y), got {n}"
                        ))
                    }
                };
                self.format = Some((fmt, line));
                fmt
            }
        };
        let mut values = Vec::with_capacity(8);
        for (c, field) in fields.iter().enumerate() {
            match field.parse::<f64>() {
                Ok(v) if v.is_finite() => values.push(v),
                _ => {
                    return Err(format!(
                        "column {} ({}): `{field}` is not a finite number",
                        c + 1,
                        fmt.column_name(c)
                    ))
                }
            }
        }
        let frame = whole(values[0], u64::MAX as f64)
            .ok_or_else(|| format!("frame {} is not a whole number >= 0", fields[0]))?;
        let id = whole(values[1], u32::MAX as f64).ok_or_else(|| {
            format!(
                "pedestrian id {} is not a whole number in 0..2^32",
                fields[1]
            )
        })?;
        let pos = match fmt {
            SceneFormat::Obsmat => Vec2::new(values[2], values[4]),
            SceneFormat::FourColumn => Vec2::new(values[2], values[3]),
        };
        Ok(Some(Row {
            line,
            frame,
            id: id as u32,
            pos,
        }))
    }
}

/// `v` as a whole number in `0..=max`, if it is one.
fn whole(v: f64, max: f64) -> Option<u64> {
    (v >= 0.0 && v <= max && v.fract() == 0.0).then_some(v as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_bad_row_is_an_error_and_the_rest_are_reports() {
        let text = "780 1 8.46 3.59\n790 1 x 3.79\n\n800 1 9.0 3.9 1\n810 2 1.0 1.0\n";
        let rows = read(text, "b.txt", 25.0, SceneFormat::FourColumn).unwrap();
        assert_eq!(rows.len(), 4);
        // Bad rows first, then reports by time.
        assert_eq!(
            rows[0].as_ref().unwrap_err().to_string(),
            "b.txt:2: column 3 (x): `x` is not a finite number"
        );
        assert_eq!(
            rows[1].as_ref().unwrap_err().to_string(),
            "b.txt:4: expected 4 columns like line 1, got 5"
        );
        assert_eq!(
            rows[2].as_ref().unwrap().report,
            Report::at(31.2, 1, 8.46, 3.59)
        );
        assert_eq!(rows[3].as_ref().unwrap().line, 5);
        // A file grouped by person is read in time order.
        let by_person = "800 1 0 0\n810 1 0 0\n790 2 5 5\n";
        let lines: Vec<usize> = read(by_person, "p.txt", 10.0, SceneFormat::FourColumn)
            .unwrap()
            .into_iter()
            .map(|r| r.unwrap().line)
            .collect();
        assert_eq!(lines, [3, 1, 2]);
        assert_eq!(
            read(text, "b.txt", 25.0, SceneFormat::Obsmat)
                .unwrap_err()
                .to_string(),
            "b.txt:1: expected 8 columns (obsmat: frame ped_id pos_x pos_z pos_y v_x v_z v_y), got 4"
        );
    }

    #[test]
    fn reads_both_formats() {
        let obsmat = "   7.8000000e+02   1.0000000e+00   8.4568443e+00   0.0000000e+00   3.5880664e+00   1.6717144e+00   0.0000000e+00   1.7629183e-01\n\n   7.8600000e+02   1.0000000e+00   9.1255301e+00   0.0000000e+00   3.6585832e+00   1.6628772e+00   0.0000000e+00   3.2672255e-01\n";
        let (fmt, rows) = parse_rows(obsmat, "o.txt").unwrap();
        assert_eq!(fmt, SceneFormat::Obsmat);
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].line, 3);
        assert_eq!(rows[1].frame, 786);
        assert_eq!(rows[1].id, 1);
        assert_eq!(rows[1].pos, Vec2::new(9.1255301, 3.6585832));

        let four = "780\t1.0\t8.46\t3.59\n790\t1.0\t9.57\t3.79\n";
        let (fmt, rows) = parse_rows(four, "f.txt").unwrap();
        assert_eq!(fmt, SceneFormat::FourColumn);
        assert_eq!(rows[0].pos, Vec2::new(8.46, 3.59));
    }

    #[test]
    fn malformed_rows_name_file_and_line() {
        let cases = [
            ("1 2 3\n", "x.txt:1: expected 4 columns"),
            (
                "1 2 3 4\n2 2 3\n",
                "x.txt:2: expected 4 columns like line 1, got 3",
            ),
            (
                "1 2 3 4\n\n2 2 abc 4\n",
                "x.txt:3: column 3 (x): `abc` is not a finite number",
            ),
            (
                "1 2 3 4\n2.5 2 3 4\n",
                "x.txt:2: frame 2.5 is not a whole number",
            ),
            ("1 -2 3 4\n", "x.txt:1: pedestrian id -2 is not"),
            ("1 2 3 NaN\n", "x.txt:1: column 4 (y)"),
            ("\n\n", "x.txt:3: no trajectory rows"),
            (
                "1 1 0 0 0 0 0 0\n1 1 0 0 0 0 0 x\n",
                "x.txt:2: column 8 (v_y)",
            ),
        ];
        for (text, want) in cases {
            let err = parse_rows(text, "x.txt").unwrap_err().to_string();
            assert!(
                err.starts_with(want),
                "{err:?} does not start with {want:?}"
            );
        }
    }
}
