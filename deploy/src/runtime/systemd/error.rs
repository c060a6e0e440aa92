//! What can stop `idmesh up --emit systemd`, each error naming the host,
//! the process, the option or the file to fix.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum SystemdError {
    #[error("host {host:?} runs no process of the topology; its hosts are {known}")]
    UnknownHost { host: String, known: String },
    #[error(
        "no process names its host (each runs on \"local\", the default): give each process \
         its host = \"NAME\", or pass --host local for the units of this one machine"
    )]
    NoHosts,
    #[error(
        "{names}: no host named (each runs on \"local\", the default): give each its \
         host = \"NAME\", or pass --host for the units of one host"
    )]
    Hostless { names: String },
    #[error(
        "{what} {name:?} cannot name a systemd unit or a folder: use ASCII letters, digits, \
         '-', '_' and '.', not starting with '.'"
    )]
    BadName { what: &'static str, name: String },
    #[error(
        "process {name:?}: its unit would be the [web] gateway's (idmesh-web.service); \
         rename the process"
    )]
    Taken { name: String },
    #[error("{option} {path}: give an absolute path (the units read it on each host)", path = path.display())]
    Relative { option: &'static str, path: PathBuf },
    #[error("{option} {path}: not UTF-8, which a unit file cannot hold", path = path.display())]
    NotUtf8 { option: &'static str, path: PathBuf },
    #[error(
        "{field} = {path:?}: leaves the topology's folder; give an absolute path (read in \
         place on each host) or one inside the folder (copied with the topology)",
        path = path.display().to_string()
    )]
    Outside { field: String, path: PathBuf },
    #[error("{path}: cannot read: {source}", path = path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: cannot write: {source}", path = path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: cannot be rewritten for the hosts: {source}", path = path.display())]
    Edit {
        path: PathBuf,
        source: toml_edit::TomlError,
    },
}
