//! `idmesh up --config T --emit systemd DIR`: writes the units that run the
//! topology's processes (`runtime::systemd`), then says, host by host,
//! what was written and what is left to do on the host.

use crate::cli::UpArgs;
use crate::runtime::systemd::{self, Emitted, Settings, CONFIG_FOLDER, TARGET};
use crate::runtime::topology::Topology;
use anyhow::{bail, Context, Result};
use std::path::Path;

pub fn run(args: &UpArgs) -> Result<()> {
    let Some([kind, dir]) = args.emit.as_deref() else {
        bail!("--emit takes two values: KIND DIR, as in --emit systemd units/");
    };
    if kind != "systemd" {
        bail!("--emit {kind}: the kind there is is systemd (--emit systemd DIR)");
    }
    let defaults = Settings::default();
    let settings = Settings {
        binary: args.binary.clone().unwrap_or(defaults.binary),
        config_dir: args.config_dir.clone().unwrap_or(defaults.config_dir),
        host: args.host.clone(),
    };
    let topology = Topology::load(&args.config)?;
    let out = Path::new(dir);
    let emitted = systemd::emit(&topology, &args.config, out, &settings)
        .with_context(|| format!("{}: --emit systemd {dir}", args.config.display()))?;
    let name = args
        .config
        .file_name()
        .unwrap_or_default()
        .to_string_lossy();
    for host in &emitted {
        report(host, &name, &settings);
    }
    println!(
        "on each host H: copy {dir}/H/*.service and {dir}/H/{TARGET} to /etc/systemd/system/, \
         {dir}/H/{CONFIG_FOLDER}/ to {}/ and idmesh to {}; then systemctl daemon-reload && \
         systemctl enable --now {TARGET} (docs/guide/lan.md)",
        settings.config_dir.display(),
        settings.binary.display(),
    );
    Ok(())
}

/// What was written for one host (`topology`: the topology file's name),
/// and what it still needs.
fn report(host: &Emitted, topology: &str, settings: &Settings) {
    let config: Vec<String> = std::iter::once(topology.to_string())
        .chain(host.copied.iter().map(|p| p.display().to_string()))
        .collect();
    println!(
        "{}: {} ({}); {CONFIG_FOLDER}/: {}",
        host.host,
        host.dir.display(),
        host.units.join(", "),
        config.join(", "),
    );
    let listed = |paths: &[std::path::PathBuf]| {
        let shown: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
        shown.join(", ")
    };
    if !host.missing.is_empty() {
        eprintln!(
            "warning: {}: not in the topology's folder, so not in {CONFIG_FOLDER}/: {}; put them \
             in {} on {} yourself",
            host.host,
            listed(&host.missing),
            settings.config_dir.display(),
            host.host,
        );
    }
    if !host.in_place.is_empty() {
        eprintln!(
            "note: {}: read where the topology says, not copied: {}",
            host.host,
            listed(&host.in_place)
        );
    }
    for unit in &host.stale {
        eprintln!(
            "warning: {}: {} runs no process of this topology (left from another?): remove it",
            host.host,
            host.dir.join(unit).display()
        );
    }
}
