//! The gateway's pure parts driven by hand: routing by interest, follows
//! (with the saturated-set rule), resends against the batch log and the
//! durable marks, and cuts now, later or never.

use crate::cuts::CutParameters;
use crate::machine::{CutOutcome, Gateway};
use crate::router::{LeaderPlace, Router, RouterConfig};
use idmesh_protocol::trace::{Header, Line, Mix, Move, Observe};
use idmesh_protocol::wire::leader_to_sensor::{
    Durable, Follow, Progress, Resend, Resent, Unfollow,
};
use idmesh_protocol::wire::sensor_to_leader::{Batch, Item};
use idmesh_protocol::wire::{decode, encode, VERSION};

/// Two leaders, a at (0, 0) and b at (10, 0); n tracks, k red.
fn router(tracks: usize, red: usize, distributed_rule: bool) -> Router {
    router_of(2, tracks, red, distributed_rule)
}

/// `leaders` leaders a, b, c, … along the x axis, 10 apart.
fn router_of(leaders: usize, tracks: usize, red: usize, distributed_rule: bool) -> Router {
    let mut header = Header::new(tracks);
    header.red = Some(red);
    let config = RouterConfig {
        factored_identity: Some(idmesh_protocol::wire::identity::DEFAULT_MAX_GROUP),
        factored: None,
        sensor: "s".into(),
        leaders: (0..leaders)
            .map(|i| LeaderPlace {
                name: ((b'a' + i as u8) as char).to_string(),
                at: Some((10.0 * i as f64, 0.0)),
            })
            .collect(),
        distributed_rule,
        budget: 0,
        omp: false,
        placed: Vec::new(),
        regions: None,
    };
    Router::new(config, &header).unwrap()
}

/// Two leaders a and b with no positions (track t belongs to t % 2),
/// exact conditioning, no pruning; the factored belief if `factored`.
fn unplaced(factored: Option<idmesh_protocol::wire::factored::FactoredStart>) -> RouterConfig {
    RouterConfig {
        factored_identity: Some(idmesh_protocol::wire::identity::DEFAULT_MAX_GROUP),
        factored,
        sensor: "s".into(),
        leaders: ["a", "b"]
            .iter()
            .map(|name| LeaderPlace {
                name: name.to_string(),
                at: None,
            })
            .collect(),
        distributed_rule: false,
        budget: 0,
        omp: false,
        placed: Vec::new(),
        regions: None,
    }
}

fn mix(a: u32, b: u32) -> Line {
    Line::Mix(Mix {
        time: 0.0,
        a,
        b,
        swap: 0.5,
    })
}

fn observe(track: u32) -> Line {
    Line::Observe(Observe {
        time: 0.0,
        track,
        red: 0.9,
        blue: 0.3,
        sensor: None,
    })
}

/// Leader a's follow request for `tracks` from item `after` on.
fn follow_of_a(after: u64, tracks: Vec<u32>) -> Vec<u8> {
    encode(&Follow {
        epoch: 0,
        version: VERSION,
        leader: 0,
        after,
        tracks,
    })
}

fn seqs(batch: &Batch) -> Vec<u64> {
    batch.items.iter().map(|s| s.seq).collect()
}

/// The batch each of `N` leaders is sent at a flush; a leader sent none
/// (nothing for it) stands as an empty batch numbered `u64::MAX`.
fn flushed<Q, const N: usize>(gateway: &mut Gateway<Q>) -> [Batch; N] {
    let mut each: [Batch; N] = std::array::from_fn(|_| Batch {
        version: VERSION,
        epoch: 0,
        sensor: "none sent".into(),
        number: u64::MAX,
        through: 0,
        events: 0,
        finished: false,
        items: Vec::new(),
    });
    for (i, batch) in gateway.flush() {
        each[i] = batch;
    }
    each
}

#[test]
fn items_go_only_to_the_leaders_whose_sets_they_may_change() {
    // 8 tracks, k = 4: before any position, track t is with leader t mod 2.
    let mut gateway: Gateway<()> = Gateway::new("s", router(8, 4, true), false);
    let begin = gateway.flush();
    assert_eq!(begin.len(), 2);
    assert!(begin
        .iter()
        .all(|(_, b)| matches!(b.items[0].item, Item::Begin(_))));
    gateway.line(&mix(0, 2)); // a's tracks only: seq 2
    gateway.line(&mix(1, 3)); // b's: seq 3
    gateway.line(&mix(2, 5)); // across: seq 4
    let [a, b] = flushed::<_, 2>(&mut gateway);
    assert_eq!((seqs(&a), seqs(&b)), (vec![2, 4], vec![3, 4]));
    assert_eq!((a.number, a.through, a.events), (1, 4, 3));
    assert!(matches!(
        a.items[1].item,
        Item::Mix {
            owner_a: 0,
            owner_b: 1,
            ..
        }
    ));
    // Track 1 walks over to a: a handover, to both of them.
    gateway.line(&Line::Move(Move {
        time: 0.0,
        track: 1,
        x: 1.0,
        y: 0.0,
    }));
    let [a, b] = flushed::<_, 2>(&mut gateway);
    assert!(matches!(
        a.items[0].item,
        Item::Handover {
            track: 1,
            from: 1,
            to: 0
        }
    ));
    assert_eq!(seqs(&a), seqs(&b));
}

#[test]
fn a_follow_gets_the_items_missed_on_its_new_tracks_and_bad_ones_are_refused() {
    let mut gateway: Gateway<()> = Gateway::new("s", router(8, 4, true), false);
    gateway.flush();
    gateway.line(&mix(1, 3)); // seq 2, b only
    gateway.line(&mix(3, 7)); // seq 3, b only
    gateway.line(&mix(0, 2)); // seq 4, a only
    gateway.flush();
    // a now follows 3 from seq 2 on: the mix of 3 and 7 at seq 3.
    let followed = gateway.follow(&follow_of_a(2, vec![3])).unwrap();
    assert_eq!(
        followed.items.iter().map(|s| s.seq).collect::<Vec<_>>(),
        [3]
    );
    // And from now on a is sent what touches 3 (and 7, mixed with it).
    gateway.line(&mix(7, 5)); // seq 5
    let [a, _] = flushed::<_, 2>(&mut gateway);
    assert_eq!(seqs(&a), [5]);
    assert!(gateway
        .follow(&follow_of_a(0, vec![8]))
        .unwrap_err()
        .contains("track 8"));
    assert!(gateway.follow(b"junk").is_err());
    assert_eq!(gateway.stats().rejected, 2);
}

#[test]
fn a_follow_that_may_bring_a_saturated_set_gets_every_observation_missed() {
    // n = 9, k = 4, three leaders of three tracks each: a's sets cannot
    // hold 4 tracks yet, so an observation of b's track 4 whose mixing log
    // does not meet a's tracks is not sent to a.
    let mut gateway: Gateway<()> = Gateway::new("s", router_of(3, 9, 4, true), false);
    gateway.flush();
    gateway.line(&observe(4)); // seq 2
    let [a, b, _] = flushed::<_, 3>(&mut gateway);
    assert!(seqs(&a).is_empty() && seqs(&b) == [2]);
    // Sets with track 1 come to a: following 4 tracks it may now hold
    // {0, 1, 3, 6} red, which says track 4 is blue. It gets the
    // observation it missed, though 4 is not among the tracks it asks for.
    let followed = gateway
        .follow(&encode(&Follow {
            epoch: 0,
            version: VERSION,
            leader: 0,
            after: 1,
            tracks: vec![1],
        }))
        .unwrap();
    assert_eq!(
        followed.items.iter().map(|s| s.seq).collect::<Vec<_>>(),
        [2]
    );
    // And every observation from now on.
    gateway.line(&observe(8)); // seq 3
    let [a, ..] = flushed::<_, 3>(&mut gateway);
    assert_eq!(seqs(&a), [3]);
}

