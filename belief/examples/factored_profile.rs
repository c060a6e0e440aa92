//! Where a factored query's time goes at a large n (for `perf record`):
//! `cargo run --release -p idmesh-belief --example factored_profile -- 100000 local 20`.
use idmesh_belief::workload::{generate_with, WorkloadSpec};
use idmesh_belief::{Coupling, FactoredBelief, FactoredOptions, Field, PropertyFilter};
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let n: usize = args.next().map_or(100_000, |a| a.parse().expect("n"));
    let coupling = match args.next().as_deref() {
        Some("coupled") => Coupling::Coupled,
        Some("flat") => Coupling::Flat,
        _ => Coupling::Local,
    };
    let queries: usize = args.next().map_or(20, |a| a.parse().expect("queries"));
    let spec = WorkloadSpec {
        events: 2 * n + 1000,
        ..WorkloadSpec::table3(n, 7)
    };
    let work = generate_with(&spec, usize::MAX);
    let options = FactoredOptions {
        coupling,
        ..FactoredOptions::default()
    };
    let mut belief =
        FactoredBelief::with_options(Field::known(n, work.initial_red.clone()), options)
            .expect("valid");
    let (warm, rest) = work.events.split_at(2 * n);
    let start = Instant::now();
    for e in warm {
        let _ = belief.apply(e);
    }
    eprintln!(
        "warm-up: {:.3} s ({:.2} µs an event)",
        start.elapsed().as_secs_f64(),
        1e6 * start.elapsed().as_secs_f64() / warm.len() as f64
    );
    belief.marginals().expect("a belief");
    let start = Instant::now();
    for e in rest.iter().take(1000) {
        let _ = belief.apply(e);
    }
    eprintln!("1000 events: {:.3} ms each", start.elapsed().as_secs_f64());
    let mut spent = 0.0;
    for e in rest.iter().take(queries) {
        let _ = belief.apply(e);
        let start = Instant::now();
        std::hint::black_box(belief.marginals().expect("a belief"));
        spent += start.elapsed().as_secs_f64();
    }
    eprintln!("query: {:.1} ms", 1e3 * spent / queries as f64);
}
