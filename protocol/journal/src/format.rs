//! The bytes: the file header and the records (see the crate's doc).

use crate::error::{Error, Problem};
use std::path::Path;

/// The first bytes of every log.
pub const MAGIC: [u8; 8] = *b"idmeshJL";
/// The format version this crate writes and reads.
pub const FORMAT: u16 = 1;
/// Bytes of the file header.
pub const HEADER_LEN: usize = 40;
/// Bytes of a record's head (length, payload checksum, head checksum).
pub const RECORD_HEAD: usize = 12;
/// The largest payload a record may hold.
pub const MAX_RECORD: u32 = 1 << 30;

/// Bytes of the header's kind field.
const KIND_LEN: usize = 16;

/// The header of a file holding `kind` (at most 16 ASCII bytes) at
/// `generation`.
pub fn header(kind: &str, generation: u64) -> [u8; HEADER_LEN] {
    // A kind is the code's own constant: a longer one would be written cut
    // short and then refused on every read as another file's, so it stops
    // the first write of it instead, in every build.
    assert!(
        kind.len() <= KIND_LEN && kind.is_ascii(),
        "a journal kind of at most {KIND_LEN} ASCII bytes, not {kind:?}"
    );
    let mut head = [0u8; HEADER_LEN];
    head[..8].copy_from_slice(&MAGIC);
    head[8..10].copy_from_slice(&FORMAT.to_le_bytes());
    let name = &kind.as_bytes()[..kind.len().min(KIND_LEN)];
    head[12..12 + name.len()].copy_from_slice(name);
    head[28..36].copy_from_slice(&generation.to_le_bytes());
    let sum = crc32fast::hash(&head[..36]);
    head[36..40].copy_from_slice(&sum.to_le_bytes());
    head
}

/// What the start of a file is.
pub(crate) enum Start {
    /// Nothing, or a prefix of a header (a file that was being created).
    Empty,
    /// A header of `kind`: its generation.
    Header(u64),
}

/// The first formats' first bytes, and what they were.
const OLD_FORMATS: [(&[u8], &str); 3] = [
    (b"idmesh-sensor-journal/1\n", "a sensor journal"),
    (b"idmesh/1", "a leader snapshot"),
    // A leader journal's first frame named the snapshot it continued:
    // kind 4, eight bytes.
    (&[4, 8, 0, 0, 0], "a leader journal"),
];

/// Reads the header of `bytes` (the file at `path`), which must hold `kind`.
pub(crate) fn read_header(bytes: &[u8], kind: &'static str, path: &Path) -> Result<Start, Error> {
    if bytes.len() < HEADER_LEN {
        // A header cut short: the file was being created (a new file is
        // written whole and renamed into place, so this is a torn copy).
        let known = &header(kind, 0)[..28];
        let n = bytes.len().min(known.len());
        if bytes[..n] == known[..n] {
            return Ok(Start::Empty);
        }
    }
    if !bytes.starts_with(&MAGIC) {
        if let Some((_, what)) = OLD_FORMATS.iter().find(|(m, _)| bytes.starts_with(m)) {
            return Err(Error::OldFormat {
                path: path.to_path_buf(),
                what,
            });
        }
        return Err(Error::NotJournal {
            path: path.to_path_buf(),
        });
    }
    if bytes.len() < HEADER_LEN {
        return Err(Error::Header {
            path: path.to_path_buf(),
        });
    }
    let head = &bytes[..HEADER_LEN];
    let sum = u32::from_le_bytes(head[36..40].try_into().unwrap_or_default());
    if crc32fast::hash(&head[..36]) != sum {
        return Err(Error::Header {
            path: path.to_path_buf(),
        });
    }
    let format = u16::from_le_bytes([head[8], head[9]]);
    if format != FORMAT {
        return Err(Error::NewerFormat {
            path: path.to_path_buf(),
            found: format,
        });
    }
    let found = &head[12..28];
    let end = found.iter().position(|&b| b == 0).unwrap_or(KIND_LEN);
    if &found[..end] != kind.as_bytes() {
        return Err(Error::WrongKind {
            path: path.to_path_buf(),
            found: String::from_utf8_lossy(&found[..end]).into_owned(),
            wanted: kind,
        });
    }
    let generation = u64::from_le_bytes(head[28..36].try_into().unwrap_or_default());
    Ok(Start::Header(generation))
}

/// Appends to `out` one record whose payload is `parts` one after the
/// other.
pub fn encode_record(parts: &[&[u8]], out: &mut Vec<u8>) {
    let length: usize = parts.iter().map(|p| p.len()).sum();
    let mut sum = crc32fast::Hasher::new();
    for part in parts {
        sum.update(part);
    }
    let mut head = [0u8; RECORD_HEAD];
    head[..4].copy_from_slice(&(length as u32).to_le_bytes());
    head[4..8].copy_from_slice(&sum.finalize().to_le_bytes());
    let check = crc32fast::hash(&head[..8]);
    head[8..12].copy_from_slice(&check.to_le_bytes());
    out.reserve(RECORD_HEAD + length);
    out.extend_from_slice(&head);
    for part in parts {
        out.extend_from_slice(part);
    }
}

/// What lies at a byte of a file where a record should start.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum At<'a> {
    /// The end of the file.
    End,
    /// A whole record: its payload.
    Whole(&'a [u8]),
    /// A record that ends past the end of the file (its head, if whole,
    /// checks): a write that did not finish.
    Short,
    /// A record that does not check; `skip` is where the next record
    /// would start if the head is to be believed (its payload is bad, its
    /// head is not).
    Bad { problem: Problem, skip: Option<u64> },
}

/// The record at byte `at` of `bytes`.
pub(crate) fn record_at(bytes: &[u8], at: u64) -> At<'_> {
    let Some(rest) = usize::try_from(at).ok().and_then(|at| bytes.get(at..)) else {
        return At::End;
    };
    if rest.is_empty() {
        return At::End;
    }
    let Some(head) = rest.get(..RECORD_HEAD) else {
        return At::Short;
    };
    let word = |i: usize| u32::from_le_bytes([head[i], head[i + 1], head[i + 2], head[i + 3]]);
    let (length, sum, check) = (word(0), word(4), word(8));
    if crc32fast::hash(&head[..8]) != check {
        return At::Bad {
            problem: Problem::Head,
            skip: None,
        };
    }
    if length > MAX_RECORD {
        return At::Bad {
            problem: Problem::Length(length),
            skip: None,
        };
    }
    let Some(payload) = rest.get(RECORD_HEAD..RECORD_HEAD + length as usize) else {
        return At::Short;
    };
    if crc32fast::hash(payload) != sum {
        return At::Bad {
            problem: Problem::Checksum,
            skip: Some(at + (RECORD_HEAD + payload.len()) as u64),
        };
    }
    At::Whole(payload)
}

/// The whole records after a bad one at `at`: found by looking, byte by
/// byte from `from` (past the bad record's payload when its head could be
/// believed), for a record that checks, and reading on from there.
pub(crate) fn whole_after(bytes: &[u8], from: u64) -> usize {
    let mut count = 0;
    let mut at = from;
    while at < bytes.len() as u64 {
        match record_at(bytes, at) {
            At::Whole(payload) => {
                count += 1;
                at += (RECORD_HEAD + payload.len()) as u64;
            }
            At::End | At::Short if count > 0 => break,
            At::Bad {
                skip: Some(skip), ..
            } if count > 0 => at = skip,
            _ => at += 1,
        }
    }
    count
}
