//! The tracking pipeline of Section IV, one module per step.
//!
//! - [`prepare`] — (1) preparation: sensor groups and overlapping segments.
//! - [`separate`] — (2) separation: FastICA on every segment group.
//! - [`cluster`] — (3) clustering: agglomerative, 1 − |corr|, 2K per slot.
//! - [`select`] — (4) selection: link correlation over n_slot slots.
//! - [`intersect`] — (5) intersection of the hearing groups' ranges, on
//!   the 5 m tiles of [`tiles`].
//! - [`vote_link`] — (6) voting and path linking (Appendix A).

pub(crate) mod cluster;
pub(crate) mod intersect;
pub(crate) mod prepare;
pub(crate) mod select;
pub(crate) mod separate;
pub(crate) mod tiles;
pub(crate) mod vote_link;
