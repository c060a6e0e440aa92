//! The factored identity belief on the wire (docs/design/identity.md, "In
//! the distributed runtime"): a linked tree of groups as it moves between
//! leaders in a [`Transfer`](super::leader_to_leader::Transfer) — a mix
//! needs the trees of its two tracks in one place — and as a leader gives
//! the trees it holds in its answer to an identity query.

use super::bounds::Bounds;
use super::valid::{distinct_tracks, require};
use serde::{Deserialize, Serialize};

/// The most tracks and ports of one group: the factored identity
/// belief's largest table (9! assignments).
pub const MAX_GROUP: u32 = 9;

/// The group cap of a deployment's factored identity belief: the
/// largest, the belief's own default (`FactoredIdentityOptions`), which is
/// exact below it.
pub const DEFAULT_MAX_GROUP: u32 = MAX_GROUP;

/// One group: k tracks (real ones below n, link ports from n on), the k
/// identities they carry between them (stars of ports from n on), and
/// the assignments of non-zero probability among the k!, by rank (in
/// increasing order) with their probabilities. Sparse because a large
/// group is: mixes and cuts leave all but a few of its assignments at
/// exactly 0 (on random-waypoint crowds of 100 and 1,000, 99.6% of the
/// entries of groups of 7 tracks or more), so a group of 9 (362,880
/// assignments, 2.9 MB dense) moves in kilobytes, bit for bit.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireGroup {
    pub tracks: Vec<u32>,
    pub identities: Vec<u32>,
    pub ranks: Vec<u32>,
    pub probs: Vec<f64>,
}

/// A real track's leak (the probability that its identity lies outside
/// its group's table) and background row: `shared` for every identity not
/// in `listed`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireBackground {
    pub track: u32,
    pub leak: f64,
    pub shared: f64,
    pub listed: Vec<(u32, f64)>,
}

/// A linked tree of groups with the background of each of its real
/// tracks.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireTree {
    pub groups: Vec<WireGroup>,
    pub backgrounds: Vec<WireBackground>,
}

impl WireTree {
    /// Groups of 1..=[`MAX_GROUP`] tracks with as many identities and k!
    /// probabilities, ids below 3n (ports are numbered in pairs from n,
    /// one pair per link of the sender's whole belief, which has fewer
    /// links than groups, each group holding a real track), one background
    /// per real track, every probability finite and in [0, 1].
    pub fn check(&self, n: u32) -> Result<(), String> {
        if self.groups.is_empty() {
            return Err("a tree of no groups".into());
        }
        let top = n.saturating_mul(3);
        let mut real = Vec::new();
        for (i, g) in self.groups.iter().enumerate() {
            let k = g.tracks.len();
            if k == 0 || k > MAX_GROUP as usize || g.identities.len() != k {
                return Err(format!(
                    "group {i}: {k} tracks and {} identities (1..={MAX_GROUP} each, as many)",
                    g.identities.len()
                ));
            }
            let count: usize = (1..=k).product();
            if g.ranks.len() != g.probs.len() || g.probs.is_empty() {
                return Err(format!(
                    "group {i}: {} ranks and {} probabilities (as many, at least one)",
                    g.ranks.len(),
                    g.probs.len()
                ));
            }
            if !g.ranks.windows(2).all(|w| w[0] < w[1])
                || g.ranks.last().is_some_and(|&r| r as usize >= count)
            {
                return Err(format!(
                    "group {i}: ranks out of order or beyond the {k}! assignments"
                ));
            }
            if let Some(p) = g.probs.iter().find(|p| !(**p > 0.0 && **p <= 1.0)) {
                return Err(format!("group {i}: probability {p}"));
            }
            distinct_tracks(&format!("group {i} tracks"), &g.tracks, top)?;
            distinct_tracks(&format!("group {i} identities"), &g.identities, top)?;
            real.extend(g.tracks.iter().copied().filter(|&t| t < n));
        }
        real.sort_unstable();
        let mut listed: Vec<u32> = self.backgrounds.iter().map(|b| b.track).collect();
        listed.sort_unstable();
        if listed != real {
            return Err(format!(
                "backgrounds for tracks {listed:?}, the tree's real tracks are {real:?}"
            ));
        }
        for b in &self.backgrounds {
            let numbers = [b.leak, b.shared]
                .into_iter()
                .chain(b.listed.iter().map(|&(_, p)| p));
            if let Some(p) = numbers.into_iter().find(|p| !(0.0..=1.0).contains(p)) {
                return Err(format!("background of track {}: probability {p}", b.track));
            }
            let ids: Vec<u32> = b.listed.iter().map(|&(i, _)| i).collect();
            distinct_tracks(&format!("background of track {}", b.track), &ids, n)?;
        }
        Ok(())
    }

