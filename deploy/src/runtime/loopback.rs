//! A whole deployment on this machine's loopback, as a typed topology:
//! [`Topology::loopback`] lays out its processes (the demo's, the bench's
//! and the process tests' topologies are all made by it), and [`topology`]
//! is the demo's and the bench's. Their leaders sit nowhere: the sensor
//! fits their regions to the crowd and redraws them as it moves
//! (`idmesh_placement::Fitted`), the default of every deployment.

use super::ports::pick_free_ports;
use super::topology::{LeaderProcess, Process, SensorProcess, Topology};
use anyhow::Result;
use std::path::Path;

/// Where the processes of a loopback topology listen.
#[derive(Debug, Clone, Copy)]
pub enum Ports {
    /// The coordinator on this port, the leaders and then the sensors on
    /// the ones after it (the demo's well-known endpoint).
    From(u16),
    /// Free ports ([`pick_free_ports`]): the bench, side by side with
    /// others.
    Free,
}

impl Ports {
    /// `n` ports, in the order [`Topology::loopback`] takes them.
    pub fn take(self, n: usize) -> Result<Vec<u16>> {
        match self {
            Ports::From(first) => Ok((0..n as u16).map(|i| first + i).collect()),
            Ports::Free => pick_free_ports(n),
        }
    }
}

impl Topology {
    /// A deployment on this machine's loopback: the coordinator
    /// (`coordinator`), `leaders` leaders (`leader-0`, …) and `sensors`
    /// sensors (`sensor-0`, …; at least one), each streaming
    /// `trace`; each process on `127.0.0.1` at one of `ports`, in that
    /// order (the coordinator's, the leaders', the sensors'). Every other
    /// setting at its default: the caller sets what it needs.
    ///
    /// # Panics
    ///
    /// If `ports` is not one port per process.
    pub fn loopback(trace: &Path, leaders: usize, sensors: usize, ports: &[u16]) -> Self {
        let sensors = sensors.max(1);
        assert_eq!(
            ports.len(),
            1 + leaders + sensors,
            "one port per process of the loopback topology"
        );
        let listen = |i: usize| format!("tcp/127.0.0.1:{}", ports[i]);
        let leader_count = leaders;
        let leaders = (0..leaders)
            .map(|i| LeaderProcess::new(format!("leader-{i}"), listen(1 + i)))
            .collect();
        let sensors = (0..sensors)
            .map(|s| SensorProcess::new(format!("sensor-{s}"), listen(1 + leader_count + s), trace))
            .collect();
        Topology::new(Process::new("coordinator", listen(0)), sensors, leaders)
    }
}

/// The loopback topology of the demo and the bench: `leaders` leaders and
/// `sensors` sensors streaming `trace`. The trace is named by its absolute
/// path: a topology resolves relative paths against its own folder, not
/// against where we were started. Every other setting is at its default.
pub fn topology(trace: &Path, leaders: usize, sensors: usize, ports: Ports) -> Result<Topology> {
    let ports = ports.take(1 + leaders + sensors.max(1))?;
    Ok(Topology::loopback(
        &std::path::absolute(trace)?,
        leaders,
        sensors,
        &ports,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::topology::{BeliefKind, Sparsification};
    use std::path::PathBuf;

    #[test]
    fn a_trace_given_relative_to_the_working_directory_is_found_from_the_topology() {
        // The demo's default `--dir` is relative: the topology written into
        // it must still name the trace beside it.
        let dir = PathBuf::from(format!("loopback-relative-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let trace = dir.join("t.jsonl");
        std::fs::write(
            &trace,
            "{\"kind\":\"header\",\"format\":\"idmesh-trace\",\"version\":1,\"tracks\":2,\"red\":1}\n",
        )
        .unwrap();
        let plan = topology(&trace, 1, 1, Ports::From(9100)).unwrap();
        let config = dir.join("topology.toml");
        plan.save(&config).unwrap();
        let found = Topology::load(&config).unwrap().trace_path();
        let exists = found.exists();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(exists, "the topology names {}", found.display());
    }

    /// What the launcher writes is what it then reads: the leaders, the
    /// ports, every setting it changed.
    #[test]
    fn a_loopback_topology_reads_back_as_written() {
        let dir = std::env::temp_dir().join(format!("idmesh-loopback-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let trace = dir.join("t.jsonl");
        std::fs::write(
            &trace,
            "{\"kind\":\"header\",\"format\":\"idmesh-trace\",\"version\":1,\"tracks\":2,\"red\":1}\n\
             {\"kind\":\"move\",\"time\":0.0,\"track\":0,\"x\":0.0,\"y\":0.0}\n\
             {\"kind\":\"move\",\"time\":1.0,\"track\":1,\"x\":30.0,\"y\":20.0}\n",
        )
        .unwrap();
        let mut plan = topology(&trace, 5, 1, Ports::From(9000)).unwrap();
        plan.prefix = "idmesh/t".into();
        plan.belief = BeliefKind::Radon;
        plan.distributed_rule = true;
        plan.budget = 100;
        plan.sparsify = Sparsification::Overcomplete;
        plan.query_timeout_ms = 1500;
        plan.sensors[0].rate = Some(50.0);
        plan.sensors[0].live = true;
        assert_eq!(plan.coordinator.listen, "tcp/127.0.0.1:9000");
        let config = dir.join("topology.toml");
        plan.save(&config).unwrap();
        let mut topology = Topology::load(&config).unwrap();
        assert_eq!(topology.dir, dir);
        topology.dir = PathBuf::new();
        assert_eq!(topology, plan);
        assert_eq!(topology.leader.len(), 5);
        assert_eq!(topology.leader[4].listen, "tcp/127.0.0.1:9005");
        assert_eq!(topology.sensor().listen, "tcp/127.0.0.1:9006");
        assert!(topology.leader.iter().all(|l| l.at.is_none()));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn free_ports_give_every_process_its_own() {
        let trace = Path::new("/nowhere/t.jsonl");
        let ports = Ports::Free.take(1 + 3 + 2).unwrap();
        let topology = Topology::loopback(trace, 3, 2, &ports);
        let names: Vec<String> = topology.members().into_iter().map(|m| m.name).collect();
        assert_eq!(
            names,
            [
                "coordinator",
                "sensor-0",
                "sensor-1",
                "leader-0",
                "leader-1",
                "leader-2"
            ]
        );
        let mut listens: Vec<String> = topology.members().into_iter().map(|m| m.listen).collect();
        listens.sort();
        listens.dedup();
        assert_eq!(listens.len(), 6, "{listens:?}");
        assert!(topology.sensors.iter().all(|s| s.trace == trace));
    }
}
