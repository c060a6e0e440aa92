//! The factored identity belief against the exact filter and the
//! information matrix on random-waypoint identity traces: n = 8 and 9
//! targets, reads at 0.9, 300 events (mixes and colour looks), seeds
//! 100..106 (held out: no test uses them). At every `truth` line, |Δp| =
//! |p[t][i] − p_exact[t][i]| over all n² entries; the table gives the
//! mean and the largest over all truth lines of all seeds, the time per
//! event (events and answers, divided by the events), and the scores
//! against the truth (Brier, log-loss, MAP accuracy, IDF1).
//!
//!     cargo run --release -p idmesh-eval --example identity_factored [SEEDS]

use idmesh_belief::identity::information::KNOWN_START_CONFIDENCE;
use idmesh_belief::identity::scoring::IdentityScores;
use idmesh_belief::identity::{
    ExactPermutationFilter, FactoredIdentity, FactoredIdentityOptions, IdentityEvent,
    IdentityFilter, InformationMatrix, InformationOptions,
};
use idmesh_belief::identity_event_of;
use idmesh_protocol::trace::Line;
use idmesh_sim::scenario::trace_out::lines;
use idmesh_sim::scenario::Scenario;
use std::time::{Duration, Instant};

/// One trace, ready to replay: the known start, and the events with the
/// truth lines between them.
struct Stream {
    initial: Vec<u32>,
    steps: Vec<Step>,
}

enum Step {
    Event(IdentityEvent),
    Truth(Vec<u32>),
}

fn stream(n: usize, seed: u64) -> Stream {
    let trace = Scenario::waypoint()
        .targets(n)
        .events(300)
        .identities(true)
        .identity_accuracy(0.9)
        .seed(seed)
        .generate()
        .expect("a valid scenario");
    let mut initial = Vec::new();
    let mut steps = Vec::new();
    for line in lines(&trace) {
        match &line {
            Line::Header(h) => initial = h.initial_identity.clone().expect("a known start"),
            Line::Truth(t) => {
                if let Some(identity) = &t.identity {
                    steps.push(Step::Truth(identity.clone()));
                }
            }
            _ => {
                if let Some(e) = identity_event_of(&line) {
                    steps.push(Step::Event(e));
                }
            }
        }
    }
    Stream { initial, steps }
}

type Make = fn(&[u32]) -> Box<dyn IdentityFilter>;

fn methods() -> Vec<(&'static str, Make)> {
    fn factored(start: &[u32], max_group: usize) -> Box<dyn IdentityFilter> {
        let options = FactoredIdentityOptions {
            max_group,
            ..FactoredIdentityOptions::default()
        };
        Box::new(FactoredIdentity::from_assignment(start, options).expect("a start"))
    }
    vec![
        ("information-matrix", |s| {
            Box::new(
                InformationMatrix::from_assignment(
                    s,
                    KNOWN_START_CONFIDENCE,
                    InformationOptions::default(),
                )
                .expect("a start"),
            )
        }),
        ("factored, cap 6", |s| factored(s, 6)),
        ("factored, cap 7", |s| factored(s, 7)),
        ("factored, cap 8", |s| factored(s, 8)),
        ("factored, cap 9", |s| factored(s, 9)),
    ]
}

#[derive(Default)]
struct Row {
    sum: f64,
    count: usize,
    max: f64,
    time: Duration,
    events: usize,
    scores: IdentityScores,
}

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(6);
    println!(
        "| n | method | mean abs dp | max abs dp | us/event | Brier | log-loss | MAP acc | IDF1 |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for n in [8, 9] {
        let streams: Vec<Stream> = (100..100 + seeds).map(|s| stream(n, s)).collect();
        // The exact marginals at every truth line, once.
        let exact: Vec<Vec<Vec<Vec<f64>>>> = streams
            .iter()
            .map(|s| {
                let mut f = ExactPermutationFilter::from_assignment(&s.initial).expect("start");
                let mut out = Vec::new();
                for step in &s.steps {
                    match step {
                        Step::Event(e) => f.apply(e).expect("event"),
                        Step::Truth(_) => out.push(f.marginals().expect("marginals")),
                    }
                }
                out
            })
            .collect();
        for (name, make) in methods() {
            let mut row = Row::default();
            for (s, want) in streams.iter().zip(&exact) {
                let mut f = make(&s.initial);
                let mut at = 0;
                let mut answers = Vec::new();
                for step in &s.steps {
                    let clock = Instant::now();
                    match step {
                        Step::Event(e) => {
                            f.apply(e).expect("event");
                            row.events += 1;
                            row.time += clock.elapsed();
                        }
                        Step::Truth(truth) => {
                            let p = f.marginals().expect("marginals");
                            row.time += clock.elapsed();
                            for (a, b) in p.iter().flatten().zip(want[at].iter().flatten()) {
                                let d = (a - b).abs();
                                row.sum += d;
                                row.count += 1;
                                row.max = row.max.max(d);
                            }
                            answers.push((p, truth.clone()));
                            at += 1;
                        }
                    }
                }
                row.scores.add_stream(&answers).expect("scores");
            }
            let sc = row.scores.summary();
            println!(
                "| {n} | {name} | {:.4} | {:.3} | {:.0} | {:.4} | {:.4} | {:.4} | {:.4} |",
                row.sum / row.count.max(1) as f64,
                row.max,
                row.time.as_secs_f64() * 1e6 / row.events.max(1) as f64,
                sc.brier,
                sc.log_loss,
                sc.map_accuracy,
                sc.idf1,
            );
        }
    }
}
