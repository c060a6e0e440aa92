//! Well-formed inputs of every fuzz target: what the processes really send
//! (a stream's opening batch, a batch of every item kind, transfers with
//! sets and rows, replies, cuts) and traces of every line kind. Mutations
//! of these reach the checks behind the decoder, which random bytes rarely
//! do; cargo-fuzz starts from them too (`scripts/fuzz-smoke` writes them
//! out).

use crate::wire::coordinator_to_leader::Partial;
use crate::wire::coordinator_to_sensor::CutPlaced;
use crate::wire::leader_to_leader::{Transfer, TransfersSent, TransfersWanted, WireRow, WireSet};
use crate::wire::leader_to_sensor::{Follow, Followed, Resend, Resent, Unfollow};
use crate::wire::sensor_to_leader::{Batch, Begin, Growth, Item, Sequenced};
use crate::wire::{encode, VERSION};

/// The inputs to start from for target `name` (empty for an unknown name).
pub fn seeds(name: &str) -> Vec<Vec<u8>> {
    match name {
        "batch" => batches().iter().map(encode).collect(),
        "transfer" => transfers().iter().map(encode).collect(),
        "followed" => vec![encode(&Followed {
            version: VERSION,
            epoch: 0,
            items: sequenced(5, items()),
        })],
        "follow" => vec![encode(&Follow {
            epoch: 0,
            version: VERSION,
            leader: 1,
            after: 12,
            tracks: vec![2, 5, 7],
        })],
        "unfollow" => vec![encode(&Unfollow {
            epoch: 0,
            version: VERSION,
            leader: 2,
            after: 40,
            tracks: vec![1, 6],
        })],
        "resend" => vec![encode(&Resend {
            epoch: 0,
            version: VERSION,
            leader: "leader-1".into(),
            from: 3,
        })],
        "resent" => vec![encode(&Resent {
            version: VERSION,
            epoch: 0,
            batches: batches(),
        })],
        "transfers_wanted" => vec![encode(&TransfersWanted {
            epoch: 0,
            version: VERSION,
            to: 2,
            after: 40,
        })],
        "transfers_sent" => vec![encode(&TransfersSent {
            epoch: 0,
            version: VERSION,
            transfers: transfers(),
        })],
        "partial" => partials().iter().map(encode).collect(),
        "cut_placed" => vec![encode(&CutPlaced {
            version: VERSION,
            epoch: 0,
            sensor: "sensor-0".into(),
            seq: 33,
            events: 30,
            leaders: vec!["leader-0".into(), "leader-1".into()],
            tracks: 8,
            red: Some(3),
            finished: false,
            identities: true,
            origins: Vec::new(),
        })],
        "trace_line" => TRACE.lines().map(|l| l.as_bytes().to_vec()).collect(),
        "trace_reader" => vec![
            TRACE.as_bytes().to_vec(),
            IDENTITY_TRACE.as_bytes().to_vec(),
        ],
        _ => Vec::new(),
    }
}

/// A trace with every line kind.
const TRACE: &str = r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":4,"red":2,"initial_red":[0,1],"source":"fuzz"}
{"kind":"mix","time":1,"a":0,"b":2,"swap":0.5}
{"kind":"move","time":1.5,"track":3,"x":-2.25,"y":10}
{"kind":"observe","time":3,"track":2,"red":0.8,"blue":0.2,"sensor":"s0"}
{"kind":"truth","time":3,"red":[1,2]}
"#;

/// An identity trace: reads and assignments.
const IDENTITY_TRACE: &str = r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"identities":3,"initial_identity":[2,0,1]}
{"kind":"mix","time":0.5,"a":0,"b":1,"swap":0.25}
{"kind":"identify","time":1,"track":1,"identity":2,"accuracy":0.9}
{"kind":"truth","time":2,"identity":[0,2,1]}
"#;

