//! A whole deployment on this machine's loopback, as a typed topology:
//! [`Topology::loopback`] lays out its processes (the demo's, the bench's
//! and the process tests' topologies are all made by it), and
//! [`topology`] places the demo's and the bench's leaders. They start at
//! the centres of a grid of cells over the trace's field and move to where
//! the crowd is (k-means over its positions, `launch::leader_places`), and
//! then on until each is sent about as many items
//! (`idmesh_placement::balanced`); tracks cross between the regions and
//! mix across them, as in the paper's sensor grid.

use super::launch::leader_places;
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
    /// (`coordinator`), a leader at each of `places` (`leader-0`, …) and
    /// `sensors` sensors (`sensor-0`, …; at least one), each streaming
    /// `trace`; each process on `127.0.0.1` at one of `ports`, in that
    /// order (the coordinator's, the leaders', the sensors'). Every other
    /// setting at its default: the caller sets what it needs.
    ///
    /// # Panics
    ///
    /// If `ports` is not one port per process.
    pub fn loopback(trace: &Path, places: &[(f64, f64)], sensors: usize, ports: &[u16]) -> Self {
        let sensors = sensors.max(1);
        assert_eq!(
            ports.len(),
            1 + places.len() + sensors,
            "one port per process of the loopback topology"
        );
        let listen = |i: usize| format!("tcp/127.0.0.1:{}", ports[i]);
        let leaders = places
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| LeaderProcess {
                at: Some([x, y]),
                ..LeaderProcess::new(format!("leader-{i}"), listen(1 + i))
            })
            .collect();
        let sensors = (0..sensors)
            .map(|s| SensorProcess::new(format!("sensor-{s}"), listen(1 + places.len() + s), trace))
            .collect();
        Topology::new(Process::new("coordinator", listen(0)), sensors, leaders)
    }
}

/// The loopback topology of the demo and the bench: `leaders` leaders
/// placed over the crowd of `placed_by` (k-means, then balanced:
/// [`leader_places`]; to the millimetre, which reads better in the file)
/// and `sensors` sensors streaming `trace` — not `placed_by` when a live
/// sensor's trace is its header alone and its events come from a producer
/// later. The trace is named by its absolute path: a topology resolves
/// relative paths against its own folder, not against where we were
/// started. Every other setting is at its default.
pub fn topology(
    trace: &Path,
    placed_by: &Path,
    leaders: usize,
    sensors: usize,
    ports: Ports,
) -> Result<Topology> {
    let millimetre = |v: f64| (v * 1000.0).round() / 1000.0;
    let places: Vec<(f64, f64)> = leader_places(placed_by, leaders)?
        .into_iter()
        .map(|(x, y)| (millimetre(x), millimetre(y)))
        .collect();
    let ports = ports.take(1 + leaders + sensors.max(1))?;
    Ok(Topology::loopback(
        &std::path::absolute(trace)?,
        &places,
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
        let plan = topology(&trace, &trace, 1, 1, Ports::From(9100)).unwrap();
        let config = dir.join("topology.toml");
        plan.save(&config).unwrap();
        let found = Topology::load(&config).unwrap().trace_path();
        let exists = found.exists();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(exists, "the topology names {}", found.display());
    }

    /// What the launcher writes is what it then reads: the placed leaders,
    /// the ports, every setting it changed.
    #[test]
    fn a_loopback_topology_reads_back_as_written_with_every_leader_inside_the_field() {
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
        let mut plan = topology(&trace, &trace, 5, 1, Ports::From(9000)).unwrap();
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
        for l in &topology.leader {
            let [x, y] = l.at.unwrap();
            assert!((0.0..=30.0).contains(&x) && (0.0..=20.0).contains(&y));
            assert_eq!((x * 1000.0).round() / 1000.0, x, "to the millimetre");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn free_ports_give_every_process_its_own() {
        let trace = Path::new("/nowhere/t.jsonl");
        let places = [(1.0, 1.0), (2.0, 2.0), (3.0, 3.0)];
        let ports = Ports::Free.take(1 + places.len() + 2).unwrap();
        let topology = Topology::loopback(trace, &places, 2, &ports);
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
        assert_eq!(topology.leader[2].at, Some([3.0, 3.0]));
        assert!(topology.sensors.iter().all(|s| s.trace == trace));
    }
}
