//! `idmesh up --config T --emit systemd DIR`: systemd units that run the
//! processes of a topology on each of its hosts, in place of a foreground
//! `idmesh up --host H` per host. Each unit runs one process with the very
//! command line `up` starts it with (`launch::role_command`), and systemd
//! takes the part of `up`'s supervisor: it starts a failed process again
//! and leaves one that ended of itself (exit 0) down.
//!
//! What `DIR` holds, for every host H of the topology (or `--host` alone):
//!
//! ```text
//! DIR/H/idmesh-<name>.service   one per process of H, its name the process's
//! DIR/H/idmesh.target           wants every service of H: enable this one
//! DIR/H/config/                 the config folder of H (--config-dir,
//!                               /etc/idmesh by default): the topology file,
//!                               its sensors' traces, and for a secured
//!                               topology certs/ca.pem and the .pem and .key
//!                               of H's own processes
//! ```
//!
//! [`plan`] chooses each host's files and [`units`] writes their text (both
//! pure); [`config`] is the topology file as the hosts keep it; [`write`]
//! puts it all on disk.

mod config;
mod error;
mod plan;
mod units;
mod write;

pub use error::SystemdError;
pub use plan::{plan, HostFiles};
pub use units::{service_name, TARGET};
pub use write::{emit, Emitted};

use std::path::PathBuf;

/// The units' `StateDirectory=`: systemd makes `/var/lib/idmesh` for the
/// service and runs it there; a relative `state_dir` moves into it.
pub const STATE_DIRECTORY: &str = "idmesh";
/// Where the units find the binary unless told.
pub const DEFAULT_BINARY: &str = "/usr/local/bin/idmesh";
/// Where the hosts keep the topology and its certificates unless told.
pub const DEFAULT_CONFIG_DIR: &str = "/etc/idmesh";
/// The folder of `DIR/<host>/` to copy to the config folder.
pub const CONFIG_FOLDER: &str = "config";

/// How the units run the processes.
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// The `idmesh` binary as the hosts have it (absolute).
    pub binary: PathBuf,
    /// Where the hosts keep the topology file and what it names
    /// (absolute).
    pub config_dir: PathBuf,
    /// Only this host's units (None: every host's).
    pub host: Option<String>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            binary: DEFAULT_BINARY.into(),
            config_dir: DEFAULT_CONFIG_DIR.into(),
            host: None,
        }
    }
}
