//! The markdown tables of results.md: Table III in the paper's shape with
//! its numbers side by side, the small-scale and sensitivity sweeps, the
//! pedestrian scenes, the distributed rule's cost and the particle filter
//! at equal time and equal memory.

use super::methods::Method;
use super::plan::{paper_table3, Experiment, PARTICLES};
use super::results::{PointResult, Results, Summary};
use super::scenarios::Start;
use std::fmt::Write;

/// A tracking error with its spread over seeds: `0.173 ± 0.012`; `—` when
/// nothing was scored.
pub(crate) fn error(s: &Summary) -> String {
    if !s.ok() {
        return "—".into();
    }
    let mut text = if s.runs > 1 {
        format!("{:.3} ± {:.3}", s.error, s.error_sd)
    } else {
        format!("{:.3}", s.error)
    };
    if s.refused > 0 {
        write!(text, " ({} refused)", s.refused).unwrap();
    }
    if !s.failures.is_empty() {
        write!(text, " ({} failed)", s.failures.len()).unwrap();
    }
    text
}

/// Seconds to three significant digits (at least whole seconds).
pub(crate) fn seconds(s: f64) -> String {
    if !s.is_finite() {
        return "—".into();
    }
    if s <= 0.0 {
        return "0".into();
    }
    let digits = (2 - s.log10().floor() as i32).max(0) as usize;
    format!("{s:.digits$}")
}

pub fn coefficients(x: f64) -> String {
    if !x.is_finite() {
        "—".into()
    } else if x >= 100.0 {
        format!("{x:.0}")
    } else {
        format!("{x:.1}")
    }
}

fn points(results: &Results, experiment: Experiment) -> Vec<&PointResult> {
    results
        .points
        .iter()
        .filter(|p| p.point.experiment == experiment)
        .collect()
}

/// The method slots of a set of points: position i of their method
/// lists (the points of one experiment list the same kinds of method,
/// with budgets scaled to n).
fn slots(points: &[&PointResult]) -> usize {
    points
        .iter()
        .map(|p| p.point.methods.len())
        .max()
        .unwrap_or(0)
}

/// Table III: method, n, error, seconds, mean and max coefficients, and
/// the paper's error and seconds where it has them.
pub(crate) fn table3(results: &Results, swap: f64, start: Start) -> String {
    let points: Vec<&PointResult> = points(results, Experiment::Table3)
        .into_iter()
        .filter(|p| p.point.swap == swap && p.point.start == start)
        .collect();
    let mut out = String::new();
    out.push_str(
        "| method | n | tracking error | seconds | mean coeff. | max coeff. | paper error | paper seconds | faster than paper |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    let row = |out: &mut String, label: &str, n: usize, s: &Summary, paper: Option<(f64, f64)>| {
        let (pe, ps, speedup) = match paper {
            Some((e, t)) => (
                format!("{e:.3}"),
                seconds(t),
                if s.ok() && s.seconds > 0.0 {
                    format!("×{:.0}", t / s.seconds)
                } else {
                    "—".into()
                },
            ),
            None => ("—".into(), "—".into(), "—".into()),
        };
        writeln!(
            out,
            "| {label} | {n} | {} | {} | {} | {} | {pe} | {ps} | {speedup} |",
            error(s),
            seconds(s.seconds),
            coefficients(s.mean_coefficients),
            s.max_coefficients,
        )
        .unwrap();
    };
    for slot in 0..slots(&points) {
        for p in &points {
            let Some(method) = p.point.methods.get(slot) else {
                continue;
            };
            let Some(s) = p.summary(method) else {
                continue;
            };
            let label = match method {
                Method::Particles(b) if *b != PARTICLES => {
                    format!("particles, equal memory (P = B = {b})")
                }
                m => m.label(),
            };
            row(
                &mut out,
                &label,
                p.point.n,
                s,
                paper_table3(method, p.point.n),
            );
        }
        // The equal-time particle filter right after the overcomplete rows.
        if points
            .iter()
            .any(|p| matches!(p.point.methods.get(slot), Some(Method::Overcomplete(_))))
        {
            for p in &points {
                for e in &p.equal_time {
                    if matches!(e.base, Method::Overcomplete(_)) {
                        let label = format!(
                            "particles, equal time to overcomplete (P = {})",
                            e.particles
                        );
                        row(&mut out, &label, p.point.n, &e.summary, None);
                    }
                }
            }
        }
    }
    out
}

