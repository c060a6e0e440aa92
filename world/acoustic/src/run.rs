//! The whole pipeline, from a field to estimated paths, metrics and trace
//! events: [`run`].
//!
//! Stages and how they are spread over threads (the machine has 2 cores):
//! the field's recordings (parallel over sensors); separation and
//! clustering (parallel over slots: each slot is independent); link
//! layers between successive slots (parallel); selection per CTS
//! (cheap, sequential); intersection for every distinct selected segment
//! (parallel); voting, linking and metrics (sequential, cheap). Every
//! random choice is seeded from the config's seed and the task's index, so
//! the result does not depend on the number of threads.

use super::config::{AcousticConfig, PipelineConfig};
use super::error::AcousticError;
use super::field::Field;
use super::metrics::tracking::{evaluate, TrackingMetrics};
use super::parallel::par_map_progress;
use super::pipeline::cluster::{cluster_slot, SlotClusters};
use super::pipeline::intersect::{hearing_groups, intersect, Area, GroupRanges};
use super::pipeline::prepare::{nearest_groups, Segmentation, SensorGroup};
use super::pipeline::select::{link_layer, select_cts, Chain, LinkLayer, SelectSettings};
use super::pipeline::separate::{
    estimate_noise_variance, separate_slot, SeparationReport, SlotSegments,
};
use super::pipeline::tiles::TileGrid;
use super::pipeline::vote_link::{link, vote, CtsEstimate, Fragment, VoteSettings};
use super::resolution;
use super::trace::path_events;
use idmesh_sim::TimedEvent;
use idmesh_sim::Vec2;
use rustc_hash::FxHashMap;
use std::time::Instant;

/// One fragment of an estimated path, as reported.
#[derive(Debug, Clone, PartialEq)]
pub struct EstimatedFragment {
    pub slot: usize,
    /// Middle of the slot, in samples.
    pub time: f64,
    /// Centroid of the intersection area.
    pub position: Vec2,
    /// Index into [`AcousticResult::areas`].
    pub area: u32,
}

/// One estimated target path (track).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct EstimatedPath {
    pub fragments: Vec<EstimatedFragment>,
}

/// Seconds spent per stage.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimes {
    pub field: f64,
    pub separate_cluster: f64,
    pub link_select: f64,
    pub intersect: f64,
    pub vote_link: f64,
    pub metrics: f64,
    pub total: f64,
}

/// What happened along the way.
#[derive(Debug, Clone, PartialEq)]
pub struct RunStats {
    /// Sensor groups after removing duplicates.
    pub groups: usize,
    /// Time slots v.
    pub slots: usize,
    /// Estimated sensor noise variance (the truth is `noise_std²`).
    pub noise_variance: f64,
    pub separation: SeparationReport,
    /// Distinct intersection areas computed.
    pub areas: usize,
    /// Fragments kept by the vote, and dropped by linking.
    pub kept: usize,
    pub dropped: usize,
    pub times: StageTimes,
}

/// The predicted resolutions (Theorems 5.3 and 5.5) for this field, with
/// the fragment length l = mean true speed × l_seg.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ResolutionSummary {
    /// r of equation (8).
    pub group_radius: f64,
    /// l, metres.
    pub fragment_length: f64,
    pub finest: Option<f64>,
    pub average: Option<f64>,
}

/// Everything a run produces.
#[derive(Debug, Clone)]
pub struct AcousticResult {
    pub config: AcousticConfig,
    pub field: Field,
    pub groups: Vec<SensorGroup>,
    pub segmentation: Segmentation,
    /// Every intersection area referred to by a path.
    pub areas: Vec<Area>,
    /// Ground truth, for diagnostics: per area, |corr| of the segment it
    /// was located from with each target's source over the same slot.
    pub area_source_corr: Vec<Vec<f32>>,
    pub grid: TileGrid,
    /// K estimated paths (some may be empty).
    pub paths: Vec<EstimatedPath>,
    pub metrics: TrackingMetrics,
    pub resolution: ResolutionSummary,
    pub stats: RunStats,
    /// `mix` and `move` events, in time order (trace times in seconds:
    /// samples / `output.sample_rate`).
    pub events: Vec<TimedEvent>,
}

