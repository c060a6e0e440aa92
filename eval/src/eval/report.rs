//! The prose of results.md that carries numbers: the summary at the top,
//! the accuracy goals and whether each method meets them ("Beating the
//! paper"), the belief's own expected error beside its actual error, and
//! the cost of the distributed rule under each start. Every number is read
//! from the run, and every verdict is computed, never written in advance.

use super::methods::Method;
use super::plan::{budget, paper_table3, Experiment, STARTS};
use super::results::{PointResult, Results, Summary};
use super::scenarios::Start;
use super::table::{coefficients, distributed_pair, runs_changed, seconds};
use idmesh_protocol::wire::factored::DEFAULT_SPREAD_ABOVE;
use std::fmt::Write;

/// Goal 1: within this of the exact filter's error at [`GOAL_N`] tracks…
pub(crate) const GOAL_GAP: f64 = 0.02;
/// …with at most this many coefficients.
pub(crate) const GOAL_COEFFICIENTS: usize = 500;
/// The n of goal 1 (the largest n the exact filter runs at).
pub(crate) const GOAL_N: usize = 20;
/// Goal 2: at least this much better than order 1 on Table III.
pub(crate) const GOAL_MARGIN: f64 = 0.08;

/// A Table III method with its budget scaled to n.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Kind {
    Exact,
    Order(usize),
    Threshold,
    Overcomplete,
    Distributed,
    ParticlesB,
    Particles1000,
    Factored,
}

impl Kind {
    pub(crate) fn at(&self, n: usize) -> Method {
        let b = budget(n);
        match *self {
            Kind::Exact => Method::Exact,
            Kind::Order(j) => Method::Order(j),
            Kind::Threshold => Method::Threshold(b),
            Kind::Overcomplete => Method::Overcomplete(b),
            Kind::Distributed => Method::Distributed(b),
            Kind::ParticlesB => Method::Particles(b),
            Kind::Particles1000 => Method::Particles(super::plan::PARTICLES),
            Kind::Factored => Method::Factored,
        }
    }

    pub(crate) fn name(&self) -> &'static str {
        match *self {
            Kind::Exact => "exact",
            Kind::Order(1) => "order 1",
            Kind::Order(_) => "order 3",
            Kind::Threshold => "threshold (B = 5n)",
            Kind::Overcomplete => "overcomplete (B = 5n)",
            Kind::Distributed => "overcomplete, distributed rule (B = 5n)",
            Kind::ParticlesB => "particles (P = 5n)",
            Kind::Particles1000 => "particles (P = 1000)",
            Kind::Factored => "factored",
        }
    }

    /// Every method of a Table III point but the exact filter.
    const APPROXIMATE: [Kind; 8] = [
        Kind::Order(1),
        Kind::Order(3),
        Kind::Threshold,
        Kind::Overcomplete,
        Kind::Distributed,
        Kind::ParticlesB,
        Kind::Particles1000,
        Kind::Factored,
    ];
}

/// The Table III grid of a run: its swaps and n, in plan order.
pub(crate) struct Grid<'a> {
    results: &'a Results,
    pub swaps: Vec<f64>,
    pub ns: Vec<usize>,
}

impl<'a> Grid<'a> {
    pub(crate) fn of(results: &'a Results) -> Grid<'a> {
        let (mut swaps, mut ns) = (Vec::new(), Vec::new());
        for p in results
            .points
            .iter()
            .filter(|p| p.point.experiment == Experiment::Table3)
        {
            if !swaps.contains(&p.point.swap) {
                swaps.push(p.point.swap);
            }
            if !ns.contains(&p.point.n) {
                ns.push(p.point.n);
            }
        }
        Grid { results, swaps, ns }
    }

    pub(crate) fn point(&self, start: Start, swap: f64, n: usize) -> Option<&'a PointResult> {
        self.results.points.iter().find(|p| {
            p.point.experiment == Experiment::Table3
                && p.point.start == start
                && p.point.swap == swap
                && p.point.n == n
        })
    }

