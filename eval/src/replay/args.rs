//! The command line of `idmesh replay`: the trace, the method, and the
//! options of each method (a `clap` argument group, parsed by the binary).

use super::identity::{IdentityMethod, MarginalChoice};
use clap::{Args, ValueEnum};
use idmesh_belief::Coupling;
use idmesh_placement::split_coupling;
use idmesh_protocol::wire::factored::{held_whole, DEFAULT_SPREAD_ABOVE};
use std::path::PathBuf;

#[derive(Debug, Clone, Args)]
#[command(allow_negative_numbers = true)]
pub struct ReplayArgs {
    /// The trace to replay (JSON Lines, shared/spec/trace.md).
    #[arg(long, value_name = "FILE")]
    pub trace: PathBuf,

    /// The filter to run (default: by the trace's header — factored for
    /// a trace with colours; for an identity trace with none,
    /// factored-identity from a known start (`initial_identity`),
    /// information-matrix without one: what the leaders hold).
    #[arg(long, value_enum)]
    pub method: Option<Method>,

    /// The most coefficients the Radon belief may hold after an event
    /// (overcomplete: optional, none = exact; threshold: required).
    #[arg(long, value_name = "N", value_parser = parse_budget)]
    pub budget: Option<usize>,

    /// Condition with the distributed rule of Section 5.4 (Radon methods
    /// only): an approximation that touches only the sets an observation's
    /// track mixed into since it was last observed.
    #[arg(long)]
    pub distributed_rule: bool,

    /// The number of particles of --method particles (default 1000).
    #[arg(long, value_name = "P", value_parser = parse_particles)]
    pub particles: Option<usize>,

    /// The seed of --method particles or of --marginals metropolis
    /// (default 0).
    #[arg(long)]
    pub seed: Option<u64>,

    /// Identity methods: how --method information-matrix turns its
    /// log-likelihoods into marginals (default exact, N ≤ 22).
    #[arg(long, value_enum)]
    pub marginals: Option<MarginalChoice>,

    /// Identity methods: the number of property bits of --method
    /// property-bits (default ⌈log₂ N⌉).
    #[arg(long, value_name = "B")]
    pub bits: Option<usize>,

    /// Identity methods: counted steps of --marginals metropolis.
    #[arg(long, value_name = "S")]
    pub samples: Option<usize>,

    /// Identity methods: the known start of --method information-matrix
    /// as log-odds C against each other identity (default: exact, −∞ on
    /// every other identity; docs/design/identity.md "Calibration").
    #[arg(long, value_name = "C")]
    pub known_start_confidence: Option<f64>,

    /// --method factored: how splits weigh the red count: `coupled` (the
    /// whole belief's weight) or `local` (the weight an uninformed rest of
    /// the field gives the pair being split, and every sighting reads only
    /// its component), or `flat` (every count the pair can hold alike: the
    /// local rule leaders ran before, kept to compare). Default: what the
    /// holders of the belief can compute, so that a deployment of the same
    /// shape computes what replay does: `coupled` for one holder, `local`
    /// with --leaders N (N > 1) or --regions.
    #[arg(long, value_enum)]
    pub coupling: Option<CouplingChoice>,

    /// --method factored: the most tracks of one component (default 6);
    /// --method factored-identity: the most tracks of one group (2 to 9,
    /// default 9).
    #[arg(long, value_name = "M")]
    pub max_component: Option<usize>,

    /// --method factored: how a component too large to keep is split
    /// (least-loss: the old cut or, if it loses less, the best cut one
    /// exchange of tracks away from it).
    #[arg(long, value_enum, default_value_t = SplitChoice::LeastLoss)]
    pub split: SplitChoice,

    /// --method factored: the regional rule of leaders at fixed places
    /// `X,Y;X,Y;…` (the topology's `at`, in its leader order, under
    /// `regions = "fixed"`): a track belongs to the leader nearest it.
    #[arg(long, value_name = "PLACES", value_parser = parse_places)]
    pub regions: Option<Places>,