#[test]
fn batches_are_sent_again_until_the_leader_says_they_are_safe() {
    let mut gateway: Gateway<()> = Gateway::new("s", router(4, 2, false), false);
    for t in 0..4 {
        gateway.line(&observe(t));
        gateway.flush();
    }
    let resend = |leader: &str, from| {
        encode(&Resend {
            epoch: 0,
            version: VERSION,
            leader: leader.into(),
            from,
        })
    };
    let again = gateway.resend(&resend("b", 2)).unwrap();
    assert_eq!(
        again.batches.iter().map(|b| b.number).collect::<Vec<_>>(),
        [2, 3]
    );
    let mark = Durable {
        epoch: 0,
        version: VERSION,
        leader: "b".into(),
        batch: 3,
        position: 4,
    };
    gateway.durable(&encode(&mark), "test");
    assert_eq!(gateway.kept(1), 1);
    assert!(gateway
        .resend(&resend("b", 2))
        .unwrap_err()
        .contains("safe through 3"));
    assert!(gateway
        .resend(&resend("z", 0))
        .unwrap_err()
        .contains("\"z\""));
    gateway.durable(b"junk", "test");
    assert_eq!(gateway.stats().rejected, 3);
}

#[test]
fn cuts_are_placed_now_at_their_point_or_refused_with_why() {
    let mut gateway: Gateway<u32> = Gateway::new("s", router(4, 2, false), false);
    let at = |tag: &str, events: Option<&str>| CutParameters {
        tag: Some(tag.into()),
        rows: false,
        events: events.map(str::to_owned),
    };
    gateway.line(&observe(0));
    match gateway.cut(1, &at("11", None)) {
        CutOutcome::Placed(p) => {
            assert_eq!((p.query, p.answer.seq, p.answer.events), (1, 3, 1));
            assert_eq!(p.answer.leaders, ["a", "b"]);
        }
        _ => panic!("placed now"),
    }
    let batches = gateway.flush();
    assert_eq!(batches.len(), 2, "a cut goes to every leader");
    assert!(batches
        .iter()
        .all(|(_, b)| matches!(b.items.last().unwrap().item, Item::Cut { tag: 11, .. })));
    assert!(matches!(
        gateway.cut(2, &at("12", Some("3"))),
        CutOutcome::Scheduled
    ));
    assert!(matches!(
        gateway.cut(3, &at("13", Some("9"))),
        CutOutcome::Scheduled
    ));
    assert!(gateway.line(&observe(1)).is_empty());
    let placed = gateway.line(&observe(2));
    assert_eq!(placed.len(), 1);
    assert_eq!((placed[0].query, placed[0].answer.events), (2, 3));
    let refused = |o| match o {
        CutOutcome::Refused(_, why) => why,
        _ => panic!("refused"),
    };
    assert!(refused(gateway.cut(4, &at("14", Some("1")))).contains("keeps no history"));
    // A point passed is no bad input; a malformed tag or point is, and is
    // counted like any (`cut?tag=abc` was answered, not counted).
    assert_eq!(gateway.stats().rejected, 0);
    assert!(refused(gateway.cut(5, &at("x", None))).contains("tag=<u64>"));
    assert!(refused(gateway.cut(7, &at("17", Some("abc")))).contains("events=<n>"));
    assert_eq!(gateway.stats().rejected, 2);
    // The stream ends before event 9: that cut is refused, and so is any
    // later point.
    let ended = gateway.end();
    assert_eq!(ended.len(), 1);
    assert!(ended[0].1.contains("ended at 3 events, before event 9"));
    assert!(refused(gateway.cut(6, &at("16", Some("5")))).contains("ended"));
    let last = gateway.flush();
    assert_eq!(last.len(), 2, "every leader is told the stream finished");
    assert!(last.iter().all(|(_, b)| b.finished));
}

/// An identity stream beyond the information matrix's track limit (n × n
/// numbers) is refused at the sensor, not streamed to leaders that drop
/// every batch; with a known start the leaders hold the factored identity
/// belief, which takes it.
#[test]
fn an_identity_stream_beyond_the_leaders_limit_is_refused_at_the_start() {
    let limit = idmesh_protocol::wire::valid::MAX_IDENTITY_TRACKS as usize;
    let config = |leaders: usize| RouterConfig {
        factored_identity: Some(idmesh_protocol::wire::identity::DEFAULT_MAX_GROUP),
        factored: None,
        sensor: "s".into(),
        leaders: (0..leaders)
            .map(|i| LeaderPlace {
                name: format!("l{i}"),
                at: None,
            })
            .collect(),
        distributed_rule: false,
        budget: 0,
        omp: false,
        placed: Vec::new(),
        regions: None,
    };
    let mut header = Header::new(limit + 1);
    header.identities = Some(limit + 1);
    let e = Router::new(config(2), &header).err().expect("refused");
    assert!(e.to_string().contains("identity stream"), "{e}");
    header.initial_identity = Some((0..=limit as u32).collect());
    let mut factored = config(2);
    factored.factored = Some(idmesh_protocol::wire::factored::FactoredStart {
        max_component: 3,
        split: idmesh_protocol::wire::factored::WireSplit::Original,
        shrink: true,
        regional: false,
        spread_above: 0,
    });
    if let Err(e) = Router::new(factored, &header) {
        panic!("a known start of {} tracks: {e}", limit + 1);
    }
    let mut header = Header::new(8);
    header.identities = Some(8);
    assert!(Router::new(config(2), &header).is_ok());
}

#[test]
fn under_exact_conditioning_every_observation_reaches_every_leader_and_a_mix_only_those_it_may_touch(
) {
    let mut gateway: Gateway<()> = Gateway::new("s", router(8, 4, false), false);
    gateway.flush();
    gateway.line(&mix(0, 2)); // seq 2: a's tracks only
    gateway.line(&observe(3)); // seq 3: every set grows, whoever holds it
    let [a, b] = flushed::<_, 2>(&mut gateway);
    assert_eq!((seqs(&a), seqs(&b)), (vec![2, 3], vec![3]));
    // Grown by an observation of track 0, b's sets may now hold it: a mix
    // of 0 and 2 reaches b too.
    gateway.line(&observe(0)); // seq 4
    gateway.line(&mix(0, 2)); // seq 5
    let [a, b] = flushed::<_, 2>(&mut gateway);
    assert_eq!((seqs(&a), seqs(&b)), (vec![4, 5], vec![4, 5]));
    // Both learn how far the stream is, whatever they were sent.
    assert_eq!((a.through, b.through, b.events), (5, 5, 4));
}

#[test]
fn an_identity_read_goes_to_the_owner_of_its_track_alone() {
    let mut header = Header::new(4);
    header.identities = Some(4);
    let config = unplaced(None);
    let mut gateway: Gateway<()> = Gateway::new("s", Router::new(config, &header).unwrap(), false);
    gateway.flush();
    gateway.line(&Line::Identify(idmesh_protocol::trace::Identify {
        time: 0.0,
        track: 3,
        identity: 1,
        accuracy: 0.9,
    }));
    let [a, b] = flushed::<_, 2>(&mut gateway);
    assert!(seqs(&a).is_empty());
    assert!(matches!(
        b.items[..],
        [idmesh_protocol::wire::sensor_to_leader::Sequenced {
            seq: 2,
            item: Item::Identify {
                track: 3,
                owner: 1,
                ..
            }
        }]
    ));
}

