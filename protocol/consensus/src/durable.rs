//! A voter's log on disk: the entries and hard state its [`Voter`] asked
//! to persist ([`Ready::persist`]), appended to one record log
//! (`idmesh-journal`, kind [`KIND`]) and fsynced before the step's
//! messages leave. Reopened after a crash, it gives back the `MemStorage`
//! the voter had: the entries replayed in the order they were stored
//! (a later append replaces an earlier one's conflicting tail, as Raft
//! asks), and the last hard state.
//!
//! What the journal says about its ends holds here: a record torn by a
//! crash was never acted on (its step's messages had not left), so it is
//! cut off; a record damaged under whole ones is an error naming the file
//! and the byte — a voter that lost part of its log must not vote on it.
//!
//! The log is never compacted: its entries are claims and releases of
//! roles, a few per takeover.
//!
//! [`Voter`]: crate::Voter
//! [`Ready::persist`]: crate::Ready

use crate::voter::Persist;
use idmesh_journal::{Ending, Writer};
use raft::eraftpb::{Entry, EntryType, HardState};
use raft::storage::MemStorage;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What the log file holds (its header names it).
pub const KIND: &str = "raft-log";

#[derive(Debug, thiserror::Error)]
pub enum DurableError {
    #[error(transparent)]
    Journal(#[from] idmesh_journal::Error),
    #[error("{path}: the record at byte {offset} is not a raft log record: {source}")]
    Record {
        path: PathBuf,
        offset: u64,
        source: postcard::Error,
    },
    #[error("{path}: the record at byte {offset} cannot be stored: {source}")]
    Store {
        path: PathBuf,
        offset: u64,
        source: raft::Error,
    },
    #[error("a record that does not encode: {0}")]
    Encode(postcard::Error),
}

/// One record of the log.
#[derive(Debug, Serialize, Deserialize)]
enum LogRecord {
    /// Entries, replacing any stored from the first one's index on.
    Entries(Vec<StoredEntry>),
    /// The hard state after a step.
    HardState { term: u64, vote: u64, commit: u64 },
}

/// An entry's fields, as stored.
#[derive(Debug, Serialize, Deserialize)]
struct StoredEntry {
    kind: u8,
    term: u64,
    index: u64,
    data: Vec<u8>,
    context: Vec<u8>,
}

impl StoredEntry {
    fn of(entry: &Entry) -> Self {
        StoredEntry {
            kind: match entry.get_entry_type() {
                EntryType::EntryNormal => 0,
                EntryType::EntryConfChange => 1,
                EntryType::EntryConfChangeV2 => 2,
            },
            term: entry.term,
            index: entry.index,
            data: entry.data.to_vec(),
            context: entry.context.to_vec(),
        }
    }

    fn entry(self) -> Entry {
        Entry {
            entry_type: match self.kind {
                1 => EntryType::EntryConfChange,
                2 => EntryType::EntryConfChangeV2,
                _ => EntryType::EntryNormal,
            },
            term: self.term,
            index: self.index,
            data: self.data.into(),
            context: self.context.into(),
            ..Entry::default()
        }
    }
}

/// A voter's log file, open for appending.
pub struct DurableLog {
    writer: Writer,
}

impl DurableLog {
    /// Opens the log at `path` (a new one, for a group of `voters`, if
    /// there is none) and returns it with the storage it holds.
    pub fn open(path: &Path, voters: &[u64]) -> Result<(DurableLog, MemStorage), DurableError> {
        let storage = MemStorage::new_with_conf_state((voters.to_vec(), vec![]));
        let Some(contents) = idmesh_journal::read(path, KIND)? else {
            let writer = Writer::create(&[path], KIND, 0, &[] as &[Vec<u8>])?;
            return Ok((DurableLog { writer }, storage));
        };
        if let Ending::Damaged(damage) = contents.ending {
            return Err(idmesh_journal::Error::Damaged(damage).into());
        }
        for record in &contents.records {
            let at = |source| DurableError::Store {
                path: path.to_path_buf(),
                offset: record.offset,
                source,
            };
            let decoded: LogRecord =
                postcard::from_bytes(&record.payload).map_err(|source| DurableError::Record {
                    path: path.to_path_buf(),
                    offset: record.offset,
                    source,
                })?;
            match decoded {
                LogRecord::Entries(entries) => {
                    let entries: Vec<Entry> = entries.into_iter().map(StoredEntry::entry).collect();
                    storage.wl().append(&entries).map_err(at)?;
                }
                LogRecord::HardState { term, vote, commit } => {
                    storage.wl().set_hardstate(HardState {
                        term,
                        vote,
                        commit,
                        ..HardState::default()
                    });
                }
            }
        }
        // A torn last record is cut off: its step's messages never left.
        let writer = Writer::resume(&[path], KIND, contents.end())?;
        Ok((DurableLog { writer }, storage))
    }

    /// Appends what a step asked to persist and syncs it: after this
    /// returns, the step's messages may leave.
    pub fn write(&mut self, persist: &Persist) -> Result<(), DurableError> {
        if persist.is_empty() {
            return Ok(());
        }
        let mut records = Vec::new();
        if !persist.entries.is_empty() {
            let entries = persist.entries.iter().map(StoredEntry::of).collect();
            records.push(LogRecord::Entries(entries));
        }
        if let Some(hs) = &persist.hard_state {
            records.push(LogRecord::HardState {
                term: hs.term,
                vote: hs.vote,
                commit: hs.commit,
            });
        }
        let payloads = records
            .iter()
            .map(postcard::to_allocvec)
            .collect::<Result<Vec<_>, _>>()
            .map_err(DurableError::Encode)?;
        self.writer.append_all(&payloads)?;
        self.writer.sync()?;
        Ok(())
    }
}
