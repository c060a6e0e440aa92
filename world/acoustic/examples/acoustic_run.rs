//! Runs the acoustic tracking pipeline once and prints its metrics, the
//! predicted resolutions and the time per stage. Options as `key=value`:
//! `sensors=` (N), `targets=` (K), `seed=`, `samples=`, `speed=` (max,
//! m/sample; `speed=v` fixes it), `zigzag=` (periods), `n_group=`,
//! `l_seg=`, `l_step=`, `n_slot=`, `hear=`, `silent=0|1`, `threads=`, `sources=chirps|ar|mixed|audio`,
//! `out=` (write the trace there).
//!
//! `cargo run --release -p idmesh-acoustic --example acoustic_run -- sensors=1000`

use idmesh_acoustic::write_trace;
use idmesh_acoustic::PathSpec;
use idmesh_acoustic::{run, AcousticConfig};
use idmesh_acoustic::{ArParams, SourceKind};
use std::io::Write;

fn main() {
    let mut c = AcousticConfig::default();
    let mut out: Option<String> = None;
    for arg in std::env::args().skip(1) {
        let Some((key, value)) = arg.split_once('=') else {
            eprintln!("expected key=value, got {arg}");
            std::process::exit(2)
        };
        let num = || -> f64 {
            value.parse().unwrap_or_else(|_| {
                eprintln!("{key}: `{value}` is not a number");
                std::process::exit(2)
            })
        };
        match key {
            "sensors" => c.field.sensors = num() as usize,
            "targets" => c.field.targets = num() as usize,
            "seed" => c.seed = num() as u64,
            "samples" => c.field.samples = num() as usize,
            "speed" => {
                c.field.paths = PathSpec::Random {
                    speed: (num(), num()),
                }
            }
            "maxspeed" => {
                c.field.paths = PathSpec::Random {
                    speed: (num() / 3.0, num()),
                }
            }
            "zigzag" => {
                c.field.paths = PathSpec::Zigzag {
                    periods: num() as u32,
                    length: 300.0,
                    width: 100.0,
                }
            }
            "n_group" => c.pipeline.n_group = num() as usize,
            "l_seg" => c.pipeline.l_seg = num() as usize,
            "l_step" => c.pipeline.l_step = num() as usize,
            "n_slot" => c.pipeline.n_slot = num() as usize,
            "hear" => c.pipeline.hear_threshold = num(),
            "silent" => c.pipeline.exclude_silent = num() != 0.0,
            "slack" => c.pipeline.silent_slack = num() as u32,
            "same" => c.pipeline.same_source = num(),
            "maxiter" => c.pipeline.separation.ica.max_iter = num() as usize,
            "tolerance" => c.pipeline.vote_tolerance = num(),
            "keep" => c.pipeline.separation.keep_factor = num(),
            "threads" => c.threads = num() as usize,
            "noise" => c.field.noise_std = num(),
            "sources" => {
                c.field.sources = match value {
                    "chirps" => SourceKind::default(),
                    "ar" => SourceKind::Ar(ArParams::default()),
                    "mixed" => SourceKind::Mixed,
                    "audio" => SourceKind::shared_recordings(),
                    other => {
                        eprintln!("unknown sources `{other}`");
                        std::process::exit(2)
                    }
                }
            }
            "out" => out = Some(value.to_string()),
            _ => {
                eprintln!("unknown option {key}");
                std::process::exit(2)
            }
        }
    }
    let mut last = 0;
    let result = run(&c, &mut |done, total| {
        let pct = done * 100 / total.max(1);
        if pct >= last + 10 || done == total {
            eprint!(" {pct}%");
            last = pct;
        }
    })
    .unwrap_or_else(|e| {
        eprintln!("error: {e}");
        std::process::exit(1)
    });
    eprintln!();
    let m = &result.metrics;
    let s = &result.stats;
    println!(
        "sensors {} targets {} groups {} slots {} | noise var {:.3e} (true {:.3e})",
        c.field.sensors,
        c.field.targets,
        s.groups,
        s.slots,
        s.noise_variance,
        c.field.noise_std * c.field.noise_std
    );
    println!(
        "separations {} silent {} not converged {} segments/slot {:.0} | areas {} kept {} dropped {}",
        s.separation.separations,
        s.separation.silent,
        s.separation.not_converged,
        s.separation.segments as f64 / s.slots as f64,
        s.areas,
        s.kept,
        s.dropped
    );
    println!(
        "mean error {:.1} m  std {:.1} m  (union of areas: {:.1} m, std {:.1} m)  coverage {:.1} %  aligned error {:.1} m  slots tracked {:.1} %  points {}",
        m.mean_error,
        m.std_error,
        m.mean_error_union,
        m.std_error_union,
        100.0 * m.coverage,
        m.aligned_error,
        100.0 * m.slot_share,
        m.points
    );
    let r = &result.resolution;
    println!(
        "resolution: r {:.1} m, l {:.1} m, finest {:?}, average {:?}",
        r.group_radius, r.fragment_length, r.finest, r.average
    );
    let t = &s.times;
    println!(
        "times (s): field {:.2} separate+cluster {:.2} link+select {:.2} intersect {:.2} vote+link {:.2} metrics {:.2} total {:.2}",
        t.field, t.separate_cluster, t.link_select, t.intersect, t.vote_link, t.metrics, t.total
    );
    let mixes = result
        .events
        .iter()
        .filter(|e| e.event.kind() == "mix")
        .count();
    println!("events: {} ({} mix)", result.events.len(), mixes);
    if let Some(path) = out {
        let file = std::fs::File::create(&path).unwrap_or_else(|e| {
            eprintln!("{path}: {e}");
            std::process::exit(1)
        });
        let w =
            write_trace(&result, std::io::BufWriter::new(file), path.clone()).unwrap_or_else(|e| {
                eprintln!("{e}");
                std::process::exit(1)
            });
        drop(w);
        let _ = std::io::stdout().flush();
        println!("trace written to {path}");
    }
}