/// |corr| of two equally long slices.
fn overlap_correlation(x: &[f32], y: &[f32]) -> f64 {
    let n = x.len().min(y.len()) as f64;
    if n < 2.0 {
        return 0.0;
    }
    let mx = x.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let my = y.iter().map(|&v| f64::from(v)).sum::<f64>() / n;
    let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
    for (&a, &b) in x.iter().zip(y) {
        let (a, b) = (f64::from(a) - mx, f64::from(b) - my);
        sxy += a * b;
        sxx += a * a;
        syy += b * b;
    }
    if sxx > 0.0 && syy > 0.0 {
        (sxy / (sxx * syy).sqrt()).abs()
    } else {
        0.0
    }
}

/// Runs the whole pipeline on the field `config` describes. `progress` is
/// called on the calling thread with (done, total) — never decreasing,
/// ending at (total, total) — for a progress bar.
pub fn run(
    config: &AcousticConfig,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<AcousticResult, AcousticError> {
    let mut results = run_variants(config, std::slice::from_ref(&config.pipeline), progress)?;
    Ok(results.pop().expect("one variant, one result"))
}

/// Whether two pipeline configs agree on everything up to and including
/// the selection step, so that one separation can serve both.
fn same_front(a: &PipelineConfig, b: &PipelineConfig) -> bool {
    a.n_group == b.n_group
        && a.l_seg == b.l_seg
        && a.l_step == b.l_step
        && a.n_slot == b.n_slot
        && a.clusters_per_target == b.clusters_per_target
        && a.linkage == b.linkage
        && a.separation == b.separation
        && a.link_candidates == b.link_candidates
        && a.min_link == b.min_link
        && a.min_support == b.min_support
        && a.aggregate_r2 == b.aggregate_r2
        && a.same_source == b.same_source
        && a.noise_probes == b.noise_probes
}

/// Runs the pipeline once up to the selection step (field, separation,
/// clustering, selection: nearly all the time) and finishes it —
/// intersection, voting, linking, metrics — once per entry of `variants`,
/// which may differ from `config.pipeline` only in those later steps
/// (`hear_threshold`, `exclude_silent`, `silent_slack`, `tile`,
/// `vote_tolerance`, `link_gate`, `max_speed`). One result per variant, in
/// order; each result's `config` has its variant's pipeline.
pub fn run_variants(
    config: &AcousticConfig,
    variants: &[PipelineConfig],
    progress: &mut dyn FnMut(u64, u64),
) -> Result<Vec<AcousticResult>, AcousticError> {
    check_variants(config, variants)?;
    let start = Instant::now();
    let p = &config.pipeline;
    let seg = Segmentation::new(p.l_seg, p.l_step, config.field.samples)?;
    let v = seg.slots();
    // Progress units: 1 for the field, v for separation, v for links and
    // selection, v per variant for intersection, 1 for the rest.
    let total = (2 + variants.len() as u64) * v as u64 + 2;
    let mut progress = Progress {
        done: 0,
        total,
        callback: progress,
    };
    (progress.callback)(0, total);

    let t = Instant::now();
    let field = Field::generate(&config.field, config.seed, config.threads)?;
    let groups = nearest_groups(&field.sensors, p.n_group)?;
    let noise_variance = estimate_noise_variance(&field.signals, &groups, &seg, p.noise_probes);
    let mut times = StageTimes {
        field: t.elapsed().as_secs_f64(),
        ..StageTimes::default()
    };
    progress.report(1);

    // (2) separation and (3) clustering, per slot.
    let t = Instant::now();
    let (slots, labels, separation) =
        separate_and_cluster(config, &field, &groups, seg, noise_variance, &mut progress)?;
    times.separate_cluster = t.elapsed().as_secs_f64();
    progress.report(1 + v as u64);

    // (4) selection: link layers, then K chains per CTS.
    let t = Instant::now();
    let chains = select_chains(config, seg, &slots, &labels, &mut progress);
    times.link_select = t.elapsed().as_secs_f64();
    progress.report(1 + 2 * v as u64);

    let front_secs = start.elapsed().as_secs_f64();
    let mut results = Vec::with_capacity(variants.len());
    for (i, variant) in variants.iter().enumerate() {
        let base = 1 + (2 + i as u64) * v as u64;
        let config = AcousticConfig {
            pipeline: variant.clone(),
            ..config.clone()
        };
        let mut result = finish(
            &config,
            Front {
                field: &field,
                groups: &groups,
                seg,
                noise_variance,
                slots: &slots,
                chains: &chains,
                separation,
                times,
            },
            &mut |d| progress.report(base + d),
        );
        result.stats.times.total += front_secs;
        results.push(result);
    }
    progress.report(total);
    Ok(results)
}

/// Refuses variants that differ from the run before the intersection
/// step, or are not valid configs themselves.
fn check_variants(
    config: &AcousticConfig,
    variants: &[PipelineConfig],
) -> Result<(), AcousticError> {
    config.validate()?;
    for variant in variants {
        if !same_front(&config.pipeline, variant) {
            return Err(AcousticError::Config(
                "a variant differs from the run before the intersection step".into(),
            ));
        }
        AcousticConfig {
            pipeline: variant.clone(),
            ..config.clone()
        }
        .validate()?;
    }
    Ok(())
}

/// Reports (done, total) to a caller's callback: never decreasing, never
/// past the total.
struct Progress<'a> {
    done: u64,
    total: u64,
    callback: &'a mut dyn FnMut(u64, u64),
}

