//! The speed targets of the engine issue, on the Table III workload of the
//! paper (n = 100, k = 50, 1000 events of which half are mixing):
//! - the overcomplete method (OMP + thresholding) with a budget of 500
//!   coefficients, single-threaded — the paper took 1342 s; goal < 0.5 s;
//! - the exact dense filter on n = 20, k = 10 (184,756 k-sets), 1000 events
//!   — goal < 1 s.
//!
//! The first-order Radon baseline runs in the same process as the yardstick
//! the figures are reported against (the machine is noisy; ratios are not).
//!
//! Run: `cargo bench -p idmesh-belief --bench table3`.

use criterion::{criterion_group, criterion_main, BatchSize, Criterion};
use idmesh_belief::workload::{generate, Workload, WorkloadSpec};
use idmesh_belief::{DenseFilter, LowOrderFilter, LowOrderRepair};
use idmesh_belief::{Field, PropertyFilter, RadonBelief, RadonOptions, Sparsify};
use std::time::Duration;

fn replay(filter: &mut dyn PropertyFilter, workload: &Workload) -> usize {
    for event in &workload.events {
        filter.apply(event).expect("the workload is valid");
    }
    filter.coefficients()
}

fn radon(field: Field, sparsify: Sparsify) -> RadonBelief {
    let options = RadonOptions {
        sparsify: Some(sparsify),
        ..RadonOptions::default()
    };
    RadonBelief::with_options(field, options).expect("valid field")
}

fn table3(c: &mut Criterion) {
    let workload = generate(&WorkloadSpec::table3(100, 1));
    let known = Field::known(100, workload.initial_red.clone());
    let uniform = Field::uniform(100, 50);
    let mut group = c.benchmark_group("table3_n100_k50_1000_events");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(8));
    group.bench_function("order1_baseline", |b| {
        b.iter_batched(
            || {
                LowOrderFilter::with_repair(known.clone(), 1, LowOrderRepair::ShrinkToUniform)
                    .expect("valid")
            },
            |mut f| replay(&mut f, &workload),
            BatchSize::LargeInput,
        )
    });
    for (name, field) in [("known_start", &known), ("uniform_prior", &uniform)] {
        group.bench_function(format!("overcomplete_budget500_{name}"), |b| {
            b.iter_batched(
                || radon(field.clone(), Sparsify::overcomplete(500)),
                |mut f| replay(&mut f, &workload),
                BatchSize::LargeInput,
            )
        });
        group.bench_function(format!("threshold_budget500_{name}"), |b| {
            b.iter_batched(
                || radon(field.clone(), Sparsify::threshold(500)),
                |mut f| replay(&mut f, &workload),
                BatchSize::LargeInput,
            )
        });
    }
    group.finish();
}

fn exact_dense(c: &mut Criterion) {
    let workload = generate(&WorkloadSpec::table3(20, 1));
    let field = Field::uniform(20, 10);
    let mut group = c.benchmark_group("exact_dense_n20_k10_1000_events");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10));
    group.bench_function("order1_baseline", |b| {
        b.iter_batched(
            || {
                LowOrderFilter::with_repair(field.clone(), 1, LowOrderRepair::ShrinkToUniform)
                    .expect("valid")
            },
            |mut f| replay(&mut f, &workload),
            BatchSize::LargeInput,
        )
    });
    group.bench_function("exact_dense", |b| {
        b.iter_batched(
            || DenseFilter::new(field.clone()).expect("fits"),
            |mut f| replay(&mut f, &workload),
            BatchSize::LargeInput,
        )
    });
    group.finish();
}

criterion_group!(benches, table3, exact_dense);
criterion_main!(benches);