/// A sweep: one row per method, one column per point (the x value and,
/// for mixing, the measured share), then the mean coefficients and
/// seconds over the points.
pub(crate) fn sweep(
    results: &Results,
    experiment: Experiment,
    n: Option<usize>,
    x_name: &str,
) -> String {
    let points: Vec<&PointResult> = points(results, experiment)
        .into_iter()
        .filter(|p| n.is_none_or(|n| p.point.n == n))
        .collect();
    if points.is_empty() {
        return String::new();
    }
    let mut out = String::from("| method |");
    for p in &points {
        match experiment {
            Experiment::SmallScale | Experiment::MixingLarge => {
                write!(out, " {x_name} {:.2} |", p.mix_share()).unwrap()
            }
            _ => write!(out, " {x_name} {} |", p.point.x).unwrap(),
        }
    }
    out.push_str(" mean coeff. | max coeff. | seconds |\n|---|");
    out.push_str(&"---:|".repeat(points.len() + 3));
    out.push('\n');
    for slot in 0..slots(&points) {
        let Some(method) = points.iter().find_map(|p| p.point.methods.get(slot)) else {
            continue;
        };
        let cells: Vec<Option<&Summary>> = points
            .iter()
            .map(|p| p.point.methods.get(slot).and_then(|m| p.summary(m)))
            .collect();
        if cells.iter().all(Option::is_none) {
            continue;
        }
        write!(out, "| {} |", method.label()).unwrap();
        for c in &cells {
            write!(out, " {} |", c.map_or("—".into(), error)).unwrap();
        }
        let ran: Vec<&Summary> = cells.iter().flatten().copied().filter(|s| s.ok()).collect();
        let mean = |f: &dyn Fn(&Summary) -> f64| {
            ran.iter().map(|s| f(s)).sum::<f64>() / ran.len().max(1) as f64
        };
        writeln!(
            out,
            " {} | {} | {} |",
            coefficients(mean(&|s| s.mean_coefficients)),
            ran.iter().map(|s| s.max_coefficients).max().unwrap_or(0),
            seconds(mean(&|s| s.seconds)),
        )
        .unwrap();
    }
    out
}

/// Table III on the pedestrian scenes (known start): per scene window, its
/// facts and every method.
pub(crate) fn pedestrians(results: &Results) -> String {
    let points: Vec<&PointResult> = points(results, Experiment::Pedestrians)
        .into_iter()
        .filter(|p| p.point.start == Start::Known)
        .collect();
    let mut out = String::from(
        "| scene | n (mean) | events (mean) | mixing share | method | tracking error | seconds | mean coeff. | max coeff. |\n\
         |---|---:|---:|---:|---|---:|---:|---:|---:|\n",
    );
    for p in points {
        if p.traces.is_empty() {
            writeln!(
                out,
                "| {} | — | — | — | no window could be made: {} | | | | |",
                p.point.label,
                p.trace_errors.join("; ")
            )
            .unwrap();
            continue;
        }
        let mut first = true;
        for (method, s) in &p.methods {
            let facts = if first {
                format!(
                    "{} | {:.0} | {:.0} | {:.2}",
                    p.point.label,
                    p.mean_info(|t| t.tracks as f64),
                    p.mean_info(|t| (t.mixes + t.observations) as f64),
                    p.mix_share()
                )
            } else {
                " | | |".into()
            };
            first = false;
            writeln!(
                out,
                "| {facts} | {} | {} | {} | {} | {} |",
                method.label(),
                error(s),
                seconds(s.seconds),
                coefficients(s.mean_coefficients),
                s.max_coefficients
            )
            .unwrap();
        }
    }
    out
}

