//! docs/identity-calibration.md carries the stamp of the code as it is:
//! any change to the identity engine or to the `identity_calibration`
//! example changes the digest (build.rs), and the committed file must then
//! be regenerated.

#[test]
fn the_committed_calibration_was_generated_by_the_code_as_it_is() {
    let stamp = format!(
        "<!-- idmesh identity calibration stamp: sources {} -->",
        env!("IDMESH_IDENTITY_CALIBRATION_STAMP")
    );
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../docs/identity-calibration.md"
    );
    let committed = std::fs::read_to_string(path).unwrap_or_default();
    assert!(
        committed.contains(&stamp),
        "docs/identity-calibration.md is stale: it does not carry {stamp:?}; regenerate it \
         with `cargo run --release -p idmesh-identity --example identity_calibration`"
    );
}
