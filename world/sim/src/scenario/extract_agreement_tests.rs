//! The simulator is the extractor plus drawn swaps: on the positions of a
//! real pedestrian scene, what `simulate --model pedestrians` says its
//! tracker reported (each track where the target it follows is, class
//! scores where the sensor saw a colour), fed to `idmesh-extract`'s
//! [`Extractor`], gives the simulator's mixes — same pairs, times, swap
//! probabilities — and its observations, also when swaps are drawn and
//! the swap probability comes from the meeting's geometry.

use super::Scenario;
use crate::events::SimEvent;
use crate::motion::pedestrians::{data_dir, Scene, Timing};
use idmesh_extract::{Extractor, MeetingModel, RosterPolicy};
use idmesh_protocol::trace::Line;
use std::sync::Arc;

/// A mix or an observation, comparable across the two: an observation by
/// its likelihood ratio (the extractor's likelihoods sum to 1, the
/// sensor's need not).
#[derive(Debug, Clone, PartialEq)]
enum Sensed {
    Mix {
        time: f64,
        a: u32,
        b: u32,
        swap: f64,
    },
    Observe {
        time: f64,
        track: u32,
        red_share: f64,
    },
}

fn close(x: &[Sensed], y: &[Sensed]) -> Result<(), String> {
    if x.len() != y.len() {
        return Err(format!("{} events against {}", x.len(), y.len()));
    }
    for (i, (p, q)) in x.iter().zip(y).enumerate() {
        let same = match (p, q) {
            (
                Sensed::Mix {
                    time: t1,
                    a: a1,
                    b: b1,
                    swap: s1,
                },
                Sensed::Mix {
                    time: t2,
                    a: a2,
                    b: b2,
                    swap: s2,
                },
            ) => (t1, a1, b1) == (t2, a2, b2) && (s1 - s2).abs() < 1e-12,
            (
                Sensed::Observe {
                    time: t1,
                    track: k1,
                    red_share: r1,
                },
                Sensed::Observe {
                    time: t2,
                    track: k2,
                    red_share: r2,
                },
            ) => t1 == t2 && k1 == k2 && (r1 - r2).abs() < 1e-9,
            _ => false,
        };
        if !same {
            return Err(format!("event {i}: {p:?} against {q:?}"));
        }
    }
    Ok(())
}

#[test]
fn the_simulated_trackers_reports_extract_to_the_simulators_events() {
    let meetings = [
        MeetingModel::Constant(0.0),
        MeetingModel::Constant(0.5),
        MeetingModel::Approach {
            p_max: 0.9,
            sigma: 0.4,
            v0: 0.8,
        },
    ];
    for (file, seed) in [
        ("zara01/obsmat/obsmat.txt", 4),
        ("univ/students001.txt", 5),
        ("hotel/obsmat/obsmat.txt", 6),
    ] {
        let scene = Arc::new(Scene::load(data_dir().join(file), Timing::Auto).unwrap());
        for model in meetings {
            let scenario = Scenario::pedestrians_loaded(scene.clone())
                .duration(120.0)
                .mix_distance(1.0)
                .meetings(model)
                .tracker_reports(true)
                .seed(seed);
            let trace = scenario.generate().unwrap();
            let simulated: Vec<Sensed> = trace
                .events
                .iter()
                .filter_map(|e| match e.event {
                    SimEvent::Mix { a, b, swap, .. } => Some(Sensed::Mix {
                        time: e.time,
                        a,
                        b,
                        swap,
                    }),
                    SimEvent::Observe { track, red, blue } => Some(Sensed::Observe {
                        time: e.time,
                        track,
                        red_share: red / (red + blue),
                    }),
                    _ => None,
                })
                .collect();
            let stats = trace.stats();
            assert!(stats.mixes > 10, "{file}: the scene should mix");
            assert!(stats.observations > 10, "{file}: the scene should be seen");
            if model != MeetingModel::Constant(0.0) {
                assert!(
                    stats.exchanges > 0,
                    "{file} {model:?}: swaps should be drawn"
                );
            }

            let n = trace.header.tracks as u32;
            let config = scenario.extraction_params().extractor_config();
            let mut extractor =
                Extractor::new(config, RosterPolicy::Declared((0..n).collect())).unwrap();
            let mut out = Vec::new();
            for report in trace.reports.clone().unwrap() {
                extractor.push(report, &mut out).unwrap();
            }
            extractor.finish(&mut out);
            let extracted: Vec<Sensed> = out
                .iter()
                .filter_map(|l| match l {
                    Line::Mix(m) => Some(Sensed::Mix {
                        time: m.time,
                        a: m.a,
                        b: m.b,
                        swap: m.swap,
                    }),
                    Line::Observe(o) => Some(Sensed::Observe {
                        time: o.time,
                        track: o.track,
                        red_share: o.red / (o.red + o.blue),
                    }),
                    _ => None,
                })
                .collect();
            if let Err(e) = close(&extracted, &simulated) {
                panic!("{file} with {model:?}: {e}");
            }
            for m in extractor.take_meetings() {
                assert!(m.distance <= scenario.extraction_params().mix_distance);
            }
        }
    }
}
