//! `idmesh replay` on identity traces: run one identity filter over a
//! recorded trace, offline.
//!
//! The header must say `identities` (an identity trace, shared/spec/trace.md);
//! `initial_identity`, when present, is the known start, otherwise every
//! assignment is equally likely. `mix` and `identify` lines are applied in
//! order (`observe` and `move` lines mean nothing to an identity filter and
//! are skipped); at every `truth` line one JSON line is written,
//!
//! ```text
//! {"time":T,"p_identity":[{"rest":r,"listed":[[i,p],…]},…],"predicted_identity":[…]}
//! ```
//!
//! with `p_identity[t]` track t's marginals by row
//! ([`idmesh_identity::SparseMarginals`]: P(track t carries
//! identity i) = p where `listed` holds \[i, p\], `rest` otherwise) and
//! `predicted_identity[t]` the identity of track t in the most likely
//! one-to-one assignment under those marginals (Hungarian algorithm on
//! −ln p); at the end a summary line
//!
//! ```text
//! {"kind":"summary","method":"…","events":E,"seconds":S,"error":X}
//! ```
//!
//! with the events applied, the filter's own time (building it, applying
//! events, computing marginals and the assignment — not reading or
//! printing) and the mean identity error (the share of tracks whose
//! predicted identity is wrong) over the `truth` lines that carry
//! `identity` (`null` when none do).
//!
//! Every error — a bad line, an event the engine rejects, a trace the method
//! cannot take — is reported as `FILE:LINE: reason` and ends the replay.
//!
//! The methods ([`IdentityMethod`]) are the engine's identity filters
//! (`idmesh_identity`): the exact filter over the N! assignments
//! (N ≤ 9), the belief matrix, the information matrix with marginals on
//! demand ([`MarginalChoice`]), identities coded by property bits (one
//! Radon property belief per bit, `--bits`, optional `--budget`), and the
//! factored identity belief (exact over the groups of tracks that mixed,
//! `--max-component` slots — tracks and link ports — per group at most,
//! linked cuts above it).
//!
//! With no `--method` replay runs what a deployment's leaders hold at
//! their defaults, so that what a user checks offline is what the
//! deployment answers: on a trace with a known start
//! ([`DEFAULT_IDENTITY_METHOD`]) the factored identity belief, exact up to
//! 9 mixed tracks and calibrated beyond (docs/design/identity.md,
//! "Factored identity belief"); without one
//! ([`IDENTITY_METHOD_WITHOUT_START`]) the information matrix, since the
//! factored belief of an unknown start is one group of all n tracks.

use super::args::ReplayArgs;
use super::driver::{drive, finish, line_error, mean_error, Replay, Timed};
use super::limits::binomial;
use anyhow::{anyhow, bail, Context, Result};
use clap::{Args, ValueEnum};
use idmesh_belief::{BeliefError, RadonOptions, Sparsify};
use idmesh_identity::factored::MAX_GROUP;
use idmesh_identity::scoring::IdentityScores;
use idmesh_identity::DEFAULT_SAMPLES;
use idmesh_identity::KNOWN_START_CONFIDENCE;
use idmesh_identity::MAX_PERMANENT_TRACKS;
use idmesh_identity::{
    identity_error, identity_event_of, BeliefMatrix, BitCode, ExactPermutationFilter,
    FactoredIdentity, FactoredIdentityOptions, IdentityEvent, IdentityFilter, IdentityRow,
    InformationMatrix, InformationOptions, MarginalMethod, PropertyBitsFilter, SparseMarginals,
};
use idmesh_protocol::trace::{Header, Line, TraceReader, Truth};
use serde::Serialize;
use std::io::{BufRead, Write};
use std::path::PathBuf;
use tracing::{debug, info, info_span, warn};

/// The options of an identity replay; a `clap` argument group, so it can be
/// flattened into a subcommand.
#[derive(Debug, Clone, PartialEq, Args)]
pub(crate) struct IdentityReplayOptions {
    /// The identity trace to replay (JSON Lines, shared/spec/trace.md).
    #[arg(long, value_name = "FILE")]
    pub trace: PathBuf,

    /// The identity filter to run.
    #[arg(long, value_enum, default_value_t = DEFAULT_IDENTITY_METHOD)]
    pub method: IdentityMethod,

    /// The most tracks of one group of --method factored-identity (2 to 9,
    /// default 9: the exact posterior up to 9 tracks).
    #[arg(long = "max-component", value_name = "M")]
    pub max_group: Option<usize>,

    /// How --method information-matrix turns its log-likelihoods into
    /// marginals (default exact, N ≤ 22).
    #[arg(long, value_enum)]
    pub marginals: Option<MarginalChoice>,

    /// The number of property bits of --method property-bits (at least
    /// ⌈log₂ N⌉, at most 16; default ⌈log₂ N⌉).
    #[arg(long, value_name = "B", value_parser = parse_positive)]
    pub bits: Option<usize>,

