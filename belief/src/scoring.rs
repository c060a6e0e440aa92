//! The scores of the trace spec (`shared/spec/trace.md`, Scoring): the
//! tracking error with ties shared fractionally, and the two calibration
//! scores, Brier and log-loss, of a belief's marginals against the truth.
//!
//! Ties: a fixed tie-break (by track number, say) rewards a filter that
//! stays at its starting assignment whenever the start sits on low tracks.
//! So marginals equal within [`TIE`] compete for the red slots left after
//! the tracks above them are taken, and each gets an equal share: the error
//! is the expected error of a uniformly random tie-break.

/// Marginals this close are tied.
pub(crate) const TIE: f64 = 1e-9;

/// Probabilities are clipped to [`LOG_LOSS_FLOOR`, 1] in the log-loss.
pub const LOG_LOSS_FLOOR: f64 = 1e-12;

/// The share of a red label each track gets: with k known, the k largest
/// marginals, tied groups (chains of marginals within [`TIE`] of the next)
/// sharing the slots they compete for equally; with k unknown, the tracks at
/// ½ or more, those within [`TIE`] of ½ getting half a label.
pub(crate) fn red_shares(marginals: &[f64], k: Option<usize>) -> Vec<f64> {
    let n = marginals.len();
    let mut share = vec![0.0; n];
    let Some(k) = k else {
        for (s, &p) in share.iter_mut().zip(marginals) {
            *s = if (p - 0.5).abs() <= TIE {
                0.5
            } else if p > 0.5 {
                1.0
            } else {
                0.0
            };
        }
        return share;
    };
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&x, &y| marginals[y].total_cmp(&marginals[x]));
    let mut slots = k.min(n);
    let mut start = 0;
    while start < n && slots > 0 {
        let mut end = start + 1;
        while end < n && marginals[order[end - 1]] - marginals[order[end]] <= TIE {
            end += 1;
        }
        let group = end - start;
        let each = if group <= slots {
            1.0
        } else {
            slots as f64 / group as f64
        };
        for &t in &order[start..end] {
            share[t] = each;
        }
        slots -= group.min(slots);
        start = end;
    }
    share
}

/// The mean of per-run scores and the half-width of its 95 % interval
/// (1.96 standard errors; 0 for a single run): how the accuracy studies
/// give every figure.
pub fn mean_with_interval(scores: &[f64]) -> (f64, f64) {
    let n = scores.len() as f64;
    let mean = scores.iter().sum::<f64>() / n;
    let var = scores.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    (mean, 1.96 * (var / n).sqrt())
}

/// 0/1 truth labels of n tracks from the list of red ones.
fn truth_labels(tracks: usize, truth: &[u32]) -> Vec<f64> {
    let mut y = vec![0.0; tracks];
    for &t in truth {
        if let Some(v) = y.get_mut(t as usize) {
            *v = 1.0;
        }
    }
    y
}

/// The spec's tracking error at one truth line, ties shared: the expected
/// fraction of mislabeled tracks, Σ_t |share_t − [t red]| / n.
pub fn expected_tracking_error(marginals: &[f64], k: Option<usize>, truth: &[u32]) -> f64 {
    let n = marginals.len();
    if n == 0 {
        return f64::NAN;
    }
    let y = truth_labels(n, truth);
    let shares = red_shares(marginals, k);
    shares
        .iter()
        .zip(&y)
        .map(|(s, y)| (s - y).abs())
        .sum::<f64>()
        / n as f64
}

/// Brier score at one truth line: the mean over tracks of (p_t − [t red])².
pub fn brier_score(marginals: &[f64], truth: &[u32]) -> f64 {
    let n = marginals.len();
    if n == 0 {
        return f64::NAN;
    }
    let y = truth_labels(n, truth);
    marginals
        .iter()
        .zip(&y)
        .map(|(p, y)| (p.clamp(0.0, 1.0) - y).powi(2))
        .sum::<f64>()
        / n as f64
}

/// Log-loss at one truth line: the mean over tracks of −ln p(true label),
/// p clipped to [1e-12, 1].
pub fn log_loss(marginals: &[f64], truth: &[u32]) -> f64 {
    let n = marginals.len();
    if n == 0 {
        return f64::NAN;
    }
    let y = truth_labels(n, truth);
    marginals
        .iter()
        .zip(&y)
        .map(|(&p, &y)| {
            let p = p.clamp(0.0, 1.0);
            let q = if y > 0.5 { p } else { 1.0 - p };
            -q.max(LOG_LOSS_FLOOR).ln()
        })
        .sum::<f64>()
        / n as f64
        // −ln 1 is −0: a perfect score prints as 0, not -0.
        + 0.0
}

/// Bins of a reliability diagram: how often a track given probability p of
/// being red was red, with p in ten equal bins.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Reliability {
    /// Per bin: marginals seen, their sum, and how many were red.
    pub count: [u64; 10],
    pub sum_p: [f64; 10],
    pub red: [u64; 10],
}

