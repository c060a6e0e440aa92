//! The factored identity belief against the exact filter over all N!
//! assignments: equal when the cap holds every group of mixed tracks,
//! close (and still a belief) when it does not.

use super::*;
use crate::exact::ExactPermutationFilter;
use crate::filter::{doubly_stochastic_residual, max_abs_difference};
use crate::workload::{generate, IdentityWorkloadSpec};
use crate::IdentityEvent;
use proptest::prelude::*;

/// A cap, and cuts of sure tracks only (exact).
fn options(max_group: usize) -> FactoredIdentityOptions {
    FactoredIdentityOptions {
        max_group,
        certain: 0.0,
        linked: true,
    }
}

/// A cap, and hard cuts only (the split step without links).
fn hard(max_group: usize) -> FactoredIdentityOptions {
    FactoredIdentityOptions {
        linked: false,
        ..options(max_group)
    }
}

fn spec(n: usize, events: usize, swap: f64, accuracy: f64, seed: u64) -> IdentityWorkloadSpec {
    IdentityWorkloadSpec {
        tracks: n,
        events,
        mix_share: 0.5,
        swap,
        accuracy,
        neighbourhood: n,
        seed,
    }
}

/// Whether `m` puts 0 on an entry to which the exact filter's `x` gives
/// more than `above`.
fn rules_out(m: &[Vec<f64>], x: &[Vec<f64>], above: f64) -> bool {
    m.iter()
        .flatten()
        .zip(x.iter().flatten())
        .any(|(&p, &q)| q > above && p <= 0.0)
}

/// Σ_t λ_t: how far the leaks can take the marginals' columns from
/// summing to one (each row mixes λ_t of itself out of the tables).
fn leaked(f: &FactoredIdentity) -> f64 {
    f.backgrounds.iter().map(|b| b.leak()).sum()
}

/// The largest |Δp| against exact over a stream, checking at every event.
fn worst_error(
    n: usize,
    max_group: usize,
    mix_share: f64,
    seed: u64,
    events: usize,
) -> (f64, SplitStats) {
    let mut s = spec(n, events, 0.5, 0.9, seed);
    s.mix_share = mix_share;
    let w = generate(&s).unwrap();
    let mut exact = ExactPermutationFilter::from_assignment(&w.initial).unwrap();
    let mut factored = FactoredIdentity::from_assignment(&w.initial, options(max_group)).unwrap();
    let mut worst: f64 = 0.0;
    for e in &w.events {
        exact.apply(e).unwrap();
        factored.apply(e).unwrap();
        // The bound is the tables' (a leak only moves mass back).
        let m = factored.table_marginals().unwrap();
        assert!(doubly_stochastic_residual(&m) < 1e-9);
        worst = worst.max(max_abs_difference(&m, &exact.marginals().unwrap()));
    }
    (worst, factored.split_stats())
}

#[test]
fn known_start_reads_and_mixes_match_the_exact_filter() {
    // The slides' example: 18/19 after a read on a half mix.
    let mut f = FactoredIdentity::from_assignment(&[0, 1, 2], options(3)).unwrap();
    f.mix(Mix {
        a: 0,
        b: 1,
        swap: 0.5,
    })
    .unwrap();
    f.identify(Identify {
        track: 0,
        identity: 0,
        accuracy: 0.9,
    })
    .unwrap();
    let m = f.marginals().unwrap();
    assert!((m[0][0] - 18.0 / 19.0).abs() < 1e-15);
    assert_eq!(m[2][2], 1.0);
    assert_eq!(f.groups().len(), 2);
    // A read of an identity outside the track's group changes nothing.
    let before = f.clone();
    f.identify(Identify {
        track: 2,
        identity: 0,
        accuracy: 0.9,
    })
    .unwrap();
    assert_eq!(f, before);
    assert_eq!(f.repairs(), 0);
    // A sure one contradicts every assignment the tables allow, and the
    // identity is in another tree: the track answers by its row, which
    // believes the read; the tables and the other tracks are as they were.
    f.identify(Identify {
        track: 2,
        identity: 0,
        accuracy: 1.0,
    })
    .unwrap();
    assert_eq!(f.repairs(), 1);
    assert_eq!(f.groups().len(), before.groups().len());
    assert!(before.groups().iter().all(|g| f.groups().contains(g)));
    let m = f.marginals().unwrap();
    assert_eq!(m[2][0], 1.0);
    assert!(
        (m[0][0] - 18.0 / 19.0).abs() < 1e-15,
        "other tracks unchanged"
    );
}