    /// The most Radon coefficients each bit's belief of --method
    /// property-bits may hold after an event (OMP, then thresholding);
    /// none = exact bit beliefs.
    #[arg(long, value_name = "N", value_parser = parse_positive)]
    pub budget: Option<usize>,

    /// The seed of --marginals metropolis.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,

    /// Counted steps of --marginals metropolis (default 10,000; a tenth as
    /// many burn-in steps before them, per block of mixed tracks).
    #[arg(long, value_name = "S", value_parser = parse_positive)]
    pub samples: Option<usize>,

    /// The known start of --method information-matrix as log-odds C
    /// against each other identity (C > 0); default exact (+∞: −∞ on
    /// every other identity, which keeps independent blocks). On long
    /// streams where all tracks have mixed, C = 3 is better calibrated
    /// (docs/design/identity.md, "Calibration").
    #[arg(long, value_name = "C", value_parser = parse_confidence)]
    pub known_start_confidence: Option<f64>,

    /// Run --method property-bits without --budget even where its exact
    /// bit beliefs are estimated to exceed [`MAX_EXACT_BIT_STATES`].
    #[arg(long)]
    pub force: bool,
}

/// The identity method replay runs when none is named on a trace with a
/// known start: the factored identity belief, which a deployment's
/// leaders hold there by default, so that replay without options
/// computes what a deployment serves.
pub(crate) const DEFAULT_IDENTITY_METHOD: IdentityMethod = IdentityMethod::FactoredIdentity;

/// The identity method replay runs when none is named on a trace without
/// a known start: the information matrix, whose rows the leaders keep
/// there.
pub(crate) const IDENTITY_METHOD_WITHOUT_START: IdentityMethod = IdentityMethod::InformationMatrix;

/// The default group cap of --method factored-identity in replay.
pub(crate) const DEFAULT_REPLAY_MAX_GROUP: usize = idmesh_identity::factored::DEFAULT_MAX_GROUP;

/// The most states an exact bit belief of --method property-bits may need
/// (the largest C(n, identities with the bit set)) before replay refuses
/// it without --force: C(22, 11) ≈ 7·10^5 passes, n = 23 with 12 bits set
/// does not. At n = 30 the exact bits took more than 3 minutes and 6.6 GB.
pub(crate) const MAX_EXACT_BIT_STATES: f64 = 1e6;

/// Above this many states replay warns (in the log) before running exact
/// bit beliefs.
pub(crate) const WARN_EXACT_BIT_STATES: f64 = 1e4;

/// `idmesh replay` on an identity trace: the identity options from the
/// command line's, with the identity default when no method is named.
pub(crate) fn run_default(args: &ReplayArgs, out: impl Write) -> Result<()> {
    let method = match args.method {
        None => {
            let header = TraceReader::open(&args.trace)
                .with_context(|| format!("cannot open trace {}", args.trace.display()))?
                .read_header()?;
            match header.initial_identity {
                Some(_) => DEFAULT_IDENTITY_METHOD,
                None => IDENTITY_METHOD_WITHOUT_START,
            }
        }
        Some(m) => m
            .identity()
            .ok_or_else(|| anyhow!("--method {} is not an identity method", m.name()))?,
    };
    if let Some(particles) = args.particles {
        bail!("--particles {particles} applies to --method particles, not to an identity trace");
    }
    if args.distributed_rule {
        bail!("--distributed-rule applies to the Radon property methods, not to an identity trace");
    }
    let options = IdentityReplayOptions {
        trace: args.trace.clone(),
        method,
        marginals: args.marginals,
        bits: args.bits,
        budget: args.budget,
        seed: args.seed.unwrap_or(0),
        samples: args.samples,
        force: args.force,
        known_start_confidence: args.known_start_confidence,
        max_group: args.max_component,
    };
    run(&options, out)
}

/// The identity filters replay can run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub(crate) enum IdentityMethod {
    /// The exact filter over all N! assignments (N ≤ 9).
    ExactPerm,
    /// The belief matrix: doubly stochastic marginals, renormalized after
    /// every read (Shin, Guibas and Zhao 2003).
    BeliefMatrix,
    /// The information matrix: accumulated log-likelihoods, marginals on
    /// demand by --marginals (Shin et al. 2005).
    InformationMatrix,
    /// Identities coded by --bits binary properties, one Radon property
    /// belief per bit (Jiang et al., TOSN 2013, Section 5.5).
    PropertyBits,
    /// Exact over the groups of tracks that mixed, the least lossy cut —
    /// linked: one exchange kept across it — when a group would outgrow
    /// --max-component slots (split/join).
    FactoredIdentity,
}

impl IdentityMethod {
    /// The name on the command line and in the summary.
    pub(crate) fn name(self) -> &'static str {
        match self {
            IdentityMethod::ExactPerm => "exact-perm",
            IdentityMethod::BeliefMatrix => "belief-matrix",
            IdentityMethod::InformationMatrix => "information-matrix",
            IdentityMethod::PropertyBits => "property-bits",
            IdentityMethod::FactoredIdentity => "factored-identity",
        }
    }
}

