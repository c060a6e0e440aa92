//! `idmesh web` beside a test [`Deployment`]: the gateway as its own
//! process, a Zenoh client of the deployment's coordinator (with the
//! deployment's client certificate when it is secured), on a free port.

use crate::deployment::Deployment;
use crate::idmesh;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};

pub struct Gateway {
    /// `http://127.0.0.1:PORT` (no trailing slash).
    pub url: String,
    child: Child,
}

impl Gateway {
    /// Starts the gateway and waits for the address it prints.
    pub fn start(deployment: &Deployment) -> Gateway {
        Self::start_with(deployment, &[])
    }

    /// [`Gateway::start`] with `extra` arguments (`--ros2-markers …`).
    pub fn start_with(deployment: &Deployment, extra: &[&str]) -> Gateway {
        let log = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(deployment.dir.join("web.log"))
            .expect("web.log");
        let mut child = Command::new(idmesh())
            .args(["web", "--listen", "127.0.0.1:0", "--connect"])
            .arg(&deployment.coordinator)
            .args(["--prefix", &deployment.prefix])
            .args(deployment.client_tls_args())
            .args(extra)
            .env("RUST_LOG", "warn")
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .expect("idmesh web starts");
        let mut line = String::new();
        let stdout = child.stdout.take().expect("piped stdout");
        BufReader::new(stdout)
            .read_line(&mut line)
            .expect("idmesh web prints its address");
        let url = line
            .trim()
            .strip_prefix("idmesh web: ")
            .unwrap_or_else(|| panic!("idmesh web printed {line:?}, not its address"))
            .trim_end_matches('/')
            .to_string();
        Gateway { url, child }
    }

    /// The URL of a key expression (`prefix/query/marginals`) and query.
    pub fn at(&self, path: &str) -> String {
        format!("{}/{}", self.url, path.trim_start_matches('/'))
    }
}

impl Drop for Gateway {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