    /// A method's summary at a point, if it was scored.
    pub fn get(&self, start: Start, swap: f64, n: usize, kind: Kind) -> Option<&'a Summary> {
        self.point(start, swap, n)?
            .summary(&kind.at(n))
            .filter(|s| s.ok())
    }

    pub(crate) fn error(&self, start: Start, swap: f64, n: usize, kind: Kind) -> Option<f64> {
        self.get(start, swap, n, kind).map(|s| s.error)
    }

    /// The lowest-error method short of the exact filter at a point.
    pub(crate) fn best(&self, start: Start, swap: f64, n: usize) -> Option<(Kind, f64)> {
        Kind::APPROXIMATE
            .iter()
            .filter_map(|&k| self.error(start, swap, n, k).map(|e| (k, e)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The largest n of the grid.
    pub(crate) fn largest(&self) -> Option<usize> {
        self.ns.iter().copied().max()
    }
}

/// How one method does against the two goals at one (start, swap).
pub(crate) struct Verdict {
    /// Error above the exact filter's at [`GOAL_N`], and the most
    /// coefficients held there.
    pub gap: Option<(f64, usize)>,
    pub goal1: Option<bool>,
    /// Order 1's error minus the method's, at each n of the grid.
    pub margins: Vec<(usize, Option<f64>)>,
    pub goal2: Option<bool>,
}

pub(crate) fn verdict(grid: &Grid, start: Start, swap: f64, kind: Kind) -> Verdict {
    let gap = match (
        grid.get(start, swap, GOAL_N, kind),
        grid.error(start, swap, GOAL_N, Kind::Exact),
    ) {
        (Some(s), Some(exact)) => Some((s.error - exact, s.max_coefficients)),
        _ => None,
    };
    let goal1 = gap.map(|(g, c)| g <= GOAL_GAP && c <= GOAL_COEFFICIENTS);
    let margins: Vec<(usize, Option<f64>)> = grid
        .ns
        .iter()
        .map(|&n| {
            let m = match (
                grid.error(start, swap, n, Kind::Order(1)),
                grid.error(start, swap, n, kind),
            ) {
                (Some(o), Some(e)) => Some(o - e),
                _ => None,
            };
            (n, m)
        })
        .collect();
    let goal2 = if margins.iter().any(|(_, m)| m.is_some()) {
        Some(
            margins
                .iter()
                .filter_map(|(_, m)| *m)
                .all(|m| m >= GOAL_MARGIN),
        )
    } else {
        None
    };
    Verdict {
        gap,
        goal1,
        margins,
        goal2,
    }
}

fn f3(x: Option<f64>) -> String {
    x.map_or("—".into(), |x| format!("{x:.3}"))
}

fn signed(x: Option<f64>) -> String {
    x.map_or("—".into(), |x| format!("{x:+.3}"))
}

fn yes_no(b: Option<bool>) -> &'static str {
    match b {
        Some(true) => "**yes**",
        Some(false) => "no",
        None => "—",
    }
}

/// The n at which a margin reaches goal 2, for the verdict column.
fn where_met(v: &Verdict) -> String {
    match v.goal2 {
        Some(true) => "**yes**".into(),
        Some(false) => {
            let met: Vec<String> = v
                .margins
                .iter()
                .filter(|(_, m)| m.is_some_and(|m| m >= GOAL_MARGIN))
                .map(|(n, _)| n.to_string())
                .collect();
            if met.is_empty() {
                "no".into()
            } else {
                format!("no (met at n = {} only)", met.join(", "))
            }
        }
        None => "—".into(),
    }
}

/// The goals table: per start and swap, the exact filter (for reference),
/// the Radon overcomplete method and the factored belief.
pub(crate) fn goals_table(grid: &Grid) -> String {
    let ns: Vec<String> = grid.ns.iter().map(|n| n.to_string()).collect();
    let mut out = String::new();
    writeln!(
        out,
        "| start | swap | method | error at n = {GOAL_N} | above exact | max coeff. at n = {GOAL_N} | goal 1 | better than order 1 at n = {} | goal 2 |\n\
         |---|---:|---|---:|---:|---:|---|---:|---|",
        ns.join(" / ")
    )
    .unwrap();
    for start in STARTS {
        for &swap in &grid.swaps {
            for kind in [Kind::Exact, Kind::Overcomplete, Kind::Factored] {
                let v = verdict(grid, start, swap, kind);
                let s = grid.get(start, swap, GOAL_N, kind);
                let margins: Vec<String> = v.margins.iter().map(|(_, m)| signed(*m)).collect();
                let (above, goal1) = if kind == Kind::Exact {
                    ("—".to_string(), "—")
                } else {
                    (signed(v.gap.map(|g| g.0)), yes_no(v.goal1))
                };
                writeln!(
                    out,
                    "| {} | {swap} | {} | {} | {above} | {} | {goal1} | {} | {} |",
                    start.label(),
                    kind.name(),
                    f3(s.map(|s| s.error)),
                    s.map_or("—".into(), |s| s.max_coefficients.to_string()),
                    margins.join(" / "),
                    if kind == Kind::Exact {
                        "—".into()
                    } else {
                        where_met(&v)
                    },
                )
                .unwrap();
            }
        }
    }
    out
}

/// Each belief's own expected error beside its actual error: the exact
/// filter (n ≤ 20) and the factored belief with both expectations (per
/// track and of the top-k labelling scored), the overcomplete method with
/// the per-track one; then each one's Brier score and log-loss (trace
/// spec, Scoring: what its probabilities are worth).
pub(crate) fn bayes_table(grid: &Grid) -> String {
    let kinds = [
        (Kind::Exact, true),
        (Kind::Factored, true),
        (Kind::Overcomplete, false),
    ];
    let mut out = String::from("| start | swap | n |");
    let mut columns = 0;
    for (k, topk) in kinds {
        write!(out, " {}: error | expects |", k.name()).unwrap();
        columns += 2;
        if topk {
            out.push_str(" expects, top k |");
            columns += 1;
        }
    }
    for (k, _) in kinds {
        write!(out, " {}: Brier | log-loss |", k.name()).unwrap();
        columns += 2;
    }
    out.push_str("\n|---|---:|---:|");
    out.push_str(&"---:|".repeat(columns));
    out.push('\n');
    for start in STARTS {
        for &swap in &grid.swaps {
            for &n in &grid.ns {
                if grid.point(start, swap, n).is_none() {
                    continue;
                }
                write!(out, "| {} | {swap} | {n} |", start.label()).unwrap();
                for (k, topk) in kinds {
                    let s = grid.get(start, swap, n, k);
                    write!(
                        out,
                        " {} | {} |",
                        f3(s.map(|s| s.error)),
                        f3(s.map(|s| s.expected_error))
                    )
                    .unwrap();
                    if topk {
                        write!(out, " {} |", f3(s.map(|s| s.expected_topk))).unwrap();
                    }
                }
                for (k, _) in kinds {
                    let s = grid.get(start, swap, n, k);
                    let (brier, loss) = (s.map(|s| s.brier), s.map(|s| s.log_loss));
                    write!(out, " {} | {} |", f3(brier), f3(loss)).unwrap();
                }
                out.push('\n');
            }
        }
    }
    out
}

/// The prose of "Beating the paper", around the two tables.
pub(crate) fn beating(grid: &Grid) -> String {
    let mut out = String::new();
    writeln!(
        out,
        "## Beating the paper: the factored belief\n\n\
         The accuracy goals: **the overcomplete method within {GOAL_GAP} of the exact filter's \
         error at n = {GOAL_N} with ≤ {GOAL_COEFFICIENTS} coefficients, and at least \
         {GOAL_MARGIN} better than order 1 on the Table III workload** (read here as: at \
         every n of Table III). Whether each method meets them, at each swap and start \
         (\"better than order 1\" is order 1's error minus the method's; the exact filter's \
         row shows how much better than order 1 any filter can be at n = {GOAL_N}):\n"
    )
    .unwrap();
    out.push_str(&goals_table(grid));
    out.push('\n');

    // Verdicts in words.
    let mut lines: Vec<String> = Vec::new();
    for start in STARTS {
        for &swap in &grid.swaps {
            let f = verdict(grid, start, swap, Kind::Factored);
            let o = verdict(grid, start, swap, Kind::Overcomplete);
            if f.goal1.is_none() && f.goal2.is_none() {
                continue;
            }
            let margins = |v: &Verdict| {
                v.margins
                    .iter()
                    .map(|(_, m)| signed(*m))
                    .collect::<Vec<_>>()
                    .join(" / ")
            };
            let both = |v: &Verdict| match (v.goal1, v.goal2) {
                (Some(true), Some(true)) => "meets both goals",
                (Some(true), _) => "meets goal 1 but not goal 2",
                (_, Some(true)) => "meets goal 2 but not goal 1",
                _ => "meets neither goal",
            };
            lines.push(format!(
                "- {}, swap {swap}: the factored belief {} ({} from the exact filter at n = \
                 {GOAL_N} with at most {} numbers; {} better than order 1 at n = {}); the \
                 overcomplete method {} ({} from the exact filter; {}).",
                capitalize(start.label()),
                both(&f),
                signed(f.gap.map(|g| g.0)),
                f.gap.map_or("—".into(), |g| g.1.to_string()),
                margins(&f),
                grid.ns
                    .iter()
                    .map(|n| n.to_string())
                    .collect::<Vec<_>>()
                    .join("/"),
                both(&o),
                signed(o.gap.map(|g| g.0)),
                margins(&o),
            ));
        }
    }
    out.push_str(&lines.join("\n"));
    out.push_str("\n\n");

    // The overcomplete method alone at swap 0.5, plainly.
    if let Some(&swap) = grid.swaps.iter().find(|&&s| s == 0.5) {
        let fails: Vec<&str> = STARTS
            .iter()
            .filter(|&&start| {
                let v = verdict(grid, start, swap, Kind::Overcomplete);
                v.goal1 == Some(false) || v.goal2 == Some(false)
            })
            .map(|s| s.label())
            .collect();
        if fails.is_empty() {
            writeln!(
                out,
                "The Radon overcomplete method alone meets both goals at swap 0.5 in this run.\n"
            )
            .unwrap();
        } else {
            let o = verdict(grid, Start::Known, swap, Kind::Overcomplete);
            writeln!(
                out,
                "**The Radon overcomplete method alone does not meet the goals at swap 0.5** \
                 ({}). With the known start and its budget of 5n coefficients it errs {} \
                 against the exact filter at n = {GOAL_N} (goal: at most +{GOAL_GAP}), and its \
                 margins over order 1 are {} at n = {} (goal: at least +{GOAL_MARGIN} at each). \
                 Where anything meets the goals, it is the factored belief.\n",
                fails.join(", "),
                signed(o.gap.map(|g| g.0)),
                o.margins
                    .iter()
                    .map(|(_, m)| signed(*m))
                    .collect::<Vec<_>>()
                    .join(" / "),
                grid.ns
                    .iter()
                    .map(|n| n.to_string())
                    .collect::<Vec<_>>()
                    .join("/"),
            )
            .unwrap();
        }
    }

    // Which method is best where.
    let mut total = 0;
    let mut factored_best = 0;
    let mut others: Vec<String> = Vec::new();
    for start in STARTS {
        for &swap in &grid.swaps {
            for &n in &grid.ns {
                if let Some((kind, e)) = grid.best(start, swap, n) {
                    total += 1;
                    if kind == Kind::Factored {
                        factored_best += 1;
                    } else {
                        let f = grid.error(start, swap, n, Kind::Factored);
                        others.push(format!(
                            "{} at {}, swap {swap}, n = {n} ({e:.3} against the factored {})",
                            kind.name(),
                            start.label(),
                            f3(f)
                        ));
                    }
                }
            }
        }
    }
    write!(
        out,
        "Our best method short of the exact filter is the factored belief at {factored_best} \
         of the {total} Table III points"
    )
    .unwrap();
    if others.is_empty() {
        writeln!(out, ".\n").unwrap();
    } else {
        writeln!(out, "; elsewhere: {}.\n", others.join("; ")).unwrap();
    }

    writeln!(
        out,
        "**What changed.** The exact belief factorizes over the connected components of the \
         mixing graph, coupled only by the total count of red targets (with a known start \
         each component holds a fixed number of them). The factored belief \
         (`idmesh_belief::factored`) keeps one exact table over all subsets of each \
         component's tracks, P(x) ∝ Π_C g_C(x ∩ C)·π(|x|). A mix inside a component is the \
         exact rollup on its table; a mix across two components merges them (outer product, \
         then rollup); an observation multiplies one table by the likelihood. Only when a \
         merged component would exceed the size cap (max_component = {max} tracks, 2^{max} \
         numbers; the default) is it split back into two parts by moment matching — an \
         assumed-density projection (Boyen–Koller) that keeps both parts' marginals exactly \
         and forgets only the correlation between them; by default along the old cut or, \
         where one loses less, the best cut one exchange of tracks away from it. Until the \
         first such split the \
         belief is exact. The Radon overcomplete method instead holds its budget by dropping \
         sets or re-fitting them by OMP, and its pruned belief comes out overconfident (see \
         its \"expects\" column below).\n",
        max = idmesh_belief::FactoredOptions::default().max_component,
    )
    .unwrap();

    writeln!(
        out,
        "**How close to the best possible.** A belief with marginals p expects to mislabel \
         Σ_t min(p_t, 1 − p_t)/n of the tracks — the Bayes risk of labelling each track by \
         itself under that belief. Computed at every truth line from the marginals and \
         averaged like the error (\"expects\"), beside the error actually made:\n"
    )
    .unwrap();
    out.push_str(&bayes_table(grid));
    out.push('\n');
    out.push_str(&evidence(grid));
    out
}

/// The reading of the Bayes-risk table: the exact filter at n = 20, the
/// factored belief there and at the largest n, swap 0.5, known start.
fn evidence(grid: &Grid) -> String {
    let mut out = String::new();
    let Some(&swap) = grid
        .swaps
        .iter()
        .find(|&&s| s == 0.5)
        .or(grid.swaps.first())
    else {
        return out;
    };
    let start = Start::Known;
    let s = |n: usize, k: Kind| grid.get(start, swap, n, k);
    let three = |x: Option<&Summary>| {
        (
            f3(x.map(|s| s.error)),
            f3(x.map(|s| s.expected_error)),
            f3(x.map(|s| s.expected_topk)),
        )
    };
    let (Some(exact), Some(fact)) = (s(GOAL_N, Kind::Exact), s(GOAL_N, Kind::Factored)) else {
        return out;
    };
    let (ee, ex, et) = three(Some(exact));
    let (fe, fx, ft) = three(Some(fact));
    let exact_margin = s(GOAL_N, Kind::Order(1)).map(|o| o.error - exact.error);
    writeln!(
        out,
        "Reading it at swap {swap}, known start. At n = {GOAL_N} the exact filter — the \
         posterior itself — errs {ee}; it expects {ex} per track and {et} for the labelling \
         actually scored (the top k must name exactly k tracks red, which costs a little \
         over the per-track risk). {} The factored belief errs {fe} and expects {fx} / \
         {ft}: {} from the exact filter in error, {} in what it expects. Even the exact \
         filter is only {} better than order 1 there, so goal 2 at n = {GOAL_N}, swap \
         {swap} is beyond any filter.\n",
        {
            let gap = (exact.error - exact.expected_topk).abs();
            if gap <= 0.02 {
                format!(
                    "Error and expectation agree to {gap:.3}, as a calibrated belief's should \
                     (over {} seeds).",
                    grid.results.seeds
                )
            } else {
                format!(
                    "Error and expectation differ by {gap:.3} over {} seeds: more than a \
                     calibrated belief's should, so read what follows with care.",
                    grid.results.seeds
                )
            }
        },
        signed(Some(fact.error - exact.error)),
        signed(Some(fact.expected_error - exact.expected_error)),
        f3(exact_margin),
    )
    .unwrap();
    let Some(n) = grid.largest().filter(|&n| n != GOAL_N) else {
        return out;
    };
    let (Some(f), Some(o)) = (s(n, Kind::Factored), s(n, Kind::Order(1))) else {
        return out;
    };
    let (fe, fx, ft) = three(Some(f));
    let target = o.error - GOAL_MARGIN;
    write!(
        out,
        "At n = {n} the factored belief errs {fe} and expects {fx} per track, {ft} for its \
         top k. Goal 2 there needs an error of at most {target:.3} (order 1's {:.3} − \
         {GOAL_MARGIN}). ",
        o.error
    )
    .unwrap();
    let calibrated = (f.error - f.expected_topk).abs() <= 0.02;
    if f.expected_error > target && calibrated {
        write!(
            out,
            "That is below even the per-track risk of the factored belief, whose error is what \
             its own marginals predict — as for the exact filter at n = {GOAL_N}. Its \
             remaining error is uncertainty the events leave, which no labelling under this \
             belief avoids: the remaining gap to the goal is near what any filter can do on \
             these traces, not an error of the approximation. "
        )
        .unwrap();
    } else if f.expected_error > target {
        write!(
            out,
            "That is below the per-track risk of the factored belief, but its error and \
             expectation differ by {:.3}, so the belief's calibration, and the argument, are \
             weaker here. ",
            (f.error - f.expected_topk).abs()
        )
        .unwrap();
    } else {
        write!(
            out,
            "The factored belief's own per-track risk is below that, so a sharper filter \
             might reach the goal there: the remaining gap is not shown to be inherent. "
        )
        .unwrap();
    }
    if let Some(over) = s(n, Kind::Overcomplete) {
        write!(
            out,
            "(The overcomplete method, by contrast, expects {:.3} and errs {:.3}: pruned to \
             its budget, its belief is overconfident, and its own expectation says nothing \
             about what is reachable.) ",
            over.expected_error, over.error
        )
        .unwrap();
    }
    writeln!(
        out,
        "This is evidence, not proof: a split forgets the correlation between its two parts, \
         so the exact posterior at n = {n} may be sharper than the factored belief; at n = \
         {GOAL_N}, where both run, it is sharper by {} in expected error.\n",
        f3(Some(fact.expected_error - exact.expected_error))
    )
    .unwrap();
    out
}

fn capitalize(s: &str) -> String {
    let mut c = s.chars();
    match c.next() {
        Some(f) => f.to_uppercase().collect::<String>() + c.as_str(),
        None => String::new(),
    }
}

/// The prose of the distributed rule's section, above its table.
pub(crate) fn distributed_intro(results: &Results) -> String {
    let mut out = String::new();
    // Per start: runs changed, compared, costs (Table III and scenes).
    let mut changed = [0usize; 2];
    let mut compared = [0usize; 2];
    let mut costs: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    let mut crowd_costs: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    let mut coeffs: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    let mut guesses: Vec<f64> = Vec::new();
    for p in results.points.iter().filter(|p| {
        matches!(
            p.point.experiment,
            Experiment::Table3 | Experiment::Pedestrians
        )
    }) {
        let i = STARTS.iter().position(|&s| s == p.point.start).unwrap_or(0);
        let Some((a, b)) = distributed_pair(p) else {
            continue;
        };
        let (c, n) = runs_changed(a, b);
        changed[i] += c;
        compared[i] += n;
        if a.ok() && b.ok() {
            costs[i].push(b.error - a.error);
            coeffs[i].push(b.mean_coefficients);
            if p.point.experiment == Experiment::Table3 {
                crowd_costs[i].push(b.error - a.error);
                if p.point.start == Start::Uniform {
                    guesses.push(b.error);
                }
            }
        }
    }
    let range = |v: &[f64]| {
        let lo = v.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lo, hi)
    };
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    writeln!(
        out,
        "\n## Cost of the distributed conditioning rule (Section 5.4)\n\n\
         The overcomplete method at the same budget, conditioning exactly (Algorithm 2) or \
         with the distributed rule: an observation of track t only grows the sets that meet \
         the tracks t mixed with since t was last observed. Cost = distributed − \
         exact-conditioning error; \"runs changed\" counts the runs (seeds) whose error \
         differs at all.\n"
    )
    .unwrap();
    let (k_lo, k_hi) = range(&costs[0]);
    let headline = if changed[0] == 0 {
        format!("the rule changed none of the {} runs", compared[0])
    } else {
        format!(
            "the rule changed {} of {} runs at all, by {:+.3} to {:+.3} in mean error",
            changed[0], compared[0], k_lo, k_hi
        )
    };
    writeln!(
        out,
        "**Known start: {headline}.** The rule has next to nothing to restrict. The belief \
         starts as one atom, the full k-set of red tracks at time 0. A mix maps full k-sets \
         to full k-sets, and an observation of t only rescales a full k-set (t is in it: red; \
         or it is not: blue) — the rule only decides which atoms grow, and full k-sets never \
         grow. The only atoms that can grow are the (k − 1)-sets OMP sometimes moves mass to \
         (its dictionary reaches one element below the sets it re-expresses){}.\n",
        if changed[0] > 0 {
            ", which is where the changed runs come from"
        } else {
            "; that can change a run, but changed none here"
        }
    )
    .unwrap();
    if !costs[1].is_empty() {
        let (u_lo, u_hi) = range(&costs[1]);
        let kept = mean(&coeffs[1]);
        let guess = range(&guesses);
        write!(
            out,
            "**Uniform prior: the rule costs {:+.3} on average on the Table III crowds \
             ({:+.3} to {:+.3} over every uniform-prior row below).** ",
            mean(&crowd_costs[1]),
            u_lo,
            u_hi,
        )
        .unwrap();
        if kept < 1.0 + 1e-9 {
            writeln!(
                out,
                "The belief now starts as the single atom φ_∅ (every k-set alike), and every \
                 set it will ever hold has to grow out of it through observations. ∅ meets no \
                 track, so under the rule as Section 5.4 states it no observation grows \
                 anything: the distributed belief keeps its one coefficient through every \
                 run, its marginals stay k/n, and its error is that of a guess ({:.3} to \
                 {:.3} on the crowds), whatever the exact-conditioning filter learns. Taken \
                 literally, the rule needs a start whose atoms the observations need not grow \
                 — in practice, a known start.\n",
                guess.0, guess.1
            )
            .unwrap();
        } else {
            writeln!(
                out,
                "The belief starts from the uniform prior. As Section 5.4 prescribes, the \
                 distributed belief holds the 1-sets {{t}} instead of the empty set \
                 (φ_∅ = Σ_t φ_{{t}}/k), so that every track's own atom can be scaled by its \
                 observations; pairs and larger sets then grow only from atoms that meet \
                 the observed track's mixing log, which is what the rule costs here. The \
                 distributed belief holds {} coefficients on average.\n",
                coefficients(kept)
            )
            .unwrap();
        }
    }
    out
}

