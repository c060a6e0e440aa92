use super::*;
use crate::event::{Event, RedCount};
use crate::factored::{Coupling, SplitRule};
use crate::workload::{generate, WorkloadSpec};
use std::sync::Arc;

/// A crowd workload with some certain sightings, certain exchanges and
/// non-events, as the belief's own tests use.
fn workload(n: usize, events: usize, seed: u64) -> (Vec<u32>, Vec<Event>) {
    let mut work = generate(&WorkloadSpec {
        tracks: n,
        red: n / 2,
        events,
        mix_share: 0.55,
        swap: 0.35,
        neighbourhood: n,
        ..WorkloadSpec::table3(n, seed)
    });
    let mut sightings = 0;
    for (event, truth) in work.events.iter_mut().zip(&work.truth) {
        match event {
            Event::Observe(o) => {
                sightings += 1;
                if sightings % 7 == 0 {
                    let red = truth.contains(&o.track);
                    (o.red, o.blue) = if red { (1.0, 0.0) } else { (0.0, 1.0) };
                }
            }
            Event::Mix(m) => match seed.wrapping_add(m.a as u64) % 11 {
                0 => m.swap = 1.0,
                1 => m.swap = 0.0,
                _ => {}
            },
        }
    }
    (work.initial_red, work.events)
}

/// `leaders` shares run the events the way leaders do (a mix of two
/// components gathers both at the holder of the first track's component;
/// a certain exchange relabels wherever the two are; now and then a
/// component moves to another leader, as a handover moves it), and the
/// coordinator's coupling of their parts equals the centralized belief
/// with the local rule after every event, to 1e-9, evaluated afresh and by
/// a [`CouplingTree`] kept from event to event (parts in any order, as the
/// leaders' replies come); a snapshot of a share reads back to the same
/// parts.
fn shares_equal_the_whole(
    field: Field,
    options: FactoredOptions,
    events: &[Event],
    leaders: usize,
) {
    let mut whole = FactoredBelief::with_options(field.clone(), options.clone()).unwrap();
    let mut shares: Vec<FactoredShare> = (0..leaders)
        .map(|l| {
            FactoredShare::start(field.clone(), options.clone(), |t| {
                t as usize % leaders == l
            })
            .unwrap()
        })
        .collect();
    let holder = |shares: &[FactoredShare], t: u32| shares.iter().position(|s| s.holds(t)).unwrap();
    let mut kept = CouplingTree::new(field.clone()).unwrap();
    let mut shared = CouplingTree::new(field.clone()).unwrap();
    let mut shared_before: Vec<Arc<CountPart>> = Vec::new();
    let mut shared_reused = 0;
    let mut moved = 0;
    for (i, event) in events.iter().enumerate() {
        let when = i as u64 + 1;
        let ok = whole.apply(event).is_ok();
        match *event {
            Event::Mix(mix) => {
                let (ha, hb) = (holder(&shares, mix.a), holder(&shares, mix.b));
                if mix.swap == 1.0 {
                    for h in [ha, hb] {
                        shares[h].mix(mix, when).unwrap();
                    }
                    if ha == hb {
                        // Once is enough: undo the second relabel.
                        shares[ha].mix(mix, when).unwrap();
                    }
                } else if mix.swap > 0.0 {
                    if ha != hb {
                        // As a leader takes them: among the mixed tracks'
                        // components only (`take` reads all it holds).
                        let comp = match i % 2 {
                            0 => shares[hb].take(|c| c.contains(&mix.b)),
                            _ => shares[hb].take_of(&[mix.a, mix.b], |c| c.contains(&mix.b)),
                        };
                        shares[ha].put(comp).unwrap();
                        moved += 1;
                    }
                    assert_eq!(shares[ha].mix(mix, when).is_ok(), ok);
                }
            }
            Event::Observe(o) => {
                let h = holder(&shares, o.track);
                assert_eq!(shares[h].observe(o).is_ok(), ok);
            }
        }
        if i % 5 == 0 {
            // A handover: the component of some track goes elsewhere.
            let t = (i * 7 % field.tracks) as u32;
            let from = holder(&shares, t);
            let to = (from + 1) % leaders;
            if to != from {
                let comp = shares[from].take(|c| c.contains(&t));
                shares[to].put(comp).unwrap();
            }
        }
        // What each share says it holds, by its index and by its flags.
        for share in &shares {
            let flagged: Vec<u32> = (0..field.tracks as u32)
                .filter(|&t| share.holds(t))
                .collect();
            let mut in_components: Vec<u32> = share
                .components()
                .into_iter()
                .flat_map(|c| c.tracks)
                .collect();
            in_components.sort_unstable();
            assert_eq!(
                share.held_tracks().collect::<Vec<_>>(),
                flagged,
                "event {i}"
            );
            assert_eq!(in_components, flagged, "event {i}");
            assert_eq!(share.tracks_held(), flagged.len());
        }
        if !ok {
            continue;
        }
        let mut parts: Vec<CountPart> = shares.iter().flat_map(|s| s.parts()).collect();
        let got = coupled_marginals(&field, &parts).unwrap();
        if i % 2 == 1 {
            parts.reverse();
        }
        let from_kept = kept.marginals(parts.iter()).unwrap();
        // As the leaders give them: a part unchanged since the last event
        // is the very same shared part, and only a changed one is new.
        let arcs: Vec<Arc<CountPart>> = shares.iter().flat_map(|s| s.shared_parts()).collect();
        // Brought up to date from what changed, they are what the share
        // holds, in its order.
        let fresh: Vec<CountPart> = shares.iter().flat_map(|s| s.parts()).collect();
        let given: Vec<CountPart> = arcs.iter().map(|a| (**a).clone()).collect();
        assert_eq!(given, fresh, "event {i}: the parts given are stale");
        let reused = arcs
            .iter()
            .filter(|a| shared_before.iter().any(|b| Arc::ptr_eq(a, b)))
            .count();
        shared_reused += reused;
        let from_shared = shared.marginals_shared(arcs.iter()).unwrap();
        shared_before = arcs;
        let want = whole.marginals().unwrap();
        for (t, ((g, k), w)) in got.iter().zip(&from_kept).zip(&want).enumerate() {
            assert!((g - w).abs() < 1e-9, "event {i}, track {t}: {g} vs {w}");
            assert!(
                (k - w).abs() < 1e-9,
                "event {i}, track {t}, kept: {k} vs {w}"
            );
            let sh = from_shared[t];
            assert!(
                (sh - w).abs() < 1e-9,
                "event {i}, track {t}, shared: {sh} vs {w}"
            );
        }
    }
    assert!(moved > 0 || leaders == 1);
    assert!(shared_reused > 0, "no part was ever shared between events");
    let split = whole.stats().splits;
    assert!(split > 0, "the workload never split");
    for share in &shares {
        let bytes = postcard::to_allocvec(share).unwrap();
        let back: FactoredShare = postcard::from_bytes(&bytes).unwrap();
        let sorted = |mut c: Vec<HeldComponent>| {
            c.sort_by(|x, y| x.tracks.cmp(&y.tracks));
            c
        };
        assert_eq!(sorted(back.components()), sorted(share.components()));
    }
}