/// The distributed conditioning rule against exact conditioning at the
/// same budget (and the exact filter where it runs), known-start rows
/// first: how many runs the rule changed at all, the cost in error, and
/// the coefficients each keeps.
pub(crate) fn distributed(results: &Results) -> String {
    let mut out = String::from(
        "| scenario | n | start | exact filter | overcomplete, exact conditioning | overcomplete, distributed rule | cost of the rule | runs changed | mean coeff. (exact cond. / distributed) | seconds (exact cond. / distributed) |\n\
         |---|---:|---|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for start in super::plan::STARTS {
        for p in results.points.iter().filter(|p| {
            p.point.start == start
                && matches!(
                    p.point.experiment,
                    Experiment::Table3 | Experiment::Pedestrians
                )
        }) {
            let Some((exact_cond, dist)) = distributed_pair(p) else {
                continue;
            };
            let exact = p.summary(&Method::Exact).map_or("—".into(), error);
            let cost = if exact_cond.ok() && dist.ok() {
                format!("{:+.3}", dist.error - exact_cond.error)
            } else {
                "—".into()
            };
            let (changed, compared) = runs_changed(exact_cond, dist);
            writeln!(
                out,
                "| {} | {} | {} | {exact} | {} | {} | {cost} | {changed} of {compared} | {} / {} | {} / {} |",
                p.point.label,
                p.point.n,
                start.label(),
                error(exact_cond),
                error(dist),
                coefficients(exact_cond.mean_coefficients),
                coefficients(dist.mean_coefficients),
                seconds(exact_cond.seconds),
                seconds(dist.seconds)
            )
            .unwrap();
        }
    }
    out
}

/// The overcomplete method's summaries at a point, conditioning exactly
/// and with the distributed rule.
pub(crate) fn distributed_pair(p: &PointResult) -> Option<(&Summary, &Summary)> {
    let find = |f: &dyn Fn(&Method) -> bool| p.methods.iter().find(|(m, _)| f(m)).map(|(_, s)| s);
    Some((
        find(&|m| matches!(m, Method::Overcomplete(_)))?,
        find(&|m| matches!(m, Method::Distributed(_)))?,
    ))
}

/// (runs whose error differs at all, runs compared): the same seeds, run
/// by run.
pub(crate) fn runs_changed(a: &Summary, b: &Summary) -> (usize, usize) {
    let pairs: Vec<(f64, f64)> = a
        .run_errors
        .iter()
        .zip(&b.run_errors)
        .filter(|(x, y)| x.is_finite() && y.is_finite())
        .map(|(x, y)| (*x, *y))
        .collect();
    (pairs.iter().filter(|(x, y)| x != y).count(), pairs.len())
}

/// Every method against a particle filter given the same time.
pub(crate) fn equal_time(results: &Results) -> String {
    let mut out = String::from(
        "| start | n | swap | method | tracking error | seconds | P at equal time | particle error | particle seconds | method − particles |\n\
         |---|---:|---:|---|---:|---:|---:|---:|---:|---:|\n",
    );
    for p in points(results, Experiment::Table3) {
        for e in &p.equal_time {
            let Some(base) = p.summary(&e.base) else {
                continue;
            };
            let gap = if base.ok() && e.summary.ok() {
                format!("{:+.3}", base.error - e.summary.error)
            } else {
                "—".into()
            };
            writeln!(
                out,
                "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {gap} |",
                p.point.start.label(),
                p.point.n,
                p.point.swap,
                e.base.label(),
                error(base),
                seconds(base.seconds),
                e.particles,
                error(&e.summary),
                seconds(e.summary.seconds)
            )
            .unwrap();
        }
    }
    out
}

/// The Radon methods against a particle filter holding as many sets.
pub(crate) fn equal_memory(results: &Results) -> String {
    let mut out = String::from(
        "| start | n | swap | B = P | exact | threshold | overcomplete | particles (P = B) | particles (P = 1000) |\n\
         |---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for p in points(results, Experiment::Table3) {
        let b = super::plan::budget(p.point.n);
        let cell = |m: Method| p.summary(&m).map_or("—".into(), error);
        writeln!(
            out,
            "| {} | {} | {} | {b} | {} | {} | {} | {} | {} |",
            p.point.start.label(),
            p.point.n,
            p.point.swap,
            cell(Method::Exact),
            cell(Method::Threshold(b)),
            cell(Method::Overcomplete(b)),
            cell(Method::Particles(b)),
            cell(Method::Particles(PARTICLES)),
        )
        .unwrap();
    }
    out
}

