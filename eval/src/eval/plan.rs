//! What `eval` runs: the experiments of the paper's Section 6 as points
//! (one scenario, several seeds) × methods, for the `quick` and `full`
//! presets.
//!
//! Budgets follow the paper: B = 5n coefficients for the Radon methods
//! ("about 50" at n = 10; 100/300/500 at n = 20/60/100 in Table III). A
//! particle filter with P = B particles holds as many sets as the Radon
//! belief: that is the equal-memory comparison; the equal-time one is
//! calibrated after the first pass (see `mod.rs`).
//!
//! Every point starts from the known red tracks except the uniform-prior
//! copies of the Table III points (every Table III method) and of the
//! pedestrian windows (the exact filter and the overcomplete method with
//! and without the distributed rule): with a known start the distributed
//! rule has next to nothing to restrict (see the section on its cost in
//! results.md), so its cost is measured under both starts.

use super::args::Preset;
use super::methods::{Method, FACTORED_AVAILABLE};
use super::scenarios::{ScenarioSpec, Sensor, Source, Start};

/// The experiments, each one table or plot of results.md.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) enum Experiment {
    /// n = 10, k = 5 at four mixing shares (Fig. 5b).
    SmallScale,
    /// Table III: n = 20, 60, 100, half of the events mixes.
    Table3,
    /// Error against the mixing share at larger n (Fig. 7a).
    MixingLarge,
    /// Error against the swap probability (Fig. 6).
    Swap,
    /// Error against the sensor's accuracy (Fig. 6).
    Likelihood,
    /// Table III on the real pedestrian scenes.
    Pedestrians,
}

/// One point of an experiment: a scenario over several seeds, and the
/// methods to run on it.
#[derive(Debug, Clone)]
pub(crate) struct Point {
    pub experiment: Experiment,
    /// The nominal n (a pedestrian window's cap).
    pub n: usize,
    /// The swap probability of every mix.
    pub swap: f64,
    /// What the filters know at time 0.
    pub start: Start,
    /// The value on the plot's x axis (target mixing share, swap
    /// probability, sensor accuracy), or 0.
    pub x: f64,
    /// A short name: "n = 20", "eth, n ≤ 20".
    pub label: String,
    /// One scenario per seed.
    pub specs: Vec<ScenarioSpec>,
    pub methods: Vec<Method>,
}

/// The whole grid of a preset.
#[derive(Debug, Clone)]
pub(crate) struct Plan {
    pub seeds: usize,
    pub points: Vec<Point>,
}

/// The Radon budget at n tracks.
pub(crate) fn budget(n: usize) -> usize {
    5 * n
}

/// The particle count every grid runs besides P = B.
pub(crate) const PARTICLES: usize = 1000;

/// The Table III rows at n (and the exact filter, which `Method::fits`
/// drops above n = 20).
fn table3_methods(n: usize) -> Vec<Method> {
    let b = budget(n);
    let mut methods = vec![
        Method::Exact,
        Method::Order(1),
        Method::Order(3),
        Method::Threshold(b),
        Method::Overcomplete(b),
        Method::Distributed(b),
        Method::Particles(b),
        Method::Particles(PARTICLES),
    ];
    if FACTORED_AVAILABLE {
        methods.push(Method::Factored);
        methods.push(Method::FactoredLocal);
        // What a deployment computes at the default settings.
        methods.extend(DEPLOYED_LEADERS.map(Method::Deployed));
    }
    methods
}

/// The leader counts of the deployed rows: the regional rule's accuracy
/// cost beside the centralized rows.
pub(crate) const DEPLOYED_LEADERS: [usize; 2] = [4, 8];

/// The uniform-prior copies of the pedestrian windows: enough for the
/// cost of the distributed rule.
fn distributed_methods(n: usize) -> Vec<Method> {
    let b = budget(n);
    vec![
        Method::Exact,
        Method::Overcomplete(b),
        Method::Distributed(b),
    ]
}

/// The lines of the plots at n.
fn plot_methods(n: usize) -> Vec<Method> {
    let b = budget(n);
    let mut methods = vec![
        Method::Exact,
        Method::Order(1),
        Method::Order(3),
        Method::Overcomplete(b),
        Method::Particles(PARTICLES),
    ];
    if FACTORED_AVAILABLE {
        methods.push(Method::Factored);
    }
    methods
}

