use idmesh_belief::workload::{generate_with, WorkloadSpec};
use idmesh_belief::*;
fn main() {
    let spec = WorkloadSpec {
        events: 200_000,
        ..WorkloadSpec::table3(10_000, 11)
    };
    let w = generate_with(&spec, 0);
    let t = std::time::Instant::now();
    let mut b = RadonBelief::with_options(
        Field::uniform(10_000, 5_000),
        RadonOptions {
            sparsify: Some(Sparsify::threshold(64)),
            ..Default::default()
        },
    )
    .unwrap();
    for e in &w.events {
        b.apply(e).unwrap();
    }
    eprintln!("{:?} {:?}", t.elapsed(), b.stats());
}
