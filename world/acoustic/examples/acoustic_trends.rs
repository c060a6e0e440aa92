//! The trends of the paper's Figs. 9–14 and 16: error distance and
//! coverage against sensor density (with Theorem 5.5), number of targets,
//! speed, segment length, step size, n_group and zigzag periods. Every
//! point runs two variants of the tracker on the same separation
//! ([`run_variants`]): the default (the ranges of the groups that do not
//! hear a source excluded from its intersection) and the paper's
//! intersection as written ([`PipelineConfig::paper_intersection`]).
//! 400 sensors and 1000-sample recordings unless a sweep needs otherwise.
//! Writes one markdown table per figure to docs/acoustic-trends.md (stamped
//! with the digest of the tracker's sources and this program: a test fails
//! when the committed file is stale) and one SVG per figure (error
//! distance and coverage) to `docs/acoustic-*.svg`.
//!
//! `cargo run --release -p idmesh-acoustic --example acoustic_trends`
//! Options: `seeds=N` (default 3, as in docs/design/acoustic.md; about 7 min on
//! 2 cores), `only=fig9,rules,fig13,...` (`rules`: the intersection and vote
//! rules at the Fig. 9 setup), `plots=DIR` (default the workspace's
//! `docs/`; `plots=none` writes none), `out=FILE` (default
//! docs/acoustic-trends.md; `out=none` only prints; a partial run with
//! `only=` only prints).

use idmesh_acoustic::PathSpec;
use idmesh_acoustic::{average_resolution, group_radius};
use idmesh_acoustic::{run_variants, AcousticConfig, PipelineConfig};
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::time::Instant;

fn base() -> AcousticConfig {
    let mut c = AcousticConfig::paper(400, 10, 0);
    c.field.samples = 1000;
    c
}

/// The two variants every point runs.
const VARIANTS: [&str; 2] = ["tracker (default)", "paper's intersection"];

fn variants(c: &AcousticConfig) -> [PipelineConfig; 2] {
    [c.pipeline.clone(), c.pipeline.clone().paper_intersection()]
}

/// Means over seeds of one variant at one point.
#[derive(Debug, Clone, Copy, Default)]
struct Stats {
    mean: f64,
    std: f64,
    coverage: f64,
    aligned: f64,
    tracked: f64,
}

struct Row {
    label: String,
    x: f64,
    stats: [Stats; 2],
    seconds: f64,
    extra: String,
}

/// Each of `variants` (of one seed's pipeline) run on the same separation
/// for seeds 1..=`seeds`: their means over the seeds (the errors over the
/// seeds where they are finite), and the seconds a seed took.
fn mean_over_seeds(
    label: &str,
    config: &AcousticConfig,
    seeds: u64,
    variants: impl Fn(&AcousticConfig) -> Vec<PipelineConfig>,
) -> (Vec<Stats>, f64) {
    let count = variants(config).len();
    let mut sum = vec![Stats::default(); count];
    let mut finite = vec![0.0f64; count];
    let mut secs = 0.0;
    for seed in 1..=seeds {
        let mut cfg = config.clone();
        cfg.seed = seed;
        let start = Instant::now();
        match run_variants(&cfg, &variants(&cfg), &mut |_, _| {}) {
            Ok(results) => {
                for (i, r) in results.iter().enumerate() {
                    let m = &r.metrics;
                    if m.mean_error.is_finite() {
                        sum[i].mean += m.mean_error;
                        sum[i].std += m.std_error;
                        sum[i].aligned += m.aligned_error;
                        finite[i] += 1.0;
                    }
                    sum[i].coverage += m.coverage;
                    sum[i].tracked += m.slot_share;
                }
            }
            Err(e) => eprintln!("{label} seed {seed}: {e}"),
        }
        secs += start.elapsed().as_secs_f64();
    }
    let k = seeds as f64;
    let stats = sum
        .iter()
        .zip(&finite)
        .map(|(s, &f)| {
            let n = if f > 0.0 { f } else { f64::NAN };
            Stats {
                mean: s.mean / n,
                std: s.std / n,
                aligned: s.aligned / n,
                coverage: 100.0 * s.coverage / k,
                tracked: 100.0 * s.tracked / k,
            }
        })
        .collect();
    (stats, secs / k)
}

