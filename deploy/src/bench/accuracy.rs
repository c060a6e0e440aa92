//! `idmesh bench --accuracy`: how well the live runtime tracks, on the
//! Table III crowds of docs/results.md.
//!
//! Each crowd is written as a trace file (the evaluation's trace, with
//! `move` lines so that tracks cross the leaders' regions) and fed to a
//! live loopback deployment of four leaders by a producer on the sensor's
//! ingest key, one stretch between two truth lines at a time; after each
//! stretch the marginals are asked right after the events before that
//! truth line (`?events=N`). Feeding in stretches is what makes every
//! truth line answerable: a point the stream has passed is refused, and a
//! stream read flat out from a file would pass some before their question
//! reached the sensor. The answers are scored with the evaluation's
//! scorer (the trace spec's tracking error, ties shared) and compared,
//! truth line by truth line, with the centralized engine's marginals on
//! the same trace:
//!
//! - the factored belief (default options, local split rule) against
//!   `factored, local rule`: the two must agree to 1e-9 at every truth
//!   line, or the command fails naming the point;
//! - the same under the regional rule against the centralized engine under
//!   that rule with the deployment's leaders' places (to 1e-9 as well),
//!   and, offline, that rule's cost in tracking error with the regions of
//!   2, 4 and 8 leaders;
//! - the Radon belief with the distributed rule, overcomplete pruning at
//!   B = 5n sets per leader, against `overcomplete, distributed rule
//!   (B = 5n)`: shown beside it, not claimed equal (each leader prunes its
//!   own sets to its own budget, which no single filter reproduces; the
//!   runtime tests bound the gap in error instead).
//!
//! A truth line that is not answered fails the command at once.

use super::ingest::{header_only, send};
use super::Deployment;
use crate::runtime::loopback::{self, Ports};
use crate::runtime::query::ask;
use crate::runtime::topology::{BeliefKind, RegionsSetting, Sparsification, Topology};
use anyhow::{bail, Context, Result};
use idmesh_eval::eval::{table3_budget, table3_crowds, Crowd, Engine, Start, Written};
use idmesh_eval::eval::{LiveRow, TABLE_HEADER};
use idmesh_placement::{factored_options, RegionRule};
use idmesh_protocol::wire::query::MarginalsAnswer;
use std::fmt::Write as _;
use std::path::Path;
use std::time::{Duration, Instant};

/// The leaders of every deployment.
const LEADERS: usize = 4;

/// The most two answers may differ where equality is claimed.
const TOLERANCE: f64 = 1e-9;

/// How long one truth line's answer may take.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(60);

/// Which of the Table III crowds to run.
#[derive(Debug, Clone)]
pub struct Crowds {
    /// The n of Table III to run (of 20, 60, 100).
    pub sizes: Vec<usize>,
    pub starts: Vec<Start>,
    /// Seeds per point: the evaluation's seeds 0, 1, ….
    pub seeds: usize,
}

/// What the deployments hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// The factored belief, local split rule.
    Factored,
    /// The same under the regional rule (`regional = true`).
    Regional,
    /// The Radon belief, distributed rule, overcomplete pruning.
    Radon,
}

impl Kind {
    fn name(self) -> &'static str {
        match self {
            Kind::Factored => "factored",
            Kind::Regional => "factored, regional rule",
            Kind::Radon => "radon",
        }
    }

    /// A short name for file and key names.
    fn tag(self) -> &'static str {
        match self {
            Kind::Factored => "factored",
            Kind::Regional => "regional",
            Kind::Radon => "radon",
        }
    }

    fn belief(self) -> BeliefKind {
        match self {
            Kind::Radon => BeliefKind::Radon,
            Kind::Factored | Kind::Regional => BeliefKind::Factored,
        }
    }

    /// Whether live and centralized must agree to [`TOLERANCE`].
    fn exact(self) -> bool {
        self != Kind::Radon
    }
}

/// The leader counts whose regions the regional rule's accuracy cost is
/// measured at (centralized, on the same traces).
const REGIONAL_LEADERS: [usize; 3] = [2, 4, 8];

/// One deployment's run on one crowd.
struct Run {
    kind: Kind,
    live_error: f64,
    central_error: f64,
    /// The largest |live − centralized| marginal over all truth lines, and
    /// where (truth line, track).
    largest: (f64, usize, usize),
    truths: usize,
    seconds: f64,
}

