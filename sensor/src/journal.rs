//! The sensor's journal: what changed the gateway's state, in the order it
//! happened, so that a sensor killed and started again rebuilds exactly
//! the state it had — the same seqs, batch numbers, batch logs, producer
//! counters and interests — by feeding the records through the pure core
//! again ([`Gateway::restore`](crate::machine::Gateway::restore)).
//!
//! What a [`Record`] is, and when the core writes one, is the core's
//! business; this module only keeps them on disk. The actor appends what
//! the core recorded and fsyncs it before anything that depends on it
//! leaves the process (a batch, an acknowledgement, a follow reply), one
//! fsync per batch of work.
//!
//! File: [`MAGIC`], then frames — length (u32, little-endian), FNV-1a
//! checksum of the body (u32, little-endian), the body (a postcard
//! [`Record`]). A process killed mid-write leaves a prefix of its last
//! frame: [`Journal::open`] drops it with a warning and cuts the file
//! there. A last whole frame whose checksum fails (a power cut) is dropped
//! the same way. Anything else that does not read — a bad frame with more
//! after it, a record that does not decode, a file that is not a sensor
//! journal — is refused with an error naming the file and the byte.

use crate::cuts::Wanted;
use idmesh_ownership::{Ownership, OwnershipError};
use idmesh_protocol::wire::sensor_to_sensor::Position;
use serde::{Deserialize, Serialize};
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The first bytes of a sensor journal.
pub const MAGIC: &[u8] = b"idmesh-sensor-journal/1\n";

/// Frames larger than this are not ours.
const MAX_FRAME: u32 = 1 << 30;

/// One change of the gateway's state. Lines routed carry the cuts placed
/// right after them (`(i, cut)`: after the record's `i`-th routed line),
/// so cuts keep their place among the lines they fall between.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum Record {
    /// The stream the records are of (its `Begin`, postcard): written
    /// each time a gateway starts journaling, so a journal is never
    /// replayed into another stream.
    Stream(Vec<u8>),
    /// The trace file's next `count` lines were routed.
    Trace {
        count: u64,
        cuts: Vec<(u32, Wanted)>,
    },
    /// An ingest request judged (its accepted lines routed).
    Offer {
        producer: Option<String>,
        counter: Option<String>,
        payload: Vec<u8>,
        cuts: Vec<(u32, Wanted)>,
    },
    /// Line `number` of standard input, judged (routed if accepted).
    Read {
        number: u64,
        text: String,
        cuts: Vec<(u32, Wanted)>,
    },
    /// A cut placed between lines.
    Cut(Wanted),
    /// A leader's `Follow` request, granted (its bytes).
    Follow(Vec<u8>),
    /// Every leader's queued items went out as its next batch.
    Flush,
    /// The source was exhausted.
    End,
    /// A leader's `Unfollow` request that dropped tracks (its bytes): it
    /// changes routing from then on, as a follow does.
    Unfollow(Vec<u8>),
    /// The whole state the records before it rebuilt (postcard, written
    /// by [`Gateway::compacted`](crate::machine::Gateway::compacted)): a
    /// compacted journal is its stream, this, and what happened since.
    Snapshot(Vec<u8>),
    /// One sensor of several: what changed its intake or its merge.
    Mesh(MeshRecord),
}

/// What changed the intake or the merge of one sensor of several
/// ([`crate::mesh`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum MeshRecord {
    /// An ingest request judged, with its tick (`time`) and whether it
    /// said the producers are finished.
    Offer {
        producer: Option<String>,
        counter: Option<String>,
        payload: Vec<u8>,
        time: Option<String>,
        finish: bool,
    },
    /// A peer's slice of its intake (its bytes) that brought something.
    Peer(Vec<u8>),
    /// A cut asked of this sensor, taken into its intake.
    Cut {
        tag: u64,
        rows: bool,
        events: Option<u64>,
    },
    /// A peer's request for this sensor's intake that changed it (the peer
    /// asked past entries it had not asked past before, which may be
    /// forgotten now; or it moved this finished sensor's watermark).
    Asked {
        peer: String,
        from: u64,
        above: Position,
    },
}

