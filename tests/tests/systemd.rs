//! `idmesh up --emit systemd DIR`, run as an operator runs it: the real
//! binary writes the units of `deploy/examples/lan.toml` and of a copy of
//! `secure-lan.toml` with its certificates, and every unit written must
//! pass `systemd-analyze verify` without a word about it — the units point
//! at the binary under test (`--binary`), which verify checks is there.
//! Each host gets one unit per process of its own, running the command
//! line `idmesh up` starts that process with, and a secured host gets the
//! CA's certificate and its own processes' keys, never the CA's key.
//! Without `systemd-analyze` (Debian's `systemd` package; `.ci/run`
//! installs it) the verification says so in one line and is skipped.

use idmesh_deploy::runtime::topology::Topology;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// The binary under test, copied once into this test's folder: the units
/// point at it, and it stays the one built from this tree whatever else
/// builds into the same target folder meanwhile.
fn idmesh() -> &'static Path {
    static COPY: OnceLock<PathBuf> = OnceLock::new();
    COPY.get_or_init(|| {
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("systemd-bin");
        std::fs::create_dir_all(&dir).unwrap();
        let copy = dir.join("idmesh");
        let _ = std::fs::remove_file(&copy);
        std::fs::copy(idmesh_tests::idmesh(), &copy).unwrap();
        copy
    })
}

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/examples")
}

/// A fresh folder of this test's own.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("systemd-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `idmesh up --config CONFIG --emit systemd OUT` and `extra`.
fn emit(config: &Path, out: &Path, extra: &[&str]) -> Output {
    Command::new(idmesh())
        .args(["up", "--config"])
        .arg(config)
        .args(["--emit", "systemd"])
        .arg(out)
        .args(extra)
        .output()
        .expect("idmesh runs")
}

fn said(output: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    )
}

/// Emits `config`'s units into `out` (pointing at the binary under test),
/// and checks that each host has exactly its processes' units, each
/// running what `up` would, and that they pass `systemd-analyze verify`.
fn emit_and_check(config: &Path, out: &Path) {
    let binary = idmesh().to_str().expect("a UTF-8 target folder");
    let output = emit(config, out, &["--binary", binary]);
    assert!(output.status.success(), "{}", said(&output));
    let topology = Topology::load(config).unwrap();
    let file = config.file_name().unwrap().to_str().unwrap();
    let members = topology.members();
    let mut hosts: Vec<&str> = members.iter().map(|m| m.host.as_str()).collect();
    hosts.sort();
    hosts.dedup();
    for host in hosts {
        let dir = out.join(host);
        let mut units = vec!["idmesh.target".to_string()];
        for m in members.iter().filter(|m| m.host == host) {
            let unit = format!("idmesh-{}.service", m.name);
            let text = std::fs::read_to_string(dir.join(&unit))
                .unwrap_or_else(|e| panic!("{host}: {unit}: {e}"));
            let exec = format!(
                "\nExecStart={binary} {} --config /etc/idmesh/{file} --name {}\n",
                m.role, m.name
            );
            assert!(text.contains(&exec), "{host}/{unit} lacks {exec}:\n{text}");
            units.push(unit);
        }
        if topology.web.is_some() && host == topology.coordinator.host {
            let unit = "idmesh-web.service".to_string();
            let text = std::fs::read_to_string(dir.join(&unit))
                .unwrap_or_else(|e| panic!("{host}: {unit}: {e}"));
            let exec = format!("\nExecStart={binary} web --listen ");
            assert!(text.contains(&exec), "{host}/{unit} lacks {exec}:\n{text}");
            units.push(unit);
        }
        let mut found: Vec<String> = std::fs::read_dir(&dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n != "config")
            .collect();
        found.sort();
        units.sort();
        assert_eq!(found, units, "{host}");
        assert!(dir.join("config").join(file).is_file(), "{host}: no {file}");
        verify(&dir, &units);
    }
}

/// Whether `systemd-analyze` is here; if not, says so once.
fn analyzer() -> bool {
    static HERE: OnceLock<bool> = OnceLock::new();
    *HERE.get_or_init(|| {
        let here = Command::new("systemd-analyze")
            .arg("--version")
            .output()
            .is_ok();
        if !here {
            eprintln!("skipped: systemd-analyze is not installed (Debian package systemd)");
        }
        here
    })
}

/// `systemd-analyze verify` on `units` of `dir`, found there by name, each
/// judged alone (`--recursive-errors=no`: the machine's own units, which
/// ours order themselves after, do not count): whether it succeeded, the
/// lines it said about our units (it warns, an unknown key for one, and
/// still exits 0), and all it said.
fn analyze(dir: &Path, units: &[String]) -> (bool, Vec<String>, String) {
    let output = Command::new("systemd-analyze")
        .args(["verify", "--man=no", "--recursive-errors=no"])
        .args(units.iter().map(|u| dir.join(u)))
        .env("SYSTEMD_UNIT_PATH", format!("{}:", dir.display()))
        .output()
        .expect("systemd-analyze runs");
    let text = said(&output);
    let ours: Vec<String> = text
        .lines()
        .filter(|l| l.contains("idmesh") || l.contains(&*dir.to_string_lossy()))
        .map(String::from)
        .collect();
    (output.status.success(), ours, text)
}

/// [`analyze`] must succeed and say nothing of our units; what it says of
/// the machine's own units, if anything, is shown, not held against ours.
fn verify(dir: &Path, units: &[String]) {
    if !analyzer() {
        return;
    }
    let (success, ours, text) = analyze(dir, units);
    for line in text.lines().filter(|l| !ours.iter().any(|o| o == l)) {
        eprintln!("systemd-analyze, not about our units: {line}");
    }
    assert!(
        success && ours.is_empty(),
        "systemd-analyze verify {}:\n{text}",
        dir.display()
    );
}

