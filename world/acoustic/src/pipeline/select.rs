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
//! (Viterbi, max-sum). In each CTS K segments of the first slot, at most
//! one per cluster, are selected, each with its chain: the chain's segment
//! in slot j is C^u_{k,j}, the k-th individual segment of slot j according
//! to CTS_u.
//!
//! **Where we depart from the paper.** Ranking by equation (5) alone does
//! not work in simulation: successive slots share (l_seg − l_step)/l_seg
//! = 90 % of their samples, so *any* fixed projection of one group's data
//! — an aggregate of two sources, a direction made by a moving source's
//! changing gain — links to itself with ρ ≈ 1, and real sources and
//! artefacts all score ≈ n_slot − 1. Equation (5) is therefore used as a
//! gate (mean link ≥ `min_link`), and candidates are ranked by their
//! spatial support — how many groups hear them (computed in the clustering
//! step) — the redundancy the paper's own rationale for clustering rests
//! on (Section IV-C: artefacts of one group are "unlikely to be generated
//! by more than one group"). Candidates heard by fewer than `min_support`
//! groups are not selected, so a slot may yield fewer than K segments
//! when fewer than K sources are separable in it.
//!
//! Aggregate segments (Section III-B: a mixture of sources that several
//! groups cannot unmix, typically far groups hearing two close targets
//! with nearly proportional gains) are heard consistently by many groups
//! and link perfectly too. They are recognised as what they are: a
//! candidate that two other, mutually uncorrelated candidates explain
//! (multiple correlation R² ≥ `aggregate_r2`) is a mixture of them and is
//! not selected. (An individual source is also "explained" by the
//! aggregate and its partner, but those two are correlated, so the test
//! does not fire for it.)

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
        let norm = part
            .iter()
            .map(|v| (v - mean) * (v - mean))
            .sum::<f32>()
            .sqrt();
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

/// How candidates are gated and ranked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SelectSettings {
    /// K, the number of chains per CTS.
    pub k: usize,
    /// Least mean link correlation along a candidate's chain.
    pub min_link: f32,
    /// Least number of groups that must hear a candidate.
    pub min_support: u32,
    /// R² above which a candidate counts as an aggregate of two others
    /// (> 1 disables the test).
    pub aggregate_r2: f32,
}

