//! Zenoh access control generated from the topology.
//!
//! Zenoh checks every message on a link against the certificate common name
//! of the process at the other end: on the way in (ingress: what that peer
//! may send us) and on the way out (egress: what we may send it), denying
//! whatever no rule allows. The rules here are written once, as grants —
//! who may send what to whom — and each process takes the ones it is the
//! receiver of as ingress rules and the ones it is the sender of as egress
//! rules. Keys carry the sender's own name where the key names a process,
//! so a sensor serves only its own keys; a leader may serve any leader
//! role's, because a leader process adopts the role of one gone for good
//! (`idmesh_leader::host`) — and nothing but leader roles. A sensor's
//! standby (`[[sensor_standby]]`) may take the sensor's role over, so it
//! counts among the sensors below and serves that sensor's keys (and no
//! other's); the sensor and its standbys replicate the journal to each
//! other and watch each other's tokens, in whichever direction the role
//! stands. Every process with a role may read the voters' map
//! (`query/roles`), through which it claims and keeps its role.
//!
//! | from | to | messages | keys |
//! |---|---|---|---|
//! | sensor S | leaders | put | `P/leader/*/events` |
//! | sensor S | leaders | liveliness query | `P/alive/leader/*` |
//! | leader L | leaders | put, query | `P/leader/*/transfer`, `P/leader/*/sent` |
//! | leader L | leaders | query | `P/leader/*/copy/*` (an adopter asks for the standby copies the others keep) |
//! | leader L | sensor | query | `P/sensor/*/follow`, `P/sensor/*/resend` |
//! | leader L | sensor | put | `P/sensor/*/unfollow` (tracks it no longer needs) |
//! | sensor | leaders | declare subscriber | `P/sensor/*/unfollow` |
//! | leader L | sensor | put | `P/leader/*/progress` (how far it has got: flow control) |
//! | sensor | leaders | declare subscriber | `P/leader/*/progress` |
//! | leader L | sensor, leaders | put | `P/leader/*/durable` (how far it is safe) |
//! | sensor, leaders | leaders | declare subscriber | `P/leader/*/durable` |
//! | leader L | leaders | liveliness subscriber, liveliness query | `P/alive/leader/*` (membership), `P/alive/home/*` (a process back for its adopted role) |
//! | coordinator | leaders | query | `P/leader/*/partial`, `P/leader/*/stats` |
//! | coordinator | sensor | query | `P/sensor/*/cut`, `P/sensor/*/stats`, `P/sensor/*/positions` |
//! | sensor, its standby | each other | query | `P/sensor/*/replicate/*` (the journal's records) |
//! | sensor, its standby | each other | liveliness subscriber, liveliness query | `P/alive/sensor/*`, `P/alive/sensor-standby/*` |
//! | every process | voters | put, query | `P/raft/propose` (claims), `P/query/roles` (the map) |
//! | clients | coordinator | query | `P/query/**` |
//! | coordinator | clients | declare queryable, reply | `P/query/**` |
//! | producers | sensor | query | `P/sensor/S/ingest` |
//! | sensor | producers | declare queryable, reply | `P/sensor/S/ingest` |
//! | every process N | every process | declare what it serves, reply, liveliness token | its own keys (`P/sensor/N/**`, `P/query/**`, `P/ping/<role>/N`, `P/alive/<role>/N`); for a leader, every leader role's (`P/leader/*/**`, `P/alive/leader/*`) and its home token `P/alive/home/N`; for a sensor's standby, that sensor's (`P/sensor/S/**`, `P/alive/sensor/S`) and a sensor with a standby stands by under `P/alive/sensor-standby/N` |
//! | leader, sensor | coordinator | reply | the wildcard keys it asks them all on (`P/leader/*/partial`, `P/leader/*/stats`, `P/sensor/*/cut`, `P/sensor/*/stats`, `P/sensor/*/positions`): Zenoh replies on the asker's key |
//! | voters | every process | reply | `P/query/roles` |
//! | every process | every process | query | `P/ping/**` |

use crate::runtime::topology::{Member, Topology};
use idmesh_protocol::wire::keys::Keys;
use idmesh_sensor::STANDBY_ROLE;
use serde_json::{json, Value};
use std::collections::{BTreeMap, BTreeSet};

