//! Identities at scale (issue 21): the time of one identity query — all
//! marginals and the most likely assignment — and its identity error, at
//! n = 100, 500, 1,000 and 10,000, for every marginal method of the
//! information matrix.
//!
//! The stream: a known start, then n events, half mixes of tracks at most
//! 3 apart (swap ½: people who met), half reads of accuracy 0.9
//! (`IdentityWorkloadSpec`, seed n). The known start is exact (−∞ entries),
//! so the mixing graph splits the tracks into independent blocks
//! (`belief::identity::blocks`) and every method answers block by block.
//!
//! First the bench prints, measured in this process, one line per n and
//! method: the query time (median of 3), the identity error of the answer
//! against the true assignment, the largest block, or the error that
//! refused the query; and, at n = 100, the belief matrix's whole-stream
//! time (it renormalizes all n² entries at every read: 141 s for the
//! n = 500 stream in a first run, so larger sizes are left out). Then criterion measures the query times.
//!
//! Run: `cargo bench -p idmesh-belief --bench identity_scale` (a few
//! minutes; `-- 10000` for one size).

use criterion::{BenchmarkId, Criterion};
use idmesh_belief::identity::workload::generate_final;
use idmesh_belief::identity::{
    identity_error, BeliefMatrix, IdentityEvent, IdentityFilter, IdentityWorkloadSpec,
    InformationMatrix, MarginalMethod,
};
use std::hint::black_box;
use std::time::{Duration, Instant};

const SIZES: [usize; 4] = [100, 500, 1_000, 10_000];

fn spec(n: usize) -> IdentityWorkloadSpec {
    IdentityWorkloadSpec {
        tracks: n,
        events: n,
        mix_share: 0.5,
        swap: 0.5,
        accuracy: 0.9,
        neighbourhood: 3,
        seed: n as u64,
    }
}

fn methods() -> Vec<MarginalMethod> {
    vec![
        MarginalMethod::Auto,
        MarginalMethod::Exact,
        MarginalMethod::half_bethe(),
        MarginalMethod::Sinkhorn,
        MarginalMethod::Metropolis {
            samples: 10_000,
            burn_in: 1_000,
            seed: 1,
        },
    ]
}

/// The information matrix after the stream, and the true assignment.
fn stream(n: usize) -> (InformationMatrix, Vec<u32>, Vec<u32>, Vec<IdentityEvent>) {
    let (initial, events, truth) = generate_final(&spec(n)).expect("valid spec");
    let mut info = InformationMatrix::from_assignment(&initial, f64::INFINITY, Default::default())
        .expect("a permutation");
    for e in &events {
        info.apply(e).expect("the stream applies");
    }
    (info, truth, initial, events)
}

fn report() {
    println!("n | method | query seconds (median of 3) | identity error | largest block");
    for n in SIZES {
        let (info, truth, initial, events) = stream(n);
        for method in methods() {
            let mut times = Vec::new();
            let mut answer = None;
            for _ in 0..3 {
                let clock = Instant::now();
                let got = info
                    .block_marginals(&method)
                    .and_then(|m| m.most_likely().map(|best| (best, m.largest_block())));
                times.push(clock.elapsed().as_secs_f64());
                answer = Some(got);
            }
            times.sort_by(f64::total_cmp);
            match answer.expect("three runs") {
                Ok((best, largest)) => println!(
                    "{n} | {} | {:.4} | {:.4} | {largest}",
                    method.name(),
                    times[1],
                    identity_error(&best, &truth)
                ),
                Err(e) => println!("{n} | {} | refused: {e}", method.name()),
            }
        }
        if n <= 100 {
            let clock = Instant::now();
            let mut bm = BeliefMatrix::from_assignment(&initial).expect("a permutation");
            let ok = events.iter().all(|e| bm.apply(e).is_ok());
            let seconds = clock.elapsed().as_secs_f64();
            let error = bm
                .most_likely()
                .map(|best| identity_error(&best, &truth))
                .unwrap_or(f64::NAN);
            println!(
                "{n} | belief matrix (whole stream{}) | {seconds:.3} | {error:.4} | -",
                if ok { "" } else { ", FAILED" }
            );
        }
    }
}

fn bench(c: &mut Criterion) {
    for n in SIZES {
        let (info, ..) = stream(n);
        let mut group = c.benchmark_group(format!("query/{n}"));
        group.sample_size(10);
        group.measurement_time(Duration::from_secs(if n >= 10_000 { 20 } else { 5 }));
        for method in methods() {
            if info.block_marginals(&method).is_err() {
                continue;
            }
            group.bench_function(BenchmarkId::from_parameter(method.name()), |b| {
                b.iter(|| {
                    let m = info.block_marginals(black_box(&method)).expect("answers");
                    black_box(m.most_likely().expect("an assignment"))
                })
            });
        }
        group.finish();
    }
}

fn main() {
    report();
    let mut criterion = Criterion::default().configure_from_args();
    bench(&mut criterion);
    criterion.final_summary();
}
