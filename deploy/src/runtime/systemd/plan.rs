//! Which files each host gets: its hosts chosen and checked, one unit per
//! process of the host and the host's target, and the files of the
//! topology's folder the host needs beside the topology (its sensors'
//! traces; for a secured topology the CA's certificate and its own
//! processes' certificates and keys, never the CA's key nor another
//! host's). Pure: the topology in, the files' names and text out.

use super::error::SystemdError;
use super::units::{self, Service, TARGET};
use super::Settings;
use crate::runtime::launch::role_command;
use crate::runtime::topology::{Member, Topology};
use std::collections::BTreeSet;
use std::path::{Component, Path, PathBuf};

/// The name of the `[web]` gateway's unit (`idmesh-web.service`), on the
/// coordinator's host.
pub const WEB: &str = "web";

/// What one host gets.
#[derive(Debug, Clone, PartialEq)]
pub struct HostFiles {
    pub host: String,
    /// Unit files, by file name, with their text: one service per process
    /// of the host, then the target.
    pub units: Vec<(String, String)>,
    /// Files the host reads from the topology's folder, relative to it:
    /// copied there into the config folder.
    pub copies: Vec<PathBuf>,
    /// Absolute paths the topology names that the host reads in place:
    /// not copied, the operator puts them there.
    pub in_place: Vec<PathBuf>,
}

/// The files of every host of `topology` (only `settings.host` if set);
/// `file_name` is the topology file's name, kept in the config folder.
pub fn plan(
    topology: &Topology,
    file_name: &str,
    settings: &Settings,
) -> Result<Vec<HostFiles>, SystemdError> {
    let binary = absolute_utf8("--binary", &settings.binary)?;
    absolute_utf8("--config-dir", &settings.config_dir)?;
    let config = settings.config_dir.join(file_name);
    let members = topology.members();
    for m in &members {
        check_name("process", &m.name)?;
        if topology.web.is_some() && m.name == WEB {
            return Err(SystemdError::Taken {
                name: m.name.clone(),
            });
        }
    }
    let hosts = hosts(&members, settings.host.as_deref())?;
    hosts
        .into_iter()
        .map(|host| {
            let on: Vec<&Member> = members.iter().filter(|m| m.host == host).collect();
            let mut names = Vec::new();
            let mut files = Vec::new();
            for m in &on {
                let mut command = vec![binary.to_string()];
                for word in role_command(m.role, &config, &m.name) {
                    // Every word is a name checked above or `config`, UTF-8.
                    command.push(word.to_string_lossy().into_owned());
                }
                let service = Service {
                    name: &m.name,
                    role: m.role,
                    host: &host,
                    command,
                };
                names.push(units::service_name(&m.name));
                files.push((units::service_name(&m.name), units::service(&service)));
            }
            if let Some(web) = topology
                .web
                .as_ref()
                .filter(|_| host == topology.coordinator.host)
            {
                // As `idmesh up` serves it, beside the coordinator; as
                // `idmesh web`, a unit of its own.
                let mut command = vec![binary.to_string(), "web".to_string()];
                for (flag, value) in [
                    ("--listen", web.listen.clone()),
                    ("--connect", topology.coordinator_endpoints()),
                    ("--prefix", topology.prefix.clone()),
                ] {
                    command.extend([flag.to_string(), value]);
                }
                command.extend(web.markers.flags());
                let service = Service {
                    name: WEB,
                    role: "gateway",
                    host: &host,
                    command,
                };
                names.push(units::service_name(WEB));
                files.push((units::service_name(WEB), units::service(&service)));
            }
            files.push((TARGET.to_string(), units::target(&host, file_name, &names)));
            let (copies, in_place) = host_reads(topology, &on)?;
            Ok(HostFiles {
                host,
                units: files,
                copies,
                in_place,
            })
        })
        .collect()
}

/// `path` as a unit file holds it: absolute and UTF-8.
fn absolute_utf8<'a>(option: &'static str, path: &'a Path) -> Result<&'a str, SystemdError> {
    if !path.is_absolute() {
        return Err(SystemdError::Relative {
            option,
            path: path.to_path_buf(),
        });
    }
    path.to_str().ok_or_else(|| SystemdError::NotUtf8 {
        option,
        path: path.to_path_buf(),
    })
}

/// A process or host name that can name a unit file and a folder as it is.
fn check_name(what: &'static str, name: &str) -> Result<(), SystemdError> {
    let fits = !name.is_empty()
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c));
    if fits {
        Ok(())
    } else {
        Err(SystemdError::BadName {
            what,
            name: name.to_string(),
        })
    }
}

