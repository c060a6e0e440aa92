//! The support floor: a mass (a Radon coefficient, a factored table's
//! entry) that the events allow is never stored as 0. Products and
//! quotients whose exact value is not 0 but rounds below the smallest
//! normal f64 are stored at that magnitude, so that a set the reads allow
//! stays in the support and a later sighting of it finds mass. Shared by
//! the Radon engine and the factored belief's tables.

/// The least magnitude a mass the events allow is stored with: the
/// smallest normal f64. Masses are renormalized to sum 1 after every
/// conditioning, and sightings 10^200 times likelier for the wrong colour
/// take an atom below the smallest f64 in two steps; flushed to 0, a later
/// certain sighting could find no mass on a valid stream. The floor moves
/// a mass by at most 2.2·10^-308 and keeps the support exact.
pub(crate) const SUPPORT_FLOOR: f64 = f64::MIN_POSITIVE;

/// m·factor, its magnitude raised to [`SUPPORT_FLOOR`] when the exact
/// product is not 0 but rounds below it.
#[inline]
pub(crate) fn floored(m: f64, factor: f64) -> f64 {
    let x = m * factor;
    if x.abs() < SUPPORT_FLOOR && m != 0.0 && factor != 0.0 {
        SUPPORT_FLOOR.copysign(x)
    } else {
        x
    }
}

/// m/total, floored as [`floored`] is: the renormalization of the whole
/// belief and of a leader's share, bit for bit the same.
#[inline]
pub(crate) fn floored_div(m: f64, total: f64) -> f64 {
    let x = m / total;
    if x.abs() < SUPPORT_FLOOR && m != 0.0 {
        SUPPORT_FLOOR.copysign(x)
    } else {
        x
    }
}
