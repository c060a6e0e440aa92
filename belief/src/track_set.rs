//! A set of track ids: the index α of a Radon basis function φ_α
//! (Section 4.1). Kept sorted so that equal sets hash equally and unions and
//! intersections are linear merges; small sets (the common case) live inline.

use smallvec::SmallVec;
use std::fmt;

/// A sorted set of distinct track ids.
#[derive(Clone, PartialEq, Eq, Hash, PartialOrd, Ord, Default)]
pub struct TrackSet(SmallVec<[u32; 6]>);

impl TrackSet {
    pub fn empty() -> Self {
        TrackSet(SmallVec::new())
    }

    /// A set from any ids; duplicates are merged.
    pub fn from_tracks(tracks: impl IntoIterator<Item = u32>) -> Self {
        let mut v: SmallVec<[u32; 6]> = tracks.into_iter().collect();
        v.sort_unstable();
        v.dedup();
        TrackSet(v)
    }

    pub fn singleton(t: u32) -> Self {
        let mut v = SmallVec::new();
        v.push(t);
        TrackSet(v)
    }

    pub fn len(&self) -> usize {
        self.0.len()
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    pub fn tracks(&self) -> &[u32] {
        &self.0
    }

    pub fn contains(&self, t: u32) -> bool {
        if self.0.len() <= 16 {
            self.0.contains(&t)
        } else {
            self.0.binary_search(&t).is_ok()
        }
    }

    /// α ∪ {t}.
    pub fn with(&self, t: u32) -> Self {
        let mut v = self.0.clone();
        if let Err(at) = v.binary_search(&t) {
            v.insert(at, t);
        }
        TrackSet(v)
    }

    /// α − {t}.
    pub fn without(&self, t: u32) -> Self {
        let mut v = self.0.clone();
        if let Ok(at) = v.binary_search(&t) {
            v.remove(at);
        }
        TrackSet(v)
    }

    /// α △ {from, to} for a set holding `from` and not `to`: the set the
    /// rollup moves mass to when the targets on `from` and `to` swap.
    pub fn replace(&self, from: u32, to: u32) -> Self {
        let mut v = self.0.clone();
        if let Ok(at) = v.binary_search(&from) {
            v.remove(at);
        }
        if let Err(at) = v.binary_search(&to) {
            v.insert(at, to);
        }
        TrackSet(v)
    }

    /// |α ∩ β| by a linear merge.
    pub fn intersection_len(&self, other: &TrackSet) -> usize {
        let (a, b) = (&self.0, &other.0);
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
    pub fn union_len(&self, other: &TrackSet) -> usize {
        self.len() + other.len() - self.intersection_len(other)
    }

    /// α ∪ β.
    pub fn union(&self, other: &TrackSet) -> TrackSet {
        TrackSet::from_tracks(self.0.iter().chain(other.0.iter()).copied())
    }

    pub fn is_subset(&self, other: &TrackSet) -> bool {
        self.intersection_len(other) == self.len()
    }

    /// Whether α and the sorted slice share an element.
    pub fn meets(&self, others: &[u32]) -> bool {
        others.iter().any(|&t| self.contains(t))
    }
}

impl fmt::Debug for TrackSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_set().entries(self.0.iter()).finish()
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
    }
}
