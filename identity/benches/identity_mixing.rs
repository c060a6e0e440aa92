//! The speed of information-matrix mixing ("Speed"): one mix of
//! two tracks of an N × N information matrix, N = 100 and N = 1000, by the
//! O(N²) closed forms against the pseudoinverse rule of Shin et al. (IPSN
//! 2005, Section 3.3: β = P†γ with P the C(N,2) × N pair matrix, "O(N⁴)").
//!
//! Measured with criterion:
//! - `closed_form/mix/N` — `InformationMatrix::mix` with the default
//!   solver (the two-row least-squares fit, closed form), swap ½;
//! - `closed_form/paper_merge/N` — the paper's merged row by its closed
//!   form (`paper_merge`);
//! - `pseudoinverse/paper_merge_pinv/100` — the paper's rule as written,
//!   the SVD pseudoinverse of the 4950 × 100 pair matrix;
//! - `pseudoinverse/mix/100` — `InformationMatrix::mix` with
//!   `MixSolver::PseudoInverse` (the 9900 × 200 two-row design).
//!
//! The pseudoinverse at N = 1000 is not run: P alone is 499,500 × 1000
//! (4.0 GB; the two-row design 16 GB) and its SVD takes hours. After the
//! criterion groups the bench times both rules itself in the same process
//! and prints the ratios: measured at N = 100, and at N = 1000 against the
//! pseudoinverse time extrapolated from N = 25, 50, 100 by a power-law fit
//! (marked as such).
//!
//! Run: `cargo bench -p idmesh-identity --bench identity_mixing` (about two
//! minutes; `-- closed_form` for the fast half only).

use criterion::{BenchmarkId, Criterion};
use idmesh_belief::Mix;
use idmesh_identity::{paper_merge, paper_merge_pinv, InformationOptions, MixSolver};
use idmesh_identity::{IdentityFilter, InformationMatrix};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::hint::black_box;
use std::time::{Duration, Instant};

/// An N × N information matrix with seeded entries in [−5, 5]: the cost of
/// a mix does not depend on the values.
fn log_likelihoods(n: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| (0..n).map(|_| rng.gen_range(-5.0..5.0)).collect())
        .collect()
}

/// Mixes tracks (k, k + 1), k = 0, 1, 2, … in turn, in place: every call
/// is one mix of a full-size matrix.
fn mixer(n: usize, solver: MixSolver) -> impl FnMut() {
    let options = InformationOptions {
        solver,
        ..InformationOptions::default()
    };
    let mut info = InformationMatrix::from_log_likelihoods(&log_likelihoods(n, n as u64), options)
        .expect("finite entries");
    let mut k = 0usize;
    move || {
        let a = (k % (n - 1)) as u32;
        k += 1;
        info.mix(Mix {
            a,
            b: a + 1,
            swap: 0.5,
        })
        .expect("a valid mix");
        black_box(&info);
    }
}

/// Two seeded rows of length `n` (the rows of the two mixing tracks).
fn rows(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut rng = ChaCha8Rng::seed_from_u64(n as u64 + 1);
    let mut row = || (0..n).map(|_| rng.gen_range(-5.0..5.0)).collect();
    (row(), row())
}

fn closed_form(c: &mut Criterion) {
    let mut group = c.benchmark_group("closed_form");
    group
        .sample_size(20)
        .measurement_time(Duration::from_secs(3));
    for n in [100usize, 1000] {
        group.bench_with_input(BenchmarkId::new("mix", n), &n, |b, &n| {
            let mut mix = mixer(n, MixSolver::ClosedForm);
            b.iter(&mut mix)
        });
        let (a, r) = rows(n);
        group.bench_with_input(BenchmarkId::new("paper_merge", n), &n, |b, _| {
            b.iter(|| paper_merge(black_box(&a), black_box(&r)).expect("finite rows"))
        });
    }
    group.finish();
}

