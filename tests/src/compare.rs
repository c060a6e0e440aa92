//! What the process tests compare: marginals in a JSON answer against the
//! centralized engine's.

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
