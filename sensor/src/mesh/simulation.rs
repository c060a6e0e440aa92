//! The sensors of a mesh under a seeded, deterministic network (the
//! simulations' one fault model, `idmesh_faults`, at this seed's rates):
//! intake requests and slices lost, doubled, delayed (hence reordered)
//! until the faults stop; sensors killed and
//! started again from their journals (whole or compacted); producers'
//! events and cut requests coming at random moments to random sensors.
//! Each schedule checks that every leader is sent the stream one gateway
//! routing the whole trace sends it (with the cuts between), that every
//! cut is placed at one seq whichever sensor answers, and that every
//! sensor finishes. The leaders and the coordinator behind the batches
//! are the whole-deployment simulator's (`tests/src/sim`), which takes
//! any batching the sensors make.

use super::tests::{finish, routed_whole, router, trace, LEADERS};
use super::MeshConfig;
use crate::cuts::CutParameters;
use crate::ingest::Offer;
use crate::journal::Record;
use crate::machine::{CutOutcome, Gateway};
use idmesh_faults::{Faults, Wire};
use idmesh_protocol::wire::coordinator_to_sensor::CutPlaced;
use idmesh_protocol::wire::encode;
use idmesh_protocol::wire::sensor_to_leader::{Item, Sequenced};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;

struct Sensor {
    config: MeshConfig,
    gateway: Gateway<u64>,
    /// On disk: every record, each synced before what depends on it left.
    journal: Vec<Record>,
    /// The counters of the events the producer gives it, and how many it
    /// has been given.
    given: Vec<usize>,
    fed: usize,
    told_finish: bool,
}

/// What travels between sensors: a sensor's request for what a peer has
/// taken in, and the slice the peer answers with.
#[derive(Clone)]
enum Delivery {
    Want {
        from: usize,
        to: usize,
        wanted: Vec<u8>,
    },
    Slice {
        to: usize,
        bytes: Vec<u8>,
    },
}

struct Schedule {
    rng: ChaCha8Rng,
    factored: bool,
    lines: Vec<String>,
    sensors: Vec<Sensor>,
    wire: Wire<usize, Delivery>,
    now: u64,
    /// What each leader was sent, in order.
    sent: Vec<Vec<Sequenced>>,
    /// Cut answers by tag (from any sensor), and refusals.
    answers: BTreeMap<u64, Vec<CutPlaced>>,
    refusals: u64,
    crashes: u64,
    /// Requests that came after what they asked for was let go.
    stale_wants: u64,
}

impl Schedule {
    fn new(seed: u64, sensors: usize, factored: bool) -> Self {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let lines = trace(&mut rng, 150);
        let names: Vec<String> = (0..sensors).map(|s| format!("sensor-{s}")).collect();
        let mut all: Vec<Sensor> = (0..sensors)
            .map(|me| {
                let config = MeshConfig {
                    sensors: names.clone(),
                    me,
                    serves: (0..LEADERS).map(|l| l % sensors == me).collect(),
                };
                let gateway = Gateway::new(&names[me], router(factored), false)
                    .meshed(&config)
                    .journaled();
                Sensor {
                    config,
                    gateway,
                    journal: Vec::new(),
                    given: Vec::new(),
                    fed: 0,
                    told_finish: false,
                }
            })
            .collect();
        for c in 0..lines.len() {
            let s = rng.gen_range(0..sensors);
            all[s].given.push(c);
            if rng.gen_bool(0.1) {
                all[(s + 1) % sensors].given.push(c);
            }
        }
        Schedule {
            rng,
            factored,
            lines,
            sensors: all,
            wire: Wire::new(Faults::NONE),
            now: 0,
            sent: vec![Vec::new(); LEADERS],
            answers: BTreeMap::new(),
            refusals: 0,
            crashes: 0,
            stale_wants: 0,
        }
    }

    /// After anything a sensor did: its records on disk, its batches out,
    /// its answers back.
    fn settle(&mut self, s: usize) {
        let sensor = &mut self.sensors[s];
        sensor.journal.extend(sensor.gateway.unjournaled());
        for (i, batch) in sensor.gateway.flush() {
            assert!(
                sensor.config.serves[i],
                "a batch for a leader another serves"
            );
            self.sent[i].extend(batch.items);
        }
        sensor.journal.extend(sensor.gateway.unjournaled());
        for placed in sensor.gateway.answered() {
            self.answers
                .entry(placed.wanted.tag)
                .or_default()
                .push(placed.answer);
        }
        self.refusals += sensor.gateway.refused().len() as u64;
    }

