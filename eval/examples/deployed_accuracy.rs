//! How far a deployment's factored belief lands from the exact filter on
//! small crowds, by how many leaders share it and by the count coupling of
//! their splits: what separates the belief a deployment of several
//! leaders serves from the one `idmesh replay` and a deployment of one
//! leader serve (docs/design/beliefs.md, "Who weighs a split").
//!
//! The Table III crowds of n = 20 (swap 0.5 and 0.1, known start and
//! uniform prior, the evaluation's seeds 0 to S − 1, `move` lines every
//! second), written as `bench --accuracy` writes them. At every truth line
//! each belief's marginals are set against the exact filter's (mean
//! |ΔP(red)| over the tracks); a crowd's score is the mean over its truth
//! lines, a row the mean over the crowds ± 1.96 standard errors, with the
//! mean paired difference from the one holder's belief (the coupled rule)
//! on the same crowds. The rows under the regional rule are
//! `idmesh_placement::Regional` with regions fitted to the crowd, as
//! `idmesh replay --leaders L` runs it; "coupled" under it is what leaders
//! would compute if each could weigh its splits by the whole belief,
//! which none can: it separates what the regional rule costs from what
//! the local rule costs.
//!
//!     cargo run --release -p idmesh-eval --example deployed_accuracy -- [--seeds S] [--out FILE]

use anyhow::{bail, Context, Result};
use idmesh_belief::{
    event_of, field_of, mean_with_interval, Coupling, DenseFilter, FactoredBelief, FactoredOptions,
    PropertyFilter,
};
use idmesh_eval::eval::table3_crowds;
use idmesh_placement::{split_coupling, RegionRule, Regional, Regions};
use idmesh_protocol::trace::{Line, TraceReader};
use idmesh_protocol::wire::factored::{held_whole, DEFAULT_SPREAD_ABOVE};
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

/// The crowd size studied: the largest Table III size the exact filter
/// runs at.
const N: usize = 20;

/// One belief of the study: its row label, its coupling (None: what a
/// deployment of that many leaders decides at its defaults), and the
/// leaders whose regions it runs under (1: no regions).
struct Config {
    name: &'static str,
    coupling: Option<Coupling>,
    leaders: usize,
}

const CONFIGS: [Config; 8] = [
    Config {
        name: "one holder: coupled (replay, one leader)",
        coupling: Some(Coupling::Coupled),
        leaders: 1,
    },
    Config {
        name: "one holder: local",
        coupling: Some(Coupling::Local),
        leaders: 1,
    },
    Config {
        name: "2 leaders as deployed (default: held whole)",
        coupling: None,
        leaders: 2,
    },
    Config {
        name: "2 leaders spread, regional: local (spread_above = 0)",
        coupling: Some(Coupling::Local),
        leaders: 2,
    },
    Config {
        name: "2 leaders spread, regional: coupled (no leader can)",
        coupling: Some(Coupling::Coupled),
        leaders: 2,
    },
    Config {
        name: "4 leaders as deployed (default: held whole)",
        coupling: None,
        leaders: 4,
    },
    Config {
        name: "4 leaders spread, regional: local (spread_above = 0)",
        coupling: Some(Coupling::Local),
        leaders: 4,
    },
    Config {
        name: "4 leaders spread, regional: coupled (no leader can)",
        coupling: Some(Coupling::Coupled),
        leaders: 4,
    },
];

