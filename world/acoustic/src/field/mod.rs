//! The acoustic field of Section VI-A: a square field with N sensors
//! dropped at random, K targets moving in its central part, each emitting
//! its own signal, and what every sensor records.
//!
//! - [`deploy`] — sensor positions.
//! - [`paths`] — target paths (random waypoint legs, zigzags).
//! - [`attenuation`] — spherical spreading and atmospheric absorption.
//! - [`signals`] — the aggregate signal at every sensor.

pub(crate) mod attenuation;
pub(crate) mod deploy;
pub(crate) mod paths;
pub(crate) mod signals;

use super::error::AcousticError;
use super::source::{self, SourceKind};
use idmesh_sim::{Rect, Vec2};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub use attenuation::Attenuation;
pub use paths::PathSpec;
pub use paths::TruePath;
pub use signals::SensorSignals;

/// Everything that makes a field. Defaults are the paper's (Section VI-A)
/// where it gives them:
///
/// | field | default | paper |
/// |---|---|---|
/// | `size` | 1600 m | 1600 m × 1600 m |
/// | `target_area` | 1000 m | central 1000 m × 1000 m |
/// | `sensors` | 1000 | 400, 700, 1000 |
/// | `range` (R) | 250 m | 250 m |
/// | `targets` (K) | 10 | 10 |
/// | `samples` | 4000 | not given |
/// | `paths` | random, 0.05–0.15 m/sample | random, below 0.15 m/sample |
/// | `sources` | synthetic bird chirps | recorded bird song |
/// | `attenuation` | 1/d and 9.9 dB/km (2 kHz, 20 °C, 50 % RH) | [15], [16] |
/// | `noise_std` | 5·10⁻⁴ (≈ 15 dB SNR at R for a unit source at 1 m) | not given |
#[derive(Debug, Clone, PartialEq)]
pub struct FieldConfig {
    /// Side of the square field, metres.
    pub size: f64,
    /// Side of the central square the targets move in, metres.
    pub target_area: f64,
    /// N, the number of sensors.
    pub sensors: usize,
    /// R, the sensing range of a sensor, metres.
    pub range: f64,
    /// K, the number of targets.
    pub targets: usize,
    /// Length of every recording, samples.
    pub samples: usize,
    pub paths: PathSpec,
    pub sources: SourceKind,
    pub attenuation: Attenuation,
    /// Standard deviation of the white noise every sensor adds.
    pub noise_std: f64,
}

impl Default for FieldConfig {
    fn default() -> Self {
        FieldConfig {
            size: 1600.0,
            target_area: 1000.0,
            sensors: 1000,
            range: 250.0,
            targets: 10,
            samples: 4000,
            paths: PathSpec::default(),
            sources: SourceKind::default(),
            attenuation: Attenuation::default(),
            noise_std: 5e-4,
        }
    }
}

impl FieldConfig {
    /// The whole field, `[0, size]²`.
    pub(crate) fn bounds(&self) -> Rect {
        Rect::with_size(self.size, self.size)
    }

    /// The central square the targets stay in.
    pub(crate) fn target_bounds(&self) -> Rect {
        self.bounds().shrink((self.size - self.target_area) / 2.0)
    }

    pub fn validate(&self) -> Result<(), AcousticError> {
        let bad = |what: &str| Err(AcousticError::Config(what.to_string()));
        if !(self.size.is_finite() && self.size > 0.0) {
            return bad(&format!("field size must be > 0 m, got {}", self.size));
        }
        if !(self.target_area.is_finite()
            && self.target_area > 0.0
            && self.target_area <= self.size)
        {
            return bad(&format!(
                "target area side must be in (0, {}] m, got {}",
                self.size, self.target_area
            ));
        }
        if self.sensors == 0 {
            return bad("need at least one sensor");
        }
        if !(self.range.is_finite() && self.range > 0.0) {
            return bad(&format!("sensing range must be > 0 m, got {}", self.range));
        }
        if self.targets == 0 {
            return bad("need at least one target");
        }
        if self.samples < 2 {
            return bad(&format!("need at least 2 samples, got {}", self.samples));
        }
        if !(self.noise_std.is_finite() && self.noise_std >= 0.0) {
            return bad(&format!("noise std must be ≥ 0, got {}", self.noise_std));
        }
        self.attenuation.validate().map_err(AcousticError::Config)?;
        self.paths
            .validate(self.target_bounds())
            .map_err(AcousticError::Config)
    }
}

/// A generated field: sensors, true paths, source signals and recordings.
#[derive(Debug, Clone)]
pub struct Field {
    pub config: FieldConfig,
    pub sensors: Vec<Vec2>,
    pub paths: Vec<TruePath>,
    /// The signal of every target (K × samples), unit RMS.
    pub sources: Vec<Vec<f64>>,
    pub signals: SensorSignals,
}

impl Field {
    /// Generates the field for `seed`, recording on `threads` threads. The
    /// same config and seed give the same field.
    pub fn generate(
        config: &FieldConfig,
        seed: u64,
        threads: usize,
    ) -> Result<Field, AcousticError> {
        config.validate()?;
        // Independent streams per part, so that (say) changing the path
        // model does not move the sensors.
        let mut root = ChaCha8Rng::seed_from_u64(seed);
        let mut sensor_rng = ChaCha8Rng::seed_from_u64(root.gen());
        let mut path_rng = ChaCha8Rng::seed_from_u64(root.gen());
        let mut source_rng = ChaCha8Rng::seed_from_u64(root.gen());
        let noise_seed: u64 = root.gen();
        let sensors = deploy::deploy_uniform(config.sensors, config.bounds(), &mut sensor_rng);
        let paths = paths::generate(
            &config.paths,
            config.targets,
            config.samples,
            config.target_bounds(),
            &mut path_rng,
        );
        let sources = source::generate(
            &config.sources,
            config.targets,
            config.samples,
            &mut source_rng,
        );
        let signals = signals::record(
            &sensors,
            &paths,
            &sources,
            config.samples,
            config.range,
            &config.attenuation,
            config.noise_std,
            noise_seed,
            threads,
        );
        Ok(Field {
            config: config.clone(),
            sensors,
            paths,
            sources,
            signals,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_field_is_deterministic_and_valid() {
        let config = FieldConfig {
            sensors: 50,
            targets: 3,
            samples: 500,
            ..FieldConfig::default()
        };
        let a = Field::generate(&config, 7, 2).unwrap();
        let b = Field::generate(&config, 7, 1).unwrap();
        assert_eq!(a.signals, b.signals);
        assert_eq!(a.sensors.len(), 50);
        assert_eq!(a.paths.len(), 3);
        assert!(a.paths.iter().all(|p| p
            .positions
            .iter()
            .all(|q| config.target_bounds().contains(*q))));
        let c = Field::generate(&config, 8, 2).unwrap();
        assert_ne!(a.signals, c.signals);
        let err = Field::generate(
            &FieldConfig {
                range: -1.0,
                ..config
            },
            1,
            1,
        )
        .unwrap_err();
        assert!(err.to_string().contains("sensing range"), "{err}");
    }
}
