//! One component: an exact dense table over every subset of its tracks.

use crate::error::BeliefError;
// Products of table entries keep every set both factors allow (the
// crate's support floor): a table's entries may lean hundreds of orders
// of magnitude against the count weights that select them (sightings
// against the truth, a known count holding the total down), and a set that
// vanished from a product by rounding would leave a later sighting of it
// no mass.
use crate::support::{floored, floored_div};

/// g_C over all subsets y of C, indexed by the bit mask of y in the local
/// order `tracks` (bit i ↔ `tracks[i]`), normalized to sum 1 with the factor
/// kept in `log_scale`, and its count vector c_C[r] = Σ_{|y| = r} g_C(y).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Component {
    pub(crate) tracks: Vec<u32>,
    pub(crate) table: Vec<f64>,
    pub(crate) log_scale: f64,
    pub(crate) counts: Vec<f64>,
}

/// The bits of `table` all but certain under table[y]·w(|y|) (w = 1 if
/// None): (bit, red?, odds of the other colour against that one), for the
/// bits whose odds are at most `margin`. The two colours' weights are
/// summed apart: 1 − P(red) would round odds of 10^-200 to 0, and odds of 0
/// split a track off as exactly certain.
pub(crate) fn certain_odds(
    table: &[f64],
    weights: Option<&[f64]>,
    bits: usize,
    margin: f64,
) -> Vec<(usize, bool, f64)> {
    if bits < 2 {
        return Vec::new();
    }
    let weighed: Vec<f64> = match weights {
        Some(w) => {
            let w = balanced(&counts_of(table, bits), w);
            table
                .iter()
                .enumerate()
                .map(|(y, &g)| g * w[y.count_ones() as usize])
                .collect()
        }
        None => table.to_vec(),
    };
    let total: f64 = weighed.iter().sum();
    if !(total > 0.0 && total.is_finite()) {
        return Vec::new();
    }
    // Per bit, the blocks where it is clear and where it is set lie side
    // by side: contiguous sums, not a walk over each entry's bits.
    let (mut set, mut clear) = (vec![0.0; bits], vec![0.0; bits]);
    for b in 0..bits {
        let half = 1usize << b;
        for block in weighed.chunks_exact(2 * half) {
            clear[b] += block[..half].iter().sum::<f64>();
            set[b] += block[half..].iter().sum::<f64>();
        }
    }
    (0..bits)
        .filter_map(|b| {
            let (red, blue) = (set[b], clear[b]);
            if red <= margin * blue {
                Some((b, false, red / blue))
            } else if blue <= margin * red {
                Some((b, true, blue / red))
            } else {
                None
            }
        })
        .collect()
}

/// The largest factor [`balanced`] puts on a weight: a count the table
/// holds below 10^-300 of its mass gets no more, so that no product
/// overflows (such a count's share is below the doubles' precision there
/// anyway).
const BALANCE_CAP_LN: f64 = 690.8; // ln 10^300

/// How far from 1 (in nats) the largest product may sit before
/// [`balanced`] rescales: products 10^-100 and smaller leave too little
/// room for the rest of the table below them.
const BALANCE_NEEDED_LN: f64 = 230.0; // ln 10^100

/// `w` times the one constant that puts the largest of counts[s]·w[s] at 1
/// (found in log space), capped at 10^300; `w` itself while that largest
/// product is within 10^±100 of 1. Every use of count weights
/// compares them within one component, so the constant changes nothing;
/// but a component's table and its weights can each span 10^200 in
/// opposite directions (a field that every sighting calls red, under a
/// known count, makes every table lean red and the rest's weights lean the
/// other way), and products table[y]·w(|y|) taken as they come underflow
/// to 0 though their ratios are fine: a split would then cut support the
/// reads allow, and the next sighting could find no mass.
pub(crate) fn balanced(counts: &[f64], w: &[f64]) -> Vec<f64> {
    let ln_max = ln_largest_product(counts, w);
    // In range already (every case but drifted tables): left bit for bit
    // as it was, so that the usual answers do not move in their last digit.
    if !ln_max.is_finite() || ln_max.abs() < BALANCE_NEEDED_LN {
        return w.to_vec();
    }
    w.iter()
        .map(|&x| {
            if x > 0.0 {
                (x.ln() - ln_max).min(BALANCE_CAP_LN).exp()
            } else {
                0.0
            }
        })
        .collect()
}

