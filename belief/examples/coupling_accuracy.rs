//! How far each count coupling of the factored belief's splits lands from
//! the exact filter on small crowds, where the exact filter runs beside it
//! (docs/design/beliefs.md, "Where the factored belief loses to the exact
//! filter"; the factored belief itself is our addition to Jiang et al.,
//! TOSN 2013, Sec. 5).
//!
//! Crowds of n = 14, 16, 18, 20, 22 tracks; seed s of a crowd has
//! k = 1 + (s − 1) mod ⌊n/2⌋ red targets, so every k from 1 to n/2 is drawn;
//! the Table III stream otherwise (1000 events, half of them mixes of tracks
//! at most 4 apart, the trace spec's colour sensor), at swap 0.5 and 0.1,
//! from the known red tracks and from the uniform prior over k-sets. Every
//! 50th event each belief's marginals are set against the exact filter's
//! (mean |ΔP(red)| over the tracks) and scored against the truth (the trace
//! spec's tracking error, k known). A run's score is its mean over those
//! points; the tables give the mean over runs with a 95 % interval
//! (1.96 standard errors), and the mean paired difference of each rule
//! from the coupled one on the same streams, with its interval.
//!
//! Run: `cargo run --release -p idmesh-belief --example coupling_accuracy
//! -- [--seeds S] [--out docs/coupling-accuracy.md] [--extra]` (S = 20 by
//! default: 20 seeds × 5 sizes × 4 cases = 400 streams, a few minutes on
//! one core; `--extra` adds other component sizes and two exchange rounds,
//! about ten times as long).
//! Every stream is seeded: the numbers are the same on every run, except the
//! time per event.

use idmesh_belief::workload::{generate, WorkloadSpec};
use idmesh_belief::{expected_tracking_error, mean_with_interval};
use idmesh_belief::{
    Coupling, DenseFilter, FactoredBelief, FactoredOptions, Field, PropertyFilter, SplitRule,
};
use std::fmt::Write as _;
use std::time::Instant;

const SIZES: [usize; 5] = [14, 16, 18, 20, 22];
const EVERY: usize = 50;

struct Config {
    name: String,
    options: FactoredOptions,
}

fn config(name: &str, coupling: Coupling, max: usize, split: SplitRule) -> Config {
    Config {
        name: name.to_string(),
        options: FactoredOptions {
            coupling,
            max_component: max,
            split,
            ..FactoredOptions::default()
        },
    }
}

