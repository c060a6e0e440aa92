//! The leader state machine driven by hand: rest points, cuts, gaps,
//! duplicates, reordering, snapshots and identity rows.

use super::*;
use idmesh_belief::Atom;
use idmesh_belief::CountPart;

fn begin(leaders: &[&str], owners: Vec<u16>) -> Item {
    Item::Begin(Begin {
        factored_identity: None,
        factored: None,
        tracks: owners.len() as u32,
        red: Some(2),
        initial_red: Some(vec![0, 1]),
        leaders: leaders.iter().map(|l| l.to_string()).collect(),
        owners,
        distributed_rule: false,
        budget: 0,
        omp: false,
        identities: false,
        initial_identity: None,
    })
}

fn batch(number: u64, items: Vec<(u64, Item)>, through: u64, finished: bool) -> Batch {
    Batch {
        version: VERSION,
        epoch: 0,
        sensor: "sensor-0".into(),
        number,
        through,
        events: through,
        finished,
        items: items
            .into_iter()
            .map(|(seq, item)| Sequenced { seq, item })
            .collect(),
    }
}

/// Leader `from`'s transfer of item `seq` with nothing in it.
fn nothing_from(from: u16, seq: u64) -> Transfer {
    Transfer {
        trees: Vec::new(),
        components: Vec::new(),
        version: VERSION,
        from,
        seq,
        sets: Vec::new(),
        rows: Vec::new(),
    }
}

fn mix(a: u32, b: u32, owner_a: u16, owner_b: u16) -> Item {
    Item::Mix {
        adopted: Vec::new(),
        a,
        b,
        swap: 0.5,
        owner_a,
        owner_b,
        handed: None,
    }
}

/// Leader "a" of a factored stream (components of at most 3 tracks,
/// interests that shrink), its `Begin` applied.
fn factored_leader(leaders: &[&str], owners: Vec<u16>) -> Leader {
    factored_leader_with(leaders, owners, false)
}

fn factored_leader_with(leaders: &[&str], owners: Vec<u16>, regional: bool) -> Leader {
    use idmesh_protocol::wire::factored::{FactoredStart, WireSplit};
    let Item::Begin(mut start) = begin(leaders, owners) else {
        unreachable!()
    };
    start.factored = Some(FactoredStart {
        max_component: 3,
        split: WireSplit::Original,
        shrink: true,
        regional,
        spread_above: 0,
    });
    let mut leader = Leader::new("a");
    leader
        .batch(batch(0, vec![(1, Item::Begin(start))], 1, false), 0)
        .unwrap();
    leader
}

#[test]
fn a_leader_rests_only_when_it_has_applied_all_it_was_sent_and_waits_for_nobody() {
    let mut leader = Leader::new("a");
    assert!(leader.quiet(false).is_none(), "no Begin yet");
    leader
        .batch(
            batch(0, vec![(1, begin(&["a", "b"], vec![0, 0, 1, 1]))], 1, false),
            0,
        )
        .unwrap();
    let rest = leader.quiet(false).expect("quiet after the Begin");
    assert_eq!((rest.sums.cut, rest.sums.finished), (1, false));
    // A mix with b's track: the leader must wait for b's sets.
    let actions = leader
        .batch(batch(1, vec![(2, mix(0, 2, 0, 1))], 2, true), 0)
        .unwrap();
    assert!(actions
        .iter()
        .any(|a| matches!(a, Action::Send { to: 1, .. })));
    assert!(leader.quiet(false).is_none(), "waiting for b's sets");
    leader.transfer(nothing_from(1, 2), 0).unwrap();
    let rest = leader.quiet(false).expect("quiet once b's sets are in");
    assert_eq!(
        (rest.sums.cut, rest.sums.events, rest.sums.finished),
        (2, 2, true)
    );
}

#[test]
fn a_cut_is_answered_by_its_tag_and_a_gap_waits_for_the_missing_batch() {
    let mut leader = Leader::new("a");
    leader
        .batch(
            batch(0, vec![(1, begin(&["a"], vec![0, 0, 0]))], 1, false),
            0,
        )
        .unwrap();
    let cut = Item::Cut {
        events: 7,
        tag: 42,
        rows: false,
    };
    let actions = leader
        .batch(batch(1, vec![(2, mix(0, 2, 0, 0)), (3, cut)], 3, false), 0)
        .unwrap();
    assert!(actions
        .iter()
        .any(|a| matches!(a, Action::CutReady(p) if p.sums.tag == 42 && p.sums.cut == 3)));
    let partial = leader.cut(42).expect("kept for late queries");
    assert_eq!(partial.sums.events, 7);
    assert!(leader.cut(41).is_none());
    // Batch 3 before batch 2: held, and batch 2 is asked for.
    let ahead = batch(3, vec![(5, mix(1, 2, 0, 0))], 5, false);
    assert!(leader.batch(ahead.clone(), 0).unwrap().is_empty());
    assert_eq!(leader.missing_batches(), Some(2));
    assert_eq!(leader.position(), 3);
    leader
        .batch(batch(2, vec![(4, mix(0, 1, 0, 0))], 4, false), 0)
        .unwrap();
    assert_eq!(leader.missing_batches(), None);
    assert_eq!(leader.position(), 5);
    // Both again: dropped, counted, nothing applied twice.
    leader.batch(ahead, 0).unwrap();
    leader.batch(batch(2, vec![], 4, false), 0).unwrap();
    let stats = leader.stats();
    assert_eq!((stats.mixes, stats.duplicates, stats.gaps), (3, 2, 1));
}

/// Delivered twice, with batches out of order, an exchange between two
/// leaders ends in the same shares as delivered once in order.
#[test]
fn duplicates_and_reordered_batches_change_nothing() {
    let begin = begin(&["a", "b"], vec![0, 0, 1, 1]);
    let items = [
        (2, mix(0, 2, 0, 1)),
        (3, mix(1, 3, 0, 1)),
        (4, mix(0, 1, 0, 0)),
        (5, mix(2, 3, 1, 1)),
    ];
    let batches = |leader: &str| -> Vec<Batch> {
        let mut out = vec![batch(0, vec![(1, begin.clone())], 1, false)];
        for (i, (seq, item)) in items.iter().enumerate() {
            let wanted = match item {
                Item::Mix {
                    owner_a, owner_b, ..
                } => {
                    let me = if leader == "a" { 0 } else { 1 };
                    *owner_a == me || *owner_b == me
                }
                _ => true,
            };
            let sent = if wanted {
                vec![(*seq, item.clone())]
            } else {
                vec![]
            };
            out.push(batch(i as u64 + 1, sent, *seq, i + 1 == items.len()));
        }
        out
    };
    // Runs both leaders to the end, delivering each one's batches in
    // `order` (indices, repeats allowed) and every transfer twice.
    // With `snapshots`, both leaders are replaced by what their
    // snapshot restores before every delivery.
    let run = |order: &[usize], snapshots: bool| {
        let (mut a, mut b) = (Leader::new("a"), Leader::new("b"));
        let (batches_a, batches_b) = (batches("a"), batches("b"));
        let mut mail: Vec<(u16, Transfer)> = Vec::new();
        for &i in order {
            if snapshots {
                a = Leader::restore(&a.snapshot()).unwrap();
                b = Leader::restore(&b.snapshot()).unwrap();
            }
            for (leader, batches) in [(&mut a, &batches_a), (&mut b, &batches_b)] {
                for action in leader.batch(batches[i].clone(), 0).unwrap() {
                    if let Action::Send { to, transfer } = action {
                        mail.push((to, transfer));
                    }
                }
            }
            while let Some((to, transfer)) = mail.pop() {
                for _ in 0..2 {
                    let leader = if to == 0 { &mut a } else { &mut b };
                    for action in leader.transfer(transfer.clone(), 0).unwrap() {
                        if let Action::Send { to, transfer } = action {
                            mail.push((to, transfer));
                        }
                    }
                }
            }
        }
        let shares: Vec<Vec<(Atom, f64)>> = [&a, &b]
            .iter()
            .map(|l| {
                let mut atoms: Vec<(Atom, f64)> = l
                    .share()
                    .unwrap()
                    .atoms()
                    .map(|(atom, m)| (atom.clone(), m))
                    .collect();
                atoms.sort_by(|x, y| format!("{:?}", x.0).cmp(&format!("{:?}", y.0)));
                atoms
            })
            .collect();
        (shares, a.position(), b.position(), a.stats().duplicates)
    };
    let once = run(&[0, 1, 2, 3, 4], false);
    let shuffled = run(&[0, 3, 1, 1, 4, 2, 0, 3, 4], false);
    // a is not sent the last mix (b's tracks only).
    assert_eq!((once.1, once.2), (4, 5));
    assert_eq!((shuffled.1, shuffled.2), (4, 5));
    assert_eq!(once.0, shuffled.0);
    assert!(shuffled.3 > once.3, "duplicates were seen and dropped");
    // Restored from snapshots at every step, held batches, transfers
    // waited for and all: the same shares.
    let restored = run(&[0, 3, 1, 1, 4, 2, 0, 3, 4], true);
    assert_eq!((restored.1, restored.2, restored.3), (4, 5, shuffled.3));
    for (x, y) in restored.0.iter().flatten().zip(shuffled.0.iter().flatten()) {
        assert_eq!(x.0, y.0);
        assert!((x.1 - y.1).abs() < 1e-12, "{x:?} vs {y:?}");
    }
}

