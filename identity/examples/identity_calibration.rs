//! Calibration of the identity engine (docs/design/identity.md,
//! "Calibration"): which known-start encoding and which evidence weight
//! make the information matrix's probabilities trustworthy, and how every
//! marginal method then scores.
//!
//! The streams are *held-out-like*: seeded workloads (seeds from 10,000 on,
//! which no test uses) with a known start, reads of accuracy 0.9 and mixes
//! of nearby tracks (swap ½), at several shares of mixes. No trace of the
//! test suite or of docs/results.md is used.
//!
//! - n ≤ 9: mean and max |Δp| against the exact filter over all n!
//!   assignments, every 10 events.
//! - n = 30, 100: Brier score (Σ_i (p_ti − 1{truth})², mean over tracks)
//!   and log-loss (−ln p of the true identity, floored at 1e-12) against
//!   the truth, every 10 events.
//!
//! An evidence weight w multiplies each read's log-odds by w; it is the
//! read model of a different accuracy, so the filters take it as such.
//!
//!     cargo run --release -p idmesh-identity --example identity_calibration [encoding|methods|large]
//!
//! A whole run (no argument) writes docs/identity-calibration.md, stamped
//! with the digest of the identity engine's sources and this program; a
//! run of one part only prints.

use idmesh_identity::workload::{generate, IdentityWorkloadSpec};
use idmesh_identity::{
    BeliefMatrix, ExactPermutationFilter, Identify, IdentityEvent, IdentityFilter,
    InformationMatrix, InformationOptions, MarginalMethod,
};
use std::time::Instant;

/// Everything the program prints also goes into the document it writes
/// (docs/identity-calibration.md), so that the page's numbers are the
/// program's.
static DOC: std::sync::Mutex<String> = std::sync::Mutex::new(String::new());

macro_rules! out {
    ($($t:tt)*) => {{
        let text = format!($($t)*);
        print!("{text}");
        DOC.lock().unwrap_or_else(|e| e.into_inner()).push_str(&text);
    }};
}

macro_rules! outln {
    () => { out!("\n") };
    ($($t:tt)*) => {{ out!($($t)*); out!("\n"); }};
}

const SEED0: u64 = 10_000;
const EVERY: usize = 10;

fn spec(
    n: usize,
    events: usize,
    mix_share: f64,
    neighbourhood: usize,
    seed: u64,
) -> IdentityWorkloadSpec {
    IdentityWorkloadSpec {
        tracks: n,
        events,
        mix_share,
        swap: 0.5,
        accuracy: 0.9,
        neighbourhood,
        seed,
    }
}

/// The read with its log-odds multiplied by `weight`.
fn weighted(read: Identify, n: usize, weight: f64) -> Identify {
    if weight == 1.0 {
        return read;
    }
    let odds = (weight * read.log_odds(n)).exp() / (n as f64 - 1.0);
    Identify {
        accuracy: odds / (1.0 + odds),
        ..read
    }
}

/// A filter factory: from the known start.
type Make = Box<dyn Fn(&[u32]) -> Box<dyn IdentityFilter>>;

fn info(confidence: f64, method: MarginalMethod) -> Make {
    Box::new(move |start: &[u32]| {
        let options = InformationOptions {
            marginals: method,
            ..InformationOptions::default()
        };
        Box::new(InformationMatrix::from_assignment(start, confidence, options).unwrap())
            as Box<dyn IdentityFilter>
    })
}

fn belief_matrix() -> Make {
    Box::new(|start: &[u32]| Box::new(BeliefMatrix::from_assignment(start).unwrap()) as _)
}

/// The streams of the small-n calibration.
fn small_streams(seeds: u64) -> Vec<IdentityWorkloadSpec> {
    let mut out = Vec::new();
    for n in 4..=9 {
        for (k, mix_share) in [0.25, 0.5, 0.75].into_iter().enumerate() {
            for neighbourhood in [2, n] {
                for s in 0..seeds {
                    let seed =
                        SEED0 + 1000 * n as u64 + 100 * k as u64 + 10 * neighbourhood as u64 + s;
                    out.push(spec(n, 40, mix_share, neighbourhood, seed));
                }
            }
        }
    }
    out
}

/// The exact marginals every EVERY events of each stream.
fn exact_answers(streams: &[IdentityWorkloadSpec]) -> Vec<Vec<Vec<Vec<f64>>>> {
    streams
        .iter()
        .map(|s| {
            let w = generate(s).unwrap();
            let mut exact = ExactPermutationFilter::from_assignment(&w.initial).unwrap();
            let mut out = Vec::new();
            for (k, e) in w.events.iter().enumerate() {
                exact.apply(e).unwrap();
                if (k + 1) % EVERY == 0 {
                    out.push(exact.marginals().unwrap());
                }
            }
            out
        })
        .collect()
}

