//! A set of track ids: the index α of a Radon basis function φ_α
//! (Section 4.1). Kept sorted so that unions and intersections are linear
//! merges; small sets (the common case) live inline. The hash is a Zobrist
//! hash (XOR of one fixed random word per track) kept up to date by every
//! operation, so hashing a set of 50 tracks costs as little as one of 1 —
//! the engine hashes sets on every event.

use smallvec::SmallVec;
use std::fmt;
use std::hash::{Hash, Hasher};

/// A sorted set of distinct track ids.
#[derive(Clone, PartialEq, Eq, PartialOrd, Ord, Default)]
pub struct TrackSet {
    tracks: SmallVec<[u32; 8]>,
    hash: u64,
}

/// The Zobrist word of a track: splitmix64 of its id, a fixed bijection
/// whose outputs look independent.
fn word(t: u32) -> u64 {
    let mut z = (t as u64).wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// On disk (a leader's snapshot) a set is its sorted ids; the hash is
/// derived again on the way back.
impl serde::Serialize for TrackSet {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_seq(self.tracks.iter())
    }
}

impl<'de> serde::Deserialize<'de> for TrackSet {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let tracks = Vec::<u32>::deserialize(deserializer)?;
        Ok(TrackSet::from_tracks(tracks))
    }
}

impl Hash for TrackSet {
    fn hash<H: Hasher>(&self, state: &mut H) {
        state.write_u64(self.hash);
    }
}

impl TrackSet {
    pub(crate) fn empty() -> Self {
        TrackSet::default()
    }

    fn sorted(tracks: SmallVec<[u32; 8]>) -> Self {
        let hash = tracks.iter().fold(0, |h, &t| h ^ word(t));
        TrackSet { tracks, hash }
    }

    /// A set from any ids; duplicates are merged.
    pub fn from_tracks(tracks: impl IntoIterator<Item = u32>) -> Self {
        let mut v: SmallVec<[u32; 8]> = tracks.into_iter().collect();
        v.sort_unstable();
        v.dedup();
        TrackSet::sorted(v)
    }

    pub(crate) fn singleton(t: u32) -> Self {
        let mut v = SmallVec::new();
        v.push(t);
        TrackSet::sorted(v)
    }

    /// The Zobrist hash (0 for the empty set).
    pub(crate) fn zobrist(&self) -> u64 {
        self.hash
    }

    pub fn len(&self) -> usize {
        self.tracks.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tracks.is_empty()
    }

    pub fn tracks(&self) -> &[u32] {
        &self.tracks
    }

    pub fn contains(&self, t: u32) -> bool {
        if self.tracks.len() <= 16 {
            self.tracks.contains(&t)
        } else {
            self.tracks.binary_search(&t).is_ok()
        }
    }

    /// α ∪ {t}.
    pub(crate) fn with(&self, t: u32) -> Self {
        let mut out = self.clone();
        if let Err(at) = out.tracks.binary_search(&t) {
            out.tracks.insert(at, t);
            out.hash ^= word(t);
        }
        out
    }

    /// α − {t}.
    pub(crate) fn without(&self, t: u32) -> Self {
        let mut out = self.clone();
        if let Ok(at) = out.tracks.binary_search(&t) {
            out.tracks.remove(at);
            out.hash ^= word(t);
        }
        out
    }

    /// α △ {from, to} for a set holding `from` and not `to`: the set the
    /// rollup moves mass to when the targets on `from` and `to` swap.
    pub(crate) fn replace(&self, from: u32, to: u32) -> Self {
        let mut out = self.clone();
        let v = &mut out.tracks;
        if let Ok(at) = v.binary_search(&from) {
            // Shift the elements between the two positions instead of a
            // remove and an insert.
            let dest = match v.binary_search(&to) {
                Ok(_) => {
                    v.remove(at);
                    out.hash ^= word(from);
                    return out;
                }
                Err(dest) => dest,
            };
            if dest > at {
                v[at..dest].rotate_left(1);
                v[dest - 1] = to;
            } else {
                v[dest..=at].rotate_right(1);
                v[dest] = to;
            }
            out.hash ^= word(from) ^ word(to);
        } else if let Err(at) = v.binary_search(&to) {
            v.insert(at, to);
            out.hash ^= word(to);
        }
        out
    }

