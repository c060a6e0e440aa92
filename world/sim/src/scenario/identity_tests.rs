//! Identity traces: determinism, every read checked against an independent
//! replay of the ground-truth motion, truth identities against the swaps,
//! the read model's frequencies, and the written trace.

use super::identity::IdentityRead;
use super::trace_out::{lines, write_trace};
use super::*;
use crate::events::{Assignment, SimEvent, TimedEvent};
use crate::geometry::Vec2;
use crate::motion::pedestrians::{data_dir, Scene, Timing};
use idmesh_protocol::trace::{Line, TraceReader};
use std::sync::Arc;

/// One event of a generated identity trace, in trace order.
#[derive(Debug, Clone, Copy)]
enum Item<'a> {
    Event(&'a TimedEvent),
    Read(&'a IdentityRead),
}

/// The events and reads of `trace` in the documented order: by time, and
/// within a time moves, mixes, observations, reads, truth (a stable sort,
/// independent of [`super::identity_out`]).
fn merged(trace: &GeneratedTrace) -> Vec<Item<'_>> {
    let rank = |item: &Item| match item {
        Item::Event(e) => match e.event {
            SimEvent::Move { .. } => 0,
            SimEvent::Mix { .. } => 1,
            SimEvent::Observe { .. } => 2,
            SimEvent::Truth { .. } => 4,
        },
        Item::Read(_) => 3,
    };
    let time = |item: &Item| match item {
        Item::Event(e) => e.time,
        Item::Read(r) => r.time,
    };
    let mut items: Vec<Item> = trace.events.iter().map(Item::Event).collect();
    items.extend(
        trace
            .identity
            .as_ref()
            .unwrap()
            .reads
            .iter()
            .map(Item::Read),
    );
    items.sort_by(|x, y| {
        time(x)
            .partial_cmp(&time(y))
            .unwrap()
            .then(rank(x).cmp(&rank(y)))
    });
    items
}

/// Replays `scenario`'s motion beside `trace` and checks every read: its
/// track follows the target it names, the target is present and isolated
/// by the observation distance, is read at most once per interval, and the
/// read is right exactly when it names the target's identity. Checks every
/// truth identity against the initial identities with the exchanges
/// applied. Returns (reads, right reads).
fn check_reads_against_motion(scenario: &Scenario, trace: &GeneratedTrace) -> (usize, usize) {
    let params = scenario.extraction_params().clone();
    let id = trace.identity.as_ref().expect("an identity trace");
    let mut motion = scenario.motion().unwrap().motion;
    let n = motion.targets();
    let dt = motion.dt();
    assert_eq!(id.target_identity.len(), n);
    assert_eq!(id.initial, id.target_identity);
    let mut sorted = id.target_identity.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, (0..n as u32).collect::<Vec<_>>());
    let mut assignment = Assignment::identity(n);
    // identity_on[t]: replayed from the initial identities by the swaps.
    let mut identity_on = id.initial.clone();
    let mut last_read = vec![f64::NEG_INFINITY; n];
    let mut positions: Vec<Option<Vec2>> = motion.positions().to_vec();
    let mut step = 0u64;
    let (mut reads, mut right) = (0, 0);
    for item in merged(trace) {
        let time = match item {
            Item::Event(e) => e.time,
            Item::Read(r) => r.time,
        };
        let want_step = (time / dt).round() as u64;
        while step < want_step {
            assert!(motion.advance(), "trace runs past the motion");
            step += 1;
            positions.copy_from_slice(motion.positions());
        }
        match item {
            Item::Event(e) => match &e.event {
                SimEvent::Mix {
                    a,
                    b,
                    exchanged: true,
                    ..
                } => {
                    let i = assignment.target_on(*a as usize) as usize;
                    let j = assignment.target_on(*b as usize) as usize;
                    assignment.exchange_targets(i, j);
                    identity_on.swap(*a as usize, *b as usize);
                }
                SimEvent::Truth { .. } => {
                    // The replayed identities are those of the followed targets.
                    for (t, &i) in identity_on.iter().enumerate() {
                        let target = assignment.target_on(t) as usize;
                        assert_eq!(i, id.target_identity[target]);
                    }
                }
                _ => {}
            },
            Item::Read(r) => {
                reads += 1;
                let i = r.target as usize;
                assert_eq!(
                    assignment.target_on(r.track as usize),
                    r.target,
                    "read at {} is on the wrong track",
                    r.time
                );
                let p = positions[i].expect("a read target is present");
                for (j, q) in positions.iter().enumerate() {
                    if let (true, Some(q)) = (j != i, q) {
                        assert!(
                            p.distance(*q) > params.observe_distance,
                            "target {i} read at {} has target {j} {} m away",
                            r.time,
                            p.distance(*q)
                        );
                    }
                }
                assert!(
                    r.time >= last_read[i] + params.observe_interval - 1e-9,
                    "target {i} read twice within the interval at {}",
                    r.time
                );
                last_read[i] = r.time;
                assert!((r.identity as usize) < n);
                assert_eq!(r.correct, r.identity == id.target_identity[i]);
                right += r.correct as usize;
            }
        }
    }
    (reads, right)
}

