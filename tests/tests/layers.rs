//! The folder tree tells the truth about what may use what: each top-level
//! folder is a layer, and a crate never depends on a crate whose folder
//! sits in a layer above its own folder's layer (the picture is in
//! docs/design/architecture.md, "Layers").
//!
//! The workspace's members are read from the root Cargo.toml, and each
//! member's `idmesh-*` entries of `[dependencies]`, `[build-dependencies]`
//! and `[dev-dependencies]` (target-specific ones too) from its own. A
//! dependency on a higher layer fails the test, naming the crate, the
//! dependency and both layers; so does a member in a top-level folder the
//! table below does not know, which must be given a layer first.

use std::collections::BTreeMap;
use std::path::Path;

/// The layers, bottom to top, by top-level folder: the table the
/// architecture page draws.
const LAYERS: &[(&str, usize, &str)] = &[
    ("protocol", 0, "the wire"),
    ("belief", 1, "the engines"),
    ("identity", 1, "the engines"),
    ("world", 2, "events, placement, evaluation"),
    ("placement", 2, "events, placement, evaluation"),
    ("eval", 2, "events, placement, evaluation"),
    ("sensor", 3, "the roles"),
    ("leader", 3, "the roles"),
    ("coordinator", 3, "the roles"),
    ("voter", 3, "the roles"),
    ("deploy", 4, "the binary"),
    ("tests", 5, "the tests"),
];

/// The dependency tables of a manifest this test reads.
const SECTIONS: &[&str] = &["dependencies", "build-dependencies", "dev-dependencies"];

/// A workspace member: its package name, its folder (from the workspace
/// root) and the `idmesh-*` packages it depends on, with the section each
/// is listed in.
#[derive(Debug, Clone)]
struct Member {
    name: String,
    folder: String,
    uses: Vec<(String, String)>,
}

/// Where a folder sits: its layer and the layer's name, or `None` when
/// the table does not know its top-level folder.
fn layer_of(folder: &str) -> Option<(usize, &'static str)> {
    let top = folder.split('/').next().unwrap_or(folder);
    LAYERS
        .iter()
        .find(|(name, _, _)| *name == top)
        .map(|&(_, layer, what)| (layer, what))
}

/// What is wrong with these members, one line each: a member in a folder
/// without a layer, a dependency on a package that is not a member, a
/// dependency on a crate in a higher layer.
fn violations(members: &[Member]) -> Vec<String> {
    let folders: BTreeMap<&str, &str> = members
        .iter()
        .map(|m| (m.name.as_str(), m.folder.as_str()))
        .collect();
    let mut wrong = Vec::new();
    for member in members {
        let Some((layer, what)) = layer_of(&member.folder) else {
            wrong.push(format!(
                "{} sits in {}/, a folder without a layer: give its top-level folder a \
                 layer in tests/tests/layers.rs and docs/design/architecture.md",
                member.name, member.folder
            ));
            continue;
        };
        for (section, used) in &member.uses {
            let Some(used_folder) = folders.get(used.as_str()) else {
                wrong.push(format!(
                    "{} ({}/) lists {used} in [{section}], which is not a workspace member",
                    member.name, member.folder
                ));
                continue;
            };
            // A member without a layer is reported above, once.
            let Some((used_layer, used_what)) = layer_of(used_folder) else {
                continue;
            };
            if used_layer > layer {
                wrong.push(format!(
                    "{} ({}/, layer {layer}: {what}) depends on {used} ({used_folder}/, \
                     layer {used_layer}: {used_what}) in [{section}]: a crate may depend \
                     only on crates of its own layer or below",
                    member.name, member.folder
                ));
            }
        }
    }
    wrong
}

fn parse(path: &Path) -> toml::Table {
    let text = std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: cannot read: {e}", path.display()));
    text.parse()
        .unwrap_or_else(|e| panic!("{}: not TOML: {e}", path.display()))
}

/// The `idmesh-*` packages a dependency table lists, by package name
/// (`package = "…"` when an entry renames one).
fn idmesh_uses(table: Option<&toml::Value>, section: &str, uses: &mut Vec<(String, String)>) {
    let Some(table) = table.and_then(toml::Value::as_table) else {
        return;
    };
    for (key, entry) in table {
        let package = entry
            .get("package")
            .and_then(toml::Value::as_str)
            .unwrap_or(key.as_str());
        if package.starts_with("idmesh-") {
            uses.push((section.to_string(), package.to_string()));
        }
    }
}

