//! The intersection step (Section IV-E): a selected individual segment
//! C^u_{k,j} is located by intersecting the sensing ranges of the sensor
//! groups that "hear" it — the groups with a separated segment of slot j
//! highly correlated with it — in order of decreasing |corr|, on the 5 m
//! tiles of Section VI-B. A group whose range would empty the area is
//! skipped (its hearing is inconsistent with the better ones before it).
//! The result, area^u_{k,j}, is an estimated path fragment.
//!
//! **Departure (on by default, `exclude_silent`):** the paper uses only
//! the groups that hear. A group that does *not* hear a source is
//! evidence too — it is out of range — and in simulation it is reliable
//! evidence: a group with a member within R of a cleanly separated source
//! hears it 85–99 % of the time at every distance up to R. Of the
//! intersection we keep the points covered by the fewest ranges of
//! non-hearing groups, or by one more (`silent_slack` = 1: a group now and
//! then misses a source it should hear) ([`exclude_silent`]). Areas shrink from hundreds of
//! tiles to a handful, and a segment that is really a mixture of two
//! targets (an *aggregate*, Section III-B, heard by the groups in range of
//! both) is no longer located in a large area spanning both: the groups
//! near either target that separated it cleanly do not hear the mixture,
//! and remove the space between.

use super::prepare::SensorGroup;
use super::separate::SlotSegments;
use super::tiles::{TileGrid, TileSet};
use idmesh_sim::Vec2;

/// The sensing range of every group, on the tile grid.
#[derive(Debug, Clone)]
pub(crate) struct GroupRanges {
    pub grid: TileGrid,
    pub ranges: Vec<TileSet>,
}

impl GroupRanges {
    /// The union of the members' disks of radius `range`, per group.
    pub(crate) fn new(
        grid: TileGrid,
        groups: &[SensorGroup],
        sensors: &[Vec2],
        range: f64,
    ) -> Self {
        let ranges = groups
            .iter()
            .map(|g| {
                let centers: Vec<Vec2> = g.members.iter().map(|&m| sensors[m as usize]).collect();
                TileSet::disk_union(&grid, &centers, range)
            })
            .collect();
        GroupRanges { grid, ranges }
    }
}

/// An estimated path fragment.
#[derive(Debug, Clone, PartialEq)]
pub struct Area {
    pub tiles: TileSet,
    /// Groups whose ranges were intersected.
    pub groups: usize,
    /// The groups that heard the segment, strongest first, with |corr|.
    pub hearing: Vec<(u32, f32)>,
    /// Groups that did not hear the segment yet cover the area's points
    /// (the fewest over the area; 0 when silent groups are not used).
    pub silent_cover: u32,
    /// Mean position of the tiles.
    pub centroid: Vec2,
}

/// The groups that hear segment `c` of slot `segs`: for each group its
/// largest |corr| with `c`, kept when ≥ `threshold`, strongest first
/// (ties by group index).
pub(crate) fn hearing_groups(segs: &SlotSegments, c: usize, threshold: f32) -> Vec<(u32, f32)> {
    let target = segs.segment(c);
    let mut best: Vec<(u32, f32)> = Vec::new();
    for i in 0..segs.len() {
        let corr: f32 = segs
            .segment(i)
            .iter()
            .zip(target)
            .map(|(a, b)| a * b)
            .sum::<f32>()
            .abs();
        if corr < threshold {
            continue;
        }
        let g = segs.group[i];
        match best.iter_mut().find(|(x, _)| *x == g) {
            Some(entry) => entry.1 = entry.1.max(corr),
            None => best.push((g, corr)),
        }
    }
    best.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    best
}

/// Intersects the ranges of `hearing` (strongest first), skipping a group
/// that would leave nothing; then, if `exclude_silent`, keeps only the
/// points covered by the fewest ranges of groups that did *not* hear the
/// segment (see [`exclude_silent`]). `None` if nobody hears.
pub(crate) fn intersect(
    ranges: &GroupRanges,
    hearing: &[(u32, f32)],
    exclude: Option<u32>,
) -> Option<Area> {
    let (&(first, _), rest) = hearing.split_first()?;
    let mut tiles = ranges.ranges[first as usize].clone();
    let mut used = 1;
    for &(g, _) in rest {
        let next = tiles.intersect(&ranges.ranges[g as usize]);
        if !next.is_empty() {
            tiles = next;
            used += 1;
        }
    }
    let mut silent_cover = 0;
    if let Some(slack) = exclude {
        (tiles, silent_cover) = exclude_silent(ranges, hearing, &tiles, slack);
    }
    let centroid = tiles.centroid(&ranges.grid)?;
    Some(Area {
        tiles,
        groups: used,
        hearing: hearing.to_vec(),
        silent_cover,
        centroid,
    })
}