impl Progress<'_> {
    fn report(&mut self, d: u64) {
        if d > self.done {
            self.done = d.min(self.total);
            (self.callback)(self.done, self.total);
        }
    }
}

/// Steps (2) and (3): every slot's segments separated and clustered, in
/// parallel over slots; with what separation reported over them all.
fn separate_and_cluster(
    config: &AcousticConfig,
    field: &Field,
    groups: &[SensorGroup],
    seg: Segmentation,
    noise_variance: f64,
    progress: &mut Progress<'_>,
) -> Result<(Vec<SlotSegments>, Vec<SlotClusters>, SeparationReport), AcousticError> {
    let p = &config.pipeline;
    let v = seg.slots();
    let slot_ids: Vec<usize> = (0..v).collect();
    let clusters = p.clusters_per_target * config.field.targets;
    let separated = par_map_progress(
        &slot_ids,
        config.threads,
        |&j| {
            separate_slot(
                &field.signals,
                groups,
                &seg,
                j,
                &p.separation,
                noise_variance,
                config.seed,
            )
            .map(|(segs, rep)| {
                let labels = cluster_slot(&segs, clusters, p.linkage, p.same_source as f32);
                (segs, labels, rep)
            })
        },
        &mut |d| progress.report(1 + d as u64),
    );
    let mut slots: Vec<SlotSegments> = Vec::with_capacity(v);
    let mut labels: Vec<SlotClusters> = Vec::with_capacity(v);
    let mut separation = SeparationReport::default();
    for r in separated {
        let (s, l, rep) = r?;
        separation.add(&rep);
        slots.push(s);
        labels.push(l);
    }
    Ok((slots, labels, separation))
}

