//! FastICA against scikit-learn's on the same mixtures, in one run.
//!
//! Generates the mixtures, separates them with idmesh's FastICA (timed
//! here), writes them to a temporary JSON file, runs
//! `scripts/fastica_sklearn.py` on it (scikit-learn timed there, around
//! `fit_transform` alone), and prints quality (Amari index, max |corr|
//! with the true sources) and time side by side, with the ratio. Both run
//! single-threaded (the script's BLAS is pinned to one thread) with the
//! same settings: parallel/symmetric, logcosh (α = 1), tol 10⁻⁴, at most
//! 200 iterations, unit-variance whitening, n_components = sources.
//!
//! Needs `python3` (or `$PYTHON`) with numpy and scikit-learn:
//! `pip install scikit-learn numpy`, then
//! `cargo run --release -p idmesh-acoustic --example acoustic_fastica_compare`.
//! Option `quick` runs fewer repetitions.

use idmesh_acoustic::{amari_index, max_abs_correlations};
use idmesh_acoustic::{ar_source, chirp_song, ArParams, ChirpParams};
use idmesh_acoustic::{FastIca, FastIcaConfig, FastIcaError};
use nalgebra::DMatrix;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::json;
use std::process::Command;
use std::time::Instant;

struct Case {
    name: &'static str,
    sources: usize,
    sensors: usize,
    samples: usize,
    reps: usize,
    acoustic: bool,
}

struct Rep {
    x: DMatrix<f64>,
    a: DMatrix<f64>,
    s: DMatrix<f64>,
}

/// i.i.d. Laplace and uniform sources (alternating), or the acoustic
/// sources of the tracker (chirps and AR), mixed by a uniform random
/// matrix in [−1, 1].
fn make(case: &Case, seed: u64) -> Rep {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut s = DMatrix::<f64>::zeros(case.sources, case.samples);
    for i in 0..case.sources {
        let row: Vec<f64> = if case.acoustic {
            if i % 2 == 0 {
                chirp_song(case.samples, &ChirpParams::default(), &mut rng)
            } else {
                ar_source(case.samples, &ArParams::default(), &mut rng)
            }
        } else if i % 2 == 0 {
            (0..case.samples)
                .map(|_| {
                    let u: f64 = rng.gen::<f64>() - 0.5;
                    -u.signum() * (1.0 - 2.0 * u.abs()).max(1e-300).ln()
                })
                .collect()
        } else {
            (0..case.samples)
                .map(|_| rng.gen::<f64>() * 2.0 - 1.0)
                .collect()
        };
        for (k, v) in row.into_iter().enumerate() {
            s[(i, k)] = v;
        }
    }
    let a = DMatrix::from_fn(case.sensors, case.sources, |_, _| {
        rng.gen::<f64>() * 2.0 - 1.0
    });
    Rep { x: &a * &s, a, s }
}

fn rows(m: &DMatrix<f64>) -> Vec<Vec<f64>> {
    m.row_iter().map(|r| r.iter().copied().collect()).collect()
}

#[derive(Default)]
struct Summary {
    seconds: Vec<f64>,
    amari: Vec<f64>,
    corr_mean: Vec<f64>,
    corr_min: Vec<f64>,
    not_converged: usize,
}

