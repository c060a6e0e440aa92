//! Events extracted from positions, on the real pedestrian scenes: the
//! section of results.md that checks `idmesh-extract` against the
//! simulator and calibrates its meeting model across scenes.
//!
//! On each scene the simulator plays a tracker that confuses people the
//! way [`TRACKER`] says (closer, slower meetings swap more: the approach
//! model of `idmesh_extract::MeetingModel`) and a colour sensor
//! that sees isolated people; it also writes what that tracker reported —
//! positions, class scores. Then:
//!
//! 1. **Same events.** The extractor, fed those reports with the
//!    tracker's own model, gives the simulator's mixes and observations,
//!    so the belief answers as on the simulator's events (the largest
//!    difference of a marginal is printed; a test holds it to 1e-9).
//! 2. **Calibration, leave one scene out.** A user does not know the
//!    tracker's model; they calibrate it on annotated meetings (did the
//!    tracker swap this pair?). For each scene the model is fitted
//!    (maximum likelihood, all three parameters) on the labelled meetings
//!    of the *other* scenes, and the scene's reports are extracted with
//!    it; beside it, the simplest calibration (a constant: the other
//!    scenes' share of swapped meetings) and the uncalibrated default
//!    (constant 0.5). The tracking error of each is the belief's on the
//!    scene's truth.

use super::methods::Method;
use super::scenarios::{convert, Trace, SCENES};
use super::score::score;
use anyhow::{bail, Context, Result};
use idmesh_extract::{Extractor, Meeting, MeetingModel, RosterPolicy};
use idmesh_protocol::trace::Line;
use idmesh_sim::ExtractionParams;
use idmesh_sim::{data_dir, Scene, Timing};
use idmesh_sim::{GeneratedTrace, Scenario, SimEvent, TimedEvent};
use std::fmt::Write as _;
use std::sync::Arc;

/// The simulated tracker: a touching, standing pair swaps with 0.8; the
/// chance falls with the closest distance (σ = 0.35 m) and with the
/// relative speed (halved at 0.7 m/s).
pub(crate) const TRACKER: MeetingModel = MeetingModel::Approach {
    p_max: 0.8,
    sigma: 0.35,
    v0: 0.7,
};

/// Seconds of each scene simulated (from its start).
const SECONDS: f64 = 300.0;

/// What the belief is: what a deployment computes by default.
const METHOD: Method = Method::Deployed(1);

/// One scene's simulation and what its tracker reported.
pub(crate) struct SceneRun {
    pub scene: &'static str,
    pub people: usize,
    pub generated: GeneratedTrace,
    pub params: ExtractionParams,
    /// The meetings of the scene with whether the tracker swapped them.
    pub meetings: Vec<(Meeting, bool)>,
}

impl SceneRun {
    /// Simulates `SECONDS` of `scene` with the [`TRACKER`] model.
    pub(crate) fn simulate(scene: &'static str, loaded: Arc<Scene>, seed: u64) -> Result<SceneRun> {
        let scenario = Scenario::pedestrians_loaded(loaded)
            .duration(SECONDS)
            .meetings(TRACKER)
            .move_interval(None)
            .tracker_reports(true)
            .seed(seed);
        let generated = scenario
            .generate()
            .with_context(|| format!("simulating {scene}"))?;
        let mut run = SceneRun {
            scene,
            people: generated.header.tracks,
            generated,
            params: scenario.extraction_params().clone(),
            meetings: Vec::new(),
        };
        // The meetings as the extractor measures them, labelled by the
        // simulator's draws (the mixes come out in the same order).
        let (_, meetings) = run.extract(TRACKER)?;
        let swaps: Vec<bool> = run
            .generated
            .events
            .iter()
            .filter_map(|e| match e.event {
                SimEvent::Mix { exchanged, .. } => Some(exchanged),
                _ => None,
            })
            .collect();
        if swaps.len() != meetings.len() {
            bail!(
                "{scene}: the extractor found {} meetings, the simulator {}",
                meetings.len(),
                swaps.len()
            );
        }
        run.meetings = meetings.into_iter().zip(swaps).collect();
        Ok(run)
    }

