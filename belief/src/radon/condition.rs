//! Conditioning on an observation: Algorithm 2 of the paper (Section 5.2)
//! specialised to the likelihoods of the trace format, L(x) = a if t ∈ x,
//! b otherwise (a = `red`, b = `blue`).
//!
//! In the paper's dictionary L = b·φ_∅ + (a − b)·φ_t, and φ_α·φ_t = φ_{α∪{t}}
//! (0 when α ∪ {t} exceeds every admissible red count), so an atom fixing t
//! red is scaled by a, and any other atom α keeps b·c_α and adds (a − b)·c_α
//! to α ∪ {t}. When a < b we write L = a·φ_∅ + (b − a)·φ_{∅|t} instead (unless
//! `signed`): the atom keeps a·c_α and adds (b − a)·c_α to the atom that also
//! fixes t blue — positive either way (see [`atom`](super::atom)). An atom
//! fixing t blue is scaled by b. Exact when nothing is pruned.
//!
//! The common factor min(a, b) is moved into the global scale (the paper's
//! "b = 1" trick, which Section 5.4 relies on): atoms that do not involve t
//! then keep their value, and only atoms grown from them are new.
//! In masses (m = c·W) a grown atom gets (factor)·m·W(i+1, o)/W(i, o) (red) or
//! (factor)·m·W(i, o+1)/W(i, o) (blue).

use super::atom::Atom;
use super::sparsify::{restore_uniform, RESTORE_SHARE};
use super::RadonBelief;
use crate::error::BeliefError;
use crate::event::Observe;
use crate::repair::REPAIR_SHARE;
use crate::weights::Weights;
use rustc_hash::FxHashMap;
use std::collections::hash_map::Entry;

/// The least red/blue likelihood ratio the signed form writes in the
/// paper's dictionary (see [`Update::new`]): below it the difference
/// b − (b − a) keeps fewer than about 6 of the 16 digits of a.
pub(crate) const SIGNED_CANCELLATION: f64 = 1e-10;

/// The likelihood, rescaled, as the engine applies it.
pub(super) struct Update {
    /// Moved into the global scale.
    pub(super) scale: f64,
    /// Factor on atoms fixing the track red / blue / neither.
    red: f64,
    blue: f64,
    pub(super) keep: f64,
    /// Weight added to the grown atom (negative only in signed form), and
    /// whether the grown atom fixes the track red (else blue).
    grow: f64,
    grow_red: bool,
}

impl Update {
    pub(super) fn new(observe: &Observe, signed: bool) -> Self {
        let (a, b) = (observe.red, observe.blue);
        // In the signed form a sighting that favours blue by more than
        // `SIGNED_CANCELLATION` is written in positive atoms all the same:
        // b·φ_∅ + (a − b)·φ_t leaves a on the sets holding t as the
        // difference b − (b − a), which rounding makes 0 (a certain red
        // sighting then finds no mass on a valid stream) or noise.
        let grow_red = (signed && a >= b * SIGNED_CANCELLATION) || a >= b;
        let keep_raw = if grow_red { b } else { a };
        // Scale so the untouched atoms keep their value when possible.
        let scale = if keep_raw > 0.0 { keep_raw } else { a.max(b) };
        let (a, b) = (a / scale, b / scale);
        let keep = if grow_red { b } else { a };
        let grow = if grow_red { a - b } else { b - a };
        Update {
            scale,
            red: a,
            blue: b,
            keep,
            grow,
            grow_red,
        }
    }
}

/// Which atoms an observation of t grows into atoms that also fix t.
#[derive(Debug, Clone, Copy)]
pub enum Growth<'a> {
    /// Every atom: exact conditioning (Algorithm 2).
    All,
    /// Atoms meeting these tracks (t's mixing log), and the empty atom: the
    /// distributed rule of Section 5.4 (Algorithm 5).
    Meeting(&'a [u32]),
}

impl Growth<'_> {
    fn grows(&self, atom: &Atom) -> bool {
        match self {
            Growth::All => true,
            // The empty atom (kept only when k is unknown, see
            // `expand_empty`) is grown always, or the belief could never
            // leave the prior.
            Growth::Meeting(p) => atom.meets(p) || (atom.red.is_empty() && atom.blue.is_empty()),
        }
    }
}

