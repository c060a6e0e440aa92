//! A meeting as seen at the frame it starts: the two tracks, how far apart
//! they are, and — from their positions one frame earlier — how fast they
//! move relative to each other and how close they will come if they keep
//! their velocities. The swap probability is decided then, so that the
//! `mix` goes out at the frame the meeting starts (as the simulator logs
//! it) instead of waiting for the pair to part.

use crate::geometry::Vec2;
use serde::{Deserialize, Serialize};

/// One meeting of tracks `a` < `b` at `time`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Meeting {
    pub time: f64,
    pub a: u32,
    pub b: u32,
    /// Metres between them at `time` (≤ the mixing distance).
    pub distance: f64,
    /// The closest they come if both keep their velocity (metres, ≤
    /// `distance`); `distance` when a velocity is unknown.
    pub closest: f64,
    /// Their relative speed (m/s); 0 when a velocity is unknown.
    pub relative_speed: f64,
}

impl Meeting {
    /// The meeting of `a` at `pa` and `b` at `pb` at `time`; `va`, `vb` are
    /// their velocities when known (both needed for the prediction).
    pub fn predict(
        time: f64,
        (a, pa, va): (u32, Vec2, Option<Vec2>),
        (b, pb, vb): (u32, Vec2, Option<Vec2>),
    ) -> Meeting {
        let r = pb - pa;
        let distance = r.norm();
        let (closest, relative_speed) = match (va, vb) {
            (Some(va), Some(vb)) => {
                let v = vb - va;
                let speed_sq = v.norm_sq();
                if speed_sq > 0.0 {
                    // The time of closest approach, not in the past: a pair
                    // already moving apart is closest now.
                    let t = (-r.dot(v) / speed_sq).max(0.0);
                    ((r + v * t).norm(), speed_sq.sqrt())
                } else {
                    (distance, 0.0)
                }
            }
            _ => (distance, 0.0),
        };
        Meeting {
            time,
            a,
            b,
            distance,
            closest,
            relative_speed,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn head_on_walkers_are_predicted_to_pass_at_their_offset() {
        // a walks +x at 1 m/s, b walks −x at 1 m/s, 0.3 m to the side.
        let m = Meeting::predict(
            2.0,
            (0, Vec2::new(0.0, 0.0), Some(Vec2::new(1.0, 0.0))),
            (1, Vec2::new(0.8, 0.3), Some(Vec2::new(-1.0, 0.0))),
        );
        assert!((m.distance - 0.8544).abs() < 1e-3);
        assert!((m.closest - 0.3).abs() < 1e-12);
        assert!((m.relative_speed - 2.0).abs() < 1e-12);
    }

    #[test]
    fn without_velocities_the_meeting_is_where_it_is() {
        let m = Meeting::predict(
            0.0,
            (0, Vec2::new(0.0, 0.0), None),
            (1, Vec2::new(0.6, 0.8), Some(Vec2::new(1.0, 0.0))),
        );
        assert_eq!((m.distance, m.closest, m.relative_speed), (1.0, 1.0, 0.0));
    }

    #[test]
    fn a_pair_moving_apart_is_closest_now() {
        let m = Meeting::predict(
            0.0,
            (0, Vec2::new(0.0, 0.0), Some(Vec2::new(-1.0, 0.0))),
            (1, Vec2::new(0.5, 0.0), Some(Vec2::new(1.0, 0.0))),
        );
        assert_eq!(m.closest, 0.5);
    }
}
