//! The leader's durable state: a snapshot plus an input log. Every message
//! the [`Leader`] state machine is fed (stream batches, peers' transfers,
//! follow replies) is appended to the journal, as the bytes that came off
//! the wire, before it is applied. The state machine is deterministic, so
//! the snapshot plus the journal replayed in order rebuild exactly the
//! state the process had when it died.
//!
//! Both files are `idmesh-journal` logs (a checksummed header, checksummed
//! records): the journal (`leader-journal`) holds one record per input —
//! its [`Kind`] byte, then the message — and the snapshot
//! (`<journal>.snapshot`, `leader-snapshot`) one record, the whole state.
//!
//! Compaction ([`Journal::compact`]): the state is written as the new
//! snapshot (a file beside it, fsynced, renamed over the old one), then the
//! journal starts again empty. Both carry a generation in their header:
//! the journal's names the snapshot it continues, so a crash between the
//! two steps leaves a journal whose entries are already in the snapshot,
//! and it is dropped rather than applied twice.
//!
//! Durability: every append is written to the file before the message is
//! applied, so a killed process (SIGKILL, a panic) loses nothing. It is
//! fsynced at most every [`JournalOptions::fsync_every`]: a power cut can
//! lose that window.
//!
//! Damage ([`Journal::open`]): a torn last record (the process or the
//! machine died writing it) is cut off. A record that does not check with
//! whole records after it — bytes changed since they were written, a
//! damaged header — is logged as an error with the file and the byte, the
//! file is saved beside the journal (`<journal>.damaged`), and the journal
//! is cut at that record: the leader comes back from its snapshot and the
//! inputs before the damage ([`Recovered::damage`] says what was lost) and
//! fetches the rest again from the sensor and its peers, as after a power
//! cut. Nothing it drops can have been forgotten by them: a leader's
//! durable mark, which lets them forget, advances only when a snapshot is
//! written ([`crate::machine`]). A damaged snapshot is not recoverable so
//! (the others forgot what it replaced) and is an error naming it.
//!
//! [`Leader`]: crate::state::Leader

use idmesh_journal::{self as log, Damage, Ending, Problem, Writer};
use idmesh_ownership::{Ownership, OwnershipError};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// What the journal's header says it holds.
pub const JOURNAL: &str = "leader-journal";
/// What the snapshot's header says it holds.
pub const SNAPSHOT: &str = "leader-snapshot";

/// What a journal entry holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A `Batch` of the event stream.
    Batch = 1,
    /// A peer's `Transfer`.
    Transfer = 2,
    /// The sensor's `Followed` reply.
    Followed = 3,
    /// An input refused at the door (empty): not applied, only counted,
    /// so that `rejected` does not restart from 0 after a restart.
    Rejected = 5,
}

impl Kind {
    fn from_byte(b: u8) -> Option<Kind> {
        match b {
            1 => Some(Kind::Batch),
            2 => Some(Kind::Transfer),
            3 => Some(Kind::Followed),
            5 => Some(Kind::Rejected),
            _ => None,
        }
    }
}

/// One input, as it came off the wire.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Entry {
    pub kind: Kind,
    pub bytes: Vec<u8>,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct JournalOptions {
    pub path: PathBuf,
    /// The longest a written entry waits for fsync.
    pub fsync_every: Duration,
}

#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    #[error(transparent)]
    Log(#[from] log::Error),
    #[error("snapshot {path}: {problem}")]
    Snapshot { path: String, problem: String },
    #[error(transparent)]
    Ownership(#[from] OwnershipError),
    /// A record that checks but is no input (written by something else).
    #[error("journal {path}: entry {entry} at byte {offset} has unknown kind {kind}")]
    Corrupt {
        path: String,
        entry: usize,
        offset: u64,
        kind: u8,
    },
}

/// An open journal, appending. It holds the role's [`Ownership`] for as
/// long as it is open: one writer per journal, whatever the network says.
pub(crate) struct Journal {
    _owner: Ownership,
    writer: Writer,
    path: PathBuf,
    fsync_every: Duration,
    synced: Instant,
    /// The generation of the snapshot the entries continue (0: none).
    generation: u64,
    /// Entries appended since the snapshot.
    entries: usize,
}

/// What a journal held when it was opened.
#[derive(Debug, Default)]
pub(crate) struct Recovered {
    /// The state as of the last compaction, if there was one.
    pub snapshot: Option<Vec<u8>>,
    /// The inputs since, in order (up to the damage, if any).
    pub entries: Vec<Entry>,
    /// The journal was damaged: what was dropped with the damaged record.
    pub damage: Option<Damage>,
}

impl Recovered {
    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.snapshot.is_none() && self.entries.is_empty()
    }
}

