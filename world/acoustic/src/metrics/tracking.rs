//! Tracking metrics of Section VI-B.
//!
//! - *Mean error distance* and its *standard deviation*: "the mean of the
//!   error distance between all points inside concatenated intersection
//!   areas and the actual path taken by a target" — every tile point of
//!   every fragment's area (5 m tiles), its distance to the target's
//!   actual path (Definition 5.1, the whole path). The areas are
//!   *concatenated*: a point in the areas of several slots counts once per
//!   slot, so the mean is the tile-weighted average over time slots of
//!   each area's own mean error — Definition 5.2's tracking resolution,
//!   which Fig. 9 compares it with, averaged over the path. (Taking the
//!   *union* of the areas instead, as this module first did, counts a
//!   correct, nearly static estimate repeated over 50 slots as one area
//!   and lets one stray area outweigh them; it is still reported, as
//!   `mean_error_union`.)
//! - *Percentage of coverage*: one minus the ratio between the summed
//!   distances of neighbouring intersection areas along the estimated path
//!   and the length of the actual path.
//!
//! Estimated paths are paired with targets by a minimum-cost assignment
//! on the time-aligned distance (fragment centroid to the target's
//! position at the middle of the fragment's slot, summed over the path's
//! fragments), since the tracker's path ids mean nothing. Two extra numbers the paper does not report are
//! given beside, because the paper's metrics are blind to them: the
//! time-aligned error (a path that jumps to another target's track
//! scores well on the paper's error distance but not on this) and the
//! share of (target, slot) pairs with a fragment (a path of one fragment
//! has full "coverage").

use super::assign::min_cost_assignment;
use crate::field::TruePath;
use crate::pipeline::intersect::Area;
use crate::pipeline::prepare::Segmentation;
use crate::pipeline::tiles::{TileGrid, TileSet};
use crate::pipeline::vote_link::Fragment;
use idmesh_sim::Vec2;

/// The metrics of one run.
#[derive(Debug, Clone, PartialEq)]
pub struct TrackingMetrics {
    /// Mean error distance, metres (Section VI-B): over the tile points
    /// of every fragment's area.
    pub mean_error: f64,
    /// Standard deviation of the error distance, metres.
    pub std_error: f64,
    /// Tile points the two above are over (with repetition).
    pub points: usize,
    /// The same over the union of each path's areas (every point once).
    pub mean_error_union: f64,
    pub std_error_union: f64,
    /// Distinct tile points.
    pub points_union: usize,
    /// Percentage of coverage, as a fraction in [0, 1], averaged over
    /// targets (a target with no estimated path counts 0).
    pub coverage: f64,
    /// Mean distance from a fragment's centroid to its target's position
    /// at the fragment's time, metres.
    pub aligned_error: f64,
    /// Share of (target, slot) pairs that have a fragment.
    pub slot_share: f64,
    /// `target_of[l]`: the target estimated path l is paired with (`None`
    /// for an empty path).
    pub target_of: Vec<Option<usize>>,
}

