//! Puts what [`super::plan`] chose on disk: each host's units, and its
//! config folder with the topology as the hosts read it and the files it
//! names copied from the topology's folder — private keys readable by
//! their owner only.

use super::config::hosted_topology;
use super::error::SystemdError;
use super::plan::{plan, HostFiles};
use super::{Settings, CONFIG_FOLDER};
use crate::runtime::topology::Topology;
use std::io::Write;
use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
use std::path::{Path, PathBuf};

/// What was written for one host.
#[derive(Debug, Clone, PartialEq)]
pub struct Emitted {
    pub host: String,
    /// `DIR/<host>`.
    pub dir: PathBuf,
    /// The unit files' names.
    pub units: Vec<String>,
    /// What went into `config/` besides the topology, relative to it.
    pub copied: Vec<PathBuf>,
    /// Files the host needs that the topology's folder does not hold (a
    /// certificate made elsewhere, a trace not there yet): the operator
    /// puts them into the host's config folder.
    pub missing: Vec<PathBuf>,
    /// Absolute paths the host reads in place.
    pub in_place: Vec<PathBuf>,
    /// `idmesh-*.service` files already in `DIR/<host>` that no process of
    /// the topology has (left from an earlier topology): not removed.
    pub stale: Vec<String>,
}

/// Writes the units of `topology`, read from `config`, into `out`.
pub fn emit(
    topology: &Topology,
    config: &Path,
    out: &Path,
    settings: &Settings,
) -> Result<Vec<Emitted>, SystemdError> {
    let file_name =
        config
            .file_name()
            .and_then(|n| n.to_str())
            .ok_or_else(|| SystemdError::NotUtf8 {
                option: "--config",
                path: config.to_path_buf(),
            })?;
    let text = std::fs::read_to_string(config).map_err(|source| SystemdError::Read {
        path: config.to_path_buf(),
        source,
    })?;
    let hosted = hosted_topology(&text, config)?;
    // Every host's files are chosen before any is written: a mistake
    // leaves nothing half written.
    let hosts = plan(topology, file_name, settings)?;
    hosts
        .iter()
        .map(|host| write_host(host, &topology.dir, (file_name, &hosted), out))
        .collect()
}

/// Writes `DIR/<host>`: units, then `config/` with the topology `(name,
/// text)` and the copies from `from`.
fn write_host(
    host: &HostFiles,
    from: &Path,
    (name, topology): (&str, &str),
    out: &Path,
) -> Result<Emitted, SystemdError> {
    let dir = out.join(&host.host);
    create_dir(&dir)?;
    let stale = stale_units(&dir, host);
    for (unit, text) in &host.units {
        write_file(&dir.join(unit), text.as_bytes(), 0o644)?;
    }
    let config = dir.join(CONFIG_FOLDER);
    create_dir(&config)?;
    write_file(&config.join(name), topology.as_bytes(), 0o644)?;
    let (mut copied, mut missing) = (Vec::new(), Vec::new());
    for path in &host.copies {
        let source = from.join(path);
        let bytes = match std::fs::read(&source) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                missing.push(path.clone());
                continue;
            }
            Err(source_error) => {
                return Err(SystemdError::Read {
                    path: source,
                    source: source_error,
                })
            }
        };
        let to = config.join(path);
        if let Some(parent) = to.parent() {
            create_dir(parent)?;
        }
        let key = path.extension().is_some_and(|e| e == "key");
        write_file(&to, &bytes, if key { 0o600 } else { 0o644 })?;
        copied.push(path.clone());
    }
    Ok(Emitted {
        host: host.host.clone(),
        dir,
        units: host.units.iter().map(|(n, _)| n.clone()).collect(),
        copied,
        missing,
        in_place: host.in_place.clone(),
        stale,
    })
}

fn create_dir(dir: &Path) -> Result<(), SystemdError> {
    std::fs::create_dir_all(dir).map_err(|source| SystemdError::Write {
        path: dir.to_path_buf(),
        source,
    })
}

/// Writes `bytes` to `path` with permissions `mode`, whatever the file had.
fn write_file(path: &Path, bytes: &[u8], mode: u32) -> Result<(), SystemdError> {
    let failed = |source| SystemdError::Write {
        path: path.to_path_buf(),
        source,
    };
    // Created with `mode`, so that a key is never readable by others,
    // not even between its creation and a chmod.
    let mut file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(true)
        .mode(mode)
        .open(path)
        .map_err(failed)?;
    file.write_all(bytes).map_err(failed)?;
    file.set_permissions(std::fs::Permissions::from_mode(mode))
        .map_err(failed)
}

/// The `idmesh-*.service` files of `dir` that `host` does not write.
fn stale_units(dir: &Path, host: &HostFiles) -> Vec<String> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut stale: Vec<String> = entries
        .flatten()
        .filter_map(|e| e.file_name().to_str().map(String::from))
        .filter(|n| n.starts_with("idmesh-") && n.ends_with(".service"))
        .filter(|n| !host.units.iter().any(|(unit, _)| unit == n))
        .collect();
    stale.sort();
    stale
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn keys_are_written_for_their_owner_only_and_missing_files_are_named() {
        let dir = std::env::temp_dir().join(format!("idmesh-systemd-write-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let from = dir.join("from");
        std::fs::create_dir_all(from.join("certs")).unwrap();
        std::fs::write(from.join("certs/ca.pem"), "-----BEGIN").unwrap();
        std::fs::write(from.join("certs/l.key"), "-----BEGIN").unwrap();
        let out = dir.join("out");
        std::fs::create_dir_all(out.join("h")).unwrap();
        std::fs::write(out.join("h/idmesh-old.service"), "").unwrap();
        let host = HostFiles {
            host: "h".into(),
            units: vec![("idmesh-l.service".into(), "[Unit]\n".into())],
            copies: ["certs/ca.pem", "certs/l.key", "certs/l.pem"]
                .map(PathBuf::from)
                .to_vec(),
            in_place: vec![],
        };
        let emitted = write_host(&host, &from, ("t.toml", "x = 1\n"), &out).unwrap();
        let mode = |p: &str| {
            let meta = std::fs::metadata(out.join("h").join(p)).unwrap();
            meta.permissions().mode() & 0o777
        };
        let result = (
            mode("config/certs/l.key"),
            mode("config/certs/ca.pem"),
            std::fs::read_to_string(out.join("h/config/t.toml")).ok(),
            emitted.missing.clone(),
            emitted.stale.clone(),
        );
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(result.0, 0o600);
        assert_eq!(result.1, 0o644);
        assert_eq!(result.2.as_deref(), Some("x = 1\n"));
        assert_eq!(result.3, [PathBuf::from("certs/l.pem")]);
        assert_eq!(result.4, ["idmesh-old.service"]);
    }
}
