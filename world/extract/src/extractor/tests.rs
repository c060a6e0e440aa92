//! The extractor on small hand-made streams: meetings, release, the
//! meeting model, observations from scores, identity reads, every refused
//! report by name, snapshot and restore, merged order.

use super::*;
use crate::meetings::MeetingModel;
use idmesh_protocol::trace::{TraceWriter, Validator};
use std::collections::BTreeMap;

fn config() -> ExtractorConfig {
    ExtractorConfig {
        move_interval: None,
        ..Default::default()
    }
}

fn scored(time: f64, track: u32, x: f64, y: f64, red: f64) -> Report {
    Report {
        scores: Some(BTreeMap::from([
            ("red".to_string(), red),
            ("blue".to_string(), 1.0 - red),
        ])),
        ..Report::at(time, track, x, y)
    }
}

/// Runs `reports` through a fresh extractor; every line out, checked by
/// the trace format's validator.
fn run(config: ExtractorConfig, policy: RosterPolicy, reports: &[Report]) -> Vec<Line> {
    let mut x = Extractor::new(config, policy).unwrap();
    let mut out = Vec::new();
    for r in reports {
        x.push(r.clone(), &mut out).unwrap();
    }
    x.finish(&mut out);
    let mut validator = Validator::new();
    for (i, line) in out.iter().enumerate() {
        validator.check(line, i + 1).unwrap();
    }
    out
}

fn mixes(lines: &[Line]) -> Vec<(f64, u32, u32, f64)> {
    lines
        .iter()
        .filter_map(|l| match l {
            Line::Mix(m) => Some((m.time, m.a, m.b, m.swap)),
            _ => None,
        })
        .collect()
}

/// Two walkers on the x axis: b at distance `gaps[i]` from a at time i.
fn pair(gaps: &[f64]) -> Vec<Report> {
    gaps.iter()
        .enumerate()
        .flat_map(|(i, &gap)| {
            let t = i as f64;
            [Report::at(t, 10, 0.0, 0.0), Report::at(t, 20, gap, 0.0)]
        })
        .collect()
}

#[test]
fn one_meeting_is_one_mix_until_released() {
    // Mix at 1 m, release at 1.25 m: in at t=1, hovering (1.1, 0.8) is the
    // same meeting, out past 1.25 at t=4, in again at t=5.
    let lines = run(
        config(),
        RosterPolicy::FirstFrame,
        &pair(&[3.0, 0.9, 1.1, 0.8, 1.3, 0.5, 0.5]),
    );
    assert_eq!(mixes(&lines), vec![(1.0, 0, 1, 0.5), (5.0, 0, 1, 0.5)]);
    let Line::Header(h) = &lines[0] else {
        panic!("{:?}", lines[0])
    };
    assert_eq!((h.version, h.tracks), (2, 2));
}

#[test]
fn the_release_distance_is_the_mix_distance_times_the_factor() {
    let wide = ExtractorConfig {
        release_factor: 2.0,
        ..config()
    };
    // 1.3 m no longer releases (release at 2 m); 2.1 m does.
    let gaps = [3.0, 0.9, 1.3, 0.9, 2.1, 0.9];
    assert_eq!(
        mixes(&run(wide, RosterPolicy::FirstFrame, &pair(&gaps))),
        vec![(1.0, 0, 1, 0.5), (5.0, 0, 1, 0.5)]
    );
}

#[test]
fn the_meeting_model_sees_closest_distance_and_speed() {
    let model = MeetingModel::Approach {
        p_max: 0.5,
        sigma: 0.5,
        v0: 1.0,
    };
    let c = ExtractorConfig {
        meeting_model: model,
        ..config()
    };
    // b walks towards a at 1.1 m/s along y = 0.3: closest approach 0.3 m.
    let reports: Vec<Report> = [2.0, 0.9, 0.0]
        .iter()
        .enumerate()
        .flat_map(|(i, &x)| {
            let t = i as f64;
            [Report::at(t, 0, 0.0, 0.0), Report::at(t, 1, x, 0.3)]
        })
        .collect();
    let mut x = Extractor::new(c.clone(), RosterPolicy::FirstFrame).unwrap();
    let mut out = Vec::new();
    for r in reports {
        x.push(r, &mut out).unwrap();
    }
    x.finish(&mut out);
    let meetings = x.take_meetings();
    assert_eq!(meetings.len(), 1);
    let m = meetings[0];
    assert_eq!(m.time, 1.0);
    assert!((m.closest - 0.3).abs() < 1e-12 && (m.relative_speed - 1.1).abs() < 1e-12);
    assert!((m.distance - 0.9f64.sqrt()).abs() < 1e-12);
    assert_eq!(mixes(&out), vec![(1.0, 0, 1, model.swap(&m))]);
}