pub fn run(runtime: &tokio::runtime::Runtime, crowds: &Crowds, dir: &Path) -> Result<String> {
    let started = Instant::now();
    let chosen: Vec<Crowd> = table3_crowds(crowds.seeds)
        .into_iter()
        .filter(|c| crowds.sizes.contains(&c.n) && crowds.starts.contains(&c.start))
        .collect();
    if chosen.is_empty() {
        bail!(
            "no Table III crowd has n in {:?} (the crowds are n = 20, 60, 100)",
            crowds.sizes
        );
    }
    let mut rows: Vec<(Crowd, Run)> = Vec::new();
    // Per crowd: the local rule's error and the regional rule's at
    // REGIONAL_LEADERS leaders' regions.
    let mut costs: Vec<(Crowd, f64, Vec<f64>)> = Vec::new();
    let mut mismatches = Vec::new();
    for crowd in chosen {
        let name = format!(
            "table3-n{}-swap{}-{}-seed{}",
            crowd.n,
            crowd.swap,
            match crowd.start {
                Start::Known => "known",
                Start::Uniform => "uniform",
            },
            crowd.seed
        );
        let folder = dir.join(&name);
        std::fs::create_dir_all(&folder)
            .with_context(|| format!("cannot create {}", folder.display()))?;
        let trace = folder.join("trace.jsonl");
        let written = crowd.write(&trace)?;
        for kind in [Kind::Factored, Kind::Regional, Kind::Radon] {
            let what = format!("{}, {}", crowd.label(), kind.name());
            eprintln!(
                "bench: {what}: {} truth lines through {LEADERS} leaders",
                written.truth_events.len()
            );
            let clock = Instant::now();
            let (live, topology) = runtime
                .block_on(live_answers(&crowd, &written, kind, &folder, &trace))
                .with_context(|| what.clone())?;
            let seconds = clock.elapsed().as_secs_f64();
            let central = match kind {
                Kind::Factored => written.centralized(Engine::FactoredLocal, crowd.seed)?,
                Kind::Radon => written.centralized(Engine::RadonDistributed, crowd.seed)?,
                Kind::Regional => regional(&written, &trace, &topology)?,
            };
            let largest = largest_difference(&live, &central).with_context(|| what.clone())?;
            if kind.exact() && largest.0 > TOLERANCE {
                mismatches.push(format!(
                    "{what}: live and centralized differ by {:e} at truth line {} (after {} \
                     events), track {}",
                    largest.0, largest.1, written.truth_events[largest.1], largest.2
                ));
            }
            rows.push((
                crowd.clone(),
                Run {
                    kind,
                    live_error: written.tracking_error(&live)?,
                    central_error: written.tracking_error(&central)?,
                    largest,
                    truths: live.len(),
                    seconds,
                },
            ));
        }
        let central_of = |kind: Kind| {
            rows.iter()
                .rev()
                .find(|(_, r)| r.kind == kind)
                .map(|(_, r)| r.central_error)
                .with_context(|| format!("the {} run of this crowd", kind.name()))
        };
        let local = central_of(Kind::Factored)?;
        let mut regional_errors = Vec::new();
        for leaders in REGIONAL_LEADERS {
            // At the deployment's own leader count, the regional run above
            // already replayed the same placement.
            if leaders == LEADERS {
                regional_errors.push(central_of(Kind::Regional)?);
                continue;
            }
            let topology = placed_topology(leaders, crowd.n, &folder, &trace)?;
            regional_errors.push(written.tracking_error(&regional(&written, &trace, &topology)?)?);
        }
        costs.push((crowd.clone(), local, regional_errors));
    }
    let report = report(&rows, &costs, crowds.seeds, started.elapsed())?;
    if !mismatches.is_empty() {
        print!("{report}");
        bail!(
            "the live factored belief differs from the centralized engine by more than \
             {TOLERANCE:e}:\n{}",
            mismatches.join("\n")
        );
    }
    Ok(report)
}

/// Feeds `written` to a live deployment holding `belief` and asks the
/// marginals at every truth line: one answer per truth line, in order.
async fn live_answers(
    crowd: &Crowd,
    written: &Written,
    kind: Kind,
    folder: &Path,
    trace: &Path,
) -> Result<(Vec<Vec<f64>>, Topology)> {
    let header = header_only(trace, folder)?;
    // The sensor streams what the producer sends (its trace is the header
    // alone); the leaders are placed over the crowd's field.
    let plan = plan(kind, LEADERS, crowd.n, &header)?;
    let config = folder.join(format!("topology-{}.toml", kind.tag()));
    let deployment = Deployment::launch(&plan, &config).await?;
    let answers = ask_every_truth_line(&deployment, written).await;
    let topology = deployment.topology.clone();
    deployment.close().await;
    Ok((answers?, topology))
}

