//! Diagnostics: `tracing` events to stderr, filtered by `RUST_LOG`
//! (default [`DEFAULT_FILTER`]), so stdout stays clean JSON Lines.

use std::io::IsTerminal;
use tracing_subscriber::EnvFilter;

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
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .init();
    if let Some((spec, error)) = bad {
        tracing::warn!("ignoring RUST_LOG={spec:?} ({error}); using {DEFAULT_FILTER:?}");
    }
}