    /// |α ∩ β| by a linear merge.
    pub(crate) fn intersection_len(&self, other: &TrackSet) -> usize {
        let (a, b) = (&self.tracks, &other.tracks);
        let (mut i, mut j, mut common) = (0, 0, 0);
        while i < a.len() && j < b.len() {
            match a[i].cmp(&b[j]) {
                std::cmp::Ordering::Less => i += 1,
                std::cmp::Ordering::Greater => j += 1,
                std::cmp::Ordering::Equal => {
                    common += 1;
                    i += 1;
                    j += 1;
                }
            }
        }
        common
    }

    /// |α ∪ β|.
    pub(crate) fn union_len(&self, other: &TrackSet) -> usize {
        self.len() + other.len() - self.intersection_len(other)
    }

    /// α ∪ β.
    #[cfg(test)]
    pub(crate) fn union(&self, other: &TrackSet) -> TrackSet {
        TrackSet::from_tracks(self.tracks.iter().chain(other.tracks.iter()).copied())
    }

    #[cfg(test)]
    pub(crate) fn is_subset(&self, other: &TrackSet) -> bool {
        self.intersection_len(other) == self.len()
    }

    /// Whether α and the sorted slice share an element.
    pub(crate) fn meets(&self, others: &[u32]) -> bool {
        others.iter().any(|&t| self.contains(t))
    }
}

impl fmt::Debug for TrackSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_set().entries(self.tracks.iter()).finish()
    }
}

impl FromIterator<u32> for TrackSet {
    fn from_iter<I: IntoIterator<Item = u32>>(iter: I) -> Self {
        TrackSet::from_tracks(iter)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_operations() {
        let a = TrackSet::from_tracks([3, 1, 2, 3]);
        assert_eq!(a.tracks(), &[1, 2, 3]);
        assert_eq!(a.with(0).tracks(), &[0, 1, 2, 3]);
        assert_eq!(a.without(2).tracks(), &[1, 3]);
        assert_eq!(a.replace(1, 4).tracks(), &[2, 3, 4]);
        let b = TrackSet::from_tracks([2, 5]);
        assert_eq!(a.intersection_len(&b), 1);
        assert_eq!(a.union_len(&b), 4);
        assert_eq!(a.union(&b).tracks(), &[1, 2, 3, 5]);
        assert!(TrackSet::from_tracks([1, 3]).is_subset(&a));
        assert!(!b.is_subset(&a));
        assert!(a.meets(&[5, 3]));
        let big = TrackSet::from_tracks(0..40);
        assert_eq!(
            big.replace(3, 45),
            TrackSet::from_tracks((0..40).filter(|&t| t != 3).chain([45]))
        );
        assert_eq!(big.replace(39, 41).tracks().last(), Some(&41));
        assert_eq!(
            TrackSet::from_tracks([5, 9]).replace(9, 1).tracks(),
            &[1, 5]
        );
    }

    #[test]
    fn hash_follows_the_content() {
        let a = TrackSet::from_tracks([1, 2, 3]);
        let b = TrackSet::singleton(2).with(3).with(1);
        assert_eq!(a.zobrist(), b.zobrist());
        assert_eq!(
            a.without(2).zobrist(),
            TrackSet::from_tracks([1, 3]).zobrist()
        );
        assert_eq!(
            a.replace(1, 7).zobrist(),
            TrackSet::from_tracks([2, 3, 7]).zobrist()
        );
        assert_eq!(TrackSet::empty().zobrist(), 0);
        assert_ne!(a.zobrist(), TrackSet::from_tracks([1, 2]).zobrist());
    }
}