/// How an information matrix is turned into marginals (each on every
/// independent block of mixed tracks alone).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ValueEnum)]
pub enum MarginalChoice {
    /// Exact on blocks of at most 16 tracks, half-Bethe up to 100,
    /// Metropolis (1,000 steps per track) on larger ones.
    #[default]
    Auto,
    /// Exact, by the matrix permanent (blocks of at most 22 tracks).
    Exact,
    /// The paper's Metropolis sampler (--samples, --seed).
    Metropolis,
    /// Sinkhorn scaling of exp(L): cheap, deterministic, under-confident.
    Sinkhorn,
    /// The fractional Bethe fixed point with γ = ½ (exact for N = 2).
    Bethe,
}

impl MarginalChoice {
    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            MarginalChoice::Auto => "auto",
            MarginalChoice::Exact => "exact",
            MarginalChoice::Metropolis => "metropolis",
            MarginalChoice::Sinkhorn => "sinkhorn",
            MarginalChoice::Bethe => "bethe",
        }
    }
}

/// The answers at one `truth` line.
#[derive(Debug, Serialize)]
pub struct Answer {
    time: f64,
    p_identity: Vec<IdentityRow>,
    predicted_identity: Vec<u32>,
}

/// The last line of a replay.
#[derive(Debug, Serialize)]
struct Summary {
    kind: &'static str,
    method: &'static str,
    events: u64,
    seconds: f64,
    error: Option<f64>,
    /// Scores of the marginals at the truth lines with `identity` (absent
    /// when none has): Brier, log-loss, MAP accuracy, IDF1.
    #[serde(skip_serializing_if = "Option::is_none")]
    scores: Option<Scores>,
}

/// The tracker scores of a replay's summary.
#[derive(Debug, Serialize)]
struct Scores {
    brier: f64,
    log_loss: f64,
    map_accuracy: f64,
    idf1: f64,
    /// (mean predicted p, observed frequency, count) per bin of ten.
    reliability: Vec<(f64, f64, u64)>,
}

/// Replays the identity trace named by `args` and writes the answers to
/// `out`.
pub fn run(args: &IdentityReplayOptions, out: impl Write) -> Result<()> {
    check_options(args)?;
    let reader = TraceReader::open(&args.trace)
        .with_context(|| format!("cannot open trace {}", args.trace.display()))?;
    replay(args, reader, out)
}

/// Refuses flags that make no sense together, before anything is read.
pub(crate) fn check_options(args: &IdentityReplayOptions) -> Result<()> {
    let method = args.method;
    if method != IdentityMethod::PropertyBits {
        if args.bits.is_some() {
            bail!(
                "--bits applies to --method property-bits, not to --method {}",
                method.name()
            );
        }
        if args.budget.is_some() {
            bail!(
                "--budget applies to --method property-bits, not to --method {}",
                method.name()
            );
        }
    }
    if method != IdentityMethod::InformationMatrix {
        if let Some(m) = args.marginals {
            bail!(
                "--marginals {} applies to --method information-matrix, not to --method {}",
                m.name(),
                method.name()
            );
        }
    }
    if args.known_start_confidence.is_some() && method != IdentityMethod::InformationMatrix {
        bail!(
            "--known-start-confidence applies to --method information-matrix, not to --method {}",
            method.name()
        );
    }
    if let Some(m) = args.max_group {
        if method != IdentityMethod::FactoredIdentity {
            bail!(
                "--max-component applies to --method factored-identity on an identity trace, \
                 not to --method {}",
                method.name()
            );
        }
        if !(2..=MAX_GROUP).contains(&m) {
            bail!("--max-component {m}: a group holds 2 to {MAX_GROUP} tracks");
        }
    }
    if args.force && method != IdentityMethod::PropertyBits {
        bail!(
            "--force applies to --method property-bits, not to --method {}",
            method.name()
        );
    }
    if args.samples.is_some() && args.marginals != Some(MarginalChoice::Metropolis) {
        bail!("--samples applies to --marginals metropolis");
    }
    Ok(())
}

