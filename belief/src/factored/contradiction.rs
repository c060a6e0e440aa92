//! What a query answers when the components, each possible on its own,
//! together hold no red count the prior π allows.
//!
//! Under the local coupling a sighting reads only its own component, so
//! two sure sightings of red on tracks of two components are both taken
//! when k = 1: each is possible where it lands, and only the count
//! coupling at the next query finds that no k-set explains both (the
//! coupled belief smooths at the sighting instead; see `observe_repaired`
//! in the module above). Such a stream contradicts itself: no world
//! produced it. The rule keeps answering, with what the reads allow: every
//! component gives [`REPAIR_MASS`] of its mass to every set whose count
//! some completion of the rest allows (all such sets alike), and the
//! coupling is evaluated again, in log space. Components the contradiction
//! does not touch keep their marginals to within that share; the ones it
//! touches share the blame as the reads weigh them (two sure sightings of
//! red for one red target: one half each).
//!
//! One function for the centralized belief's queries and for the
//! coordinator's [`CouplingTree`](super::CouplingTree), on the same parts,
//! so a deployment and its replay answer alike here too.

use super::counts::CountPrior;
use super::{CountPart, REPAIR_MASS};
use crate::error::BeliefError;

/// The marginals of the belief whose components are `parts` (covering the
/// field's `tracks` once) under the repair rule of the module
/// documentation. Errs only where π allows no count at all, or where the
/// field is too large for the eager evaluation.
pub(crate) fn repaired_marginals(
    prior: &CountPrior,
    parts: &[CountPart],
    tracks: usize,
) -> Result<Vec<f64>, BeliefError> {
    super::check_eager(tracks)?;
    let smoothed: Vec<CountPart> = parts.iter().map(|p| smoothed(prior, p)).collect();
    let counts: Vec<&[f64]> = smoothed.iter().map(|p| &p.counts[..]).collect();
    let weights = prior.all_leave_one_out(&counts);
    let dot = |v: &[f64], r: &[f64]| v.iter().zip(r).map(|(x, y)| x * y).sum::<f64>();
    let mut out = vec![0.0; tracks];
    for (p, r) in smoothed.iter().zip(weights) {
        let r = r.ok_or(BeliefError::Degenerate { normalizer: 0.0 })?;
        let total = dot(&p.counts, &r);
        if !(total > 0.0 && total.is_finite()) {
            return Err(BeliefError::Degenerate { normalizer: total });
        }
        for (&t, w) in p.tracks.iter().zip(&p.red) {
            out[t as usize] = (dot(w, &r) / total).clamp(0.0, 1.0);
        }
    }
    Ok(out)
}

/// `part` normalized, with [`REPAIR_MASS`] of it spread over every set of
/// an open count alike: C(m, s) sets hold count s, C(m − 1, s − 1) of them
/// a given track red.
fn smoothed(prior: &CountPrior, part: &CountPart) -> CountPart {
    let m = part.tracks.len();
    let open: Vec<bool> = prior.uninformed_rest(m).iter().map(|&w| w > 0.0).collect();
    let choose = |n: usize, s: usize| -> f64 {
        (0..s).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
    };
    let sets: f64 = (0..=m).filter(|&s| open[s]).map(|s| choose(m, s)).sum();
    let total: f64 = part.counts.iter().sum();
    // A part without finite mass keeps only the smoothing.
    let spread = |share: f64| if sets > 0.0 { share / sets } else { 0.0 };
    let (keep, spread) = if total > 0.0 && total.is_finite() {
        ((1.0 - REPAIR_MASS) / total, spread(REPAIR_MASS))
    } else {
        (0.0, spread(1.0))
    };
    let counts = (0..=m)
        .map(|s| keep * part.counts[s] + if open[s] { spread * choose(m, s) } else { 0.0 })
        .collect();
    let red = part
        .red
        .iter()
        .map(|w| {
            (0..=m)
                .map(|s| {
                    let uniform = if open[s] && s > 0 {
                        spread * choose(m - 1, s - 1)
                    } else {
                        0.0
                    };
                    keep * w[s] + uniform
                })
                .collect()
        })
        .collect();
    CountPart {
        tracks: part.tracks.clone(),
        counts,
        red,
    }
}
