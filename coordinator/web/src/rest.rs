//! REST and Server-Sent Events over the query API, in the convention of
//! Zenoh's REST plugin: the path is the key expression, the query string
//! its parameters (`&` or `;` between them).
//!
//! `GET /idmesh/default/query/marginals?events=500` answers with the
//! coordinator's JSON, byte for byte; an error with its status (see
//! [`crate::asker`]) and the coordinator's `{"error":"…"}`. Only the query
//! API is served (`<prefix>/query/…`): the gateway is a client and asks
//! nothing else of the mesh.
//!
//! With `Accept: text/event-stream` the same path streams: a fresh answer
//! every `interval=<ms>` (default [`DEFAULT_INTERVAL`], bounded by
//! [`MIN_INTERVAL`] and [`MAX_INTERVAL`]; the gateway's own parameter, not
//! passed on), each as an `answer` event whose data is the JSON answer (a
//! `failure` event with the error when there is none), preceded by a
//! `latency` event `{"ms":…,"status":…}`: how long the gateway waited for
//! it. The first answer is asked at once.

use crate::asker::{error_body, Answer, Asker};
use axum::body::Body;
use axum::extract::State;
use axum::http::{header, HeaderMap, Method, StatusCode, Uri};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use futures_util::stream::{self, StreamExt};
use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;

pub(crate) const DEFAULT_INTERVAL: Duration = Duration::from_millis(1000);
pub(crate) const MIN_INTERVAL: Duration = Duration::from_millis(100);
pub(crate) const MAX_INTERVAL: Duration = Duration::from_secs(60);

/// The questions of the query API, by their key under `<prefix>/query/`:
/// (pattern, name in the latency histograms); `*` is one chunk.
const QUESTIONS: [(&str, &str); 6] = [
    ("marginals", "marginals"),
    ("track/*", "track"),
    ("identity", "identity"),
    ("identity/*", "identity track"),
    ("positions", "positions"),
    ("stats", "stats"),
];

/// A request, read: the selector to ask, and for a stream its interval.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Asked {
    pub selector: String,
    pub what: &'static str,
    pub interval: Duration,
}

/// Reads a request's path and query string; an error is (status, message).
pub fn read(prefix: &str, path: &str, query: Option<&str>) -> Result<Asked, (u16, String)> {
    let key = path.trim_start_matches('/');
    let api = format!("{prefix}/query/");
    let Some(question) = key.strip_prefix(&api) else {
        return Err((
            404,
            format!("/{key}: this gateway serves the query API only, /{api}…"),
        ));
    };
    let what = QUESTIONS
        .iter()
        .find(|(pattern, _)| matches(pattern, question))
        .map(|(_, what)| *what)
        .ok_or_else(|| {
            (
                404,
                format!(
                    "/{key}: no such question (marginals, track/<t>, identity, identity/<t>, positions, stats)"
                ),
            )
        })?;
    let mut parameters = Vec::new();
    let mut interval = None;
    for pair in query
        .unwrap_or("")
        .split(['&', ';'])
        .filter(|p| !p.is_empty())
    {
        match pair.strip_prefix("interval=") {
            Some(ms) => {
                if interval.is_some() {
                    return Err((400, "parameter interval given twice".into()));
                }
                let ms: u64 = ms
                    .parse()
                    .map_err(|_| (400, format!("interval={ms}: expected milliseconds")))?;
                let wanted = Duration::from_millis(ms);
                if !(MIN_INTERVAL..=MAX_INTERVAL).contains(&wanted) {
                    return Err((
                        400,
                        format!(
                            "interval={ms}: must be from {} to {} ms",
                            MIN_INTERVAL.as_millis(),
                            MAX_INTERVAL.as_millis()
                        ),
                    ));
                }
                interval = Some(wanted);
            }
            None => parameters.push(pair),
        }
    }
    let selector = if parameters.is_empty() {
        key.to_string()
    } else {
        format!("{key}?{}", parameters.join(";"))
    };
    Ok(Asked {
        selector,
        what,
        interval: interval.unwrap_or(DEFAULT_INTERVAL),
    })
}

/// Whether `question` is `pattern`, chunk by chunk (`*` is any one chunk).
fn matches(pattern: &str, question: &str) -> bool {
    let (p, q): (Vec<&str>, Vec<&str>) =
        (pattern.split('/').collect(), question.split('/').collect());
    p.len() == q.len()
        && p.iter()
            .zip(&q)
            .all(|(p, q)| *p == "*" && !q.is_empty() || p == q)
}