/// Replays a trace from any reader (the testable core of [`run`]).
pub(crate) fn replay<R: BufRead>(
    args: &IdentityReplayOptions,
    mut reader: TraceReader<R>,
    mut out: impl Write,
) -> Result<()> {
    let span = info_span!(
        "replay_identity",
        trace = reader.source(),
        method = args.method.name()
    );
    let _entered = span.enter();

    let header = reader.read_header()?;
    let source = reader.source().to_string();
    let n = match header.identities {
        Some(n) => n,
        None => bail!(
            "{source}:1: header: not an identity trace (no `identities`); \
             replay it with a property method"
        ),
    };
    debug!(
        identities = n,
        known_start = header.initial_identity.is_some(),
        "identities"
    );
    let filter = Timed::start(|| build(args, &header)).map_err(|e| match e {
        Built::Engine(e) => line_error(&source)(1, "header", e),
        Built::Refused(reason) => anyhow!("{source}:1: header: {reason}"),
    })?;
    let mut engine = Engine {
        filter,
        errors: Vec::new(),
        scored: Vec::new(),
    };
    drive(reader, &mut engine, &mut out)?;
    let scores = if engine.scored.is_empty() {
        None
    } else {
        let mut pooled = IdentityScores::default();
        pooled
            .add_stream(&engine.scored)
            .map_err(|e| anyhow!("{source}: scoring: {e}"))?;
        let s = pooled.summary();
        Some(Scores {
            brier: s.brier,
            log_loss: s.log_loss,
            map_accuracy: s.map_accuracy,
            idf1: s.idf1,
            reliability: pooled.reliability.points(),
        })
    };

    let summary = Summary {
        kind: "summary",
        method: args.method.name(),
        events: engine.filter.events,
        seconds: engine.filter.time.as_secs_f64(),
        error: mean_error(&engine.errors),
        scores,
    };
    info!(
        events = summary.events,
        seconds = summary.seconds,
        error = ?summary.error,
        "replayed"
    );
    finish(out, &summary)
}

/// Why no filter could be built for a header.
enum Built {
    /// The engine refused (e.g. too many tracks for the exact filter).
    Engine(BeliefError),
    /// The options do not fit this trace.
    Refused(String),
}

impl From<BeliefError> for Built {
    fn from(e: BeliefError) -> Self {
        Built::Engine(e)
    }
}

/// The marginal method `args` asks for.
fn marginal_method(args: &IdentityReplayOptions) -> MarginalMethod {
    let choice = args.marginals.unwrap_or_default();
    let samples = args.samples.unwrap_or(DEFAULT_SAMPLES);
    MarginalMethod::named(choice.name(), samples, args.seed).unwrap_or_default()
}

/// The filter `args.method` names, for the trace `header` (which has
/// `identities`).
fn build(args: &IdentityReplayOptions, header: &Header) -> Result<Box<dyn IdentityFilter>, Built> {
    let n = header.tracks;
    let initial = header.initial_identity.as_deref();
    Ok(match args.method {
        IdentityMethod::ExactPerm => Box::new(match initial {
            Some(start) => ExactPermutationFilter::from_assignment(start)?,
            None => ExactPermutationFilter::uniform(n)?,
        }),
        IdentityMethod::BeliefMatrix => Box::new(match initial {
            Some(start) => BeliefMatrix::from_assignment(start)?,
            None => BeliefMatrix::uniform(n)?,
        }),
        IdentityMethod::InformationMatrix => {
            let choice = args.marginals.unwrap_or_default();
            // Without a known start the whole matrix is one block; with
            // one, blocks are known only at a query, which then says which
            // block is too large.
            if choice == MarginalChoice::Exact && initial.is_none() && n > MAX_PERMANENT_TRACKS {
                return Err(Built::Refused(format!(
                    "exact marginals take blocks of at most {MAX_PERMANENT_TRACKS} \
                     tracks, and with no known start (`initial_identity`) the {n} \
                     tracks are one block; use --marginals auto, metropolis, sinkhorn \
                     or bethe"
                )));
            }
            let options = InformationOptions {
                marginals: marginal_method(args),
                ..InformationOptions::default()
            };
            Box::new(match initial {
                Some(start) => InformationMatrix::from_assignment(
                    start,
                    args.known_start_confidence
                        .unwrap_or(KNOWN_START_CONFIDENCE),
                    options,
                )?,
                None => InformationMatrix::uniform_with(n, options)?,
            })
        }
        IdentityMethod::FactoredIdentity => {
            let options = FactoredIdentityOptions {
                max_group: args.max_group.unwrap_or(DEFAULT_REPLAY_MAX_GROUP),
                ..FactoredIdentityOptions::default()
            };
            match initial {
                Some(start) => Box::new(FactoredIdentity::from_assignment(start, options)?),
                None if n <= options.max_group => Box::new(FactoredIdentity::uniform(n, options)?),
                None => {
                    return Err(Built::Refused(format!(
                        "--method factored-identity starts from a known assignment or from \
                         one group of all tracks, and with no known start \
                         (`initial_identity`) the {n} tracks are more than its groups hold \
                         ({}); use information-matrix",
                        options.max_group
                    )))
                }
            }
        }
        IdentityMethod::PropertyBits => {
            let bits = args.bits.unwrap_or_else(|| BitCode::min_bits(n));
            let code = BitCode::new(n, bits).map_err(|_| {
                Built::Refused(format!(
                    "--bits {bits} cannot code {n} identities: it takes from {} to 16 bits",
                    BitCode::min_bits(n)
                ))
            })?;
            if args.budget.is_none() {
                let states = exact_bit_states(&code);
                if states > MAX_EXACT_BIT_STATES && !args.force {
                    return Err(Built::Refused(format!(
                        "--method property-bits without --budget keeps every bit's belief \
                         exactly, which is exponential: here up to {states:.1e} states per \
                         bit ({bits} bits), above the limit of {MAX_EXACT_BIT_STATES:.0e} \
                         (at n = 30, 1.6e8 states, it took more than 3 minutes and \
                         6.6 GB); give --budget N (200 is the paper's) or --force"
                    )));
                }
                if states > WARN_EXACT_BIT_STATES {
                    warn!(
                        states,
                        bits, "property-bits without --budget: exact bit beliefs, exponential"
                    );
                }
            }
            let options = RadonOptions {
                sparsify: args.budget.map(Sparsify::overcomplete),
                ..RadonOptions::default()
            };
            Box::new(PropertyBitsFilter::new(code, initial, options)?)
        }
    })
}

