//! What leaders would pay to carry the factored identity belief whole:
//! each leader holds the linked trees of groups of some tracks
//! (`IdentityShare`); a mix gathers the trees of its two tracks in one
//! place, which applies it; a read is applied where its track's tree is
//! (routed by interest, as components are). Trees never split on a
//! handover, so the answer is the centralized belief's exactly (checked
//! at the end of every run); the cost is the trees moved between leaders.
//! Where a mix gathers its trees, two rules:
//!
//! - *the mix's leader*: the leader surveilling `a` (the regions the
//!   sensor fits to the crowd, as a deployment's);
//! - *the larger tree*: the holder of the tree with more table entries,
//!   so that the smaller moves, unless that holder applied more than
//!   1.2× the leaders' mean so far (then the mix's leader).
//!
//! Random-waypoint identity traces (reads at 0.9, swap ½, known start),
//! n = 100 (300 events) and 1,000 (3,000 events), at 2, 4 and 8 leaders:
//! per 1,000 events the trees moved and their table entries, the largest
//! tree moved, and the busiest leader's events (a mix counts at its leader
//! and at every other holder of one of its trees) over an even share.
//!
//!     cargo run --release -p idmesh-eval --example identity_leaders [SEEDS] [CAP]

use idmesh_identity::factored::{assemble, IdentityShare};
use idmesh_identity::identity_event_of;
use idmesh_identity::max_abs_difference;
use idmesh_identity::{FactoredIdentity, FactoredIdentityOptions, IdentityEvent, IdentityFilter};
use idmesh_placement::{leading_places, RegionRule, Regions};
use idmesh_protocol::trace::Line;
use idmesh_protocol::wire::sensor_to_leader::{keeper, UNHELD};
use idmesh_sim::lines;
use idmesh_sim::Scenario;

#[derive(Default)]
struct Cost {
    events: u64,
    moves: u64,
    entries: u64,
    largest: usize,
    items: Vec<u64>,
}

/// Where a mix gathers its two trees.
#[derive(Clone, Copy)]
enum Gather {
    MixLeader,
    LargerTree,
}

/// The larger tree's holder gives way to the mix's leader above this many
/// times the leaders' mean events so far.
const BUSY: f64 = 1.2;

fn run(n: usize, seed: u64, leaders: usize, cap: usize, gather: Gather) -> Cost {
    let trace = Scenario::waypoint()
        .targets(n)
        .events(3 * n)
        .identities(true)
        .identity_accuracy(0.9)
        .seed(seed)
        .generate()
        .expect("a valid scenario");
    let all: Vec<Line> = lines(&trace).collect();
    let Some(Line::Header(header)) = all.first() else {
        panic!("a header first")
    };
    let initial = header.initial_identity.clone().expect("a known start");
    let options = FactoredIdentityOptions {
        max_group: cap,
        ..FactoredIdentityOptions::default()
    };
    let mut central = FactoredIdentity::from_assignment(&initial, options).expect("a start");
    let leading = leading_places(n, &all);
    let mut regions = Regions::starting(&RegionRule::fitted(), leaders, n, &leading);
    let owners = regions.owners();
    let mut shares: Vec<IdentityShare> = (0..leaders as u16)
        .map(|me| {
            // A track nobody surveils yet is kept by its keeper.
            IdentityShare::start(&initial, options, |t| match owners[t as usize] {
                UNHELD => keeper(t, leaders) == me,
                owner => owner == me,
            })
            .expect("a share")
        })
        .collect();
    let mut cost = Cost {
        items: vec![0; leaders],
        ..Cost::default()
    };
    let holder = |shares: &[IdentityShare], t: u32| {
        shares
            .iter()
            .position(|s| s.holds(t))
            .expect("every tree held once")
    };
    for line in &all {
        regions.before(line);
        if let Some(event) = identity_event_of(line) {
            cost.events += 1;
            match &event {
                IdentityEvent::Mix(m) => {
                    let mut at = usize::from(regions.owner(m.a).expect("a known track"));
                    let (ha, hb) = (holder(&shares, m.a), holder(&shares, m.b));
                    if let Gather::LargerTree = gather {
                        let entries = |h: usize, t: u32| shares[h].tree_entries(t).expect("held");
                        let larger = if entries(ha, m.a) >= entries(hb, m.b) {
                            ha
                        } else {
                            hb
                        };
                        let mean = cost.items.iter().sum::<u64>() as f64 / leaders as f64;
                        if cost.items[larger] as f64 <= BUSY * mean.max(1.0) {
                            at = larger;
                        }
                    }
                    let mut counted = vec![false; leaders];
                    counted[at] = true;
                    for t in [m.a, m.b] {
                        // a's tree may hold b too, moved with it.
                        let h = holder(&shares, t);
                        if h != at {
                            cost.entries += shares[h].tree_entries(t).expect("held") as u64;
                            let tree = shares[h].take(t).expect("a held tree");
                            cost.moves += 1;
                            cost.largest = cost
                                .largest
                                .max(tree.groups.iter().map(|g| g.size()).max().unwrap_or(0));
                            shares[at].put(tree).expect("a tree taken in");
                            counted[h] = true;
                        }
                    }
                    for (l, c) in counted.iter().enumerate() {
                        cost.items[l] += u64::from(*c);
                    }
                    shares[at].apply(&event).expect("a mix applied");
                }
                IdentityEvent::Identify(r) => {
                    let h = holder(&shares, r.track);
                    cost.items[h] += 1;
                    shares[h].apply(&event).expect("a read applied");
                }
            }
            central.apply(&event).expect("the centralized belief");
        }
        regions.after(line);
    }
    let trees = shares.iter().flat_map(IdentityShare::held_trees).collect();
    let whole = assemble(n, options, trees).expect("the trees assemble");
    let d = max_abs_difference(&whole.marginals().unwrap(), &central.marginals().unwrap());
    assert!(
        d < 1e-9,
        "the leaders' trees differ from the centralized belief by {d}"
    );
    cost
}

fn main() {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(3);
    let cap: usize = std::env::args()
        .nth(2)
        .and_then(|s| s.parse().ok())
        .unwrap_or(FactoredIdentityOptions::default().max_group);
    println!("cap {cap}");
    for (gather, name) in [
        (Gather::MixLeader, "the mix's leader"),
        (Gather::LargerTree, "the larger tree"),
    ] {
        println!("\nGathered at {name}:\n");
        println!("| n | leaders | trees moved / 1,000 events | table entries moved / event | largest group moved | busiest leader's events / even share |");
        println!("|---:|---:|---:|---:|---:|---:|");
        for n in [100usize, 1000] {
            for leaders in [2usize, 4, 8] {
                let mut total = Cost {
                    items: Vec::new(),
                    ..Cost::default()
                };
                let mut shares = Vec::new();
                for seed in 300..300 + seeds {
                    let c = run(n, seed, leaders, cap, gather);
                    total.events += c.events;
                    total.moves += c.moves;
                    total.entries += c.entries;
                    total.largest = total.largest.max(c.largest);
                    let busiest = c.items.iter().copied().max().unwrap_or(0) as f64;
                    shares.push(busiest * leaders as f64 / c.events.max(1) as f64);
                }
                let mean_share = shares.iter().sum::<f64>() / shares.len().max(1) as f64;
                println!(
                    "| {n} | {leaders} | {:.0} | {:.1} | {} | {:.2}× |",
                    1000.0 * total.moves as f64 / total.events as f64,
                    total.entries as f64 / total.events as f64,
                    total.largest,
                    mean_share
                );
            }
        }
    }
}