#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    #[error("sensor journal {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("sensor journal {path} is corrupt at byte {offset}: {problem}")]
    Corrupt {
        path: String,
        offset: u64,
        problem: String,
    },
    /// Another sensor process has this journal open.
    #[error(transparent)]
    Ownership(#[from] OwnershipError),
}

/// What a journal's bytes hold.
#[derive(Debug, Default, PartialEq)]
pub struct Parsed {
    pub records: Vec<Record>,
    /// Where the last whole record ends; bytes after it are a torn write.
    pub whole: u64,
}

/// A journal open for appending, by the one process holding its lock
/// (two sensors appending to one journal would interleave two streams).
pub struct Journal {
    file: File,
    path: PathBuf,
    _owner: Ownership,
    /// Bytes on disk now, and right after the last compaction (or at open).
    length: u64,
    base: u64,
    /// Compact once this many bytes came since `base` (and at least as
    /// many as `base`, so that compacting stays a fraction of appending).
    compact_after: u64,
}

/// How much a journal grows before it is compacted, by default.
pub const COMPACT_AFTER: u64 = 16 << 20;

impl Journal {
    /// Opens (or creates) the journal at `path` and returns the records it
    /// holds, in order; a torn last frame is cut off with a warning.
    pub fn open(path: &Path, holder: &str) -> Result<(Journal, Vec<Record>), JournalError> {
        let owner = Ownership::try_take(path, holder)?.ok_or_else(|| Ownership::refused(path))?;
        let io = |source| JournalError::Io {
            path: path.display().to_string(),
            source,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let bytes = match std::fs::read(path) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
            Err(e) => return Err(io(e)),
        };
        let parsed = parse(&bytes).map_err(|(offset, problem)| JournalError::Corrupt {
            path: path.display().to_string(),
            offset,
            problem,
        })?;
        let mut file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .map_err(io)?;
        let length = bytes.len() as u64;
        if parsed.whole < length {
            tracing::warn!(journal = %path.display(), at = parsed.whole, torn = length - parsed.whole,
                "dropping a torn last record (the process died writing it)");
            file.set_len(parsed.whole).map_err(io)?;
        }
        if parsed.whole == 0 {
            file.write_all(MAGIC).map_err(io)?;
            file.sync_data().map_err(io)?;
        }
        let length = parsed.whole.max(MAGIC.len() as u64);
        Ok((
            Journal {
                file,
                path: path.to_path_buf(),
                _owner: owner,
                length,
                base: length,
                compact_after: COMPACT_AFTER,
            },
            parsed.records,
        ))
    }

    /// Appends `records` and fsyncs them (nothing to do for none).
    pub fn append(&mut self, records: &[Record]) -> Result<(), JournalError> {
        if records.is_empty() {
            return Ok(());
        }
        let mut bytes = Vec::new();
        for record in records {
            frame(record, &mut bytes);
        }
        let io = |source| JournalError::Io {
            path: self.path.display().to_string(),
            source,
        };
        self.file.write_all(&bytes).map_err(io)?;
        self.file.sync_data().map_err(io)?;
        self.length += bytes.len() as u64;
        Ok(())
    }

    /// Compacts after `bytes` more bytes instead of [`COMPACT_AFTER`].
    pub fn compact_after(mut self, bytes: u64) -> Self {
        self.compact_after = bytes.max(1);
        self
    }

    /// Whether it has grown enough since its last compaction to be
    /// compacted now.
    pub fn due(&self) -> bool {
        self.length.saturating_sub(self.base) >= self.compact_after.max(self.base)
    }

    /// Waits another [`Journal::compact_after`] before it is due again (a
    /// snapshot could not be taken: the journal stays whole).
    pub fn postpone(&mut self) {
        self.base = self.length;
    }