/// The most states an exact bit belief of `code` can hold: the largest
/// C(n, k) over the bits, k the identities with the bit set (the red sets
/// of that bit's property belief).
pub(crate) fn exact_bit_states(code: &BitCode) -> f64 {
    let n = code.identities();
    (0..code.bits())
        .map(|j| binomial(n, code.red_count(j)))
        .fold(1.0, f64::max)
}

/// An identity filter being replayed: its clock and counts, and the
/// errors at the truth lines that carry identities.
struct Engine {
    filter: Timed<dyn IdentityFilter>,
    errors: Vec<f64>,
    /// The marginals and truth at every truth line with `identity`, for
    /// the scores of the summary.
    scored: Vec<(SparseMarginals, Vec<u32>)>,
}

impl Replay for Engine {
    type Event = IdentityEvent;
    type Answer = Answer;

    fn event_of(line: &Line) -> Option<IdentityEvent> {
        identity_event_of(line)
    }

    fn apply(&mut self, event: &IdentityEvent) -> Result<(), BeliefError> {
        self.filter.apply(|f| f.apply(event))
    }

    /// The marginals and the most likely assignment under them.
    fn answer(&mut self, truth: &Truth) -> Result<Answer, BeliefError> {
        let (p_identity, predicted_identity) = self.filter.time(|filter| {
            filter
                .sparse_marginals()
                .and_then(|p| p.most_likely().map(|best| (p, best)))
        })?;
        if let Some(identity) = &truth.identity {
            self.errors
                .push(identity_error(&predicted_identity, identity));
            self.scored.push((p_identity.clone(), identity.clone()));
        }
        Ok(Answer {
            time: truth.time,
            p_identity: p_identity.into_rows(),
            predicted_identity,
        })
    }
}

fn parse_confidence(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(c) if c > 0.0 && !c.is_nan() => Ok(c),
        Ok(c) => Err(format!("{c}: must be positive (inf = exact)")),
        Err(e) => Err(format!("not a number: {e}")),
    }
}