#[test]
fn identities_add_lines_and_change_no_other_event() {
    let base = Scenario::crowd().targets(15).duration(60.0).seed(4);
    let plain = base.clone().generate().unwrap();
    let with = base.clone().identities(true).generate().unwrap();
    assert_eq!(plain.identity, None);
    assert_eq!(plain.events, with.events);
    assert_eq!(plain.true_initial_red, with.true_initial_red);
    let id = with.identity.as_ref().unwrap();
    assert!(id.reads.len() > 20, "{}", id.reads.len());
    assert_eq!(id.accuracy, 0.9);
    // Same seed, same trace; another seed, other identities and reads.
    assert_eq!(with, base.clone().identities(true).generate().unwrap());
    let other = base.clone().identities(true).seed(5).generate().unwrap();
    assert_ne!(other.identity.unwrap().reads, id.reads);
    // A plain trace writes exactly as before: no identity anywhere.
    let text = String::from_utf8(write_trace(&plain, Vec::new(), "p.jsonl").unwrap()).unwrap();
    assert!(!text.contains("identit"));
}

#[test]
fn crowd_reads_match_the_motion() {
    let s = Scenario::crowd()
        .targets(30)
        .duration(120.0)
        .identities(true)
        .seed(3);
    let trace = s.generate().unwrap();
    assert!(trace.stats().exchanges > 10);
    let (reads, right) = check_reads_against_motion(&s, &trace);
    assert!(reads > 200, "{reads}");
    let rate = right as f64 / reads as f64;
    assert!((rate - 0.9).abs() < 0.05, "{rate}");
}

#[test]
fn pedestrian_reads_match_the_motion() {
    // People arrive and leave: absent targets are never read.
    let scene =
        Arc::new(Scene::load(data_dir().join("eth/obsmat/obsmat.txt"), Timing::Auto).unwrap());
    let s = Scenario::pedestrians_loaded(scene)
        .start(100.0)
        .duration(150.0)
        .identities(true)
        .identity_accuracy(0.7)
        .seed(2);
    let trace = s.generate().unwrap();
    let (reads, right) = check_reads_against_motion(&s, &trace);
    assert!(reads > 20, "{reads}");
    let rate = right as f64 / reads as f64;
    assert!((rate - 0.7).abs() < 0.12, "{rate}");
}

#[test]
fn waypoint_truth_identities_follow_the_swaps() {
    let s = Scenario::waypoint()
        .targets(10)
        .duration(120.0)
        .swap(0.8)
        .mix_distance(1.5)
        .truth_interval(0.5)
        .identities(true)
        .seed(8);
    let trace = s.generate().unwrap();
    assert!(trace.stats().exchanges > 5);
    check_reads_against_motion(&s, &trace);
    // The written truth lines: identity[t] = initial with the exchanges applied.
    let id = trace.identity.as_ref().unwrap();
    let mut current = id.initial.clone();
    let mut truths = trace
        .events
        .iter()
        .filter_map(|e| match &e.event {
            SimEvent::Mix {
                a,
                b,
                exchanged: true,
                ..
            } => {
                current.swap(*a as usize, *b as usize);
                None
            }
            SimEvent::Truth { .. } => Some(current.clone()),
            _ => None,
        })
        .collect::<Vec<_>>()
        .into_iter();
    let mut changed = false;
    for line in lines(&trace) {
        if let Line::Truth(t) = line {
            let want = truths.next().unwrap();
            changed |= want != id.initial;
            assert_eq!(t.identity.as_ref(), Some(&want));
            assert!(t.red.is_some());
        }
    }
    assert!(truths.next().is_none());
    assert!(changed, "some swap should move an identity");
}

