//! The simulator is the extractor plus drawn swaps: on the positions of a
//! real pedestrian scene, `simulate --model pedestrians` and
//! `idmesh-extract`'s [`Extractor`] fed those positions as a tracker's
//! reports find the same mixes — same pairs, same times — and the
//! extractor's meeting distances are the distances of those positions.

use super::Scenario;
use crate::events::SimEvent;
use crate::geometry::Vec2;
use crate::motion::pedestrians::{data_dir, Scene, Timing};
use idmesh_extract::{Extractor, ExtractorConfig, MeetingModel, Report, RosterPolicy};
use idmesh_protocol::trace::Line;
use std::sync::Arc;

#[test]
fn simulate_pedestrians_and_extract_agree_on_every_mix() {
    let scene = Scene::load(data_dir().join("zara01/obsmat/obsmat.txt"), Timing::Auto).unwrap();
    // Swap 0: every track keeps its target, so the simulator's tracks are
    // the targets the extractor is told about.
    let scenario = Scenario::pedestrians_loaded(Arc::new(scene))
        .duration(90.0)
        .swap(0.0)
        .seed(4);
    let trace = scenario.generate().unwrap();
    let simulated: Vec<(f64, u32, u32)> = trace
        .events
        .iter()
        .filter_map(|e| match e.event {
            SimEvent::Mix { a, b, .. } => Some((e.time, a, b)),
            _ => None,
        })
        .collect();
    assert!(simulated.len() > 10, "the scene should mix: {simulated:?}");

    let params = scenario.extraction_params().clone();
    let config = ExtractorConfig {
        mix_distance: params.mix_distance,
        release_factor: params.release_factor,
        observe_distance: params.observe_distance,
        observe_interval: params.observe_interval,
        meeting_model: MeetingModel::Constant(0.0),
        move_interval: None,
        ..Default::default()
    };
    let mut motion = scenario.motion().unwrap().motion;
    let n = motion.targets() as u32;
    let mut extractor = Extractor::new(config, RosterPolicy::Declared((0..n).collect())).unwrap();
    let mut out = Vec::new();
    let mut frames: Vec<(f64, Vec<Option<Vec2>>)> = Vec::new();
    let dt = motion.dt();
    let mut step = 0u64;
    loop {
        // The simulator's step times (rounded to the nanosecond).
        let time = (step as f64 * dt * 1e9).round() / 1e9;
        for (target, p) in motion.positions().iter().enumerate() {
            if let Some(p) = p {
                extractor
                    .push(Report::at(time, target as u32, p.x, p.y), &mut out)
                    .unwrap();
            }
        }
        frames.push((time, motion.positions().to_vec()));
        if time >= trace.duration - 1e-9 || !motion.advance() {
            break;
        }
        step += 1;
    }
    extractor.finish(&mut out);
    let extracted: Vec<(f64, u32, u32)> = out
        .iter()
        .filter_map(|l| match l {
            Line::Mix(m) => Some((m.time, m.a, m.b)),
            _ => None,
        })
        .collect();
    assert_eq!(extracted, simulated);
    let meetings = extractor.take_meetings();
    assert_eq!(meetings.len(), simulated.len());
    for m in meetings {
        let (_, positions) = frames.iter().find(|(t, _)| *t == m.time).unwrap();
        let (pa, pb) = (
            positions[m.a as usize].unwrap(),
            positions[m.b as usize].unwrap(),
        );
        let distance = (pb - pa).norm();
        assert!((m.distance - distance).abs() < 1e-12);
        assert!(m.distance <= params.mix_distance);
    }
}
