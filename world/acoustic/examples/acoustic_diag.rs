//! Diagnostics of one acoustic tracking run: where the error distance
//! comes from. Per fragment of the estimated paths: area size, how many
//! groups heard it and how many of those are really in range of its
//! target, the centroid's distance to its target and to the nearest
//! target, and the area's mean tile distance to the target's path.
//!
//! `cargo run --release -p idmesh-acoustic --example acoustic_diag -- sensors=400 seed=1`

use idmesh_acoustic::PathSpec;
use idmesh_acoustic::{run, AcousticConfig};
use idmesh_sim::Vec2;

fn quantiles(mut v: Vec<f64>) -> String {
    if v.is_empty() {
        return "-".into();
    }
    v.sort_by(f64::total_cmp);
    let q = |p: f64| v[((v.len() - 1) as f64 * p).round() as usize];
    format!(
        "n {} mean {:.1} | p10 {:.1} p50 {:.1} p90 {:.1} max {:.1}",
        v.len(),
        v.iter().sum::<f64>() / v.len() as f64,
        q(0.1),
        q(0.5),
        q(0.9),
        q(1.0)
    )
}

/// Replays separation, clustering and selection for CTS `u` and prints,
/// per cluster, its size and its best candidate, and per true source the
/// best-matching segment of slot u.
fn slot_report(c: &AcousticConfig, u: usize) {
    use idmesh_acoustic::cluster_slot;
    use idmesh_acoustic::Field;
    use idmesh_acoustic::{estimate_noise_variance, separate_slot};
    use idmesh_acoustic::{link_layer, select_cts, SelectSettings};
    use idmesh_acoustic::{nearest_groups, Segmentation};
    let p = &c.pipeline;
    let field = Field::generate(&c.field, c.seed, 2).unwrap();
    let groups = nearest_groups(&field.sensors, p.n_group).unwrap();
    let seg = Segmentation::new(p.l_seg, p.l_step, c.field.samples).unwrap();
    let nv = estimate_noise_variance(&field.signals, &groups, &seg, p.noise_probes);
    let slots: Vec<_> = (u..u + p.n_slot)
        .map(|j| {
            separate_slot(&field.signals, &groups, &seg, j, &p.separation, nv, c.seed)
                .unwrap()
                .0
        })
        .collect();
    let k = c.field.targets;
    let cl = cluster_slot(
        &slots[0],
        p.clusters_per_target * k,
        p.linkage,
        p.same_source as f32,
    );
    let layers: Vec<_> = (0..p.n_slot - 1)
        .map(|i| link_layer(&slots[i], &slots[i + 1], p.l_step, p.link_candidates))
        .collect();
    let refs: Vec<_> = layers.iter().collect();
    let s0 = &slots[0];
    let dot = |a: usize, b: usize| -> f32 {
        s0.segment(a)
            .iter()
            .zip(s0.segment(b))
            .map(|(x, y)| x * y)
            .sum()
    };
    let chains = select_cts(
        &refs,
        &cl.labels,
        &cl.support,
        slots[p.n_slot - 1].len(),
        &SelectSettings {
            k,
            min_link: p.min_link as f32,
            min_support: p.min_support,
            aggregate_r2: p.aggregate_r2 as f32,
        },
        &|a, b| dot(a as usize, b as usize),
    );
    let from = seg.start(u);
    let src_corr = |i: usize| -> Vec<f32> {
        let x = s0.segment(i);
        field
            .sources
            .iter()
            .map(|src| {
                let y = &src[from..from + seg.l_seg];
                let my = y.iter().sum::<f64>() / y.len() as f64;
                let ny = y.iter().map(|v| (v - my) * (v - my)).sum::<f64>().sqrt();
                (x.iter()
                    .zip(y)
                    .map(|(a, b)| f64::from(*a) * (b - my))
                    .sum::<f64>()
                    / ny)
                    .abs() as f32
            })
            .collect()
    };
    let fmt = |v: &[f32]| {
        let mut idx: Vec<usize> = (0..v.len()).collect();
        idx.sort_by(|a, b| v[*b].total_cmp(&v[*a]));
        format!("s{}={:.2} s{}={:.2}", idx[0], v[idx[0]], idx[1], v[idx[1]])
    };
    println!("slot {u}: {} segments", s0.len());
    let win = |t: usize| -> Vec<f64> {
        let y = &field.sources[t][from..from + seg.l_seg];
        let my = y.iter().sum::<f64>() / y.len() as f64;
        let ny = y.iter().map(|v| (v - my) * (v - my)).sum::<f64>().sqrt();
        y.iter().map(|v| (v - my) / ny).collect()
    };
    for a in 0..k {
        for b in a + 1..k {
            let c: f64 = win(a).iter().zip(win(b)).map(|(x, y)| x * y).sum();
            if c.abs() > 0.3 {
                println!("sources {a} and {b} correlate {c:.2} in this slot");
            }
        }
    }
    let nclusters = cl.labels.iter().map(|&l| l as usize + 1).max().unwrap_or(0);
    for cidx in 0..nclusters {
        let members: Vec<usize> = (0..s0.len())
            .filter(|&i| cl.labels[i] as usize == cidx)
            .collect();
        let best = members
            .iter()
            .max_by_key(|&&i| cl.support[i])
            .copied()
            .unwrap();
        let chosen = chains.iter().any(|ch| ch.cluster as usize == cidx);
        println!(
            "cluster {cidx:2}: {:4} segs, top support {:3} ({}){}",
            members.len(),
            cl.support[best],
            fmt(&src_corr(best)),
            if chosen { "  SELECTED" } else { "" }
        );
    }
    if std::env::var("SELECT_DEBUG").is_ok() {
        for i in 0..s0.len() {
            println!("SEG {i} support {} {}", cl.support[i], fmt(&src_corr(i)));
        }
    }
    for ch in &chains {
        let s = ch.segments[0].unwrap() as usize;
        println!(
            "chain: cluster {} seg {s} support {} score {:.2} {}",
            ch.cluster,
            cl.support[s],
            ch.score,
            fmt(&src_corr(s))
        );
    }
    for t in 0..k {
        let (best, corr) = (0..s0.len())
            .map(|i| (i, src_corr(i)[t]))
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap();
        let n9 = (0..s0.len()).filter(|&i| src_corr(i)[t] >= 0.9).count();
        println!(
            "source {t}: best seg {best} |corr| {corr:.2} cluster {} support {}; {n9} segments ≥ 0.9",
            cl.labels[best], cl.support[best]
        );
    }
}

