//! The leader's durable input log: every message the [`Leader`] state
//! machine is fed (stream batches, peers' transfers, follow replies) is
//! appended here, as the bytes that came off the wire, before it is applied.
//! The state machine is deterministic, so replaying the journal in order
//! rebuilds exactly the state the process had when it died, bit for bit —
//! the event log of the reliability issue, kept at the input rather than
//! the state so that no state needs a serialized form.
//!
//! Frame: kind (1 byte), length (u32, little-endian), the message. A crash
//! can tear only the last frame; [`Journal::open`] reads up to the last
//! whole frame and cuts the file there.
//!
//! Durability: every append is written to the file before the message is
//! applied, so a killed process (SIGKILL, a panic) loses nothing. It is
//! fsynced at most every [`JournalOptions::fsync_every`]: a power cut can
//! lose that window, which the restarted leader fetches again from the
//! sensor and its peers like anything else it missed (see the actor).
//!
//! [`Leader`]: crate::state::Leader

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
}

impl Kind {
    fn from_byte(b: u8) -> Option<Kind> {
        match b {
            1 => Some(Kind::Batch),
            2 => Some(Kind::Transfer),
            3 => Some(Kind::Followed),
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
    #[error("journal {path}: entry {entry} at byte {offset} has unknown kind {kind}")]
    Corrupt {
        path: String,
        entry: usize,
        offset: u64,
        kind: u8,
    },
}

/// An open journal, appending.
pub struct Journal {
    file: File,
    path: PathBuf,
    fsync_every: Duration,
    synced: Instant,
    dirty: bool,
}

/// Frames larger than this are not ours: a torn length, or garbage.
const MAX_FRAME: u32 = 1 << 30;

impl Journal {
    /// Opens (or creates) the journal and returns the entries already in
    /// it, in order; a torn last frame is cut off.
    pub fn open(options: &JournalOptions) -> Result<(Journal, Vec<Entry>), JournalError> {
        let path = options.path.clone();
        let io = |source| JournalError::Io {
            path: path.display().to_string(),
            source,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let mut file = OpenOptions::new()
            .read(true)
            .append(true)
            .create(true)
            .open(&path)
            .map_err(io)?;
        let (entries, whole) = read_entries(&mut file, &path)?;
        let length = file.metadata().map_err(io)?.len();
        if whole < length {
            tracing::warn!(journal = %path.display(), torn = length - whole, "cutting a torn last entry");
            file.set_len(whole).map_err(io)?;
        }
        file.seek(SeekFrom::End(0)).map_err(io)?;
        Ok((
            Journal {
                file,
                path,
                fsync_every: options.fsync_every,
                synced: Instant::now(),
                dirty: false,
            },
            entries,
        ))
    }

    /// Writes one entry through to the file (fsync per the policy).
    pub fn append(&mut self, kind: Kind, bytes: &[u8]) -> Result<(), JournalError> {
        let mut frame = Vec::with_capacity(5 + bytes.len());
        frame.push(kind as u8);
        frame.extend_from_slice(&(bytes.len() as u32).to_le_bytes());
        frame.extend_from_slice(bytes);
        self.file.write_all(&frame).map_err(|e| self.io(e))?;
        self.dirty = true;
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
        JournalOptions {
            path,
            fsync_every: Duration::from_millis(100),
        }
    }

    #[test]
    fn entries_come_back_in_order_after_reopening() {
        let options = options("order");
        let (mut journal, old) = Journal::open(&options).unwrap();
        assert!(old.is_empty());
        journal.append(Kind::Batch, b"first").unwrap();
        journal.append(Kind::Transfer, b"").unwrap();
        journal.append(Kind::Followed, &[7; 300]).unwrap();
        drop(journal);
        let (mut journal, entries) = Journal::open(&options).unwrap();
        let kinds: Vec<Kind> = entries.iter().map(|e| e.kind).collect();
        assert_eq!(kinds, [Kind::Batch, Kind::Transfer, Kind::Followed]);
        assert_eq!(entries[0].bytes, b"first");
        assert_eq!(entries[2].bytes.len(), 300);
        journal.append(Kind::Batch, b"fourth").unwrap();
        drop(journal);
        assert_eq!(Journal::open(&options).unwrap().1.len(), 4);
    }

    #[test]
    fn a_torn_last_entry_is_cut_off_and_appending_goes_on_after_the_last_whole_one() {
        let options = options("torn");
        let (mut journal, _) = Journal::open(&options).unwrap();
        journal.append(Kind::Batch, b"whole").unwrap();
        drop(journal);
        // A crash in the middle of the next write: a header and half a body.
        let mut file = OpenOptions::new().append(true).open(&options.path).unwrap();
        file.write_all(&[1, 10, 0, 0, 0, b'h', b'a']).unwrap();
        drop(file);
        let (mut journal, entries) = Journal::open(&options).unwrap();
        assert_eq!(entries.len(), 1);
        journal.append(Kind::Transfer, b"next").unwrap();
        drop(journal);
        let entries = Journal::open(&options).unwrap().1;
        assert_eq!(entries.len(), 2);
        assert_eq!(entries[1].bytes, b"next");
    }

    #[test]
    fn a_frame_of_unknown_kind_is_an_error_naming_where() {
        let options = options("corrupt");
        std::fs::create_dir_all(options.path.parent().unwrap()).unwrap();
        std::fs::write(&options.path, [9u8, 0, 0, 0, 0]).unwrap();
        let error = Journal::open(&options).err().expect("refused");
        assert!(error.to_string().contains("entry 0 at byte 0"), "{error}");
    }
}
