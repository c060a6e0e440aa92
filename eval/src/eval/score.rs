//! Replaying an in-memory trace through one filter and scoring it as the
//! trace spec says: at every truth line the k tracks with the largest
//! marginals are predicted red (ties within 1e-9 sharing the slots they
//! compete for), the error there is the expected fraction of tracks
//! mislabeled, and a run's error is the mean over its truth lines; beside
//! it the Brier score and log-loss of the marginals, and the counts of a
//! reliability diagram.
//!
//! Only the filter's own calls are timed (building it, every event, every
//! marginals call), as `idmesh replay` does, but on the CPU-time clock of
//! the worker thread rather than the wall clock: the grid runs beside other
//! work on shared cores, and a thread preempted inside a millisecond-long
//! run would otherwise be charged the other thread's time slice (10 ms
//! spikes on runs of 0.1 ms). The loop that is timed only calls the filter
//! and keeps its marginals; the prediction and scoring come after. The
//! coefficient count is read after every event for its mean and maximum.
//!
//! Beside the error the filter makes, the error its own belief expects:
//! at a truth line with marginals p, Σ_t min(p_t, 1 − p_t)/n — the Bayes
//! risk of labelling each track by itself under that belief (the fewest
//! mislabeled tracks it expects of any labelling, the top-k one included).
//! A calibrated belief's actual error comes out near it; the exact
//! filter's is the least error any filter can expect on the trace.
//!
//! An event the filter refuses (an observation a particle filter's
//! particles all rule out, say) leaves it unchanged, as the
//! `PropertyFilter` contract says; the run goes on and the refusal is
//! counted, so one bad event does not void a whole cell of a table.

use super::methods::Method;
use super::scenarios::{Step, Trace};
use crate::filters::Recipe;
use idmesh_belief::{
    brier_score, expected_tracking_error, log_loss, predict_red, BeliefError, FactoredBelief,
    Field, PropertyFilter, Reliability,
};
use idmesh_placement::{split_coupling, RegionRule, Regional, Regions};
use idmesh_protocol::wire::factored::{held_whole, DEFAULT_SPREAD_ABOVE};
use std::time::Instant;

/// Seconds of CPU time this thread has used (`CLOCK_THREAD_CPUTIME_ID`), or
/// `None` where that clock cannot be read.
fn thread_cpu_seconds() -> Option<f64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec for the call's duration.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    (rc == 0).then_some(ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9)
}

/// A stopwatch on the thread's CPU clock, falling back to the wall clock.
pub(super) struct Stopwatch {
    cpu: Option<f64>,
    wall: Instant,
}

impl Stopwatch {
    pub(super) fn start() -> Stopwatch {
        Stopwatch {
            cpu: thread_cpu_seconds(),
            wall: Instant::now(),
        }
    }

    pub(super) fn seconds(&self) -> f64 {
        match (self.cpu, thread_cpu_seconds()) {
            (Some(start), Some(now)) => now - start,
            _ => self.wall.elapsed().as_secs_f64(),
        }
    }
}

/// How one method did on one trace.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Score {
    /// Mean tracking error over the truth lines (NaN if the run failed or
    /// had no truth line).
    pub error: f64,
    /// Mean over the truth lines of the belief's own expected error
    /// Σ_t min(p_t, 1 − p_t)/n (NaN as `error`).
    pub expected_error: f64,
    /// Mean over the truth lines of the error the belief expects of the
    /// labelling actually scored (its top k red): never below
    /// `expected_error`, and equal to `error` in expectation when the belief
    /// is the true posterior.
    pub expected_topk: f64,
    /// Mean Brier score and log-loss over the truth lines (NaN as `error`).
    pub brier: f64,
    pub log_loss: f64,
    /// How often a track given probability p was red, over the truth lines.
    pub reliability: Reliability,
    /// Seconds inside the filter.
    pub seconds: f64,
    /// Mean and largest coefficient count after an event.
    pub mean_coefficients: f64,
    pub max_coefficients: usize,
    /// Events the filter refused (and skipped).
    pub refused: usize,
    /// Why the run could not be scored at all (the filter could not be
    /// built, or could not answer).
    pub failure: Option<String>,
}

