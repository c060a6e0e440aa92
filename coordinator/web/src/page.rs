//! The live map's four files, compiled into the binary (no CDN, no
//! internet): `index.html`, `map.js` (vanilla JavaScript drawing on a
//! canvas, fed by Server-Sent Events from [`crate::rest`] and by the
//! gateway's [`crate::history`]), `labels.js` (where the map's labels go,
//! so that none covers another) and `map.css`.
//! The page learns the deployment's prefix from a `<meta>` tag filled in
//! here.

use crate::asker::Asker;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use std::sync::Arc;

const INDEX: &str = include_str!("../assets/index.html");
const SCRIPT: &str = include_str!("../assets/map.js");
const LABELS: &str = include_str!("../assets/labels.js");
const STYLE: &str = include_str!("../assets/map.css");

pub async fn index(State(asker): State<Arc<Asker>>) -> Response {
    // A prefix is key-expression chunks: no quote or angle bracket can be
    // in it, but escape them anyway rather than trust that.
    let prefix: String = asker
        .keys
        .prefix()
        .chars()
        .filter(|c| !matches!(c, '"' | '<' | '>' | '&' | '\''))
        .collect();
    let page = INDEX.replace("{{PREFIX}}", &prefix);
    ([(header::CONTENT_TYPE, "text/html; charset=utf-8")], page).into_response()
}

pub(crate) async fn script() -> Response {
    javascript(SCRIPT)
}

pub(crate) async fn labels() -> Response {
    javascript(LABELS)
}

fn javascript(source: &'static str) -> Response {
    (
        [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
        source,
    )
        .into_response()
}

pub(crate) async fn style() -> Response {
    ([(header::CONTENT_TYPE, "text/css; charset=utf-8")], STYLE).into_response()
}