/// Step (4): the link layers between successive slots (in parallel),
/// then K chains per CTS.
fn select_chains(
    config: &AcousticConfig,
    seg: Segmentation,
    slots: &[SlotSegments],
    labels: &[SlotClusters],
    progress: &mut Progress<'_>,
) -> Vec<Vec<Chain>> {
    let p = &config.pipeline;
    let v = seg.slots();
    let pairs: Vec<usize> = (0..v.saturating_sub(1)).collect();
    let layers: Vec<LinkLayer> = par_map_progress(
        &pairs,
        config.threads,
        |&j| link_layer(&slots[j], &slots[j + 1], seg.l_step, p.link_candidates),
        &mut |d| progress.report(1 + v as u64 + d as u64),
    );
    let n_cts = v + 1 - p.n_slot.min(v);
    let select = SelectSettings {
        k: config.field.targets,
        min_link: p.min_link as f32,
        min_support: p.min_support,
        aggregate_r2: p.aggregate_r2 as f32,
    };
    (0..n_cts)
        .map(|u| {
            let span = p.n_slot.min(v);
            let refs: Vec<&LinkLayer> = layers[u..u + span - 1].iter().collect();
            let slot = &slots[u];
            let corr = |a: u32, b: u32| -> f32 {
                slot.segment(a as usize)
                    .iter()
                    .zip(slot.segment(b as usize))
                    .map(|(x, y)| x * y)
                    .sum()
            };
            select_cts(
                &refs,
                &labels[u].labels,
                &labels[u].support,
                slots[u + span - 1].len(),
                &select,
                &corr,
            )
        })
        .collect()
}

/// What the front end (up to selection) hands to [`finish`].
struct Front<'a> {
    field: &'a Field,
    groups: &'a [SensorGroup],
    seg: Segmentation,
    noise_variance: f64,
    slots: &'a [SlotSegments],
    chains: &'a [Vec<Chain>],
    separation: SeparationReport,
    times: StageTimes,
}

/// Intersection, voting, linking, metrics and events of one variant.
/// `progress(d)` reports d of v slots' worth of intersections done.
fn finish(
    config: &AcousticConfig,
    front: Front<'_>,
    progress: &mut dyn FnMut(u64),
) -> AcousticResult {
    let start = Instant::now();
    let p = &config.pipeline;
    let seg = front.seg;
    let v = seg.slots();
    let mut times = front.times;
    // (5) intersection, once per distinct (slot, segment).
    let t = Instant::now();
    let grid = TileGrid::new(config.field.size, p.tile);
    let Located {
        areas,
        area_source_corr,
        area_of,
    } = locate(config, &front, grid, progress);
    times.intersect = t.elapsed().as_secs_f64();
    progress(v as u64);

    // (6) voting and linking.
    let t = Instant::now();
    let (linked, kept, dropped) = vote_and_link(config, &front, &areas, &grid, &area_of);
    times.vote_link = t.elapsed().as_secs_f64();

    let t = Instant::now();
    let metrics = evaluate(&linked, &areas, &grid, &front.field.paths, &seg);
    let paths = estimated_paths(&linked, &areas, &seg);
    let events = path_events(&paths, &seg, &config.output);
    let resolution = resolution_summary(config, front.field);
    times.metrics = t.elapsed().as_secs_f64();
    times.total = start.elapsed().as_secs_f64();
    AcousticResult {
        config: config.clone(),
        stats: RunStats {
            groups: front.groups.len(),
            slots: v,
            noise_variance: front.noise_variance,
            separation: front.separation,
            areas: areas.len(),
            kept,
            dropped,
            times,
        },
        field: front.field.clone(),
        groups: front.groups.to_vec(),
        segmentation: seg,
        areas,
        area_source_corr,
        grid,
        paths,
        metrics,
        resolution,
        events,
    }
}

/// The intersection areas the selected chains refer to.
struct Located {
    areas: Vec<Area>,
    /// Per area, |corr| of its segment with each target's source.
    area_source_corr: Vec<Vec<f32>>,
    /// The area of each (slot, segment) that has one.
    area_of: FxHashMap<(u32, u32), u32>,
}

