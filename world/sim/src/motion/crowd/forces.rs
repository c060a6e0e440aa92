//! The accelerations of the social-force model: the driving term towards the
//! desired velocity, the exponential repulsion between two people (weaker
//! from behind), the repulsion of the four walls, and a small fluctuation.

use super::agent::standard_normal;
use super::CrowdParams;
use crate::geometry::{Rect, Vec2};
use rand_chacha::ChaCha8Rng;

/// (v0·e − v) / τ: relaxes the velocity towards the desired one.
pub(super) fn driving(desired: Vec2, vel: Vec2, relaxation: f64) -> Vec2 {
    (desired - vel) * (1.0 / relaxation)
}

/// Push on a person at `pos` looking along `heading` (unit or zero) from a
/// person at `other`: A·exp((2r − d)/B)·n, with n the unit vector from
/// `other` to `pos`, weighted by λ + (1 − λ)(1 + cos φ)/2 where φ is the
/// angle between the heading and the direction to the other person.
pub(super) fn between_people(pos: Vec2, heading: Vec2, other: Vec2, p: &CrowdParams) -> Vec2 {
    let diff = pos - other;
    let d = diff.norm();
    let n = if d > 1e-9 {
        diff * (1.0 / d)
    } else {
        // Exactly on top of each other: push along a fixed axis; the pair
        // separates on the next steps through the fluctuation.
        Vec2::new(1.0, 0.0)
    };
    let cos_phi = -n.dot(heading);
    let lambda = p.anisotropy;
    let weight = lambda + (1.0 - lambda) * (1.0 + cos_phi) / 2.0;
    n * (p.repulsion * ((2.0 * p.radius - d) / p.repulsion_range).exp() * weight)
}

/// Push from the four walls of `field`: A_w·exp((r − d_w)/B_w) along each
/// wall's inward normal, for walls within the interaction cutoff.
pub(super) fn from_walls(pos: Vec2, field: Rect, p: &CrowdParams) -> Vec2 {
    let push = |d: f64| {
        if d < p.interaction_cutoff {
            p.wall_repulsion * ((p.radius - d.max(0.0)) / p.wall_range).exp()
        } else {
            0.0
        }
    };
    Vec2::new(
        push(pos.x - field.min.x) - push(field.max.x - pos.x),
        push(pos.y - field.min.y) - push(field.max.y - pos.y),
    )
}

/// An independent normal fluctuation of each component, standard
/// deviation `sigma` (always two draws, so the random stream does not depend
/// on the value).
pub(super) fn fluctuation(rng: &mut ChaCha8Rng, sigma: f64) -> Vec2 {
    let x = standard_normal(rng);
    let y = standard_normal(rng);
    Vec2::new(x, y) * sigma
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn repulsion_is_stronger_close_and_in_front() {
        let p = CrowdParams::default();
        let east = Vec2::new(1.0, 0.0);
        // The other person is ahead (east) of us: we are pushed west.
        let near = between_people(Vec2::ZERO, east, Vec2::new(0.6, 0.0), &p);
        let far = between_people(Vec2::ZERO, east, Vec2::new(1.5, 0.0), &p);
        assert!(near.x < 0.0 && near.y == 0.0);
        assert!(near.norm() > far.norm());
        // The same person behind us pushes less.
        let behind = between_people(Vec2::ZERO, east, Vec2::new(-0.6, 0.0), &p);
        assert!(behind.x > 0.0);
        assert!((behind.norm() - near.norm() * p.anisotropy).abs() < 1e-12);
    }

    #[test]
    fn walls_push_inwards() {
        let p = CrowdParams::default();
        let field = Rect::with_size(10.0, 10.0);
        let a = from_walls(Vec2::new(0.3, 9.7), field, &p);
        assert!(a.x > 0.0 && a.y < 0.0);
        assert_eq!(from_walls(Vec2::new(5.0, 5.0), field, &p), Vec2::ZERO);
        assert_eq!(
            driving(Vec2::new(1.0, 0.0), Vec2::ZERO, 0.5),
            Vec2::new(2.0, 0.0)
        );
    }
}