#[test]
fn follows_and_marks_from_leaders_not_of_the_stream_change_nothing() {
    let mut gateway: Gateway<()> = Gateway::new("s", router(4, 2, true), false);
    gateway.flush();
    gateway.line(&mix(0, 2));
    gateway.flush();
    let error = gateway
        .follow(&encode(&Follow {
            epoch: 0,
            version: VERSION,
            leader: 5,
            after: 0,
            tracks: vec![1],
        }))
        .unwrap_err();
    assert!(error.contains('5'), "{error}");
    assert_eq!(gateway.stats().rejected, 1);
    // A mark from nobody of this stream drops nothing.
    let stranger = Durable {
        epoch: 0,
        version: VERSION,
        leader: "z".into(),
        batch: 2,
        position: 2,
    };
    gateway.durable(&encode(&stranger), "test");
    // b was sent the Begin alone: the mix is of a's tracks.
    assert_eq!((gateway.kept(0), gateway.kept(1)), (2, 1));
    assert_eq!(gateway.router().logged(), 1);
    // A resend from a batch not sent yet is empty, not an error.
    let ahead = gateway
        .resend(&encode(&Resend {
            epoch: 0,
            version: VERSION,
            leader: "a".into(),
            from: 9,
        }))
        .unwrap();
    assert!(ahead.batches.is_empty());
}

#[test]
fn the_log_is_dropped_only_once_every_leader_is_safe_past_it() {
    let mut gateway: Gateway<()> = Gateway::new("s", router(4, 2, true), false);
    gateway.flush();
    gateway.line(&mix(0, 2)); // seq 2
    gateway.line(&mix(1, 3)); // seq 3
    gateway.flush();
    assert_eq!(gateway.router().logged(), 2);
    let mark = |leader: &str, position| Durable {
        epoch: 0,
        version: VERSION,
        leader: leader.into(),
        batch: 2,
        position,
    };
    gateway.durable(&encode(&mark("a", 3)), "test");
    assert_eq!(gateway.router().logged(), 2, "b may still follow from 0");
    gateway.durable(&encode(&mark("b", 2)), "test");
    assert_eq!(gateway.router().logged(), 1, "both safe through seq 2");
    // A mark that goes back does not bring anything back, nor move on.
    gateway.durable(&encode(&mark("b", 1)), "test");
    assert_eq!(gateway.router().logged(), 1);
}

#[test]
fn cuts_at_one_point_are_placed_together_with_their_rows_and_none_past_the_end() {
    let mut gateway: Gateway<u32> = Gateway::new("s", router(4, 2, false), false).ending_at(3);
    let at = |tag: &str, rows, events: &str| CutParameters {
        tag: Some(tag.into()),
        rows,
        events: Some(events.into()),
    };
    assert!(matches!(
        gateway.cut(1, &at("21", true, "2")),
        CutOutcome::Scheduled
    ));
    assert!(matches!(
        gateway.cut(2, &at("22", false, "2")),
        CutOutcome::Scheduled
    ));
    match gateway.cut(3, &at("23", false, "4")) {
        CutOutcome::Refused(3, why) => assert!(why.contains("ends at 3 events"), "{why}"),
        _ => panic!("refused at once: the stream ends at 3"),
    }
    match gateway.cut(
        4,
        &CutParameters {
            tag: Some("24".into()),
            rows: false,
            events: Some("two".into()),
        },
    ) {
        CutOutcome::Refused(4, why) => assert!(why.contains("count of events"), "{why}"),
        _ => panic!("refused: not a count"),
    }
    gateway.flush();
    assert!(gateway.line(&observe(0)).is_empty());
    let placed = gateway.line(&observe(1));
    let placed: Vec<(u32, u64)> = placed.iter().map(|p| (p.query, p.answer.seq)).collect();
    assert_eq!(placed, [(1, 4), (2, 5)]);
    let [a, b] = flushed::<_, 2>(&mut gateway);
    for batch in [a, b] {
        let cuts: Vec<(u64, bool)> = batch
            .items
            .iter()
            .filter_map(|s| match s.item {
                Item::Cut { tag, rows, .. } => Some((tag, rows)),
                _ => None,
            })
            .collect();
        assert_eq!(cuts, [(21, true), (22, false)]);
    }
}

/// Live ingestion through the gateway: an acknowledgement comes only for
/// lines already routed (their items are in the next batch, and `events`
/// counts them), a cut waiting for a point is placed by the ingested line
/// that reaches it, a line sent again is routed once, and a finished
/// stream takes nothing more.
#[test]
fn ingested_lines_are_routed_before_they_are_acknowledged_and_only_once() {
    use crate::ingest::{IngestRefusal, Offer};
    let mut gateway: Gateway<u32> = Gateway::new("s", router(4, 2, false), false);
    gateway.flush();
    assert!(matches!(
        gateway.cut(
            1,
            &CutParameters {
                tag: Some("5".into()),
                rows: false,
                events: Some("2".into()),
            }
        ),
        CutOutcome::Scheduled
    ));
    let payload = r#"{"kind":"mix","time":0,"a":0,"b":2,"swap":0.5}
{"kind":"observe","time":0,"track":1,"red":0.9,"blue":0.3}"#;
    let offer = |counter| Offer {
        producer: Some("cam"),
        counter: Some(counter),
        payload: payload.as_bytes(),
        time: None,
        finish: false,
    };
    let (ack, placed) = gateway.ingest(offer("0")).unwrap();
    assert_eq!((ack.accepted.clone(), ack.events), (vec![0, 1], 2));
    assert_eq!(placed.len(), 1);
    assert_eq!((placed[0].query, placed[0].answer.events), (1, 2));
    let [a, b] = flushed::<_, 2>(&mut gateway);
    // The mix (seq 2) of a's tracks, the observation (seq 3) to both, the
    // cut (seq 4) to both.
    assert_eq!((seqs(&a), seqs(&b)), (vec![2, 3, 4], vec![3, 4]));
    // The whole history again: acknowledged, nothing routed.
    let (again, placed) = gateway.ingest(offer("0")).unwrap();
    assert_eq!((again.duplicates, again.accepted.len()), (vec![0, 1], 0));
    assert!(placed.is_empty());
    assert!(gateway.flush().is_empty(), "nothing routed, no batch");
    assert_eq!(gateway.router().events(), 2);
    gateway.end();
    assert!(matches!(
        gateway.ingest(offer("2")),
        Err(IngestRefusal::Finished)
    ));
    let stats = gateway.stats();
    assert_eq!(
        (stats.ingested, stats.duplicates, stats.rejected),
        (2, 2, 1)
    );
}

