//! # idmesh-identity — which track carries which identity
//!
//! The identity beliefs of idmesh, beside the property beliefs of
//! `idmesh-belief` and in the same layer: the engines, which depend only on
//! the wire (`idmesh-protocol`) and on each other. It implements Shin,
//! Lee, Thrun and Guibas, *Lazy Inference on Object Identities in Wireless
//! Sensor Networks* (IPSN 2005): identities kept as an information matrix
//! of accumulated log-likelihoods, normalization put off until a query
//! asks, the least-squares mixing rule, Metropolis sampling for the
//! marginals and the matrix's rows spread over the agents that follow the
//! tracks; and, for identities coded by properties, Section 5.5 and Table
//! IV of Jiang et al. (TOSN 2013).
//!
//! N tracks carry N targets with distinct identities; p\[t\]\[i\] = P(track
//! t carries identity i). Targets that come close may swap tracks (a
//! [`Mix`](idmesh_belief::Mix)); sensors now and then read an identity on a
//! track ([`Identify`]). This crate keeps beliefs over the N! assignments
//! under those two events. Pure, synchronous, no I/O; every update is
//! all-or-nothing. From `idmesh-belief` it takes the mix event, the
//! errors ([`BeliefError`](idmesh_belief::BeliefError)), the property
//! scores and, for identities coded by property bits, the Radon belief.
//!
//! A map, one idea per file (private modules behind the re-exports below;
//! `factored`, `scoring` and `workload` are public namespaces):
//! - `event` — the [`Identify`] read and its accuracy model (Definition 3),
//!   [`IdentityEvent`], and input checks.
//! - `from_trace` — [`identity_event_of`], the identity event a trace
//!   line carries (the property events are `idmesh_belief::from_trace`'s).
//! - `filter` — [`IdentityFilter`], the interface every belief offers.
//! - `assignment` — [`most_likely_assignment`] (Hungarian algorithm) and
//!   [`identity_error`].
//! - `permutation` — the N! assignments indexed by Lehmer rank.
//! - `exact` — [`ExactPermutationFilter`], the exact filter (Section 2),
//!   N ≤ 9: the yardstick.
//! - [`factored`] — [`FactoredIdentity`], exact over the small groups of
//!   tracks that mixed, split by the least lossy cut when a join would
//!   outgrow a cap (split/join of Huang, Guestrin and Guibas).
//! - `belief_matrix` — [`BeliefMatrix`], the doubly stochastic marginals of
//!   Shin et al. 2003, renormalized by Sinkhorn after every read.
//! - `information` — [`InformationMatrix`], accumulated log-likelihoods
//!   (Section 3): O(1) reads, the least-squares mixing rule (the paper's
//!   pseudoinverse and an O(N²) closed form), and what "exact for N ≤ 3"
//!   really requires.
//! - `support_mix` — the mixing rule for rows that rule identities out
//!   (−∞ entries, e.g. an exact known start): exact when two blocks meet.
//! - `blocks` — the independent blocks of a belief (the groups of tracks
//!   mixing has connected since a known start), which every marginal
//!   method answers one at a time.
//! - `rows` — [`InformationRows`], one leader's rows of an information
//!   matrix: reads applied locally, rows exchanged at a mix across leaders,
//!   the whole matrix assembled only for a query (Section 4's distribution).
//! - `marginals`, `permanent`, `metropolis`, `sinkhorn` — marginals
//!   of an information matrix on demand ([`MarginalMethod`]): exact by the
//!   permanent (Ryser or Glynn, Gray code, all N² marginals in one pass),
//!   the paper's Metropolis sampler, Sinkhorn scaling, and a fractional
//!   Bethe fixed point. `sinkhorn` is also the doubly stochastic scaling
//!   the belief matrix and the property-bits filter use.
//! - `property_bits` — [`PropertyBitsFilter`]: identities coded by b
//!   binary properties, one Radon property belief per bit (TOSN Sec. 5.5).
//! - `sparse_marginals` — [`SparseMarginals`], marginals by row: the
//!   identities a track may carry and one probability for all others; the
//!   form answers take, and the most likely assignment over it at any N
//!   (`sparse_assignment`).
//! - [`scoring`] — Brier, log-loss, MAP accuracy, IDF1 and reliability of
//!   identity marginals against the truth.
//! - [`workload`] — seeded random identity event streams with ground truth.

/// The line of docs/identity-paper.md that says which code made it: the
/// digest of the identity engine's sources and the `identity_results`
/// example (build.rs).
pub fn paper_stamp_line() -> String {
    format!(
        "<!-- idmesh identity stamp: sources {} -->",
        env!("IDMESH_IDENTITY_PAPER_STAMP")
    )
}

mod assignment;
mod belief_matrix;
mod blocks;
mod event;
mod exact;
pub mod factored;
mod filter;
mod from_trace;
mod information;
mod marginals;
mod metropolis;
mod permanent;
mod permutation;
mod property_bits;
mod rows;
pub mod scoring;
mod sinkhorn;
mod sparse_assignment;
mod sparse_marginals;
mod support_mix;
pub mod workload;

// Events, and the identity event a trace line carries.
pub use event::{Identify, IdentityEvent};
pub use from_trace::identity_event_of;
// The interface every belief offers, and its answers.
pub use assignment::{identity_error, most_likely_assignment};
pub use filter::{max_abs_difference, to_rows, IdentityFilter};
pub use sparse_marginals::{IdentityRow, SparseMarginals};
// The beliefs: exact, factored, belief matrix, property bits.
pub use belief_matrix::BeliefMatrix;
pub use exact::ExactPermutationFilter;
pub use factored::{FactoredIdentity, FactoredIdentityOptions};
pub use property_bits::{BitCode, PropertyBitsFilter};
// The information matrix, its rows at one leader, and its mixing rules.
pub use information::{
    paper_merge, paper_merge_pinv, InformationMatrix, InformationOptions, MixSolver,
    KNOWN_START_CONFIDENCE,
};
pub use rows::InformationRows;
// Marginals on demand, and the blocks they are answered one at a time by.
pub use blocks::mixing_block_sizes;
pub use marginals::{BlockMarginals, MarginalMethod, DEFAULT_SAMPLES};
pub use permanent::MAX_PERMANENT_TRACKS;
pub use sinkhorn::SinkhornOptions;

#[cfg(test)]
mod stamp_tests {
    #[test]
    fn the_committed_paper_results_were_generated_by_the_code_as_it_is() {
        // Any change to the identity engine or to the results program
        // changes the stamp: regenerate docs/identity-paper.md and commit it.
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/identity-paper.md");
        let committed = std::fs::read_to_string(path).unwrap_or_default();
        assert!(
            committed.contains(&super::paper_stamp_line()),
            "docs/identity-paper.md is stale: it does not carry {:?}; regenerate it with \
             `cargo run --release -p idmesh-identity --example identity_results`",
            super::paper_stamp_line()
        );
    }
}
