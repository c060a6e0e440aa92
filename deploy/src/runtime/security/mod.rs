//! Securing a deployment: mutual TLS between every process and Zenoh access
//! control generated from the topology.
//!
//! With a `[security]` section in the topology, every link is TLS and both
//! ends show a certificate signed by the deployment's CA; a certificate's
//! common name is the process name (or a client's name) and is what the
//! access rules are written against. The rules let each process do what its
//! role needs and nothing else: only the listed sensor may put events, only
//! a leader may serve leader keys, the coordinator asks the leaders and the
//! sensor, clients may only ask `P/query/**`.
//!
//! [`section`] is the topology's `[security]` section, [`tls`] a process's
//! certificate files and its endpoints, [`rules`] the access-control config
//! generated from the topology.

pub(crate) mod error;
pub(crate) mod rules;
pub(crate) mod section;
pub(crate) mod tls;

pub use section::SecuritySection;
pub use tls::Tls;
