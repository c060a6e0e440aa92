//! What the start of a stream says of the field — n tracks, k red when
//! known, the red tracks at time 0 when known — whether it comes as a trace
//! header (offline replay, the gateway reading a file) or as the `Begin`
//! item on the wire (every leader). One trait over both, so the engine turns
//! either into its starting field the same way
//! (`idmesh_belief::field_of`).

use crate::trace::Header;
use crate::wire::sensor_to_leader::Begin;

/// The start of a stream, as far as the field goes.
pub trait StreamStart {
    /// n, the number of tracks.
    fn tracks(&self) -> usize;
    /// k when the start fixes it; `None` = unknown.
    fn red_count(&self) -> Option<usize>;
    /// The red tracks at time 0; `None` = not revealed.
    fn initial_red(&self) -> Option<&[u32]>;
}

/// A trace header: k is `red`, or else the length of `initial_red`.
impl StreamStart for Header {
    fn tracks(&self) -> usize {
        self.tracks
    }

    fn red_count(&self) -> Option<usize> {
        Header::red_count(self)
    }

    fn initial_red(&self) -> Option<&[u32]> {
        self.initial_red.as_deref()
    }
}

/// A stream's `Begin`: the gateway wrote the header's k into `red`.
impl StreamStart for Begin {
    fn tracks(&self) -> usize {
        self.tracks as usize
    }

    fn red_count(&self) -> Option<usize> {
        self.red.map(|k| k as usize)
    }

    fn initial_red(&self) -> Option<&[u32]> {
        self.initial_red.as_deref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_header_fixes_k_by_red_or_by_the_initial_red_tracks() {
        let mut header = Header::new(5);
        assert_eq!(StreamStart::red_count(&header), None);
        header.initial_red = Some(vec![4, 2]);
        assert_eq!(StreamStart::red_count(&header), Some(2));
        assert_eq!(StreamStart::initial_red(&header), Some(&[4, 2][..]));
        header.red = Some(3);
        assert_eq!(StreamStart::red_count(&header), Some(3));
        assert_eq!(StreamStart::tracks(&header), 5);
    }
}
