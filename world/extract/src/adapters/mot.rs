//! MOTChallenge result files: one box per row,
//! `frame,id,bb_left,bb_top,bb_width,bb_height,conf,x,y,z` (comma
//! separated; the last three may be absent or −1), or MOT16/17/20's
//! `frame,id,bb_left,bb_top,bb_width,bb_height,conf,class,visibility`
//! (nine columns, as annotations and some trackers write them). A track
//! stands where its box touches the ground: the bottom centre
//! (bb_left + bb_width / 2, bb_top + bb_height), in pixels, taken to the
//! ground by
//!
//! - a scale (metres per pixel; the image's axes, y growing downwards), or
//! - a [`Homography`] in the ETH/UCY `H.txt` format.
//!
//! Frame f is at time f / fps. `conf` is read but not used: a result file
//! holds the tracker's kept boxes, and a box is a report whatever its
//! confidence.
//!
//! **What a box says about its target.** Positions alone make mixes, not
//! observations. Class scores and identity reads come
//!
//! - from a second file beside the MOT file ([`Reads`]): JSON lines keyed
//!   by frame and track id,
//!   `{"frame":12,"id":3,"scores":{"red":0.8,"blue":0.2}}` and/or
//!   `"identity":2,"accuracy":0.9`, in frame order like the boxes; or
//! - from a nine-column row's `class` and `visibility`: a class mapped to
//!   a label ([`MotOptions::classes`]) is a classification as sure as the
//!   box is visible — the class's label scores (1 + visibility) / 2, the
//!   rest goes to the property's label (or `other` when the class is the
//!   property's); a hidden box says nothing either way.
//!
//! **Streaming.** Rows are read in frame order, as trackers write them,
//! with a bounded window for rows a little out of order
//! ([`MotOptions::window`] frames): a frame goes out once a row more than
//! `window` frames later has been read, and a row of a frame that went out
//! already is a bad row naming its line. The reader holds at most the
//! rows of `window + 1` frames ([`MotReader::most_held`]), whatever the
//! file's length.

use super::homography::Homography;
use super::{check_fps, frame_time, Located, RowError};
use crate::extractor::{IdentityRead, Report};
use idmesh_protocol::trace::check_scores;
use std::collections::btree_map::Entry;
use std::collections::{BTreeMap, BTreeSet, VecDeque};
use std::io::BufRead;

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

/// How a MOT file is read.
#[derive(Debug, Clone, PartialEq)]
pub struct MotOptions {
    /// Frames per second: frame f is at f / fps seconds.
    pub fps: f64,
    pub ground: Ground,
    /// How many frames a row may come behind the latest frame read.
    pub window: u64,
    /// Nine-column rows: MOTChallenge class ids to class labels (a class
    /// not listed gives no scores).
    pub classes: BTreeMap<u32, String>,
    /// The property's label (`--label`): where a class's remaining score
    /// goes.
    pub label: String,
}

/// The default reorder window, in frames: a tracker that writes a frame's
/// boxes as its tracks finish them is a frame or two behind at most.
pub const DEFAULT_WINDOW: u64 = 5;

impl MotOptions {
    /// Options at `fps` with `ground`, the rest at their defaults.
    pub fn new(fps: f64, ground: Ground) -> Self {
        MotOptions {
            fps,
            ground,
            window: DEFAULT_WINDOW,
            classes: BTreeMap::new(),
            label: "red".into(),
        }
    }

