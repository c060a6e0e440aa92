// Temporary diagnostics (not to be kept).
use idmesh_sensor::acoustic::field::Field;
use idmesh_sensor::acoustic::pipeline::cluster::cluster_slot;
use idmesh_sensor::acoustic::pipeline::intersect::{hearing_groups, intersect, GroupRanges};
use idmesh_sensor::acoustic::pipeline::prepare::{nearest_groups, Segmentation};
use idmesh_sensor::acoustic::pipeline::select::{link_layer, select_cts, LinkLayer};
use idmesh_sensor::acoustic::pipeline::separate::*;
use idmesh_sensor::acoustic::pipeline::tiles::TileGrid;
use idmesh_sensor::acoustic::AcousticConfig;

fn corr(a: &[f64], b: &[f32]) -> f64 {
    let n = a.len() as f64;
    let ma = a.iter().sum::<f64>() / n;
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        let (x, y) = (x - ma, *y as f64);
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    }
    sab / (saa * sbb).sqrt()
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let sensors: usize = args.get(1).map(|s| s.parse().unwrap()).unwrap_or(400);
    let mut c = AcousticConfig::default();
    c.field.sensors = sensors;
    c.field.samples = 600;
    if let Some(k) = args.get(2) { c.field.targets = k.parse().unwrap(); }
    let field = Field::generate(&c.field, 0, 2).unwrap();
    let groups = nearest_groups(&field.sensors, 10).unwrap();
    let seg = Segmentation::new(100, 10, c.field.samples).unwrap();
    let var = estimate_noise_variance(&field.signals, &groups, &seg, 1000);
    let mut settings = SeparationSettings::default();
    if let Some(m) = args.get(3) { settings.ica.max_iter = m.parse().unwrap(); }
    let t = std::time::Instant::now();
    let mut iters = vec![0usize; 0];
    let slots: Vec<_> = (0..seg.slots()).map(|j| separate_slot(&field.signals, &groups, &seg, j, &settings, var, 1).unwrap()).collect();
    println!("separation {:.2}s", t.elapsed().as_secs_f64());
    let _ = &mut iters;
    let rep = slots.iter().fold(SeparationReport::default(), |mut a, (_, r)| { a.add(r); a });
    println!("{rep:?}");
    // Component count distribution.
    let mut hist = [0usize; 12];
    for (s, _) in &slots[..3] {
        let mut per = vec![0usize; groups.len()];
        for &g in &s.group { per[g as usize] += 1; }
        for p in per { hist[p.min(11)] += 1; }
    }
    println!("components per group (3 slots): {hist:?}");
    let k = c.field.targets;
    let j = 10;
    let (segs, _) = &slots[j];
    let start = seg.start(j);
    let mid = start + 50;
    for (t, src) in field.sources.iter().enumerate() {
        let truth = &src[start..start + 100];
        let cs: Vec<f64> = (0..segs.len()).map(|i| corr(truth, segs.segment(i)).abs()).collect();
        let best = cs.iter().cloned().fold(0.0, f64::max);
        let n90 = cs.iter().filter(|&&x| x > 0.9).count();
        let hearing_groups_true = groups.iter().filter(|g| g.members.iter().any(|&m| field.sensors[m as usize].distance(field.paths[t].positions[mid]) <= 250.0)).count();
        println!("source {t}: best |corr| {best:.3}, segs>0.9: {n90}, groups in range {hearing_groups_true}");
    }
    let labels = cluster_slot(segs, 2 * k, idmesh_sensor::acoustic::pipeline::cluster::Linkage::Average);
    // cluster composition: for each cluster: size, best source and mean corr
    for cl in 0..(2 * k) as u32 {
        let members: Vec<usize> = (0..segs.len()).filter(|&i| labels[i] == cl).collect();
        let mut cnt = vec![0usize; k];
        for &i in &members {
            let (bt, bc) = (0..k).map(|t| (t, corr(&field.sources[t][start..start + 100], segs.segment(i)).abs())).fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
            if bc > 0.8 { cnt[bt] += 1; }
        }
        println!("cluster {cl}: {} members, by source (>0.8): {cnt:?}", members.len());
    }
    let layers: Vec<LinkLayer> = (j..j + 4).map(|x| link_layer(&slots[x].0, &slots[x + 1].0, 10, 8)).collect();
    let refs: Vec<&LinkLayer> = layers.iter().collect();
    let chains = select_cts(&refs, &labels, slots[j + 4].0.len(), k);
    let grid = TileGrid::new(1600.0, 5.0);
    let ranges = GroupRanges::new(grid, &groups, &field.sensors, 250.0);
    for ch in &chains {
        let s = ch.segments[0].unwrap() as usize;
        let (bt, bc) = (0..k).map(|t| (t, corr(&field.sources[t][start..start + 100], segs.segment(s)).abs())).fold((0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
        let hearing = hearing_groups(segs, s, 0.9);
        let area = intersect(&ranges, &hearing).unwrap();
        let truth = field.paths[bt].positions[mid];
        let inside = area.tiles.points().any(|(r, cc)| grid.point(r, cc).distance(truth) < 5.0);
        println!("chain score {:.2} cluster {} -> source {bt} corr {bc:.3}; hearing {} used {} tiles {} centroid err {:.1} truth inside {inside}",
            ch.score, ch.cluster, hearing.len(), area.groups, area.tiles.count(), area.centroid.distance(truth));
    }
}