/// Every path the routes do not claim: a question to the coordinator.
pub(crate) async fn rest(
    State(asker): State<Arc<Asker>>,
    method: Method,
    uri: Uri,
    headers: HeaderMap,
) -> Response {
    if method != Method::GET {
        return json(405, error_body(&format!("{method}: only GET is served")));
    }
    let asked = match read(asker.keys.prefix(), uri.path(), uri.query()) {
        Ok(asked) => asked,
        Err((status, message)) => return json(status, error_body(&message)),
    };
    let streaming = headers
        .get_all(header::ACCEPT)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .any(|v| v.contains("text/event-stream"));
    if streaming {
        return sse(asker, asked).into_response();
    }
    let answer = asker.ask(&asked.selector, asked.what).await;
    json(answer.status, answer.body)
}

fn json(status: u16, body: Vec<u8>) -> Response {
    Response::builder()
        .status(StatusCode::from_u16(status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR))
        .header(header::CONTENT_TYPE, "application/json")
        .body(Body::from(body))
        .unwrap_or_else(|_| StatusCode::INTERNAL_SERVER_ERROR.into_response())
}

/// A fresh answer every interval, for as long as the client listens.
fn sse(
    asker: Arc<Asker>,
    asked: Asked,
) -> Sse<impl futures_util::Stream<Item = Result<Event, Infallible>>> {
    let mut ticks = tokio::time::interval(asked.interval);
    ticks.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    let state = (asker, asked, ticks, 0u64);
    let answers = stream::unfold(state, |(asker, asked, mut ticks, n)| async move {
        ticks.tick().await;
        let answer = asker.ask(&asked.selector, asked.what).await;
        let events = events(&answer, n);
        Some((events, (asker, asked, ticks, n + 1)))
    });
    let events = answers.flat_map(|events| stream::iter(events.into_iter().map(Ok)));
    Sse::new(events).keep_alive(KeepAlive::default())
}

/// The events of the n-th answer of a stream.
fn events(answer: &Answer, n: u64) -> Vec<Event> {
    let latency = format!(
        "{{\"ms\":{:.3},\"status\":{}}}",
        answer.took.as_secs_f64() * 1e3,
        answer.status
    );
    let body = String::from_utf8_lossy(&answer.body).into_owned();
    let name = if answer.ok() { "answer" } else { "failure" };
    vec![
        Event::default().event("latency").data(latency),
        Event::default().event(name).id(n.to_string()).data(body),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paths_and_parameters_are_read_into_selectors() {
        let p = "idmesh/default";
        let a = read(p, "/idmesh/default/query/marginals", None).unwrap();
        assert_eq!(a.selector, "idmesh/default/query/marginals");
        assert_eq!((a.what, a.interval), ("marginals", DEFAULT_INTERVAL));
        let a = read(
            p,
            "/idmesh/default/query/identity/3",
            Some("marginals=sinkhorn&interval=250;events=9"),
        )
        .unwrap();
        assert_eq!(
            a.selector,
            "idmesh/default/query/identity/3?marginals=sinkhorn;events=9"
        );
        assert_eq!(a.what, "identity track");
        assert_eq!(a.interval, Duration::from_millis(250));
        // The coordinator judges a track that is not a number.
        assert_eq!(
            read(p, "/idmesh/default/query/track/abc", None)
                .unwrap()
                .what,
            "track"
        );
    }

    #[test]
    fn what_the_gateway_does_not_serve_is_refused_with_why() {
        let p = "idmesh/default";
        let status = |path: &str, query: Option<&str>| read(p, path, query).unwrap_err().0;
        assert_eq!(status("/idmesh/default/leader/leader-0/stats", None), 404);
        assert_eq!(status("/idmesh/default/query/bogus", None), 404);
        assert_eq!(status("/idmesh/default/query/track", None), 404);
        assert_eq!(status("/idmesh/default/query/track/1/2", None), 404);
        assert_eq!(status("/other/query/marginals", None), 404);
        let q = "/idmesh/default/query/marginals";
        assert_eq!(status(q, Some("interval=5")), 400);
        assert_eq!(status(q, Some("interval=600000")), 400);
        assert_eq!(status(q, Some("interval=x")), 400);
        assert_eq!(status(q, Some("interval=200&interval=300")), 400);
    }
}