    /// Checks the frame rate and the scale, before any row is read.
    pub(crate) fn check(&self, file: &str) -> Result<(), RowError> {
        check_fps(self.fps).map_err(|reason| RowError::malformed(file, 0, reason))?;
        if let Ground::Scale(s) = self.ground {
            if !(s.is_finite() && s > 0.0) {
                return Err(RowError::malformed(
                    file,
                    0,
                    format!("scale must be finite and > 0, got {s}"),
                ));
            }
        }
        Ok(())
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

/// One row as its frame and report, or why not. Non-finite coordinates
/// are passed on: the extractor refuses them with its own named error.
fn row(raw: &str, options: &MotOptions) -> Result<(u64, Report), String> {
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
    if !(frame >= 0.0 && frame.fract() == 0.0 && frame < 2f64.powi(53)) {
        return Err(format!("frame {} is not a whole number >= 0", fields[0]));
    }
    if !(id >= 0.0 && id <= u32::MAX as f64 && id.fract() == 0.0) {
        return Err(format!("id {} is not a whole number in 0..2^32", fields[1]));
    }
    let (u, v) = (left + width / 2.0, top + height);
    let (x, y) = options
        .ground
        .apply(u, v)
        .ok_or_else(|| format!("pixel ({u}, {v}) is on the homography's horizon"))?;
    let mut report = Report::at(frame_time(frame, options.fps), id as u32, x, y);
    if fields.len() == 9 {
        report.scores = class_scores(fields[7], fields[8], options)?;
    }
    Ok((frame as u64, report))
}

/// A nine-column row's class and visibility as class scores (see the
/// module docs); `None` for a class no label is given for.
fn class_scores(
    class: &str,
    visibility: &str,
    options: &MotOptions,
) -> Result<Option<BTreeMap<String, f64>>, String> {
    if options.classes.is_empty() {
        return Ok(None);
    }
    let id = class
        .parse::<f64>()
        .ok()
        .filter(|c| *c >= 0.0 && *c <= u32::MAX as f64 && c.fract() == 0.0)
        .ok_or_else(|| format!("column 8 (class): `{class}` is not a class id"))?;
    let Some(label) = options.classes.get(&(id as u32)) else {
        return Ok(None);
    };
    let seen: f64 = visibility
        .parse()
        .map_err(|_| format!("column 9 (visibility): `{visibility}` is not a number"))?;
    // −1: not given, the box taken as fully visible.
    let seen = if seen == -1.0 { 1.0 } else { seen };
    if !(0.0..=1.0).contains(&seen) {
        return Err(format!(
            "column 9 (visibility): {visibility} is not in [0, 1] (or -1)"
        ));
    }
    let rest = if *label == options.label {
        "other"
    } else {
        options.label.as_str()
    };
    Ok(Some(BTreeMap::from([
        (label.clone(), (1.0 + seen) / 2.0),
        (rest.to_string(), (1.0 - seen) / 2.0),
    ])))
}

/// Rows keyed by frame, let out in frame order once no row to come may
/// join them: a frame more than `window` frames behind the latest frame
/// read is complete. Holds the rows of at most `window + 1` frames (and a
/// frame's rows), whatever came before.
#[derive(Debug)]
pub(crate) struct FrameWindow<T> {
    window: u64,
    held: BTreeMap<u64, Vec<T>>,
    /// The latest frame read.
    latest: Option<u64>,
    /// The last frame let out.
    out: Option<u64>,
    rows: usize,
    most: usize,
}

impl<T> FrameWindow<T> {
    pub(crate) fn new(window: u64) -> Self {
        FrameWindow {
            window,
            held: BTreeMap::new(),
            latest: None,
            out: None,
            rows: 0,
            most: 0,
        }
    }

    /// Holds a row of `frame`, or says why it comes too late.
    pub(crate) fn push(&mut self, frame: u64, item: T) -> Result<(), String> {
        if let (Some(out), Some(latest)) = (self.out, self.latest) {
            if frame <= out {
                return Err(format!(
                    "frame {frame} comes after frame {latest}: rows must be in frame order, \
                     at most {} frames behind (--reorder-window), and frame {out} went out already",
                    self.window
                ));
            }
        }
        self.latest = Some(self.latest.map_or(frame, |l| l.max(frame)));
        self.held.entry(frame).or_default().push(item);
        self.rows += 1;
        self.most = self.most.max(self.rows);
        Ok(())
    }

    /// The earliest held frame that is complete (more than `window` frames
    /// behind the latest), let out.
    pub(crate) fn complete(&mut self) -> Option<(u64, Vec<T>)> {
        let latest = self.latest?;
        let (&frame, _) = self.held.first_key_value()?;
        if frame.saturating_add(self.window) < latest {
            self.let_out()
        } else {
            None
        }
    }

    /// The earliest held frame if it is no later than `frame`, let out.
    pub(crate) fn through(&mut self, frame: u64) -> Option<(u64, Vec<T>)> {
        let (&first, _) = self.held.first_key_value()?;
        if first <= frame {
            self.let_out()
        } else {
            None
        }
    }

    /// The latest frame read.
    pub(crate) fn latest(&self) -> Option<u64> {
        self.latest
    }

    /// The most rows held at once.
    #[cfg(test)]
    pub(crate) fn most_held(&self) -> usize {
        self.most
    }

    fn let_out(&mut self) -> Option<(u64, Vec<T>)> {
        let (frame, rows) = self.held.pop_first()?;
        self.rows -= rows.len();
        self.out = Some(frame);
        Some((frame, rows))
    }
}

/// One line of a reads file.
#[derive(Debug, Clone, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct ReadRow {
    frame: u64,
    id: u32,
    #[serde(default)]
    scores: Option<BTreeMap<String, f64>>,
    #[serde(default)]
    identity: Option<u32>,
    #[serde(default)]
    accuracy: Option<f64>,
}

/// What a classifier or an identity reader said about the boxes of a MOT
/// file, from a file of its own (JSON lines, in frame order give or take
/// the window): class scores and identity reads keyed by (frame, track
/// id). Read frame by frame beside the boxes, never whole.
pub struct Reads {
    input: Box<dyn BufRead>,
    file: String,
    number: usize,
    text: String,
    done: bool,
    window: FrameWindow<(usize, ReadRow)>,
}

impl Reads {
    /// The reads in `input` (named `file` in errors), with the boxes'
    /// reorder window.
    pub fn new(input: Box<dyn BufRead>, file: &str, window: u64) -> Self {
        Reads {
            input,
            file: file.to_string(),
            number: 0,
            text: String::new(),
            done: false,
            window: FrameWindow::new(window),
        }
    }

