//! The topology's `[security]` section.
//!
//! ```toml
//! [security]
//! certs = "certs"          # relative to the topology file: ca.pem, and
//!                          # <name>.pem + <name>.key for every process
//! access_control = true    # generated Zenoh access rules (default true)
//! clients = ["operator"]   # certificate common names that may query
//! producers = ["camera-7"] # … that may feed the sensor (its ingest key)
//! verify_names = true      # a listener's certificate must name its host
//! ```
//!
//! A process's certificate has its topology name as common name: that name
//! is what the access rules let do what.

use super::error::SecurityError;
use super::tls::Tls;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

#[derive(Debug, Clone, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SecuritySection {
    /// The folder with `ca.pem` and every process's `<name>.pem` and
    /// `<name>.key` (relative to the topology file). A host needs only the
    /// CA and the files of the processes it runs.
    pub certs: PathBuf,
    /// Zenoh access control from the topology; without it TLS still keeps
    /// out whoever has no certificate from the CA.
    #[serde(default = "yes", skip_serializing_if = "is_yes")]
    pub access_control: bool,
    /// Common names of the client certificates that may ask `P/query/**`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub clients: Vec<String>,
    /// Common names of the producers' certificates: they may send trace
    /// lines to the sensor (`P/sensor/<name>/ingest`), and nothing else.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub producers: Vec<String>,
    /// Check the host names in a listener's certificate when connecting.
    #[serde(default = "yes", skip_serializing_if = "is_yes")]
    pub verify_names: bool,
}

fn yes() -> bool {
    true
}

fn is_yes(value: &bool) -> bool {
    *value
}

impl SecuritySection {
    /// Certificates in `certs`, every setting at its default: access
    /// control on, names verified, no clients, no producers.
    pub fn new(certs: impl Into<PathBuf>) -> Self {
        SecuritySection {
            certs: certs.into(),
            access_control: true,
            clients: Vec::new(),
            producers: Vec::new(),
            verify_names: true,
        }
    }
}

impl SecuritySection {
    /// The TLS files of process `name`; `dir` is the topology file's folder.
    pub(crate) fn tls_for(&self, dir: &Path, name: &str) -> Result<Tls, SecurityError> {
        let certs = dir.join(&self.certs);
        Tls::new(
            certs.join("ca.pem"),
            certs.join(format!("{name}.pem")),
            certs.join(format!("{name}.key")),
            self.verify_names,
            &format!("[security] certs = {:?}", self.certs.display().to_string()),
        )
    }

    /// Client and producer names must be names of their own: one named
    /// like a process would be let do what the process does.
    pub(crate) fn check<'a>(
        &self,
        mut members: impl Iterator<Item = &'a str>,
    ) -> Result<(), SecurityError> {
        let outsiders = || self.clients.iter().chain(&self.producers);
        if outsiders().any(|c| c.trim().is_empty()) {
            return Err(SecurityError::EmptyClient);
        }
        match members.find(|m| outsiders().any(|c| c == m)) {
            Some(name) => Err(SecurityError::ClientIsMember {
                name: name.to_string(),
            }),
            None => Ok(()),
        }
    }
}
