//! Identities at scale: the time of one identity query — all
//! marginals and the most likely assignment — and its identity error, at
//! n = 100, 500, 1,000 and 10,000, for every marginal method of the
//! information matrix.
//!
//! The stream: a known start, then n events, half mixes of tracks at most
//! 3 apart (swap ½: people who met), half reads of accuracy 0.9
//! (`IdentityWorkloadSpec`, seed n). The known start is exact (−∞ entries),
//! so the mixing graph splits the tracks into independent blocks
//! (`idmesh_identity::blocks`) and every method answers block by block.
//!
//! A second stream, `crowd`, is what 20 s of the simulated crowd of the
//! process test does (`idmesh simulate --model crowd --identities`, 1,000
//! targets: 1,624 mixes, 1,726 reads, one block of 901 tracks): 3.3·n
//! events, half mixes of *any* two tracks, so the mixing graph percolates
//! into one block of most tracks — sparse (a track can carry only the
//! identities that reached it through mixes in time order), but far beyond
//! exact marginals.
//!
//! First the bench prints, measured in this process, one line per n and
//! method: the query time (median of 3), the identity error of the answer
//! against the true assignment, the largest block, or the error that
//! refused the query; and, at n = 100, the belief matrix's whole-stream
//! time (it renormalizes all n² entries at every read: 141 s for the
//! n = 500 stream in a first run, so larger sizes are left out). Then criterion measures the query times.
//!
//! The machine these run on is shared and noisy, so every line also gives
//! the query time as a ratio to a baseline measured in the same process
//! right before it: one read of every entry of the dense n × n matrix
//! (`scan`, what any query must do at least once while the matrix is
//! stored densely). A ratio moves much less than a time when other builds
//! take the cores.
//!
//! Run: `cargo bench -p idmesh-identity --bench identity_scale` (a few
//! minutes; `-- 10000` for one size).

use criterion::{BenchmarkId, Criterion};
use idmesh_identity::workload::{generate_final, IdentityWorkloadSpec};
use idmesh_identity::{
    identity_error, BeliefMatrix, IdentityEvent, IdentityFilter, InformationMatrix, MarginalMethod,
};
use std::hint::black_box;
use std::time::{Duration, Instant};

const SIZES: [usize; 4] = [100, 500, 1_000, 10_000];

/// Which stream.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    /// n events, mixes of tracks at most 3 apart: small blocks.
    Local,
    /// 3.3·n events, mixes of any two tracks: one block of most tracks.
    Crowd,
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::Local => "local",
            Kind::Crowd => "crowd",
        }
    }
}

fn spec(n: usize, kind: Kind) -> IdentityWorkloadSpec {
    let (events, neighbourhood) = match kind {
        Kind::Local => (n, 3),
        Kind::Crowd => (n * 33 / 10, n),
    };
    IdentityWorkloadSpec {
        tracks: n,
        events,
        mix_share: 0.5,
        swap: 0.5,
        accuracy: 0.9,
        neighbourhood,
        seed: n as u64,
    }
}

/// The sizes and streams to run: all but `crowd/10000`, or those whose
/// `n` or `kind/n` is named on the command line (`-- 1000`,
/// `-- crowd/1000`). `crowd/10000` runs only when named so: its one block
/// of 9,590 tracks takes seconds a query (it took about 2 minutes while the
/// most likely assignment and Metropolis's start were dense Hungarian runs,
/// O(k³)), and criterion would take it 10 times more.
fn runs() -> Vec<(Kind, usize)> {
    let named: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| a.starts_with(|c: char| c.is_ascii_digit()) || a.contains('/'))
        .collect();
    [Kind::Local, Kind::Crowd]
        .into_iter()
        .flat_map(|kind| SIZES.map(|n| (kind, n)))
        .filter(|(kind, n)| {
            let slow = (*kind, *n) == (Kind::Crowd, 10_000);
            let by_size = |a: &String| !slow && *a == n.to_string();
            (named.is_empty() && !slow)
                || named
                    .iter()
                    .any(|a| by_size(a) || *a == format!("{}/{n}", kind.name()))
        })
        .collect()
}

/// Every marginal method, or those named on the command line (`-- sinkhorn`).
fn methods() -> Vec<MarginalMethod> {
    let all = vec![
        MarginalMethod::Auto,
        MarginalMethod::Exact,
        MarginalMethod::half_bethe(),
        MarginalMethod::Sinkhorn,
        MarginalMethod::Metropolis {
            samples: 10_000,
            burn_in: 1_000,
            seed: 1,
        },
    ];
    let named: Vec<String> = std::env::args().skip(1).collect();
    if all.iter().any(|m| named.iter().any(|a| a == m.name())) {
        all.into_iter()
            .filter(|m| named.iter().any(|a| a == m.name()))
            .collect()
    } else {
        all
    }
}

/// The information matrix after the stream, and the true assignment.
fn stream(n: usize, kind: Kind) -> (InformationMatrix, Vec<u32>, Vec<u32>, Vec<IdentityEvent>) {
    let (initial, events, truth) = generate_final(&spec(n, kind)).expect("valid spec");
    let mut info = InformationMatrix::from_assignment(&initial, f64::INFINITY, Default::default())
        .expect("a permutation");
    for e in &events {
        info.apply(e).expect("the stream applies");
    }
    (info, truth, initial, events)
}

/// The baseline: one read of every entry of the n × n matrix (how many are
/// finite, i.e. possible).
fn scan(info: &InformationMatrix) -> usize {
    info.entries()
        .iter()
        .filter(|&&x| x > f64::NEG_INFINITY)
        .count()
}

/// The median of three timings of `f`, in seconds.
fn median_of_3<T>(mut f: impl FnMut() -> T) -> (f64, T) {
    let mut times = Vec::new();
    let mut last = None;
    for _ in 0..3 {
        let clock = Instant::now();
        last = Some(black_box(f()));
        times.push(clock.elapsed().as_secs_f64());
    }
    times.sort_by(f64::total_cmp);
    (times[1], last.expect("three runs"))
}

fn report() {
    println!(
        "stream | n | method | query seconds (median of 3) | ratio to scan | identity error | largest block"
    );
    for (kind, n) in runs() {
        let (info, truth, initial, events) = stream(n, kind);
        let kind = kind.name();
        for method in methods() {
            let (baseline, _) = median_of_3(|| scan(&info));
            let (seconds, answer) = median_of_3(|| {
                info.block_marginals(&method)
                    .and_then(|m| m.most_likely().map(|best| (best, m.largest_block())))
            });
            match answer {
                Ok((best, largest)) => println!(
                    "{kind} | {n} | {} | {seconds:.4} | {:.1} | {:.4} | {largest}",
                    method.name(),
                    seconds / baseline,
                    identity_error(&best, &truth)
                ),
                Err(e) => println!("{kind} | {n} | {} | refused: {e}", method.name()),
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
                "{kind} | {n} | belief matrix (whole stream{}) | {seconds:.3} | - | {error:.4} | -",
                if ok { "" } else { ", FAILED" }
            );
        }
    }
}

fn bench(c: &mut Criterion) {
    for (kind, n) in runs() {
        let (info, ..) = stream(n, kind);
        let mut group = c.benchmark_group(match kind {
            Kind::Local => format!("query/{n}"),
            Kind::Crowd => format!("query/crowd/{n}"),
        });
        group.sample_size(10);
        group.measurement_time(Duration::from_secs(if n >= 10_000 { 20 } else { 5 }));
        group.bench_function(BenchmarkId::from_parameter("scan"), |b| {
            b.iter(|| scan(black_box(&info)))
        });
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
