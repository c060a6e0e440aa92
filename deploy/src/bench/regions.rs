//! How evenly the leaders share a stream's items, by region rule: what
//! each leader of a deployment at the default settings is sent
//! (`idmesh_placement::items_sent`, the items the router sends under the
//! regional rule) against an even share of what one leader alone applies,
//! at 2, 4 and 8 leaders, on the bench's crowd and on a random-waypoint
//! crowd (denser in the middle of its field), under fitted regions (the
//! default) and under leaders at fixed places on a grid over the field.
//! Computed from the streams, not timed: the throughput tables above
//! show the same counts read off the leaders of the bench's crowd.

use super::BenchOptions;
use crate::runtime::launch::{field_corners, simulate_into};
use anyhow::Result;
use idmesh_placement::{busiest_share, grid_places, items_sent, RegionRule};
use idmesh_protocol::trace::Line;
use std::fmt::Write as _;
use std::path::Path;

/// The leader counts of the table.
const LEADERS: [usize; 3] = [2, 4, 8];

/// The table, over the bench's crowd `trace` and a waypoint crowd of as
/// many targets, simulated (and kept) beside it.
pub fn report(options: &BenchOptions, trace: &Path) -> Result<String> {
    let waypoint = options.dir.join(format!(
        "waypoint-{}-{}-{}.jsonl",
        options.targets, options.red, options.duration
    ));
    if !waypoint.exists() {
        simulate_into(
            idmesh_sim::Scenario::waypoint(),
            options.targets,
            options.red,
            options.duration,
            options.seed,
            &waypoint,
        )?;
    }
    let mut out = String::from(
        "\n### Items per leader by region rule\n\nThe busiest leader's items ÷ an even share of what one leader alone applies, at the default settings (regions fitted to the crowd and redrawn) and with leaders at fixed places on a grid over the field (`regions = \"fixed\"`); computed from each stream by the router's own rule (`idmesh_placement::items_sent`).\n\n| crowd | leaders | fitted regions (default) | fixed places on a grid |\n|---|---|---|---|\n",
    );
    for (name, path) in [
        ("the bench's crowd", trace),
        ("random waypoint (dense middle)", &waypoint),
    ] {
        let (tracks, lines) = read(path)?;
        let single = items_sent(&RegionRule::fitted(), 1, tracks, &lines)[0];
        let corners = field_corners(path)?;
        for leaders in LEADERS {
            let fitted = items_sent(&RegionRule::fitted(), leaders, tracks, &lines);
            let grid = RegionRule::Fixed(
                grid_places(corners, leaders)
                    .into_iter()
                    .map(Some)
                    .collect(),
            );
            let fixed = items_sent(&grid, leaders, tracks, &lines);
            writeln!(
                out,
                "| {name} | {leaders} | {:.2}× | {:.2}× |",
                busiest_share(&fitted, single),
                busiest_share(&fixed, single)
            )?;
        }
    }
    Ok(out)
}

/// A trace's track count and lines.
fn read(path: &Path) -> Result<(usize, Vec<Line>)> {
    let mut reader = idmesh_protocol::TraceReader::open(path)?;
    let header = reader.read_header()?;
    let mut lines = Vec::new();
    while let Some(n) = reader.read_line()? {
        lines.push(n.line);
    }
    Ok((header.tracks, lines))
}
