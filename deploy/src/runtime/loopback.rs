//! A whole deployment on this machine's loopback, written as a topology
//! file: the demo's and the bench's. Leaders start at the centres of a grid
//! of cells over the trace's field and move to where the crowd is (k-means
//! over its positions, `launch::leader_places`), and then on until each is
//! sent about as many items (`idmesh_placement::balanced`); tracks cross
//! between the regions and mix across them, as in the paper's sensor grid.

use super::launch::leader_places;
use super::topology::{BeliefKind, Sparsification};
use anyhow::Result;
use std::path::Path;

#[derive(Debug, Clone)]
pub struct Loopback {
    pub prefix: String,
    pub leaders: usize,
    /// The leaders' belief on a property stream; the Radon settings below
    /// serve it under "radon", and identity streams under either.
    pub belief: BeliefKind,
    /// Factored: leaders' interests shrink (`shrink_interest`).
    pub shrink_interest: bool,
    /// Factored: the regional rule (`regional`).
    pub regional: bool,
    /// The sensor's flow control (`window`); None: no window.
    pub window: Option<u64>,
    pub distributed_rule: bool,
    /// Sets per leader; 0 = no pruning.
    pub budget: u32,
    pub sparsify: Sparsification,
    /// Events per second; None = as fast as the mesh takes them.
    pub rate: Option<f64>,
    /// Stop the stream after this many events.
    pub events: Option<u64>,
    /// How long the coordinator waits for the leaders.
    pub query_timeout_ms: u64,
    pub ports: Ports,
    /// The sensor stays open for producers after its trace (`live`).
    pub live: bool,
    /// Where the leaders and the sensor journal (`state_dir`); None: no
    /// journal.
    pub state_dir: Option<std::path::PathBuf>,
    /// How many sensors (`[[sensor]]`, `sensor-0`, `sensor-1`, …; their
    /// settings alike); 0 or 1: one `[sensor]`.
    pub sensors: usize,
}

#[derive(Debug, Clone, Copy)]
pub enum Ports {
    /// The coordinator on this port, leaders and the sensor on the ones after
    /// it (the demo's well-known endpoint).
    From(u16),
    /// Whatever the kernel has free (the bench, side by side with others).
    Free,
}

impl Ports {
    /// The port of process `index`. A free port stays bound in `held`
    /// until the whole topology is written: released at once, the kernel
    /// may hand the same port out again to the next process.
    fn take(self, index: u16, held: &mut Vec<std::net::TcpListener>) -> Result<u16> {
        match self {
            Ports::From(first) => Ok(first + index),
            Ports::Free => {
                let listener = std::net::TcpListener::bind("127.0.0.1:0")?;
                let port = listener.local_addr()?.port();
                held.push(listener);
                Ok(port)
            }
        }
    }
}

impl Loopback {
    /// The topology streaming `trace`, with its coordinator's endpoint. The
    /// trace is named by its absolute path: a topology resolves relative
    /// paths against its own folder, not against where we were started.
    pub fn topology(&self, trace: &Path) -> Result<(String, String)> {
        self.topology_placed(trace, trace)
    }

