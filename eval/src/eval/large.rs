//! The large-field section of `idmesh eval` (the issue "The factored
//! belief at city scale"): fields of n = 500, 2,000 and 10,000 tracks,
//! k = n/2, 5,000 events of the Table III shape (half mixes at swap 0.5,
//! partners at most 4 apart in id: crowds of one density; the colour
//! histogram sensor of the trace spec), from the known red tracks.
//!
//! The factored belief (coupled and local splits) against particle filters
//! sized to take as long as it and ten times as long, the first-order
//! Radon projection and the overcomplete Radon method (Section 5.3, B =
//! 5n). Scores are the trace spec's (ties shared, Brier) at every 100th
//! event. The streams come from `idmesh_belief::workload` rather than the
//! crowd simulator: a social-force crowd of 10,000 people would take
//! longer to simulate than the filters take to run, and the shape of the
//! events is what the filters see.
//!
//! Self-contained: one call, [`section`], returns the markdown.

use super::methods::Method;
use super::scenarios::Step;
use super::score::{Running, Stopwatch};
use anyhow::Result;
use idmesh_belief::workload::{generate_with, WorkloadSpec};
use idmesh_belief::{brier_score, expected_tracking_error, Field};
use std::fmt::Write as _;

/// The sizes and event count of a run of the section.
#[derive(Debug, Clone)]
pub(crate) struct LargeFields {
    pub sizes: Vec<usize>,
    pub events: usize,
    /// Score every this many events.
    pub every: usize,
}

impl LargeFields {
    /// The grid asked for.
    pub(crate) fn full() -> Self {
        LargeFields {
            sizes: vec![500, 2_000, 10_000],
            events: 5_000,
            every: 100,
        }
    }

    /// A small grid for the quick preset (and tests).
    pub(crate) fn quick() -> Self {
        LargeFields {
            sizes: vec![200],
            events: 1_000,
            every: 100,
        }
    }
}

/// The overcomplete Radon method runs up to this n only: each of its atoms
/// holds up to k = n/2 tracks, so an event costs O(B·k) and a run at
/// n = 2,000 would take longer than the rest of the evaluation together.
const OVERCOMPLETE_UP_TO: usize = 500;

/// Its budget: Table III's largest (5n at n = 100).
const OVERCOMPLETE_BUDGET: usize = 500;

/// The leaders of the deployed row: its tracks placed along a street, in
/// fitted regions.
const LEADERS: usize = 8;

/// The probe run that prices one particle: P of this many.
const PROBE_PARTICLES: usize = 1_000;

/// The particle counts sized from the probe stay within these bounds.
const PARTICLE_BOUNDS: (usize, usize) = (10, 2_000_000);

/// How one filter did on one stream.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Run {
    error: f64,
    brier: f64,
    seconds: f64,
}

/// Replays the stream of `spec` through `method`, scoring at every
/// `every`-th event; `None` when the filter fails.
fn run(method: Method, spec: &WorkloadSpec, every: usize) -> Option<Run> {
    let work = generate_with(spec, every);
    let field = Field::known(spec.tracks, work.initial_red.clone());
    let watch = Stopwatch::start();
    let built = method.build(field.clone(), spec.seed).ok()?;
    let mut filter = Running::new(built, method, &field).ok()?;
    if let Running::Deployed(regional) = &mut filter {
        // The workload's tracks mix with those at most a few indices
        // away: a track's index is its place along the street.
        for track in 0..spec.tracks as u32 {
            let at = Step::Move {
                track,
                x: f64::from(track),
                y: 0.0,
            };
            regional.apply_line(&at.line()).ok()?;
        }
    }
    let mut scored = Vec::new();
    let mut truth = work.truth.iter();
    for (i, event) in work.events.iter().enumerate() {
        match &mut filter {
            Running::Plain(filter) => filter.apply(event).ok()?,
            Running::Deployed(regional) => regional.apply_line(&Step::Event(*event).line()).ok()?,
        }
        if (i + 1) % every == 0 {
            let m = filter.marginals().ok()?;
            scored.push((m, truth.next()?));
        }
    }
    let seconds = watch.seconds();
    let k = Some(spec.red);
    let count = scored.len().max(1) as f64;
    let error = scored
        .iter()
        .map(|(m, t)| expected_tracking_error(m, k, t))
        .sum::<f64>()
        / count;
    let brier = scored.iter().map(|(m, t)| brier_score(m, t)).sum::<f64>() / count;
    Some(Run {
        error,
        brier,
        seconds,
    })
}

/// Runs `jobs` on `workers` threads, results in order.
fn parallel(jobs: &[(Method, WorkloadSpec)], every: usize, workers: usize) -> Vec<Option<Run>> {
    let visit: Vec<usize> = (0..jobs.len()).collect();
    super::grid::parallel_map(
        jobs,
        &visit,
        workers.max(1),
        |_, (method, spec)| run(*method, spec, every),
        &|_, _| {},
    )
}

