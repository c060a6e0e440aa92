//! Trace types inside a binary (postcard) record: written as their JSON
//! text. The trace format leaves absent fields out of its JSON
//! (`skip_serializing_if`), which a format without field names cannot
//! read back; `#[serde(with = "idmesh_protocol::trace::as_json")]` on a
//! field that holds them (a sensor's snapshot keeps its stream's header)
//! writes the JSON the trace format reads.

use serde::de::DeserializeOwned;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

pub fn serialize<T: Serialize, S: Serializer>(value: &T, s: S) -> Result<S::Ok, S::Error> {
    let text = serde_json::to_string(value).map_err(serde::ser::Error::custom)?;
    s.serialize_str(&text)
}

pub fn deserialize<'de, T: DeserializeOwned, D: Deserializer<'de>>(d: D) -> Result<T, D::Error> {
    let text = String::deserialize(d)?;
    serde_json::from_str(&text).map_err(serde::de::Error::custom)
}
