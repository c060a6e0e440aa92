//! The standby's copy of another role's snapshot, on its own disk.
//!
//! Every leader role sends each snapshot it writes to its standby — the
//! process that would adopt the role if its own died
//! ([`crate::machine`] says when, and how the role's durable mark waits
//! for it). The standby writes it here, under its own `state_dir`, as
//! `<role>.standby.snapshot`: beside the role's own journal and snapshot
//! (`<role>.journal`, `<role>.journal.snapshot`) but never over them, so
//! processes that share a disk do not collide. The file is an
//! `idmesh-journal` log of kind [`STANDBY`] with two records, the
//! snapshot's durable mark and the snapshot, written whole (a file beside
//! it, fsynced, renamed over it): a crash leaves the old copy or the new
//! one.
//!
//! A process that adopts a role and finds none of its journal in its
//! state directory (the role ran on another disk) installs the copy as
//! the role's snapshot ([`prepare_adoption`]); the role then recovers
//! from it as from its own, and fetches what came after it from the
//! sensor and its peers, who kept it. A real journal of the role (a
//! shared disk) is newer and wins. A damaged or torn copy is refused
//! with its file and byte.

use crate::host::journal_path;
use crate::journal::{read_whole, snapshot_path, SNAPSHOT};
use idmesh_journal::{self as log, Ending};
use idmesh_protocol::wire::leader_to_leader::{StandbyCopy, StandbyStored};
use idmesh_protocol::wire::leader_to_sensor::Durable;
use idmesh_protocol::wire::{decode, encode, VERSION};
use std::path::{Path, PathBuf};

/// What a standby copy's header says it holds.
pub const STANDBY: &str = "leader-standby";

#[derive(Debug, thiserror::Error)]
pub enum StandbyError {
    #[error(transparent)]
    Log(#[from] log::Error),
    #[error("standby copy {path}: {problem}")]
    Refused { path: String, problem: String },
}

/// Where a process keeps, under `dir`, its standby copy of `role`.
pub(crate) fn standby_path(dir: &Path, role: &str) -> PathBuf {
    dir.join(format!("{role}.standby.snapshot"))
}

/// Writes `copy` under `dir` whole and fsynced, and returns the word that
/// says so, from process `host`. A copy behind the one kept (an older
/// snapshot that arrived late, reordered on the way) does not replace it:
/// the role may have been told the newer one is kept, and published its
/// mark; the word names the copy kept.
pub(crate) fn keep(
    dir: &Path,
    copy: &StandbyCopy,
    host: &str,
) -> Result<StandbyStored, StandbyError> {
    let path = standby_path(dir, &copy.role);
    let mark = match read(&path) {
        Ok(Some((kept, _))) if behind(&copy.mark, &kept) => kept,
        _ => {
            write(&path, &copy.mark, &copy.state)?;
            copy.mark.clone()
        }
    };
    Ok(StandbyStored {
        version: VERSION,
        role: copy.role.clone(),
        standby: copy.to.clone(),
        host: host.to_string(),
        mark,
    })
}

/// Whether `mark` is behind `than`: not past it in either field, and not
/// the same.
pub(crate) fn behind(mark: &Durable, than: &Durable) -> bool {
    mark.batch <= than.batch
        && mark.position <= than.position
        && (mark.batch, mark.position) != (than.batch, than.position)
}

/// Writes the copy file at `path`: the mark, then the state.
pub(crate) fn write(path: &Path, mark: &Durable, state: &[u8]) -> Result<u64, StandbyError> {
    Ok(log::write_file(
        path,
        STANDBY,
        1,
        &[&encode(mark)[..], state],
    )?)
}

/// The copy at `path` — its snapshot's mark and the snapshot — if there
/// is one; refused, naming the file and the byte, if it is torn or
/// damaged.
pub(crate) fn read(path: &Path) -> Result<Option<(Durable, Vec<u8>)>, StandbyError> {
    let refused = |problem: String| StandbyError::Refused {
        path: path.display().to_string(),
        problem,
    };
    let Some(contents) = read_whole(path, STANDBY, refused)? else {
        return Ok(None);
    };
    match (&contents.ending, &contents.records[..]) {
        (Ending::Clean, [mark, state]) => match decode::<Durable>(&mark.payload) {
            Ok(mark) => Ok(Some((mark, state.payload.clone()))),
            Err(e) => Err(refused(format!(
                "its mark at byte {}: {e}",
                mark_offset(&contents)
            ))),
        },
        (Ending::Clean, records) => Err(refused(format!(
            "{} records where a standby copy has two",
            records.len()
        ))),
        (Ending::Torn { at, .. }, _) => Err(refused(format!("damaged or cut short at byte {at}"))),
        (Ending::Damaged(damage), _) => Err(refused(format!(
            "damaged at byte {} ({})",
            damage.at, damage.problem
        ))),
    }
}

fn mark_offset(contents: &log::Contents) -> u64 {
    contents.records.first().map_or(0, |r| r.offset)
}

/// Where an adopted role's state comes from.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Source {
    /// Its own journal (or snapshot) in this state directory: a shared
    /// disk, or the role ran here before.
    Journal,
    /// The standby copy this process kept, installed as its snapshot.
    StandbyCopy(Durable),
    /// Nothing: the role starts from the stream's beginning.
    Nothing,
}

