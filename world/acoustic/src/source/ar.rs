//! Autoregressive sources: an AR(2) resonator (a damped oscillation at a
//! random frequency) driven by sparse impulses. Gaussian innovations would
//! make a Gaussian process, which no ICA can separate; impulsive ones keep
//! the output heavy-tailed, like knocks, footsteps or calls.

use rand::Rng;

/// Parameters of an AR(2) source.
#[derive(Debug, Clone, PartialEq)]
pub struct ArParams {
    /// Pole radius range (closer to 1 = longer ringing).
    pub radius: (f64, f64),
    /// Resonance frequency range, cycles per sample.
    pub frequency: (f64, f64),
    /// Probability that a sample carries an impulse.
    pub impulse_rate: f64,
}

impl Default for ArParams {
    fn default() -> Self {
        ArParams {
            radius: (0.8, 0.95),
            frequency: (0.02, 0.3),
            impulse_rate: 0.05,
        }
    }
}

/// `samples` samples, zero mean and unit RMS.
pub fn ar_source(samples: usize, params: &ArParams, rng: &mut impl Rng) -> Vec<f64> {
    let r = rng.gen_range(params.radius.0..=params.radius.1);
    let f = rng.gen_range(params.frequency.0..=params.frequency.1);
    let a1 = 2.0 * r * (std::f64::consts::TAU * f).cos();
    let a2 = -r * r;
    let (mut y1, mut y2) = (0.0, 0.0);
    let mut out = Vec::with_capacity(samples);
    // Burn in so the start is not special.
    for k in 0..samples + 200 {
        let e = if rng.gen::<f64>() < params.impulse_rate {
            crate::pipeline::separate::fastica::standard_normal(rng)
        } else {
            0.0
        };
        let y = a1 * y1 + a2 * y2 + e;
        y2 = y1;
        y1 = y;
        if k >= 200 {
            out.push(y);
        }
    }
    super::normalize(&mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn ar_sources_are_heavy_tailed_and_stable() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let s = ar_source(5000, &ArParams::default(), &mut rng);
        assert_eq!(s.len(), 5000);
        assert!(s.iter().all(|v| v.is_finite()));
        let kurt = s.iter().map(|v| v.powi(4)).sum::<f64>() / 5000.0 - 3.0;
        assert!(kurt > 0.5, "excess kurtosis {kurt}");
    }
}