    /// The producer gives sensor `s` its next few events, one request per
    /// run of consecutive counters, each with the next event's time.
    fn feed(&mut self, s: usize, n: usize) {
        let sensor = &mut self.sensors[s];
        let upto = (sensor.fed + n).min(sensor.given.len());
        for &c in &sensor.given[sensor.fed..upto] {
            let counter = c.to_string();
            let time = self.lines.get(c + 1).map(|l| line_time(l).to_string());
            let (ack, _) = sensor
                .gateway
                .ingest(Offer {
                    producer: Some("tracker"),
                    counter: Some(&counter),
                    payload: self.lines[c].as_bytes(),
                    time: time.as_deref(),
                    finish: false,
                })
                .expect("taken");
            assert_eq!(ack.accepted, vec![c as u64], "{:?}", ack.errors);
        }
        sensor.fed = upto;
        if sensor.fed == sensor.given.len() && !sensor.told_finish {
            sensor.told_finish = true;
            finish(&mut sensor.gateway);
        }
        self.settle(s);
    }

    /// Sensor `s` asks each peer for its intake, over the wire.
    fn fetch(&mut self, s: usize) {
        for (peer, wanted) in self.sensors[s].gateway.wanted() {
            let p = self
                .sensors
                .iter()
                .position(|o| o.config.sensors[o.config.me] == peer)
                .expect("a peer");
            let want = Delivery::Want {
                from: s,
                to: p,
                wanted,
            };
            self.wire.send(&mut self.rng, self.now, s, p, want);
        }
    }

    /// What the wire holds for now arrives (in time order): a request is
    /// answered with a slice, over the wire again; a slice is merged.
    fn deliver(&mut self) {
        while let Some((_, delivery)) = self.wire.pop_due(self.now) {
            match delivery {
                Delivery::Want { from, to, wanted } => {
                    // A request that comes late or twice may ask for
                    // what every sensor has since let go: the driver
                    // answers that with an error, and the asker asks
                    // again from where it is.
                    let answer = self.sensors[to].gateway.intake(&wanted);
                    self.settle(to);
                    match answer {
                        Ok((slice, _)) => {
                            let bytes = encode(&slice);
                            let slice = Delivery::Slice { to: from, bytes };
                            self.wire.send(&mut self.rng, self.now, to, from, slice);
                        }
                        Err(e) => {
                            assert!(e.contains("forgotten"), "an intake refused: {e}");
                            self.stale_wants += 1;
                        }
                    }
                }
                Delivery::Slice { to, bytes } => {
                    self.sensors[to]
                        .gateway
                        .peer(&bytes)
                        .expect("a slice merges or is skipped");
                    self.settle(to);
                }
            }
        }
    }

    /// A cut asked of some sensors (all, as the coordinator asks, but a
    /// request may be lost on the way to one).
    fn ask_cut(&mut self, tag: u64) {
        let events = self
            .rng
            .gen_bool(0.3)
            .then(|| self.rng.gen_range(0..=self.lines.len() as u64));
        let parameters = CutParameters {
            tag: Some(tag.to_string()),
            rows: false,
            events: events.map(|e| e.to_string()),
        };
        for s in 0..self.sensors.len() {
            if self.rng.gen_bool(0.2) {
                continue;
            }
            match self.sensors[s].gateway.cut(tag, &parameters) {
                CutOutcome::Placed(placed) => {
                    self.answers.entry(tag).or_default().push(placed.answer)
                }
                CutOutcome::Scheduled => {}
                CutOutcome::Refused(..) => self.refusals += 1,
            }
            self.settle(s);
        }
    }

    /// Sensor `s` killed and started again from its journal (compacted
    /// half the time, as the actor does once it grew): the cut queries it
    /// held are gone with the process.
    fn crash(&mut self, s: usize) {
        self.crashes += 1;
        let sensor = &mut self.sensors[s];
        if self.rng.gen_bool(0.5) {
            sensor.journal = sensor.gateway.compacted().expect("a snapshot");
        }
        let mut restored = Gateway::new(
            &sensor.config.sensors[sensor.config.me],
            router(self.factored),
            false,
        )
        .meshed(&sensor.config);
        restored
            .restore(sensor.journal.clone(), &[])
            .expect("the journal replays");
        sensor.gateway = restored.journaled();
        self.settle(s);
    }

