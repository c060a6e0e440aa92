//! A loaded scene: every annotated person as a time-stamped trajectory, in
//! seconds from the scene's first annotated frame.
//!
//! Timing (the README of `shared/data/pedestrians`): annotations are at
//! 2.5 Hz, one annotation step = 0.4 s. The frame step between two
//! annotations of a person (6 for eth's obsmat at 15 fps, 10 elsewhere) is
//! read from the data, so seconds per frame = 0.4 s / frame step — with one
//! exception the README documents: the four-column `biwi_eth.txt` was
//! re-sampled, and one of its steps is 10/6 × 0.4 s ≈ 0.667 s.
//! [`Timing::SecondsPerFrame`] overrides all of this.
//!
//! A person is present from their first to their last annotation. A gap in
//! a person's annotations longer than 1.5 annotation steps (none occurs in
//! the shipped files) is treated as an absence; between annotations closer
//! than that, the position is interpolated linearly.

use super::error::SceneError;
use super::format::{parse_rows, SceneFormat};
use crate::geometry::Vec2;
use std::collections::BTreeMap;
use std::path::Path;

/// How frame numbers turn into seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Timing {
    /// From the README: 0.4 s per annotation step (0.667 s for the
    /// four-column `biwi_eth.txt`), frame step read from the data.
    Auto,
    /// Exactly this many seconds per frame number.
    SecondsPerFrame(f64),
}

/// One annotated position of a person.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Sample {
    /// Seconds from the scene's first annotated frame.
    pub time: f64,
    pub pos: Vec2,
}

/// One person's trajectory, samples in time order.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Person {
    /// The pedestrian id in the file.
    pub id: u32,
    pub samples: Vec<Sample>,
}

impl Person {
    pub(crate) fn first_time(&self) -> f64 {
        self.samples[0].time
    }

    pub(crate) fn last_time(&self) -> f64 {
        self.samples[self.samples.len() - 1].time
    }
}

/// A whole annotated scene.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The file it was read from (for messages and trace headers).
    pub source: String,
    pub format: SceneFormat,
    /// Seconds per frame number.
    pub seconds_per_frame: f64,
    /// Seconds between two annotations of a person.
    pub annotation_step: f64,
    /// Everyone in the scene, ordered by first appearance, then id.
    pub(crate) people: Vec<Person>,
}

/// Two annotations of a person further apart than this many annotation
/// steps leave the person absent in between.
const GAP_STEPS: f64 = 1.5;

/// Tolerance on times, seconds (sample times are products of floats).
pub(super) const TIME_EPS: f64 = 1e-9;

impl Scene {
    /// Reads and checks a scene file.
    pub fn load(path: impl AsRef<Path>, timing: Timing) -> Result<Scene, SceneError> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).map_err(|source| SceneError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Scene::parse(&text, &path.display().to_string(), timing)
    }

    /// Parses the text of a scene file; `file` names it in errors (and is
    /// used to recognise `biwi_eth.txt` under [`Timing::Auto`]).
    pub(crate) fn parse(text: &str, file: &str, timing: Timing) -> Result<Scene, SceneError> {
        let (format, rows) = parse_rows(text, file)?;
        // Per person, frame -> row; a second row for the same frame is an error.
        let mut by_person: BTreeMap<u32, BTreeMap<u64, (usize, Vec2)>> = BTreeMap::new();
        for row in &rows {
            let frames = by_person.entry(row.id).or_default();
            if let Some(&(first_line, _)) = frames.get(&row.frame) {
                return Err(SceneError::Malformed {
                    file: file.to_string(),
                    line: row.line,
                    reason: format!(
                        "pedestrian {} appears twice in frame {} (first at line {first_line})",
                        row.id, row.frame
                    ),
                });
            }
            frames.insert(row.frame, (row.line, row.pos));
        }
        let first_frame = rows.iter().map(|r| r.frame).min().unwrap_or(0);
        let frame_step = detect_frame_step(&by_person, &rows);
        let seconds_per_frame = match timing {
            Timing::SecondsPerFrame(s) => {
                if !(s.is_finite() && s > 0.0) {
                    return Err(SceneError::Window {
                        file: file.to_string(),
                        reason: format!("seconds per frame must be finite and > 0, got {s}"),
                    });
                }
                s
            }
            Timing::Auto => {
                let step_seconds = if format == SceneFormat::FourColumn && is_biwi_eth(file) {
                    0.4 * 10.0 / 6.0
                } else {
                    0.4
                };
                step_seconds / frame_step as f64
            }
        };
        let mut people: Vec<Person> = by_person
            .into_iter()
            .map(|(id, frames)| Person {
                id,
                samples: frames
                    .into_iter()
                    .map(|(frame, (_, pos))| Sample {
                        time: (frame - first_frame) as f64 * seconds_per_frame,
                        pos,
                    })
                    .collect(),
            })
            .collect();
        people.sort_by(|a, b| {
            a.first_time()
                .total_cmp(&b.first_time())
                .then(a.id.cmp(&b.id))
        });
        Ok(Scene {
            source: file.to_string(),
            format,
            seconds_per_frame,
            annotation_step: frame_step as f64 * seconds_per_frame,
            people,
        })
    }

    /// Time of the last annotation, seconds from the first.
    pub fn duration(&self) -> f64 {
        self.people
            .iter()
            .map(Person::last_time)
            .fold(0.0, f64::max)
    }

    /// Number of rows (annotated positions).
    #[cfg(test)]
    pub(crate) fn rows(&self) -> usize {
        self.people.iter().map(|p| p.samples.len()).sum()
    }

    /// Where `person` is at `time`, or `None` if absent then. Linear
    /// interpolation between annotations; `hint` is a cursor into the
    /// person's samples that only moves forward, making a replay in time
    /// order O(1) per call (pass 0 for a one-off look-up).
    pub(crate) fn position_at(&self, person: usize, time: f64, hint: &mut usize) -> Option<Vec2> {
        let s = &self.people[person].samples;
        if time < s[0].time - TIME_EPS || time > s[s.len() - 1].time + TIME_EPS {
            return None;
        }
        if *hint >= s.len() || s[*hint].time > time + TIME_EPS {
            *hint = 0;
        }
        while *hint + 1 < s.len() && s[*hint + 1].time <= time + TIME_EPS {
            *hint += 1;
        }
        let a = s[*hint];
        if (time - a.time).abs() <= TIME_EPS || *hint + 1 == s.len() {
            return Some(a.pos);
        }
        let b = s[*hint + 1];
        if b.time - a.time > GAP_STEPS * self.annotation_step + TIME_EPS {
            return None;
        }
        Some(a.pos.lerp(b.pos, (time - a.time) / (b.time - a.time)))
    }
}

