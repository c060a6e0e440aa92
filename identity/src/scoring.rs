//! The scores trackers use, for identity marginals against a truth line
//! (`truth[t]` = identity on track t): Brier score and log-loss of the
//! marginals, the accuracy of the MAP assignment (the most likely
//! one-to-one assignment under the marginals), IDF1 over a stream
//! (Ristani et al., *Performance Measures and a Data Set for Multi-Target,
//! Multi-Camera Tracking*, ECCV 2016 workshops) and a reliability diagram.
//! The property scores of the trace spec are [`idmesh_belief::brier_score`]
//! and its neighbours.
//!
//! IDF1 with given tracks: every (track, truth line) is one unit of
//! track-time, labelled by the identity the tracker predicts there and
//! carrying the true one. Predicted labels are matched one-to-one to true
//! identities once for the whole stream (the Hungarian algorithm on the
//! co-occurrence counts), and IDF1 is the share of track-time whose matched
//! label is the true identity. Since every track is present at every line,
//! IDP = IDR = IDF1; it is never below the MAP accuracy (the identity
//! matching is one candidate) and forgives a consistent relabelling.

use super::sparse_assignment::{sparse_min_cost_assignment_with_rest, SparseRow};
use super::sparse_marginals::SparseMarginals;
use idmesh_belief::BeliefError;
use idmesh_belief::{Reliability, LOG_LOSS_FLOOR};
use std::collections::BTreeMap;

fn check_truth(p: &SparseMarginals, truth: &[u32]) -> Result<usize, BeliefError> {
    let n = p.size();
    if truth.len() != n || truth.iter().any(|&i| i as usize >= n) {
        return Err(BeliefError::BadInitialIdentity {
            tracks: n,
            got: truth.to_vec(),
        });
    }
    Ok(n)
}

/// Brier score at one truth line: the mean over tracks of
/// Σ_i (p\[t\]\[i\] − 1{truth\[t\] = i})², over the listed entries and
/// each row's rest (as many times as it stands for).
pub fn brier(p: &SparseMarginals, truth: &[u32]) -> Result<f64, BeliefError> {
    let n = check_truth(p, truth)?;
    let total: f64 = p
        .rows()
        .iter()
        .zip(truth)
        .map(|(row, &y)| {
            let listed: f64 = row
                .listed
                .iter()
                .map(|&(i, q)| (q.clamp(0.0, 1.0) - f64::from(i == y)).powi(2))
                .sum();
            let rest = row.rest.clamp(0.0, 1.0);
            let unlisted = (n - row.listed.len()) as f64;
            let mut sum = listed + unlisted * rest * rest;
            if row.listed.binary_search_by_key(&y, |x| x.0).is_err() {
                // The truth is one of the unlisted: (rest − 1)² instead.
                sum += 1.0 - 2.0 * rest;
            }
            sum
        })
        .sum();
    Ok(total / n as f64)
}

/// Log-loss at one truth line: the mean over tracks of
/// −ln p\[t\]\[truth\[t\]\], p clipped to \[1e-12, 1\].
pub fn log_loss(p: &SparseMarginals, truth: &[u32]) -> Result<f64, BeliefError> {
    let n = check_truth(p, truth)?;
    let total: f64 = p
        .rows()
        .iter()
        .zip(truth)
        .map(|(row, &y)| -row.probability(y).clamp(LOG_LOSS_FLOOR, 1.0).ln())
        .sum();
    // −ln 1 is −0: a perfect score prints as 0.
    Ok(total / n as f64 + 0.0)
}

/// The share of tracks whose identity in the most likely one-to-one
/// assignment under `p` is the true one.
#[cfg(test)]
pub(crate) fn map_accuracy(p: &SparseMarginals, truth: &[u32]) -> Result<f64, BeliefError> {
    let n = check_truth(p, truth)?;
    let best = p.most_likely()?;
    let right = best.iter().zip(truth).filter(|(a, b)| a == b).count();
    Ok(right as f64 / n as f64)
}

