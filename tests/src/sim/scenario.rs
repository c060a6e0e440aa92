//! A random little world for one schedule: n tracks, k red, L leaders
//! (with regions fitted to the tracks and redrawn, the default, or at
//! random fixed places), and a trace of mixes, observations and moves
//! (moves and redraws make handovers, mixes of tracks of two leaders make
//! transfers, and transfers make follows). With it, what the centralized engine says
//! after every prefix of the trace: the answer any cut must give. Half the
//! factored schedules carry identities too (identity reads among the
//! events): for them also the centralized information matrix after every
//! prefix, which the leaders' rows at a cut must put back together.

use idmesh_belief::{FactoredBelief, Field, PropertyFilter};
use idmesh_belief::{RadonBelief, RadonOptions};
use idmesh_identity::identity_event_of;
use idmesh_identity::to_rows;
use idmesh_identity::KNOWN_START_CONFIDENCE;
use idmesh_identity::{
    FactoredIdentity, IdentityFilter, InformationMatrix, InformationOptions, MarginalMethod,
};
use idmesh_placement::{factored_options, identity_options, RegionRule, Regional, Regions};
use idmesh_protocol::trace::{Header, Identify, Line, Mix, Move, Observe};
use idmesh_protocol::wire::factored::{FactoredStart, WireSplit, DEFAULT_SPREAD_ABOVE};
use idmesh_sensor::{Gateway, LeaderPlace, Router, RouterConfig};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

pub struct Scenario {
    pub header: Header,
    pub leaders: Vec<LeaderPlace>,
    /// The trace's event lines.
    pub lines: Vec<Line>,
    /// `centralized[e]`: the marginals after the first e events.
    pub centralized: Vec<Vec<f64>>,
    pub red: usize,
    /// The distributed rule of Section 5.4.2 (observations grow only the
    /// sets meeting the observed track's mixing log), or exact
    /// conditioning.
    pub distributed_rule: bool,
    /// The leaders hold the factored belief (None: the Radon belief).
    pub factored: Option<FactoredStart>,
    /// The sensor's flow control window (None: no window).
    pub window: Option<u64>,
    /// How tracks are shared among the leaders.
    pub regions: RegionRule,
    /// The sensor knows the stream's leading moves ahead (it streams a
    /// trace file), or takes them as they come (a stream fed live).
    pub placed_ahead: bool,
    /// Seqs after which a leader with nothing queued is sent a batch.
    pub idle_every: u64,
    /// On a stream with identities, the centralized information matrix
    /// after every prefix of the trace.
    pub identity: Option<CentralIdentity>,
    /// The factored identity belief's cap on a group's slots, small in
    /// most schedules so that these few tracks are cut, linked and
    /// repaired as crowds are.
    pub identity_cap: u32,
}

/// What `idmesh replay` runs by default after every prefix: the factored
/// identity belief on a stream with a known start (what the leaders hold
/// there), the information matrix without one.
pub(crate) struct CentralIdentity {
    /// `rows[e]`: the information matrix's log-likelihood rows after the
    /// first e events (None: the factored identity belief).
    pub rows: Option<Vec<Vec<Vec<f64>>>>,
    /// `marginals[e]`: their exact marginals (track × identity).
    pub marginals: Vec<Vec<Vec<f64>>>,
}