/// Two leaders on an identity stream, driven by hand: reads cost no
/// message, a cross-leader mix exchanges the two rows, a handover moves
/// one; the rows put together equal the centralized information matrix.
#[test]
fn identity_rows_live_with_their_tracks_and_only_mixes_and_handovers_move_them() {
    use idmesh_identity::{IdentityFilter, InformationMatrix, InformationOptions};
    let start = vec![2, 0, 3, 1];
    let begin = Item::Begin(Begin {
        factored_identity: None,
        factored: None,
        tracks: 4,
        red: None,
        initial_red: None,
        leaders: vec!["a".into(), "b".into()],
        owners: vec![0, 0, 1, 1],
        distributed_rule: false,
        budget: 0,
        omp: false,
        identities: true,
        initial_identity: Some(start.clone()),
    });
    let read = |track, identity, owner| Item::Identify {
        adopted: false,
        track,
        identity,
        accuracy: 0.8,
        owner,
    };
    let mut central = InformationMatrix::from_assignment(
        &start,
        KNOWN_START_CONFIDENCE,
        InformationOptions::default(),
    )
    .unwrap();
    let (mut a, mut b) = (Leader::new("a"), Leader::new("b"));
    a.batch(batch(0, vec![(1, begin.clone())], 1, false), 0)
        .unwrap();
    b.batch(batch(0, vec![(1, begin)], 1, false), 0).unwrap();

    // Reads: applied where the row is, nothing sent.
    let actions = a
        .batch(batch(1, vec![(2, read(0, 1, 0))], 2, false), 0)
        .unwrap();
    assert!(actions.is_empty(), "{actions:?}");
    let actions = b
        .batch(batch(1, vec![(3, read(3, 3, 1))], 3, false), 0)
        .unwrap();
    assert!(actions.is_empty(), "{actions:?}");
    for (track, identity) in [(0, 1), (3, 3)] {
        central
            .identify(Identify {
                track,
                identity,
                accuracy: 0.8,
            })
            .unwrap();
    }

    // A mix across the two: each sends its row, unmixed, and waits.
    let mix = |seq| {
        (
            seq,
            Item::Mix {
                adopted: Vec::new(),
                a: 1,
                b: 2,
                swap: 0.3,
                owner_a: 0,
                owner_b: 1,
                handed: None,
            },
        )
    };
    let sent_by_a = a.batch(batch(2, vec![mix(4)], 4, false), 0).unwrap();
    let sent_by_b = b.batch(batch(2, vec![mix(4)], 4, false), 0).unwrap();
    central
        .mix(Mix {
            a: 1,
            b: 2,
            swap: 0.3,
        })
        .unwrap();
    let transfer = |actions: Vec<Action>| match actions.as_slice() {
        [Action::Send { transfer, .. }] => transfer.clone(),
        other => panic!("one transfer expected, got {other:?}"),
    };
    let (to_b, to_a) = (transfer(sent_by_a), transfer(sent_by_b));
    assert_eq!(to_b.rows.iter().map(|r| r.track).collect::<Vec<_>>(), [1]);
    assert_eq!(to_a.rows.iter().map(|r| r.track).collect::<Vec<_>>(), [2]);
    a.transfer(to_a, 0).unwrap();
    b.transfer(to_b, 0).unwrap();

    // Track 0 moves to b: its row goes along.
    let handover = (
        5,
        Item::Handover {
            track: 0,
            from: 0,
            to: 1,
        },
    );
    let sent = a
        .batch(batch(3, vec![handover.clone()], 5, true), 0)
        .unwrap();
    b.batch(batch(3, vec![handover], 5, true), 0).unwrap();
    b.transfer(transfer(sent), 0).unwrap();
    assert_eq!(a.stats().rows_held, 1);
    assert_eq!(b.stats().rows_held, 3);
    assert_eq!((a.stats().identifies, b.stats().identifies), (1, 1));

    let rows = [a.quiet(true).unwrap(), b.quiet(true).unwrap()]
        .into_iter()
        .flat_map(|p| p.sums.rows.clone())
        .map(|r| (r.track, r.ln_likelihoods));
    let assembled = InformationRows::assemble(4, rows, InformationOptions::default()).unwrap();
    assert_eq!(assembled.log_likelihoods(), central.log_likelihoods());
    assert!(
        a.quiet(false).unwrap().sums.rows.is_empty(),
        "rows only when asked"
    );
}

