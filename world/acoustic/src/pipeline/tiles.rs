//! Areas on the 5 m tile grid of Section VI-B: "we quantize the whole area
//! using 5 m × 5 m tiles. One intersection area is represented by a set of
//! points inside the area, each point representing the corner of the
//! corresponding tile." A [`TileSet`] is such a set of grid points, stored
//! as one bit per point in full-width rows over the rows it spans, so that
//! intersecting two sensing ranges is a word-wise AND.

use idmesh_sim::Vec2;

/// The grid points (c·spacing, r·spacing), 0 ≤ r, c < `side`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TileGrid {
    pub spacing: f64,
    /// Points per side.
    pub side: usize,
    /// 64-bit words per row.
    pub words: usize,
}

impl TileGrid {
    /// A grid covering `[0, size]²`.
    pub(crate) fn new(size: f64, spacing: f64) -> Self {
        let side = (size / spacing).floor() as usize + 1;
        TileGrid {
            spacing,
            side,
            words: side.div_ceil(64),
        }
    }

    /// The point at row `r`, column `c`.
    pub fn point(&self, r: usize, c: usize) -> Vec2 {
        Vec2::new(c as f64 * self.spacing, r as f64 * self.spacing)
    }
}

/// A set of grid points.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TileSet {
    /// First row held.
    row0: usize,
    /// Words per row (the grid's).
    words: usize,
    /// `rows × words` bits, row-major; empty for the empty set.
    bits: Vec<u64>,
}

impl TileSet {
    /// The empty set.
    pub(crate) fn empty(grid: &TileGrid) -> Self {
        TileSet {
            row0: 0,
            words: grid.words,
            bits: Vec::new(),
        }
    }

    fn rows(&self) -> usize {
        self.bits.len().checked_div(self.words).unwrap_or(0)
    }

    /// The grid points within `radius` of any of `centers` (the sensing
    /// range of a sensor group: the union of its members' disks). A disk
    /// meets each row in one run of columns, so this is a few range fills.
    pub(crate) fn disk_union(grid: &TileGrid, centers: &[Vec2], radius: f64) -> Self {
        if centers.is_empty() {
            return TileSet::empty(grid);
        }
        let s = grid.spacing;
        let last = grid.side as isize - 1;
        let row_of = |y: f64| (y / s).floor() as isize;
        let lo = centers
            .iter()
            .map(|c| row_of(c.y - radius))
            .min()
            .unwrap_or(0)
            .clamp(0, last) as usize;
        let hi = centers
            .iter()
            .map(|c| row_of(c.y + radius) + 1)
            .max()
            .unwrap_or(0)
            .clamp(0, last) as usize;
        let mut set = TileSet {
            row0: lo,
            words: grid.words,
            bits: vec![0; (hi - lo + 1) * grid.words],
        };
        let r2 = radius * radius;
        for c in centers {
            for r in lo..=hi {
                let dy = r as f64 * s - c.y;
                let w2 = r2 - dy * dy;
                if w2 < 0.0 {
                    continue;
                }
                let w = w2.sqrt();
                let c0 = ((c.x - w) / s).ceil().max(0.0);
                let c1 = ((c.x + w) / s).floor().min(last as f64);
                if c0 > c1 {
                    continue;
                }
                set.fill(r - lo, c0 as usize, c1 as usize);
            }
        }
        set.trim();
        set
    }

    /// The set of the given (row, col) points, which must be in the grid.
    pub(crate) fn from_points(
        grid: &TileGrid,
        points: impl IntoIterator<Item = (usize, usize)>,
    ) -> Self {
        let pts: Vec<(usize, usize)> = points.into_iter().collect();
        let (Some(lo), Some(hi)) = (pts.iter().map(|p| p.0).min(), pts.iter().map(|p| p.0).max())
        else {
            return TileSet::empty(grid);
        };
        let mut set = TileSet {
            row0: lo,
            words: grid.words,
            bits: vec![0; (hi - lo + 1) * grid.words],
        };
        for (r, c) in pts {
            set.bits[(r - lo) * grid.words + c / 64] |= 1 << (c % 64);
        }
        set
    }

    /// Sets columns c0..=c1 of local row `lr`.
    fn fill(&mut self, lr: usize, c0: usize, c1: usize) {
        let row = &mut self.bits[lr * self.words..(lr + 1) * self.words];
        let (w0, w1) = (c0 / 64, c1 / 64);
        for (w, word) in row.iter_mut().enumerate().take(w1 + 1).skip(w0) {
            let from = if w == w0 { c0 % 64 } else { 0 };
            let to = if w == w1 { c1 % 64 } else { 63 };
            let mask = (u64::MAX >> (63 - to)) & (u64::MAX << from);
            *word |= mask;
        }
    }