fn measure(label: String, x: f64, config: &AcousticConfig, seeds: u64, extra: String) -> Row {
    let (stats, seconds) = mean_over_seeds(&label, config, seeds, |c| variants(c).to_vec());
    eprintln!(
        "  {label}: {:.1} m / {:.1} m ({:.0} s)",
        stats[0].mean,
        stats[1].mean,
        seconds * seeds as f64
    );
    Row {
        label,
        x,
        stats: [stats[0], stats[1]],
        seconds,
        extra,
    }
}

fn table(title: &str, column: &str, extra: &str, rows: &[Row]) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    writeln!(out, "\n#### {title}\n").unwrap();
    let (x, xs) = if extra.is_empty() {
        (String::new(), String::new())
    } else {
        (format!(" {extra} |"), "---|".to_string())
    };
    writeln!(out, "| {column} | variant | mean error (m) | std (m) | coverage (%) | aligned error (m) | slots tracked (%) |{x} s/run |").unwrap();
    writeln!(out, "|---|---|---|---|---|---|---|{xs}---|").unwrap();
    for r in rows {
        for (i, s) in r.stats.iter().enumerate() {
            let e = if extra.is_empty() {
                String::new()
            } else if i == 0 {
                format!(" {} |", r.extra)
            } else {
                " |".to_string()
            };
            let (label, secs) = if i == 0 {
                (r.label.as_str(), format!("{:.1}", r.seconds))
            } else {
                ("", String::new())
            };
            let v = if i == 0 { "tracker" } else { "paper" };
            writeln!(
                out,
                "| {label} | {v} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |{e} {secs} |",
                s.mean, s.std, s.coverage, s.aligned, s.tracked
            )
            .unwrap();
        }
    }
    out
}

/// One line of a plot panel.
struct Line {
    name: String,
    colour: RGBColor,
    points: Vec<(f64, f64)>,
    /// Draw point markers (measured) or only the line (theory).
    markers: bool,
}

const BLUE: RGBColor = RGBColor(0x1f, 0x77, 0xb4);
const RED: RGBColor = RGBColor(0xd6, 0x27, 0x28);
const GREY: RGBColor = RGBColor(0x55, 0x55, 0x55);

fn measured(rows: &[Row], pick: impl Fn(&Stats) -> f64) -> [Line; 2] {
    [0, 1].map(|i| Line {
        name: VARIANTS[i].to_string(),
        colour: if i == 0 { BLUE } else { RED },
        points: rows
            .iter()
            .map(|r| (r.x, pick(&r.stats[i])))
            .filter(|p| p.1.is_finite())
            .collect(),
        markers: true,
    })
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

/// A tick label without trailing zeros: 400, 0.03, 2.5.
fn tick(v: &f64) -> String {
    let s = format!("{v:.2}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

fn panel(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    title: &str,
    x_label: &str,
    y_label: &str,
    y_range: Option<(f64, f64)>,
    legend: SeriesLabelPosition,
    lines: &[Line],
) -> DrawResult {
    let xs = lines.iter().flat_map(|l| l.points.iter().map(|p| p.0));
    let (x0, x1) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    });
    let pad = if x1 > x0 { 0.05 * (x1 - x0) } else { 0.5 };
    let (y0, y1) = y_range.unwrap_or_else(|| {
        let top = lines
            .iter()
            .flat_map(|l| l.points.iter().map(|p| p.1))
            .fold(0.0f64, f64::max);
        // Head room for the legend (upper right).
        (0.0, if top > 0.0 { top * 1.45 } else { 1.0 })
    });
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 17))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(55)
        .build_cartesian_2d(x0 - pad..x1 + pad, y0..y1)?;
    chart
        .configure_mesh()
        .x_desc(x_label)
        .y_desc(y_label)
        .x_label_formatter(&tick)
        .y_label_formatter(&|v| format!("{v:.0}"))
        .light_line_style(WHITE.mix(0.0))
        .draw()?;
    for l in lines {
        let style = l.colour.stroke_width(2);
        chart
            .draw_series(LineSeries::new(l.points.iter().copied(), style))?
            .label(l.name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 22, y)], style));
        if l.markers {
            let fill = l.colour.filled();
            chart.draw_series(l.points.iter().map(|&p| Circle::new(p, 3, fill)))?;
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .position(legend)
        .draw()?;
    Ok(())
}