/// The components of one mix coming in two transfers, at two moments: the
/// leader follows every track they bring, not only the last transfer's.
/// (It once followed only the last one's, and a later sighting of a track
/// of the first never reached the component's holder: seed 1676 of the
/// simulator, a wrong answer.)
#[test]
fn components_of_one_mix_in_two_transfers_have_all_their_tracks_followed() {
    use idmesh_protocol::wire::factored::WireComponent;
    let mut leader = factored_leader(&["a", "b", "c"], vec![0, 1, 2, 1, 2]);
    // Seq 3: b gathers track 0's component (b surveils track 1); seq 5:
    // a surveils track 0, so it gathers the components of 0 and 2, held by
    // b ({1, 3, 0}: b had mixed 1 with 3 before) and by c ({2, 4}).
    let actions = leader
        .batch(
            batch(1, vec![(3, mix(1, 0, 1, 0)), (5, mix(0, 2, 0, 2))], 5, true),
            0,
        )
        .unwrap();
    assert!(actions
        .iter()
        .any(|a| matches!(a, Action::Send { to: 1, .. })));
    assert_eq!(leader.waiting_for_components(), Some(5));
    let transfer = |from: u16, tracks: Vec<u32>| Transfer {
        trees: Vec::new(),
        version: VERSION,
        from,
        seq: 5,
        sets: Vec::new(),
        rows: Vec::new(),
        components: vec![WireComponent {
            table: vec![1.0; 1 << tracks.len()],
            last_mix: vec![3; tracks.len()],
            log_scale: 0.0,
            tracks,
        }],
    };
    let first = leader.transfer(transfer(1, vec![1, 3, 0]), 0).unwrap();
    assert!(
        !first.iter().any(|a| matches!(a, Action::Follow(_))),
        "{first:?}"
    );
    assert_eq!(leader.waiting_for_components(), Some(5), "c's is missing");
    let second = leader.transfer(transfer(2, vec![2, 4]), 0).unwrap();
    let followed: Vec<&Follow> = second
        .iter()
        .filter_map(|a| match a {
            Action::Follow(f) => Some(f),
            _ => None,
        })
        .collect();
    assert_eq!(followed.len(), 1, "{second:?}");
    // Every track it holds but does not surveil: no mix grows a factored
    // interest, so 1 and 2 (the mixes' partners) are asked for too.
    assert_eq!(
        (followed[0].after, &followed[0].tracks[..]),
        (5, &[1, 2, 3, 4][..])
    );
    let held = leader.factored().unwrap();
    assert_eq!(held.held_tracks().collect::<Vec<_>>(), vec![0, 1, 2, 3, 4]);
}

/// A factored leader's interest is its own tracks and its components'
/// tracks: once a component leaves, the tracks it neither surveils nor
/// holds any more are unfollowed, and its interest shrinks back.
#[test]
fn a_leader_that_sends_a_component_away_unfollows_its_tracks() {
    use idmesh_protocol::wire::factored::WireComponent;
    let mut leader = factored_leader(&["a", "b"], vec![0, 1, 1]);
    // Seq 3: a surveils track 0, so it gathers {0} and b's {1}.
    leader
        .batch(batch(1, vec![(3, mix(0, 1, 0, 1))], 3, false), 0)
        .unwrap();
    let actions = leader
        .transfer(
            Transfer {
                trees: Vec::new(),
                version: VERSION,
                from: 1,
                seq: 3,
                sets: Vec::new(),
                rows: Vec::new(),
                components: vec![WireComponent {
                    table: vec![0.5, 0.5],
                    last_mix: vec![0],
                    log_scale: 0.0,
                    tracks: vec![1],
                }],
            },
            0,
        )
        .unwrap();
    assert!(
        matches!(&actions[..], [Action::Follow(f)] if f.tracks == [1]),
        "{actions:?}"
    );
    leader.followed(Vec::new()).unwrap();
    assert_eq!(leader.stats().tracks_followed, 2);
    // Seq 7: b surveils track 1 and gathers {0, 1} and {2}: a keeps
    // following its own track 0, and unfollows 1.
    let actions = leader
        .batch(batch(2, vec![(7, mix(1, 2, 1, 1))], 7, true), 0)
        .unwrap();
    let unfollows: Vec<&Unfollow> = actions
        .iter()
        .filter_map(|a| match a {
            Action::Unfollow(u) => Some(u),
            _ => None,
        })
        .collect();
    assert!(
        actions
            .iter()
            .any(|a| matches!(a, Action::Send { to: 1, .. })),
        "{actions:?}"
    );
    assert_eq!(unfollows.len(), 1, "{actions:?}");
    assert_eq!(
        (unfollows[0].after, &unfollows[0].tracks[..]),
        (7, &[1][..])
    );
    let stats = leader.stats();
    assert_eq!((stats.tracks_followed, stats.unfollows), (1, 1));
}

/// A component as leader `from` sends it at item `seq`.
fn component_transfer(from: u16, seq: u64, track: u32, table: Vec<f64>) -> Transfer {
    Transfer {
        trees: Vec::new(),
        version: VERSION,
        from,
        seq,
        sets: Vec::new(),
        rows: Vec::new(),
        components: vec![idmesh_protocol::wire::factored::WireComponent {
            tracks: vec![track],
            table,
            log_scale: 0.0,
            last_mix: vec![0],
        }],
    }
}

/// The tracks of the components a `Send` action carries to `to`.
fn sent_tracks(actions: &[Action], to: u16) -> Vec<Vec<u32>> {
    actions
        .iter()
        .filter_map(|a| match a {
            Action::Send { to: t, transfer } if *t == to => Some(
                transfer
                    .components
                    .iter()
                    .map(|c| c.tracks.clone())
                    .collect::<Vec<_>>(),
            ),
            _ => None,
        })
        .flatten()
        .collect()
}

/// The regional rule, seen from each side of a mix across two regions:
/// the leader surveilling a gathers both components, mixes them apart and
/// sends b's back; the leader surveilling b sends its component and waits
/// for it to come back, keeping the track in its interest meanwhile.
#[test]
fn a_regional_mix_across_regions_sends_b_component_back_and_its_leader_waits_for_it() {
    // Tracks 0 (red) with a, 1 (red) and 2 (blue) with b.
    let mut gatherer = factored_leader_with(&["a", "b"], vec![0, 1, 1], true);
    let actions = gatherer
        .batch(batch(1, vec![(2, mix(0, 2, 0, 1))], 2, false), 0)
        .unwrap();
    assert!(sent_tracks(&actions, 1).is_empty(), "nothing to send yet");
    assert_eq!(gatherer.waiting_for_components(), Some(2));
    let actions = gatherer
        .transfer(component_transfer(1, 2, 2, vec![1.0, 0.0]), 0)
        .unwrap();
    assert_eq!(
        sent_tracks(&actions, 1),
        vec![vec![2]],
        "b's component goes back"
    );
    let held = gatherer.factored().unwrap();
    assert!(held.holds(0) && !held.holds(2));
    assert_eq!(held.component_of(0), vec![0], "kept apart");
    assert_eq!(held.stats().kept_apart, 1);
    assert_eq!(gatherer.waiting_for_components(), None);

    // The other side: "a" surveils b's track 0 of the mix (2, 0).
    let mut returner = factored_leader_with(&["a", "b"], vec![0, 1, 1], true);
    let actions = returner
        .batch(batch(1, vec![(2, mix(2, 0, 1, 0))], 2, false), 0)
        .unwrap();
    assert_eq!(sent_tracks(&actions, 1), vec![vec![0]]);
    assert_eq!(returner.waiting_for_transfer(), Some((2, 1)));
    assert!(!returner.factored().unwrap().holds(0));
    let actions = returner
        .transfer(component_transfer(1, 2, 0, vec![0.5, 0.5]), 0)
        .unwrap();
    assert!(actions.iter().all(|a| !matches!(a, Action::Unfollow(_))));
    assert!(returner.factored().unwrap().holds(0));
    assert_eq!(returner.waiting_for_transfer(), None);
    assert_eq!(returner.position(), 2);
}

/// Without the rule the same mix merges at the gatherer, which keeps both.
#[test]
fn without_the_regional_rule_the_gatherer_keeps_the_merged_component() {
    let mut gatherer = factored_leader_with(&["a", "b"], vec![0, 1, 1], false);
    gatherer
        .batch(batch(1, vec![(2, mix(0, 2, 0, 1))], 2, false), 0)
        .unwrap();
    let actions = gatherer
        .transfer(component_transfer(1, 2, 2, vec![1.0, 0.0]), 0)
        .unwrap();
    assert!(sent_tracks(&actions, 1).is_empty());
    let held = gatherer.factored().unwrap();
    assert!(held.holds(0) && held.holds(2));
    assert_eq!(held.component_of(0).len(), 2);
}