impl Score {
    fn failed(reason: String) -> Score {
        Score {
            error: f64::NAN,
            expected_error: f64::NAN,
            expected_topk: f64::NAN,
            brier: f64::NAN,
            log_loss: f64::NAN,
            reliability: Reliability::default(),
            seconds: 0.0,
            mean_coefficients: 0.0,
            max_coefficients: 0,
            refused: 0,
            failure: Some(reason),
        }
    }
}

/// One replay of a trace through a method: the marginals at every truth
/// line (with the truth there), and what the timed loop counted.
pub(super) struct Replayed<'a> {
    pub answers: Vec<(Vec<f64>, &'a [u32])>,
    /// Seconds inside the filter.
    pub seconds: f64,
    coefficient_sum: f64,
    events: usize,
    max_coefficients: usize,
    last_coefficients: usize,
    refused: usize,
}

/// Replays `trace` through `method` (seeded with `seed`): only the
/// filter's own calls are inside the clock. An event the filter refuses is
/// skipped and counted; a filter that cannot be built or cannot answer
/// ends the run (the reason).
pub(super) fn replay(method: Method, trace: &Trace, seed: u64) -> Result<Replayed<'_>, String> {
    let clock = Stopwatch::start();
    let built = method
        .build(trace.field.clone(), seed)
        .map_err(|e| format!("{method}: {e}"))?;
    let mut filter =
        Running::new(built, method, &trace.field).map_err(|e| format!("{method}: {e}"))?;
    let (mut coefficient_sum, mut events, mut max_coefficients) = (0.0, 0usize, 0usize);
    let mut refused = 0;
    // (marginals, truth) at every truth line, scored after the clock stops.
    let mut answers: Vec<(Vec<f64>, &[u32])> = Vec::new();
    for step in &trace.steps {
        match step {
            Step::Move { .. } => {
                if let Running::Deployed(regional) = &mut filter {
                    if regional.apply_line(&step.line()).is_err() {
                        refused += 1;
                    }
                }
            }
            Step::Event(event) => {
                let applied = match &mut filter {
                    Running::Plain(filter) => filter.apply(event),
                    Running::Deployed(regional) => regional.apply_line(&step.line()),
                };
                if applied.is_err() {
                    refused += 1;
                }
                let c = filter.coefficients();
                coefficient_sum += c as f64;
                max_coefficients = max_coefficients.max(c);
                events += 1;
            }
            Step::Truth(red) => match filter.marginals() {
                Ok(m) => answers.push((m, red)),
                Err(e) => return Err(format!("{method}: marginals: {e}")),
            },
        }
    }
    Ok(Replayed {
        answers,
        seconds: clock.seconds(),
        coefficient_sum,
        events,
        max_coefficients,
        last_coefficients: filter.coefficients(),
        refused,
    })
}

/// A method's filter as the replay drives it: a plain one takes the
/// events; a deployed one ([`Method::Deployed`]) takes every line, its
/// regions following the `move` lines as the sensor's router does.
pub(super) enum Running {
    Plain(Box<dyn PropertyFilter>),
    Deployed(Box<Regional>),
}

impl Running {
    /// Wraps `built` (the method's belief) in the regions of `method`'s
    /// leaders, if it names any.
    pub(super) fn new(
        built: Box<dyn PropertyFilter>,
        method: Method,
        field: &Field,
    ) -> Result<Running, BeliefError> {
        let Some(leaders) = method.leaders() else {
            return Ok(Running::Plain(built));
        };
        // A crowd the deployment holds whole: one holder's belief.
        if held_whole(field.tracks as u32, leaders, DEFAULT_SPREAD_ABOVE) {
            let whole = Recipe::factored(split_coupling(true)).build(field.clone())?;
            return Ok(Running::Plain(whole));
        }
        let Recipe::Factored(options) = method.recipe(0) else {
            return Err(BeliefError::Unsupported {
                method: "deployed",
                what: "a belief other than the factored one",
            });
        };
        let belief = FactoredBelief::with_options(field.clone(), options)?;
        let regions = Regions::new(&RegionRule::fitted(), leaders, field.tracks);
        Ok(Running::Deployed(Box::new(Regional::new(belief, regions))))
    }

