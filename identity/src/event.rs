//! The identity events: a [`Mix`] of two tracks (reused from the property
//! engine, [`idmesh_belief::Mix`]) and an [`Identify`] reading, with the read
//! model of Shin et al., *Lazy Inference on Object Identities in Wireless
//! Sensor Networks* (IPSN 2005), Definition 3, generalized from the paper's
//! 0.9 / 0.1/(N − 1) to any accuracy.
//!
//! Conventions used by every identity filter: there are N tracks and N
//! identities, both numbered 0..N, and p\[t\]\[i\] = P(track t carries identity
//! i). The paper writes its matrices the other way round (column = object);
//! our row t is the paper's column t.

use idmesh_belief::BeliefError;
use idmesh_belief::Mix;

/// A sensor read identity `identity` on the target of track `track`.
///
/// The read model: with probability `accuracy` the sensor reads the true
/// identity; otherwise it reads one of the N − 1 other identities, each
/// equally likely. So P(read = i | true identity = x) = `accuracy` if x = i,
/// (1 − `accuracy`)/(N − 1) otherwise. The paper's model is accuracy 0.9.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Identify {
    pub track: u32,
    pub identity: u32,
    /// P(read = true identity), in (0, 1].
    pub accuracy: f64,
}

impl Identify {
    /// P(this read | track carries `truth`) among `n` identities.
    pub(crate) fn likelihood(&self, n: usize, truth: usize) -> f64 {
        if truth == self.identity as usize {
            self.accuracy
        } else {
            self.wrong_read_likelihood(n)
        }
    }

    /// P(this read | the track carries one given identity other than the
    /// one read): (1 − accuracy)/(N − 1). With one identity there is no
    /// other identity, and the value is never used; we return 0.
    pub(crate) fn wrong_read_likelihood(&self, n: usize) -> f64 {
        if n > 1 {
            (1.0 - self.accuracy) / (n as f64 - 1.0)
        } else {
            0.0
        }
    }

    /// ln(accuracy) − ln((1 − accuracy)/(N − 1)): the log-likelihood ratio of
    /// "the read is right" against "it is one given wrong identity". By the
    /// paper's Property 1 this is all an information matrix needs to add.
    /// +∞ for accuracy 1; 0 for N = 1 (a read then says nothing).
    pub fn log_odds(&self, n: usize) -> f64 {
        if n > 1 {
            self.accuracy.ln() - self.wrong_read_likelihood(n).ln()
        } else {
            0.0
        }
    }
}

/// One event for an identity filter.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum IdentityEvent {
    Mix(Mix),
    Identify(Identify),
}

/// Checks a mix against `n` tracks: two distinct tracks in range and a swap
/// probability in [0, 1].
pub(crate) fn check_mix(n: usize, mix: &Mix) -> Result<(), BeliefError> {
    check_track(n, mix.a)?;
    check_track(n, mix.b)?;
    if mix.a == mix.b {
        return Err(BeliefError::SelfMix { track: mix.a });
    }
    // `contains` is false for NaN, so NaN is refused too.
    if !(0.0..=1.0).contains(&mix.swap) {
        return Err(BeliefError::BadSwap { swap: mix.swap });
    }
    Ok(())
}

/// Checks a read against `n` tracks and identities.
pub(crate) fn check_identify(n: usize, identify: &Identify) -> Result<(), BeliefError> {
    check_track(n, identify.track)?;
    if identify.identity as usize >= n {
        return Err(BeliefError::UnknownIdentity {
            identity: identify.identity,
            track: identify.track,
            identities: n,
        });
    }
    if !(identify.accuracy > 0.0 && identify.accuracy <= 1.0) {
        return Err(BeliefError::BadAccuracy {
            accuracy: identify.accuracy,
        });
    }
    Ok(())
}

/// Checks a track id against `n` tracks.
pub(crate) fn check_track(n: usize, track: u32) -> Result<(), BeliefError> {
    if (track as usize) < n {
        Ok(())
    } else {
        Err(BeliefError::UnknownTrack { track, tracks: n })
    }
}

/// Checks that `assignment` (track t carries identity `assignment[t]`) is a
/// permutation of 0..n.
pub(crate) fn check_assignment(n: usize, assignment: &[u32]) -> Result<(), BeliefError> {
    let bad = || BeliefError::BadInitialIdentity {
        tracks: n,
        got: assignment.to_vec(),
    };
    if assignment.len() != n {
        return Err(bad());
    }
    let mut seen = vec![false; n];
    for &i in assignment {
        let slot = seen.get_mut(i as usize).ok_or_else(bad)?;
        if *slot {
            return Err(bad());
        }
        *slot = true;
    }
    Ok(())
}

/// Checks that `matrix` is n × n with n ≥ 1 and returns n.
pub(crate) fn check_square(matrix: &[Vec<f64>]) -> Result<usize, BeliefError> {
    let n = matrix.len();
    if n == 0 {
        return Err(BeliefError::NoTracks);
    }
    if let Some(row) = matrix.iter().find(|row| row.len() != n) {
        return Err(BeliefError::Numerical {
            step: "matrix shape",
            detail: format!("expected {n} × {n}, found a row of length {}", row.len()),
        });
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_model_is_a_distribution_over_reads() {
        // For a fixed truth, the reads' probabilities sum to 1.
        let n = 5;
        for truth in 0..n {
            let total: f64 = (0..n as u32)
                .map(|i| {
                    Identify {
                        track: 0,
                        identity: i,
                        accuracy: 0.9,
                    }
                    .likelihood(n, truth)
                })
                .sum();
            assert!((total - 1.0).abs() < 1e-12);
        }
        let paper = Identify {
            track: 0,
            identity: 0,
            accuracy: 0.9,
        };
        assert!((paper.wrong_read_likelihood(3) - 0.05).abs() < 1e-15);
        assert!((paper.log_odds(3) - (0.9f64 / 0.05).ln()).abs() < 1e-12);
    }

    #[test]
    fn checks_refuse_bad_events() {
        let mix = |a, b, swap| Mix { a, b, swap };
        assert!(check_mix(3, &mix(0, 2, 0.5)).is_ok());
        assert_eq!(
            check_mix(3, &mix(0, 3, 0.5)),
            Err(BeliefError::UnknownTrack {
                track: 3,
                tracks: 3
            })
        );
        assert_eq!(
            check_mix(3, &mix(1, 1, 0.5)),
            Err(BeliefError::SelfMix { track: 1 })
        );
        assert!(check_mix(3, &mix(0, 1, f64::NAN)).is_err());
        let read = |identity, accuracy| Identify {
            track: 0,
            identity,
            accuracy,
        };
        assert!(check_identify(3, &read(2, 1.0)).is_ok());
        assert!(matches!(
            check_identify(3, &read(3, 0.9)),
            Err(BeliefError::UnknownIdentity { .. })
        ));
        for bad in [0.0, -0.1, 1.5, f64::NAN] {
            assert!(matches!(
                check_identify(3, &read(0, bad)),
                Err(BeliefError::BadAccuracy { .. })
            ));
        }
        assert!(check_assignment(3, &[2, 0, 1]).is_ok());
        assert!(check_assignment(3, &[2, 0, 0]).is_err());
        assert!(check_assignment(3, &[2, 0, 3]).is_err());
        assert!(check_assignment(3, &[0, 1]).is_err());
        assert!(check_square(&[vec![1.0, 2.0], vec![3.0]]).is_err());
        assert!(check_square(&[]).is_err());
    }
}