/// Distance from `p` to the segment a–b.
fn point_segment(p: Vec2, a: Vec2, b: Vec2) -> f64 {
    let ab = b - a;
    let len2 = ab.norm_sq();
    let t = if len2 > 0.0 {
        ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    p.distance(a + ab * t)
}

/// The true path as a polyline of every `stride`-th sample (and the last):
/// the paths are straight between waypoints and zigzag corners, so a
/// stride of a slot step loses at most a fraction of a metre at corners.
fn polyline(path: &TruePath, stride: usize) -> Vec<Vec2> {
    let n = path.positions.len();
    let mut out: Vec<Vec2> = path
        .positions
        .iter()
        .step_by(stride.max(1))
        .copied()
        .collect();
    if n > 0 && !(n - 1).is_multiple_of(stride.max(1)) {
        out.push(path.positions[n - 1]);
    }
    out
}

fn distance_to_polyline(p: Vec2, line: &[Vec2]) -> f64 {
    match line {
        [] => f64::INFINITY,
        [a] => p.distance(*a),
        _ => line
            .windows(2)
            .map(|w| point_segment(p, w[0], w[1]))
            .fold(f64::INFINITY, f64::min),
    }
}

/// Target `t`'s position at the middle of `slot`.
fn true_position(truth: &[TruePath], seg: &Segmentation, t: usize, slot: usize) -> Vec2 {
    let pos = &truth[t].positions;
    let i = (seg.middle(slot).round() as usize).min(pos.len() - 1);
    pos[i]
}

/// The target each estimated path is paired with (`None` for an empty
/// path, or one left over when there are more paths than targets).
fn pair_with_targets(
    paths: &[Vec<Fragment>],
    areas: &[Area],
    truth: &[TruePath],
    seg: &Segmentation,
) -> Vec<Option<usize>> {
    let k = truth.len();
    let position_at = |t: usize, slot: usize| true_position(truth, seg, t, slot);
    // Pair estimated paths with targets: cost = the aligned distances
    // summed over the path's fragments, so that a long path goes to the
    // target it follows and a stray path of two fragments cannot take its
    // place. (A mean per path, as first written, weighs both alike: a
    // stray two-fragment path near target A and a long path on A, with
    // target B never tracked, paired the long path with B.)
    let nonempty: Vec<usize> = (0..paths.len()).filter(|&l| !paths[l].is_empty()).collect();
    let cost: Vec<Vec<f64>> = nonempty
        .iter()
        .map(|&l| {
            (0..k)
                .map(|t| {
                    paths[l]
                        .iter()
                        .map(|f| {
                            areas[f.area as usize]
                                .centroid
                                .distance(position_at(t, f.slot))
                        })
                        .sum::<f64>()
                })
                .collect()
        })
        .collect();
    let mut target_of = vec![None; paths.len()];
    if !nonempty.is_empty() && nonempty.len() <= k {
        for (row, t) in min_cost_assignment(&cost).into_iter().enumerate() {
            target_of[nonempty[row]] = Some(t);
        }
    } else if nonempty.len() > k {
        // More paths than targets: pair the targets with their best paths,
        // leave the rest unpaired.
        let transposed: Vec<Vec<f64>> = (0..k)
            .map(|t| cost.iter().map(|r| r[t]).collect())
            .collect();
        for (t, row) in min_cost_assignment(&transposed).into_iter().enumerate() {
            target_of[nonempty[row]] = Some(t);
        }
    }
    target_of
}

/// Evaluates estimated paths (fragments over `areas`) against the truth.
pub(crate) fn evaluate(
    paths: &[Vec<Fragment>],
    areas: &[Area],
    grid: &TileGrid,
    truth: &[TruePath],
    seg: &Segmentation,
) -> TrackingMetrics {
    let k = truth.len();
    let position_at = |t: usize, slot: usize| true_position(truth, seg, t, slot);
    let target_of = pair_with_targets(paths, areas, truth, seg);
    let (mut sum, mut sum2, mut points) = (0.0, 0.0, 0usize);
    let (mut usum, mut usum2, mut upoints) = (0.0, 0.0, 0usize);
    let (mut aligned, mut fragments) = (0.0, 0usize);
    let mut coverage = vec![0.0; k];
    let mut slots_with = vec![0usize; k];
    for (l, path) in paths.iter().enumerate() {
        let Some(t) = target_of[l] else { continue };
        let line = polyline(&truth[t], seg.l_step);
        let mut union = TileSet::empty(grid);
        // Per area: (Σd, Σd², points), computed once however many
        // fragments share it.
        let mut per_area: rustc_hash::FxHashMap<u32, (f64, f64, usize)> =
            rustc_hash::FxHashMap::default();
        for f in path {
            let area = &areas[f.area as usize];
            union.union_with(&area.tiles);
            aligned += area.centroid.distance(position_at(t, f.slot));
            fragments += 1;
            let (s1, s2, n) = *per_area.entry(f.area).or_insert_with(|| {
                area.tiles
                    .points()
                    .fold((0.0, 0.0, 0), |(s1, s2, n), (r, c)| {
                        let d = distance_to_polyline(grid.point(r, c), &line);
                        (s1 + d, s2 + d * d, n + 1)
                    })
            });
            sum += s1;
            sum2 += s2;
            points += n;
        }
        for (r, c) in union.points() {
            let d = distance_to_polyline(grid.point(r, c), &line);
            usum += d;
            usum2 += d * d;
            upoints += 1;
        }
        let gaps: f64 = path
            .windows(2)
            .map(|w| {
                areas[w[0].area as usize]
                    .tiles
                    .distance(&areas[w[1].area as usize].tiles, grid)
            })
            .sum();
        let length = truth[t].length();
        coverage[t] = if length > 0.0 {
            (1.0 - gaps / length).clamp(0.0, 1.0)
        } else {
            1.0
        };
        slots_with[t] = path.len();
    }
    let moments = |s1: f64, s2: f64, n: usize| -> (f64, f64) {
        if n == 0 {
            return (f64::NAN, f64::NAN);
        }
        let mean = s1 / n as f64;
        (mean, (s2 / n as f64 - mean * mean).max(0.0).sqrt())
    };
    let (mean, std) = moments(sum, sum2, points);
    let (umean, ustd) = moments(usum, usum2, upoints);
    TrackingMetrics {
        mean_error: mean,
        std_error: std,
        points,
        mean_error_union: umean,
        std_error_union: ustd,
        points_union: upoints,
        coverage: if k > 0 {
            coverage.iter().sum::<f64>() / k as f64
        } else {
            0.0
        },
        aligned_error: if fragments > 0 {
            aligned / fragments as f64
        } else {
            f64::NAN
        },
        slot_share: slots_with.iter().sum::<usize>() as f64 / (k * seg.slots()).max(1) as f64,
        target_of,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn perfect_fragments_score_small_errors_and_full_coverage() {
        let grid = TileGrid::new(500.0, 5.0);
        let seg = Segmentation::new(10, 5, 101).unwrap();
        // Two targets moving right at 1 m/sample, at y = 100 and y = 300.
        let truth: Vec<TruePath> = [100.0, 300.0]
            .iter()
            .map(|&y| TruePath {
                positions: (0..101).map(|k| Vec2::new(100.0 + k as f64, y)).collect(),
            })
            .collect();
        let mut areas = Vec::new();
        let mut paths = vec![Vec::new(), Vec::new()];
        // Estimated path 0 follows target 1 and path 1 target 0 (ids are
        // arbitrary), each fragment a 10 m disk around the true position.
        for slot in 0..seg.slots() {
            for (l, t) in [(0usize, 1usize), (1, 0)] {
                let p = truth[t].positions[seg.middle(slot).round() as usize];
                let tiles = TileSet::disk_union(&grid, &[p], 10.0);
                areas.push(Area {
                    centroid: tiles.centroid(&grid).unwrap(),
                    tiles,
                    groups: 1,
                    hearing: Vec::new(),
                    silent_cover: 0,
                });
                paths[l].push(Fragment {
                    slot,
                    area: areas.len() as u32 - 1,
                    segment: 0,
                });
            }
        }
        let m = evaluate(&paths, &areas, &grid, &truth, &seg);
        assert_eq!(m.target_of, vec![Some(1), Some(0)]);
        assert!(m.mean_error > 2.0 && m.mean_error < 8.0, "{m:?}");
        assert!(m.aligned_error < 3.0, "{m:?}");
        assert_eq!(m.coverage, 1.0);
        assert_eq!(m.slot_share, 1.0);
        // Only one fragment per path, far apart: coverage loses the gaps.
        let sparse: Vec<Vec<Fragment>> = paths.iter().map(|p| vec![p[0], p[p.len() - 1]]).collect();
        let m = evaluate(&sparse, &areas, &grid, &truth, &seg);
        // Gap: 90 m between centres less two 10 m radii, over 100 m.
        assert!((m.coverage - 0.3).abs() < 0.01, "{m:?}");
        // Concatenated vs union: a small correct area repeated in every
        // slot and one large stray area. Concatenated, the stray area
        // weighs as one slot; in the union it outweighs the repeats.
        let good = areas[0].clone();
        let stray_tiles = TileSet::disk_union(&grid, &[Vec2::new(110.0, 200.0)], 20.0);
        let stray = Area {
            centroid: stray_tiles.centroid(&grid).unwrap(),
            tiles: stray_tiles,
            groups: 1,
            hearing: Vec::new(),
            silent_cover: 0,
        };
        let two = vec![good, stray];
        let mut one_path: Vec<Fragment> = (0..seg.slots() - 1)
            .map(|slot| Fragment {
                slot,
                area: 0,
                segment: 0,
            })
            .collect();
        one_path.push(Fragment {
            slot: seg.slots() - 1,
            area: 1,
            segment: 0,
        });
        let m = evaluate(&[vec![], one_path], &two, &grid, &truth, &seg);
        assert_eq!(m.target_of, vec![None, Some(1)]);
        // Stray points lie ≈ 100 m from the path (y = 300), 49 of them;
        // the repeated area's 13 points within 10 m, counted 18 times.
        assert_eq!(m.points, 18 * 13 + 49);
        assert_eq!(m.points_union, 13 + 49);
        assert!(m.mean_error < 30.0, "{m:?}");
        assert!(m.mean_error_union > 70.0, "{m:?}");
        // Target A crosses the field (4 m/sample) to where B waits; a long
        // path follows A, a stray two-fragment path lies 40 m off A's
        // start. Per-path *mean* costs would pair the long path with B
        // (about 200 m on average) and the stray with A (40 m); summed
        // over fragments, the long path is A's.
        let moving = vec![
            TruePath {
                positions: (0..101)
                    .map(|k| Vec2::new(50.0 + 4.0 * k as f64, 50.0))
                    .collect(),
            },
            TruePath {
                positions: vec![Vec2::new(450.0, 60.0); 101],
            },
        ];
        let mut on_a = Vec::new();
        let mut long = Vec::new();
        let mut stray = Vec::new();
        for slot in 0..seg.slots() {
            let p = moving[0].positions[seg.middle(slot).round() as usize];
            for (off, list) in [(0.0, &mut long), (40.0, &mut stray)] {
                if off > 0.0 && slot >= 2 {
                    continue;
                }
                let tiles = TileSet::disk_union(&grid, &[p + Vec2::new(0.0, off)], 10.0);
                on_a.push(Area {
                    centroid: tiles.centroid(&grid).unwrap(),
                    tiles,
                    groups: 1,
                    hearing: Vec::new(),
                    silent_cover: 0,
                });
                list.push(Fragment {
                    slot,
                    area: on_a.len() as u32 - 1,
                    segment: 0,
                });
            }
        }
        let m = evaluate(&[long, stray], &on_a, &grid, &moving, &seg);
        assert_eq!(m.target_of, vec![Some(0), Some(1)]);
        // No paths at all.
        let m = evaluate(&[vec![], vec![]], &areas, &grid, &truth, &seg);
        assert_eq!(m.coverage, 0.0);
        assert!(m.mean_error.is_nan());
    }
}