    fn filter(&self) -> &dyn PropertyFilter {
        match self {
            Running::Plain(filter) => filter.as_ref(),
            Running::Deployed(regional) => regional.as_ref(),
        }
    }

    pub(super) fn marginals(&self) -> Result<Vec<f64>, BeliefError> {
        self.filter().marginals()
    }

    pub(super) fn coefficients(&self) -> usize {
        self.filter().coefficients()
    }
}

/// The trace spec's tracking error of answers at truth lines: the mean
/// over them of the expected fraction of tracks mislabeled when the k
/// largest marginals are called red, ties sharing the slots (NaN without
/// a truth line).
pub fn tracking_error(answers: &[(Vec<f64>, &[u32])], k: Option<usize>) -> f64 {
    if answers.is_empty() {
        return f64::NAN;
    }
    let total: f64 = answers
        .iter()
        .map(|(m, red)| expected_tracking_error(m, k, red))
        .sum();
    total / answers.len() as f64
}

/// Replays `trace` through `method` (seeded with `seed`) and scores it.
pub(crate) fn score(method: Method, trace: &Trace, seed: u64) -> Score {
    let run = match replay(method, trace, seed) {
        Ok(run) => run,
        Err(reason) => return Score::failed(reason),
    };
    let answers = &run.answers;
    let n = trace.field.tracks;
    let k = trace.field.red.known();
    let (mut expected, mut expected_topk) = (0.0, 0.0);
    let (mut brier, mut loss, mut reliability) = (0.0, 0.0, Reliability::default());
    for (m, red) in answers {
        debug_assert_eq!(m.len(), n);
        expected += bayes_risk(m);
        expected_topk += expected_mislabels(m, &predict_red(m, k));
        brier += brier_score(m, red);
        loss += log_loss(m, red);
        reliability.add(m, red);
    }
    let mean = |total: f64| {
        if answers.is_empty() {
            f64::NAN
        } else {
            total / answers.len() as f64
        }
    };
    Score {
        error: tracking_error(answers, k),
        expected_error: mean(expected),
        expected_topk: mean(expected_topk),
        brier: mean(brier),
        log_loss: mean(loss),
        reliability,
        seconds: run.seconds,
        mean_coefficients: if run.events > 0 {
            run.coefficient_sum / run.events as f64
        } else {
            run.last_coefficients as f64
        },
        max_coefficients: run.max_coefficients,
        refused: run.refused,
        failure: None,
    }
}

/// The error a belief with these marginals expects of the best per-track
/// labelling: Σ_t min(p_t, 1 − p_t)/n.
pub(crate) fn bayes_risk(marginals: &[f64]) -> f64 {
    if marginals.is_empty() {
        return f64::NAN;
    }
    let sum: f64 = marginals
        .iter()
        .map(|&p| p.clamp(0.0, 1.0).min(1.0 - p.clamp(0.0, 1.0)))
        .sum();
    sum / marginals.len() as f64
}

