//! Rollup for a mixing event: Algorithm 1 of the paper (Section 5.1).
//!
//! The transition matrices commute with the Radon bases (Theorem 2), so
//! mixing acts on the coefficients like it acts on the sets themselves: an
//! atom the transposition (a b) leaves unchanged keeps its value; any other
//! atom α keeps p·c_α and sends (1 − p)·c_α to its image (α △ {a, b} for a
//! Radon atom). Sizes are preserved, so masses transform like coefficients.

use super::atom::Atom;
use super::condition::floored;
use super::RadonBelief;
use crate::event::Mix;
use rustc_hash::FxHashMap;

impl RadonBelief {
    pub(super) fn rollup(&mut self, mix: Mix) {
        rollup_masses(&mut self.masses, mix);
    }
}

/// Algorithm 1 on any collection of masses: linear, so it may run on a
/// leader's share of the belief as well as on the whole.
pub(super) fn rollup_masses(masses: &mut FxHashMap<Atom, f64>, mix: Mix) {
    let (a, b) = (mix.a, mix.b);
    let keep = 1.0 - mix.swap;
    // Take out every atom the swap moves; the others are untouched
    // (Algorithm 1, first branch).
    let moved: FxHashMap<Atom, f64> = masses
        .extract_if(|atom, _| !atom.invariant_under(a, b))
        .collect();
    for (atom, &mass) in &moved {
        let image = atom.swapped(a, b);
        // New value of α: p·m_α + (1 − p)·m_{σα}, computed directly (not
        // as a difference) so that swap = 0 or 1 moves values exactly.
        let image_mass = moved.get(&image).copied();
        // Floored like conditioning (`crate::support`): a mass
        // the mix keeps possible never rounds to 0. The sum of a kept and
        // a swapped-in mass is not floored: in the signed form it may
        // cancel exactly.
        let value = floored(mass, keep) + floored(image_mass.unwrap_or(0.0), mix.swap);
        if value != 0.0 {
            masses.insert(atom.clone(), value);
        }
        if image_mass.is_none() {
            let value = floored(mass, mix.swap);
            if value != 0.0 {
                masses.insert(image, value);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::event::{Field, Mix, Observe};
    use crate::filter::PropertyFilter;
    use crate::radon::RadonBelief;
    use crate::track_set::TrackSet;

    fn set(t: &[u32]) -> TrackSet {
        TrackSet::from_tracks(t.iter().copied())
    }

    /// Table II: four tracks (0-based here: the paper's track i is i − 1),
    /// {1,2} red at first, then tracks 1,3 and 3,4 mix with p = ½.
    #[test]
    fn table_ii_distributions() {
        let mut belief = RadonBelief::new(Field::known(4, vec![0, 1])).unwrap();
        belief
            .mix(Mix {
                a: 0,
                b: 2,
                swap: 0.5,
            })
            .unwrap();
        assert!((belief.coefficient(&set(&[0, 1])) - 0.5).abs() < 1e-12);
        assert!((belief.coefficient(&set(&[1, 2])) - 0.5).abs() < 1e-12);
        assert_eq!(belief.coefficients(), 2);
        // Example 5.1: the mix of tracks 3 and 4.
        belief
            .mix(Mix {
                a: 2,
                b: 3,
                swap: 0.5,
            })
            .unwrap();
        assert!((belief.coefficient(&set(&[0, 1])) - 0.5).abs() < 1e-12);
        assert!((belief.coefficient(&set(&[1, 2])) - 0.25).abs() < 1e-12);
        assert!((belief.coefficient(&set(&[1, 3])) - 0.25).abs() < 1e-12);
        assert_eq!(belief.coefficients(), 3);
    }

    #[test]
    fn rollup_preserves_total_mass_and_moves_exactly_on_certain_swaps() {
        let mut belief = RadonBelief::new(Field::uniform(6, 3)).unwrap();
        belief
            .observe(Observe {
                track: 1,
                red: 0.8,
                blue: 0.2,
            })
            .unwrap();
        belief
            .observe(Observe {
                track: 2,
                red: 0.1,
                blue: 0.7,
            })
            .unwrap();
        let before = belief.log_normalizer();
        belief
            .mix(Mix {
                a: 1,
                b: 4,
                swap: 0.3,
            })
            .unwrap();
        assert!((belief.log_normalizer() - before).abs() < 1e-12);
        belief
            .mix(Mix {
                a: 2,
                b: 4,
                swap: 1.0,
            })
            .unwrap();
        assert!((belief.log_normalizer() - before).abs() < 1e-12);
        // swap = 1 is a relabelling: applying it twice restores every value.
        let mut again = belief.clone();
        again
            .mix(Mix {
                a: 1,
                b: 4,
                swap: 1.0,
            })
            .unwrap();
        again
            .mix(Mix {
                a: 1,
                b: 4,
                swap: 1.0,
            })
            .unwrap();
        assert_eq!(again.coefficients(), belief.coefficients());
        for (atom, c) in belief.coefficients_iter() {
            assert_eq!(again.coefficient_of(atom), c);
        }
    }
}
