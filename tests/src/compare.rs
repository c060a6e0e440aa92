//! What the process tests compare: marginals in a JSON answer against the
//! centralized engine's.

use idmesh_identity::{IdentityRow, SparseMarginals};
use serde_json::Value;

/// The numbers of a JSON array.
pub fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("an array: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap_or_else(|| panic!("a number: {x}")))
        .collect()
}

/// An answer's `p_red` equals `expected` to 1e-9, track by track.
pub fn assert_same_marginals(got: &Value, expected: &[f64], what: &str) {
    let got = floats(&got["p_red"]);
    assert_eq!(got.len(), expected.len(), "{what}: number of tracks");
    for (t, (g, e)) in got.iter().zip(expected).enumerate() {
        assert!((g - e).abs() < 1e-9, "{what}, track {t}: {g} vs {e}");
    }
}

/// An answer's `p_identity` (rows of [`IdentityRow`]) as its dense n × n
/// matrix, checked as the engine checks its own.
pub fn identity_matrix(v: &Value) -> Vec<Vec<f64>> {
    identity_marginals(v).dense()
}

/// An answer's `p_identity` as the engine's [`SparseMarginals`].
pub fn identity_marginals(v: &Value) -> SparseMarginals {
    let rows: Vec<IdentityRow> =
        serde_json::from_value(v.clone()).unwrap_or_else(|e| panic!("identity rows ({e}): {v}"));
    SparseMarginals::new(rows).unwrap_or_else(|e| panic!("identity rows: {e}"))
}

/// The largest difference between two answers' `p_identity`, entry by
/// entry (∞ when their sizes differ).
pub fn identity_difference(a: &Value, b: &Value) -> f64 {
    identity_marginals(a).max_abs_difference(&identity_marginals(b))
}

/// One track's `p_identity` row of a per-track answer, over n identities.
pub fn identity_row(v: &Value, n: usize) -> Vec<f64> {
    let row: IdentityRow =
        serde_json::from_value(v.clone()).unwrap_or_else(|e| panic!("an identity row ({e}): {v}"));
    row.dense(n)
}