/// The parts of an answer, whole, sorted by tracks: `before`'s less the
/// parts `gone` and those `changed` sends again, plus those it sends (as
/// the coordinator rebuilds them).
fn rebuilt(before: &[Arc<CountPart>], changed: &[CountPart], gone: &[u32]) -> Vec<CountPart> {
    let replaced: Vec<u32> = gone
        .iter()
        .copied()
        .chain(changed.iter().map(|c| c.tracks[0]))
        .collect();
    let mut whole: Vec<CountPart> = before
        .iter()
        .filter(|b| !replaced.contains(&b.tracks[0]))
        .map(|b| (**b).clone())
        .chain(changed.iter().cloned())
        .collect();
    whole.sort_by(|a, b| a.tracks.cmp(&b.tracks));
    whole
}

/// `parts` as plain values, sorted by tracks.
fn sorted(parts: &[Arc<CountPart>]) -> Vec<CountPart> {
    let mut parts: Vec<CountPart> = parts.iter().map(|p| (**p).clone()).collect();
    parts.sort_by(|a, b| a.tracks.cmp(&b.tracks));
    parts
}

#[test]
fn an_answer_told_as_a_change_to_a_kept_one_rebuilds_the_whole() {
    let mut leader = factored_leader(&["a"], vec![0, 0, 0, 0]);
    let cut = |tag| Item::Cut {
        events: 0,
        tag,
        rows: false,
    };
    leader
        .batch(batch(1, vec![(2, cut(7))], 2, false), 0)
        .unwrap();
    // Red track 1 and blue track 2 merge; 0 and 3 stay as they were.
    leader
        .batch(
            batch(2, vec![(3, mix(1, 2, 0, 0)), (4, cut(8))], 4, false),
            0,
        )
        .unwrap();
    let (before, now) = (
        leader.cut(7).unwrap().clone(),
        leader.cut(8).unwrap().clone(),
    );
    let change = leader
        .relative_to(&now, 7)
        .expect("the answer at 7 is kept");
    assert_eq!(change.base, Some(7));
    let sent: Vec<Vec<u32>> = change
        .components
        .iter()
        .flatten()
        .map(|c| c.tracks.clone())
        .collect();
    assert_eq!(sent.len(), 1, "only the merged component: {sent:?}");
    assert_eq!(change.gone, vec![2], "track 2 no longer starts a component");
    let (kept_before, kept_now) = (before.parts.as_ref().unwrap(), now.parts.as_ref().unwrap());
    let sent = change.components.as_ref().unwrap();
    assert_eq!(rebuilt(kept_before, sent, &change.gone), sorted(kept_now));
    // Components unchanged since the answer at 7 are its very parts.
    let zero =
        |parts: &Vec<Arc<CountPart>>| parts.iter().find(|p| p.tracks == [0]).unwrap().clone();
    assert!(Arc::ptr_eq(&zero(kept_before), &zero(kept_now)));
    // A snapshot writes the kept answers whole, whether a query made the
    // whole copy already (7) or not (8), and reads them back the same.
    before.whole();
    let restored = Leader::restore(&leader.snapshot()).unwrap();
    for tag in [7, 8] {
        assert_eq!(restored.cut(tag), leader.cut(tag), "cut {tag}");
    }
    // Against itself nothing changed; an answer not kept gives none.
    let same = leader.relative_to(&now, 8).unwrap();
    assert!(same.components.as_ref().unwrap().is_empty() && same.gone.is_empty());
    assert!(leader.relative_to(&now, 6).is_none());
}

#[test]
fn the_answer_where_a_leader_rests_is_kept_until_an_input_changes_anything() {
    let mut leader = Leader::new("a");
    leader
        .batch(
            batch(0, vec![(1, begin(&["a", "b"], vec![0, 0, 1, 1]))], 1, false),
            0,
        )
        .unwrap();
    let first = leader.quiet_kept(false).unwrap();
    assert!(Arc::ptr_eq(&first, &leader.quiet_kept(false).unwrap()));
    leader
        .batch(batch(1, vec![(2, mix(0, 1, 0, 0))], 2, false), 0)
        .unwrap();
    let after_batch = leader.quiet_kept(false).unwrap();
    assert_eq!(after_batch.sums.cut, 2);
    assert_eq!(*after_batch, *leader.quiet(false).unwrap());
    // A mix with b's track waits for b's sets: no rest, and once they
    // are in, the answer where it rests again is the new one.
    leader
        .batch(batch(2, vec![(3, mix(1, 2, 0, 1))], 3, true), 0)
        .unwrap();
    assert!(leader.quiet_kept(false).is_none());
    leader.transfer(nothing_from(1, 3), 0).unwrap();
    let rest = leader.quiet_kept(false).unwrap();
    assert_eq!((rest.sums.cut, rest.sums.finished), (3, true));
    assert_eq!(*rest, *leader.quiet(false).unwrap());
}

/// The change between two answers' parts, walked side by side (as a share
/// orders them) or looked up (any other order), rebuilds the newer one.
#[test]
fn the_change_between_two_answers_is_the_same_walked_or_looked_up() {
    use rand::{Rng, SeedableRng};
    let part = |tracks: Vec<u32>, x: f64| {
        let m = tracks.len();
        Arc::new(CountPart {
            tracks,
            counts: vec![x; m + 1],
            red: vec![vec![x; m + 1]; m],
        })
    };
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    for _ in 0..200 {
        // Tracks 0..20 in runs of 1 to 3 consecutive tracks.
        let partition = |rng: &mut rand::rngs::StdRng| {
            let mut parts = Vec::new();
            let mut t = 0;
            while t < 20 {
                let m = rng.gen_range(1..=3).min(20 - t);
                parts.push((t..t + m).collect::<Vec<u32>>());
                t += m;
            }
            parts
        };
        let before: Vec<Arc<CountPart>> = partition(&mut rng)
            .into_iter()
            .map(|t| part(t, 1.0))
            .collect();
        let now: Vec<Arc<CountPart>> = partition(&mut rng)
            .into_iter()
            .map(|t| {
                match before.iter().find(|b| b.tracks == t) {
                    // Kept as it was (shared), or with new numbers.
                    Some(b) if rng.gen_bool(0.7) => b.clone(),
                    _ => part(t, rng.gen_range(0.1..1.0)),
                }
            })
            .collect();
        let (changed, gone) = super::cuts::changes(&before, &now);
        let mut shuffled = now.clone();
        shuffled.reverse();
        let (mut changed_looked_up, mut gone_looked_up) = super::cuts::changes(&before, &shuffled);
        let mut walked = (changed.clone(), gone.clone());
        for v in [&mut walked.0, &mut changed_looked_up] {
            v.sort_by(|a, b| a.tracks.cmp(&b.tracks));
        }
        walked.1.sort_unstable();
        gone_looked_up.sort_unstable();
        assert_eq!(walked, (changed_looked_up, gone_looked_up));
        // Rebuilt as the coordinator does: the newer answer's parts.
        assert_eq!(rebuilt(&before, &changed, &gone), sorted(&now));
    }
}

fn observe(track: u32) -> Item {
    Item::Observe {
        adopted_by: None,
        track,
        red: 0.9,
        blue: 0.1,
        growth: Growth::All,
        global: false,
    }
}

