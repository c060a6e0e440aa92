//! Several gateways merging their intakes, driven by hand in seeded
//! random orders: whatever order the producers' requests, the peers'
//! fetches and the flushes come in, every leader is sent exactly the items
//! one gateway routing the whole trace sends it, and a cut asked of any
//! of them is placed at one seq everywhere.

use super::MeshConfig;
use crate::cuts::CutParameters;
use crate::ingest::Offer;
use crate::journal::Record;
use crate::machine::Gateway;
use crate::router::{LeaderPlace, Router, RouterConfig};
use idmesh_protocol::trace::{Header, Line};
use idmesh_protocol::wire::encode;
use idmesh_protocol::wire::sensor_to_leader::Sequenced;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub(super) const TRACKS: u32 = 12;
pub(super) const LEADERS: usize = 3;

fn header() -> Header {
    let mut header = Header::new(TRACKS as usize);
    header.red = Some(4);
    header
}

pub(super) fn router(factored: bool) -> Router {
    let config = RouterConfig {
        factored_identity: Some(idmesh_protocol::wire::identity::DEFAULT_MAX_GROUP),
        factored: factored.then_some(idmesh_protocol::wire::factored::FactoredStart {
            max_component: 4,
            split: idmesh_protocol::wire::factored::WireSplit::Original,
            shrink: false,
            regional: false,
            spread_above: 0,
        }),
        sensor: "s".into(),
        leaders: (0..LEADERS)
            .map(|i| LeaderPlace {
                name: format!("leader-{i}"),
                at: Some((10.0 * i as f64, 0.0)),
            })
            .collect(),
        distributed_rule: false,
        budget: 0,
        omp: false,
        placed: Vec::new(),
        regions: None,
    };
    Router::new(config, &header()).expect("a router")
}