/// ln of the largest counts[s]·w[s] when it sits 10^100 or more away from
/// 1 (None: within, where products taken as they come keep their ratios).
/// There a component's table and its weights span 10^200 and more in
/// opposite directions, and even [`balanced`] weights can lose the ratio
/// of a count held at 10^-319 (a subnormal) to one held at 10^-207 (its
/// factor would pass the cap); a weighted sum is then taken term by term
/// in log space against this largest product instead, as
/// [`weighted_sum`] does.
pub(crate) fn drifted(counts: &[f64], w: &[f64]) -> Option<f64> {
    let ln_max = ln_largest_product(counts, w);
    (ln_max.is_finite() && ln_max.abs() >= BALANCE_NEEDED_LN).then_some(ln_max)
}

/// ln max_s counts[s]·w[s], found in log space (−∞ where every product
/// is 0).
fn ln_largest_product(counts: &[f64], w: &[f64]) -> f64 {
    counts
        .iter()
        .zip(w)
        .filter(|(c, w)| **c > 0.0 && **w > 0.0)
        .map(|(c, w)| c.ln() + w.ln())
        .fold(f64::NEG_INFINITY, f64::max)
}

/// Σ_s a[s]·w[s] divided by e^ln_max, each term in log space: a weighted
/// sum of a drifted component ([`drifted`]), in a scale shared by every
/// sum taken against the same largest product.
pub(crate) fn weighted_sum(a: &[f64], w: &[f64], ln_max: f64) -> f64 {
    a.iter()
        .zip(w)
        .filter(|(x, y)| **x > 0.0 && **y > 0.0)
        .map(|(x, y)| (x.ln() + y.ln() - ln_max).exp())
        .sum()
}

/// Σ_{|y| = r} table[y] for r = 0..=bits.
pub(crate) fn counts_of(table: &[f64], bits: usize) -> Vec<f64> {
    let mut counts = vec![0.0; bits + 1];
    for (y, &g) in table.iter().enumerate() {
        counts[y.count_ones() as usize] += g;
    }
    counts
}

impl Component {
    /// One track with weight `blue` on "not red" and `red` on "red".
    pub(crate) fn singleton(track: u32, blue: f64, red: f64) -> Self {
        Component::from_table(vec![track], vec![blue, red], 0.0)
            .expect("a singleton with positive weight")
    }

    /// Normalizes `table` (its sum goes into the scale) and counts it.
    pub(crate) fn from_table(
        tracks: Vec<u32>,
        mut table: Vec<f64>,
        log_scale: f64,
    ) -> Result<Self, BeliefError> {
        debug_assert_eq!(table.len(), 1 << tracks.len());
        let total: f64 = table.iter().sum();
        if !(total > 0.0 && total.is_finite()) {
            return Err(BeliefError::Degenerate { normalizer: total });
        }
        for g in &mut table {
            *g = floored_div(*g, total);
        }
        let counts = counts_of(&table, tracks.len());
        Ok(Component {
            tracks,
            table,
            log_scale: log_scale + total.ln(),
            counts,
        })
    }

    pub(crate) fn len(&self) -> usize {
        self.tracks.len()
    }

    /// Exact rollup of a mix of local bits i ≠ j: every set holding exactly
    /// one of them trades `swap` of its weight with its image.
    pub(crate) fn rollup(&mut self, i: usize, j: usize, swap: f64) {
        let (bi, bj) = (1usize << i, 1usize << j);
        let stay = 1.0 - swap;
        for y in 0..self.table.len() {
            if y & bi != 0 && y & bj == 0 {
                let z = y ^ bi ^ bj;
                let (gy, gz) = (self.table[y], self.table[z]);
                self.table[y] = stay * gy + swap * gz;
                self.table[z] = stay * gz + swap * gy;
            }
        }
        // The count vector is unchanged: the two images have equal size.
    }

    /// The table times the likelihood of a sighting of local bit `bit`
    /// (unnormalized).
    pub(crate) fn observed(&self, bit: usize, red: f64, blue: f64) -> Vec<f64> {
        let b = 1usize << bit;
        self.table
            .iter()
            .enumerate()
            .map(|(y, &g)| floored(g, if y & b != 0 { red } else { blue }))
            .collect()
    }