/// Under `belief = "factored"` a stream with identities holds the factored
/// belief as one without does (its leaders keep the information matrix's
/// rows beside it), so its observations are routed by the factored rule:
/// to the followers of the track alone. (When such a stream held the Radon
/// belief, routing it by the factored rule grew nothing, and the colour
/// answers went wrong: the router must read the stream's belief.)
#[test]
fn an_identity_stream_under_the_factored_setting_is_factored() {
    use idmesh_protocol::wire::factored::{FactoredStart, WireSplit};
    for identities in [None, Some(4)] {
        let mut header = Header::new(4);
        header.red = Some(2);
        header.identities = identities;
        let config = unplaced(Some(FactoredStart {
            max_component: 3,
            split: WireSplit::Original,
            shrink: true,
            regional: false,
            spread_above: 0,
        }));
        let router = Router::new(config, &header).unwrap();
        assert!(
            router.begin().factored.is_some(),
            "identities {identities:?}"
        );
        assert_eq!(router.begin().identities, identities.is_some());
        let mut gateway: Gateway<()> = Gateway::new("s", router, false);
        gateway.flush();
        gateway.line(&observe(3));
        let [a, b] = flushed::<_, 2>(&mut gateway);
        // Factored: only the follower of track 3 (b) hears it.
        let expected = (vec![], vec![2]);
        assert_eq!((seqs(&a), seqs(&b)), expected, "identities {identities:?}");
    }
}

/// A factored stream's interest changes only by requests and handovers: a
/// mix grows nobody's; an unfollow drops a track unless the track entered
/// the interest again at or after the request's item (a late request must
/// not undo a later follow or handover); a Radon stream refuses one.
#[test]
fn a_factored_interest_shrinks_by_unfollow_requests_that_are_not_stale() {
    use idmesh_protocol::wire::factored::{FactoredStart, WireSplit};
    let mut header = Header::new(6);
    header.red = Some(2);
    let factored = Some(FactoredStart {
        max_component: 3,
        split: WireSplit::Original,
        shrink: true,
        regional: false,
        spread_above: 0,
    });
    // Placed as in `router`: a at (0, 0), b at (10, 0).
    let mut config = unplaced(factored);
    config.leaders[1].at = Some((10.0, 0.0));
    config.leaders[0].at = Some((0.0, 0.0));
    let routes = Router::new(config, &header).unwrap();
    let mut gateway: Gateway<()> = Gateway::new("s", routes, false);
    gateway.flush();
    let unfollow = |after, tracks: Vec<u32>| {
        encode(&Unfollow {
            epoch: 0,
            version: VERSION,
            leader: 0,
            after,
            tracks,
        })
    };
    gateway.line(&mix(0, 1)); // seq 2: a (0) and b (1)
    gateway.line(&mix(1, 3)); // seq 3: b's alone, a is not grown by seq 2
    let [a, _] = flushed::<_, 2>(&mut gateway);
    assert_eq!(seqs(&a), [2]);
    // a gathered {0, 1} at seq 2 and follows 1 from there.
    let followed = gateway.follow(&follow_of_a(2, vec![1])).unwrap();
    assert_eq!(
        followed.items.iter().map(|s| s.seq).collect::<Vec<_>>(),
        [3]
    );
    // A request decided before that follow (seq 2) is stale.
    assert_eq!(gateway.unfollow(&unfollow(2, vec![1])), Ok(0));
    gateway.line(&observe(1)); // seq 4
    let [a, _] = flushed::<_, 2>(&mut gateway);
    assert_eq!(seqs(&a), [4]);
    // At seq 4 a sent {0, 1} away: 1 goes, twice is harmless.
    assert_eq!(gateway.unfollow(&unfollow(4, vec![1])), Ok(1));
    assert_eq!(gateway.unfollow(&unfollow(4, vec![1])), Ok(0));
    gateway.line(&observe(1)); // seq 5
    let [a, _] = flushed::<_, 2>(&mut gateway);
    assert!(seqs(&a).is_empty());
    // Track 3 walks over to a (seq 6): a request from before it keeps it.
    gateway.line(&Line::Move(Move {
        time: 0.0,
        track: 3,
        x: 0.0,
        y: 0.0,
    }));
    gateway.flush();
    assert_eq!(gateway.unfollow(&unfollow(5, vec![3])), Ok(0));
    gateway.line(&observe(3)); // seq 7
    let [a, _] = flushed::<_, 2>(&mut gateway);
    assert_eq!(seqs(&a), [7]);
    assert!(gateway
        .unfollow(&unfollow(9, vec![6]))
        .unwrap_err()
        .contains("track 6"));
    assert_eq!(gateway.stats().rejected, 1);

    let mut radon: Gateway<()> = Gateway::new("s", router(6, 2, true), false);
    assert!(radon
        .unfollow(&unfollow(2, vec![1]))
        .unwrap_err()
        .contains("Radon"));
}

/// Under the regional rule with shrinking interests a leader follows
/// exactly the tracks it surveils, so a handover ends the old leader's
/// interest in the track at once, without waiting for its unfollow
/// request (which then changes nothing); a track that comes back is
/// routed to it again. Without the rule the old leader keeps the track
/// until it asks.
#[test]
fn under_the_regional_rule_a_handover_ends_the_old_leaders_interest() {
    use idmesh_protocol::wire::factored::{FactoredStart, WireSplit};
    let walk = |track, x| {
        Line::Move(Move {
            time: 0.0,
            track,
            x,
            y: 0.0,
        })
    };
    for regional in [true, false] {
        let mut header = Header::new(4);
        header.red = Some(2);
        let mut config = unplaced(Some(FactoredStart {
            max_component: 3,
            split: WireSplit::Original,
            shrink: true,
            regional,
            spread_above: 0,
        }));
        config.leaders[0].at = Some((0.0, 0.0));
        config.leaders[1].at = Some((10.0, 0.0));
        let mut gateway: Gateway<()> =
            Gateway::new("s", Router::new(config, &header).unwrap(), false);
        gateway.flush();
        gateway.line(&walk(0, 0.0)); // track 0 placed at a (round robin put it there)
        gateway.line(&walk(0, 10.0)); // seq 2: handed over to b
        gateway.line(&observe(0)); // seq 3
        let [a, b] = flushed::<_, 2>(&mut gateway);
        let expected_a: &[u64] = if regional { &[2] } else { &[2, 3] };
        assert_eq!(seqs(&a), expected_a, "regional {regional}");
        assert_eq!(seqs(&b), [2, 3]);
        let late = encode(&Unfollow {
            epoch: 0,
            version: VERSION,
            leader: 0,
            after: 2,
            tracks: vec![0],
        });
        assert_eq!(
            gateway.unfollow(&late),
            Ok(usize::from(!regional)),
            "regional {regional}"
        );
        gateway.line(&walk(0, 0.0)); // seq 4: back to a
        gateway.line(&observe(0)); // seq 5
        let [a, b] = flushed::<_, 2>(&mut gateway);
        assert_eq!(seqs(&a), [4, 5]);
        let expected_b: &[u64] = if regional { &[4] } else { &[4, 5] };
        assert_eq!(seqs(&b), expected_b, "regional {regional}");
    }
}

/// Everything a gateway would say about its state: every batch it keeps
/// for each leader (as a resend gets them), its counters, its seq and how
/// far it read its trace.
fn state_of(gateway: &mut Gateway<u32>) -> Vec<Vec<u8>> {
    let mut state: Vec<Vec<u8>> = ["a", "b"]
        .iter()
        .map(|leader| {
            let resend = encode(&Resend {
                epoch: 0,
                version: VERSION,
                leader: leader.to_string(),
                from: 0,
            });
            encode(&gateway.resend(&resend).unwrap())
        })
        .collect();
    state.push(serde_json::to_vec(gateway.stats()).unwrap());
    state.push(gateway.router().seq().to_le_bytes().to_vec());
    state.push(gateway.traced().to_le_bytes().to_vec());
    state
}