/// The small-scale rows: every order up to 3 (order 5 = the exact filter).
fn small_methods(n: usize) -> Vec<Method> {
    let b = budget(n);
    let mut methods = vec![
        Method::Exact,
        Method::Order(1),
        Method::Order(2),
        Method::Order(3),
        Method::Threshold(b),
        Method::Overcomplete(b),
        Method::Particles(b),
        Method::Particles(PARTICLES),
    ];
    if FACTORED_AVAILABLE {
        methods.push(Method::Factored);
    }
    methods
}

struct Sizes {
    events: usize,
    small_shares: Vec<f64>,
    table3_n: Vec<usize>,
    table3_swaps: Vec<f64>,
    large_n: Vec<usize>,
    large_shares: Vec<f64>,
    sweep_n: usize,
    swaps: Vec<f64>,
    accuracies: Vec<f64>,
    /// (scene, cap) pairs.
    scenes: Vec<(&'static str, Option<usize>)>,
}

/// The starts of the Table III and pedestrian points, in table order.
pub(crate) const STARTS: [Start; 2] = [Start::Known, Start::Uniform];

impl Plan {
    /// The grid of `preset` with `seeds` seeds per point (default: 1 for
    /// quick, 5 for full).
    pub(crate) fn new(preset: Preset, seeds: Option<usize>) -> Plan {
        let (seeds, sizes) = match preset {
            Preset::Quick => (
                seeds.unwrap_or(1),
                Sizes {
                    events: 300,
                    small_shares: vec![0.3, 0.7],
                    table3_n: vec![10, 20],
                    table3_swaps: vec![0.5, 0.1],
                    large_n: vec![20],
                    large_shares: vec![0.3, 0.7],
                    sweep_n: 10,
                    swaps: vec![0.1, 0.5],
                    accuracies: vec![0.7, 0.9],
                    scenes: vec![("zara01", Some(20))],
                },
            ),
            Preset::Full => (
                seeds.unwrap_or(5),
                Sizes {
                    events: 1000,
                    small_shares: vec![0.2, 0.4, 0.6, 0.8],
                    table3_n: vec![20, 60, 100],
                    table3_swaps: vec![0.5, 0.1],
                    large_n: vec![20, 100],
                    large_shares: vec![0.2, 0.4, 0.6, 0.8],
                    sweep_n: 20,
                    swaps: vec![0.05, 0.1, 0.2, 0.3, 0.4, 0.5],
                    accuracies: vec![0.6, 0.7, 0.8, 0.9, 0.95],
                    scenes: vec![
                        ("eth", Some(20)),
                        ("hotel", Some(20)),
                        ("zara01", Some(20)),
                        ("zara02", Some(20)),
                        ("eth", Some(60)),
                        ("zara01", Some(60)),
                        ("zara02", Some(60)),
                        ("univ", Some(100)),
                    ],
                },
            ),
        };
        let crowd_from =
            |n: usize, share: f64, swap: f64, sensor: Sensor, start: Start| -> Vec<ScenarioSpec> {
                (0..seeds as u64)
                    .map(|seed| ScenarioSpec {
                        source: Source::Crowd {
                            n,
                            events: sizes.events,
                            share: Some(share),
                        },
                        swap,
                        sensor,
                        seed,
                        start,
                    })
                    .collect()
            };
        let crowd = |n: usize, share: f64, swap: f64, sensor: Sensor| {
            crowd_from(n, share, swap, sensor, Start::Known)
        };
        let mut points = Vec::new();
        for &share in &sizes.small_shares {
            points.push(Point {
                experiment: Experiment::SmallScale,
                n: 10,
                swap: 0.5,
                start: Start::Known,
                x: share,
                label: format!("mixing share {share}"),
                specs: crowd(10, share, 0.5, Sensor::Histogram),
                methods: small_methods(10),
            });
        }
        for start in STARTS {
            for &swap in &sizes.table3_swaps {
                for &n in &sizes.table3_n {
                    points.push(Point {
                        experiment: Experiment::Table3,
                        n,
                        swap,
                        start,
                        x: 0.5,
                        label: format!("n = {n}, swap {swap}"),
                        specs: crowd_from(n, 0.5, swap, Sensor::Histogram, start),
                        methods: table3_methods(n),
                    });
                }
            }
        }
        for &n in &sizes.large_n {
            for &share in &sizes.large_shares {
                points.push(Point {
                    experiment: Experiment::MixingLarge,
                    n,
                    swap: 0.5,
                    start: Start::Known,
                    x: share,
                    label: format!("n = {n}, mixing share {share}"),
                    specs: crowd(n, share, 0.5, Sensor::Histogram),
                    methods: plot_methods(n),
                });
            }
        }
        let n = sizes.sweep_n;
        for &swap in &sizes.swaps {
            points.push(Point {
                experiment: Experiment::Swap,
                n,
                swap,
                start: Start::Known,
                x: swap,
                label: format!("swap {swap}"),
                specs: crowd(n, 0.5, swap, Sensor::Histogram),
                methods: plot_methods(n),
            });
        }
        for &a in &sizes.accuracies {
            points.push(Point {
                experiment: Experiment::Likelihood,
                n,
                swap: 0.5,
                start: Start::Known,
                x: a,
                label: format!("sensor accuracy {a}"),
                specs: crowd(n, 0.5, 0.5, Sensor::Symmetric(a)),
                methods: plot_methods(n),
            });
        }
        for start in STARTS {
            for &(scene, cap) in &sizes.scenes {
                let n = cap.unwrap_or(100);
                points.push(Point {
                    experiment: Experiment::Pedestrians,
                    n,
                    swap: 0.5,
                    start,
                    x: 0.0,
                    label: format!("{scene}, n ≤ {n}"),
                    specs: (0..seeds)
                        .map(|window| ScenarioSpec {
                            source: Source::Pedestrians {
                                scene,
                                cap,
                                window,
                                windows: seeds,
                            },
                            swap: 0.5,
                            sensor: Sensor::Histogram,
                            seed: window as u64,
                            start,
                        })
                        .collect(),
                    methods: match start {
                        Start::Known => table3_methods(n),
                        Start::Uniform => distributed_methods(n),
                    },
                });
            }
        }
        Plan { seeds, points }
    }

