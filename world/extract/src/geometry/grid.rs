//! A uniform bucket grid over the present targets of one frame, so that
//! "which pairs are within r" and "who is near target i" cost about O(n)
//! instead of O(n²) at the densities of a crowd. Rebuilt every frame; the
//! grid only needs its cell side to be at least the largest query radius.

use super::Vec2;

/// Buckets of target indices on a regular grid covering the present
/// targets' bounding box. Build with [`NeighbourGrid::rebuild`], then query
/// with radii up to the `reach` it was built for.
#[derive(Debug, Clone, Default)]
pub struct NeighbourGrid {
    reach: f64,
    cell: f64,
    origin: Vec2,
    cols: usize,
    rows: usize,
    /// `starts[c] .. starts[c + 1]` indexes `items` for cell `c`.
    starts: Vec<usize>,
    items: Vec<u32>,
    /// Cell of each target, `usize::MAX` for absent ones.
    cell_of: Vec<usize>,
}

impl NeighbourGrid {
    pub fn new() -> Self {
        NeighbourGrid::default()
    }

    /// Buckets the present targets (`None` = absent) for queries of radius
    /// at most `reach` metres.
    pub fn rebuild(&mut self, positions: &[Option<Vec2>], reach: f64) {
        assert!(
            reach.is_finite() && reach > 0.0,
            "grid reach must be > 0, got {reach}"
        );
        self.reach = reach;
        self.cell_of.clear();
        self.cell_of.resize(positions.len(), usize::MAX);
        let mut lo = Vec2::new(f64::INFINITY, f64::INFINITY);
        let mut hi = Vec2::new(f64::NEG_INFINITY, f64::NEG_INFINITY);
        let mut present = 0usize;
        for p in positions.iter().flatten() {
            lo = Vec2::new(lo.x.min(p.x), lo.y.min(p.y));
            hi = Vec2::new(hi.x.max(p.x), hi.y.max(p.y));
            present += 1;
        }
        self.items.clear();
        if present == 0 {
            self.cols = 0;
            self.rows = 0;
            self.starts.clear();
            self.starts.push(0);
            return;
        }
        // Cells at least `reach` wide, and not many more cells than targets.
        let span = hi - lo;
        let mut cell = reach;
        let max_cells = (4 * present + 16) as f64;
        let cells_at = |c: f64| ((span.x / c).floor() + 1.0) * ((span.y / c).floor() + 1.0);
        if cells_at(cell) > max_cells {
            cell = ((span.x + reach) * (span.y + reach) / max_cells)
                .sqrt()
                .max(reach);
            while cells_at(cell) > max_cells {
                cell *= 1.5;
            }
        }
        self.cell = cell;
        self.origin = lo;
        self.cols = (span.x / cell).floor() as usize + 1;
        self.rows = (span.y / cell).floor() as usize + 1;
        let ncells = self.cols * self.rows;
        self.starts.clear();
        self.starts.resize(ncells + 1, 0);
        for (i, p) in positions.iter().enumerate() {
            if let Some(p) = p {
                let c = self.cell_index(*p);
                self.cell_of[i] = c;
                self.starts[c + 1] += 1;
            }
        }
        for c in 0..ncells {
            self.starts[c + 1] += self.starts[c];
        }
        self.items.resize(present, 0);
        let mut fill = self.starts.clone();
        for (i, &c) in self.cell_of.iter().enumerate() {
            if c != usize::MAX {
                self.items[fill[c]] = i as u32;
                fill[c] += 1;
            }
        }
    }

    fn cell_index(&self, p: Vec2) -> usize {
        let cx = (((p.x - self.origin.x) / self.cell).floor() as usize).min(self.cols - 1);
        let cy = (((p.y - self.origin.y) / self.cell).floor() as usize).min(self.rows - 1);
        cy * self.cols + cx
    }

    /// Calls `f(j, distance)` for every present target `j ≠ i` within
    /// `radius` of target `i` (which must be present), in a fixed order.
    pub fn for_each_neighbour(
        &self,
        positions: &[Option<Vec2>],
        i: usize,
        radius: f64,
        mut f: impl FnMut(usize, f64),
    ) {
        debug_assert!(radius <= self.reach, "query radius above the grid reach");
        let Some(pi) = positions[i] else { return };
        let c = self.cell_of[i];
        if c == usize::MAX {
            return;
        }
        let (cx, cy) = (c % self.cols, c / self.cols);
        let r2 = radius * radius;
        for ny in cy.saturating_sub(1)..=(cy + 1).min(self.rows - 1) {
            for nx in cx.saturating_sub(1)..=(cx + 1).min(self.cols - 1) {
                let cell = ny * self.cols + nx;
                for &j in &self.items[self.starts[cell]..self.starts[cell + 1]] {
                    let j = j as usize;
                    if j == i {
                        continue;
                    }
                    if let Some(pj) = positions[j] {
                        let d2 = pi.distance_sq(pj);
                        if d2 <= r2 {
                            f(j, d2.sqrt());
                        }
                    }
                }
            }
        }
    }

    /// Calls `f(i, j, distance)` once for every pair `i < j` of present
    /// targets within `radius` of each other, in a fixed order.
    pub(crate) fn for_each_pair_within(
        &self,
        positions: &[Option<Vec2>],
        radius: f64,
        mut f: impl FnMut(usize, usize, f64),
    ) {
        for i in 0..positions.len() {
            self.for_each_neighbour(positions, i, radius, |j, d| {
                if j > i {
                    f(i, j, d)
                }
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn pairs_match_brute_force() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut grid = NeighbourGrid::new();
        for round in 0..20 {
            let n = 1 + round * 7;
            let side = 1.0 + round as f64 * 5.0;
            let positions: Vec<Option<Vec2>> = (0..n)
                .map(|_| {
                    (rng.gen::<f64>() < 0.85)
                        .then(|| Vec2::new(rng.gen::<f64>() * side - 3.0, rng.gen::<f64>() * side))
                })
                .collect();
            for radius in [0.3, 1.0, 2.5] {
                grid.rebuild(&positions, radius);
                let mut got = Vec::new();
                grid.for_each_pair_within(&positions, radius, |i, j, d| got.push((i, j, d)));
                got.sort_by_key(|&(i, j, _)| (i, j));
                let mut want = Vec::new();
                for i in 0..n {
                    for j in i + 1..n {
                        if let (Some(a), Some(b)) = (positions[i], positions[j]) {
                            if a.distance(b) <= radius {
                                want.push((i, j, a.distance(b)));
                            }
                        }
                    }
                }
                assert_eq!(got.len(), want.len(), "n={n} radius={radius}");
                for (g, w) in got.iter().zip(&want) {
                    assert_eq!((g.0, g.1), (w.0, w.1));
                    assert!((g.2 - w.2).abs() < 1e-12);
                }
            }
        }
    }

    #[test]
    fn far_apart_targets_do_not_blow_up_the_grid() {
        let positions = vec![Some(Vec2::new(0.0, 0.0)), Some(Vec2::new(1e6, 1e6))];
        let mut grid = NeighbourGrid::new();
        grid.rebuild(&positions, 0.01);
        assert!(grid.cols * grid.rows <= 4 * 2 + 16);
        let mut hits = 0;
        grid.for_each_pair_within(&positions, 0.01, |_, _, _| hits += 1);
        assert_eq!(hits, 0);
        grid.rebuild(&[None, None], 1.0);
        grid.for_each_pair_within(&[None, None], 1.0, |_, _, _| hits += 1);
        assert_eq!(hits, 0);
    }
}
