//! A bound on the unbudgeted Radon belief: never more coefficients than
//! the dense representation has numbers.
//!
//! The dictionary is overcomplete (Section 4.2): with the uniform prior,
//! exact conditioning (Algorithm 2) adds an atom {t} ∪ α for every held α,
//! so the atoms multiply towards every α|β with |α| ≤ k, |β| ≤ n − k —
//! about 3^n of them (333,072 after 186 events at n = 12, k = 4), while the
//! belief is a function on the C(n, k) red sets (495 there). When the atoms
//! outnumber the sets, the belief is rewritten on the point atoms φ_x,
//! |x| = k (the indicator of the one set x: a Radon atom of the paper's
//! dictionary), each carrying f(x). Those stay point atoms under rollup
//! (Algorithm 1 maps x to x △ {a, b}) and conditioning (a point atom fixes
//! every track, see `condition::role`), so from then on the belief holds at
//! most C(n, k) coefficients, and it is still exact. Only with exact
//! conditioning and k known, and only while C(n, k) ≤ [`DENSE_SETS_LIMIT`].

use super::atom::Atom;
use super::RadonBelief;
use crate::track_set::TrackSet;
use rustc_hash::FxHashMap;

/// The most red sets for which the belief is rewritten densely: the rewrite
/// costs (sets × atoms), about 2·10⁸ steps at this size.
pub(crate) const DENSE_SETS_LIMIT: usize = 10_000;

impl RadonBelief {
    /// C(n, k) with k known, when at most [`DENSE_SETS_LIMIT`]; `None` with
    /// k unknown (not bounded yet: the admissible sets span every size).
    pub(super) fn dense_sets(&self) -> Option<usize> {
        let k = self.field.red.known()?;
        let n = self.field.tracks;
        let mut c = 1usize;
        for i in 0..k.min(n - k) {
            c = c.checked_mul(n - i)? / (i + 1);
            if c > DENSE_SETS_LIMIT {
                return None;
            }
        }
        Some(c)
    }

    /// Rewrites the belief on point atoms when it holds more atoms than
    /// there are red sets (see the module documentation). Exact: each
    /// atom's mass is spread evenly over the W(atom) sets it covers, which
    /// is what mass means (Section 5.3.2: the l1 contribution of c_α φ_α).
    pub(super) fn bound_by_dense(&mut self) {
        // The distributed rule is an approximation that depends on which
        // atoms are held (it grows only those meeting a mixing log): a
        // rewrite would change what it computes, not just how.
        if self.options.distributed_rule {
            return;
        }
        let Some(sets) = self.dense_sets() else {
            return;
        };
        if self.masses.len() <= sets {
            return;
        }
        let k = self.field.red.known().expect("dense_sets needs k");
        let n = self.field.tracks as u32;
        // Every atom's mass per covered set, in point-atom units: m_α ·
        // W(x)/W(α), and W(x) = C(n − k, 0) = 1.
        let atoms: Vec<(Vec<u32>, Vec<u32>, f64)> = self
            .masses
            .iter()
            .map(|(a, &m)| {
                let (i, o) = a.sizes();
                // Floored: a possible set never rounds to 0 here either.
                let per_set = super::condition::floored(m, (-self.weights.ln2(i, o)).exp());
                (a.red.tracks().to_vec(), a.blue.tracks().to_vec(), per_set)
            })
            .collect();
        let mut dense: FxHashMap<Atom, f64> = FxHashMap::default();
        let mut x: Vec<u32> = (0..k as u32).collect();
        let mut member = vec![false; n as usize];
        loop {
            member.iter_mut().for_each(|b| *b = false);
            for &t in &x {
                member[t as usize] = true;
            }
            let (mut value, mut size) = (0.0, 0.0);
            for (_, _, m) in atoms.iter().filter(|(red, blue, _)| {
                red.iter().all(|&t| member[t as usize]) && blue.iter().all(|&t| !member[t as usize])
            }) {
                value += m;
                size += m.abs();
            }
            // A signed expansion (`RadonOptions::signed`) cancels to
            // rounding noise where f(x) = 0: below that noise the set is
            // impossible, as conditioning decides too.
            if value.abs() > 1e-12 * size {
                dense.insert(Atom::radon(TrackSet::from_tracks(x.iter().copied())), value);
            }
            if !next_combination(&mut x, n) {
                break;
            }
        }
        self.masses = dense;
        // The total mass is unchanged up to rounding; renormalize anyway
        // (an all-zero belief cannot arise: the masses summed to 1).
        let _ = self.renormalize();
    }
}

/// The next k-subset of 0..n in lexicographic order; false after the last.
fn next_combination(x: &mut [u32], n: u32) -> bool {
    let k = x.len();
    for i in (0..k).rev() {
        if x[i] < n - (k - i) as u32 {
            x[i] += 1;
            for j in i + 1..k {
                x[j] = x[j - 1] + 1;
            }
            return true;
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::baseline::DenseFilter;
    use crate::event::Field;
    use crate::filter::PropertyFilter;
    use crate::workload::{generate, WorkloadSpec};

    #[test]
    fn combinations_are_enumerated_once() {
        let mut x = vec![0, 1];
        let mut count = 1;
        while next_combination(&mut x, 5) {
            count += 1;
        }
        assert_eq!(count, 10);
        assert_eq!(x, vec![3, 4]);
    }

    /// The case asked about: the uniform prior at n = 12, k = 4, no budget. The
    /// belief never holds more than C(12, 4) = 495 coefficients (plus the
    /// growth of the one event that crosses it), and stays exact.
    #[test]
    fn the_unbudgeted_belief_is_bounded_by_the_dense_one() {
        for seed in 1..=3 {
            let spec = WorkloadSpec {
                events: 300,
                ..WorkloadSpec::table3(12, seed)
            };
            let spec = WorkloadSpec { red: 4, ..spec };
            let work = generate(&spec);
            let field = Field::uniform(12, 4);
            let mut radon = RadonBelief::new(field.clone()).unwrap();
            let mut dense = DenseFilter::new(field).unwrap();
            for (i, e) in work.events.iter().enumerate() {
                radon.apply(e).unwrap();
                dense.apply(e).unwrap();
                assert!(radon.coefficients() <= 495, "seed {seed} event {i}");
                if i % 25 == 0 {
                    let (a, b) = (radon.marginals().unwrap(), dense.marginals().unwrap());
                    for (x, y) in a.iter().zip(&b) {
                        assert!(
                            (x - y).abs() < 1e-9,
                            "seed {seed} event {i}: {a:?} vs {b:?}"
                        );
                    }
                }
            }
            // The bound costs nothing in the normalizer either.
            assert!((radon.log_normalizer() - dense.log_normalizer()).abs() < 1e-9);
            assert!(radon.stats().max_coefficients <= 495);
        }
    }
}
