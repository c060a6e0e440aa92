//! The distributed runtime's side of the binary: the topology file, the
//! one function that opens a Zenoh session, one runner per role, the
//! launcher (`up`, `demo`), the loopback topology they and the bench use,
//! the one picker of free ports, the query client, the web gateway's
//! session (`web`), what secures a deployment (TLS, access control), and
//! the systemd units that run a topology's processes in `up`'s place.

pub mod launch;
pub mod loopback;
pub mod mesh;
pub mod ports;
pub mod query;
pub mod roles;
pub mod routing_loss;
pub mod security;
mod supervise;
pub mod systemd;
pub mod topology;
mod twin;
pub mod web;