/// Per run and option set: mean |Δp|, tracking error, seconds per event.
#[derive(Default, Clone)]
struct Runs {
    delta: Vec<f64>,
    error: Vec<f64>,
    seconds: f64,
    events: usize,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |flag: &str| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|i| args.get(i + 1))
    };
    let seeds: u64 = value("--seeds")
        .map(|s| s.parse().expect("--seeds takes a number"))
        .unwrap_or(20);
    let out = value("--out").cloned();
    let extra = args.iter().any(|a| a == "--extra");

    let defaults = FactoredOptions::default();
    let (max, split) = (defaults.max_component, defaults.split);
    let (original, least) = (SplitRule::Original, SplitRule::LeastLoss { rounds: 1 });
    let mut configs = vec![
        config(
            "coupled (the default: replay, a crowd held whole)",
            Coupling::Coupled,
            max,
            split,
        ),
        config(
            "local (each of several sharing a crowd)",
            Coupling::Local,
            max,
            split,
        ),
        config("flat (an older local rule)", Coupling::Flat, max, split),
        config(
            "local, max 7, original (the former default)",
            Coupling::Local,
            7,
            original,
        ),
        config("coupled, max 7, original", Coupling::Coupled, 7, original),
    ];
    if extra {
        // What larger components and more exchange rounds buy, and at
        // what cost per event.
        configs.extend([
            config("local, max 5", Coupling::Local, 5, split),
            config("local, max 7", Coupling::Local, 7, least),
            config("coupled, max 7", Coupling::Coupled, 7, least),
            config(
                "local, two exchange rounds",
                Coupling::Local,
                max,
                SplitRule::LeastLoss { rounds: 2 },
            ),
        ]);
    }
    let reference = configs
        .iter()
        .position(|c| c.options.coupling == Coupling::Coupled)
        .expect("a coupled option set");

    let started = Instant::now();
    let mut cases = Vec::new();
    for swap in [0.5, 0.1] {
        for known in [true, false] {
            let mut runs = vec![Runs::default(); configs.len()];
            let mut exact_error = Vec::new();
            for &n in &SIZES {
                for seed in 1..=seeds {
                    let k = 1 + (seed as usize - 1) % (n / 2);
                    let work = generate(&WorkloadSpec {
                        red: k,
                        swap,
                        ..WorkloadSpec::table3(n, seed)
                    });
                    let field = if known {
                        Field::known(n, work.initial_red.clone())
                    } else {
                        Field::uniform(n, k)
                    };
                    one_stream(&field, &work, k, &configs, &mut runs, &mut exact_error);
                }
            }
            cases.push((swap, known, runs, exact_error));
            eprintln!(
                "swap {swap}, {}: done at {:.0} s",
                if known {
                    "known start"
                } else {
                    "uniform prior"
                },
                started.elapsed().as_secs_f64()
            );
        }
    }

    let mut md = String::new();
    let _ = writeln!(
        md,
        "# The factored belief's count couplings against the exact filter\n\n\
         Written by `cargo run --release -p idmesh-belief --example coupling_accuracy -- \
         --seeds {seeds}{} --out docs/coupling-accuracy.md` (belief/examples/coupling_accuracy.rs), \
         {:.0} s on this machine. Every stream is seeded: every number but the time per event \
         is the same on every run.\n\n\
         Crowds of n = 14, 16, 18, 20 and 22 tracks, seeds 1 to {seeds} each; seed s has \
         k = 1 + (s − 1) mod ⌊n/2⌋ red targets, so every k from 1 to n/2 is drawn. The stream is \
         Table III's otherwise (1000 events, half of them mixes of tracks at most 4 apart, the \
         trace spec's colour sensor). Every {EVERY}th event each belief's marginals are set against \
         the exact filter's (mean \\|ΔP(red)\\| over the tracks) and scored against the truth (the \
         trace spec's tracking error). A stream's score is its mean over those points; a cell is \
         the mean over the {} streams of a case ± 1.96 standard errors. \"− coupled\" is the mean \
         paired difference from the coupled rule on the same streams (± 1.96 standard errors): \
         negative is closer to the exact filter. The defaults (components of at most {max} \
         tracks, least-loss splits: the old cut or, where one loses less, the best cut one \
         exchange of tracks away from it) unless the row says otherwise; µs/event is the time per event of the \
         whole run (CPU, this machine, shared with other work: compare rows, not runs). \
         \"coupled\" weighs every split by the whole belief: what `idmesh replay` and a deployment holding the crowd whole \
         (one leader, or several on a crowd of at most `spread_above` tracks, 64 by default) run by default. \"local\" is \
         what each leader runs where several share a larger crowd, \"flat\" a local rule they ran \
         before.\n",
        if extra { " --extra" } else { "" },
        started.elapsed().as_secs_f64(),
        seeds as usize * SIZES.len(),
    );
    for (swap, known, runs, exact_error) in &cases {
        let (e, ci) = mean_with_interval(exact_error);
        let _ = writeln!(
            md,
            "\n## swap {swap}, {} (exact filter's tracking error {e:.4} ± {ci:.4})\n\n\
             | coupling | mean \\|ΔP(red)\\| | − coupled | tracking error | µs/event |\n\
             |---|---|---|---|---|",
            if *known {
                "known start"
            } else {
                "uniform prior, k known"
            },
        );
        for (c, r) in configs.iter().zip(runs) {
            let (d, dci) = mean_with_interval(&r.delta);
            let (t, tci) = mean_with_interval(&r.error);
            let paired: Vec<f64> = r
                .delta
                .iter()
                .zip(&runs[reference].delta)
                .map(|(a, b)| a - b)
                .collect();
            let (p, pci) = mean_with_interval(&paired);
            let _ = writeln!(
                md,
                "| {} | {d:.4} ± {dci:.4} | {p:+.4} ± {pci:.4} | {t:.4} ± {tci:.4} | {:.1} |",
                c.name,
                1e6 * r.seconds / r.events as f64
            );
        }
    }
    // Over every case: the figure the default is held to.
    let _ = writeln!(
        md,
        "\n## All cases together ({} streams)\n\n\
         | coupling | mean \\|ΔP(red)\\| | − coupled | tracking error |\n|---|---|---|---|",
        cases.len() * seeds as usize * SIZES.len()
    );
    for (i, c) in configs.iter().enumerate() {
        let all = |f: fn(&Runs) -> &Vec<f64>, j: usize| -> Vec<f64> {
            cases.iter().flat_map(|x| f(&x.2[j]).clone()).collect()
        };
        let delta = all(|r| &r.delta, i);
        let paired: Vec<f64> = delta
            .iter()
            .zip(all(|r| &r.delta, reference))
            .map(|(a, b)| a - b)
            .collect();
        let (d, dci) = mean_with_interval(&delta);
        let (p, pci) = mean_with_interval(&paired);
        let (t, tci) = mean_with_interval(&all(|r| &r.error, i));
        let _ = writeln!(
            md,
            "| {} | {d:.4} ± {dci:.4} | {p:+.4} ± {pci:.4} | {t:.4} ± {tci:.4} |",
            c.name
        );
    }
    let exact: Vec<f64> = cases.iter().flat_map(|x| x.3.clone()).collect();
    let (e, eci) = mean_with_interval(&exact);
    let _ = writeln!(md, "| exact filter | 0 | | {e:.4} ± {eci:.4} |");
    print!("{md}");
    if let Some(path) = out {
        std::fs::write(&path, md).expect("write the table");
        eprintln!("wrote {path}");
    }
}