    /// The product table of two components: `self`'s tracks take the low
    /// bits, `other`'s the high ones.
    pub(crate) fn outer(&self, other: &Component) -> Component {
        let mut tracks = self.tracks.clone();
        tracks.extend_from_slice(&other.tracks);
        let mut table = Vec::with_capacity(self.table.len() * other.table.len());
        for &h in &other.table {
            table.extend(self.table.iter().map(|&l| floored(l, h)));
        }
        let mut counts = vec![0.0; tracks.len() + 1];
        for (r, &x) in self.counts.iter().enumerate() {
            for (q, &y) in other.counts.iter().enumerate() {
                counts[r + q] += floored(x, y);
            }
        }
        Component {
            tracks,
            table,
            log_scale: self.log_scale + other.log_scale,
            counts,
        }
    }

    /// P(bit i set) for every local bit under the weights table[y]·w(|y|),
    /// and the total weight Σ_y table[y]·w(|y|).
    /// Writes P(bit set) under the table alone into `out[track]` for each
    /// of the component's tracks (no allocation: a query does this for most
    /// of a large field).
    pub(crate) fn write_marginals(&self, out: &mut [f64]) {
        let total: f64 = self.table.iter().sum();
        for (i, &t) in self.tracks.iter().enumerate() {
            let half = 1usize << i;
            let s: f64 = self
                .table
                .chunks_exact(2 * half)
                .map(|b| b[half..].iter().sum::<f64>())
                .sum();
            out[t as usize] = (s / total).clamp(0.0, 1.0);
        }
    }

    pub(crate) fn weighted_marginals(&self, w: &[f64]) -> (Vec<f64>, f64) {
        let bits = self.len();
        if let Some(ln_max) = drifted(&self.counts, w) {
            return self.drifted_marginals(w, ln_max);
        }
        let w = balanced(&self.counts, w);
        let mut weighted: Vec<f64> = self
            .table
            .iter()
            .enumerate()
            .map(|(y, &g)| g * w[y.count_ones() as usize])
            .collect();
        let total: f64 = weighted.iter().sum();
        let mut marginals = vec![0.0; bits];
        // Per bit, the strided sum of the sets holding it.
        for (i, m) in marginals.iter_mut().enumerate() {
            let half = 1usize << i;
            let mut s = 0.0;
            for block in weighted.chunks_exact(2 * half) {
                s += block[half..].iter().sum::<f64>();
            }
            *m = if total > 0.0 { s / total } else { 0.0 };
        }
        weighted.clear();
        (marginals, total)
    }

    /// [`Component::weighted_marginals`] of a drifted component: from
    /// each track's weight by count (the coordinator's parts hold the
    /// same), every weighted sum in log space ([`weighted_sum`]); the
    /// total in units of e^ln_max.
    fn drifted_marginals(&self, w: &[f64], ln_max: f64) -> (Vec<f64>, f64) {
        let total = weighted_sum(&self.counts, w, ln_max);
        let marginals = self
            .red_by_count()
            .iter()
            .map(|red| {
                if total > 0.0 {
                    weighted_sum(red, w, ln_max) / total
                } else {
                    0.0
                }
            })
            .collect();
        (marginals, total)
    }

    /// Per track, Σ_{|y| = s, y ∋ track} table[y] for s = 0..=bits.
    pub(crate) fn red_by_count(&self) -> Vec<Vec<f64>> {
        let m = self.len();
        let mut red = vec![vec![0.0; m + 1]; m];
        for (y, &g) in self.table.iter().enumerate() {
            let s = y.count_ones() as usize;
            // Only the tracks red in y gain its weight.
            let mut bits = y;
            while bits != 0 {
                red[bits.trailing_zeros() as usize][s] += g;
                bits &= bits - 1;
            }
        }
        red
    }

    /// c[r] = Σ_{|y| = r, y ⊇ need} table[y].
    pub(crate) fn counts_holding(&self, need: usize) -> Vec<f64> {
        let mut counts = vec![0.0; self.len() + 1];
        for (y, &g) in self.table.iter().enumerate() {
            if y & need == need {
                counts[y.count_ones() as usize] += g;
            }
        }
        counts
    }

