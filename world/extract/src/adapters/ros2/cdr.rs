//! CDR as ROS 2 puts it on the wire and in bags: a 4-byte encapsulation
//! header (representation id, then two option bytes) and the message in
//! plain CDR of that byte order, aligned from the end of the header.
//! Decoding and encoding are `cdr-encoding`'s; this module reads and
//! writes the header around them.

use byteorder::{BigEndian, LittleEndian};
use serde::de::DeserializeOwned;
use serde::Serialize;

/// `CDR_BE` and `CDR_LE`, the representation ids ROS 2 writes.
const CDR_BE: [u8; 2] = [0x00, 0x00];
const CDR_LE: [u8; 2] = [0x00, 0x01];

/// Why a payload is not a message.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CdrError {
    #[error("{0} bytes: shorter than the 4-byte CDR encapsulation header")]
    Short(usize),
    #[error("encapsulation {0:02x}{1:02x}: not plain CDR (big or little endian)")]
    Representation(u8, u8),
    #[error("bad CDR: {0}")]
    Body(String),
}

/// The message a payload holds.
pub fn decode<T: DeserializeOwned>(payload: &[u8]) -> Result<T, CdrError> {
    let (header, body) = match payload.split_at_checked(4) {
        Some(parts) => parts,
        None => return Err(CdrError::Short(payload.len())),
    };
    let decoded = match [header[0], header[1]] {
        CDR_LE => cdr_encoding::from_bytes::<T, LittleEndian>(body),
        CDR_BE => cdr_encoding::from_bytes::<T, BigEndian>(body),
        _ => return Err(CdrError::Representation(header[0], header[1])),
    };
    decoded
        .map(|(message, _)| message)
        .map_err(|e| CdrError::Body(e.to_string()))
}

/// A message as a little-endian payload, header included.
pub fn encode<T: Serialize>(message: &T) -> Result<Vec<u8>, CdrError> {
    let mut out = vec![CDR_LE[0], CDR_LE[1], 0, 0];
    cdr_encoding::to_writer::<T, LittleEndian, _>(&mut out, message)
        .map_err(|e| CdrError::Body(e.to_string()))?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adapters::ros2::geometry::Header;

    #[test]
    fn a_header_round_trips_and_bad_payloads_are_named() {
        let header = Header {
            stamp: crate::adapters::ros2::geometry::Time { sec: 3, nanosec: 5 },
            frame_id: "map".into(),
        };
        let bytes = encode(&header).unwrap();
        // sec, nanosec, then the string's length with its NUL, and "map\0".
        assert_eq!(bytes.len(), 4 + 4 + 4 + 4 + 4);
        assert_eq!(decode::<Header>(&bytes).unwrap(), header);
        assert_eq!(decode::<Header>(&bytes[..2]), Err(CdrError::Short(2)));
        assert!(matches!(
            decode::<Header>(&bytes[..10]),
            Err(CdrError::Body(_))
        ));
        let mut xcdr = bytes.clone();
        xcdr[1] = 0x07;
        assert_eq!(decode::<Header>(&xcdr), Err(CdrError::Representation(0, 7)));
    }
}