#[test]
fn isolated_tracks_with_scores_are_observed_at_a_limited_rate() {
    let c = ExtractorConfig {
        observe_interval: 2.0,
        ..config()
    };
    let mut reports = Vec::new();
    for t in 0..5 {
        let t = t as f64;
        reports.push(scored(t, 0, 0.0, 0.0, 0.8));
        // Track 1 is isolated too but has no scores until t = 3: it is not
        // looked at before, and its first look is at 3, not used up.
        if t >= 3.0 {
            reports.push(scored(t, 1, 50.0, 0.0, 0.3));
        } else {
            reports.push(Report::at(t, 1, 50.0, 0.0));
        }
    }
    let lines = run(c, RosterPolicy::FirstFrame, &reports);
    let observed: Vec<(f64, u32)> = lines
        .iter()
        .filter_map(|l| match l {
            Line::Observe(o) => Some((o.time, o.track)),
            _ => None,
        })
        .collect();
    assert_eq!(observed, vec![(0.0, 0), (2.0, 0), (3.0, 1), (4.0, 0)]);
    let Some(Line::Observe(o)) = lines.iter().find(|l| matches!(l, Line::Observe(_))) else {
        panic!()
    };
    assert!((o.red - 0.8).abs() < 1e-12 && (o.blue - 0.2).abs() < 1e-12);
}

#[test]
fn identity_reads_become_identify_lines_and_moves_follow_their_interval() {
    let c = ExtractorConfig {
        identities: true,
        move_interval: Some(2.0),
        ..config()
    };
    let mut reports = pair(&[5.0, 5.0, 5.0]);
    reports[3].identity = Some(IdentityRead {
        identity: 0,
        accuracy: 0.9,
    });
    let lines = run(c, RosterPolicy::Declared(vec![10, 20]), &reports);
    let kinds: Vec<&str> = lines.iter().map(Line::kind).collect();
    assert_eq!(
        kinds,
        ["header", "move", "move", "identify", "move", "move"]
    );
    let Line::Identify(i) = &lines[3] else {
        panic!()
    };
    assert_eq!((i.time, i.track, i.identity), (1.0, 1, 0));
}

#[test]
fn every_refused_report_is_named_and_changes_nothing() {
    let mut x = Extractor::new(config(), RosterPolicy::FirstFrame).unwrap();
    let mut out = Vec::new();
    for r in pair(&[3.0, 3.0]) {
        x.push(r, &mut out).unwrap();
    }
    let before = x.snapshot();
    let bad_sum = Report {
        scores: Some(BTreeMap::from([
            ("red".to_string(), 0.5),
            ("blue".to_string(), 0.2),
        ])),
        ..Report::at(2.0, 10, 0.0, 0.0)
    };
    let read = |identity, accuracy| Report {
        identity: Some(IdentityRead { identity, accuracy }),
        ..Report::at(2.0, 10, 0.0, 0.0)
    };
    let cases: Vec<(Report, &str, &str)> = vec![
        (Report::at(0.5, 10, 0.0, 0.0), "out of time order", "time 0.5 is before time 1 of an earlier report: reports must come in time order"),
        (Report::at(2.0, 10, f64::NAN, 0.0), "non-finite position", "position x = NaN is not a finite number"),
        (Report::at(f64::INFINITY, 10, 0.0, 0.0), "non-finite time", "time inf is not a finite number"),
        (Report::at(2.0, 30, 0.0, 0.0), "unknown track", "track 30 is not in the roster of 2 tracks fixed by the first frame: a track that appears mid-stream is refused"),
        (Report::at(1.0, 10, 0.0, 0.0), "duplicate track", "track 10 is reported twice at time 1"),
        (bad_sum, "bad scores", "detect: scores sum to 0.7, not 1 (tolerance 0.01)"),
        (read(0, 0.9), "bad identity read", "an identity read needs identities: turn them on in the extractor's configuration"),
    ];
    for (report, reason, message) in cases {
        let e = x.push(report, &mut out).unwrap_err();
        assert_eq!((e.reason(), e.to_string().as_str()), (reason, message));
        assert_eq!(x.snapshot(), before, "{reason} changed the state");
    }
    let mut with_ids = Extractor::new(
        ExtractorConfig {
            identities: true,
            ..config()
        },
        RosterPolicy::Declared(vec![10, 20]),
    )
    .unwrap();
    assert_eq!(
        with_ids
            .push(read(2, 0.9), &mut out)
            .unwrap_err()
            .to_string(),
        "identity read 2 is not one of the 2 identities (one per track)"
    );
    // Before the first frame fixes the roster, a read must name one of
    // the tracks seen so far.
    let mut first = Extractor::new(
        ExtractorConfig {
            identities: true,
            ..config()
        },
        RosterPolicy::FirstFrame,
    )
    .unwrap();
    assert_eq!(
        first.push(read(1, 0.9), &mut out).unwrap_err().to_string(),
        "identity read 1 is not one of the 1 identities (one per track)"
    );
    assert_eq!(
        with_ids.push(read(1, 0.0), &mut out).unwrap_err().reason(),
        "bad identity read"
    );
    assert_eq!(
        with_ids.push(Report::at(0.0, 11, 0.0, 0.0), &mut out).unwrap_err().to_string(),
        "track 11 is not in the roster of 2 tracks fixed by declaration: a track that appears mid-stream is refused"
    );
}

