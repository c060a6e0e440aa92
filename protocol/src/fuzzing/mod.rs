//! The fuzz targets: one function per decoder of outside bytes, each given
//! any bytes at all. It must not panic on any of them, and what it accepts
//! must keep the promises its consumers rely on (a decoded message is
//! valid and survives re-encoding; a trace line the reader accepts, the
//! writer writes). The same functions run under cargo-fuzz (`fuzz/`, on
//! nightly, coverage-guided) and under a plain `cargo test` on stable
//! (`tests/fuzz_smoke.rs`: [`smoke`] on seeded inputs, plus every file of
//! the regression corpus `fuzz/regressions/<target>/`).
//!
//! - [`seeds`] — well-formed inputs of every target, to start from.
//! - [`mutate`] — a seeded generator of bad inputs from the seeds.

mod mutate;
mod seeds;

// Well-formed inputs of every target, to start from.
pub use seeds::seeds;

use crate::trace::{Header, Line, TraceReader, TraceWriter};
use crate::wire::bounds::Bounds;
use crate::wire::coordinator_to_leader::Partial;
use crate::wire::coordinator_to_sensor::CutPlaced;
use crate::wire::leader_to_leader::{Transfer, TransfersSent, TransfersWanted};
use crate::wire::leader_to_sensor::{Follow, Followed, Resend, Resent, Unfollow};
use crate::wire::sensor_to_leader::{Batch, Item};
use crate::wire::{decode, encode, Valid};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::fmt::Debug;

/// A fuzz target: any bytes in, a panic on a broken promise.
pub(crate) type Target = fn(&[u8]);

/// Every target by name (the names of `fuzz/fuzz_targets/*.rs` and of the
/// folders of `fuzz/regressions/`).
pub const TARGETS: &[(&str, Target)] = &[
    ("batch", batch),
    ("transfer", transfer),
    ("followed", followed),
    ("follow", follow),
    ("unfollow", unfollow),
    ("resend", resend),
    ("resent", resent),
    ("transfers_wanted", transfers_wanted),
    ("transfers_sent", transfers_sent),
    ("partial", partial),
    ("cut_placed", cut_placed),
    ("trace_line", trace_line),
    ("trace_reader", trace_reader),
];

/// The target called `name`.
pub fn target(name: &str) -> Option<Target> {
    TARGETS.iter().find(|(n, _)| *n == name).map(|(_, t)| *t)
}

/// Runs `target` on `runs` inputs made by [`mutate::Mutator`] from the
/// target's [`seeds`] with `seed`; returns how many were accepted (decoded
/// and valid), so a test can see the mutations reach past the decoder.
pub fn smoke(name: &str, runs: usize, seed: u64) -> usize {
    let Some(run) = target(name) else {
        return 0;
    };
    let seeds = seeds::seeds(name);
    let mut mutator = mutate::Mutator::new(seed);
    let mut accepted = 0;
    for _ in 0..runs {
        let input = mutator.input(&seeds);
        if accepts(name, &input) {
            accepted += 1;
        }
        run(&input);
    }
    accepted
}

/// Whether the decoder of `name` takes `bytes` (for the smoke run's count).
fn accepts(name: &str, bytes: &[u8]) -> bool {
    match name {
        "batch" => decode::<Batch>(bytes).is_ok(),
        "transfer" => decode::<Transfer>(bytes).is_ok(),
        "followed" => decode::<Followed>(bytes).is_ok(),
        "follow" => decode::<Follow>(bytes).is_ok(),
        "unfollow" => decode::<Unfollow>(bytes).is_ok(),
        "resend" => decode::<Resend>(bytes).is_ok(),
        "resent" => decode::<Resent>(bytes).is_ok(),
        "transfers_wanted" => decode::<TransfersWanted>(bytes).is_ok(),
        "transfers_sent" => decode::<TransfersSent>(bytes).is_ok(),
        "partial" => decode::<Partial>(bytes).is_ok(),
        "cut_placed" => decode::<CutPlaced>(bytes).is_ok(),
        "trace_line" => std::str::from_utf8(bytes).is_ok_and(|t| Line::parse(t).is_ok()),
        "trace_reader" => TraceReader::new(bytes, "fuzz").all(|l| l.is_ok()),
        _ => false,
    }
}

/// A field to check decoded messages against as a leader would: small, so
/// that random tracks and indices fall on both sides of its bounds.
const FIELD: Bounds = Bounds {
    tracks: 8,
    leaders: 3,
    identities: true,
    adopts: true,
};

