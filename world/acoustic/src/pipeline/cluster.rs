//! The clustering step (Section IV-C): within one time slot, separated
//! segments from all groups are clustered by agglomerative hierarchical
//! clustering with the distance of equation (2), D = 1 − |corr|, into
//! 2K clusters. A real source is separated, in similar form, by several
//! neighbouring groups (spatial redundancy), so it forms a tight cluster;
//! noise and artefacts of one group do not.
//!
//! The dendrogram is built with the nearest-neighbour-chain algorithm
//! (O(ρ²) time for ρ segments, against the O(ρ³) the paper quotes for the
//! naive method), which is exact for the reducible linkages offered here.

use super::separate::SlotSegments;
use nalgebra::DMatrix;

/// How the distance between two clusters follows from their members'.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Linkage {
    /// Nearest members (chains easily through noise).
    Single,
    /// Farthest members.
    Complete,
    /// Mean over member pairs (UPGMA): the default, robust to a few
    /// artefacts in a cluster.
    Average,
}

impl Linkage {
    /// Lance–Williams update: distance from the union of clusters a and b
    /// (sizes `na`, `nb`) to another cluster.
    #[inline]
    fn combine(self, da: f32, db: f32, na: usize, nb: usize) -> f32 {
        match self {
            Linkage::Single => da.min(db),
            Linkage::Complete => da.max(db),
            Linkage::Average => (na as f32 * da + nb as f32 * db) / (na + nb) as f32,
        }
    }
}

/// The distance matrix of equation (2), D = 1 − |corr|, of a slot's
/// segments (unit norm, so corr is a dot product: one matrix product).
pub(crate) fn correlation_distances(segs: &SlotSegments) -> DMatrix<f32> {
    let n = segs.len();
    let s = DMatrix::from_row_slice(n, segs.l_seg, &segs.data);
    let mut d = &s * s.transpose();
    d.apply(|c| *c = (1.0 - c.abs()).max(0.0));
    d.fill_diagonal(0.0);
    d
}

/// Cuts the dendrogram of `dist` (symmetric, consumed) at `clusters`
/// clusters. Returns a label per item, 0-based in order of first
/// appearance.
pub(crate) fn agglomerate(mut dist: DMatrix<f32>, clusters: usize, linkage: Linkage) -> Vec<u32> {
    let n = dist.nrows();
    if n == 0 {
        return Vec::new();
    }
    let merges = nn_chain(&mut dist, linkage);
    // Reducible linkages: the dendrogram is the chain's merges sorted by
    // height (stable sort keeps the order of equal heights).
    let mut order: Vec<usize> = (0..merges.len()).collect();
    order.sort_by(|&a, &b| merges[a].2.total_cmp(&merges[b].2));
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut x: usize) -> usize {
        while parent[x] != x {
            parent[x] = parent[parent[x]];
            x = parent[x];
        }
        x
    }
    let cuts = n.saturating_sub(clusters.max(1));
    for &m in order.iter().take(cuts) {
        let (a, b, _) = merges[m];
        let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
        if ra != rb {
            parent[rb] = ra;
        }
    }
    let mut label_of_root = vec![u32::MAX; n];
    let mut next = 0;
    (0..n)
        .map(|i| {
            let r = find(&mut parent, i);
            if label_of_root[r] == u32::MAX {
                label_of_root[r] = next;
                next += 1;
            }
            label_of_root[r]
        })
        .collect()
}

/// The nearest-neighbour chain: follow nearest neighbours until two
/// clusters are each other's nearest, merge them, continue from the rest
/// of the chain. Returns the n − 1 merges (a, b, height), a keeping the
/// merged cluster.
fn nn_chain(d: &mut DMatrix<f32>, linkage: Linkage) -> Vec<(usize, usize, f32)> {
    let n = d.nrows();
    let mut active: Vec<usize> = (0..n).collect();
    let mut pos: Vec<usize> = (0..n).collect();
    let mut size = vec![1usize; n];
    let mut chain: Vec<usize> = Vec::new();
    let mut merges = Vec::with_capacity(n.saturating_sub(1));
    while active.len() > 1 {
        if chain.is_empty() {
            chain.push(active[0]);
        }
        let (a, b) = loop {
            let a = chain[chain.len() - 1];
            let prev = (chain.len() >= 2).then(|| chain[chain.len() - 2]);
            // Column a is contiguous (column-major), and d is symmetric.
            let col = d.column(a);
            let (mut best, mut best_d) = match prev {
                Some(p) => (p, col[p]),
                None => (usize::MAX, f32::INFINITY),
            };
            for &x in &active {
                // Strictly smaller: ties keep the previous link, which is
                // what guarantees the chain ends in a reciprocal pair.
                if x != a && col[x] < best_d {
                    best = x;
                    best_d = col[x];
                }
            }
            if best == usize::MAX {
                // Only NaNs around: take any other active cluster.
                best = *active.iter().find(|&&x| x != a).unwrap_or(&a);
            }
            if Some(best) == prev {
                chain.pop();
                chain.pop();
                break (a, best);
            }
            chain.push(best);
        };
        let height = d[(a, b)];
        merges.push((a, b, height));
        for &x in &active {
            if x != a && x != b {
                let v = linkage.combine(d[(x, a)], d[(x, b)], size[a], size[b]);
                d[(x, a)] = v;
                d[(a, x)] = v;
            }
        }
        size[a] += size[b];
        let pb = pos[b];
        active.swap_remove(pb);
        if pb < active.len() {
            pos[active[pb]] = pb;
        }
    }
    merges
}