/// A crowd of 6 walking across each other, with scores and reads.
fn crowd() -> Vec<Report> {
    let mut reports = Vec::new();
    for step in 0..200 {
        let t = step as f64 * 0.1;
        for id in 0..6u32 {
            let phase = id as f64;
            let x = 5.0 * (0.3 * t + phase).sin() + id as f64 * 0.2;
            let y = 3.0 * (0.2 * t + 2.0 * phase).cos();
            let mut r = scored(t, id * 3 + 1, x, y, if id % 2 == 0 { 0.7 } else { 0.25 });
            if step % 37 == id as usize {
                r.identity = Some(IdentityRead {
                    identity: id,
                    accuracy: 0.8,
                });
            }
            reports.push(r);
        }
    }
    reports
}

fn crowd_config() -> ExtractorConfig {
    ExtractorConfig {
        identities: true,
        observe_distance: 1.5,
        meeting_model: MeetingModel::Approach {
            p_max: 0.5,
            sigma: 0.4,
            v0: 1.0,
        },
        ..Default::default()
    }
}

#[test]
fn snapshot_and_restore_mid_stream_gives_identical_output() {
    let reports = crowd();
    let whole = run(crowd_config(), RosterPolicy::FirstFrame, &reports);
    assert!(mixes(&whole).len() > 3, "the crowd should meet");
    for cut in [1, 7, 600, 601, 1199] {
        let mut x = Extractor::new(crowd_config(), RosterPolicy::FirstFrame).unwrap();
        let mut out = Vec::new();
        for r in &reports[..cut] {
            x.push(r.clone(), &mut out).unwrap();
        }
        let snapshot = x.snapshot();
        drop(x);
        let mut y = Extractor::restore(&snapshot).unwrap();
        for r in &reports[cut..] {
            y.push(r.clone(), &mut out).unwrap();
        }
        y.finish(&mut out);
        assert_eq!(out, whole, "cut at {cut}");
    }
}

#[test]
fn reports_of_one_frame_in_any_order_give_the_same_events() {
    let reports = crowd();
    let whole = run(crowd_config(), RosterPolicy::FirstFrame, &reports);
    // Reverse the order within each frame (6 reports per frame).
    let shuffled: Vec<Report> = reports
        .chunks(6)
        .flat_map(|frame| frame.iter().rev().cloned())
        .collect();
    assert_eq!(
        run(crowd_config(), RosterPolicy::FirstFrame, &shuffled),
        whole
    );
}

#[test]
fn the_output_is_a_valid_version_2_trace() {
    let lines = run(crowd_config(), RosterPolicy::FirstFrame, &crowd());
    let mut writer = TraceWriter::new(Vec::new(), "out.jsonl");
    for line in &lines {
        writer.write(line).unwrap();
    }
}