/// (mean |Δp|, max |Δp|, failures) of `make` with evidence weight `weight`.
fn against_exact(
    streams: &[IdentityWorkloadSpec],
    exact: &[Vec<Vec<Vec<f64>>>],
    make: &Make,
    weight: f64,
) -> (f64, f64, usize) {
    let (mut sum, mut count, mut worst, mut failures) = (0.0, 0usize, 0.0f64, 0);
    for (s, answers) in streams.iter().zip(exact) {
        let w = generate(s).unwrap();
        let n = s.tracks;
        let mut filter = make(&w.initial);
        let mut q = 0;
        for (k, e) in w.events.iter().enumerate() {
            let e = match *e {
                IdentityEvent::Identify(r) => IdentityEvent::Identify(weighted(r, n, weight)),
                m => m,
            };
            if filter.apply(&e).is_err() {
                failures += 1;
                break;
            }
            if (k + 1) % EVERY == 0 {
                match filter.marginals() {
                    Ok(p) => {
                        for (x, y) in p.iter().flatten().zip(answers[q].iter().flatten()) {
                            let d = (x - y).abs();
                            if d > 0.9 && std::env::var_os("WORST").is_some() {
                                eprintln!(
                                    "{s:?} after {} events: {p:?} vs {:?}",
                                    k + 1,
                                    answers[q]
                                );
                            }
                            sum += d;
                            count += 1;
                            worst = worst.max(d);
                        }
                    }
                    Err(_) => failures += 1,
                }
                q += 1;
            }
        }
    }
    (sum / count.max(1) as f64, worst, failures)
}

fn fmt_c(c: f64) -> String {
    if c.is_infinite() {
        "∞ (exact)".into()
    } else {
        format!("{c}")
    }
}

fn encoding() -> (f64, f64) {
    let streams = small_streams(8);
    let clock = Instant::now();
    let exact = exact_answers(&streams);
    eprintln!(
        "{} streams, exact answers in {:.1} s",
        streams.len(),
        clock.elapsed().as_secs_f64()
    );
    let (bm, bm_max, _) = against_exact(&streams, &exact, &belief_matrix(), 1.0);
    outln!("### Known-start encoding and evidence weight (n = 4..9, information matrix, exact marginals)\n");
    outln!("belief matrix for comparison: mean |Δp| {bm:.4}, max {bm_max:.3}\n");
    outln!("| known-start log-odds c | evidence weight w | mean abs Δp | max abs Δp |");
    outln!("|---|---|---|---|");
    let mut best = (f64::INFINITY, 0.0, 0.0);
    for c in [1.0, 2.0, 3.0, 5.0, 10.0, 20.0, f64::INFINITY] {
        for w in [0.5, 0.7, 0.85, 1.0] {
            let (mean, max, failures) =
                against_exact(&streams, &exact, &info(c, MarginalMethod::Exact), w);
            let note = if failures > 0 {
                format!(" ({failures} failures)")
            } else {
                String::new()
            };
            outln!("| {} | {w} | {mean:.4} | {max:.3}{note} |", fmt_c(c));
            if mean < best.0 {
                best = (mean, c, w);
            }
        }
    }
    outln!(
        "\nbest: c = {}, w = {} (mean |Δp| {:.4})\n",
        fmt_c(best.1),
        best.2,
        best.0
    );
    (best.1, best.2)
}

fn methods(c: f64, w: f64) {
    let streams = small_streams(8);
    let exact = exact_answers(&streams);
    outln!(
        "### Every method against exact S_N (n = 4..9, c = {}, w = {w})\n",
        fmt_c(c)
    );
    outln!("| method | mean abs Δp | max abs Δp |");
    outln!("|---|---|---|");
    let metropolis = MarginalMethod::Metropolis {
        samples: 10_000,
        burn_in: 1_000,
        seed: 1,
    };
    let rows: Vec<(&str, Make, f64)> = vec![
        ("belief matrix", belief_matrix(), 1.0),
        (
            "information matrix, c = 20, w = 1 (before)",
            info(20.0, MarginalMethod::Exact),
            1.0,
        ),
        ("information, exact", info(c, MarginalMethod::Exact), w),
        ("information, auto", info(c, MarginalMethod::Auto), w),
        ("information, Metropolis 10^4", info(c, metropolis), w),
        (
            "information, Sinkhorn",
            info(c, MarginalMethod::Sinkhorn),
            w,
        ),
        (
            "information, half-Bethe",
            info(c, MarginalMethod::half_bethe()),
            w,
        ),
    ];
    for (name, make, weight) in rows {
        let (mean, max, failures) = against_exact(&streams, &exact, &make, weight);
        let note = if failures > 0 {
            format!(" ({failures} failures)")
        } else {
            String::new()
        };
        outln!("| {name} | {mean:.4} | {max:.3}{note} |");
    }
    outln!();
}

