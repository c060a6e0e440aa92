//! The one network-fault model of idmesh's deterministic simulations, in
//! the spirit of TigerBeetle's VOPR and FoundationDB's simulated network:
//! a queue of events on virtual time, and a wire that loses, doubles and
//! delays what is put on it (random delays reorder it), and cuts
//! endpoints off until they are healed. One seed, one schedule: every
//! choice is drawn from the caller's seeded generator.
//!
//! Both the sensor mesh's schedules (`sensor/src/mesh/simulation.rs`) and
//! the whole-deployment simulator (`tests/src/sim`) put their messages on
//! a [`Wire`] with [`Faults`] drawn by [`Faults::random`], so a fault one
//! of them is tested against is a fault the other is tested against too.
//! The queue carries whatever the simulation schedules (deliveries, and
//! its own crashes and partitions), so one clock orders them all.

use rand::Rng;
use std::collections::{BTreeMap, BTreeSet};

/// Virtual time, in milliseconds.
pub type Ms = u64;

/// How a wire misbehaves: each message is lost with probability `drop`,
/// else doubled with probability `duplicate`, and each copy arrives after
/// a delay drawn uniformly from `delay` (inclusive).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Faults {
    pub drop: f64,
    pub duplicate: f64,
    pub delay: (Ms, Ms),
}

impl Faults {
    /// A wire that delivers everything once, at once.
    pub const NONE: Faults = Faults {
        drop: 0.0,
        duplicate: 0.0,
        delay: (0, 0),
    };

    /// The rates a schedule is run under, drawn by its seed: from a clean
    /// wire to one that loses one message in seven, doubles one in five
    /// and delays by up to 100 ms.
    pub fn random(rng: &mut impl Rng) -> Faults {
        Faults {
            drop: [0.0, 0.01, 0.05, 0.15][rng.gen_range(0..4)],
            duplicate: [0.0, 0.05, 0.2][rng.gen_range(0..3)],
            delay: [(1, 2), (1, 20), (5, 100)][rng.gen_range(0..3)],
        }
    }

    /// The same delays, nothing lost or doubled: the faults are over.
    pub fn calm(self) -> Faults {
        Faults {
            drop: 0.0,
            duplicate: 0.0,
            ..self
        }
    }
}

/// A seeded faulty wire between endpoints `E`, on one queue of events `T`
/// ordered by time (ties keep the order they were scheduled in).
#[derive(Debug, Clone)]
pub struct Wire<E, T> {
    queue: BTreeMap<(Ms, u64), T>,
    order: u64,
    faults: Faults,
    isolated: BTreeSet<E>,
}

impl<E: Ord, T: Clone> Wire<E, T> {
    pub fn new(faults: Faults) -> Self {
        Wire {
            queue: BTreeMap::new(),
            order: 0,
            faults,
            isolated: BTreeSet::new(),
        }
    }

    /// The rates the wire runs under now.
    pub fn faults(&self) -> Faults {
        self.faults
    }

    /// Schedules `event` at `time` (the simulation's own events: crashes,
    /// partitions, timers).
    pub fn at(&mut self, time: Ms, event: T) {
        self.order += 1;
        self.queue.insert((time, self.order), event);
    }

    /// The earliest scheduled event, taken off the queue.
    pub fn pop(&mut self) -> Option<(Ms, T)> {
        self.queue
            .pop_first()
            .map(|((time, _), event)| (time, event))
    }

    /// The earliest scheduled event if it is due by `now`.
    pub fn pop_due(&mut self, now: Ms) -> Option<(Ms, T)> {
        match self.queue.first_key_value() {
            Some((&(time, _), _)) if time <= now => self.pop(),
            _ => None,
        }
    }

    /// Puts `delivery` on the wire from `from` to `to` at `now`: lost if
    /// either end is cut off or by the drop rate, else scheduled once or
    /// twice after random delays. Whether it was sent.
    pub fn send(&mut self, rng: &mut impl Rng, now: Ms, from: E, to: E, delivery: T) -> bool {
        if self.isolated.contains(&from) || self.isolated.contains(&to) {
            return false;
        }
        if self.faults.drop > 0.0 && rng.gen_bool(self.faults.drop) {
            return false;
        }
        let copies = if self.faults.duplicate > 0.0 && rng.gen_bool(self.faults.duplicate) {
            2
        } else {
            1
        };
        let (lo, hi) = self.faults.delay;
        for _ in 0..copies {
            self.at(now + rng.gen_range(lo..=hi), delivery.clone());
        }
        true
    }

