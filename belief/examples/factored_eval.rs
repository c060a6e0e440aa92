//! Tracking error and time of the factored belief against the exact filter,
//! the first-order Radon baseline and the thresholded Radon belief, on
//! recorded traces (JSON Lines, shared/spec/trace.md), e.g. the crowd
//! simulator's:
//!
//! ```sh
//! idmesh simulate --model crowd --targets 20 --events 1000 --seed 1 --out crowd.jsonl
//! cargo run --release -p idmesh-belief --example factored_eval -- \
//!     --method exact --method order1 --method threshold:500 \
//!     --method factored:max=8,rule=recent,budget=500 crowd.jsonl
//! ```
//!
//! Methods: `exact`, `order1`, `threshold:N`, `overcomplete:N`,
//! `particles:P`, `factored[:max=M,rule=original|recent|loss|lossR,
//! budget=N,coupling=coupled|local]` (`lossR` = LeastLoss with R rounds).
//! For each trace and method it prints one line: the mean tracking error
//! over the truth lines (the spec's score: the k tracks with the largest
//! marginals are predicted red, ties shared), the Brier score, with
//! `--against-exact` the mean |Δp| of the marginals against the exact
//! filter's at every truth line (n ≤ 20), the filter's own
//! seconds (events and marginals; reading excluded), the largest number of
//! stored numbers, how many events the filter rejected (and skipped), and
//! the error the filter expects of itself from its marginals (for the exact
//! filter, the Bayes risk of the prediction rule).

use idmesh_belief::{
    brier_score, event_of, expected_tracking_error, field_of, predict_red, Coupling, DenseFilter,
    Event, FactoredBelief, FactoredOptions, Field, ParticleFilter, PropertyFilter, RadonBelief,
    RadonOptions, Sparsify, SplitRule,
};
use idmesh_belief::{LowOrderFilter, LowOrderRepair};
use idmesh_protocol::trace::{Line as TraceLine, TraceReader};
use std::time::Instant;

enum Line {
    Event(Event),
    Truth(Vec<u32>),
}

struct Trace {
    name: String,
    field: Field,
    lines: Vec<Line>,
}

/// The trace at `path`, read and checked by the workspace's one trace
/// reader, its events turned into the engine's as `idmesh replay` does.
fn read_trace(path: &str) -> Result<Trace, String> {
    let mut reader = TraceReader::open(path).map_err(|e| format!("{path}: {e}"))?;
    let header = reader.read_header().map_err(|e| e.to_string())?;
    let mut lines = Vec::new();
    for numbered in reader {
        let line = numbered.map_err(|e| e.to_string())?.line;
        if let TraceLine::Truth(truth) = &line {
            if let Some(red) = &truth.red {
                lines.push(Line::Truth(red.clone()));
            }
        } else if let Some(event) = event_of(&line) {
            lines.push(Line::Event(event));
        }
    }
    Ok(Trace {
        name: path.rsplit('/').next().unwrap_or(path).to_string(),
        field: field_of(&header),
        lines,
    })
}

fn factored_options(spec: &str) -> Result<FactoredOptions, String> {
    let mut options = FactoredOptions::default();
    for part in spec.split(',').filter(|p| !p.is_empty()) {
        let (key, value) = part.split_once('=').ok_or(format!("bad option {part}"))?;
        match key {
            "max" => options.max_component = value.parse().map_err(|e| format!("{e}"))?,
            "budget" => options.max_numbers = Some(value.parse().map_err(|e| format!("{e}"))?),
            "rule" => {
                options.split = match value {
                    "original" => SplitRule::Original,
                    "recent" => SplitRule::Recent,
                    v if v.starts_with("loss") => SplitRule::LeastLoss {
                        rounds: v[4..].parse().unwrap_or(2),
                    },
                    v => return Err(format!("unknown rule {v}")),
                }
            }
            "coupling" => {
                options.coupling = match value {
                    "coupled" => Coupling::Coupled,
                    "local" => Coupling::Local,
                    v => return Err(format!("unknown coupling {v}")),
                }
            }
            k => return Err(format!("unknown option {k}")),
        }
    }
    Ok(options)
}

