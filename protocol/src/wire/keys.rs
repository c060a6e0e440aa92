//! Key expressions. Everything lives under a deployment prefix (default
//! `idmesh/default`) so that several deployments can share a network.
//!
//! | key | who declares | what |
//! |---|---|---|
//! | `P/leader/<name>/events` | leader subscribes | its event stream ([`sensor_to_leader`](super::sensor_to_leader)) |
//! | `P/leader/<name>/transfer` | leader subscribes | sets handed to it, a step's in one `TransfersSent` ([`leader_to_leader`](super::leader_to_leader)) |
//! | `P/leader/<name>/partial` | leader queryable | partial sums at a cut |
//! | `P/leader/<name>/stats` | leader queryable | its counters |
//! | `P/sensor/<name>/cut` | sensor queryable | a cut of the stream |
//! | `P/sensor/<name>/follow` | sensor queryable | follow tracks, with the events missed |
//! | `P/sensor/<name>/unfollow` | leader puts; sensor subscribes | stop following tracks (factored streams; fire and forget) |
//! | `P/sensor/<name>/resend` | sensor queryable | batches a leader lost, again |
//! | `P/sensor/<name>/stats` | sensor queryable | its counters (JSON) |
//! | `P/sensor/<name>/ingest` | sensor queryable | trace lines from any producer, acknowledged ([`producer_to_sensor`](super::producer_to_sensor)) |
//! | `P/sensor/<name>/intake` | sensor queryable | its intake, for the other sensors to merge ([`sensor_to_sensor`](super::sensor_to_sensor)) |
//! | `P/sensor/<name>/positions` | sensor queryable | every track's last position and owner where the stream is (JSON) |
//! | `P/leader/<name>/sent` | leader queryable | transfers it sent a peer, again (for a restarted peer) |
//! | `P/leader/<name>/durable` | leader publishes; sensor and peers subscribe | how far its state is safe: what others may stop keeping for it |
//! | `P/leader/<name>/standby` | the process hosting leader role `<name>` subscribes | snapshots of the roles it would adopt, to keep on its disk ([`leader_to_leader`](super::leader_to_leader)) |
//! | `P/leader/<name>/stored` | a standby puts; leader role `<name>` subscribes | the standby's word that it keeps the role's snapshot |
//! | `P/leader/<name>/progress` | leader publishes; sensor subscribes | how far it has applied the stream: the sensor's flow control |
//! | `P/query/marginals`, `P/query/track/<t>`, `P/query/stats` | coordinator queryables | the user API (JSON) |
//! | `P/query/identity`, `P/query/identity/<t>` | coordinator queryables | identity marginals, all tracks or one (JSON) |
//! | `P/query/positions` | coordinator queryable | where every track was last seen, and its leader (JSON) |
//! | `P/alive/<role>/<name>` | every process | liveliness token |
//! | `P/alive/home/<name>` | a leader process standing by for its own role | asks the process that adopted the role to hand it back |
//! | `P/ping/<role>/<name>` | every process | answers at once: the raw round trip, for health checks and the bench |

pub const DEFAULT_PREFIX: &str = "idmesh/default";

#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Keys {
    prefix: String,
}

impl Keys {
    pub fn new(prefix: impl Into<String>) -> Self {
        let prefix: String = prefix.into();
        Keys {
            prefix: prefix.trim_end_matches('/').to_string(),
        }
    }

    pub fn prefix(&self) -> &str {
        &self.prefix
    }

    pub fn leader_events(&self, leader: &str) -> String {
        format!("{}/leader/{leader}/events", self.prefix)
    }

    pub fn leader_transfer(&self, leader: &str) -> String {
        format!("{}/leader/{leader}/transfer", self.prefix)
    }

    pub fn leader_partial(&self, leader: &str) -> String {
        format!("{}/leader/{leader}/partial", self.prefix)
    }

    pub fn every_leader_partial(&self) -> String {
        format!("{}/leader/*/partial", self.prefix)
    }

    /// Where a leader puts its partial sums at the cut tagged `tag` as
    /// soon as it reaches it, unasked: the coordinator that placed the cut
    /// takes them from here rather than asking (see `Partial`).
    pub fn leader_pushed(&self, leader: &str, tag: u64) -> String {
        format!("{}/leader/{leader}/pushed/{tag}", self.prefix)
    }

    pub fn every_leader_pushed(&self) -> String {
        format!("{}/leader/*/pushed/*", self.prefix)
    }

    pub fn leader_stats(&self, leader: &str) -> String {
        format!("{}/leader/{leader}/stats", self.prefix)
    }

    pub fn every_leader_stats(&self) -> String {
        format!("{}/leader/*/stats", self.prefix)
    }

    pub fn sensor_cut(&self, sensor: &str) -> String {
        format!("{}/sensor/{sensor}/cut", self.prefix)
    }

    pub fn every_sensor_cut(&self) -> String {
        format!("{}/sensor/*/cut", self.prefix)
    }

    pub fn sensor_follow(&self, sensor: &str) -> String {
        format!("{}/sensor/{sensor}/follow", self.prefix)
    }

    pub fn sensor_unfollow(&self, sensor: &str) -> String {
        format!("{}/sensor/{sensor}/unfollow", self.prefix)
    }

    pub fn sensor_stats(&self, sensor: &str) -> String {
        format!("{}/sensor/{sensor}/stats", self.prefix)
    }