/// A loopback deployment of `leaders` leaders holding `kind` for a crowd
/// of `n` targets: its sensor streams `trace`.
fn plan(kind: Kind, leaders: usize, n: usize, trace: &Path) -> Result<Topology> {
    let mut topology = loopback::topology(trace, leaders, 1, Ports::Free)?;
    topology.prefix = format!("idmesh/accuracy-{}-{}", kind.tag(), std::process::id());
    topology.belief = kind.belief();
    topology.regional = kind == Kind::Regional;
    // It measures the leaders sharing a crowd, so every crowd is spread;
    // a crowd held whole is one leader's, the one holder's belief
    // (tests/tests/factored.rs holds such a deployment to replay).
    topology.spread_above = 0;
    // The Radon belief's settings (only `belief = "radon"` reads
    // them): the distributed rule, the
    // overcomplete pruning at the Table III budget per leader.
    topology.distributed_rule = true;
    topology.budget = table3_budget(n) as u32;
    topology.sparsify = Sparsification::Overcomplete;
    topology.query_timeout_ms = ANSWER_TIMEOUT.as_millis() as u64;
    topology.sensors[0].live = true;
    Ok(topology)
}

/// The topology of a regional deployment of `leaders` leaders placed over
/// `trace`'s crowd as the loopback places them (written to `folder` and
/// read back, so the places are what a deployment reads).
fn placed_topology(leaders: usize, n: usize, folder: &Path, trace: &Path) -> Result<Topology> {
    let topology = plan(Kind::Regional, leaders, n, trace)?;
    let path = folder.join(format!("topology-regional-{leaders}.toml"));
    topology.save(&path)?;
    Topology::load(&path)
}

/// The centralized engine a regional deployment with `topology` equals:
/// the factored belief with its settings under the regional rule of its
/// leaders' regions.
fn regional(written: &Written, trace: &Path, topology: &Topology) -> Result<Vec<Vec<f64>>> {
    let start = topology
        .factored()
        .context("a regional topology holds the factored belief")?;
    let rule = match topology.regions {
        RegionsSetting::Fitted => RegionRule::fitted(),
        RegionsSetting::Fixed => RegionRule::Fixed(
            topology
                .leader
                .iter()
                .map(|l| l.at.map(|[x, y]| (x, y)))
                .collect(),
        ),
    };
    written.regional(
        trace,
        factored_options(&start, false),
        &rule,
        topology.leader.len(),
    )
}