fn main() {
    let mut c = AcousticConfig::paper(400, 10, 1);
    c.field.samples = 1000;
    c.field.paths = PathSpec::Random {
        speed: (0.03, 0.03),
    };
    let mut slot = None;
    for arg in std::env::args().skip(1) {
        let (k, v) = arg.split_once('=').expect("key=value");
        let num = || v.parse::<f64>().expect("number");
        match k {
            "sensors" => c.field.sensors = num() as usize,
            "targets" => c.field.targets = num() as usize,
            "seed" => c.seed = num() as u64,
            "samples" => c.field.samples = num() as usize,
            "speed" => {
                c.field.paths = PathSpec::Random {
                    speed: (num(), num()),
                }
            }
            "hear" => c.pipeline.hear_threshold = num(),
            "silent" => c.pipeline.exclude_silent = num() != 0.0,
            "slack" => c.pipeline.silent_slack = num() as u32,
            "tolerance" => c.pipeline.vote_tolerance = num(),
            "n_group" => c.pipeline.n_group = num() as usize,
            "slot" => slot = Some(num() as usize),
            "default_paths" => c.field.paths = PathSpec::default(),
            _ => panic!("unknown option {k}"),
        }
    }
    if std::env::var("DIAG_SOURCES").is_ok() {
        use idmesh_acoustic::Field;
        let field = Field::generate(&c.field, c.seed, 2).unwrap();
        let l = c.pipeline.l_seg;
        let k = field.sources.len();
        let mut all = vec![];
        let mut start = 0;
        while start + l <= c.field.samples {
            let win = |t: usize| -> Vec<f64> {
                let y = &field.sources[t][start..start + l];
                let my = y.iter().sum::<f64>() / l as f64;
                let ny = y
                    .iter()
                    .map(|v| (v - my) * (v - my))
                    .sum::<f64>()
                    .sqrt()
                    .max(1e-300);
                y.iter().map(|v| (v - my) / ny).collect()
            };
            for a in 0..k {
                for b in a + 1..k {
                    let cab: f64 = win(a).iter().zip(win(b)).map(|(x, y)| x * y).sum();
                    all.push(cab.abs());
                }
            }
            start += c.pipeline.l_step;
        }
        let n = all.len() as f64;
        println!(
            "pairwise |corr| over {}-sample windows: >0.3 {:.1} %, >0.5 {:.1} %, >0.7 {:.1} %",
            l,
            100.0 * all.iter().filter(|&&x| x > 0.3).count() as f64 / n,
            100.0 * all.iter().filter(|&&x| x > 0.5).count() as f64 / n,
            100.0 * all.iter().filter(|&&x| x > 0.7).count() as f64 / n
        );
        return;
    }
    if let Some(u) = slot {
        slot_report(&c, u);
        return;
    }
    let r = run(&c, &mut |_, _| {}).expect("run");
    let m = &r.metrics;
    println!(
        "mean error {:.1} std {:.1} coverage {:.1}% aligned {:.1} slots {:.1}% points {} ({:.1} s)",
        m.mean_error,
        m.std_error,
        100.0 * m.coverage,
        m.aligned_error,
        100.0 * m.slot_share,
        m.points,
        r.stats.times.total
    );
    let range = c.field.range;
    let seg = r.segmentation;
    let at = |t: usize, slot: usize| -> Vec2 {
        let p = &r.field.paths[t].positions;
        p[(seg.middle(slot).round() as usize).min(p.len() - 1)]
    };
    let group_hears = |g: u32, p: Vec2| -> bool {
        r.groups[g as usize]
            .members
            .iter()
            .any(|&s| r.field.sensors[s as usize].distance(p) <= range)
    };
    let dist_path = |t: usize, q: Vec2| -> f64 {
        r.field.paths[t]
            .positions
            .iter()
            .map(|p| p.distance(q))
            .fold(f64::INFINITY, f64::min)
    };
    let (mut sizes, mut used, mut heard, mut true_share) = (vec![], vec![], vec![], vec![]);
    let (mut own, mut nearest, mut tile_err) = (vec![], vec![], vec![]);
    let mut truly = vec![];
    let (mut wrong, mut total) = (0, 0);
    let (mut mass_bad, mut mass) = (0.0, 0.0);
    let mut contains = 0;
    // Multiset ("concatenated") metric: every area's points count once per
    // fragment; against the paired target, and against the best target.
    let (mut ms_sum, mut ms_n, mut best_sum) = (0.0, 0usize, 0.0);
    for (l, path) in r.paths.iter().enumerate() {
        let Some(t) = m.target_of[l] else { continue };
        for f in &path.fragments {
            let a = &r.areas[f.area as usize];
            let p = at(t, f.slot);
            total += 1;
            sizes.push(a.tiles.count() as f64);
            used.push(a.groups as f64);
            heard.push(a.hearing.len() as f64);
            let ok = a.hearing.iter().filter(|(g, _)| group_hears(*g, p)).count();
            true_share.push(ok as f64 / a.hearing.len().max(1) as f64);
            truly.push(
                (0..r.groups.len() as u32)
                    .filter(|&g| group_hears(g, p))
                    .count() as f64,
            );
            own.push(a.centroid.distance(p));
            let (near_t, near_d) = (0..r.field.paths.len())
                .map(|u| (u, a.centroid.distance(at(u, f.slot))))
                .min_by(|x, y| x.1.total_cmp(&y.1))
                .unwrap();
            nearest.push(near_d);
            if near_t != t {
                wrong += 1;
            }
            let s = r.grid.spacing;
            if a.tiles
                .contains((p.y / s).round() as usize, (p.x / s).round() as usize)
            {
                contains += 1;
            }
            let te: f64 = a
                .tiles
                .points()
                .map(|(i, j)| dist_path(t, r.grid.point(i, j)))
                .sum::<f64>()
                / a.tiles.count() as f64;
            tile_err.push(te);
            ms_sum += te * a.tiles.count() as f64;
            ms_n += a.tiles.count();
            best_sum += (0..r.field.paths.len())
                .map(|u| {
                    a.tiles
                        .points()
                        .map(|(i, j)| dist_path(u, r.grid.point(i, j)))
                        .sum::<f64>()
                })
                .fold(f64::INFINITY, f64::min);
            mass += te * a.tiles.count() as f64;
            if near_t != t {
                mass_bad += te * a.tiles.count() as f64;
            }
        }
    }
    if std::env::var("DIAG_PATHS").is_ok() {
        for (l, path) in r.paths.iter().enumerate() {
            let mut line = format!("path {l} → {:?}:", m.target_of[l]);
            for f in &path.fragments {
                let a = &r.areas[f.area as usize];
                let (u, d) = (0..r.field.paths.len())
                    .map(|u| (u, a.centroid.distance(at(u, f.slot))))
                    .min_by(|x, y| x.1.total_cmp(&y.1))
                    .unwrap();
                let sc = &r.area_source_corr[f.area as usize];
                let (bt, bc) = sc
                    .iter()
                    .enumerate()
                    .max_by(|x, y| x.1.total_cmp(y.1))
                    .map(|(i, c)| (i, *c))
                    .unwrap();
                line += &format!(
                    " {}:t{u}/{d:.0}/{}/s{bt}={bc:.2}/{}of{}/v{}",
                    f.slot,
                    a.tiles.count(),
                    a.groups,
                    a.hearing.len(),
                    a.silent_cover
                );
            }
            println!("{line}");
        }
        for t in 0..r.field.paths.len() {
            let p0 = at(t, 0);
            let others = (0..r.field.paths.len())
                .filter(|&u| u != t)
                .map(|u| at(u, 0).distance(p0))
                .fold(f64::INFINITY, f64::min);
            println!(
                "target {t} at ({:.0}, {:.0}), nearest other {others:.0} m",
                p0.x, p0.y
            );
        }
    }
    // Hearing rate by the distance of a group's nearest member to the
    // source, for fragments located from a clean segment (|corr| ≥ 0.9
    // with their target's source).
    {
        let mut bins = [(0usize, 0usize); 8];
        for (l, path) in r.paths.iter().enumerate() {
            let Some(t) = m.target_of[l] else { continue };
            for f in &path.fragments {
                let a = &r.areas[f.area as usize];
                if r.area_source_corr[f.area as usize][t] < 0.9 {
                    continue;
                }
                let p = at(t, f.slot);
                for (g, group) in r.groups.iter().enumerate() {
                    let d = group
                        .members
                        .iter()
                        .map(|&s| r.field.sensors[s as usize].distance(p))
                        .fold(f64::INFINITY, f64::min);
                    let b = (d / 50.0) as usize;
                    if b >= bins.len() {
                        continue;
                    }
                    bins[b].1 += 1;
                    if a.hearing.iter().any(|h| h.0 == g as u32) {
                        bins[b].0 += 1;
                    }
                }
            }
        }
        let line: Vec<String> = bins
            .iter()
            .enumerate()
            .map(|(i, (h, n))| {
                format!(
                    "{}-{} m: {:.0} %",
                    i * 50,
                    i * 50 + 50,
                    100.0 * *h as f64 / (*n).max(1) as f64
                )
            })
            .collect();
        println!(
            "hearing rate by nearest member distance: {}",
            line.join(", ")
        );
    }
    println!("fragments {total}, centroid nearer another target: {wrong}, area contains own target: {contains}");
    println!(
        "multiset mean error {:.1} m (paired target), {:.1} m (each area vs its best target)",
        ms_sum / ms_n as f64,
        best_sum / ms_n as f64
    );
    println!("area points        {}", quantiles(sizes));
    println!("groups intersected {}", quantiles(used));
    println!("groups hearing     {}", quantiles(heard));
    println!(
        "share of hearing groups really in range {}",
        quantiles(true_share)
    );
    println!("groups really in range {}", quantiles(truly));
    println!("centroid→own target {}", quantiles(own));
    println!("centroid→nearest target {}", quantiles(nearest));
    println!("per-area mean tile error {}", quantiles(tile_err));
    println!(
        "tile-error mass from fragments nearer another target: {:.0} %",
        100.0 * mass_bad / mass.max(1e-9)
    );
}
