//! `idmesh replay` on a property trace: run one filter over a recorded
//! trace, offline.
//!
//! The header makes the `Field`; `mix` and `observe` lines are applied in
//! order (`identify` lines mean nothing to a property filter and are
//! skipped, and so are `move` lines except under the regional rule of
//! `--leaders` or `--regions`, where a track handed over is split off its
//! component); at every `truth` line one JSON line is written with the
//! marginals, the predicted red tracks and the coefficient count; at the end
//! a summary line with the mean tracking error and the engine's own time.
//!
//! Every error — a bad line, an event the engine rejects — is reported as
//! `FILE:LINE: reason` and ends the replay.

use super::args::{Method, Places, ReplayArgs, SplitChoice};
use super::driver::{drive, finish, line_error, mean_error, Replay, Timed};
use super::limits::binomial;
use crate::filters::Recipe;
use anyhow::{anyhow, bail, Context, Result};
use idmesh_belief::MAX_STATES;
use idmesh_belief::{
    brier_score, event_of, expected_tracking_error, field_of, log_loss, predict_red, BeliefError,
    Event, FactoredBelief, FactoredOptions, Field, PropertyFilter, Sparsify, SplitRule,
};
use idmesh_placement::{RegionRule, Regional, Regions};
use idmesh_protocol::trace::{Line, TraceReader, Truth};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use std::io::{BufRead, Write};
use tracing::{debug, info, info_span};

