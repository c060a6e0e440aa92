//! How evenly a region rule shares a trace's items among leaders:
//! `cargo run --release -p idmesh-placement --example balance -- TRACE`
//! prints, for 2, 4 and 8 leaders, the busiest leader's items over an even
//! share under fitted regions and under fixed places on a grid, split into
//! its two causes: all the leaders' items over one leader's (a mix across
//! two leaders is an item at each, a handover too) and the busiest over
//! the mean.

use idmesh_placement::{busiest_share, grid_places, items_sent, share_causes, RegionRule};
use idmesh_protocol::trace::{Line, TraceReader};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let path = std::env::args().nth(1).ok_or("usage: balance TRACE")?;
    let (header, lines) = TraceReader::open(std::path::Path::new(&path))?.read_all()?;
    let tracks = header.tracks;
    let mut b = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for line in &lines {
        if let Line::Move(m) = line {
            b = (b.0.min(m.x), b.1.min(m.y), b.2.max(m.x), b.3.max(m.y));
        }
    }
    let single = items_sent(&RegionRule::fitted(), 1, tracks, &lines)[0];
    println!("{path}: {tracks} tracks, {single} items through one leader");
    for leaders in [2, 4, 8] {
        let fitted = items_sent(&RegionRule::fitted(), leaders, tracks, &lines);
        let grid = RegionRule::Fixed(grid_places(b, leaders).into_iter().map(Some).collect());
        let fixed = items_sent(&grid, leaders, tracks, &lines);
        let (f, g) = (share_causes(&fitted, single), share_causes(&fixed, single));
        let (f_total, f_even, g_total, g_even) =
            (f.duplication, f.unevenness, g.duplication, g.unevenness);
        println!(
            "{leaders} leaders: fitted {:.2} (all items {f_total:.2}x one leader's, busiest {f_even:.2}x the mean), grid {:.2} ({g_total:.2}x, {g_even:.2}x)",
            busiest_share(&fitted, single),
            busiest_share(&fixed, single)
        );
    }
    Ok(())
}