/// Processes named `from` may send `messages` on `keys` to processes
/// named `to` (certificate common names).
#[derive(Debug, Clone)]
pub(crate) struct Grant {
    /// A short name for the rule ids, so that Zenoh's logs say which.
    pub what: String,
    pub from: Vec<String>,
    pub to: Vec<String>,
    pub messages: &'static [&'static str],
    pub keys: Vec<String>,
}

/// Declares what a process serves and answers for it.
const SERVE: &[&str] = &["declare_queryable", "reply"];

/// Who takes part, by certificate common name.
struct Parties {
    coordinator: Vec<String>,
    /// The processes that may act as a sensor: the sensors and their
    /// standbys.
    sensor: Vec<String>,
    /// The sensor roles (whose keys, such as the ingest key, are named
    /// after them).
    sensor_roles: Vec<String>,
    /// Each sensor standby, and the sensor it stands by for.
    stands_by: BTreeMap<String, String>,
    leaders: Vec<String>,
    voters: Vec<String>,
    members: Vec<String>,
    /// Those who may ask the coordinator (none without `[security]`).
    clients: Vec<String>,
    /// Those who may feed the sensors (none without `[security]`).
    producers: Vec<String>,
}

impl Parties {
    fn of(topology: &Topology) -> Self {
        Parties {
            coordinator: topology.coordinators().map(|c| c.name.clone()).collect(),
            sensor: topology
                .sensors
                .iter()
                .map(|s| s.name.clone())
                .chain(topology.sensor_standbys.iter().map(|s| s.name.clone()))
                .collect(),
            sensor_roles: topology.sensors.iter().map(|s| s.name.clone()).collect(),
            stands_by: topology
                .sensor_standbys
                .iter()
                .map(|s| (s.name.clone(), s.sensor.clone()))
                .collect(),
            leaders: topology.leader.iter().map(|l| l.name.clone()).collect(),
            voters: topology.voters.iter().map(|v| v.name.clone()).collect(),
            members: topology.members().into_iter().map(|m| m.name).collect(),
            clients: topology
                .security
                .as_ref()
                .map(|s| s.clients.clone())
                .unwrap_or_default(),
            producers: topology
                .security
                .as_ref()
                .map(|s| s.producers.clone())
                .unwrap_or_default(),
        }
    }

    /// The sensor role process `name` acts as: the one it stands by for,
    /// once it takes it over; a sensor's own otherwise.
    fn sensor_of<'a>(&'a self, name: &'a str) -> &'a str {
        self.stands_by.get(name).map_or(name, String::as_str)
    }

    /// Whether sensor `name` has a standby (and so may stand by for it).
    fn has_standby(&self, name: &str) -> bool {
        self.stands_by.values().any(|sensor| sensor == name)
    }
}

/// Processes `from` may send `messages` on `keys` to processes `to`.
fn grant(
    what: &str,
    from: &[String],
    to: &[String],
    messages: &'static [&'static str],
    keys: Vec<String>,
) -> Grant {
    Grant {
        what: what.to_string(),
        from: from.to_vec(),
        to: to.to_vec(),
        messages,
        keys,
    }
}

/// Every grant of the deployment.
pub(crate) fn grants(topology: &Topology) -> Vec<Grant> {
    let keys = Keys::new(topology.prefix.clone());
    let parties = Parties::of(topology);
    let mut grants = stream_grants(&keys, &parties);
    grants.extend(coordinator_grants(&keys, &parties));
    grants.push(grant(
        "pings",
        &parties.members,
        &parties.members,
        &["query"],
        vec![format!("{}/ping/**", keys.prefix())],
    ));
    grants.extend(voter_grants(&keys, &parties));
    grants.extend(standby_grants(&keys, &parties));
    grants.extend(outside_grants(&keys, &parties));
    // What each process serves, under its own name.
    for m in topology.members() {
        grants.extend(member_grants(&keys, &parties, &m));
    }
    grants
}