/// A journaled gateway driven through every kind of change — trace lines,
/// an ingest request with a cut scheduled inside it, standard input (a
/// good line and a bad one), a cut now, a follow, flushes, the end — and
/// a new gateway restored from its records (through the journal's bytes)
/// at each point along the way: the same batches, counters, seq and trace
/// position; the same producer counters (its lines again are duplicates)
/// and, after the end, the same batches for what comes next (a follow
/// that changed the interests included).
#[test]
fn a_gateway_restored_from_its_journal_is_the_gateway_it_was_at_every_point() {
    use crate::ingest::Offer;
    use crate::journal::{from_bytes, to_bytes, Record};
    let trace = [mix(0, 2), observe(3), mix(1, 3), mix(3, 7), observe(7)];
    let payload = "{\"kind\":\"mix\",\"time\":0,\"a\":0,\"b\":5,\"swap\":0.5}\n\
        {\"kind\":\"observe\",\"time\":0,\"track\":2,\"red\":0.9,\"blue\":0.3}\nnot a line";
    let offer = |counter| Offer {
        producer: Some("cam"),
        counter: Some(counter),
        payload: payload.as_bytes(),
        time: None,
        finish: false,
    };
    let cut = |tag: &str, events: Option<&str>| CutParameters {
        tag: Some(tag.into()),
        rows: false,
        events: events.map(str::to_owned),
    };
    let new = || Gateway::<u32>::new("s", router(8, 4, true), false).journaled();
    let mut original = new();
    let mut journal: Vec<Record> = Vec::new();
    // (records so far, the state they stand for, the producer's lines
    // taken)
    let mut points = Vec::new();
    // The journal compacted at each point, too.
    let mut compacted = Vec::new();
    let mut point = |gateway: &mut Gateway<u32>, journal: &mut Vec<Record>, offered: bool| {
        journal.extend(gateway.unjournaled());
        points.push((journal.len(), state_of(gateway), offered));
        compacted.push(gateway.compacted().unwrap());
    };
    original.flush();
    point(&mut original, &mut journal, false);
    for line in &trace[..2] {
        original.line(line);
    }
    assert!(matches!(
        original.cut(1, &cut("7", Some("3"))),
        CutOutcome::Scheduled
    ));
    let (ack, placed) = original.ingest(offer("0")).unwrap();
    assert_eq!((ack.accepted.len(), ack.next, placed.len()), (2, 3, 1));
    original.flush();
    point(&mut original, &mut journal, true);
    let good = "{\"kind\":\"observe\",\"time\":0,\"track\":1,\"red\":0.8,\"blue\":0.4}\n";
    assert!(original.read(2, good).is_ok());
    assert!(original.read(3, "{\"kind\":\"mix\"}\n").is_err());
    assert!(matches!(
        original.cut(2, &cut("8", None)),
        CutOutcome::Placed(_)
    ));
    original.flush();
    point(&mut original, &mut journal, true);
    original.line(&trace[2]);
    original.line(&trace[3]);
    let follow = encode(&Follow {
        epoch: 0,
        version: VERSION,
        leader: 0,
        after: 2,
        tracks: vec![3],
    });
    assert!(!original.follow(&follow).unwrap().items.is_empty());
    original.flush();
    point(&mut original, &mut journal, true);
    original.line(&trace[4]);
    original.end();
    original.flush();
    point(&mut original, &mut journal, true);
    assert!(journal
        .iter()
        .any(|r| matches!(r, Record::Offer { cuts, .. } if cuts.len() == 1)));
    assert!(journal.iter().any(|r| matches!(r, Record::Follow(_))));
    // Through the journal's bytes, as a restarted process reads them.
    let journal = from_bytes(&to_bytes(&journal)).unwrap();
    let unjournaled = || Gateway::<u32>::new("s", router(8, 4, true), false);
    for (records, state, offered) in &points {
        let mut restored = unjournaled();
        restored
            .restore(journal[..*records].to_vec(), &trace)
            .unwrap();
        assert!(
            restored.unjournaled().is_empty(),
            "restoring records nothing"
        );
        assert_eq!(&state_of(&mut restored), state, "after {records} records");
        if !restored.finished() {
            let (again, _) = restored.ingest(offer("0")).unwrap();
            assert_eq!(
                again.accepted.is_empty(),
                *offered,
                "after {records} records"
            );
        }
    }
    // A journal compacted at any point, and the records that came after
    // it, rebuild the same gateway as the whole journal: the same state
    // (its snapshot, byte for byte, and what it says) and producer
    // counters.
    for (i, snapshot) in compacted.iter().enumerate() {
        let snapshot = from_bytes(&to_bytes(snapshot)).unwrap();
        assert!(matches!(
            snapshot[..],
            [Record::Stream(_), Record::Snapshot(_)]
        ));
        for (j, (records, state, offered)) in points.iter().enumerate().skip(i) {
            let mut records_now = snapshot.clone();
            records_now.extend(journal[points[i].0..*records].iter().cloned());
            let mut restored = unjournaled();
            restored.restore(records_now, &trace).unwrap();
            assert_eq!(&state_of(&mut restored), state, "snapshot {i}, point {j}");
            assert_eq!(
                restored.compacted().unwrap(),
                compacted[j],
                "snapshot {i}, point {j}"
            );
            if !restored.finished() {
                let (again, _) = restored.ingest(offer("0")).unwrap();
                assert_eq!(
                    again.accepted.is_empty(),
                    *offered,
                    "snapshot {i}, point {j}"
                );
            }
        }
    }
    // A snapshot of another stream's size is refused by name.
    let error = Gateway::<u32>::new("s", router_of(3, 8, 4, true), false)
        .restore(vec![compacted[1][1].clone()], &trace)
        .expect_err("refused")
        .to_string();
    assert!(
        error.contains("the snapshot is of 2 leaders, the stream has 3"),
        "{error}"
    );
    // After the end both go on alike: a cut now, and the lines that touch
    // the track the follow added reach leader a in both.
    let mut restored = new();
    restored.restore(journal.clone(), &trace).unwrap();
    assert!(restored.finished());
    assert_eq!(restored.traced(), 5);
    // Standard input fed again from its start: the lines read before
    // are passed over (not routed, not counted), the next one is read.
    let (events, ingested) = (restored.router().events(), restored.stats().ingested);
    assert!(restored.read(2, good).unwrap().is_empty());
    assert!(restored.read(3, "{\"kind\":\"mix\"}\n").is_ok());
    assert_eq!(
        (restored.router().events(), restored.stats().ingested),
        (events, ingested)
    );
    assert!(restored.read(4, good).is_ok());
    assert_eq!(restored.router().events(), events + 1);
    original.read(4, good).unwrap();
    for gateway in [&mut original, &mut restored] {
        assert!(matches!(
            gateway.cut(3, &cut("9", None)),
            CutOutcome::Placed(_)
        ));
        gateway.line(&mix(3, 7));
        gateway.flush();
    }
    let (after, restored_after) = (state_of(&mut original), state_of(&mut restored));
    assert_eq!(after, restored_after);
    let batches: Resent = decode(&after[0]).unwrap();
    let last = &batches.batches.last().unwrap().items;
    assert!(
        matches!(last.last().unwrap().item, Item::Mix { a: 3, b: 7, .. }),
        "a follows 3: {last:?}"
    );
    // A journal of another stream (here: exact conditioning) is refused.
    let error = Gateway::<u32>::new("s", router(8, 4, false), false)
        .restore(journal.clone(), &trace)
        .expect_err("refused")
        .to_string();
    assert!(
        error.starts_with("journal record 0: the journal is of another stream"),
        "{error}"
    );
    // A trace shorter than the journal says is refused, naming the record.
    let error = new()
        .restore(journal, &trace[..3])
        .expect_err("refused")
        .to_string();
    assert!(
        error.starts_with("journal record") && error.contains("lines of the trace, which has 3"),
        "{error}"
    );
}