impl Scenario {
    pub(crate) fn random(rng: &mut ChaCha8Rng) -> Result<Scenario, String> {
        let tracks = rng.gen_range(3..=7usize);
        let red = rng.gen_range(1..tracks);
        let mut header = Header::new(tracks);
        header.red = Some(red);
        if rng.gen_bool(0.5) {
            let mut initial: Vec<u32> = (0..tracks as u32).collect();
            for i in (1..initial.len()).rev() {
                initial.swap(i, rng.gen_range(0..=i));
            }
            initial.truncate(red);
            initial.sort_unstable();
            header.initial_red = Some(initial);
        }
        let (leaders, regions) = random_leaders(rng);
        let mut lines = random_lines(rng, tracks);
        let distributed_rule = rng.gen_bool(0.5);
        let factored = random_factored(rng);
        let distributed_rule = distributed_rule && factored.is_none();
        // Half the factored schedules carry identities: a few reads among
        // the events, and a known start now and then
        // (IDMESH_SIM_IDENTITIES=0 runs none).
        let identities = factored.is_some()
            && !std::env::var("IDMESH_SIM_IDENTITIES").is_ok_and(|v| v == "0")
            && rng.gen_bool(0.5);
        let identity_cap = match rng.gen_range(0..4) {
            0 => idmesh_protocol::wire::identity::DEFAULT_MAX_GROUP,
            _ => rng.gen_range(2..=4),
        };
        if identities {
            header.identities = Some(tracks);
            let mut truth: Vec<u32> = (0..tracks as u32).collect();
            for i in (1..truth.len()).rev() {
                truth.swap(i, rng.gen_range(0..=i));
            }
            if rng.gen_bool(0.5) {
                header.initial_identity = Some(truth.clone());
            }
            lines = valid_reads(rng, lines, truth);
        }
        let identity = identities
            .then(|| central_identity(&header, &lines, identity_cap))
            .transpose()?;
        let centralized = centralized(
            &header,
            &lines,
            distributed_rule,
            factored,
            (&regions, leaders.len()),
        )?;
        // Half the schedules stream under flow control, with windows so
        // small that the sensor waits for progress marks again and again
        // (which the network loses, doubles and delays like the rest).
        let window = rng.gen_bool(0.5).then(|| rng.gen_range(1..=8));
        // A leader with nothing queued is sent no batch until the stream
        // is this far past its last one: short here, so that these short
        // streams send such batches too.
        let idle_every = rng.gen_range(1..=16);
        Ok(Scenario {
            header,
            leaders,
            lines,
            centralized,
            red,
            distributed_rule,
            factored,
            window,
            regions,
            placed_ahead: rng.gen_bool(0.5),
            idle_every,
            identity,
            identity_cap,
        })
    }

    /// The sensor's gateway, empty, with the scenario's window.
    pub(crate) fn gateway<Q>(&self, router: Router) -> Gateway<Q> {
        let gateway = Gateway::new("sensor-0", router, self.lines.is_empty())
            .journaled()
            .idle_batches_every(self.idle_every);
        match self.window {
            Some(window) => gateway.windowed(window),
            None => gateway,
        }
    }

    /// Whether several leaders hold the factored belief and the first
    /// holds it whole (`FactoredStart::whole`).
    pub(crate) fn held_whole(&self) -> bool {
        let (tracks, leaders) = (self.header.tracks as u32, self.leaders.len());
        leaders > 1 && (self.factored.as_ref()).is_some_and(|f| f.whole(tracks, leaders))
    }

    /// The router's settings: no pruning (the setting in which the
    /// deployment must equal the centralized engine to 1e-9).
    pub(crate) fn router(&self) -> RouterConfig {
        RouterConfig {
            factored_identity: Some(self.identity_cap),
            factored: self.factored,
            sensor: "sensor-0".into(),
            leaders: self.leaders.clone(),
            distributed_rule: self.distributed_rule,
            budget: 0,
            omp: false,
            placed: match self.placed_ahead {
                true => idmesh_placement::leading_places(self.header.tracks, &self.lines),
                false => Vec::new(),
            },
            regions: Some(self.regions.clone()),
        }
    }
}

/// One to four leaders, and how the tracks are shared among them. Half
/// the schedules fit the regions to the tracks, with windows of a few
/// items so that these short streams redraw them; the other half place
/// the leaders at random fixed places.
fn random_leaders(rng: &mut ChaCha8Rng) -> (Vec<LeaderPlace>, RegionRule) {
    let count = rng.gen_range(1..=4usize);
    let fitted = rng.gen_bool(0.5);
    let leaders: Vec<LeaderPlace> = (0..count)
        .map(|i| LeaderPlace {
            name: format!("leader-{i}"),
            at: (!fitted).then(|| (rng.gen_range(0.0..10.0), rng.gen_range(0.0..10.0))),
        })
        .collect();
    let regions = match fitted {
        true => RegionRule::Fitted {
            window_per_leader: rng.gen_range(1..=4),
        },
        false => RegionRule::Fixed(leaders.iter().map(|l| l.at).collect()),
    };
    (leaders, regions)
}

