//! The topology file as the hosts keep it in their config folder: the
//! file as written, comments and all, but for a relative `state_dir`,
//! which would resolve against the config folder (`/etc/idmesh/state`)
//! and is moved into the units' state directory instead
//! (`/var/lib/idmesh/state`), where systemd makes the folder, gives it to
//! the service and keeps it across restarts. An absolute `state_dir`
//! (shared storage, for roles to be adopted) is kept.

use super::error::SystemdError;
use super::plan::inside;
use super::STATE_DIRECTORY;
use std::path::{Path, PathBuf};

/// `text`, the topology file `path`, as the hosts read it.
pub(crate) fn hosted_topology(text: &str, path: &Path) -> Result<String, SystemdError> {
    let mut document: toml_edit::DocumentMut =
        text.parse().map_err(|source| SystemdError::Edit {
            path: path.to_path_buf(),
            source,
        })?;
    let Some(state) = document.get_mut("state_dir").and_then(|i| i.as_value_mut()) else {
        return Ok(text.to_string());
    };
    let Some(dir) = state.as_str().map(PathBuf::from) else {
        // `Topology::load` read it as a path: it is a string.
        return Ok(text.to_string());
    };
    if dir.is_absolute() {
        return Ok(text.to_string());
    }
    if !inside(&dir) {
        return Err(SystemdError::Outside {
            field: "state_dir".into(),
            path: dir,
        });
    }
    let moved = Path::new("/var/lib").join(STATE_DIRECTORY).join(&dir);
    let decor = state.decor().clone();
    let mut value = toml_edit::Value::from(moved.display().to_string());
    *value.decor_mut() = decor;
    *state = value;
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
    Ok(format!(
        "# {} as the units of `idmesh up --emit systemd` read it: state_dir\n\
         # {:?} moved into their state directory, the rest as written.\n{document}",
        name.unwrap_or_default(),
        dir.display().to_string(),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_relative_state_dir_moves_into_the_state_directory_and_comments_stay() {
        let text = "prefix = \"p\"\nstate_dir = \"state\"    # journals here\n[coordinator]\n";
        let hosted = hosted_topology(text, Path::new("/x/lan.toml")).unwrap();
        assert!(
            hosted.contains("state_dir = \"/var/lib/idmesh/state\"    # journals here\n"),
            "{hosted}"
        );
        assert!(hosted.starts_with("# lan.toml as the units"), "{hosted}");
        assert!(hosted.ends_with("prefix = \"p\"\nstate_dir = \"/var/lib/idmesh/state\"    # journals here\n[coordinator]\n"), "{hosted}");
        for kept in ["prefix = \"p\"\n", "state_dir = \"/nfs/idmesh\"\n"] {
            assert_eq!(hosted_topology(kept, Path::new("t.toml")).unwrap(), kept);
        }
        let e = hosted_topology("state_dir = \"../s\"\n", Path::new("t.toml")).unwrap_err();
        assert!(e.to_string().starts_with("state_dir = \"../s\""), "{e}");
    }
}
