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
//! File: an `idmesh-journal` log (`sensor-journal`: a checksummed header
//! whose generation counts compactions, then checksummed records, each a
//! postcard [`Record`]), kept twice — `<journal>` and `<journal>.copy`,
//! the same bytes written to both before the fsync. A process killed
//! mid-write leaves a prefix of its last record: [`Journal::open`] drops
//! it with a warning and cuts the files there (it was never acted on).
//!
//! Why two copies: the journal holds what exists nowhere else whole —
//! ingested lines the sensor acknowledged (their producer let them go),
//! and where cuts, follows and batch boundaries fell among the lines,
//! which the leaders have already acted on (a trace file holds its lines,
//! not those). A sensor that came back from the records before a damaged
//! one would go on with a different stream than the one its leaders
//! hold. So a record that does not check in one file is taken from the
//! other ([`idmesh_journal::read_copies`]: logged, counted in
//! `journal_repaired`, and both files written again whole); a record
//! damaged in both, or a damaged journal without its copy, stops the
//! sensor with an error naming the file and the byte
//! ([`JournalError::Damaged`]) rather than let it lose accepted input
//! silently. A record that checks but does not decode, or a file that is
//! not a sensor journal, is refused likewise.

use crate::cuts::Wanted;
use idmesh_journal::{self as log, Damage, Ending, Writer};
use idmesh_ownership::{Ownership, OwnershipError};
use idmesh_protocol::wire::sensor_to_sensor::Position;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What the journal's header says it holds.
pub const KIND: &str = "sensor-journal";

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
    /// compacted journal is its stream, this, the named track ids'
    /// numbers ([`Record::TrackIds`]), and what happened since.
    Snapshot(Vec<u8>),
    /// One sensor of several: what changed its intake or its merge.
    Mesh(MeshRecord),
    /// Named track ids of `producer` (a ROS 2 topic's, `ros2:<topic>`)
    /// given the track numbers `first`, `first + 1`, …: written before the
    /// first offer whose lines carry them, so that a sensor resumed from
    /// its journal gives those ids the same numbers, and a new id the next
    /// one, rather than numbering from 0 again. A compacted journal states
    /// them all again after its snapshot.
    ///
    /// Keep it the last variant, and add any later one after it: a
    /// record's payload starts with its variant's index (postcard), so
    /// journals written before a variant was added read as they did.
    TrackIds {
        producer: String,
        first: u32,
        ids: Vec<String>,
    },
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
    #[error("sensor journal: {0}")]
    Log(#[from] log::Error),
    #[error(
        "sensor journal {0}: the damaged records held what this sensor accepted and did (lines \
         routed, ingested lines acknowledged, cuts, follows, the batches it sent), which exist \
         nowhere else in full, so it does not start rather than go on with a different stream; \
         restore the journal or its copy from a backup, or remove the deployment's state \
         directory to start the stream again from its beginning"
    )]
    Damaged(Damage),
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

/// A journal open for appending, by the one process holding its lock
/// (two sensors appending to one journal would interleave two streams).
pub struct Journal {
    writer: Writer,
    path: PathBuf,
    _owner: Ownership,
    /// Compactions so far (the files' generation).
    generation: u64,
    /// Bytes on disk right after the last compaction (or at open).
    base: u64,
    /// Compact once this many bytes came since `base` (and at least as
    /// many as `base`, so that compacting stays a fraction of appending).
    compact_after: u64,
    /// Records found damaged in one copy at open and taken from the other.
    repaired: usize,
}

/// How much a journal grows before it is compacted, by default.
pub(crate) const COMPACT_AFTER: u64 = 16 << 20;

/// Where the copy of the journal at `path` is.
pub fn copy_path(path: &Path) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(".copy");
    PathBuf::from(name)
}

impl Journal {
    /// Opens (or creates) the journal at `path` and its copy and returns
    /// the records they hold, in order; a torn last record is cut off with
    /// a warning, a record damaged in one copy is taken from the other.
    pub fn open(path: &Path, holder: &str) -> Result<(Journal, Vec<Record>), JournalError> {
        let owner = Ownership::try_take(path, holder)?.ok_or_else(|| Ownership::refused(path))?;
        let copy = copy_path(path);
        let paths = [path, copy.as_path()];
        let Some(merged) = log::read_copies(path, &copy, KIND)? else {
            let writer = Writer::create::<&[u8]>(&paths, KIND, 0, &[])?;
            return Ok((Journal::new(writer, path, owner, 0, 0), Vec::new()));
        };
        let contents = merged.contents;
        let records = decode(&contents, path)?;
        match contents.ending {
            Ending::Clean => {}
            Ending::Torn { at, bytes } => {
                tracing::warn!(journal = %path.display(), at, torn = bytes,
                    "dropping a torn last record (the process died writing it)");
            }
            Ending::Damaged(damage) => return Err(JournalError::Damaged(damage)),
        }
        for repair in &merged.repairs {
            tracing::warn!(journal = %repair.path.display(), at = repair.at, problem = %repair.problem,
                "a damaged record of the sensor journal, taken from its other copy");
        }
        let generation = contents.generation;
        let writer = if merged.rewrite {
            // Both copies whole again, from what was read.
            let payloads: Vec<&[u8]> = contents.records.iter().map(|r| &r.payload[..]).collect();
            Writer::create(&paths, KIND, generation, &payloads)?
        } else {
            Writer::resume(&paths, KIND, contents.end())?
        };
        let journal = Journal::new(writer, path, owner, generation, merged.repairs.len());
        Ok((journal, records))
    }

