//! A deterministic network simulator for the distributed core, in the
//! spirit of FoundationDB's and TigerBeetle's simulation testing and of
//! raft-rs's in-process `Network`: one sensor gateway, L leaders and the
//! coordinator's gathering run their real pure state machines
//! (`idmesh_sensor::Gateway`, `idmesh_leader::Node`,
//! `idmesh_coordinator::machine`) in one thread, on virtual time, through
//! a seeded network that loses, doubles, delays and reorders messages,
//! cuts leaders off and heals them, while leaders crash (killed, or losing
//! what was not fsynced) and come back from their journal and snapshot —
//! in a quarter of the crashes from a journal found damaged, cut before a
//! random entry — and queries come at random points.
//!
//! Every role is held by a process at an epoch of the voters' role map,
//! decided by three raft-rs voters (`world/voters.rs`): in the schedules
//! that claim a role mid-stream they run on the simulated clock, their
//! messages on the same faulty wire, one of them crashed or cut off for a
//! while, and an adopter claims through them as a process does. In a third of the schedules with more than one leader the
//! roles keep standbys — each snapshot goes to the heir process through
//! the network, which keeps it on its own disk and says so — and one
//! host fault strikes: a host lost for good with its disk, or a holder
//! cut off long enough to be superseded, which keeps running at its old
//! epoch, is heard again by the sensor, the peers and the coordinator once
//! the cut heals, and stops a while later. Either way the role is adopted
//! by the heir process from its standby copy (no journal, `adopted`) at
//! the next epoch, by a claim fencing the old one (`world/hosts.rs`).
//! In a quarter of the schedules the sensor keeps a standby
//! (`world/sensor_standby.rs`): its journal replicated as the driver does
//! it, the standby going away, coming back and restarting, and in half
//! of those the sensor's host lost for good, the role then served from
//! the standby's copy at the next epoch.
//!
//! Every schedule checks:
//! - every answer equals the centralized engine's at its watermark to
//!   1e-9 (exact conditioning, no pruning), and its marginals sum to k;
//! - on a factored stream with identities (half the factored schedules),
//!   the leaders' rows at every answer's cut, put together, are the
//!   centralized information matrix at its watermark, and the exact
//!   identity marginals made of them are the engine's;
//! - watermarks only move forward: an answer is never older than one
//!   given before the query was asked;
//! - a leader never goes back, comes back no lower than the durable mark
//!   it published, and a killed leader replays its journal to exactly
//!   where it was;
//! - an adopted role comes back no lower than the durable mark the role
//!   published either (the standby rule: the sensor and the peers never
//!   forget what the adopter needs);
//! - no receiver — the sensor, a peer, the coordinator — applies a message
//!   whose epoch is older than the newest it has heard of that role: each
//!   such message must be counted refused (the tally's `fenced`);
//! - every voter applies one history of commands, in one order (also
//!   again from its log after a restart);
//! - no two processes are ever recorded holding one role at one epoch, a
//!   holder runs only at the epoch the map gives it, and every answer
//!   carries an epoch the map gave;
//! - no item is applied twice or lost: each leader applied exactly the
//!   items routed to it up to its position;
//! - a sensor role taken over from the standby's copy stands exactly
//!   where the lost sensor stood, and expects the producer's next line;
//!   a sensor going on without its standby first moves its role to an
//!   epoch the copy can no longer claim;
//! - once the faults stop, every orphaned role is adopted and every former
//!   holder stopped, the final answer comes (liveness), covering the
//!   whole stream.
//!
//! A seed is a schedule: [`run`] it alone to replay a failure.

mod network;
mod scenario;
mod world;

pub use world::{Aimed, Tally};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// A property a schedule broke.
#[derive(Debug, Clone)]
pub struct Violation {
    pub what: String,
}

impl Violation {
    fn new(what: String) -> Self {
        Violation { what }
    }

    fn setup(what: String) -> Self {
        Violation {
            what: format!("could not set the world up: {what}"),
        }
    }
}

impl std::fmt::Display for Violation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.what)
    }
}

/// Runs schedule `seed` to its end.
pub fn run(seed: u64) -> Result<Tally, Violation> {
    run_aimed(seed, Aimed::default())
}

/// Runs schedule `seed` with the `aimed` faults added.
pub fn run_aimed(seed: u64, aimed: Aimed) -> Result<Tally, Violation> {
    let mut world = world::World::aimed(ChaCha8Rng::seed_from_u64(seed), aimed)?;
    world.run()?;
    Ok(world.tally.clone())
}
