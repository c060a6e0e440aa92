//! # idmesh-journal — the one record log on disk
//!
//! Every durable file of an idmesh role is one of these logs: a leader's
//! input journal and its snapshot, the sensor's journal (and its copy).
//! What a record *means* is the role's business; this crate only keeps
//! records, tells whole ones from torn and damaged ones, and says where.
//!
//! ## Format (version [`FORMAT`])
//!
//! A file starts with a header of [`HEADER_LEN`] bytes:
//!
//! | bytes  | what |
//! |--------|------|
//! | 0..8   | [`MAGIC`] |
//! | 8..10  | the format version, u16 little-endian |
//! | 10..12 | reserved, 0 |
//! | 12..28 | what the file holds (`leader-journal`, `sensor-journal`, …), ASCII, zero-padded: one role's file is never read as another's |
//! | 28..36 | a generation, u64 little-endian (the role's: which snapshot a leader's journal continues, how often the sensor's was compacted) |
//! | 36..40 | CRC-32 of bytes 0..36 |
//!
//! then records, each [`RECORD_HEAD`] bytes and its payload:
//!
//! | bytes  | what |
//! |--------|------|
//! | 0..4   | payload length, u32 little-endian (at most [`MAX_RECORD`]) |
//! | 4..8   | CRC-32 of the payload |
//! | 8..12  | CRC-32 of bytes 0..8 |
//! | 12..   | the payload |
//!
//! The record head has its own checksum so that a damaged length is caught
//! before it is believed: with one checksum over length and payload, a
//! flipped length bit would be checked against a different stretch of
//! bytes, and caught only by chance. Here a flipped bit anywhere in a
//! record fails one of the two checks for certain.
//!
//! **Why CRC-32** (`crc32fast`, the IEEE polynomial, hardware-accelerated
//! where the processor has it) rather than the FNV-1a the sensor's journal
//! used: a CRC is made to catch damage — every single-bit error, every
//! burst of up to 32 bits, every odd number of flipped bits — where FNV-1a
//! is a hash that catches them only with high probability. Both are 32
//! bits, so random garbage passes either one time in 2^32; a CRC is also
//! faster than a byte-at-a-time FNV loop. It is not a defence against
//! someone who can write the file (nothing short of a MAC is): that is the
//! file system's permissions' job.
//!
//! ## Reading: whole, torn, damaged
//!
//! [`read`] returns the whole records from the start and says how the file
//! ended ([`Ending`]):
//!
//! - **clean**: the last record ends where the file does;
//! - **torn**: the last record is incomplete, or whole in length but bad in
//!   content, and nothing valid follows it — a process (or a machine) died
//!   writing it. The role cuts it off ([`Writer::resume`]) and goes on: a
//!   record is written whole before anything that depends on it leaves the
//!   process, so one torn by a crash was never acted on. (A last record
//!   damaged later cannot be told from a torn one, so a role must be able
//!   to lose it: the leader can, the sensor has its copy.)
//! - **damaged**: a record that does not check, with whole records after
//!   it — the disk, or someone, changed bytes that were written whole.
//!   [`Damage`] names the file, the byte, why, and what follows it (how
//!   many whole records, how many bytes): what the role has lost, for it
//!   to recover. The reader never returns a record past the damage: a log
//!   is replayed in order, and the records after a lost one are not the
//!   state they were written in.
//!
//! A file of another version is refused naming it ([`Error::NewerFormat`]);
//! the formats idmesh wrote before this crate existed (a leader's journal
//! of `kind, length, bytes` frames without checksums, its `idmesh/1`
//! snapshot, the sensor's FNV-1a journal) are recognised and refused with
//! what to do ([`Error::OldFormat`]) rather than read: they carry no
//! checksums, so reading them would take damaged records for whole ones,
//! the very thing this format exists to stop.
//!
//! ## What each role does with damage
//!
//! **The leader** ([`Writer`] on one file): its journal is its inputs
//! (stream batches, peers' transfers, follow replies) since its last
//! snapshot. On damage it keeps the snapshot and the records before the
//! damaged one, drops that record and everything after it (saving the
//! damaged file beside the journal, logging the file and byte, counting
//! it), and recovers as a leader whose journal ended there: the sensor
//! and its peers send again what it lacks. That is sound only because a
//! leader's durable mark — what tells the sensor and the peers they may
//! forget what they keep for it — advances only when a snapshot is
//! written: everything after the snapshot, damaged or not, is still kept
//! elsewhere. A damaged *snapshot* cannot be recovered that way (the
//! others forgot what it replaced) and is refused with its file and byte.
//!
//! **The sensor** ([`Writer`] on two files, [`read_copies`]): its journal
//! holds what only it has — ingested lines it acknowledged (the producer
//! let them go), and where cuts, follows and batch boundaries fell, which
//! the leaders have already acted on; the trace file holds the lines but
//! not those. So it writes every record to two files, each checksummed; a
//! record damaged in one is taken from the other, and only a record
//! damaged in both (or a damaged journal without its copy) stops the
//! sensor, with an error naming the file and the byte, rather than let it
//! go on with a different stream.

mod error;
mod format;
mod number;
mod read;
mod write;

#[cfg(test)]
mod tests;

pub use error::{Damage, Error, Problem};
pub use format::{encode_record, header, FORMAT, HEADER_LEN, MAGIC, MAX_RECORD, RECORD_HEAD};
pub use number::{read_number, write_number};
pub use read::{parse, read, read_copies, Contents, Ending, Merged, Record, Repair};
pub use write::{fsyncs, remove_file, write_file, Writer};
