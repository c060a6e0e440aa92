//! The factored colour belief on long *valid* streams: a hidden truth (which
//! targets are red, and where each went at every mix) is drawn along with
//! the stream, so every observation has a positive likelihood for the true
//! colour of its track and the exact filter would never run out of mass.
//! Observations of every kind are drawn: soft ones, certain ones (the other
//! colour's likelihood 0), and contradicting ones (a likelihood a billion
//! times or 10^200 times higher for the wrong colour, but never 0 for the
//! right one). Fields of up to a few hundred tracks, thousands of events.
//!
//! Whatever the coupling of the splits (coupled, local, flat) and for a
//! leader's share holding every track, the belief must take every event
//! and answer finite marginals in [0, 1] that sum to k (k known), with a
//! finite normalizer: an approximation may be far from the exact filter,
//! but it may not halt on a stream the world could have produced.

use idmesh_belief::{coupled_marginals, FactoredShare};
use idmesh_belief::{
    Coupling, Event, FactoredBelief, FactoredOptions, Field, Mix, Observe, PropertyFilter,
    SplitRule,
};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

mod common;
use common::valid::{check_marginals, contradicting_stream};

/// A stream and the truth behind it: `n` tracks, `k` red, `len` events.
fn valid_stream(n: usize, k: usize, len: usize, seed: u64) -> (Vec<u32>, Vec<Event>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut red = vec![false; n];
    let mut ids: Vec<usize> = (0..n).collect();
    for i in 0..k {
        let j = rng.gen_range(i..n);
        ids.swap(i, j);
        red[ids[i]] = true;
    }
    let initial: Vec<u32> = (0..n as u32).filter(|&t| red[t as usize]).collect();
    let mut events = Vec::with_capacity(len);
    for _ in 0..len {
        if n >= 2 && rng.gen_bool(0.5) {
            let a = rng.gen_range(0..n);
            // Mostly neighbours, as crowds mix; sometimes anyone.
            let b = if rng.gen_bool(0.8) {
                (a + rng.gen_range(1..=4.min(n - 1))) % n
            } else {
                (a + rng.gen_range(1..n)) % n
            };
            let swap = match rng.gen_range(0..6) {
                0 => 0.0,
                1 => 1.0,
                2 => 0.5,
                3 => rng.gen_range(1e-9..1e-3),
                4 => 1.0 - rng.gen_range(1e-9..1e-3),
                _ => rng.gen_range(0.0..1.0),
            };
            if rng.gen_bool(swap) {
                red.swap(a, b);
            }
            events.push(Event::Mix(Mix {
                a: a as u32,
                b: b as u32,
                swap,
            }));
        } else {
            let t = rng.gen_range(0..n);
            // (likelihood of the true colour, of the other one)
            let (right, wrong) = match rng.gen_range(0..8) {
                0 => (1.0, 0.0),
                1 => (0.8, 0.2),
                2 => (0.2, 0.8),
                // Contradicting: far likelier for the wrong colour.
                3 => (1e-3, 1.0),
                4 => (1e-2, 1.0),
                5 => (1.0, 1.0),
                6 => (rng.gen_range(1e-6..1.0), 0.0),
                _ => (rng.gen_range(1e-3..1.0), rng.gen_range(0.0..1.0)),
            };
            let (r, b) = if red[t] {
                (right, wrong)
            } else {
                (wrong, right)
            };
            events.push(Event::Observe(Observe {
                track: t as u32,
                red: r,
                blue: b,
            }));
        }
    }
    (initial, events)
}

/// k, the field (known start or uniform prior) and a valid stream on it:
/// n tracks in `tracks`, a red share in `share`, `events` events.
fn case(
    tracks: std::ops::RangeInclusive<usize>,
    share: std::ops::RangeInclusive<f64>,
    events: std::ops::RangeInclusive<usize>,
) -> impl Strategy<Value = (usize, Field, Vec<Event>)> {
    (tracks, share, any::<bool>(), any::<u64>(), events).prop_map(
        |(n, k_share, known, seed, len)| {
            let k = ((n as f64 * k_share).round() as usize).min(n);
            let (initial, events) = valid_stream(n, k, len, seed);
            let field = if known {
                Field::known(n, initial)
            } else {
                Field::uniform(n, k)
            };
            (k, field, events)
        },
    )
}

/// Up to 300 tracks, 200 to 3000 events.
fn valid_case() -> impl Strategy<Value = (usize, Field, Vec<Event>)> {
    case(2..=300, 0.0..=1.0, 200..=3000)
}

