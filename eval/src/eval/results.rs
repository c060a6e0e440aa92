//! The scores of a grid gathered per point and method: means over the
//! seeds, and the equal-time particle runs beside the method they match.

use super::methods::Method;
use super::plan::Point;
use super::scenarios::TraceInfo;
use super::score::Score;
use idmesh_belief::Reliability;

/// A method's scores on one point, over its seeds.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Summary {
    /// Runs scored (failures excluded).
    pub runs: usize,
    /// Mean and standard deviation (over seeds) of the tracking error.
    pub error: f64,
    pub error_sd: f64,
    /// Mean of the runs' own expected error (see `score::bayes_risk`).
    pub expected_error: f64,
    /// Mean of the runs' expected error of their top-k labelling.
    pub expected_topk: f64,
    /// Means of the runs' Brier score and log-loss.
    pub brier: f64,
    pub log_loss: f64,
    /// The runs' reliability counts, added up.
    pub reliability: Reliability,
    /// Every run's error in seed order (NaN for a failed run), to compare
    /// two methods run by run.
    pub run_errors: Vec<f64>,
    /// Mean seconds inside the filter per run.
    pub seconds: f64,
    /// Mean over runs of the mean coefficient count; largest count seen.
    pub mean_coefficients: f64,
    pub max_coefficients: usize,
    /// Events refused, over all runs.
    pub refused: usize,
    /// Runs that could not be scored, with the reason.
    pub failures: Vec<String>,
}

impl Summary {
    pub(crate) fn of(scores: &[&Score]) -> Summary {
        let ok: Vec<&Score> = scores
            .iter()
            .copied()
            .filter(|s| s.failure.is_none() && s.error.is_finite())
            .collect();
        let runs = ok.len();
        let mean = |f: &dyn Fn(&Score) -> f64| -> f64 {
            if runs == 0 {
                f64::NAN
            } else {
                ok.iter().map(|s| f(s)).sum::<f64>() / runs as f64
            }
        };
        let error = mean(&|s| s.error);
        let error_sd = if runs > 1 {
            (ok.iter().map(|s| (s.error - error).powi(2)).sum::<f64>() / (runs - 1) as f64).sqrt()
        } else {
            0.0
        };
        Summary {
            runs,
            error,
            error_sd,
            expected_error: mean(&|s| s.expected_error),
            expected_topk: mean(&|s| s.expected_topk),
            brier: mean(&|s| s.brier),
            log_loss: mean(&|s| s.log_loss),
            reliability: ok.iter().fold(Reliability::default(), |mut r, s| {
                r.merge(&s.reliability);
                r
            }),
            run_errors: scores.iter().map(|s| s.error).collect(),
            seconds: mean(&|s| s.seconds),
            mean_coefficients: mean(&|s| s.mean_coefficients),
            max_coefficients: ok.iter().map(|s| s.max_coefficients).max().unwrap_or(0),
            refused: scores.iter().map(|s| s.refused).sum(),
            failures: scores.iter().filter_map(|s| s.failure.clone()).collect(),
        }
    }

    pub(crate) fn ok(&self) -> bool {
        self.runs > 0
    }
}

/// A particle filter sized to take as long as another method.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct EqualTime {
    /// The method whose time it matches.
    pub base: Method,
    /// The particle count chosen.
    pub particles: usize,
    pub summary: Summary,
}

/// Everything measured at one point.
#[derive(Debug, Clone)]
pub(crate) struct PointResult {
    pub point: Point,
    /// The traces of its seeds that could be made.
    pub traces: Vec<TraceInfo>,
    /// Why the others could not.
    pub trace_errors: Vec<String>,
    /// In the point's method order; methods that do not fit are absent.
    pub methods: Vec<(Method, Summary)>,
    pub equal_time: Vec<EqualTime>,
}

impl PointResult {
    pub(crate) fn summary(&self, method: &Method) -> Option<&Summary> {
        self.methods
            .iter()
            .find(|(m, _)| m == method)
            .map(|(_, s)| s)
    }

    /// Mean over the traces of a trace fact.
    pub(crate) fn mean_info(&self, f: impl Fn(&TraceInfo) -> f64) -> f64 {
        if self.traces.is_empty() {
            return f64::NAN;
        }
        self.traces.iter().map(f).sum::<f64>() / self.traces.len() as f64
    }

    /// Mean mixing share of the traces.
    pub(crate) fn mix_share(&self) -> f64 {
        self.mean_info(|t| t.mix_share)
    }
}

/// The whole evaluation.
#[derive(Debug, Clone)]
pub(crate) struct Results {
    pub points: Vec<PointResult>,
    /// Seconds the whole run took, wall clock.
    pub wall_seconds: f64,
    pub workers: usize,
    pub seeds: usize,
    pub events: usize,
}
