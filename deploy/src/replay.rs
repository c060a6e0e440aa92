//! `idmesh replay`: run one filter over a recorded trace, offline.
//!
//! The header makes the [`Field`]; `mix` and `observe` lines are applied in
//! order (`move` and `identify` lines mean nothing to a property filter and
//! are skipped); at every `truth` line one JSON line is written with the
//! marginals, the predicted red tracks and the coefficient count; at the end
//! a summary line with the mean tracking error and the engine's own time.
//!
//! Every error — a bad line, an event the engine rejects — is reported as
//! `FILE:LINE: reason` and ends the replay.

use crate::cli::{Method, ReplayArgs};
use anyhow::{anyhow, bail, Context, Result};
use idmesh_belief::baseline::{DenseFilter, LowOrderFilter, LowOrderRepair, MAX_STATES};
use idmesh_belief::{
    brier_score, expected_tracking_error, log_loss, predict_red, BeliefError, Event,
    FactoredBelief, Field, ParticleFilter, PropertyFilter, RadonBelief, RadonOptions, Sparsify,
};
use idmesh_protocol::trace::{Header, Line, NumberedLine, TraceReader};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use std::io::{BufRead, Write};
use std::time::{Duration, Instant};
use tracing::{debug, info, info_span};

/// The answers at one `truth` line.
#[derive(Debug, Serialize)]
struct Answer<'a> {
    time: f64,
    p_red: &'a [f64],
    predicted_red: &'a [u32],
    coefficients: usize,
}

/// The last line of a replay.
#[derive(Debug, Serialize)]
struct Summary {
    kind: &'static str,
    method: &'static str,
    events: u64,
    seconds: f64,
    /// Mean tracking error over the truth lines, ties shared (trace spec,
    /// Scoring).
    error: Option<f64>,
    /// Mean Brier score and log-loss of the marginals over the truth lines.
    brier: Option<f64>,
    log_loss: Option<f64>,
    max_coefficients: usize,
    /// P(red) of every track after the last event (what a live deployment
    /// answers at the end of the stream).
    final_p_red: Option<Vec<f64>>,
}

/// Writes one JSON Lines record.
pub fn write_line(out: &mut impl Write, value: &impl serde::Serialize) -> Result<()> {
    serde_json::to_writer(&mut *out, value)
        .map_err(std::io::Error::from)
        .and_then(|()| out.write_all(b"\n"))
        .map_err(|e| anyhow!("cannot write the output: {e}"))
}

/// The `FILE:LINE: kind: reason` error of the replays, for trace `source`.
pub fn line_error(source: &str) -> impl Fn(usize, &str, BeliefError) -> anyhow::Error + '_ {
    move |line, kind, error| anyhow!("{source}:{line}: {kind}: {error}")
}

/// The mean error over the truth lines (None when there were none).
pub fn mean_error(errors: &[f64]) -> Option<f64> {
    (!errors.is_empty()).then(|| errors.iter().sum::<f64>() / errors.len() as f64)
}

/// Writes the summary line and flushes: the end of every replay.
pub fn finish(mut out: impl Write, summary: &impl serde::Serialize) -> Result<()> {
    write_line(&mut out, summary)?;
    out.flush()
        .map_err(|e| anyhow!("cannot write the output: {e}"))
}

/// Time spent inside a filter, and nothing else (reading and printing
/// excluded): the `seconds` of a replay's summary.
#[derive(Debug, Default)]
pub struct Stopwatch {
    pub total: Duration,
}

impl Stopwatch {
    pub fn time<T>(&mut self, work: impl FnOnce() -> T) -> T {
        let clock = Instant::now();
        let result = work();
        self.total += clock.elapsed();
        result
    }
}

