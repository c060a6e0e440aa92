//! The selection step (Section IV-D): from the clusters of every slot,
//! pick the K segments most likely to be individual sources. A real source
//! heard in slot j is heard again in slot j + 1, and the two segments
//! share l_seg − l_step samples: the *link correlation* of equation (4),
//! ρ = |corr(S_j(l_step, l_seg), S_{j+1}(0, l_seg − l_step))|, is high
//! between them, while noise and artefacts do not repeat.
//!
//! Over a CTS (n_slot consecutive slots) the score of a segment is the
//! best sum of link correlations along a chain of segments starting at it,
//! one per slot (equation (5)); the chain is found by dynamic programming
//! (Viterbi, max-sum). In each CTS the K best-scoring segments of the
//! first slot, at most one per cluster, are selected, each with its chain:
//! the chain's segment in slot j is C^u_{k,j}, the k-th individual segment
//! of slot j according to CTS_u.

use super::separate::SlotSegments;
use nalgebra::DMatrix;

/// The strongest link correlations from each segment of slot j to the
/// segments of slot j + 1.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LinkLayer {
    /// Per segment of slot j: (segment of slot j + 1, ρ), best first.
    pub links: Vec<Vec<(u32, f32)>>,
}

/// The overlapping part of every segment — the tail (`from_tail`) or the
/// head — re-centred and scaled to unit norm, as rows of a matrix.
fn overlap_rows(segs: &SlotSegments, l_step: usize, from_tail: bool) -> DMatrix<f32> {
    let ov = segs.l_seg - l_step;
    let mut m = DMatrix::<f32>::zeros(segs.len(), ov);
    for i in 0..segs.len() {
        let s = segs.segment(i);
        let part = if from_tail { &s[l_step..] } else { &s[..ov] };
        let mean = part.iter().sum::<f32>() / ov as f32;
        let norm = part.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>().sqrt();
        let inv = if norm > 0.0 { 1.0 / norm } else { 0.0 };
        for (k, v) in part.iter().enumerate() {
            m[(i, k)] = (v - mean) * inv;
        }
    }
    m
}

/// Link correlations (equation (4)) from every segment of slot j (`a`) to
/// every segment of slot j + 1 (`b`), keeping the `keep` strongest per
/// segment: a chain never profits from a weak link when strong ones exist,
/// and the dense matrices of all slot pairs would not fit in memory.
pub fn link_layer(a: &SlotSegments, b: &SlotSegments, l_step: usize, keep: usize) -> LinkLayer {
    if a.is_empty() || b.is_empty() {
        return LinkLayer {
            links: vec![Vec::new(); a.len()],
        };
    }
    let tails = overlap_rows(a, l_step, true);
    let heads = overlap_rows(b, l_step, false);
    let rho = &tails * heads.transpose();
    let keep = keep.max(1).min(b.len());
    let mut row: Vec<(u32, f32)> = Vec::with_capacity(b.len());
    let links = (0..a.len())
        .map(|i| {
            row.clear();
            row.extend((0..b.len()).map(|j| (j as u32, rho[(i, j)].abs())));
            let by_rho = |x: &(u32, f32), y: &(u32, f32)| y.1.total_cmp(&x.1).then(x.0.cmp(&y.0));
            if keep < row.len() {
                row.select_nth_unstable_by(keep - 1, by_rho);
                row.truncate(keep);
            }
            row.sort_by(by_rho);
            row.clone()
        })
        .collect();
    LinkLayer { links }
}

/// One selected individual segment and its chain through a CTS.
#[derive(Debug, Clone, PartialEq)]
pub struct Chain {
    /// Sum of link correlations along the chain (equation (5)).
    pub score: f32,
    /// Cluster of the first segment.
    pub cluster: u32,
    /// The chain's segment in each slot of the CTS (`None` once a slot has
    /// nothing to link to).
    pub segments: Vec<Option<u32>>,
}