/// The hosts to write units for, in name order: `only`, or every host of
/// the topology, which must then name a host for every process.
fn hosts(members: &[Member], only: Option<&str>) -> Result<Vec<String>, SystemdError> {
    let all: BTreeSet<&str> = members.iter().map(|m| m.host.as_str()).collect();
    let hosts = match only {
        Some(host) if all.contains(host) => vec![host.to_string()],
        Some(host) => {
            return Err(SystemdError::UnknownHost {
                host: host.to_string(),
                known: all.into_iter().collect::<Vec<_>>().join(", "),
            })
        }
        None => {
            let hostless: Vec<&str> = members
                .iter()
                .filter(|m| m.host == "local")
                .map(|m| m.name.as_str())
                .collect();
            if hostless.len() == members.len() {
                return Err(SystemdError::NoHosts);
            }
            if !hostless.is_empty() {
                return Err(SystemdError::Hostless {
                    names: hostless.join(", "),
                });
            }
            all.into_iter().map(String::from).collect()
        }
    };
    for host in &hosts {
        check_name("host", host)?;
    }
    Ok(hosts)
}

/// The files processes `on` read besides the topology: the copies (inside
/// the topology's folder) and those read in place (absolute).
fn host_reads(
    topology: &Topology,
    on: &[&Member],
) -> Result<(Vec<PathBuf>, Vec<PathBuf>), SystemdError> {
    let mut reads: Vec<(String, PathBuf)> = Vec::new();
    for sensor in &topology.sensors {
        if on.iter().any(|m| m.name == sensor.name) {
            let field = format!("sensor {}: trace", sensor.name);
            reads.push((field, sensor.trace.clone()));
        }
    }
    if let Some(security) = &topology.security {
        let certs = &security.certs;
        let field = "[security] certs".to_string();
        reads.push((field.clone(), certs.join("ca.pem")));
        for m in on {
            reads.push((field.clone(), certs.join(format!("{}.pem", m.name))));
            reads.push((field.clone(), certs.join(format!("{}.key", m.name))));
        }
    }
    let (mut copies, mut in_place) = (Vec::new(), Vec::new());
    for (field, path) in reads {
        if path.is_absolute() {
            in_place.push(path);
        } else if inside(&path) {
            copies.push(path);
        } else {
            return Err(SystemdError::Outside { field, path });
        }
    }
    copies.dedup();
    in_place.dedup();
    Ok((copies, in_place))
}