fn pseudoinverse(c: &mut Criterion) {
    let mut group = c.benchmark_group("pseudoinverse");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(5));
    let n = 100usize;
    let (a, r) = rows(n);
    group.bench_with_input(BenchmarkId::new("paper_merge_pinv", n), &n, |b, _| {
        b.iter(|| paper_merge_pinv(black_box(&a), black_box(&r)).expect("finite rows"))
    });
    group.bench_with_input(BenchmarkId::new("mix", n), &n, |b, &n| {
        let mut mix = mixer(n, MixSolver::PseudoInverse);
        b.iter(&mut mix)
    });
    group.finish();
}

/// The median of `reps` timings of `f`, in seconds.
fn median_seconds(reps: usize, mut f: impl FnMut()) -> f64 {
    let mut times: Vec<f64> = (0..reps)
        .map(|_| {
            let clock = Instant::now();
            f();
            clock.elapsed().as_secs_f64()
        })
        .collect();
    times.sort_by(|x, y| x.partial_cmp(y).expect("finite times"));
    times[reps / 2]
}

/// Least-squares fit of ln t = ln c + k ln N; returns (c, k).
fn power_law(points: &[(f64, f64)]) -> (f64, f64) {
    let m = points.len() as f64;
    let mx = points.iter().map(|&(n, _)| n.ln()).sum::<f64>() / m;
    let my = points.iter().map(|&(_, t)| t.ln()).sum::<f64>() / m;
    let sxy: f64 = points
        .iter()
        .map(|&(n, t)| (n.ln() - mx) * (t.ln() - my))
        .sum();
    let sxx: f64 = points.iter().map(|&(n, _)| (n.ln() - mx).powi(2)).sum();
    let k = sxy / sxx;
    ((my - k * mx).exp(), k)
}

/// Both rules timed in this process; the ratios printed.
fn ratios(quick: bool) {
    let reps = if quick { 1 } else { 5 };
    println!();
    println!("identity mixing, one mix of two tracks (median of {reps} or more timings):");
    // The paper's rule β = P†γ at sizes it can be run at.
    let mut fit = Vec::new();
    for n in [25usize, 50, 100] {
        let (a, r) = rows(n);
        let pinv = median_seconds(reps, || {
            black_box(paper_merge_pinv(&a, &r).expect("finite rows"));
        });
        fit.push((n as f64, pinv));
    }
    let (scale, exponent) = power_law(&fit);
    println!("  pseudoinverse rule ~ {scale:.3e} s · N^{exponent:.2} (fit on N = 25, 50, 100)");
    println!(
        "  {:>5} | {:>14} | {:>14} | {:>27} | {:>12} | {:>10}",
        "N", "paper, closed", "mix, closed", "paper, pseudoinverse", "pinv/closed", "pinv/mix"
    );
    for n in [100usize, 1000] {
        let (a, r) = rows(n);
        let inner = if n >= 1000 { 20 } else { 200 };
        let closed = median_seconds(reps.max(3), || {
            for _ in 0..inner {
                black_box(paper_merge(&a, &r).expect("finite rows"));
            }
        }) / inner as f64;
        let mut mix = mixer(n, MixSolver::ClosedForm);
        let mix_time = median_seconds(reps.max(3), || {
            for _ in 0..inner {
                mix();
            }
        }) / inner as f64;
        let (pinv, how) = match fit.iter().find(|&&(m, _)| m == n as f64) {
            Some(&(_, t)) => (t, "measured"),
            None => (scale * (n as f64).powf(exponent), "extrapolated"),
        };
        println!(
            "  {n:>5} | {:>11.3} ms | {:>11.3} ms | {:>10.3e} s {how:>12} | {:>11.0}x | {:>9.0}x",
            closed * 1e3,
            mix_time * 1e3,
            pinv,
            pinv / closed,
            pinv / mix_time
        );
    }
}

fn main() {
    let mut c = Criterion::default().configure_from_args();
    closed_form(&mut c);
    pseudoinverse(&mut c);
    c.final_summary();
    // `cargo bench -- --test` (or `cargo test --benches`) runs everything
    // once: keep the ratio table quick there too.
    let quick = std::env::args().any(|a| a == "--test");
    ratios(quick);
}