#[test]
fn leaders_holding_the_components_answer_as_the_whole() {
    for (seed, rule) in [
        (1, SplitRule::Original),
        (2, SplitRule::Recent),
        (3, SplitRule::LeastLoss { rounds: 1 }),
    ] {
        let n = 14;
        let (initial, events) = workload(n, 300, seed);
        let options = FactoredOptions {
            max_component: 3,
            split: rule,
            coupling: Coupling::Local,
            ..FactoredOptions::default()
        };
        let fields = [
            Field::known(n, initial.clone()),
            Field::uniform(n, n / 2),
            Field {
                tracks: n,
                red: RedCount::unknown_uniform(n),
                initial_red: None,
            },
        ];
        for field in fields {
            for leaders in [1, 2, 4] {
                shares_equal_the_whole(field.clone(), options.clone(), &events, leaders);
            }
            // The one holder of the whole belief weighs by all of it.
            let coupled = FactoredOptions {
                coupling: Coupling::Coupled,
                ..options.clone()
            };
            shares_equal_the_whole(field, coupled, &events, 1);
        }
    }
}

/// The one holder of the whole belief runs the coupled rule: step for step
/// the centralized belief with it (not the local rule's answers), also
/// after its snapshot is read back midway, as a leader restarted from its
/// snapshot goes on; and once it has given a component away it refuses to
/// split by weights it no longer holds.
#[test]
fn the_one_holder_splits_by_the_whole_belief_also_from_its_snapshot() {
    let n = 16;
    let (initial, events) = workload(n, 400, 7);
    let options = FactoredOptions {
        max_component: 3,
        coupling: Coupling::Coupled,
        ..FactoredOptions::default()
    };
    let local = FactoredOptions {
        coupling: Coupling::Local,
        ..options.clone()
    };
    for field in [Field::known(n, initial.clone()), Field::uniform(n, 5)] {
        let mut whole = FactoredBelief::with_options(field.clone(), options.clone()).unwrap();
        let mut other = FactoredBelief::with_options(field.clone(), local.clone()).unwrap();
        let mut share = FactoredShare::start(field.clone(), options.clone(), |_| true).unwrap();
        let mut restored: Option<FactoredShare> = None;
        let mut apart = 0.0f64;
        for (i, event) in events.iter().enumerate() {
            let when = i as u64 + 1;
            let ok = whole.apply(event).is_ok();
            let _ = other.apply(event);
            if i == events.len() / 2 {
                let bytes = postcard::to_allocvec(&share).unwrap();
                restored = Some(postcard::from_bytes(&bytes).unwrap());
            }
            for s in std::iter::once(&mut share).chain(restored.as_mut()) {
                let applied = match *event {
                    Event::Mix(mix) => s.mix(mix, when),
                    Event::Observe(o) => s.observe(o),
                };
                assert_eq!(applied.is_ok(), ok, "event {i}");
            }
            let want = whole.marginals().unwrap();
            let local = other.marginals().unwrap();
            for s in std::iter::once(&share).chain(restored.as_ref()) {
                let got = coupled_marginals(&field, &s.parts()).unwrap();
                for (t, (g, w)) in got.iter().zip(&want).enumerate() {
                    assert!((g - w).abs() < 1e-9, "event {i}, track {t}: {g} vs {w}");
                }
            }
            apart = want
                .iter()
                .zip(&local)
                .map(|(w, l)| (w - l).abs())
                .fold(apart, f64::max);
        }
        assert!(restored.is_some());
        assert!(whole.stats().splits > 0, "the stream never split");
        assert!(apart > 1e-6, "the coupled and the local rule never parted");
        // Given away, a component leaves the share without the whole.
        let gone = share.take(|c| c.contains(&0));
        assert!(!gone.is_empty());
        let e = share
            .mix(
                Mix {
                    a: 1,
                    b: 2,
                    swap: 0.5,
                },
                1_000,
            )
            .unwrap_err()
            .to_string();
        assert!(e.contains("coupled rule"), "{e}");
    }
}