/// Adds one truth line of identity marginals to a reliability diagram:
/// every entry p\[t\]\[i\] is one prediction, right when track t carries
/// i (a row's rest counts once for each identity it stands for).
pub fn add_reliability(
    diagram: &mut Reliability,
    p: &SparseMarginals,
    truth: &[u32],
) -> Result<(), BeliefError> {
    let n = check_truth(p, truth)?;
    for (row, &y) in p.rows().iter().zip(truth) {
        let mut truth_listed = false;
        for &(i, q) in &row.listed {
            truth_listed |= i == y;
            diagram.add_many(q, 1, u64::from(i == y));
        }
        let unlisted = (n - row.listed.len()) as u64;
        diagram.add_many(row.rest, unlisted, u64::from(!truth_listed));
    }
    Ok(())
}

/// [`brier`] of a dense matrix.
#[cfg(test)]
pub(crate) fn identity_brier(p: &[Vec<f64>], truth: &[u32]) -> Result<f64, BeliefError> {
    brier(&SparseMarginals::from_dense(p)?, truth)
}

/// [`log_loss`] of a dense matrix.
#[cfg(test)]
pub(crate) fn identity_log_loss(p: &[Vec<f64>], truth: &[u32]) -> Result<f64, BeliefError> {
    log_loss(&SparseMarginals::from_dense(p)?, truth)
}

/// IDF1 of a stream of (predicted, true) assignments over the same n
/// tracks (see the module docs): the share of track-time right after one
/// global matching of predicted labels to true identities.
pub fn idf1(lines: &[(Vec<u32>, Vec<u32>)]) -> Result<f64, BeliefError> {
    let (tp, total) = idf1_counts(lines)?;
    Ok(if total == 0 {
        1.0
    } else {
        tp as f64 / total as f64
    })
}

/// (IDTP, track-time) of [`idf1`], to pool streams.
pub(crate) fn idf1_counts(lines: &[(Vec<u32>, Vec<u32>)]) -> Result<(u64, u64), BeliefError> {
    let Some((first, _)) = lines.first() else {
        return Ok((0, 0));
    };
    let n = first.len();
    // counts[label][identity]: few labels meet many identities, so the
    // matching runs over the pairs seen (a pair never seen counts 0).
    let mut counts: Vec<BTreeMap<u32, u64>> = vec![BTreeMap::new(); n];
    for (predicted, truth) in lines {
        if predicted.len() != n || truth.len() != n {
            return Err(BeliefError::BadInitialIdentity {
                tracks: n,
                got: truth.clone(),
            });
        }
        for (&label, &identity) in predicted.iter().zip(truth) {
            if label as usize >= n || identity as usize >= n {
                return Err(BeliefError::UnknownIdentity {
                    identity: label.max(identity),
                    track: 0,
                    identities: n,
                });
            }
            *counts[label as usize].entry(identity).or_default() += 1;
        }
    }
    let rows: Vec<SparseRow> = counts
        .iter()
        .map(|row| row.iter().map(|(&i, &c)| (i, -(c as f64))).collect())
        .collect();
    // Each line's labels are one-to-one with its identities, so the pairs
    // seen hold a perfect matching.
    let matching = sparse_min_cost_assignment_with_rest(&rows, &vec![0.0; n]).ok_or(
        BeliefError::Numerical {
            step: "IDF1",
            detail: "predicted labels that are not one-to-one with the identities".into(),
        },
    )?;
    let tp = matching
        .iter()
        .enumerate()
        .map(|(l, &i)| counts[l].get(&i).copied().unwrap_or(0))
        .sum();
    Ok((tp, (lines.len() * n) as u64))
}

/// The scores of [`IdentityScores`], averaged.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct IdentityScoreSummary {
    /// Truth lines scored.
    pub lines: u64,
    pub brier: f64,
    pub log_loss: f64,
    pub map_accuracy: f64,
    pub idf1: f64,
}