    /// The trace the belief replays: the simulator's own events.
    pub(crate) fn simulated(&self) -> Trace {
        convert(
            &self.generated,
            self.params.mix_distance,
            self.params.observe_distance,
        )
    }

    /// The trace of the events `idmesh-extract` finds in the reports with
    /// `model`, with the simulator's truth lines; and the meetings.
    pub(crate) fn extract(&self, model: MeetingModel) -> Result<(Trace, Vec<Meeting>)> {
        let config = ExtractionParams {
            meetings: model,
            ..self.params.clone()
        }
        .extractor_config();
        let n = self.people as u32;
        let mut extractor = Extractor::new(config, RosterPolicy::Declared((0..n).collect()))
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let mut lines = Vec::new();
        let reports = self
            .generated
            .reports
            .as_ref()
            .context("the simulation kept no reports")?;
        for report in reports {
            extractor
                .push(report.clone(), &mut lines)
                .with_context(|| format!("{}: a simulated report", self.scene))?;
        }
        extractor.finish(&mut lines);
        let mut events: Vec<TimedEvent> = lines
            .iter()
            .filter_map(|line| {
                let (time, event) = match line {
                    Line::Mix(m) => (
                        m.time,
                        SimEvent::Mix {
                            a: m.a,
                            b: m.b,
                            swap: m.swap,
                            exchanged: false,
                        },
                    ),
                    Line::Observe(o) => (
                        o.time,
                        SimEvent::Observe {
                            track: o.track,
                            red: o.red,
                            blue: o.blue,
                        },
                    ),
                    _ => return None,
                };
                Some(TimedEvent { time, event })
            })
            .collect();
        // The truth lines after the events of their time, as simulated.
        let truths = self
            .generated
            .events
            .iter()
            .filter(|e| matches!(e.event, SimEvent::Truth { .. }));
        let mut merged = Vec::with_capacity(events.len());
        let mut events_left = events.drain(..).peekable();
        for truth in truths {
            while let Some(e) = events_left.next_if(|e| e.time <= truth.time) {
                merged.push(e);
            }
            merged.push(truth.clone());
        }
        merged.extend(events_left);
        let extracted = GeneratedTrace {
            events: merged,
            reports: None,
            ..self.generated.clone()
        };
        Ok((
            convert(
                &extracted,
                self.params.mix_distance,
                self.params.observe_distance,
            ),
            extractor.take_meetings(),
        ))
    }
}

/// Every scene, simulated with `seed`.
pub(crate) fn scene_runs(seed: u64) -> Result<Vec<SceneRun>> {
    SCENES
        .iter()
        .map(|&(name, file)| {
            let path = data_dir().join(file);
            let scene = Scene::load(&path, Timing::Auto)
                .with_context(|| format!("cannot load scene {}", path.display()))?;
            SceneRun::simulate(name, Arc::new(scene), seed)
        })
        .collect()
}

/// The largest difference between two traces' answers at their truth
/// lines, under the default belief.
pub(crate) fn largest_difference(x: &Trace, y: &Trace) -> Result<f64> {
    let answers = |t: &Trace| -> Result<Vec<Vec<f64>>> {
        let run = super::score::replay(METHOD, t, 0).map_err(|e| anyhow::anyhow!(e))?;
        Ok(run.answers.into_iter().map(|(m, _)| m).collect())
    };
    let (a, b) = (answers(x)?, answers(y)?);
    if a.len() != b.len() {
        bail!("{} truth lines against {}", a.len(), b.len());
    }
    Ok(a.iter()
        .zip(&b)
        .flat_map(|(p, q)| p.iter().zip(q).map(|(u, v)| (u - v).abs()))
        .fold(0.0, f64::max))
}

fn describe(model: &MeetingModel) -> String {
    match *model {
        MeetingModel::Constant(p) => format!("constant {p:.3}"),
        MeetingModel::Approach { p_max, sigma, v0 } => {
            format!("p_max {p_max:.2}, σ {sigma:.2} m, v₀ {v0:.2} m/s")
        }
    }
}