/// Long valid streams on fields to 80 tracks: 5,000 to 20,000 events.
/// Sightings that contradict the truth favour red for a blue target, so
/// over a long stream every table leans red by hundreds of nats a track
/// while a known count holds the total down: the tables and the count
/// weights drift apart, and whatever is computed from their products must
/// not underflow.
fn long_case() -> impl Strategy<Value = (usize, Field, Vec<Event>)> {
    case(2..=80, 0.0..=0.5, 5000..=20000)
}

fn coupling() -> impl Strategy<Value = Coupling> {
    prop_oneof![
        Just(Coupling::Coupled),
        Just(Coupling::Local),
        Just(Coupling::Flat)
    ]
}

fn split() -> impl Strategy<Value = SplitRule> {
    prop_oneof![
        3 => Just(SplitRule::Original),
        1 => Just(SplitRule::Recent),
        1 => Just(SplitRule::LeastLoss { rounds: 1 }),
    ]
}

/// Applies `events` and checks the marginals and the normalizer every 97
/// events and at the end.
fn takes_every_event(
    field: Field,
    options: FactoredOptions,
    k: usize,
    events: &[Event],
) -> Result<(), TestCaseError> {
    let mut belief = FactoredBelief::with_options(field, options).unwrap();
    for (i, e) in events.iter().enumerate() {
        if let Err(err) = belief.apply(e) {
            return Err(TestCaseError::fail(format!("event {i} {e:?}: {err}")));
        }
        if i % 97 == 0 || i + 1 == events.len() {
            let p = belief.marginals().map_err(|err| {
                TestCaseError::fail(format!("marginals after event {i} {e:?}: {err}"))
            })?;
            check_marginals(&p, k, i)?;
            // (A stream that contradicts itself across components has no
            // evidence left: the contradiction rule answers its queries.)
            let ln_z = belief.log_normalizer();
            let contradicted = belief.query_repairs() > 0;
            prop_assert!(
                ln_z.is_finite() || contradicted,
                "ln Z = {} after event {}",
                ln_z,
                i
            );
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn factored_takes_every_valid_stream(
        (k, field, events) in valid_case(),
        max in 1usize..=8,
        split in split(),
        coupling in coupling(),
    ) {
        let options = FactoredOptions { max_component: max, split, coupling, ..FactoredOptions::default() };
        takes_every_event(field, options, k, &events)?;
    }

    /// Every coupling, on long streams whose tables lean hundreds of
    /// orders of magnitude against the count weights (and, in the share
    /// test below, the coordinator's coupled query over a leader's parts).
    #[test]
    fn factored_takes_every_long_valid_stream(
        (k, field, events) in long_case(),
        max in 4usize..=8,
        split in split(),
        coupling in coupling(),
    ) {
        let options = FactoredOptions { max_component: max, split, coupling, ..FactoredOptions::default() };
        takes_every_event(field, options, k, &events)?;
    }

    #[test]
    fn a_share_takes_every_long_valid_stream(
        (k, field, events) in long_case(),
        max in 4usize..=8,
        flat in any::<bool>(),
    ) {
        // The leaders' rules; a share under the coupled rule is the whole
        // belief, which the long test above drives.
        let coupling = if flat { Coupling::Flat } else { Coupling::Local };
        let options = FactoredOptions { max_component: max, coupling, ..FactoredOptions::default() };
        share_takes_every_event(field, options, k, &events)?;
    }

    #[test]
    fn a_share_takes_every_valid_stream(
        (k, field, events) in valid_case(),
        max in 1usize..=8,
        coupling in coupling(),
    ) {
        let options = FactoredOptions { max_component: max, coupling, ..FactoredOptions::default() };
        share_takes_every_event(field, options, k, &events)?;
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(128))]

    /// A stream that contradicts itself never stops the belief: every
    /// sighting is taken (by the repair rule where the belief ruled it
    /// out) or set aside (where the prior rules it out), and every query
    /// answers marginals that sum to k (by the contradiction rule where
    /// the components together allow no count). A leader's share and the
    /// coordinator's coupling answer the same to 1e-9.
    #[test]
    fn a_contradicting_stream_never_stops_the_belief(
        n in 2usize..=120,
        k_share in 0.0f64..=1.0,
        known in any::<bool>(),
        seed in any::<u64>(),
        len in 20usize..=2000,
        max in 1usize..=8,
        split in split(),
        coupling in coupling(),
    ) {
        let k = ((n as f64 * k_share).round() as usize).min(n);
        let field = if known { Field::known(n, (0..k as u32).collect()) } else { Field::uniform(n, k) };
        let events = contradicting_stream(n, len, seed);
        let options = FactoredOptions { max_component: max, split, coupling, ..FactoredOptions::default() };
        takes_every_event(field.clone(), options.clone(), k, &events)?;
        {
            // The one holder of the whole belief, under every rule.
            let mut belief = FactoredBelief::with_options(field.clone(), options.clone()).unwrap();
            let mut share = FactoredShare::start(field.clone(), options, |_| true).unwrap();
            for (i, e) in events.iter().enumerate() {
                belief.apply(e).map_err(|err| TestCaseError::fail(format!("event {i}: {err}")))?;
                match e {
                    Event::Mix(m) => share.mix(*m, i as u64),
                    Event::Observe(o) => share.observe(*o),
                }
                .map_err(|err| TestCaseError::fail(format!("share, event {i}: {err}")))?;
            }
            let offline = belief.marginals().map_err(|err| TestCaseError::fail(err.to_string()))?;
            let live = coupled_marginals(&field, &share.parts()).map_err(|err| TestCaseError::fail(err.to_string()))?;
            for (t, (a, b)) in offline.iter().zip(&live).enumerate() {
                prop_assert!((a - b).abs() < 1e-9, "track {}: {} vs {}", t, a, b);
            }
        }
    }
}

/// A leader's share holding every track applies `events`; the coupled
/// marginals over its parts (what the coordinator answers) are checked
/// every 97 events and at the end.
fn share_takes_every_event(
    field: Field,
    options: FactoredOptions,
    k: usize,
    events: &[Event],
) -> Result<(), TestCaseError> {
    let mut share = FactoredShare::start(field.clone(), options, |_| true).unwrap();
    for (i, e) in events.iter().enumerate() {
        let done = match e {
            Event::Mix(m) => share.mix(*m, i as u64),
            Event::Observe(o) => share.observe(*o),
        };
        if let Err(err) = done {
            return Err(TestCaseError::fail(format!("event {i} {e:?}: {err}")));
        }
        if i % 97 == 0 || i + 1 == events.len() {
            let p = coupled_marginals(&field, &share.parts()).map_err(|err| {
                TestCaseError::fail(format!("marginals after event {i} {e:?}: {err}"))
            })?;
            check_marginals(&p, k, i)?;
        }
    }
    Ok(())
}

/// The stream that halted the belief when tracks within 10^-12 of certain
/// were split off as certain: two tracks, one red, mix; a sighting makes
/// the truth (the other one is red now) a 10^-13 chance; a certain
/// sighting then confirms it. The exact filter takes it; so must every
/// coupling (the split-off kept none of that 10^-13, and the pair's
/// correlation with it, and the belief found no mass).
#[test]
fn a_truth_made_unlikely_then_seen_for_certain_is_taken() {
    for coupling in [Coupling::Coupled, Coupling::Local, Coupling::Flat] {
        let field = Field::known(4, vec![0, 2]);
        let options = FactoredOptions {
            coupling,
            ..FactoredOptions::default()
        };
        let mut belief = FactoredBelief::with_options(field, options).unwrap();
        let events = [
            Event::Mix(Mix {
                a: 0,
                b: 1,
                swap: 0.5,
            }),
            // Track 1 is red (the targets swapped), seen as all but blue.
            Event::Observe(Observe {
                track: 1,
                red: 1e-13,
                blue: 1.0,
            }),
            // Track 0 is blue, seen for certain.
            Event::Observe(Observe {
                track: 0,
                red: 0.0,
                blue: 1.0,
            }),
        ];
        for e in &events {
            belief
                .apply(e)
                .unwrap_or_else(|err| panic!("{coupling:?}, {e:?}: {err}"));
        }
        let p = belief.marginals().unwrap();
        assert!(
            p[0].abs() < 1e-12 && (p[1] - 1.0).abs() < 1e-12,
            "{coupling:?}: {p:?}"
        );
    }
}

/// With no red target, sets holding a red track weigh nothing, but a
/// component's table kept them; sightings that favour red 10^200 to 1
/// (valid: blue keeps a positive likelihood) then underflowed the one set
/// that matters under their scale, and the next sighting was refused.
#[test]
fn sets_the_count_rules_out_do_not_hold_a_table_s_scale() {
    for coupling in [Coupling::Coupled, Coupling::Local, Coupling::Flat] {
        let options = FactoredOptions {
            coupling,
            ..FactoredOptions::default()
        };
        let mut belief = FactoredBelief::with_options(Field::uniform(3, 0), options).unwrap();
        belief
            .apply(&Event::Mix(Mix {
                a: 0,
                b: 1,
                swap: 0.5,
            }))
            .unwrap();
        for _ in 0..3 {
            let seen = Event::Observe(Observe {
                track: 0,
                red: 1.0,
                blue: 1e-200,
            });
            belief
                .apply(&seen)
                .unwrap_or_else(|err| panic!("{coupling:?}: {err}"));
        }
        assert_eq!(belief.marginals().unwrap(), vec![0.0; 3], "{coupling:?}");
    }
}

/// Streams the property tests found halting the coupled belief, each a
/// member of one class: count weights and tables leaning 10^30 a red track
/// apart, their products taken as they came.
/// - (n 23, k 4): the count tree flushed the rest's weights to 0 at counts
///   the component held (10^-81 where its own table held 10^67 more), the
///   certainty test took a track with P(red) = 0.92 for certain blue, and
///   a certain sighting of it red found no mass;
/// - (n 58, k 6): a split's certainty test multiplied a table at 10^-297
///   by weights at 10^-30 (every product below 10^-308) and cut nine
///   tracks off as certain blue;
/// - (n 49, k 1, 17,680 events): a merge left a table all red at 1 (a
///   count the known count rules out) and the one count that matters at
///   10^-252, later at 0;
/// - (n 78, k 3, 11,350 events, both starts): a component held count 0 at
///   10^-319 (a subnormal) and count 1 at 10^-207 against weights leaning
///   10^109 the other way; the balanced weights capped the factor of
///   count 0, whose share was e^-8, and the marginals summed to 3.99.
///   Such sums are now taken in log space.
#[test]
fn streams_that_halted_the_coupled_belief_are_taken() {
    let cases: [(usize, usize, bool, u64, usize, usize, SplitRule); 5] = [
        (
            23,
            4,
            true,
            6730904944286581594,
            2779,
            6,
            SplitRule::LeastLoss { rounds: 1 },
        ),
        (
            58,
            6,
            true,
            12426236060244738125,
            2930,
            8,
            SplitRule::LeastLoss { rounds: 1 },
        ),
        (
            49,
            1,
            true,
            2238318247340994325,
            17680,
            6,
            SplitRule::Original,
        ),
        (
            78,
            3,
            false,
            4705270416714993086,
            11350,
            4,
            SplitRule::LeastLoss { rounds: 1 },
        ),
        (
            78,
            3,
            true,
            4705270416714993086,
            11350,
            4,
            SplitRule::LeastLoss { rounds: 1 },
        ),
    ];
    for (n, k, known, seed, len, max, split) in cases {
        let (initial, events) = valid_stream(n, k, len, seed);
        let field = if known {
            Field::known(n, initial)
        } else {
            Field::uniform(n, k)
        };
        let options = FactoredOptions {
            max_component: max,
            split,
            coupling: Coupling::Coupled,
            ..FactoredOptions::default()
        };
        if let Err(e) = takes_every_event(field, options, k, &events) {
            panic!("n {n}, k {k}, seed {seed}: {e}");
        }
    }
}

/// The coupled belief held a track certainly blue (rounding in a split,
/// where the exact filter says P(red) = 0.043) and refused a sure sighting
/// of red at event 9,289. The repair rule took it; now that products of
/// table entries keep the sets both factors allow, the support is kept
/// and no repair is needed.
#[test]
fn a_sure_sighting_the_coupled_belief_rounded_away_is_taken() {
    let (n, k, seed, len) = (33, 2, 2u64, 9300);
    let (_initial, events) = valid_stream(n, k, len, seed);
    let field = Field::uniform(n, k);
    let options = FactoredOptions {
        max_component: 4,
        split: SplitRule::Recent,
        coupling: Coupling::Coupled,
        ..FactoredOptions::default()
    };
    let mut belief = FactoredBelief::with_options(field, options).unwrap();
    for (i, e) in events.iter().enumerate() {
        if let Err(err) = belief.apply(e) {
            panic!("event {i} {e:?}: {err}; stats {:?}", belief.stats());
        }
    }
    assert_eq!(belief.stats().repairs, 0, "{:?}", belief.stats());
    check_marginals(&belief.marginals().unwrap(), k, len).unwrap();
}