/// Selects the chains of CTS_u. `layers[i]` links slot u + i to
/// u + i + 1 (n_slot − 1 layers); `labels` and `support` are the clusters
/// and support of slot u's segments and `last_len` the number of segments
/// in the CTS's last slot.
/// `corr(a, b)` is the correlation of segments a and b of slot u.
pub fn select_cts(
    layers: &[&LinkLayer],
    labels: &[u32],
    support: &[u32],
    last_len: usize,
    settings: &SelectSettings,
    corr: &dyn Fn(u32, u32) -> f32,
) -> Vec<Chain> {
    let steps = layers.len();
    // best[i][s]: best chain score from segment s of slot u + i to the end
    // (−∞ when the chain cannot reach the last slot).
    let mut best: Vec<Vec<f32>> = vec![Vec::new(); steps + 1];
    let mut next: Vec<Vec<Option<u32>>> = vec![Vec::new(); steps];
    best[steps] = vec![0.0; last_len];
    for i in (0..steps).rev() {
        let (scores, nexts): (Vec<f32>, Vec<Option<u32>>) = layers[i]
            .links
            .iter()
            .map(|links| {
                let mut top = (f32::NEG_INFINITY, None);
                for &(t, rho) in links {
                    let v = rho
                        + best[i + 1]
                            .get(t as usize)
                            .copied()
                            .unwrap_or(f32::NEG_INFINITY);
                    if v > top.0 {
                        top = (v, Some(t));
                    }
                }
                top
            })
            .unzip();
        best[i] = scores;
        next[i] = nexts;
    }
    let gate = settings.min_link * steps as f32;
    // Per cluster, the gated candidate with the most support (then the
    // best chain, then the lowest index); then the best clusters.
    let clusters = labels.iter().map(|&l| l as usize + 1).max().unwrap_or(0);
    let mut per_cluster: Vec<Option<(u32, f32, u32)>> = vec![None; clusters];
    for (s, &l) in labels.iter().enumerate() {
        let score = best[0].get(s).copied().unwrap_or(f32::NEG_INFINITY);
        let sup = support.get(s).copied().unwrap_or(0);
        // NaN scores (never produced, but) fail the gate too.
        let passes = score
            .partial_cmp(&gate)
            .is_some_and(|o| o != std::cmp::Ordering::Less);
        if !passes || sup < settings.min_support {
            continue;
        }
        let slot = &mut per_cluster[l as usize];
        if slot.is_none_or(|(bs, bv, _)| (sup, score) > (bs, bv)) {
            *slot = Some((sup, score, s as u32));
        }
    }
    let mut ranked: Vec<(u32, f32, u32, u32)> = per_cluster
        .iter()
        .enumerate()
        .filter_map(|(c, b)| b.map(|(sup, v, s)| (sup, v, c as u32, s)))
        .collect();
    if settings.aggregate_r2 <= 1.0 && ranked.len() >= 3 {
        let reps: Vec<u32> = ranked.iter().map(|r| r.3).collect();
        let aggregate = aggregates(&reps, settings.aggregate_r2, corr);
        let mut i = 0;
        ranked.retain(|_| {
            i += 1;
            !aggregate[i - 1]
        });
    }
    ranked.sort_by(|a, b| b.0.cmp(&a.0).then(b.1.total_cmp(&a.1)).then(a.3.cmp(&b.3)));
    ranked
        .into_iter()
        .take(settings.k)
        .map(|(_, score, cluster, s)| {
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

/// Which of `reps` are mixtures of two others: R² of the regression on a
/// pair (a, b) with |corr(a, b)| small (< 0.3), neither of them the same
/// source as the candidate (|corr| < 0.9).
fn aggregates(reps: &[u32], r2_min: f32, corr: &dyn Fn(u32, u32) -> f32) -> Vec<bool> {
    let n = reps.len();
    let mut c = vec![0f32; n * n];
    for i in 0..n {
        for j in i + 1..n {
            let v = corr(reps[i], reps[j]);
            c[i * n + j] = v;
            c[j * n + i] = v;
        }
    }
    (0..n)
        .map(|x| {
            for a in 0..n {
                let rxa = c[x * n + a];
                if a == x || rxa.abs() >= 0.9 {
                    continue;
                }
                for b in a + 1..n {
                    let (rxb, rab) = (c[x * n + b], c[a * n + b]);
                    if b == x || rxb.abs() >= 0.9 || rab.abs() >= 0.3 {
                        continue;
                    }
                    let r2 = (rxa * rxa + rxb * rxb - 2.0 * rxa * rxb * rab) / (1.0 - rab * rab);
                    if r2 >= r2_min {
                        return true;
                    }
                }
            }
            false
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
        let src: Vec<Vec<f64>> = (0..2)
            .map(|_| (0..200).map(|_| rng.gen::<f64>() - 0.5).collect())
            .collect();
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
    fn an_aggregate_of_two_candidates_is_not_selected() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let a: Vec<f64> = (0..100).map(|_| rng.gen::<f64>() - 0.5).collect();
        let b: Vec<f64> = (0..100).map(|_| rng.gen::<f64>() - 0.5).collect();
        let mut segs = SlotSegments {
            l_seg: 100,
            ..SlotSegments::default()
        };
        segs.push(0, a.iter().zip(&b).map(|(x, y)| x + 0.8 * y));
        segs.push(1, a.iter().copied());
        segs.push(2, b.iter().copied());
        let corr = |i: u32, j: u32| -> f32 {
            segs.segment(i as usize)
                .iter()
                .zip(segs.segment(j as usize))
                .map(|(x, y)| x * y)
                .sum()
        };
        assert_eq!(aggregates(&[0, 1, 2], 0.9, &corr), vec![true, false, false]);
        // The aggregate has the most support, yet the two sources win.
        let layer = LinkLayer {
            links: vec![vec![(0, 1.0)], vec![(1, 1.0)], vec![(2, 1.0)]],
        };
        let settings = SelectSettings {
            k: 3,
            min_link: 0.9,
            min_support: 1,
            aggregate_r2: 0.9,
        };
        let chains = select_cts(&[&layer], &[0, 1, 2], &[50, 10, 10], 3, &settings, &corr);
        assert_eq!(
            chains
                .iter()
                .map(|c| c.segments[0].unwrap())
                .collect::<Vec<_>>(),
            vec![1, 2]
        );
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
        let settings = SelectSettings {
            k: 2,
            min_link: 0.9,
            min_support: 1,
            aggregate_r2: 0.9,
        };
        let corr = |a: u32, b: u32| -> f32 {
            s[0].segment(a as usize)
                .iter()
                .zip(s[0].segment(b as usize))
                .map(|(x, y)| x * y)
                .sum()
        };
        // Each segment its own cluster; all equally supported: the gate
        // removes the noise.
        let chains = select_cts(&refs, &[0, 1, 2], &[1, 1, 1], s[3].len(), &settings, &corr);
        assert_eq!(chains.len(), 2);
        let mut firsts: Vec<u32> = chains.iter().map(|c| c.segments[0].unwrap()).collect();
        firsts.sort();
        assert_eq!(firsts, vec![1, 2]);
        for c in &chains {
            assert!(c.score > 2.99, "{c:?}");
            let s0 = c.segments[0].unwrap();
            assert!(c.segments.iter().all(|&x| x == Some(s0)));
        }
        // Sources 1 and 2 in one cluster: only one of them may be chosen,
        // the better supported; the noise fails the gate.
        let chains = select_cts(&refs, &[0, 1, 1], &[5, 2, 3], s[3].len(), &settings, &corr);
        assert_eq!(chains.len(), 1);
        assert_eq!(chains[0].segments[0], Some(2));
        // Support ranks clusters; too little support is not selected.
        let chains = select_cts(
            &refs,
            &[0, 1, 2],
            &[9, 2, 3],
            s[3].len(),
            &SelectSettings {
                min_support: 3,
                ..settings
            },
            &corr,
        );
        assert_eq!(chains.len(), 1);
        assert_eq!(chains[0].segments[0], Some(2));
    }
}
