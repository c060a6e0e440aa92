//! The text of the unit files: one service per process, which runs the
//! command line `idmesh up` starts that process with, and the target that
//! groups a host's services. Pure: names and paths in, text out.

use super::STATE_DIRECTORY;

/// The target every unit of a host belongs to.
pub const TARGET: &str = "idmesh.target";

/// How long systemd waits before it starts a failed process again: well
/// under the default `takeover_after_ms` (3 s), so that a process that
/// crashed is back before a leader elsewhere adopts its role.
pub(crate) const RESTART_SEC: &str = "1s";
/// A process that failed this many times within [`START_LIMIT_INTERVAL`]
/// stays failed: at one start a second that is a process failing within
/// seconds of every start, for a reason a restart will not fix (a wrong
/// address, a missing certificate), which `systemctl status` then shows.
/// A process that runs ten seconds or more before it fails can never reach
/// the limit, and is started again for as long as it fails.
pub(crate) const START_LIMIT_BURST: u32 = 30;
pub(crate) const START_LIMIT_INTERVAL: &str = "5min";
/// How long a process has to stop after SIGTERM before SIGKILL, as
/// `idmesh up` waits for its children (roles stop cleanly on SIGTERM).
pub(crate) const TIMEOUT_STOP_SEC: &str = "10s";

/// The unit of process `name`.
pub fn service_name(name: &str) -> String {
    format!("idmesh-{name}.service")
}

/// One process of the topology, as its unit runs it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Service<'a> {
    pub name: &'a str,
    pub role: &'a str,
    pub host: &'a str,
    /// The command line, binary first, each word unquoted.
    pub command: Vec<String>,
}

/// The unit file of `service`.
pub(crate) fn service(service: &Service) -> String {
    let exec: Vec<String> = service.command.iter().map(|w| quote(w)).collect();
    format!(
        "# idmesh {role} {name} on host {host}, written by `idmesh up --emit systemd`.\n\
         # systemd starts it again when it fails, as `idmesh up` would.\n\
         [Unit]\n\
         Description=idmesh {role} {name}\n\
         After=network-online.target\n\
         Wants=network-online.target\n\
         PartOf={TARGET}\n\
         # A process that fails this often, this fast, needs a fix, not a restart.\n\
         StartLimitIntervalSec={START_LIMIT_INTERVAL}\n\
         StartLimitBurst={START_LIMIT_BURST}\n\
         \n\
         [Service]\n\
         Type=exec\n\
         ExecStart={exec}\n\
         Restart=on-failure\n\
         RestartSec={RESTART_SEC}\n\
         TimeoutStopSec={TIMEOUT_STOP_SEC}\n\
         StateDirectory={state}\n\
         WorkingDirectory=/var/lib/{state}\n\
         StandardOutput=journal\n\
         StandardError=journal\n\
         SyslogIdentifier=idmesh-{name}\n\
         NoNewPrivileges=yes\n\
         ProtectSystem=full\n\
         \n\
         [Install]\n\
         WantedBy={TARGET}\n",
        role = service.role,
        name = service.name,
        host = service.host,
        exec = exec.join(" "),
        state = STATE_DIRECTORY,
    )
}

/// The target of host `host`, which starts and stops `services` (unit
/// names) together: it wants each, and each is part of it.
pub(crate) fn target(host: &str, topology: &str, services: &[String]) -> String {
    format!(
        "# The idmesh processes of host {host} ({topology}), written by\n\
         # `idmesh up --emit systemd`: `systemctl enable --now {TARGET}` starts them\n\
         # and starts them at boot; stopping or restarting it does the same to each.\n\
         [Unit]\n\
         Description=idmesh processes of host {host} ({topology})\n\
         Wants={services}\n\
         \n\
         [Install]\n\
         WantedBy=multi-user.target\n",
        services = services.join(" "),
    )
}