/// Scores pooled over truth lines and streams: Brier, log-loss and MAP
/// accuracy averaged over truth lines; IDF1 matched per stream and pooled
/// over track-time; the reliability of every marginal entry.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct IdentityScores {
    lines: u64,
    brier: f64,
    log_loss: f64,
    map_right: f64,
    idf1_tp: u64,
    idf1_total: u64,
    pub reliability: Reliability,
}

impl IdentityScores {
    /// Adds one stream: its marginals and truth at every truth line.
    pub fn add_stream(&mut self, lines: &[(SparseMarginals, Vec<u32>)]) -> Result<(), BeliefError> {
        let mut assignments = Vec::with_capacity(lines.len());
        for (p, truth) in lines {
            self.brier += brier(p, truth)?;
            self.log_loss += log_loss(p, truth)?;
            let best = p.most_likely()?;
            let right = best.iter().zip(truth).filter(|(a, b)| a == b).count();
            self.map_right += right as f64 / truth.len().max(1) as f64;
            add_reliability(&mut self.reliability, p, truth)?;
            self.lines += 1;
            assignments.push((best, truth.clone()));
        }
        let (tp, total) = idf1_counts(&assignments)?;
        self.idf1_tp += tp;
        self.idf1_total += total;
        Ok(())
    }