/// A sure read of an identity the track's group holds, at probability 0
/// for that track: a swap the belief missed, with the likeliest other
/// carrier of the identity — what the exact filter gives had that swap
/// been in the stream (at probability ε).
#[test]
fn a_sure_read_the_table_rules_out_is_a_swap_the_belief_missed() {
    let start = [0, 1, 2, 3];
    let mut f = FactoredIdentity::from_assignment(&start, options(4)).unwrap();
    let mut exact = ExactPermutationFilter::from_assignment(&start).unwrap();
    let mixes = [(0, 1, 0.5), (1, 2, 0.5), (2, 3, 0.1)];
    for (a, b, swap) in mixes {
        f.mix(Mix { a, b, swap }).unwrap();
        exact.mix(Mix { a, b, swap }).unwrap();
    }
    // Identity 3 is on track 3 (0.9) or 2, never on track 0.
    assert_eq!(f.marginals().unwrap()[0][3], 0.0);
    let read = Identify {
        track: 0,
        identity: 3,
        accuracy: 1.0,
    };
    f.identify(read).unwrap();
    assert_eq!(f.repairs(), 1);
    exact
        .mix(Mix {
            a: 0,
            b: 3,
            swap: repair::SMOOTHING,
        })
        .unwrap();
    exact.identify(read).unwrap();
    let (got, want) = (f.marginals().unwrap(), exact.marginals().unwrap());
    assert!(
        max_abs_difference(&got, &want) < 1e-9,
        "{got:?} vs {want:?}"
    );
    assert!((got[0][3] - 1.0).abs() < 1e-9);
}

#[test]
fn sure_swaps_move_tracks_without_joining() {
    let mut f = FactoredIdentity::from_assignment(&[2, 0, 1], options(2)).unwrap();
    f.mix(Mix {
        a: 0,
        b: 2,
        swap: 1.0,
    })
    .unwrap();
    f.mix(Mix {
        a: 0,
        b: 1,
        swap: 0.0,
    })
    .unwrap();
    assert_eq!(f.largest_group(), 1);
    assert_eq!(f.most_likely().unwrap(), vec![1, 0, 2]);
}

#[test]
fn bad_options_and_starts_are_refused() {
    assert!(FactoredIdentity::from_assignment(&[0, 1], options(1)).is_err());
    assert!(FactoredIdentity::from_assignment(&[0, 1], options(MAX_GROUP + 1)).is_err());
    assert!(FactoredIdentity::from_assignment(&[0, 0], options(4)).is_err());
    assert!(FactoredIdentity::uniform(5, options(4)).is_err());
    assert!(FactoredIdentity::uniform(0, options(4)).is_err());
    let mut f = FactoredIdentity::uniform(3, options(3)).unwrap();
    assert!(f
        .mix(Mix {
            a: 0,
            b: 3,
            swap: 0.5
        })
        .is_err());
}

