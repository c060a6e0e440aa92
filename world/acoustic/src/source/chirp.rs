//! Bird-like chirps: a song of syllables, each a frequency sweep under a
//! smooth (Hann) envelope, separated by short silences. Like real bird
//! song (the paper used recordings of Florida birds, Section VI-A) the
//! signal is sparse in time and strongly non-Gaussian, which is what
//! FastICA needs.

use rand::Rng;

/// Parameters of a synthetic song. Frequencies are in cycles per sample.
#[derive(Debug, Clone, PartialEq)]
pub struct ChirpParams {
    /// Syllable length range, samples.
    pub syllable: (usize, usize),
    /// Silence between syllables, samples.
    pub gap: (usize, usize),
    /// Start frequency range of a sweep.
    pub frequency: (f64, f64),
    /// End frequency = start × a factor from this range.
    pub sweep: (f64, f64),
}

impl Default for ChirpParams {
    fn default() -> Self {
        ChirpParams {
            syllable: (40, 160),
            gap: (0, 40),
            frequency: (0.02, 0.3),
            sweep: (0.5, 2.0),
        }
    }
}

/// `samples` samples of song, zero mean and unit RMS.
pub fn chirp_song(samples: usize, params: &ChirpParams, rng: &mut impl Rng) -> Vec<f64> {
    let mut out = vec![0.0; samples];
    let mut t = rng.gen_range(0..=params.gap.1.max(1));
    while t < samples {
        let len = rng
            .gen_range(params.syllable.0..=params.syllable.1.max(params.syllable.0))
            .max(2);
        let f0 = rng.gen_range(params.frequency.0..=params.frequency.1);
        let f1 = (f0 * rng.gen_range(params.sweep.0..=params.sweep.1)).min(0.45);
        let amplitude = rng.gen_range(0.5..=1.5);
        let mut phase = rng.gen::<f64>() * std::f64::consts::TAU;
        for k in 0..len {
            if t + k >= samples {
                break;
            }
            let s = k as f64 / (len - 1) as f64;
            let f = f0 + (f1 - f0) * s;
            phase += std::f64::consts::TAU * f;
            let envelope = (std::f64::consts::PI * s).sin().powi(2);
            out[t + k] = amplitude * envelope * phase.sin();
        }
        t += len + rng.gen_range(params.gap.0..=params.gap.1.max(params.gap.0));
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
    fn songs_are_unit_rms_super_or_sub_gaussian_and_independent() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let a = chirp_song(4000, &ChirpParams::default(), &mut rng);
        let b = chirp_song(4000, &ChirpParams::default(), &mut rng);
        let rms = (a.iter().map(|v| v * v).sum::<f64>() / 4000.0).sqrt();
        assert!((rms - 1.0).abs() < 1e-9);
        let kurt = a.iter().map(|v| v.powi(4)).sum::<f64>() / 4000.0 - 3.0;
        assert!(kurt.abs() > 0.3, "excess kurtosis {kurt}");
        let c = crate::metrics::separation::correlation(&a, &b);
        assert!(c.abs() < 0.1, "{c}");
    }
}
