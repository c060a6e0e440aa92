//! Decoding one line of text into a [`Line`], with messages that say which
//! kind of line and which field was wrong (serde's derived decoder for a
//! tagged enum would only say "missing field `swap`").
//!
//! The text is decoded twice — once for `kind` alone, once as the struct of
//! that kind — which keeps a malformed line, a line that is not an object, a
//! missing or unknown kind and a bad field apart without building a
//! `serde_json::Value` tree for every line.

use super::line::{Detect, Header, Identify, Line, Mix, Move, Observe, Truth};
use super::problem::Problem;
use serde::de::DeserializeOwned;
use serde::Deserialize;
use serde_json::error::Category;

/// Only the tag; every other field is ignored at this stage.
#[derive(Deserialize)]
struct Tag {
    #[serde(default)]
    kind: Option<serde_json::Value>,
}

impl Line {
    /// Decodes one line of a trace (without its newline). Checks the shape
    /// only; the spec's rules are [`Validator`](super::Validator)'s.
    pub fn parse(text: &str) -> Result<Line, Problem> {
        if text.trim().is_empty() {
            return Err(Problem::BlankLine);
        }
        if !text.trim_start().starts_with('{') {
            return Err(match serde_json::from_str::<serde_json::Value>(text) {
                Ok(value) => Problem::NotAnObject(json_type(&value)),
                Err(e) => Problem::MalformedJson(without_position(&e)),
            });
        }
        let tag: Tag =
            serde_json::from_str(text).map_err(|e| Problem::MalformedJson(without_position(&e)))?;
        let kind = match tag.kind {
            None => return Err(Problem::MissingKind),
            Some(serde_json::Value::String(kind)) => kind,
            Some(other) => return Err(Problem::KindNotAString(other.to_string())),
        };
        match kind.as_str() {
            "header" => fields::<Header>("header", text).map(Line::Header),
            "mix" => fields::<Mix>("mix", text).map(Line::Mix),
            "observe" => fields::<Observe>("observe", text).map(Line::Observe),
            "identify" => fields::<Identify>("identify", text).map(Line::Identify),
            "move" => fields::<Move>("move", text).map(Line::Move),
            "truth" => fields::<Truth>("truth", text).map(Line::Truth),
            // Parsed whatever the version; the validator refuses it in a
            // version-1 trace, with a message that says so.
            "detect" => fields::<Detect>("detect", text).map(Line::Detect),
            _ => Err(Problem::UnknownKind(kind)),
        }
    }
}

fn fields<T: DeserializeOwned>(kind: &'static str, text: &str) -> Result<T, Problem> {
    serde_json::from_str(text).map_err(|e| match e.classify() {
        Category::Data => Problem::BadField {
            kind,
            message: without_position(&e),
        },
        // E.g. a number too large for an f64, which the tag pass skipped.
        _ => Problem::MalformedJson(without_position(&e)),
    })
}

/// serde_json's message without its " at line 1 column N" suffix: the line
/// is the trace's, which the caller adds. The column is kept where it
/// points at the fault (not for a missing field, where it is the line's
/// end).
fn without_position(error: &serde_json::Error) -> String {
    let message = error.to_string();
    let suffix = format!(" at line {} column {}", error.line(), error.column());
    match message.strip_suffix(&suffix) {
        Some(bare) if error.column() > 0 && !bare.starts_with("missing field") => {
            format!("{bare} (column {})", error.column())
        }
        Some(bare) => bare.to_string(),
        None => message,
    }
}

/// The JSON type of a value, as a phrase.
fn json_type(value: &serde_json::Value) -> &'static str {
    match value {
        serde_json::Value::Array(_) => "an array",
        serde_json::Value::String(_) => "a string",
        serde_json::Value::Number(_) => "a number",
        serde_json::Value::Bool(_) => "a boolean",
        serde_json::Value::Null => "null",
        serde_json::Value::Object(_) => "an object",
    }
}