/// A random trace: moves across the leaders' regions, mixes (some of
/// tracks far apart) and observations, several at each time.
pub(super) fn trace(rng: &mut ChaCha8Rng, events: usize) -> Vec<String> {
    (0..events)
        .map(|i| {
            let time = (i / 3) as f64;
            let a = rng.gen_range(0..TRACKS);
            match rng.gen_range(0..3) {
                0 => format!(
                    r#"{{"kind":"move","time":{time},"track":{a},"x":{},"y":0}}"#,
                    rng.gen_range(-5.0..25.0)
                ),
                1 => {
                    let b = (a + rng.gen_range(1..TRACKS)) % TRACKS;
                    format!(r#"{{"kind":"mix","time":{time},"a":{a},"b":{b},"swap":0.4}}"#)
                }
                _ => format!(
                    r#"{{"kind":"observe","time":{time},"track":{a},"red":0.8,"blue":0.3}}"#
                ),
            }
        })
        .collect()
}

/// The producer tells `gateway` it gives it no more events.
pub(super) fn finish(gateway: &mut Gateway<u64>) {
    gateway
        .ingest(Offer {
            producer: Some("tracker"),
            counter: None,
            payload: b"",
            time: None,
            finish: true,
        })
        .expect("finished");
}

/// What each leader is sent, in order, by one gateway routing it all.
pub(super) fn routed_whole(lines: &[String], factored: bool) -> Vec<Vec<Sequenced>> {
    let mut gateway: Gateway<()> = Gateway::new("s", router(factored), false);
    let mut sent = vec![Vec::new(); LEADERS];
    for text in lines {
        gateway.line(&Line::parse(text).expect("a line"));
        for (i, batch) in gateway.flush() {
            sent[i].extend(batch.items);
        }
    }
    sent
}

struct Mesh {
    gateways: Vec<Gateway<u64>>,
    configs: Vec<MeshConfig>,
    factored: bool,
    /// Each gateway's journal so far (compacted now and then).
    journals: Vec<Vec<Record>>,
    /// Per sensor, the counters of the lines it is given, in order.
    given: Vec<Vec<usize>>,
    next: Vec<usize>,
    sent: Vec<Vec<Sequenced>>,
}

impl Mesh {
    fn new(sensors: usize, factored: bool) -> Self {
        let names: Vec<String> = (0..sensors).map(|s| format!("sensor-{s}")).collect();
        let configs: Vec<MeshConfig> = (0..sensors)
            .map(|me| MeshConfig {
                sensors: names.clone(),
                me,
                serves: (0..LEADERS).map(|l| l % sensors == me).collect(),
            })
            .collect();
        let gateways = configs
            .iter()
            .map(|config| {
                Gateway::new(&config.sensors[config.me], router(factored), false)
                    .meshed(config)
                    .journaled()
            })
            .collect();
        Mesh {
            gateways,
            configs,
            factored,
            journals: vec![Vec::new(); sensors],
            given: vec![Vec::new(); sensors],
            next: vec![0; sensors],
            sent: vec![Vec::new(); LEADERS],
        }
    }

    fn flush(&mut self, s: usize) {
        for (i, batch) in self.gateways[s].flush() {
            assert_eq!(
                i % self.gateways.len(),
                s,
                "a batch for a leader another serves"
            );
            self.sent[i].extend(batch.items);
        }
        self.journal();
    }

    /// What every gateway recorded, onto its journal.
    fn journal(&mut self) {
        for (g, journal) in self.gateways.iter_mut().zip(&mut self.journals) {
            journal.extend(g.unjournaled());
        }
    }

    /// Sensor `s` as its journal rebuilds it equals sensor `s`; now and
    /// then its journal is compacted, as the actor does.
    fn check_restore(&mut self, s: usize, compact: bool) {
        self.journal();
        let config = &self.configs[s];
        let mut restored: Gateway<u64> =
            Gateway::new(&config.sensors[config.me], router(self.factored), false).meshed(config);
        restored
            .restore(self.journals[s].clone(), &[])
            .expect("the journal replays");
        let live = self.gateways[s].compacted().expect("a snapshot");
        assert_eq!(
            restored.compacted().expect("a snapshot"),
            live,
            "sensor {s} rebuilt from its journal is another"
        );
        if compact {
            self.journals[s] = live;
        }
    }

    /// Sensor `s` is given its next `n` lines, one request.
    fn feed(&mut self, s: usize, n: usize, lines: &[String]) {
        let from = self.next[s];
        let upto = (from + n).min(self.given[s].len());
        if from == upto {
            return;
        }
        let counters = &self.given[s][from..upto];
        // Counters with gaps go one a request: a request's lines are
        // numbered one after another.
        for &c in counters {
            let payload = lines[c].clone();
            let counter = c.to_string();
            let (ack, _) = self.gateways[s]
                .ingest(Offer {
                    producer: Some("tracker"),
                    counter: Some(&counter),
                    payload: payload.as_bytes(),
                    time: None,
                    finish: false,
                })
                .expect("taken");
            assert_eq!(ack.accepted, vec![c as u64], "{:?}", ack.errors);
        }
        self.next[s] = upto;
    }

    fn finish(&mut self, s: usize) {
        finish(&mut self.gateways[s]);
    }

    /// Sensor `s` fetches from every peer once.
    fn fetch(&mut self, s: usize) {
        for (peer, wanted) in self.gateways[s].wanted() {
            let p = self
                .gateways
                .iter()
                .position(|g| g.mesh().is_some_and(|m| m.name() == peer))
                .expect("a peer");
            let slice = encode(&self.gateways[p].intake(&wanted).expect("a slice").0);
            self.gateways[s].peer(&slice).expect("merged");
        }
        self.journal();
    }
}

fn check_merge(seed: u64, sensors: usize, factored: bool) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let lines = trace(&mut rng, 120);
    let whole = routed_whole(&lines, factored);
    let mut mesh = Mesh::new(sensors, factored);
    for (c, _) in lines.iter().enumerate() {
        let s = rng.gen_range(0..sensors);
        mesh.given[s].push(c);
        // Now and then a second sensor takes the same event too.
        if rng.gen_bool(0.1) {
            mesh.given[(s + 1) % sensors].push(c);
        }
    }
    for _ in 0..400 {
        let s = rng.gen_range(0..sensors);
        match rng.gen_range(0..3) {
            0 => mesh.feed(s, rng.gen_range(1..6), &lines),
            1 => mesh.fetch(s),
            _ => mesh.flush(s),
        }
        if rng.gen_bool(0.03) {
            mesh.check_restore(s, rng.gen_bool(0.5));
        }
    }
    for s in 0..sensors {
        mesh.feed(s, usize::MAX / 2, &lines);
        mesh.finish(s);
    }
    for _ in 0..3 {
        for s in 0..sensors {
            mesh.fetch(s);
            mesh.flush(s);
        }
    }
    for g in &mesh.gateways {
        assert!(
            g.finished(),
            "seed {seed}: a sensor whose stream did not end"
        );
    }
    let twice: u64 = mesh
        .gateways
        .iter()
        .map(|g| g.stats().merged_twice)
        .max()
        .unwrap_or(0);
    let doubled = (0..lines.len())
        .filter(|c| mesh.given.iter().filter(|g| g.contains(c)).count() > 1)
        .count() as u64;
    assert_eq!(twice, doubled, "seed {seed}");
    for (leader, whole) in whole.iter().enumerate() {
        assert_eq!(
            &mesh.sent[leader], whole,
            "seed {seed}, {sensors} sensors: leader {leader} was sent another stream"
        );
    }
}

