//! The intersection step (Section IV-E): a selected individual segment
//! C^u_{k,j} is located by intersecting the sensing ranges of the sensor
//! groups that "hear" it — the groups with a separated segment of slot j
//! highly correlated with it — in order of decreasing |corr|, on the 5 m
//! tiles of Section VI-B. A group whose range would empty the area is
//! skipped (its hearing is inconsistent with the better ones before it).
//! The result, area^u_{k,j}, is an estimated path fragment.

use super::prepare::SensorGroup;
use super::separate::SlotSegments;
use super::tiles::{TileGrid, TileSet};
use crate::geometry::Vec2;

/// The sensing range of every group, on the tile grid.
#[derive(Debug, Clone)]
pub struct GroupRanges {
    pub grid: TileGrid,
    pub ranges: Vec<TileSet>,
}

impl GroupRanges {
    /// The union of the members' disks of radius `range`, per group.
    pub fn new(grid: TileGrid, groups: &[SensorGroup], sensors: &[Vec2], range: f64) -> Self {
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
pub fn hearing_groups(segs: &SlotSegments, c: usize, threshold: f32) -> Vec<(u32, f32)> {
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
pub fn intersect(ranges: &GroupRanges, hearing: &[(u32, f32)], exclude: bool) -> Option<Area> {
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
    if exclude {
        (tiles, silent_cover) = exclude_silent(ranges, hearing, &tiles);
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
/// cleanly separated source hears it 93–99 % of the time, at every
/// distance up to R (examples/acoustic_diag.rs). So of `area`, keep the
/// points that the fewest silent groups' ranges cover (the rare group
/// that misses a source it should hear then costs precision, never the
/// whole area), and return that count. The paper (Section IV-E)
/// intersects only the ranges of the groups that hear.
pub fn exclude_silent(
    ranges: &GroupRanges,
    hearing: &[(u32, f32)],
    area: &TileSet,
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
        pts.iter().copied().filter(|p| at(p) == fewest),
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
        let area = intersect(&ranges, &hearing, false).unwrap();
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
        let area = intersect(&ranges, &[(0, 1.0), (3, 0.99), (1, 0.98)], false).unwrap();
        assert_eq!(area.groups, 2);
        assert!(intersect(&ranges, &[]).is_none());
    }
}
