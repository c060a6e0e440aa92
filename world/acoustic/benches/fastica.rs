//! Criterion benchmark of idmesh's FastICA (the separation step's kernel)
//! on fixed mixtures: the pipeline's typical problem (3 sources heard by a
//! 10-sensor group over a 100-sample segment), the goal's 10 × 10 × 100
//! case, and a larger 10 × 10 × 5000 one, each with the symmetric and the
//! deflation algorithm. The comparison with scikit-learn on the same
//! mixtures is `examples/acoustic_fastica_compare.rs`.
//!
//! `cargo bench -p idmesh-acoustic --bench fastica`

use criterion::{black_box, criterion_group, criterion_main, BenchmarkId, Criterion};
use idmesh_acoustic::{Algorithm, Components, FastIca, FastIcaConfig, FastIcaError};
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Laplace and uniform sources, alternating, mixed by a random matrix.
fn mixture(sources: usize, sensors: usize, samples: usize, seed: u64) -> DMatrix<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let s = DMatrix::from_fn(sources, samples, |i, _| {
        let u: f64 = rng.gen::<f64>() - 0.5;
        if i % 2 == 0 {
            -u.signum() * (1.0 - 2.0 * u.abs()).max(1e-300).ln()
        } else {
            2.0 * u
        }
    });
    let a = DMatrix::from_fn(sensors, sources, |_, _| rng.gen::<f64>() * 2.0 - 1.0);
    a * s
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("fastica");
    for &(sources, sensors, samples) in &[(3, 10, 100), (10, 10, 100), (10, 10, 5000)] {
        let x = mixture(sources, sensors, samples, 7);
        for algorithm in [Algorithm::Symmetric, Algorithm::Deflation] {
            let ica = FastIca::new(FastIcaConfig {
                algorithm,
                components: Components::Fixed(sources),
                ..FastIcaConfig::default()
            });
            let id = BenchmarkId::new(
                algorithm.to_string(),
                format!("{sources}x{sensors}x{samples}"),
            );
            group.bench_with_input(id, &x, |b, x| {
                b.iter(|| match ica.fit(black_box(x)) {
                    Ok(r) => r.iterations,
                    // A capped run still did the work being measured.
                    Err(FastIcaError::NotConverged { iterations, .. }) => iterations,
                    Err(e) => panic!("{e}"),
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
