//! The rule every property filter follows when a sighting contradicts its
//! belief (a sure red on a track the belief holds surely blue; two sure
//! reds where one target is red). Such a stream is valid input — a sensor
//! of accuracy 1.0 can be wrong, and reads arrive in any order — so it may
//! not stop a filter, a replay or a leader:
//!
//! - A sighting the belief gives probability 0 is taken after the belief
//!   gives [`REPAIR_SHARE`] of its mass to the uninformed prior (every red
//!   set the count prior allows, weighted as the uniform prior weighs it):
//!   the sighting then decides, as it would for a belief that had kept a
//!   little doubt.
//! - A sighting the prior itself rules out (a sure red where no target is
//!   red, a sure blue where all are) teaches nothing any belief could
//!   keep: it is set aside, the belief left as it was.
//!
//! Either is counted ([`PropertyFilter::repairs`](crate::PropertyFilter::repairs))
//! and logged once per filter. The factored belief follows the same rule
//! per component, and a contradiction only the red count shows at query
//! time (`factored::contradiction`).

use crate::event::{Field, Observe, RedCount};

/// The share of a belief's mass a repair gives to the uninformed prior.
pub(crate) const REPAIR_SHARE: f64 = 1e-9;

impl Field {
    /// Whether no red set the count prior allows gives `observe` a positive
    /// likelihood: a sure red when no count above 0 is possible, a sure blue
    /// when only all red is. (The initial red set does not restrict this:
    /// mixing can take any target anywhere.)
    pub(crate) fn rules_out(&self, observe: &Observe) -> bool {
        let n = self.tracks;
        let (can_hold, can_lack) = match &self.red {
            RedCount::Known(k) => (*k >= 1, *k < n),
            RedCount::Unknown { prior } => (
                prior.iter().skip(1).any(|&p| p > 0.0),
                prior.iter().take(n).any(|&p| p > 0.0),
            ),
        };
        !((observe.red > 0.0 && can_hold) || (observe.blue > 0.0 && can_lack))
    }
}

/// Counts a repair of `method`'s belief (`set_aside`: the prior ruled the
/// sighting out) and logs the first.
pub(crate) fn note(method: &'static str, repairs: &mut u64, observe: &Observe, set_aside: bool) {
    if *repairs == 0 {
        if set_aside {
            tracing::warn!(
                method,
                ?observe,
                "a sighting the prior rules out was set aside \
                 (counted as a belief repair; logged once)"
            );
        } else {
            tracing::warn!(
                method,
                ?observe,
                "a sighting the belief held impossible was taken after a repair \
                 (counted as a belief repair; logged once)"
            );
        }
    }
    *repairs += 1;
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sure(red: bool) -> Observe {
        Observe {
            track: 0,
            red: if red { 1.0 } else { 0.0 },
            blue: if red { 0.0 } else { 1.0 },
        }
    }

    #[test]
    fn the_prior_rules_out_only_what_no_count_allows() {
        let none = Field::uniform(3, 0);
        assert!(none.rules_out(&sure(true)));
        assert!(!none.rules_out(&sure(false)));
        let all = Field::uniform(3, 3);
        assert!(!all.rules_out(&sure(true)));
        assert!(all.rules_out(&sure(false)));
        // A known start does not restrict it.
        assert!(!Field::known(3, vec![1]).rules_out(&sure(true)));
        let only_zero = Field {
            tracks: 2,
            red: RedCount::Unknown {
                prior: vec![1.0, 0.0, 0.0],
            },
            initial_red: None,
        };
        assert!(only_zero.rules_out(&sure(true)));
        // A soft read is never ruled out.
        let soft = Observe {
            track: 0,
            red: 0.9,
            blue: 0.1,
        };
        assert!(!none.rules_out(&soft));
    }
}
