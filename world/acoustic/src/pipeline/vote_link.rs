//! The voting step and path linking (Section IV-F, Appendix A, Algorithm 1).
//!
//! **Voting.** Every CTS_u estimates the fragments of its n_slot slots
//! (one area per chain and slot). A fragment area^u_{k,u} is kept as
//! Pseg_{k,u} only if it agrees with
//! - the later fragments of its own chain in CTS_u:
//!   dcur_{k,u} = Σ_j d_area(area^u_{k,u}, area^u_{k,j+1}) = 0, and
//! - the estimates of slot u made by the previous CTSs:
//!   dpre_{k,u} = Σ_m min_{k'} d_area(area^u_{k,u}, area^{u−m}_{k',u}) = 0
//!   (the text's version, "the same time slot based on different CTS";
//!   the pseudo code's indices read slot u − m, which the text
//!   contradicts). A previous CTS with no estimate of slot u abstains.
//!
//! The last CTS also hands on the fragments of its remaining slots that
//! touch its first one (Algorithm 1, `u == v − n_slot + 1`).
//! `tolerance` relaxes "= 0" to "every term ≤ tolerance" (0 = the paper,
//! and the default; a tolerance keeps more fragments — 40 m takes the
//! share of target-slots tracked from about 35 % to 50–60 % — but the
//! fragments it adds are less consistent, and the paper's coverage, which
//! counts every gap between successive areas, falls to near 0).
//!
//! **Linking.** Slot by slot, the kept fragments are attached to the K
//! estimated paths: each path continues with the nearest fragment (zero
//! distance first, as in Algorithm 1; one fragment per path and one path
//! per fragment, nearest pairs first). Where fragments of two targets
//! overlap (close targets, large areas) "nearest" is ambiguous, and the
//! paper's tie-break (the fragment's index) swaps tracks at random; we
//! first prefer the fragment whose segment continues the path's last
//! segment in the signal itself (link correlation of the overlapping
//! samples ≥ `min_link` — the chaining of Fig. 4 applied across CTSs),
//! then zero distance, then the nearest centroid. Further choices the
//! paper leaves open:
//! a fragment farther from every path than a gate (`link_gate` plus the
//! distance a target can cover at `max_speed` since the path's last
//! fragment) starts a new path while one is free and is dropped otherwise,
//! and two kept fragments of one slot whose segments are the same source
//! (|corr| ≥ `same_source`) or whose areas touch (d_area ≤ one tile)
//! count once — otherwise a source located twice, from a clean segment
//! and from a partly mixed one, takes two of the K paths and leaves a
//! target without one.

use super::intersect::Area;
use super::tiles::TileGrid;

/// One CTS's estimate: per chain, per slot of the CTS, the fragment's area
/// id and the segment it was computed from.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct CtsEstimate {
    /// `chains[k][i]` = (area id, segment) of chain k in slot u + i.
    pub chains: Vec<Vec<Option<(u32, u32)>>>,
}

/// A fragment kept by the vote.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Kept {
    pub area: u32,
    pub segment: u32,
}

/// Settings of voting and linking.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct VoteSettings {
    pub n_slot: usize,
    /// d_area values up to this many metres count as 0 (paper: 0).
    pub tolerance: f64,
    /// Metres a fragment may lie from a path and still extend it, on top
    /// of what the speed limit allows.
    pub link_gate: f64,
    /// The speed limit of Section II, assumption (4), m/sample.
    pub max_speed: f64,
    /// Samples between slots.
    pub l_step: usize,
    /// Link correlation at which a fragment continues a path's signal.
    pub min_link: f64,
}

/// `continuity(slot_a, seg_a, slot_b, seg_b)`: the link correlation of two
/// segments over their common samples, `None` if they share too few.
pub(crate) type Continuity<'a> = &'a dyn Fn(usize, u32, usize, u32) -> Option<f64>;