/// Under the regional rule a leader handed a track goes on past the
/// handover: it applies what does not touch the track, stops before what
/// does, and takes the component in when it comes. Meanwhile it counts as
/// having received only up to before the handover (its peers keep the
/// transfer for it) and is not quiet. Without the rule it stops at once.
#[test]
fn a_handover_under_the_regional_rule_stops_only_what_touches_its_track() {
    // Tracks 0 and 1 with "a", 2 and 3 with "b"; track 2 comes to "a".
    let items = vec![
        (
            2,
            Item::Handover {
                track: 2,
                from: 1,
                to: 0,
            },
        ),
        (3, mix(0, 1, 0, 0)),
        (4, observe(2)),
        (5, mix(1, 0, 0, 0)),
    ];
    let mut leader = factored_leader_with(&["a", "b"], vec![0, 0, 1, 1], true);
    leader.batch(batch(1, items.clone(), 5, false), 0).unwrap();
    assert_eq!(leader.position(), 3, "the mix after the handover applied");
    assert_eq!(leader.done_through(), 3, "stopped before the observation");
    assert_eq!(leader.received_through(), 1);
    assert_eq!(leader.durable().position, 1);
    assert_eq!(leader.waiting_for_transfer(), Some((2, 1)));
    assert!(!leader.stats().quiet);
    assert!(!leader.factored().unwrap().holds(2));

    leader
        .transfer(component_transfer(1, 2, 2, vec![0.5, 0.5]), 0)
        .unwrap();
    assert_eq!(leader.position(), 5, "the rest applied once it came");
    assert_eq!(leader.received_through(), 5);
    assert_eq!(leader.waiting_for_transfer(), None);
    assert!(leader.stats().quiet);
    assert!(leader.factored().unwrap().holds(2));
    let duplicates = leader.stats().duplicates;
    leader
        .transfer(component_transfer(1, 2, 2, vec![0.5, 0.5]), 0)
        .unwrap();
    assert_eq!(
        leader.stats().duplicates,
        duplicates + 1,
        "a copy is dropped"
    );

    // The same stream without the rule stops at the handover itself.
    let mut strict = factored_leader_with(&["a", "b"], vec![0, 0, 1, 1], false);
    strict.batch(batch(1, items, 5, false), 0).unwrap();
    assert_eq!(strict.position(), 1);
    assert_eq!(strict.waiting_for_transfer(), Some((2, 1)));
}

/// A transfer that comes early (before the handover) is taken in as soon
/// as the handover is reached; a cut waits for every pending transfer, so
/// that its answer holds the handed component.
#[test]
fn an_early_transfer_is_taken_in_at_its_handover_and_a_cut_waits_for_a_late_one() {
    let mut leader = factored_leader_with(&["a", "b"], vec![0, 0, 1, 1], true);
    leader
        .transfer(component_transfer(1, 2, 2, vec![0.5, 0.5]), 0)
        .unwrap();
    let handover = |track| Item::Handover {
        track,
        from: 1,
        to: 0,
    };
    let cut = Item::Cut {
        events: 4,
        tag: 9,
        rows: false,
    };
    let actions = leader
        .batch(
            batch(
                1,
                vec![(2, handover(2)), (3, handover(3)), (4, cut)],
                4,
                false,
            ),
            0,
        )
        .unwrap();
    assert!(leader.factored().unwrap().holds(2), "taken in at once");
    assert_eq!(leader.position(), 3);
    assert_eq!(leader.waiting_for_transfer(), Some((3, 1)));
    assert!(actions.iter().all(|a| !matches!(a, Action::CutReady(_))));
    let actions = leader
        .transfer(component_transfer(1, 3, 3, vec![0.5, 0.5]), 0)
        .unwrap();
    let Some(Action::CutReady(answer)) = actions.iter().find(|a| matches!(a, Action::CutReady(_)))
    else {
        panic!("the cut is reached once the transfer came: {actions:?}");
    };
    let parts = answer.parts.as_ref().unwrap();
    assert!(
        parts.iter().any(|p| p.tracks == [3]),
        "the handed component is in the answer"
    );
}

/// Under the regional rule a handover's transfer brings the track alone;
/// one that brings another track breaks the rule and is refused, naming
/// the item, the track and what it may bring.
#[test]
fn a_handover_transfer_bringing_another_track_is_refused() {
    let mut leader = factored_leader_with(&["a", "b"], vec![0, 0, 1, 1], true);
    let handover = Item::Handover {
        track: 2,
        from: 1,
        to: 0,
    };
    leader
        .batch(batch(1, vec![(2, handover)], 2, false), 0)
        .unwrap();
    let mut transfer = component_transfer(1, 2, 2, vec![0.25, 0.25, 0.25, 0.25]);
    transfer.components[0].tracks = vec![2, 3];
    transfer.components[0].last_mix = vec![0, 0];
    let error = leader.transfer(transfer, 0).unwrap_err().to_string();
    assert!(
        error.contains("item 2") && error.contains("track 3") && error.contains("[2]"),
        "{error}"
    );
}

/// The leader surveilling b of a mix across regions sends b's component
/// to the leader surveilling a and, under the regional rule, goes on
/// while it is away: it stops only before an item on b, until it comes
/// back.
#[test]
fn a_component_away_for_a_mix_across_regions_stops_only_what_touches_it() {
    // Tracks 0 and 2 with "a", 1 and 3 with "b"; "b" gathers the mix (1, 0).
    let mut leader = factored_leader_with(&["a", "b"], vec![0, 1, 0, 1], true);
    let items = vec![(2, mix(1, 0, 1, 0)), (3, observe(2)), (4, observe(0))];
    let actions = leader.batch(batch(1, items, 4, false), 0).unwrap();
    assert_eq!(sent_tracks(&actions, 1), vec![vec![0]]);
    assert_eq!(leader.position(), 3, "the observation of track 2 applied");
    assert_eq!(leader.waiting_for_transfer(), Some((2, 1)));
    assert_eq!(leader.received_through(), 1);
    leader
        .transfer(component_transfer(1, 2, 0, vec![0.5, 0.5]), 0)
        .unwrap();
    assert_eq!(leader.position(), 4);
    assert!(leader.factored().unwrap().holds(0));
    assert!(leader.stats().quiet);
}

/// Leaders of one factored identity stream driven by hand: every item
/// goes to every leader but an identity read, which goes to its track's
/// owner alone (as the router sends it), and every transfer is delivered
/// as soon as it is sent.
struct Hand {
    leaders: Vec<Leader>,
    batches: Vec<u64>,
}

impl Hand {
    fn new(begin: Item, names: &[&str]) -> Hand {
        let mut hand = Hand {
            leaders: names.iter().map(|n| Leader::new(*n)).collect(),
            batches: vec![0; names.len()],
        };
        hand.item(1, begin, None);
        hand
    }

    /// Item `seq` to every leader, or to `only`.
    fn item(&mut self, seq: u64, item: Item, only: Option<usize>) {
        for i in 0..self.leaders.len() {
            if only.is_some_and(|o| o != i) {
                continue;
            }
            let number = self.batches[i];
            self.batches[i] += 1;
            let actions = self.leaders[i]
                .batch(batch(number, vec![(seq, item.clone())], seq, false), 0)
                .unwrap();
            self.carry_out(i, actions);
        }
    }

    fn carry_out(&mut self, from: usize, actions: Vec<Action>) {
        for action in actions {
            match action {
                Action::Send { to, transfer } => {
                    let actions = self.leaders[to as usize].transfer(transfer, 0).unwrap();
                    self.carry_out(to as usize, actions);
                }
                Action::Follow(_) => {
                    // Every item reaches every leader here: none missed.
                    let actions = self.leaders[from].followed(Vec::new()).unwrap();
                    self.carry_out(from, actions);
                }
                Action::Unfollow(_) | Action::CutReady(_) => {}
            }
        }
    }