    /// Cuts `endpoint` off: nothing it sends or is sent arrives.
    pub fn isolate(&mut self, endpoint: E) {
        self.isolated.insert(endpoint);
    }

    pub fn heal(&mut self, endpoint: E) {
        self.isolated.remove(&endpoint);
    }

    /// The faults are over: every endpoint healed, nothing lost or doubled
    /// from now on (the delays stay).
    pub fn calm(&mut self) {
        self.faults = self.faults.calm();
        self.isolated.clear();
    }

    /// Runs the wire under other rates from now on.
    pub fn set_faults(&mut self, faults: Faults) {
        self.faults = faults;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    #[test]
    fn a_clean_wire_delivers_everything_once_in_time_order() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut wire: Wire<u8, u32> = Wire::new(Faults {
            delay: (1, 50),
            ..Faults::NONE
        });
        for m in 0..100 {
            assert!(wire.send(&mut rng, 10, 0, 1, m));
        }
        let mut seen = Vec::new();
        let mut last = 0;
        while let Some((time, m)) = wire.pop() {
            assert!((11..=60).contains(&time) && time >= last);
            last = time;
            seen.push(m);
        }
        seen.sort();
        assert_eq!(seen, (0..100).collect::<Vec<_>>());
    }

    #[test]
    fn a_faulty_wire_loses_and_doubles_at_about_its_rates() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        let faults = Faults {
            drop: 0.2,
            duplicate: 0.25,
            delay: (0, 0),
        };
        let mut wire: Wire<u8, u32> = Wire::new(faults);
        let sent = (0..10_000)
            .filter(|&m| wire.send(&mut rng, 0, 0, 1, m))
            .count();
        let arrived = std::iter::from_fn(|| wire.pop()).count();
        assert!((7_700..8_300).contains(&sent), "{sent} sent");
        let doubled = arrived - sent;
        assert!((1_800..2_200).contains(&doubled), "{doubled} doubled");
    }

    #[test]
    fn an_isolated_endpoint_neither_sends_nor_receives_until_healed() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut wire: Wire<u8, u32> = Wire::new(Faults::NONE);
        wire.isolate(1);
        assert!(!wire.send(&mut rng, 0, 0, 1, 1));
        assert!(!wire.send(&mut rng, 0, 1, 2, 2));
        assert!(wire.send(&mut rng, 0, 0, 2, 3));
        wire.heal(1);
        assert!(wire.send(&mut rng, 0, 0, 1, 4));
        let arrived: Vec<u32> = std::iter::from_fn(|| wire.pop()).map(|(_, m)| m).collect();
        assert_eq!(arrived, vec![3, 4]);
    }

    #[test]
    fn only_due_events_are_taken_and_ties_keep_their_order() {
        let mut wire: Wire<u8, &str> = Wire::new(Faults::NONE);
        wire.at(5, "b");
        wire.at(3, "a");
        wire.at(5, "c");
        assert_eq!(wire.pop_due(2), None);
        assert_eq!(wire.pop_due(4), Some((3, "a")));
        assert_eq!(wire.pop_due(4), None);
        assert_eq!(wire.pop_due(5), Some((5, "b")));
        assert_eq!(wire.pop_due(5), Some((5, "c")));
    }

    #[test]
    fn calm_keeps_the_delays_and_stops_the_losses() {
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let mut wire: Wire<u8, u32> = Wire::new(Faults {
            drop: 0.9,
            duplicate: 0.9,
            delay: (7, 7),
        });
        wire.isolate(0);
        wire.calm();
        for m in 0..50 {
            assert!(wire.send(&mut rng, 0, 0, 1, m));
        }
        let arrived: Vec<(Ms, u32)> = std::iter::from_fn(|| wire.pop()).collect();
        assert_eq!(arrived.len(), 50);
        assert!(arrived.iter().all(|&(t, _)| t == 7));
    }
}