/// Writes `dir/file`: error distance (left) and coverage (right) against
/// the figure's parameter; `theory` adds lines to the error panel.
fn plot(
    dir: &Path,
    file: &str,
    title: &str,
    x_label: &str,
    rows: &[Row],
    theory: Vec<Line>,
) -> DrawResult {
    let path = dir.join(file);
    let root = SVGBackend::new(&path, (1000, 420)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(500);
    let mut errors: Vec<Line> = measured(rows, |s| s.mean).into_iter().collect();
    errors.extend(theory);
    panel(
        &left,
        &format!("{title}: (a) error distance"),
        x_label,
        "mean error distance (m)",
        None,
        SeriesLabelPosition::UpperRight,
        &errors,
    )?;
    panel(
        &right,
        &format!("{title}: (b) coverage"),
        x_label,
        "percentage of coverage (%)",
        Some((0.0, 105.0)),
        SeriesLabelPosition::LowerRight,
        &measured(rows, |s| s.coverage),
    )?;
    root.present()?;
    eprintln!("wrote {}", path.display());
    Ok(())
}

/// A variant of the pipeline's settings.
type Rule = fn(PipelineConfig) -> PipelineConfig;

/// The intersection and vote rules at the Fig. 9 setup (speed 0.03
/// m/sample, 400 / 700 / 1000 sensors), each on the same separation: the
/// paper's intersection, the silent groups' ranges excluded (the fewest
/// only, then the default's fewest or one more), and two vote tolerances
/// that buy fragments back (docs/design/acoustic.md, "Accuracy").
fn departures(seeds: u64) -> String {
    use std::fmt::Write;
    let densities = [400usize, 700, 1000];
    let rules: [(&str, Rule); 5] = [
        ("the paper's intersection", |p| p.paper_intersection()),
        ("silent groups' ranges excluded, the fewest only", |p| {
            PipelineConfig {
                silent_slack: 0,
                ..p
            }
        }),
        ("… the fewest or one more (the default)", |p| p),
        (
            "the default, vote tolerance 6 m (speed limit × CTS span)",
            |p| PipelineConfig {
                vote_tolerance: 6.0,
                ..p
            },
        ),
        ("the fewest only, vote tolerance 40 m", |p| PipelineConfig {
            silent_slack: 0,
            vote_tolerance: 40.0,
            ..p
        }),
    ];
    // By density, each rule's means over the seeds.
    let by_density: Vec<Vec<Stats>> = densities
        .iter()
        .map(|&n| {
            let mut c = base();
            c.field.sensors = n;
            c.field.paths = PathSpec::Random {
                speed: (0.03, 0.03),
            };
            let label = format!("departures, {n} sensors");
            let (stats, _) = mean_over_seeds(&label, &c, seeds, |c| {
                rules.iter().map(|(_, f)| f(c.pipeline.clone())).collect()
            });
            eprintln!("  {label}");
            stats
        })
        .collect();
    let mut out = String::new();
    writeln!(
        out,
        "\n#### The intersection and the vote at the Fig. 9 setup (speed 0.03 m/sample)\n\n\
         Each rule on the same separation, mean of the seeds; the defect fixes apply to all \
         (docs/design/acoustic.md, \"Accuracy\"). Theorem 5.5 is in the Fig. 9 table.\n"
    )
    .unwrap();
    writeln!(out, "| rule | mean error (m) 400 / 700 / 1000 | coverage (%) | aligned error (m) | slots tracked (%) |").unwrap();
    writeln!(out, "|---|---|---|---|---|").unwrap();
    for (r, (name, _)) in rules.iter().enumerate() {
        let per = |pick: fn(&Stats) -> f64| {
            by_density
                .iter()
                .map(|stats| format!("{:.1}", pick(&stats[r])))
                .collect::<Vec<_>>()
                .join(" / ")
        };
        writeln!(
            out,
            "| {name} | {} | {} | {} | {} |",
            per(|s| s.mean),
            per(|s| s.coverage),
            per(|s| s.aligned),
            per(|s| s.tracked)
        )
        .unwrap();
    }
    out
}

fn main() {
    let mut seeds = 3u64;
    let mut only: Option<Vec<String>> = None;
    let docs = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../docs");
    let mut plots: Option<PathBuf> = Some(docs.clone());
    let mut out: Option<PathBuf> = Some(docs.join("acoustic-trends.md"));
    for arg in std::env::args().skip(1) {
        match arg.split_once('=') {
            Some(("seeds", v)) => seeds = v.parse().unwrap_or(3),
            Some(("only", v)) => only = Some(v.split(',').map(str::to_string).collect()),
            Some(("plots", "none")) => plots = None,
            Some(("plots", v)) => plots = Some(PathBuf::from(v)),
            Some(("out", "none")) => out = None,
            Some(("out", v)) => out = Some(PathBuf::from(v)),
            _ => {
                eprintln!(
                    "options: seeds=N only=fig9,rules,fig10,fig11,fig12,fig13,fig14,fig16 plots=DIR|none \
                     out=FILE|none"
                );
                std::process::exit(2)
            }
        }
    }
    let want = |f: &str| only.as_ref().is_none_or(|o| o.iter().any(|x| x == f));
    let draw = |file: &str, title: &str, x_label: &str, rows: &[Row], theory: Vec<Line>| {
        if let Some(dir) = &plots {
            if let Err(e) = plot(dir, file, title, x_label, rows, theory) {
                eprintln!("{file}: {e}");
            }
        }
    };
    let start = Instant::now();
    let mut doc = format!(
        "# Acoustic tracking trends (Figs. 9–14, 16)\n\n\
         Generated by `cargo run --release -p idmesh-acoustic --example acoustic_trends` \
         (about 7 minutes on 2 cores); do not edit by hand.\n\n{}\n\n\
         {seeds} seed(s) per point; 400 sensors, 10 targets, 1000 samples, R = 250 m, \
         n_group = 10, l_seg = 100, l_step = 10 unless the column says otherwise. Each point \
         runs the tracker's default (\"tracker\") and the paper's intersection (\"paper\") \
         on the same separation; docs/design/acoustic.md says what the trends mean.\n",
        idmesh_acoustic::trends_stamp_line()
    );

    if want("fig9") {
        let densities = [400usize, 700, 1000, 1300];
        let rows: Vec<Row> = densities
            .iter()
            .map(|&n| {
                let mut c = base();
                c.field.sensors = n;
                c.field.paths = PathSpec::Random {
                    speed: (0.03, 0.03),
                };
                let r = group_radius(10, 1600.0, 1600.0, n);
                let th = |l: f64| {
                    average_resolution(250.0, r, l).map_or("-".into(), |v| format!("{v:.1}"))
                };
                measure(
                    n.to_string(),
                    n as f64,
                    &c,
                    seeds,
                    format!("{} / {}", th(3.0), th(100.0)),
                )
            })
            .collect();
        doc += &table(
            "Fig. 9 — sensor density, speed 0.03 m/sample, vs Theorem 5.5",
            "sensors",
            "Thm 5.5 (m), l = 3 m / 100 m",
            &rows,
        );
        let theorem = Line {
            name: "Theorem 5.5, l = 100 m".into(),
            colour: GREY,
            points: (0..=18)
                .map(|i| 400.0 + 50.0 * i as f64)
                .filter_map(|n| {
                    let r = group_radius(10, 1600.0, 1600.0, n as usize);
                    average_resolution(250.0, r, 100.0).map(|v| (n, v))
                })
                .collect(),
            markers: false,
        };
        draw(
            "acoustic-fig09-density.svg",
            "Fig. 9",
            "sensors in the 1600 m field",
            &rows,
            vec![theorem],
        );
    }
    if want("rules") {
        doc.push_str(&departures(seeds));
    }
    if want("fig10") {
        let rows: Vec<Row> = [2usize, 4, 6, 8, 10]
            .iter()
            .map(|&k| {
                let mut c = base();
                c.field.targets = k;
                measure(k.to_string(), k as f64, &c, seeds, String::new())
            })
            .collect();
        doc += &table("Fig. 10 — number of targets", "targets", "", &rows);
        draw(
            "acoustic-fig10-targets.svg",
            "Fig. 10",
            "number of targets",
            &rows,
            vec![],
        );
    }
    if want("fig11") {
        let rows: Vec<Row> = [0.03, 0.06, 0.09, 0.12, 0.15]
            .iter()
            .map(|&v| {
                let mut c = base();
                c.field.paths = PathSpec::Random { speed: (v, v) };
                measure(format!("{v:.2}"), v, &c, seeds, String::new())
            })
            .collect();
        doc += &table("Fig. 11 — speed (m/sample)", "speed", "", &rows);
        draw(
            "acoustic-fig11-speed.svg",
            "Fig. 11",
            "speed (m/sample)",
            &rows,
            vec![],
        );
    }
    if want("fig12") {
        let rows: Vec<Row> = [50usize, 100, 150, 200]
            .iter()
            .map(|&l| {
                let mut c = base();
                c.pipeline.l_seg = l;
                measure(l.to_string(), l as f64, &c, seeds, String::new())
            })
            .collect();
        doc += &table(
            "Fig. 12 — segment length l_seg (l_step = 10)",
            "l_seg",
            "",
            &rows,
        );
        draw(
            "acoustic-fig12-lseg.svg",
            "Fig. 12",
            "segment length l_seg (samples)",
            &rows,
            vec![],
        );
    }
    if want("fig13") {
        let rows: Vec<Row> = [5usize, 10, 20, 30]
            .iter()
            .map(|&l| {
                let mut c = base();
                c.pipeline.l_step = l;
                measure(l.to_string(), l as f64, &c, seeds, String::new())
            })
            .collect();
        doc += &table(
            "Fig. 13 — step size l_step (l_seg = 100)",
            "l_step",
            "",
            &rows,
        );
        draw(
            "acoustic-fig13-lstep.svg",
            "Fig. 13",
            "step size l_step (samples)",
            &rows,
            vec![],
        );
    }
    if want("fig14") {
        let rows: Vec<Row> = [4usize, 6, 10, 14]
            .iter()
            .map(|&g| {
                let mut c = base();
                c.pipeline.n_group = g;
                measure(g.to_string(), g as f64, &c, seeds, String::new())
            })
            .collect();
        doc += &table("Fig. 14 — sensors per group n_group", "n_group", "", &rows);
        draw(
            "acoustic-fig14-ngroup.svg",
            "Fig. 14",
            "sensors per group n_group",
            &rows,
            vec![],
        );
    }
    if want("fig16") {
        let rows: Vec<Row> = [1u32, 2, 3, 4]
            .iter()
            .map(|&p| {
                let mut c = base();
                c.field.samples = 2000;
                c.field.paths = PathSpec::Zigzag {
                    periods: p,
                    length: 300.0,
                    width: 100.0,
                };
                let len = 4.0 * p as f64 * (50f64.powi(2) + (75.0 / p as f64).powi(2)).sqrt();
                measure(
                    p.to_string(),
                    p as f64,
                    &c,
                    seeds,
                    format!("{:.2}", len / 1999.0),
                )
            })
            .collect();
        doc += &table(
            "Fig. 16 — zigzag paths (A–B 300 m, width 100 m, 2000 samples)",
            "periods",
            "speed (m/sample)",
            &rows,
        );
        draw(
            "acoustic-fig16-zigzag.svg",
            "Fig. 16",
            "zigzag periods",
            &rows,
            vec![],
        );
    }
    print!("{doc}");
    println!("\nTotal {:.0} s.", start.elapsed().as_secs_f64());
    // Only a whole run is the document: a partial one (`only=`) prints.
    if let (Some(out), None) = (&out, &only) {
        match std::fs::write(out, &doc) {
            Ok(()) => eprintln!("wrote {}", out.display()),
            Err(e) => {
                eprintln!("{}: {e}", out.display());
                std::process::exit(1)
            }
        }
    }
}
