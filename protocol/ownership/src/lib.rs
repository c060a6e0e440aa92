//! Who may write a journal: the one process holding its lock. A leader
//! runs a role only while it owns the role's journal, and a sensor streams
//! only while it owns its stream's journal (two sensors on one journal
//! would interleave two streams' records in it).
//!
//! A role's liveliness token says who *answers* for it, but tokens are
//! only as good as the network: across a partition each side sees the
//! other's tokens vanish and, with `takeover_after_ms` shorter than the
//! cut, would adopt roles whose processes still run them. Two processes
//! then write one journal and both put the role's transfers; after the
//! partition heals the deployment never finishes. The journal in the shared state directory is what both must
//! touch, so it is where the role is fenced: a process runs a role only
//! while it holds an exclusive advisory lock (`flock`) on
//! `<journal>.lock`. The kernel (or the file server) drops the lock when
//! the holder dies, however it dies, so a role whose process is gone for
//! good is free to adopt, while a role whose process is only cut off stays
//! with it, and its answers stay `degraded` until the cut heals.
//!
//! The lock file names its holder (process and pid), so a refusal says who
//! holds the role. On a network file system the lock is the server's: a
//! holder that vanishes keeps it until the server's lease expires (NFSv4:
//! about 90 s), which is then the shortest takeover.

use std::fs::{File, OpenOptions, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};
use std::time::Duration;

/// The lock could not be had.
#[derive(Debug, thiserror::Error)]
pub enum OwnershipError {
    #[error("journal lock {path}: {source}")]
    Io {
        path: String,
        source: std::io::Error,
    },
    #[error("journal lock {path} is held by {holder}: its role runs elsewhere")]
    Held { path: String, holder: String },
}

/// The right to write a journal; the lock is released on drop.
#[derive(Debug)]
pub struct Ownership {
    _file: File,
}

/// How long a process waits for a role's lock when it expects it free
/// soon (the process handing the role back is stopping its actor).
pub const HANDOVER_PATIENCE: Duration = Duration::from_secs(5);

impl Ownership {
    /// Takes the lock of `journal` for `holder` if nobody holds it.
    pub fn try_take(journal: &Path, holder: &str) -> Result<Option<Self>, OwnershipError> {
        let Some(mut file) = lock(journal)? else {
            return Ok(None);
        };
        // Held now: say who holds it, for the refusals of others.
        let named = file
            .set_len(0)
            .and_then(|()| file.rewind())
            .and_then(|()| writeln!(file, "{holder} (pid {})", std::process::id()));
        named.map_err(|source| OwnershipError::Io {
            path: lock_path(journal).display().to_string(),
            source,
        })?;
        Ok(Some(Ownership { _file: file }))
    }

    /// The error for a lock someone else kept: names the lock and holder.
    pub fn refused(journal: &Path) -> OwnershipError {
        OwnershipError::Held {
            path: lock_path(journal).display().to_string(),
            holder: holder_of(journal),
        }
    }
}

/// Who holds `journal`'s lock now, or None if nobody does. Checking takes
/// the lock for an instant (and writes nothing), so the answer can be
/// stale by the time it is read: [`Ownership::try_take`] is the decision,
/// this only avoids starting a role that would then be refused.
pub fn held_by(journal: &Path) -> Option<String> {
    match lock(journal) {
        Ok(Some(_released_here)) => None,
        Ok(None) => Some(holder_of(journal)),
        // Cannot even open the lock: let the role's start say why.
        Err(_) => None,
    }
}

/// The lock file of `journal`, locked here; None if another holds it.
fn lock(journal: &Path) -> Result<Option<File>, OwnershipError> {
    let path = lock_path(journal);
    let io = |source| OwnershipError::Io {
        path: path.display().to_string(),
        source,
    };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(io)?;
    }
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(io)?;
    match file.try_lock() {
        Ok(()) => Ok(Some(file)),
        Err(TryLockError::WouldBlock) => Ok(None),
        Err(TryLockError::Error(source)) => Err(io(source)),
    }
}

/// What the holder wrote into the lock file.
fn holder_of(journal: &Path) -> String {
    let mut text = String::new();
    let read = File::open(lock_path(journal)).and_then(|mut f| f.read_to_string(&mut text));
    match text.trim() {
        named if read.is_ok() && !named.is_empty() => named.to_string(),
        _ => "an unknown process".into(),
    }
}

/// `<journal>.lock`.
pub(crate) fn lock_path(journal: &Path) -> PathBuf {
    let mut name = journal.as_os_str().to_owned();
    name.push(".lock");
    PathBuf::from(name)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A journal's path in a fresh folder, removed when the folder is
    /// dropped.
    fn journal(name: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::Builder::new()
            .prefix("idmesh-ownership-")
            .tempdir()
            .unwrap();
        let path = dir.path().join(format!("{name}.journal"));
        (dir, path)
    }

    #[test]
    fn a_role_has_one_owner_at_a_time_and_is_free_once_it_lets_go() {
        let (_dir, path) = journal("one-owner");
        let first = Ownership::try_take(&path, "leader-0").unwrap();
        assert!(first.is_some());
        // Another open file description is another owner, as another
        // process would be (flock locks belong to the open file).
        assert!(Ownership::try_take(&path, "leader-1").unwrap().is_none());
        assert_eq!(
            held_by(&path).as_deref().map(|h| h.starts_with("leader-0")),
            Some(true)
        );
        drop(first);
        assert_eq!(held_by(&path), None);
        assert!(Ownership::try_take(&path, "leader-1").unwrap().is_some());
    }

    #[test]
    fn a_refusal_names_the_holder_and_the_lock() {
        let (_dir, path) = journal("refusal");
        let _held = Ownership::try_take(&path, "leader-3").unwrap();
        let text = Ownership::refused(&path).to_string();
        assert!(text.contains("leader-3"), "{text}");
        assert!(text.contains("refusal.journal.lock"), "{text}");
    }
}