    /// One step of an identity stream, item `seq`, to the leaders and the
    /// centralized belief: a read of identity y on track x at accuracy z
    /// (to every leader when `reads_to_all`, as leaders holding trees
    /// hear them, else to the track's owner alone), a mix of x and y with
    /// swap z, or a handover of x to leader y. `owners` follows the
    /// handovers.
    fn step(
        &mut self,
        seq: u64,
        (what, x, y, z): (&str, u32, u32, f64),
        owners: &mut [usize],
        central: &mut impl idmesh_identity::IdentityFilter,
        reads_to_all: bool,
    ) {
        match what {
            "read" => {
                let owner = owners[x as usize];
                let item = Item::Identify {
                    adopted: false,
                    track: x,
                    identity: y,
                    accuracy: z,
                    owner: owner as u16,
                };
                self.item(seq, item, (!reads_to_all).then_some(owner));
                let read = Identify {
                    track: x,
                    identity: y,
                    accuracy: z,
                };
                central.identify(read).unwrap();
            }
            "mix" => {
                let item = Item::Mix {
                    adopted: Vec::new(),
                    a: x,
                    b: y,
                    swap: z,
                    owner_a: owners[x as usize] as u16,
                    owner_b: owners[y as usize] as u16,
                    handed: None,
                };
                self.item(seq, item, None);
                central
                    .mix(Mix {
                        a: x,
                        b: y,
                        swap: z,
                    })
                    .unwrap();
            }
            _ => {
                let from = owners[x as usize] as u16;
                owners[x as usize] = y as usize;
                let handover = Item::Handover {
                    track: x,
                    from,
                    to: y as u16,
                };
                self.item(seq, handover, None);
            }
        }
    }

    /// The rows of every leader, put together.
    fn matrix(&self, n: usize) -> Vec<Vec<f64>> {
        use idmesh_identity::InformationOptions;
        let rows = self
            .leaders
            .iter()
            .flat_map(|l| l.quiet(true).unwrap().sums.rows.clone())
            .map(|r| (r.track, r.ln_likelihoods));
        InformationRows::assemble(n, rows, InformationOptions::default())
            .unwrap()
            .log_likelihoods()
    }
}

/// A factored stream with identities, under the regional rule or not:
/// the rows stay with the leader surveilling their tracks whatever
/// components move — a mix across two leaders sends b's row to the leader
/// surveilling a, which fits the pair and sends b's new row back with
/// what it sends anyway; a certain exchange swaps the two rows; a
/// handover moves the row; a snapshot taken while a leader waits for a
/// row restores it waiting — and the rows put together equal the
/// centralized information matrix bit for bit after every item.
#[test]
fn factored_leaders_carry_the_rows_through_mixes_exchanges_handovers_and_snapshots() {
    use idmesh_identity::{InformationMatrix, InformationOptions};
    use idmesh_protocol::wire::factored::{FactoredStart, WireSplit};
    for regional in [false, true] {
        let start = vec![2, 0, 3, 1, 4];
        let Item::Begin(mut begin) = begin(&["a", "b", "c"], vec![0, 0, 1, 1, 2]) else {
            unreachable!()
        };
        begin.tracks = 5;
        begin.identities = true;
        begin.initial_identity = Some(start.clone());
        begin.factored = Some(FactoredStart {
            max_component: 2,
            split: WireSplit::Original,
            shrink: true,
            regional,
            spread_above: 0,
        });
        let mut central = InformationMatrix::from_assignment(
            &start,
            KNOWN_START_CONFIDENCE,
            InformationOptions::default(),
        )
        .unwrap();
        let mut hand = Hand::new(Item::Begin(begin), &["a", "b", "c"]);
        let mut owners = vec![0usize, 0, 1, 1, 2];
        let steps: Vec<(&str, u32, u32, f64)> = vec![
            ("read", 0, 1, 0.8),
            ("read", 3, 3, 0.7),
            ("mix", 1, 2, 0.3),
            ("snapshot", 0, 0, 0.0),
            ("mix", 2, 4, 0.6),
            ("mix", 1, 0, 0.45),
            ("read", 2, 0, 0.9),
            ("mix", 0, 3, 1.0),
            ("handover", 0, 1, 0.0),
            ("mix", 0, 3, 0.4),
            ("mix", 4, 1, 0.25),
            ("mix", 3, 4, 1.0),
            ("read", 1, 2, 0.85),
        ];
        let mut seq = 1;
        for (what, x, y, z) in steps {
            if what == "snapshot" {
                // Leader a is stopped at the mix (its component is
                // wanted, or b's row is): restored, it goes on there.
                let snapshot = hand.leaders[0].snapshot();
                hand.leaders[0] = Leader::restore(&snapshot).unwrap();
                continue;
            }
            seq += 1;
            hand.step(seq, (what, x, y, z), &mut owners, &mut central, false);
            for leader in &hand.leaders {
                let stopped = (
                    leader.waiting_for_transfer(),
                    leader.waiting_for_components(),
                );
                assert_eq!(stopped, (None, None), "regional {regional}: {what} {x} {y}");
                assert!(leader.caught_up());
            }
            assert_eq!(
                hand.matrix(5),
                central.log_likelihoods(),
                "regional {regional}: after {what} {x} {y}"
            );
            let held: Vec<u64> = hand.leaders.iter().map(|l| l.stats().rows_held).collect();
            let want: Vec<u64> = (0..3)
                .map(|i| owners.iter().filter(|&&o| o == i).count() as u64)
                .collect();
            assert_eq!(held, want, "rows stay with the surveilling leader");
        }
    }
}

/// Leader "a" of a factored stream with identities (three tracks, uniform
/// start), its `Begin` applied.
fn factored_identity_leader(owners: Vec<u16>, regional: bool) -> Leader {
    use idmesh_protocol::wire::factored::{FactoredStart, WireSplit};
    let Item::Begin(mut start) = begin(&["a", "b"], owners) else {
        unreachable!()
    };
    start.identities = true;
    start.factored = Some(FactoredStart {
        max_component: 3,
        split: WireSplit::Original,
        shrink: true,
        regional,
        spread_above: 0,
    });
    let mut leader = Leader::new("a");
    leader
        .batch(batch(0, vec![(1, Item::Begin(start))], 1, false), 0)
        .unwrap();
    leader
}

/// The transfers a leader sent leader `to`: the tracks of their rows and
/// of their components.
fn sent_rows_and_tracks(actions: &[Action], to: u16) -> Vec<(Vec<u32>, Vec<Vec<u32>>)> {
    actions
        .iter()
        .filter_map(|a| match a {
            Action::Send { to: t, transfer } if *t == to => Some((
                transfer.rows.iter().map(|r| r.track).collect(),
                transfer
                    .components
                    .iter()
                    .map(|c| c.tracks.clone())
                    .collect(),
            )),
            _ => None,
        })
        .collect()
}