#[test]
fn the_lan_topologys_units_pass_systemd_analyze_verify() {
    let out = scratch("lan");
    emit_and_check(&examples().join("lan.toml"), &out);
    // The sensor's trace goes with the topology to its host, and only there.
    assert!(out.join("gateway/config/crowd.jsonl").is_file());
    assert!(!out.join("east/config/crowd.jsonl").exists());
    let hosted = std::fs::read_to_string(out.join("east/config/lan.toml")).unwrap();
    assert!(
        hosted.contains("state_dir = \"/var/lib/idmesh/state\""),
        "{hosted}"
    );
    // The check above sees a mistake: a unit with a key systemd does not
    // know (which it ignores, exiting 0) is named.
    if analyzer() {
        let unit = "idmesh-leader-0.service";
        let text = std::fs::read_to_string(out.join("east").join(unit)).unwrap();
        let bad = scratch("lan-bad");
        let text = text.replace(
            "Restart=on-failure\n",
            "Restart=on-failure\nRestartEvery=1s\n",
        );
        std::fs::write(bad.join(unit), text).unwrap();
        let (_, ours, said) = analyze(&bad, &[unit.to_string()]);
        assert!(ours.iter().any(|l| l.contains("RestartEvery")), "{said}");
    }
}

/// A topology's `[web]` gateway gets a unit of its own on the
/// coordinator's host, which runs `idmesh web` and verifies.
#[test]
fn the_web_gateway_gets_a_unit_that_verifies() {
    let dir = scratch("lan-web");
    let config = dir.join("lan.toml");
    let lan = std::fs::read_to_string(examples().join("lan.toml")).unwrap();
    let web = "\n[web]\nlisten = \"0.0.0.0:8080\"\nros2_markers = \"/idmesh/markers\"\n";
    std::fs::write(&config, lan + web).unwrap();
    std::fs::copy(examples().join("crowd.jsonl"), dir.join("crowd.jsonl")).unwrap();
    let out = dir.join("units");
    emit_and_check(&config, &out);
    let text = std::fs::read_to_string(out.join("gateway/idmesh-web.service")).unwrap();
    assert!(text.contains(" --ros2-markers /idmesh/markers "), "{text}");
}

#[test]
fn a_secured_host_gets_its_own_certificates_and_units_that_verify() {
    let dir = scratch("secure");
    let config = dir.join("secure-lan.toml");
    std::fs::copy(examples().join("secure-lan.toml"), &config).unwrap();
    std::fs::copy(examples().join("crowd.jsonl"), dir.join("crowd.jsonl")).unwrap();
    // What make-certs.sh leaves: copying is all that is done with them.
    let certs = dir.join("certs");
    std::fs::create_dir_all(&certs).unwrap();
    let topology = Topology::load(&config).unwrap();
    let names = topology.members().into_iter().map(|m| m.name);
    for name in names.chain(["ca".into(), "operator".into()]) {
        for ext in ["pem", "key"] {
            let path = certs.join(format!("{name}.{ext}"));
            std::fs::write(path, "-----BEGIN PRIVATE KEY-----\n").unwrap();
        }
    }
    let out = dir.join("units");
    emit_and_check(&config, &out);
    let held = |host: &str| -> Vec<String> {
        let mut files: Vec<String> = std::fs::read_dir(out.join(host).join("config/certs"))
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        files.sort();
        files
    };
    let east = [
        "ca.pem",
        "leader-0.key",
        "leader-0.pem",
        "leader-1.key",
        "leader-1.pem",
    ];
    assert_eq!(held("east"), east);
    let gateway = [
        "ca.pem",
        "coordinator.key",
        "coordinator.pem",
        "sensor-0.key",
        "sensor-0.pem",
    ];
    assert_eq!(held("gateway"), gateway);
    let key = std::fs::metadata(out.join("east/config/certs/leader-0.key")).unwrap();
    assert_eq!(key.permissions().mode() & 0o777, 0o600);
}

#[test]
fn bad_input_is_refused_naming_what_and_where() {
    let dir = scratch("bad");
    let lan = examples().join("lan.toml");
    let refused = |config: &Path, out: &Path, extra: &[&str], wanted: &[&str]| {
        let output = emit(config, out, extra);
        let text = said(&output);
        assert!(!output.status.success(), "{text}");
        for w in wanted {
            assert!(text.contains(w), "{w:?} not in: {text}");
        }
    };
    let out = dir.join("units");
    refused(
        &lan,
        &out,
        &["--host", "north"],
        &["lan.toml", "host \"north\"", "east, gateway, west"],
    );
    refused(
        &examples().join("topology.toml"),
        &out,
        &[],
        &["topology.toml", "no process names its host"],
    );
    // A file where a folder of DIR would go.
    let blocked = dir.join("file");
    std::fs::write(&blocked, "").unwrap();
    let east = blocked.join("east").display().to_string();
    refused(&lan, &blocked, &[], &["cannot write", &east]);
    refused(
        &lan,
        &out,
        &["--binary", "idmesh"],
        &["--binary idmesh", "absolute"],
    );
    let wrong_kind = Command::new(idmesh())
        .args(["up", "--config"])
        .arg(&lan)
        .args(["--emit", "docker"])
        .arg(&out)
        .output()
        .unwrap();
    let text = said(&wrong_kind);
    assert!(
        !wrong_kind.status.success() && text.contains("--emit docker"),
        "{text}"
    );
    assert!(!out.exists(), "a refused run wrote {}", out.display());
}