/// Before adopting `role` with state directory `dir`: if the role has no
/// journal and no snapshot here but this process kept a standby copy of
/// it, the copy becomes the role's snapshot (with an empty journal after
/// it). Says which state the role will start from.
pub(crate) fn prepare_adoption(dir: &Path, role: &str) -> Result<Source, StandbyError> {
    if journal_kept(dir, role) {
        return Ok(Source::Journal);
    }
    let Some((mark, state)) = read(&standby_path(dir, role))? else {
        return Ok(Source::Nothing);
    };
    let snapshot = snapshot_path(&journal_path(dir, role));
    log::write_file(&snapshot, SNAPSHOT, 1, &[&state])?;
    Ok(Source::StandbyCopy(mark))
}

/// What an adoption of `role` here would start from, without changing
/// anything: this process's journal of it if it was written in the
/// holding the map names last (`last`), else the standby copy kept here.
pub(crate) fn adoption_source(dir: &Path, role: &str, last: u64) -> Result<Source, StandbyError> {
    if journal_kept(dir, role) && written_at(dir, role) == last {
        return Ok(Source::Journal);
    }
    Ok(match read(&standby_path(dir, role))? {
        Some((mark, _)) => Source::StandbyCopy(mark),
        None => Source::Nothing,
    })
}

/// What an epoch stamp's header says it holds.
pub const EPOCH: &str = "leader-epoch";

/// Where a process keeps, under `dir`, the epoch at which it last held
/// `role` (with voters): the holding its journal of the role was written in.
pub(crate) fn epoch_path(dir: &Path, role: &str) -> PathBuf {
    dir.join(format!("{role}.journal.epoch"))
}

/// Notes, whole and fsynced, that this process holds `role` at `epoch`
/// from now on: what it journals of the role belongs to that holding.
pub(crate) fn stamp_epoch(dir: &Path, role: &str, epoch: u64) -> Result<(), StandbyError> {
    log::write_number(&epoch_path(dir, role), EPOCH, epoch)?;
    Ok(())
}

/// The epoch `role`'s journal here was written at; 0 when none was noted
/// (a journal from before the deployment had voters).
pub(crate) fn stamped_epoch(dir: &Path, role: &str) -> Result<u64, StandbyError> {
    let path = epoch_path(dir, role);
    let refused = |problem: &str| StandbyError::Refused {
        path: path.display().to_string(),
        problem: problem.to_string(),
    };
    match log::read_number(&path, EPOCH) {
        Ok(epoch) => Ok(epoch.unwrap_or(0)),
        Err(log::Error::Header { .. }) => {
            Err(refused("damaged at byte 0 (its header fails its checksum)"))
        }
        Err(log::Error::NotANumber { .. }) => Err(refused("not one whole epoch")),
        Err(e) => Err(e.into()),
    }
}

/// What a file of heard durable marks' header says it holds.
pub const MARKS: &str = "leader-marks";

/// Where a process keeps, under `dir`, the newest durable mark it heard of
/// each leader role.
pub(crate) fn marks_path(dir: &Path) -> PathBuf {
    dir.join("heard.marks")
}

/// Keeps, whole and fsynced, the newest durable mark heard of each role:
/// started again, the process knows them before any holder publishes
/// anew — and a role whose holder is gone never does, which is when an
/// adoption must tell whether its copy is behind the mark.
pub(crate) fn keep_marks<'a>(
    dir: &Path,
    marks: impl Iterator<Item = &'a Durable>,
) -> Result<(), StandbyError> {
    let records: Vec<Vec<u8>> = marks.map(encode).collect();
    log::write_file(&marks_path(dir), MARKS, 1, &records)?;
    Ok(())
}