#[test]
fn every_leader_is_sent_what_one_gateway_would_send_whatever_the_interleaving() {
    for seed in 0..40 {
        check_merge(seed, 2, seed % 2 == 0);
        check_merge(seed, 3, seed % 2 == 1);
    }
}

#[test]
fn a_cut_asked_of_every_sensor_is_placed_once_at_one_seq() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let lines = trace(&mut rng, 30);
    let mut mesh = Mesh::new(2, true);
    for c in 0..lines.len() {
        mesh.given[c % 2].push(c);
    }
    mesh.feed(0, 4, &lines);
    mesh.feed(1, 4, &lines);
    let cut = |tag: u64, events: Option<u64>| CutParameters {
        tag: Some(tag.to_string()),
        rows: false,
        events: events.map(|e| e.to_string()),
    };
    for (s, g) in mesh.gateways.iter_mut().enumerate() {
        let _ = g.cut(s as u64, &cut(5, None));
        let _ = g.cut(10 + s as u64, &cut(6, Some(20)));
    }
    for _ in 0..2 {
        mesh.fetch(0);
        mesh.fetch(1);
    }
    let first: Vec<_> = mesh.gateways.iter_mut().map(|g| g.answered()).collect();
    assert_eq!(first[0].len(), 1);
    assert_eq!(first[1].len(), 1);
    let same = |a: &idmesh_protocol::wire::coordinator_to_sensor::CutPlaced,
                b: &idmesh_protocol::wire::coordinator_to_sensor::CutPlaced| {
        assert_eq!((a.seq, a.events, &a.origins), (b.seq, b.events, &b.origins));
    };
    same(&first[0][0].answer, &first[1][0].answer);
    assert_eq!(first[0][0].answer.origins.len(), 2);
    // The cut at event 20 waits for it, then is placed at one seq too.
    mesh.feed(0, 100, &lines);
    mesh.feed(1, 100, &lines);
    for s in 0..2 {
        mesh.finish(s);
    }
    for _ in 0..2 {
        mesh.fetch(0);
        mesh.fetch(1);
    }
    let later: Vec<_> = mesh.gateways.iter_mut().map(|g| g.answered()).collect();
    assert_eq!(later[0].len(), 1);
    assert_eq!(later[0][0].answer.events, 20);
    same(&later[0][0].answer, &later[1][0].answer);
    // After the end, a cut asked of one finished sensor alone is placed
    // once its peer has been asked for its intake (the peer moves its
    // watermark past it).
    let _ = mesh.gateways[0].cut(99, &cut(8, None));
    mesh.fetch(0);
    mesh.fetch(1);
    mesh.fetch(0);
    let end: Vec<_> = mesh.gateways.iter_mut().map(|g| g.answered()).collect();
    assert_eq!(end[0].len(), 1);
    assert!(end[0][0].answer.finished);
    let again = mesh.gateways[1].cut(98, &cut(8, None));
    match again {
        crate::machine::CutOutcome::Placed(p) => same(&p.answer, &end[0][0].answer),
        _ => panic!("a cut merged already is answered from memory"),
    }
}

#[test]
fn a_late_event_is_refused_with_why_and_counted() {
    let mut mesh = Mesh::new(2, false);
    let line = |time: f64| format!(r#"{{"kind":"mix","time":{time},"a":0,"b":1,"swap":0.5}}"#);
    let offer = |g: &mut Gateway<u64>, counter: &str, text: &str| {
        g.ingest(Offer {
            producer: Some("cam"),
            counter: Some(counter),
            payload: text.as_bytes(),
            time: None,
            finish: false,
        })
        .expect("judged")
        .0
    };
    let g = &mut mesh.gateways[0];
    assert_eq!(offer(g, "0", &line(2.0)).accepted, [0]);
    let late = offer(g, "3", &line(1.0));
    assert!(late.accepted.is_empty());
    assert!(
        late.errors[0].reason.starts_with("late"),
        "{:?}",
        late.errors
    );
    // A counter below the last taken that was never taken is refused; one
    // taken is a duplicate.
    assert_eq!(offer(g, "0", &line(2.0)).duplicates, [0]);
    assert!(!offer(g, "2", &line(3.0)).errors.is_empty());
    assert_eq!(g.stats().late, 1);
    assert_eq!(g.stats().out_of_order, 1);
}
