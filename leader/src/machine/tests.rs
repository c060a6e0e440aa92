//! The leader's timers and recovery policy, driven by hand with a clock
//! that only moves when the test says so.

use super::*;
use idmesh_protocol::wire::sensor_to_leader::{Begin, Item, Sequenced};

const MS: Duration = Duration::from_millis(1);

fn timers() -> Timers {
    Timers::new(Duration::from_secs(2), true, Some(4))
}

fn begin(leaders: &[&str]) -> Item {
    Item::Begin(Begin {
        factored_identity: None,
        factored: None,
        tracks: 4,
        red: Some(2),
        initial_red: Some(vec![0, 1]),
        leaders: leaders.iter().map(|l| l.to_string()).collect(),
        // Tracks 0, 1 with the first leader, 2, 3 with the last.
        owners: vec![0, 0, leaders.len() as u16 - 1, leaders.len() as u16 - 1],
        distributed_rule: false,
        budget: 0,
        omp: false,
        identities: false,
        initial_identity: None,
    })
}

fn batch(number: u64, items: Vec<(u64, Item)>, through: u64) -> Input {
    let batch = Batch {
        version: VERSION,
        epoch: 0,
        sensor: "s".into(),
        number,
        through,
        events: through,
        finished: false,
        items: items
            .into_iter()
            .map(|(seq, item)| Sequenced { seq, item })
            .collect(),
    };
    Input::Message {
        kind: Kind::Batch,
        bytes: encode(&batch),
        origin: "test".into(),
    }
}