async fn ask_every_truth_line(deployment: &Deployment, written: &Written) -> Result<Vec<Vec<f64>>> {
    let keys = deployment.keys();
    let sensor = deployment.topology.sensor().name.clone();
    let ping = keys.ping("sensor", &sensor);
    let started = Instant::now();
    while let Err(e) = deployment.ping(&ping, 1).await {
        if started.elapsed() > Duration::from_secs(60) {
            return Err(e.context("the sensor did not come up"));
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    // A sensor answers pings while it still waits for its leaders, and
    // takes ingest requests only from its stream loop, which also answers
    // its counters: a first request sent before that could wait longer
    // than its timeout (it did, now and then, on this machine).
    let counters = keys.sensor_stats(&sensor);
    while let Err(e) = ask(&deployment.session, &counters, Duration::from_secs(1)).await {
        if started.elapsed() > Duration::from_secs(60) {
            return Err(e.context("the sensor did not start its stream"));
        }
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
    let ingest = keys.sensor_ingest(&sensor);
    let marginals = keys.query_marginals();
    let mut sent = 0usize;
    let mut answers = Vec::with_capacity(written.truth_events.len());
    for (i, &events) in written.truth_events.iter().enumerate() {
        let point = || format!("truth line {i} (after {events} events)");
        // The stretch up to this truth line, at most 1000 lines a request.
        let upto = events as usize;
        for chunk in written.event_lines[sent..upto].chunks(1000) {
            let ack = send(
                deployment,
                &ingest,
                "accuracy",
                sent as u64,
                &chunk.join("\n"),
            )
            .await
            .with_context(point)?;
            if ack.accepted.len() != chunk.len() {
                bail!(
                    "{}: {} of {} lines accepted: {:?}",
                    point(),
                    ack.accepted.len(),
                    chunk.len(),
                    ack.errors.first()
                );
            }
            sent += chunk.len();
            if ack.events != sent as u64 {
                bail!(
                    "{}: the sensor is at {} events after {sent} were sent",
                    point(),
                    ack.events
                );
            }
        }
        let body = ask(
            &deployment.session,
            &format!("{marginals}?events={events}"),
            ANSWER_TIMEOUT,
        )
        .await
        .with_context(|| format!("{} was not answered", point()))?;
        let answer: MarginalsAnswer = serde_json::from_slice(&body)
            .with_context(|| format!("{}: not a marginals answer", point()))?;
        let at = answer.watermark.get(&sensor).copied();
        if at != Some(events) {
            bail!("{}: answered at {at:?} events", point());
        }
        answers.push(answer.p_red);
    }
    Ok(answers)
}

/// The largest |live − centralized| over every truth line and track, with
/// its truth line and track.
fn largest_difference(live: &[Vec<f64>], central: &[Vec<f64>]) -> Result<(f64, usize, usize)> {
    if live.len() != central.len() {
        bail!("{} live answers, {} centralized", live.len(), central.len());
    }
    let mut largest = (0.0f64, 0, 0);
    for (i, (l, c)) in live.iter().zip(central).enumerate() {
        if l.len() != c.len() {
            bail!(
                "truth line {i}: {} live marginals, {} centralized",
                l.len(),
                c.len()
            );
        }
        for (t, (a, b)) in l.iter().zip(c).enumerate() {
            let d = (a - b).abs();
            // A NaN is the largest difference of all (infinite: it fails the check).
            if d.is_nan() || d > largest.0 {
                largest = (if d.is_nan() { f64::INFINITY } else { d }, i, t);
            }
        }
    }
    Ok(largest)
}

/// docs/live-accuracy.md: what was run, and one row per point and belief
/// (means over the seeds, the largest difference over all of them).
fn report(
    rows: &[(Crowd, Run)],
    costs: &[(Crowd, f64, Vec<f64>)],
    seeds: usize,
    took: Duration,
) -> Result<String> {
    let mut out = String::new();
    writeln!(
        out,
        "# Live accuracy on the Table III crowds\n\n\
         Written by `idmesh bench --accuracy --out docs/live-accuracy.md` \
         (deploy/src/bench/accuracy.rs); {seeds} seed(s) per point (the evaluation's seed 0{}), \
         {:.0} s on this machine.\n\n\
         The crowds of docs/results.md's Table III (k = n/2, 1000 mix + observe events, half \
         of them mixes; `move` lines added every second, which draw no randomness, so the \
         filters see the evaluation's very trace) are fed to a live deployment on loopback \
         (a coordinator, {LEADERS} leaders placed over the crowd by k-means on its positions and then balanced by the items each is sent, a sensor) by a producer \
         on the sensor's ingest key, one stretch between two truth lines at a time, and \
         after each stretch the coordinator is asked the marginals right after the events \
         before that truth line (`?events=N`): every truth line is answered, or the command \
         fails. The answers are scored as every table of results.md is (the trace spec's \
         tracking error: the k largest marginals called red, ties sharing the slots, the \
         fraction of tracks mislabeled, averaged over the truth lines), beside the \
         centralized engine replaying the same trace:\n\n\
         - **factored**: the leaders' factored belief at its defaults (components of at most \
         {max} tracks, split \"least-loss\", local split rule; the count coupling at the \
         coordinator) against \
         `factored, local rule`. They are the same computation distributed: the command fails \
         if any marginal at any truth line differs by more than {TOLERANCE:e}.\n\
         - **factored, regional rule**: the same under the regional rule (`regional = true`) \
         against the centralized engine under the same rule and the deployment's leaders' \
         places (`idmesh replay --regions`); the same check, the same tolerance.\n\
         - **radon**: the Radon belief with the distributed rule of Section 5.4, overcomplete \
         pruning to B = 5n sets **per leader**, against `overcomplete, distributed rule (B = \
         5n)`. Not claimed equal: each leader prunes its own sets to its own budget, which no \
         single filter reproduces; the difference is shown as measured.\n\n\
         The centralized column is computed as docs/results.md's `factored, local rule` and \
         `overcomplete, distributed rule` rows of Table III are, on the same traces (with 5 \
         seeds, the very numbers there). Per row: truth lines answered over the seeds, the \
         mean tracking errors over the seeds, the largest difference of one marginal over \
         every truth line and seed, and the wall seconds of the live runs (starting the \
         processes included).\n",
        if seeds > 1 {
            format!(" to {}", seeds - 1)
        } else {
            String::new()
        },
        took.as_secs_f64(),
        max = idmesh_belief::FactoredOptions::default().max_component,
    )?;
    write_live_rows(&mut out, rows)?;
    write_regional_cost(&mut out, costs)?;
    Ok(out)
}

/// The table of live against centralized accuracy: one row per crowd and
/// belief, its seeds pooled.
fn write_live_rows(out: &mut String, rows: &[(Crowd, Run)]) -> std::fmt::Result {
    writeln!(out, "{TABLE_HEADER}")?;
    let mut done: Vec<(usize, u64, Start, Kind)> = Vec::new();
    for (crowd, run) in rows {
        let key = (crowd.n, crowd.swap.to_bits(), crowd.start, run.kind);
        if done.contains(&key) {
            continue;
        }
        done.push(key);
        let same: Vec<&Run> = rows
            .iter()
            .filter(|(c, r)| (c.n, c.swap.to_bits(), c.start, r.kind) == key)
            .map(|(_, r)| r)
            .collect();
        let mean = |f: fn(&Run) -> f64| same.iter().map(|r| f(r)).sum::<f64>() / same.len() as f64;
        let largest = same.iter().map(|r| r.largest.0).fold(0.0, f64::max);
        let row = LiveRow {
            n: crowd.n,
            swap: crowd.swap,
            start: crowd.start.label().to_string(),
            belief: run.kind.name().to_string(),
            truth_lines: same.iter().map(|r| r.truths).sum(),
            live: mean(|r| r.live_error),
            centralized: mean(|r| r.central_error),
            largest,
            seconds: same.iter().map(|r| r.seconds).sum(),
        };
        writeln!(out, "{}", row.markdown())?;
    }
    Ok(())
}

/// The section on the regional rule's cost: the local rule against the
/// regional one with 2, 4 and 8 leaders, one row per crowd.
fn write_regional_cost(out: &mut String, costs: &[(Crowd, f64, Vec<f64>)]) -> std::fmt::Result {
    writeln!(
        out,
        "\n## The regional rule's accuracy cost\n\n\
         The regional rule keeps every component inside one leader's region, so that \
         leaders seldom move components ([deploying](guide/deploying.md)): a mix of tracks in two \
         regions takes both to one of the two leaders (with fitted regions; with fixed places it \
         is projected back onto their two components instead of merging them), and a \
         track handed over to another region is split off its component (by moment \
         matching, [architecture](design/architecture.md)). Its cost depends on how many regions the field is \
         cut into. The centralized engine runs it exactly as the leaders do (the rows \
         *factored, regional rule* above agree to {TOLERANCE:e} with {LEADERS} leaders); here \
         it is run on the same traces with the leaders of a loopback deployment of 2, 4 and 8 \
         leaders (regions fitted to the crowd, the default), against the local rule alone (mean tracking error \
         over the seeds; the difference in brackets).\n"
    )?;
    writeln!(
        out,
        "| n | swap | start | local rule | regional, 2 leaders | regional, 4 leaders | regional, 8 leaders |"
    )?;
    writeln!(out, "|---:|---:|---|---:|---:|---:|---:|")?;
    let mut seen: Vec<(usize, u64, Start)> = Vec::new();
    for (crowd, _, _) in costs {
        let key = (crowd.n, crowd.swap.to_bits(), crowd.start);
        if seen.contains(&key) {
            continue;
        }
        seen.push(key);
        let same: Vec<&(Crowd, f64, Vec<f64>)> = costs
            .iter()
            .filter(|(c, _, _)| (c.n, c.swap.to_bits(), c.start) == key)
            .collect();
        let count = same.len() as f64;
        let local = same.iter().map(|c| c.1).sum::<f64>() / count;
        let mut line = format!(
            "| {} | {} | {} | {local:.4} |",
            crowd.n,
            crowd.swap,
            crowd.start.label()
        );
        for i in 0..REGIONAL_LEADERS.len() {
            let regional = same.iter().map(|c| c.2[i]).sum::<f64>() / count;
            line.push_str(&format!(" {regional:.4} ({:+.4}) |", regional - local));
        }
        writeln!(out, "{line}")?;
    }
    Ok(())
}