#[test]
fn wrong_reads_spread_evenly_over_the_other_identities() {
    // 4 identities, accuracy 0.4: each wrong identity gets 0.2 of the reads
    // of a target.
    let trace = Scenario::crowd()
        .targets(4)
        .field(40.0, 40.0)
        .duration(600.0)
        .observe_interval(0.0)
        .identities(true)
        .identity_accuracy(0.4)
        .move_interval(None)
        .seed(6)
        .generate()
        .unwrap();
    let id = trace.identity.as_ref().unwrap();
    let mut counts = [[0usize; 4]; 4];
    for r in &id.reads {
        counts[id.target_identity[r.target as usize] as usize][r.identity as usize] += 1;
    }
    for (truth, row) in counts.iter().enumerate() {
        let total: usize = row.iter().sum();
        assert!(total > 1000, "{counts:?}");
        for (read, &c) in row.iter().enumerate() {
            let share = c as f64 / total as f64;
            let want = if read == truth { 0.4 } else { 0.2 };
            assert!((share - want).abs() < 0.03, "{truth}->{read}: {share}");
        }
    }
}

#[test]
fn written_identity_trace_reads_back() {
    let s = Scenario::crowd()
        .targets(8)
        .duration(40.0)
        .identities(true)
        .seed(1);
    let trace = s.generate().unwrap();
    let bytes = write_trace(&trace, Vec::new(), "id.jsonl").unwrap();
    let text = String::from_utf8(bytes).unwrap();
    let read: Vec<Line> = TraceReader::new(text.as_bytes(), "id.jsonl")
        .map(|l| l.unwrap().line)
        .collect();
    let written: Vec<Line> = lines(&trace).collect();
    assert_eq!(read, written);
    let id = trace.identity.as_ref().unwrap();
    assert_eq!(read.len(), 1 + trace.events.len() + id.reads.len());
    let Line::Header(header) = &read[0] else {
        panic!("header first")
    };
    assert_eq!(header.identities, Some(8));
    assert_eq!(header.initial_identity.as_ref(), Some(&id.initial));
    assert!(trace.header.description.contains("identities read"));
    // The identify lines are the reads, in order, with the accuracy.
    let identifies: Vec<_> = read
        .iter()
        .filter_map(|l| match l {
            Line::Identify(i) => Some(*i),
            _ => None,
        })
        .collect();
    assert_eq!(identifies.len(), id.reads.len());
    for (line, r) in identifies.iter().zip(&id.reads) {
        assert_eq!(
            (line.time, line.track, line.identity, line.accuracy),
            (r.time, r.track, r.identity, 0.9)
        );
    }
    // Within a time: moves, mixes, observations, reads, truth.
    let rank = |l: &Line| match l {
        Line::Move(_) => 0,
        Line::Mix(_) => 1,
        Line::Observe(_) => 2,
        Line::Identify(_) => 3,
        Line::Truth(_) => 4,
        Line::Header(_) | Line::Detect(_) => unreachable!(),
    };
    for pair in read[1..].windows(2) {
        let (t0, t1) = (pair[0].time().unwrap(), pair[1].time().unwrap());
        assert!(t0 < t1 || (t0 == t1 && rank(&pair[0]) <= rank(&pair[1])));
    }
    assert!(text.contains(r#""kind":"identify","time":"#));
    assert!(text.contains(r#","identity":["#));
    // Hidden initial identities: no `initial_identity`, the rest the same.
    let hidden = s.clone().reveal_initial_identity(false).generate().unwrap();
    let Line::Header(h) = lines(&hidden).next().unwrap() else {
        panic!()
    };
    assert_eq!((h.identities, h.initial_identity), (Some(8), None));
    assert_eq!(hidden.identity.as_ref().unwrap().reads, id.reads);
}

#[test]
fn bad_accuracy_is_refused() {
    for bad in [0.0, -0.5, 1.5, f64::NAN] {
        match Scenario::crowd()
            .targets(4)
            .identities(true)
            .identity_accuracy(bad)
            .generate()
        {
            Err(ScenarioError::Invalid(m)) => assert!(m.contains("accuracy"), "{m}"),
            other => panic!("expected an invalid scenario, got {other:?}"),
        }
    }
    // A perfect reader is allowed and always right.
    let t = Scenario::crowd()
        .targets(6)
        .duration(30.0)
        .identities(true)
        .identity_accuracy(1.0)
        .generate()
        .unwrap();
    let id = t.identity.unwrap();
    assert!(!id.reads.is_empty());
    assert_eq!(id.correct_reads(), id.reads.len());
}
