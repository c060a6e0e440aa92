//! Real recordings as sources: WAV through `hound`, Ogg Vorbis through
//! `lewton`, mixed down to mono and resampled to one rate (the files in
//! shared/data/audio are at 22 kHz, 22.05 kHz and 44.1 kHz). The paper
//! used recordings of birds (Section VI-A); these are the nearest we ship.
//!
//! A file that cannot be read or decoded is skipped with a logged warning
//! ([`load_dir`]): a broken recording must never bring a run down.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

/// Why one recording could not be used.
#[derive(Debug, thiserror::Error)]
pub(crate) enum AudioError {
    #[error("{path}: cannot open: {cause}")]
    Open {
        path: PathBuf,
        #[source]
        cause: std::io::Error,
    },
    #[error("{path}: not a readable WAV file: {cause}")]
    Wav {
        path: PathBuf,
        #[source]
        cause: hound::Error,
    },
    #[error("{path}: not a readable Ogg Vorbis file: {cause}")]
    Vorbis {
        path: PathBuf,
        #[source]
        cause: lewton::VorbisError,
    },
    #[error("{path}: unsupported sample format ({detail})")]
    Format { path: PathBuf, detail: String },
    #[error("{path}: no audio samples")]
    Empty { path: PathBuf },
}

/// One decoded recording, mono.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Recording {
    pub path: PathBuf,
    pub sample_rate: u32,
    pub samples: Vec<f64>,
}

/// Decodes a `.wav` or `.ogg` file by its extension.
pub(crate) fn load(path: &Path) -> Result<Recording, AudioError> {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    let rec = match ext.as_deref() {
        Some("wav") => load_wav(path)?,
        Some("ogg") | Some("oga") => load_ogg(path)?,
        _ => {
            return Err(AudioError::Format {
                path: path.to_path_buf(),
                detail: "extension is neither .wav nor .ogg".into(),
            })
        }
    };
    if rec.samples.is_empty() || rec.sample_rate == 0 {
        return Err(AudioError::Empty {
            path: path.to_path_buf(),
        });
    }
    Ok(rec)
}

fn load_wav(path: &Path) -> Result<Recording, AudioError> {
    let wav = |cause| AudioError::Wav {
        path: path.to_path_buf(),
        cause,
    };
    let reader = hound::WavReader::open(path).map_err(wav)?;
    let spec = reader.spec();
    let channels = usize::from(spec.channels.max(1));
    let interleaved: Vec<f64> = match (spec.sample_format, spec.bits_per_sample) {
        (hound::SampleFormat::Float, 32) => reader
            .into_samples::<f32>()
            .map(|s| s.map(f64::from))
            .collect::<Result<_, _>>()
            .map_err(wav)?,
        (hound::SampleFormat::Int, bits @ 1..=32) => {
            let scale = 1.0 / (1u64 << (bits - 1)) as f64;
            reader
                .into_samples::<i32>()
                .map(|s| s.map(|v| v as f64 * scale))
                .collect::<Result<_, _>>()
                .map_err(wav)?
        }
        (format, bits) => {
            return Err(AudioError::Format {
                path: path.to_path_buf(),
                detail: format!("{format:?} with {bits} bits"),
            })
        }
    };
    Ok(Recording {
        path: path.to_path_buf(),
        sample_rate: spec.sample_rate,
        samples: mix_down(&interleaved, channels),
    })
}

fn load_ogg(path: &Path) -> Result<Recording, AudioError> {
    let file = File::open(path).map_err(|cause| AudioError::Open {
        path: path.to_path_buf(),
        cause,
    })?;
    let vorbis = |cause| AudioError::Vorbis {
        path: path.to_path_buf(),
        cause,
    };
    let mut reader =
        lewton::inside_ogg::OggStreamReader::new(BufReader::new(file)).map_err(vorbis)?;
    let channels = usize::from(reader.ident_hdr.audio_channels.max(1));
    let rate = reader.ident_hdr.audio_sample_rate;
    let mut interleaved = Vec::new();
    while let Some(packet) = reader.read_dec_packet_itl().map_err(vorbis)? {
        interleaved.extend(packet.into_iter().map(|v| f64::from(v) / 32768.0));
    }
    Ok(Recording {
        path: path.to_path_buf(),
        sample_rate: rate,
        samples: mix_down(&interleaved, channels),
    })
}

/// Averages the channels of interleaved audio (a stereo recording of one
/// bird has two nearly equal channels: they are not two sources).
fn mix_down(interleaved: &[f64], channels: usize) -> Vec<f64> {
    if channels <= 1 {
        return interleaved.to_vec();
    }
    interleaved
        .chunks_exact(channels)
        .map(|frame| frame.iter().sum::<f64>() / channels as f64)
        .collect()
}