    fn new(
        writer: Writer,
        path: &Path,
        owner: Ownership,
        generation: u64,
        repaired: usize,
    ) -> Journal {
        let base = writer.len();
        Journal {
            writer,
            path: path.to_path_buf(),
            _owner: owner,
            generation,
            base,
            compact_after: COMPACT_AFTER,
            repaired,
        }
    }

    /// Appends `records` and fsyncs them (nothing to do for none).
    pub(crate) fn append(&mut self, records: &[Record]) -> Result<(), JournalError> {
        if records.is_empty() {
            return Ok(());
        }
        let payloads: Vec<Vec<u8>> = records.iter().map(encode).collect();
        self.writer.append_all(&payloads)?;
        self.writer.sync()?;
        Ok(())
    }

    /// Appends records already encoded (a standby's copy: as the sensor
    /// sent them) and fsyncs them.
    pub(crate) fn append_encoded(&mut self, payloads: &[Vec<u8>]) -> Result<(), JournalError> {
        if payloads.is_empty() {
            return Ok(());
        }
        self.writer.append_all(payloads)?;
        self.writer.sync()?;
        Ok(())
    }

    /// Replaces the journal by records already encoded (a standby's copy
    /// made whole again), atomically as [`Journal::compact`] does.
    pub(crate) fn replace_encoded(&mut self, payloads: &[Vec<u8>]) -> Result<(), JournalError> {
        self.generation += 1;
        self.writer.replace(self.generation, payloads)?;
        self.base = self.bytes();
        Ok(())
    }

    /// Compacts after `bytes` more bytes instead of [`COMPACT_AFTER`].
    pub fn compact_after(mut self, bytes: u64) -> Self {
        self.compact_after = bytes.max(1);
        self
    }

    /// Whether it has grown enough since its last compaction to be
    /// compacted now.
    pub(crate) fn due(&self) -> bool {
        self.bytes().saturating_sub(self.base) >= self.compact_after.max(self.base)
    }

    /// Waits another [`Journal::compact_after`] before it is due again (a
    /// snapshot could not be taken: the journal stays whole).
    pub(crate) fn postpone(&mut self) {
        self.base = self.bytes();
    }

    /// Bytes on disk (in each copy).
    pub(crate) fn bytes(&self) -> u64 {
        self.writer.len()
    }

    /// Where the journal is on disk.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Records found damaged in one copy when it was opened, and taken
    /// from the other.
    pub(crate) fn repaired(&self) -> usize {
        self.repaired
    }

    /// Replaces the journal by `records` (a compacted journal: the
    /// stream and a snapshot), atomically: each copy is written to a file
    /// beside it, fsynced, and renamed over it, so a kill at any point
    /// leaves either the old journal or the new one whole in each (the
    /// newer generation wins at the next open). Appends go to the new one
    /// from then on.
    pub(crate) fn compact(&mut self, records: &[Record]) -> Result<(), JournalError> {
        let payloads: Vec<Vec<u8>> = records.iter().map(encode).collect();
        self.generation += 1;
        self.writer.replace(self.generation, &payloads)?;
        self.base = self.bytes();
        Ok(())
    }
}

/// `record` as a journal record's payload.
pub fn encode(record: &Record) -> Vec<u8> {
    postcard::to_stdvec(record).unwrap_or_default()
}

/// A record's payload back to the record (a standby checks what it is sent).
pub fn decode_record(payload: &[u8]) -> Result<Record, postcard::Error> {
    postcard::from_bytes(payload)
}

/// The records of a log's contents, or where one does not decode.
fn decode(contents: &log::Contents, path: &Path) -> Result<Vec<Record>, JournalError> {
    contents
        .records
        .iter()
        .map(|r| {
            postcard::from_bytes(&r.payload).map_err(|e| JournalError::Corrupt {
                path: path.display().to_string(),
                offset: r.offset,
                problem: format!("a record that does not decode: {e}"),
            })
        })
        .collect()
}