    /// Splits off the local bits in `fixed` (bit, red?, odds of the other
    /// colour; see [`certain_odds`]), each all but certain: the rest keeps the
    /// slice of the table where those bits take their fixed values, and
    /// each fixed track becomes a singleton with those odds. Exact when the sets outside
    /// the slice have no weight (the singleton is then certain); otherwise
    /// the rest forgets how they differ, but the other colour keeps its
    /// weight: a later certain sighting of it, which a stream the world
    /// produced may hold, still finds mass.
    pub(crate) fn restrict(
        &self,
        fixed: &[(usize, bool, f64)],
    ) -> Result<(Component, Vec<Component>), BeliefError> {
        let fixed_mask: usize = fixed.iter().map(|&(b, _, _)| 1usize << b).sum();
        let value: usize = fixed
            .iter()
            .filter(|&&(_, red, _)| red)
            .map(|&(b, _, _)| 1usize << b)
            .sum();
        let keep: Vec<usize> = (0..self.len())
            .filter(|b| fixed_mask & (1 << b) == 0)
            .collect();
        let tracks = keep.iter().map(|&b| self.tracks[b]).collect();
        let table = (0..1usize << keep.len())
            .map(|local| {
                let mut y = value;
                for (i, &b) in keep.iter().enumerate() {
                    if local & (1 << i) != 0 {
                        y |= 1 << b;
                    }
                }
                self.table[y]
            })
            .collect();
        let rest = Component::from_table(tracks, table, self.log_scale)?;
        let singles = fixed
            .iter()
            .map(|&(b, red, odds)| {
                let t = self.tracks[b];
                // The likely colour weighs 1, so a certain track stays
                // exactly certain.
                if red {
                    Component::singleton(t, odds, 1.0)
                } else {
                    Component::singleton(t, 1.0, odds)
                }
            })
            .collect();
        Ok((rest, singles))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rollup_blends_images_and_keeps_counts() {
        let mut c = Component::from_table(vec![5, 6], vec![0.1, 0.2, 0.3, 0.4], 0.0).unwrap();
        let before = c.counts.clone();
        c.rollup(0, 1, 0.25);
        // y = {5} (mask 1) and z = {6} (mask 2) trade a quarter.
        assert!((c.table[1] - (0.75 * 0.2 + 0.25 * 0.3)).abs() < 1e-15);
        assert!((c.table[2] - (0.75 * 0.3 + 0.25 * 0.2)).abs() < 1e-15);
        assert_eq!(c.table[0], 0.1);
        assert_eq!(c.table[3], 0.4);
        assert_eq!(c.counts, before);
    }

    #[test]
    fn outer_product_and_restriction_invert() {
        let a = Component::from_table(vec![0, 1], vec![0.1, 0.2, 0.3, 0.4], 0.5).unwrap();
        let b = Component::singleton(2, 0.0, 1.0);
        let m = a.outer(&b);
        assert_eq!(m.tracks, vec![0, 1, 2]);
        assert_eq!(m.counts, counts_of(&m.table, 3));
        let (rest, singles) = m.restrict(&[(2, true, 0.0)]).unwrap();
        assert_eq!(rest.tracks, a.tracks);
        for (x, y) in rest.table.iter().zip(&a.table) {
            assert!((x - y).abs() < 1e-15);
        }
        assert!((rest.log_scale - a.log_scale).abs() < 1e-15);
        assert_eq!(singles, vec![b]);
    }

    #[test]
    fn weighted_marginals_count_the_sets_holding_each_bit() {
        let c = Component::from_table(vec![0, 1], vec![0.1, 0.2, 0.3, 0.4], 0.0).unwrap();
        let (m, total) = c.weighted_marginals(&[1.0, 1.0, 1.0]);
        assert!((total - 1.0).abs() < 1e-15);
        assert!((m[0] - 0.6).abs() < 1e-15);
        assert!((m[1] - 0.7).abs() < 1e-15);
        // Only sets of one track count: P(bit 0) = 0.2 / 0.5.
        let (m, _) = c.weighted_marginals(&[0.0, 1.0, 0.0]);
        assert!((m[0] - 0.4).abs() < 1e-15);
    }
}