/// Resamples to `to` Hz: a moving average as anti-alias filter when
/// downsampling, then linear interpolation. Crude next to a polyphase
/// filter, but the tracker only needs the recordings to stay independent
/// and non-Gaussian, not hi-fi.
pub(crate) fn resample(samples: &[f64], from: u32, to: u32) -> Vec<f64> {
    if from == to || samples.is_empty() || from == 0 || to == 0 {
        return samples.to_vec();
    }
    let ratio = f64::from(from) / f64::from(to);
    let smoothed: Vec<f64> = if ratio > 1.0 {
        let w = ratio.round().max(1.0) as usize;
        let mut acc = 0.0;
        let mut out = Vec::with_capacity(samples.len());
        for (i, &v) in samples.iter().enumerate() {
            acc += v;
            if i >= w {
                acc -= samples[i - w];
            }
            out.push(acc / (i + 1).min(w) as f64);
        }
        out
    } else {
        samples.to_vec()
    };
    let n = ((samples.len() as f64) / ratio).floor() as usize;
    (0..n)
        .map(|k| {
            let x = k as f64 * ratio;
            let i = x.floor() as usize;
            let f = x - i as f64;
            let a = smoothed[i.min(smoothed.len() - 1)];
            let b = smoothed[(i + 1).min(smoothed.len() - 1)];
            a + (b - a) * f
        })
        .collect()
}

/// Every `.wav` and `.ogg` file of `dir` (sorted by name, so runs are
/// reproducible), decoded and resampled to `rate` Hz. Unreadable files are
/// skipped with a warning; a missing directory gives an empty list (and a
/// warning).
pub(crate) fn load_dir(dir: &Path, rate: u32) -> Vec<Recording> {
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) => {
            tracing::warn!("audio directory {}: {e}; no recordings used", dir.display());
            return Vec::new();
        }
    };
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| {
            matches!(
                p.extension()
                    .and_then(|e| e.to_str())
                    .map(str::to_ascii_lowercase)
                    .as_deref(),
                Some("wav") | Some("ogg") | Some("oga")
            )
        })
        .collect();
    paths.sort();
    let mut out = Vec::new();
    for path in paths {
        match load(&path) {
            Ok(rec) => {
                let samples = resample(&rec.samples, rec.sample_rate, rate);
                tracing::debug!(
                    "audio {}: {} samples at {} Hz -> {} at {rate} Hz",
                    path.display(),
                    rec.samples.len(),
                    rec.sample_rate,
                    samples.len()
                );
                out.push(Recording {
                    path: rec.path,
                    sample_rate: rate,
                    samples,
                });
            }
            Err(e) => tracing::warn!("skipping recording: {e}"),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("idmesh-audio-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn wav_round_trip_and_broken_files_are_skipped() {
        let dir = scratch("wav");
        let spec = hound::WavSpec {
            channels: 2,
            sample_rate: 16_000,
            bits_per_sample: 16,
            sample_format: hound::SampleFormat::Int,
        };
        let path = dir.join("a.wav");
        let mut w = hound::WavWriter::create(&path, spec).unwrap();
        for k in 0..1000 {
            let v = ((k as f64 * 0.05).sin() * 16000.0) as i16;
            w.write_sample(v).unwrap();
            w.write_sample(v).unwrap();
        }
        w.finalize().unwrap();
        std::fs::write(dir.join("b.ogg"), b"not an ogg stream").unwrap();
        std::fs::write(dir.join("c.wav"), b"RIFF....nonsense").unwrap();
        std::fs::write(dir.join("notes.txt"), b"ignored").unwrap();
        let recs = load_dir(&dir, 8000);
        assert_eq!(recs.len(), 1, "only the good file");
        assert_eq!(recs[0].samples.len(), 500);
        let peak = recs[0].samples.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!((0.4..0.5).contains(&peak), "{peak}");
        assert!(matches!(
            load(&dir.join("b.ogg")),
            Err(AudioError::Vorbis { .. })
        ));
        let err = load(&dir.join("c.wav")).unwrap_err();
        assert!(err.to_string().contains("c.wav"), "{err}");
        assert!(load_dir(&dir.join("missing"), 8000).is_empty());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn shared_recordings_decode_when_present() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/audio");
        if !dir.is_dir() {
            return;
        }
        let recs = load_dir(&dir, 22_050);
        assert!(recs.len() >= 4, "{}", recs.len());
        for r in &recs {
            assert!(r.samples.len() > 22_050, "{}", r.path.display());
            assert!(r.samples.iter().all(|v| v.is_finite()));
        }
    }

    #[test]
    fn resampling_keeps_duration() {
        let x: Vec<f64> = (0..44_100).map(|k| (k as f64 * 0.01).sin()).collect();
        assert_eq!(resample(&x, 44_100, 22_050).len(), 22_050);
        assert_eq!(resample(&x, 22_000, 22_050).len(), 44_200);
        assert_eq!(resample(&x, 100, 100), x);
    }
}