    /// --method factored: the regional rule of a deployment of this many
    /// leaders, with regions fitted to the crowd and redrawn as it moves
    /// (a deployment's default): a mix of tracks in two leaders' regions
    /// keeps their components apart, and a track handed over is split off
    /// its component. 1 (the default): one leader, no regions.
    #[arg(long, value_name = "L", value_parser = clap::value_parser!(u16).range(1..))]
    pub leaders: Option<u16>,

    /// --method factored with --leaders or --regions: a crowd of at most
    /// this many tracks is held whole by one leader, as a deployment holds
    /// it (splits weighed by the whole belief, no regions); a larger one is
    /// spread. Default: a deployment's (64); 0 spreads every crowd.
    #[arg(long, value_name = "N")]
    pub spread_above: Option<u32>,

    /// Compute what the deployment this topology file describes computes:
    /// its belief settings and its leaders (`idmesh` reads the file and
    /// sets the options above from it; they may not be given as well).
    #[arg(long, value_name = "FILE")]
    pub topology: Option<PathBuf>,

    /// Run a setting replay refuses as exponential (--method property-bits
    /// without --budget on many identities) anyway.
    #[arg(long)]
    pub force: bool,
}

impl ReplayArgs {
    /// The property method asked for, or the default for property traces.
    pub(crate) fn property_method(&self) -> Method {
        self.method.unwrap_or(DEFAULT_PROPERTY_METHOD)
    }

    /// How many leaders replay runs the factored belief under: one unless
    /// --leaders or --regions say.
    pub(crate) fn leaders(&self) -> usize {
        match (&self.regions, self.leaders) {
            (Some(places), _) => places.0.len(),
            (None, Some(leaders)) => usize::from(leaders),
            (None, None) => 1,
        }
    }

    /// Whether those leaders hold a crowd of `tracks` tracks whole, as a
    /// deployment does (`FactoredStart::whole`): one holder, no regions.
    pub(crate) fn whole(&self, tracks: usize) -> bool {
        let spread_above = self.spread_above.unwrap_or(DEFAULT_SPREAD_ABOVE);
        held_whole(tracks as u32, self.leaders(), spread_above)
    }

    /// The coupling of the factored belief's splits on a crowd of
    /// `tracks` tracks: the one named, or the one its holders compute
    /// (`idmesh_placement::split_coupling`; none given: one holder).
    pub(crate) fn coupling(&self, tracks: usize) -> Coupling {
        self.coupling
            .map_or_else(|| split_coupling(self.whole(tracks)), Coupling::from)
    }
}

/// Leaders' places for `--regions`.
#[derive(Debug, Clone, PartialEq)]
pub struct Places(pub Vec<(f64, f64)>);

pub(crate) fn parse_places(text: &str) -> Result<Places, String> {
    let places = text
        .split(';')
        .map(|point| {
            let bad = || format!("{point:?} is not a place X,Y (finite numbers)");
            let (x, y) = point.split_once(',').ok_or_else(bad)?;
            let (x, y): (f64, f64) = (
                x.trim().parse().map_err(|_| bad())?,
                y.trim().parse().map_err(|_| bad())?,
            );
            if !(x.is_finite() && y.is_finite()) {
                return Err(bad());
            }
            Ok((x, y))
        })
        .collect::<Result<Vec<_>, String>>()?;
    Ok(Places(places))
}

/// The method `replay` runs on a property trace when none is named.
pub(crate) const DEFAULT_PROPERTY_METHOD: Method = Method::Factored;

/// The coupling of the factored belief's splits (`belief::Coupling`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CouplingChoice {
    Coupled,
    Local,
    Flat,
}

impl From<CouplingChoice> for Coupling {
    fn from(choice: CouplingChoice) -> Self {
        match choice {
            CouplingChoice::Coupled => Coupling::Coupled,
            CouplingChoice::Local => Coupling::Local,
            CouplingChoice::Flat => Coupling::Flat,
        }
    }
}