#[test]
fn a_share_refuses_what_does_not_fit_by_name() {
    let field = Field::uniform(4, 2);
    let options = FactoredOptions {
        coupling: Coupling::Local,
        ..FactoredOptions::default()
    };
    let coupled = FactoredShare::start(field.clone(), FactoredOptions::default(), |t| t < 2);
    assert!(coupled.unwrap_err().to_string().contains("coupled rule"));
    let mut share = FactoredShare::start(field.clone(), options, |t| t < 2).unwrap();
    let comp = |tracks: Vec<u32>, table: Vec<f64>| HeldComponent {
        last_mix: vec![0; tracks.len()],
        tracks,
        table,
        log_scale: 0.0,
    };
    for (c, says) in [
        (comp(vec![1], vec![0.5, 0.5]), "held here"),
        (comp(vec![2, 3], vec![1.0; 3]), "3 numbers"),
        (comp(vec![2, 2], vec![1.0; 4]), "twice"),
        (comp(vec![9], vec![1.0; 2]), "out of range"),
        (comp(vec![3], vec![f64::NAN, 1.0]), "NaN"),
    ] {
        let e = share.put(vec![c]).unwrap_err().to_string();
        assert!(e.contains(says), "{e}");
    }
    let e = share
        .mix(
            Mix {
                a: 0,
                b: 2,
                swap: 0.5,
            },
            1,
        )
        .unwrap_err()
        .to_string();
    assert!(e.contains("does not hold both"), "{e}");
    let parts = share.parts();
    let e = coupled_marginals(&field, &parts).unwrap_err().to_string();
    assert!(e.contains("no component holds track 2"), "{e}");
    share.put(vec![comp(vec![2, 3], vec![0.25; 4])]).unwrap();
    let p = coupled_marginals(&field, &share.parts()).unwrap();
    assert!((p.iter().sum::<f64>() - 2.0).abs() < 1e-12, "{p:?}");
}

