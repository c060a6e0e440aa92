//! What the property tests of every approximation share: random fields
//! (known start, uniform prior, unknown count with a lopsided prior) and
//! random event streams with red, blue and certain sightings and swaps of 0,
//! 1 and in between, all compared against the exact dense filter.

#![allow(dead_code)] // each test file uses its own part

pub mod valid;

use idmesh_belief::{Event, Field, Mix, Observe, RedCount};
use proptest::prelude::*;

#[derive(Debug, Clone)]
pub enum Start {
    Uniform,
    Known,
    UnknownCount,
}

pub fn field(n: usize, k: usize, start: &Start, seed: u64) -> Field {
    match start {
        Start::Uniform => Field::uniform(n, k),
        Start::Known => {
            // A seeded choice of k distinct tracks.
            let mut ids: Vec<u32> = (0..n as u32).collect();
            let mut s = seed;
            for i in (1..ids.len()).rev() {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ids.swap(i, (s >> 33) as usize % (i + 1));
            }
            Field::known(n, ids[..k].to_vec())
        }
        Start::UnknownCount => {
            // A lopsided prior over the count, to see it used.
            let prior = (0..=n)
                .map(|j| 1.0 + ((j + seed as usize) % 4) as f64)
                .collect();
            Field {
                tracks: n,
                red: RedCount::Unknown { prior },
                initial_red: None,
            }
        }
    }
}

pub fn likelihood() -> impl Strategy<Value = (f64, f64)> {
    prop_oneof![
        (0.01f64..1.0, 0.01f64..1.0),
        Just((0.8, 0.2)),
        Just((0.1, 0.7)),
        Just((1.0, 0.0)),
        Just((0.0, 1.0)),
    ]
}

pub fn swap() -> impl Strategy<Value = f64> {
    prop_oneof![0.0f64..=1.0, Just(0.0), Just(1.0), Just(0.5)]
}

pub fn events(n: usize, len: usize) -> impl Strategy<Value = Vec<Event>> {
    let n = n as u32;
    let one = prop_oneof![
        3 => (0..n, 1..n, swap()).prop_map(move |(a, d, swap)| Event::Mix(Mix {
            a,
            b: (a + d) % n,
            swap
        })),
        2 => (0..n, likelihood()).prop_map(|(track, (red, blue))| Event::Observe(Observe {
            track,
            red,
            blue
        })),
    ];
    prop::collection::vec(one, 0..len)
}

pub fn case(
    max_n: usize,
    len: usize,
) -> impl Strategy<Value = (usize, usize, Start, u64, Vec<Event>)> {
    (2usize..=max_n).prop_flat_map(move |n| {
        (
            Just(n),
            0..=n,
            prop_oneof![
                Just(Start::Uniform),
                Just(Start::Known),
                Just(Start::UnknownCount)
            ],
            any::<u64>(),
            events(n, len),
        )
    })
}

/// Equal to 1e-9, element by element.
pub fn assert_close(a: &[f64], b: &[f64], what: &str) {
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(b) {
        assert!((x - y).abs() < 1e-9, "{what}: {a:?} vs {b:?}");
    }
}