    /// The crowd events per trace.
    pub(crate) fn events(&self) -> usize {
        self.points
            .iter()
            .flat_map(|p| &p.specs)
            .find_map(|s| match s.source {
                Source::Crowd { events, .. } => Some(events),
                _ => None,
            })
            .unwrap_or_default()
    }
}

/// The paper's Table III (TOSN 2013): (method, n) → (tracking error,
/// seconds). Its overcomplete budgets were "up to hundreds of bases".
pub(crate) fn paper_table3(method: &Method, n: usize) -> Option<(f64, f64)> {
    let row = match method {
        Method::Order(1) => [(20, 0.3167, 0.02), (60, 0.2804, 0.17), (100, 0.2836, 0.46)],
        Method::Order(3) => [
            (20, 0.2977, 29.79),
            (60, 0.2845, 119.45),
            (100, 0.2891, 912.21),
        ],
        Method::Overcomplete(_) => [
            (20, 0.1727, 29.69),
            (60, 0.1751, 292.90),
            (100, 0.1823, 1342.35),
        ],
        _ => return None,
    };
    row.iter()
        .find(|(m, _, _)| *m == n)
        .map(|&(_, e, s)| (e, s))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_cover_every_experiment() {
        for preset in [Preset::Quick, Preset::Full] {
            let plan = Plan::new(preset, None);
            for e in [
                Experiment::SmallScale,
                Experiment::Table3,
                Experiment::MixingLarge,
                Experiment::Swap,
                Experiment::Likelihood,
                Experiment::Pedestrians,
            ] {
                assert!(plan.points.iter().any(|p| p.experiment == e), "{e:?}");
            }
            assert!(plan.points.iter().all(|p| p.specs.len() == plan.seeds));
            assert!(plan
                .points
                .iter()
                .all(|p| p.specs.iter().all(|s| s.start == p.start)));
            // Table III under both starts, the same (swap, n) grid.
            let grid = |start: Start| -> Vec<(u64, usize)> {
                plan.points
                    .iter()
                    .filter(|p| p.experiment == Experiment::Table3 && p.start == start)
                    .map(|p| (p.swap.to_bits(), p.n))
                    .collect()
            };
            assert!(!grid(Start::Known).is_empty());
            assert_eq!(grid(Start::Known), grid(Start::Uniform));
        }
        assert_eq!(Plan::new(Preset::Full, None).seeds, 5);
        assert_eq!(Plan::new(Preset::Full, None).events(), 1000);
        assert_eq!(
            paper_table3(&Method::Overcomplete(500), 100),
            Some((0.1823, 1342.35))
        );
        assert_eq!(paper_table3(&Method::Exact, 20), None);
    }
}