/// Step (5): intersects the hearing groups of every distinct (slot,
/// segment) the chains selected, once each. `progress(d)` reports d of v
/// slots' worth done.
fn locate(
    config: &AcousticConfig,
    front: &Front<'_>,
    grid: TileGrid,
    progress: &mut dyn FnMut(u64),
) -> Located {
    let p = &config.pipeline;
    let (field, slots, seg) = (front.field, front.slots, front.seg);
    let v = seg.slots();
    let ranges = GroupRanges::new(grid, front.groups, &field.sensors, config.field.range);
    let mut wanted: Vec<(u32, u32)> = front
        .chains
        .iter()
        .enumerate()
        .flat_map(|(u, cs)| {
            cs.iter().flat_map(move |c| {
                c.segments
                    .iter()
                    .enumerate()
                    .filter_map(move |(i, s)| s.map(|s| ((u + i) as u32, s)))
            })
        })
        .collect();
    wanted.sort_unstable();
    wanted.dedup();
    let threshold = p.hear_threshold as f32;
    let area_total = wanted.len().max(1) as u64;
    let computed: Vec<Option<Area>> = par_map_progress(
        &wanted,
        config.threads,
        |&(j, s)| {
            let hearing = hearing_groups(&slots[j as usize], s as usize, threshold);
            intersect(
                &ranges,
                &hearing,
                p.exclude_silent.then_some(p.silent_slack),
            )
        },
        &mut |d| progress(d as u64 * v as u64 / area_total),
    );
    let mut located = Located {
        areas: Vec::new(),
        area_source_corr: Vec::new(),
        area_of: FxHashMap::default(),
    };
    for (key, area) in wanted.iter().zip(computed) {
        if let Some(a) = area {
            located.area_of.insert(*key, located.areas.len() as u32);
            located.areas.push(a);
            let (j, s) = (key.0 as usize, key.1 as usize);
            let x: Vec<f32> = slots[j].segment(s).to_vec();
            let from = seg.start(j);
            located.area_source_corr.push(
                field
                    .sources
                    .iter()
                    .map(|src| {
                        let y: Vec<f32> = src[from..from + seg.l_seg]
                            .iter()
                            .map(|&v| v as f32)
                            .collect();
                        overlap_correlation(&x, &y) as f32
                    })
                    .collect(),
            );
        }
    }
    located
}

/// Step (6): votes on the chains' areas per CTS and links the fragments
/// kept into K paths; returns the paths, the fragments kept by the vote
/// and those dropped by linking.
fn vote_and_link(
    config: &AcousticConfig,
    front: &Front<'_>,
    areas: &[Area],
    grid: &TileGrid,
    area_of: &FxHashMap<(u32, u32), u32>,
) -> (Vec<Vec<Fragment>>, usize, usize) {
    let p = &config.pipeline;
    let (slots, seg) = (front.slots, front.seg);
    let v = seg.slots();
    let estimates: Vec<CtsEstimate> = front
        .chains
        .iter()
        .enumerate()
        .map(|(u, cs)| CtsEstimate {
            chains: cs
                .iter()
                .map(|c| {
                    c.segments
                        .iter()
                        .enumerate()
                        .map(|(i, s)| {
                            s.and_then(|s| area_of.get(&((u + i) as u32, s)).map(|&a| (a, s)))
                        })
                        .collect()
                })
                .collect(),
        })
        .collect();
    let settings = VoteSettings {
        n_slot: p.n_slot.min(v),
        tolerance: p.vote_tolerance,
        link_gate: p.link_gate,
        max_speed: p.max_speed,
        l_step: p.l_step,
        min_link: p.min_link,
    };
    let same = p.same_source as f32;
    let same_source = |j: usize, a: u32, b: u32| -> bool {
        let s = &slots[j];
        let c: f32 = s
            .segment(a as usize)
            .iter()
            .zip(s.segment(b as usize))
            .map(|(x, y)| x * y)
            .sum();
        c.abs() >= same
    };
    let pseg = vote(&estimates, v, areas, grid, &settings, &same_source);
    let kept = pseg.iter().map(Vec::len).sum();
    let continuity = |ja: usize, a: u32, jb: usize, b: u32| -> Option<f64> {
        let shift = (jb - ja) * seg.l_step;
        // At least a quarter segment in common, or the correlation is noise.
        if shift * 4 > seg.l_seg * 3 {
            return None;
        }
        let x = &slots[ja].segment(a as usize)[shift..];
        let y = &slots[jb].segment(b as usize)[..seg.l_seg - shift];
        Some(overlap_correlation(x, y))
    };
    let (linked, dropped) = link(
        &pseg,
        config.field.targets,
        areas,
        grid,
        &settings,
        &continuity,
    );
    (linked, kept, dropped)
}