/// (Brier, log-loss, identity error) against the truth.
fn against_truth(
    streams: &[IdentityWorkloadSpec],
    make: &Make,
    weight: f64,
) -> Option<(f64, f64, f64)> {
    let (mut brier, mut logloss, mut wrong, mut count) = (0.0, 0.0, 0.0, 0usize);
    for s in streams {
        let w = generate(s).unwrap();
        let n = s.tracks;
        let mut filter = make(&w.initial);
        for (k, e) in w.events.iter().enumerate() {
            let e = match *e {
                IdentityEvent::Identify(r) => IdentityEvent::Identify(weighted(r, n, weight)),
                m => m,
            };
            filter.apply(&e).ok()?;
            if (k + 1) % (5 * n) == 0 {
                let p = filter.marginals().ok()?;
                let best = idmesh_identity::most_likely_assignment(&p).ok()?;
                let truth = &w.truth[k];
                for t in 0..n {
                    let i = truth[t] as usize;
                    brier += p[t]
                        .iter()
                        .enumerate()
                        .map(|(j, &x)| (x - if j == i { 1.0 } else { 0.0 }).powi(2))
                        .sum::<f64>();
                    logloss -= p[t][i].max(1e-12).ln();
                    wrong += f64::from(best[t] != truth[t]);
                    count += 1;
                }
            }
        }
    }
    let c = count as f64;
    Some((brier / c, logloss / c, wrong / c))
}

fn large(c: f64, w: f64) {
    outln!("### Against the truth (n = 30, 100; 20n events, half mixes of tracks ≤ 3 apart)\n");
    outln!("| n | method | Brier | log-loss | identity error | seconds |");
    outln!("|---|---|---|---|---|---|");
    for n in [30, 100] {
        let streams: Vec<_> = (0..5)
            .map(|s| spec(n, 20 * n, 0.5, 3, SEED0 + 50_000 + 100 * n as u64 + s))
            .collect();
        let metropolis = MarginalMethod::Metropolis {
            samples: 10_000,
            burn_in: 1_000,
            seed: 1,
        };
        let rows: Vec<(&str, Make, f64)> = vec![
            ("belief matrix", belief_matrix(), 1.0),
            (
                "information, c = 20, w = 1, half-Bethe (before)",
                info(20.0, MarginalMethod::half_bethe()),
                1.0,
            ),
            ("information, auto", info(c, MarginalMethod::Auto), w),
            ("information, Metropolis 10^4", info(c, metropolis), w),
            (
                "information, Sinkhorn",
                info(c, MarginalMethod::Sinkhorn),
                w,
            ),
            (
                "information, half-Bethe",
                info(c, MarginalMethod::half_bethe()),
                w,
            ),
        ];
        let quick = std::env::args().nth(4).as_deref() == Some("quick");
        for (name, make, weight) in rows {
            if quick && name != "information, auto" {
                continue;
            }
            let clock = Instant::now();
            match against_truth(&streams, &make, weight) {
                Some((b, l, e)) => outln!(
                    "| {n} | {name} | {b:.4} | {l:.3} | {e:.3} | {:.1} |",
                    clock.elapsed().as_secs_f64()
                ),
                None => outln!("| {n} | {name} | failed | | | |"),
            }
        }
    }
    outln!();
}

fn main() {
    let which = std::env::args().nth(1).unwrap_or_default();
    let parse = |k: usize, default: f64| {
        std::env::args()
            .nth(k)
            .map(|x| {
                if x == "inf" {
                    f64::INFINITY
                } else {
                    x.parse().unwrap()
                }
            })
            .unwrap_or(default)
    };
    match which.as_str() {
        "encoding" => {
            encoding();
        }
        "methods" => methods(parse(2, f64::INFINITY), parse(3, 1.0)),
        "worst" => {
            let streams = small_streams(8);
            let exact = exact_answers(&streams);
            against_exact(
                &streams,
                &exact,
                &info(f64::INFINITY, MarginalMethod::Exact),
                1.0,
            );
        }
        "large" => large(parse(2, f64::INFINITY), parse(3, 1.0)),
        _ => {
            let (c, w) = encoding();
            methods(c, w);
            large(c, w);
            write_document();
        }
    }
}

/// The line of docs/identity-calibration.md that says which code made it
/// (build.rs; tests/calibration_stamp.rs checks the committed file).
fn calibration_stamp_line() -> String {
    format!(
        "<!-- idmesh identity calibration stamp: sources {} -->",
        env!("IDMESH_IDENTITY_CALIBRATION_STAMP")
    )
}

/// docs/identity-calibration.md: what a whole run printed, stamped with
/// the digest of the identity engine's sources and this program (a test
/// fails when the committed file is stale).
fn write_document() {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../docs/identity-calibration.md"
    );
    let body = DOC.lock().unwrap_or_else(|e| e.into_inner()).clone();
    let doc = format!(
        "# Calibration of the identity engine\n\n\
         Generated by `cargo run --release -p idmesh-identity --example identity_calibration` \
         (about 15 minutes; every stream seeded, only the timings vary); do not edit by hand. \
         docs/design/identity.md (\"Calibration\") says what it means.\n\n{}\n\n{body}",
        calibration_stamp_line()
    );
    match std::fs::write(path, doc) {
        Ok(()) => eprintln!("wrote {path}"),
        Err(e) => {
            eprintln!("{path}: {e}");
            std::process::exit(1)
        }
    }
}