/// The track numbers a producer's decoder gave named ids are recorded
/// ahead of the offer whose lines carry them, and come back from the
/// journal whole or compacted (and compacted with records after it); a
/// record that gives a number another id has, or skips one, is refused.
#[test]
fn named_track_ids_come_back_from_the_journal_whole_or_compacted() {
    use crate::ingest::Offer;
    use crate::journal::{from_bytes, to_bytes, Record};
    use std::collections::BTreeMap;
    let new = || Gateway::<u32>::new("s", router(8, 4, true), false);
    let ids = |names: &[&str]| names.iter().map(|n| n.to_string()).collect::<Vec<_>>();
    let mut gateway = new().journaled();
    gateway
        .name_tracks("ros2:/a", 0, ids(&["walker", "cart"]))
        .unwrap();
    let payload = "{\"kind\":\"observe\",\"time\":0,\"track\":1,\"red\":0.9,\"blue\":0.3}\n";
    let offer = Offer {
        producer: Some("ros2:/a"),
        counter: Some("0"),
        payload: payload.as_bytes(),
        time: None,
        finish: false,
    };
    assert_eq!(gateway.ingest(offer).unwrap().0.accepted, [0]);
    gateway.name_tracks("ros2:/a", 2, ids(&["late"])).unwrap();
    gateway.name_tracks("ros2:/b", 0, ids(&["x"])).unwrap();
    let error = gateway
        .name_tracks("ros2:/a", 5, ids(&["gap"]))
        .expect_err("a number skipped");
    assert!(error.contains("only 3 ids were numbered"), "{error}");
    let want = BTreeMap::from([
        ("ros2:/a".to_string(), ids(&["walker", "cart", "late"])),
        ("ros2:/b".to_string(), ids(&["x"])),
    ]);
    assert_eq!(gateway.named_tracks(), &want);
    let journal = gateway.unjournaled();
    let at = |want: fn(&Record) -> bool| journal.iter().position(want).unwrap();
    assert!(
        at(|r| matches!(r, Record::TrackIds { .. })) < at(|r| matches!(r, Record::Offer { .. })),
        "{journal:?}"
    );
    let restored = |records: Vec<Record>| {
        let mut gateway = new();
        gateway
            .restore(from_bytes(&to_bytes(&records)).unwrap(), &[])
            .map(|()| gateway.named_tracks().clone())
            .map_err(|e| e.to_string())
    };
    assert_eq!(restored(journal.clone()), Ok(want.clone()));
    let compacted = gateway.compacted().unwrap();
    assert_eq!(restored(compacted.clone()), Ok(want.clone()));
    let mut later = compacted.clone();
    later.push(Record::TrackIds {
        producer: "ros2:/a".into(),
        first: 3,
        ids: ids(&["later"]),
    });
    let mut more = want.clone();
    more.get_mut("ros2:/a").unwrap().push("later".into());
    assert_eq!(restored(later), Ok(more));
    let mut contradicted = journal;
    contradicted.push(Record::TrackIds {
        producer: "ros2:/a".into(),
        first: 0,
        ids: ids(&["cart"]),
    });
    let error = restored(contradicted).expect_err("refused");
    assert!(
        error.contains("ros2:/a: track 0 is id \"walker\", not \"cart\""),
        "{error}"
    );
}

fn progress(leader: &str, through: u64, batch: u64) -> Vec<u8> {
    encode(&Progress {
        epoch: 0,
        version: VERSION,
        leader: leader.into(),
        through,
        batch,
    })
}

#[test]
fn the_window_lets_the_stream_at_most_its_width_past_the_slowest_leader() {
    let mut gateway: Gateway<()> = Gateway::new("s", router(8, 4, true), false).windowed(3);
    assert_eq!(
        gateway.room(),
        Some(2),
        "the Begin took seq 1; no leader has said a word"
    );
    gateway.flush();
    gateway.line(&mix(0, 2));
    gateway.line(&mix(1, 3));
    gateway.flush();
    assert_eq!(gateway.router().seq(), 3);
    assert_eq!(gateway.room(), Some(0), "held: nobody has got anywhere");
    gateway.progress(&progress("a", 3, 2), "test");
    assert_eq!(
        gateway.room(),
        Some(0),
        "b is the slowest, and it has said nothing"
    );
    gateway.progress(&progress("b", 2, 2), "test");
    assert_eq!(
        gateway.room(),
        Some(2),
        "b done through 2: the stream may go to 5"
    );
    // The latest mark counts, not the highest: a leader restarted from
    // its journal may be behind what it said before.
    gateway.progress(&progress("b", 1, 1), "test");
    assert_eq!(gateway.room(), Some(0), "1 free, under half the window");
    // Bad marks change nothing and are counted.
    gateway.progress(b"junk", "test");
    gateway.progress(&progress("z", 100, 100), "test");
    assert_eq!(gateway.room(), Some(0));
    gateway.progress(&progress("b", 3, 2), "test");
    assert_eq!(gateway.room(), Some(3));
    assert_eq!(gateway.stats().rejected, 1);
    // No window, no limit.
    let free: Gateway<()> = Gateway::new("s", router(8, 4, true), false);
    assert_eq!(free.room(), None);
}

#[test]
fn a_held_stream_sends_again_the_batches_a_leader_still_waits_for_once_its_mark_stands_still() {
    let mut gateway: Gateway<()> = Gateway::new("s", router(8, 4, true), false).windowed(1);
    gateway.flush(); // batch 0 to each
    gateway.line(&mix(0, 1));
    gateway.flush(); // batch 1 to each: lost on its way to b
                     // a has both; b still waits for batch 1, and nothing after it will
                     // show that it was lost while the window holds the stream.
    gateway.progress(&progress("a", 2, 2), "test");
    gateway.progress(&progress("b", 1, 1), "test");
    assert_eq!(gateway.room(), Some(0));
    assert!(
        gateway.stalled().is_empty(),
        "a mark seen for the first time may just be behind what is in flight"
    );
    let again = gateway.stalled();
    assert_eq!(
        again
            .iter()
            .map(|(i, b)| (*i, b.number))
            .collect::<Vec<_>>(),
        vec![(1, 1)],
        "b's batch 1 again, and nothing for a"
    );
    // b moves: its mark changed since the last look, so nothing is sent
    // until it stands still again.
    gateway.progress(&progress("b", 2, 2), "test");
    assert!(gateway.stalled().is_empty());
    assert!(gateway.stalled().is_empty(), "b has everything it was sent");
}

