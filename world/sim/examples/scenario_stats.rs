//! Generates a scenario and prints its event counts, mixing share and
//! generation time. Options as `key=value`: `model=crowd|waypoint|PATH`,
//! `n=`, `mix=` (m), `obs=` (m), `interval=` (s), `side=` (field side, m),
//! `stalls=` (crowd goals at this many stalls), `duration=` (s), `seed=`,
//! `out=` (write the trace there).
//!
//! `cargo run --release -p idmesh-sensor --example scenario_stats -- n=100`

use idmesh_sim::write_trace;
use idmesh_sim::{CrowdParams, Goals};
use idmesh_sim::{Model, Scenario};
use std::time::Instant;

fn main() {
    let mut s = Scenario::crowd();
    let mut out: Option<String> = None;
    for arg in std::env::args().skip(1) {
        let (key, value) = arg.split_once('=').unwrap_or_else(|| {
            eprintln!("expected key=value, got {arg}");
            std::process::exit(2)
        });
        let num = || -> f64 {
            value.parse().unwrap_or_else(|_| {
                eprintln!("{key}: `{value}` is not a number");
                std::process::exit(2)
            })
        };
        s = match key {
            "model" => {
                let base = match value {
                    "crowd" => Scenario::crowd(),
                    "waypoint" => Scenario::waypoint(),
                    path => Scenario::pedestrians(path),
                };
                s.with_model(base.model().clone())
            }
            "n" => s.targets(num() as usize),
            "mix" => s.mix_distance(num()),
            "obs" => s.observe_distance(num()),
            "interval" => s.observe_interval(num()),
            "side" => s.field(num(), num()),
            "duration" => s.duration(num()),
            "seed" => s.seed(num() as u64),
            "out" => {
                out = Some(value.to_string());
                s
            }
            "stalls" => {
                let goals = Goals::Stalls {
                    count: num() as usize,
                    spread: 3.0,
                };
                let model = Model::Crowd(CrowdParams {
                    goals,
                    ..Default::default()
                });
                s.with_model(model)
            }
            _ => {
                eprintln!("unknown option {key}");
                std::process::exit(2)
            }
        };
    }
    let start = Instant::now();
    let trace = match s.generate() {
        Ok(t) => t,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(1);
        }
    };
    let elapsed = start.elapsed();
    if let Some(path) = out {
        let started = Instant::now();
        let file = std::fs::File::create(&path).unwrap_or_else(|e| {
            eprintln!("{path}: {e}");
            std::process::exit(1)
        });
        let written = write_trace(&trace, std::io::BufWriter::new(file), path.as_str());
        if let Err(e) = written {
            eprintln!("{e}");
            std::process::exit(1);
        }
        println!("wrote {path} in {:.3} s", started.elapsed().as_secs_f64());
    }
    let st = trace.stats();
    println!("{}", trace.header.description);
    println!(
        "tracks {} red {} | {:.1} s of motion | mixes {} (exchanged {}) observes {} moves {} truths {} | mix share {:.3} | {:.3} s",
        trace.header.tracks,
        trace.header.red,
        trace.duration,
        st.mixes,
        st.exchanges,
        st.observations,
        st.moves,
        st.truths,
        st.mix_share,
        elapsed.as_secs_f64()
    );
}