/// The linked fragments as reported: each at the middle of its slot, at
/// its area's centroid.
fn estimated_paths(
    linked: &[Vec<Fragment>],
    areas: &[Area],
    seg: &Segmentation,
) -> Vec<EstimatedPath> {
    linked
        .iter()
        .map(|fr| EstimatedPath {
            fragments: fr
                .iter()
                .map(|f: &Fragment| EstimatedFragment {
                    slot: f.slot,
                    time: seg.middle(f.slot),
                    position: areas[f.area as usize].centroid,
                    area: f.area,
                })
                .collect(),
        })
        .collect()
}

/// The resolutions Theorems 5.3 and 5.5 predict for this field.
fn resolution_summary(config: &AcousticConfig, field: &Field) -> ResolutionSummary {
    let p = &config.pipeline;
    let k = config.field.targets;
    let mean_speed = field.paths.iter().map(|p| p.mean_speed()).sum::<f64>() / k as f64;
    let r = resolution::group_radius(
        p.n_group,
        config.field.size,
        config.field.size,
        config.field.sensors,
    );
    let l = mean_speed * p.l_seg as f64;
    ResolutionSummary {
        group_radius: r,
        fragment_length: l,
        finest: resolution::finest_resolution(config.field.range, r, l),
        average: resolution::average_resolution(config.field.range, r, l),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> AcousticConfig {
        let mut c = AcousticConfig::paper(250, 3, 5);
        c.field.size = 800.0;
        c.field.target_area = 400.0;
        c.field.samples = 400;
        c
    }

    #[test]
    fn a_small_field_is_tracked_and_variants_match_single_runs() {
        let config = small();
        let paper = config.pipeline.clone().paper_intersection();
        let mut last = (0, 0);
        let both = run_variants(
            &config,
            &[config.pipeline.clone(), paper.clone()],
            &mut |d, t| {
                assert!(d >= last.0 && d <= t);
                last = (d, t);
            },
        )
        .unwrap();
        assert_eq!(last.0, last.1);
        assert_eq!(both.len(), 2);
        let single = run(&config, &mut |_, _| {}).unwrap();
        let single_paper = run(
            &AcousticConfig {
                pipeline: paper.clone(),
                ..config.clone()
            },
            &mut |_, _| {},
        )
        .unwrap();
        for (a, b) in [(&both[0], &single), (&both[1], &single_paper)] {
            assert_eq!(a.config, b.config);
            assert_eq!(a.paths, b.paths);
            assert_eq!(a.metrics, b.metrics);
        }
        // Every target is tracked somewhere, to within tens of metres, and
        // excluding the silent groups' ranges shrinks the areas.
        let m = &single.metrics;
        assert!(m.slot_share > 0.15, "{m:?}");
        assert!(m.mean_error < 40.0, "{m:?}");
        let mean_area = |r: &AcousticResult| {
            r.areas.iter().map(|a| a.tiles.count()).sum::<usize>() as f64 / r.areas.len() as f64
        };
        assert!(mean_area(&single) < mean_area(&single_paper));
        // A variant that would separate differently is refused.
        let mut other = config.pipeline.clone();
        other.l_step = 20;
        assert!(run_variants(&config, &[other], &mut |_, _| {}).is_err());
    }
}