fn begin(identities: bool) -> Begin {
    Begin {
        factored_identity: None,
        factored: None,
        tracks: 8,
        red: Some(3),
        initial_red: Some(vec![0, 3, 6]),
        leaders: vec!["leader-0".into(), "leader-1".into(), "leader-2".into()],
        owners: vec![0, 1, 2, 0, 1, 2, 0, 1],
        distributed_rule: true,
        budget: 100,
        omp: false,
        identities,
        initial_identity: identities.then(|| vec![7, 6, 5, 4, 3, 2, 1, 0]),
    }
}

/// One item of every kind but Begin.
fn items() -> Vec<Item> {
    vec![
        Item::Mix {
            adopted: Vec::new(),
            a: 1,
            b: 4,
            swap: 0.5,
            owner_a: 1,
            owner_b: 1,
            handed: None,
        },
        Item::Observe {
            adopted_by: None,
            track: 4,
            red: 0.8,
            blue: 0.2,
            growth: Growth::Meeting(vec![1, 4]),
            global: false,
        },
        Item::Observe {
            adopted_by: None,
            track: 0,
            red: 0.1,
            blue: 0.7,
            growth: Growth::All,
            global: true,
        },
        Item::Identify {
            adopted: false,
            track: 2,
            identity: 5,
            accuracy: 0.9,
            owner: 2,
        },
        Item::Handover {
            track: 5,
            from: 2,
            to: 0,
        },
        Item::Cut {
            events: 9,
            tag: 77,
            rows: true,
        },
    ]
}

fn sequenced(first: u64, items: Vec<Item>) -> Vec<Sequenced> {
    items
        .into_iter()
        .enumerate()
        .map(|(i, item)| Sequenced {
            seq: first + i as u64,
            item,
        })
        .collect()
}

fn batches() -> Vec<Batch> {
    let mut opening = vec![Item::Begin(begin(true))];
    opening.extend(items().into_iter().take(2));
    let batch = |number, items: Vec<Sequenced>, finished| Batch {
        version: VERSION,
        epoch: 0,
        sensor: "sensor-0".into(),
        number,
        through: items.last().map_or(20, |s| s.seq),
        events: 12,
        finished,
        items,
    };
    vec![
        batch(0, sequenced(1, opening), false),
        batch(1, sequenced(4, items()), false),
        batch(2, Vec::new(), true),
    ]
}

fn transfers() -> Vec<Transfer> {
    vec![
        Transfer {
            trees: Vec::new(),
            components: Vec::new(),
            version: VERSION,
            from: 1,
            seq: 9,
            sets: vec![
                WireSet {
                    red: vec![1, 4],
                    blue: vec![],
                    ln_mass: -0.5,
                },
                WireSet {
                    red: vec![5],
                    blue: vec![2, 7],
                    ln_mass: f64::NEG_INFINITY,
                },
            ],
            rows: vec![WireRow {
                track: 4,
                ln_likelihoods: vec![0.0, -1.0, -2.5, f64::NEG_INFINITY, 0.0, -0.1, -3.0, -4.0],
            }],
        },
        Transfer {
            trees: Vec::new(),
            components: Vec::new(),
            version: VERSION,
            from: 2,
            seq: 11,
            sets: Vec::new(),
            rows: Vec::new(),
        },
    ]
}

fn partials() -> Vec<Partial> {
    vec![Partial {
        epoch: 0,
        trees: Vec::new(),
        components: None,
        base: None,
        gone: Vec::new(),
        passive: Vec::new(),
        version: VERSION,
        leader: "leader-1".into(),
        cut: 14,
        tag: 77,
        events: 9,
        finished: false,
        log_scale: -3.5,
        total: 1.25,
        outside: 0.25,
        inside: vec![(1, 0.5), (4, -0.125), (7, 0.75)],
        coefficients: 12,
        rows: vec![WireRow {
            track: 1,
            ln_likelihoods: vec![-1.0; 8],
        }],
    }]
}