    /// Its real tracks (below n).
    pub fn tracks(&self, n: u32) -> impl Iterator<Item = u32> + '_ {
        self.groups
            .iter()
            .flat_map(|g| g.tracks.iter().copied())
            .filter(move |&t| t < n)
    }

    /// The probabilities it carries (what moving it costs).
    pub fn entries(&self) -> usize {
        self.groups.iter().map(|g| g.probs.len()).sum()
    }
}

impl Bounds {
    /// Trees of the factored identity belief, on an identity stream only.
    pub(crate) fn check_trees(&self, trees: &[WireTree]) -> Result<(), String> {
        require(trees.is_empty() || self.identities, || {
            "trees of a factored identity belief on a stream without identities".into()
        })?;
        for (i, tree) in trees.iter().enumerate() {
            tree.check(self.tracks)
                .map_err(|e| format!("tree {i}: {e}"))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tree() -> WireTree {
        WireTree {
            groups: vec![
                WireGroup {
                    tracks: vec![0, 4],
                    identities: vec![1, 5],
                    ranks: vec![0, 1],
                    probs: vec![0.75, 0.25],
                },
                WireGroup {
                    tracks: vec![2, 5],
                    identities: vec![3, 4],
                    ranks: vec![1],
                    probs: vec![1.0],
                },
            ],
            backgrounds: vec![
                WireBackground {
                    track: 0,
                    leak: 0.0,
                    shared: 0.0,
                    listed: vec![(1, 1.0)],
                },
                WireBackground {
                    track: 2,
                    leak: 0.1,
                    shared: 0.25,
                    listed: vec![],
                },
            ],
        }
    }

    #[test]
    fn a_tree_is_checked_before_anything_reads_it() {
        // n = 4: tracks 0 and 2 are real, 4 and 5 the two ends of a link.
        assert_eq!(tree().check(4), Ok(()));
        assert_eq!(tree().tracks(4).collect::<Vec<_>>(), vec![0, 2]);
        assert_eq!(tree().entries(), 3);
        let mut t = tree();
        t.groups[0].probs.pop();
        assert!(t
            .check(4)
            .unwrap_err()
            .contains("2 ranks and 1 probabilities"));
        let mut t = tree();
        t.groups[1].ranks[0] = 2;
        assert!(t
            .check(4)
            .unwrap_err()
            .contains("beyond the 2! assignments"));
        let mut t = tree();
        t.groups[0].ranks = vec![1, 0];
        assert!(t.check(4).unwrap_err().contains("out of order"));
        let mut t = tree();
        t.groups[0].probs[1] = 0.0;
        assert!(t.check(4).unwrap_err().contains("probability 0"));
        let mut t = tree();
        t.groups[1].tracks[1] = u32::MAX;
        assert!(t.check(4).unwrap_err().contains("out of range"));
        // Port ids name links of the sender's whole belief: any below 3n.
        let mut t = tree();
        t.groups[0].tracks[1] = 10;
        t.groups[1].tracks[1] = 11;
        assert_eq!(t.check(4), Ok(()));
        t.groups[1].tracks[1] = 12;
        assert!(t
            .check(4)
            .unwrap_err()
            .contains("12 is out of range (0..12)"));
        let mut t = tree();
        t.backgrounds.pop();
        assert!(t.check(4).unwrap_err().contains("real tracks are [0, 2]"));
        let mut t = tree();
        t.backgrounds[1].leak = f64::NAN;
        assert!(t.check(4).unwrap_err().contains("probability NaN"));
        let mut t = tree();
        t.groups[0].identities[1] = 1;
        assert!(t.check(4).unwrap_err().contains("lists 1 twice"));
        assert!(WireTree {
            groups: vec![],
            backgrounds: vec![]
        }
        .check(4)
        .is_err());
    }
}