/// Conditioning of a collection of masses on an observation of track `t`:
/// per atom, linear, so a leader's share of the belief is conditioned with
/// exactly the arithmetic of the whole. Returns nothing; the caller owns
/// the scale and the normalization.
pub(super) struct Conditioning<'a> {
    pub(super) weights: &'a Weights,
    pub(super) t: u32,
    pub(super) update: Update,
    pub(super) growth: Growth<'a>,
}

impl Conditioning<'_> {
    /// What the atom says of t: fixed red or blue, or free. An atom whose
    /// free tracks are all forced (|α| = k: the rest are blue; |β| = n − k:
    /// the rest are red) fixes t implicitly; treating it so keeps the
    /// dictionary free of duplicates of the same k-set.
    fn role(&self, atom: &Atom) -> Option<bool> {
        atom.fixes(self.t).or_else(|| {
            let (i, o) = atom.sizes();
            if self.weights.ratio_red(i, o) == 0.0 {
                Some(false)
            } else if self.weights.ratio_blue(i, o) == 0.0 {
                Some(true)
            } else {
                None
            }
        })
    }

    fn growth_ratio(&self, atom: &Atom) -> f64 {
        let (i, o) = atom.sizes();
        if self.update.grow_red {
            self.weights.ratio_red(i, o)
        } else {
            self.weights.ratio_blue(i, o)
        }
    }

    /// (new total, total of absolute values) without changing anything.
    pub(super) fn totals(&self, masses: &FxHashMap<Atom, f64>) -> (f64, f64) {
        let update = &self.update;
        let (mut total, mut size) = (0.0, 0.0);
        for (atom, &m) in masses {
            let (kept, grown) = match self.role(atom) {
                Some(true) => (update.red * m, 0.0),
                Some(false) => (update.blue * m, 0.0),
                None if self.growth.grows(atom) => {
                    (update.keep * m, update.grow * m * self.growth_ratio(atom))
                }
                None => (update.keep * m, 0.0),
            };
            total += kept + grown;
            size += kept.abs() + grown.abs();
        }
        (total, size)
    }

    pub(super) fn apply(&self, masses: &mut FxHashMap<Atom, f64>) {
        let update = &self.update;
        let t = self.t;
        let mut added: FxHashMap<Atom, f64> = FxHashMap::default();
        masses.retain(|atom, m| {
            match self.role(atom) {
                Some(true) => *m = floored(*m, update.red),
                Some(false) => *m = floored(*m, update.blue),
                None => {
                    if update.grow != 0.0 && self.growth.grows(atom) {
                        let ratio = self.growth_ratio(atom);
                        let grown = if update.grow_red {
                            atom.with_red(t)
                        } else {
                            atom.with_blue(t)
                        };
                        *added.entry(grown).or_insert(0.0) +=
                            floored(floored(update.grow, *m), ratio);
                    }
                    *m = floored(*m, update.keep);
                }
            }
            *m != 0.0
        });
        for (atom, m) in added {
            match masses.entry(atom) {
                Entry::Occupied(mut held) => {
                    *held.get_mut() += m;
                    if *held.get() == 0.0 {
                        held.remove();
                    }
                }
                Entry::Vacant(free) => {
                    if m != 0.0 {
                        free.insert(m);
                    }
                }
            }
        }
    }
}

// The support floor is the crate's (`crate::support`): the factored
// belief's tables keep theirs by the same two functions.
pub(super) use crate::support::{floored, floored_div};