/// A whole journal file's bytes holding `records` (tests: restoring from
/// the bytes a process would read).
#[cfg(test)]
pub(crate) fn to_bytes(records: &[Record]) -> Vec<u8> {
    let mut bytes = log::header(KIND, 0).to_vec();
    for record in records {
        log::encode_record(&[&encode(record)], &mut bytes);
    }
    bytes
}

/// The records of a journal file's bytes; damage is an error.
#[cfg(test)]
pub(crate) fn from_bytes(bytes: &[u8]) -> Result<Vec<Record>, JournalError> {
    let path = Path::new("(bytes)");
    match log::parse(bytes, KIND, path)? {
        None => Ok(Vec::new()),
        Some(contents) => match &contents.ending {
            Ending::Damaged(damage) => Err(JournalError::Damaged(damage.clone())),
            _ => decode(&contents, path),
        },
    }
}

/// The records of the journal at `path` and its copy, as a restart would
/// read them (without taking the journal or mending it).
pub fn read(path: &Path) -> Result<Vec<Record>, JournalError> {
    match log::read_copies(path, &copy_path(path), KIND)? {
        None => Ok(Vec::new()),
        Some(merged) => match &merged.contents.ending {
            Ending::Damaged(damage) => Err(JournalError::Damaged(damage.clone())),
            _ => decode(&merged.contents, path),
        },
    }
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

    /// A journal's path in a fresh folder, removed when the folder is
    /// dropped.
    fn path(name: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::Builder::new()
            .prefix("idmesh-sensor-journal-")
            .tempdir()
            .unwrap();
        let path = dir.path().join(name);
        (dir, path)
    }

    /// Where each record starts in a journal holding `records`.
    fn offsets(path: &Path) -> Vec<u64> {
        log::read(path, KIND)
            .unwrap()
            .unwrap()
            .records
            .iter()
            .map(|r| r.offset)
            .collect()
    }

    #[test]
    fn records_come_back_in_order_after_reopening_and_appending_goes_on() {
        let (_dir, path) = path("order");
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
        assert_eq!(std::fs::read(&path).unwrap(), to_bytes(&records()));
        assert_eq!(
            std::fs::read(copy_path(&path)).unwrap(),
            to_bytes(&records())
        );
        assert_eq!(read(&path).unwrap(), records());
    }

    /// A journal holding the named ids' numbers reads them back in
    /// order after reopening, and the records every earlier journal holds
    /// keep the bytes they were written with (a variant's index first),
    /// so those journals read as they did.
    #[test]
    fn track_ids_come_back_after_reopening_and_older_records_keep_their_bytes() {
        let (_dir, path) = path("track-ids");
        let (mut journal, _) = Journal::open(&path, "test").unwrap();
        let named = |first: u32, ids: &[&str]| Record::TrackIds {
            producer: "ros2:/tracker/detections".into(),
            first,
            ids: ids.iter().map(|id| id.to_string()).collect(),
        };
        let written = [
            named(0, &["walker", "cart"]),
            records()[2].clone(),
            named(2, &["c5e7f0a2-93b1-4d6e-8a40-1f2e3d4c5b6a"]),
            records()[2].clone(),
        ];
        journal.append(&written[..2]).unwrap();
        drop(journal);
        let (mut journal, old) = Journal::open(&path, "test").unwrap();
        assert_eq!(old, written[..2]);
        journal.append(&written[2..]).unwrap();
        drop(journal);
        assert_eq!(read(&path).unwrap(), written);
        // Records as an idmesh without `TrackIds` wrote them: variant
        // index, then fields (postcard).
        let earlier: [(&[u8], Record); 4] = [
            (&[0, 2, 9, 9], Record::Stream(vec![9, 9])),
            (&[6], Record::Flush),
            (&[7], Record::End),
            (&[8, 1, 5], Record::Unfollow(vec![5])),
        ];
        for (bytes, record) in earlier {
            assert_eq!(encode(&record), bytes, "{record:?}");
            assert_eq!(postcard::from_bytes::<Record>(bytes).unwrap(), record);
        }
        assert_eq!(encode(&named(0, &[]))[0], 11, "the last variant");
    }

    #[test]
    fn one_process_at_a_time_writes_a_journal_and_a_refusal_names_the_holder() {
        let (_dir, path) = path("owned");
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
    fn a_torn_tail_is_dropped_and_the_whole_records_before_it_kept() {
        let (_dir, path) = path("torn");
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        let full = to_bytes(&records());
        // The process died writing the last record: in the first copy,
        // half of it; the second not written at all.
        std::fs::write(&path, &full[..full.len() - 1]).unwrap();
        std::fs::write(copy_path(&path), to_bytes(&records()[..5])).unwrap();
        let (mut journal, old) = Journal::open(&path, "test").unwrap();
        assert_eq!(old, records()[..5]);
        assert_eq!(journal.repaired(), 0, "a torn tail is no damage");
        journal.append(&[Record::End]).unwrap();
        drop(journal);
        assert_eq!(std::fs::read(&path).unwrap(), full);
        assert_eq!(std::fs::read(copy_path(&path)).unwrap(), full);
    }

    #[test]
    fn a_record_damaged_in_one_copy_is_taken_from_the_other_and_both_made_whole() {
        let (_dir, path) = path("repaired");
        let (mut journal, _) = Journal::open(&path, "test").unwrap();
        journal.append(&records()).unwrap();
        drop(journal);
        // 32 bytes overwritten, across the third record and the fourth.
        let (third, fourth) = (offsets(&path)[2] as usize, offsets(&path)[3] as usize);
        assert!(third + 36 > fourth);
        let mut bytes = std::fs::read(&path).unwrap();
        bytes[third + 4..third + 36].fill(0);
        std::fs::write(&path, &bytes).unwrap();
        let (journal, old) = Journal::open(&path, "test").unwrap();
        assert_eq!(old, records());
        assert_eq!(journal.repaired(), 2);
        drop(journal);
        assert_eq!(std::fs::read(&path).unwrap(), to_bytes(&records()));
        assert_eq!(
            std::fs::read(copy_path(&path)).unwrap(),
            to_bytes(&records())
        );
    }

    #[test]
    fn a_record_damaged_in_both_copies_stops_the_sensor_naming_the_file_and_the_byte() {
        let (_dir, path) = path("damaged");
        let (mut journal, _) = Journal::open(&path, "test").unwrap();
        journal.append(&records()).unwrap();
        drop(journal);
        let at = offsets(&path)[2];
        for file in [path.clone(), copy_path(&path)] {
            let mut bytes = std::fs::read(&file).unwrap();
            bytes[at as usize + 13] ^= 0x08;
            std::fs::write(&file, &bytes).unwrap();
        }
        let before = std::fs::read(&path).unwrap();
        let error = Journal::open(&path, "test")
            .err()
            .expect("refused")
            .to_string();
        assert!(error.contains(&path.display().to_string()), "{error}");
        assert!(
            error.contains(&copy_path(&path).display().to_string()),
            "{error}"
        );
        assert!(error.contains(&format!("at byte {at}")), "{error}");
        assert!(error.contains("does not start"), "{error}");
        // Refused, not cut: the files are left for whoever looks into them.
        assert_eq!(std::fs::read(&path).unwrap(), before);
        // Without its copy, damage in the one file is the same.
        std::fs::remove_file(copy_path(&path)).unwrap();
        let error = Journal::open(&path, "test")
            .err()
            .expect("refused")
            .to_string();
        assert!(error.contains(&format!("at byte {at}")), "{error}");
    }

    #[test]
    fn compaction_replaces_both_copies_and_a_crash_between_them_keeps_the_newer() {
        let (_dir, path) = path("compacted");
        let (mut journal, _) = Journal::open(&path, "test").unwrap();
        journal.append(&records()).unwrap();
        let old = std::fs::read(copy_path(&path)).unwrap();
        journal.compact(&records()[..1]).unwrap();
        journal.append(&records()[5..]).unwrap();
        drop(journal);
        let compacted = vec![Record::Flush, Record::End];
        assert_eq!(Journal::open(&path, "test").unwrap().1, compacted);
        // Killed after the first file was replaced, before the second.
        std::fs::write(copy_path(&path), old).unwrap();
        assert_eq!(Journal::open(&path, "test").unwrap().1, compacted);
        assert_eq!(
            std::fs::read(copy_path(&path)).unwrap(),
            std::fs::read(&path).unwrap()
        );
    }

    #[test]
    fn a_journal_of_an_earlier_format_or_another_kind_is_refused_naming_it() {
        let (_dir, path) = path("old");
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, b"idmesh-sensor-journal/1\n\x01\0\0\0").unwrap();
        let error = Journal::open(&path, "test")
            .err()
            .expect("refused")
            .to_string();
        assert!(
            error.contains("old") && error.contains("earlier idmesh"),
            "{error}"
        );
        std::fs::write(&path, b"not a journal at all, long enough to be one").unwrap();
        let error = Journal::open(&path, "test")
            .err()
            .expect("refused")
            .to_string();
        assert!(error.contains("not an idmesh journal"), "{error}");
        assert_eq!(
            std::fs::read(&path).unwrap(),
            b"not a journal at all, long enough to be one"
        );
        // A record that checks but is no record of ours.
        log::write_file(&path, KIND, 0, &[[0xffu8; 3]]).unwrap();
        let _ = std::fs::remove_file(copy_path(&path));
        let error = Journal::open(&path, "test")
            .err()
            .expect("refused")
            .to_string();
        assert!(error.contains("corrupt at byte 40"), "{error}");
    }
}
