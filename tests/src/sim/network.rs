//! The simulated network: a queue of events in virtual time, and a wire
//! that loses, doubles and delays messages (random delays reorder them),
//! and cuts a leader off for a while. Seeded: one seed, one schedule.

use super::world::{Event, Ms, Msg};
use rand::Rng;
use rand_chacha::ChaCha8Rng;
use std::collections::{BTreeMap, BTreeSet};

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Endpoint {
    Sensor,
    Leader(usize),
    Coordinator,
}

pub(crate) struct Network {
    /// Events by (time, order of scheduling): ties keep their order.
    queue: BTreeMap<(Ms, u64), Event>,
    order: u64,
    drop: f64,
    duplicate: f64,
    delay: (Ms, Ms),
    isolated: BTreeSet<Endpoint>,
}

impl Network {
    /// A wire with this seed's fault rates.
    pub(crate) fn random(rng: &mut ChaCha8Rng, _leaders: usize) -> Network {
        let drop = [0.0, 0.01, 0.05, 0.15][rng.gen_range(0..4)];
        let duplicate = [0.0, 0.05, 0.2][rng.gen_range(0..3)];
        let delay = [(1, 2), (1, 20), (5, 100)][rng.gen_range(0..3)];
        Network {
            queue: BTreeMap::new(),
            order: 0,
            drop,
            duplicate,
            delay,
            isolated: BTreeSet::new(),
        }
    }

    /// Crashes and partitions at random points before `span`.
    pub(crate) fn schedule_faults(&mut self, rng: &mut ChaCha8Rng, span: Ms, leaders: usize) {
        for _ in 0..rng.gen_range(0..=2) {
            let at = rng.gen_range(0..span);
            self.at(at, Event::Crash(rng.gen_range(0..leaders)));
        }
        for _ in 0..rng.gen_range(0..=2) {
            let at = rng.gen_range(0..span);
            let leader = rng.gen_range(0..leaders);
            self.at(at, Event::Isolate(leader));
            self.at(at + rng.gen_range(50..=1500), Event::Heal(leader));
        }
    }

    pub(crate) fn at(&mut self, time: Ms, event: Event) {
        self.order += 1;
        self.queue.insert((time, self.order), event);
    }

    pub fn next(&mut self) -> Option<(Ms, Event)> {
        self.queue
            .pop_first()
            .map(|((time, _), event)| (time, event))
    }

    /// Puts `msg` on the wire; false if it is lost.
    pub(crate) fn send(
        &mut self,
        rng: &mut ChaCha8Rng,
        now: Ms,
        from: Endpoint,
        to: Endpoint,
        msg: Msg,
    ) -> bool {
        if self.isolated.contains(&from) || self.isolated.contains(&to) {
            return false;
        }
        if self.drop > 0.0 && rng.gen_bool(self.drop) {
            return false;
        }
        let copies = if self.duplicate > 0.0 && rng.gen_bool(self.duplicate) {
            2
        } else {
            1
        };
        for _ in 0..copies {
            let delay = rng.gen_range(self.delay.0..=self.delay.1);
            self.at(now + delay, Event::Deliver(msg.clone()));
        }
        true
    }

    pub(crate) fn isolate(&mut self, endpoint: Endpoint) {
        self.isolated.insert(endpoint);
    }

    pub(crate) fn heal(&mut self, endpoint: Endpoint) {
        self.isolated.remove(&endpoint);
    }

    /// The faults are over: nothing is lost or doubled from now on.
    pub(crate) fn calm(&mut self) {
        self.drop = 0.0;
        self.duplicate = 0.0;
        self.isolated.clear();
    }
}