fn cut(tag: u64) -> Item {
    Item::Cut {
        events: 0,
        tag,
        rows: false,
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

fn started(name: &str, leaders: &[&str]) -> Node {
    let mut node = Node::new(Leader::new(name), timers());
    node.step(Duration::ZERO, batch(0, vec![(1, begin(leaders))], 1));
    node
}

fn resends(out: &[Output]) -> usize {
    out.iter()
        .filter(|o| matches!(o, Output::AskResend(_)))
        .count()
}

fn answers(out: &[Output]) -> Vec<(u64, Result<Partial, String>)> {
    out.iter()
        .filter_map(|o| match o {
            Output::Answer { id, answer } => {
                Some((*id, answer.as_deref().cloned().map_err(Clone::clone)))
            }
            _ => None,
        })
        .collect()
}

#[test]
fn a_held_query_is_answered_at_its_cut_and_expires_with_an_error_if_it_never_comes() {
    let mut node = started("a", &["a"]);
    assert!(node
        .step(
            10 * MS,
            Input::Partial {
                id: 1,
                ask: Ask::Cut(7),
                base: None,
            }
        )
        .is_empty());
    assert!(node
        .step(
            20 * MS,
            Input::Partial {
                id: 2,
                ask: Ask::Cut(8),
                base: None,
            }
        )
        .is_empty());
    assert_eq!(node.held(), 2);
    let out = node.step(30 * MS, batch(1, vec![(2, cut(7))], 2));
    let answered = answers(&out);
    assert_eq!(answered.len(), 1);
    assert_eq!(answered[0].0, 1);
    assert_eq!(answered[0].1.as_ref().unwrap().cut, 2);
    // Asked again later: answered from the cuts kept.
    let out = node.step(
        40 * MS,
        Input::Partial {
            id: 3,
            ask: Ask::Cut(7),
            base: None,
        },
    );
    assert!(answers(&out)[0].1.is_ok());
    // Query 2's cut never comes: an error once it waited the timeout
    // less two sweeps, so that the coordinator (which waits the timeout)
    // hears why before it gives up.
    let out = node.step(1400 * MS, Input::Tick);
    assert!(answers(&out).is_empty(), "not yet: {out:?}");
    let out = node.step(1600 * MS, Input::Tick);
    let answered = answers(&out);
    assert_eq!(answered.len(), 1);
    let error = answered[0].1.as_ref().unwrap_err();
    assert!(
        error.contains("leader a did not reach the cut tagged 8"),
        "{error}"
    );
    assert!(error.contains("no batch with the cut came"), "{error}");
    assert_eq!(node.held(), 0);
}

/// A leader waiting for a dead peer's sets says whose, before
/// the coordinator's timeout, so that every degraded answer names who is
/// missing.
#[test]
fn a_query_held_behind_a_peers_sets_expires_naming_the_peer() {
    let mut node = started("a", &["a", "b"]);
    node.step(
        10 * MS,
        batch(1, vec![(2, mix(0, 2, 0, 1)), (3, cut(9))], 3),
    );
    assert_eq!(node.leader().waiting_for_transfer(), Some((2, 1)));
    node.step(
        20 * MS,
        Input::Partial {
            id: 1,
            ask: Ask::Cut(9),
            base: None,
        },
    );
    assert_eq!(node.held(), 1);
    let out = node.step(1600 * MS, Input::Tick);
    let answered = answers(&out);
    assert_eq!(answered.len(), 1, "{out:?}");
    let error = answered[0].1.as_ref().unwrap_err();
    assert!(error.contains("waits for sets from b at item 2"), "{error}");
}

/// A malformed partial-sums query is bad input: answered with why, and
/// counted.
#[test]
fn a_malformed_partial_query_is_counted() {
    let mut node = started("a", &["a"]);
    let ask = Ask::parse(false, false, Some("abc"));
    let out = node.step(
        MS,
        Input::Partial {
            id: 1,
            ask,
            base: None,
        },
    );
    assert!(answers(&out)[0]
        .1
        .as_ref()
        .unwrap_err()
        .contains("tag=<u64>"));
    assert_eq!(node.leader().stats().rejected, 1);
}

#[test]
fn a_late_cut_asks_for_the_batches_again_once_at_a_time() {
    let mut node = started("a", &["a"]);
    node.step(
        Duration::ZERO,
        Input::Partial {
            id: 1,
            ask: Ask::Cut(7),
            base: None,
        },
    );
    assert_eq!(
        resends(&node.step(250 * MS, Input::Tick)),
        0,
        "not late yet"
    );
    let out = node.step(600 * MS, Input::Tick);
    assert_eq!(resends(&out), 1, "{out:?}");
    match out.iter().find(|o| matches!(o, Output::AskResend(_))) {
        Some(Output::AskResend(r)) => assert_eq!((r.leader.as_str(), r.from), ("a", 1)),
        _ => unreachable!(),
    }
    // One request at a time, until it is answered (here: it failed).
    assert_eq!(resends(&node.step(850 * MS, Input::Tick)), 0);
    node.step(900 * MS, Input::Resent(Err("timeout".into())));
    assert_eq!(resends(&node.step(1100 * MS, Input::Tick)), 1);
    // The resent batch carries the cut: the query is answered.
    let resent = Batch {
        version: VERSION,
        epoch: 0,
        sensor: "s".into(),
        number: 1,
        through: 2,
        events: 2,
        finished: false,
        items: vec![Sequenced {
            seq: 2,
            item: cut(7),
        }],
    };
    let out = node.step(1200 * MS, Input::Resent(Ok(vec![resent])));
    assert_eq!(answers(&out).len(), 1);
}

/// A sensor that refuses resend requests again and again (it dropped the
/// batches a role needs) is asked again only after a backoff that doubles,
/// not at every input and tick; an answer starts the backoff over.
#[test]
fn refused_resend_requests_back_off() {
    let mut node = started("a", &["a"]);
    // Batch 1 is missing: asked for at once.
    let mut now = MS;
    let mut out = node.step(now, batch(2, vec![(3, mix(0, 1, 0, 0))], 3));
    let mut asked_at = Vec::new();
    // Ten minutes of ticks and inputs: every request refused as soon as
    // it is made.
    while now < 600_000 * MS {
        if resends(&out) > 0 {
            asked_at.push(now.as_millis() as u64);
            let refusal = Err("a asks for batches from 1, but ... were dropped".to_string());
            out = node.step(now, Input::Resent(refusal));
            continue;
        }
        now += 50 * MS;
        out = if (now.as_millis() / 50).is_multiple_of(2) {
            node.step(now, Input::Tick)
        } else {
            node.step(now, batch(3, vec![], 3))
        };
    }
    // The first refusal is asked again at once; then 0.5 s, 1 s, 2 s, …
    // up to 30 s between requests.
    let gaps: Vec<u64> = asked_at.windows(2).map(|w| w[1] - w[0]).collect();
    assert_eq!(gaps[0], 0, "{gaps:?}");
    assert!((500..=600).contains(&gaps[1]), "{gaps:?}");
    assert!(
        gaps.windows(2).all(|g| g[1] + 100 >= g[0]),
        "never shorter: {gaps:?}"
    );
    assert!(gaps.iter().all(|&g| g <= 30_100), "{gaps:?}");
    assert!(gaps.iter().rev().take(5).all(|&g| g >= 30_000), "{gaps:?}");
    assert!(
        asked_at.len() < 40,
        "{} requests in ten minutes",
        asked_at.len()
    );
    // An answer (here with nothing in it) starts it over: the batch still
    // missing is asked for again at once.
    let out = node.step(now, Input::Resent(Ok(Vec::new())));
    assert_eq!(resends(&out), 1);
}

#[test]
fn a_gap_in_batch_numbers_is_asked_for_at_once() {
    let mut node = started("a", &["a"]);
    let out = node.step(MS, batch(2, vec![(3, mix(0, 1, 0, 0))], 3));
    assert_eq!(resends(&out), 1);
    assert_eq!(node.leader().missing_batches(), Some(1));
    // Still missing while the request is out: not asked twice.
    assert_eq!(resends(&node.step(2 * MS, batch(3, vec![], 3))), 0);
    let out = node.step(3 * MS, batch(1, vec![(2, mix(0, 2, 0, 0))], 2));
    assert_eq!(resends(&out), 0);
    assert_eq!(node.leader().position(), 3);
}

#[test]
fn a_transfer_waited_for_too_long_is_asked_of_its_sender() {
    let mut node = started("a", &["a", "b"]);
    let out = node.step(10 * MS, batch(1, vec![(2, mix(0, 2, 0, 1))], 2));
    assert!(out
        .iter()
        .any(|o| matches!(o, Output::Send { to, seqs, .. } if to == "b" && seqs == &[2])));
    assert_eq!(node.leader().waiting_for_transfer(), Some((2, 1)));
    let asked = |out: &[Output]| transfer_requests_to(out, "b");
    assert_eq!(asked(&node.step(300 * MS, Input::Tick)), 0, "not late yet");
    let out = node.step(600 * MS, Input::Tick);
    assert_eq!(asked(&out), 1);
    match out
        .iter()
        .find(|o| matches!(o, Output::AskTransfers { .. }))
    {
        Some(Output::AskTransfers { wanted, .. }) => assert_eq!((wanted.to, wanted.after), (0, 1)),
        _ => unreachable!(),
    }
    assert_eq!(
        asked(&node.step(850 * MS, Input::Tick)),
        0,
        "one request out"
    );
    let lost = Transfer {
        trees: Vec::new(),
        components: Vec::new(),
        version: VERSION,
        from: 1,
        seq: 2,
        sets: Vec::new(),
        rows: Vec::new(),
    };
    node.step(
        900 * MS,
        Input::Transfers {
            peer: "b".into(),
            result: Ok(TransfersSent {
                epoch: 0,
                version: VERSION,
                transfers: vec![lost],
            }),
        },
    );
    assert_eq!(node.leader().waiting_for_transfer(), None);
    assert_eq!(node.leader().position(), 2);
}

/// The transfer requests in `out` to `to`.
fn transfer_requests_to(out: &[Output], to: &str) -> usize {
    out.iter()
        .filter(|o| matches!(o, Output::AskTransfers { peer, .. } if peer == to))
        .count()
}

/// A peer that fails transfer requests (down, its role not adopted yet)
/// is asked again at once after the first failure, then after a wait
/// that doubles with each failure in a row, at most a few seconds; an
/// answer ends the wait.
#[test]
fn failed_transfer_requests_back_off() {
    let mut node = started("a", &["a", "b"]);
    node.step(10 * MS, batch(1, vec![(2, mix(0, 2, 0, 1))], 2));
    let asked = |out: &[Output]| transfer_requests_to(out, "b");
    let failed = |node: &mut Node, at: Duration| {
        node.step(
            at,
            Input::Transfers {
                peer: "b".into(),
                result: Err("nobody answered".into()),
            },
        );
    };
    assert_eq!(asked(&node.step(600 * MS, Input::Tick)), 1, "late: asked");
    failed(&mut node, 700 * MS);
    assert_eq!(asked(&node.step(850 * MS, Input::Tick)), 1, "again at once");
    failed(&mut node, 900 * MS);
    // Two failures in a row: not before `late` (500 ms) has passed.
    assert_eq!(asked(&node.step(1100 * MS, Input::Tick)), 0, "backing off");
    assert_eq!(
        asked(&node.step(1450 * MS, Input::Tick)),
        1,
        "after the wait"
    );
    let mut at = 1500 * MS;
    for _ in 0..8 {
        at += 10 * MS;
        failed(&mut node, at);
    }
    let wait = super::transfers_backoff(10, Duration::from_millis(500));
    assert_eq!(wait, super::MAX_TRANSFERS_BACKOFF, "capped");
    assert_eq!(asked(&node.step(at + wait - MS, Input::Tick)), 0);
    assert_eq!(asked(&node.step(at + wait, Input::Tick)), 1);
    // An answer, if empty, ends the backoff.
    node.step(
        at + wait + MS,
        Input::Transfers {
            peer: "b".into(),
            result: Ok(TransfersSent {
                epoch: 0,
                version: VERSION,
                transfers: Vec::new(),
            }),
        },
    );
    assert_eq!(asked(&node.step(at + wait + 2 * MS, Input::Tick)), 1);
}

#[test]
fn a_failed_follow_request_is_made_again() {
    let mut node = started("a", &["a", "b"]);
    node.step(10 * MS, batch(1, vec![(2, mix(0, 2, 0, 1))], 2));
    // b's sets bring track 3, which a does not follow yet.
    let sets = vec![idmesh_protocol::wire::leader_to_leader::WireSet {
        red: vec![3],
        blue: vec![],
        ln_mass: -1.0,
    }];
    let out = node.step(20 * MS, sets_from_b(2, sets));
    let follows = |out: &[Output]| {
        out.iter()
            .filter(|o| matches!(o, Output::AskFollow(_)))
            .count()
    };
    assert_eq!(follows(&out), 1);
    assert_eq!(
        follows(&node.step(250 * MS, Input::Tick)),
        0,
        "one request out"
    );
    node.step(300 * MS, Input::Followed(Err("no answer in time".into())));
    assert!(node.failure().is_none(), "a lost reply is not a failure");
    assert_eq!(follows(&node.step(500 * MS, Input::Tick)), 1);
}

fn marks(out: &[Output]) -> Vec<Option<(u64, u64)>> {
    out.iter()
        .filter_map(|o| match o {
            Output::Persist { mark } => Some(mark.as_ref().map(|m| (m.batch, m.position))),
            _ => None,
        })
        .collect()
}

fn snapshots(out: &[Output]) -> usize {
    out.iter()
        .filter(|o| matches!(o, Output::Snapshot(_)))
        .count()
}

#[test]
fn the_mark_is_the_last_snapshots_and_published_after_it_once() {
    let mut node = started("a", &["a"]);
    // Nothing is safe before a snapshot: the journal after one may yet be
    // found damaged, and then the sensor must still have what it held.
    let out = node.step(250 * MS, Input::Tick);
    assert_eq!((marks(&out), snapshots(&out)), (vec![None], 0));
    // At rest (nothing journaled since the last sweep): a snapshot, and
    // its mark, after it in the driver's order.
    let out = node.step(500 * MS, Input::Tick);
    assert_eq!((marks(&out), snapshots(&out)), (vec![Some((1, 1))], 1));
    let snapshot = out
        .iter()
        .position(|o| matches!(o, Output::Snapshot(_)))
        .unwrap();
    let persist = out
        .iter()
        .position(|o| matches!(o, Output::Persist { .. }))
        .unwrap();
    assert!(snapshot < persist);
    let out = node.step(750 * MS, Input::Tick);
    assert_eq!(
        (marks(&out), snapshots(&out)),
        (vec![None], 0),
        "synced, not republished, no snapshot of nothing new"
    );
    // Moved, but not snapshotted yet: the mark stays.
    node.step(800 * MS, batch(1, vec![(2, mix(0, 1, 0, 0))], 2));
    assert_eq!(marks(&node.step(1000 * MS, Input::Tick)), vec![None]);
    assert_eq!(
        marks(&node.step(1250 * MS, Input::Tick)),
        vec![Some((2, 2))]
    );
    // A failed leader tells nobody it is safe.
    node.step(1300 * MS, Input::Failed("disk full".into()));
    node.step(1400 * MS, batch(2, vec![], 2));
    assert_eq!(marks(&node.step(1500 * MS, Input::Tick)), vec![None]);
    assert_eq!(marks(&node.step(1750 * MS, Input::Tick)), vec![None]);
    let out = node.step(
        1800 * MS,
        Input::Partial {
            id: 9,
            ask: Ask::Quiet { rows: false },
            base: None,
        },
    );
    assert!(answers(&out)[0]
        .1
        .as_ref()
        .unwrap_err()
        .contains("disk full"));

    // Without a journal nothing can be lost to damage: what was applied is
    // the mark, published when it moved.
    let mut node = Node::new(
        Leader::new("a"),
        Timers::new(Duration::from_secs(2), false, None),
    );
    node.step(Duration::ZERO, batch(0, vec![(1, begin(&["a"]))], 1));
    assert_eq!(marks(&node.step(250 * MS, Input::Tick)), vec![Some((1, 1))]);
    assert!(marks(&node.step(500 * MS, Input::Tick)).is_empty());
}

#[test]
fn a_leader_restored_from_a_snapshot_publishes_that_snapshots_mark_whatever_its_journal_held() {
    let mut before = started("a", &["a"]);
    before.step(MS, batch(1, vec![(2, mix(0, 1, 0, 0))], 2));
    let state = before.leader().snapshot();
    // Everything after the snapshot was lost to damage (three entries).
    let (mut node, out) =
        Node::recover("a", "a", Some(&state), [], false, Some(3), timers(), MS).unwrap();
    assert_eq!(resends(&out), 1, "it catches up");
    assert_eq!(node.leader().stats().journal_damage, 1);
    assert_eq!(node.leader().stats().journal_dropped, 3);
    assert_eq!(marks(&node.step(250 * MS, Input::Tick)), vec![Some((2, 2))]);
    // Damaged before anything was replayed, with no snapshot: it still
    // asks for what it missed, from the first batch.
    let (_, out) = Node::recover("a", "a", None, [], false, Some(1), timers(), MS).unwrap();
    assert!(out
        .iter()
        .any(|o| matches!(o, Output::AskResend(r) if r.from == 0)));
}

#[test]
fn inputs_are_journaled_before_their_effects_and_snapshots_come_every_n() {
    let mut node = Node::new(Leader::new("a"), timers());
    let out = node.step(MS, batch(0, vec![(1, begin(&["a", "b"]))], 1));
    assert!(matches!(
        out[0],
        Output::Journal {
            kind: Kind::Batch,
            ..
        }
    ));
    let out = node.step(2 * MS, batch(1, vec![(2, mix(0, 2, 0, 1))], 2));
    let kinds: Vec<&str> = out
        .iter()
        .map(|o| match o {
            Output::Journal { .. } => "journal",
            Output::Send { .. } => "send",
            _ => "other",
        })
        .collect();
    assert_eq!(kinds, ["journal", "send"]);
    // Refused at the door: only the refusal is journaled (so the count
    // survives a restart), not its bytes, and it is no input.
    let out = node.step(
        3 * MS,
        Input::Message {
            kind: Kind::Batch,
            bytes: vec![9, 9],
            origin: "x".into(),
        },
    );
    assert_eq!(
        out,
        [Output::Journal {
            kind: Kind::Rejected,
            bytes: Vec::new()
        }]
    );
    assert_eq!(node.leader().stats().rejected, 1);
    node.step(4 * MS, batch(2, vec![], 2));
    let out = node.step(5 * MS, batch(3, vec![], 2));
    assert!(
        out.iter().any(|o| matches!(o, Output::Snapshot(_))),
        "the 4th journaled input: {out:?}"
    );
    assert_eq!(node.leader().stats().snapshots, 1);
}

#[test]
fn a_restarted_leader_catches_up_and_says_it_is_recovering_until_it_has() {
    // Leader a's life before the crash, as its journal holds it.
    let mut before = started("a", &["a", "b"]);
    let mut journal: Vec<(Kind, Vec<u8>)> = Vec::new();
    let mut keep = |out: Vec<Output>| {
        for o in out {
            if let Output::Journal { kind, bytes } = o {
                journal.push((kind, bytes));
            }
        }
    };
    let mut fresh = Node::new(Leader::new("a"), timers());
    keep(fresh.step(MS, batch(0, vec![(1, begin(&["a", "b"]))], 1)));
    keep(fresh.step(2 * MS, batch(1, vec![(2, mix(0, 2, 0, 1))], 2)));
    before.step(2 * MS, batch(1, vec![(2, mix(0, 2, 0, 1))], 2));

    let entries = journal.iter().map(|(k, b)| (*k, b.as_slice()));
    let (mut node, out) =
        Node::recover("a", "host-a", None, entries, false, None, timers(), 10 * MS).unwrap();
    assert_eq!(node.leader().position(), before.leader().position());
    // Its transfer again, the batches after its journal, b's transfers.
    assert!(out
        .iter()
        .any(|o| matches!(o, Output::Send { to, seqs, .. } if to == "b" && seqs == &[2])));
    assert_eq!(resends(&out), 1);
    assert!(out
        .iter()
        .any(|o| matches!(o, Output::AskTransfers { peer, .. } if peer == "b")));
    let out = node.step(
        20 * MS,
        Input::Partial {
            id: 1,
            ask: Ask::Quiet { rows: false },
            base: None,
        },
    );
    assert!(answers(&out)[0]
        .1
        .as_ref()
        .unwrap_err()
        .contains("recovering"));
    // The sensor refuses: it dropped what the role needs. Answers say so
    // (not "ask again shortly") until the sensor answers.
    let dropped = "a asks for batches from 2, but it said its state was safe through 5 \
                   and those before were dropped";
    node.step(25 * MS, Input::Resent(Err(dropped.into())));
    let out = node.step(
        26 * MS,
        Input::Partial {
            id: 2,
            ask: Ask::Quiet { rows: false },
            base: None,
        },
    );
    let said = answers(&out)[0].1.clone().unwrap_err();
    assert!(
        said.contains("cannot be rebuilt") && said.contains("were dropped"),
        "{said}"
    );
    // The sensor answers, then b: caught up.
    node.step(30 * MS, Input::Resent(Ok(Vec::new())));
    assert!(node.recovering_since().is_some());
    let transfer = Transfer {
        trees: Vec::new(),
        components: Vec::new(),
        version: VERSION,
        from: 1,
        seq: 2,
        sets: Vec::new(),
        rows: Vec::new(),
    };
    node.step(
        40 * MS,
        Input::Transfers {
            peer: "b".into(),
            result: Ok(TransfersSent {
                epoch: 0,
                version: VERSION,
                transfers: vec![transfer],
            }),
        },
    );
    assert!(node.recovering_since().is_none());
    assert_eq!(node.leader().stats().recoveries, 1);
    assert!(node.leader().quiet(false).is_some());
    // With nothing in its journal, a leader just starts.
    let (node, out) = Node::recover("a", "h", None, [], false, None, timers(), MS).unwrap();
    assert!(out.is_empty() && node.recovering_since().is_none());
}

/// A batch that came before the Begin is checked against it when
/// the Begin comes; refused, it is asked for again at once — not at the
/// next gap, which at the stream's end never comes.
#[test]
fn a_batch_held_before_the_begin_and_refused_is_asked_for_again_at_once() {
    let mut node = Node::new(Leader::new("a"), timers());
    // Track 9 of a stream of 4: a misfit only the Begin can tell.
    let out = node.step(MS, batch(1, vec![(2, mix(0, 9, 0, 0))], 2));
    assert_eq!(resends(&out), 1, "the gap before it is asked for");
    node.step(2 * MS, batch(0, vec![(1, begin(&["a"]))], 1));
    assert_eq!(node.leader().stats().rejected, 1);
    assert_eq!(node.leader().missing_batches(), Some(1));
    // The first request comes back (batch 0 came meanwhile): batch 1 is
    // asked for again at once.
    let out = node.step(3 * MS, Input::Resent(Ok(vec![])));
    assert_eq!(resends(&out), 1, "{out:?}");
}

/// `rejected` survives a restart — a refusal is journaled (as
/// a mark, not the bytes) and counted again on replay.
#[test]
fn the_rejected_count_survives_a_restart() {
    let mut node = started("a", &["a"]);
    let mut journal: Vec<(Kind, Vec<u8>)> = Vec::new();
    let mut keep = |out: Vec<Output>| {
        for o in out {
            if let Output::Journal { kind, bytes } = o {
                journal.push((kind, bytes));
            }
        }
    };
    keep(node.step(MS, batch(0, vec![(1, begin(&["a"]))], 1)));
    let junk = Input::Message {
        kind: Kind::Transfer,
        bytes: b"junk".to_vec(),
        origin: "test".into(),
    };
    keep(node.step(2 * MS, junk));
    keep(node.step(
        3 * MS,
        Input::Partial {
            id: 1,
            ask: Ask::parse(false, false, Some("abc")),
            base: None,
        },
    ));
    assert_eq!(node.leader().stats().rejected, 2);
    let (back, _) = Node::recover(
        "a",
        "a",
        None,
        journal.iter().map(|(k, b)| (*k, b.as_slice())),
        false,
        None,
        timers(),
        4 * MS,
    )
    .unwrap();
    assert_eq!(back.leader().stats().rejected, 2);
}

#[test]
fn a_transfer_request_never_answered_is_made_again_once_it_is_stale() {
    let mut node = started("a", &["a", "b"]);
    node.step(10 * MS, batch(1, vec![(2, mix(0, 2, 0, 1))], 2));
    let asked = |out: &[Output]| transfer_requests_to(out, "b");
    assert_eq!(asked(&node.step(600 * MS, Input::Tick)), 1);
    // The answer is lost: no second request while the first may still
    // come (query timeout + late = 2.5 s) …
    let mut again = 0;
    let mut now = 600 * MS;
    while now < 3100 * MS {
        now += 250 * MS;
        again += asked(&node.step(now, Input::Tick));
    }
    assert_eq!(again, 0, "asked again before the first request was stale");
    // … then the request is given up and made again on the next tick.
    now += 250 * MS;
    let out = node.step(now, Input::Tick);
    now += 250 * MS;
    let out2 = node.step(now, Input::Tick);
    assert_eq!(asked(&out) + asked(&out2), 1, "{out:?} {out2:?}");
    assert_eq!(node.leader().waiting_for_transfer(), Some((2, 1)));
}

#[test]
fn a_recovery_waits_for_the_sensor_through_failed_resends_but_not_for_a_peer_that_failed() {
    let mut journal: Vec<(Kind, Vec<u8>)> = Vec::new();
    let mut fresh = Node::new(Leader::new("a"), timers());
    for out in [
        fresh.step(MS, batch(0, vec![(1, begin(&["a", "b"]))], 1)),
        fresh.step(2 * MS, batch(1, vec![(2, mix(0, 1, 0, 0))], 2)),
    ] {
        for o in out {
            if let Output::Journal { kind, bytes } = o {
                journal.push((kind, bytes));
            }
        }
    }
    let entries = journal.iter().map(|(k, b)| (*k, b.as_slice()));
    let (mut node, out) =
        Node::recover("a", "host-a", None, entries, false, None, timers(), 10 * MS).unwrap();
    assert_eq!(resends(&out), 1);
    // The sensor's answer is lost: still recovering, and the next tick
    // asks again (one request at a time).
    node.step(20 * MS, Input::Resent(Err("timeout".into())));
    assert!(node.recovering_since().is_some());
    assert_eq!(resends(&node.step(260 * MS, Input::Tick)), 1);
    assert_eq!(resends(&node.step(510 * MS, Input::Tick)), 0);
    // b is down: its failure counts as its answer (it sends its transfers
    // again when it comes back).
    node.step(
        520 * MS,
        Input::Transfers {
            peer: "b".into(),
            result: Err("no answer".into()),
        },
    );
    assert!(
        node.recovering_since().is_some(),
        "the sensor has not answered"
    );
    node.step(530 * MS, Input::Resent(Ok(Vec::new())));
    assert_eq!(node.recovering_since(), None);
    assert_eq!(node.leader().stats().recoveries, 1);
}

#[test]
fn a_peers_durable_mark_lets_the_leader_forget_what_it_sent_there() {
    let mut node = started("a", &["a", "b"]);
    node.step(10 * MS, batch(1, vec![(2, mix(0, 2, 0, 1))], 2));
    let sent_to_b = |node: &mut Node, id| {
        let wanted = TransfersWanted {
            epoch: 0,
            version: VERSION,
            to: 1,
            after: 0,
        };
        let out = node.step(
            20 * MS,
            Input::SentWanted {
                id,
                bytes: encode(&wanted),
                origin: "b".into(),
            },
        );
        match &out[..] {
            [Output::AnswerSent { id: got, answer }] if *got == id => {
                answer.as_ref().map(|s| s.transfers.len()).unwrap()
            }
            _ => panic!("one answer: {out:?}"),
        }
    };
    assert_eq!(sent_to_b(&mut node, 1), 1);
    // Its own mark, or b's below the transfer, changes nothing.
    let mark = |leader: &str, position| Input::Durable {
        bytes: encode(&Durable {
            epoch: 0,
            version: VERSION,
            leader: leader.into(),
            batch: 1,
            position,
        }),
        origin: leader.into(),
    };
    node.step(30 * MS, mark("a", 2));
    node.step(30 * MS, mark("b", 1));
    assert_eq!(sent_to_b(&mut node, 2), 1);
    node.step(40 * MS, mark("b", 2));
    assert_eq!(sent_to_b(&mut node, 3), 0, "b is safe past it");
    // Bytes that are no mark, or no request, are counted and answered.
    node.step(
        50 * MS,
        Input::Durable {
            bytes: vec![1],
            origin: "x".into(),
        },
    );
    let out = node.step(
        60 * MS,
        Input::SentWanted {
            id: 4,
            bytes: vec![1],
            origin: "x".into(),
        },
    );
    // (Each refusal is journaled too, so the count survives a restart.)
    let answers: Vec<_> = out
        .iter()
        .filter(|o| matches!(o, Output::AnswerSent { .. }))
        .collect();
    assert!(
        matches!(
            &answers[..],
            [Output::AnswerSent {
                id: 4,
                answer: Err(_)
            }]
        ),
        "{out:?}"
    );
    assert_eq!(node.leader().stats().rejected, 2);
}

fn progress(out: &[Output]) -> Vec<(u64, u64)> {
    out.iter()
        .filter_map(|o| match o {
            Output::Progress(p) => Some((p.through, p.batch)),
            _ => None,
        })
        .collect()
}

/// The sensor's flow control reads how far a leader has got: said after
/// every input that moves it (past items for others, since a batch says
/// how far the stream is), never past an item it waits at, and again at
/// every sweep whether it moved or not.
#[test]
fn progress_is_published_when_it_moves_and_at_every_sweep() {
    let mut node = Node::new(Leader::new("a"), timers());
    let out = node.step(Duration::ZERO, batch(0, vec![(1, begin(&["a", "b"]))], 1));
    assert_eq!(progress(&out), vec![(1, 1)]);
    // Nothing for a in items 2..=5: done through 5 all the same.
    let out = node.step(MS, batch(1, vec![], 5));
    assert_eq!(progress(&out), vec![(5, 2)]);
    // A mix across a and b at 6: a waits for b's sets there.
    let out = node.step(2 * MS, batch(2, vec![(6, mix(0, 2, 0, 1))], 8));
    assert_eq!(node.leader().waiting_for_transfer(), Some((6, 1)));
    assert_eq!(progress(&out), vec![], "stopped at 5, as it was");
    assert_eq!(node.leader().done_through(), 5);
    let out = node.step(300 * MS, Input::Tick);
    assert_eq!(progress(&out), vec![(5, 3)], "said again at the sweep");
    // A second mix across at 10; b's sets of 6 come: a moves on to 9 and
    // stops again. Not caught up: nothing said until it is.
    node.step(301 * MS, batch(3, vec![(10, mix(1, 3, 0, 1))], 12));
    let out = node.step(302 * MS, sets_from_b(6, Vec::new()));
    assert_eq!(node.leader().done_through(), 9);
    assert_eq!(progress(&out), vec![], "stopped mid-batch");
    let out = node.step(303 * MS, sets_from_b(10, Vec::new()));
    assert_eq!(progress(&out), vec![(12, 4)], "caught up with its batches");
}

/// b's sets of a mix across at item `seq`, as they come from the network.
fn sets_from_b(seq: u64, sets: Vec<idmesh_protocol::wire::leader_to_leader::WireSet>) -> Input {
    sets_from_b_at(0, seq, sets)
}

/// [`sets_from_b`] from b's holder at `epoch`.
fn sets_from_b_at(
    epoch: u64,
    seq: u64,
    sets: Vec<idmesh_protocol::wire::leader_to_leader::WireSet>,
) -> Input {
    Input::Message {
        kind: Kind::Transfer,
        bytes: encode(&TransfersSent {
            epoch,
            version: VERSION,
            transfers: vec![Transfer {
                trees: Vec::new(),
                components: Vec::new(),
                version: VERSION,
                from: 1,
                seq,
                sets,
                rows: Vec::new(),
            }],
        }),
        origin: "b".into(),
    }
}

/// Without a window nothing waits for progress marks: a leader says how
/// far it got at its sweep only, not after every batch.
#[test]
fn without_flow_control_progress_is_published_at_the_sweep_only() {
    let timers = Timers {
        flow_control: false,
        ..timers()
    };
    let mut node = Node::new(Leader::new("a"), timers);
    let out = node.step(Duration::ZERO, batch(0, vec![(1, begin(&["a", "b"]))], 1));
    assert_eq!(progress(&out), vec![]);
    let out = node.step(MS, batch(1, vec![], 5));
    assert_eq!(progress(&out), vec![]);
    let out = node.step(300 * MS, Input::Tick);
    assert_eq!(progress(&out), vec![(5, 2)], "at the sweep");
}

/// Every cut a leader reaches, it pushes its sums at unasked: whole at the
/// first, then as a change to the cut it pushed before (on a factored
/// stream, only the components changed since); a held query at the same
/// cut is still answered.
#[test]
fn a_leader_pushes_its_sums_at_every_cut_as_a_change_to_the_last_pushed() {
    use idmesh_protocol::wire::factored::{FactoredStart, WireSplit};
    let Item::Begin(mut start) = begin(&["a"]) else {
        unreachable!()
    };
    start.factored = Some(FactoredStart {
        max_component: 3,
        split: WireSplit::Original,
        shrink: false,
        regional: false,
        spread_above: 0,
    });
    let mut node = Node::new(Leader::new("a"), timers());
    node.step(Duration::ZERO, batch(0, vec![(1, Item::Begin(start))], 1));
    let pushed = |out: &[Output]| -> Vec<Partial> {
        out.iter()
            .filter_map(|o| match o {
                Output::Push(p) => Some((**p).clone()),
                _ => None,
            })
            .collect()
    };
    let out = node.step(MS, batch(1, vec![(2, cut(7))], 2));
    let first = pushed(&out);
    assert_eq!(first.len(), 1, "{out:?}");
    assert_eq!((first[0].tag, first[0].cut, first[0].base), (7, 2, None));
    assert_eq!(first[0].components.as_ref().map(Vec::len), Some(4));
    let held = Input::Partial {
        id: 1,
        ask: Ask::Cut(9),
        base: None,
    };
    assert!(node.step(2 * MS, held).is_empty());
    let out = node.step(3 * MS, batch(2, vec![(3, mix(0, 2, 0, 0)), (4, cut(9))], 4));
    let second = pushed(&out);
    assert_eq!(second.len(), 1, "{out:?}");
    assert_eq!((second[0].tag, second[0].base), (9, Some(7)));
    let changed = second[0].components.as_ref().expect("factored");
    assert_eq!(changed.len(), 1, "only the merged component: {changed:?}");
    assert_eq!(changed[0].tracks, vec![0, 2]);
    assert_eq!(answers(&out).len(), 1, "the held query answered too");
}

/// The fence: once b's successor (epoch 2) has been heard, what b's former
/// holder (epoch 1, cut off but running) sends is refused, counted, and
/// never journaled; its durable mark makes nothing forgotten.
#[test]
fn a_peers_former_holder_is_fenced_off_once_its_successor_is_heard() {
    let mut node = started("a", &["a", "b"]);
    let journaled = |out: &[Output]| {
        out.iter()
            .filter(|o| matches!(o, Output::Journal { kind, .. } if *kind != Kind::Rejected))
            .count()
    };
    let out = node.step(10 * MS, sets_from_b_at(2, 5, Vec::new()));
    assert_eq!(journaled(&out), 1);
    let rejected = node.leader().stats().rejected;
    let out = node.step(20 * MS, sets_from_b_at(1, 6, Vec::new()));
    assert_eq!(journaled(&out), 0, "refused, not journaled");
    assert_eq!(node.leader().stats().rejected, rejected + 1);
    let out = node.step(30 * MS, sets_from_b_at(2, 6, Vec::new()));
    assert_eq!(journaled(&out), 1, "the holder is heard");
    let mark = |epoch| Input::Durable {
        bytes: encode(&Durable {
            epoch,
            version: VERSION,
            leader: "b".into(),
            batch: 1,
            position: 9,
        }),
        origin: "b".into(),
    };
    node.step(40 * MS, mark(1));
    assert_eq!(node.leader().stats().rejected, rejected + 2);
    node.step(50 * MS, mark(2));
    assert_eq!(node.leader().stats().rejected, rejected + 2);
}

/// Before its Begin a leader cannot tell which role a transfer's sender
/// index names: one older than the newest epoch it heard of any role
/// (here b's successor's durable mark) may be a former holder's, and is
/// refused, counted and not journaled; one at that epoch is taken.
#[test]
fn a_transfer_before_the_begin_older_than_any_epoch_heard_is_refused() {
    let mut node = Node::new(Leader::new("a"), timers());
    let journaled = |out: &[Output]| {
        out.iter()
            .filter(|o| matches!(o, Output::Journal { kind, .. } if *kind != Kind::Rejected))
            .count()
    };
    let out = node.step(MS, sets_from_b_at(1, 5, Vec::new()));
    assert_eq!(journaled(&out), 1, "no epoch heard yet: taken");
    node.step(
        2 * MS,
        Input::Durable {
            bytes: encode(&Durable {
                epoch: 2,
                version: VERSION,
                leader: "b".into(),
                batch: 1,
                position: 3,
            }),
            origin: "b".into(),
        },
    );
    let rejected = node.leader().stats().rejected;
    let out = node.step(3 * MS, sets_from_b_at(1, 6, Vec::new()));
    assert_eq!(journaled(&out), 0, "refused, not journaled");
    assert_eq!(node.leader().stats().rejected, rejected + 1);
    let out = node.step(4 * MS, sets_from_b_at(2, 6, Vec::new()));
    assert_eq!(journaled(&out), 1, "the successor is heard");
    assert_eq!(node.leader().stats().rejected, rejected + 1);
}

/// The copies the node asks to send its standby: (to, batch, position).
fn offers(out: &[Output]) -> Vec<(String, u64, u64)> {
    out.iter()
        .filter_map(|o| match o {
            Output::ToStandby { to, mark } => Some((to.clone(), mark.batch, mark.position)),
            _ => None,
        })
        .collect()
}

fn stored(role: &str, standby: &str, batch: u64, position: u64) -> Input {
    Input::StandbyStored {
        bytes: encode(&idmesh_protocol::wire::leader_to_leader::StandbyStored {
            version: VERSION,
            role: role.into(),
            standby: standby.into(),
            host: standby.into(),
            mark: Durable {
                epoch: 0,
                version: VERSION,
                leader: role.into(),
                batch,
                position,
            },
        }),
        origin: "test".into(),
    }
}

#[test]
fn the_mark_with_a_standby_is_the_older_of_its_own_and_the_standbys() {
    let mark = |batch, position| Durable {
        epoch: 0,
        version: VERSION,
        leader: "a".into(),
        batch,
        position,
    };
    let rule = |own: Option<Durable>, standby: Option<Durable>| {
        standby::standby_mark(own.as_ref(), standby.as_ref()).map(|m| (m.batch, m.position))
    };
    assert_eq!(rule(Some(mark(5, 40)), Some(mark(3, 20))), Some((3, 20)));
    assert_eq!(rule(Some(mark(3, 20)), Some(mark(5, 40))), Some((3, 20)));
    assert_eq!(
        rule(Some(mark(5, 20)), Some(mark(3, 40))),
        Some((3, 20)),
        "field-wise"
    );
    assert_eq!(
        rule(Some(mark(5, 40)), None),
        None,
        "nothing the standby does not hold"
    );
    assert_eq!(rule(None, Some(mark(3, 20))), None);
}

/// With a standby, every snapshot goes to it, and the published mark is
/// only ever one the current standby said it holds: an earlier standby's
/// word, or none yet, holds it back; it never steps back.
#[test]
fn the_published_mark_waits_for_the_current_standby() {
    let timers = Timers {
        standby: true,
        ..timers()
    };
    let mut node = Node::new(Leader::new("a"), timers);
    node.step(Duration::ZERO, batch(0, vec![(1, begin(&["a", "b"]))], 1));
    // At rest: a snapshot at (1, 1), and no standby to send it to.
    node.step(250 * MS, Input::Tick);
    let out = node.step(500 * MS, Input::Tick);
    assert_eq!((snapshots(&out), offers(&out)), (1, vec![]));
    assert_eq!(marks(&out), vec![None], "no standby holds it");
    // A standby: the last snapshot goes to it at once.
    let out = node.step(600 * MS, Input::Standby(Some("b".into())));
    assert_eq!(offers(&out), vec![("b".into(), 1, 1)]);
    assert_eq!(marks(&node.step(750 * MS, Input::Tick)), vec![None]);
    // Another process's word counts for nothing; the standby's does.
    node.step(800 * MS, stored("a", "c", 1, 1));
    assert_eq!(marks(&node.step(1000 * MS, Input::Tick)), vec![None]);
    node.step(1100 * MS, stored("a", "b", 1, 1));
    assert_eq!(
        marks(&node.step(1250 * MS, Input::Tick)),
        vec![Some((1, 1))]
    );
    // A new snapshot goes to the standby; the mark waits for its word.
    node.step(1300 * MS, batch(1, vec![(2, mix(0, 1, 0, 0))], 2));
    node.step(1500 * MS, Input::Tick);
    let out = node.step(1750 * MS, Input::Tick);
    assert_eq!(
        (snapshots(&out), offers(&out)),
        (1, vec![("b".into(), 2, 2)])
    );
    assert_eq!(marks(&out), vec![None], "still (1, 1), not published again");
    node.step(1800 * MS, stored("a", "b", 2, 2));
    assert_eq!(
        marks(&node.step(2000 * MS, Input::Tick)),
        vec![Some((2, 2))]
    );
    // The standby changes: the new one is sent the last snapshot, and an
    // older word of it does not move the mark back.
    let out = node.step(2100 * MS, Input::Standby(Some("c".into())));
    assert_eq!(offers(&out), vec![("c".into(), 2, 2)]);
    node.step(2200 * MS, stored("a", "c", 1, 1));
    assert_eq!(marks(&node.step(2250 * MS, Input::Tick)), vec![None]);
    // Unanswered, the copy is sent again after the retry's wait.
    let late = 2100 * MS + standby::STANDBY_RETRY;
    assert_eq!(offers(&node.step(late - MS, Input::Tick)), vec![]);
    assert_eq!(
        offers(&node.step(late, Input::Tick)),
        vec![("c".into(), 2, 2)]
    );
    node.step(late + MS, stored("a", "c", 2, 2));
    assert_eq!(offers(&node.step(late + 250 * MS, Input::Tick)), vec![]);
    // No standby at all (no other process alive): nothing is sent.
    assert_eq!(
        offers(&node.step(late + 300 * MS, Input::Standby(None))),
        vec![]
    );
}

/// Without a standby (one leader process, or none configured) nothing is
/// sent and the mark is the snapshot's, as before.
#[test]
fn without_a_standby_the_mark_is_the_snapshots() {
    let mut node = started("a", &["a", "b"]);
    node.step(250 * MS, Input::Tick);
    let out = node.step(500 * MS, Input::Tick);
    assert_eq!(marks(&out), vec![Some((1, 1))]);
    let out = node.step(600 * MS, Input::Standby(Some("b".into())));
    assert_eq!(offers(&out), vec![]);
}

/// The fence on the sensor role: once a batch of the sensor's successor
/// (its standby, at epoch 2) has been heard, a batch of the former holder
/// (epoch 1, cut off but running) is refused, counted and never
/// journaled; so is a follow reply of an older epoch.
#[test]
fn a_former_sensor_holder_is_fenced_off_once_its_successor_is_heard() {
    let mut node = started("a", &["a", "b"]);
    let journaled = |out: &[Output]| {
        out.iter()
            .filter(|o| matches!(o, Output::Journal { kind, .. } if *kind != Kind::Rejected))
            .count()
    };
    let at = |epoch, number: u64| {
        let Input::Message { bytes, .. } = batch(number, Vec::new(), number + 1) else {
            unreachable!("a batch is a message")
        };
        let mut b: Batch = idmesh_protocol::wire::decode(&bytes).unwrap();
        b.epoch = epoch;
        Input::Message {
            kind: Kind::Batch,
            bytes: encode(&b),
            origin: "sensor".into(),
        }
    };
    let out = node.step(10 * MS, at(2, 1));
    assert_eq!(journaled(&out), 1, "the successor is heard");
    let rejected = node.leader().stats().rejected;
    let out = node.step(20 * MS, at(1, 2));
    assert_eq!(journaled(&out), 0, "refused, not journaled");
    assert_eq!(node.leader().stats().rejected, rejected + 1);
    let followed = |epoch| {
        encode(&idmesh_protocol::wire::leader_to_sensor::Followed {
            version: VERSION,
            epoch,
            items: Vec::new(),
        })
    };
    node.step(30 * MS, Input::Followed(Ok(followed(2))));
    node.step(40 * MS, Input::Followed(Ok(followed(1))));
    assert_eq!(node.leader().stats().rejected, rejected + 2);
}