/// Selects the K chains of CTS_u. `layers[i]` links slot u + i to
/// u + i + 1 (n_slot − 1 layers); `labels` are the clusters of slot u's
/// segments and `last_len` the number of segments in the CTS's last slot.
pub fn select_cts(layers: &[&LinkLayer], labels: &[u32], last_len: usize, k: usize) -> Vec<Chain> {
    let steps = layers.len();
    // best[i][s]: best chain score from segment s of slot u + i to the end.
    let mut best: Vec<Vec<f32>> = vec![Vec::new(); steps + 1];
    let mut next: Vec<Vec<Option<u32>>> = vec![Vec::new(); steps];
    best[steps] = vec![0.0; last_len];
    for i in (0..steps).rev() {
        let (scores, nexts): (Vec<f32>, Vec<Option<u32>>) = layers[i]
            .links
            .iter()
            .map(|links| {
                let mut top = (0.0f32, None);
                for &(t, rho) in links {
                    let v = rho + best[i + 1].get(t as usize).copied().unwrap_or(0.0);
                    if top.1.is_none() || v > top.0 {
                        top = (v, Some(t));
                    }
                }
                top
            })
            .unzip();
        best[i] = scores;
        next[i] = nexts;
    }
    let first = if steps == 0 { &best[0] } else { &best[0] };
    // The best segment of every cluster, then the K best clusters.
    let clusters = labels.iter().map(|&l| l as usize + 1).max().unwrap_or(0);
    let mut per_cluster: Vec<Option<(f32, u32)>> = vec![None; clusters];
    for (s, &l) in labels.iter().enumerate() {
        let v = first.get(s).copied().unwrap_or(0.0);
        let slot = &mut per_cluster[l as usize];
        if slot.is_none_or(|(b, _)| v > b) {
            *slot = Some((v, s as u32));
        }
    }
    let mut ranked: Vec<(f32, u32, u32)> = per_cluster
        .iter()
        .enumerate()
        .filter_map(|(c, b)| b.map(|(v, s)| (v, c as u32, s)))
        .collect();
    ranked.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.2.cmp(&b.2)));
    ranked
        .into_iter()
        .take(k)
        .map(|(score, cluster, s)| {
            let mut segments = Vec::with_capacity(steps + 1);
            let mut cur = Some(s);
            segments.push(cur);
            for nx in next.iter() {
                cur = cur.and_then(|c| nx.get(c as usize).copied().flatten());
                segments.push(cur);
            }
            Chain {
                score,
                cluster,
                segments,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Slots cut from two long sources with l_seg = 20, l_step = 5; every
    /// slot also has a fresh noise segment.
    fn slots(n: usize) -> Vec<SlotSegments> {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let src: Vec<Vec<f64>> = (0..2).map(|_| (0..200).map(|_| rng.gen::<f64>() - 0.5).collect()).collect();
        (0..n)
            .map(|j| {
                let mut s = SlotSegments {
                    l_seg: 20,
                    ..SlotSegments::default()
                };
                s.push(0, (0..20).map(|_| rng.gen::<f64>() - 0.5));
                s.push(1, src[1][5 * j..5 * j + 20].iter().map(|v| -v));
                s.push(2, src[0][5 * j..5 * j + 20].iter().copied());
                s
            })
            .collect()
    }

    #[test]
    fn link_correlation_chains_the_same_source() {
        let s = slots(2);
        let layer = link_layer(&s[0], &s[1], 5, 3);
        assert_eq!(layer.links[1][0].0, 1);
        assert!(layer.links[1][0].1 > 0.999);
        assert_eq!(layer.links[2][0].0, 2);
        assert!(layer.links[0][0].1 < 0.9);
        assert_eq!(link_layer(&s[0], &s[1], 5, 1).links[2].len(), 1);
    }

    #[test]
    fn selection_picks_sources_not_noise_one_per_cluster() {
        let s = slots(4);
        let layers: Vec<LinkLayer> = (0..3).map(|j| link_layer(&s[j], &s[j + 1], 5, 3)).collect();
        let refs: Vec<&LinkLayer> = layers.iter().collect();
        // Each segment its own cluster.
        let chains = select_cts(&refs, &[0, 1, 2], s[3].len(), 2);
        assert_eq!(chains.len(), 2);
        let mut firsts: Vec<u32> = chains.iter().map(|c| c.segments[0].unwrap()).collect();
        firsts.sort();
        assert_eq!(firsts, vec![1, 2]);
        for c in &chains {
            assert!(c.score > 2.99, "{c:?}");
            let s0 = c.segments[0].unwrap();
            assert!(c.segments.iter().all(|&x| x == Some(s0)));
        }
        // Sources 1 and 2 in one cluster: only one of them may be chosen.
        let chains = select_cts(&refs, &[0, 1, 1], s[3].len(), 2);
        assert_eq!(chains.len(), 2);
        assert_eq!(chains[1].segments[0], Some(0));
        assert!(chains[1].score < chains[0].score);
    }
}