/// A trace of 5 to 50 mixes, observations and moves of `tracks` tracks,
/// one every 0.1 s.
fn random_lines(rng: &mut ChaCha8Rng, tracks: usize) -> Vec<Line> {
    let events = rng.gen_range(5..=50usize);
    let mut lines = Vec::with_capacity(events);
    for e in 0..events {
        let time = e as f64 * 0.1;
        let line = match rng.gen_range(0..10) {
            0..=3 => {
                let a = rng.gen_range(0..tracks as u32);
                let mut b = rng.gen_range(0..tracks as u32 - 1);
                if b >= a {
                    b += 1;
                }
                // Now and then a certain exchange (a relabelling),
                // which moves no component but changes whose tracks
                // a component holds.
                let swap = match rng.gen_range(0..10) {
                    0 => 1.0,
                    _ => rng.gen_range(0.05..0.95),
                };
                Line::Mix(Mix { time, a, b, swap })
            }
            4..=6 => Line::Observe(Observe {
                time,
                track: rng.gen_range(0..tracks as u32),
                red: rng.gen_range(0.05..1.0),
                blue: rng.gen_range(0.05..1.0),
                sensor: None,
            }),
            _ => Line::Move(Move {
                time,
                track: rng.gen_range(0..tracks as u32),
                x: rng.gen_range(0.0..10.0),
                y: rng.gen_range(0.0..10.0),
            }),
        };
        lines.push(line);
    }
    // Half the streams begin by placing some tracks (as the crowd
    // simulator writes where everybody starts): the Begin puts those
    // with the nearest leader at once.
    if rng.gen_bool(0.5) {
        let leading: Vec<Line> = (0..rng.gen_range(1..=tracks))
            .map(|_| {
                Line::Move(Move {
                    time: 0.0,
                    track: rng.gen_range(0..tracks as u32),
                    x: rng.gen_range(0.0..10.0),
                    y: rng.gen_range(0.0..10.0),
                })
            })
            .collect();
        lines.splice(0..0, leading);
    }
    lines
}

/// A third of the schedules run the factored belief (small components,
/// so that merges, splits and moves all happen), half of them under the
/// regional rule (the default); IDMESH_SIM_FACTORED=0 runs the Radon
/// belief alone.
fn random_factored(rng: &mut ChaCha8Rng) -> Option<FactoredStart> {
    let factored_share = if std::env::var("IDMESH_SIM_FACTORED").is_ok_and(|v| v == "0") {
        0.0
    } else {
        1.0 / 3.0
    };
    rng.gen_bool(factored_share).then(|| FactoredStart {
        max_component: rng.gen_range(1..=3),
        split: [
            WireSplit::Original,
            WireSplit::Recent,
            WireSplit::LeastLoss { rounds: 1 },
        ][rng.gen_range(0..3)],
        shrink: true,
        regional: rng.gen_bool(0.5),
        // A third of them held whole by the first leader (the default
        // for crowds this small), the others spread.
        spread_above: match rng.gen_bool(1.0 / 3.0) {
            true => DEFAULT_SPREAD_ABOVE,
            false => 0,
        },
    })
}

/// The centralized engine (`idmesh replay --method overcomplete`, no
/// budget, with or without `--distributed-rule`) after every prefix of
/// `lines`.
fn centralized(
    header: &Header,
    lines: &[Line],
    distributed_rule: bool,
    factored: Option<FactoredStart>,
    (rule, leaders): (&RegionRule, usize),
) -> Result<Vec<Vec<f64>>, String> {
    let field = Field::with_count(
        header.tracks,
        header.red_count(),
        header.initial_red.clone(),
    );
    let options = RadonOptions {
        distributed_rule,
        ..RadonOptions::default()
    };
    // The centralized engine with the leaders' options: the factored
    // belief with the local rule (and the regional rule where the leaders
    // run it), or the Radon belief.
    let whole = (factored.as_ref()).is_some_and(|f| f.whole(header.tracks as u32, leaders));
    if let Some(start) = factored.filter(|f| f.regional && !whole) {
        let belief = FactoredBelief::with_options(field, factored_options(&start, whole))
            .map_err(|e| e.to_string())?;
        let mut engine = Regional::new(belief, Regions::new(rule, leaders, header.tracks));
        let mut out = vec![engine.marginals().map_err(|e| e.to_string())?];
        for line in lines {
            engine.apply_line(line).map_err(|e| e.to_string())?;
            out.push(engine.marginals().map_err(|e| e.to_string())?);
        }
        return Ok(out);
    }
    let mut engine: Box<dyn PropertyFilter> = match &factored {
        Some(start) => Box::new(
            FactoredBelief::with_options(field, factored_options(start, whole))
                .map_err(|e| e.to_string())?,
        ),
        None => Box::new(RadonBelief::with_options(field, options).map_err(|e| e.to_string())?),
    };
    let mut out = vec![engine.marginals().map_err(|e| e.to_string())?];
    for line in lines {
        match line {
            Line::Mix(m) => engine.mix(idmesh_belief::Mix {
                a: m.a,
                b: m.b,
                swap: m.swap,
            }),
            Line::Observe(o) => engine.observe(idmesh_belief::Observe {
                track: o.track,
                red: o.red,
                blue: o.blue,
            }),
            _ => Ok(()),
        }
        .map_err(|e| e.to_string())?;
        out.push(engine.marginals().map_err(|e| e.to_string())?);
    }
    Ok(out)
}

