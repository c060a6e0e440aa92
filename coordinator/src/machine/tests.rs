//! The gathering of one query, fed replies by hand: good, missing, late,
//! of another tag, that do not decode, that do not fit the field.

use super::*;
use idmesh_protocol::wire::factored::WireCounts;
use idmesh_protocol::wire::{encode, VERSION};

fn cut(seq: u64, leaders: &[&str]) -> CutPlaced {
    CutPlaced {
        version: VERSION,
        epoch: 0,
        sensor: "sensor-0".into(),
        seq,
        events: seq * 2,
        leaders: leaders.iter().map(|l| l.to_string()).collect(),
        tracks: 3,
        red: Some(1),
        finished: false,
        identities: false,
        origins: Vec::new(),
    }
}

/// A leader's share: `total` with track `t` fixing `inside`.
fn part(leader: &str, cut: u64, tag: u64, total: f64, inside: Vec<(u32, f64)>) -> Partial {
    Partial {
        epoch: 0,
        trees: Vec::new(),
        base: None,
        gone: Vec::new(),
        passive: Vec::new(),
        components: None,
        version: VERSION,
        leader: leader.into(),
        cut,
        tag,
        events: cut * 2,
        finished: false,
        log_scale: 0.0,
        total,
        outside: total / 3.0,
        inside,
        coefficients: 1,
        rows: Vec::new(),
    }
}

fn gather(tag: u64, replies: Vec<Result<Vec<u8>, String>>, memory: &Memory) -> Partials {
    let mut partials = Partials::new(Some(tag));
    for r in replies {
        partials.reply(r, "P/leader/x/partial", memory);
    }
    partials
}

