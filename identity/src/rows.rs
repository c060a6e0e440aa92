//! A leader's share of an information matrix: the rows (the paper's
//! columns) of the tracks it surveils.
//!
//! Section 3 of Shin et al. (IPSN 2005) is local by construction, which is
//! what its Section 4 builds the distributed version on: a read of track t
//! changes only row t (an O(1) addition, no normalization), and a mix of a
//! and b changes only rows a and b. So a leader holding the rows of its own
//! tracks applies every read with no message at all; a mix of tracks of two
//! leaders needs the two rows exchanged, after which both leaders run the
//! same fit ([`mixed_rows`], a pure function: same inputs, same bits) and
//! each keeps its own row; when a track changes region its row moves with
//! it. The whole matrix exists only when a query asks for marginals:
//! [`InformationRows::assemble`] puts the leaders' rows back together, and
//! the result is the centralized [`InformationMatrix`] bit for bit, since
//! every row saw the same operations in the same order.

use super::event::{check_assignment, check_identify, check_mix, check_track, Identify};
use super::information::{
    add_evidence, mixed_rows, start_row, InformationMatrix, InformationOptions, MixSolver,
};
use idmesh_belief::BeliefError;
use idmesh_belief::Mix;
use std::collections::BTreeMap;

/// The rows of some tracks of an N × N information matrix.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InformationRows {
    n: usize,
    rows: BTreeMap<u32, Vec<f64>>,
    solver: MixSolver,
}

impl InformationRows {
    /// The start rows of `held` tracks: uniform (L = 0), or, with a known
    /// `initial` assignment, [`start_row`] with `confidence` on each
    /// track's identity (as [`InformationMatrix::from_assignment`]).
    pub fn start(
        n: usize,
        held: impl IntoIterator<Item = u32>,
        initial: Option<&[u32]>,
        confidence: f64,
    ) -> Result<Self, BeliefError> {
        if n == 0 {
            return Err(BeliefError::NoTracks);
        }
        if let Some(start) = initial {
            check_assignment(n, start)?;
        }
        let mut rows = BTreeMap::new();
        for t in held {
            check_track(n, t)?;
            let known = initial.map(|start| start[t as usize]);
            rows.insert(t, start_row(n, known, confidence));
        }
        Ok(InformationRows {
            n,
            rows,
            solver: MixSolver::ClosedForm,
        })
    }

    /// N, the tracks (and identities) of the whole matrix.
    pub fn size(&self) -> usize {
        self.n
    }

    pub fn holds(&self, track: u32) -> bool {
        self.rows.contains_key(&track)
    }

    pub fn row(&self, track: u32) -> Option<&[f64]> {
        self.rows.get(&track).map(Vec::as_slice)
    }