/// The centralized identity belief `idmesh replay` runs by default after
/// every prefix of `lines`, with its marginals: the factored identity
/// belief with a known start, else the information matrix (with exact
/// marginals).
/// `lines` with reads among them that the world could have produced: a
/// hidden truth (`truth[t]`, the identity on track t) follows the mixes,
/// each swapping it with its probability, and each read is of the true
/// identity with its accuracy, of another one otherwise; accuracies span
/// what the trace format allows, sure reads (accuracy 1, always true)
/// included, which the factored identity belief's cuts may have ruled out.
fn valid_reads(rng: &mut ChaCha8Rng, lines: Vec<Line>, mut truth: Vec<u32>) -> Vec<Line> {
    let n = truth.len() as u32;
    let reads = rng.gen_range(1..=12usize);
    let mut at: Vec<usize> = (0..reads).map(|_| rng.gen_range(0..=lines.len())).collect();
    at.sort_unstable();
    let mut out = Vec::with_capacity(lines.len() + reads);
    let mut next = at.into_iter().peekable();
    let mut time = 0.0;
    for (i, line) in lines.into_iter().enumerate() {
        while next.next_if(|&a| a == i).is_some() {
            out.push(Line::Identify(read_of(rng, &truth, time, n)));
        }
        if let Line::Mix(mix) = &line {
            if rng.gen_bool(mix.swap) {
                truth.swap(mix.a as usize, mix.b as usize);
            }
        }
        time = line.time().unwrap_or(time);
        out.push(line);
    }
    for _ in next {
        out.push(Line::Identify(read_of(rng, &truth, time, n)));
    }
    out
}

fn read_of(rng: &mut ChaCha8Rng, truth: &[u32], time: f64, n: u32) -> Identify {
    let track = rng.gen_range(0..n);
    let accuracy = [1.0, 1.0, 0.99, 0.9, 0.6, 1e-3][rng.gen_range(0..6)];
    let right = accuracy >= 1.0 || rng.gen_bool(accuracy);
    let identity = match right {
        true => truth[track as usize],
        false => (truth[track as usize] + rng.gen_range(1..n)) % n,
    };
    Identify {
        time,
        track,
        identity,
        accuracy,
    }
}

fn central_identity(header: &Header, lines: &[Line], cap: u32) -> Result<CentralIdentity, String> {
    let n = header.tracks;
    let failed = |e: idmesh_belief::BeliefError| e.to_string();
    if let Some(start) = &header.initial_identity {
        let mut belief =
            FactoredIdentity::from_assignment(start, identity_options(cap)).map_err(failed)?;
        let mut marginals = vec![belief.marginals().map_err(failed)?];
        for line in lines {
            if let Some(event) = identity_event_of(line) {
                belief.apply(&event).map_err(failed)?;
            }
            marginals.push(belief.marginals().map_err(failed)?);
        }
        return Ok(CentralIdentity {
            rows: None,
            marginals,
        });
    }
    let options = InformationOptions::default();
    let mut matrix = match &header.initial_identity {
        Some(start) => InformationMatrix::from_assignment(start, KNOWN_START_CONFIDENCE, options)
            .map_err(failed)?,
        None => InformationMatrix::uniform_with(n, options).map_err(failed)?,
    };
    let mut rows = Vec::with_capacity(lines.len() + 1);
    let mut marginals = Vec::with_capacity(lines.len() + 1);
    let mut keep = |matrix: &InformationMatrix| -> Result<(), String> {
        rows.push(matrix.log_likelihoods());
        marginals.push(exact_marginals(matrix)?);
        Ok(())
    };
    keep(&matrix)?;
    for line in lines {
        if let Some(event) = identity_event_of(line) {
            matrix.apply(&event).map_err(failed)?;
        }
        keep(&matrix)?;
    }
    Ok(CentralIdentity {
        rows: Some(rows),
        marginals,
    })
}

/// The exact marginals of `matrix`, track by identity, as the coordinator
/// computes them from the rows it assembles.
pub(crate) fn exact_marginals(matrix: &InformationMatrix) -> Result<Vec<Vec<f64>>, String> {
    let blocks = matrix
        .block_marginals(&MarginalMethod::Exact)
        .map_err(|e| e.to_string())?;
    Ok(to_rows(matrix.log_likelihoods().len(), &blocks.dense()))
}
