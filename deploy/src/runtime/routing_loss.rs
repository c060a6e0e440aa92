//! A Zenoh session that has lost the key expressions a peer declared to
//! it, watched for from Zenoh's own error events, and the process ended
//! so that a new session replaces it.
//!
//! A peer may name a key expression by a number it declared on the link
//! before (a *scope*); a session that does not know the number drops the
//! message and logs `Route query with unknown scope N!` (or `Route data
//! …`). In the ten-minute nemesis, after cut-offs and slow links, a leader
//! process logged that for every query the coordinators sent it, several
//! a second, for over two minutes: its role's token stayed up, so nothing
//! took the role over, and every answer of the deployment said the leader
//! did not answer. The session does not recover by itself; a new one
//! does, since its peers declare everything again to a new face.
//!
//! So every process of a deployment watches for those events ([`layer`],
//! installed beside the log's own filter, so that `RUST_LOG` cannot hide
//! them from it). Once they have gone on for [`PERSISTENCE`], with no gap
//! longer than [`GAP`], the process stops its role as on a signal
//! ([`lost`] ends, and `roles::shutdown` with it) and exits with an error
//! ([`check`]); `idmesh up` starts it again with a new session, and the
//! role comes back from its journal, as after a kill. A process whose stop
//! hangs on the broken session is ended after [`HARD_EXIT_AFTER`].
//! A burst while links reconnect (a few messages, well under the
//! persistence) ends nothing.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Metadata, Subscriber};
use tracing_subscriber::layer::{Context, Filter, Layer};

/// How long the losses must go on before the process ends.
pub const PERSISTENCE: Duration = Duration::from_secs(10);

/// A longer silence between two losses starts the count again.
pub const GAP: Duration = Duration::from_secs(5);

/// How long a process may take to stop once the session is given up.
const HARD_EXIT_AFTER: Duration = Duration::from_secs(10);

/// The run of losses seen so far: a pure machine of the times they came.
#[derive(Debug, Default, Clone)]
pub struct Run {
    first: Option<Instant>,
    last: Option<Instant>,
    count: u64,
}

impl Run {
    /// A loss seen at `now`: whether the run has now gone on for
    /// `persistence`, with no gap longer than `gap`.
    pub fn seen(&mut self, now: Instant, persistence: Duration, gap: Duration) -> bool {
        match self.last {
            Some(last) if now.saturating_duration_since(last) <= gap => {}
            _ => {
                self.first = Some(now);
                self.count = 0;
            }
        }
        self.last = Some(now);
        self.count += 1;
        self.first
            .is_some_and(|first| now.saturating_duration_since(first) >= persistence)
    }

    /// How many losses the current run holds.
    pub fn count(&self) -> u64 {
        self.count
    }
}

/// What the process knows of its session's losses.
struct Watch {
    run: Mutex<Run>,
    tripped: AtomicBool,
    notify: tokio::sync::Notify,
}

fn watch() -> &'static Watch {
    static WATCH: OnceLock<Watch> = OnceLock::new();
    WATCH.get_or_init(|| Watch {
        run: Mutex::new(Run::default()),
        tripped: AtomicBool::new(false),
        notify: tokio::sync::Notify::new(),
    })
}

/// Reads an event's message.
struct Message(String);

impl Visit for Message {
    fn record_str(&mut self, field: &Field, value: &str) {
        if field.name() == "message" {
            self.0.push_str(value);
        }
    }

    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            self.0.push_str(&format!("{value:?}"));
        }
    }
}

/// The layer that watches Zenoh's errors (see the module documentation).
pub struct Watcher;

/// Only Zenoh's errors reach the watcher, whatever the log's filter.
pub struct ZenohErrors;

impl<S> Filter<S> for ZenohErrors {
    fn enabled(&self, metadata: &Metadata<'_>, _: &Context<'_, S>) -> bool {
        *metadata.level() == Level::ERROR && metadata.target().starts_with("zenoh")
    }