/// The answers at one `truth` line.
#[derive(Debug, Serialize)]
pub struct Answer {
    time: f64,
    p_red: Vec<f64>,
    predicted_red: Vec<u32>,
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
    /// Sightings the filter took by its repair rule or set aside, and (the
    /// factored belief) queries answered by its contradiction rule: 0 on a
    /// stream that never contradicts itself (`PropertyFilter::repairs`).
    repairs: u64,
    /// P(red) of every track after the last event (what a live deployment
    /// answers at the end of the stream).
    final_p_red: Option<Vec<f64>>,
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
pub(crate) const DEFAULT_PARTICLES: usize = 1000;

/// The flags that make no sense together, refused before anything is read.
pub(crate) fn check_options(args: &ReplayArgs) -> Result<()> {
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
    let factored_options = args.coupling.is_some()
        || args.max_component.is_some()
        || args.split != SplitChoice::LeastLoss
        || args.regions.is_some()
        || args.leaders.is_some_and(|l| l > 1)
        || args.spread_above.is_some();
    if method != Method::Factored && factored_options {
        bail!(
            "--coupling, --max-component, --split, --regions, --leaders and --spread-above apply to --method factored, not to --method {}",
            method.name()
        );
    }
    if args.regions.is_some() && args.leaders.is_some() {
        bail!("--regions places the leaders itself: give --regions or --leaders, not both");
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
pub(crate) fn replay<R: BufRead>(
    args: &ReplayArgs,
    mut reader: TraceReader<R>,
    out: impl Write,
) -> Result<()> {
    let span = info_span!(
        "replay",
        trace = reader.source(),
        method = args.property_method().name()
    );
    let _entered = span.enter();

    let header = reader.read_header()?;
    let source = reader.source().to_string();
    let field = field_of(&header);
    check_size(args, &field).map_err(|e| anyhow!("{source}:1: header: {e}"))?;
    debug!(tracks = field.tracks, red = ?field.red.known(), known_start = field.initial_red.is_some(), "field");
    let red = field.red.known();
    let built = |e| line_error(&source)(1, "header", e);
    let recipe = recipe(args, field.tracks).map_err(built)?;
    match (region_rule(args, field.tracks), recipe) {
        (Some((rule, leaders)), Recipe::Factored(options)) => {
            let filter = Timed::start(|| {
                let belief = FactoredBelief::with_options(field.clone(), options)?;
                Ok(Box::new(Regional::new(
                    belief,
                    Regions::new(&rule, leaders, field.tracks),
                )))
            })
            .map_err(built)?;
            run_engine(args, reader, Engine::new(filter, red), out)
        }
        (_, recipe) => {
            let filter = Timed::start(|| recipe.build(field.clone())).map_err(built)?;
            run_engine(args, reader, Engine::new(filter, red), out)
        }
    }
}

/// The regional rule `args` ask for on a crowd of `tracks` tracks, with
/// its leader count: fixed places (`--regions`) or cells fitted to the
/// crowd (`--leaders`, more than one); none for a crowd held whole.
fn region_rule(args: &ReplayArgs, tracks: usize) -> Option<(RegionRule, usize)> {
    if args.whole(tracks) {
        return None;
    }
    match (&args.regions, args.leaders) {
        (Some(Places(places)), _) => Some((
            RegionRule::Fixed(places.iter().map(|&p| Some(p)).collect()),
            places.len(),
        )),
        (None, Some(leaders)) => Some((RegionRule::fitted(), usize::from(leaders))),
        _ => None,
    }
}

/// Drives `engine` over the rest of the trace and writes the summary.
fn run_engine<R: BufRead, F: PropertyFilter + Moves + ?Sized>(
    args: &ReplayArgs,
    reader: TraceReader<R>,
    mut engine: Engine<F>,
    mut out: impl Write,
) -> Result<()> {
    drive(reader, &mut engine, &mut out)?;

    // The final marginals first: a factored belief's query may count a
    // repair (its contradiction rule).
    let final_p_red = engine.filter.time(|f| f.marginals()).ok();
    let summary = Summary {
        kind: "summary",
        method: args.property_method().name(),
        events: engine.filter.events,
        seconds: engine.filter.time.as_secs_f64(),
        error: mean_error(&engine.errors),
        brier: mean_error(&engine.briers),
        log_loss: mean_error(&engine.log_losses),
        max_coefficients: engine.max_coefficients,
        repairs: engine.filter.filter.repairs(),
        final_p_red,
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

/// What a replayed filter does around each line: nothing, except under
/// the regional rule, whose handovers come before and after a line's
/// event ([`Regional::before`], [`Regional::after`]).
trait Moves {
    fn before(&mut self, line: &Line) -> Result<(), BeliefError>;
    fn after(&mut self, line: &Line) -> Result<(), BeliefError>;
}

impl Moves for dyn PropertyFilter {
    fn before(&mut self, _: &Line) -> Result<(), BeliefError> {
        Ok(())
    }
    fn after(&mut self, _: &Line) -> Result<(), BeliefError> {
        Ok(())
    }
}

impl Moves for Regional {
    fn before(&mut self, line: &Line) -> Result<(), BeliefError> {
        Regional::before(self, line)
    }
    fn after(&mut self, line: &Line) -> Result<(), BeliefError> {
        Regional::after(self, line)
    }
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

/// The filter `args.method` names, for the one factory; an identity method
/// is not one (`replay::dispatch` sends those to `replay::identity`).
fn recipe(args: &ReplayArgs, tracks: usize) -> Result<Recipe, BeliefError> {
    let radon = |sparsify: fn(usize) -> Sparsify| Recipe::Radon {
        sparsify: args.budget.map(sparsify),
        distributed_rule: args.distributed_rule,
    };
    Ok(match args.property_method() {
        Method::Overcomplete => radon(Sparsify::overcomplete),
        // `check_options` made sure the budget is there.
        Method::Threshold => radon(Sparsify::threshold),
        Method::Exact => Recipe::Exact,
        // The paper's projection alone leaves the simplex on real traces and
        // then refuses observations as impossible; the recipe repairs it.
        Method::Order1 => Recipe::Order(1),
        Method::Order2 => Recipe::Order(2),
        Method::Order3 => Recipe::Order(3),
        Method::Factored => Recipe::Factored(FactoredOptions {
            coupling: args.coupling(tracks),
            max_component: args
                .max_component
                .unwrap_or(FactoredOptions::default().max_component),
            split: match args.split {
                SplitChoice::Original => SplitRule::Original,
                SplitChoice::Recent => SplitRule::Recent,
                SplitChoice::LeastLoss => SplitRule::LeastLoss { rounds: 1 },
            },
            ..FactoredOptions::default()
        }),
        Method::Particles => Recipe::Particles {
            count: args.particles.unwrap_or(DEFAULT_PARTICLES),
            seed: args.seed.unwrap_or(0),
        },
        Method::ExactPerm
        | Method::BeliefMatrix
        | Method::InformationMatrix
        | Method::PropertyBits
        | Method::FactoredIdentity => {
            return Err(BeliefError::Unsupported {
                method: "the property replay",
                what: "an identity method",
            })
        }
    })
}

/// A property filter being replayed: its clock and counts, the largest
/// coefficient count seen, and the scores at the truth lines.
struct Engine<F: ?Sized> {
    filter: Timed<F>,
    /// k, when the trace fixes it (the prediction takes the top k).
    red: Option<usize>,
    max_coefficients: usize,
    errors: Vec<f64>,
    briers: Vec<f64>,
    log_losses: Vec<f64>,
}

impl<F: PropertyFilter + ?Sized> Engine<F> {
    fn new(filter: Timed<F>, red: Option<usize>) -> Self {
        let max_coefficients = filter.filter.coefficients();
        Engine {
            filter,
            red,
            max_coefficients,
            errors: Vec::new(),
            briers: Vec::new(),
            log_losses: Vec::new(),
        }
    }
}

impl<F: PropertyFilter + Moves + ?Sized> Replay for Engine<F> {
    type Event = Event;
    type Answer = Answer;

    fn event_of(line: &Line) -> Option<Event> {
        event_of(line)
    }

    fn before(&mut self, line: &Line) -> Result<(), BeliefError> {
        self.filter.time(|f| f.before(line))
    }

    fn after(&mut self, line: &Line) -> Result<(), BeliefError> {
        self.filter.time(|f| f.after(line))
    }

    fn apply(&mut self, event: &Event) -> Result<(), BeliefError> {
        self.filter.apply(|f| f.apply(event))?;
        let coefficients = self.filter.filter.coefficients();
        self.max_coefficients = self.max_coefficients.max(coefficients);
        debug!(coefficients, "applied");
        Ok(())
    }

    fn answer(&mut self, truth: &Truth) -> Result<Answer, BeliefError> {
        let p_red = self.filter.time(|f| f.marginals())?;
        let predicted_red = predict_red(&p_red, self.red);
        if let Some(red) = &truth.red {
            self.errors
                .push(expected_tracking_error(&p_red, self.red, red));
            self.briers.push(brier_score(&p_red, red));
            self.log_losses.push(log_loss(&p_red, red));
        }
        Ok(Answer {
            time: truth.time,
            p_red,
            predicted_red,
            coefficients: self.filter.filter.coefficients(),
        })
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::replay::args::{parse_places, CouplingChoice};
    use crate::replay::driver::output_lines;
    use idmesh_belief::Coupling;
    use idmesh_protocol::wire::factored::DEFAULT_SPREAD_ABOVE;
    use std::path::PathBuf;

    /// Replay arguments naming `method` and `budget`, nothing else.
    pub(in crate::replay) fn args(method: Method, budget: Option<usize>) -> ReplayArgs {
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
            coupling: None,
            max_component: None,
            split: SplitChoice::LeastLoss,
            regions: None,
            leaders: None,
            spread_above: None,
            topology: None,
        }
    }

    /// The replay's output lines, parsed, or its error as text.
    fn replay_text(args: &ReplayArgs, trace: &str) -> Result<Vec<serde_json::Value>, String> {
        output_lines(|out| {
            check_options(args)?;
            replay(args, TraceReader::new(trace.as_bytes(), "mem.jsonl"), out)
        })
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

    /// Without `--coupling`, the factored belief splits as the leaders of
    /// the same shape would: by the whole belief for one holder (also
    /// under the regions of one place, and on a crowd small enough to be
    /// held whole), by the local rule for several sharing a larger crowd.
    #[test]
    fn the_default_coupling_is_what_the_leaders_of_that_shape_compute() {
        let with = |leaders: Option<u16>, places: Option<&str>| ReplayArgs {
            leaders,
            regions: places.map(|p| parse_places(p).unwrap()),
            ..args(Method::Factored, None)
        };
        let large = DEFAULT_SPREAD_ABOVE as usize + 1;
        assert_eq!(with(None, None).coupling(large), Coupling::Coupled);
        assert_eq!(with(Some(1), None).coupling(large), Coupling::Coupled);
        assert_eq!(with(Some(4), None).coupling(large), Coupling::Local);
        assert_eq!(with(None, Some("0,0")).coupling(large), Coupling::Coupled);
        assert_eq!(with(None, Some("0,0;5,0")).coupling(large), Coupling::Local);
        // A small crowd is held whole by one of the leaders.
        let small = DEFAULT_SPREAD_ABOVE as usize;
        assert_eq!(with(Some(4), None).coupling(small), Coupling::Coupled);
        assert_eq!(
            with(None, Some("0,0;5,0")).coupling(small),
            Coupling::Coupled
        );
        assert!(region_rule(&with(Some(4), None), small).is_none());
        assert!(region_rule(&with(Some(4), None), large).is_some());
        let spread = ReplayArgs {
            spread_above: Some(0),
            ..with(Some(4), None)
        };
        assert_eq!(spread.coupling(small), Coupling::Local);
        assert!(region_rule(&spread, small).is_some());
        let named = ReplayArgs {
            coupling: Some(CouplingChoice::Flat),
            ..with(Some(4), None)
        };
        assert_eq!(named.coupling(large), Coupling::Flat);
    }

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

    /// `--regions`: leaders at x = 0 and x = 2 surveil tracks 0, 2 and
    /// 1, 3 (track mod 2) until moves say otherwise. Track 3 comes to
    /// leader 0 and mixes with 2; the mix of 1 and 3 across the regions is
    /// kept apart, and track 2 leaving for leader 1 is split off its
    /// component: the answer differs from the plain factored belief's. One
    /// region is the plain belief; a bad place or a Radon method is
    /// refused.
    #[test]
    fn regions_run_the_regional_rule_and_bad_places_are_refused() {
        let trace = concat!(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":4,"red":2,"initial_red":[0,1]}"#,
            "\n",
            r#"{"kind":"mix","time":1,"a":0,"b":2,"swap":0.5}"#,
            "\n",
            r#"{"kind":"move","time":1,"track":3,"x":0.5,"y":0}"#,
            "\n",
            r#"{"kind":"mix","time":2,"a":2,"b":3,"swap":0.3}"#,
            "\n",
            r#"{"kind":"mix","time":3,"a":1,"b":3,"swap":0.4}"#,
            "\n",
            r#"{"kind":"move","time":3,"track":2,"x":1.8,"y":0}"#,
            "\n",
            r#"{"kind":"observe","time":4,"track":2,"red":0.8,"blue":0.3}"#,
            "\n",
            r#"{"kind":"truth","time":4,"red":[1,2]}"#,
            "\n",
        );
        let factored = |regions: Option<&str>| {
            let mut a = args(Method::Factored, None);
            a.regions = regions.map(|r| parse_places(r).unwrap());
            // So small a crowd is held whole unless told to spread.
            a.spread_above = Some(0);
            let out = replay_text(&a, trace).unwrap();
            out[0]["p_red"].clone()
        };
        let plain = factored(None);
        assert_eq!(factored(Some("0,0")), plain);
        assert_ne!(factored(Some("0,0;2,0")), plain);
        for bad in ["1", "1,x", "1,2;", "inf,0"] {
            let e = parse_places(bad).unwrap_err();
            assert!(e.contains("is not a place"), "{bad}: {e}");
        }
        let mut radon = args(Method::Overcomplete, None);
        radon.regions = Some(parse_places("0,0;1,1").unwrap());
        let e = replay_text(&radon, TABLE1).unwrap_err();
        assert!(e.contains("--regions"), "{e}");
    }

    #[test]
    fn engine_errors_name_their_line() {
        // The low-order filters need k: the header's line is named.
        let trace = concat!(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3}"#,
            "\n",
            r#"{"kind":"mix","time":0,"a":1,"b":2,"swap":0.5}"#,
            "\n",
        );
        let error = replay_text(&args(Method::Order2, None), trace).unwrap_err();
        assert!(
            error.starts_with("mem.jsonl:1: header: ") && error.contains("unknown number"),
            "{error}"
        );
        // A sighting the stream rules out is no error: it is taken by the
        // repair rule (`idmesh_belief`'s `repair`).
        let contradicting = concat!(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"initial_red":[0]}"#,
            "\n",
            r#"{"kind":"observe","time":0,"track":1,"red":1,"blue":0}"#,
            "\n",
        );
        let out = replay_text(&args(Method::Overcomplete, None), contradicting).unwrap();
        assert_eq!(out[0]["final_p_red"][1], 1.0);
    }

    #[test]
    fn an_identity_method_is_no_property_filter() {
        let error = replay_text(&args(Method::InformationMatrix, None), TABLE1).unwrap_err();
        assert!(
            error.starts_with("mem.jsonl:1: header: ") && error.contains("identity method"),
            "{error}"
        );
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
}
