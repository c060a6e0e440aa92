//! The leader's durable state: a snapshot plus an input log. Every message
//! the [`Leader`] state machine is fed (stream batches, peers' transfers,
//! follow replies) is appended to the journal, as the bytes that came off
//! the wire, before it is applied. The state machine is deterministic, so
//! the snapshot plus the journal replayed in order rebuild exactly the
//! state the process had when it died.
//!
//! Frame: kind (1 byte), length (u32, little-endian), the message. A crash
//! can tear only the last frame; [`Journal::open`] reads up to the last
//! whole frame and cuts the file there.
//!
//! Compaction ([`Journal::compact`]): the whole state is written to
//! `<journal>.snapshot` (to a temporary file, fsynced, renamed over the
//! old one), then the journal starts again empty. Both carry a generation:
//! the journal's first frame names the snapshot it continues, so a crash
//! between the two steps leaves a journal whose entries are already in the
//! snapshot, and it is dropped rather than applied twice.
//!
//! Durability: every append is written to the file before the message is
//! applied, so a killed process (SIGKILL, a panic) loses nothing. It is
//! fsynced at most every [`JournalOptions::fsync_every`]: a power cut can
//! lose that window, which the restarted leader fetches again from the
//! sensor and its peers like anything else it missed (see the actor). The
//! leader tells the others how far it is safe only after an fsync.
//!
//! [`Leader`]: crate::state::Leader

use idmesh_ownership::{Ownership, OwnershipError};
use std::fs::{File, OpenOptions};
use std::io::{BufReader, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

/// What a journal entry holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A `Batch` of the event stream.
    Batch = 1,
    /// A peer's `Transfer`.
    Transfer = 2,
    /// The sensor's `Followed` reply.
    Followed = 3,
    /// The first frame: the generation of the snapshot this journal
    /// continues (u64, little-endian). Not an input.
    Generation = 4,
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
            4 => Some(Kind::Generation),
            5 => Some(Kind::Rejected),
            _ => None,
        }
    }
}

/// One input, as it came off the wire.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Entry {
    pub kind: Kind,
    pub bytes: Vec<u8>,
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JournalOptions {
    pub path: PathBuf,
    /// The longest a written entry waits for fsync.
    pub fsync_every: Duration,
}