/// The summary at the top of results.md: what is measured, the headline
/// numbers, the speedups against the paper.
/// The summary's line on what a deployment costs: the mean and the largest
/// change of each "as deployed" row's error from the centralized local
/// rule's, on the Table III crowds and on the scenes.
fn deployed_cost(results: &Results) -> Option<String> {
    let mut parts = Vec::new();
    for (experiment, what) in [
        (Experiment::Table3, "the Table III crowds"),
        (Experiment::Pedestrians, "the pedestrian scenes"),
    ] {
        for leaders in super::plan::DEPLOYED_LEADERS {
            let changes: Vec<f64> = results
                .points
                .iter()
                .filter(|p| p.point.experiment == experiment)
                .filter_map(|p| {
                    let local = p.summary(&Method::FactoredLocal)?;
                    let deployed = p.summary(&Method::Deployed(leaders))?;
                    let change = deployed.error - local.error;
                    change.is_finite().then_some(change)
                })
                .collect();
            if changes.is_empty() {
                continue;
            }
            let largest = changes.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            parts.push(format!(
                "{leaders} leaders on {what} {:+.3} on average, at most {largest:+.3}",
                changes.iter().sum::<f64>() / changes.len() as f64
            ));
        }
    }
    (!parts.is_empty()).then(|| {
        format!(
            "- **What a deployment computes** (the \"as deployed\" rows: the default settings, \
             a crowd of at most {DEFAULT_SPREAD_ABOVE} tracks held whole by the first leader, a larger one spread \
             over regions fitted to the crowd) against the centralized local rule, tracking \
             error: {}.",
            parts.join("; ")
        )
    })
}