impl RadonBelief {
    pub(super) fn condition(&mut self, observe: Observe) -> Result<(), BeliefError> {
        let partners: Option<Vec<u32>> = self
            .options
            .distributed_rule
            .then(|| self.mixing_log.partners(observe.track).to_vec());
        let conditioning = Conditioning {
            weights: &self.weights,
            t: observe.track,
            update: Update::new(&observe, self.options.signed),
            growth: match &partners {
                Some(p) => Growth::Meeting(p),
                None => Growth::All,
            },
        };
        // A read-only pass for the new total first, so that an impossible
        // observation leaves the belief untouched.
        let (mut total, mut size) = conditioning.totals(&self.masses);
        let old_total = self.total_mass();
        // A signed expansion can cancel to rounding noise where the true
        // probability is 0: below that noise the observation is impossible.
        let possible = |total: f64, size: f64| total.is_finite() && total > 1e-12 * size;
        let mut restored = None;
        if !possible(total, size) {
            // The approximation may have dropped the sets the observation
            // allows: the rule of `sparsify`; the exact belief held it
            // impossible: the repair rule (`crate::repair`), with its
            // smaller share. On a copy until it is known to help.
            let share = if self.approximate() {
                RESTORE_SHARE
            } else {
                REPAIR_SHARE
            };
            let mut masses = self.masses.clone();
            restore_uniform(&mut masses, share);
            (total, size) = conditioning.totals(&masses);
            restored = Some(masses);
        }
        if !possible(total, size) {
            return Err(BeliefError::ImpossibleObservation {
                probability: conditioning.update.scale * total / old_total,
            });
        }
        if let Some(masses) = restored {
            self.masses = masses;
            crate::repair::note("radon", &mut self.stats.restorations, &observe, false);
        }
        conditioning.apply(&mut self.masses);
        self.log_scale += conditioning.update.scale.ln();
        self.renormalize()
    }
}

#[cfg(test)]
mod tests {
    use crate::event::{Field, Observe};
    use crate::filter::PropertyFilter;
    use crate::radon::{RadonBelief, RadonOptions};
    use crate::track_set::TrackSet;

    #[test]
    fn blue_sighting_gives_negative_coefficients_in_the_signed_form_only() {
        let signed = RadonOptions {
            signed: true,
            ..RadonOptions::default()
        };
        let mut paper = RadonBelief::with_options(Field::uniform(5, 2), signed).unwrap();
        let mut ours = RadonBelief::new(Field::uniform(5, 2)).unwrap();
        let blue = Observe {
            track: 3,
            red: 0.1,
            blue: 0.7,
        };
        paper.observe(blue).unwrap();
        ours.observe(blue).unwrap();
        assert!(paper.coefficient(&TrackSet::singleton(3)) < 0.0);
        assert!(ours.coefficients_iter().all(|(_, c)| c > 0.0));
        let (p, q) = (paper.marginals().unwrap(), ours.marginals().unwrap());
        for (x, y) in p.iter().zip(&q) {
            assert!((x - y).abs() < 1e-12);
        }
        assert!((paper.log_normalizer() - ours.log_normalizer()).abs() < 1e-12);
    }

    #[test]
    fn certain_blue_removes_every_set_with_the_track() {
        let mut belief = RadonBelief::new(Field::uniform(6, 3)).unwrap();
        belief
            .observe(Observe {
                track: 2,
                red: 0.9,
                blue: 0.3,
            })
            .unwrap();
        belief
            .observe(Observe {
                track: 2,
                red: 0.0,
                blue: 1.0,
            })
            .unwrap();
        let p = belief.marginals().unwrap();
        assert!(p[2].abs() < 1e-12);
        assert!((p.iter().sum::<f64>() - 3.0).abs() < 1e-12);
    }

    #[test]
    fn a_contradicting_sighting_is_taken_as_by_the_exact_filter() {
        let field = Field::known(4, vec![0, 1]);
        let mut belief = RadonBelief::new(field.clone()).unwrap();
        let mut exact = crate::baseline::DenseFilter::new(field).unwrap();
        let sighting = Observe {
            track: 3,
            red: 1.0,
            blue: 0.0,
        };
        belief.observe(sighting).unwrap();
        exact.observe(sighting).unwrap();
        let (p, q) = (belief.marginals().unwrap(), exact.marginals().unwrap());
        for (a, b) in p.iter().zip(&q) {
            assert!((a - b).abs() < 1e-12, "{p:?} vs {q:?}");
        }
        assert!((p[3] - 1.0).abs() < 1e-12);
        assert_eq!((belief.repairs(), exact.repairs()), (1, 1));
        // A sure red with no red target is set aside.
        let mut none = RadonBelief::new(Field::uniform(4, 0)).unwrap();
        let before = none.marginals().unwrap();
        none.observe(sighting).unwrap();
        assert_eq!(none.marginals().unwrap(), before);
        assert_eq!(none.repairs(), 1);
    }