/// A kept coupling asked again about the same parts answers from what it
/// computed; bad parts are refused by name and leave it as it was.
#[test]
fn a_kept_coupling_answers_an_unchanged_cut_from_memory() {
    let n = 10;
    let (initial, events) = workload(n, 120, 4);
    let field = Field::known(n, initial);
    let options = FactoredOptions {
        max_component: 3,
        coupling: Coupling::Local,
        ..FactoredOptions::default()
    };
    let mut share = FactoredShare::start(field.clone(), options, |_| true).unwrap();
    for (i, e) in events.iter().enumerate() {
        let _ = match *e {
            Event::Mix(m) => share.mix(m, i as u64 + 1),
            Event::Observe(o) => share.observe(o),
        };
    }
    let parts = share.parts();
    let mut kept = CouplingTree::new(field.clone()).unwrap();
    let first = kept.marginals(parts.iter()).unwrap();
    assert!(kept.last.is_some());
    assert_eq!(kept.marginals(parts.iter()).unwrap(), first);
    let mut bad = parts.clone();
    bad.pop();
    let e = kept.marginals(bad.iter()).unwrap_err().to_string();
    assert!(e.contains("no component holds track"), "{e}");
    assert_eq!(kept.marginals(parts.iter()).unwrap(), first);
    let fresh = coupled_marginals(&field, &parts).unwrap();
    for (k, f) in first.iter().zip(&fresh) {
        assert!((k - f).abs() < 1e-12, "{k} vs {f}");
    }
}

/// A leader looks for the components left without a track it surveils at
/// every handover it makes, among those changed since its last look and
/// those of the track it released (`take_changed`); what it finds is what a
/// look at everything it holds (`take`) finds, through mixes that merge and
/// split, relabels, sightings that split off certain tracks, components
/// coming and going, and tracks handed over both ways, split off or not.
/// Leader 0 is watched; leader 1 holds what leader 0 sends away.
#[test]
fn the_components_left_without_a_surveilled_track_are_found_among_the_changed() {
    let mut total = 0;
    for seed in 1..=6 {
        let n = 30;
        let (initial, events) = workload(n, 400, seed);
        let options = FactoredOptions {
            max_component: 3,
            coupling: Coupling::Local,
            ..FactoredOptions::default()
        };
        let field = Field::known(n, initial);
        // Which leader surveils each track.
        let mut surveils: Vec<usize> = (0..n).map(|t| t % 2).collect();
        let mut shares: Vec<FactoredShare> = (0..2)
            .map(|l| {
                FactoredShare::start(field.clone(), options.clone(), |t| t as usize % 2 == l)
                    .unwrap()
            })
            .collect();
        let holder =
            |shares: &[FactoredShare], t: u32| shares.iter().position(|s| s.holds(t)).unwrap();
        let mut found = 0;
        for (i, event) in events.iter().enumerate() {
            let when = i as u64 + 1;
            match *event {
                Event::Mix(mix) if mix.swap == 1.0 => {
                    let (ha, hb) = (holder(&shares, mix.a), holder(&shares, mix.b));
                    shares[ha].mix(mix, when).unwrap();
                    if ha != hb {
                        shares[hb].mix(mix, when).unwrap();
                    }
                }
                Event::Mix(mix) if mix.swap > 0.0 => {
                    let (ha, hb) = (holder(&shares, mix.a), holder(&shares, mix.b));
                    if ha != hb {
                        let comp = shares[hb].take_of(&[mix.b], |_| true);
                        shares[ha].put(comp).unwrap();
                    }
                    let _ = shares[ha].mix(mix, when);
                }
                Event::Mix(_) => {}
                Event::Observe(o) => {
                    let h = holder(&shares, o.track);
                    let _ = shares[h].observe(o);
                }
            }
            // A track changes leader: the old one (split it off its
            // component now and then, as the regional rule does).
            let t = (i * 7 % n) as u32;
            let from = surveils[t as usize];
            if i % 4 == 0 {
                let h = holder(&shares, t);
                shares[h].split_off(t).unwrap();
            }
            surveils[t as usize] = 1 - from;
            if from != 0 {
                continue;
            }
            let homeless = |tracks: &[u32]| tracks.iter().all(|&u| surveils[u as usize] != 0);
            let want = shares[0].clone().take(homeless);
            let got = shares[0].take_changed(&[t], homeless);
            assert_eq!(got, want, "seed {seed}, event {i}");
            found += got.len();
            shares[1].put(got).unwrap();
        }
        assert!(
            found > 0,
            "seed {seed}: no component was left without a track"
        );
        total += found;
    }
    assert!(
        total > 40,
        "only {total} components were left without a track"
    );
}
