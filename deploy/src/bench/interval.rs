//! How sure a median of noisy rounds is: the distribution-free confidence
//! interval of a median, from order statistics.
//!
//! On this machine one round's CPU ratio of four leaders to one ranges
//! from 0.9× to 2.1× with the same binary, so the median of three rounds
//! can land anywhere from 1.3× to 1.7×. Whether a goal of 1.5× is met is
//! then a question of how many rounds were run, and the report says it:
//! with n rounds sorted, x₍ₖ₎ ≤ median ≤ x₍ₙ₋ₖ₊₁₎ holds with probability
//! 1 − 2·P(B ≤ k − 1), B ~ Binomial(n, ½), whatever the rounds' law (each
//! round's ratio is above the true median or below it with even odds).

/// The interval's confidence.
pub const CONFIDENCE: f64 = 0.95;

/// The middle sample (the upper of the two middle ones for an even count);
/// NaN for none.
pub fn median(samples: &[f64]) -> f64 {
    let mut sorted = samples.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted.get(sorted.len() / 2).copied().unwrap_or(f64::NAN)
}

/// The narrowest interval of order statistics of `samples` that holds
/// their law's median with probability at least [`CONFIDENCE`]:
/// `(low, high, confidence)`. None for fewer than six samples: even their
/// smallest and largest hold the median with less (5: 93.75%).
pub fn median_interval(samples: &[f64]) -> Option<(f64, f64, f64)> {
    if samples.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let n = samples.len();
    let mut sorted = samples.to_vec();
    sorted.sort_by(f64::total_cmp);
    // P(B ≤ j) for j = 0, 1, …, built term by term in logarithms: 2⁻ⁿ
    // alone is 0 in floating point past about a thousand rounds.
    let mut below = Vec::with_capacity(n / 2 + 1);
    let (mut ln_term, mut sum) = (-(n as f64) * std::f64::consts::LN_2, 0.0);
    for j in 0..=n / 2 {
        sum += ln_term.exp();
        below.push(sum);
        ln_term += ((n - j) as f64 / (j + 1) as f64).ln();
    }
    // The largest k whose interval is still sure enough.
    let k = (1..=n / 2)
        .take_while(|&k| 1.0 - 2.0 * below[k - 1] >= CONFIDENCE)
        .last()?;
    Some((sorted[k - 1], sorted[n - k], 1.0 - 2.0 * below[k - 1]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn five_rounds_are_too_few_and_six_give_their_extremes() {
        assert!(median_interval(&[1.0, 2.0, 3.0, 4.0, 5.0]).is_none());
        let (low, high, sure) = median_interval(&[6.0, 1.0, 5.0, 2.0, 4.0, 3.0]).unwrap();
        assert_eq!((low, high), (1.0, 6.0));
        assert!((sure - (1.0 - 2.0 / 64.0)).abs() < 1e-12, "{sure}");
    }

    /// The textbook values: 9 samples give (x₂, x₈) at 96.1%, 20 give
    /// (x₆, x₁₅) at 95.9%.
    #[test]
    fn the_interval_is_the_one_order_statistics_tables_give() {
        let nine: Vec<f64> = (1..=9).rev().map(f64::from).collect();
        let (low, high, sure) = median_interval(&nine).unwrap();
        assert_eq!((low, high), (2.0, 8.0));
        assert!((sure - (1.0 - 2.0 * 10.0 / 512.0)).abs() < 1e-12, "{sure}");
        let twenty: Vec<f64> = (1..=20).map(f64::from).collect();
        let (low, high, sure) = median_interval(&twenty).unwrap();
        assert_eq!((low, high), (6.0, 15.0));
        assert!((sure - 0.958_610_5).abs() < 1e-6, "{sure}");
    }

    /// Drawn from a known law, the interval holds its median about as
    /// often as it says.
    #[test]
    fn the_interval_holds_the_median_as_often_as_it_claims() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut uniform = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let (trials, n) = (4000, 15);
        let mut held = 0;
        for _ in 0..trials {
            // Exponential draws: skewed, median ln 2.
            let draws: Vec<f64> = (0..n).map(|_| -(1.0 - uniform()).ln()).collect();
            let (low, high, _) = median_interval(&draws).unwrap();
            held += usize::from(low <= 2f64.ln() && 2f64.ln() <= high);
        }
        let rate = held as f64 / trials as f64;
        assert!((0.94..=0.99).contains(&rate), "held {rate}");
    }

    /// Thousands of rounds: the interval narrows to about ±1.96·√n/2
    /// order statistics around the middle, as the normal law says.
    #[test]
    fn many_rounds_give_a_narrow_interval_around_the_middle() {
        let n = 3000;
        let samples: Vec<f64> = (0..n).map(f64::from).collect();
        let (low, high, sure) = median_interval(&samples).unwrap();
        let half_width = 1.96 * (n as f64).sqrt() / 2.0;
        let middle = (n as f64 - 1.0) / 2.0;
        assert!((middle - low - half_width).abs() < 3.0, "{low}");
        assert!((high - middle - half_width).abs() < 3.0, "{high}");
        assert!((0.95..0.96).contains(&sure), "{sure}");
    }

    #[test]
    fn a_ratio_that_is_not_a_number_gives_no_interval() {
        assert!(median_interval(
            &[1.0; 5]
                .iter()
                .chain([f64::NAN].iter())
                .copied()
                .collect::<Vec<_>>()
        )
        .is_none());
    }
}
