//! The atoms of our dictionary: φ_{α|β}(x) = [α ⊆ x and β ∩ x = ∅], "the
//! tracks of α are red and those of β are blue".
//!
//! With β = ∅ this is the paper's Radon basis function φ_α (Section 4.1), and
//! a belief built only from red-favouring sightings never leaves that
//! dictionary. A sighting that favours blue (red < blue likelihood) is, in
//! the Radon basis alone, b·φ_∅ + (a − b)·φ_t with a − b < 0: negative
//! coefficients, inclusion–exclusion over the blue tracks, and an expansion
//! that truncation can turn negative. Written as a·φ_∅ + (b − a)·φ_{∅|t}
//! instead, every coefficient stays positive, so thresholding drops
//! hypotheses rather than breaking the belief, and the l1 contribution of an
//! atom is simply its mass. φ_{α|β} = Σ_{γ ⊆ β} (−1)^{|γ|} φ_{α ∪ γ}, so the
//! dictionary spans the same space; it is just better conditioned for
//! approximation. [`crate::radon::RadonOptions::signed`] keeps the paper's
//! signed form instead.

use crate::track_set::TrackSet;
use std::fmt;
use std::hash::{Hash, Hasher};

/// α | β: tracks fixed red and tracks fixed blue (disjoint).
#[derive(Clone, PartialEq, Eq, PartialOrd, Ord, Default, serde::Serialize, serde::Deserialize)]
pub struct Atom {
    pub red: TrackSet,
    pub blue: TrackSet,
}

impl Hash for Atom {
    fn hash<H: Hasher>(&self, state: &mut H) {
        // The same Zobrist words on both sides: rotate one so that α|β and
        // β|α differ.
        state.write_u64(self.red.zobrist() ^ self.blue.zobrist().rotate_left(29));
    }
}

impl Atom {
    /// The Radon atom φ_α.
    pub(crate) fn radon(red: TrackSet) -> Self {
        Atom {
            red,
            blue: TrackSet::empty(),
        }
    }

    pub fn new(red: TrackSet, blue: TrackSet) -> Self {
        Atom { red, blue }
    }

    /// (|α|, |β|): what the weights depend on.
    pub(crate) fn sizes(&self) -> (usize, usize) {
        (self.red.len(), self.blue.len())
    }

    /// Some(true) if t is fixed red, Some(false) if fixed blue.
    pub(crate) fn fixes(&self, t: u32) -> Option<bool> {
        if self.red.contains(t) {
            Some(true)
        } else if self.blue.contains(t) {
            Some(false)
        } else {
            None
        }
    }

    /// The atom with t also fixed red.
    pub(crate) fn with_red(&self, t: u32) -> Self {
        Atom {
            red: self.red.with(t),
            blue: self.blue.clone(),
        }
    }

    /// The atom with t also fixed blue.
    pub(crate) fn with_blue(&self, t: u32) -> Self {
        Atom {
            red: self.red.clone(),
            blue: self.blue.with(t),
        }
    }

    /// The image of the atom under the transposition of tracks a and b.
    pub(crate) fn swapped(&self, a: u32, b: u32) -> Self {
        let swap = |set: &TrackSet| match (set.contains(a), set.contains(b)) {
            (true, false) => set.replace(a, b),
            (false, true) => set.replace(b, a),
            _ => set.clone(),
        };
        Atom {
            red: swap(&self.red),
            blue: swap(&self.blue),
        }
    }

    /// Whether the transposition of a and b leaves the atom unchanged.
    pub(crate) fn invariant_under(&self, a: u32, b: u32) -> bool {
        self.fixes(a) == self.fixes(b)
    }

    /// Whether some track of `tracks` is fixed (red or blue) by the atom.
    pub(crate) fn meets(&self, tracks: &[u32]) -> bool {
        self.red.meets(tracks) || self.blue.meets(tracks)
    }

    /// Every track the atom fixes.
    pub fn tracks(&self) -> impl Iterator<Item = u32> + '_ {
        self.red.tracks().iter().chain(self.blue.tracks()).copied()
    }
}

impl fmt::Debug for Atom {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.blue.is_empty() {
            write!(f, "{:?}", self.red)
        } else {
            write!(f, "{:?}|{:?}", self.red, self.blue)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(t: &[u32]) -> TrackSet {
        TrackSet::from_tracks(t.iter().copied())
    }

    #[test]
    fn swapping_moves_both_sides() {
        let atom = Atom::new(set(&[0, 4]), set(&[2]));
        assert_eq!(atom.swapped(0, 2), Atom::new(set(&[2, 4]), set(&[0])));
        assert_eq!(atom.swapped(0, 1), Atom::new(set(&[1, 4]), set(&[2])));
        assert!(atom.invariant_under(1, 3));
        assert!(!atom.invariant_under(0, 2));
        assert!(Atom::new(set(&[0, 4]), set(&[])).invariant_under(0, 4));
        assert_eq!(atom.fixes(2), Some(false));
        assert_eq!(atom.fixes(4), Some(true));
        assert_eq!(atom.fixes(3), None);
    }
}