/// What the sensors and the leaders send one another as the stream runs.
fn stream_grants(keys: &Keys, parties: &Parties) -> Vec<Grant> {
    vec![
        // Several sensors fetch one another's intake.
        grant(
            "intake",
            &parties.sensor,
            &parties.sensor,
            &["query", "declare_queryable", "reply"],
            vec![keys.sensor_intake("*")],
        ),
        grant(
            "events",
            &parties.sensor,
            &parties.leaders,
            &["put"],
            vec![keys.leader_events("*")],
        ),
        // The sensor starts streaming once it sees every leader's token.
        grant(
            "leaders-up",
            &parties.sensor,
            &parties.leaders,
            &["liveliness_query"],
            vec![keys.alive_role("leader")],
        ),
        grant(
            "transfers",
            &parties.leaders,
            &parties.leaders,
            &["put", "query"],
            vec![keys.leader_transfer("*"), keys.leader_sent("*")],
        ),
        grant(
            "standby-copies",
            &parties.leaders,
            &parties.leaders,
            &["query"],
            vec![keys.every_leader_copy("*")],
        ),
        grant(
            "follow",
            &parties.leaders,
            &parties.sensor,
            &["query"],
            vec![keys.sensor_follow("*"), keys.sensor_resend("*")],
        ),
        grant(
            "unfollow",
            &parties.leaders,
            &parties.sensor,
            &["put"],
            vec![keys.sensor_unfollow("*")],
        ),
        grant(
            "unfollow-subscriber",
            &parties.sensor,
            &parties.leaders,
            &["declare_subscriber"],
            vec![keys.sensor_unfollow("*")],
        ),
        grant(
            "durable",
            &parties.leaders,
            &[parties.sensor.clone(), parties.leaders.clone()].concat(),
            &["put"],
            vec![keys.every_leader_durable()],
        ),
        grant(
            "durable-subscribers",
            &[parties.sensor.clone(), parties.leaders.clone()].concat(),
            &parties.leaders,
            &["declare_subscriber"],
            vec![keys.every_leader_durable()],
        ),
        grant(
            "progress",
            &parties.leaders,
            &parties.sensor,
            &["put"],
            vec![keys.every_leader_progress()],
        ),
        grant(
            "progress-subscriber",
            &parties.sensor,
            &parties.leaders,
            &["declare_subscriber"],
            vec![keys.every_leader_progress()],
        ),
        // Leader processes watch one another's roles, to adopt the role of
        // one gone for good.
        grant(
            "membership",
            &parties.leaders,
            &parties.leaders,
            &["declare_liveliness_subscriber", "liveliness_query"],
            // `P/alive/home/*`: a process back for its role, which the
            // process that adopted it hands back.
            vec![keys.alive_role("leader"), keys.alive_role("home")],
        ),
    ]
}

/// What the coordinator asks the leaders and the sensors, and what the
/// leaders push to it.
fn coordinator_grants(keys: &Keys, parties: &Parties) -> Vec<Grant> {
    vec![
        grant(
            "pushed",
            &parties.leaders,
            &parties.coordinator,
            &["put"],
            vec![keys.every_leader_pushed()],
        ),
        grant(
            "pushed-subscriber",
            &parties.coordinator,
            &parties.leaders,
            &["declare_subscriber"],
            vec![keys.every_leader_pushed()],
        ),
        grant(
            "partials",
            &parties.coordinator,
            &parties.leaders,
            &["query"],
            vec![keys.every_leader_partial(), keys.every_leader_stats()],
        ),
        grant(
            "cuts",
            &parties.coordinator,
            &parties.sensor,
            &["query"],
            // Its counters and positions too (`query/stats` lists the sensor's).
            vec![
                keys.every_sensor_cut(),
                keys.every_sensor_stats(),
                keys.every_sensor_positions(),
            ],
        ),
    ]
}

/// What the voters send one another (raft's messages, each voter
/// subscribing to its own key), the proposals any process of the
/// deployment may put to them, and the coordinator's way to their map
/// (`query/roles`, which clients ask through it).
fn voter_grants(keys: &Keys, parties: &Parties) -> Vec<Grant> {
    if parties.voters.is_empty() {
        return Vec::new();
    }
    let raft = format!("{}/raft/*", keys.prefix());
    vec![
        grant(
            "raft",
            &parties.voters,
            &parties.voters,
            &["put", "declare_subscriber"],
            vec![raft],
        ),
        grant(
            "propose",
            &parties.members,
            &parties.voters,
            &["put"],
            vec![keys.raft_propose()],
        ),
        grant(
            "propose-subscriber",
            &parties.voters,
            &parties.members,
            &["declare_subscriber"],
            vec![keys.raft_propose()],
        ),
        // The coordinator, for its clients; every other process, to claim
        // and keep its role.
        grant(
            "roles",
            &parties.members,
            &parties.voters,
            &["query"],
            vec![keys.query_roles()],
        ),
    ]
}