fn build(method: &str, field: &Field) -> Result<Box<dyn PropertyFilter>, String> {
    let (name, arg) = method.split_once(':').unwrap_or((method, ""));
    let field = field.clone();
    let e = |e: idmesh_belief::BeliefError| e.to_string();
    Ok(match name {
        "exact" => Box::new(DenseFilter::new(field).map_err(e)?),
        "order1" => Box::new(
            LowOrderFilter::with_repair(field, 1, LowOrderRepair::ShrinkToUniform).map_err(e)?,
        ),
        "threshold" | "overcomplete" => {
            let budget = arg.parse().map_err(|e| format!("{method}: {e}"))?;
            let sparsify = if name == "threshold" {
                Sparsify::threshold(budget)
            } else {
                Sparsify::overcomplete(budget)
            };
            let options = RadonOptions {
                sparsify: Some(sparsify),
                ..RadonOptions::default()
            };
            Box::new(RadonBelief::with_options(field, options).map_err(e)?)
        }
        "particles" => {
            let p = arg.parse().map_err(|e| format!("{method}: {e}"))?;
            Box::new(ParticleFilter::new(field, p, 1).map_err(e)?)
        }
        "factored" => {
            Box::new(FactoredBelief::with_options(field, factored_options(arg)?).map_err(e)?)
        }
        _ => return Err(format!("unknown method {method}")),
    })
}

struct Score {
    error: f64,
    brier: f64,
    /// Mean |Δp| against the exact filter (NaN without `--against-exact`).
    delta: f64,
    /// The error the filter expects of itself: Σ_{predicted} (1 − p) +
    /// Σ_{others} p over n. For the exact filter this is the Bayes risk of
    /// the top-k rule, which no filter beats in expectation when the trace
    /// follows the model.
    expected: f64,
    seconds: f64,
    max_numbers: usize,
    rejected: usize,
}

fn run(trace: &Trace, method: &str, against_exact: bool) -> Result<Score, String> {
    let mut filter = build(method, &trace.field)?;
    let mut exact = if against_exact {
        Some(DenseFilter::new(trace.field.clone()).map_err(|e| e.to_string())?)
    } else {
        None
    };
    let k = trace.field.red.known();
    let (mut errors, mut truths, mut rejected) = (0.0, 0usize, 0usize);
    let (mut brier, mut delta) = (0.0, 0.0);
    let mut expected = 0.0;
    let mut max_numbers = filter.coefficients();
    let mut seconds = 0.0;
    for line in &trace.lines {
        match line {
            Line::Event(event) => {
                let start = Instant::now();
                let result = filter.apply(event);
                seconds += start.elapsed().as_secs_f64();
                if let Some(exact) = &mut exact {
                    let _ = exact.apply(event);
                }
                if result.is_err() {
                    rejected += 1;
                }
                max_numbers = max_numbers.max(filter.coefficients());
            }
            Line::Truth(red) => {
                let start = Instant::now();
                let marginals = filter.marginals().map_err(|e| e.to_string())?;
                seconds += start.elapsed().as_secs_f64();
                let predicted = predict_red(&marginals, k);
                errors += expected_tracking_error(&marginals, k, red);
                brier += brier_score(&marginals, red);
                if let Some(exact) = &exact {
                    let want = exact.marginals().map_err(|e| e.to_string())?;
                    delta += want
                        .iter()
                        .zip(&marginals)
                        .map(|(a, b)| (a - b).abs())
                        .sum::<f64>()
                        / want.len() as f64;
                }
                let mut red_label = vec![false; marginals.len()];
                for &t in &predicted {
                    red_label[t as usize] = true;
                }
                expected += marginals
                    .iter()
                    .zip(&red_label)
                    .map(|(&p, &r)| if r { 1.0 - p } else { p })
                    .sum::<f64>()
                    / trace.field.tracks as f64;
                truths += 1;
            }
        }
    }
    Ok(Score {
        error: errors / truths.max(1) as f64,
        brier: brier / truths.max(1) as f64,
        delta: if exact.is_some() {
            delta / truths.max(1) as f64
        } else {
            f64::NAN
        },
        expected: expected / truths.max(1) as f64,
        seconds,
        max_numbers,
        rejected,
    })
}

fn main() {
    let mut methods = Vec::new();
    let mut paths = Vec::new();
    let mut against_exact = false;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        if arg == "--against-exact" {
            against_exact = true;
        } else if arg == "--method" {
            methods.push(args.next().expect("--method needs a value"));
        } else {
            paths.push(arg);
        }
    }
    if methods.is_empty() {
        methods = vec!["factored".into()];
    }
    println!("trace\tmethod\terror\tbrier\tdelta_p\tseconds\tmax_numbers\trejected\texpected");
    for path in &paths {
        let trace = match read_trace(path) {
            Ok(t) => t,
            Err(e) => {
                eprintln!("{e}");
                std::process::exit(1);
            }
        };
        for method in &methods {
            match run(&trace, method, against_exact) {
                Ok(s) => println!(
                    "{}\t{}\t{:.4}\t{:.4}\t{:.4}\t{:.4}\t{}\t{}\t{:.4}",
                    trace.name,
                    method,
                    s.error,
                    s.brier,
                    s.delta,
                    s.seconds,
                    s.max_numbers,
                    s.rejected,
                    s.expected
                ),
                Err(e) => println!("{}\t{}\tFAILED: {}", trace.name, method, e),
            }
        }
    }
}
