//! Reading a log back: the whole records, and how the file ended; or two
//! copies of one log merged record by record.

use crate::error::{Damage, Error, Problem};
use crate::format::{read_header, record_at, whole_after, At, Start, HEADER_LEN, RECORD_HEAD};
use std::path::{Path, PathBuf};

/// A whole record: where it starts in the file, and its payload.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Record {
    pub offset: u64,
    pub payload: Vec<u8>,
}

impl Record {
    /// Where the next record starts.
    pub fn end(&self) -> u64 {
        self.offset + (RECORD_HEAD + self.payload.len()) as u64
    }
}

/// How a log ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Ending {
    /// With its last whole record.
    Clean,
    /// With an incomplete or bad record at `at` and nothing whole after
    /// it: `bytes` from there to the end, to be cut off.
    Torn { at: u64, bytes: u64 },
    /// With a bad record that whole ones follow.
    Damaged(Damage),
}

/// What a log holds.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Contents {
    /// The header's generation.
    pub generation: u64,
    /// The whole records from the start, up to the end or the first that
    /// does not check.
    pub records: Vec<Record>,
    pub ending: Ending,
}

impl Contents {
    /// Where the whole records end: the file goes on from here once what
    /// follows is cut off.
    pub fn end(&self) -> u64 {
        self.records.last().map_or(HEADER_LEN as u64, Record::end)
    }

    /// The damage, if the file is damaged.
    pub(crate) fn damage(&self) -> Option<&Damage> {
        match &self.ending {
            Ending::Damaged(damage) => Some(damage),
            _ => None,
        }
    }
}

/// The log in `bytes` (the file at `path`, named in errors), which must
/// hold `kind`: None if it is empty (or its header was never whole).
pub fn parse(bytes: &[u8], kind: &'static str, path: &Path) -> Result<Option<Contents>, Error> {
    let generation = match read_header(bytes, kind, path)? {
        Start::Empty => return Ok(None),
        Start::Header(generation) => generation,
    };
    let mut records = Vec::new();
    let mut at = HEADER_LEN as u64;
    let ending = loop {
        match record_at(bytes, at) {
            At::End => break Ending::Clean,
            At::Whole(payload) => {
                records.push(Record {
                    offset: at,
                    payload: payload.to_vec(),
                });
                at += (RECORD_HEAD + payload.len()) as u64;
            }
            bad => break ending_at(bytes, at, bad, path),
        }
    };
    Ok(Some(Contents {
        generation,
        records,
        ending,
    }))
}

/// How a file ends at a record that is not whole: torn, if nothing whole
/// follows it; damaged otherwise.
fn ending_at(bytes: &[u8], at: u64, bad: At<'_>, path: &Path) -> Ending {
    let rest = bytes.len() as u64 - at;
    let (problem, after) = scan(bytes, at, &bad);
    match (problem, after) {
        (Some(problem), after) if after > 0 => Ending::Damaged(Damage {
            path: path.to_path_buf(),
            copy: None,
            at,
            problem,
            after,
            bytes: rest,
        }),
        _ => Ending::Torn { at, bytes: rest },
    }
}

/// Why the record at `at` is bad (None: it is only short) and how many
/// whole records follow it.
fn scan(bytes: &[u8], at: u64, bad: &At<'_>) -> (Option<Problem>, usize) {
    match *bad {
        // A record that runs past the end: nothing can follow it.
        At::End | At::Short | At::Whole(_) => (None, 0),
        At::Bad { problem, skip } => (Some(problem), whole_after(bytes, skip.unwrap_or(at + 1))),
    }
}

/// The bytes of the file at `path`; None if there is none.
fn load(path: &Path) -> Result<Option<Vec<u8>>, Error> {
    match std::fs::read(path) {
        Ok(bytes) => Ok(Some(bytes)),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(e) => Err(Error::io(path)(e)),
    }
}

/// The log at `path` (see [`parse`]); None if there is no file or it is
/// empty.
pub fn read(path: &Path, kind: &'static str) -> Result<Option<Contents>, Error> {
    match load(path)? {
        Some(bytes) => parse(&bytes, kind, path),
        None => Ok(None),
    }
}

/// A record of one copy that did not check, taken from the other.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Repair {
    /// The copy it was damaged in.
    pub path: PathBuf,
    pub at: u64,
    pub problem: Problem,
}

/// Two copies of one log, read as one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Merged {
    /// Every record whole in either copy, in order; the ending is torn or
    /// damaged only where both copies are.
    pub contents: Contents,
    /// Records damaged in one copy and taken from the other.
    pub repairs: Vec<Repair>,
    /// The two files do not both hold exactly `contents` (a copy missing,
    /// behind, torn or repaired): write them again before appending.
    pub rewrite: bool,
}

/// One copy of a log, as found.
enum Copy {
    /// No file, or an empty one.
    Missing,
    /// Its header does not check.
    Unreadable(Error),
    Read {
        bytes: Vec<u8>,
        generation: u64,
    },
}