#[test]
fn the_belief_round_trips_and_tampering_is_refused() {
    let w = generate(&spec(7, 60, 0.4, 0.9, 3)).unwrap();
    let mut f = FactoredIdentity::from_assignment(&w.initial, options(4)).unwrap();
    for e in &w.events {
        f.apply(e).unwrap();
    }
    let bytes = postcard::to_allocvec(&f).unwrap();
    let back: FactoredIdentity = postcard::from_bytes(&bytes).unwrap();
    assert_eq!(back, f);
    assert_eq!(back.marginals().unwrap(), f.marginals().unwrap());
    // A group above the cap is refused on the way in.
    let mut wide = f.clone();
    wide.options.max_group = 2;
    let bytes = postcard::to_allocvec(&wide).unwrap();
    if f.largest_group() > 2 {
        assert!(postcard::from_bytes::<FactoredIdentity>(&bytes).is_err());
    }
    // A track claimed twice is refused.
    let mut twice = f.clone();
    assert!(twice.groups.len() > 1);
    let other = twice.groups[1].tracks[0];
    twice.groups[0].tracks[0] = other;
    let bytes = postcard::to_allocvec(&twice).unwrap();
    assert!(postcard::from_bytes::<FactoredIdentity>(&bytes).is_err());
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// With the cap at least n no cut is ever made and the belief is the
    /// exact filter's, from a known start or the uniform one.
    #[test]
    fn with_room_for_every_group_it_is_exact(
        n in 1usize..=6,
        extra in 0usize..=2,
        seed in any::<u64>(),
        swap in prop_oneof![Just(0.0), Just(1.0), 0.05f64..0.95],
        accuracy in 0.3f64..=0.99,
        known in any::<bool>(),
    ) {
        let w = generate(&spec(n, 40, swap, accuracy, seed)).unwrap();
        let cap = (n + extra).clamp(2, MAX_GROUP);
        let (mut exact, mut factored) = if known {
            (
                ExactPermutationFilter::from_assignment(&w.initial).unwrap(),
                FactoredIdentity::from_assignment(&w.initial, options(cap)).unwrap(),
            )
        } else {
            (
                ExactPermutationFilter::uniform(n).unwrap(),
                FactoredIdentity::uniform(n, options(cap)).unwrap(),
            )
        };
        for e in &w.events {
            let (ra, rb) = (exact.apply(e), factored.apply(e));
            prop_assert_eq!(ra.is_ok(), rb.is_ok());
            let d = max_abs_difference(&exact.marginals().unwrap(), &factored.marginals().unwrap());
            prop_assert!(d < 1e-9, "{} after {:?}", d, e);
        }
        prop_assert_eq!(factored.split_stats().lossy_cuts, 0);
    }

    /// Without reads, every cut adds at most (1 − P(E)) + √(I/2) of total
    /// variation and mixes never add any: the error stays below the
    /// belief's own running bound.
    #[test]
    fn on_mixes_alone_the_error_stays_below_the_cut_bound(
        n in 3usize..=6,
        seed in any::<u64>(),
    ) {
        let (worst, stats) = worst_error(n, n - 1, 1.0, seed, 30);
        prop_assert!(worst <= stats.total_variation_bound + 1e-9, "{} > {:?}", worst, stats);
    }

    /// With a smaller cap the marginals stay a doubly stochastic matrix,
    /// and while every cut made was exact (nothing lost) they are still
    /// the exact filter's.
    #[test]
    fn with_a_smaller_cap_it_stays_a_belief(
        n in 3usize..=6,
        seed in any::<u64>(),
        swap in 0.05f64..0.95,
    ) {
        let w = generate(&spec(n, 40, swap, 0.9, seed)).unwrap();
        let cap = n - 1;
        let mut exact = ExactPermutationFilter::from_assignment(&w.initial).unwrap();
        let mut factored = FactoredIdentity::from_assignment(&w.initial, options(cap)).unwrap();
        for e in &w.events {
            exact.apply(e).unwrap();
            factored.apply(e).unwrap();
            prop_assert!(factored.largest_group() <= cap);
            prop_assert!(doubly_stochastic_residual(&factored.table_marginals().unwrap()) < 1e-9);
            let m = factored.marginals().unwrap();
            prop_assert!(m.iter().all(|row| (row.iter().sum::<f64>() - 1.0).abs() < 1e-9));
            prop_assert!(m.iter().flatten().all(|&p| (-1e-12..=1.0 + 1e-12).contains(&p)));
            if factored.split_stats().lossy_cuts == 0 {
                let d = max_abs_difference(&m, &exact.marginals().unwrap());
                prop_assert!(d < 1e-9, "{}", d);
            }
        }
    }
}

#[test]
fn events_of_every_kind_apply() {
    // The IdentityFilter default `apply` routes to mix and identify.
    let mut f = FactoredIdentity::from_assignment(&[1, 0], options(2)).unwrap();
    f.apply(&IdentityEvent::Mix(Mix {
        a: 0,
        b: 1,
        swap: 0.5,
    }))
    .unwrap();
    f.apply(&IdentityEvent::Identify(Identify {
        track: 1,
        identity: 1,
        accuracy: 0.8,
    }))
    .unwrap();
    let m = f.marginals().unwrap();
    assert!((m[1][1] - 0.8).abs() < 1e-12);
}