/// The section's markdown, run on `workers` threads.
pub(crate) fn section(grid: &LargeFields, workers: usize) -> Result<String> {
    let spec = |n: usize| WorkloadSpec {
        events: grid.events,
        ..WorkloadSpec::table3(n, 1)
    };
    let fixed = |n: usize| {
        let mut methods = vec![
            Method::Factored,
            Method::FactoredLocal,
            Method::Deployed(LEADERS),
            Method::Order(1),
            Method::Particles(PROBE_PARTICLES),
        ];
        if n <= OVERCOMPLETE_UP_TO {
            methods.push(Method::Overcomplete(OVERCOMPLETE_BUDGET));
        }
        methods
    };
    // First pass: everything but the sized particle filters.
    let jobs: Vec<(Method, WorkloadSpec)> = grid
        .sizes
        .iter()
        .flat_map(|&n| fixed(n).into_iter().map(move |m| (m, spec(n))))
        .collect();
    eprintln!("eval: large fields, {} runs", jobs.len());
    let first = parallel(&jobs, grid.every, workers);
    let result = |n: usize, m: Method| -> Option<Run> {
        jobs.iter()
            .zip(&first)
            .find(|((jm, js), _)| *jm == m && js.tracks == n)
            .and_then(|(_, r)| *r)
    };
    // Second pass: particles priced by the probe (time linear in P), at
    // the time of each factored variant and at ten times it.
    let sized = |n: usize, base: Method, factor: f64| -> Option<usize> {
        let probe = result(n, Method::Particles(PROBE_PARTICLES))?;
        let target = result(n, base)?.seconds * factor;
        let p = (PROBE_PARTICLES as f64 * target / probe.seconds).round() as usize;
        Some(p.clamp(PARTICLE_BOUNDS.0, PARTICLE_BOUNDS.1))
    };
    let mut planned: Vec<(usize, Method, f64, usize)> = Vec::new();
    for &n in &grid.sizes {
        for base in [Method::Factored, Method::FactoredLocal] {
            for factor in [1.0, 10.0] {
                if let Some(p) = sized(n, base, factor) {
                    planned.push((n, base, factor, p));
                }
            }
        }
    }
    let jobs2: Vec<(Method, WorkloadSpec)> = planned
        .iter()
        .map(|&(n, _, _, p)| (Method::Particles(p), spec(n)))
        .collect();
    let second = parallel(&jobs2, grid.every, workers);

    let mut out = String::new();
    writeln!(
        out,
        "\n## Large fields: the factored belief at city scale\n\n\
         n = {} tracks, k = n/2, {} events of the Table III shape (half of them mixes at swap \
         0.5 between tracks at most 4 apart, so every field is a crowd of the same density; the \
         trace spec's colour-histogram sensor), from the known red tracks, one stream per n \
         (`idmesh_belief::workload`, seed 1: a simulated crowd of 10,000 would take longer to \
         simulate than the filters take to run). Scored at every {}th event: tracking error with \
         ties shared, Brier score. Seconds are CPU time inside the filter (building it, every \
         event, every query). The particle filters are sized from a P = {} run (time is linear \
         in P) to take as long as each factored variant, and ten times as long; their seconds \
         column says how close that came. The deployed row is what {} leaders compute at the \
         default settings, each track placed at its index along a street (the workload's \
         neighbours) and the regions fitted to them. The overcomplete Radon method (B = {}) runs at \
         n ≤ {} only: its atoms hold up to k tracks each, so an event costs O(B·k).\n",
        grid.sizes
            .iter()
            .map(|n| n.to_string())
            .collect::<Vec<_>>()
            .join(" / "),
        grid.events,
        grid.every,
        PROBE_PARTICLES,
        LEADERS,
        OVERCOMPLETE_BUDGET,
        OVERCOMPLETE_UP_TO,
    )?;
    writeln!(
        out,
        "| n | method | tracking error | Brier | seconds |\n|---|---|---|---|---|"
    )?;
    let row = |out: &mut String, n: usize, label: &str, r: Option<Run>| -> Result<()> {
        match r {
            Some(r) => writeln!(
                out,
                "| {n} | {label} | {:.3} | {:.3} | {:.3} |",
                r.error, r.brier, r.seconds
            )?,
            None => writeln!(out, "| {n} | {label} | failed | | |")?,
        }
        Ok(())
    };
    let mut verdicts = Vec::new();
    for &n in &grid.sizes {
        for m in fixed(n) {
            let label = match m {
                Method::Factored => "factored, coupled splits".to_string(),
                Method::FactoredLocal => "factored, local rule".to_string(),
                Method::Deployed(l) => format!(
                    "factored, as deployed on {l} leaders (default: local rule, regional rule, fitted regions)"
                ),
                other => other.label(),
            };
            row(&mut out, n, &label, result(n, m))?;
        }
        for ((pn, base, factor, p), r) in planned.iter().zip(&second) {
            if *pn != n {
                continue;
            }
            let what = match base {
                Method::Factored => "coupled",
                _ => "local",
            };
            let label = if *factor == 1.0 {
                format!("particles (P = {p}), equal time to factored {what}")
            } else {
                format!("particles (P = {p}), {factor:.0}× the time of factored {what}")
            };
            row(&mut out, n, &label, *r)?;
            if *factor > 1.0 {
                if let (Some(f), Some(r)) = (result(n, *base), r) {
                    verdicts.push(format!(
                        "n = {n}, {what}: {:.3} vs {:.3} ({})",
                        f.error,
                        r.error,
                        if f.error < r.error {
                            "beats"
                        } else {
                            "does not beat"
                        }
                    ));
                }
            }
        }
    }
    writeln!(
        out,
        "\nFactored against particles at ten times its time (tracking error): {}.",
        verdicts.join("; ")
    )?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_small_grid_has_every_row() {
        let grid = LargeFields {
            sizes: vec![40],
            events: 200,
            every: 50,
        };
        let text = section(&grid, 1).unwrap();
        for what in [
            "factored, coupled",
            "factored, local rule",
            "order 1",
            "overcomplete (B = 500)",
            "equal time to factored coupled",
            "10× the time of factored local",
        ] {
            assert!(text.contains(what), "{what}:\n{text}");
        }
        assert!(!text.contains("failed"), "{text}");
    }
}