#[test]
fn a_leader_with_nothing_to_apply_is_sent_no_batch_until_it_is_owed_one() {
    use crate::machine::IDLE_BATCH_EVERY;
    let sent = |batches: Vec<(usize, Batch)>| -> Vec<(usize, u64, u64, usize)> {
        batches
            .iter()
            .map(|(i, b)| (*i, b.number, b.through, b.items.len()))
            .collect()
    };
    let mut gateway: Gateway<()> = Gateway::new("s", router(8, 4, true), false).windowed(4);
    assert_eq!(
        sent(gateway.flush()),
        [(0, 0, 1, 1), (1, 0, 1, 1)],
        "the Begin"
    );
    gateway.line(&mix(0, 2)); // a's tracks: seq 2
    assert_eq!(sent(gateway.flush()), [(0, 1, 2, 1)], "nothing for b");
    // b applied all it was sent and nothing waits for it: it is as far as
    // the stream (2). a is the slowest until it applies the mix.
    gateway.progress(&progress("a", 1, 1), "test");
    gateway.progress(&progress("b", 1, 1), "test");
    assert_eq!(gateway.room(), Some(3));
    gateway.progress(&progress("a", 2, 2), "test");
    assert_eq!(gateway.room(), Some(4));
    // b's mark behind its last batch (lost, or not yet applied) holds it.
    gateway.line(&mix(1, 3)); // b's: seq 3
    gateway.flush();
    assert_eq!(gateway.room(), Some(2), "b done through 1 of the 3 sent");
    // Far enough past b's last batch, b is sent one saying so.
    let mut to_b = Vec::new();
    for _ in 0..IDLE_BATCH_EVERY {
        gateway.line(&mix(0, 2));
        to_b.extend(sent(gateway.flush()).into_iter().filter(|b| b.0 == 1));
    }
    assert_eq!(to_b, [(1, 2, 3 + IDLE_BATCH_EVERY, 0)]);
    // A follow is owed a batch: the items it brings wait for the stream's
    // position, which only a batch tells.
    let before = gateway.router().seq();
    gateway
        .follow(&encode(&Follow {
            epoch: 0,
            version: VERSION,
            leader: 1,
            after: before,
            tracks: vec![1],
        }))
        .unwrap();
    assert_eq!(sent(gateway.flush()), [(1, 3, before, 0)]);
    assert!(gateway.flush().is_empty(), "once");
    // The end is told to every leader.
    gateway.end();
    let last = gateway.flush();
    assert_eq!(last.len(), 2);
    assert!(last.iter().all(|(_, b)| b.finished));
}

/// A tracker's reports of four tracks over ten frames: tracks 0 and 1
/// walk at each other, meet and part (a mix); tracks 2 and 3 stand apart
/// with class scores (observations).
fn reports() -> Vec<Line> {
    use idmesh_protocol::trace::Detect;
    let mut lines = Vec::new();
    for frame in 0..10 {
        let time = f64::from(frame) * 0.5;
        let walk = 0.6 * f64::from(frame);
        let places = [(walk, 0.0), (6.0 - walk, 0.2), (0.0, 20.0), (30.0, 20.0)];
        for (track, &(x, y)) in places.iter().enumerate() {
            let track = track as u32;
            let line = if track < 2 {
                Line::Move(Move { time, track, x, y })
            } else {
                let red = if track == 2 { 0.8 } else { 0.3 };
                let scores = [("red".to_string(), red), ("blue".to_string(), 1.0 - red)];
                Line::Detect(Detect {
                    time,
                    track,
                    x,
                    y,
                    scores: Some(scores.into_iter().collect()),
                    identity: None,
                    accuracy: None,
                })
            };
            lines.push(line);
        }
    }
    lines
}

/// Two leaders at (0, 0) and (10, 0) over the stream `header` describes.
fn router_for(header: &Header) -> Router {
    let config = RouterConfig {
        leaders: ["a", "b"]
            .iter()
            .enumerate()
            .map(|(i, name)| LeaderPlace {
                name: name.to_string(),
                at: Some((10.0 * i as f64, 0.0)),
            })
            .collect(),
        ..unplaced(None)
    };
    Router::new(config, header).unwrap()
}

/// A gateway extracting its events from a tracker's reports routes, batch
/// for batch, what a gateway routes from `idmesh extract`'s lines of the
/// same reports; restored from its journal compacted halfway, it goes on
/// to the same batches.
#[test]
fn a_gateway_extracting_from_reports_routes_what_the_extracted_trace_routes() {
    use crate::extraction::Extraction;
    use crate::journal::{from_bytes, to_bytes};
    use idmesh_extract::{Extractor, ExtractorConfig, RosterPolicy};
    let mut header = Header::new_v2(4);
    header.red = Some(2);
    let config = ExtractorConfig::default();
    let reports = reports();
    // Offline, as `idmesh extract` does it.
    let mut extractor = Extractor::new(config.clone(), RosterPolicy::Declared(vec![0, 1, 2, 3]))
        .unwrap()
        .with_prior(&header);
    let mut extracted = Vec::new();
    for line in &reports {
        let report = match line {
            Line::Move(m) => (*m).into(),
            Line::Detect(d) => d.clone().into(),
            _ => unreachable!(),
        };
        extractor.push(report, &mut extracted).unwrap();
    }
    extractor.finish(&mut extracted);
    let Some(Line::Header(written)) = extracted.first() else {
        panic!("the extractor writes its header first");
    };
    assert_eq!(written.red, Some(2), "the prior is carried");
    let count = |kind: &str| extracted.iter().filter(|l| l.kind() == kind).count();
    assert_eq!(count("mix"), 1, "{extracted:?}");
    assert!(count("observe") >= 2, "{extracted:?}");
    let mut plain = Gateway::<u32>::new("s", router_for(&header), false);
    for line in &extracted[1..] {
        plain.line(line);
    }
    plain.end();
    let want: [Batch; 2] = flushed(&mut plain);
    assert!(want.iter().all(|b| b.finished));

    let extracting = || {
        Gateway::<u32>::new("s", router_for(&header), false)
            .extracting(Extraction::new(config.clone(), &header).unwrap())
    };
    let mut live = extracting().journaled();
    let half = reports.len() / 2;
    for line in &reports[..half] {
        live.line(line);
    }
    let snapshot = from_bytes(&to_bytes(&live.compacted().unwrap())).unwrap();
    for line in &reports[half..] {
        live.line(line);
    }
    live.end();
    assert_eq!(flushed::<u32, 2>(&mut live), want);
    let mut restored = extracting();
    restored.restore(snapshot, &reports).unwrap();
    for line in &reports[half..] {
        restored.line(line);
    }
    restored.end();
    assert_eq!(flushed::<u32, 2>(&mut restored), want);
    // An event where reports are expected is refused by name.
    let mut refused = extracting();
    let error = refused.read(
        2,
        "{\"kind\":\"mix\",\"time\":9,\"a\":0,\"b\":1,\"swap\":0.5}\n",
    );
    let Err(error) = error else {
        panic!("an event taken where reports are expected");
    };
    assert!(error.contains("send move and detect lines"), "{error}");
}