/// A relative path that stays inside the folder it is relative to.
pub(crate) fn inside(path: &Path) -> bool {
    path.components()
        .all(|c| matches!(c, Component::Normal(_) | Component::CurDir))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::runtime::security::SecuritySection;
    use crate::runtime::topology::{LeaderProcess, Process, SensorProcess};

    /// lan.toml's processes: the coordinator and the sensor on `gateway`,
    /// two leaders on each of `east` and `west`.
    fn lan() -> Topology {
        let on = |host: &str, mut p: LeaderProcess| {
            p.host = host.into();
            p
        };
        let mut sensor = SensorProcess::new("sensor-0", "tcp/10.0.0.1:2", "crowd.jsonl");
        sensor.host = "gateway".into();
        let mut coordinator = Process::new("coordinator", "tcp/10.0.0.1:1");
        coordinator.host = "gateway".into();
        let leaders = (0..4)
            .map(|i| {
                let host = if i < 2 { "east" } else { "west" };
                on(
                    host,
                    LeaderProcess::new(format!("leader-{i}"), format!("tcp/10.0.0.2:{i}")),
                )
            })
            .collect();
        Topology::new(coordinator, vec![sensor], leaders)
    }

    fn settings() -> Settings {
        Settings {
            binary: "/usr/local/bin/idmesh".into(),
            config_dir: "/etc/idmesh".into(),
            host: None,
        }
    }

    fn unit<'a>(host: &'a HostFiles, name: &str) -> &'a str {
        host.units
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, text)| text.as_str())
            .unwrap_or_else(|| panic!("{}: no {name}", host.host))
    }

    #[test]
    fn every_process_has_one_unit_on_its_host_that_runs_what_up_runs() {
        let topology = lan();
        let hosts = plan(&topology, "lan.toml", &settings()).unwrap();
        let names: Vec<&str> = hosts.iter().map(|h| h.host.as_str()).collect();
        assert_eq!(names, ["east", "gateway", "west"]);
        let mut seen = Vec::new();
        for host in &hosts {
            let target = unit(host, TARGET);
            for m in topology.members().iter().filter(|m| m.host == host.host) {
                let text = unit(host, &units::service_name(&m.name));
                let exec = format!(
                    "ExecStart=/usr/local/bin/idmesh {} --config /etc/idmesh/lan.toml --name {}\n",
                    m.role, m.name
                );
                assert!(text.contains(&exec), "{text}");
                assert!(text.contains("\nRestart=on-failure\n"), "{text}");
                assert!(target.contains(&units::service_name(&m.name)), "{target}");
                seen.push(m.name.clone());
            }
            // Its processes and the target, nothing else.
            assert_eq!(host.units.len(), 3, "{}", host.host);
        }
        seen.sort();
        let mut all: Vec<String> = topology.members().into_iter().map(|m| m.name).collect();
        all.sort();
        assert_eq!(seen, all);
        let gateway = &hosts[1];
        assert_eq!(gateway.copies, [PathBuf::from("crowd.jsonl")]);
        assert!(hosts[0].copies.is_empty() && hosts[0].in_place.is_empty());
    }

    #[test]
    fn a_secured_host_gets_the_ca_and_its_own_certificates_only() {
        let mut topology = lan();
        topology.security = Some(SecuritySection::new("certs"));
        let mut only_east = settings();
        only_east.host = Some("east".into());
        let hosts = plan(&topology, "secure-lan.toml", &only_east).unwrap();
        assert_eq!(hosts.len(), 1);
        let copies: Vec<String> = hosts[0]
            .copies
            .iter()
            .map(|p| p.display().to_string())
            .collect();
        assert_eq!(
            copies,
            [
                "certs/ca.pem",
                "certs/leader-0.pem",
                "certs/leader-0.key",
                "certs/leader-1.pem",
                "certs/leader-1.key"
            ]
        );
        topology.security = Some(SecuritySection::new("/srv/pki"));
        topology.sensors[0].trace = "/data/crowd.jsonl".into();
        let gateway = &plan(&topology, "t.toml", &settings()).unwrap()[1];
        assert!(gateway.copies.is_empty());
        assert!(gateway
            .in_place
            .contains(&PathBuf::from("/data/crowd.jsonl")));
        assert!(gateway
            .in_place
            .contains(&PathBuf::from("/srv/pki/sensor-0.key")));
    }

    #[test]
    fn bad_input_is_refused_naming_what_is_wrong() {
        let error = |topology: &Topology, settings: &Settings| {
            plan(topology, "lan.toml", settings)
                .unwrap_err()
                .to_string()
        };
        let mut only = settings();
        only.host = Some("north".into());
        let e = error(&lan(), &only);
        assert!(
            e.contains("\"north\"") && e.contains("east, gateway, west"),
            "{e}"
        );

        let mut hostless = lan();
        hostless.coordinator.host = "local".into();
        let e = error(&hostless, &settings());
        assert!(e.starts_with("coordinator: no host named"), "{e}");
        let nowhere = Topology::new(
            Process::new("c", "tcp/127.0.0.1:1"),
            vec![SensorProcess::new("s", "tcp/127.0.0.1:2", "x.jsonl")],
            vec![LeaderProcess::new("l", "tcp/127.0.0.1:3")],
        );
        assert!(error(&nowhere, &settings()).contains("no process names its host"));
        only.host = Some("local".into());
        assert_eq!(plan(&nowhere, "t.toml", &only).unwrap()[0].units.len(), 4);

        let mut relative = settings();
        relative.binary = "target/release/idmesh".into();
        assert!(error(&lan(), &relative).starts_with("--binary target/release/idmesh:"));
        let mut relative = settings();
        relative.config_dir = "etc".into();
        assert!(error(&lan(), &relative).starts_with("--config-dir etc:"));

        let mut spaced = lan();
        spaced.leader[0].name = "leader 0".into();
        assert!(error(&spaced, &settings()).contains("process \"leader 0\""));
        let mut outside = lan();
        outside.sensors[0].trace = "../crowd.jsonl".into();
        let e = error(&outside, &settings());
        assert!(
            e.starts_with("sensor sensor-0: trace = \"../crowd.jsonl\""),
            "{e}"
        );
        let mut taken = lan();
        taken.web = Some(crate::runtime::topology::WebSection::new("0.0.0.0:8080"));
        taken.leader[0].name = WEB.into();
        assert!(error(&taken, &settings()).starts_with("process \"web\": its unit"));
    }

    /// A topology's `[web]` is a unit of its own on the coordinator's
    /// host, running `idmesh web` with the section's settings as flags.
    #[test]
    fn the_web_gateway_is_a_unit_beside_the_coordinator() {
        let mut topology = lan();
        let mut web = crate::runtime::topology::WebSection::new("0.0.0.0:8080");
        web.markers.ros2_markers = Some("/idmesh/markers".into());
        web.markers.ros2_humble = true;
        topology.web = Some(web);
        let hosts = plan(&topology, "lan.toml", &settings()).unwrap();
        for host in &hosts {
            let has = host.units.iter().any(|(n, _)| n == "idmesh-web.service");
            assert_eq!(has, host.host == "gateway", "{}", host.host);
        }
        let gateway = &hosts[1];
        let text = unit(gateway, "idmesh-web.service");
        let exec = "ExecStart=/usr/local/bin/idmesh web --listen 0.0.0.0:8080 \
                    --connect tcp/10.0.0.1:1 --prefix idmesh/default --ros2-markers /idmesh/markers \
                    --ros2-domain 0 --ros2-rate 2 --ros2-frame map --ros2-humble\n";
        assert!(text.contains(exec), "{text}");
        assert!(unit(gateway, TARGET).contains("idmesh-web.service"));
    }
}