    fn run(&mut self) {
        let sensors = self.sensors.len();
        self.wire.set_faults(Faults::random(&mut self.rng));
        let mut tag = 0u64;
        for _ in 0..600 {
            self.now += 1;
            let s = self.rng.gen_range(0..sensors);
            match self.rng.gen_range(0..10) {
                0..=2 => {
                    let n = self.rng.gen_range(1..5);
                    self.feed(s, n);
                }
                3..=6 => self.fetch(s),
                7 => {
                    tag += 1;
                    self.ask_cut(tag);
                }
                8 if self.rng.gen_bool(0.1) => self.crash(s),
                _ => {}
            }
            self.deliver();
        }
        // Calm: everything given, nothing lost, until every sensor ends.
        self.wire.calm();
        let round_trip = 2 * self.wire.faults().delay.1 + 1;
        for s in 0..sensors {
            self.feed(s, usize::MAX / 2);
        }
        for _ in 0..10 {
            for s in 0..sensors {
                self.fetch(s);
            }
            self.now += round_trip;
            self.deliver();
        }
    }

    fn check(&self, what: &str) {
        for sensor in &self.sensors {
            assert!(sensor.gateway.finished(), "{what}: a sensor did not finish");
        }
        let whole = routed_whole(&self.lines, self.factored);
        let mut cut_seqs: Option<Vec<u64>> = None;
        for (leader, sent) in self.sent.iter().enumerate() {
            let cuts: Vec<u64> = sent
                .iter()
                .filter(|s| matches!(s.item, Item::Cut { .. }))
                .map(|s| s.seq)
                .collect();
            // Without its cuts, and with the seqs they took closed up, a
            // leader's stream is one gateway's.
            let events: Vec<Sequenced> = sent
                .iter()
                .filter(|s| !matches!(s.item, Item::Cut { .. }))
                .map(|s| Sequenced {
                    seq: s.seq - cuts.iter().filter(|&&c| c < s.seq).count() as u64,
                    item: s.item.clone(),
                })
                .collect();
            assert_eq!(
                events, whole[leader],
                "{what}: leader {leader} was sent another stream"
            );
            match &cut_seqs {
                None => cut_seqs = Some(cuts),
                Some(first) => assert_eq!(first, &cuts, "{what}: leaders were sent other cuts"),
            }
        }
        for (tag, answers) in &self.answers {
            let first = &answers[0];
            for a in answers {
                assert_eq!(
                    (a.seq, a.events, &a.origins),
                    (first.seq, first.events, &first.origins),
                    "{what}: cut {tag} answered at two points"
                );
            }
            assert!(
                cut_seqs.as_ref().is_some_and(|c| c.contains(&first.seq)),
                "{what}: cut {tag} answered at seq {}, which no leader was sent",
                first.seq
            );
        }
    }
}

fn line_time(text: &str) -> f64 {
    serde_json::from_str::<serde_json::Value>(text)
        .ok()
        .and_then(|v| v["time"].as_f64())
        .unwrap_or_default()
}

/// Schedules per run: `IDMESH_SIM_SEEDS`, as the whole-deployment
/// simulator's (default 1,000).
fn seeds() -> u64 {
    std::env::var("IDMESH_SIM_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000)
}

#[test]
fn every_schedule_of_lost_doubled_late_slices_and_killed_sensors_routes_one_stream() {
    let (mut crashes, mut answers, mut refusals, mut stale) = (0, 0, 0, 0);
    for seed in 0..seeds() {
        let sensors = 2 + (seed % 2) as usize;
        let factored = seed % 3 != 0;
        let mut schedule = Schedule::new(seed, sensors, factored);
        schedule.run();
        schedule.check(&format!(
            "seed {seed} ({sensors} sensors, factored {factored})"
        ));
        crashes += schedule.crashes;
        answers += schedule.answers.values().map(Vec::len).sum::<usize>();
        refusals += schedule.refusals;
        stale += schedule.stale_wants;
    }
    // The schedules did what they are for.
    assert!(crashes > seeds() / 4, "{crashes} crashes");
    assert!(answers as u64 > seeds(), "{answers} cut answers");
    println!(
        "{} schedules: {crashes} sensor kills, {answers} cut answers, {refusals} refused, \
         {stale} stale intake requests",
        seeds()
    );
}