/// The marks [`keep_marks`] kept here (none without the file).
pub(crate) fn heard_marks(dir: &Path) -> Result<Vec<Durable>, StandbyError> {
    let path = marks_path(dir);
    let refused = |problem: String| StandbyError::Refused {
        path: path.display().to_string(),
        problem,
    };
    let Some(contents) = read_whole(&path, MARKS, refused)? else {
        return Ok(Vec::new());
    };
    if !matches!(contents.ending, Ending::Clean) {
        return Err(refused("not whole".to_string()));
    }
    contents
        .records
        .iter()
        .map(|r| decode::<Durable>(&r.payload).map_err(|e| refused(e.to_string())))
        .collect()
}

/// Before this process runs `role` again, with voters: its journal of the
/// role here is the role's newest state only if it was written in the
/// holding the map named last (`last`, its epoch before this claim) —
/// this process was then the last to act for the role. Written in an
/// earlier holding, it stopped where the role left this process, and the
/// holders since have moved on: the sensor and the peers forgot what lies
/// between (they keep only what follows the published mark), so a role
/// started from it would wait for inputs gone for good. Such a journal is
/// removed (the standby copy, if any, is used instead). Returns the epoch
/// of the journal forgotten, if one was.
pub(crate) fn forget_stale_journal(
    dir: &Path,
    role: &str,
    last: u64,
) -> Result<Option<u64>, StandbyError> {
    if !journal_kept(dir, role) {
        return Ok(None);
    }
    let written = written_at(dir, role);
    if written == last {
        return Ok(None);
    }
    forget_journal(dir, role)?;
    Ok(Some(written))
}

/// Whether this process keeps a journal or a snapshot of `role` in `dir`.
pub(crate) fn journal_kept(dir: &Path, role: &str) -> bool {
    let journal = journal_path(dir, role);
    journal.exists() || snapshot_path(&journal).exists()
}

/// The epoch of the holding `role`'s journal here was written in; a
/// stamp that does not read matches no holding (u64::MAX).
fn written_at(dir: &Path, role: &str) -> u64 {
    stamped_epoch(dir, role).unwrap_or(u64::MAX)
}

/// Removes `role`'s journal and snapshot from `dir` (none there is no
/// error): a role handed home leaves them stale here.
pub(crate) fn forget_journal(dir: &Path, role: &str) -> Result<(), StandbyError> {
    let journal = journal_path(dir, role);
    for old in [snapshot_path(&journal), journal] {
        log::remove_file(&old)?;
    }
    Ok(())
}

