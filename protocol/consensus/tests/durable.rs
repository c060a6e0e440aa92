//! Voters whose logs are on disk ([`DurableLog`]): a group of three
//! decides claims, every voter's process dies at once, and the group
//! reopened from its files has the map it had, keeps its votes and terms,
//! and goes on deciding. A log torn by the crash is cut and read; one
//! damaged under whole records is refused naming the file and the byte.

use idmesh_consensus::{Command, DurableLog, Envelope, Voter, VoterConfig};
use std::path::{Path, PathBuf};

const IDS: [u64; 3] = [1, 2, 3];

fn config(id: u64) -> VoterConfig {
    VoterConfig {
        id,
        voters: IDS.to_vec(),
        election_ticks: 10,
        heartbeat_ticks: 3,
        // Drawn timeouts: voters ticking in step would split every vote.
        fixed_timeouts: false,
    }
}

fn log_path(dir: &Path, id: u64) -> PathBuf {
    dir.join(format!("voter-{id}.raft"))
}

/// Three voters, each with its log open, as three processes would be.
struct Group {
    voters: Vec<(Voter, DurableLog)>,
    wire: Vec<Envelope>,
}

impl Group {
    fn open(dir: &Path) -> Group {
        let voters = IDS
            .iter()
            .map(|&id| {
                let (log, storage) = DurableLog::open(&log_path(dir, id), &IDS).unwrap();
                (Voter::new(&config(id), storage).unwrap(), log)
            })
            .collect();
        Group {
            voters,
            wire: Vec::new(),
        }
    }

    /// One period: every voter ticks, takes what came for it, persists
    /// what its step asks and only then sends.
    fn step(&mut self) {
        let wire = std::mem::take(&mut self.wire);
        for (voter, log) in &mut self.voters {
            voter.tick();
            let id = voter.id();
            for envelope in wire.iter().filter(|e| e.to == id) {
                voter.step(envelope.message.clone()).unwrap();
            }
            let ready = voter.ready();
            log.write(&ready.persist).unwrap();
            self.wire.extend(ready.send);
        }
    }

    fn run_until(&mut self, what: &str, done: impl Fn(&Group) -> bool) {
        for _ in 0..500 {
            if done(self) {
                return;
            }
            self.step();
        }
        panic!("{what}: not within 500 periods");
    }

    fn leader(&self) -> Option<usize> {
        self.voters.iter().position(|(v, _)| v.is_leader())
    }

    /// Proposes a claim at the leader and runs until every voter applied it.
    fn claim(&mut self, role: &str, holder: &str) {
        self.run_until("a leader", |g| g.leader().is_some());
        let leader = self.leader().unwrap();
        let fencing = self.voters[leader].0.map().get(role).map(|h| h.epoch);
        let command = Command::Claim {
            role: role.into(),
            holder: holder.into(),
            fencing,
        };
        self.voters[leader].0.propose(&command).unwrap();
        self.run_until("the claim applied everywhere", |g| {
            g.voters.iter().all(|(v, _)| {
                v.map()
                    .get(role)
                    .is_some_and(|h| h.holder.as_deref() == Some(holder))
            })
        });
    }

    fn maps(&self) -> Vec<String> {
        self.voters
            .iter()
            .map(|(v, _)| format!("{:?}", v.map().roles().collect::<Vec<_>>()))
            .collect()
    }
}

#[test]
fn a_group_killed_at_once_comes_back_from_its_logs_and_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let mut group = Group::open(dir.path());
    group.claim("leader-0", "east");
    group.claim("sensor-0", "gateway");
    group.claim("leader-0", "west");
    let maps = group.maps();
    let terms: Vec<u64> = group.voters.iter().map(|(v, _)| v.term()).collect();
    drop(group); // every process dies; only the files are left

    let mut group = Group::open(dir.path());
    for ((voter, _), term) in group.voters.iter().zip(&terms) {
        // The term (and the vote in it) is what was stored.
        assert_eq!(voter.term(), *term);
    }
    // The committed log rebuilds each map as it is applied again.
    group.run_until("the maps rebuilt", |g| g.maps() == maps);
    group.claim("leader-0", "north");
    let holding = group.voters[0].0.map().get("leader-0").unwrap().clone();
    assert_eq!(holding.holder.as_deref(), Some("north"));
    // Three changes of holder: each raised the epoch.
    assert_eq!(holding.epoch, 3);
}

#[test]
fn a_torn_tail_is_cut_and_damage_is_refused_naming_file_and_byte() {
    let dir = tempfile::tempdir().unwrap();
    let mut group = Group::open(dir.path());
    group.claim("leader-0", "east");
    let maps = group.maps();
    drop(group);

    // A crash in the middle of a write: half a record at the end.
    let path = log_path(dir.path(), 1);
    let whole = std::fs::read(&path).unwrap();
    let mut torn = whole.clone();
    torn.extend_from_slice(&[7, 0, 0, 0, 1, 2]);
    std::fs::write(&path, &torn).unwrap();
    let mut group = Group::open(dir.path());
    group.run_until("the maps rebuilt", |g| g.maps() == maps);
    drop(group);
    assert!(std::fs::read(&path).unwrap().len() >= whole.len());

    // A flipped byte inside an early record, whole records after it.
    let mut damaged = std::fs::read(&path).unwrap();
    let at = idmesh_journal::HEADER_LEN + idmesh_journal::RECORD_HEAD + 1;
    damaged[at] ^= 0x40;
    std::fs::write(&path, &damaged).unwrap();
    let error = match DurableLog::open(&path, &IDS) {
        Ok(_) => panic!("a damaged log was opened"),
        Err(e) => e.to_string(),
    };
    assert!(
        error.contains(&path.display().to_string()) && error.contains("byte"),
        "{error}"
    );
}