    /// The averages (NaN where nothing was scored).
    pub fn summary(&self) -> IdentityScoreSummary {
        let per_line = |x: f64| {
            if self.lines == 0 {
                f64::NAN
            } else {
                x / self.lines as f64
            }
        };
        IdentityScoreSummary {
            lines: self.lines,
            brier: per_line(self.brier),
            log_loss: per_line(self.log_loss),
            map_accuracy: per_line(self.map_right),
            idf1: if self.idf1_total == 0 {
                f64::NAN
            } else {
                self.idf1_tp as f64 / self.idf1_total as f64
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn brier_and_log_loss_by_hand() {
        // Track 0: (0.8, 0.2), truth 0 → 0.04 + 0.04; track 1: (0.2, 0.8),
        // truth 0 → 0.64 + 0.64. Mean 0.68. Log-loss (−ln 0.8 − ln 0.2)/2.
        let p = vec![vec![0.8, 0.2], vec![0.2, 0.8]];
        let truth = [0, 0];
        // Not a permutation, but scores take any identity per track.
        assert!(identity_brier(&p, &truth).is_ok());
        let truth = [0, 1];
        assert!((identity_brier(&p, &truth).unwrap() - 0.08).abs() < 1e-12);
        let swapped = [1, 0];
        assert!((identity_brier(&p, &swapped).unwrap() - 1.28).abs() < 1e-12);
        let want = -(0.2f64.ln());
        assert!((identity_log_loss(&p, &swapped).unwrap() - want).abs() < 1e-12);
        assert_eq!(identity_log_loss(&[vec![1.0]], &[0]).unwrap(), 0.0);
        // A zero is floored at 1e-12.
        let sure = vec![vec![1.0, 0.0], vec![0.0, 1.0]];
        let floor = -(1e-12f64.ln());
        assert!((identity_log_loss(&sure, &[1, 0]).unwrap() - floor).abs() < 1e-9);
        assert!(identity_brier(&p, &[0, 2]).is_err());
        assert!(identity_brier(&p, &[0]).is_err());
    }

    #[test]
    fn a_rest_scores_as_the_entries_it_stands_for() {
        use crate::sparse_marginals::IdentityRow;
        // Track 0 lists identity 1; identities 0, 2, 3 share 0.1 each.
        let rows = vec![
            IdentityRow::collect(0.1, vec![(1, 0.7)]),
            IdentityRow::collect(0.0, vec![(0, 0.5), (2, 0.5)]),
            IdentityRow::collect(0.25, vec![]),
            IdentityRow::collect(0.0, vec![(3, 1.0)]),
        ];
        let sparse = SparseMarginals::new(rows).unwrap();
        let dense = sparse.dense();
        for truth in [[1, 0, 2, 3], [0, 2, 1, 3], [2, 0, 3, 1]] {
            let want = identity_brier(&dense, &truth).unwrap();
            assert!((brier(&sparse, &truth).unwrap() - want).abs() < 1e-12);
            let want = identity_log_loss(&dense, &truth).unwrap();
            assert!((log_loss(&sparse, &truth).unwrap() - want).abs() < 1e-12);
            let (mut a, mut b) = (Reliability::default(), Reliability::default());
            add_reliability(&mut a, &sparse, &truth).unwrap();
            for (i, column) in (0..4).map(|i| (i, dense.iter().map(|r| r[i]).collect::<Vec<_>>())) {
                let carrier: Vec<u32> = truth
                    .iter()
                    .position(|&x| x == i as u32)
                    .map(|t| vec![t as u32])
                    .unwrap_or_default();
                b.add(&column, &carrier);
            }
            assert_eq!((a.count, a.red), (b.count, b.red));
        }
    }

    #[test]
    fn map_accuracy_takes_the_one_to_one_assignment() {
        // Row-wise argmax would give identity 0 twice; the assignment
        // maximizes the product: 0.9·0.4 > 0.1·0.6, so track 1 gets 1.
        let p = vec![
            vec![0.9, 0.1, 0.0],
            vec![0.6, 0.4, 0.0],
            vec![0.0, 0.0, 1.0],
        ];
        let p = SparseMarginals::from_dense(&p).unwrap();
        assert!((map_accuracy(&p, &[0, 1, 2]).unwrap() - 1.0).abs() < 1e-12);
        assert!((map_accuracy(&p, &[1, 0, 2]).unwrap() - 1.0 / 3.0).abs() < 1e-12);
    }

    #[test]
    fn idf1_forgives_a_consistent_relabelling_only() {
        // Two tracks, three lines. The tracker swaps the two labels for the
        // whole stream: MAP accuracy 0, IDF1 1.
        let swapped: Vec<(Vec<u32>, Vec<u32>)> = (0..3).map(|_| (vec![1, 0], vec![0, 1])).collect();
        assert_eq!(idf1(&swapped).unwrap(), 1.0);
        // Right twice, swapped once: the identity matching keeps 4 of 6.
        let once = vec![
            (vec![0, 1], vec![0, 1]),
            (vec![0, 1], vec![0, 1]),
            (vec![1, 0], vec![0, 1]),
        ];
        assert!((idf1(&once).unwrap() - 4.0 / 6.0).abs() < 1e-12);
        assert_eq!(idf1(&[]).unwrap(), 1.0);
        assert!(idf1(&[(vec![0, 1], vec![0])]).is_err());
    }

    #[test]
    fn scores_pool_lines_and_reliability_counts_every_entry() {
        let p = SparseMarginals::from_dense(&[vec![0.75, 0.25], vec![0.25, 0.75]]).unwrap();
        let mut scores = IdentityScores::default();
        scores
            .add_stream(&[(p.clone(), vec![0, 1]), (p, vec![1, 0])])
            .unwrap();
        let s = scores.summary();
        assert_eq!(s.lines, 2);
        // Brier: 0.125 then 1.125; MAP right then wrong; IDF1: labels
        // (0,1) vs truths (0,1) and (1,0) → 2 of 4 whichever matching.
        assert!((s.brier - 0.625).abs() < 1e-12);
        assert!((s.map_accuracy - 0.5).abs() < 1e-12);
        assert!((s.idf1 - 0.5).abs() < 1e-12);
        // Eight entries: four at 0.75 (two right), four at 0.25 (two right).
        let points = scores.reliability.points();
        assert_eq!(points, vec![(0.25, 0.5, 4), (0.75, 0.5, 4)]);
        assert!(IdentityScores::default().summary().brier.is_nan());
    }
}