    /// [`Loopback::topology`] with the leaders placed over the field of
    /// `placed_by`'s moves: a live sensor's trace is its header alone, and
    /// its events come from a producer later.
    pub fn topology_placed(&self, trace: &Path, placed_by: &Path) -> Result<(String, String)> {
        let places = leader_places(placed_by, self.leaders)?;
        let trace = std::path::absolute(trace)?;
        let mut held = Vec::new();
        let coordinator = format!("tcp/127.0.0.1:{}", self.ports.take(0, &mut held)?);
        let mut toml = format!(
            "prefix = {:?}\nbelief = \"{}\"\nshrink_interest = {}\nregional = {}\ndistributed_rule = {}\nbudget = {}\nsparsify = \"{}\"\nquery_timeout_ms = {}\n\n[coordinator]\nname = \"coordinator\"\nlisten = \"{coordinator}\"\n",
            self.prefix,
            self.belief.name(),
            self.shrink_interest,
            self.regional,
            self.distributed_rule,
            self.budget,
            match self.sparsify {
                Sparsification::Threshold => "threshold",
                Sparsification::Overcomplete => "overcomplete",
            },
            self.query_timeout_ms,
        );
        let sensors = self.sensors.max(1);
        for s in 0..sensors {
            let table = if sensors > 1 {
                "[[sensor]]"
            } else {
                "[sensor]"
            };
            let port = self
                .ports
                .take(self.leaders as u16 + 1 + s as u16, &mut held)?;
            toml.push_str(&format!(
                "\n{table}\nname = \"sensor-{s}\"\nlisten = \"tcp/127.0.0.1:{port}\"\ntrace = {:?}\n",
                trace.display().to_string(),
            ));
            if let Some(rate) = self.rate {
                toml.push_str(&format!("rate = {rate}\n"));
            }
            if let Some(events) = self.events {
                toml.push_str(&format!("events = {events}\n"));
            }
            if self.live {
                toml.push_str("live = true\n");
            }
            if let Some(window) = self.window {
                toml.push_str(&format!("window = {window}\n"));
            }
        }
        if let Some(dir) = &self.state_dir {
            toml.insert_str(0, &format!("state_dir = {:?}\n", dir.display().to_string()));
        }
        for (i, (x, y)) in places.into_iter().enumerate() {
            toml.push_str(&format!(
                "\n[[leader]]\nname = \"leader-{i}\"\nlisten = \"tcp/127.0.0.1:{}\"\nat = [{x:.3}, {y:.3}]\n",
                self.ports.take(i as u16 + 1, &mut held)?
            ));
        }
        Ok((toml, coordinator))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::topology::Topology;
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
        let plan = Loopback {
            prefix: "idmesh/t".into(),
            leaders: 1,
            belief: BeliefKind::Factored,
            shrink_interest: false,
            regional: false,
            window: None,
            distributed_rule: false,
            budget: 0,
            sparsify: Sparsification::Threshold,
            rate: None,
            events: None,
            query_timeout_ms: 1000,
            ports: Ports::From(9100),
            live: false,
            state_dir: None,
            sensors: 1,
        };
        let (toml, _) = plan.topology(&trace).unwrap();
        let config = dir.join("topology.toml");
        std::fs::write(&config, toml).unwrap();
        let found = Topology::load(&config).unwrap().trace_path();
        let exists = found.exists();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(exists, "the topology names {}", found.display());
    }

    #[test]
    fn a_loopback_topology_loads_with_every_leader_placed_inside_the_field() {
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
        let plan = Loopback {
            prefix: "idmesh/t".into(),
            leaders: 5,
            belief: BeliefKind::Radon,
            shrink_interest: false,
            regional: false,
            window: None,
            distributed_rule: true,
            budget: 100,
            sparsify: Sparsification::Overcomplete,
            rate: Some(50.0),
            events: None,
            query_timeout_ms: 1500,
            ports: Ports::From(9000),
            live: true,
            state_dir: None,
            sensors: 1,
        };
        let (toml, coordinator) = plan.topology(&trace).unwrap();
        assert_eq!(coordinator, "tcp/127.0.0.1:9000");
        let config = dir.join("topology.toml");
        std::fs::write(&config, toml).unwrap();
        let topology = Topology::load(&config).unwrap();
        assert_eq!(topology.leader.len(), 5);
        assert_eq!(topology.sensor().listen, "tcp/127.0.0.1:9006");
        for l in &topology.leader {
            let [x, y] = l.at.unwrap();
            assert!((0.0..=30.0).contains(&x) && (0.0..=20.0).contains(&y));
        }
        assert_eq!(topology.belief, BeliefKind::Radon);
        assert!(topology.distributed_rule && topology.budget == 100);
        assert_eq!(topology.sparsify, Sparsification::Overcomplete);
        assert_eq!(topology.query_timeout_ms, 1500);
        assert!(topology.sensor().live);
    }
}