/// The clusters of one slot, and the spatial support of every segment.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SlotClusters {
    /// Cluster of every segment, 0-based.
    pub labels: Vec<u32>,
    /// Per segment, the number of distinct groups (its own included) that
    /// separated a segment with |corr| ≥ the hearing threshold to it: how
    /// many neighbouring groups "hear" it — the spatial redundancy that
    /// Section IV-C's rationale rests on.
    pub support: Vec<u32>,
}

/// Clusters one slot's segments into `clusters` clusters and counts each
/// segment's support at `hear_threshold`.
pub fn cluster_slot(
    segs: &SlotSegments,
    clusters: usize,
    linkage: Linkage,
    hear_threshold: f32,
) -> SlotClusters {
    if segs.is_empty() {
        return SlotClusters::default();
    }
    let d = correlation_distances(segs);
    let support = support(&d, &segs.group, hear_threshold);
    SlotClusters {
        labels: agglomerate(d, clusters, linkage),
        support,
    }
}

/// Distinct groups within distance 1 − `threshold` of every item.
fn support(d: &DMatrix<f32>, group: &[u32], threshold: f32) -> Vec<u32> {
    let n = d.nrows();
    let max_d = 1.0 - threshold;
    let groups = group.iter().map(|&g| g as usize + 1).max().unwrap_or(0);
    let mut seen = vec![usize::MAX; groups];
    (0..n)
        .map(|i| {
            let col = d.column(i);
            let mut count = 0;
            for j in 0..n {
                let g = group[j] as usize;
                if col[j] <= max_d && seen[g] != i {
                    seen[g] = i;
                    count += 1;
                }
            }
            count
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Brute-force agglomerative clustering, O(n³), for checking.
    fn naive(d: &DMatrix<f32>, clusters: usize, linkage: Linkage) -> Vec<Vec<usize>> {
        let mut groups: Vec<Vec<usize>> = (0..d.nrows()).map(|i| vec![i]).collect();
        let dist = |a: &Vec<usize>, b: &Vec<usize>| -> f32 {
            let it = a.iter().flat_map(|&i| b.iter().map(move |&j| (i, j)));
            match linkage {
                Linkage::Single => it.map(|(i, j)| d[(i, j)]).fold(f32::INFINITY, f32::min),
                Linkage::Complete => it.map(|(i, j)| d[(i, j)]).fold(0.0, f32::max),
                Linkage::Average => {
                    it.map(|(i, j)| d[(i, j)]).sum::<f32>() / (a.len() * b.len()) as f32
                }
            }
        };
        while groups.len() > clusters {
            let mut best = (f32::INFINITY, 0, 0);
            for i in 0..groups.len() {
                for j in i + 1..groups.len() {
                    let v = dist(&groups[i], &groups[j]);
                    if v < best.0 {
                        best = (v, i, j);
                    }
                }
            }
            let g = groups.remove(best.2);
            groups[best.1].extend(g);
        }
        let mut out: Vec<Vec<usize>> = groups
            .into_iter()
            .map(|mut g| {
                g.sort();
                g
            })
            .collect();
        out.sort();
        out
    }

    fn as_sets(labels: &[u32]) -> Vec<Vec<usize>> {
        let k = labels.iter().map(|&l| l as usize + 1).max().unwrap_or(0);
        let mut out = vec![Vec::new(); k];
        for (i, &l) in labels.iter().enumerate() {
            out[l as usize].push(i);
        }
        out.sort();
        out
    }

    #[test]
    fn nn_chain_matches_the_naive_algorithm() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        for trial in 0..20 {
            let n = 5 + trial * 2;
            let pts: Vec<(f32, f32)> = (0..n).map(|_| (rng.gen(), rng.gen())).collect();
            let d = DMatrix::from_fn(n, n, |i, j| {
                ((pts[i].0 - pts[j].0).powi(2) + (pts[i].1 - pts[j].1).powi(2)).sqrt()
            });
            for linkage in [Linkage::Single, Linkage::Complete, Linkage::Average] {
                for k in [1, 3, n / 2] {
                    let got = as_sets(&agglomerate(d.clone(), k, linkage));
                    assert_eq!(got, naive(&d, k, linkage), "{linkage:?} n={n} k={k}");
                }
            }
        }
    }

    #[test]
    fn segments_of_one_source_cluster_together() {
        // Three sources, each seen by four groups with a little noise, plus
        // two pure-noise segments.
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let src: Vec<Vec<f64>> = (0..3)
            .map(|_| (0..100).map(|_| rng.gen::<f64>() - 0.5).collect())
            .collect();
        let mut segs = SlotSegments {
            l_seg: 100,
            ..SlotSegments::default()
        };
        for g in 0..12u32 {
            let s = &src[g as usize % 3];
            let sign = if g % 2 == 0 { 1.0 } else { -1.0 };
            segs.push(
                g,
                s.iter().map(|v| sign * v + 0.05 * (rng.gen::<f64>() - 0.5)),
            );
        }
        for g in 12..14u32 {
            segs.push(g, (0..100).map(|_| rng.gen::<f64>() - 0.5));
        }
        let clusters = cluster_slot(&segs, 5, Linkage::Average, 0.9);
        let labels = &clusters.labels;
        // Each source is heard by its four groups; noise only by its own.
        assert_eq!(&clusters.support[..12], &[4; 12]);
        assert_eq!(&clusters.support[12..], &[1, 1]);
        for i in 0..12 {
            for j in 0..12 {
                assert_eq!(labels[i] == labels[j], i % 3 == j % 3, "{labels:?}");
            }
        }
        assert_ne!(labels[12], labels[13]);
        assert!(labels[12..].iter().all(|l| !labels[..12].contains(l)));
    }
}
