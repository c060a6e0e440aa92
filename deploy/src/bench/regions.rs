//! How evenly the leaders share a stream's items, by region rule: what
//! each leader of a deployment at the default settings is sent
//! (`idmesh_placement::items_sent`, the items the router sends under the
//! regional rule) against an even share of what one leader alone applies,
//! at 2, 4 and 8 leaders, on the bench's crowd, on a random-waypoint
//! crowd of as many targets (denser in the middle of its field), on one of
//! five times as many and on the real pedestrian scenes of
//! shared/data/pedestrians (people crowding paths and doors, entering and
//! leaving), under fitted regions (the default) — with the share taken
//! apart into its two causes — and under leaders at fixed places on a
//! grid over the field.
//! Computed from the streams, not timed: the throughput tables above
//! show the same counts read off the leaders of the bench's crowd.

use super::BenchOptions;
use crate::runtime::launch::{field_corners, simulate_into, write_simulation};
use anyhow::{Context, Result};
use idmesh_placement::{busiest_share, grid_places, items_sent, share_causes, RegionRule};
use idmesh_protocol::trace::Line;
use idmesh_sim::data_dir;
use idmesh_sim::Scenario;
use std::fmt::Write as _;
use std::path::Path;

/// The leader counts of the table.
const LEADERS: [usize; 3] = [2, 4, 8];

/// The table, over the bench's crowd `trace` and waypoint crowds of as
/// many and five times as many targets, simulated (and kept) beside it.
pub fn report(options: &BenchOptions, trace: &Path) -> Result<String> {
    let waypoint = |targets: usize, red: usize| -> Result<std::path::PathBuf> {
        let path = options.dir.join(format!(
            "waypoint-{targets}-{red}-{}.jsonl",
            options.duration
        ));
        if !path.exists() {
            simulate_into(
                idmesh_sim::Scenario::waypoint(),
                targets,
                red,
                options.duration,
                options.seed,
                &path,
            )?;
        }
        Ok(path)
    };
    let same = waypoint(options.targets, options.red)?;
    let larger = waypoint(5 * options.targets, 5 * options.red)?;
    let mut out = String::from(
        "\n### Items per leader by region rule\n\nThe busiest leader's items ÷ an even share of what one leader alone applies, at the default settings (regions fitted to the crowd and redrawn) and with leaders at fixed places on a grid over the field (`regions = \"fixed\"`); computed from each stream by the router's own rule (`idmesh_placement::items_sent`). Under fitted regions the share is the product of two causes, shown beside it: all the leaders' items ÷ one leader's alone (a mix across two leaders is an item at each, a handover too: the fewer tracks a leader holds, the more mixes cross) and the busiest leader's items ÷ the leaders' mean (what placement decides).\n\n| crowd | leaders | fitted regions (default) | all items ÷ one leader's | busiest ÷ mean | fixed places on a grid |\n|---|---|---|---|---|---|\n",
    );
    let mut crowds = vec![
        ("the bench's crowd".to_string(), trace.to_path_buf()),
        ("random waypoint (dense middle)".to_string(), same),
        (
            format!("random waypoint, {} targets", 5 * options.targets),
            larger,
        ),
    ];
    let mut missing = Vec::new();
    for (scene, file) in idmesh_eval::eval::SCENES {
        let source = data_dir().join(file);
        if !source.is_file() {
            missing.push(source.display().to_string());
            continue;
        }
        let path = options
            .dir
            .join(format!("scene-{scene}-{}.jsonl", options.seed));
        if !path.exists() {
            write_simulation(Scenario::pedestrians(&source).seed(options.seed), &path)
                .with_context(|| format!("the scene {}", source.display()))?;
        }
        crowds.push((format!("real scene `{scene}`"), path));
    }
    for (name, path) in &crowds {
        let (name, path) = (name.as_str(), path.as_path());
        let (tracks, lines) = read(path)?;
        let single = items_sent(&RegionRule::fitted(), 1, tracks, &lines)[0];
        let corners = field_corners(path)?;
        for leaders in LEADERS {
            let fitted = items_sent(&RegionRule::fitted(), leaders, tracks, &lines);
            let causes = share_causes(&fitted, single);
            let grid = RegionRule::Fixed(
                grid_places(corners, leaders)
                    .into_iter()
                    .map(Some)
                    .collect(),
            );
            let fixed = items_sent(&grid, leaders, tracks, &lines);
            writeln!(
                out,
                "| {name} | {leaders} | {:.2}× | {:.2}× | {:.2}× | {:.2}× |",
                busiest_share(&fitted, single),
                causes.duplication,
                causes.unevenness,
                busiest_share(&fixed, single)
            )?;
        }
    }
    if !missing.is_empty() {
        writeln!(
            out,
            "\nScenes not found (set `IDMESH_PEDESTRIANS` to the folder of shared/data/pedestrians): {}.",
            missing.join(", ")
        )?;
    }
    Ok(out)
}

/// A trace's track count and lines.
fn read(path: &Path) -> Result<(usize, Vec<Line>)> {
    let (header, lines) = idmesh_protocol::trace::TraceReader::open(path)?.read_all()?;
    Ok((header.tracks, lines))
}
