//! The local coupling (`Coupling::Local`: a split weighs the merged red
//! count s of m tracks by Σ_K π(K)·C(n − m, K − s), the uninformed rest)
//! where it must be exact (docs/design/beliefs.md, "The local rule"):
//! - while nothing is split it is the exact filter;
//! - while the merged count of every split is fixed (a known start and hard
//!   sightings) it is the coupled rule;
//! - disjoint events commute (what lets leaders apply them in any order).
//!
//! That its weight is the true one when the rest is uninformed is a unit
//! test beside the code (`the_local_weight_is_the_weight_of_an_uninformed_rest`).

use idmesh_belief::DenseFilter;
use idmesh_belief::{
    Coupling, Event, FactoredBelief, FactoredOptions, Mix, Observe, PropertyFilter,
};
use proptest::prelude::*;

mod common;
use common::{case, field};

fn close(a: &[f64], b: &[f64], tol: f64) -> Result<(), TestCaseError> {
    prop_assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        prop_assert!((x - y).abs() <= tol, "{:?} vs {:?}", a, b);
    }
    Ok(())
}

fn options(coupling: Coupling, max: usize) -> FactoredOptions {
    FactoredOptions {
        max_component: max,
        coupling,
        ..FactoredOptions::default()
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn unsplit_local_belief_is_the_exact_filter((n, k, start, seed, events) in case(10, 30)) {
        let field = field(n, k, &start, seed);
        let mut exact = DenseFilter::new(field.clone()).unwrap();
        let mut local = FactoredBelief::with_options(field, options(Coupling::Local, 12)).unwrap();
        for event in &events {
            let a = exact.apply(event);
            let b = local.apply(event);
            prop_assert!(a.is_ok(), "{:?} on {:?}", a, event);
            if exact.repairs() > 0 {
                // A sighting the whole belief rules out, taken by the
                // repair rule: the local rule repairs its component only;
                // nothing to compare after that.
                break;
            }
            prop_assert!(b.is_ok(), "{:?} on {:?}", b, event);
            close(&exact.marginals().unwrap(), &local.marginals().unwrap(), 1e-9)?;
        }
        prop_assert_eq!(local.stats().splits, 0);
    }

    #[test]
    fn local_is_coupled_while_the_merged_count_is_fixed(
        n in 4usize..=12,
        k_share in 0.0f64..=1.0,
        seed in any::<u64>(),
        max in 1usize..=4,
        events in common::events(12, 200),
    ) {
        let k = ((n as f64 * k_share) as usize).min(n);
        let field = field(n, k, &common::Start::Known, seed);
        let mut coupled = FactoredBelief::with_options(field.clone(), options(Coupling::Coupled, max)).unwrap();
        let mut local = FactoredBelief::with_options(field.clone(), options(Coupling::Local, max)).unwrap();
        // Only the sightings the exact filter takes without a repair: a
        // hard sighting of the wrong colour would be repaired, and the
        // repairs differ by rule.
        let mut exact = DenseFilter::new(field).unwrap();
        for e in &events {
            // Tracks of this field, and hard sightings only: every
            // component's count stays fixed until a split spreads it.
            let e = match *e {
                Event::Mix(m) => Event::Mix(Mix { a: m.a % n as u32, b: m.b % n as u32, swap: m.swap }),
                Event::Observe(o) => {
                    let red = o.red > o.blue;
                    Event::Observe(Observe {
                        track: o.track % n as u32,
                        red: if red { 1.0 } else { 0.0 },
                        blue: if red { 0.0 } else { 1.0 },
                    })
                }
            };
            if let Event::Mix(m) = e {
                if m.a == m.b {
                    continue;
                }
            }
            let before = exact.clone();
            exact.apply(&e).unwrap();
            if exact.repairs() > 0 {
                exact = before;
                continue;
            }
            let splits = coupled.stats().splits;
            coupled.apply(&e).unwrap();
            local.apply(&e).unwrap();
            close(&coupled.marginals().unwrap(), &local.marginals().unwrap(), 1e-9)?;
            if coupled.stats().splits > splits {
                // This split spread the counts of its halves.
                break;
            }
        }
    }

    #[test]
    fn disjoint_local_events_commute(
        (n, k, start, seed, events) in case(16, 40),
        max in 1usize..=4,
        flat in any::<bool>(),
    ) {
        let coupling = if flat { Coupling::Flat } else { Coupling::Local };
        let field = field(n, k, &start, seed);
        let mut ab = FactoredBelief::with_options(field.clone(), options(coupling, max)).unwrap();
        let mut ba = FactoredBelief::with_options(field, options(coupling, max)).unwrap();
        let tracks = |e: &Event| match e {
            Event::Mix(m) => vec![m.a, m.b],
            Event::Observe(o) => vec![o.track],
        };
        let mut i = 0;
        while i + 1 < events.len() {
            let (e, f) = (&events[i], &events[i + 1]);
            // Swap two neighbouring events whose components are disjoint.
            let comps = ab.components();
            let comp = |t: u32| comps.iter().position(|c| c.contains(&t));
            let (ce, cf): (Vec<_>, Vec<_>) = (
                tracks(e).into_iter().map(comp).collect(),
                tracks(f).into_iter().map(comp).collect(),
            );
            let disjoint = ce.iter().all(|c| !cf.contains(c));
            let (x, y) = if disjoint { (f, e) } else { (e, f) };
            let r1 = ab.apply(e).and_then(|()| ab.apply(f));
            let r2 = ba.apply(x).and_then(|()| ba.apply(y));
            prop_assert_eq!(r1.is_ok(), r2.is_ok());
            if r1.is_err() {
                break;
            }
            match (ab.marginals(), ba.marginals()) {
                (Ok(p), Ok(q)) => close(&p, &q, 1e-9)?,
                (Err(_), Err(_)) => break,
                (p, q) => prop_assert!(false, "{:?} vs {:?}", p, q),
            }
            i += 2;
        }
    }
}
