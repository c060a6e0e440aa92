//! The trace the rest of idmesh consumes (shared/spec/trace.md): one track
//! per estimated path (`header` with tracks = K), a `move` line for every
//! fragment (its area's centroid at the middle of its slot), and a `mix`
//! line whenever two estimated paths come within the mixing distance —
//! the moments where "who is who" may be lost and the property and
//! identity beliefs must mix the two tracks. Written through the
//! validating `TraceWriter`, so the output is always a trace replay
//! accepts.

use super::config::OutputConfig;
use super::pipeline::prepare::Segmentation;
use super::run::{AcousticResult, EstimatedPath};
use idmesh_protocol::trace::{Header, Line, TraceError, TraceWriter};
use idmesh_sim::event_line;
use idmesh_sim::{MixDetector, SimEvent, TimedEvent};
use idmesh_sim::{NeighbourGrid, Vec2};
use std::io::Write;

/// Position of a path at slot `j`: its fragment there, or linear
/// interpolation between the fragments around a gap; `None` before its
/// first or after its last fragment.
fn position_at(path: &EstimatedPath, j: usize) -> Option<Vec2> {
    let f = &path.fragments;
    let i = f.partition_point(|x| x.slot < j);
    match (i.checked_sub(1).map(|p| &f[p]), f.get(i)) {
        (_, Some(next)) if next.slot == j => Some(next.position),
        (Some(prev), Some(next)) => {
            let s = (j - prev.slot) as f64 / (next.slot - prev.slot) as f64;
            Some(prev.position.lerp(next.position, s))
        }
        _ => None,
    }
}

/// The `mix` and `move` events of estimated paths, in time order (mixes
/// before moves at one time).
pub(crate) fn path_events(
    paths: &[EstimatedPath],
    seg: &Segmentation,
    output: &OutputConfig,
) -> Vec<TimedEvent> {
    let mut events = Vec::new();
    let mut detector = MixDetector::new(
        output.mix_distance,
        output.mix_distance * output.release_factor,
    );
    let mut grid = NeighbourGrid::new();
    let mut positions: Vec<Option<Vec2>> = vec![None; paths.len()];
    let mut entering = Vec::new();
    let mut cursor = vec![0usize; paths.len()];
    for j in 0..seg.slots() {
        let time = seg.middle(j) / output.sample_rate;
        for (l, path) in paths.iter().enumerate() {
            positions[l] = position_at(path, j);
        }
        grid.rebuild(&positions, detector.reach());
        entering.clear();
        detector.step(&grid, &positions, &mut entering);
        for &(a, b) in &entering {
            events.push(TimedEvent {
                time,
                event: SimEvent::Mix {
                    a,
                    b,
                    swap: output.swap,
                    // The tracker cannot know; the trace's mix line does
                    // not carry it.
                    exchanged: false,
                },
            });
        }
        for (l, path) in paths.iter().enumerate() {
            while let Some(f) = path.fragments.get(cursor[l]) {
                if f.slot != j {
                    break;
                }
                events.push(TimedEvent {
                    time,
                    event: SimEvent::Move {
                        track: l as u32,
                        x: f.position.x,
                        y: f.position.y,
                    },
                });
                cursor[l] += 1;
            }
        }
    }
    events
}

/// The header line of a run's trace.
pub(crate) fn header_line(result: &AcousticResult) -> Line {
    let c = &result.config;
    let mut header = Header::new(result.paths.len().max(1));
    header.source = Some("idmesh acoustic (Zhu et al., TMC 2014)".into());
    header.description = Some(format!(
        "{} sensors, {} targets, field {} m, R {} m, n_group {}, l_seg {}, l_step {}, sources {}, seed {}; times in units of {} samples/s",
        c.field.sensors,
        c.field.targets,
        c.field.size,
        c.field.range,
        c.pipeline.n_group,
        c.pipeline.l_seg,
        c.pipeline.l_step,
        c.field.sources.name(),
        c.seed,
        c.output.sample_rate
    ));
    Line::Header(header)
}

/// Writes the run's trace to `output`; `sink` names it in errors. Returns
/// the output, flushed.
pub fn write_trace<W: Write>(
    result: &AcousticResult,
    output: W,
    sink: impl Into<String>,
) -> Result<W, TraceError> {
    let mut writer = TraceWriter::new(output, sink);
    writer.write(&header_line(result))?;
    for e in &result.events {
        writer.write(&event_line(e))?;
    }
    writer.finish()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::run::EstimatedFragment;

    fn frag(slot: usize, x: f64, y: f64) -> EstimatedFragment {
        EstimatedFragment {
            slot,
            time: slot as f64,
            position: Vec2::new(x, y),
            area: 0,
        }
    }

    #[test]
    fn crossing_paths_mix_once_and_every_fragment_moves() {
        let seg = Segmentation::new(10, 5, 5 * 20 + 5).unwrap();
        // Two paths crossing at slot 10, one with a gap.
        let a = EstimatedPath {
            fragments: (0..20).map(|j| frag(j, 10.0 * j as f64, 0.0)).collect(),
        };
        let b = EstimatedPath {
            fragments: (0..20)
                .filter(|j| !(8..13).contains(j))
                .map(|j| frag(j, 200.0 - 10.0 * j as f64, 0.0))
                .collect(),
        };
        let events = path_events(&[a.clone(), b.clone()], &seg, &OutputConfig::default());
        let mixes: Vec<_> = events
            .iter()
            .filter(|e| matches!(e.event, SimEvent::Mix { .. }))
            .collect();
        assert_eq!(mixes.len(), 1, "{mixes:?}");
        assert!(matches!(mixes[0].event, SimEvent::Mix { a: 0, b: 1, .. }));
        let moves = events
            .iter()
            .filter(|e| matches!(e.event, SimEvent::Move { .. }))
            .count();
        assert_eq!(moves, a.fragments.len() + b.fragments.len());
        assert!(events.windows(2).all(|w| w[0].time <= w[1].time));
        assert_eq!(position_at(&b, 10), Some(Vec2::new(100.0, 0.0)));
        assert_eq!(position_at(&b, 25), None);
    }
}
