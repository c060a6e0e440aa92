//! One get to the deployment's query API, timed, and what its outcome
//! means in HTTP. The coordinator answers a question it cannot answer with
//! an error reply `{"error":"…"}`; the gateway passes that body on as it
//! came and picks the status from what kind of failure it names:
//!
//! | coordinator's error | status |
//! |---|---|
//! | `degraded: …`, no sensor, no leader | 503 Service Unavailable |
//! | anything else it refused (a bad parameter, a track out of range, a point already passed, identities asked of a property stream) | 400 Bad Request |
//! | no reply at all (coordinator down, not connected) | 502 Bad Gateway |
//! | no reply within the timeout | 504 Gateway Timeout |

use idmesh_protocol::wire::keys::Keys;
use idmesh_protocol::wire::query::QueryError;
use prometheus_client::metrics::family::Family;
use prometheus_client::metrics::histogram::{exponential_buckets, Histogram};
use std::time::{Duration, Instant};
use zenoh::Session;

/// A query's labels in the latency histograms: which question, and
/// whether it was answered.
pub(crate) type QueryLabels = Vec<(String, String)>;
pub(crate) type LatencyFamily = Family<QueryLabels, Histogram, fn() -> Histogram>;

/// The answer to one get: an HTTP status and the JSON body.
#[derive(Debug, Clone)]
pub struct Answer {
    pub status: u16,
    pub body: Vec<u8>,
    pub took: Duration,
}

impl Answer {
    pub(crate) fn ok(&self) -> bool {
        self.status == 200
    }

    /// The error message of a failed answer.
    pub(crate) fn error(&self) -> Option<String> {
        (!self.ok()).then(|| {
            serde_json::from_slice::<QueryError>(&self.body)
                .map(|e| e.error)
                .unwrap_or_else(|_| String::from_utf8_lossy(&self.body).into_owned())
        })
    }
}

/// The gateway's Zenoh client side.
pub(crate) struct Asker {
    pub session: Session,
    pub keys: Keys,
    pub timeout: Duration,
    /// Seconds per get, by question and outcome (`/metrics`).
    pub latency: LatencyFamily,
    /// The latency of the last marginals question answered since the
    /// history last took it (the charts' latency is that of questions
    /// someone asked, never of one asked only to draw it).
    answered_marginals: std::sync::Mutex<Option<Duration>>,
}

/// The latency family with every question's answered series present.
pub(crate) fn latency_family() -> LatencyFamily {
    let family = Family::new_with_constructor(latency_histogram as fn() -> Histogram);
    for question in QUESTIONS {
        drop(family.get_or_create(&query_labels(question, "ok")));
    }
    family
}

fn latency_histogram() -> Histogram {
    // 0.25 ms to 8 s.
    Histogram::new(exponential_buckets(0.000_25, 2.0, 16))
}

/// The questions of the query API, whose answered latencies are there from
/// the first scrape (zero until asked): a series that appears only once
/// something happened cannot be told from one that was never scraped, and
/// an empty family is more than some parsers accept.
pub(crate) const QUESTIONS: [&str; 5] = ["marginals", "track", "identity", "positions", "stats"];

/// A latency histogram's labels.
pub(crate) fn query_labels(what: &str, outcome: &str) -> QueryLabels {
    vec![
        ("query".to_string(), what.to_string()),
        ("outcome".to_string(), outcome.to_string()),
    ]
}

impl Asker {
    pub(crate) fn new(session: Session, keys: Keys, timeout: Duration) -> Self {
        Asker {
            session,
            keys,
            timeout,
            latency: latency_family(),
            answered_marginals: std::sync::Mutex::new(None),
        }
    }

    /// The latency of the last marginals question answered since the
    /// last call, if any.
    pub(crate) fn take_marginals_latency(&self) -> Option<Duration> {
        self.answered_marginals
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take()
    }

    /// Asks `selector` (a key under the prefix, with `?parameters`); `what`
    /// names the question in the latency histograms.
    pub(crate) async fn ask(&self, selector: &str, what: &str) -> Answer {
        let started = Instant::now();
        let (status, body) = self.get(selector).await;
        let took = started.elapsed();
        let outcome = if status == 200 { "ok" } else { "error" };
        if status == 200 && what == "marginals" {
            *self
                .answered_marginals
                .lock()
                .unwrap_or_else(|e| e.into_inner()) = Some(took);
        }
        self.latency
            .get_or_create(&query_labels(what, outcome))
            .observe(took.as_secs_f64());
        Answer { status, body, took }
    }

    async fn get(&self, selector: &str) -> (u16, Vec<u8>) {
        let replies = match self.session.get(selector).timeout(self.timeout).await {
            Ok(replies) => replies,
            Err(e) => return (502, error_body(&format!("cannot ask {selector}: {e}"))),
        };
        let wait = self.timeout + Duration::from_secs(1);
        match tokio::time::timeout(wait, replies.recv_async()).await {
            Err(_) => (
                504,
                error_body(&format!(
                    "the coordinator did not answer {selector} within {:?}",
                    self.timeout
                )),
            ),
            Ok(Err(_)) => (
                502,
                error_body(&format!(
                    "nobody answered {selector}: is the coordinator up, and this gateway connected to it?"
                )),
            ),
            Ok(Ok(reply)) => match reply.result() {
                Ok(sample) => (200, sample.payload().to_bytes().into_owned()),
                Err(e) => {
                    let body = e.payload().to_bytes().into_owned();
                    let message = serde_json::from_slice::<QueryError>(&body)
                        .map(|q| q.error)
                        .unwrap_or_else(|_| String::from_utf8_lossy(&body).into_owned());
                    (status_of(&message), body)
                }
            },
        }
    }
}

/// The HTTP status of an error the coordinator answered with.
pub(crate) fn status_of(error: &str) -> u16 {
    let unavailable = ["degraded", "no sensor", "no leader"];
    if unavailable.iter().any(|p| error.starts_with(p)) {
        503
    } else {
        400
    }
}

/// `{"error":"…"}`, the coordinator's own error shape.
pub(crate) fn error_body(error: &str) -> Vec<u8> {
    serde_json::to_vec(&QueryError {
        error: error.to_string(),
    })
    .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_map_to_statuses_by_kind() {
        assert_eq!(
            status_of("degraded: leaders [\"leader-1\"] did not answer"),
            503
        );
        assert_eq!(
            status_of("no sensor gateway answered: the stream has no source yet"),
            503
        );
        assert_eq!(status_of("no leader is listed by the sensor"), 503);
        assert_eq!(status_of("events=abc: expected a count of events"), 400);
        assert_eq!(
            status_of("track 99 is out of range: there are 40 tracks"),
            400
        );
    }
}