/// The error a belief with these marginals expects of labelling exactly
/// `predicted` red: (Σ_{t ∈ predicted} (1 − p_t) + Σ_{t ∉ predicted} p_t)/n.
pub(crate) fn expected_mislabels(marginals: &[f64], predicted: &[u32]) -> f64 {
    if marginals.is_empty() {
        return f64::NAN;
    }
    let mut red = vec![false; marginals.len()];
    for &t in predicted {
        if let Some(r) = red.get_mut(t as usize) {
            *r = true;
        }
    }
    let sum: f64 = marginals
        .iter()
        .zip(&red)
        .map(|(&p, &r)| {
            let p = p.clamp(0.0, 1.0);
            if r {
                1.0 - p
            } else {
                p
            }
        })
        .sum();
    sum / marginals.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eval::scenarios::TraceInfo;
    use idmesh_belief::{Event, Field, Mix, Observe};

    fn table_one() -> Trace {
        Trace {
            field: Field::known(4, vec![0, 1]),
            initial_red: vec![0, 1],
            steps: vec![
                Step::Event(Event::Mix(Mix {
                    a: 0,
                    b: 2,
                    swap: 0.5,
                })),
                Step::Truth(vec![1, 2]),
                Step::Event(Event::Mix(Mix {
                    a: 2,
                    b: 3,
                    swap: 0.5,
                })),
                Step::Event(Event::Observe(Observe {
                    track: 2,
                    red: 1.0,
                    blue: 0.0,
                })),
                Step::Truth(vec![1, 2]),
            ],
            info: TraceInfo {
                tracks: 4,
                red: 2,
                mixes: 2,
                observations: 1,
                truths: 2,
                mix_share: 2.0 / 3.0,
                seconds_of_motion: 3.0,
                mix_distance: 1.0,
                observe_distance: 3.5,
            },
        }
    }

    #[test]
    fn scores_the_worked_example() {
        let trace = table_one();
        let exact = score(Method::Exact, &trace, 0);
        // After the first mix tracks 0 and 2 tie at 1/2 for the one slot
        // track 1 leaves: half a red label each, so against the truth
        // {1, 2} half a track is expected wrong on each (error 1/4); after
        // the observation the answer is certain (error 0).
        assert_eq!(exact.error, 0.125);
        // Brier: (¼ + 0 + ¼ + 0)/4 at the first line, 0 at the second.
        assert!((exact.brier - 0.0625).abs() < 1e-12);
        assert!((exact.log_loss - 2f64.ln() / 4.0).abs() < 1e-12);
        assert_eq!(exact.reliability.count.iter().sum::<u64>(), 8);
        // It expects as much: 2 of 4 tracks at 1/2, then certainty.
        assert!((exact.expected_error - 0.125).abs() < 1e-12);
        assert!((exact.expected_topk - 0.125).abs() < 1e-12);
        assert_eq!(exact.refused, 0);
        assert_eq!(exact.max_coefficients, 6);
        assert!(exact.seconds > 0.0 && exact.failure.is_none());
        let particles = score(Method::Particles(64), &trace, 0);
        assert_eq!(particles.mean_coefficients, 64.0);
    }

    #[test]
    fn bayes_risk_counts_the_expected_mistakes() {
        assert_eq!(bayes_risk(&[0.0, 1.0, 1.0, 0.0]), 0.0);
        assert!((bayes_risk(&[0.5, 0.5, 0.9, 0.2]) - 1.3 / 4.0).abs() < 1e-12);
        assert!(bayes_risk(&[]).is_nan());
        // Labelling 3 red although 0.5 < 0.9: 0.5 + 0.5 + 0.1 + 0.2 over 4.
        let p = [0.5, 0.5, 0.9, 0.2];
        assert!((expected_mislabels(&p, &[0, 2]) - 1.3 / 4.0).abs() < 1e-12);
        assert!((expected_mislabels(&p, &[3, 2]) - 1.9 / 4.0).abs() < 1e-12);
    }

    #[test]
    fn refusals_are_counted_and_failures_reported() {
        let mut trace = table_one();
        // A mix of a track with itself is refused (a sighting the stream
        // rules out no longer is: the repair rule takes it).
        trace.steps.insert(
            0,
            Step::Event(Event::Mix(Mix {
                a: 3,
                b: 3,
                swap: 0.5,
            })),
        );
        let s = score(Method::Exact, &trace, 0);
        assert_eq!(s.refused, 1);
        assert_eq!(s.error, 0.125);
        trace.field = Field::uniform(4, 5);
        let s = score(Method::Exact, &trace, 0);
        assert!(s.failure.is_some() && s.error.is_nan());
    }
}