/// Negative information: a group that does not hear a source is out of
/// range of it — in simulation a group with a member within R of a
/// cleanly separated source hears it 85–99 % of the time, at every
/// distance up to R (examples/acoustic_diag.rs). So of `area`, keep the
/// points that the fewest silent groups' ranges cover, plus those covered
/// by up to `slack` more (the rare group that misses a source it should
/// hear then costs precision, never the whole area), and return the
/// fewest. The paper (Section IV-E) intersects only the ranges of the
/// groups that hear.
pub(crate) fn exclude_silent(
    ranges: &GroupRanges,
    hearing: &[(u32, f32)],
    area: &TileSet,
    slack: u32,
) -> (TileSet, u32) {
    let rows = area.row_range();
    if rows.is_empty() {
        return (area.clone(), 0);
    }
    let pts: Vec<(usize, usize)> = area.points().collect();
    let c0 = pts.iter().map(|p| p.1).min().unwrap_or(0);
    let c1 = pts.iter().map(|p| p.1).max().unwrap_or(0);
    let width = c1 - c0 + 1;
    let mut count = vec![0u32; rows.len() * width];
    let mut heard = vec![false; ranges.ranges.len()];
    for &(g, _) in hearing {
        heard[g as usize] = true;
    }
    for (g, range) in ranges.ranges.iter().enumerate() {
        if heard[g] || !range.overlaps(area) {
            continue;
        }
        for (r, c) in area.intersect(range).points() {
            count[(r - rows.start) * width + (c - c0)] += 1;
        }
    }
    let at = |&(r, c): &(usize, usize)| count[(r - rows.start) * width + (c - c0)];
    let fewest = pts.iter().map(at).min().unwrap_or(0);
    let kept = TileSet::from_points(
        &ranges.grid,
        pts.iter().copied().filter(|p| at(p) <= fewest + slack),
    );
    (kept, fewest)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_source_heard_by_three_groups_is_located_in_their_lens() {
        let grid = TileGrid::new(400.0, 5.0);
        let sensors = vec![
            Vec2::new(100.0, 200.0),
            Vec2::new(300.0, 200.0),
            Vec2::new(200.0, 100.0),
            Vec2::new(390.0, 390.0),
        ];
        let groups: Vec<SensorGroup> = (0..4)
            .map(|i| SensorGroup {
                members: vec![i],
                center: sensors[i as usize],
                radius: 0.0,
            })
            .collect();
        let ranges = GroupRanges::new(grid, &groups, &sensors, 110.0);
        // Segments: group 0, 1, 2 hear the same signal (with sign and a
        // little noise), group 3 something else.
        let sig: Vec<f64> = (0..50).map(|k| ((k * k) as f64 * 0.37).sin()).collect();
        let mut segs = SlotSegments {
            l_seg: 50,
            ..SlotSegments::default()
        };
        segs.push(2, sig.iter().map(|v| v * 0.9 + 0.01));
        segs.push(3, (0..50).map(|k| (k as f64 * 0.5).cos()));
        segs.push(0, sig.iter().copied());
        segs.push(1, sig.iter().map(|v| -v));
        let hearing = hearing_groups(&segs, 2, 0.9);
        assert_eq!(
            hearing.iter().map(|h| h.0).collect::<Vec<_>>(),
            vec![0, 1, 2]
        );
        let area = intersect(&ranges, &hearing, None).unwrap();
        assert_eq!(area.groups, 3);
        assert!(
            area.centroid.distance(Vec2::new(200.0, 190.0)) < 15.0,
            "{:?}",
            area.centroid
        );
        // Every point is within range of all three.
        for (r, c) in area.tiles.points() {
            for s in &sensors[..3] {
                assert!(grid.point(r, c).distance(*s) <= 110.0 + 1e-9);
            }
        }
        // An inconsistent group (3, far away) is skipped, not emptying.
        let area = intersect(&ranges, &[(0, 1.0), (3, 0.99), (1, 0.98)], None).unwrap();
        assert_eq!(area.groups, 2);
        assert!(intersect(&ranges, &[], None).is_none());
    }

    #[test]
    fn groups_that_do_not_hear_remove_their_ranges() {
        let grid = TileGrid::new(400.0, 5.0);
        // Groups 0 and 1 hear; 2 (at the lens' lower part) and 3 (far)
        // do not.
        let sensors = vec![
            Vec2::new(100.0, 200.0),
            Vec2::new(300.0, 200.0),
            Vec2::new(200.0, 60.0),
            Vec2::new(390.0, 390.0),
        ];
        let groups: Vec<SensorGroup> = (0..4)
            .map(|i| SensorGroup {
                members: vec![i],
                center: sensors[i as usize],
                radius: 0.0,
            })
            .collect();
        let ranges = GroupRanges::new(grid, &groups, &sensors, 110.0);
        let hearing = [(0, 0.99), (1, 0.95)];
        let lens = intersect(&ranges, &hearing, None).unwrap();
        let area = intersect(&ranges, &hearing, Some(0)).unwrap();
        assert_eq!(area.silent_cover, 0);
        assert!(area.tiles.count() < lens.tiles.count());
        // What is left is the lens minus group 2's disk: its upper part.
        for (r, c) in area.tiles.points() {
            let p = grid.point(r, c);
            assert!(lens.tiles.contains(r, c));
            assert!(p.distance(sensors[2]) > 110.0, "{p:?}");
        }
        assert!(area.centroid.y > lens.centroid.y);
        // A silent group covering the whole area only costs its count.
        let (kept, fewest) = exclude_silent(&ranges, &[(0, 1.0)], &area.tiles, 0);
        assert_eq!(kept, area.tiles);
        assert_eq!(fewest, 1);
        // Slack keeps the points one more silent group covers.
        let (wider, fewest) = exclude_silent(&ranges, &hearing, &lens.tiles, 1);
        assert_eq!(fewest, 0);
        assert_eq!(wider, lens.tiles);
    }
}