/// Runs the exact filter and every option set over one stream.
fn one_stream(
    field: &Field,
    work: &idmesh_belief::workload::Workload,
    k: usize,
    configs: &[Config],
    runs: &mut [Runs],
    exact_error: &mut Vec<f64>,
) {
    let n = field.tracks;
    let mut exact = DenseFilter::new(field.clone()).expect("a small field");
    let mut checks = Vec::new();
    let mut errors = Vec::new();
    for (i, e) in work.events.iter().enumerate() {
        exact.apply(e).expect("the exact filter on a drawn stream");
        if i % EVERY == EVERY - 1 {
            let m = exact.marginals().expect("exact marginals");
            errors.push(expected_tracking_error(&m, Some(k), &work.truth[i]));
            checks.push((i, m));
        }
    }
    exact_error.push(errors.iter().sum::<f64>() / errors.len() as f64);
    for (c, r) in configs.iter().zip(runs.iter_mut()) {
        let mut f =
            FactoredBelief::with_options(field.clone(), c.options.clone()).expect("options");
        let (mut delta, mut error, mut next) = (0.0, 0.0, 0);
        let mut seconds = 0.0;
        for (i, e) in work.events.iter().enumerate() {
            let t = Instant::now();
            f.apply(e).expect("the factored belief on a drawn stream");
            seconds += t.elapsed().as_secs_f64();
            if next < checks.len() && checks[next].0 == i {
                let m = f.marginals().expect("factored marginals");
                delta += m
                    .iter()
                    .zip(&checks[next].1)
                    .map(|(a, b)| (a - b).abs())
                    .sum::<f64>()
                    / n as f64;
                error += expected_tracking_error(&m, Some(k), &work.truth[i]);
                next += 1;
            }
        }
        r.delta.push(delta / checks.len() as f64);
        r.error.push(error / checks.len() as f64);
        r.seconds += seconds;
        r.events += work.events.len();
    }
}
