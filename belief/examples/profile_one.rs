use idmesh_belief::workload::{generate, WorkloadSpec};
use idmesh_belief::*;
fn main() {
    let known = std::env::args().nth(1).as_deref() == Some("known");
    let method = std::env::args().nth(2).unwrap_or("overcomplete".into());
    for seed in 1..6 {
        let w = generate(&WorkloadSpec::table3(100, seed));
        let field = if known {
            Field::known(100, w.initial_red.clone())
        } else {
            Field::uniform(100, 50)
        };
        let sparsify = if method == "overcomplete" {
            Sparsify::overcomplete(500)
        } else {
            Sparsify::threshold(500)
        };
        let mut b = RadonBelief::with_options(
            field,
            RadonOptions {
                sparsify: Some(sparsify),
                ..Default::default()
            },
        )
        .unwrap();
        for e in &w.events {
            b.apply(e).unwrap();
        }
        eprintln!("{:?}", b.stats());
    }
}
