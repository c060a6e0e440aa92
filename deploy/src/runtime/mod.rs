//! The distributed runtime's side of the binary: the topology file, the
//! one function that opens a Zenoh session, one runner per role, the
//! launcher (`up`, `demo`) and the query client.

pub mod launch;
pub mod mesh;
pub mod query;
pub mod roles;
pub mod topology;