    /// Bytes on disk.
    pub fn bytes(&self) -> u64 {
        self.length
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Replaces the journal by `records` (a compacted journal: the
    /// stream and a snapshot), atomically: they are written to a file
    /// beside it, fsynced, and renamed over it, so a kill at any point
    /// leaves either the old journal or the new one whole. Appends go to
    /// the new one from then on.
    pub fn compact(&mut self, records: &[Record]) -> Result<(), JournalError> {
        let io = |source| JournalError::Io {
            path: self.path.display().to_string(),
            source,
        };
        let mut bytes = MAGIC.to_vec();
        for record in records {
            frame(record, &mut bytes);
        }
        let mut name = self.path.file_name().unwrap_or_default().to_os_string();
        name.push(".compacting");
        let temporary = self.path.with_file_name(name);
        let mut file = File::create(&temporary).map_err(io)?;
        file.write_all(&bytes).map_err(io)?;
        file.sync_all().map_err(io)?;
        std::fs::rename(&temporary, &self.path).map_err(io)?;
        // The rename itself is durable once the directory is.
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            File::open(dir).and_then(|d| d.sync_all()).map_err(io)?;
        }
        self.file = OpenOptions::new()
            .append(true)
            .open(&self.path)
            .map_err(io)?;
        self.length = bytes.len() as u64;
        self.base = self.length;
        Ok(())
    }
}

/// `record` as a frame, appended to `out`.
pub fn frame(record: &Record, out: &mut Vec<u8>) {
    let body = postcard::to_stdvec(record).unwrap_or_default();
    out.extend_from_slice(&(body.len() as u32).to_le_bytes());
    out.extend_from_slice(&checksum(&body).to_le_bytes());
    out.extend_from_slice(&body);
}

/// The records of a journal's bytes, or where and why they do not read.
pub fn parse(bytes: &[u8]) -> Result<Parsed, (u64, String)> {
    if bytes.len() < MAGIC.len() {
        return if MAGIC.starts_with(bytes) {
            Ok(Parsed::default())
        } else {
            Err((0, "not a sensor journal".into()))
        };
    }
    if !bytes.starts_with(MAGIC) {
        return Err((0, "not a sensor journal".into()));
    }
    let mut parsed = Parsed {
        records: Vec::new(),
        whole: MAGIC.len() as u64,
    };
    let mut at = MAGIC.len();
    while at < bytes.len() {
        let rest = &bytes[at..];
        let Some(head) = rest.get(..8) else { break };
        let length = u32::from_le_bytes([head[0], head[1], head[2], head[3]]);
        let sum = u32::from_le_bytes([head[4], head[5], head[6], head[7]]);
        if length > MAX_FRAME {
            return Err((at as u64, format!("a frame of {length} bytes")));
        }
        let end = 8 + length as usize;
        let Some(body) = rest.get(8..end) else { break };
        if checksum(body) != sum {
            if at + end == bytes.len() {
                // The last frame, whole in length but not in content: a
                // write the disk did not finish.
                break;
            }
            return Err((at as u64, "checksum mismatch".into()));
        }
        let record = postcard::from_bytes(body)
            .map_err(|e| (at as u64, format!("a record that does not decode: {e}")))?;
        parsed.records.push(record);
        at += end;
        parsed.whole = at as u64;
    }
    Ok(parsed)
}

/// FNV-1a, 32 bits.
fn checksum(bytes: &[u8]) -> u32 {
    bytes.iter().fold(0x811c_9dc5u32, |h, &b| {
        (h ^ u32::from(b)).wrapping_mul(0x0100_0193)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn records() -> Vec<Record> {
        vec![
            Record::Flush,
            Record::Trace {
                count: 3,
                cuts: vec![(1, Wanted { tag: 7, rows: true })],
            },
            Record::Offer {
                producer: Some("p".into()),
                counter: Some("0".into()),
                payload: b"{\"kind\":\"mix\"}".to_vec(),
                cuts: Vec::new(),
            },
            Record::Cut(Wanted {
                tag: 9,
                rows: false,
            }),
            Record::Follow(vec![1, 2, 3]),
            Record::End,
        ]
    }

    fn bytes_of(records: &[Record]) -> Vec<u8> {
        let mut bytes = MAGIC.to_vec();
        for record in records {
            frame(record, &mut bytes);
        }
        bytes
    }

    fn path(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("idmesh-sensor-journal-{}", std::process::id()));
        let path = dir.join(name);
        let _ = std::fs::remove_file(&path);
        path
    }

    #[test]
    fn records_come_back_in_order_after_reopening_and_appending_goes_on() {
        let path = path("order");
        let (mut journal, old) = Journal::open(&path, "test").unwrap();
        assert!(old.is_empty());
        journal.append(&records()[..2]).unwrap();
        journal.append(&[]).unwrap();
        drop(journal);
        let (mut journal, old) = Journal::open(&path, "test").unwrap();
        assert_eq!(old, records()[..2]);
        journal.append(&records()[2..]).unwrap();
        drop(journal);
        assert_eq!(Journal::open(&path, "test").unwrap().1, records());
        assert_eq!(std::fs::read(&path).unwrap(), bytes_of(&records()));
    }

    #[test]
    fn one_process_at_a_time_writes_a_journal_and_a_refusal_names_the_holder() {
        let path = path("owned");
        let (journal, _) = Journal::open(&path, "sensor-0").unwrap();
        let error = Journal::open(&path, "sensor-0 again")
            .err()
            .expect("refused while the first holds it")
            .to_string();
        assert!(error.contains("sensor-0 (pid"), "{error}");
        assert!(error.contains("owned.lock"), "{error}");
        drop(journal);
        assert!(Journal::open(&path, "sensor-0 again").is_ok());
    }

    #[test]
    fn every_torn_tail_is_dropped_and_the_whole_records_before_it_kept() {
        let whole = bytes_of(&records()[..5]);
        let full = bytes_of(&records());
        // Every prefix of the last frame: the process died writing it.
        for cut in whole.len()..full.len() {
            let parsed = parse(&full[..cut]).expect("a torn tail is not corruption");
            assert_eq!(parsed.records, records()[..5], "cut at {cut}");
            assert_eq!(parsed.whole, whole.len() as u64);
        }
        // A torn magic is an empty journal.
        assert_eq!(parse(&MAGIC[..5]).unwrap(), Parsed::default());
        // On disk: cut off, and the next record goes after the whole ones.
        let path = path("torn");
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &full[..full.len() - 1]).unwrap();
        let (mut journal, old) = Journal::open(&path, "test").unwrap();
        assert_eq!(old, records()[..5]);
        journal.append(&[Record::End]).unwrap();
        drop(journal);
        assert_eq!(std::fs::read(&path).unwrap(), full);
    }

    #[test]
    fn a_last_frame_with_a_bad_checksum_is_torn_but_one_in_the_middle_is_corruption() {
        let mut bytes = bytes_of(&records());
        let last = bytes.len() - 1;
        bytes[last] ^= 0xff;
        assert_eq!(parse(&bytes).unwrap().records, records()[..5]);
        let mut bytes = bytes_of(&records());
        let second = MAGIC.len() + 8 + postcard::to_stdvec(&Record::Flush).unwrap().len();
        bytes[second + 9] ^= 0xff;
        assert_eq!(
            parse(&bytes).unwrap_err(),
            (second as u64, "checksum mismatch".to_string())
        );
    }

    #[test]
    fn corruption_is_an_error_naming_the_file_and_the_byte() {
        let path = path("corrupt");
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let mut bytes = bytes_of(&records());
        let at = MAGIC.len() + 8 + postcard::to_stdvec(&Record::Flush).unwrap().len();
        bytes[at + 3] = 0x7f; // a length of gigabytes
        std::fs::write(&path, &bytes).unwrap();
        let error = Journal::open(&path, "test")
            .err()
            .expect("refused")
            .to_string();
        assert!(error.contains(&path.display().to_string()), "{error}");
        assert!(error.contains(&format!("at byte {at}")), "{error}");
        std::fs::write(&path, b"not a journal at all, long enough").unwrap();
        let error = Journal::open(&path, "test")
            .err()
            .expect("refused")
            .to_string();
        assert!(error.contains("at byte 0: not a sensor journal"), "{error}");
        // Refused, not cut: the file is left for whoever looks into it.
        assert_eq!(
            std::fs::read(&path).unwrap(),
            b"not a journal at all, long enough"
        );
    }
}
