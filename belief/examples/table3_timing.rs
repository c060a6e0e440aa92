use idmesh_belief::workload::{generate, WorkloadSpec};
use idmesh_belief::LowOrderFilter;
use idmesh_belief::*;
use std::time::Instant;

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(100);
    let budget: usize = std::env::args()
        .nth(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(500);
    for known in [true, false] {
        for method in ["exact", "order1", "threshold", "overcomplete"] {
            let mut err = 0.0;
            let mut secs = 0.0;
            let mut count = 0;
            for seed in 1..4 {
                let w = generate(&WorkloadSpec::table3(n, seed));
                let field = if known {
                    Field::known(n, w.initial_red.clone())
                } else {
                    Field::uniform(n, n / 2)
                };
                let sparsify = if method == "overcomplete" {
                    Sparsify::overcomplete(budget)
                } else {
                    Sparsify::threshold(budget)
                };
                let mut b: Box<dyn PropertyFilter> = if method == "exact" {
                    if n > 24 {
                        continue;
                    }
                    Box::new(idmesh_belief::DenseFilter::new(field).unwrap())
                } else if method == "order1" {
                    Box::new(LowOrderFilter::new(field, 1).unwrap())
                } else {
                    Box::new(
                        RadonBelief::with_options(
                            field,
                            RadonOptions {
                                sparsify: Some(sparsify),
                                ..Default::default()
                            },
                        )
                        .unwrap(),
                    )
                };
                let start = Instant::now();
                for (i, e) in w.events.iter().enumerate() {
                    if let Err(e) = b.apply(e) {
                        println!("{method} error {e}");
                        break;
                    }
                    if i % 50 == 49 {
                        let p = b.predicted_red().unwrap();
                        err += tracking_error(n, &p, &w.truth[i]);
                        count += 1;
                    }
                }
                secs += start.elapsed().as_secs_f64();
            }
            println!(
                "known={known} {method:10}: {:.3}s err={:.3}",
                secs / 3.0,
                err / count as f64
            );
        }
    }
}