/// The smallest frame difference between two consecutive annotations of
/// one person (falls back to the smallest difference between distinct
/// frames of the file, then to 1).
fn detect_frame_step(
    by_person: &BTreeMap<u32, BTreeMap<u64, (usize, Vec2)>>,
    rows: &[super::format::Row],
) -> u64 {
    let per_person = by_person
        .values()
        .flat_map(|frames| {
            let keys: Vec<u64> = frames.keys().copied().collect();
            keys.windows(2).map(|w| w[1] - w[0]).collect::<Vec<_>>()
        })
        .min();
    per_person
        .or_else(|| {
            let mut frames: Vec<u64> = rows.iter().map(|r| r.frame).collect();
            frames.sort_unstable();
            frames.dedup();
            frames.windows(2).map(|w| w[1] - w[0]).min()
        })
        .unwrap_or(1)
        .max(1)
}

fn is_biwi_eth(file: &str) -> bool {
    Path::new(file)
        .file_name()
        .is_some_and(|n| n.eq_ignore_ascii_case("biwi_eth.txt"))
}

#[cfg(test)]
mod tests {
    use super::*;

    const TINY: &str = "\
10 1 0.0 0.0
10 2 5.0 5.0
20 1 1.0 0.0
20 2 5.0 6.0
30 1 2.0 0.0
50 1 4.0 0.0
60 3 9.0 9.0
";

    #[test]
    fn timing_presence_and_interpolation() {
        let scene = Scene::parse(TINY, "tiny.txt", Timing::Auto).unwrap();
        assert_eq!(scene.format, SceneFormat::FourColumn);
        assert!((scene.seconds_per_frame - 0.04).abs() < 1e-12);
        assert!((scene.annotation_step - 0.4).abs() < 1e-12);
        assert_eq!(scene.people.len(), 3);
        assert_eq!(scene.rows(), 7);
        assert!((scene.duration() - 2.0).abs() < 1e-12);
        let ids: Vec<u32> = scene.people.iter().map(|p| p.id).collect();
        assert_eq!(ids, [1, 2, 3]);
        let mut h = 0;
        let p1 = |t: f64, h: &mut usize| scene.position_at(0, t, h);
        assert_eq!(p1(0.0, &mut h), Some(Vec2::new(0.0, 0.0)));
        let mid = p1(0.2, &mut h).unwrap();
        assert!((mid.x - 0.5).abs() < 1e-12);
        assert_eq!(p1(0.8, &mut h), Some(Vec2::new(2.0, 0.0)));
        // Frames 30 -> 50 is a gap of two annotation steps: absent between.
        assert_eq!(p1(1.0, &mut h), None);
        assert_eq!(p1(1.6, &mut h), Some(Vec2::new(4.0, 0.0)));
        assert_eq!(p1(1.7, &mut h), None);
        // Going back in time resets the cursor.
        assert_eq!(p1(0.4, &mut h), Some(Vec2::new(1.0, 0.0)));
        assert_eq!(scene.position_at(1, 0.5, &mut 0), None);
    }

    #[test]
    fn biwi_eth_uses_its_resampled_step() {
        let four = "780\t1.0\t8.46\t3.59\n790\t1.0\t9.57\t3.79\n";
        let scene = Scene::parse(four, "data/eth/biwi_eth.txt", Timing::Auto).unwrap();
        assert!((scene.annotation_step - 0.4 * 10.0 / 6.0).abs() < 1e-12);
        let other = Scene::parse(four, "data/hotel/biwi_hotel.txt", Timing::Auto).unwrap();
        assert!((other.annotation_step - 0.4).abs() < 1e-12);
        let fixed = Scene::parse(four, "x", Timing::SecondsPerFrame(0.1)).unwrap();
        assert!((fixed.annotation_step - 1.0).abs() < 1e-12);
    }

    #[test]
    fn duplicate_rows_are_rejected_with_their_line() {
        let text = "10 1 0 0\n20 1 1 0\n10 1 0 0\n";
        let err = Scene::parse(text, "dup.txt", Timing::Auto).unwrap_err();
        assert_eq!(
            err.to_string(),
            "dup.txt:3: pedestrian 1 appears twice in frame 10 (first at line 1)"
        );
    }
}