    /// Drops empty rows at both ends.
    fn trim(&mut self) {
        let rows = self.rows();
        let w = self.words;
        let nonempty = |r: usize| self.bits[r * w..(r + 1) * w].iter().any(|&x| x != 0);
        let Some(first) = (0..rows).find(|&r| nonempty(r)) else {
            self.bits.clear();
            self.row0 = 0;
            return;
        };
        let last = (0..rows).rev().find(|&r| nonempty(r)).unwrap_or(first);
        self.bits.drain((last + 1) * w..);
        self.bits.drain(..first * w);
        self.row0 += first;
    }

    pub fn is_empty(&self) -> bool {
        self.bits.iter().all(|&x| x == 0)
    }

    /// Number of points.
    pub fn count(&self) -> usize {
        self.bits.iter().map(|x| x.count_ones() as usize).sum()
    }

    /// Rows spanned, as a half-open range (empty set: `0..0`).
    pub(crate) fn row_range(&self) -> std::ops::Range<usize> {
        self.row0..self.row0 + self.rows()
    }

    /// The common rows of two sets as (first row, count).
    fn common_rows(&self, other: &TileSet) -> Option<(usize, usize)> {
        let a = self.row_range();
        let b = other.row_range();
        let lo = a.start.max(b.start);
        let hi = a.end.min(b.end);
        (lo < hi).then_some((lo, hi - lo))
    }

    /// The intersection.
    pub(crate) fn intersect(&self, other: &TileSet) -> TileSet {
        let w = self.words;
        let Some((lo, n)) = self.common_rows(other) else {
            return TileSet {
                row0: 0,
                words: w,
                bits: Vec::new(),
            };
        };
        let a = &self.bits[(lo - self.row0) * w..(lo - self.row0 + n) * w];
        let b = &other.bits[(lo - other.row0) * w..(lo - other.row0 + n) * w];
        let mut set = TileSet {
            row0: lo,
            words: w,
            bits: a.iter().zip(b).map(|(x, y)| x & y).collect(),
        };
        set.trim();
        set
    }

    /// Whether the two sets share a point.
    pub(crate) fn overlaps(&self, other: &TileSet) -> bool {
        let w = self.words;
        let Some((lo, n)) = self.common_rows(other) else {
            return false;
        };
        let a = &self.bits[(lo - self.row0) * w..(lo - self.row0 + n) * w];
        let b = &other.bits[(lo - other.row0) * w..(lo - other.row0 + n) * w];
        a.iter().zip(b).any(|(x, y)| x & y != 0)
    }

    /// Adds every point of `other`.
    pub(crate) fn union_with(&mut self, other: &TileSet) {
        if other.bits.is_empty() {
            return;
        }
        if self.bits.is_empty() {
            *self = other.clone();
            return;
        }
        let w = self.words;
        let lo = self.row0.min(other.row0);
        let hi = self.row_range().end.max(other.row_range().end);
        let mut bits = vec![0u64; (hi - lo) * w];
        for set in [&*self, other] {
            let off = (set.row0 - lo) * w;
            for (d, s) in bits[off..off + set.bits.len()].iter_mut().zip(&set.bits) {
                *d |= s;
            }
        }
        self.row0 = lo;
        self.bits = bits;
    }

    /// Whether (row, col) is in the set.
    pub fn contains(&self, r: usize, c: usize) -> bool {
        if !self.row_range().contains(&r) || c / 64 >= self.words {
            return false;
        }
        self.bits[(r - self.row0) * self.words + c / 64] >> (c % 64) & 1 == 1
    }

