//! What a live deployment is scored against (`idmesh bench --accuracy`):
//! the Table III crowds of the full preset (n = 20/60/100, swap 0.5 and
//! 0.1, known start and uniform prior, the evaluation's seeds) written as
//! trace files, the centralized engine's marginals at their truth lines,
//! and the trace spec's tracking error, the scorer of every table of
//! results.md. Nothing here runs a deployment: this is the evaluation's
//! side of the comparison, so both sides replay the very traces and score
//! them the same way.

use super::args::Preset;
use super::methods::Method;
use super::plan::{budget, Experiment, Plan};
use super::scenarios::{ScenarioSpec, Scenes, Step, Trace};
use super::score::{replay, tracking_error};
use anyhow::{bail, Context, Result};
use idmesh_belief::{field_of, FactoredBelief, FactoredOptions, PropertyFilter};
use idmesh_placement::{RegionRule, Regional, Regions};
use idmesh_protocol::trace::{Line, TraceReader};
use idmesh_sim::write_trace;
use idmesh_sim::SimEvent;
use std::path::Path;

use super::scenarios::Start;

use super::scenarios::MOVE_INTERVAL;

/// One Table III crowd: a point of the full preset and one of its seeds.
#[derive(Debug, Clone)]
pub struct Crowd {
    pub n: usize,
    pub swap: f64,
    pub start: Start,
    pub seed: u64,
    spec: ScenarioSpec,
}

/// The Table III crowds of the full preset with `seeds` seeds per point
/// (the evaluation's seeds 0, 1, …), in the evaluation's order.
pub fn table3_crowds(seeds: usize) -> Vec<Crowd> {
    Plan::new(Preset::Full, Some(seeds))
        .points
        .into_iter()
        .filter(|p| p.experiment == Experiment::Table3)
        .flat_map(|p| {
            p.specs.into_iter().map(move |spec| Crowd {
                n: p.n,
                swap: p.swap,
                start: p.start,
                seed: spec.seed,
                spec,
            })
        })
        .collect()
}

/// The centralized engines a live belief is compared with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Engine {
    /// The factored belief, default options, local split rule: what
    /// factored leaders run when there are several (the `factored, local
    /// rule` rows).
    FactoredLocal,
    /// The overcomplete Radon belief with the distributed rule at the
    /// Table III budget B = 5n (the `overcomplete, distributed rule` rows).
    RadonDistributed,
}

impl Engine {
    fn method(self, n: usize) -> Method {
        match self {
            Engine::FactoredLocal => Method::FactoredLocal,
            Engine::RadonDistributed => Method::Distributed(budget(n)),
        }
    }
}

/// The Table III budget at n tracks (B = 5n).
pub fn table3_budget(n: usize) -> usize {
    budget(n)
}

/// A crowd written as a trace file, with what scoring it needs.
pub struct Written {
    /// Per truth line, in order: the events (mix, observe and move lines)
    /// before it, which is where `?events=N` asks.
    pub truth_events: Vec<u64>,
    /// The event lines of the file, in order (what a producer sends).
    pub event_lines: Vec<String>,
    trace: Trace,
}

impl Crowd {
    /// "n = 20, swap 0.5, known start, seed 0".
    pub fn label(&self) -> String {
        format!(
            "n = {}, swap {}, {}, seed {}",
            self.n,
            self.swap,
            self.start.label(),
            self.seed
        )
    }

    /// Generates the crowd and writes it to `path`, with `move` lines; the
    /// filters' trace is the evaluation's (moves draw no randomness).
    pub fn write(&self, path: &Path) -> Result<Written> {
        let (file, trace) = self
            .spec
            .generated(&Scenes::default(), Some(MOVE_INTERVAL))
            .with_context(|| self.label())?;
        let out = std::fs::File::create(path)
            .with_context(|| format!("cannot create {}", path.display()))?;
        write_trace(
            &file,
            std::io::BufWriter::new(out),
            path.display().to_string(),
        )
        .with_context(|| format!("cannot write {}", path.display()))?;
        let mut events = 0u64;
        let mut truth_events = Vec::new();
        for e in &file.events {
            match e.event {
                SimEvent::Truth { .. } => truth_events.push(events),
                _ => events += 1,
            }
        }
        let event_lines: Vec<String> = std::fs::read_to_string(path)?
            .lines()
            .skip(1)
            .filter(|line| !line.starts_with("{\"kind\":\"truth\""))
            .map(str::to_owned)
            .collect();
        let truths = trace
            .steps
            .iter()
            .filter(|s| matches!(s, Step::Truth(_)))
            .count();
        if truths != truth_events.len() || event_lines.len() as u64 != events {
            bail!(
                "{}: {} truth lines and {} event lines written, {} truths and {events} events \
                 generated",
                path.display(),
                truth_events.len(),
                event_lines.len(),
                truths
            );
        }
        Ok(Written {
            truth_events,
            event_lines,
            trace,
        })
    }
}

impl Written {
    pub fn tracks(&self) -> usize {
        self.trace.field.tracks
    }

    /// The centralized engine's marginals at every truth line, in order.
    pub fn centralized(&self, engine: Engine, seed: u64) -> Result<Vec<Vec<f64>>> {
        let run =
            replay(engine.method(self.tracks()), &self.trace, seed).map_err(anyhow::Error::msg)?;
        Ok(run.answers.into_iter().map(|(m, _)| m).collect())
    }

