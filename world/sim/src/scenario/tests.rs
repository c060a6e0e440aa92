//! Whole-scenario tests: determinism, and every event of a generated trace
//! checked against an independent replay of its ground-truth motion.

use super::*;
use crate::events::{Assignment, SensorModel, SimEvent};
use crate::geometry::Vec2;
use crate::motion::pedestrians::{data_dir, Scene, Timing};
use idmesh_extract::MeetingModel;
use std::collections::BTreeMap;
use std::sync::Arc;

/// Replays `scenario`'s motion step by step next to `trace` and checks every
/// event, as a tracker sees it — each track where the target it follows was
/// at the start of the step: mixes are pairs of present tracks within the
/// mixing distance that were apart (beyond the release distance, or one
/// absent) since their last mix; observed tracks are present, isolated by
/// the observation distance and not observed twice within the interval; moves are the positions of
/// the targets the tracks follow; truth lines equal the initial red set
/// with every exchange applied. Returns how many observations reported
/// "red" for red and for blue targets: (red seen red, red total, blue seen
/// red, blue total).
fn check_against_motion(scenario: &Scenario, trace: &GeneratedTrace) -> [usize; 4] {
    let params = scenario.extraction_params().clone();
    let release = params.mix_distance * params.release_factor;
    let mut motion = scenario.motion().unwrap().motion;
    let n = motion.targets();
    let dt = motion.dt();
    assert_eq!(trace.header.tracks, n);
    assert_eq!(trace.true_initial_red.len(), trace.header.red);
    // Track t starts on target t, so the initial red tracks are the red targets.
    let mut target_red = vec![false; n];
    for &t in &trace.true_initial_red {
        target_red[t as usize] = true;
    }
    let mut assignment = Assignment::identity(n);
    let mut red_tracks: Vec<bool> = target_red.clone();
    // Per pair: has it been apart since its last mix?
    let mut armed: BTreeMap<(usize, usize), bool> = BTreeMap::new();
    let mut last_observed: Vec<f64> = vec![f64::NEG_INFINITY; n];
    let mut colour_counts = [0usize; 4];
    let mut step = 0u64;
    let mut positions: Vec<Option<Vec2>> = motion.positions().to_vec();
    let mut prev_time = 0.0;
    let mut truths = 0;

    let on_tracks = |assignment: &Assignment, pos: &[Option<Vec2>]| -> Vec<Option<Vec2>> {
        (0..pos.len())
            .map(|t| pos[assignment.target_on(t) as usize])
            .collect()
    };
    let mut tracks = on_tracks(&assignment, &positions);
    let update_armed = |armed: &mut BTreeMap<(usize, usize), bool>, pos: &[Option<Vec2>]| {
        for ((i, j), a) in armed.iter_mut() {
            let apart = match (pos[*i], pos[*j]) {
                (Some(p), Some(q)) => p.distance(q) > release,
                _ => true,
            };
            *a |= apart;
        }
    };

    for e in &trace.events {
        assert!(e.time >= prev_time - 1e-12, "time goes back at {}", e.time);
        prev_time = e.time;
        let want_step = (e.time / dt).round() as u64;
        assert!((want_step as f64 * dt - e.time).abs() < 1e-6);
        while step < want_step {
            assert!(motion.advance(), "trace runs past the motion");
            step += 1;
            positions.copy_from_slice(motion.positions());
            tracks = on_tracks(&assignment, &positions);
            update_armed(&mut armed, &tracks);
        }
        match &e.event {
            SimEvent::Mix {
                a,
                b,
                swap,
                exchanged,
            } => {
                assert_ne!(a, b);
                assert_eq!(MeetingModel::Constant(*swap), params.meetings);
                let i = assignment.target_on(*a as usize) as usize;
                let j = assignment.target_on(*b as usize) as usize;
                let (p, q) = (tracks[*a as usize].unwrap(), tracks[*b as usize].unwrap());
                let d = p.distance(q);
                assert!(
                    d <= params.mix_distance + 1e-12,
                    "mix of tracks {a},{b} at {} is {d} m apart",
                    e.time
                );
                let key = (*a.min(b) as usize, *a.max(b) as usize);
                let was_armed = armed.insert(key, false).unwrap_or(true);
                assert!(
                    was_armed,
                    "tracks {a},{b} mixed again at {} without separating",
                    e.time
                );
                if *exchanged {
                    assignment.exchange_targets(i, j);
                    red_tracks.swap(*a as usize, *b as usize);
                }
            }
            SimEvent::Observe { track, red, blue } => {
                let i = assignment.target_on(*track as usize) as usize;
                let t = *track as usize;
                let p = tracks[t].expect("observed track is present");
                for (u, q) in tracks.iter().enumerate() {
                    if let (true, Some(q)) = (u != t, q) {
                        assert!(
                            p.distance(*q) > params.observe_distance,
                            "observed track {t} at {} has track {u} at {} m",
                            e.time,
                            p.distance(*q)
                        );
                    }
                }
                assert!(
                    e.time >= last_observed[t] + params.observe_interval - 1e-9,
                    "track {t} observed twice within the interval at {}",
                    e.time
                );
                last_observed[t] = e.time;
                assert!(*red >= 0.0 && *blue >= 0.0 && red + blue > 0.0);
                let seen_red = red > blue;
                if target_red[i] {
                    colour_counts[0] += seen_red as usize;
                    colour_counts[1] += 1;
                } else {
                    colour_counts[2] += seen_red as usize;
                    colour_counts[3] += 1;
                }
                assert_eq!(red_tracks[*track as usize], target_red[i]);
            }
            SimEvent::Move { track, x, y } => {
                let i = assignment.target_on(*track as usize) as usize;
                assert_eq!(positions[i], Some(Vec2::new(*x, *y)));
            }
            SimEvent::Truth { red } => {
                truths += 1;
                assert_eq!(
                    red.len(),
                    trace.header.red,
                    "truth at {} has the wrong size",
                    e.time
                );
                let want: Vec<u32> = (0..n as u32).filter(|&t| red_tracks[t as usize]).collect();
                assert_eq!(red, &want, "truth at {}", e.time);
                assert!(red.windows(2).all(|w| w[0] < w[1]));
            }
        }
    }
    assert!(truths > 0);
    assert!(matches!(
        trace.events.last().unwrap().event,
        SimEvent::Truth { .. }
    ));
    colour_counts
}

