//! The independent blocks of an identity belief: which tracks can carry
//! which identities at all.
//!
//! A belief p(π) ∝ Π_t A\[t\]\[π(t)\] with some entries A\[t\]\[i\] = 0 (in
//! an information matrix: L\[t\]\[i\] = −∞, "track t cannot carry identity
//! i") factorizes over the connected components of the bipartite graph
//! with an edge t — i for every positive entry: a permutation with
//! positive weight maps the tracks of a component onto its identities, so
//! p is a product of one independent belief per component, and so are its
//! marginals (zero between components) and its most likely assignment.
//!
//! ## Which blocks a known start and mixes create
//! With a known start, track t can carry only its initial identity π₀(t):
//! n blocks of one track. A mix of tracks a and b joins the blocks of a and
//! b — the one target may now be on either track — and nothing else: the
//! exact belief after any events is supported on the assignments that map
//! each connected component of the *mixing graph* (tracks joined by the
//! mixes since the start) onto the initial identities of its tracks. Reads
//! never join blocks (a read of an identity outside the track's block has
//! the same likelihood under every possible assignment and changes
//! nothing). So with a known start the blocks are the components of the
//! mixing graph; in a crowd of 10,000 people most people have met few
//! others, and the belief is a permutation of small blocks
//! ([`crate::information`] keeps the −∞ entries exactly, and
//! [`crate::marginals`] computes each block on its own — exactly
//! when it is small). Without a known start there is one block of n.

/// One independent block: `tracks.len() == identities.len()` in a belief
/// with any positive assignment. Both lists are ascending.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Block {
    pub tracks: Vec<usize>,
    pub identities: Vec<usize>,
}

impl Block {
    /// The number of tracks.
    pub fn size(&self) -> usize {
        self.tracks.len()
    }

    /// Whether the block has as many tracks as identities (else no
    /// assignment has positive weight).
    pub(crate) fn is_balanced(&self) -> bool {
        self.tracks.len() == self.identities.len()
    }
}

/// The blocks of the n × n row-major pattern `positive(t, i)`, in the order
/// of their smallest track; tracks or identities with no positive entry at
/// all form blocks with an empty other side.
pub(crate) fn blocks(n: usize, positive: impl Fn(usize, usize) -> bool) -> Vec<Block> {
    // Union–find over 2n nodes: tracks 0..n, identities n..2n.
    let mut parent: Vec<usize> = (0..2 * n).collect();
    for t in 0..n {
        for i in 0..n {
            if positive(t, i) {
                let (a, b) = (root(&mut parent, t), root(&mut parent, n + i));
                if a != b {
                    parent[a.max(b)] = a.min(b);
                }
            }
        }
    }
    let mut index = vec![usize::MAX; 2 * n];
    let mut out: Vec<Block> = Vec::new();
    for node in 0..2 * n {
        let r = root(&mut parent, node);
        if index[r] == usize::MAX {
            index[r] = out.len();
            out.push(Block {
                tracks: Vec::new(),
                identities: Vec::new(),
            });
        }
        let block = &mut out[index[r]];
        if node < n {
            block.tracks.push(node);
        } else {
            block.identities.push(node - n);
        }
    }
    out
}

/// The root of `x` in a union–find forest, halving paths.
fn root(parent: &mut [usize], mut x: usize) -> usize {
    while parent[x] != x {
        parent[x] = parent[parent[x]];
        x = parent[x];
    }
    x
}

/// The sizes of the blocks a known start and `mixes` (pairs of tracks
/// that mixed with a positive swap) make among `n` tracks: the connected
/// components of the mixing graph (see the module docs), largest first.
pub fn mixing_block_sizes(n: usize, mixes: impl IntoIterator<Item = (usize, usize)>) -> Vec<usize> {
    let mut parent: Vec<usize> = (0..n).collect();
    for (a, b) in mixes {
        let (a, b) = (root(&mut parent, a), root(&mut parent, b));
        if a != b {
            parent[a.max(b)] = a.min(b);
        }
    }
    let mut sizes = vec![0usize; n];
    for t in 0..n {
        let r = root(&mut parent, t);
        sizes[r] += 1;
    }
    sizes.retain(|&s| s > 0);
    sizes.sort_unstable_by(|a, b| b.cmp(a));
    sizes
}

/// The blocks of an information matrix (row-major, entries finite or −∞).
pub(crate) fn blocks_of_log_likelihoods(n: usize, l: &[f64]) -> Vec<Block> {
    blocks(n, |t, i| l[t * n + i] > f64::NEG_INFINITY)
}

/// The k × k sub-matrix of a row-major n × n matrix on a block's tracks and
/// identities, row-major.
pub(crate) fn sub_matrix(n: usize, m: &[f64], block: &Block) -> Vec<f64> {
    let mut out = Vec::with_capacity(block.tracks.len() * block.identities.len());
    for &t in &block.tracks {
        let row = &m[t * n..(t + 1) * n];
        out.extend(block.identities.iter().map(|&i| row[i]));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_permutation_of_pairs_and_singles() {
        // Tracks 0 and 2 share identities {1, 3}; track 1 is identity 0;
        // track 3 is identity 2.
        let inf = f64::NEG_INFINITY;
        let l = vec![
            inf, 0.0, inf, -1.0, //
            0.0, inf, inf, inf, //
            inf, -2.0, inf, 0.0, //
            inf, inf, 0.0, inf,
        ];
        let b = blocks_of_log_likelihoods(4, &l);
        assert_eq!(
            b,
            vec![
                Block {
                    tracks: vec![0, 2],
                    identities: vec![1, 3]
                },
                Block {
                    tracks: vec![1],
                    identities: vec![0]
                },
                Block {
                    tracks: vec![3],
                    identities: vec![2]
                },
            ]
        );
        assert!(b.iter().all(Block::is_balanced));
        assert_eq!(sub_matrix(4, &l, &b[0]), vec![0.0, -1.0, -2.0, 0.0]);
    }

    #[test]
    fn mixes_join_blocks_and_nothing_else() {
        // 0–1–2 chained, 3 alone, 4–5.
        assert_eq!(
            mixing_block_sizes(6, [(0, 1), (4, 5), (2, 1)]),
            vec![3, 2, 1]
        );
        assert_eq!(mixing_block_sizes(3, []), vec![1, 1, 1]);
    }

    #[test]
    fn dense_is_one_block_and_an_empty_row_is_unbalanced() {
        assert_eq!(blocks(3, |_, _| true).len(), 1);
        let b = blocks(2, |t, _| t == 0);
        assert_eq!(b.len(), 2);
        assert!(!b[0].is_balanced());
        assert_eq!(b[1].tracks, vec![1]);
        assert!(b[1].identities.is_empty());
    }
}