/// One word of an `ExecStart=` line, as systemd splits and expands it:
/// `%` (a specifier) and `$` (a variable) doubled, and a word with
/// anything but plain path characters in double quotes, its `\` and `"`
/// escaped and control characters written as C escapes.
pub(crate) fn quote(word: &str) -> String {
    let plain = !word.is_empty()
        && word
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "/._-+=:,@%$".contains(c));
    let mut out = String::with_capacity(word.len() + 2);
    for c in word.chars() {
        match c {
            '%' => out.push_str("%%"),
            '$' => out.push_str("$$"),
            '\\' => out.push_str("\\\\"),
            '"' => out.push_str("\\\""),
            c if c.is_control() => out.push_str(&format!("\\x{:02x}", c as u32)),
            c => out.push(c),
        }
    }
    if plain {
        out
    } else {
        format!("\"{out}\"")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leader() -> Service<'static> {
        Service {
            name: "leader-0",
            role: "leader",
            host: "east",
            command: ["/usr/local/bin/idmesh", "leader", "--config"]
                .into_iter()
                .map(String::from)
                .chain(["/etc/idmesh/lan.toml".into(), "--name".into()])
                .chain(["leader-0".into()])
                .collect(),
        }
    }

    /// The value of `key=` in `text`, if it is there once.
    fn value<'a>(text: &'a str, key: &str) -> Option<&'a str> {
        let mut found = text
            .lines()
            .filter_map(|l| l.strip_prefix(&format!("{key}=")));
        let first = found.next();
        assert!(found.next().is_none(), "{key}= twice:\n{text}");
        first
    }

    #[test]
    fn a_service_runs_its_process_and_restarts_it_on_failure() {
        let text = service(&leader());
        let want = [
            (
                "ExecStart",
                "/usr/local/bin/idmesh leader --config /etc/idmesh/lan.toml --name leader-0",
            ),
            ("Restart", "on-failure"),
            ("RestartSec", RESTART_SEC),
            ("StartLimitIntervalSec", START_LIMIT_INTERVAL),
            ("StartLimitBurst", "30"),
            ("After", "network-online.target"),
            ("Wants", "network-online.target"),
            ("PartOf", TARGET),
            ("WantedBy", TARGET),
            ("StandardOutput", "journal"),
            ("StandardError", "journal"),
            ("SyslogIdentifier", "idmesh-leader-0"),
            ("StateDirectory", "idmesh"),
            ("WorkingDirectory", "/var/lib/idmesh"),
        ];
        for (key, expected) in want {
            assert_eq!(value(&text, key), Some(expected), "{key}:\n{text}");
        }
        // The start limit is a [Unit] setting: in [Service] systemd ignores it.
        let unit = &text[text.find("[Unit]").unwrap()..text.find("[Service]").unwrap()];
        assert!(unit.contains("StartLimitBurst=") && unit.contains("StartLimitIntervalSec="));
        assert_eq!(service_name("leader-0"), "idmesh-leader-0.service");
    }

    #[test]
    fn a_target_wants_every_service_of_its_host() {
        let services = vec![service_name("leader-0"), service_name("leader-1")];
        let text = target("east", "lan.toml", &services);
        assert_eq!(
            value(&text, "Wants"),
            Some("idmesh-leader-0.service idmesh-leader-1.service")
        );
        assert_eq!(value(&text, "WantedBy"), Some("multi-user.target"));
    }

    #[test]
    fn words_are_quoted_as_systemd_splits_them() {
        assert_eq!(quote("/usr/local/bin/idmesh"), "/usr/local/bin/idmesh");
        assert_eq!(quote("/opt/id mesh/bin"), "\"/opt/id mesh/bin\"");
        assert_eq!(quote("/etc/100%/$HOME"), "/etc/100%%/$$HOME");
        assert_eq!(quote("a\"b\\c"), "\"a\\\"b\\\\c\"");
        assert_eq!(quote("a\nb"), "\"a\\x0ab\"");
        assert_eq!(quote(""), "\"\"");
    }
}