fn eth() -> Arc<Scene> {
    Arc::new(Scene::load(data_dir().join("eth/obsmat/obsmat.txt"), Timing::Auto).unwrap())
}

#[test]
fn same_seed_same_trace_other_seed_other_trace() {
    for base in [
        Scenario::crowd().targets(30).duration(60.0),
        Scenario::waypoint().targets(30).duration(60.0),
        Scenario::pedestrians_loaded(eth()).duration(120.0),
    ] {
        let a = base.clone().seed(7).generate().unwrap();
        let b = base.clone().seed(7).generate().unwrap();
        let c = base.clone().seed(8).generate().unwrap();
        assert_eq!(a, b, "{}", base.model().name());
        assert_ne!(a.events, c.events, "{}", base.model().name());
        assert!(a.stats().mixes > 0 && a.stats().observations > 0);
    }
}

#[test]
fn crowd_events_match_the_motion() {
    let s = Scenario::crowd().targets(40).duration(120.0).seed(3);
    let trace = s.generate().unwrap();
    let st = trace.stats();
    assert!(st.mixes > 100 && st.observations > 100, "{st:?}");
    let [rr, rt, br, bt] = check_against_motion(&s, &trace);
    // The colour histogram: a red target is seen red 8/9 of the time it is
    // reported, a blue one 2/9 — only if observations land on the right track.
    let red_rate = rr as f64 / rt as f64;
    let blue_rate = br as f64 / bt as f64;
    assert!((red_rate - 8.0 / 9.0).abs() < 0.06, "{red_rate}");
    assert!((blue_rate - 2.0 / 9.0).abs() < 0.06, "{blue_rate}");
}

#[test]
fn waypoint_events_match_the_motion() {
    let s = Scenario::waypoint()
        .targets(25)
        .red(5)
        .duration(120.0)
        .swap(0.3)
        .seed(4);
    let trace = s.generate().unwrap();
    assert_eq!(trace.header.red, 5);
    check_against_motion(&s, &trace);
}

#[test]
fn pedestrian_events_match_the_motion() {
    let s = Scenario::pedestrians_loaded(eth())
        .start(100.0)
        .duration(200.0)
        .mix_distance(1.5)
        .seed(5);
    let trace = s.generate().unwrap();
    let st = trace.stats();
    assert!(st.mixes > 10 && st.observations > 10, "{st:?}");
    check_against_motion(&s, &trace);
    // Capped: the run ends before the 31st arrival.
    let capped = Scenario::pedestrians_loaded(eth()).targets(30).seed(5);
    let trace = capped.generate().unwrap();
    assert!(trace.header.tracks <= 30 && trace.header.tracks >= 25);
    check_against_motion(&capped, &trace);
}

#[test]
fn truth_follows_the_swaps_under_many_options() {
    let s = Scenario::crowd()
        .targets(12)
        .red_tracks(vec![1, 4, 5])
        .duration(90.0)
        .swap(0.9)
        .mix_distance(1.5)
        .observe_distance(2.0)
        .observe_interval(0.0)
        .sensor(SensorModel::symmetric(0.95).unwrap())
        .truth_interval(0.7)
        .move_interval(None)
        .reveal_initial_red(false)
        .seed(11);
    let trace = s.generate().unwrap();
    assert_eq!(trace.true_initial_red, vec![1, 4, 5]);
    assert_eq!(trace.header.initial_red, None);
    assert_eq!(trace.stats().moves, 0);
    // Truth every 0.7 s after 0, and at the end (90 s).
    assert_eq!(trace.stats().truths, 128 + 1);
    assert!(trace.stats().exchanges > 0);
    check_against_motion(&s, &trace);
}