impl Config {
    /// The coupling and the leaders the belief runs under: a row "as
    /// deployed" takes what a deployment of its leaders decides for a
    /// crowd of `tracks` at the default `spread_above` (held whole: one
    /// holder, the coupled rule; spread: the local rule under regions).
    fn resolved(&self, tracks: usize) -> (Coupling, usize) {
        match self.coupling {
            Some(coupling) => (coupling, self.leaders),
            None => match held_whole(tracks as u32, self.leaders, DEFAULT_SPREAD_ABOVE) {
                true => (split_coupling(true), 1),
                false => (split_coupling(false), self.leaders),
            },
        }
    }
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let value = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
    };
    let seeds: usize = match value("--seeds") {
        Some(s) => s.parse().context("--seeds takes a number")?,
        None => 20,
    };
    let out = value("--out").cloned();
    let started = Instant::now();
    let dir = std::env::temp_dir().join(format!("idmesh-deployed-accuracy-{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    // Per case (swap, start), per config: each crowd's mean |ΔP|.
    let mut cases: Vec<(String, Vec<Vec<f64>>)> = Vec::new();
    for crowd in table3_crowds(seeds).into_iter().filter(|c| c.n == N) {
        let case = format!("swap {}, {}", crowd.swap, crowd.start.label());
        let path = dir.join("crowd.jsonl");
        crowd.write(&path)?;
        let exact = answers(&path, None)?;
        let mut scores = Vec::new();
        for config in &CONFIGS {
            let got = answers(&path, Some(config))?;
            scores.push(distance(&got, &exact).with_context(|| crowd.label())?);
        }
        if cases.last().is_none_or(|(c, _)| *c != case) {
            cases.push((case, vec![Vec::new(); CONFIGS.len()]));
        }
        let (_, rows) = cases.last_mut().expect("just pushed");
        for (row, score) in rows.iter_mut().zip(scores) {
            row.push(score);
        }
        eprintln!(
            "{}: done at {:.0} s",
            crowd.label(),
            started.elapsed().as_secs_f64()
        );
    }
    std::fs::remove_dir_all(&dir).ok();
    let md = report(&cases, seeds, started.elapsed().as_secs_f64());
    match out {
        Some(path) => {
            std::fs::write(&path, &md).with_context(|| format!("cannot write {path}"))?;
            eprintln!("wrote {path}");
        }
        None => print!("{md}"),
    }
    Ok(())
}

/// The marginals at every truth line of the trace at `path`: the exact
/// filter's (`config` None) or the factored belief's under `config`.
fn answers(path: &Path, config: Option<&Config>) -> Result<Vec<Vec<f64>>> {
    let mut reader = TraceReader::open(path)?;
    let field = field_of(&reader.read_header()?);
    let tracks = field.tracks;
    enum Filter {
        Plain(Box<dyn PropertyFilter>),
        Regional(Box<Regional>),
    }
    let mut filter = match config {
        None => Filter::Plain(Box::new(DenseFilter::new(field)?)),
        Some(c) => {
            let (coupling, leaders) = c.resolved(tracks);
            let options = FactoredOptions {
                coupling,
                ..FactoredOptions::default()
            };
            let belief = FactoredBelief::with_options(field, options)?;
            match leaders {
                1 => Filter::Plain(Box::new(belief)),
                l => Filter::Regional(Box::new(Regional::new(
                    belief,
                    Regions::new(&RegionRule::fitted(), l, tracks),
                ))),
            }
        }
    };
    let mut out = Vec::new();
    while let Some(numbered) = reader.read_line()? {
        let at = |e| anyhow::anyhow!("{}:{}: {e}", path.display(), numbered.number);
        match (&numbered.line, &mut filter) {
            (Line::Truth(_), Filter::Plain(f)) => out.push(f.marginals().map_err(at)?),
            (Line::Truth(_), Filter::Regional(r)) => out.push(r.marginals().map_err(at)?),
            (line, Filter::Regional(r)) => r.apply_line(line).map_err(at)?,
            (line, Filter::Plain(f)) => {
                if let Some(event) = event_of(line) {
                    f.apply(&event).map_err(at)?;
                }
            }
        }
    }
    Ok(out)
}

/// The mean over truth lines of the mean |ΔP(red)| over the tracks.
fn distance(got: &[Vec<f64>], exact: &[Vec<f64>]) -> Result<f64> {
    if got.len() != exact.len() || got.is_empty() {
        bail!("{} answers against {} exact ones", got.len(), exact.len());
    }
    let per_line = got
        .iter()
        .zip(exact)
        .map(|(g, e)| g.iter().zip(e).map(|(a, b)| (a - b).abs()).sum::<f64>() / e.len() as f64);
    Ok(per_line.sum::<f64>() / got.len() as f64)
}

fn report(cases: &[(String, Vec<Vec<f64>>)], seeds: usize, seconds: f64) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# The deployed factored belief against the exact filter on small crowds\n\n\
         Written by `cargo run --release -p idmesh-eval --example deployed_accuracy -- \
         --seeds {seeds} --out docs/deployed-accuracy.md` (eval/examples/deployed_accuracy.rs), \
         {seconds:.0} s on this machine. Every crowd is seeded: every number is the same on \
         every run.\n\n\
         The Table III crowds of n = {N} (the evaluation's seeds 0 to {}, k = n/2, 1000 \
         events, `move` lines every second). At every truth line each belief's marginals are \
         set against the exact filter's (mean \\|ΔP(red)\\| over the tracks); a crowd's score \
         is its mean over the truth lines, a cell the mean over the crowds ± 1.96 standard \
         errors, and \"− one holder\" the mean paired difference from the first row on the \
         same crowds. Every belief runs the default options (components of at most 6 tracks, \
         least-loss splits). The first row is what `idmesh replay` and a deployment of one \
         leader compute. \"As deployed\" rows are what a deployment of that many leaders \
         computes at the default settings (`idmesh replay --leaders L`): a crowd of at most \
         {DEFAULT_SPREAD_ABOVE} tracks is held whole by the first leader, so they are the first \
         row. The \"spread\" rows are what those leaders compute when told to share so small \
         a crowd (`spread_above = 0`, `idmesh replay --leaders L --spread-above 0`: the local \
         rule under the regional rule, regions fitted to the crowd), beside the regional rule \
         with every split weighed by the whole belief, which no leader of several can: they \
         part what the regional rule costs from what the local rule costs.",
        seeds.saturating_sub(1)
    );
    let mut all: Vec<Vec<f64>> = vec![Vec::new(); CONFIGS.len()];
    for (case, rows) in cases {
        let _ = writeln!(md, "\n## {case} ({} crowds)\n", rows[0].len());
        table(&mut md, rows);
        for (a, r) in all.iter_mut().zip(rows) {
            a.extend(r);
        }
    }
    let _ = writeln!(md, "\n## All cases together ({} crowds)\n", all[0].len());
    table(&mut md, &all);
    md
}

fn table(md: &mut String, rows: &[Vec<f64>]) {
    let _ = writeln!(
        md,
        "| belief | mean \\|ΔP(red)\\| | − one holder |\n|---|---|---|"
    );
    for (config, row) in CONFIGS.iter().zip(rows) {
        let (d, dci) = mean_with_interval(row);
        let paired: Vec<f64> = row.iter().zip(&rows[0]).map(|(a, b)| a - b).collect();
        let (p, pci) = mean_with_interval(&paired);
        let _ = writeln!(
            md,
            "| {} | {d:.4} ± {dci:.4} | {p:+.4} ± {pci:.4} |",
            config.name
        );
    }
}