fn parse_positive(text: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(0) => Err("must be at least 1".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(format!("not a whole number: {e}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::replay::driver::output_lines;
    use clap::Parser;

    fn new(trace: &str, method: IdentityMethod) -> IdentityReplayOptions {
        IdentityReplayOptions {
            trace: trace.into(),
            method,
            marginals: None,
            bits: None,
            budget: None,
            seed: 0,
            samples: None,
            force: false,
            known_start_confidence: None,
            max_group: None,
        }
    }

    fn options(method: IdentityMethod) -> IdentityReplayOptions {
        new("mem.jsonl", method)
    }

    /// The replay's output lines, parsed, or its error as text.
    fn replay_text(
        args: &IdentityReplayOptions,
        trace: &str,
    ) -> Result<Vec<serde_json::Value>, String> {
        output_lines(|out| {
            check_options(args)?;
            replay(args, TraceReader::new(trace.as_bytes(), "mem.jsonl"), out)
        })
    }

    /// The dense matrix of an answer's rows.
    fn matrix(value: &serde_json::Value) -> Vec<Vec<f64>> {
        let rows: Vec<IdentityRow> = serde_json::from_value(value.clone()).unwrap();
        SparseMarginals::new(rows).unwrap().dense()
    }

    /// Three people with known identities; tracks 0 and 1 mix with
    /// probability ½, a reader says identity 0 (accuracy 0.9) on track 0; a
    /// colour sighting and a move in between are skipped. The exact
    /// posterior of "no swap" is 0.9/(0.9 + 0.05) = 18/19.
    const SMALL: &str = concat!(
        r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"red":1,"identities":3,"initial_identity":[0,1,2]}"#,
        "\n",
        r#"{"kind":"mix","time":1,"a":0,"b":1,"swap":0.5}"#,
        "\n",
        r#"{"kind":"observe","time":1.5,"track":2,"red":0.8,"blue":0.2}"#,
        "\n",
        r#"{"kind":"move","time":1.5,"track":2,"x":3,"y":4}"#,
        "\n",
        r#"{"kind":"truth","time":1.5,"red":[2]}"#,
        "\n",
        r#"{"kind":"identify","time":2,"track":0,"identity":0,"accuracy":0.9}"#,
        "\n",
        r#"{"kind":"truth","time":3,"identity":[0,1,2]}"#,
        "\n",
    );

    fn assert_close(got: &[Vec<f64>], want: &[Vec<f64>], tolerance: f64) {
        for (g, w) in got.iter().flatten().zip(want.iter().flatten()) {
            assert!((g - w).abs() < tolerance, "{got:?} vs {want:?}");
        }
    }

    #[test]
    fn exact_and_information_matrix_give_the_exact_posterior() {
        let (s, r) = (18.0 / 19.0, 1.0 / 19.0);
        let posterior = vec![vec![s, r, 0.0], vec![r, s, 0.0], vec![0.0, 0.0, 1.0]];
        let half = vec![
            vec![0.5, 0.5, 0.0],
            vec![0.5, 0.5, 0.0],
            vec![0.0, 0.0, 1.0],
        ];
        let mut infos = vec![options(IdentityMethod::InformationMatrix)];
        for m in [
            MarginalChoice::Exact,
            MarginalChoice::Metropolis,
            MarginalChoice::Bethe,
        ] {
            let mut o = options(IdentityMethod::InformationMatrix);
            o.marginals = Some(m);
            infos.push(o);
        }
        for (k, args) in [
            options(IdentityMethod::ExactPerm),
            options(IdentityMethod::FactoredIdentity),
        ]
        .into_iter()
        .chain(infos)
        .enumerate()
        {
            let out = replay_text(&args, SMALL).unwrap();
            assert_eq!(out.len(), 3, "{out:?}");
            // Metropolis is an estimate: 10,000 samples.
            let tolerance = if args.marginals == Some(MarginalChoice::Metropolis) {
                0.02
            } else {
                1e-8
            };
            assert_eq!(out[0]["time"], 1.5);
            assert_close(&matrix(&out[0]["p_identity"]), &half, tolerance);
            assert_eq!(out[1]["time"], 3.0);
            assert_close(&matrix(&out[1]["p_identity"]), &posterior, tolerance);
            assert_eq!(out[1]["predicted_identity"], serde_json::json!([0, 1, 2]));
            let summary = &out[2];
            assert_eq!(summary["kind"], "summary", "case {k}");
            assert_eq!(summary["method"], args.method.name());
            assert_eq!(summary["events"], 2);
            // Only the truth line with `identity` is scored.
            assert_eq!(summary["error"], 0.0);
            assert!(summary["seconds"].as_f64().unwrap() >= 0.0);
            let keys: Vec<&String> = summary.as_object().unwrap().keys().collect();
            assert_eq!(keys.len(), 6, "{keys:?}");
            // One scored line, predicted right with p = 18/19 on tracks 0
            // and 1 (Metropolis: about).
            let scores = &summary["scores"];
            assert_eq!(scores["map_accuracy"], 1.0);
            assert_eq!(scores["idf1"], 1.0);
            let log_loss = -(2.0 * (18.0f64 / 19.0).ln()) / 3.0;
            assert!((scores["log_loss"].as_f64().unwrap() - log_loss).abs() < tolerance);
        }
    }

    #[test]
    fn belief_matrix_and_property_bits_on_the_small_trace() {
        // The belief matrix keeps the 2 × 2 cross ratio: odds √18.
        let out = replay_text(&options(IdentityMethod::BeliefMatrix), SMALL).unwrap();
        let odds = 18f64.sqrt();
        let p = matrix(&out[1]["p_identity"]);
        assert!((p[0][0] - odds / (1.0 + odds)).abs() < 1e-9, "{p:?}");
        assert_eq!(out[2]["method"], "belief-matrix");
        assert_eq!(out[2]["error"], 0.0);
        // Property bits (2 bits by default, 3 and a budget on request).
        for (bits, budget) in [(None, None), (Some(3), Some(4))] {
            let mut args = options(IdentityMethod::PropertyBits);
            args.bits = bits;
            args.budget = budget;
            let out = replay_text(&args, SMALL).unwrap();
            let p = matrix(&out[1]["p_identity"]);
            assert!(p[0][0] > 0.8 && p[2][2] > 0.999, "{p:?}");
            assert_eq!(out[1]["predicted_identity"], serde_json::json!([0, 1, 2]));
            assert_eq!(out[2]["method"], "property-bits");
            assert_eq!(out[2]["error"], 0.0);
        }
    }

    #[test]
    fn the_error_is_the_mean_over_scored_truth_lines() {
        // Uniform start, no events: the prediction is some assignment; a
        // sure read pins track 0 and the two truths disagree on the rest.
        let trace = concat!(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":2,"identities":2}"#,
            "\n",
            r#"{"kind":"identify","time":0,"track":0,"identity":1,"accuracy":0.99}"#,
            "\n",
            r#"{"kind":"truth","time":1,"identity":[1,0]}"#,
            "\n",
            r#"{"kind":"truth","time":2,"identity":[0,1]}"#,
            "\n",
        );
        for method in [
            IdentityMethod::ExactPerm,
            IdentityMethod::BeliefMatrix,
            IdentityMethod::InformationMatrix,
            IdentityMethod::PropertyBits,
            IdentityMethod::FactoredIdentity,
        ] {
            let out = replay_text(&options(method), trace).unwrap();
            assert_eq!(out[0]["predicted_identity"], serde_json::json!([1, 0]));
            // Right at time 1, both tracks wrong at time 2: mean ½.
            assert_eq!(out[2]["error"], 0.5, "{}", method.name());
        }
    }

    #[test]
    fn no_identity_truth_means_no_error() {
        let trace = concat!(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"identities":3}"#,
            "\n",
            r#"{"kind":"mix","time":0,"a":0,"b":2,"swap":0.3}"#,
            "\n",
        );
        let out = replay_text(&options(IdentityMethod::BeliefMatrix), trace).unwrap();
        assert_eq!(out.len(), 1);
        assert_eq!(out[0]["error"], serde_json::Value::Null);
        assert_eq!(out[0]["events"], 1);
    }

    #[test]
    fn engine_errors_name_their_line() {
        // A perfect read that contradicts the known start.
        let trace = concat!(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"identities":3,"initial_identity":[0,1,2]}"#,
            "\n",
            r#"{"kind":"mix","time":0,"a":0,"b":1,"swap":0.5}"#,
            "\n",
            r#"{"kind":"identify","time":1,"track":2,"identity":0,"accuracy":1}"#,
            "\n",
        );
        let exact = replay_text(&options(IdentityMethod::ExactPerm), trace).unwrap_err();
        assert!(exact.starts_with("mem.jsonl:3: identify: "), "{exact}");
        // The information matrix refuses any perfect read.
        let info = replay_text(&options(IdentityMethod::InformationMatrix), trace).unwrap_err();
        assert!(info.starts_with("mem.jsonl:3: identify: "), "{info}");
        // A line that breaks the format stops the replay at that line.
        let bad = concat!(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"identities":3}"#,
            "\n",
            r#"{"kind":"identify","time":0,"track":0,"identity":5,"accuracy":0.9}"#,
            "\n",
        );
        let error = replay_text(&options(IdentityMethod::BeliefMatrix), bad).unwrap_err();
        assert!(error.starts_with("mem.jsonl:2: "), "{error}");
    }

    #[test]
    fn traces_the_method_cannot_take_are_refused_at_the_header() {
        let property = concat!(
            r#"{"kind":"header","format":"idmesh-trace","version":1,"tracks":3,"red":1}"#,
            "\n",
        );
        let error = replay_text(&options(IdentityMethod::BeliefMatrix), property).unwrap_err();
        assert!(
            error.starts_with("mem.jsonl:1: header: not an identity trace"),
            "{error}"
        );
        let big = |n: usize| {
            format!(
                r#"{{"kind":"header","format":"idmesh-trace","version":1,"tracks":{n},"identities":{n}}}"#
            ) + "\n"
        };
        let error = replay_text(&options(IdentityMethod::ExactPerm), &big(10)).unwrap_err();
        assert!(error.starts_with("mem.jsonl:1: header: "), "{error}");
        let mut exact = options(IdentityMethod::InformationMatrix);
        exact.marginals = Some(MarginalChoice::Exact);
        let error = replay_text(&exact, &big(23)).unwrap_err();
        assert!(
            error.starts_with("mem.jsonl:1: header: exact marginals take blocks of at most 22"),
            "{error}"
        );
        // The default (auto) answers any size.
        let out = replay_text(&options(IdentityMethod::InformationMatrix), &big(23)).unwrap();
        assert_eq!(out[0]["kind"], "summary");
        // Exact bit beliefs are refused above the limit, with an estimate,
        // unless forced or given a budget.
        let error = replay_text(&options(IdentityMethod::PropertyBits), &big(30)).unwrap_err();
        assert!(
            error.contains("without --budget") && error.contains("states per bit"),
            "{error}"
        );
        let mut budget = options(IdentityMethod::PropertyBits);
        budget.budget = Some(50);
        assert!(replay_text(&budget, &big(30)).is_ok());
        let mut forced = options(IdentityMethod::PropertyBits);
        forced.force = true;
        assert!(replay_text(&forced, &big(30)).is_ok());
        assert!(replay_text(&options(IdentityMethod::PropertyBits), &big(20)).is_ok());
        let mut sinkhorn = options(IdentityMethod::InformationMatrix);
        sinkhorn.marginals = Some(MarginalChoice::Sinkhorn);
        let out = replay_text(&sinkhorn, &big(23)).unwrap();
        assert_eq!(out[0]["kind"], "summary");
        let mut bits = options(IdentityMethod::PropertyBits);
        bits.bits = Some(2);
        let error = replay_text(&bits, &big(5)).unwrap_err();
        assert!(
            error.starts_with("mem.jsonl:1: header: --bits 2 cannot code 5"),
            "{error}"
        );
    }

    #[test]
    fn a_finite_known_start_is_the_old_encoding() {
        // With log-odds 3 the known start leaves weight on every identity:
        // track 2, never mixed, is no longer certain.
        let mut args = options(IdentityMethod::InformationMatrix);
        args.known_start_confidence = Some(3.0);
        let out = replay_text(&args, SMALL).unwrap();
        let p = matrix(&out[1]["p_identity"]);
        assert!(p[2][2] < 1.0 && p[2][2] > 0.5, "{p:?}");
        let exact = replay_text(&options(IdentityMethod::InformationMatrix), SMALL).unwrap();
        assert_eq!(matrix(&exact[1]["p_identity"])[2][2], 1.0);
        let mut wrong = options(IdentityMethod::BeliefMatrix);
        wrong.known_start_confidence = Some(3.0);
        assert!(check_options(&wrong)
            .unwrap_err()
            .to_string()
            .contains("--known-start-confidence applies"));
        assert!(parse_confidence("0").is_err() && parse_confidence("inf").is_ok());
    }

    #[test]
    fn options_that_do_not_fit_are_refused() {
        let mut args = options(IdentityMethod::BeliefMatrix);
        args.bits = Some(4);
        assert!(check_options(&args)
            .unwrap_err()
            .to_string()
            .contains("--bits applies"));
        args.bits = None;
        args.budget = Some(10);
        assert!(check_options(&args).is_err());
        args.budget = None;
        args.marginals = Some(MarginalChoice::Sinkhorn);
        assert!(check_options(&args)
            .unwrap_err()
            .to_string()
            .contains("--marginals sinkhorn applies"));
        let mut info = options(IdentityMethod::InformationMatrix);
        info.samples = Some(100);
        assert!(check_options(&info).is_err());
        info.marginals = Some(MarginalChoice::Metropolis);
        assert!(check_options(&info).is_ok());
        let mut bits = options(IdentityMethod::PropertyBits);
        bits.bits = Some(5);
        bits.budget = Some(50);
        assert!(check_options(&bits).is_ok());
    }

    #[test]
    fn factored_identity_takes_a_known_start_or_what_a_group_holds() {
        let big = |n: usize, start: bool| {
            let initial = if start {
                format!(
                    r#","initial_identity":{:?}"#,
                    (0..n as u32).collect::<Vec<_>>()
                )
            } else {
                String::new()
            };
            format!(
                r#"{{"kind":"header","format":"idmesh-trace","version":1,"tracks":{n},"identities":{n}{initial}}}"#
            ) + "\n"
        };
        // A known start takes any size; a uniform one only what a group holds.
        let factored = options(IdentityMethod::FactoredIdentity);
        assert!(replay_text(&factored, &big(30, true)).is_ok());
        assert!(replay_text(&factored, &big(9, false)).is_ok());
        let error = replay_text(&factored, &big(10, false)).unwrap_err();
        assert!(error.contains("use information-matrix"), "{error}");
        let mut small = options(IdentityMethod::FactoredIdentity);
        small.max_group = Some(3);
        assert!(replay_text(&small, &big(3, false)).is_ok());
        small.max_group = Some(1);
        assert!(check_options(&small).is_err());
        let mut wrong = options(IdentityMethod::InformationMatrix);
        wrong.max_group = Some(4);
        assert!(check_options(&wrong)
            .unwrap_err()
            .to_string()
            .contains("--max-component applies"));
    }

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        options: IdentityReplayOptions,
    }

    #[test]
    fn the_options_flatten_into_a_command_line() {
        use clap::CommandFactory;
        Cli::command().debug_assert();
        let cli = Cli::try_parse_from([
            "idmesh",
            "--trace",
            "t.jsonl",
            "--method",
            "information-matrix",
            "--marginals",
            "metropolis",
            "--samples",
            "500",
            "--seed",
            "3",
        ])
        .unwrap();
        let mut want = new("t.jsonl", IdentityMethod::InformationMatrix);
        want.marginals = Some(MarginalChoice::Metropolis);
        want.samples = Some(500);
        want.seed = 3;
        assert_eq!(cli.options, want);
        let cli = Cli::try_parse_from([
            "idmesh",
            "--trace",
            "t",
            "--method",
            "property-bits",
            "--bits",
            "7",
            "--budget",
            "200",
        ])
        .unwrap();
        assert_eq!(cli.options.bits, Some(7));
        assert_eq!(cli.options.budget, Some(200));
        assert!(Cli::try_parse_from(["idmesh", "--trace", "t", "--bits", "0"]).is_err());
        for method in IdentityMethod::value_variants() {
            assert_eq!(
                method.to_possible_value().unwrap().get_name(),
                method.name()
            );
        }
        for m in MarginalChoice::value_variants() {
            assert_eq!(m.to_possible_value().unwrap().get_name(), m.name());
        }
    }
}