    /// The rows held, by track.
    pub fn rows(&self) -> impl Iterator<Item = (u32, &[f64])> + '_ {
        self.rows.iter().map(|(&t, r)| (t, r.as_slice()))
    }

    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// A read: the lazy O(1) update of the read track's row.
    pub fn identify(&mut self, identify: Identify) -> Result<(), BeliefError> {
        check_identify(self.n, &identify)?;
        let row = self.held_mut(identify.track)?;
        add_evidence(row, &identify)
    }

    /// A mix of two tracks whose rows are both held here.
    pub fn mix(&mut self, mix: Mix) -> Result<(), BeliefError> {
        check_mix(self.n, &mix)?;
        let (row_a, row_b) = (self.held(mix.a)?, self.held(mix.b)?);
        if let Some((x, y)) = mixed_rows(row_a, row_b, mix.swap, self.solver)? {
            self.rows.insert(mix.a, x);
            self.rows.insert(mix.b, y);
        }
        Ok(())
    }

    /// A mix of a held track with one held elsewhere, whose row (as it was
    /// before the mix) is `partner`: the fit both holders compute, of which
    /// this one keeps its own row.
    pub fn mix_with(&mut self, mix: Mix, partner: &[f64]) -> Result<(), BeliefError> {
        check_mix(self.n, &mix)?;
        self.check_row(partner)?;
        let (mine_is_a, mine) = match (self.holds(mix.a), self.holds(mix.b)) {
            (true, false) => (true, mix.a),
            (false, true) => (false, mix.b),
            _ => {
                return Err(BeliefError::Unsupported {
                    method: "a share of an information matrix",
                    what: "a mix with a partner row when this share holds both rows or neither",
                })
            }
        };
        let own = self.held(mine)?;
        let (row_a, row_b) = if mine_is_a {
            (own, partner)
        } else {
            (partner, own)
        };
        if let Some((x, y)) = mixed_rows(row_a, row_b, mix.swap, self.solver)? {
            self.rows.insert(mine, if mine_is_a { x } else { y });
        }
        Ok(())
    }

    /// Takes in the start row of `track` (as [`InformationRows::start`]
    /// gives it), for a track no item touched yet and no share held (a
    /// deployment's newcomer, adopted at its first item).
    pub fn adopt(
        &mut self,
        track: u32,
        initial: Option<&[u32]>,
        confidence: f64,
    ) -> Result<(), BeliefError> {
        check_track(self.n, track)?;
        if self.holds(track) {
            return Err(BeliefError::BadComponent {
                detail: format!("track {track} to adopt, whose row is held here"),
            });
        }
        let known = initial.and_then(|start| start.get(track as usize).copied());
        self.insert(track, start_row(self.n, known, confidence))
    }

    /// Gives up the row of a track that leaves this share.
    pub fn take(&mut self, track: u32) -> Option<Vec<f64>> {
        self.rows.remove(&track)
    }

    /// Takes the row of a track that joins this share.
    pub fn insert(&mut self, track: u32, row: Vec<f64>) -> Result<(), BeliefError> {
        check_track(self.n, track)?;
        self.check_row(&row)?;
        self.rows.insert(track, row);
        Ok(())
    }

    /// The whole matrix from every share's rows; each track's row must
    /// come exactly once.
    pub fn assemble(
        n: usize,
        rows: impl IntoIterator<Item = (u32, Vec<f64>)>,
        options: InformationOptions,
    ) -> Result<InformationMatrix, BeliefError> {
        if n == 0 {
            return Err(BeliefError::NoTracks);
        }
        let mut whole: Vec<Option<Vec<f64>>> = vec![None; n];
        for (t, row) in rows {
            check_track(n, t)?;
            let slot = &mut whole[t as usize];
            if slot.is_some() {
                return Err(BeliefError::Numerical {
                    step: "assembling an information matrix",
                    detail: format!("the row of track {t} came twice"),
                });
            }
            *slot = Some(row);
        }
        let mut l = Vec::with_capacity(n);
        for (t, row) in whole.into_iter().enumerate() {
            l.push(row.ok_or_else(|| BeliefError::Numerical {
                step: "assembling an information matrix",
                detail: format!("no share holds the row of track {t}"),
            })?);
        }
        InformationMatrix::from_log_likelihoods(&l, options)
    }

    fn held(&self, track: u32) -> Result<&[f64], BeliefError> {
        self.row(track).ok_or(BeliefError::Unsupported {
            method: "a share of an information matrix",
            what: "an event on a track whose row this share does not hold",
        })
    }

    fn held_mut(&mut self, track: u32) -> Result<&mut [f64], BeliefError> {
        self.rows
            .get_mut(&track)
            .map(Vec::as_mut_slice)
            .ok_or(BeliefError::Unsupported {
                method: "a share of an information matrix",
                what: "an event on a track whose row this share does not hold",
            })
    }

    fn check_row(&self, row: &[f64]) -> Result<(), BeliefError> {
        let bad = |x: &f64| x.is_nan() || *x == f64::INFINITY;
        if row.len() != self.n || row.iter().any(bad) || row.iter().all(|&x| x == f64::NEG_INFINITY)
        {
            return Err(BeliefError::Numerical {
                step: "a row of an information matrix",
                detail: format!(
                    "a row must hold {} log-likelihoods, finite or −∞ and not all −∞, \
                     got {} ({} NaN or +∞)",
                    self.n,
                    row.len(),
                    row.iter().filter(|x| bad(x)).count()
                ),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::information::KNOWN_START_CONFIDENCE;
    use crate::workload::{generate, IdentityWorkload, IdentityWorkloadSpec};
    use crate::{IdentityEvent, IdentityFilter};

    /// Tracks split among `shares` holders round-robin, each event applied
    /// the way leaders apply it (exchanging rows at a mix across two
    /// holders), and the assembled matrix equals the centralized one bit
    /// for bit.
    #[test]
    fn shares_exchanging_rows_at_mixes_equal_the_whole_matrix() {
        for (seed, shares) in [(1, 2), (2, 3), (3, 5)] {
            let n = 7;
            let spec = IdentityWorkloadSpec {
                events: 120,
                mix_share: 0.6,
                swap: 0.3,
                ..IdentityWorkloadSpec::paper(n, 1.0, seed)
            };
            let workload: IdentityWorkload = generate(&spec).unwrap();
            let start = workload.initial.clone();
            let mut whole = InformationMatrix::from_assignment(
                &start,
                KNOWN_START_CONFIDENCE,
                InformationOptions::default(),
            )
            .unwrap();
            let mut owner: Vec<usize> = (0..n).map(|t| t % shares).collect();
            let mut parts: Vec<InformationRows> = (0..shares)
                .map(|s| {
                    let held = (0..n as u32).filter(|&t| owner[t as usize] == s);
                    InformationRows::start(n, held, Some(&start), KNOWN_START_CONFIDENCE).unwrap()
                })
                .collect();
            for (i, event) in workload.events.iter().enumerate() {
                whole.apply(event).unwrap();
                match *event {
                    IdentityEvent::Identify(read) => {
                        parts[owner[read.track as usize]].identify(read).unwrap()
                    }
                    IdentityEvent::Mix(mix) => {
                        let (oa, ob) = (owner[mix.a as usize], owner[mix.b as usize]);
                        if oa == ob {
                            parts[oa].mix(mix).unwrap();
                        } else {
                            let row_a = parts[oa].row(mix.a).unwrap().to_vec();
                            let row_b = parts[ob].row(mix.b).unwrap().to_vec();
                            parts[oa].mix_with(mix, &row_b).unwrap();
                            parts[ob].mix_with(mix, &row_a).unwrap();
                        }
                    }
                }
                // Now and then a track changes region, its row with it.
                if i % 7 == 3 {
                    let t = (i % n) as u32;
                    let (from, to) = (owner[t as usize], (owner[t as usize] + 1) % shares);
                    let row = parts[from].take(t).unwrap();
                    parts[to].insert(t, row).unwrap();
                    owner[t as usize] = to;
                }
            }
            let rows = parts
                .iter()
                .flat_map(|p| p.rows().map(|(t, r)| (t, r.to_vec())))
                .collect::<Vec<_>>();
            let assembled =
                InformationRows::assemble(n, rows, InformationOptions::default()).unwrap();
            assert_eq!(assembled.log_likelihoods(), whole.log_likelihoods());
        }
    }

    #[test]
    fn a_share_refuses_what_it_cannot_apply_and_assembly_checks_every_row() {
        let mut share = InformationRows::start(4, [0, 1], None, 20.0).unwrap();
        let read = Identify {
            track: 2,
            identity: 1,
            accuracy: 0.9,
        };
        assert!(share.identify(read).is_err());
        let mix = Mix {
            a: 0,
            b: 1,
            swap: 0.5,
        };
        assert!(share.mix_with(mix, &[0.0; 4]).is_err());
        let across = Mix {
            a: 0,
            b: 3,
            swap: 0.5,
        };
        assert!(share.mix_with(across, &[0.0; 3]).is_err());
        assert!(share.mix_with(across, &[0.0, f64::NAN, 0.0, 0.0]).is_err());
        assert!(share.insert(9, vec![0.0; 4]).is_err());
        let only_two = share
            .rows()
            .map(|(t, r)| (t, r.to_vec()))
            .collect::<Vec<_>>();
        let err = InformationRows::assemble(4, only_two.clone(), InformationOptions::default())
            .unwrap_err();
        assert!(err.to_string().contains("track 2"), "{err}");
        let twice = only_two.iter().chain(&only_two).cloned();
        assert!(InformationRows::assemble(4, twice, InformationOptions::default()).is_err());
    }
}