pub(crate) fn summary(results: &Results) -> String {
    let grid = Grid::of(results);
    let mut lines: Vec<String> = Vec::new();
    let ns = grid
        .ns
        .iter()
        .map(|n| n.to_string())
        .collect::<Vec<_>>()
        .join("/");
    lines.push(format!(
        "- **What is measured**: the tracking error (fraction of the n tracks mislabeled red \
         or blue) and CPU time of each filter replaying the same simulated crowds (k = n/2 \
         red, {} mix + observe events) and real pedestrian scenes, over {} seed(s), with the \
         red tracks at time 0 known or a uniform prior; the paper's Table III numbers beside \
         ours.",
        results.events, results.seeds
    ));
    let row = |start: Start, swap: f64, kind: Kind| -> String {
        grid.ns
            .iter()
            .map(|&n| f3(grid.error(start, swap, n, kind)))
            .collect::<Vec<_>>()
            .join(" / ")
    };
    let paper_over: String = grid
        .ns
        .iter()
        .map(|&n| f3(paper_table3(&Kind::Overcomplete.at(n), n).map(|p| p.0)))
        .collect::<Vec<_>>()
        .join(" / ");
    for &swap in &grid.swaps {
        lines.push(format!(
            "- **Table III, swap {swap}, known start** (n = {ns}): factored {}, our Radon \
             overcomplete {}, order 1 {}; exact filter at n = {GOAL_N}: {} (the paper's \
             overcomplete: {paper_over}).",
            row(Start::Known, swap, Kind::Factored),
            row(Start::Known, swap, Kind::Overcomplete),
            row(Start::Known, swap, Kind::Order(1)),
            f3(grid.error(Start::Known, swap, GOAL_N, Kind::Exact)),
        ));
    }
    if grid
        .point(Start::Uniform, grid.swaps[0], grid.ns[0])
        .is_some()
    {
        let parts: Vec<String> = grid
            .swaps
            .iter()
            .map(|&swap| {
                format!(
                    "swap {swap}: factored {}, overcomplete {}, order 1 {}",
                    row(Start::Uniform, swap, Kind::Factored),
                    row(Start::Uniform, swap, Kind::Overcomplete),
                    row(Start::Uniform, swap, Kind::Order(1)),
                )
            })
            .collect();
        lines.push(format!(
            "- **Uniform prior** (n = {ns}): {}.",
            parts.join("; ")
        ));
    }
    // Speed against the paper.
    let mut over: Vec<f64> = Vec::new();
    let mut fact: Vec<(usize, f64, f64)> = Vec::new();
    for &swap in &grid.swaps {
        for &n in &grid.ns {
            if let (Some(s), Some((_, t))) = (
                grid.get(Start::Known, swap, n, Kind::Overcomplete),
                paper_table3(&Kind::Overcomplete.at(n), n),
            ) {
                if s.seconds > 0.0 {
                    over.push(t / s.seconds);
                }
                if let Some(f) = grid.get(Start::Known, swap, n, Kind::Factored) {
                    fact.push((n, f.seconds, t));
                }
            }
        }
    }
    if !over.is_empty() {
        let lo = over.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = over.iter().copied().fold(0.0, f64::max);
        let mut text = format!(
            "- **Speed**: our overcomplete method runs ×{lo:.0} to ×{hi:.0} faster than the \
             paper's times for it (known start; another machine and decade: orders of \
             magnitude only)"
        );
        if let Some(&(n, f, t)) = fact
            .iter()
            .filter(|x| x.0 == grid.largest().unwrap_or(0))
            .max_by(|a, b| a.1.total_cmp(&b.1))
        {
            write!(
                text,
                "; the factored belief takes at most {} s a run at n = {n}, against the paper's \
                 {} s for its overcomplete method (×{:.0})",
                seconds(f),
                seconds(t),
                t / f
            )
            .unwrap();
        }
        text.push('.');
        lines.push(text);
    }
    // Goals.
    let verdicts: Vec<Verdict> = STARTS
        .iter()
        .flat_map(|&start| {
            grid.swaps
                .iter()
                .map(move |&swap| (start, swap))
                .collect::<Vec<_>>()
        })
        .map(|(start, swap)| verdict(&grid, start, swap, Kind::Factored))
        .filter(|v| v.goal1.is_some() || v.goal2.is_some())
        .collect();
    if !verdicts.is_empty() {
        let total = verdicts.len();
        let met1 = verdicts.iter().filter(|v| v.goal1 == Some(true)).count();
        let met2 = verdicts.iter().filter(|v| v.goal2 == Some(true)).count();
        let worst_gap = verdicts
            .iter()
            .filter_map(|v| v.gap.map(|g| g.0))
            .fold(f64::NEG_INFINITY, f64::max);
        let most = verdicts
            .iter()
            .filter_map(|v| v.gap.map(|g| g.1))
            .max()
            .unwrap_or(0);
        let known: Vec<String> = grid
            .swaps
            .iter()
            .map(|&swap| {
                let v = verdict(&grid, Start::Known, swap, Kind::Factored);
                let m: Vec<String> = v.margins.iter().map(|(_, m)| f3(*m)).collect();
                format!("{} at swap {swap}", m.join("/"))
            })
            .collect();
        let exact: Vec<String> = grid
            .swaps
            .iter()
            .map(|&swap| {
                f3(grid
                    .error(Start::Known, swap, GOAL_N, Kind::Order(1))
                    .zip(grid.error(Start::Known, swap, GOAL_N, Kind::Exact))
                    .map(|(o, e)| o - e))
            })
            .collect();
        let over_fails = grid.swaps.contains(&0.5)
            && STARTS.iter().all(|&start| {
                let v = verdict(&grid, start, 0.5, Kind::Overcomplete);
                v.goal1 != Some(true) && v.goal2 != Some(true)
            });
        lines.push(format!(
            "- **The accuracy goals** (within {GOAL_GAP} of exact at n = {GOAL_N} with ≤ \
             {GOAL_COEFFICIENTS} coefficients; ≥ {GOAL_MARGIN} better than order 1 at every \
             n): the factored belief meets goal 1 in {met1} of the {total} swap × start \
             cases (at most {worst_gap:+.3} from exact, ≤ {most} numbers) and goal 2 in \
             {met2}: with the known start it is {} better than order 1 at n = {ns}, while at \
             n = {GOAL_N} even the exact filter is only {} better (swap {}).{} See \
             \"Beating the paper\".",
            known.join(" and "),
            exact.join(" / "),
            grid.swaps
                .iter()
                .map(|s| s.to_string())
                .collect::<Vec<_>>()
                .join(" / "),
            if over_fails {
                " The Radon overcomplete method alone meets neither goal at swap 0.5."
            } else {
                ""
            }
        ));
    }
    // The distributed rule.
    let mut known = (0, 0);
    let mut stuck = true;
    let mut uniform: Vec<f64> = Vec::new();
    for p in results.points.iter().filter(|p| {
        matches!(
            p.point.experiment,
            Experiment::Table3 | Experiment::Pedestrians
        )
    }) {
        if let Some((a, b)) = distributed_pair(p) {
            match p.point.start {
                Start::Known => {
                    let (c, n) = runs_changed(a, b);
                    known.0 += c;
                    known.1 += n;
                }
                Start::Uniform if a.ok() && b.ok() && p.point.experiment == Experiment::Table3 => {
                    uniform.push(b.error - a.error);
                    stuck &= b.max_coefficients <= 1;
                }
                Start::Uniform => {}
            }
        }
    }
    if known.1 > 0 {
        let mut text = format!(
            "- **Distributed rule** (Section 5.4): free with a known start (it changed {} of \
             {} runs at all, crowds and scenes)",
            known.0, known.1
        );
        if !uniform.is_empty() {
            write!(
                text,
                "; under the uniform prior it costs {:+.3} on average on the Table III crowds{}",
                uniform.iter().sum::<f64>() / uniform.len() as f64,
                if stuck {
                    ", because it never grows the empty set the belief starts from"
                } else {
                    ""
                }
            )
            .unwrap();
        }
        text.push('.');
        lines.push(text);
    }
    lines.extend(deployed_cost(results));
    let mut out = String::from("## Summary\n\n");
    out.push_str(&lines.join("\n"));
    out.push_str("\n\n");
    out
}