    /// The reads of `frame` by track id: every read of a frame up to
    /// `frame` is out of the file by then. A bad line, a read of a frame
    /// before `frame` (which had no box) and a second read of one box go
    /// to `errors`.
    fn frame(
        &mut self,
        frame: u64,
        errors: &mut VecDeque<RowError>,
    ) -> BTreeMap<u32, (usize, ReadRow)> {
        let horizon = frame.saturating_add(self.window.window);
        while !self.done && self.window.latest().is_none_or(|l| l <= horizon) {
            self.read_line(errors);
        }
        let mut reads = BTreeMap::new();
        while let Some((at, rows)) = self.window.through(frame) {
            for (line, read) in rows {
                if at < frame {
                    errors.push_back(self.no_box(line, &read));
                    continue;
                }
                match reads.entry(read.id) {
                    Entry::Occupied(_) => errors.push_back(RowError::malformed(
                        &self.file,
                        line,
                        format!("a second read of track {} in frame {at}", read.id),
                    )),
                    Entry::Vacant(slot) => {
                        slot.insert((line, read));
                    }
                }
            }
        }
        reads
    }

    /// The reads left once the boxes are over: each of a frame with no
    /// box.
    fn rest(&mut self, errors: &mut VecDeque<RowError>) {
        while !self.done {
            self.read_line(errors);
        }
        while let Some((_, rows)) = self.window.through(u64::MAX) {
            for (line, read) in rows {
                errors.push_back(self.no_box(line, &read));
            }
        }
    }

    fn no_box(&self, line: usize, read: &ReadRow) -> RowError {
        RowError::malformed(
            &self.file,
            line,
            format!(
                "a read of track {} in frame {}, which has no box of it",
                read.id, read.frame
            ),
        )
    }