    /// The centralized factored belief with `options` under the regional
    /// rule of `leaders` leaders with regions by `rule`
    /// (docs/design/architecture.md, "Components that stay in their
    /// region"), replaying the file this crowd was written to (`path`, with
    /// its `move` lines): its marginals at every truth line, in order. What
    /// `idmesh replay --leaders` (or `--regions`) computes.
    pub fn regional(
        &self,
        path: &Path,
        options: FactoredOptions,
        rule: &RegionRule,
        leaders: usize,
    ) -> Result<Vec<Vec<f64>>> {
        let mut reader = TraceReader::open(path)?;
        let field = field_of(&reader.read_header()?);
        let tracks = field.tracks;
        let mut engine = Regional::new(
            FactoredBelief::with_options(field, options)?,
            Regions::new(rule, leaders, tracks),
        );
        let mut answers = Vec::new();
        while let Some(numbered) = reader.read_line()? {
            let at = |e| anyhow::anyhow!("{}:{}: {e}", path.display(), numbered.number);
            match &numbered.line {
                Line::Truth(_) => answers.push(engine.marginals().map_err(at)?),
                line => engine.apply_line(line).map_err(at)?,
            }
        }
        Ok(answers)
    }

    /// The trace spec's tracking error of `answers`, one per truth line in
    /// order: the evaluation's scorer.
    pub fn tracking_error(&self, answers: &[Vec<f64>]) -> Result<f64> {
        let truths: Vec<&[u32]> = self
            .trace
            .steps
            .iter()
            .filter_map(|s| match s {
                Step::Truth(red) => Some(red.as_slice()),
                Step::Event(_) | Step::Move { .. } => None,
            })
            .collect();
        if answers.len() != truths.len() {
            bail!("{} answers for {} truth lines", answers.len(), truths.len());
        }
        if let Some((i, m)) = answers
            .iter()
            .enumerate()
            .find(|(_, m)| m.len() != self.tracks())
        {
            bail!(
                "truth line {i}: {} marginals for {} tracks",
                m.len(),
                self.tracks()
            );
        }
        let paired: Vec<(Vec<f64>, &[u32])> = answers.iter().cloned().zip(truths).collect();
        Ok(tracking_error(&paired, self.trace.field.red.known()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_crowds_are_the_table3_grid_and_score_as_the_evaluation_does() {
        let crowds = table3_crowds(1);
        // 3 n × 2 swaps × 2 starts, one seed each.
        assert_eq!(crowds.len(), 12);
        assert!(crowds.iter().all(|c| c.seed == 0));
        let crowd = crowds
            .iter()
            .find(|c| c.n == 20 && c.start == Start::Uniform)
            .unwrap();
        let dir = std::env::temp_dir().join(format!("idmesh-accuracy-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("crowd.jsonl");
        let written = crowd.write(&path).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert!(!text.lines().next().unwrap().contains("initial_red"));
        assert!(text.contains("\"kind\":\"move\""));
        let central = written.centralized(Engine::FactoredLocal, 0).unwrap();
        let error = written.tracking_error(&central).unwrap();
        let scored = super::super::score::score(Method::FactoredLocal, &written.trace, 0);
        assert_eq!(error, scored.error);
        assert!(written.tracking_error(&central[1..]).is_err());
    }

    #[test]
    fn a_deployed_row_is_the_regional_replay_of_the_written_file() {
        let crowd = table3_crowds(1)
            .into_iter()
            .find(|c| c.n == 100 && c.swap == 0.5 && c.start == Start::Known)
            .unwrap();
        let dir = std::env::temp_dir().join(format!("idmesh-deployed-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("crowd.jsonl");
        let written = crowd.write(&path).unwrap();
        let options = match Method::FactoredLocal.recipe(0) {
            crate::filters::Recipe::Factored(options) => options,
            other => panic!("{other:?}"),
        };
        let scored = |leaders: usize| {
            super::super::score::score(Method::Deployed(leaders), &written.trace, 0).error
        };
        for leaders in [4, 8] {
            let regional = written
                .regional(&path, options.clone(), &RegionRule::fitted(), leaders)
                .unwrap();
            assert_eq!(written.tracking_error(&regional).unwrap(), scored(leaders));
        }
        // The regions matter: one leader holds the whole belief and weighs
        // its splits by all of it, and eight keep components apart at
        // other events.
        let coupled = super::super::score::score(Method::Factored, &written.trace, 0).error;
        let local = super::super::score::score(Method::FactoredLocal, &written.trace, 0).error;
        assert_eq!(scored(1), coupled);
        assert_ne!(scored(8), local);
        // A crowd of 20 is held whole by one of the leaders.
        let small = table3_crowds(1)
            .into_iter()
            .find(|c| c.n == 20 && c.swap == 0.5 && c.start == Start::Known)
            .unwrap();
        let small = small.write(&dir.join("small.jsonl")).unwrap();
        let score = |method| super::super::score::score(method, &small.trace, 0).error;
        assert_eq!(score(Method::Deployed(4)), score(Method::Factored));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