impl Summary {
    fn add(&mut self, seconds: f64, amari: f64, corr: &[f64], converged: bool) {
        self.seconds.push(seconds);
        self.amari.push(amari);
        self.corr_mean
            .push(corr.iter().sum::<f64>() / corr.len().max(1) as f64);
        self.corr_min
            .push(corr.iter().cloned().fold(f64::INFINITY, f64::min));
        self.not_converged += usize::from(!converged);
    }
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

fn main() {
    let quick = std::env::args().any(|a| a == "quick");
    let r = |n: usize| if quick { n.div_ceil(10) } else { n };
    let cases = [
        Case {
            name: "10 src x 10 sensors x 100 samples (Laplace/uniform)",
            sources: 10,
            sensors: 10,
            samples: 100,
            reps: r(200),
            acoustic: false,
        },
        Case {
            name: "10 src x 10 sensors x 100 samples (chirps/AR)",
            sources: 10,
            sensors: 10,
            samples: 100,
            reps: r(200),
            acoustic: true,
        },
        Case {
            name: "3 src x 10 sensors x 100 samples (pipeline-sized)",
            sources: 3,
            sensors: 10,
            samples: 100,
            reps: r(500),
            acoustic: false,
        },
        Case {
            name: "10 src x 10 sensors x 5000 samples (Laplace/uniform)",
            sources: 10,
            sensors: 10,
            samples: 5000,
            reps: r(20),
            acoustic: false,
        },
        Case {
            name: "20 src x 20 sensors x 20000 samples (chirps/AR)",
            sources: 20,
            sensors: 20,
            samples: 20000,
            reps: r(5),
            acoustic: true,
        },
    ];
    let mut data = Vec::new();
    let mut ours = Vec::new();
    for (ci, case) in cases.iter().enumerate() {
        let reps: Vec<Rep> = (0..case.reps)
            .map(|i| make(case, 1000 * ci as u64 + i as u64))
            .collect();
        let mut sum = Summary::default();
        for (i, rep) in reps.iter().enumerate() {
            let ica = FastIca::new(FastIcaConfig {
                components: idmesh_acoustic::Components::Fixed(case.sources),
                seed: i as u64,
                ..FastIcaConfig::default()
            });
            let t = Instant::now();
            let out = ica.fit(&rep.x);
            let seconds = t.elapsed().as_secs_f64();
            let (result, converged) = match out {
                Ok(r) => (r, true),
                Err(FastIcaError::NotConverged { partial, .. }) => (*partial, false),
                Err(e) => {
                    eprintln!("{}: repetition {i}: {e}", case.name);
                    std::process::exit(1)
                }
            };
            let corr = max_abs_correlations(&rep.s, &result.sources);
            sum.add(
                seconds,
                amari_index(&(&result.unmixing * &rep.a)),
                &corr,
                converged,
            );
        }
        ours.push(sum);
        data.push(json!({
            "name": case.name,
            "reps": reps.iter().map(|r| json!({"x": rows(&r.x), "a": rows(&r.a), "s": rows(&r.s)})).collect::<Vec<_>>(),
        }));
    }
    let dir = std::env::temp_dir().join(format!("idmesh-fastica-{}", std::process::id()));
    if let Err(e) = std::fs::create_dir_all(&dir) {
        eprintln!("{}: {e}", dir.display());
        std::process::exit(1)
    }
    let input = dir.join("mixtures.json");
    let output = dir.join("sklearn.json");
    let write = serde_json::to_vec(&json!({ "cases": data }))
        .map_err(|e| e.to_string())
        .and_then(|bytes| std::fs::write(&input, bytes).map_err(|e| e.to_string()));
    if let Err(e) = write {
        eprintln!("{}: {e}", input.display());
        std::process::exit(1)
    }
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../scripts/fastica_sklearn.py"
    );
    let python = std::env::var("PYTHON").unwrap_or_else(|_| "python3".into());
    let status = Command::new(&python)
        .arg(script)
        .arg(&input)
        .arg(&output)
        .env("OMP_NUM_THREADS", "1")
        .env("OPENBLAS_NUM_THREADS", "1")
        .env("MKL_NUM_THREADS", "1")
        .status();
    let sk: Option<serde_json::Value> = match status {
        Ok(s) if s.success() => std::fs::read(&output)
            .ok()
            .and_then(|b| serde_json::from_slice(&b).ok()),
        Ok(s) => {
            eprintln!("{python} {script} failed ({s}); is `pip install scikit-learn numpy` done? Showing idmesh only.");
            None
        }
        Err(e) => {
            eprintln!("cannot run {python}: {e}; showing idmesh only.");
            None
        }
    };
    let _ = std::fs::remove_dir_all(&dir);
    if let Some(v) = &sk {
        println!(
            "scikit-learn {} / numpy {} (single-threaded BLAS) vs idmesh FastICA (nalgebra), same mixtures\n",
            v["sklearn"].as_str().unwrap_or("?"),
            v["numpy"].as_str().unwrap_or("?")
        );
    }
    println!(
        "{:<54} {:>6} | {:>8} {:>8} {:>8} {:>5} | {:>10} {:>10} | {:>7}",
        "case", "impl", "amari", "corr", "min corr", "n.c.", "mean time", "median", "speedup"
    );
    for (ci, case) in cases.iter().enumerate() {
        let o = &ours[ci];
        let line = |who: &str, s: &Summary, speedup: String| {
            println!(
                "{:<54} {:>6} | {:>8.4} {:>8.4} {:>8.4} {:>5} | {:>9.1}µs {:>9.1}µs | {:>7}",
                case.name,
                who,
                mean(&s.amari),
                mean(&s.corr_mean),
                mean(&s.corr_min),
                s.not_converged,
                1e6 * mean(&s.seconds),
                1e6 * median(&s.seconds),
                speedup
            )
        };
        line("idmesh", o, String::new());
        if let Some(v) = &sk {
            let mut s = Summary::default();
            for r in v["cases"][ci]["results"].as_array().into_iter().flatten() {
                let corr: Vec<f64> = r["max_corr"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter_map(|c| c.as_f64())
                    .collect();
                s.add(
                    r["seconds"].as_f64().unwrap_or(f64::NAN),
                    r["amari"].as_f64().unwrap_or(f64::NAN),
                    &corr,
                    r["converged"].as_bool().unwrap_or(false),
                );
            }
            line(
                "sklearn",
                &s,
                format!("{:.1}x", mean(&s.seconds) / mean(&o.seconds)),
            );
        }
    }
    println!("\namari: Amari index of W·A (0 = perfect); corr: mean over sources of the best |corr| with an estimate; min corr: the worst source; n.c.: runs that hit 200 iterations (kept, as scikit-learn does); speedup = sklearn mean time / idmesh mean time.");
}
