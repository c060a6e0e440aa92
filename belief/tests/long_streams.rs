//! Numerical soundness over long streams and large fields: a million events,
//! and n = 10,000 tracks (k = 5,000) where the binomial weights have
//! thousands of digits, must leave finite, normalized answers — and the
//! normalizer, which shrinks with every observation, must stay finite too.
//! (A budget this small makes the surviving hypotheses fix hundreds of
//! tracks each, so the 10,000-track runs are kept to 10^5 events.)
//!
//! These lengths run with `IDMESH_LONG_TESTS=1` (an opt-in); without it
//! every run is a 25th as long, so a newcomer's `cargo test` stays short.

use idmesh_belief::workload::{generate_with, WorkloadSpec};
use idmesh_belief::{Field, PropertyFilter, RadonBelief, RadonOptions, Sparsify};

fn run(field: Field, sparsify: Sparsify, full_length: usize) {
    let long = std::env::var("IDMESH_LONG_TESTS").is_ok_and(|v| v == "1");
    let events = if long { full_length } else { full_length / 25 };
    let n = field.tracks;
    let spec = WorkloadSpec {
        events,
        ..WorkloadSpec::table3(n, 11)
    };
    let workload = generate_with(&spec, 0);
    let field = match field.initial_red {
        Some(_) => Field::known(n, workload.initial_red.clone()),
        None => field,
    };
    let options = RadonOptions {
        sparsify: Some(sparsify),
        ..RadonOptions::default()
    };
    let mut belief = RadonBelief::with_options(field, options).unwrap();
    let first = belief.log_normalizer();
    let mut last = first;
    for (i, event) in workload.events.iter().enumerate() {
        belief.apply(event).unwrap();
        if i % 100_000 == 99_999 || i + 1 == workload.events.len() {
            let p = belief.marginals().unwrap();
            assert!(p
                .iter()
                .all(|x| x.is_finite() && (-1e-9..=1.0 + 1e-9).contains(x)));
            let sum: f64 = p.iter().sum();
            assert!(
                (sum - (n / 2) as f64).abs() < 1e-6,
                "sum of marginals {sum}"
            );
            let z = belief.log_normalizer();
            // Every observation multiplies the total by a likelihood ≤ 1.
            assert!(z.is_finite() && z <= last + 1e-9, "log Z {z} after {last}");
            last = z;
        }
    }
    // Thousands of sightings with likelihoods ≤ 0.8 shrink Z by far more
    // than a double's range (a factor 1e-308, 709 in log): only the log
    // scale keeps it.
    assert!(last < first - 709.0, "log Z went from {first} to {last}");
}

#[test]
fn a_million_events_uniform_prior() {
    run(
        Field::uniform(1_000, 500),
        Sparsify::threshold(32),
        1_000_000,
    );
}

#[test]
fn ten_thousand_tracks_uniform_prior() {
    run(
        Field::uniform(10_000, 5_000),
        Sparsify::threshold(64),
        100_000,
    );
}

/// A known start keeps every hypothesis a full 5,000-track set, so each
/// mix copies kilobytes per atom: a hundred thousand events suffice here.
#[test]
fn ten_thousand_tracks_known_start() {
    let placeholder = Field::known(10_000, (0..5_000).collect());
    run(placeholder, Sparsify::threshold(64), 100_000);
}

#[test]
fn omp_on_ten_thousand_tracks() {
    run(
        Field::uniform(10_000, 5_000),
        Sparsify::overcomplete(64),
        100_000,
    );
}