impl Reliability {
    /// Adds one truth line.
    pub fn add(&mut self, marginals: &[f64], truth: &[u32]) {
        let y = truth_labels(marginals.len(), truth);
        for (&p, &y) in marginals.iter().zip(&y) {
            let p = p.clamp(0.0, 1.0);
            let bin = ((p * 10.0) as usize).min(9);
            self.count[bin] += 1;
            self.sum_p[bin] += p;
            self.red[bin] += u64::from(y > 0.5);
        }
    }

    /// Adds `count` predictions of probability `p`, `right` of them right.
    pub fn add_many(&mut self, p: f64, count: u64, right: u64) {
        if count == 0 {
            return;
        }
        let p = p.clamp(0.0, 1.0);
        let bin = ((p * 10.0) as usize).min(9);
        self.count[bin] += count;
        self.sum_p[bin] += p * count as f64;
        self.red[bin] += right.min(count);
    }

    /// Adds another diagram's counts.
    pub fn merge(&mut self, other: &Reliability) {
        for b in 0..10 {
            self.count[b] += other.count[b];
            self.sum_p[b] += other.sum_p[b];
            self.red[b] += other.red[b];
        }
    }

    /// (mean predicted p, observed red frequency, count) of every bin that
    /// saw a marginal.
    pub fn points(&self) -> Vec<(f64, f64, u64)> {
        (0..10)
            .filter(|&b| self.count[b] > 0)
            .map(|b| {
                let c = self.count[b] as f64;
                (self.sum_p[b] / c, self.red[b] as f64 / c, self.count[b])
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_interval_is_1_96_standard_errors_and_none_for_one_run() {
        let (mean, half) = mean_with_interval(&[1.0, 2.0, 3.0]);
        assert_eq!(mean, 2.0);
        assert!((half - 1.96 * (1.0f64 / 3.0).sqrt()).abs() < 1e-15);
        assert_eq!(mean_with_interval(&[0.25]), (0.25, 0.0));
    }

    #[test]
    fn ties_share_the_slots_they_compete_for() {
        // 0.9 takes a slot; 0.5, 0.5 (+ 1e-10) compete for one: half each.
        let p = [0.5, 0.9, 0.5 + 1e-10, 0.1];
        assert_eq!(red_shares(&p, Some(2)), vec![0.5, 1.0, 0.5, 0.0]);
        // Enough slots for the whole group: all red.
        assert_eq!(red_shares(&p, Some(3)), vec![1.0, 1.0, 1.0, 0.0]);
        // No tie: the fixed order.
        assert_eq!(red_shares(&[0.5, 0.6, 0.4], Some(1)), vec![0.0, 1.0, 0.0]);
        // Three-way tie for two slots.
        let s = red_shares(&[0.3, 0.3, 0.3, 0.0], Some(2));
        for x in &s[..3] {
            assert!((x - 2.0 / 3.0).abs() < 1e-15);
        }
        // k unknown: the threshold, ½ itself half a label.
        assert_eq!(red_shares(&[0.5, 0.7, 0.2], None), vec![0.5, 1.0, 0.0]);
    }

    #[test]
    fn a_filter_stuck_at_its_start_is_not_rewarded_for_low_tracks() {
        // Everything tied at ½ (nothing learnt) with the start {0, 1}: a
        // low-track tie-break would score 0 against the truth {0, 1} and
        // 1 against {2, 3}; shared, both score ½.
        let p = [0.5; 4];
        assert_eq!(expected_tracking_error(&p, Some(2), &[0, 1]), 0.5);
        assert_eq!(expected_tracking_error(&p, Some(2), &[2, 3]), 0.5);
        assert_eq!(
            expected_tracking_error(&[0.9, 0.8, 0.1, 0.2], Some(2), &[0, 2]),
            0.5
        );
    }

    #[test]
    fn calibration_scores() {
        let p = [1.0, 0.0, 0.5, 0.8];
        let truth = [0, 3];
        // (0 + 0 + 0.25 + 0.04) / 4
        assert!((brier_score(&p, &truth) - 0.29 / 4.0).abs() < 1e-15);
        // (0 + 0 + ln 2 − ln 0.8) / 4
        let want = (2f64.ln() - 0.8f64.ln()) / 4.0;
        assert!((log_loss(&p, &truth) - want).abs() < 1e-15);
        // A certain mistake costs −ln 1e-12, not infinity.
        assert!((log_loss(&[0.0], &[0]) - 1e12f64.ln()).abs() < 1e-9);
        // Certain and right: 0, not -0 (which the JSON summaries would print).
        assert_eq!(log_loss(&[1.0, 0.0], &[0]).to_bits(), 0f64.to_bits());
        assert!(brier_score(&[], &[]).is_nan());
    }

    #[test]
    fn reliability_bins_count_how_often_red_was_red() {
        let mut r = Reliability::default();
        r.add(&[0.05, 0.95, 0.97, 1.0], &[1, 3]);
        let points = r.points();
        assert_eq!(points.len(), 2);
        assert_eq!(points[0], (0.05, 0.0, 1));
        let (p, freq, c) = points[1];
        assert!((p - (0.95 + 0.97 + 1.0) / 3.0).abs() < 1e-15);
        assert!((freq - 2.0 / 3.0).abs() < 1e-15 && c == 3);
        let mut both = r.clone();
        both.merge(&r);
        assert_eq!(both.count[9], 6);
    }
}
