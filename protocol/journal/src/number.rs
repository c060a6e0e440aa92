//! One number kept whole on disk: a log of a single record, written over
//! durably ([`write_file`]). The roles note there the epoch a state was
//! written in (a leader's journal of a role, a sensor standby's copy), for
//! a later start to know which holding that state belongs to.

use crate::{read, write_file, Ending, Error};
use std::path::Path;

/// Writes `number` to `path` as the only record of a `kind` file, whole
/// and fsynced.
pub fn write_number(path: &Path, kind: &'static str, number: u64) -> Result<(), Error> {
    write_file(path, kind, 1, &[&number.to_le_bytes()[..]])?;
    Ok(())
}

/// The number [`write_number`] kept at `path`; None without the file.
pub fn read_number(path: &Path, kind: &'static str) -> Result<Option<u64>, Error> {
    let Some(contents) = read(path, kind)? else {
        return Ok(None);
    };
    let bytes = match (&contents.ending, &contents.records[..]) {
        (Ending::Clean, [record]) => <[u8; 8]>::try_from(&record.payload[..]).ok(),
        _ => None,
    };
    bytes
        .map(|b| Some(u64::from_le_bytes(b)))
        .ok_or_else(|| Error::NotANumber {
            path: path.to_path_buf(),
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_number_reads_back_and_a_file_of_records_does_not_pass_for_one() {
        let dir = std::env::temp_dir().join(format!("idmesh-number-{}", std::process::id()));
        let path = dir.join("copy.epoch");
        assert_eq!(read_number(&path, "test-epoch").unwrap(), None);
        write_number(&path, "test-epoch", 7).unwrap();
        write_number(&path, "test-epoch", 9).unwrap();
        assert_eq!(read_number(&path, "test-epoch").unwrap(), Some(9));
        write_file(&path, "test-epoch", 1, &[&b"ab"[..], &b"cd"[..]]).unwrap();
        let e = read_number(&path, "test-epoch").unwrap_err();
        assert!(matches!(e, Error::NotANumber { .. }), "{e}");
        assert!(read_number(&path, "other-kind").is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
