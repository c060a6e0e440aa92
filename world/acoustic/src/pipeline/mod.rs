//! The tracking pipeline of Section IV, one module per step.
//!
//! - [`prepare`] — (1) preparation: sensor groups and overlapping segments.
//! - [`separate`] — (2) separation: FastICA on every segment group.
//! - [`cluster`] — (3) clustering: agglomerative, 1 − |corr|, 2K per slot.
//! - [`select`] — (4) selection: link correlation over n_slot slots.
//! - [`intersect`] — (5) intersection of the hearing groups' ranges, on
//!   the 5 m tiles of [`tiles`].
//! - [`vote_link`] — (6) voting and path linking (Appendix A).

pub mod cluster;
pub mod intersect;
pub mod prepare;
pub mod select;
pub mod separate;
pub mod tiles;
pub mod vote_link;