impl Journal {
    /// Opens (or creates) the journal `owner` was granted and returns the
    /// snapshot and the entries after it, in order; a torn last record is
    /// cut off, and so is a damaged one with everything after it (see the
    /// module's doc).
    pub(crate) fn open(
        options: &JournalOptions,
        owner: Ownership,
    ) -> Result<(Journal, Recovered), JournalError> {
        let path = options.path.clone();
        let (generation, snapshot) = match read_snapshot(&snapshot_path(&path))? {
            Some((generation, bytes)) => (generation, Some(bytes)),
            None => (0, None),
        };
        let (continues, records, end, mut damage) = match log::read(&path, JOURNAL) {
            Ok(None) => (generation, Vec::new(), None, None),
            Ok(Some(contents)) => {
                let end = contents.end();
                let damage = match contents.ending {
                    Ending::Clean => None,
                    Ending::Torn { at, bytes } => {
                        tracing::warn!(journal = %path.display(), at, torn = bytes, "cutting a torn last entry");
                        None
                    }
                    Ending::Damaged(damage) => Some(damage),
                };
                (contents.generation, contents.records, Some(end), damage)
            }
            // Which snapshot the entries continue is unknown: all of them
            // are dropped, as damaged.
            Err(log::Error::Header { .. }) => {
                let bytes = std::fs::metadata(&path).map_or(0, |m| m.len());
                let damage = Damage {
                    path: path.clone(),
                    copy: None,
                    at: 0,
                    problem: Problem::Header,
                    after: 0,
                    bytes,
                };
                (generation, Vec::new(), None, Some(damage))
            }
            Err(e) => return Err(e.into()),
        };
        if continues > generation {
            return Err(JournalError::Snapshot {
                path: snapshot_path(&path).display().to_string(),
                problem: format!(
                    "the journal continues snapshot {continues}, but the snapshot is {generation}"
                ),
            });
        }
        let mut entries = Vec::with_capacity(records.len());
        for (i, record) in records.into_iter().enumerate() {
            let mut bytes = record.payload;
            let kind = bytes.first().copied().unwrap_or(0);
            let Some(kind) = Kind::from_byte(kind) else {
                return Err(JournalError::Corrupt {
                    path: path.display().to_string(),
                    entry: i,
                    offset: record.offset,
                    kind,
                });
            };
            bytes.remove(0);
            entries.push(Entry { kind, bytes });
        }
        if continues < generation {
            // A crash between writing a snapshot and starting the journal
            // again: its entries, damaged or not, are in the snapshot.
            tracing::info!(journal = %path.display(), entries = entries.len(), "entries already in the snapshot are dropped");
            entries.clear();
            damage = None;
        }
        if let Some(damage) = &damage {
            let saved = keep_damaged(&path);
            tracing::error!(journal = %path.display(), at = damage.at, problem = %damage.problem,
                lost = damage.records(), kept = entries.len(), saved = %saved,
                "the journal is damaged: replaying what comes before the damage; the rest is fetched again from the sensor and the peers");
        }
        let writer = match end {
            Some(end) if continues == generation && damage.as_ref().is_none_or(|d| d.at > 0) => {
                Writer::resume(&[&path], JOURNAL, end)?
            }
            // New, superseded by the snapshot, or unreadable from its
            // header: started again.
            _ => Writer::create::<&[u8]>(&[&path], JOURNAL, generation, &[])?,
        };
        let journal = Journal {
            _owner: owner,
            writer,
            path,
            fsync_every: options.fsync_every,
            synced: Instant::now(),
            generation,
            entries: entries.len(),
        };
        Ok((
            journal,
            Recovered {
                snapshot,
                entries,
                damage,
            },
        ))
    }

    /// Inputs appended since the last snapshot.
    #[cfg(test)]
    pub(crate) fn entries(&self) -> usize {
        self.entries
    }

    /// Writes `state` (the whole leader, as of every entry appended) as
    /// the new snapshot and starts the journal again empty.
    pub(crate) fn compact(&mut self, state: &[u8]) -> Result<(), JournalError> {
        let next = self.generation + 1;
        log::write_file(&snapshot_path(&self.path), SNAPSHOT, next, &[state])?;
        self.generation = next;
        self.writer.replace::<&[u8]>(next, &[])?;
        self.entries = 0;
        self.synced = Instant::now();
        Ok(())
    }

