//! MOTChallenge result files: one box per row,
//! `frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z` (comma
//! separated; the last three may be absent or −1). A track stands where
//! its box touches the ground: the bottom centre (bb_left + bb_width / 2,
//! bb_top + bb_height), in pixels, taken to the ground by
//!
//! - a scale (metres per pixel; the image's axes, y growing downwards), or
//! - a [`Homography`] in the ETH/UCY `H.txt` format.
//!
//! Frame f is at time f / fps. `conf` is read but not used: a result file
//! holds the tracker's kept boxes, and a box is a report whatever its
//! confidence.

use super::homography::Homography;
use super::{check_fps, frame_time, Located, RowError, Rows};
use crate::extractor::Report;

/// From pixels to the ground.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Ground {
    /// Metres per pixel.
    Scale(f64),
    Homography(Homography),
}

impl Ground {
    /// The ground point of pixel (u, v).
    pub fn apply(&self, u: f64, v: f64) -> Option<(f64, f64)> {
        match self {
            Ground::Scale(s) => Some((u * s, v * s)),
            Ground::Homography(h) => h.apply(u, v),
        }
    }
}

const COLUMNS: [&str; 10] = [
    "frame",
    "id",
    "bb_left",
    "bb_top",
    "bb_width",
    "bb_height",
    "conf",
    "x",
    "y",
    "z",
];

/// Reads every row of a result file at `fps` frames per second. Blank
/// lines are skipped; every other row is a report or an error.
pub fn read(text: &str, file: &str, fps: f64, ground: Ground) -> Result<Rows, RowError> {
    check_fps(fps).map_err(|reason| RowError::malformed(file, 0, reason))?;
    if let Ground::Scale(s) = ground {
        if !(s.is_finite() && s > 0.0) {
            return Err(RowError::malformed(
                file,
                0,
                format!("scale must be finite and > 0, got {s}"),
            ));
        }
    }
    Ok(text
        .lines()
        .enumerate()
        .filter(|(_, raw)| !raw.trim().is_empty())
        .map(|(index, raw)| {
            let line = index + 1;
            row(raw, fps, ground)
                .map(|report| Located { line, report })
                .map_err(|reason| RowError::malformed(file, line, reason))
        })
        .collect())
}

/// One row as a report, or why not. Non-finite coordinates are passed
/// on: the extractor refuses them with its own named error.
fn row(raw: &str, fps: f64, ground: Ground) -> Result<Report, String> {
    let fields: Vec<&str> = raw.split(',').map(str::trim).collect();
    if !(6..=10).contains(&fields.len()) {
        return Err(format!(
            "expected 6 to 10 comma-separated columns (frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z), got {}",
            fields.len()
        ));
    }
    let mut values = [0.0; 6];
    for (c, value) in values.iter_mut().enumerate() {
        *value = fields[c].parse::<f64>().map_err(|_| {
            format!(
                "column {} ({}): `{}` is not a number",
                c + 1,
                COLUMNS[c],
                fields[c]
            )
        })?;
    }
    let [frame, id, left, top, width, height] = values;
    if !(frame >= 0.0 && frame.fract() == 0.0) {
        return Err(format!("frame {} is not a whole number >= 0", fields[0]));
    }
    if !(id >= 0.0 && id <= u32::MAX as f64 && id.fract() == 0.0) {
        return Err(format!("id {} is not a whole number in 0..2^32", fields[1]));
    }
    let (u, v) = (left + width / 2.0, top + height);
    let (x, y) = ground
        .apply(u, v)
        .ok_or_else(|| format!("pixel ({u}, {v}) is on the homography's horizon"))?;
    Ok(Report::at(frame_time(frame, fps), id as u32, x, y))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_stand_on_their_bottom_centre() {
        let text = "1,7,100,50,20,80,0.9,-1,-1,-1\n\n2,7,110,50,20,80,0.8\n";
        let rows = read(text, "mot.txt", 10.0, Ground::Scale(0.01)).unwrap();
        let r: Vec<Located> = rows.into_iter().map(Result::unwrap).collect();
        assert_eq!(r[0].line, 1);
        assert_eq!(r[0].report, Report::at(0.1, 7, 1.1, 1.3));
        assert_eq!(r[1].line, 3);
        assert!((r[1].report.x - 1.2).abs() < 1e-12);
        let h = Homography([[2.0, 0.0, 1.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]);
        let rows = read("1,7,100,50,20,80,1\n", "m", 25.0, Ground::Homography(h)).unwrap();
        let report = &rows[0].as_ref().unwrap().report;
        assert_eq!((report.x, report.y), (221.0, 260.0));
    }

    #[test]
    fn bad_rows_name_their_line() {
        let text = "1,7,100,50,20\n1,x,100,50,20,80\n1.5,7,100,50,20,80\n1,7,nan,50,20,80\n";
        let rows = read(text, "mot.txt", 10.0, Ground::Scale(1.0)).unwrap();
        let errors: Vec<String> = rows
            .iter()
            .filter_map(|r| r.as_ref().err().map(ToString::to_string))
            .collect();
        assert_eq!(
            errors,
            [
                "mot.txt:1: expected 6 to 10 comma-separated columns (frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z), got 5",
                "mot.txt:2: column 2 (id): `x` is not a number",
                "mot.txt:3: frame 1.5 is not a whole number >= 0",
            ]
        );
        // A NaN coordinate reads; the extractor refuses it by name.
        assert!(rows[3].as_ref().unwrap().report.x.is_nan());
        assert!(read("", "m", 0.0, Ground::Scale(1.0)).is_err());
        assert!(read("", "m", 10.0, Ground::Scale(-1.0)).is_err());
    }
}
