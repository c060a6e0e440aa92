//! What every sensor records (Section III-B, equation (1)): the sum of the
//! sources within its sensing range R, each scaled by the attenuation of
//! its current distance, plus white sensor noise. Because targets move,
//! the mixing matrix changes from sample to sample — the effect Section
//! V-A discusses. Propagation delay is ignored, as in the paper's
//! instantaneous model.

use super::attenuation::Attenuation;
use super::paths::TruePath;
use crate::parallel::par_map;
use crate::pipeline::separate::fastica::standard_normal;
use idmesh_sim::Vec2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The recordings of all sensors: `samples` samples per sensor, row-major
/// (sensor `i` is `data[i * samples .. (i + 1) * samples]`).
#[derive(Debug, Clone, PartialEq)]
pub struct SensorSignals {
    pub sensors: usize,
    pub samples: usize,
    pub data: Vec<f64>,
}

impl SensorSignals {
    /// The recording of sensor `i`.
    pub(crate) fn sensor(&self, i: usize) -> &[f64] {
        &self.data[i * self.samples..(i + 1) * self.samples]
    }
}

/// Mixes `sources` (one signal per target, ≥ `samples` long) as heard at
/// `sensors`, with Gaussian noise of standard deviation `noise_std` drawn
/// from a stream per sensor (seeded by `seed` and the sensor index), so the
/// result does not depend on how many threads compute it.
#[allow(clippy::too_many_arguments)]
pub(crate) fn record(
    sensors: &[Vec2],
    paths: &[TruePath],
    sources: &[Vec<f64>],
    samples: usize,
    range: f64,
    attenuation: &Attenuation,
    noise_std: f64,
    seed: u64,
    threads: usize,
) -> SensorSignals {
    let r2 = range * range;
    let indices: Vec<usize> = (0..sensors.len()).collect();
    let rows = par_map(&indices, threads, |&i| {
        let at = sensors[i];
        let mut rng =
            ChaCha8Rng::seed_from_u64(seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let mut row: Vec<f64> = (0..samples)
            .map(|_| noise_std * standard_normal(&mut rng))
            .collect();
        for (path, source) in paths.iter().zip(sources) {
            for (t, x) in row.iter_mut().enumerate() {
                let d2 = at.distance_sq(path.positions[t]);
                if d2 <= r2 {
                    *x += attenuation.gain(d2.sqrt()) * source[t];
                }
            }
        }
        row
    });
    SensorSignals {
        sensors: sensors.len(),
        samples,
        data: rows.concat(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sensor_hears_only_sources_in_range_attenuated() {
        let sensors = vec![Vec2::new(0.0, 0.0), Vec2::new(1000.0, 0.0)];
        let paths = vec![TruePath {
            positions: vec![Vec2::new(10.0, 0.0); 4],
        }];
        let sources = vec![vec![1.0, -1.0, 2.0, 0.0]];
        let att = Attenuation::default();
        let s = record(&sensors, &paths, &sources, 4, 250.0, &att, 0.0, 1, 2);
        let g = att.gain(10.0);
        assert_eq!(s.sensor(0), &[g, -g, 2.0 * g, 0.0]);
        assert_eq!(s.sensor(1), &[0.0; 4]);
        let noisy = record(&sensors, &paths, &sources, 4, 250.0, &att, 1e-3, 1, 1);
        assert!(noisy.sensor(1).iter().all(|v| v.abs() < 1e-2 && *v != 0.0));
        assert_eq!(
            noisy,
            record(&sensors, &paths, &sources, 4, 250.0, &att, 1e-3, 1, 2)
        );
    }
}