    /// Writes one entry through to the file (fsync per the policy).
    pub(crate) fn append(&mut self, kind: Kind, bytes: &[u8]) -> Result<(), JournalError> {
        self.writer.append(&[&[kind as u8], bytes])?;
        self.entries += 1;
        if self.synced.elapsed() >= self.fsync_every {
            self.sync()?;
        }
        Ok(())
    }

    /// fsyncs what was written since the last sync.
    pub(crate) fn sync(&mut self) -> Result<(), JournalError> {
        self.writer.sync()?;
        self.synced = Instant::now();
        Ok(())
    }
}

/// Where the snapshot of the journal at `journal` is.
pub(crate) fn snapshot_path(journal: &Path) -> PathBuf {
    with_suffix(journal, ".snapshot")
}

fn with_suffix(path: &Path, suffix: &str) -> PathBuf {
    let mut name = path.as_os_str().to_owned();
    name.push(suffix);
    PathBuf::from(name)
}

/// Copies a damaged journal beside it, for whoever looks into it, before
/// it is cut; says where (or why not).
fn keep_damaged(path: &Path) -> String {
    let saved = with_suffix(path, ".damaged");
    match std::fs::copy(path, &saved) {
        Ok(_) => saved.display().to_string(),
        Err(e) => format!("not saved: {e}"),
    }
}

/// The snapshot's generation and state, if there is one.
/// A one-file log of `kind` (a snapshot, a standby copy) read whole; a
/// damaged header is refused through `refused`, naming byte 0.
pub(crate) fn read_whole<E: From<log::Error>>(
    path: &Path,
    kind: &'static str,
    refused: impl Fn(String) -> E,
) -> Result<Option<log::Contents>, E> {
    match log::read(path, kind) {
        Ok(contents) => Ok(contents),
        Err(log::Error::Header { .. }) => Err(refused(
            "damaged at byte 0 (its header fails its checksum)".into(),
        )),
        Err(e) => Err(e.into()),
    }
}