fn open_copy(path: &Path, kind: &'static str) -> Result<Copy, Error> {
    let Some(bytes) = load(path)? else {
        return Ok(Copy::Missing);
    };
    match read_header(&bytes, kind, path) {
        Ok(Start::Empty) => Ok(Copy::Missing),
        Ok(Start::Header(generation)) => Ok(Copy::Read { bytes, generation }),
        Err(e @ Error::Header { .. }) => Ok(Copy::Unreadable(e)),
        // Another format, another role's file: not damage, and not to be
        // read past.
        Err(e) => Err(e),
    }
}

/// The log kept in two files, `path` and its `copy`, written alike
/// ([`crate::Writer`] with two paths): each record is taken from
/// whichever file holds it whole, so damage in one is repaired from the
/// other. Only a record bad in both ends the log early (torn, or damaged
/// if whole records follow in either). A copy missing, or behind the
/// other (the process died between the two writes), is no damage. If the
/// two are of different generations (the process died between replacing
/// one and the other), the newer is taken unless it is damaged.
pub fn read_copies(path: &Path, copy: &Path, kind: &'static str) -> Result<Option<Merged>, Error> {
    let (first, second) = (open_copy(path, kind)?, open_copy(copy, kind)?);
    let alone = |bytes: &[u8], at: &Path, other: Option<(Error, &Path)>| {
        let contents = parse(bytes, kind, at)?;
        let repairs = other
            .map(|(_, other)| Repair {
                path: other.to_path_buf(),
                at: 0,
                problem: Problem::Head,
            })
            .into_iter()
            .collect();
        Ok(contents.map(|contents| Merged {
            contents,
            repairs,
            rewrite: true,
        }))
    };
    match (first, second) {
        (Copy::Missing, Copy::Missing) => Ok(None),
        (Copy::Unreadable(e), Copy::Missing | Copy::Unreadable(_))
        | (Copy::Missing, Copy::Unreadable(e)) => Err(e),
        (Copy::Read { bytes, .. }, Copy::Missing) => alone(&bytes, path, None),
        (Copy::Missing, Copy::Read { bytes, .. }) => alone(&bytes, copy, None),
        (Copy::Read { bytes, .. }, Copy::Unreadable(e)) => alone(&bytes, path, Some((e, copy))),
        (Copy::Unreadable(e), Copy::Read { bytes, .. }) => alone(&bytes, copy, Some((e, path))),
        (
            Copy::Read {
                bytes: a,
                generation: ga,
            },
            Copy::Read {
                bytes: b,
                generation: gb,
            },
        ) if ga != gb => {
            let (newer, older) = if ga > gb {
                ((&a, path), (&b, copy))
            } else {
                ((&b, copy), (&a, path))
            };
            let chosen = match alone(newer.0, newer.1, None)? {
                Some(m) if m.contents.damage().is_none() => Some(m),
                newer_read => match alone(older.0, older.1, None)? {
                    Some(m) if m.contents.damage().is_none() => Some(m),
                    _ => newer_read,
                },
            };
            Ok(chosen)
        }
        (
            Copy::Read {
                bytes: a,
                generation,
            },
            Copy::Read { bytes: b, .. },
        ) => merge(&a, &b, generation, path, copy).map(Some),
    }
}

/// Two copies of one generation, record by record: both were written the
/// same bytes, so their records start at the same offsets.
fn merge(a: &[u8], b: &[u8], generation: u64, path: &Path, copy: &Path) -> Result<Merged, Error> {
    let mut records = Vec::new();
    let mut repairs = Vec::new();
    let mut rewrite = false;
    let mut at = HEADER_LEN as u64;
    let ending = loop {
        let (x, y) = (record_at(a, at), record_at(b, at));
        let whole = match (&x, &y) {
            (At::End, At::End) => break Ending::Clean,
            (At::Whole(p), At::Whole(q)) if p != q => {
                return Err(Error::Diverged {
                    path: path.to_path_buf(),
                    copy: copy.to_path_buf(),
                    at,
                })
            }
            (At::Whole(p), At::Whole(_)) => p.to_vec(),
            (At::Whole(p), other) | (other, At::Whole(p)) => {
                let damaged = if matches!(x, At::Whole(_)) {
                    copy
                } else {
                    path
                };
                if let At::Bad { problem, .. } = other {
                    repairs.push(Repair {
                        path: damaged.to_path_buf(),
                        at,
                        problem: *problem,
                    });
                }
                rewrite = true;
                p.to_vec()
            }
            _ => {
                // Bad, short or ended in both.
                let length = a.len().max(b.len()) as u64;
                let (problem_a, after_a) = scan(a, at, &x);
                let (problem_b, after_b) = scan(b, at, &y);
                if at < length {
                    rewrite = true;
                }
                break match problem_a.or(problem_b) {
                    Some(problem) if after_a + after_b > 0 => Ending::Damaged(Damage {
                        path: path.to_path_buf(),
                        copy: Some(copy.to_path_buf()),
                        at,
                        problem,
                        after: after_a.max(after_b),
                        bytes: length - at,
                    }),
                    _ if at < length => Ending::Torn {
                        at,
                        bytes: length - at,
                    },
                    _ => Ending::Clean,
                };
            }
        };
        let end = at + (RECORD_HEAD + whole.len()) as u64;
        records.push(Record {
            offset: at,
            payload: whole,
        });
        at = end;
    };
    Ok(Merged {
        contents: Contents {
            generation,
            records,
            ending,
        },
        repairs,
        rewrite,
    })
}
