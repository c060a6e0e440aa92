//! The recent past of what the live map's charts plot — the stream's
//! events per second and the latency of a marginals query — kept by the
//! gateway, so that a page opened late in a stream or between two streams
//! starts with the last few minutes rather than with empty charts.
//!
//! A background task asks `query/positions` (the sensors' event counts:
//! no leader is asked, nothing global is computed) every [`SAMPLE_EVERY`]
//! for as long as the gateway serves (whether or not a page is open: the
//! past is wanted exactly when nobody was looking) and keeps the last
//! [`CAPACITY`] samples in a ring buffer, a bounded memory whatever the
//! uptime. The latency is that of the last marginals question someone
//! asked through the gateway in that second (none asked: null), so that
//! keeping the history never makes the leaders work.
//! `GET /history` serves them as JSON:
//!
//! ```text
//! {"every_ms":1000,"capacity":300,"now_ms":…,
//!  "samples":[{"at_ms":…,"events":…,"rate":…,"latency_ms":…},…]}
//! ```
//!
//! `at_ms` and `now_ms` are the gateway's clock (milliseconds since the
//! Unix epoch), so a page on another machine can shift them onto its own.
//! A look the coordinator did not answer leaves `events` and `rate` null:
//! a gap in the charts. `rate` is null too at the
//! first answer after a gap and when the watermark went back (a new
//! stream began).

use crate::asker::Asker;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// How often the gateway asks for the watermark.
pub(crate) const SAMPLE_EVERY: Duration = Duration::from_secs(1);

/// Samples kept: five minutes at one a second.
pub(crate) const CAPACITY: usize = 300;

/// One look at the deployment.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub(crate) struct Sample {
    pub at_ms: u64,
    /// Events in the answer's watermark.
    pub events: Option<u64>,
    /// Events per second since the sample before.
    pub rate: Option<f64>,
    /// How long the gateway waited for the answer.
    pub latency_ms: Option<f64>,
}

/// What `/history` answers.
#[derive(Debug, Serialize)]
struct Served<'a> {
    every_ms: u64,
    capacity: usize,
    now_ms: u64,
    samples: &'a VecDeque<Sample>,
}

/// The ring buffer of samples, and the last answer the next rate is
/// measured from.
#[derive(Debug)]
pub(crate) struct History {
    capacity: usize,
    inner: Mutex<Ring>,
}

#[derive(Debug, Default)]
struct Ring {
    samples: VecDeque<Sample>,
    /// When the last sample was answered, and its events (None after a
    /// question nobody answered).
    last: Option<(Instant, u64)>,
}

/// The one field of a positions answer the history needs.
#[derive(Deserialize)]
struct Watermarked {
    watermark: BTreeMap<String, u64>,
}

impl History {
    pub(crate) fn new(capacity: usize) -> Self {
        History {
            capacity: capacity.max(1),
            inner: Mutex::new(Ring::default()),
        }
    }

    fn ring(&self) -> std::sync::MutexGuard<'_, Ring> {
        // A panic elsewhere while the lock was held leaves a ring that is
        // still a ring: keep serving it.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Records one look taken `at` (`at_ms` on the wall clock): the
    /// events when the coordinator answered, and the latency of the last
    /// marginals question asked since the look before.
    pub(crate) fn record(
        &self,
        at: Instant,
        at_ms: u64,
        answered: Option<u64>,
        latency_ms: Option<f64>,
    ) {
        let mut ring = self.ring();
        let rate = match (ring.last, answered) {
            (Some((then, before)), Some(events)) if events >= before && at > then => {
                Some((events - before) as f64 / (at - then).as_secs_f64())
            }
            _ => None,
        };
        ring.last = answered.map(|events| (at, events));
        if ring.samples.len() == self.capacity {
            ring.samples.pop_front();
        }
        ring.samples.push_back(Sample {
            at_ms,
            events: answered,
            rate,
            latency_ms,
        });
    }

    /// The JSON `/history` serves.
    pub(crate) fn to_json(&self) -> Vec<u8> {
        let ring = self.ring();
        serde_json::to_vec(&Served {
            every_ms: SAMPLE_EVERY.as_millis() as u64,
            capacity: self.capacity,
            now_ms: now_ms(),
            samples: &ring.samples,
        })
        .unwrap_or_default()
    }
}

fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// Asks for the watermark every [`SAMPLE_EVERY`], for ever (the caller
/// aborts the task when the gateway stops).
pub(crate) async fn sample(asker: Arc<Asker>, history: Arc<History>) {
    let selector = asker.keys.query_positions();
    let mut ticks = tokio::time::interval(SAMPLE_EVERY);
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        ticks.tick().await;
        let (at, at_ms) = (Instant::now(), now_ms());
        let answer = asker.ask(&selector, "positions").await;
        let answered = match answer.error() {
            Some(error) => {
                tracing::debug!(%error, "no sample of the watermark");
                None
            }
            None => match serde_json::from_slice::<Watermarked>(&answer.body) {
                Ok(w) => Some(w.watermark.values().sum()),
                Err(error) => {
                    tracing::warn!(%error, "a positions answer without a watermark");
                    None
                }
            },
        };
        let latency = asker.take_marginals_latency();
        history.record(at, at_ms, answered, latency.map(|d| d.as_secs_f64() * 1e3));
    }
}

/// `GET /history`.
pub(crate) async fn history(State(history): State<Arc<History>>) -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        history.to_json(),
    )
        .into_response()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_are_measured_between_answers_and_not_across_gaps_or_streams() {
        let history = History::new(10);
        let t0 = Instant::now();
        let at = |s: u64| t0 + Duration::from_secs(s);
        history.record(at(0), 0, Some(100), Some(2.0));
        history.record(at(1), 1000, Some(400), Some(3.0));
        history.record(at(2), 2000, None, None);
        history.record(at(3), 3000, Some(900), Some(2.5));
        history.record(at(5), 5000, Some(1100), Some(2.5));
        // A new stream: the watermark starts again from zero.
        history.record(at(6), 6000, Some(50), Some(1.0));
        let ring = history.ring();
        let rates: Vec<Option<f64>> = ring.samples.iter().map(|s| s.rate).collect();
        assert_eq!(
            rates,
            vec![None, Some(300.0), None, None, Some(100.0), None]
        );
        assert_eq!(ring.samples[2].latency_ms, None);
        assert_eq!(ring.samples[3].events, Some(900));
    }

    #[test]
    fn the_ring_keeps_the_last_samples_only() {
        let history = History::new(3);
        let t0 = Instant::now();
        for s in 0..7u64 {
            history.record(t0 + Duration::from_secs(s), s * 1000, Some(s * 10), None);
        }
        let served: serde_json::Value = serde_json::from_slice(&history.to_json()).unwrap();
        let at: Vec<u64> = served["samples"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s["at_ms"].as_u64().unwrap())
            .collect();
        assert_eq!(at, vec![4000, 5000, 6000]);
        assert_eq!(served["capacity"], 3);
        assert_eq!(served["every_ms"], SAMPLE_EVERY.as_millis() as u64);
        assert_eq!(served["samples"][2]["rate"], 10.0);
    }
}