/// The vote: for each of the `slots` slots, the fragments kept (Pseg).
/// `estimates[u]` is CTS_u's. `same_source(slot, s1, s2)` tells whether two
/// segments of a slot are the same source.
pub(crate) fn vote(
    estimates: &[CtsEstimate],
    slots: usize,
    areas: &[Area],
    grid: &TileGrid,
    settings: &VoteSettings,
    same_source: &dyn Fn(usize, u32, u32) -> bool,
) -> Vec<Vec<Kept>> {
    let n_slot = settings.n_slot;
    let tol = settings.tolerance;
    let close = |a: u32, b: u32| -> bool {
        a == b
            || areas[a as usize]
                .tiles
                .distance(&areas[b as usize].tiles, grid)
                <= tol
    };
    let mut pseg: Vec<Vec<Kept>> = vec![Vec::new(); slots];
    // Two fragments of one slot are one target if their segments are the
    // same source, or if their areas touch (d_area ≤ one tile): two
    // segments of one source that correlate below `same_source` (one of
    // them partly mixed) locate it twice, and with areas of a few tiles
    // two targets are rarely that close.
    let touch = grid.spacing * 1.01;
    let mut keep = |slot: usize, k: Kept| {
        let list = &mut pseg[slot];
        if !list.iter().any(|x| {
            x.segment == k.segment
                || same_source(slot, x.segment, k.segment)
                || areas[x.area as usize]
                    .tiles
                    .distance(&areas[k.area as usize].tiles, grid)
                    <= touch
        }) {
            list.push(k);
        }
    };
    let last = estimates.len().saturating_sub(1);
    for (u, est) in estimates.iter().enumerate() {
        for chain in &est.chains {
            let Some(Some((first, seg0))) = chain.first().copied() else {
                continue;
            };
            let dcur_ok = chain[1..]
                .iter()
                .all(|c| c.is_some_and(|(a, _)| close(first, a)));
            let dpre_ok = (1..n_slot.min(u + 1)).all(|m| {
                let earlier: Vec<u32> = estimates[u - m]
                    .chains
                    .iter()
                    .filter_map(|c| c.get(m).copied().flatten().map(|(a, _)| a))
                    .collect();
                earlier.is_empty() || earlier.iter().any(|&a| close(first, a))
            });
            if dcur_ok && dpre_ok {
                keep(
                    u,
                    Kept {
                        area: first,
                        segment: seg0,
                    },
                );
            }
            if u == last {
                for (i, c) in chain.iter().enumerate().skip(1) {
                    if let Some((a, s)) = *c {
                        if u + i < slots && close(first, a) {
                            keep(
                                u + i,
                                Kept {
                                    area: a,
                                    segment: s,
                                },
                            );
                        }
                    }
                }
            }
        }
    }
    pseg
}

/// A fragment of an estimated path.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Fragment {
    pub slot: usize,
    pub area: u32,
    /// The segment (of its slot) it was located from.
    pub segment: u32,
}

