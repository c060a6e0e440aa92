//! Diagnostics: `tracing` events to stderr, filtered by `RUST_LOG`
//! (default [`DEFAULT_FILTER`]), so stdout stays clean JSON Lines; and
//! Zenoh's errors to the watcher of a session that drops what its peers
//! send (`idmesh_deploy::runtime::routing_loss`).

use idmesh_deploy::runtime::routing_loss;
use std::io::IsTerminal;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{EnvFilter, Layer};

/// Our warnings, and Zenoh's errors only: Zenoh warns about things a user
/// cannot act on (scouting delays, every failed reconnection of a link that
/// idmesh already reports in its own words). Directive targets match by
/// prefix, so `zenoh` covers every `zenoh_*` crate. Its channel handlers
/// report, as errors, samples that arrive for a subscriber being dropped:
/// the ordinary end of a process, so they are off. `RUST_LOG` replaces the
/// whole filter, Zenoh's part included.
pub const DEFAULT_FILTER: &str = "warn,zenoh=error,zenoh::api::handlers=off";

/// Installs the global subscriber. An unparsable `RUST_LOG` falls back to
/// the default and says so.
pub fn init() {
    let (filter, bad) = match std::env::var("RUST_LOG") {
        Ok(spec) if !spec.is_empty() => match EnvFilter::try_new(&spec) {
            Ok(filter) => (filter, None),
            Err(e) => (EnvFilter::new(DEFAULT_FILTER), Some((spec, e))),
        },
        _ => (EnvFilter::new(DEFAULT_FILTER), None),
    };
    let log = tracing_subscriber::fmt::layer()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_filter(filter);
    // Beside the log's filter: Zenoh's errors reach the watcher of a
    // session that lost its peers' key expressions whatever `RUST_LOG`
    // says.
    tracing_subscriber::registry()
        .with(log)
        .with(routing_loss::layer())
        .init();
    if let Some((spec, error)) = bad {
        tracing::warn!("ignoring RUST_LOG={spec:?} ({error}); using {DEFAULT_FILTER:?}");
    }
}