/// What a sensor and its standby send each other: the journal's records
/// (from whichever holds the role to the other) and the watch on each
/// other's tokens.
fn standby_grants(keys: &Keys, parties: &Parties) -> Vec<Grant> {
    if parties.stands_by.is_empty() {
        return Vec::new();
    }
    vec![
        grant(
            "replicate",
            &parties.sensor,
            &parties.sensor,
            &["query"],
            vec![keys.sensor_replicate("*", "*")],
        ),
        grant(
            "standby-watch",
            &parties.sensor,
            &parties.sensor,
            &["declare_liveliness_subscriber", "liveliness_query"],
            vec![keys.alive_role("sensor"), keys.alive_role(STANDBY_ROLE)],
        ),
    ]
}

/// What clients and producers outside the deployment may ask and send,
/// and the answers they get.
fn outside_grants(keys: &Keys, parties: &Parties) -> Vec<Grant> {
    let p = keys.prefix();
    let mut grants = Vec::new();
    if !parties.clients.is_empty() {
        grants.push(grant(
            "ask",
            &parties.clients,
            &parties.coordinator,
            &["query"],
            vec![format!("{p}/query/**")],
        ));
        grants.push(grant(
            "answer",
            &parties.coordinator,
            &parties.clients,
            SERVE,
            vec![format!("{p}/query/**")],
        ));
    }
    if !parties.producers.is_empty() {
        let ingest: Vec<String> = parties
            .sensor_roles
            .iter()
            .map(|s| keys.sensor_ingest(s))
            .collect();
        grants.push(grant(
            "feed",
            &parties.producers,
            &parties.sensor,
            &["query"],
            ingest.clone(),
        ));
        grants.push(grant(
            "acknowledge",
            &parties.sensor,
            &parties.producers,
            SERVE,
            ingest,
        ));
    }
    grants
}

/// What process `m` serves under its own name, answers on the keys it is
/// asked on, and its liveliness tokens.
fn member_grants(keys: &Keys, parties: &Parties, m: &Member) -> Vec<Grant> {
    let p = keys.prefix();
    let mut grants = Vec::new();
    let me = vec![m.name.clone()];
    let mut served = vec![keys.ping(m.role, &m.name)];
    // Zenoh replies on the key the asker used, wildcards included (an
    // error reply always does): the coordinator asks every leader, and
    // every sensor, at once.
    let mut asked_as = Vec::new();
    // Who asks it on wildcard keys: the coordinator (the voters are asked
    // by every process).
    let mut askers = &parties.coordinator;
    match m.role {
        "sensor" | STANDBY_ROLE => {
            // A standby serves as its sensor once it takes the role over.
            served.push(format!("{p}/sensor/{}/**", parties.sensor_of(&m.name)));
            asked_as.extend([
                keys.every_sensor_cut(),
                keys.every_sensor_stats(),
                keys.every_sensor_positions(),
            ]);
        }
        "leader" => {
            // Any leader role: its own, or one it adopts.
            served.push(format!("{p}/leader/*/**"));
            asked_as.extend([keys.every_leader_partial(), keys.every_leader_stats()]);
            grants.push(grant(
                &format!("{}-subscribes", m.name),
                &me,
                &parties.members,
                &["declare_subscriber"],
                vec![keys.leader_events("*"), keys.leader_transfer("*")],
            ));
        }
        "voter" => {
            served.push(keys.query_roles());
            asked_as.push(keys.query_roles());
            askers = &parties.members;
        }
        _ => served.push(format!("{p}/query/**")),
    }
    grants.push(grant(
        &format!("{}-serves", m.name),
        &me,
        &parties.members,
        SERVE,
        served,
    ));
    if !asked_as.is_empty() {
        grants.push(grant(
            &format!("{}-answers", m.name),
            &me,
            askers,
            &["reply"],
            asked_as,
        ));
    }
    let tokens = match m.role {
        // Any leader role's, and its own home token (standing by
        // for its role).
        "leader" => vec![keys.alive_role("leader"), keys.alive("home", &m.name)],
        // Its own, and its sensor's once it holds that role.
        STANDBY_ROLE => vec![
            keys.alive(STANDBY_ROLE, &m.name),
            keys.alive("sensor", parties.sensor_of(&m.name)),
        ],
        // Its own, and with a standby its token standing by for it once
        // the standby holds the role.
        "sensor" if parties.has_standby(&m.name) => vec![
            keys.alive("sensor", &m.name),
            keys.alive(STANDBY_ROLE, &m.name),
        ],
        role => vec![keys.alive(role, &m.name)],
    };
    grants.push(grant(
        &format!("{}-alive", m.name),
        &me,
        &parties.members,
        &["liveliness_token"],
        tokens,
    ));
    grants
}