    fn read_line(&mut self, errors: &mut VecDeque<RowError>) {
        self.text.clear();
        match self.input.read_line(&mut self.text) {
            Ok(0) => self.done = true,
            Ok(_) => {
                self.number += 1;
                let text = self.text.trim();
                if text.is_empty() {
                    return;
                }
                let read = serde_json::from_str::<ReadRow>(text)
                    .map_err(|e| format!("not a read: {e}"))
                    .and_then(|read| check_read(&read).map(|()| read))
                    .and_then(|read| self.window.push(read.frame, (self.number, read)));
                if let Err(reason) = read {
                    errors.push_back(RowError::malformed(&self.file, self.number, reason));
                }
            }
            Err(e) => {
                self.done = true;
                errors.push_back(RowError::malformed(
                    &self.file,
                    self.number + 1,
                    format!("cannot read: {e}"),
                ));
            }
        }
    }
}

/// A read says something, and says it in range.
fn check_read(read: &ReadRow) -> Result<(), String> {
    if read.scores.is_none() && read.identity.is_none() {
        return Err("a read needs scores, or identity and accuracy".into());
    }
    if let Some(scores) = &read.scores {
        check_scores(scores).map_err(|p| p.to_string())?;
    }
    match (read.identity, read.accuracy) {
        (None, None) => Ok(()),
        (Some(_), Some(a)) if a > 0.0 && a <= 1.0 => Ok(()),
        (Some(_), Some(a)) => Err(format!("accuracy = {a} is not in (0, 1]")),
        _ => Err("an identity read needs both identity and accuracy".into()),
    }
}

/// The boxes of a MOT file as reports, in frame order, streamed (see the
/// module docs), with the reads of a [`Reads`] file joined to them.
pub struct MotReader {
    input: Box<dyn BufRead>,
    file: String,
    options: MotOptions,
    number: usize,
    text: String,
    window: FrameWindow<Located>,
    reads: Option<Reads>,
    ready: VecDeque<Result<Located, RowError>>,
    done: bool,
}

impl MotReader {
    /// Reads `input` (named `file` in errors) with `options`, joining
    /// `reads` when given.
    pub fn new(
        input: Box<dyn BufRead>,
        file: &str,
        options: MotOptions,
        reads: Option<Reads>,
    ) -> Result<Self, RowError> {
        options.check(file)?;
        Ok(MotReader {
            input,
            file: file.to_string(),
            window: FrameWindow::new(options.window),
            options,
            number: 0,
            text: String::new(),
            reads,
            ready: VecDeque::new(),
            done: false,
        })
    }

    /// The most box rows held at once.
    #[cfg(test)]
    pub(crate) fn most_held(&self) -> usize {
        self.window.most_held()
    }

    /// Reads one more line (or, at the end, lets every frame out).
    fn advance(&mut self) {
        self.text.clear();
        match self.input.read_line(&mut self.text) {
            Ok(0) => {
                while let Some((frame, rows)) = self.window.through(u64::MAX) {
                    self.let_out(frame, rows);
                }
                if let Some(reads) = &mut self.reads {
                    let mut errors = VecDeque::new();
                    reads.rest(&mut errors);
                    self.ready.extend(errors.into_iter().map(Err));
                }
                self.done = true;
            }
            Ok(_) => {
                self.number += 1;
                let line = self.number;
                if self.text.trim().is_empty() {
                    return;
                }
                let pushed = row(&self.text, &self.options)
                    .and_then(|(frame, report)| self.window.push(frame, Located { line, report }));
                if let Err(reason) = pushed {
                    self.ready
                        .push_back(Err(RowError::malformed(&self.file, line, reason)));
                }
                while let Some((frame, rows)) = self.window.complete() {
                    self.let_out(frame, rows);
                }
            }
            Err(e) => {
                self.done = true;
                self.ready.push_back(Err(RowError::malformed(
                    &self.file,
                    self.number + 1,
                    format!("cannot read: {e}"),
                )));
            }
        }
    }

    /// A complete frame's rows, with their reads, ready to go.
    fn let_out(&mut self, frame: u64, mut rows: Vec<Located>) {
        if let Some(reads) = &mut self.reads {
            let mut errors = VecDeque::new();
            let mut found = reads.frame(frame, &mut errors);
            for row in &mut rows {
                if let Some((_, read)) = found.remove(&row.report.track) {
                    if read.scores.is_some() {
                        row.report.scores = read.scores;
                    }
                    row.report.identity = read
                        .identity
                        .zip(read.accuracy)
                        .map(|(identity, accuracy)| IdentityRead { identity, accuracy });
                }
            }
            errors.extend(found.values().map(|(line, read)| reads.no_box(*line, read)));
            self.ready.extend(errors.into_iter().map(Err));
        }
        self.ready.extend(rows.into_iter().map(Ok));
    }
}

impl Iterator for MotReader {
    type Item = Result<Located, RowError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(item) = self.ready.pop_front() {
                return Some(item);
            }
            if self.done {
                return None;
            }
            self.advance();
        }
    }
}