#[test]
fn every_leader_at_the_cut_adds_up_to_marginals_summing_to_k() {
    let memory = Memory::default();
    let replies = vec![
        Ok(encode(&part("a", 7, 9, 1.0, vec![(0, 0.5)]))),
        Ok(encode(&part("b", 7, 9, 2.0, vec![(1, -0.5), (2, 0.0)]))),
    ];
    let (parts, errors) = gather(9, replies, &memory).into_parts();
    let collected = check(cut(7, &["a", "b"]), parts, errors, Duration::ZERO, &memory).unwrap();
    let answer = marginals_of(&collected, &memory).unwrap();
    assert_eq!(answer.leaders, 2);
    assert_eq!(answer.watermark.get("sensor-0"), Some(&14));
    // outside = 1/3 + 2/3 = 1 over total 3, plus each track's inside.
    let want = [1.5 / 3.0, 0.5 / 3.0, 1.0 / 3.0];
    for (p, w) in answer.p_red.iter().zip(want) {
        assert!((p - w).abs() < 1e-12, "{:?}", answer.p_red);
    }
    assert!((answer.p_red.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    assert_eq!(memory.stats().bad_replies, 0);
}

#[test]
fn a_missing_leader_fails_the_query_by_name() {
    let memory = Memory::default();
    let (parts, errors) =
        gather(9, vec![Ok(encode(&part("a", 7, 9, 1.0, vec![])))], &memory).into_parts();
    let e = check(cut(7, &["a", "b"]), parts, errors, Duration::ZERO, &memory).unwrap_err();
    assert!(
        matches!(&e, GatherError::Missing { missing, .. } if missing == &["b"]),
        "{e}"
    );
}

/// While leader c is down, b holds the cut waiting for c's sets
/// and says so; Zenoh's bare "Timeout" names nobody. The answer names c
/// as missing, every time, with what b said, and not b.
#[test]
fn the_leader_that_did_not_answer_is_named_beside_what_the_others_said() {
    let memory = Memory::default();
    let replies = vec![
        Ok(encode(&part("a", 7, 9, 1.0, vec![]))),
        Err("degraded: leader b did not reach the cut tagged 9 within 1.5s: it waits for sets from c at item 5".into()),
        Err("Timeout".into()),
    ];
    let (parts, errors) = gather(9, replies, &memory).into_parts();
    let e = check(
        cut(7, &["a", "b", "c"]),
        parts,
        errors,
        Duration::ZERO,
        &memory,
    )
    .unwrap_err();
    assert!(
        matches!(&e, GatherError::Missing { missing, .. } if missing == &["c"]),
        "{e}"
    );
    let text = e.to_string();
    assert!(text.contains("waits for sets from c"), "{text}");
    assert!(!text.contains("Timeout"), "{text}");
}

#[test]
fn bad_replies_are_counted_and_refuse_the_answer() {
    let memory = Memory::default();
    let replies = vec![
        Ok(b"not postcard".to_vec()),
        // Another tag: a reply meant for another query.
        Ok(encode(&part("a", 7, 8, 1.0, vec![]))),
        Err("degraded: leader b is recovering its state".into()),
    ];
    let partials = gather(9, replies, &memory);
    assert_eq!(partials.answered(), 0);
    let (parts, errors) = partials.into_parts();
    let e = check(cut(7, &["a", "b"]), parts, errors, Duration::ZERO, &memory)
        .unwrap_err()
        .to_string();
    assert!(e.contains("P/leader/x/partial"), "{e}");
    assert!(e.contains("a answered tag 8"), "{e}");
    assert!(e.contains("recovering"), "{e}");
    assert_eq!(memory.stats().bad_replies, 1);
}

#[test]
fn sums_at_another_seq_or_beyond_the_field_are_refused() {
    let memory = Memory::default();
    let replies = vec![
        Ok(encode(&part("a", 6, 9, 1.0, vec![]))),
        Ok(encode(&part("b", 7, 9, 1.0, vec![(3, 0.1)]))),
    ];
    let (parts, errors) = gather(9, replies, &memory).into_parts();
    let e = check(cut(7, &["a", "b"]), parts, errors, Duration::ZERO, &memory)
        .unwrap_err()
        .to_string();
    assert!(e.contains("a answered at seq 6 for a cut at 7"), "{e}");
    assert!(e.contains("b:"), "{e}");
    assert_eq!(memory.stats().bad_replies, 1);
}

#[test]
fn the_cut_reply_decides_and_a_bad_one_is_counted() {
    let memory = Memory::default();
    let placed = read_cut(Ok(encode(&cut(3, &["a"]))), "P/sensor/s/cut", &memory).unwrap();
    assert_eq!(placed.seq, 3);
    let e = read_cut(Ok(vec![1, 2, 3]), "P/sensor/s/cut", &memory).unwrap_err();
    assert!(e.to_string().contains("P/sensor/s/cut"), "{e}");
    let e = read_cut(Err("the stream is past event 3".into()), "k", &memory).unwrap_err();
    assert!(e.to_string().contains("past event 3"), "{e}");
    assert_eq!(memory.stats().bad_replies, 1);
    assert_eq!(
        cut_parameters(5, At::Events(4), Share::Rows),
        "tag=5;events=4;rows"
    );
}

#[test]
fn leaders_resting_at_the_same_end_answer_without_a_cut() {
    let memory = Memory::default();
    let mut last = cut(7, &["a", "b"]);
    last.finished = true;
    let rest = |leader: &str, at: u64| {
        let mut p = part(leader, at, 0, 1.0, vec![]);
        p.finished = true;
        p
    };
    let parts =
        |a: Partial, b: Partial| BTreeMap::from([("a".to_string(), a), ("b".to_string(), b)]);
    let collected = at_rest_of(
        last.clone(),
        parts(rest("a", 9), rest("b", 9)),
        Vec::new(),
        Duration::ZERO,
        &memory,
    )
    .expect("both rest at 9");
    assert_eq!((collected.cut.seq, collected.cut.events), (9, 18));
    // Resting at different points, or one not finished: the long way.
    assert!(at_rest_of(
        last.clone(),
        parts(rest("a", 9), rest("b", 8)),
        Vec::new(),
        Duration::ZERO,
        &memory
    )
    .is_none());
    let mut unfinished = rest("b", 9);
    unfinished.finished = false;
    assert!(at_rest_of(
        last,
        parts(rest("a", 9), unfinished),
        Vec::new(),
        Duration::ZERO,
        &memory
    )
    .is_none());
}

#[test]
fn sums_from_a_leader_the_cut_does_not_list_are_refused_not_added() {
    // A process of another stream (or a stale one) answering on the same
    // prefix with the right tag: its sums would silently change the answer.
    let memory = Memory::default();
    let replies = vec![
        Ok(encode(&part("a", 7, 9, 1.0, vec![]))),
        Ok(encode(&part("b", 7, 9, 1.0, vec![]))),
        Ok(encode(&part("stray", 7, 9, 5.0, vec![(0, 5.0)]))),
    ];
    let (parts, errors) = gather(9, replies, &memory).into_parts();
    let e = check(cut(7, &["a", "b"]), parts, errors, Duration::ZERO, &memory)
        .unwrap_err()
        .to_string();
    assert!(e.contains("stray") && e.contains("not a leader"), "{e}");
    assert_eq!(memory.stats().bad_replies, 1);
}

#[test]
fn no_leaders_or_no_mass_is_an_error_not_an_answer() {
    let memory = Memory::default();
    let e = check(
        cut(7, &[]),
        BTreeMap::new(),
        Vec::new(),
        Duration::ZERO,
        &memory,
    );
    assert!(matches!(e, Err(GatherError::NoLeaders)), "{e:?}");
    // Every share empty: the observations ruled out every red set.
    let (parts, errors) =
        gather(9, vec![Ok(encode(&part("a", 7, 9, 0.0, vec![])))], &memory).into_parts();
    let collected = check(cut(7, &["a"]), parts, errors, Duration::ZERO, &memory).unwrap();
    assert!(matches!(
        marginals_of(&collected, &memory),
        Err(GatherError::Degenerate)
    ));
}

#[test]
fn a_repeated_reply_counts_once_and_a_late_error_does_not_hide_it() {
    let memory = Memory::default();
    let replies = vec![
        Ok(encode(&part("a", 7, 9, 1.0, vec![]))),
        Ok(encode(&part("a", 7, 9, 1.0, vec![]))),
    ];
    let partials = gather(9, replies, &memory);
    assert_eq!(partials.answered(), 1);
    let (parts, errors) = partials.into_parts();
    let e = check(
        cut(7, &["a", "b"]),
        parts,
        errors,
        Duration::from_secs(3),
        &memory,
    )
    .unwrap_err();
    assert!(
        matches!(&e, GatherError::Missing { missing, timeout, .. } if missing == &["b"] && timeout.as_secs() == 3),
        "{e}"
    );
}

/// A singleton component of track `t`, red with weight `r` (blue 1 − r).
fn singleton(t: u32, r: f64) -> WireCounts {
    WireCounts {
        tracks: vec![t],
        counts: vec![1.0 - r, r],
        red: vec![vec![0.0, r]],
    }
}

/// Leader `leader`'s factored answer at cut `cut` tagged `tag`.
fn factored(leader: &str, cut: u64, tag: u64, components: Vec<WireCounts>) -> Partial {
    Partial {
        components: Some(components),
        ..part(leader, cut, tag, 0.0, vec![])
    }
}

fn marginals(parts: Vec<Partial>, seq: u64, memory: &Memory) -> Result<Vec<f64>, GatherError> {
    let leaders: Vec<&str> = parts.iter().map(|p| p.leader.as_str()).collect();
    let collected = Collected {
        cut: cut(seq, &leaders),
        parts,
    };
    marginals_of(&collected, memory).map(|a| a.p_red)
}

#[test]
fn leaders_answering_with_what_changed_give_the_answer_of_their_whole_shares() {
    let memory = Memory::default();
    assert_eq!(memory.base(), None, "nothing kept before the first answer");
    let first = vec![
        factored("a", 7, 11, vec![singleton(0, 0.2), singleton(1, 0.5)]),
        factored("b", 7, 11, vec![singleton(2, 0.7)]),
    ];
    marginals(first, 7, &memory).unwrap();
    assert_eq!(memory.base(), Some(11));
    // At cut 9: a's track 1 is now held by b, whose component of 2 changed;
    // a's component of 0 did not. Told as changes to the answer at tag 11
    // (a's track 1 gone, b's new component whole) and whole, alike.
    let now_a = vec![singleton(0, 0.2)];
    let now_b = vec![singleton(1, 0.4), singleton(2, 0.9)];
    let whole = marginals(
        vec![
            factored("a", 9, 12, now_a.clone()),
            factored("b", 9, 12, now_b.clone()),
        ],
        9,
        &Memory::default(),
    )
    .unwrap();
    let changes = vec![
        Partial {
            base: Some(11),
            gone: vec![1],
            ..factored("a", 9, 12, Vec::new())
        },
        Partial {
            base: Some(11),
            ..factored("b", 9, 12, now_b)
        },
    ];
    let told = marginals(changes, 9, &memory).unwrap();
    for (t, (w, c)) in whole.iter().zip(&told).enumerate() {
        assert!(
            (w - c).abs() < 1e-12,
            "track {t}: whole {w}, told as changes {c}"
        );
    }
    assert_eq!(memory.base(), Some(12));
    // At rest (tag 0), nothing changed since 12: the answer at 12 stands;
    // nothing changed since 11 (still kept): the answer at 11, computed.
    let unchanged = |base: u64| {
        ["a", "b"]
            .map(|l| Partial {
                base: Some(base),
                ..factored(l, 9, 0, Vec::new())
            })
            .to_vec()
    };
    assert_eq!(marginals(unchanged(12), 9, &memory).unwrap(), told);
    let at_11 = marginals(unchanged(11), 9, &memory).unwrap();
    assert_ne!(at_11, told);
    let first_again = marginals(
        vec![
            factored("a", 7, 11, vec![singleton(0, 0.2), singleton(1, 0.5)]),
            factored("b", 7, 11, vec![singleton(2, 0.7)]),
        ],
        7,
        &Memory::default(),
    )
    .unwrap();
    assert_eq!(at_11, first_again);
    assert_eq!(marginals(unchanged(12), 9, &memory).unwrap(), told);
    // A change to an answer the coordinator no longer keeps is named, not
    // guessed at (the coordinator then asks for whole shares at that cut).
    let stale = vec![
        Partial {
            base: Some(99),
            ..factored("a", 9, 13, Vec::new())
        },
        factored("b", 9, 13, vec![singleton(1, 0.4), singleton(2, 0.9)]),
    ];
    let e = marginals(stale, 9, &memory).unwrap_err();
    assert!(
        matches!(&e, GatherError::StaleBase { leader, base: 99 } if leader == "a"),
        "{e}"
    );
}

/// An answer asked again unchanged is the same JSON, not encoded again;
/// any change, the smallest, encodes it anew.
#[test]
fn the_json_of_an_unchanged_answer_is_kept_and_a_changed_one_encoded_anew() {
    let memory = Memory::default();
    let answer = MarginalsAnswer {
        watermark: [("sensor-0".to_string(), 7)].into_iter().collect(),
        tracks: 3,
        red: Some(1),
        p_red: vec![0.5, 0.25, 0.25],
        predicted_red: vec![0],
        leaders: 2,
        coefficients: 6,
        finished: true,
    };
    let first = memory.marginals_json(answer.clone());
    let again = memory.marginals_json(answer.clone());
    assert_eq!(first.as_ptr(), again.as_ptr(), "encoded again");
    assert_eq!(
        serde_json::from_slice::<MarginalsAnswer>(&first).unwrap(),
        answer
    );
    let mut moved = answer.clone();
    moved.p_red[2] = 0.25 + 1e-12;
    let changed = memory.marginals_json(moved.clone());
    assert_ne!(first.as_ptr(), changed.as_ptr());
    assert_eq!(
        serde_json::from_slice::<MarginalsAnswer>(&changed).unwrap(),
        moved
    );
    let mut later = moved.clone();
    later.watermark.insert("sensor-0".into(), 8);
    assert_eq!(
        serde_json::from_slice::<MarginalsAnswer>(&memory.marginals_json(later.clone())).unwrap(),
        later,
        "a new watermark is a new answer"
    );
}

/// A stream asked at every cut: most answers differ from the last in the
/// watermark alone, and their JSON is the kept bytes behind a new
/// watermark — byte for byte what encoding the whole answer gives, through
/// watermarks that grow, gain sensors, and answers that change between.
#[test]
fn an_answer_that_moved_only_its_watermark_is_the_same_json_as_encoded_whole() {
    let memory = Memory::default();
    let mut answer = MarginalsAnswer {
        watermark: [("sensor-0".to_string(), 7)].into_iter().collect(),
        tracks: 4,
        red: Some(2),
        p_red: vec![0.5, 0.25, 0.75, 0.5],
        predicted_red: vec![0, 2],
        leaders: 2,
        coefficients: 8,
        finished: false,
    };
    for step in 0..40u64 {
        answer.watermark.insert("sensor-0".into(), 7 + step * 997);
        if step == 10 {
            answer.watermark.insert("sensor-1 \"quoted\"".into(), 3);
        }
        if step % 7 == 3 {
            answer.p_red[1] += 1e-3;
        }
        if step % 11 == 5 {
            answer.predicted_red = vec![1, 2];
        }
        answer.finished = step == 39;
        let json = memory.marginals_json(answer.clone());
        assert_eq!(
            &json[..],
            &serde_json::to_vec(&answer).unwrap()[..],
            "step {step}"
        );
    }
}

/// Changes that would leave a track in two components, or in none, are
/// refused by name, and the next answer is as if they had never come.
#[test]
fn changes_that_do_not_cover_the_field_once_are_refused_by_name() {
    let memory = Memory::default();
    let first = || {
        vec![
            factored("a", 7, 11, vec![singleton(0, 0.2), singleton(1, 0.5)]),
            factored("b", 7, 11, vec![singleton(2, 0.7)]),
        ]
    };
    let expected = marginals(first(), 7, &memory).unwrap();
    let changed = |tag, gone: Vec<u32>, b: Vec<WireCounts>| {
        vec![
            Partial {
                base: Some(11),
                gone,
                ..factored("a", 9, tag, Vec::new())
            },
            Partial {
                base: Some(11),
                ..factored("b", 9, tag, b)
            },
        ]
    };
    let twice = marginals(changed(12, vec![], vec![singleton(0, 0.4)]), 9, &memory);
    assert!(
        matches!(&twice, Err(GatherError::Refused(e)) if e.contains("track 0 is in two components")),
        "{twice:?}"
    );
    let none = marginals(changed(13, vec![1], vec![]), 9, &memory);
    assert!(
        matches!(&none, Err(GatherError::Refused(e)) if e.contains("no component holds track 1")),
        "{none:?}"
    );
    let unchanged = marginals(changed(14, vec![], vec![]), 9, &memory).unwrap();
    assert_eq!(unchanged, expected);
}

/// A keeper's passive part of a track (its start component, `Partial::passive`)
/// counts only where no other leader holds the track: it was not told of
/// the adoption. Rows alike.
#[test]
fn a_passive_part_gives_way_to_the_track_held_elsewhere() {
    let passive = |p: Partial, tracks: Vec<u32>| Partial {
        passive: tracks,
        ..p
    };
    // a keeps 0 and 2 passive; b adopted 2 (and 1) and read it.
    let parts = vec![
        passive(
            factored(
                "a",
                7,
                0,
                vec![singleton(0, 1.0 / 3.0), singleton(2, 1.0 / 3.0)],
            ),
            vec![0, 2],
        ),
        factored("b", 7, 0, vec![singleton(1, 0.5), singleton(2, 0.9)]),
    ];
    let held = vec![
        factored("a", 7, 0, vec![singleton(0, 1.0 / 3.0)]),
        factored("b", 7, 0, vec![singleton(1, 0.5), singleton(2, 0.9)]),
    ];
    let memory = Memory::default();
    let got = marginals(parts.clone(), 7, &memory).unwrap();
    assert_eq!(got, marginals(held, 7, &Memory::default()).unwrap());
    // Not passive, the same parts hold track 2 twice: refused.
    let twice: Vec<Partial> = parts.into_iter().map(|p| passive(p, Vec::new())).collect();
    assert!(matches!(
        marginals(twice, 7, &Memory::default()),
        Err(GatherError::Refused(e)) if e.contains("two components")
    ));
    // Rows: a's passive row of 2 gives way to b's; its row of 0 stays.
    let row = |track, x| WireRow {
        track,
        ln_likelihoods: vec![x; 3],
    };
    let collected = Collected {
        cut: cut(7, &["a", "b"]),
        parts: vec![
            Partial {
                rows: vec![row(0, 0.0), row(2, 0.0)],
                passive: vec![0, 2],
                ..part("a", 7, 0, 0.0, vec![])
            },
            Partial {
                rows: vec![row(1, 1.0), row(2, 2.0)],
                ..part("b", 7, 0, 0.0, vec![])
            },
        ],
    };
    let rows: Vec<(u32, f64)> = collected
        .rows()
        .iter()
        .map(|r| (r.track, r.ln_likelihoods[0]))
        .collect();
    assert_eq!(rows, vec![(0, 0.0), (1, 1.0), (2, 2.0)]);
}

/// Two processes answering for one role (a former holder cut off but
/// running, and its successor): the answer at the newer epoch is the
/// role's, in either order, and from then on the former one is refused.
#[test]
fn the_answer_of_a_roles_newest_holder_is_kept_and_the_former_fenced() {
    let memory = Memory::default();
    let at = |epoch, total| Partial {
        epoch,
        ..part("a", 7, 9, total, vec![])
    };
    for replies in [
        vec![Ok(encode(&at(1, 5.0))), Ok(encode(&at(2, 1.0)))],
        vec![Ok(encode(&at(2, 1.0))), Ok(encode(&at(1, 5.0)))],
    ] {
        let (parts, _) = gather(9, replies, &memory).into_parts();
        assert_eq!(parts["a"].epoch, 2);
        assert_eq!(parts["a"].total, 1.0);
    }
    // First heard before its successor, the former holder's answer was
    // taken and then replaced; heard after, it was refused and counted.
    assert_eq!(memory.stats().bad_replies, 1);
    let (parts, _) = gather(9, vec![Ok(encode(&at(1, 5.0)))], &memory).into_parts();
    assert!(
        parts.is_empty(),
        "alone, the former holder is still refused"
    );
}

/// A cut placed by a former holder of the sensor role (cut off, still
/// answering) is refused once its successor's has been admitted, and the
/// sensor's fence leaves the leaders' alone.
#[test]
fn a_cut_from_a_former_sensor_holder_is_refused() {
    let memory = Memory::default();
    let placed_at = |epoch| CutPlaced {
        epoch,
        ..cut(5, &["a"])
    };
    let what = CutPlaced::WHAT;
    let successor = placed_at(2);
    assert!(memory
        .admit_epoch(what, &successor.sensor, successor.epoch)
        .is_ok());
    let former = placed_at(1);
    let refused = memory
        .admit_epoch(what, &former.sensor, former.epoch)
        .expect_err("a former holder's cut");
    assert_eq!((refused.epoch, refused.current), (1, 2));
    assert!(
        memory.admit_epoch(what, "sensor-0", 2).is_ok(),
        "the holder's next"
    );
    assert!(
        memory.admit_epoch(Partial::WHAT, "a", 1).is_ok(),
        "a leader role's epochs are its own"
    );
}
