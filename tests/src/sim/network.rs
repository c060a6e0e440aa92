//! The simulated deployment's network: the wire of the one fault model
//! the sensor mesh's schedules use too (`idmesh_faults`), between the
//! sensor, the leaders and the coordinator, with this seed's fault rates,
//! and the crashes and partitions a schedule adds on the same clock.

use super::world::{Event, Ms};
use idmesh_faults::{Faults, Wire};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Endpoint {
    Sensor,
    Leader(usize),
    /// A role's former holder, cut off and superseded, still running.
    Former(usize),
    Coordinator,
    /// A voter (1 and up).
    Voter(u64),
    /// A process's word with the voters: its claims and its reads of the
    /// map.
    Claimant,
}

/// The queue of the simulation's events, and the wire deliveries take.
pub(crate) type Network = Wire<Endpoint, Event>;

/// A wire with this seed's fault rates.
pub(crate) fn random(rng: &mut ChaCha8Rng) -> Network {
    Wire::new(Faults::random(rng))
}

/// Crashes and partitions of leaders at random points before `span`.
pub(crate) fn schedule_faults(net: &mut Network, rng: &mut ChaCha8Rng, span: Ms, leaders: usize) {
    for _ in 0..rng.gen_range(0..=2) {
        let at = rng.gen_range(0..span);
        net.at(at, Event::Crash(rng.gen_range(0..leaders)));
    }
    for _ in 0..rng.gen_range(0..=2) {
        let at = rng.gen_range(0..span);
        let leader = rng.gen_range(0..leaders);
        net.at(at, Event::Isolate(leader));
        net.at(at + rng.gen_range(50..=1500), Event::Heal(leader));
    }
}
