//! The leader's door, without a network: garbage, well-formed messages
//! with bad numbers, and messages of another field are rejected and
//! counted, and leave the state exactly as it was — the leader then goes
//! on to the same shares as one that never saw them.

use idmesh_leader::door::{admit, apply};
use idmesh_leader::journal::Kind;
use idmesh_leader::{Action, Leader};
use idmesh_protocol::wire::coordinator_to_leader::Partial;
use idmesh_protocol::wire::leader_to_leader::{Transfer, TransfersSent, WireSet};
use idmesh_protocol::wire::leader_to_sensor::Followed;
use idmesh_protocol::wire::sensor_to_leader::{Batch, Begin, Growth, Item, Sequenced};
use idmesh_protocol::wire::{encode, VERSION};
use std::sync::Arc;

fn begin() -> Item {
    Item::Begin(Begin {
        factored_identity: None,
        factored: None,
        tracks: 4,
        red: Some(2),
        initial_red: Some(vec![0, 1]),
        leaders: vec!["a".into(), "b".into()],
        owners: vec![0, 0, 1, 1],
        distributed_rule: false,
        budget: 0,
        omp: false,
        identities: false,
        initial_identity: None,
    })
}

fn batch(number: u64, items: Vec<(u64, Item)>, through: u64) -> Batch {
    Batch {
        version: VERSION,
        epoch: 0,
        sensor: "sensor-0".into(),
        number,
        through,
        events: through,
        finished: false,
        items: items
            .into_iter()
            .map(|(seq, item)| Sequenced { seq, item })
            .collect(),
    }
}

fn mix(a: u32, b: u32, swap: f64) -> Item {
    Item::Mix {
        adopted: Vec::new(),
        a,
        b,
        swap,
        owner_a: 0,
        owner_b: 0,
        handed: None,
    }
}

fn observe(track: u32, red: f64, blue: f64) -> Item {
    Item::Observe {
        adopted_by: None,
        track,
        red,
        blue,
        growth: Growth::All,
        global: true,
    }
}

/// Admits and applies, as the actor does; panics on a rejection.
fn feed(leader: &mut Leader, kind: Kind, bytes: &[u8]) -> Vec<Action> {
    let input = admit(leader, kind, bytes).expect("admitted");
    apply(leader, input, bytes.len()).expect("applied")
}

/// What a query would see of the leader.
fn seen(leader: &Leader) -> (Option<Partial>, u64, u64) {
    (
        leader
            .quiet(false)
            .map(|answer| Arc::unwrap_or_clone(answer.whole())),
        leader.position(),
        leader.next_batch(),
    )
}