/// Links the kept fragments into `k` paths (some may stay empty).
/// Returns the paths and the number of fragments dropped.
pub(crate) fn link(
    pseg: &[Vec<Kept>],
    k: usize,
    areas: &[Area],
    grid: &TileGrid,
    settings: &VoteSettings,
    continuity: Continuity<'_>,
) -> (Vec<Vec<Fragment>>, usize) {
    let mut paths: Vec<Vec<Fragment>> = vec![Vec::new(); k];
    let mut dropped = 0;
    for (j, kept) in pseg.iter().enumerate() {
        if kept.is_empty() {
            continue;
        }
        // (signal does not continue, d_area, centroid distance, path, fragment)
        let mut pairs: Vec<(bool, f64, f64, usize, usize)> = Vec::new();
        for (p, path) in paths.iter().enumerate() {
            let Some(last) = path.last() else { continue };
            let gap = (j - last.slot) * settings.l_step;
            let gate = settings.link_gate + settings.max_speed * gap as f64;
            let from = &areas[last.area as usize];
            for (f, frag) in kept.iter().enumerate() {
                let to = &areas[frag.area as usize];
                let d = from.tiles.distance(&to.tiles, grid);
                if d > gate {
                    continue;
                }
                let same_signal = continuity(last.slot, last.segment, j, frag.segment)
                    .is_some_and(|rho| rho >= settings.min_link);
                pairs.push((!same_signal, d, from.centroid.distance(to.centroid), p, f));
            }
        }
        pairs.sort_by(|a, b| {
            a.0.cmp(&b.0)
                .then(a.1.total_cmp(&b.1))
                .then(a.2.total_cmp(&b.2))
                .then(a.3.cmp(&b.3))
                .then(a.4.cmp(&b.4))
        });
        let mut path_done = vec![false; k];
        let mut frag_done = vec![false; kept.len()];
        for (_, _, _, p, f) in pairs {
            if path_done[p] || frag_done[f] {
                continue;
            }
            paths[p].push(Fragment {
                slot: j,
                area: kept[f].area,
                segment: kept[f].segment,
            });
            path_done[p] = true;
            frag_done[f] = true;
        }
        for (f, frag) in kept.iter().enumerate() {
            if frag_done[f] {
                continue;
            }
            match paths.iter().position(|p| p.is_empty()) {
                Some(p) => paths[p].push(Fragment {
                    slot: j,
                    area: frag.area,
                    segment: frag.segment,
                }),
                None => dropped += 1,
            }
        }
    }
    (paths, dropped)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::tiles::TileSet;
    use idmesh_sim::Vec2;

    fn grid() -> TileGrid {
        TileGrid::new(1000.0, 5.0)
    }

    fn disk(x: f64, y: f64) -> Area {
        let tiles = TileSet::disk_union(&grid(), &[Vec2::new(x, y)], 10.0);
        Area {
            centroid: tiles.centroid(&grid()).unwrap(),
            tiles,
            groups: 1,
            hearing: Vec::new(),
            silent_cover: 0,
        }
    }

    fn settings() -> VoteSettings {
        VoteSettings {
            n_slot: 3,
            tolerance: 0.0,
            link_gate: 50.0,
            max_speed: 0.15,
            l_step: 10,
            min_link: 0.9,
        }
    }

    #[test]
    fn consistent_fragments_are_kept_and_outliers_voted_out() {
        // Two targets moving right, one at y = 100, one at y = 500; areas
        // 0..6 along the first, 6..12 along the second; 12 is far off.
        let mut areas: Vec<Area> = (0..6)
            .map(|i| disk(100.0 + 5.0 * i as f64, 100.0))
            .collect();
        areas.extend((0..6).map(|i| disk(100.0 + 5.0 * i as f64, 500.0)));
        areas.push(disk(800.0, 800.0));
        // 4 slots, n_slot 3: CTS 0 and 1. Segment id = area id.
        let chain = |ids: &[u32]| ids.iter().map(|&a| Some((a, a))).collect::<Vec<_>>();
        let estimates = vec![
            CtsEstimate {
                chains: vec![chain(&[0, 1, 2]), chain(&[6, 7, 8])],
            },
            CtsEstimate {
                // The second chain's first fragment is an outlier.
                chains: vec![chain(&[1, 2, 3]), chain(&[12, 8, 9])],
            },
        ];
        let pseg = vote(&estimates, 4, &areas, &grid(), &settings(), &|_, _, _| {
            false
        });
        assert_eq!(
            pseg[0].iter().map(|k| k.area).collect::<Vec<_>>(),
            vec![0, 6]
        );
        assert_eq!(pseg[1].iter().map(|k| k.area).collect::<Vec<_>>(), vec![1]);
        // Last CTS hands on its later slots that touch its first fragment.
        assert_eq!(pseg[2].iter().map(|k| k.area).collect::<Vec<_>>(), vec![2]);
        assert_eq!(pseg[3].iter().map(|k| k.area).collect::<Vec<_>>(), vec![3]);
        let (paths, dropped) = link(&pseg, 2, &areas, &grid(), &settings(), &|_, _, _, _| None);
        assert_eq!(dropped, 0);
        let ids = |p: &Vec<Fragment>| p.iter().map(|f| f.area).collect::<Vec<_>>();
        assert_eq!(ids(&paths[0]), vec![0, 1, 2, 3]);
        assert_eq!(ids(&paths[1]), vec![6]);
    }

    #[test]
    fn linking_follows_nearest_fragments_and_gates_far_ones() {
        let areas = vec![
            disk(100.0, 100.0),
            disk(400.0, 100.0),
            disk(110.0, 100.0),
            disk(390.0, 100.0),
            disk(900.0, 900.0),
        ];
        let kept = |ids: &[u32]| {
            ids.iter()
                .map(|&a| Kept {
                    area: a,
                    segment: a,
                })
                .collect::<Vec<_>>()
        };
        // Slot 0: two fragments; slot 1: the same two targets listed in the
        // other order plus a far one with no free path.
        let pseg = vec![kept(&[0, 1]), kept(&[3, 2, 4])];
        let (paths, dropped) = link(&pseg, 2, &areas, &grid(), &settings(), &|_, _, _, _| None);
        assert_eq!(
            paths[0].iter().map(|f| f.area).collect::<Vec<_>>(),
            vec![0, 2]
        );
        assert_eq!(
            paths[1].iter().map(|f| f.area).collect::<Vec<_>>(),
            vec![1, 3]
        );
        assert_eq!(dropped, 1);
        // Overlapping fragments of two targets: the signal decides.
        let areas = vec![
            disk(100.0, 100.0),
            disk(110.0, 100.0),
            disk(105.0, 100.0),
            disk(106.0, 100.0),
        ];
        let pseg = vec![kept(&[0, 1]), kept(&[2, 3])];
        let signal = |_: usize, a: u32, _: usize, b: u32| {
            Some(if (a, b) == (0, 3) || (a, b) == (1, 2) {
                0.99
            } else {
                0.1
            })
        };
        let (paths, _) = link(&pseg, 2, &areas, &grid(), &settings(), &signal);
        assert_eq!(
            paths[0].iter().map(|f| f.area).collect::<Vec<_>>(),
            vec![0, 3]
        );
        assert_eq!(
            paths[1].iter().map(|f| f.area).collect::<Vec<_>>(),
            vec![1, 2]
        );
        // Duplicates of one source in a slot count once.
        let estimates = vec![CtsEstimate {
            chains: vec![
                vec![Some((0, 7)), Some((0, 7))],
                vec![Some((2, 8)), Some((2, 8))],
            ],
        }];
        let pseg = vote(
            &estimates,
            2,
            &areas,
            &grid(),
            &VoteSettings {
                n_slot: 2,
                ..settings()
            },
            &|_, a, b| (a, b) == (7, 8) || (a, b) == (8, 7),
        );
        assert_eq!(pseg[0].len(), 1);
        // Two segments of different sources (as far as correlation
        // tells) whose areas touch: one target, kept once.
        let areas = vec![disk(100.0, 100.0), disk(120.0, 100.0), disk(300.0, 100.0)];
        let estimates = vec![CtsEstimate {
            chains: vec![
                vec![Some((0, 0)), Some((0, 0))],
                vec![Some((1, 1)), Some((1, 1))],
                vec![Some((2, 2)), Some((2, 2))],
            ],
        }];
        let pseg = vote(
            &estimates,
            2,
            &areas,
            &grid(),
            &VoteSettings {
                n_slot: 2,
                ..settings()
            },
            &|_, _, _| false,
        );
        assert_eq!(
            pseg[0].iter().map(|k| k.area).collect::<Vec<_>>(),
            vec![0, 2]
        );
    }
}