/// `idmesh replay`: the identity replay ([`crate::replay_identity`]) for
/// an identity trace, this property replay otherwise; with no `--method`,
/// the default for the trace — one that answers at any size: factored for
/// a trace with colours, the information matrix for an identity trace that
/// says nothing of colours (its header has `identities` and neither `red`
/// nor `initial_red`). A property method on such an identity trace, or an
/// identity method on a trace without identities, is an error that says so.
pub fn dispatch(args: &ReplayArgs, out: impl Write) -> Result<()> {
    // A property method's flags are checked before anything is read.
    if args.method.is_some_and(|m| m.identity().is_none()) {
        check_options(args)?;
    }
    let mut reader = TraceReader::open(&args.trace)
        .with_context(|| format!("cannot open trace {}", args.trace.display()))?;
    let header = reader.read_header()?;
    let identities_only = header.identities.is_some() && header.red_count().is_none();
    let source = reader.source().to_string();
    match (header.identities, args.method) {
        (Some(_), None) if identities_only => crate::replay_identity::run_default(args, out),
        (Some(_), Some(method)) if method.identity().is_some() => {
            crate::replay_identity::run_default(args, out)
        }
        (Some(n), Some(method)) if identities_only => bail!(
            "{source}:1: header: an identity trace ({n} identities) with no colours, and \
             --method {} is a property method; use exact-perm, belief-matrix, \
             information-matrix (the default) or property-bits",
            method.name()
        ),
        (None, Some(method)) if method.identity().is_some() => bail!(
            "{source}:1: header: a property trace (no `identities`), and --method {} is an \
             identity method; use a property method (default {})",
            method.name(),
            crate::cli::DEFAULT_PROPERTY_METHOD.name()
        ),
        _ => run(args, out),
    }
}