    /// Every point as (row, col), row by row.
    pub fn points(&self) -> impl Iterator<Item = (usize, usize)> + '_ {
        let w = self.words;
        self.bits.iter().enumerate().flat_map(move |(i, &word)| {
            let (r, base) = (self.row0 + i / w, (i % w) * 64);
            let mut x = word;
            std::iter::from_fn(move || {
                if x == 0 {
                    return None;
                }
                let b = x.trailing_zeros() as usize;
                x &= x - 1;
                Some((r, base + b))
            })
        })
    }

    /// The mean position of the points (`None` when empty).
    pub(crate) fn centroid(&self, grid: &TileGrid) -> Option<Vec2> {
        let (mut sr, mut sc, mut n) = (0.0, 0.0, 0usize);
        for (r, c) in self.points() {
            sr += r as f64;
            sc += c as f64;
            n += 1;
        }
        (n > 0).then(|| Vec2::new(sc / n as f64 * grid.spacing, sr / n as f64 * grid.spacing))
    }

    /// Points with a 4-neighbour outside the set: the closest point of the
    /// set to anything outside it is always one of them.
    pub(crate) fn boundary(&self) -> Vec<(usize, usize)> {
        self.points()
            .filter(|&(r, c)| {
                r == 0
                    || c == 0
                    || !self.contains(r - 1, c)
                    || !self.contains(r + 1, c)
                    || !self.contains(r, c - 1)
                    || !self.contains(r, c + 1)
            })
            .collect()
    }

    /// d_area of Section IV-F: the smallest distance between a point of
    /// each set, 0 when they overlap, infinite if either is empty.
    pub(crate) fn distance(&self, other: &TileSet, grid: &TileGrid) -> f64 {
        if self.is_empty() || other.is_empty() {
            return f64::INFINITY;
        }
        if self.overlaps(other) {
            return 0.0;
        }
        let a = self.boundary();
        let b = other.boundary();
        // Rows of `a`, each with its sorted columns.
        let mut rows: Vec<(usize, Vec<usize>)> = Vec::new();
        for (r, c) in a {
            match rows.last_mut() {
                Some((lr, cols)) if *lr == r => cols.push(c),
                _ => rows.push((r, vec![c])),
            }
        }
        let mut best = i64::MAX;
        for (qr, qc) in b {
            for (r, cols) in &rows {
                let dy = *r as i64 - qr as i64;
                if dy * dy >= best {
                    continue;
                }
                let i = cols.partition_point(|&c| c < qc);
                for &c in cols
                    .get(i.saturating_sub(1)..(i + 1).min(cols.len()))
                    .unwrap_or(&[])
                {
                    let dx = c as i64 - qc as i64;
                    best = best.min(dx * dx + dy * dy);
                }
            }
        }
        (best as f64).sqrt() * grid.spacing
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disks_intersections_and_distances() {
        let grid = TileGrid::new(200.0, 5.0);
        assert_eq!(grid.side, 41);
        let a = TileSet::disk_union(&grid, &[Vec2::new(50.0, 50.0)], 20.0);
        // Lattice points within 4 units of the origin: 49.
        assert_eq!(a.count(), 49);
        assert_eq!(a.centroid(&grid), Some(Vec2::new(50.0, 50.0)));
        assert!(a.contains(10, 14) && !a.contains(10, 15) && !a.contains(20, 20));
        let b = TileSet::disk_union(&grid, &[Vec2::new(80.0, 50.0)], 20.0);
        let ab = a.intersect(&b);
        // Lens: columns 12..=14 between the two disks.
        assert!(ab.points().all(|(_, c)| (12..=14).contains(&c)));
        assert!(a.overlaps(&b) && ab.count() > 0);
        assert_eq!(a.distance(&b, &grid), 0.0);
        let far = TileSet::disk_union(&grid, &[Vec2::new(150.0, 50.0)], 20.0);
        assert!(!a.overlaps(&far));
        // Rightmost of a: x = 70; leftmost of far: x = 130.
        assert!((a.distance(&far, &grid) - 60.0).abs() < 1e-9);
        assert!(a.intersect(&far).is_empty());
        assert_eq!(a.intersect(&far).row_range(), 0..0);
        let mut u = a.clone();
        u.union_with(&far);
        assert_eq!(u.count(), 2 * 49);
        let two = TileSet::disk_union(
            &grid,
            &[Vec2::new(50.0, 50.0), Vec2::new(150.0, 50.0)],
            20.0,
        );
        assert_eq!(two, u);
        assert!(a.boundary().len() < 49 && a.boundary().len() >= 16);
        // Clipped at the field's edge.
        let corner = TileSet::disk_union(&grid, &[Vec2::new(0.0, 0.0)], 10.0);
        assert_eq!(corner.count(), 6);
        assert_eq!(TileSet::empty(&grid).distance(&a, &grid), f64::INFINITY);
        assert_eq!(TileSet::from_points(&grid, a.points()), a);
        assert!(TileSet::from_points(&grid, std::iter::empty()).is_empty());
    }

    #[test]
    fn rows_wider_than_a_word() {
        let grid = TileGrid::new(1600.0, 5.0);
        assert_eq!(grid.words, 6);
        let a = TileSet::disk_union(&grid, &[Vec2::new(800.0, 800.0)], 250.0);
        let expected = (0..grid.side)
            .flat_map(|r| (0..grid.side).map(move |c| (r, c)))
            .filter(|&(r, c)| grid.point(r, c).distance(Vec2::new(800.0, 800.0)) <= 250.0 + 1e-9)
            .count();
        assert_eq!(a.count(), expected);
        let pts: Vec<_> = a.points().collect();
        assert!(pts
            .iter()
            .all(|&(r, c)| grid.point(r, c).distance(Vec2::new(800.0, 800.0)) <= 250.0 + 1e-9));
    }
}