/// Two producers feeding one extracting sensor: a report older than a
/// frame the other producer already sent cannot go into the stream's one
/// order. The extractor refuses it where the stream is merged, and the
/// producer, still waiting for its acknowledgement, is told which line and
/// why; its other lines are taken.
#[test]
fn a_report_behind_another_producers_frame_is_refused_to_its_producer() {
    use crate::extraction::Extraction;
    use crate::ingest::Offer;
    use idmesh_extract::ExtractorConfig;
    let mut header = Header::new_v2(4);
    header.red = Some(2);
    let mut gateway = Gateway::<u32>::new("s", router_for(&header), false)
        .extracting(Extraction::new(ExtractorConfig::default(), &header).unwrap());
    let offer = |producer, payload: &'static str| Offer {
        producer: Some(producer),
        counter: Some("0"),
        payload: payload.as_bytes(),
        time: None,
        finish: false,
    };
    let (ack, _) = gateway
        .ingest(offer(
            "left",
            "{\"kind\":\"move\",\"time\":2,\"track\":0,\"x\":0,\"y\":0}\n\
             {\"kind\":\"move\",\"time\":2,\"track\":1,\"x\":9,\"y\":0}",
        ))
        .unwrap();
    assert_eq!((ack.accepted, ack.errors.len()), (vec![0, 1], 0));
    let (ack, _) = gateway
        .ingest(offer(
            "right",
            "{\"kind\":\"move\",\"time\":2,\"track\":2,\"x\":20,\"y\":0}\n\
             {\"kind\":\"move\",\"time\":1,\"track\":3,\"x\":30,\"y\":0}\n\
             {\"kind\":\"move\",\"time\":2,\"track\":3,\"x\":30,\"y\":0}",
        ))
        .unwrap();
    assert_eq!(ack.accepted, vec![0, 2]);
    assert_eq!(ack.errors.len(), 1, "{:?}", ack.errors);
    let refused = &ack.errors[0];
    assert_eq!((refused.counter, refused.line), (1, 2));
    assert!(refused.reason.contains("before"), "{}", refused.reason);
    assert_eq!(gateway.stats().rejected, 1);
}

/// The fence: once a role's successor (a newer epoch) has been heard, what
/// its former holder (cut off, still running) marks or asks changes
/// nothing and is refused: its durable mark does not make the sensor
/// forget, its resend and follow requests are answered with why not.
#[test]
fn a_former_holder_of_a_role_is_fenced_off_once_its_successor_is_heard() {
    let mut gateway: Gateway<()> = Gateway::new("s", router(4, 2, true), false);
    gateway.flush();
    gateway.line(&mix(0, 2)); // seq 2
    gateway.line(&mix(1, 3)); // seq 3
    gateway.flush();
    let mark = |epoch, position| Durable {
        epoch,
        version: VERSION,
        leader: "a".into(),
        batch: 1,
        position,
    };
    // The successor, at epoch 2, is safe only through its Begin.
    gateway.durable(&encode(&mark(2, 1)), "successor");
    let kept = gateway.kept(0);
    assert!(kept > 0);
    // The former holder, at epoch 1, says it is safe much further.
    let rejected = gateway.stats().rejected;
    let stale = Durable {
        batch: 9,
        ..mark(1, 3)
    };
    gateway.durable(&encode(&stale), "former holder");
    assert_eq!(
        gateway.kept(0),
        kept,
        "a fenced mark makes nothing forgotten"
    );
    assert_eq!(gateway.stats().rejected, rejected + 1);
    let resend = |epoch| {
        encode(&Resend {
            epoch,
            version: VERSION,
            leader: "a".into(),
            from: 1,
        })
    };
    let refused = gateway.resend(&resend(1)).unwrap_err();
    assert!(refused.contains("fenced"), "{refused}");
    assert!(gateway.resend(&resend(2)).is_ok(), "the holder is answered");
    let follow = |epoch| Follow {
        epoch,
        version: VERSION,
        leader: 0,
        after: 3,
        tracks: vec![3],
    };
    assert!(gateway.follow(&encode(&follow(1))).is_err());
    assert!(gateway.follow(&encode(&follow(2))).is_ok());
    // The other role's epochs are its own.
    assert!(gateway
        .resend(&encode(&Resend {
            epoch: 0,
            version: VERSION,
            leader: "b".into(),
            from: 0,
        }))
        .is_ok());
}

/// A sensor role held at an epoch stamps it on every batch and reply to a
/// leader, and on every cut's answer to the coordinator; batches kept from a former holder and sent again carry the
/// epoch of the holder that resends them.
#[test]
fn batches_and_replies_carry_the_sensor_roles_epoch() {
    let mut former: Gateway<()> = Gateway::new("s", router(4, 2, true), false).at_epoch(1);
    let first = former.flush();
    assert!(!first.is_empty());
    assert!(first.iter().all(|(_, b)| b.epoch == 1));
    // The successor restored from the former holder's journal (its
    // standby's copy), at epoch 2.
    let records = former.compacted().unwrap();
    let mut successor: Gateway<()> = Gateway::new("s", router(4, 2, true), false).at_epoch(2);
    successor.restore(records, &[]).unwrap();
    let resent = successor
        .resend(&encode(&Resend {
            epoch: 0,
            version: VERSION,
            leader: "a".into(),
            from: 0,
        }))
        .unwrap();
    assert_eq!(resent.epoch, 2);
    assert!(!resent.batches.is_empty());
    assert!(resent.batches.iter().all(|b| b.epoch == 2), "restamped");
    successor.line(&mix(0, 2));
    assert!(successor.flush().iter().all(|(_, b)| b.epoch == 2));
    let followed = successor
        .follow(&encode(&Follow {
            epoch: 0,
            version: VERSION,
            leader: 0,
            after: 0,
            tracks: vec![3],
        }))
        .unwrap();
    assert_eq!(followed.epoch, 2);
    // A cut's answer too, placed now or once the stream reaches it.
    let at = |tag: &str, events: Option<&str>| CutParameters {
        tag: Some(tag.into()),
        rows: false,
        events: events.map(str::to_owned),
    };
    match successor.cut((), &at("7", None)) {
        CutOutcome::Placed(p) => assert_eq!(p.answer.epoch, 2),
        _ => panic!("placed now"),
    }
    assert!(matches!(
        successor.cut((), &at("8", Some("2"))),
        CutOutcome::Scheduled
    ));
    let placed = successor.line(&mix(1, 2));
    assert_eq!(placed.len(), 1, "placed once its point is reached");
    assert_eq!(placed[0].answer.epoch, 2);
}

/// A factored crowd of at most `spread_above` tracks among several
/// leaders is the first leader's alone, from its `Begin` on and for good
/// (moves included), and its positions answer names a place slot for
/// every leader, as the coordinator checks; a larger one is spread.
#[test]
fn a_small_factored_crowd_is_held_whole_by_the_first_leader() {
    use idmesh_protocol::wire::factored::{FactoredStart, WireSplit, DEFAULT_SPREAD_ABOVE};
    let router = |tracks: usize| {
        let config = unplaced(Some(FactoredStart {
            max_component: 6,
            split: WireSplit::LeastLoss { rounds: 1 },
            shrink: true,
            regional: true,
            spread_above: DEFAULT_SPREAD_ABOVE,
        }));
        Router::new(config, &Header::new(tracks)).unwrap()
    };
    let small = DEFAULT_SPREAD_ABOVE as usize;
    let mut whole = router(small);
    assert!(whole.begin().held_whole());
    assert!(whole.begin().owners.iter().all(|&o| o == 0));
    for (track, x) in [(3u32, 0.0), (40, 90.0), (7, -50.0)] {
        whole.line(&Line::Move(Move {
            time: 1.0,
            track,
            x,
            y: 0.0,
        }));
        whole.line(&mix(track, track + 1));
    }
    let positions = whole.positions("s", false);
    assert!(positions.owners.iter().all(|&o| o == 0), "{positions:?}");
    assert_eq!(positions.check(), Ok(()));
    assert!(!router(small + 1).begin().held_whole());
}
