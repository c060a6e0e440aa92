//! SVG line plots (plotters): tracking error against one parameter, one
//! line per method, the exact filter (where n ≤ 20) drawn black as the
//! optimum; and the reliability diagram (how often a track given
//! probability p was red, per method, the diagonal black).

use super::methods::Method;
use super::plan::Experiment;
use super::results::{PointResult, Results};
use anyhow::{anyhow, Context, Result};
use idmesh_belief::Reliability;
use plotters::prelude::*;
use std::path::Path;

/// One line: a name and its (x, error) points, x ascending.
#[derive(Debug, Clone, PartialEq)]
pub struct Series {
    pub name: String,
    pub exact: bool,
    pub points: Vec<(f64, f64)>,
}

/// A plot to write: file name (in the output directory), title, x label,
/// and what it shows.
#[derive(Debug, Clone)]
pub struct Plot {
    pub file: String,
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
}

/// The y label of the error plots.
pub(crate) const ERROR_LABEL: &str = "tracking error (fraction mislabeled)";

/// The reliability diagram over every run of the grid: per method, the
/// mean predicted P(red) of each tenth of [0, 1] against how often those
/// tracks were red; a calibrated belief lies on the diagonal.
pub(crate) fn reliability(results: &Results) -> Plot {
    let mut by_method: Vec<(String, Reliability)> = Vec::new();
    for p in &results.points {
        for (m, s) in &p.methods {
            let label = m.label();
            match by_method.iter_mut().find(|(l, _)| *l == label) {
                Some((_, r)) => r.merge(&s.reliability),
                None => by_method.push((label, s.reliability.clone())),
            }
        }
    }
    Plot {
        file: "results-reliability.svg".into(),
        title: "Reliability: how often a track given P(red) = p was red (all runs)".into(),
        x_label: "predicted P(red), mean of each tenth".into(),
        y_label: "observed share red".into(),
        series: reliability_series(&by_method, 1),
    }
}

/// The lines of a reliability diagram: the diagonal (black), then one per
/// method of its bins holding at least `min_count` predictions, mean
/// predicted against observed (a method with no such bin draws none).
pub fn reliability_series(methods: &[(String, Reliability)], min_count: u64) -> Vec<Series> {
    let mut series = vec![Series {
        name: "calibrated".into(),
        exact: true,
        points: vec![(0.0, 0.0), (1.0, 1.0)],
    }];
    for (name, r) in methods {
        let points: Vec<(f64, f64)> = r
            .points()
            .into_iter()
            .filter(|&(_, _, count)| count >= min_count)
            .map(|(p, f, _)| (p, f))
            .collect();
        if !points.is_empty() {
            series.push(Series {
                name: name.clone(),
                exact: false,
                points,
            });
        }
    }
    series
}

/// The series of an experiment's points (filtered to n): one per method
/// slot, x = the point's x, or its measured mixing share.
pub(crate) fn series_of(results: &Results, experiment: Experiment, n: usize) -> Vec<Series> {
    let points: Vec<&PointResult> = results
        .points
        .iter()
        .filter(|p| p.point.experiment == experiment && p.point.n == n)
        .collect();
    let slots = points
        .iter()
        .map(|p| p.point.methods.len())
        .max()
        .unwrap_or(0);
    let mut series = Vec::new();
    for slot in 0..slots {
        let Some(method) = points.iter().find_map(|p| p.point.methods.get(slot)) else {
            continue;
        };
        let mut xy: Vec<(f64, f64)> = points
            .iter()
            .filter_map(|p| {
                let m = p.point.methods.get(slot)?;
                let s = p.summary(m).filter(|s| s.ok())?;
                let x = match experiment {
                    Experiment::SmallScale | Experiment::MixingLarge => p.mix_share(),
                    _ => p.point.x,
                };
                Some((x, s.error))
            })
            .collect();
        if xy.is_empty() {
            continue;
        }
        xy.sort_by(|a, b| a.0.total_cmp(&b.0));
        series.push(Series {
            name: method.label(),
            exact: *method == Method::Exact,
            points: xy,
        });
    }
    series
}

const COLOURS: [RGBColor; 8] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0x8c, 0x56, 0x4b),
    RGBColor(0xe3, 0x77, 0xc2),
    RGBColor(0x17, 0xbe, 0xcf),
];

/// Draws `plot` as an SVG file in `dir`.
pub fn draw(plot: &Plot, dir: &Path) -> Result<()> {
    let path = dir.join(&plot.file);
    let failed = |e: &dyn std::fmt::Display| anyhow!("{}: {e}", path.display());
    let xs = plot
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.0));
    let (x_min, x_max) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
        (lo.min(x), hi.max(x))
    });
    let (x_min, x_max) = if x_min.is_finite() && x_max > x_min {
        let pad = 0.05 * (x_max - x_min);
        (x_min - pad, x_max + pad)
    } else if x_min.is_finite() {
        (x_min - 0.5, x_min + 0.5)
    } else {
        (0.0, 1.0)
    };
    let y_max = plot
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .fold(0.0f64, f64::max);
    let y_max = if y_max > 0.0 { y_max * 1.15 } else { 0.5 };

    let root = SVGBackend::new(&path, (800, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| failed(&e))?;
    let mut chart = ChartBuilder::on(&root)
        .caption(&plot.title, ("sans-serif", 20))
        .margin(16)
        .x_label_area_size(45)
        .y_label_area_size(60)
        .build_cartesian_2d(x_min..x_max, 0.0..y_max)
        .map_err(|e| failed(&e))?;
    chart
        .configure_mesh()
        .x_desc(plot.x_label.as_str())
        .y_desc(plot.y_label.as_str())
        .light_line_style(WHITE.mix(0.0))
        .draw()
        .map_err(|e| failed(&e))?;
    let mut colour = 0;
    for s in &plot.series {
        let style = if s.exact {
            BLACK.stroke_width(3)
        } else {
            let c = COLOURS[colour % COLOURS.len()];
            colour += 1;
            c.stroke_width(2)
        };
        let fill = style.color.filled();
        chart
            .draw_series(LineSeries::new(s.points.iter().copied(), style))
            .map_err(|e| failed(&e))?
            .label(s.name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], style));
        chart
            .draw_series(s.points.iter().map(|&p| Circle::new(p, 3, fill)))
            .map_err(|e| failed(&e))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .position(SeriesLabelPosition::UpperLeft)
        .draw()
        .map_err(|e| failed(&e))?;
    root.present()
        .map_err(|e| failed(&e))
        .with_context(|| format!("cannot write {}", path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_an_svg() {
        let dir = std::env::temp_dir().join(format!("idmesh-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let plot = Plot {
            file: "t.svg".into(),
            title: "error vs swap".into(),
            x_label: "swap probability".into(),
            y_label: ERROR_LABEL.into(),
            series: vec![
                Series {
                    name: "exact".into(),
                    exact: true,
                    points: vec![(0.1, 0.05), (0.5, 0.2)],
                },
                Series {
                    name: "order 1".into(),
                    exact: false,
                    points: vec![(0.1, 0.1), (0.5, 0.3)],
                },
            ],
        };
        draw(&plot, &dir).unwrap();
        let svg = std::fs::read_to_string(dir.join("t.svg")).unwrap();
        assert!(svg.starts_with("<svg"), "{}", &svg[..40.min(svg.len())]);
        assert!(svg.contains("order 1"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