/// Before a process takes its own `role` back home: if the process that
/// ran the role meanwhile sent its snapshot here (a role handed home over
/// the network), that copy replaces this process's own journal and
/// snapshot, which stopped when the role left (the others have forgotten
/// what lies between them and the copy). The copy is then removed: it is
/// the role's snapshot now.
pub(crate) fn prepare_return(dir: &Path, role: &str) -> Result<Source, StandbyError> {
    let copy = standby_path(dir, role);
    let Some((mark, state)) = read(&copy)? else {
        return Ok(if journal_kept(dir, role) {
            Source::Journal
        } else {
            Source::Nothing
        });
    };
    forget_journal(dir, role)?;
    log::write_file(
        &snapshot_path(&journal_path(dir, role)),
        SNAPSHOT,
        1,
        &[&state],
    )?;
    std::fs::remove_file(&copy).map_err(|source| {
        StandbyError::Log(log::Error::Io {
            path: copy.clone(),
            source,
        })
    })?;
    Ok(Source::StandbyCopy(mark))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh folder for one test's files, removed when dropped.
    fn dir(name: &str) -> tempfile::TempDir {
        tempfile::Builder::new()
            .prefix(&format!("idmesh-standby-{name}-"))
            .tempdir()
            .unwrap()
    }

    fn mark(batch: u64) -> Durable {
        Durable {
            epoch: 0,
            version: VERSION,
            leader: "l1".into(),
            batch,
            position: batch * 10,
        }
    }

    fn copy(batch: u64, state: Vec<u8>) -> StandbyCopy {
        StandbyCopy {
            version: VERSION,
            role: "l1".into(),
            to: "l2".into(),
            mark: mark(batch),
            state,
        }
    }

    #[test]
    fn a_role_sent_home_replaces_the_journal_it_left_and_the_copy_is_used_once() {
        let scratch = dir("return");
        let dir = scratch.path();
        // The role's old journal and snapshot, from before it left.
        std::fs::write(journal_path(dir, "l1"), b"old journal").unwrap();
        std::fs::write(snapshot_path(&journal_path(dir, "l1")), b"old").unwrap();
        assert!(matches!(prepare_return(dir, "l1"), Ok(Source::Journal)));
        let home = StandbyCopy {
            to: "l1".into(),
            ..copy(7, vec![4, 5, 6])
        };
        keep(dir, &home, "l1").unwrap();
        match prepare_return(dir, "l1") {
            Ok(Source::StandbyCopy(mark)) => assert_eq!(mark.batch, 7),
            other => panic!("{other:?}"),
        }
        assert!(!journal_path(dir, "l1").exists(), "the old journal is gone");
        assert!(
            !standby_path(dir, "l1").exists(),
            "the copy is the snapshot now"
        );
        let snapshot = snapshot_path(&journal_path(dir, "l1"));
        let contents = log::read(&snapshot, SNAPSHOT).unwrap().unwrap();
        let state = contents.records.last().map(|r| r.payload.clone());
        assert_eq!(state, Some(vec![4u8, 5, 6]));
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn a_kept_copy_reads_back_and_the_newest_replaces_the_last() {
        let scratch = dir("keep");
        let dir = scratch.path();
        let path = standby_path(dir, "l1");
        assert_eq!(read(&path).unwrap(), None);
        let stored = keep(dir, &copy(3, vec![7; 1000]), "l2").unwrap();
        assert_eq!((stored.host.as_str(), stored.mark.batch), ("l2", 3));
        assert_eq!(read(&path).unwrap(), Some((mark(3), vec![7; 1000])));
        keep(dir, &copy(5, vec![9; 10]), "l2").unwrap();
        assert_eq!(read(&path).unwrap(), Some((mark(5), vec![9; 10])));
        // An older copy arriving late keeps the newer one, and says so.
        let stored = keep(dir, &copy(4, vec![1; 10]), "l2").unwrap();
        assert_eq!(stored.mark.batch, 5);
        assert_eq!(read(&path).unwrap(), Some((mark(5), vec![9; 10])));
        assert!(path.ends_with("l1.standby.snapshot"));
        assert_ne!(path, snapshot_path(&journal_path(dir, "l1")));
    }

    #[test]
    fn a_torn_or_damaged_copy_is_refused_naming_the_file_and_the_byte() {
        let scratch = dir("damaged");
        let dir = scratch.path();
        let path = standby_path(dir, "l1");
        keep(dir, &copy(3, vec![7; 200]), "l2").unwrap();
        let whole = std::fs::read(&path).unwrap();

        std::fs::write(&path, &whole[..whole.len() - 20]).unwrap();
        let e = read(&path).unwrap_err().to_string();
        assert!(
            e.contains("l1.standby.snapshot") && e.contains("cut short at byte"),
            "{e}"
        );

        let mut damaged = whole.clone();
        let at = damaged.len() - 100;
        damaged[at] ^= 0x10;
        std::fs::write(&path, &damaged).unwrap();
        let e = read(&path).unwrap_err().to_string();
        assert!(
            e.contains("l1.standby.snapshot") && e.contains("at byte"),
            "{e}"
        );

        let mut header = whole.clone();
        header[20] ^= 1;
        std::fs::write(&path, &header).unwrap();
        let e = read(&path).unwrap_err().to_string();
        assert!(e.contains("damaged at byte 0"), "{e}");

        // Nor is a leader's own snapshot taken for a copy.
        std::fs::remove_file(&path).unwrap();
        log::write_file(&path, SNAPSHOT, 1, &[&[1u8, 2][..]]).unwrap();
        assert!(read(&path).is_err());
    }

    #[test]
    fn an_adopter_uses_the_roles_journal_if_there_is_one_else_its_copy() {
        let scratch = dir("adopt");
        let dir = scratch.path();
        assert_eq!(prepare_adoption(dir, "l1").unwrap(), Source::Nothing);
        keep(dir, &copy(4, vec![5; 64]), "l2").unwrap();
        assert_eq!(
            prepare_adoption(dir, "l1").unwrap(),
            Source::StandbyCopy(mark(4))
        );
        let snapshot = snapshot_path(&journal_path(dir, "l1"));
        let contents = log::read(&snapshot, SNAPSHOT).unwrap().unwrap();
        assert_eq!(contents.generation, 1);
        assert_eq!(contents.records[0].payload, vec![5; 64]);
        // From then on the role's own files are there: they win.
        keep(dir, &copy(6, vec![6; 64]), "l2").unwrap();
        assert_eq!(prepare_adoption(dir, "l1").unwrap(), Source::Journal);
        let contents = log::read(&snapshot, SNAPSHOT).unwrap().unwrap();
        assert_eq!(contents.records[0].payload, vec![5; 64], "left as it was");
    }

    #[test]
    fn a_journal_of_an_earlier_holding_is_forgotten_and_the_copy_used() {
        let scratch = dir("stale");
        let dir = scratch.path();
        let journal = journal_path(dir, "l1");
        // No journal: nothing to forget, whatever the epoch.
        assert_eq!(forget_stale_journal(dir, "l1", 3).unwrap(), None);
        // Written while this process held the role at epoch 3: the map's
        // last holding is that one, so it is the newest state.
        std::fs::write(&journal, b"journal").unwrap();
        stamp_epoch(dir, "l1", 3).unwrap();
        assert_eq!(stamped_epoch(dir, "l1").unwrap(), 3);
        assert_eq!(forget_stale_journal(dir, "l1", 3).unwrap(), None);
        assert!(journal.exists());
        // Another held it at 4 since: this journal stopped where the role
        // left, and the copy this process keeps is used instead.
        keep(dir, &copy(9, vec![9; 16]), "l2").unwrap();
        assert_eq!(forget_stale_journal(dir, "l1", 4).unwrap(), Some(3));
        assert!(!journal.exists());
        assert_eq!(
            prepare_adoption(dir, "l1").unwrap(),
            Source::StandbyCopy(mark(9))
        );
        // A journal never stamped (kept from before the voters) counts as
        // written at epoch 0.
        std::fs::remove_file(epoch_path(dir, "l1")).unwrap();
        assert_eq!(stamped_epoch(dir, "l1").unwrap(), 0);
        assert_eq!(forget_stale_journal(dir, "l1", 0).unwrap(), None);
        assert_eq!(forget_stale_journal(dir, "l1", 1).unwrap(), Some(0));
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn the_adoption_source_is_read_without_changing_anything() {
        let scratch = dir("source");
        let dir = scratch.path();
        assert_eq!(adoption_source(dir, "l1", 0).unwrap(), Source::Nothing);
        keep(dir, &copy(5, vec![1; 8]), "l2").unwrap();
        assert_eq!(
            adoption_source(dir, "l1", 2).unwrap(),
            Source::StandbyCopy(mark(5))
        );
        // A journal of the last holding wins; of an earlier one, the copy.
        let journal = journal_path(dir, "l1");
        std::fs::write(&journal, b"journal").unwrap();
        stamp_epoch(dir, "l1", 2).unwrap();
        assert_eq!(adoption_source(dir, "l1", 2).unwrap(), Source::Journal);
        assert_eq!(
            adoption_source(dir, "l1", 3).unwrap(),
            Source::StandbyCopy(mark(5))
        );
        assert!(journal.exists(), "nothing is removed");
        std::fs::remove_dir_all(dir).ok();
    }

    #[test]
    fn the_marks_heard_are_read_back_as_kept_and_a_damaged_file_is_refused() {
        let scratch = dir("marks");
        let dir = scratch.path();
        assert!(heard_marks(dir).unwrap().is_empty(), "none kept yet");
        let other = Durable {
            leader: "l2".into(),
            epoch: 3,
            ..mark(9)
        };
        keep_marks(dir, [mark(4), other.clone()].iter()).unwrap();
        assert_eq!(heard_marks(dir).unwrap(), vec![mark(4), other.clone()]);
        keep_marks(dir, [other.clone()].iter()).unwrap();
        assert_eq!(heard_marks(dir).unwrap(), vec![other], "replaced whole");
        let path = marks_path(dir);
        let mut bytes = std::fs::read(&path).unwrap();
        let last = bytes.len() - 3;
        bytes[last] ^= 0xff;
        std::fs::write(&path, bytes).unwrap();
        assert!(
            heard_marks(dir).is_err(),
            "a damaged file is said, not read"
        );
        std::fs::remove_dir_all(dir).ok();
    }
}
