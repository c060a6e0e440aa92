//! What the valid-stream tests of the identity beliefs share.

#![allow(dead_code)] // each test file uses its own part

/// The partners and swap probabilities of the property beliefs' valid
/// streams (idmesh-belief's `tests/common/valid.rs`): identity streams mix
/// the same way.
#[path = "../../../belief/tests/common/valid.rs"]
pub mod drawn;
pub mod valid;
