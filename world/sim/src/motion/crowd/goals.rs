//! Where the walkers of the crowd go: anywhere in the field, or to a few
//! "stalls" of a market where people gather.

use crate::geometry::{Rect, Vec2};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// How goals are drawn.
#[derive(Debug, Clone, PartialEq)]
pub enum Goals {
    /// Uniformly in the field, at least 1 m from the walls.
    Uniform,
    /// At one of `count` stalls placed uniformly in the field when the crowd
    /// starts, within `spread` metres of it: a market, with crowding at the
    /// stalls and streams between them.
    Stalls { count: usize, spread: f64 },
}

impl Goals {
    pub(super) fn validate(&self) -> Result<(), String> {
        match self {
            Goals::Uniform => Ok(()),
            Goals::Stalls { count, spread } => {
                if *count == 0 {
                    Err("a market needs at least one stall".into())
                } else if !(spread.is_finite() && *spread >= 0.0) {
                    Err(format!(
                        "stall spread must be finite and >= 0, got {spread}"
                    ))
                } else {
                    Ok(())
                }
            }
        }
    }
}

/// Draws goals for one crowd.
#[derive(Debug, Clone)]
pub(super) struct GoalSampler {
    area: Rect,
    stalls: Vec<Vec2>,
    spread: f64,
}

impl GoalSampler {
    pub(crate) fn new(goals: &Goals, field: Rect, rng: &mut ChaCha8Rng) -> Self {
        let area = field.shrink(1.0);
        match goals {
            Goals::Uniform => GoalSampler {
                area,
                stalls: Vec::new(),
                spread: 0.0,
            },
            Goals::Stalls { count, spread } => GoalSampler {
                area,
                stalls: (0..*count).map(|_| area.sample(rng)).collect(),
                spread: *spread,
            },
        }
    }

    pub(crate) fn sample(&self, rng: &mut ChaCha8Rng) -> Vec2 {
        if self.stalls.is_empty() {
            return self.area.sample(rng);
        }
        let stall = self.stalls[rng.gen_range(0..self.stalls.len())];
        // Uniform in the disc of radius `spread` around the stall.
        let r = self.spread * rng.gen::<f64>().sqrt();
        let a = std::f64::consts::TAU * rng.gen::<f64>();
        self.area.clamp(stall + Vec2::new(r * a.cos(), r * a.sin()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn goals_fall_in_the_field_and_near_stalls() {
        let field = Rect::with_size(30.0, 20.0);
        let mut rng = ChaCha8Rng::seed_from_u64(4);
        let uniform = GoalSampler::new(&Goals::Uniform, field, &mut rng);
        for _ in 0..200 {
            assert!(field.shrink(1.0).contains(uniform.sample(&mut rng)));
        }
        let market = GoalSampler::new(
            &Goals::Stalls {
                count: 3,
                spread: 2.0,
            },
            field,
            &mut rng,
        );
        for _ in 0..200 {
            let g = market.sample(&mut rng);
            assert!(field.contains(g));
            let nearest = market
                .stalls
                .iter()
                .map(|s| s.distance(g))
                .fold(f64::INFINITY, f64::min);
            assert!(nearest <= 2.0 + 1e-9);
        }
        assert!(Goals::Stalls {
            count: 0,
            spread: 1.0
        }
        .validate()
        .is_err());
    }
}