/// The workspace's members as its manifests describe them.
fn read_workspace(root: &Path) -> Vec<Member> {
    let manifest = parse(&root.join("Cargo.toml"));
    let members = manifest
        .get("workspace")
        .and_then(|w| w.get("members"))
        .and_then(toml::Value::as_array)
        .expect("the root Cargo.toml lists [workspace] members");
    members
        .iter()
        .map(|folder| {
            let folder = folder.as_str().expect("a member is a folder name");
            let manifest = parse(&root.join(folder).join("Cargo.toml"));
            let name = manifest
                .get("package")
                .and_then(|p| p.get("name"))
                .and_then(toml::Value::as_str)
                .unwrap_or_else(|| panic!("{folder}/Cargo.toml names no package"))
                .to_string();
            let mut uses = Vec::new();
            for section in SECTIONS {
                idmesh_uses(manifest.get(*section), section, &mut uses);
            }
            let targets = manifest.get("target").and_then(toml::Value::as_table);
            for (cfg, target) in targets.into_iter().flatten() {
                for section in SECTIONS {
                    idmesh_uses(
                        target.get(*section),
                        &format!("target.'{cfg}'.{section}"),
                        &mut uses,
                    );
                }
            }
            Member {
                name,
                folder: folder.trim_end_matches('/').to_string(),
                uses,
            }
        })
        .collect()
}

fn workspace_root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

#[test]
fn no_crate_depends_on_a_higher_layer() {
    let members = read_workspace(workspace_root());
    assert!(
        members.len() >= LAYERS.len(),
        "only {} members read: {members:?}",
        members.len()
    );
    let wrong = violations(&members);
    assert!(
        wrong.is_empty(),
        "the layers are broken:\n{}",
        wrong.join("\n")
    );
}

/// The founding folders and every layer's folder exist, and the
/// architecture page shows each folder the table knows.
#[test]
fn the_table_is_the_one_the_docs_show() {
    let root = workspace_root();
    for founding in [
        "Cargo.toml",
        "README.md",
        "protocol",
        "belief",
        "sensor",
        "leader",
        "coordinator",
        "deploy",
        "tests",
    ] {
        assert!(root.join(founding).exists(), "{founding} is gone");
    }
    let page = std::fs::read_to_string(root.join("docs/design/architecture.md")).unwrap();
    let layers = page
        .split("\n## Layers")
        .nth(1)
        .expect("docs/design/architecture.md has a \"## Layers\" section");
    let layers = layers.split("\n## ").next().unwrap_or(layers);
    for (folder, layer, _) in LAYERS {
        assert!(root.join(folder).is_dir(), "{folder}/ is not a folder");
        assert!(
            layers.contains(&format!("{folder}/")),
            "the architecture page's layers do not show {folder}/ (layer {layer})"
        );
    }
}

fn member(name: &str, folder: &str, uses: &[&str]) -> Member {
    Member {
        name: name.to_string(),
        folder: folder.to_string(),
        uses: uses
            .iter()
            .map(|used| ("dependencies".to_string(), used.to_string()))
            .collect(),
    }
}

/// The check can fail: a crate reaching up is named, with its dependency
/// and both layers; one reaching down or across its layer is not.
#[test]
fn a_crate_reaching_up_is_named() {
    let members = [
        member("idmesh-protocol", "protocol", &[]),
        member("idmesh-belief", "belief", &["idmesh-protocol"]),
        member("idmesh-identity", "identity", &["idmesh-belief"]),
        member("idmesh-placement", "protocol/placement", &["idmesh-belief"]),
        member("idmesh-sensor", "sensor", &["idmesh-placement"]),
    ];
    let wrong = violations(&members);
    assert_eq!(wrong.len(), 1, "{wrong:#?}");
    for part in [
        "idmesh-placement (protocol/placement/, layer 0: the wire)",
        "depends on idmesh-belief (belief/, layer 1: the engines)",
        "[dependencies]",
    ] {
        assert!(
            wrong[0].contains(part),
            "{:?} does not say {part:?}",
            wrong[0]
        );
    }
}

/// A member in a folder the table does not know is named; so is a
/// dependency on a package outside the workspace's members.
#[test]
fn an_unknown_folder_or_package_is_named() {
    let members = [
        member("idmesh-protocol", "protocol", &[]),
        member("idmesh-gadget", "gadgets/gadget", &["idmesh-protocol"]),
        member("idmesh-leader", "leader", &["idmesh-gone"]),
    ];
    let wrong = violations(&members);
    assert_eq!(wrong.len(), 2, "{wrong:#?}");
    assert!(
        wrong[0].contains("idmesh-gadget sits in gadgets/gadget/, a folder without a layer"),
        "{}",
        wrong[0]
    );
    assert!(
        wrong[1].contains("lists idmesh-gone in [dependencies], which is not a workspace member"),
        "{}",
        wrong[1]
    );
}