/// Decodes `bytes` as a `T`; what decodes must be valid, re-encode to a
/// message that decodes to itself, and go through `then`.
fn message<T>(bytes: &[u8], then: impl FnOnce(&T))
where
    T: DeserializeOwned + Serialize + Valid + PartialEq + Debug,
{
    let Ok(message) = decode::<T>(bytes) else {
        return;
    };
    assert!(
        message.problem().is_none(),
        "decode let an invalid {message:?} through"
    );
    match decode::<T>(&encode(&message)) {
        Ok(again) => assert_eq!(again, message, "re-encoding changed the message"),
        Err(e) => panic!("{message:?} decoded, but not once re-encoded: {e}"),
    }
    then(&message);
}

pub fn batch(bytes: &[u8]) {
    message::<Batch>(bytes, |batch| {
        // A batch that opens a stream fits its own field by construction.
        if let Some(Item::Begin(begin)) = batch.items.first().map(|s| &s.item) {
            let own = Bounds::of(begin);
            assert!(
                own.check_batch(batch).is_ok(),
                "batch 0 misfits its own Begin"
            );
        }
        let _ = FIELD.check_batch(batch);
    });
}

pub fn transfer(bytes: &[u8]) {
    message::<Transfer>(bytes, |t| {
        let _ = FIELD.check_transfer(t, 0);
    });
}

pub fn followed(bytes: &[u8]) {
    message::<Followed>(bytes, |f| {
        let _ = FIELD.check_followed(&f.items);
    });
}

pub fn follow(bytes: &[u8]) {
    message::<Follow>(bytes, |_| {});
}

pub fn unfollow(bytes: &[u8]) {
    message::<Unfollow>(bytes, |_| {});
}

pub fn resend(bytes: &[u8]) {
    message::<Resend>(bytes, |_| {});
}

pub fn resent(bytes: &[u8]) {
    message::<Resent>(bytes, |r| {
        for b in &r.batches {
            let _ = FIELD.check_batch(b);
        }
    });
}

pub fn transfers_wanted(bytes: &[u8]) {
    message::<TransfersWanted>(bytes, |_| {});
}

pub fn transfers_sent(bytes: &[u8]) {
    message::<TransfersSent>(bytes, |s| {
        for t in &s.transfers {
            let _ = FIELD.check_transfer(t, 1);
        }
    });
}

pub fn partial(bytes: &[u8]) {
    message::<Partial>(bytes, |p| {
        let _ = FIELD.check_partial(p);
    });
}

pub fn cut_placed(bytes: &[u8]) {
    message::<CutPlaced>(bytes, |_| {});
}

/// One line of a trace: parsed, checked against a small identity field;
/// a line that parses, written back, parses to the same kind.
pub fn trace_line(bytes: &[u8]) {
    let Ok(text) = std::str::from_utf8(bytes) else {
        return;
    };
    match Line::parse(text) {
        Ok(line) => {
            let mut header = Header::new(8);
            header.red = Some(3);
            header.identities = Some(8);
            let _ = line.validate(&header).map_err(|p| p.to_string());
            let written = match serde_json::to_string(&line) {
                Ok(written) => written,
                Err(e) => panic!("{line:?} parsed but cannot be written: {e}"),
            };
            match Line::parse(&written) {
                Ok(again) => assert_eq!(again.kind(), line.kind()),
                Err(p) => panic!("{text:?} parsed, but not once written as {written:?}: {p}"),
            }
        }
        Err(problem) => {
            let _ = problem.to_string();
        }
    }
}

/// A whole trace: read to its end or first error; every line the reader
/// accepts the writer writes, and what it wrote reads back, line for line.
pub fn trace_reader(bytes: &[u8]) {
    let mut accepted = Vec::new();
    for result in TraceReader::new(bytes, "fuzz") {
        match result {
            Ok(line) => accepted.push(line.line),
            Err(e) => {
                assert!(e.line() >= 1, "an error at line 0: {e}");
                let _ = e.to_string();
            }
        }
    }
    if accepted.is_empty() {
        return;
    }
    let mut writer = TraceWriter::new(Vec::new(), "fuzz");
    for line in &accepted {
        if let Err(e) = writer.write(line) {
            panic!("the reader took {line:?}, the writer refuses it: {e}");
        }
    }
    let written = match writer.finish() {
        Ok(written) => written,
        Err(e) => panic!("a trace the reader took cannot be finished: {e}"),
    };
    let again: Result<Vec<_>, _> = TraceReader::new(&written[..], "written").collect();
    match again {
        Ok(again) => {
            let kinds = |lines: &mut dyn Iterator<Item = &Line>| -> Vec<&'static str> {
                lines.map(Line::kind).collect()
            };
            assert_eq!(
                kinds(&mut again.iter().map(|l| &l.line)),
                kinds(&mut accepted.iter())
            );
        }
        Err(e) => panic!("the writer wrote a trace the reader refuses: {e}"),
    }
}