#[test]
fn a_run_of_a_number_of_events() {
    let s = Scenario::crowd().targets(20).events(500).seed(2);
    let trace = s.generate().unwrap();
    assert_eq!(trace.sensing_events().count(), 500);
    check_against_motion(&s, &trace);
    let last_sensing = trace.sensing_events().last().unwrap().time;
    assert_eq!(trace.events.last().unwrap().time, last_sensing);
    assert_eq!(trace.duration, last_sensing);
    // A scene too short for the request is an error, not a short trace.
    let err = Scenario::pedestrians_loaded(eth())
        .events(1_000_000)
        .generate()
        .unwrap_err();
    assert!(
        matches!(err, ScenarioError::TooFewEvents { ended: true, .. }),
        "{err}"
    );
}

#[test]
fn mixing_share_grows_with_the_mixing_distance() {
    let mut shares = Vec::new();
    for d in [0.5, 1.0, 1.5, 2.0, 3.0] {
        let t = Scenario::crowd()
            .targets(40)
            .duration(120.0)
            .mix_distance(d)
            .seed(1)
            .generate()
            .unwrap();
        shares.push(t.stats().mix_share);
    }
    assert!(shares.windows(2).all(|w| w[0] < w[1]), "{shares:?}");
    assert!(shares[0] < 0.4 && shares[4] > 0.6, "{shares:?}");
    // And falls as observations get easier (shorter isolation distance).
    let share_at = |obs: f64| {
        Scenario::crowd()
            .targets(40)
            .duration(120.0)
            .observe_distance(obs)
            .seed(1)
            .generate()
            .unwrap()
            .stats()
            .mix_share
    };
    assert!(share_at(2.0) < share_at(3.5) && share_at(3.5) < share_at(5.0));
}

#[test]
fn defaults_give_about_half_mixes() {
    let t = Scenario::crowd().targets(60).seed(1).generate().unwrap();
    let st = t.stats();
    assert!((0.4..0.6).contains(&st.mix_share), "{st:?}");
    assert_eq!(t.header.tracks, 60);
    assert_eq!(t.header.red, 30);
    assert_eq!(t.header.initial_red.as_ref(), Some(&t.true_initial_red));
    assert!((t.duration - 300.0).abs() < 1e-9);
    assert_eq!(st.truths, 300);
    assert_eq!(st.moves, 60 * 301);
    // Swaps happen about as often as the swap probability says.
    let rate = st.exchanges as f64 / st.mixes as f64;
    assert!((rate - 0.5).abs() < 0.05, "{rate}");
}

#[test]
fn progress_reaches_the_total() {
    let mut calls: Vec<(u64, u64)> = Vec::new();
    Scenario::crowd()
        .targets(10)
        .duration(50.0)
        .generate_with_progress(&mut |d, t| calls.push((d, t)))
        .unwrap();
    assert_eq!(calls.last(), Some(&(500, 500)));
    assert!(calls
        .windows(2)
        .all(|w| w[0].0 < w[1].0 && w[0].1 == w[1].1));
    let mut last = None;
    Scenario::crowd()
        .targets(10)
        .events(100)
        .generate_with_progress(&mut |d, t| last = Some((d, t)))
        .unwrap();
    assert_eq!(last, Some((100, 100)));
}

#[test]
fn invalid_options_are_rejected() {
    let invalid = |s: Scenario| match s.generate() {
        Err(ScenarioError::Invalid(m)) => m,
        other => panic!("expected an invalid scenario, got {other:?}"),
    };
    assert!(invalid(Scenario::crowd().targets(4).red(5)).contains("5 red targets"));
    assert!(invalid(Scenario::crowd().targets(4).red_tracks(vec![1, 1])).contains("twice"));
    assert!(invalid(Scenario::crowd().targets(4).red_tracks(vec![4])).contains("out of range"));
    assert!(invalid(Scenario::crowd().mix_distance(0.0)).contains("mixing distance"));
    assert!(invalid(Scenario::crowd().swap(1.5)).contains("swap"));
    assert!(invalid(Scenario::crowd().targets(0)).contains("at least one"));
    assert!(invalid(Scenario::waypoint().dt(-1.0)).contains("dt"));
    assert!(invalid(Scenario::crowd().field(0.0, 5.0)).contains("field"));
    let scene = Scenario::pedestrians(data_dir().join("univ/students001.txt"))
        .targets(20)
        .generate()
        .unwrap_err();
    assert!(
        scene.to_string().contains("people are present at 0 s"),
        "{scene}"
    );
    let missing = Scenario::pedestrians("/nonexistent/scene.txt")
        .generate()
        .unwrap_err();
    assert!(
        missing.to_string().starts_with("/nonexistent/scene.txt: "),
        "{missing}"
    );
}