fn read_snapshot(path: &Path) -> Result<Option<(u64, Vec<u8>)>, JournalError> {
    let refused = |problem: String| JournalError::Snapshot {
        path: path.display().to_string(),
        problem: format!(
            "{problem}: the role's state cannot be rebuilt from it (the sensor and the peers kept \
             only what came after it); restore it from a backup, or remove the deployment's state \
             directory to start the stream again from its beginning"
        ),
    };
    let Some(contents) = read_whole(path, SNAPSHOT, refused)? else {
        return Ok(None);
    };
    match (&contents.ending, &contents.records[..]) {
        (Ending::Clean, [state]) => Ok(Some((contents.generation, state.payload.clone()))),
        (Ending::Clean, records) => Err(refused(format!(
            "{} records where a snapshot has one",
            records.len()
        ))),
        (Ending::Torn { at, .. }, _) => Err(refused(format!("damaged or cut short at byte {at}"))),
        (Ending::Damaged(damage), _) => Err(refused(format!(
            "damaged at byte {} ({})",
            damage.at, damage.problem
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A journal's options in a fresh folder, removed when the folder is
    /// dropped.
    fn options(name: &str) -> (tempfile::TempDir, JournalOptions) {
        let dir = tempfile::Builder::new()
            .prefix("idmesh-journal-")
            .tempdir()
            .unwrap();
        let path = dir.path().join(name);
        let options = JournalOptions {
            path,
            fsync_every: Duration::from_millis(100),
        };
        (dir, options)
    }

    /// Opens as the one owner (an earlier journal on the path must be
    /// dropped first, as a process that stopped).
    fn open(options: &JournalOptions) -> Result<(Journal, Recovered), JournalError> {
        let owner = Ownership::try_take(&options.path, "a test")?
            .expect("the journal's previous opener let go of it");
        Journal::open(options, owner)
    }

    /// Where each entry's record starts in the journal's file.
    fn offsets(path: &Path) -> Vec<u64> {
        log::read(path, JOURNAL)
            .unwrap()
            .unwrap()
            .records
            .iter()
            .map(|r| r.offset)
            .collect()
    }

    #[test]
    fn entries_come_back_in_order_after_reopening() {
        let (_dir, options) = options("order");
        let (mut journal, old) = open(&options).unwrap();
        assert!(old.is_empty());
        let _ = std::fs::remove_file(snapshot_path(&options.path));
        journal.append(Kind::Batch, b"first").unwrap();
        journal.append(Kind::Transfer, b"").unwrap();
        journal.append(Kind::Followed, &[7; 300]).unwrap();
        drop(journal);
        let (mut journal, Recovered { entries, .. }) = open(&options).unwrap();
        let kinds: Vec<Kind> = entries.iter().map(|e| e.kind).collect();
        assert_eq!(kinds, [Kind::Batch, Kind::Transfer, Kind::Followed]);
        assert_eq!(entries[0].bytes, b"first");
        assert_eq!(entries[2].bytes.len(), 300);
        journal.append(Kind::Batch, b"fourth").unwrap();
        drop(journal);
        assert_eq!(open(&options).unwrap().1.entries.len(), 4);
    }

    #[test]
    fn a_torn_last_entry_is_cut_off_and_appending_goes_on_after_the_last_whole_one() {
        let (_dir, options) = options("torn");
        let (mut journal, _) = open(&options).unwrap();
        journal.append(Kind::Batch, b"whole").unwrap();
        journal.append(Kind::Batch, b"half written").unwrap();
        drop(journal);
        // A crash in the middle of the last write: a head and half a body.
        let length = std::fs::metadata(&options.path).unwrap().len();
        let file = std::fs::OpenOptions::new()
            .write(true)
            .open(&options.path)
            .unwrap();
        file.set_len(length - 6).unwrap();
        drop(file);
        let (mut journal, recovered) = open(&options).unwrap();
        assert_eq!(recovered.entries.len(), 1);
        assert!(recovered.damage.is_none(), "a torn tail is no damage");
        journal.append(Kind::Transfer, b"next").unwrap();
        drop(journal);
        let entries = open(&options).unwrap().1.entries;
        assert_eq!(entries.len(), 2);
        assert_eq!(entries[1].bytes, b"next");
    }

    #[test]
    fn a_damaged_entry_is_dropped_with_everything_after_it_and_reported() {
        let (_dir, options) = options("damaged");
        let (mut journal, _) = open(&options).unwrap();
        for i in 0..6u8 {
            journal.append(Kind::Batch, &[i; 40]).unwrap();
        }
        drop(journal);
        let at = offsets(&options.path)[2];
        // 32 bytes overwritten in the middle of the third entry.
        let mut bytes = std::fs::read(&options.path).unwrap();
        bytes[at as usize + 8..at as usize + 40].fill(0x5a);
        std::fs::write(&options.path, &bytes).unwrap();
        let (mut journal, recovered) = open(&options).unwrap();
        let kept: Vec<u8> = recovered.entries.iter().map(|e| e.bytes[0]).collect();
        assert_eq!(kept, [0, 1], "the entries before the damage, none after");
        let damage = recovered.damage.expect("reported");
        assert_eq!((damage.at, damage.after, damage.records()), (at, 3, 4));
        assert!(damage.to_string().contains("damaged at byte"), "{damage}");
        // Saved as found, then cut: the next entry goes after the kept ones.
        assert_eq!(
            std::fs::read(with_suffix(&options.path, ".damaged")).unwrap(),
            bytes
        );
        journal.append(Kind::Transfer, b"next").unwrap();
        drop(journal);
        let recovered = open(&options).unwrap().1;
        assert!(recovered.damage.is_none());
        assert_eq!(recovered.entries.len(), 3);
        assert_eq!(recovered.entries[2].bytes, b"next");

        // A damaged header: which snapshot it continues is unknown, so
        // everything after the snapshot is dropped.
        let mut bytes = std::fs::read(&options.path).unwrap();
        bytes[20] ^= 1;
        std::fs::write(&options.path, &bytes).unwrap();
        let (_, recovered) = open(&options).unwrap();
        assert!(recovered.entries.is_empty());
        let damage = recovered.damage.expect("reported");
        assert_eq!((damage.at, damage.problem), (0, Problem::Header));
    }

    #[test]
    fn a_record_of_unknown_kind_is_an_error_naming_where() {
        let (_dir, options) = options("corrupt");
        let (journal, _) = open(&options).unwrap();
        drop(journal);
        let mut writer = Writer::resume(
            &[&options.path],
            JOURNAL,
            std::fs::metadata(&options.path).unwrap().len(),
        )
        .unwrap();
        writer.append(&[&[9u8]]).unwrap();
        drop(writer);
        let error = open(&options).err().expect("refused");
        assert!(error.to_string().contains("entry 0 at byte 40"), "{error}");
    }

    #[test]
    fn a_snapshot_replaces_the_entries_before_it() {
        let (_dir, options) = options("compact");
        let (mut journal, _) = open(&options).unwrap();
        journal.append(Kind::Batch, b"one").unwrap();
        journal.append(Kind::Batch, b"two").unwrap();
        journal.compact(b"state after two").unwrap();
        assert_eq!(journal.entries(), 0);
        journal.append(Kind::Transfer, b"three").unwrap();
        drop(journal);
        let (mut journal, recovered) = open(&options).unwrap();
        assert_eq!(recovered.snapshot.as_deref(), Some(&b"state after two"[..]));
        assert_eq!(recovered.entries.len(), 1);
        assert_eq!(recovered.entries[0].bytes, b"three");
        // A second compaction, then more: still only what came after.
        journal.compact(b"state after three").unwrap();
        journal.append(Kind::Batch, b"four").unwrap();
        drop(journal);
        let (_, recovered) = open(&options).unwrap();
        assert_eq!(
            recovered.snapshot.as_deref(),
            Some(&b"state after three"[..])
        );
        let bytes: Vec<&[u8]> = recovered.entries.iter().map(|e| &e.bytes[..]).collect();
        assert_eq!(bytes, [&b"four"[..]]);
    }

    #[test]
    fn a_crash_between_snapshot_and_new_journal_applies_nothing_twice() {
        let (_dir, options) = options("between");
        let (mut journal, _) = open(&options).unwrap();
        journal.append(Kind::Batch, b"one").unwrap();
        journal.append(Kind::Batch, b"two").unwrap();
        let before = std::fs::read(&options.path).unwrap();
        journal.compact(b"state after two").unwrap();
        drop(journal);
        // The journal as it was: the crash came before it started again.
        std::fs::write(&options.path, before).unwrap();
        let (mut journal, recovered) = open(&options).unwrap();
        assert_eq!(recovered.snapshot.as_deref(), Some(&b"state after two"[..]));
        assert!(
            recovered.entries.is_empty(),
            "one and two are in the snapshot"
        );
        journal.append(Kind::Batch, b"three").unwrap();
        drop(journal);
        assert_eq!(open(&options).unwrap().1.entries.len(), 1);
    }

    #[test]
    fn a_snapshot_that_is_not_ours_or_is_damaged_is_an_error_naming_it() {
        let (_dir, options) = options("foreign");
        std::fs::create_dir_all(options.path.parent().unwrap()).unwrap();
        std::fs::write(
            snapshot_path(&options.path),
            b"garbage, long enough to be a header of ours",
        )
        .unwrap();
        let error = open(&options).err().expect("refused").to_string();
        assert!(error.contains("foreign.snapshot"), "{error}");
        assert!(error.contains("not an idmesh journal"), "{error}");

        let (mut journal, _) = {
            std::fs::remove_file(snapshot_path(&options.path)).unwrap();
            open(&options).unwrap()
        };
        journal.compact(&[3; 100]).unwrap();
        drop(journal);
        let mut bytes = std::fs::read(snapshot_path(&options.path)).unwrap();
        bytes[80] ^= 0x04;
        std::fs::write(snapshot_path(&options.path), bytes).unwrap();
        let error = open(&options).err().expect("refused").to_string();
        assert!(error.contains("foreign.snapshot"), "{error}");
        assert!(error.contains("at byte 40"), "{error}");
        assert!(error.contains("cannot be rebuilt"), "{error}");
    }

    #[test]
    fn files_of_the_format_before_checksums_are_refused_saying_what_to_do() {
        let (_dir, options) = options("old");
        std::fs::create_dir_all(options.path.parent().unwrap()).unwrap();
        // The old journal's first frame: its snapshot's generation.
        let mut old = vec![4u8, 8, 0, 0, 0];
        old.extend_from_slice(&0u64.to_le_bytes());
        old.extend_from_slice(&[1, 3, 0, 0, 0, b'a', b'b', b'c']);
        std::fs::write(&options.path, &old).unwrap();
        let error = open(&options).err().expect("refused").to_string();
        assert!(error.contains("old"), "{error}");
        assert!(error.contains("earlier idmesh"), "{error}");
        assert!(
            error.contains("remove the deployment's state directory"),
            "{error}"
        );
        // Left as it was.
        assert_eq!(std::fs::read(&options.path).unwrap(), old);
    }
}