    /// The example of Section 5.4.2 (track ids as in the paper): the leader
    /// holds {1},{3},{3,5},{5},{4,5},{5,8}; track 3 mixed with 8, 1 and 2
    /// since it was last observed; observing it red adds {1,3} and {3,5,8}
    /// only, rescales {3} and {3,5}, and leaves the rest unchanged.
    #[test]
    fn distributed_rule_grows_only_sets_meeting_the_mixing_log() {
        let held = [
            vec![1],
            vec![3],
            vec![3, 5],
            vec![5],
            vec![4, 5],
            vec![5, 8],
        ];
        let options = RadonOptions {
            distributed_rule: true,
            ..RadonOptions::default()
        };
        let coefficients = held
            .iter()
            .map(|s| (TrackSet::from_tracks(s.iter().copied()), 1.0));
        let mut belief =
            RadonBelief::from_coefficients(Field::uniform(9, 4), options, coefficients).unwrap();
        for partner in [8, 1, 2] {
            // swap = 0: logged as a mix, the coefficients do not move.
            belief
                .mix(crate::event::Mix {
                    a: 3,
                    b: partner,
                    swap: 0.0,
                })
                .unwrap();
        }
        let before: Vec<(crate::radon::Atom, f64)> = belief
            .coefficients_iter()
            .map(|(a, c)| (a.clone(), c))
            .collect();
        belief
            .observe(Observe {
                track: 3,
                red: 0.8,
                blue: 0.2,
            })
            .unwrap();
        let mut now: Vec<Vec<u32>> = belief
            .coefficients_iter()
            .map(|(a, _)| a.red.tracks().to_vec())
            .collect();
        now.sort();
        let mut expected: Vec<Vec<u32>> = held
            .iter()
            .cloned()
            .chain([vec![1, 3], vec![3, 5, 8]])
            .collect();
        expected.sort();
        assert_eq!(now, expected);
        // Relative to {1}, untouched sets keep their ratio; {3} is scaled by 4.
        let c = |s: &[u32]| belief.coefficient(&TrackSet::from_tracks(s.iter().copied()));
        let c0 = |s: &[u32]| {
            before
                .iter()
                .find(|(a, _)| a.red.tracks() == s)
                .map(|x| x.1)
                .unwrap()
        };
        assert!((c(&[5]) / c(&[1]) - c0(&[5]) / c0(&[1])).abs() < 1e-12);
        assert!((c(&[3]) / c(&[1]) - 4.0 * c0(&[3]) / c0(&[1])).abs() < 1e-12);
        // The log was cleared: observing 3 again grows nothing new.
        belief
            .observe(Observe {
                track: 3,
                red: 0.8,
                blue: 0.2,
            })
            .unwrap();
        assert_eq!(belief.coefficients(), expected.len());
    }

    /// From the uniform prior the distributed rule starts from the 1-sets
    /// (Section 5.4: "each 1-set is always maintained", the empty set never),
    /// so a sighting moves the belief even before any mix: the same first
    /// step as exact conditioning.
    #[test]
    fn distributed_rule_starts_from_the_one_sets() {
        let options = RadonOptions {
            distributed_rule: true,
            ..RadonOptions::default()
        };
        let mut rule = RadonBelief::with_options(Field::uniform(6, 3), options).unwrap();
        assert_eq!(rule.coefficients(), 6);
        assert!(rule.coefficients_iter().all(|(a, _)| a.red.len() == 1));
        let mut exact = RadonBelief::new(Field::uniform(6, 3)).unwrap();
        let sighting = Observe {
            track: 2,
            red: 0.8,
            blue: 0.2,
        };
        rule.observe(sighting).unwrap();
        exact.observe(sighting).unwrap();
        let (p, q) = (rule.marginals().unwrap(), exact.marginals().unwrap());
        assert!(p[2] > 0.5 + 0.1, "{p:?}");
        assert!((p.iter().sum::<f64>() - 3.0).abs() < 1e-12);
        // Not exact: the rule drops the pairs {2, s} exact conditioning adds.
        assert!((p[2] - q[2]).abs() > 1e-6);
    }
}
