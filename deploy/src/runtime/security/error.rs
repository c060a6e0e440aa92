//! What can be wrong with a secured setup, each error naming the file or
//! the field to fix.

use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum SecurityError {
    #[error("{field}: cannot read {path}: {source}", path = path.display())]
    Unreadable {
        /// Where the path came from, e.g. `[security] certs (CA certificate)`.
        field: String,
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{field}: {path} is not PEM (no \"-----BEGIN\" line)", path = path.display())]
    NotPem { field: String, path: PathBuf },
    #[error("endpoint {endpoint:?}: a secured deployment names tcp/host:port endpoints (reached as quic/host:port, mutual TLS over QUIC) or quic/ ones; not tls/, whose Zenoh link is unsound (eclipse-zenoh/zenoh#2557)")]
    Endpoint { endpoint: String },
    #[error("TLS needs --ca, --cert and --key together; {missing} is missing")]
    Incomplete { missing: &'static str },
    #[error("[security] clients, producers: {name:?} is also a process of the topology; give clients and producers names of their own")]
    ClientIsMember { name: String },
    #[error("[security] clients, producers: an empty name")]
    EmptyClient,
}
