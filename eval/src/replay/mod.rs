//! `idmesh replay`: one filter over a recorded trace, offline — a property
//! filter (`property`) or an identity filter (`identity`), both through
//! one driver loop (`driver`) that turns trace lines into engine events
//! the one way the engine knows (`idmesh_belief::from_trace`).
//!
//! - `args` — the command line of `idmesh replay`.
//! - `driver` — the shared loop, the clock and the JSON Lines output.
//! - `property` — marginals of red, tracking error, Brier, log-loss.
//! - `identity` — identity marginals, the most likely assignment.
//! - `limits` — the size estimates that refuse exponential settings.

mod args;
mod driver;
mod identity;
mod limits;
mod property;

// The command's arguments and the choices they name.
pub use args::{CouplingChoice, Method, Places, ReplayArgs, SplitChoice};
pub use identity::MarginalChoice;

pub(crate) use args::DEFAULT_PROPERTY_METHOD;

use anyhow::{bail, Context, Result};
use idmesh_protocol::trace::TraceReader;
use std::io::Write;

/// `idmesh replay`: the identity replay for an identity trace, the
/// property replay otherwise; with no `--method`, the default for the
/// trace — one that answers at any size: factored for a trace with
/// colours; for an identity trace that says nothing of colours (its
/// header has `identities` and neither `red` nor `initial_red`), what the
/// leaders serve: the factored identity belief with a known start
/// (`identity::DEFAULT_IDENTITY_METHOD`), the information matrix without. A property method on such an identity trace, or an
/// identity method on a trace without identities, is an error that says so.
pub fn dispatch(args: &ReplayArgs, out: impl Write) -> Result<()> {
    if let Some(path) = &args.topology {
        anyhow::bail!(
            "--topology {}: the idmesh binary reads the topology and sets the options from it",
            path.display()
        );
    }
    // A property method's flags are checked before anything is read.
    if args.method.is_some_and(|m| m.identity().is_none()) {
        property::check_options(args)?;
    }
    let mut reader = TraceReader::open(&args.trace)
        .with_context(|| format!("cannot open trace {}", args.trace.display()))?;
    let header = reader.read_header()?;
    let identities_only = header.identities.is_some() && header.red_count().is_none();
    let source = reader.source().to_string();
    match (header.identities, args.method) {
        (Some(_), None) if identities_only => identity::run_default(args, out),
        (Some(_), Some(method)) if method.identity().is_some() => identity::run_default(args, out),
        (Some(n), Some(method)) if identities_only => bail!(
            "{source}:1: header: an identity trace ({n} identities) with no colours, and \
             --method {} is a property method; use factored-identity (the default with a known \
             start), information-matrix (the default without), exact-perm, belief-matrix or \
             property-bits",
            method.name()
        ),
        (None, Some(method)) if method.identity().is_some() => bail!(
            "{source}:1: header: a property trace (no `identities`), and --method {} is an \
             identity method; use a property method (default {})",
            method.name(),
            DEFAULT_PROPERTY_METHOD.name()
        ),
        _ => property::run(args, out),
    }
}

#[cfg(test)]
mod tests {
    use super::property::tests::args;
    use super::*;

    #[test]
    fn dispatch_picks_the_replay_by_the_header_and_refuses_mismatches() {
        let dir = std::env::temp_dir().join(format!("idmesh-dispatch-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let identity = dir.join("ids.jsonl");
        std::fs::write(
            &identity,
            concat!(
                r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":2,"identities":2,"initial_identity":[1,0]}"#,
                "\n",
                r#"{"kind":"truth","time":1,"identity":[1,0]}"#,
                "\n"
            ),
        )
        .unwrap();
        let property = dir.join("red.jsonl");
        std::fs::write(
            &property,
            concat!(
                r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":2,"red":1}"#,
                "\n"
            ),
        )
        .unwrap();
        let run = |trace: &std::path::Path, method: Option<Method>| {
            let mut a = args(Method::Overcomplete, None);
            a.trace = trace.to_path_buf();
            a.method = method;
            let mut out = Vec::new();
            dispatch(&a, &mut out)
                .map(|()| String::from_utf8(out).unwrap())
                .map_err(|e| format!("{e:#}"))
        };
        // A known start: what the leaders hold there by default.
        let out = run(&identity, None).unwrap();
        assert!(out.contains(r#""method":"factored-identity""#), "{out}");
        let unknown = dir.join("ids-unknown.jsonl");
        std::fs::write(
            &unknown,
            concat!(
                r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":2,"identities":2}"#,
                "\n",
                r#"{"kind":"identify","time":0.5,"track":0,"identity":1,"accuracy":0.9}"#,
                "\n",
                r#"{"kind":"truth","time":1,"identity":[1,0]}"#,
                "\n"
            ),
        )
        .unwrap();
        let out = run(&unknown, None).unwrap();
        assert!(out.contains(r#""method":"information-matrix""#), "{out}");
        assert!(out.contains(r#""predicted_identity":[1,0]"#), "{out}");
        let out = run(&identity, Some(Method::BeliefMatrix)).unwrap();
        assert!(out.contains(r#""method":"belief-matrix""#), "{out}");
        let error = run(&identity, Some(Method::Overcomplete)).unwrap_err();
        assert!(
            error.ends_with("header: an identity trace (2 identities) with no colours, and --method overcomplete is a property method; use factored-identity (the default with a known start), information-matrix (the default without), exact-perm, belief-matrix or property-bits"),
            "{error}"
        );
        let error = run(&property, Some(Method::InformationMatrix)).unwrap_err();
        assert!(
            error.contains("a property trace (no `identities`), and --method information-matrix is an identity method"),
            "{error}"
        );
        let out = run(&property, None).unwrap();
        assert!(out.contains(r#""method":"factored""#), "{out}");
        // Colours and identities (the demo's crowd): colours by default,
        // identities on request.
        let both = dir.join("both.jsonl");
        std::fs::write(
            &both,
            concat!(
                r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":2,"red":1,"identities":2}"#,
                "\n"
            ),
        )
        .unwrap();
        let out = run(&both, None).unwrap();
        assert!(out.contains(r#""method":"factored""#), "{out}");
        let out = run(&both, Some(Method::InformationMatrix)).unwrap();
        assert!(out.contains(r#""method":"information-matrix""#), "{out}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