/// Replays the trace named by `args` and writes the answers to `out`. On a
/// terminal, a bar on stderr shows how much of the trace has been read.
pub fn run(args: &ReplayArgs, out: impl Write) -> Result<()> {
    check_options(args)?;
    let file = std::fs::File::open(&args.trace)
        .with_context(|| format!("cannot open trace {}", args.trace.display()))?;
    let bytes = file.metadata().map(|m| m.len()).unwrap_or(0);
    let bar = ProgressBar::with_draw_target(Some(bytes), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template(
            "replay {bar:30} {percent:>3}% of the trace · {elapsed} · ~{eta} left",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let reader = TraceReader::new(
        std::io::BufReader::new(bar.wrap_read(file)),
        args.trace.display().to_string(),
    );
    let result = replay(args, reader, out);
    bar.finish_and_clear();
    result
}

/// The particle count of `--method particles` when `--particles` is not given.
pub const DEFAULT_PARTICLES: usize = 1000;

/// The flags that make no sense together, refused before anything is read.
fn check_options(args: &ReplayArgs) -> Result<()> {
    let method = args.property_method();
    if args.marginals.is_some()
        || args.bits.is_some()
        || args.samples.is_some()
        || args.force
        || args.known_start_confidence.is_some()
    {
        bail!(
            "--marginals, --bits, --samples, --known-start-confidence and --force apply to the identity methods, not to --method {}",
            method.name()
        );
    }
    if method != Method::Particles {
        if args.particles.is_some() {
            bail!(
                "--particles applies to --method particles, not to --method {}",
                method.name()
            );
        }
        if args.seed.is_some() {
            bail!(
                "--seed applies to --method particles (the only randomized filter), not to --method {}",
                method.name()
            );
        }
    }
    if method == Method::Threshold && args.budget.is_none() {
        bail!("--method threshold needs --budget N: the number of coefficients to keep");
    }
    if !method.is_radon() {
        if args.budget.is_some() {
            bail!(
                "--budget applies to the Radon methods (overcomplete, threshold), not to --method {}",
                method.name()
            );
        }
        if args.distributed_rule {
            bail!(
                "--distributed-rule applies to the Radon methods (overcomplete, threshold), not to --method {}",
                method.name()
            );
        }
    }
    Ok(())
}

/// Replays a trace from any reader (the testable core of [`run`]).
pub fn replay<R: BufRead>(
    args: &ReplayArgs,
    mut reader: TraceReader<R>,
    mut out: impl Write,
) -> Result<()> {
    let span = info_span!(
        "replay",
        trace = reader.source(),
        method = args.property_method().name()
    );
    let _entered = span.enter();

    let header = reader.read_header()?;
    let source = reader.source().to_string();
    let at = line_error(&source);
    let field = field_of(&header);
    check_size(args, &field).map_err(|e| anyhow!("{source}:1: header: {e}"))?;
    debug!(tracks = field.tracks, red = ?field.red.known(), known_start = field.initial_red.is_some(), "field");
    let mut engine =
        Engine::start(|| build(args, field.clone())).map_err(|e| at(1, "header", e))?;

    let (mut errors, mut briers, mut log_losses) = (Vec::new(), Vec::new(), Vec::new());
    for line in reader {
        let NumberedLine { number, line } = line?;
        match &line {
            Line::Mix(mix) => {
                let event = Event::Mix(idmesh_belief::Mix {
                    a: mix.a,
                    b: mix.b,
                    swap: mix.swap,
                });
                engine.apply(&event).map_err(|e| at(number, "mix", e))?;
            }
            Line::Observe(observe) => {
                let event = Event::Observe(idmesh_belief::Observe {
                    track: observe.track,
                    red: observe.red,
                    blue: observe.blue,
                });
                engine.apply(&event).map_err(|e| at(number, "observe", e))?;
            }
            Line::Truth(truth) => {
                let p_red = engine.marginals().map_err(|e| at(number, "truth", e))?;
                let predicted = predict_red(&p_red, field.red.known());
                if let Some(red) = &truth.red {
                    errors.push(expected_tracking_error(&p_red, field.red.known(), red));
                    briers.push(brier_score(&p_red, red));
                    log_losses.push(log_loss(&p_red, red));
                }
                let answer = Answer {
                    time: truth.time,
                    p_red: &p_red,
                    predicted_red: &predicted,
                    coefficients: engine.filter.coefficients(),
                };
                write_line(&mut out, &answer)?;
            }
            // Positions and identity reads do not bear on a property belief.
            Line::Move(_) | Line::Identify(_) | Line::Header(_) => {}
        }
        debug!(
            line = number,
            kind = line.kind(),
            coefficients = engine.filter.coefficients(),
            "line"
        );
    }

    let summary = Summary {
        kind: "summary",
        method: args.property_method().name(),
        events: engine.events,
        seconds: engine.time.total.as_secs_f64(),
        error: mean_error(&errors),
        brier: mean_error(&briers),
        log_loss: mean_error(&log_losses),
        max_coefficients: engine.max_coefficients,
        final_p_red: engine.marginals().ok(),
    };
    info!(
        events = summary.events,
        seconds = summary.seconds,
        error = ?summary.error,
        max_coefficients = summary.max_coefficients,
        "replayed"
    );
    finish(out, &summary)
}

/// The field a trace header describes: k known (from `red` or the length of
/// `initial_red`) or unknown with the uniform prior over counts, and the
/// red tracks at time 0 when the header gives them.
pub fn field_of(header: &Header) -> Field {
    Field::with_count(
        header.tracks,
        header.red_count(),
        header.initial_red.clone(),
    )
}

/// Refuses a Radon method without a budget where the exact belief it keeps
/// may outgrow the machine: it can hold as many coefficients as the exact
/// dense filter has states (C(n, k), or 2^n with k unknown), so past the
/// dense filter's own limit it is refused with that estimate. The other
/// methods check their own sizes when they are built.
fn check_size(args: &ReplayArgs, field: &Field) -> Result<()> {
    if !args.property_method().is_radon() || args.budget.is_some() {
        return Ok(());
    }
    let n = field.tracks;
    let (sets, what) = match field.red.known() {
        Some(k) => (binomial(n, k), format!("C({n}, {k})")),
        None => (2f64.powi(n.min(1024) as i32), format!("2^{n}")),
    };
    if sets > MAX_STATES as f64 {
        bail!(
            "--method {} without --budget is exact, and on this trace it may hold as many \
             coefficients as there are red sets, {what} ≈ {sets:.2e} (limit {MAX_STATES}): \
             give --budget N (say 500), or use --method factored",
            args.property_method().name()
        );
    }
    Ok(())
}

/// C(n, k) as a float (infinite when it overflows).
fn binomial(n: usize, k: usize) -> f64 {
    let k = k.min(n - k.min(n));
    (0..k).fold(1.0, |c, i| c * (n - i) as f64 / (i + 1) as f64)
}

/// The filter `args.method` names, for `field`.
fn build(args: &ReplayArgs, field: Field) -> Result<Box<dyn PropertyFilter>, BeliefError> {
    let radon = |sparsify: Option<Sparsify>| -> Result<Box<dyn PropertyFilter>, BeliefError> {
        let options = RadonOptions {
            sparsify,
            distributed_rule: args.distributed_rule,
            ..RadonOptions::default()
        };
        Ok(Box::new(RadonBelief::with_options(field.clone(), options)?))
    };
    match args.property_method() {
        Method::Overcomplete => radon(args.budget.map(Sparsify::overcomplete)),
        // `check_options` made sure the budget is there.
        Method::Threshold => radon(args.budget.map(Sparsify::threshold)),
        Method::Exact => Ok(Box::new(DenseFilter::new(field)?)),
        // The paper's projection alone leaves the simplex on real traces and
        // then refuses observations as impossible; the repair keeps it going.
        Method::Order1 | Method::Order2 | Method::Order3 => {
            let order = match args.property_method() {
                Method::Order1 => 1,
                Method::Order2 => 2,
                _ => 3,
            };
            Ok(Box::new(LowOrderFilter::with_repair(
                field,
                order,
                LowOrderRepair::ShrinkToUniform,
            )?))
        }
        Method::Factored => Ok(Box::new(FactoredBelief::new(field)?)),
        // Identity methods are replayed by `replay_identity` (see main).
        Method::ExactPerm
        | Method::BeliefMatrix
        | Method::InformationMatrix
        | Method::PropertyBits => Err(BeliefError::Unsupported {
            method: "the property replay",
            what: "an identity method",
        }),
        Method::Particles => Ok(Box::new(ParticleFilter::new(
            field,
            args.particles.unwrap_or(DEFAULT_PARTICLES),
            args.seed.unwrap_or(0),
        )?)),
    }
}

/// A filter with the bookkeeping of a replay: the time spent inside the
/// filter (and nothing else), the events applied, the largest coefficient
/// count seen.
struct Engine {
    filter: Box<dyn PropertyFilter>,
    time: Stopwatch,
    events: u64,
    max_coefficients: usize,
}

impl Engine {
    fn start(
        build: impl FnOnce() -> Result<Box<dyn PropertyFilter>, BeliefError>,
    ) -> Result<Self, BeliefError> {
        let mut time = Stopwatch::default();
        let filter = time.time(build)?;
        let max_coefficients = filter.coefficients();
        Ok(Engine {
            filter,
            time,
            events: 0,
            max_coefficients,
        })
    }

    fn apply(&mut self, event: &Event) -> Result<(), BeliefError> {
        let filter = &mut self.filter;
        self.time.time(|| filter.apply(event))?;
        self.events += 1;
        self.max_coefficients = self.max_coefficients.max(self.filter.coefficients());
        Ok(())
    }

    fn marginals(&mut self) -> Result<Vec<f64>, BeliefError> {
        let filter = &self.filter;
        self.time.time(|| filter.marginals())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use idmesh_belief::RedCount;
    use std::path::PathBuf;

    fn args(method: Method, budget: Option<usize>) -> ReplayArgs {
        ReplayArgs {
            trace: PathBuf::from("mem.jsonl"),
            method: Some(method),
            budget,
            distributed_rule: false,
            particles: None,
            seed: None,
            marginals: None,
            bits: None,
            samples: None,
            force: false,
            known_start_confidence: None,
        }
    }

    /// The replay's output lines, parsed, or its error as text.
    fn replay_text(args: &ReplayArgs, trace: &str) -> Result<Vec<serde_json::Value>, String> {
        check_options(args).map_err(|e| format!("{e:#}"))?;
        let mut out = Vec::new();
        replay(
            args,
            TraceReader::new(trace.as_bytes(), "mem.jsonl"),
            &mut out,
        )
        .map_err(|e| format!("{e:#}"))?;
        Ok(String::from_utf8(out)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect())
    }

    const TABLE1: &str = concat!(
        r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":4,"red":2,"initial_red":[0,1]}"#,
        "\n",
        r#"{"kind":"mix","time":1,"a":0,"b":2,"swap":0.5}"#,
        "\n",
        r#"{"kind":"mix","time":2,"a":2,"b":3,"swap":0.5}"#,
        "\n",
        r#"{"kind":"move","time":2,"track":3,"x":1.5,"y":0}"#,
        "\n",
        r#"{"kind":"observe","time":3,"track":2,"red":1,"blue":0}"#,
        "\n",
        r#"{"kind":"truth","time":3,"red":[1,2]}"#,
        "\n",
    );

    #[test]
    fn an_exact_radon_belief_too_big_for_the_machine_is_refused_with_an_estimate() {
        let header =
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":60,"red":30}"#;
        let error = replay_text(&args(Method::Overcomplete, None), header).unwrap_err();
        assert!(
            error.contains("--method overcomplete without --budget is exact")
                && error.contains("C(60, 30) ≈ 1.18e17")
                && error.contains("use --method factored"),
            "{error}"
        );
        // With a budget, or a field the dense limit allows, it runs.
        assert!(replay_text(&args(Method::Overcomplete, Some(50)), header).is_ok());
        let small = r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":20,"red":10}"#;
        assert!(replay_text(&args(Method::Overcomplete, None), small).is_ok());
    }

    #[test]
    fn table_one_on_the_radon_engine() {
        let out = replay_text(&args(Method::Overcomplete, None), TABLE1).unwrap();
        assert_eq!(out.len(), 2);
        let p: Vec<f64> = serde_json::from_value(out[0]["p_red"].clone()).unwrap();
        for (got, want) in p.iter().zip([0.0, 1.0, 1.0, 0.0]) {
            assert!((got - want).abs() < 1e-9, "{p:?}");
        }
        assert_eq!(out[0]["predicted_red"], serde_json::json!([1, 2]));
        assert_eq!(out[0]["time"], 3.0);
        assert_eq!(out[1]["kind"], "summary");
        assert_eq!(out[1]["method"], "overcomplete");
        assert_eq!(out[1]["events"], 3);
        assert_eq!(out[1]["error"], 0.0);
        assert!(out[1]["max_coefficients"].as_u64().unwrap() >= 1);
        assert!(out[1]["seconds"].as_f64().unwrap() >= 0.0);
    }

    #[test]
    fn engine_errors_name_their_line() {
        let trace = concat!(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"initial_red":[0]}"#,
            "\n",
            r#"{"kind":"observe","time":0,"track":1,"red":1,"blue":0}"#,
            "\n",
        );
        let error = replay_text(&args(Method::Overcomplete, None), trace).unwrap_err();
        assert!(error.starts_with("mem.jsonl:2: observe: "), "{error}");
    }

    #[test]
    fn no_truth_means_no_error() {
        let trace = concat!(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"red":1}"#,
            "\n",
            r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":0.25}"#,
            "\n",
        );
        let out = replay_text(&args(Method::Overcomplete, Some(8)), trace).unwrap();
        assert_eq!(out.len(), 1);
        assert_eq!(out[0]["error"], serde_json::Value::Null);
        assert_eq!(out[0]["events"], 1);
    }

    #[test]
    fn field_from_header() {
        let mut header = Header::new(5);
        assert_eq!(field_of(&header).red, RedCount::unknown_uniform(5));
        header.initial_red = Some(vec![4, 2]);
        let field = field_of(&header);
        assert_eq!(field.red, RedCount::Known(2));
        assert_eq!(field.initial_red, Some(vec![4, 2]));
        header.initial_red = None;
        header.red = Some(3);
        assert_eq!(field_of(&header), Field::uniform(5, 3));
    }

    #[test]
    fn options_that_do_not_fit_are_refused() {
        let threshold = check_options(&args(Method::Threshold, None)).unwrap_err();
        assert!(
            threshold.to_string().contains("needs --budget"),
            "{threshold}"
        );
        let exact = check_options(&args(Method::Exact, Some(10))).unwrap_err();
        assert!(exact.to_string().contains("--budget applies"), "{exact}");
        let mut order = args(Method::Order2, None);
        order.distributed_rule = true;
        assert!(check_options(&order).is_err());
        assert!(check_options(&args(Method::Threshold, Some(4))).is_ok());
        let mut particles = args(Method::Exact, None);
        particles.particles = Some(10);
        let error = check_options(&particles).unwrap_err();
        assert!(error.to_string().contains("--particles applies"), "{error}");
        particles.particles = None;
        particles.seed = Some(1);
        assert!(check_options(&particles).is_err());
        particles.method = Some(Method::Particles);
        assert!(check_options(&particles).is_ok());
        particles.budget = Some(3);
        assert!(check_options(&particles).is_err());
    }

    #[test]
    fn table_one_on_the_particle_filter() {
        let mut particles = args(Method::Particles, None);
        particles.particles = Some(200);
        particles.seed = Some(4);
        let out = replay_text(&particles, TABLE1).unwrap();
        assert_eq!(out.len(), 2);
        assert_eq!(out[0]["p_red"], serde_json::json!([0.0, 1.0, 1.0, 0.0]));
        assert_eq!(out[0]["coefficients"], 200);
        assert_eq!(out[1]["method"], "particles");
        assert_eq!(out[1]["error"], 0.0);
        assert_eq!(out[1]["max_coefficients"], 200);
    }

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
        let out = run(&identity, None).unwrap();
        assert!(out.contains(r#""method":"information-matrix""#), "{out}");
        assert!(out.contains(r#""predicted_identity":[1,0]"#), "{out}");
        let out = run(&identity, Some(Method::BeliefMatrix)).unwrap();
        assert!(out.contains(r#""method":"belief-matrix""#), "{out}");
        let error = run(&identity, Some(Method::Overcomplete)).unwrap_err();
        assert!(
            error.ends_with("header: an identity trace (2 identities) with no colours, and --method overcomplete is a property method; use exact-perm, belief-matrix, information-matrix (the default) or property-bits"),
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