impl From<Coupling> for CouplingChoice {
    fn from(coupling: Coupling) -> Self {
        match coupling {
            Coupling::Coupled => CouplingChoice::Coupled,
            Coupling::Local => CouplingChoice::Local,
            Coupling::Flat => CouplingChoice::Flat,
        }
    }
}

/// The factored belief's split rule (`belief::SplitRule`; least-loss
/// makes one round of exchanges, as `belief = "factored"`'s does).
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SplitChoice {
    Original,
    Recent,
    LeastLoss,
}

/// The filters `replay` can run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Method {
    /// Radon belief on the overcomplete basis; OMP then thresholding once
    /// --budget is exceeded (exact without --budget).
    Overcomplete,
    /// Radon belief pruned to --budget coefficients by thresholding alone.
    Threshold,
    /// The exact dense filter over every red set (small fields only).
    Exact,
    /// First-order Radon projection (Table III baseline; shrunk towards
    /// uniform whenever the projection leaves the probability simplex).
    Order1,
    /// Second-order Radon projection (as order1).
    Order2,
    /// Third-order Radon projection (as order1).
    Order3,
    /// Sequential Monte Carlo over red sets: --particles weighted
    /// particles, resampled when the effective sample size halves.
    Particles,
    /// Our improvement: exact per-component beliefs over the connected
    /// groups of mixed tracks, coupled by the red count, split by moment
    /// matching when a group outgrows a cap.
    Factored,
    /// Identity traces: the exact filter over all N! assignments (N ≤ 9).
    ExactPerm,
    /// Identity traces: the belief matrix (doubly stochastic marginals).
    BeliefMatrix,
    /// Identity traces: the information matrix (lazy log-likelihoods),
    /// marginals by --marginals.
    InformationMatrix,
    /// Identity traces: identities coded by --bits properties, one Radon
    /// belief per bit.
    PropertyBits,
    /// Identity traces: exact over the groups of tracks that mixed, cut by
    /// the least lossy (linked) split when a group would outgrow
    /// --max-component slots.
    FactoredIdentity,
}

impl Method {
    /// The name on the command line and in the summary.
    pub fn name(self) -> &'static str {
        match self {
            Method::Overcomplete => "overcomplete",
            Method::Threshold => "threshold",
            Method::Exact => "exact",
            Method::Order1 => "order1",
            Method::Order2 => "order2",
            Method::Order3 => "order3",
            Method::Particles => "particles",
            Method::Factored => "factored",
            Method::ExactPerm => "exact-perm",
            Method::BeliefMatrix => "belief-matrix",
            Method::InformationMatrix => "information-matrix",
            Method::PropertyBits => "property-bits",
            Method::FactoredIdentity => "factored-identity",
        }
    }

    /// The identity filter this method names, if it is one.
    pub(crate) fn identity(self) -> Option<IdentityMethod> {
        match self {
            Method::ExactPerm => Some(IdentityMethod::ExactPerm),
            Method::BeliefMatrix => Some(IdentityMethod::BeliefMatrix),
            Method::InformationMatrix => Some(IdentityMethod::InformationMatrix),
            Method::PropertyBits => Some(IdentityMethod::PropertyBits),
            Method::FactoredIdentity => Some(IdentityMethod::FactoredIdentity),
            _ => None,
        }
    }

    /// Whether the method is the Radon engine (and so takes --budget and
    /// --distributed-rule).
    pub(crate) fn is_radon(self) -> bool {
        matches!(self, Method::Overcomplete | Method::Threshold)
    }
}

fn parse_particles(text: &str) -> Result<usize, String> {
    parse_count(text, "particles")
}

fn parse_budget(text: &str) -> Result<usize, String> {
    parse_count(text, "coefficients")
}

/// A whole number of `what`, at least 1.
fn parse_count(text: &str, what: &str) -> Result<usize, String> {
    match text.parse::<usize>() {
        Ok(0) => Err(format!("there must be at least 1 of the {what}")),
        Ok(n) => Ok(n),
        Err(_) => Err(format!(
            "expected a whole number of {what} (1 or more), got {text:?}"
        )),
    }
}
