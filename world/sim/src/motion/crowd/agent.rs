//! One pedestrian of the crowd: where it is, how fast it goes, where it is
//! heading, and the pause at a reached goal.

use super::goals::GoalSampler;
use super::CrowdParams;
use crate::geometry::Vec2;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

#[derive(Debug, Clone)]
pub(super) struct Agent {
    pub pos: Vec2,
    pub vel: Vec2,
    pub goal: Vec2,
    /// v0, m/s.
    pub desired_speed: f64,
    /// Seconds of pause left at the reached goal; 0 = walking.
    pub dwell_left: f64,
}

impl Agent {
    /// A walker at `pos` with a fresh goal, already at its desired speed.
    pub(crate) fn new(
        pos: Vec2,
        p: &CrowdParams,
        goals: &GoalSampler,
        rng: &mut ChaCha8Rng,
    ) -> Self {
        let (mean, sd) = p.desired_speed;
        let desired_speed = (mean + sd * standard_normal(rng)).clamp(0.5, 2.5);
        let goal = goals.sample(rng);
        let vel = (goal - pos).normalized() * desired_speed;
        Agent {
            pos,
            vel,
            goal,
            desired_speed,
            dwell_left: 0.0,
        }
    }

    /// The velocity the walker would like to have: v0 towards the goal, or
    /// standing still during a pause.
    pub(crate) fn desired_velocity(&self) -> Vec2 {
        if self.dwell_left > 0.0 {
            Vec2::ZERO
        } else {
            (self.goal - self.pos).normalized() * self.desired_speed
        }
    }

    /// The direction the walker looks in (for the anisotropy of the
    /// repulsion): towards its goal, or along its velocity while pausing.
    pub(crate) fn heading(&self) -> Vec2 {
        if self.dwell_left > 0.0 {
            self.vel.normalized()
        } else {
            (self.goal - self.pos).normalized()
        }
    }

    /// After a move: start a pause at a reached goal, count a pause down,
    /// and pick the next goal when it is over.
    pub(crate) fn update_goal(
        &mut self,
        dt: f64,
        p: &CrowdParams,
        goals: &GoalSampler,
        rng: &mut ChaCha8Rng,
    ) {
        if self.dwell_left > 0.0 {
            self.dwell_left -= dt;
            if self.dwell_left <= 0.0 {
                self.dwell_left = 0.0;
                self.goal = goals.sample(rng);
            }
        } else if self.pos.distance(self.goal) < p.arrival_radius {
            let (lo, hi) = p.dwell;
            self.dwell_left = lo + (hi - lo) * rng.gen::<f64>();
            if self.dwell_left <= 0.0 {
                self.goal = goals.sample(rng);
            }
        }
    }
}

/// A standard normal draw (Box–Muller), from two uniform draws.
pub(super) fn standard_normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = 1.0 - rng.gen::<f64>(); // (0, 1]
    let u2: f64 = rng.gen();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn standard_normal_has_unit_moments() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let xs: Vec<f64> = (0..20_000).map(|_| standard_normal(&mut rng)).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        assert!(mean.abs() < 0.03, "{mean}");
        assert!((var - 1.0).abs() < 0.05, "{var}");
    }
}