/// Every track id of the good rows of a MOT file, read through once (the
/// roster `--roster all` declares), holding the ids alone.
pub fn ids(input: impl BufRead, options: &MotOptions) -> std::io::Result<Vec<u32>> {
    let mut ids = BTreeSet::new();
    for text in input.lines() {
        let text = text?;
        if let Ok((_, report)) = row(&text, options) {
            ids.insert(report.track);
        }
    }
    Ok(ids.into_iter().collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn read_all(
        text: &str,
        options: MotOptions,
        reads: Option<&str>,
    ) -> Vec<Result<Located, RowError>> {
        let reads = reads.map(|r| {
            Reads::new(
                Box::new(std::io::Cursor::new(r.to_string())),
                "reads.jsonl",
                options.window,
            )
        });
        MotReader::new(
            Box::new(std::io::Cursor::new(text.to_string())),
            "mot.txt",
            options,
            reads,
        )
        .unwrap()
        .collect()
    }

    #[test]
    fn boxes_stand_on_their_bottom_centre() {
        let text = "1,7,100,50,20,80,0.9,-1,-1,-1\n\n2,7,110,50,20,80,0.8\n";
        let rows = read_all(text, MotOptions::new(10.0, Ground::Scale(0.01)), None);
        let r: Vec<Located> = rows.into_iter().map(Result::unwrap).collect();
        assert_eq!(r[0].line, 1);
        assert_eq!(r[0].report, Report::at(0.1, 7, 1.1, 1.3));
        assert_eq!(r[1].line, 3);
        assert!((r[1].report.x - 1.2).abs() < 1e-12);
        let h = Homography([[2.0, 0.0, 1.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]]);
        let rows = read_all(
            "1,7,100,50,20,80,1\n",
            MotOptions::new(25.0, Ground::Homography(h)),
            None,
        );
        let report = &rows[0].as_ref().unwrap().report;
        assert_eq!((report.x, report.y), (221.0, 260.0));
    }

    #[test]
    fn bad_rows_name_their_line() {
        let text = "1,7,100,50,20\n1,x,100,50,20,80\n1.5,7,100,50,20,80\n1,7,nan,50,20,80\n";
        let rows = read_all(text, MotOptions::new(10.0, Ground::Scale(1.0)), None);
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
        let empty = || Box::new(std::io::Cursor::new(Vec::new()));
        assert!(
            MotReader::new(empty(), "m", MotOptions::new(0.0, Ground::Scale(1.0)), None).is_err()
        );
        assert!(MotReader::new(
            empty(),
            "m",
            MotOptions::new(10.0, Ground::Scale(-1.0)),
            None
        )
        .is_err());
    }

    /// Rows a few frames out of order come out in frame order; a row
    /// behind a frame that went out is a bad row naming its line.
    #[test]
    fn rows_a_little_out_of_order_are_put_in_order_and_beyond_the_window_refused() {
        let mut options = MotOptions::new(1.0, Ground::Scale(1.0));
        options.window = 2;
        let text = "2,1,0,0,1,1,1\n1,1,0,0,1,1,1\n3,1,0,0,1,1,1\n4,1,0,0,1,1,1\n\
                    5,1,0,0,1,1,1\n6,1,0,0,1,1,1\n2,2,0,0,1,1,1\n";
        let rows = read_all(text, options, None);
        let frames: Vec<f64> = rows
            .iter()
            .filter_map(|r| r.as_ref().ok())
            .map(|l| l.report.time)
            .collect();
        assert_eq!(frames, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        let error = rows
            .iter()
            .find_map(|r| r.as_ref().err())
            .unwrap()
            .to_string();
        assert!(
            error.starts_with("mot.txt:7: frame 2 comes after frame 6"),
            "{error}"
        );
    }

    /// A long file is read holding at most the window's frames: the rows
    /// held never pass (window + 1) × the boxes of a frame.
    #[test]
    fn a_long_file_is_read_holding_only_the_window() {
        let (frames, boxes, window) = (5_000u64, 20u64, 3u64);
        let mut text = String::new();
        for f in 1..=frames {
            for id in 0..boxes {
                // Each frame's rows written a frame late, every other frame.
                let frame = if f % 2 == 0 && id == 0 { f - 1 } else { f };
                text.push_str(&format!("{frame},{id},{},0,1,1,1\n", id * 10));
            }
        }
        let mut options = MotOptions::new(25.0, Ground::Scale(1.0));
        options.window = window;
        let mut reader = MotReader::new(
            Box::new(std::io::Cursor::new(text)),
            "long.txt",
            options,
            None,
        )
        .unwrap();
        let mut count = 0u64;
        let mut last = 0.0;
        for row in reader.by_ref() {
            let row = row.unwrap();
            assert!(row.report.time >= last, "frame order");
            last = row.report.time;
            count += 1;
        }
        assert_eq!(count, frames * boxes);
        let most = reader.most_held() as u64;
        assert!(most <= (window + 2) * boxes, "{most} rows held");
        assert!(most >= window * boxes, "{most}: the window is used");
    }

    #[test]
    fn reads_beside_the_boxes_join_by_frame_and_id() {
        let text = "1,1,0,0,1,1,1\n1,2,50,0,1,1,1\n2,1,0,0,1,1,1\n3,1,0,0,1,1,1\n";
        let reads = "{\"frame\":1,\"id\":2,\"scores\":{\"red\":0.8,\"blue\":0.2}}\n\
                     {\"frame\":2,\"id\":1,\"identity\":1,\"accuracy\":0.9}\n\
                     {\"frame\":2,\"id\":2,\"scores\":{\"red\":1}}\n\
                     {\"frame\":3,\"id\":1,\"scores\":{\"red\":0.5}}\n";
        let rows = read_all(text, MotOptions::new(1.0, Ground::Scale(1.0)), Some(reads));
        let good: Vec<&Located> = rows.iter().filter_map(|r| r.as_ref().ok()).collect();
        assert_eq!(good.len(), 4);
        assert_eq!(good[1].report.scores.as_ref().unwrap()["red"], 0.8);
        assert_eq!(
            good[2].report.identity,
            Some(IdentityRead {
                identity: 1,
                accuracy: 0.9
            })
        );
        assert!(good[0].report.scores.is_none() && good[3].report.scores.is_none());
        let errors: Vec<String> = rows
            .iter()
            .filter_map(|r| r.as_ref().err())
            .map(ToString::to_string)
            .collect();
        assert_eq!(errors.len(), 2, "{errors:?}");
        assert!(
            errors[0].starts_with("reads.jsonl:4: detect: scores sum to 0.5"),
            "{errors:?}"
        );
        assert!(
            errors[1].starts_with("reads.jsonl:3: a read of track 2 in frame 2, which has no box"),
            "{errors:?}"
        );
    }

    #[test]
    fn a_class_column_is_a_classification_as_sure_as_the_box_is_visible() {
        let mut options = MotOptions::new(1.0, Ground::Scale(1.0));
        options.classes = BTreeMap::from([(1, "red".to_string()), (2, "blue".to_string())]);
        let text = "1,1,0,0,1,1,1,1,0.6\n1,2,0,0,1,1,1,2,1\n1,3,0,0,1,1,1,7,1\n1,4,0,0,1,1,1,1,0\n";
        let rows: Vec<Located> = read_all(text, options, None)
            .into_iter()
            .map(Result::unwrap)
            .collect();
        let scores = |i: usize| rows[i].report.scores.clone();
        assert_eq!(scores(0).unwrap()["red"], 0.8);
        assert_eq!(scores(1).unwrap()["red"], 0.0);
        assert_eq!(scores(1).unwrap()["blue"], 1.0);
        assert_eq!(scores(2), None, "class 7 has no label");
        assert_eq!(scores(3).unwrap()["red"], 0.5, "a hidden box says nothing");
    }
}
