//! The trends of the paper's Figs. 9–14 and 16: error distance and
//! coverage against sensor density (with Theorem 5.5), number of targets,
//! speed, segment length, step size, n_group and zigzag periods. Small
//! enough to run in minutes on 2 cores: 400 sensors (the paper's lowest
//! density) and 1000-sample recordings unless a sweep needs otherwise, a
//! few seeds per point. Prints one markdown table per figure.
//!
//! `cargo run --release -p idmesh-sensor --example acoustic_trends`
//! Options: `seeds=N` (default 1; docs/acoustic.md used 2), `only=fig10,fig13,...`.

use idmesh_sensor::acoustic::field::PathSpec;
use idmesh_sensor::acoustic::resolution::{average_resolution, group_radius};
use idmesh_sensor::acoustic::{run, AcousticConfig};
use std::time::Instant;

fn base() -> AcousticConfig {
    let mut c = AcousticConfig::paper(400, 10, 0);
    c.field.samples = 1000;
    c
}

struct Row {
    label: String,
    mean: f64,
    std: f64,
    coverage: f64,
    aligned: f64,
    tracked: f64,
    seconds: f64,
    extra: String,
}

fn measure(label: String, config: &AcousticConfig, seeds: u64, extra: String) -> Row {
    let (mut m, mut s, mut c, mut a, mut t, mut secs, mut n) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for seed in 1..=seeds {
        let mut cfg = config.clone();
        cfg.seed = seed;
        let start = Instant::now();
        match run(&cfg, &mut |_, _| {}) {
            Ok(r) => {
                let x = &r.metrics;
                if x.mean_error.is_finite() {
                    m += x.mean_error;
                    s += x.std_error;
                    a += x.aligned_error;
                    n += 1.0;
                }
                c += x.coverage;
                t += x.slot_share;
            }
            Err(e) => eprintln!("{label} seed {seed}: {e}"),
        }
        secs += start.elapsed().as_secs_f64();
    }
    let k = seeds as f64;
    let n = if n > 0.0 { n } else { f64::NAN };
    Row {
        label,
        mean: m / n,
        std: s / n,
        coverage: 100.0 * c / k,
        aligned: a / n,
        tracked: 100.0 * t / k,
        seconds: secs / k,
        extra,
    }
}

fn table(title: &str, column: &str, extra: &str, rows: &[Row]) {
    println!("\n### {title}\n");
    let x = if extra.is_empty() {
        String::new()
    } else {
        format!(" {extra} |")
    };
    let xs = if extra.is_empty() {
        String::new()
    } else {
        "---|".to_string()
    };
    println!("| {column} | mean error (m) | std (m) | coverage (%) | aligned error (m) | slots tracked (%) |{x} s/run |");
    println!("|---|---|---|---|---|---|{xs}---|");
    for r in rows {
        let e = if extra.is_empty() {
            String::new()
        } else {
            format!(" {} |", r.extra)
        };
        println!(
            "| {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} |{e} {:.1} |",
            r.label, r.mean, r.std, r.coverage, r.aligned, r.tracked, r.seconds
        );
    }
}

fn main() {
    let mut seeds = 1u64;
    let mut only: Option<Vec<String>> = None;
    for arg in std::env::args().skip(1) {
        match arg.split_once('=') {
            Some(("seeds", v)) => seeds = v.parse().unwrap_or(1),
            Some(("only", v)) => only = Some(v.split(',').map(str::to_string).collect()),
            _ => {
                eprintln!("options: seeds=N only=fig9,fig10,fig11,fig12,fig13,fig14,fig16");
                std::process::exit(2)
            }
        }
    }
    let want = |f: &str| only.as_ref().is_none_or(|o| o.iter().any(|x| x == f));
    let start = Instant::now();
    println!("Acoustic tracking trends: {seeds} seed(s) per point; 400 sensors, 10 targets, 1000 samples, R = 250 m, n_group = 10, l_seg = 100, l_step = 10 unless the column says otherwise.");

    if want("fig9") {
        let rows: Vec<Row> = [400usize, 700, 1000]
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
                    &c,
                    seeds,
                    format!("{} / {}", th(3.0), th(100.0)),
                )
            })
            .collect();
        table(
            "Fig. 9 — sensor density, speed 0.03 m/sample, vs Theorem 5.5",
            "sensors",
            "Thm 5.5 (m), l = 3 m / 100 m",
            &rows,
        );
    }
    if want("fig10") {
        let rows: Vec<Row> = [2usize, 4, 6, 8, 10]
            .iter()
            .map(|&k| {
                let mut c = base();
                c.field.targets = k;
                measure(k.to_string(), &c, seeds, String::new())
            })
            .collect();
        table("Fig. 10 — number of targets", "targets", "", &rows);
    }
    if want("fig11") {
        let rows: Vec<Row> = [0.03, 0.06, 0.09, 0.12, 0.15]
            .iter()
            .map(|&v| {
                let mut c = base();
                c.field.paths = PathSpec::Random { speed: (v, v) };
                measure(format!("{v:.2}"), &c, seeds, String::new())
            })
            .collect();
        table("Fig. 11 — speed (m/sample)", "speed", "", &rows);
    }
    if want("fig12") {
        let rows: Vec<Row> = [50usize, 100, 150, 200]
            .iter()
            .map(|&l| {
                let mut c = base();
                c.pipeline.l_seg = l;
                measure(l.to_string(), &c, seeds, String::new())
            })
            .collect();
        table(
            "Fig. 12 — segment length l_seg (l_step = 10)",
            "l_seg",
            "",
            &rows,
        );
    }
    if want("fig13") {
        let rows: Vec<Row> = [5usize, 10, 20, 30]
            .iter()
            .map(|&l| {
                let mut c = base();
                c.pipeline.l_step = l;
                measure(l.to_string(), &c, seeds, String::new())
            })
            .collect();
        table(
            "Fig. 13 — step size l_step (l_seg = 100)",
            "l_step",
            "",
            &rows,
        );
    }
    if want("fig14") {
        let rows: Vec<Row> = [4usize, 6, 10, 14]
            .iter()
            .map(|&g| {
                let mut c = base();
                c.pipeline.n_group = g;
                measure(g.to_string(), &c, seeds, String::new())
            })
            .collect();
        table("Fig. 14 — sensors per group n_group", "n_group", "", &rows);
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
                measure(p.to_string(), &c, seeds, format!("{:.2}", len / 1999.0))
            })
            .collect();
        table(
            "Fig. 16 — zigzag paths (A–B 300 m, width 100 m, 2000 samples)",
            "periods",
            "speed (m/sample)",
            &rows,
        );
    }
    println!("\nTotal {:.0} s.", start.elapsed().as_secs_f64());
}