/// The `access_control` config of process `me`: default deny; the grants it
/// receives as ingress rules for their senders, the grants it sends as
/// egress rules for their receivers.
pub(crate) fn access_control(topology: &Topology, me: &str) -> Value {
    let mut rules = Vec::new();
    let mut policies = Vec::new();
    let mut subjects = BTreeSet::new();
    for (i, g) in grants(topology).iter().enumerate() {
        let me_owned = me.to_string();
        let sides = [
            ("ingress", g.to.contains(&me_owned).then_some(&g.from)),
            ("egress", g.from.contains(&me_owned).then_some(&g.to)),
        ];
        for (flow, peers) in sides {
            let Some(peers) = peers else { continue };
            let peers: Vec<&String> = peers.iter().filter(|p| **p != me).collect();
            if peers.is_empty() {
                continue;
            }
            let id = format!("{i}-{}-{flow}", g.what);
            rules.push(json!({
                "id": id,
                "messages": g.messages,
                "flows": [flow],
                "permission": "allow",
                "key_exprs": g.keys,
            }));
            policies.push(json!({ "rules": [id], "subjects": peers }));
            subjects.extend(peers.into_iter().cloned());
        }
    }
    let subjects: Vec<Value> = subjects
        .iter()
        .map(|s| json!({ "id": s, "cert_common_names": [s] }))
        .collect();
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use zenoh::key_expr::keyexpr;

    fn topology() -> Topology {
        // A folder per call, removed once the topology is read.
        let dir = tempfile::Builder::new()
            .prefix("idmesh-rules-")
            .tempdir()
            .unwrap();
        let path = dir.path().join("t.toml");
        std::fs::write(
            &path,
            r#"
prefix = "p"
[coordinator]
name = "c"
listen = "tcp/127.0.0.1:1"
[sensor]
name = "s"
listen = "tcp/127.0.0.1:2"
trace = "x.jsonl"
[[leader]]
name = "l0"
listen = "tcp/127.0.0.1:3"
[[leader]]
name = "l1"
listen = "tcp/127.0.0.1:4"
[security]
certs = "certs"
clients = ["operator"]
producers = ["camera"]
"#,
        )
        .unwrap();
        Topology::load(&path).unwrap()
    }

    /// What Zenoh decides at process `me` for `message` on `key` with
    /// `peer` at the other end of the link (default deny; any allow wins).
    fn allowed(acl: &Value, flow: &str, peer: &str, message: &str, key: &str) -> bool {
        let key = keyexpr::new(key).unwrap();
        acl["policies"].as_array().unwrap().iter().any(|policy| {
            policy["subjects"]
                .as_array()
                .unwrap()
                .iter()
                .any(|s| s == peer)
                && policy["rules"].as_array().unwrap().iter().any(|id| {
                    let rule = acl["rules"]
                        .as_array()
                        .unwrap()
                        .iter()
                        .find(|r| r["id"] == *id)
                        .unwrap();
                    rule["flows"][0] == flow
                        && rule["messages"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .any(|m| m == message)
                        && rule["key_exprs"]
                            .as_array()
                            .unwrap()
                            .iter()
                            .any(|k| keyexpr::new(k.as_str().unwrap()).unwrap().includes(key))
                })
        })
    }

    #[test]
    fn only_the_sensor_may_put_events_and_only_the_coordinator_may_ask_leaders() {
        let t = topology();
        let l0 = access_control(&t, "l0");
        assert!(allowed(&l0, "ingress", "s", "put", "p/leader/l0/events"));
        assert!(!allowed(&l0, "ingress", "c", "put", "p/leader/l0/events"));
        assert!(!allowed(&l0, "ingress", "l1", "put", "p/leader/l0/events"));
        assert!(!allowed(
            &l0,
            "ingress",
            "operator",
            "put",
            "p/leader/l0/events"
        ));
        assert!(!allowed(
            &l0,
            "ingress",
            "intruder",
            "put",
            "p/leader/l0/events"
        ));
        assert!(allowed(&l0, "ingress", "l1", "put", "p/leader/l0/transfer"));
        assert!(allowed(&l0, "ingress", "c", "query", "p/leader/*/partial"));
        assert!(!allowed(
            &l0,
            "ingress",
            "operator",
            "query",
            "p/leader/*/stats"
        ));
        assert!(allowed(&l0, "egress", "c", "reply", "p/leader/l0/partial"));
        // The coordinator asks every leader at once; the reply has its key.
        assert!(allowed(&l0, "egress", "c", "reply", "p/leader/*/partial"));
        // Answers pushed at a cut go to the coordinator, and only there.
        assert!(allowed(&l0, "egress", "c", "put", "p/leader/*/pushed/*"));
        assert!(!allowed(&l0, "egress", "l1", "put", "p/leader/*/pushed/*"));
        assert!(allowed(
            &access_control(&t, "c"),
            "ingress",
            "l0",
            "put",
            "p/leader/*/pushed/*"
        ));
        assert!(allowed(
            &access_control(&t, "c"),
            "ingress",
            "l0",
            "reply",
            "p/leader/*/stats"
        ));
        // A leader serves leader roles (its own, or one it adopts), and
        // nothing else.
        assert!(allowed(
            &l0,
            "egress",
            "c",
            "declare_queryable",
            "p/leader/l0/stats"
        ));
        assert!(allowed(
            &l0,
            "egress",
            "c",
            "declare_queryable",
            "p/leader/l1/stats"
        ));
        assert!(!allowed(
            &l0,
            "egress",
            "c",
            "declare_queryable",
            "p/sensor/s/cut"
        ));
        assert!(!allowed(
            &l0,
            "egress",
            "c",
            "declare_queryable",
            "p/query/marginals"
        ));
        assert!(!allowed(
            &access_control(&t, "s"),
            "ingress",
            "c",
            "declare_queryable",
            "p/leader/l0/stats"
        ));
        // Durable marks reach the sensor from leaders only.
        let s = access_control(&t, "s");
        assert!(allowed(&s, "ingress", "l1", "put", "p/leader/l1/durable"));
        assert!(!allowed(&s, "ingress", "c", "put", "p/leader/l1/durable"));
        let l1 = access_control(&t, "l1");
        assert!(allowed(&l1, "ingress", "l0", "reply", "p/leader/l0/sent"));
        // An adopter asks the other leader processes for their copies.
        assert!(allowed(&l1, "ingress", "l0", "query", "p/leader/l2/copy/*"));
        assert!(allowed(&l1, "egress", "l0", "reply", "p/leader/l2/copy/*"));
        assert!(!allowed(&l1, "ingress", "c", "query", "p/leader/l2/copy/*"));
        // The coordinator may ask the sensor for its counters (once,
        // `query/stats` had `"sensors": []` under `[security]`).
        let c = access_control(&t, "c");
        assert!(allowed(&c, "egress", "s", "query", "p/sensor/*/stats"));
        assert!(allowed(&s, "ingress", "c", "query", "p/sensor/*/stats"));
        assert!(allowed(&s, "egress", "c", "reply", "p/sensor/*/stats"));
        assert!(allowed(&c, "ingress", "s", "reply", "p/sensor/*/stats"));
        assert!(!allowed(&c, "ingress", "l0", "reply", "p/sensor/*/stats"));
        // A leader cannot answer in the sensor's name.
        assert!(!allowed(
            &access_control(&t, "c"),
            "ingress",
            "l0",
            "reply",
            "p/sensor/*/cut"
        ));
    }

    #[test]
    fn clients_may_only_query_the_coordinator_s_api() {
        let t = topology();
        let c = access_control(&t, "c");
        assert!(allowed(
            &c,
            "ingress",
            "operator",
            "query",
            "p/query/marginals"
        ));
        assert!(allowed(
            &c,
            "egress",
            "operator",
            "reply",
            "p/query/track/3"
        ));
        assert!(!allowed(
            &c,
            "ingress",
            "operator",
            "query",
            "p/leader/*/stats"
        ));
        assert!(!allowed(&c, "ingress", "operator", "query", "p/**"));
        assert!(!allowed(
            &c,
            "egress",
            "operator",
            "declare_queryable",
            "p/leader/l0/stats"
        ));
        let s = access_control(&t, "s");
        assert!(!allowed(
            &s,
            "ingress",
            "operator",
            "query",
            "p/sensor/s/cut"
        ));
        assert!(allowed(&s, "ingress", "c", "query", "p/sensor/*/cut"));
        assert!(allowed(&s, "egress", "l0", "put", "p/leader/l0/events"));
    }

    /// The test topology with three voters.
    fn with_voters() -> Topology {
        let mut t = topology();
        t.state_dir = Some("state".into());
        t.voters = (1..=3)
            .map(|i| {
                crate::runtime::topology::Process::new(
                    format!("v{i}"),
                    format!("tcp/127.0.0.1:{}", 10 + i),
                )
            })
            .collect();
        t
    }

    /// Voters hear raft only from voters, proposals from the deployment's
    /// processes, and the roles question from them too (each claims its
    /// role through it; a client asks it through the coordinator, never a
    /// voter directly).
    #[test]
    fn voters_hear_raft_from_voters_and_the_roles_question_from_the_processes() {
        let t = with_voters();
        assert!(allowed(
            &access_control(&t, "v2"),
            "ingress",
            "l0",
            "query",
            "p/query/roles"
        ));
        assert!(allowed(
            &access_control(&t, "l0"),
            "ingress",
            "v2",
            "reply",
            "p/query/roles"
        ));
        let v1 = access_control(&t, "v1");
        assert!(allowed(&v1, "ingress", "v2", "put", "p/raft/1"));
        assert!(allowed(&v1, "egress", "v3", "put", "p/raft/3"));
        assert!(allowed(
            &v1,
            "egress",
            "v2",
            "declare_subscriber",
            "p/raft/1"
        ));
        assert!(!allowed(&v1, "ingress", "l0", "put", "p/raft/1"));
        assert!(!allowed(&v1, "ingress", "operator", "put", "p/raft/1"));
        assert!(allowed(&v1, "ingress", "l0", "put", "p/raft/propose"));
        assert!(!allowed(
            &v1,
            "ingress",
            "operator",
            "put",
            "p/raft/propose"
        ));
        assert!(allowed(&v1, "ingress", "c", "query", "p/query/roles"));
        assert!(allowed(&v1, "egress", "c", "reply", "p/query/roles"));
        assert!(!allowed(
            &v1,
            "ingress",
            "operator",
            "query",
            "p/query/roles"
        ));
        assert!(!allowed(
            &v1,
            "egress",
            "c",
            "declare_queryable",
            "p/query/marginals"
        ));
        let c = access_control(&t, "c");
        assert!(allowed(&c, "ingress", "operator", "query", "p/query/roles"));
        assert!(allowed(&c, "egress", "v1", "query", "p/query/roles"));
        assert!(allowed(&c, "ingress", "v1", "reply", "p/query/roles"));
        assert!(allowed(&c, "egress", "operator", "reply", "p/query/roles"));
    }

    /// A sensor's standby acts as its sensor, on that sensor's keys only,
    /// and the two replicate to and watch each other.
    #[test]
    fn a_sensor_standby_serves_its_sensor_s_keys_and_no_other_s() {
        let mut t = with_voters();
        t.sensor_standbys = vec![crate::runtime::topology::SensorStandbyProcess {
            name: "sb".into(),
            sensor: "s".into(),
            host: "local".into(),
            listen: "tcp/127.0.0.1:20".into(),
        }];
        let sb = access_control(&t, "sb");
        for (peer, message, key) in [
            ("l0", "put", "p/leader/l0/events"),
            ("l0", "liveliness_query", "p/alive/leader/l0"),
            ("c", "reply", "p/sensor/s/cut"),
            ("c", "declare_queryable", "p/sensor/s/cut"),
            ("l0", "liveliness_token", "p/alive/sensor/s"),
            ("s", "liveliness_token", "p/alive/sensor-standby/sb"),
            ("s", "query", "p/sensor/s/replicate/sb"),
            ("s", "declare_liveliness_subscriber", "p/alive/sensor/s"),
            ("v1", "query", "p/query/roles"),
            ("v1", "put", "p/raft/propose"),
        ] {
            assert!(
                allowed(&sb, "egress", peer, message, key),
                "{message} {key}"
            );
        }
        assert!(!allowed(
            &sb,
            "egress",
            "c",
            "declare_queryable",
            "p/sensor/other/cut"
        ));
        assert!(!allowed(
            &sb,
            "egress",
            "l0",
            "liveliness_token",
            "p/alive/sensor/other"
        ));
        assert!(allowed(
            &sb,
            "ingress",
            "s",
            "query",
            "p/sensor/s/replicate/sb"
        ));
        assert!(allowed(&sb, "ingress", "l0", "query", "p/sensor/s/follow"));
        assert!(!allowed(
            &sb,
            "ingress",
            "operator",
            "query",
            "p/sensor/s/replicate/sb"
        ));
        let s = access_control(&t, "s");
        assert!(allowed(
            &s,
            "egress",
            "sb",
            "query",
            "p/sensor/s/replicate/sb"
        ));
        assert!(allowed(
            &s,
            "egress",
            "sb",
            "reply",
            "p/sensor/s/replicate/sb"
        ));
        assert!(allowed(
            &s,
            "egress",
            "l0",
            "liveliness_token",
            "p/alive/sensor-standby/s"
        ));
        let l0 = access_control(&t, "l0");
        assert!(allowed(&l0, "ingress", "sb", "put", "p/leader/l0/events"));
        assert!(!allowed(
            &l0,
            "ingress",
            "sb",
            "put",
            "p/leader/l0/transfer"
        ));
    }

    /// A sensor's second standby acts as its sensor too, and whichever of
    /// the three holds the role replicates to the others.
    #[test]
    fn a_second_sensor_standby_serves_the_same_keys_and_replicates_to_the_first() {
        let mut t = with_voters();
        let standby = |name: &str, port: u16| crate::runtime::topology::SensorStandbyProcess {
            name: name.into(),
            sensor: "s".into(),
            host: "local".into(),
            listen: format!("tcp/127.0.0.1:{port}"),
        };
        t.sensor_standbys = vec![standby("sb", 20), standby("sb2", 21)];
        let sb2 = access_control(&t, "sb2");
        for (peer, message, key) in [
            ("l0", "put", "p/leader/l0/events"),
            ("c", "declare_queryable", "p/sensor/s/cut"),
            ("sb", "query", "p/sensor/s/replicate/sb"),
            ("s", "query", "p/sensor/s/replicate/s"),
            ("sb", "liveliness_token", "p/alive/sensor-standby/sb2"),
        ] {
            assert!(
                allowed(&sb2, "egress", peer, message, key),
                "{message} {key}"
            );
        }
        assert!(allowed(
            &sb2,
            "ingress",
            "sb",
            "query",
            "p/sensor/s/replicate/sb2"
        ));
        let sb = access_control(&t, "sb");
        assert!(allowed(
            &sb,
            "ingress",
            "sb2",
            "query",
            "p/sensor/s/replicate/sb"
        ));
        assert!(!allowed(
            &sb2,
            "egress",
            "c",
            "declare_queryable",
            "p/sensor/other/cut"
        ));
    }

    #[test]
    fn producers_may_only_feed_the_sensor() {
        let t = topology();
        let s = access_control(&t, "s");
        assert!(allowed(
            &s,
            "ingress",
            "camera",
            "query",
            "p/sensor/s/ingest"
        ));
        assert!(allowed(
            &s,
            "egress",
            "camera",
            "reply",
            "p/sensor/s/ingest"
        ));
        assert!(!allowed(&s, "ingress", "camera", "query", "p/sensor/s/cut"));
        assert!(!allowed(
            &s,
            "ingress",
            "camera",
            "query",
            "p/sensor/*/follow"
        ));
        assert!(!allowed(
            &s,
            "ingress",
            "operator",
            "query",
            "p/sensor/s/ingest"
        ));
        let c = access_control(&t, "c");
        assert!(!allowed(
            &c,
            "ingress",
            "camera",
            "query",
            "p/query/marginals"
        ));
        let l0 = access_control(&t, "l0");
        assert!(!allowed(
            &l0,
            "ingress",
            "camera",
            "put",
            "p/leader/l0/events"
        ));
        assert!(!allowed(
            &l0,
            "ingress",
            "camera",
            "query",
            "p/leader/l0/partial"
        ));
    }

    #[test]
    fn the_generated_rules_are_a_valid_zenoh_config() {
        let t = topology();
        for m in t.members() {
            let acl = access_control(&t, &m.name);
            let mut config = zenoh::Config::default();
            config
                .insert_json5("access_control", &acl.to_string())
                .unwrap_or_else(|e| panic!("{}: {e}\n{acl:#}", m.name));
        }
    }
}