#[test]
fn bad_inputs_are_rejected_counted_and_change_nothing() {
    let good = [
        batch(0, vec![(1, begin())], 1),
        batch(1, vec![(2, mix(0, 1, 0.3)), (3, observe(1, 0.8, 0.2))], 3),
        batch(2, vec![(4, observe(0, 0.1, 0.7))], 4),
    ];
    let mut control = Leader::new("a");
    for b in &good {
        feed(&mut control, Kind::Batch, &encode(b));
    }

    let mut leader = Leader::new("a");
    feed(&mut leader, Kind::Batch, &encode(&good[0]));
    let before = seen(&leader);
    let mut wrong_version = good[1].clone();
    wrong_version.version = VERSION + 1;
    let full = encode(&good[1]);
    let transfer = |from, red: Vec<u32>, ln_mass| Transfer {
        trees: Vec::new(),
        components: Vec::new(),
        version: VERSION,
        from,
        seq: 2,
        sets: vec![WireSet {
            red,
            blue: vec![],
            ln_mass,
        }],
        rows: vec![],
    };
    let garbage: Vec<(&str, Kind, Vec<u8>)> = vec![
        ("truncated", Kind::Batch, full[..full.len() / 2].to_vec()),
        ("empty", Kind::Batch, Vec::new()),
        (
            "random",
            Kind::Batch,
            (0..200u32).map(|i| (i * 37 % 251) as u8).collect(),
        ),
        ("wrong version", Kind::Batch, encode(&wrong_version)),
        (
            "NaN likelihood",
            Kind::Batch,
            encode(&batch(1, vec![(2, observe(1, f64::NAN, 0.2))], 2)),
        ),
        (
            "negative likelihood",
            Kind::Batch,
            encode(&batch(1, vec![(2, observe(1, -0.5, 0.2))], 2)),
        ),
        (
            "swap 1.5",
            Kind::Batch,
            encode(&batch(1, vec![(2, mix(0, 1, 1.5))], 2)),
        ),
        (
            "track out of range",
            Kind::Batch,
            encode(&batch(1, vec![(2, mix(0, 9, 0.5))], 2)),
        ),
        (
            "a second Begin",
            Kind::Batch,
            encode(&batch(1, vec![(2, begin())], 2)),
        ),
        (
            "transfer with a track out of range",
            Kind::Transfer,
            bundle(transfer(1, vec![7], 0.0)),
        ),
        (
            "transfer from itself",
            Kind::Transfer,
            bundle(transfer(0, vec![2], 0.0)),
        ),
        (
            "transfer with a NaN mass",
            Kind::Transfer,
            bundle(transfer(1, vec![2], f64::NAN)),
        ),
        (
            "follow reply out of range",
            Kind::Followed,
            encode(&Followed {
                version: VERSION,
                epoch: 0,
                items: vec![Sequenced {
                    seq: 5,
                    item: observe(12, 0.5, 0.5),
                }],
            }),
        ),
    ];
    for (what, kind, bytes) in &garbage {
        let e = admit(&leader, *kind, bytes).expect_err(what);
        eprintln!("{what}: {e}");
        leader.note_rejected();
        assert_eq!(seen(&leader), before, "{what} changed the state");
    }
    assert_eq!(leader.stats().rejected, garbage.len() as u64);

    for b in &good[1..] {
        feed(&mut leader, Kind::Batch, &encode(b));
    }
    assert_eq!(seen(&leader), seen(&control));
}

/// A batch that came ahead of a missing one before the stream's Begin was
/// known, and a transfer before the Begin, are checked when the field is
/// known: dropped and counted, never applied.
#[test]
fn inputs_held_from_before_the_begin_are_checked_once_it_comes() {
    let mut leader = Leader::new("a");
    let outside = batch(2, vec![(4, mix(0, 9, 0.5))], 4);
    let stray = Transfer {
        trees: Vec::new(),
        components: Vec::new(),
        version: VERSION,
        from: 1,
        seq: 6,
        sets: vec![WireSet {
            red: vec![5],
            blue: vec![],
            ln_mass: 0.0,
        }],
        rows: vec![],
    };
    // Nothing to check them against yet: on their own they are fine.
    feed(&mut leader, Kind::Batch, &encode(&outside));
    feed(&mut leader, Kind::Transfer, &bundle(stray));
    feed(
        &mut leader,
        Kind::Batch,
        &encode(&batch(0, vec![(1, begin())], 1)),
    );
    assert_eq!(leader.stats().rejected, 1, "the transfer, at the Begin");
    feed(
        &mut leader,
        Kind::Batch,
        &encode(&batch(1, vec![(2, mix(0, 1, 0.5))], 3)),
    );
    let stats = leader.stats();
    assert_eq!((stats.rejected, stats.mixes), (2, 1), "batch 2 dropped");
    assert_eq!(leader.next_batch(), 2, "batch 2 is still wanted");
    // The real batch 2 then goes in as usual.
    feed(
        &mut leader,
        Kind::Batch,
        &encode(&batch(2, vec![(4, mix(0, 2, 0.5))], 4)),
    );
    assert_eq!(leader.position(), 4);
}

#[test]
fn a_begin_that_does_not_name_the_leader_is_rejected() {
    let leader = Leader::new("z");
    let e = admit(
        &leader,
        Kind::Batch,
        &encode(&batch(0, vec![(1, begin())], 1)),
    )
    .unwrap_err();
    assert!(e.to_string().contains("do not include z"), "{e}");
}

/// A transfer as a peer puts it on the transfer key: in a message of its
/// own.
fn bundle(transfer: Transfer) -> Vec<u8> {
    encode(&TransfersSent {
        epoch: 0,
        version: VERSION,
        transfers: vec![transfer],
    })
}
