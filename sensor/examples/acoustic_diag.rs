//! Diagnostics of one acoustic tracking run: where the error distance
//! comes from. Per fragment of the estimated paths: area size, how many
//! groups heard it and how many of those are really in range of its
//! target, the centroid's distance to its target and to the nearest
//! target, and the area's mean tile distance to the target's path.
//!
//! `cargo run --release -p idmesh-sensor --example acoustic_diag -- sensors=400 seed=1`

use idmesh_sensor::acoustic::field::PathSpec;
use idmesh_sensor::acoustic::{run, AcousticConfig};
use idmesh_sensor::geometry::Vec2;

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

fn main() {
    let mut c = AcousticConfig::paper(400, 10, 1);
    c.field.samples = 1000;
    c.field.paths = PathSpec::Random {
        speed: (0.03, 0.03),
    };
    for arg in std::env::args().skip(1) {
        let (k, v) = arg.split_once('=').expect("key=value");
        let num = || v.parse::<f64>().expect("number");
        match k {
            "sensors" => c.field.sensors = num() as usize,
            "targets" => c.field.targets = num() as usize,
            "seed" => c.seed = num() as u64,
            "samples" => c.field.samples = num() as usize,
            "speed" => c.field.paths = PathSpec::Random { speed: (num(), num()) },
            "hear" => c.pipeline.hear_threshold = num(),
            "n_group" => c.pipeline.n_group = num() as usize,
            _ => panic!("unknown option {k}"),
        }
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
            if a.tiles.contains((p.y / s).round() as usize, (p.x / s).round() as usize) {
                contains += 1;
            }
            let te: f64 = a
                .tiles
                .points()
                .map(|(i, j)| dist_path(t, r.grid.point(i, j)))
                .sum::<f64>()
                / a.tiles.count() as f64;
            tile_err.push(te);
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
                    " {}:t{u}/{d:.0}/{}/s{bt}={bc:.2}",
                    f.slot,
                    a.tiles.count()
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
            println!("target {t} at ({:.0}, {:.0}), nearest other {others:.0} m", p0.x, p0.y);
        }
    }
    println!("fragments {total}, centroid nearer another target: {wrong}, area contains own target: {contains}");
    println!("area points        {}", quantiles(sizes));
    println!("groups intersected {}", quantiles(used));
    println!("groups hearing     {}", quantiles(heard));
    println!("share of hearing groups really in range {}", quantiles(true_share));
    println!("groups really in range {}", quantiles(truly));
    println!("centroid→own target {}", quantiles(own));
    println!("centroid→nearest target {}", quantiles(nearest));
    println!("per-area mean tile error {}", quantiles(tile_err));
    println!(
        "tile-error mass from fragments nearer another target: {:.0} %",
        100.0 * mass_bad / mass.max(1e-9)
    );
}
