//! The factored belief's mean |Δp| against the exact filter's marginals at
//! n = 20 (k = 10, the Table III workload, swap 0.5 and 0.1, known start
//! and uniform prior), for a few option sets within 1,000 numbers:
//! `cargo run --release -p idmesh-belief --example factored_accuracy`.
use idmesh_belief::workload::{generate, WorkloadSpec};
use idmesh_belief::{
    Coupling, DenseFilter, FactoredBelief, FactoredOptions, Field, PropertyFilter, SplitRule,
};

fn main() {
    let n = 20;
    let configs: Vec<(&str, FactoredOptions)> = vec![
        (
            "default (max 7, Original, coupled)",
            FactoredOptions::default(),
        ),
        (
            "max 9, ≤ 1000 numbers, Original",
            FactoredOptions {
                max_component: 9,
                max_numbers: Some(1000),
                ..FactoredOptions::default()
            },
        ),
        (
            "max 9, ≤ 1000 numbers, LeastLoss 4",
            FactoredOptions {
                max_component: 9,
                max_numbers: Some(1000),
                split: SplitRule::LeastLoss { rounds: 4 },
                ..FactoredOptions::default()
            },
        ),
        (
            "max 9, ≤ 1000 numbers, Recent",
            FactoredOptions {
                max_component: 9,
                max_numbers: Some(1000),
                split: SplitRule::Recent,
                ..FactoredOptions::default()
            },
        ),
        (
            "default, local",
            FactoredOptions {
                coupling: Coupling::Local,
                ..FactoredOptions::default()
            },
        ),
    ];
    for swap in [0.5, 0.1] {
        for known in [true, false] {
            for (name, options) in &configs {
                let (mut sum, mut count, mut numbers) = (0.0, 0usize, 0usize);
                for seed in 1..=3 {
                    let work = generate(&WorkloadSpec {
                        swap,
                        ..WorkloadSpec::table3(n, seed)
                    });
                    let field = if known {
                        Field::known(n, work.initial_red.clone())
                    } else {
                        Field::uniform(n, n / 2)
                    };
                    let mut exact = DenseFilter::new(field.clone()).expect("field");
                    let mut f = FactoredBelief::with_options(field, options.clone()).expect("opts");
                    for (i, e) in work.events.iter().enumerate() {
                        exact.apply(e).expect("exact");
                        f.apply(e).expect("factored");
                        if i % 10 == 9 {
                            let (a, b) = (exact.marginals().unwrap(), f.marginals().unwrap());
                            sum += a.iter().zip(&b).map(|(x, y)| (x - y).abs()).sum::<f64>();
                            count += n;
                        }
                    }
                    numbers = numbers.max(f.stats().max_coefficients);
                }
                println!(
                    "swap {swap} {} | {name} | mean |Δp| {:.4} | max numbers {numbers}",
                    if known { "known" } else { "uniform" },
                    sum / count as f64
                );
            }
        }
    }
}
