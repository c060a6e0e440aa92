//! What can go wrong reading or writing a log, each naming the file.

use std::fmt;
use std::path::PathBuf;

/// Why a record does not read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Problem {
    /// The file's header fails its checksum (a role that can do without
    /// the whole file reports its damage as at byte 0).
    Header,
    /// The record's head (its length and checksum) fails its own check.
    Head,
    /// The payload fails the checksum its head gives.
    Checksum,
    /// The head checks but claims more than a record may hold.
    Length(u32),
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Problem::Header => f.write_str("the file's header fails its checksum"),
            Problem::Head => f.write_str("its head fails its checksum"),
            Problem::Checksum => f.write_str("its payload fails its checksum"),
            Problem::Length(n) => write!(f, "it claims {n} bytes"),
        }
    }
}

/// A record that does not check, with whole records after it: bytes that
/// were written whole and changed since. What the reader knows of what
/// was lost: the damaged record and everything after it is not returned.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Damage {
    pub path: PathBuf,
    /// The copy of the file, damaged at the same record ([`crate::read_copies`]).
    pub copy: Option<PathBuf>,
    /// Where the damaged record starts.
    pub at: u64,
    pub problem: Problem,
    /// Whole records found after it (by looking for the next record that
    /// checks), not returned. A role that reports a damaged header as
    /// damage at byte 0 ([`Problem::Header`]) does not look: 0.
    pub after: usize,
    /// Bytes from the damaged record to the end of the file.
    pub bytes: u64,
}

impl Damage {
    /// The records lost: the damaged one and the whole ones after it.
    pub fn records(&self) -> u64 {
        self.after as u64 + 1
    }
}

impl fmt::Display for Damage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{} is damaged at byte {} ({})",
            self.path.display(),
            self.at,
            self.problem
        )?;
        if let Some(copy) = &self.copy {
            write!(f, ", and so is its copy {} there", copy.display())?;
        }
        write!(
            f,
            "; {} whole records follow in the {} bytes from there to the end",
            self.after, self.bytes
        )
    }
}

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    /// The first bytes are neither this format's header nor an earlier
    /// idmesh format's.
    #[error("{path} is not an idmesh journal (no journal header at byte 0)")]
    NotJournal { path: PathBuf },
    /// A file in a format idmesh wrote before this one (no checksums).
    #[error(
        "{path} is {what} in the format of an earlier idmesh, without checksums, which this \
         version does not read: finish its stream with the idmesh that wrote it, or remove the \
         deployment's state directory to start the stream again from its beginning"
    )]
    OldFormat { path: PathBuf, what: &'static str },
    #[error(
        "{path} is in journal format {found}; this idmesh reads format {}",
        crate::FORMAT
    )]
    NewerFormat { path: PathBuf, found: u16 },
    #[error("{path} holds a {found}, not a {wanted}")]
    WrongKind {
        path: PathBuf,
        found: String,
        wanted: &'static str,
    },
    /// The header fails its checksum: which generation the file is of,
    /// and so what its records continue, is unknown.
    #[error("{path} is damaged at byte 0: its header fails its checksum")]
    Header { path: PathBuf },
    #[error("{0}")]
    Damaged(Damage),
    /// Two copies of one log hold different whole records at one byte:
    /// they are not copies of each other.
    #[error("{path} and its copy {copy} hold different records at byte {at}")]
    Diverged {
        path: PathBuf,
        copy: PathBuf,
        at: u64,
    },
    /// A file of one number ([`crate::write_number`]) that holds
    /// something else.
    #[error("{path} does not hold one whole number")]
    NotANumber { path: PathBuf },
    /// A record too large for the format (the caller's bug, or a state
    /// that outgrew it).
    #[error("{path}: a record of {bytes} bytes, more than a record may hold")]
    TooLarge { path: PathBuf, bytes: usize },
}

impl Error {
    pub(crate) fn io(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> Error + '_ {
        move |source| Error::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}
