//! Diagnostics: `tracing` events to stderr, filtered by `RUST_LOG`
//! (default `warn`), so stdout stays clean JSON Lines.

use std::io::IsTerminal;
use tracing_subscriber::EnvFilter;

/// Installs the global subscriber. An unparsable `RUST_LOG` falls back to
/// `warn` and says so.
pub fn init() {
    let (filter, bad) = match std::env::var("RUST_LOG") {
        Ok(spec) if !spec.is_empty() => match EnvFilter::try_new(&spec) {
            Ok(filter) => (filter, None),
            Err(e) => (EnvFilter::new("warn"), Some((spec, e))),
        },
        _ => (EnvFilter::new("warn"), None),
    };
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .init();
    if let Some((spec, error)) = bad {
        tracing::warn!("ignoring RUST_LOG={spec:?} ({error}); logging warnings only");
    }
}
