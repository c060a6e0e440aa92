//! What a user asked, read from a query's key and parameters before any
//! work is done: the track number of `P/query/track/<t>`, `events=N`,
//! `marginals=`, `samples=`, `seed=`. A parameter that is malformed, given
//! twice or unknown makes the query an error reply that says which and
//! why (a typo such as `?event=500` would otherwise answer a different
//! question than the one asked). Parameters starting with `_` are Zenoh's
//! own and are left to it.

use crate::driver::gather::At;
use crate::identity::Method;

/// A query, checked.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Request {
    Marginals(At),
    Track(At, u32),
    Identity(At, Method),
    IdentityTrack(At, u32, Method),
    Positions,
    Stats,
}

/// The parameters each kind of query takes.
const KNOWN: [&str; 4] = ["events", "marginals", "samples", "seed"];

impl Request {
    /// The request of a `kind` query (`marginals`, `track`, `identity`,
    /// `identity track`, `stats`) on `key` with `parameters`.
    pub fn parse<'a>(
        kind: &str,
        key: &str,
        parameters: impl IntoIterator<Item = (&'a str, &'a str)>,
    ) -> Result<Request, String> {
        let mut seen: Vec<(&str, &str)> = Vec::new();
        for (name, value) in parameters {
            if name.starts_with('_') {
                continue;
            }
            if !KNOWN.contains(&name) {
                return Err(format!(
                    "unknown parameter {name:?} (expected events, marginals, samples or seed)"
                ));
            }
            if seen.iter().any(|(n, _)| *n == name) {
                return Err(format!("parameter {name} given twice"));
            }
            seen.push((name, value));
        }
        let get = |name: &str| seen.iter().find(|(n, _)| *n == name).map(|(_, v)| *v);
        if kind == "stats" || kind == "positions" {
            return match (seen.first(), kind) {
                (None, "stats") => Ok(Request::Stats),
                (None, _) => Ok(Request::Positions),
                (Some((name, _)), _) => Err(format!("{kind} takes no parameters, got {name}")),
            };
        }
        let at = match get("events") {
            None => At::Latest,
            Some(n) => At::Events(
                n.parse()
                    .map_err(|_| format!("events={n}: expected a count of events"))?,
            ),
        };
        let method = || Method::from_parameters(get("marginals"), get("samples"), get("seed"));
        let property_only = || match ["marginals", "samples", "seed"]
            .iter()
            .find(|p| get(p).is_some())
        {
            Some(p) => Err(format!("{p}= is for identity queries")),
            None => Ok(()),
        };
        match kind {
            "marginals" => {
                property_only()?;
                Ok(Request::Marginals(at))
            }
            "track" => {
                property_only()?;
                Ok(Request::Track(at, track_of(key)?))
            }
            "identity" => Ok(Request::Identity(at, method()?)),
            "identity track" => Ok(Request::IdentityTrack(at, track_of(key)?, method()?)),
            other => Err(format!("no query of kind {other:?}")),
        }
    }
}

/// The track in `P/query/track/<t>` or `P/query/identity/<t>`.
fn track_of(key: &str) -> Result<u32, String> {
    let last = key.rsplit('/').next().unwrap_or(key);
    last.parse().map_err(|_| {
        format!(
            "{key}: the last chunk must be a track number (0 to {}), got {last:?}",
            u32::MAX
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(kind: &str, key: &str, parameters: &[(&str, &str)]) -> Result<Request, String> {
        Request::parse(kind, key, parameters.iter().copied())
    }

    #[test]
    fn well_formed_queries_are_read() {
        assert_eq!(
            parse("marginals", "p/query/marginals", &[]),
            Ok(Request::Marginals(At::Latest))
        );
        assert_eq!(
            parse(
                "track",
                "p/query/track/12",
                &[("events", "500"), ("_time", "x")]
            ),
            Ok(Request::Track(At::Events(500), 12))
        );
        assert!(matches!(
            parse(
                "identity track",
                "p/query/identity/3",
                &[("marginals", "sinkhorn")]
            ),
            Ok(Request::IdentityTrack(At::Latest, 3, Method::Named(_)))
        ));
        assert_eq!(parse("stats", "p/query/stats", &[]), Ok(Request::Stats));
        assert_eq!(
            parse("positions", "p/query/positions", &[]),
            Ok(Request::Positions)
        );
        assert!(parse("positions", "p/query/positions", &[("events", "5")])
            .is_err_and(|e| e.contains("positions takes no parameters")));
    }

    #[test]
    fn every_bad_parameter_is_an_error_that_names_it() {
        type Case<'a> = (&'a str, &'a str, &'a [(&'a str, &'a str)], &'a str);
        let cases: [Case; 10] = [
            (
                "marginals",
                "p/query/marginals",
                &[("events", "-1")],
                "events=-1",
            ),
            (
                "marginals",
                "p/query/marginals",
                &[("events", "1e3")],
                "events=1e3",
            ),
            (
                "marginals",
                "p/query/marginals",
                &[("event", "5")],
                "unknown parameter \"event\"",
            ),
            (
                "marginals",
                "p/query/marginals",
                &[("events", "1"), ("events", "2")],
                "twice",
            ),
            (
                "marginals",
                "p/query/marginals",
                &[("marginals", "exact")],
                "identity queries",
            ),
            ("track", "p/query/track/abc", &[], "\"abc\""),
            ("track", "p/query/track/4294967296", &[], "\"4294967296\""),
            (
                "identity",
                "p/query/identity",
                &[("marginals", "guess")],
                "marginals=guess",
            ),
            (
                "identity",
                "p/query/identity",
                &[("marginals", "metropolis"), ("samples", "0")],
                "samples=0",
            ),
            (
                "stats",
                "p/query/stats",
                &[("events", "3")],
                "no parameters",
            ),
        ];
        for (kind, key, parameters, expected) in cases {
            let e = parse(kind, key, parameters).expect_err(expected);
            assert!(e.contains(expected), "{kind} {parameters:?}: {e}");
        }
    }
}