/// The leader surveilling a of a mix across two leaders on a factored
/// identity stream waits for b's row as for b's component, then sends b's
/// fitted row back: alone, or with b's component under the regional rule
/// (one transfer). A row of another track, or from a leader that does not
/// surveil b, is refused.
#[test]
fn the_leader_surveilling_a_fits_both_rows_and_sends_b_its_new_row() {
    let row = |track| WireRow {
        track,
        ln_likelihoods: vec![0.0, -1.0, -2.0],
    };
    for regional in [false, true] {
        // Track 0 with a, 1 and 2 with b.
        let mut gatherer = factored_identity_leader(vec![0, 1, 1], regional);
        gatherer
            .batch(batch(1, vec![(2, mix(0, 2, 0, 1))], 2, false), 0)
            .unwrap();
        assert_eq!(gatherer.waiting_for_components(), Some(2));
        // b's component alone is not enough: its row must come too.
        let mut transfer = component_transfer(1, 2, 2, vec![1.0, 0.0]);
        transfer.rows = vec![row(2)];
        let actions = gatherer.transfer(transfer, 0).unwrap();
        let back = match regional {
            true => vec![(vec![2], vec![vec![2]])],
            false => vec![(vec![2], vec![])],
        };
        assert_eq!(
            sent_rows_and_tracks(&actions, 1),
            back,
            "regional {regional}"
        );
        assert_eq!(gatherer.waiting_for_components(), None);
        assert_eq!(gatherer.stats().rows_held, 1, "b's row went back");

        for (from, track) in [(1, 1), (2, 2)] {
            let mut wrong = factored_identity_leader(vec![0, 1, 1], regional);
            wrong
                .batch(batch(1, vec![(2, mix(0, 2, 0, 1))], 2, false), 0)
                .unwrap();
            let mut transfer = component_transfer(1, 2, 2, vec![1.0, 0.0]);
            transfer.from = from;
            transfer.rows = vec![row(track)];
            assert!(
                matches!(
                    wrong.transfer(transfer, 0),
                    Err(LeaderError::BadTransfer(_))
                ),
                "a row of track {track} from leader {from}"
            );
        }
    }
}

/// The leader surveilling b sends its row with its component (with no
/// component if it holds none) and waits for its fitted row to come back.
#[test]
fn the_leader_surveilling_b_sends_its_row_and_waits_for_the_fitted_one() {
    for holds_b in [true, false] {
        // Track 0 with a, 1 and 2 with b; the mix (2, 0) is b's to gather.
        let mut returner = factored_identity_leader(vec![0, 1, 1], false);
        let mut seq = 2;
        if !holds_b {
            // Track 0's component goes to b first (a mix gathered there),
            // and its fitted row comes back.
            let actions = returner
                .batch(batch(1, vec![(2, mix(1, 0, 1, 0))], 2, false), 0)
                .unwrap();
            assert_eq!(
                sent_rows_and_tracks(&actions, 1),
                [(vec![0], vec![vec![0]])]
            );
            let mut back = nothing_from(1, 2);
            back.rows = vec![WireRow {
                track: 0,
                ln_likelihoods: vec![0.0, -0.5, -0.5],
            }];
            returner.transfer(back, 0).unwrap();
            assert_eq!(returner.position(), 2);
            seq = 3;
        }
        let actions = returner
            .batch(
                batch(
                    if holds_b { 1 } else { 2 },
                    vec![(seq, mix(2, 0, 1, 0))],
                    seq,
                    false,
                ),
                0,
            )
            .unwrap();
        let components = if holds_b { vec![vec![0]] } else { vec![] };
        assert_eq!(sent_rows_and_tracks(&actions, 1), [(vec![0], components)]);
        assert_eq!(returner.waiting_for_transfer(), Some((seq, 1)));
        let mut back = nothing_from(1, seq);
        back.rows = vec![WireRow {
            track: 0,
            ln_likelihoods: vec![0.0, -0.25, -0.75],
        }];
        returner.transfer(back, 0).unwrap();
        assert_eq!(returner.position(), seq);
        let rows = returner.quiet(true).unwrap().sums.rows.clone();
        let own: Vec<_> = rows
            .iter()
            .map(|r| (r.track, r.ln_likelihoods.clone()))
            .collect();
        assert_eq!(own, [(0, vec![0.0, -0.25, -0.75])], "the fitted row, kept");
    }
}

/// Tracks that start unheld: each leader keeps its start components of the
/// tracks `t mod L` names it as a passive part; a track's first item
/// adopts it with no transfer (made here, or the kept one becoming the
/// leader's own); a keeper drops what it kept at the first item it hears
/// after the track's adoption elsewhere.
#[test]
fn a_track_no_leader_surveilled_is_adopted_at_its_first_item() {
    use idmesh_protocol::wire::sensor_to_leader::UNHELD;
    let mut a = factored_leader_with(&["a", "b"], vec![UNHELD; 4], true);
    let rest = a.quiet(false).expect("quiet after the Begin");
    assert_eq!(rest.sums.passive, vec![0, 2], "a keeps tracks 0 and 2");
    let tracks = |parts: &[Arc<CountPart>]| -> Vec<Vec<u32>> {
        sorted(parts).iter().map(|p| p.tracks.clone()).collect()
    };
    assert_eq!(
        tracks(rest.parts.as_ref().expect("factored")),
        vec![vec![0], vec![2]]
    );
    // Track 1 (kept by b) first seen, adopted here: made here, no
    // transfer waited for.
    let first_seen = Item::Observe {
        track: 1,
        red: 0.9,
        blue: 0.1,
        growth: Growth::All,
        global: false,
        adopted_by: Some(0),
    };
    let actions = a
        .batch(batch(1, vec![(2, first_seen)], 2, false), 0)
        .unwrap();
    assert!(sent_tracks(&actions, 1).is_empty());
    assert!(a.factored().unwrap().holds(1));
    assert!(a.quiet(false).is_some(), "nothing to wait for");
    // Track 2, kept here, meets 1 at its first item and is adopted here.
    let first_mix = Item::Mix {
        a: 2,
        b: 1,
        swap: 0.5,
        owner_a: 0,
        owner_b: 0,
        handed: None,
        adopted: vec![2],
    };
    a.batch(batch(2, vec![(3, first_mix)], 3, false), 0)
        .unwrap();
    assert_eq!(
        a.factored().unwrap().component_of(2),
        vec![2, 1],
        "mixed here"
    );
    let rest = a.quiet(false).expect("nothing to wait for");
    assert_eq!(rest.sums.passive, vec![0], "2 is a's own now");
    // Track 0 was adopted by b meanwhile (a was not told); b hands it
    // over: a drops the start component it kept and takes b's.
    let handover = Item::Handover {
        track: 0,
        from: 1,
        to: 0,
    };
    a.batch(batch(3, vec![(4, handover)], 4, false), 0).unwrap();
    assert!(!a.factored().unwrap().holds(0), "the kept one is gone");
    a.transfer(component_transfer(1, 4, 0, vec![0.0, 1.0]), 0)
        .unwrap();
    assert!(a.factored().unwrap().holds(0));
    let rest = a.quiet(false).expect("the transfer is in");
    assert!(rest.sums.passive.is_empty());
    assert_eq!(
        a.stats().items,
        4,
        "the Begin and three items: adoptions are none"
    );
}