    pub fn every_sensor_stats(&self) -> String {
        format!("{}/sensor/*/stats", self.prefix)
    }

    pub fn sensor_positions(&self, sensor: &str) -> String {
        format!("{}/sensor/{sensor}/positions", self.prefix)
    }

    pub fn every_sensor_positions(&self) -> String {
        format!("{}/sensor/*/positions", self.prefix)
    }

    pub fn sensor_ingest(&self, sensor: &str) -> String {
        format!("{}/sensor/{sensor}/ingest", self.prefix)
    }

    pub fn sensor_resend(&self, sensor: &str) -> String {
        format!("{}/sensor/{sensor}/resend", self.prefix)
    }

    /// Where process `standby`, standing by for sensor role `sensor`,
    /// takes the journal's records (one key per standby: the holder
    /// replicates to one of them at a time).
    pub fn sensor_replicate(&self, sensor: &str, standby: &str) -> String {
        format!("{}/sensor/{sensor}/replicate/{standby}", self.prefix)
    }

    pub fn sensor_intake(&self, sensor: &str) -> String {
        format!("{}/sensor/{sensor}/intake", self.prefix)
    }

    pub fn leader_sent(&self, leader: &str) -> String {
        format!("{}/leader/{leader}/sent", self.prefix)
    }

    pub fn leader_durable(&self, leader: &str) -> String {
        format!("{}/leader/{leader}/durable", self.prefix)
    }

    pub fn every_leader_durable(&self) -> String {
        format!("{}/leader/*/durable", self.prefix)
    }

    /// Where snapshots go for the process hosting role `standby` to keep.
    pub fn leader_standby(&self, standby: &str) -> String {
        format!("{}/leader/{standby}/standby", self.prefix)
    }

    /// Where process `process` answers with the standby copy it keeps of
    /// role `role`.
    pub fn leader_copy(&self, role: &str, process: &str) -> String {
        format!("{}/leader/{role}/copy/{process}", self.prefix)
    }

    /// Every process's standby copy of role `role` (an adopter's question).
    pub fn every_leader_copy(&self, role: &str) -> String {
        self.leader_copy(role, "*")
    }

    /// Where role `leader`'s standby says it keeps its snapshot.
    pub fn leader_stored(&self, leader: &str) -> String {
        format!("{}/leader/{leader}/stored", self.prefix)
    }

    pub fn leader_progress(&self, leader: &str) -> String {
        format!("{}/leader/{leader}/progress", self.prefix)
    }

    pub fn every_leader_progress(&self) -> String {
        format!("{}/leader/*/progress", self.prefix)
    }

    pub fn query_marginals(&self) -> String {
        format!("{}/query/marginals", self.prefix)
    }

    pub fn query_track(&self, track: u32) -> String {
        format!("{}/query/track/{track}", self.prefix)
    }

    pub fn query_any_track(&self) -> String {
        format!("{}/query/track/*", self.prefix)
    }

    pub fn query_identity(&self) -> String {
        format!("{}/query/identity", self.prefix)
    }

    pub fn query_identity_track(&self, track: u32) -> String {
        format!("{}/query/identity/{track}", self.prefix)
    }

    pub fn query_any_identity_track(&self) -> String {
        format!("{}/query/identity/*", self.prefix)
    }

    pub fn query_positions(&self) -> String {
        format!("{}/query/positions", self.prefix)
    }

    pub fn query_stats(&self) -> String {
        format!("{}/query/stats", self.prefix)
    }

    /// Raft messages for voter `id` (the role map's consensus).
    pub fn raft(&self, id: u64) -> String {
        format!("{}/raft/{id}", self.prefix)
    }

    /// Commands proposed to the voters: claims and releases of roles.
    pub fn raft_propose(&self) -> String {
        format!("{}/raft/propose", self.prefix)
    }

    /// The role map as each voter's committed log built it.
    pub fn query_roles(&self) -> String {
        format!("{}/query/roles", self.prefix)
    }

    pub fn alive(&self, role: &str, name: &str) -> String {
        format!("{}/alive/{role}/{name}", self.prefix)
    }

    pub fn alive_role(&self, role: &str) -> String {
        format!("{}/alive/{role}/*", self.prefix)
    }

    pub fn ping(&self, role: &str, name: &str) -> String {
        format!("{}/ping/{role}/{name}", self.prefix)
    }

    pub fn every_ping(&self, role: &str) -> String {
        format!("{}/ping/{role}/*", self.prefix)
    }

    /// The last chunk of a key: the name in `P/leader/<name>/partial`, the
    /// track in `P/query/track/<t>`, the name in `P/alive/leader/<name>`.
    pub fn chunk(key: &str, from_end: usize) -> Option<&str> {
        key.rsplit('/').nth(from_end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_sit_under_the_prefix_and_names_can_be_read_back() {
        let keys = Keys::new("idmesh/test/");
        assert_eq!(keys.leader_events("l0"), "idmesh/test/leader/l0/events");
        assert_eq!(keys.query_track(12), "idmesh/test/query/track/12");
        assert_eq!(Keys::chunk(&keys.leader_partial("l3"), 1), Some("l3"));
        assert_eq!(Keys::chunk(&keys.alive("leader", "l2"), 0), Some("l2"));
    }
}