#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    #[error("journal {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("snapshot {path}: {problem}")]
    Snapshot { path: String, problem: String },
    #[error(transparent)]
    Ownership(#[from] OwnershipError),
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
pub struct Journal {
    _owner: Ownership,
    file: File,
    path: PathBuf,
    fsync_every: Duration,
    synced: Instant,
    dirty: bool,
    /// The generation of the snapshot the entries continue (0: none).
    generation: u64,
    /// Entries appended since the snapshot.
    entries: usize,
}

/// What a journal held when it was opened.
#[derive(Debug, Default)]
pub struct Recovered {
    /// The state as of the last compaction, if there was one.
    pub snapshot: Option<Vec<u8>>,
    /// The inputs since, in order.
    pub entries: Vec<Entry>,
}

impl Recovered {
    pub fn is_empty(&self) -> bool {
        self.snapshot.is_none() && self.entries.is_empty()
    }
}

/// Frames larger than this are not ours: a torn length, or garbage.
const MAX_FRAME: u32 = 1 << 30;

/// The first bytes of a snapshot file.
const SNAPSHOT_MAGIC: &[u8; 8] = b"idmesh/1";

impl Journal {
    /// Opens (or creates) the journal `owner` was granted and returns the
    /// snapshot and the entries after it, in order; a torn last frame is
    /// cut off.
    pub fn open(
        options: &JournalOptions,
        owner: Ownership,
    ) -> Result<(Journal, Recovered), JournalError> {
        let path = options.path.clone();
        let io = |source| JournalError::Io {
            path: path.display().to_string(),
            source,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let (generation, snapshot) = match read_snapshot(&snapshot_path(&path))? {
            Some((generation, bytes)) => (generation, Some(bytes)),
            None => (0, None),
        };
        let mut file = OpenOptions::new()
            .read(true)
            .append(true)
            .create(true)
            .open(&path)
            .map_err(io)?;
        let (mut entries, whole) = read_entries(&mut file, &path)?;
        let length = file.metadata().map_err(io)?.len();
        if whole < length {
            tracing::warn!(journal = %path.display(), torn = length - whole, "cutting a torn last entry");
            file.set_len(whole).map_err(io)?;
        }
        let continues = if entries.first().is_some_and(|e| e.kind == Kind::Generation) {
            generation_of(&entries.remove(0).bytes)
        } else {
            0
        };
        file.seek(SeekFrom::End(0)).map_err(io)?;
        let mut journal = Journal {
            _owner: owner,
            file,
            path: path.clone(),
            fsync_every: options.fsync_every,
            synced: Instant::now(),
            dirty: false,
            generation,
            entries: entries.len(),
        };
        if continues > generation {
            return Err(JournalError::Snapshot {
                path: snapshot_path(&path).display().to_string(),
                problem: format!(
                    "the journal continues snapshot {continues}, but the snapshot is {generation}"
                ),
            });
        }
        if continues < generation || length == 0 {
            // A crash between writing a snapshot and starting the journal
            // again: its entries are in the snapshot. Or a new journal.
            if continues < generation {
                tracing::info!(journal = %path.display(), entries = entries.len(), "entries already in the snapshot are dropped");
            }
            entries.clear();
            journal.restart()?;
        }
        Ok((journal, Recovered { snapshot, entries }))
    }

    /// Inputs appended since the last snapshot.
    pub fn entries(&self) -> usize {
        self.entries
    }

    /// Writes `state` (the whole leader, as of every entry appended) as
    /// the new snapshot and starts the journal again empty.
    pub fn compact(&mut self, state: &[u8]) -> Result<(), JournalError> {
        let next = self.generation + 1;
        let target = snapshot_path(&self.path);
        let mut body = Vec::with_capacity(16 + state.len());
        body.extend_from_slice(SNAPSHOT_MAGIC);
        body.extend_from_slice(&next.to_le_bytes());
        body.extend_from_slice(state);
        write_durably(&target, &body).map_err(|e| self.io(e))?;
        self.generation = next;
        self.restart()
    }

    /// Replaces the journal with one that holds only its generation frame.
    fn restart(&mut self) -> Result<(), JournalError> {
        let mut frame = vec![Kind::Generation as u8];
        frame.extend_from_slice(&8u32.to_le_bytes());
        frame.extend_from_slice(&self.generation.to_le_bytes());
        write_durably(&self.path, &frame).map_err(|e| self.io(e))?;
        self.file = OpenOptions::new()
            .append(true)
            .open(&self.path)
            .map_err(|e| self.io(e))?;
        self.entries = 0;
        self.dirty = false;
        self.synced = Instant::now();
        Ok(())
    }

    /// Writes one entry through to the file (fsync per the policy).
    pub fn append(&mut self, kind: Kind, bytes: &[u8]) -> Result<(), JournalError> {
        let mut frame = Vec::with_capacity(5 + bytes.len());
        frame.push(kind as u8);
        frame.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
        frame.extend_from_slice(bytes);
        self.file.write_all(&frame).map_err(|e| self.io(e))?;
        self.dirty = true;
        self.entries += 1;
        if self.synced.elapsed() >= self.fsync_every {
            self.sync()?;
        }
        Ok(())
    }

    /// fsyncs what was written since the last sync.
    pub fn sync(&mut self) -> Result<(), JournalError> {
        if self.dirty {
            self.file.sync_data().map_err(|e| self.io(e))?;
            self.dirty = false;
        }
        self.synced = Instant::now();
        Ok(())
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    fn io(&self, source: std::io::Error) -> JournalError {
        JournalError::Io {
            path: self.path.display().to_string(),
            source,
        }
    }
}

/// The whole entries from the start of `file`, and the byte where they end.
fn read_entries(file: &mut File, path: &Path) -> Result<(Vec<Entry>, u64), JournalError> {
    let io = |source| JournalError::Io {
        path: path.display().to_string(),
        source,
    };
    file.seek(SeekFrom::Start(0)).map_err(io)?;
    let mut reader = BufReader::new(&mut *file);
    let mut entries = Vec::new();
    let mut whole = 0u64;
    loop {
        let mut head = [0u8; 5];
        match read_full(&mut reader, &mut head).map_err(io)? {
            Filled::Full => {}
            Filled::Short => break,
        }
        let Some(kind) = Kind::from_byte(head[0]) else {
            return Err(JournalError::Corrupt {
                path: path.display().to_string(),
                entry: entries.len(),
                offset: whole,
                kind: head[0],
            });
        };
        let length = u32::from_le_bytes([head[1], head[2], head[3], head[4]]);
        if length > MAX_FRAME {
            break;
        }
        let mut bytes = vec![0u8; length as usize];
        match read_full(&mut reader, &mut bytes).map_err(io)? {
            Filled::Full => {}
            Filled::Short => break,
        }
        whole += 5 + length as u64;
        entries.push(Entry { kind, bytes });
    }
    Ok((entries, whole))
}

fn snapshot_path(journal: &Path) -> PathBuf {
    let mut name = journal.as_os_str().to_owned();
    name.push(".snapshot");
    PathBuf::from(name)
}

fn generation_of(bytes: &[u8]) -> u64 {
    bytes.try_into().map(u64::from_le_bytes).unwrap_or_default()
}

/// The snapshot's generation and state, if there is one.
fn read_snapshot(path: &Path) -> Result<Option<(u64, Vec<u8>)>, JournalError> {
    let bytes = match std::fs::read(path) {
        Ok(bytes) => bytes,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => {
            return Err(JournalError::Io {
                path: path.display().to_string(),
                source,
            })
        }
    };
    if bytes.len() < 16 || &bytes[..8] != SNAPSHOT_MAGIC {
        return Err(JournalError::Snapshot {
            path: path.display().to_string(),
            problem: "not an idmesh snapshot (bad header)".into(),
        });
    }
    Ok(Some((generation_of(&bytes[8..16]), bytes[16..].to_vec())))
}

/// Writes `body` to `path` so that a crash leaves the old file or the new
/// one, whole: a temporary file, fsynced, renamed over, the folder fsynced.
fn write_durably(path: &Path, body: &[u8]) -> std::io::Result<()> {
    let mut temporary = path.as_os_str().to_owned();
    temporary.push(".tmp");
    let temporary = PathBuf::from(temporary);
    let mut file = File::create(&temporary)?;
    file.write_all(body)?;
    file.sync_all()?;
    std::fs::rename(&temporary, path)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        File::open(dir)?.sync_all()?;
    }
    Ok(())
}

enum Filled {
    Full,
    /// The file ended first (a torn frame, or the clean end at 0 bytes).
    Short,
}

fn read_full(reader: &mut impl Read, buffer: &mut [u8]) -> std::io::Result<Filled> {
    let mut filled = 0;
    while filled < buffer.len() {
        match reader.read(&mut buffer[filled..])? {
            0 => return Ok(Filled::Short),
            n => filled += n,
        }
    }
    Ok(Filled::Full)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options(name: &str) -> JournalOptions {
        let dir = std::env::temp_dir().join(format!("idmesh-journal-{}", std::process::id()));
        let path = dir.join(name);
        let _ = std::fs::remove_file(&path);
        let _ = std::fs::remove_file(snapshot_path(&path));
        JournalOptions {
            path,
            fsync_every: Duration::from_millis(100),
        }
    }

    /// Opens as the one owner (an earlier journal on the path must be
    /// dropped first, as a process that stopped).
    fn open(options: &JournalOptions) -> Result<(Journal, Recovered), JournalError> {
        let owner = Ownership::try_take(&options.path, "a test")?
            .expect("the journal's previous opener let go of it");
        Journal::open(options, owner)
    }

    #[test]
    fn entries_come_back_in_order_after_reopening() {
        let options = options("order");
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
        let options = options("torn");
        let (mut journal, _) = open(&options).unwrap();
        journal.append(Kind::Batch, b"whole").unwrap();
        drop(journal);
        // A crash in the middle of the next write: a header and half a body.
        let mut file = OpenOptions::new().append(true).open(&options.path).unwrap();
        file.write_all(&[1, 10, 0, 0, 0, b'h', b'a']).unwrap();
        drop(file);
        let (mut journal, Recovered { entries, .. }) = open(&options).unwrap();
        assert_eq!(entries.len(), 1);
        journal.append(Kind::Transfer, b"next").unwrap();
        drop(journal);
        let entries = open(&options).unwrap().1.entries;
        assert_eq!(entries.len(), 2);
        assert_eq!(entries[1].bytes, b"next");
    }

    #[test]
    fn a_frame_of_unknown_kind_is_an_error_naming_where() {
        let options = options("corrupt");
        std::fs::create_dir_all(options.path.parent().unwrap()).unwrap();
        std::fs::write(&options.path, [9u8, 0, 0, 0, 0]).unwrap();
        let error = open(&options).err().expect("refused");
        assert!(error.to_string().contains("entry 0 at byte 0"), "{error}");
    }

    #[test]
    fn a_snapshot_replaces_the_entries_before_it() {
        let options = options("compact");
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
        let options = options("between");
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
    fn a_snapshot_that_is_not_ours_is_an_error_naming_it() {
        let options = options("foreign");
        std::fs::create_dir_all(options.path.parent().unwrap()).unwrap();
        std::fs::write(snapshot_path(&options.path), b"garbage").unwrap();
        let error = open(&options).err().expect("refused");
        assert!(error.to_string().contains("foreign.snapshot"), "{error}");
        assert!(error.to_string().contains("bad header"), "{error}");
    }
}