/// The joint over the n! assignments of real identities to real tracks
/// that the groups and their links stand for, by brute force: every
/// combination of the groups' assignments whose links agree, a track on a
/// star given what the partner's phantom carries.
fn joint(f: &FactoredIdentity) -> Vec<Vec<f64>> {
    let n = f.n;
    let mut m = vec![vec![0.0; n]; n];
    let mut total = 0.0;
    let groups = &f.groups;
    let mut ranks = vec![0usize; groups.len()];
    loop {
        let mut p = 1.0;
        for (g, &r) in groups.iter().zip(&ranks) {
            p *= g.probability(r as u32);
        }
        if p > 0.0 {
            // carried[id] = global identity on global track id.
            let mut carried = std::collections::HashMap::new();
            for (g, &r) in groups.iter().zip(&ranks) {
                for (j, &x) in g.table().get(r).iter().enumerate() {
                    carried.insert(g.tracks[j], g.identities[x as usize]);
                }
            }
            let consistent = carried.iter().all(|(&t, &i)| {
                if (t as usize) < n {
                    return true;
                }
                let q = f.partner(t);
                (i == t) == (carried[&q] == q)
            });
            if consistent {
                total += p;
                for t in 0..n as u32 {
                    let mut i = carried[&t];
                    if i as usize >= n {
                        i = carried[&f.partner(i)];
                    }
                    assert!((i as usize) < n, "an identity crossing two links");
                    m[t as usize][i as usize] += p;
                }
            }
        }
        // Next combination.
        let mut g = 0;
        loop {
            if g == groups.len() {
                m.iter_mut().flatten().for_each(|x| *x /= total);
                return m;
            }
            ranks[g] += 1;
            if ranks[g] < groups[g].assignments() {
                break;
            }
            ranks[g] = 0;
            g += 1;
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The marginals (belief propagation over the links) are those of the
    /// joint the groups and links stand for.
    #[test]
    fn linked_marginals_are_those_of_the_joint(
        n in 4usize..=6,
        seed in any::<u64>(),
    ) {
        let w = generate(&spec(n, 30, 0.5, 0.9, seed)).unwrap();
        let mut f = FactoredIdentity::from_assignment(&w.initial, options(n - 2)).unwrap();
        for e in &w.events {
            f.apply(e).unwrap();
            let d = max_abs_difference(&f.table_marginals().unwrap(), &joint(&f));
            prop_assert!(d < 1e-9, "{} after {:?}", d, e);
        }
    }
}

#[test]
fn a_read_across_a_linked_cut_moves_mass_back() {
    // Tracks 0, 1, 2 and 3, 4 mix; then 0 and 3 mix, and the cap of 4
    // forces a cut of {0, 1, 2}. Reads of identity 1 on track 0 then say
    // the first swap happened: the hard cut of track 0 ruled that out for
    // good, the linked cut keeps it.
    let mix = |a, b, swap| IdentityEvent::Mix(Mix { a, b, swap });
    let events = [
        mix(0, 1, 0.3),
        mix(1, 2, 0.3),
        mix(3, 4, 0.45),
        mix(0, 3, 0.5),
    ];
    let read = IdentityEvent::Identify(Identify {
        track: 0,
        identity: 1,
        accuracy: 0.9,
    });
    let start = [0, 1, 2, 3, 4];
    let mut exact = ExactPermutationFilter::from_assignment(&start).unwrap();
    let mut linked = FactoredIdentity::from_assignment(&start, options(4)).unwrap();
    let mut cut = FactoredIdentity::from_assignment(&start, hard(4)).unwrap();
    for e in events.iter().chain([&read, &read, &read]) {
        exact.apply(e).unwrap();
        linked.apply(e).unwrap();
        cut.apply(e).unwrap();
    }
    let (x, l, h) = (
        exact.marginals().unwrap(),
        linked.marginals().unwrap(),
        cut.marginals().unwrap(),
    );
    eprintln!(
        "exact {:?}\nlinked {:?}\nhard {:?}\n{:?}",
        x[0],
        l[0],
        h[0],
        linked.split_stats()
    );
    assert!(x[0][1] > 0.8, "{:?}", x[0]);
    assert_eq!(linked.split_stats().linked_cuts, 1);
    // The hard cut's table rules the swap out for good; only its leak,
    // which the reads raised, gives it back some mass.
    assert_eq!(cut.table_marginals().unwrap()[0][1], 0.0);
    assert!(h[0][1] > 0.3, "{:?}", h[0]);
    assert!(max_abs_difference(&l, &x) < 0.05, "{:?} against {:?}", l, x);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Linked cuts that lose no mass (at most one identity crossed each)
    /// leave nothing at 0 that the exact filter gives more than 0.1, after
    /// reads too; and every cut stays within the cap.
    #[test]
    fn lossless_linked_cuts_leave_no_stuck_zeros(
        n in 4usize..=6,
        seed in any::<u64>(),
        swap in 0.05f64..0.95,
    ) {
        let w = generate(&spec(n, 40, swap, 0.9, seed)).unwrap();
        let mut exact = ExactPermutationFilter::from_assignment(&w.initial).unwrap();
        let mut f = FactoredIdentity::from_assignment(&w.initial, options(n - 1)).unwrap();
        for e in &w.events {
            exact.apply(e).unwrap();
            f.apply(e).unwrap();
            prop_assert!(f.largest_group() < n);
            if f.split_stats().lost_mass > 1e-12 {
                break;
            }
            let (m, x) = (f.marginals().unwrap(), exact.marginals().unwrap());
            // Losses below 1e-12 still leak, and reads that contradict
            // the tables can raise a leak by orders of magnitude; a row's
            // leak is the only part of it that can unbalance a column.
            prop_assert!(doubly_stochastic_residual(&m) < 1e-9 + 2.0 * leaked(&f));
            prop_assert!(!rules_out(&m, &x, 0.1), "{:?} against {:?} after {:?}", m, x, e);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// Hard cuts rule assignments out of the tables, but their leaks
    /// keep every identity the exact filter still allows possible: no
    /// entry is 0 that the exact filter gives more than 1e-9, whatever
    /// was lost, and every row sums to one.
    #[test]
    fn leaks_leave_nothing_possible_at_zero(
        n in 4usize..=6,
        seed in any::<u64>(),
        swap in 0.05f64..0.95,
    ) {
        let w = generate(&spec(n, 40, swap, 0.9, seed)).unwrap();
        let mut exact = ExactPermutationFilter::from_assignment(&w.initial).unwrap();
        let mut f = FactoredIdentity::from_assignment(&w.initial, hard(n - 2)).unwrap();
        for e in &w.events {
            exact.apply(e).unwrap();
            f.apply(e).unwrap();
            let (m, x) = (f.marginals().unwrap(), exact.marginals().unwrap());
            prop_assert!(m.iter().all(|row| (row.iter().sum::<f64>() - 1.0).abs() < 1e-9));
            prop_assert!(!rules_out(&m, &x, 1e-9), "{:?} against {:?} after {:?}", m, x, e);
        }
    }
}

#[test]
fn a_cut_leaks_the_mass_it_conditions_away() {
    // Tracks 0 and 1 swap with ½, then 1 and 2 with ½: one group of three.
    // A cap of 3 makes the mix of 2 and 3 cut the group first. Each track
    // leaks the probability that it carried an identity of the other
    // side: at most the mass the cut lost, and, since every assignment it
    // rules out moves at least two tracks across, at least twice that
    // mass over all of them.
    let mut f = FactoredIdentity::from_assignment(&[0, 1, 2, 3], hard(3)).unwrap();
    for (a, b) in [(0, 1), (1, 2)] {
        f.mix(Mix { a, b, swap: 0.5 }).unwrap();
    }
    assert_eq!(f.split_stats().lossy_cuts, 0);
    f.mix(Mix {
        a: 2,
        b: 3,
        swap: 0.5,
    })
    .unwrap();
    let lost = f.split_stats().lost_mass;
    assert!(lost > 0.1, "{:?}", f.split_stats());
    let leaks: Vec<f64> = f.backgrounds.iter().map(Background::leak).collect();
    assert!(
        leaks.iter().all(|&l| l <= lost + 1e-12),
        "{leaks:?} against {lost}"
    );
    assert!(
        leaks.iter().sum::<f64>() >= 2.0 * lost - 1e-12,
        "{leaks:?} against {lost}"
    );
    // Rows still sum to one, and nothing the exact filter allows is
    // ruled out.
    let mut exact = ExactPermutationFilter::from_assignment(&[0, 1, 2, 3]).unwrap();
    for (a, b) in [(0, 1), (1, 2), (2, 3)] {
        exact.mix(Mix { a, b, swap: 0.5 }).unwrap();
    }
    let (m, x) = (f.marginals().unwrap(), exact.marginals().unwrap());
    assert!(m
        .iter()
        .all(|row| (row.iter().sum::<f64>() - 1.0).abs() < 1e-12));
    assert!(!rules_out(&m, &x, 0.0), "{m:?} against {x:?}");
}
