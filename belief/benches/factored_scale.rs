//! The factored belief at city scale (issue: no global work per event): the
//! cost of one event and of one query (all n marginals, right after an
//! event) at n = 100, 1,000, 10,000 and 100,000 tracks, k = n/2, in crowds
//! of the same density (mixes pair tracks at most 4 apart, the Table III
//! workload's neighbourhood), after a warm-up of 2n events so that every
//! track has mixed and been seen a few times; under both split rules (the
//! query is the same code under both, on the beliefs each rule leaves).
//!
//! Goals: per-event cost flat in n (within 2× from n = 100 to 100,000) and a
//! query at n = 100,000 under 100 ms on one core. The n = 100 figures are
//! the baseline the others are read against (the machine is noisy; ratios
//! measured in one run are not).
//!
//! Run: `cargo bench -p idmesh-belief --bench factored_scale`.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use idmesh_belief::workload::{generate_with, WorkloadSpec};
use idmesh_belief::{Coupling, Event, FactoredBelief, FactoredOptions, Field, PropertyFilter};
use std::time::{Duration, Instant};

const SIZES: [usize; 4] = [100, 1_000, 10_000, 100_000];

/// A warmed-up belief and the events that follow its warm-up.
fn warmed(n: usize, coupling: Coupling) -> (FactoredBelief, Vec<Event>) {
    // No truth lines: a list of k tracks per event would not fit at 100,000.
    let spec = WorkloadSpec {
        events: 2 * n + 20_000,
        ..WorkloadSpec::table3(n, 7)
    };
    let work = generate_with(&spec, usize::MAX);
    let options = FactoredOptions {
        coupling,
        ..FactoredOptions::default()
    };
    let field = Field::known(n, work.initial_red.clone());
    let mut belief = FactoredBelief::with_options(field, options).expect("valid field");
    let (warm, rest) = work.events.split_at(2 * n);
    for e in warm {
        let _ = belief.apply(e);
    }
    belief.marginals().expect("a belief");
    (belief, rest.to_vec())
}

fn scale(c: &mut Criterion) {
    let mut group = c.benchmark_group("factored_scale");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3));
    for n in SIZES {
        for (name, coupling) in [("local", Coupling::Local), ("coupled", Coupling::Coupled)] {
            let (mut belief, events) = warmed(n, coupling);
            let mut next = 0usize;
            group.bench_function(BenchmarkId::new(format!("event_{name}"), n), |b| {
                b.iter_custom(|iters| {
                    let start = Instant::now();
                    for _ in 0..iters {
                        let _ = belief.apply(&events[next % events.len()]);
                        next += 1;
                    }
                    start.elapsed()
                })
            });
            group.bench_function(BenchmarkId::new(format!("query_{name}"), n), |b| {
                b.iter_custom(|iters| {
                    let mut spent = Duration::ZERO;
                    for _ in 0..iters {
                        let _ = belief.apply(&events[next % events.len()]);
                        next += 1;
                        let start = Instant::now();
                        let m = belief.marginals().expect("a belief");
                        spent += start.elapsed();
                        std::hint::black_box(m);
                    }
                    spent
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, scale);
criterion_main!(benches);