/// The headline of Table III: at each swap and n, the paper's three
/// methods ranked by our error and by the paper's, whether the order
/// matches, and how much faster our overcomplete method is.
pub(crate) fn ordering(results: &Results) -> String {
    let mut out = String::from(
        "| start | swap | n | our ranking | paper's ranking | same best | same order | overcomplete: ours vs paper seconds |\n\
         |---|---:|---:|---|---|---|---|---|\n",
    );
    for p in points(results, Experiment::Table3) {
        let n = p.point.n;
        let three = [
            Method::Order(1),
            Method::Order(3),
            Method::Overcomplete(super::plan::budget(n)),
        ];
        let mut ours: Vec<(f64, &str)> = Vec::new();
        let mut paper: Vec<(f64, &str)> = Vec::new();
        let name = |m: &Method| match m {
            Method::Order(1) => "order 1",
            Method::Order(_) => "order 3",
            _ => "overcomplete",
        };
        for m in &three {
            if let (Some(s), Some((e, _))) = (p.summary(m).filter(|s| s.ok()), paper_table3(m, n)) {
                ours.push((s.error, name(m)));
                paper.push((e, name(m)));
            }
        }
        if ours.len() < 3 {
            continue;
        }
        ours.sort_by(|a, b| a.0.total_cmp(&b.0));
        paper.sort_by(|a, b| a.0.total_cmp(&b.0));
        let rank = |v: &[(f64, &str)]| {
            v.iter()
                .map(|(e, m)| format!("{m} {e:.3}"))
                .collect::<Vec<_>>()
                .join(" < ")
        };
        let same_best = ours[0].1 == paper[0].1;
        let same_order = ours.iter().zip(&paper).all(|(a, b)| a.1 == b.1);
        let speed = match (p.summary(&three[2]), paper_table3(&three[2], n)) {
            (Some(s), Some((_, t))) if s.ok() && s.seconds > 0.0 => format!(
                "{} s vs {} s (×{:.0})",
                seconds(s.seconds),
                seconds(t),
                t / s.seconds
            ),
            _ => "—".into(),
        };
        let yes = |b: bool| if b { "yes" } else { "**no**" };
        writeln!(
            out,
            "| {} | {} | {n} | {} | {} | {} | {} | {speed} |",
            p.point.start.label(),
            p.point.swap,
            rank(&ours),
            rank(&paper),
            yes(same_best),
            yes(same_order)
        )
        .unwrap();
    }
    out
}

/// The facts of the traces of every point: how the scenarios came out (a
/// uniform-prior point runs the traces of its known-start twin, so only
/// the known-start points are listed).
pub(crate) fn traces(results: &Results) -> String {
    let mut out = String::from(
        "| experiment | point | traces | n | events | mixing share | truth lines | mix / observe distance (m) |\n\
         |---|---|---:|---:|---:|---:|---:|---|\n",
    );
    for p in results
        .points
        .iter()
        .filter(|p| p.point.start == Start::Known)
    {
        writeln!(
            out,
            "| {:?} | {} | {} | {:.0} | {:.0} | {:.3} | {:.0} | {:.2} / {:.2} |",
            p.point.experiment,
            p.point.label,
            p.traces.len(),
            p.mean_info(|t| t.tracks as f64),
            p.mean_info(|t| (t.mixes + t.observations) as f64),
            p.mix_share(),
            p.mean_info(|t| t.truths as f64),
            p.mean_info(|t| t.mix_distance),
            p.mean_info(|t| t.observe_distance),
        )
        .unwrap();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_formatted_for_reading() {
        assert_eq!(seconds(1342.35), "1342");
        assert_eq!(seconds(29.79), "29.8");
        assert_eq!(seconds(0.46), "0.460");
        assert_eq!(seconds(0.0012345), "0.00123");
        assert_eq!(seconds(f64::NAN), "—");
        let s = Summary {
            runs: 3,
            error: 0.1734,
            error_sd: 0.01,
            expected_error: 0.17,
            expected_topk: 0.175,
            brier: 0.12,
            log_loss: 0.4,
            reliability: Default::default(),
            run_errors: vec![0.16, 0.17, 0.19],
            seconds: 0.5,
            mean_coefficients: 99.0,
            max_coefficients: 100,
            refused: 0,
            failures: vec![],
        };
        assert_eq!(error(&s), "0.173 ± 0.010");
    }
}
