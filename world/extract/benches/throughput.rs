//! How many reports one sensor extracts per second: crowds of 1,000 and
//! 10,000 tracks walking at 1.3 m/s on a field of 10 m² per person,
//! reported at 10 frames per second, a third of the reports with class
//! scores. The goal is 10,000 tracks at 10 frames/s on one core: a frame
//! (10,000 reports) extracted in under 100 ms. The 1,000-track figure is
//! the baseline the other is read against (per report, the cost should
//! not grow with the crowd: the neighbour grid keeps each frame linear).
//!
//! Run: `cargo bench -p idmesh-extract --bench throughput`.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use idmesh_extract::{Extractor, ExtractorConfig, Report, RosterPolicy};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

const FPS: f64 = 10.0;
const SPEED: f64 = 1.3;

/// `frames` frames of `n` walkers bouncing off the walls of a square field
/// of 10 m² each.
fn crowd(n: usize, frames: usize) -> Vec<Vec<Report>> {
    let mut rng = ChaCha8Rng::seed_from_u64(n as u64);
    let side = (10.0 * n as f64).sqrt();
    let mut walkers: Vec<(f64, f64, f64, f64)> = (0..n)
        .map(|_| {
            let heading: f64 = rng.gen_range(0.0..std::f64::consts::TAU);
            let (x, y) = (rng.gen_range(0.0..side), rng.gen_range(0.0..side));
            (x, y, SPEED * heading.cos(), SPEED * heading.sin())
        })
        .collect();
    (0..frames)
        .map(|f| {
            let time = f as f64 / FPS;
            walkers
                .iter_mut()
                .enumerate()
                .map(|(track, w)| {
                    for (p, v) in [(&mut w.0, &mut w.2), (&mut w.1, &mut w.3)] {
                        *p += *v / FPS;
                        if !(0.0..=side).contains(p) {
                            *v = -*v;
                            *p = p.clamp(0.0, side);
                        }
                    }
                    let mut report = Report::at(time, track as u32, w.0, w.1);
                    if (track + f) % 3 == 0 {
                        let red = if track % 2 == 0 { 0.8 } else { 0.3 };
                        let scores: BTreeMap<String, f64> =
                            [("red".to_string(), red), ("blue".to_string(), 1.0 - red)].into();
                        report.scores = Some(scores);
                    }
                    report
                })
                .collect()
        })
        .collect()
}

fn throughput(c: &mut Criterion) {
    let mut group = c.benchmark_group("extract a frame");
    group.sample_size(10);
    for n in [1_000usize, 10_000] {
        // A warm-up of 20 frames (meetings open, observations scheduled),
        // then the frames measured.
        let frames = crowd(n, 60);
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::from_parameter(n), &frames, |b, frames| {
            b.iter_custom(|iterations| {
                let mut spent = Duration::ZERO;
                for _ in 0..iterations {
                    let roster = RosterPolicy::Declared((0..n as u32).collect());
                    let mut extractor =
                        Extractor::new(ExtractorConfig::default(), roster).expect("settings");
                    let mut out = Vec::new();
                    for frame in &frames[..20] {
                        for report in frame {
                            extractor
                                .push(report.clone(), &mut out)
                                .expect("a good report");
                        }
                    }
                    out.clear();
                    let started = Instant::now();
                    for frame in &frames[20..] {
                        for report in frame {
                            extractor
                                .push(report.clone(), &mut out)
                                .expect("a good report");
                        }
                    }
                    spent += started.elapsed() / (frames.len() - 20) as u32;
                    std::hint::black_box(&out);
                }
                spent
            })
        });
    }
    group.finish();
}

criterion_group!(benches, throughput);
criterion_main!(benches);