/// The results.md section.
pub(crate) fn section(seed: u64) -> Result<String> {
    let runs = scene_runs(seed)?;
    let mut out = String::new();
    let MeetingModel::Approach { p_max, sigma, v0 } = TRACKER else {
        unreachable!("the tracker follows the approach model")
    };
    writeln!(
        out,
        "\n## Events extracted from positions, on the real scenes\n\n\
         The first {SECONDS:.0} s of each scene (seed {seed}). The simulated tracker swaps a \
         meeting with the approach model (p_max {p_max}, σ {sigma} m, v₀ {v0} m/s: closer, \
         slower meetings swap more); the colour sensor looks at isolated people. The \
         simulator writes what that tracker reported (positions each step, class scores where \
         the sensor saw a colour), and `idmesh-extract` turns the reports back into events. \
         The belief is {} (what a deployment computes).\n\n\
         - *simulator*: the simulator's own events.\n\
         - *extracted, tracker's model*: the reports extracted with the model the tracker \
         follows; |Δp| is the largest difference of a marginal from the simulator's answers \
         at any truth line (the same events: a test holds it to 1e-9).\n\
         - *calibrated on the other scenes*: the model a user fits (maximum likelihood over \
         p_max, σ, v₀; `MeetingModel::fit_approach_all`) to the annotated meetings of the \
         four other scenes, then uses on this one — no scene is calibrated on itself.\n\
         - *constant, calibrated*: the simplest model, the other scenes' share of swapped \
         meetings.\n\
         - *constant 0.5*: no calibration (the extractor's default).\n",
        METHOD
    )
    .unwrap();
    writeln!(
        out,
        "| scene | people | mixes | swapped | simulator | extracted, tracker's model | |Δp| | \
         calibrated on the other scenes | fitted | constant, calibrated | constant 0.5 |"
    )
    .unwrap();
    writeln!(out, "|---|---|---|---|---|---|---|---|---|---|---|").unwrap();
    for (i, run) in runs.iter().enumerate() {
        let others: Vec<(Meeting, bool)> = runs
            .iter()
            .enumerate()
            .filter(|(j, _)| *j != i)
            .flat_map(|(_, r)| r.meetings.iter().copied())
            .collect();
        let fit = |m: Result<MeetingModel, _>| m.map_err(|e| anyhow::anyhow!("{e}"));
        let fitted = fit(MeetingModel::fit_approach_all(&others))?;
        let constant = fit(MeetingModel::fit_constant(&others))?;
        let simulated = run.simulated();
        let (same, _) = run.extract(TRACKER)?;
        let error = |t: &Trace| score(METHOD, t, seed).error;
        let swapped = run.meetings.iter().filter(|(_, s)| *s).count();
        writeln!(
            out,
            "| {} | {} | {} | {} | {:.3} | {:.3} | {:.0e} | {:.3} | {} | {:.3} ({}) | {:.3} |",
            run.scene,
            run.people,
            run.meetings.len(),
            swapped,
            error(&simulated),
            error(&same),
            largest_difference(&simulated, &same)?,
            error(&run.extract(fitted)?.0),
            describe(&fitted),
            error(&run.extract(constant)?.0),
            describe(&constant),
            error(&run.extract(MeetingModel::Constant(0.5))?.0),
        )
        .unwrap();
    }
    writeln!(
        out,
        "\nTracking error: the expected share of tracks labelled wrong at a truth line (lower \
         is better). How to calibrate a real tracker: [extracting.md](guide/extracting.md)."
    )
    .unwrap();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extracted_events_answer_as_the_simulators_on_every_scene() {
        for run in scene_runs(1).unwrap() {
            assert!(run.meetings.len() > 10, "{}: too few meetings", run.scene);
            let (same, _) = run.extract(TRACKER).unwrap();
            let difference = largest_difference(&run.simulated(), &same).unwrap();
            assert!(difference < 1e-9, "{}: {difference}", run.scene);
            // A model the tracker does not follow answers otherwise: the
            // comparison can fail.
            let (other, _) = run.extract(MeetingModel::Constant(0.5)).unwrap();
            assert!(largest_difference(&run.simulated(), &other).unwrap() > 1e-3);
        }
    }
}