    fn max_level_hint(&self) -> Option<tracing::level_filters::LevelFilter> {
        Some(tracing::level_filters::LevelFilter::ERROR)
    }
}

impl<S: Subscriber> Layer<S> for Watcher {
    // Only Zenoh's errors come here ([`ZenohErrors`], in [`layer`]).
    fn on_event(&self, event: &Event<'_>, _: Context<'_, S>) {
        let mut message = Message(String::new());
        event.record(&mut message);
        if !message.0.contains("with unknown scope") {
            return;
        }
        let watch = watch();
        let (tripped, count) = match watch.run.lock() {
            Ok(mut run) => (run.seen(Instant::now(), PERSISTENCE, GAP), run.count()),
            Err(_) => return,
        };
        if tripped && !watch.tripped.swap(true, Ordering::SeqCst) {
            eprintln!(
                "idmesh: the zenoh session has dropped messages naming key expressions it does \
                 not know ({count} in {PERSISTENCE:?} or more); stopping this process, to be \
                 started again with a new session"
            );
            watch.notify.notify_waiters();
            std::thread::spawn(|| {
                std::thread::sleep(HARD_EXIT_AFTER);
                eprintln!("idmesh: the process did not stop in {HARD_EXIT_AFTER:?}; exiting");
                std::process::exit(1);
            });
        }
    }
}

/// The watcher, filtered to Zenoh's errors, for the global subscriber.
pub fn layer<S>() -> tracing_subscriber::filter::Filtered<Watcher, ZenohErrors, S>
where
    S: Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
{
    Watcher.with_filter(ZenohErrors)
}

/// Ends once the session has been given up (never, while it is sound).
pub async fn lost() {
    let watch = watch();
    loop {
        let notified = watch.notify.notified();
        if watch.tripped.load(Ordering::SeqCst) {
            return;
        }
        notified.await;
    }
}

/// After a role stopped: an error if it stopped because the session was
/// given up, so that the process's supervisor starts it again.
pub fn check() -> anyhow::Result<()> {
    match watch().tripped.load(Ordering::SeqCst) {
        true => Err(anyhow::anyhow!(
            "stopped: the zenoh session dropped messages naming key expressions it does not \
             know (\"unknown scope\") for {PERSISTENCE:?}; to be started again with a new session"
        )),
        false => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: Duration = Duration::from_secs(10);
    const G: Duration = Duration::from_secs(5);

    /// Losses every second trip the run after ten seconds; a burst, or
    /// losses with longer gaps between them, never do.
    #[test]
    fn only_losses_that_go_on_end_the_process() {
        let start = Instant::now();
        let at = |s: u64| start + Duration::from_secs(s);
        let mut run = Run::default();
        assert!((0..10).all(|s| !run.seen(at(s), P, G)));
        assert!(run.seen(at(10), P, G));

        let mut burst = Run::default();
        assert!((0..50).all(|_| !burst.seen(at(1), P, G)));

        let mut sparse = Run::default();
        assert!((0..10).all(|k| !sparse.seen(at(6 * k), P, G)));
        assert_eq!(sparse.count(), 1);
    }

    /// The watcher takes Zenoh's "unknown scope" errors and nothing else.
    #[test]
    fn the_watcher_counts_only_zenohs_unknown_scope_errors() {
        use tracing_subscriber::layer::SubscriberExt;
        let subscriber = tracing_subscriber::registry().with(layer());
        tracing::subscriber::with_default(subscriber, || {
            tracing::error!(target: "zenoh::net::routing::dispatcher::queries",
                "north/cf023344:11:1245 Route query with unknown scope 1! Send final reply.");
            tracing::error!(target: "zenoh::net::routing", "something else");
            tracing::warn!(target: "zenoh::net::routing", "Route data with unknown scope 1!");
            tracing::error!(target: "idmesh_leader", "Route data with unknown scope 1!");
        });
        let count = watch().run.lock().map(|r| r.count()).unwrap_or(0);
        assert_eq!(count, 1);
        assert!(check().is_ok());
    }
}
