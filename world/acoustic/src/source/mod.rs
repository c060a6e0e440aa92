//! The signals the targets emit (Section VI-A: recordings of birds). Every
//! target emits its own, independent signal — the assumption that makes
//! blind source separation possible (Section III-B).
//!
//! - [`chirp`] — synthetic bird-like songs (the default).
//! - [`ar`] — autoregressive resonators driven by sparse impulses.
//! - [`audio`] — real recordings (WAV, Ogg Vorbis), e.g. shared/data/audio.

pub(crate) mod ar;
pub(crate) mod audio;
pub(crate) mod chirp;

use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;

pub use ar::ArParams;
pub use chirp::ChirpParams;

/// What the targets emit.
#[derive(Debug, Clone, PartialEq)]
pub enum SourceKind {
    /// Synthetic bird-like songs.
    Chirps(ChirpParams),
    /// AR(2) resonators with impulsive innovations.
    Ar(ArParams),
    /// Alternating chirps and AR sources.
    Mixed,
    /// Windows of the recordings in `dir`, resampled to `rate` Hz; each
    /// target gets its own window (different files first, then different
    /// offsets of the same file). Targets beyond what the recordings can
    /// give (or all of them, if no file decodes) fall back to chirps, with
    /// a warning.
    Recordings { dir: PathBuf, rate: u32 },
}

impl Default for SourceKind {
    fn default() -> Self {
        SourceKind::Chirps(ChirpParams::default())
    }
}

impl SourceKind {
    /// The recordings shipped beside the repository (shared/data/audio).
    pub fn shared_recordings() -> Self {
        SourceKind::Recordings {
            dir: PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/audio"),
            rate: 22_050,
        }
    }

    /// A short name for tables and trace headers.
    pub(crate) fn name(&self) -> &'static str {
        match self {
            SourceKind::Chirps(_) => "chirps",
            SourceKind::Ar(_) => "ar",
            SourceKind::Mixed => "mixed",
            SourceKind::Recordings { .. } => "recordings",
        }
    }
}

/// Scales to zero mean and unit RMS (an all-zero signal stays zero).
pub(crate) fn normalize(x: &mut [f64]) {
    if x.is_empty() {
        return;
    }
    let mean = x.iter().sum::<f64>() / x.len() as f64;
    x.iter_mut().for_each(|v| *v -= mean);
    let rms = (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt();
    if rms > 0.0 {
        x.iter_mut().for_each(|v| *v /= rms);
    }
}

/// `count` independent source signals of `samples` samples each, zero mean
/// and unit RMS, drawn from `rng`.
pub(crate) fn generate(
    kind: &SourceKind,
    count: usize,
    samples: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<Vec<f64>> {
    match kind {
        SourceKind::Chirps(p) => (0..count)
            .map(|_| chirp::chirp_song(samples, p, rng))
            .collect(),
        SourceKind::Ar(p) => (0..count).map(|_| ar::ar_source(samples, p, rng)).collect(),
        SourceKind::Mixed => (0..count)
            .map(|i| {
                if i % 2 == 0 {
                    chirp::chirp_song(samples, &ChirpParams::default(), rng)
                } else {
                    ar::ar_source(samples, &ArParams::default(), rng)
                }
            })
            .collect(),
        SourceKind::Recordings { dir, rate } => {
            let recordings = audio::load_dir(dir, *rate);
            recording_windows(&recordings, count, samples, rng)
        }
    }
}

/// Cuts `count` windows of `samples` samples from the recordings, cycling
/// through the files, each window at a random offset and, within one file,
/// not overlapping an earlier window. A window is kept only if it is not
/// nearly silent (RMS ≥ ¼ of the file's), so a target does not go quiet
/// for the whole run. Falls back to chirps where windows run out.
fn recording_windows(
    recordings: &[audio::Recording],
    count: usize,
    samples: usize,
    rng: &mut ChaCha8Rng,
) -> Vec<Vec<f64>> {
    let mut out = Vec::with_capacity(count);
    let mut taken: Vec<Vec<(usize, usize)>> = vec![Vec::new(); recordings.len()];
    let usable: Vec<usize> = (0..recordings.len())
        .filter(|&i| recordings[i].samples.len() >= samples)
        .collect();
    for target in 0..count {
        let mut window = None;
        for attempt in 0..usable.len() * 20 {
            let file = usable[(target + attempt) % usable.len()];
            let rec = &recordings[file].samples;
            let start = rng.gen_range(0..=rec.len() - samples);
            let end = start + samples;
            if taken[file].iter().any(|&(a, b)| start < b && a < end) {
                continue;
            }
            let file_rms = (rec.iter().map(|v| v * v).sum::<f64>() / rec.len() as f64).sqrt();
            let w = &rec[start..end];
            let rms = (w.iter().map(|v| v * v).sum::<f64>() / samples as f64).sqrt();
            if rms < 0.25 * file_rms {
                continue;
            }
            taken[file].push((start, end));
            window = Some(w.to_vec());
            break;
        }
        let mut signal = window.unwrap_or_else(|| {
            tracing::warn!("no recording window left for target {target}; it sings chirps");
            chirp::chirp_song(samples, &ChirpParams::default(), rng)
        });
        normalize(&mut signal);
        out.push(signal);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn every_kind_gives_unit_rms_signals() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for kind in [
            SourceKind::default(),
            SourceKind::Ar(ArParams::default()),
            SourceKind::Mixed,
            SourceKind::Recordings {
                dir: PathBuf::from("/nonexistent/idmesh"),
                rate: 8000,
            },
        ] {
            let s = generate(&kind, 3, 1000, &mut rng);
            assert_eq!(s.len(), 3);
            for x in &s {
                let rms = (x.iter().map(|v| v * v).sum::<f64>() / 1000.0).sqrt();
                assert!((rms - 1.0).abs() < 1e-9, "{}", kind.name());
            }
        }
    }

    #[test]
    fn shared_recordings_give_distinct_windows() {
        let kind = SourceKind::shared_recordings();
        let SourceKind::Recordings { dir, .. } = &kind else {
            unreachable!()
        };
        if !dir.is_dir() {
            return;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(6);
        let s = generate(&kind, 10, 4000, &mut rng);
        for i in 0..s.len() {
            for j in 0..i {
                let c = crate::metrics::separation::correlation(&s[i], &s[j]);
                assert!(c.abs() < 0.5, "{i} {j} {c}");
            }
        }
    }
}