/// A keeper is not told of an adoption elsewhere, and the adopter's
/// component of the track can reach it before any item that names the
/// track: a mix of two other tracks brings it. The keeper drops what it
/// kept and takes the component, where it refused the transfer before
/// (found by `idmesh bench --accuracy`: every leader stopped).
#[test]
fn a_kept_track_adopted_elsewhere_can_come_in_a_component() {
    use idmesh_protocol::wire::factored::WireComponent;
    use idmesh_protocol::wire::sensor_to_leader::UNHELD;
    let mut a = factored_leader_with(&["a", "b"], vec![UNHELD; 4], true);
    let rest = a.quiet(false).expect("quiet after the Begin");
    assert_eq!(rest.sums.passive, vec![0, 2], "a keeps tracks 0 and 2");
    // b adopted 0 and 3 and mixed them (a heard nothing of it); now 2,
    // adopted here, meets 3 across the two regions: a waits for the
    // component of 3, which holds 0.
    let mix = Item::Mix {
        a: 2,
        b: 3,
        swap: 0.5,
        owner_a: 0,
        owner_b: 1,
        handed: None,
        adopted: vec![2],
    };
    a.batch(batch(1, vec![(2, mix)], 2, false), 0).unwrap();
    assert!(
        a.factored().unwrap().holds(0),
        "still kept: nothing named 0"
    );
    let transfer = Transfer {
        trees: Vec::new(),
        version: VERSION,
        from: 1,
        seq: 2,
        sets: Vec::new(),
        rows: Vec::new(),
        components: vec![WireComponent {
            tracks: vec![3, 0],
            table: vec![0.0, 0.5, 0.5, 0.0],
            log_scale: 0.0,
            last_mix: vec![1, 1],
        }],
    };
    let actions = a.transfer(transfer, 0).expect("the component is taken in");
    assert_eq!(
        sent_tracks(&actions, 1),
        vec![vec![3, 0]],
        "kept apart, 3's component goes back whole"
    );
    let rest = a.quiet(false).expect("nothing left to wait for");
    assert!(rest.sums.passive.is_empty(), "the kept 0 is gone");
}

/// On an identity stream an adopted track's row is the start row, made
/// where it is adopted; a keeper's kept row goes with its start component.
#[test]
fn an_adopted_track_takes_its_start_row() {
    use idmesh_protocol::wire::sensor_to_leader::UNHELD;
    let mut a = factored_identity_leader(vec![UNHELD; 4], true);
    let rows = |leader: &Leader| -> Vec<u32> {
        leader
            .quiet(true)
            .expect("quiet")
            .sums
            .rows
            .iter()
            .map(|r| r.track)
            .collect()
    };
    assert_eq!(rows(&a), vec![0, 2], "the rows a keeps");
    let first_read = Item::Identify {
        track: 3,
        identity: 1,
        accuracy: 0.9,
        owner: 0,
        adopted: true,
    };
    a.batch(batch(1, vec![(2, first_read)], 2, false), 0)
        .unwrap();
    assert_eq!(rows(&a), vec![0, 2, 3]);
    // Track 2 was adopted by b (a was not told); b hands it over riding
    // on a mix with a's track 3: a drops its kept row and component first,
    // then waits for b's.
    let ride = Item::Mix {
        a: 3,
        b: 2,
        swap: 0.5,
        owner_a: 0,
        owner_b: 0,
        handed: Some(Handed { track: 2, from: 1 }),
        adopted: Vec::new(),
    };
    a.batch(batch(2, vec![(3, ride)], 3, false), 0).unwrap();
    assert_eq!(a.waiting_for_components(), Some(3), "waits for b's");
    assert!(!a.factored().unwrap().holds(2));
}

/// A factored stream whose leaders hold the factored identity belief,
/// under the regional rule or not, at a cap that cuts groups or not: a
/// mix gathers its two trees at the leader surveilling a, a sure swap is
/// relabelled where the trees lie, a handover moves no tree, every read
/// is applied once, by the holder of its track's tree, and a snapshot
/// taken while a leader waits restores it waiting — and the trees put
/// together equal the centralized belief after every item.
#[test]
fn factored_leaders_carry_identity_trees_through_mixes_swaps_handovers_and_snapshots() {
    use idmesh_identity::factored::assemble;
    use idmesh_identity::max_abs_difference;
    use idmesh_identity::{FactoredIdentity, IdentityFilter};
    use idmesh_placement::{from_wire_tree, identity_options};
    use idmesh_protocol::wire::factored::{FactoredStart, WireSplit};
    for (regional, cap) in [(false, 9), (true, 9), (true, 3)] {
        let start = vec![2, 0, 3, 1, 4, 5];
        let n = start.len();
        let Item::Begin(mut begin) = begin(&["a", "b", "c"], vec![0, 0, 1, 1, 2, 2]) else {
            unreachable!()
        };
        begin.tracks = n as u32;
        begin.identities = true;
        begin.initial_identity = Some(start.clone());
        begin.factored_identity = Some(cap);
        begin.factored = Some(FactoredStart {
            max_component: 2,
            split: WireSplit::Original,
            shrink: true,
            regional,
            spread_above: 0,
        });
        let mut central = FactoredIdentity::from_assignment(&start, identity_options(cap)).unwrap();
        let mut hand = Hand::new(Item::Begin(begin), &["a", "b", "c"]);
        let mut owners = vec![0usize, 0, 1, 1, 2, 2];
        let steps: Vec<(&str, u32, u32, f64)> = vec![
            ("read", 0, 1, 0.8),
            ("mix", 1, 2, 0.3),
            ("snapshot", 0, 0, 0.0),
            ("mix", 4, 1, 0.6),
            ("read", 2, 0, 0.9),
            ("mix", 5, 3, 0.45),
            ("mix", 0, 3, 1.0),
            ("handover", 0, 1, 0.0),
            ("mix", 2, 5, 0.4),
            ("read", 3, 2, 0.7),
            ("mix", 0, 4, 0.25),
            ("mix", 3, 4, 1.0),
            ("read", 1, 3, 0.85),
            ("mix", 5, 0, 0.5),
            ("read", 4, 4, 0.9),
        ];
        let (mut seq, mut reads, mut moved) = (1, 0, 0);
        for (what, x, y, z) in steps {
            if what == "snapshot" {
                let snapshot = hand.leaders[0].snapshot();
                hand.leaders[0] = Leader::restore(&snapshot).unwrap();
                continue;
            }
            seq += 1;
            let received: u64 = hand
                .leaders
                .iter()
                .map(|l| l.stats().transfers_received)
                .sum();
            reads += u64::from(what == "read");
            hand.step(seq, (what, x, y, z), &mut owners, &mut central, true);
            let after: u64 = hand
                .leaders
                .iter()
                .map(|l| l.stats().transfers_received)
                .sum();
            moved += after - received;
            for leader in &hand.leaders {
                let stopped = (
                    leader.waiting_for_transfer(),
                    leader.waiting_for_components(),
                );
                assert_eq!(stopped, (None, None), "regional {regional}: {what} {x} {y}");
                assert!(leader.caught_up());
            }
            let trees: Vec<_> = hand
                .leaders
                .iter()
                .flat_map(|l| l.quiet(true).unwrap().sums.trees.clone())
                .map(|t| from_wire_tree(t).unwrap())
                .collect();
            let holders: usize = trees.iter().map(|t| t.tracks(n).len()).sum();
            assert_eq!(holders, n, "every track in one tree, at one leader");
            let whole = assemble(n, identity_options(cap), trees).unwrap();
            let d = max_abs_difference(&whole.marginals().unwrap(), &central.marginals().unwrap());
            assert!(
                d < 1e-12,
                "regional {regional}, cap {cap}: {d} after {what} {x} {y}"
            );
            assert!(hand
                .leaders
                .iter()
                .all(|l| l.quiet(true).unwrap().sums.rows.is_empty()));
        }
        let applied: u64 = hand.leaders.iter().map(|l| l.stats().identifies).sum();
        assert_eq!(applied, reads, "each read applied once");
        assert!(moved > 0, "mixes across leaders moved trees");
    }
}
