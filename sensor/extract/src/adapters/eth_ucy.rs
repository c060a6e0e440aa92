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

use super::error::SceneError;
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
    pub fn columns(self) -> usize {
        match self {
            SceneFormat::Obsmat => 8,
            SceneFormat::FourColumn => 4,
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

/// Parses the text of a scene file. `file` only names it in errors.
pub fn parse_rows(text: &str, file: &str) -> Result<(SceneFormat, Vec<Row>), SceneError> {
    let bad = |line: usize, reason: String| SceneError::Malformed {
        file: file.to_string(),
        line,
        reason,
    };
    let mut format: Option<(SceneFormat, usize)> = None;
    let mut rows = Vec::new();
    let mut values = Vec::with_capacity(8);
    let mut last_line = 0;
    for (index, raw) in text.lines().enumerate() {
        let line = index + 1;
        last_line = line;
        let fields: Vec<&str> = raw.split_whitespace().collect();
        if fields.is_empty() {
            continue;
        }
        let fmt = match format {
            Some((fmt, first_line)) => {
                if fields.len() != fmt.columns() {
                    return Err(bad(
                        line,
                        format!(
                            "expected {} columns like line {first_line}, got {}",
                            fmt.columns(),
                            fields.len()
                        ),
                    ));
                }
                fmt
            }
            None => {
                let fmt = match fields.len() {
                    8 => SceneFormat::Obsmat,
                    4 => SceneFormat::FourColumn,
                    n => {
                        return Err(bad(
                            line,
                            format!(
                                "expected 4 columns (frame ped_id x y) or 8 columns \
                                 (obsmat: frame ped_id pos_x pos_z pos_y v_x v_z v_y), got {n}"
                            ),
                        ))
                    }
                };
                format = Some((fmt, line));
                fmt
            }
        };
        values.clear();
        for (c, field) in fields.iter().enumerate() {
            match field.parse::<f64>() {
                Ok(v) if v.is_finite() => values.push(v),
                _ => {
                    return Err(bad(
                        line,
                        format!(
                            "column {} ({}): `{field}` is not a finite number",
                            c + 1,
                            fmt.column_name(c)
                        ),
                    ))
                }
            }
        }
        let frame = whole(values[0], u64::MAX as f64).ok_or_else(|| {
            bad(
                line,
                format!("frame {} is not a whole number >= 0", fields[0]),
            )
        })?;
        let id = whole(values[1], u32::MAX as f64).ok_or_else(|| {
            bad(
                line,
                format!(
                    "pedestrian id {} is not a whole number in 0..2^32",
                    fields[1]
                ),
            )
        })?;
        let pos = match fmt {
            SceneFormat::Obsmat => Vec2::new(values[2], values[4]),
            SceneFormat::FourColumn => Vec2::new(values[2], values[3]),
        };
        rows.push(Row {
            line,
            frame,
            id: id as u32,
            pos,
        });
    }
    match format {
        Some((fmt, _)) => Ok((fmt, rows)),
        None => Err(bad(last_line + 1, "no trajectory rows in the file".into())),
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
